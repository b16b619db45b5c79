//! `jsim.transit_flux`: a limb-darkened transit's light curve (`engine::scene::transit`) on a numpy array of
//! times; `jsim.box_least_squares`: the transit search on a light curve (`engine::analysis::lightcurve`);
//! `jsim.transit`: a transit-monitoring stare (what `jsim transit` runs), its light curve as numpy arrays.

use crate::OrPy;
use crate::config::PyConfig;
use crate::scoring::column;
use engine::scene::transit::Transit;
use engine::studies::transit::{Spec, run};
use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

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

/// Simulate and analyse a transit stare: one bright target and its comparison stars read in windows,
/// plate after plate (`jsim transit`). Keyword arguments set the stare's fields (`target_hw`,
/// `duration_h`, `depth`, `comparisons`, `intra_pixel_amplitude`, `aperture_px`, `decorrelate`, … as in the
/// `[transit]` file). Returns a dict: the light curve's arrays (`time` in days, `flux` decorrelated,
/// `flux_raw`, `flux_aperture`, `flux_psf`, `x`, `y`, `sky`, `telemetry_x`, `telemetry_y`,
/// `telemetry_sigma`, `in_box`), the truth's `injected` flux (for scoring), and dicts `readout`,
/// `precision`, `budget`, `recovery` (None without a transit found) and `detections`.
#[pyfunction]
#[pyo3(signature = (config = None, **fields))]
pub fn transit<'py>(
    py: Python<'py>,
    config: Option<PyConfig>,
    fields: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let cfg = config.map(|c| c.inner).unwrap_or_default();
    cfg.validate().or_py()?;
    let mut spec = Spec::default();
    if let Some(f) = fields {
        for (k, v) in f.iter() {
            let key: String = k.extract()?;
            let text = crate::config::toml_text(&v)?;
            spec = spec.set(&key, &text).map_err(PyValueError::new_err)?;
        }
    }
    let (obs, r) = py
        .detach(|| run::run(&cfg, &spec))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let d = PyDict::new(py);
    let lc = &r.lc;
    for (name, v) in [
        ("time", &lc.t_days),
        ("flux", &lc.flux),
        ("flux_raw", &lc.flux_raw),
        ("flux_aperture", &lc.aperture_rel),
        ("flux_psf", &lc.psf_rel),
        ("x", &lc.x_px),
        ("y", &lc.y_px),
        ("sky", &lc.sky_e),
        ("telemetry_x", &lc.telemetry_x_mas),
        ("telemetry_y", &lc.telemetry_y_mas),
        ("telemetry_sigma", &lc.telemetry_sigma_mas),
    ] {
        d.set_item(name, v.clone().into_pyarray(py))?;
    }
    d.set_item("in_box", lc.in_box.clone().into_pyarray(py))?;
    let injected: Vec<f64> = obs.truth.iter().map(|t| t.transit_flux).collect();
    d.set_item("injected", injected.into_pyarray(py))?;
    d.set_item("aperture_px", lc.aperture_px)?;
    let json = |v: serde_json::Value| -> PyResult<Bound<'py, PyAny>> {
        let json_mod = py.import("json")?;
        json_mod.call_method1("loads", (v.to_string(),))
    };
    let readout = &r.readout;
    d.set_item(
        "readout",
        json(serde_json::json!({
            "plate_s": readout.plate_s,
            "sub_exposures": readout.sub_exposures,
            "exposure_s": readout.exposure_s,
            "longest_safe_exposure_s": readout.longest_safe_s,
            "cadence_s": readout.cadence_s,
            "read_noise_e": readout.read_noise_e,
        }))?,
    )?;
    d.set_item("precision", json(serde_json::json!(r.precision))?)?;
    d.set_item("budget", json(serde_json::json!(r.budget))?)?;
    d.set_item("recovery", json(serde_json::json!(r.recovery))?)?;
    d.set_item("detections", json(serde_json::json!(r.detections))?)?;
    Ok(d)
}
