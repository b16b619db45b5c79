//! `jsim.transit_flux`: a limb-darkened transit's light curve (`engine::scene::transit`) on a numpy array of
//! times; `jsim.box_least_squares`: the transit search on a light curve (`engine::analysis::lightcurve`).

use crate::scoring::column;
use engine::scene::transit::Transit;
use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The relative flux of a star with a transiting planet (circular orbit, quadratic limb darkening) at
/// times `t_days` (days): `t0` mid-transit, `per` the period (days), `rp` the planet's radius and `a` the
/// orbit's semi-major axis in stellar radii, `inc` the inclination (degrees), `u = (u1, u2)`; each value
/// averaged over `exp_time` days sampled `supersample` times (batman's `exp_time` and
/// `supersample_factor`). A bad parameter is a ValueError naming it.
#[pyfunction]
#[pyo3(signature = (t_days, *, t0, per, rp, a, inc, u, exp_time = 0.0, supersample = 1))]
#[allow(clippy::too_many_arguments)]
pub fn transit_flux<'py>(
    py: Python<'py>,
    t_days: &Bound<'py, PyAny>,
    t0: f64,
    per: f64,
    rp: f64,
    a: f64,
    inc: f64,
    u: (f64, f64),
    exp_time: f64,
    supersample: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let t = column(t_days, "t_days")?;
    let transit = Transit {
        t0_days: t0,
        period_days: per,
        rp_over_rs: rp,
        a_over_rs: a,
        inclination_deg: inc,
        u1: u.0,
        u2: u.1,
    };
    transit.validate().map_err(PyValueError::new_err)?;
    if !(exp_time.is_finite() && exp_time >= 0.0 && (1..=1000).contains(&supersample)) {
        return Err(PyValueError::new_err(format!(
            "exp_time {exp_time} (allowed ≥ 0 days) or supersample {supersample} (allowed 1 … 1000)"
        )));
    }
    let f: Vec<f64> = t
        .iter()
        .map(|&x| {
            if exp_time > 0.0 {
                transit.mean_flux(x - exp_time / 2.0, exp_time, supersample)
            } else {
                transit.flux(x)
            }
        })
        .collect();
    Ok(f.into_pyarray(py))
}

/// Box least squares (`engine::analysis::lightcurve`): the most significant box over the trial periods and
/// durations (days) of a light curve `t_days, flux, sigma`. Returns a dict — `period, t0, duration, depth,
/// depth_sigma, snr, points_in` — or None when no box holds a point.
#[pyfunction]
#[pyo3(signature = (t_days, flux, sigma, *, periods, durations))]
pub fn box_least_squares<'py>(
    py: Python<'py>,
    t_days: &Bound<'py, PyAny>,
    flux: &Bound<'py, PyAny>,
    sigma: &Bound<'py, PyAny>,
    periods: &Bound<'py, PyAny>,
    durations: &Bound<'py, PyAny>,
) -> PyResult<Option<Bound<'py, pyo3::types::PyDict>>> {
    let (t, f, s) = (
        column(t_days, "t_days")?,
        column(flux, "flux")?,
        column(sigma, "sigma")?,
    );
    if f.len() != t.len() || s.len() != t.len() {
        return Err(PyValueError::new_err(format!(
            "t_days ({}), flux ({}) and sigma ({}): one value each",
            t.len(),
            f.len(),
            s.len()
        )));
    }
    let (p, d) = (column(periods, "periods")?, column(durations, "durations")?);
    let Some(fit) = engine::analysis::lightcurve::box_least_squares(&t, &f, &s, &p, &d) else {
        return Ok(None);
    };
    let out = pyo3::types::PyDict::new(py);
    out.set_item("period", fit.period_days)?;
    out.set_item("t0", fit.t0_days)?;
    out.set_item("duration", fit.duration_days)?;
    out.set_item("depth", fit.depth)?;
    out.set_item("depth_sigma", fit.depth_sigma)?;
    out.set_item("snr", fit.snr)?;
    out.set_item("points_in", fit.points_in)?;
    Ok(Some(out))
}
