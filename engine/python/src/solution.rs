//! `jsim.solve`: the astrometric solution (`engine::solution::solve`, what `jsim solve` runs after
//! reading a sequence's products) on arrays: observations on a tangent plane in, every source's five
//! parameters and every exposure's attitude out.

use crate::scoring::column;
use engine::solution::{
    ExposureGeometry, Method, Observation, Options, Reference, SourceModel, solve as solve_engine,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Column `name` of dict `d` (`what` names the dict in errors).
fn need(d: &Bound<'_, PyDict>, what: &str, name: &str) -> PyResult<Vec<f64>> {
    let v = d
        .get_item(name)?
        .ok_or_else(|| PyValueError::new_err(format!("{what}: needs a column {name:?}")))?;
    column(&v, &format!("{what}[{name:?}]"))
}

/// A column of indices: each a whole number ≥ 0.
fn indices(d: &Bound<'_, PyDict>, what: &str, name: &str) -> PyResult<Vec<usize>> {
    need(d, what, name)?
        .into_iter()
        .enumerate()
        .map(|(k, v)| {
            if v >= 0.0 && v.fract() == 0.0 && v < u32::MAX as f64 {
                Ok(v as usize)
            } else {
                Err(PyValueError::new_err(format!(
                    "{what}[{name:?}][{k}] = {v}: allowed a whole number 0 … 2³² − 2"
                )))
            }
        })
        .collect()
}

/// The iteration named by `method`: "cg" (conjugate gradients) or "block".
fn method_of(method: &str) -> PyResult<Method> {
    match method {
        "cg" => Ok(Method::ConjugateGradient),
        "block" => Ok(Method::Block),
        m => Err(PyValueError::new_err(format!(
            "method = {m:?}: allowed \"cg\" or \"block\""
        ))),
    }
}

/// A source's parameters' column names, in [`engine::solution::Params`]' order.
const PARAMS: [&str; 5] = ["xi_mas", "eta_mas", "pm_xi", "pm_eta", "parallax"];

/// Columns that must all have `n` values.
fn same_length(n: usize, what: &str, cols: &[(&str, usize)]) -> PyResult<()> {
    for (name, len) in cols {
        if *len != n {
            return Err(PyValueError::new_err(format!(
                "{what}[{name:?}]: {len} values, its first column has {n}"
            )));
        }
    }
    Ok(())
}

/// The astrometric solution of observations on one tangent plane (mas): `observations` a dict of 1-D arrays
/// `exposure, source` (indices), `xi_mas, eta_mas, sigma_mas`; `exposures` one row per exposure: `t_yr`
/// (years from the reference epoch), `parallax_xi, parallax_eta` (its parallax factors), `centre_xi_mas,
/// centre_eta_mas` (the point its attitude turns about) and, optionally, `stare` and `visit` (indices: the
/// groups whose observations of a source share an error, for `excess_noise`; default each exposure its own);
/// `references` the catalogue that fixes the frame:
/// `source`, `xi_mas, eta_mas, pm_xi, pm_eta, parallax` and their `sigma_…` (0 or inf leaves one free).
/// `model`: "full" (five parameters) or "position"; `method`: "cg" (conjugate gradients, the default) or
/// "block"; `excess_noise`: "none" (the default), "per-stare" or "per-visit" (the error a source's observations
/// share within a group, measured from the residuals between groups and carried into the σ). Returns a dict of arrays per source (`xi_mas, eta_mas, pm_xi, pm_eta, parallax`, `sigma_…`,
/// `observations`, `chi2`), per exposure (`p, q, offset_xi_mas, offset_eta_mas`: `o = c + [[p, −q], [q, p]]
/// (s − c) + offset`; NaN for an exposure left out, listed in `skipped_exposures`) and `iterations, converged,
/// rejected, chi2_per_dof`. Bad input is a `ValueError`
/// naming the field.
#[pyfunction]
#[pyo3(signature = (observations, exposures, references, *, model = "full", method = "cg", tolerance_sigma = 1e-3, clip_sigma = 5.0, max_iterations = 500, excess_noise = "none"))]
#[allow(clippy::too_many_arguments)]
pub fn solve<'py>(
    py: Python<'py>,
    observations: &Bound<'py, PyDict>,
    exposures: &Bound<'py, PyDict>,
    references: &Bound<'py, PyDict>,
    model: &str,
    method: &str,
    tolerance_sigma: f64,
    clip_sigma: f64,
    max_iterations: usize,
    excess_noise: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let model =
        SourceModel::parse(model).map_err(|e| PyValueError::new_err(format!("model = {e}")))?;
    let method = method_of(method)?;
    let excess = engine::solution::ExcessNoise::parse(excess_noise)
        .map_err(|e| PyValueError::new_err(format!("excess_noise: {e}")))?;
    let obs = observations_of(observations)?;
    let geometry = exposures_of(exposures)?;
    let (refs, rs) = references_of(references)?;
    let os = obs.iter().map(|o| o.source());
    let n_sources = os
        .chain(rs.iter().copied())
        .map(|s| s + 1)
        .max()
        .unwrap_or(0);
    let opt = Options {
        model,
        method,
        tolerance_sigma,
        clip_sigma,
        max_iterations,
        excess,
        ..Options::default()
    };
    let sol = py
        .detach(|| solve_engine(&obs, &geometry, &refs, n_sources, &opt))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    solution_dict(py, sol)
}

/// The observations' columns (`exposure, source, xi_mas, eta_mas, sigma_mas`) as the solution's
/// [`Observation`]s, on array 0 at the axis (the calibration is not solved from Python).
fn observations_of(observations: &Bound<'_, PyDict>) -> PyResult<Vec<Observation>> {
    let o = "observations";
    let (oe, os) = (
        indices(observations, o, "exposure")?,
        indices(observations, o, "source")?,
    );
    let (ox, oy, osig) = (
        need(observations, o, "xi_mas")?,
        need(observations, o, "eta_mas")?,
        need(observations, o, "sigma_mas")?,
    );
    same_length(
        oe.len(),
        o,
        &[
            ("source", os.len()),
            ("xi_mas", ox.len()),
            ("eta_mas", oy.len()),
            ("sigma_mas", osig.len()),
        ],
    )?;
    Ok((0..oe.len())
        .map(|k| Observation::new(oe[k], os[k], [ox[k], oy[k]], osig[k], 0, [0.0, 0.0]))
        .collect())
}

/// The exposures' columns (`t_yr`, parallax factors, centres, optional `stare` and `visit`) as their
/// [`ExposureGeometry`].
fn exposures_of(exposures: &Bound<'_, PyDict>) -> PyResult<Vec<ExposureGeometry>> {
    let e = "exposures";
    let t = need(exposures, e, "t_yr")?;
    let cols: Vec<Vec<f64>> = [
        "parallax_xi",
        "parallax_eta",
        "centre_xi_mas",
        "centre_eta_mas",
    ]
    .iter()
    .map(|n| need(exposures, e, n))
    .collect::<PyResult<_>>()?;
    same_length(
        t.len(),
        e,
        &[
            ("parallax_xi", cols[0].len()),
            ("parallax_eta", cols[1].len()),
            ("centre_xi_mas", cols[2].len()),
            ("centre_eta_mas", cols[3].len()),
        ],
    )?;
    // the groups that share an error: given, or every exposure its own
    let group = |name: &str| -> PyResult<Vec<usize>> {
        if exposures.contains(name)? {
            let g = indices(exposures, e, name)?;
            same_length(t.len(), e, &[(name, g.len())])?;
            Ok(g)
        } else {
            Ok((0..t.len()).collect())
        }
    };
    let (stare, visit) = (group("stare")?, group("visit")?);
    Ok((0..t.len())
        .map(|k| ExposureGeometry {
            t_yr: t[k],
            parallax_factor: [cols[0][k], cols[1][k]],
            centre_mas: [cols[2][k], cols[3][k]],
            to_plane: [1.0, 0.0, 0.0, 1.0],
            stare: stare[k],
            visit: visit[k],
        })
        .collect())
}

/// The reference catalogue's columns (`source`, the five parameters and their `sigma_…`) as [`Reference`]s,
/// with the source indices (the solution's source count reads them).
fn references_of(references: &Bound<'_, PyDict>) -> PyResult<(Vec<Reference>, Vec<usize>)> {
    let r = "references";
    let rs = indices(references, r, "source")?;
    let values: Vec<Vec<f64>> = PARAMS
        .iter()
        .map(|n| need(references, r, n))
        .collect::<PyResult<_>>()?;
    let sigmas: Vec<Vec<f64>> = PARAMS
        .iter()
        .map(|n| need(references, r, &format!("sigma_{n}")))
        .collect::<PyResult<_>>()?;
    for (n, v) in PARAMS.iter().zip(&values) {
        same_length(rs.len(), r, &[(n, v.len())])?;
    }
    for (n, v) in PARAMS.iter().zip(&sigmas) {
        same_length(rs.len(), r, &[(&format!("sigma_{n}"), v.len())])?;
    }
    let refs: Vec<Reference> = (0..rs.len())
        .map(|k| Reference {
            source: rs[k],
            params: std::array::from_fn(|j| values[j][k]),
            sigma: std::array::from_fn(|j| sigmas[j][k]),
        })
        .collect();
    Ok((refs, rs))
}

/// The solution as the dict `jsim.solve` returns.
fn solution_dict<'py>(
    py: Python<'py>,
    sol: engine::solution::Solution,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let vector = |v: Vec<f64>| crate::convert::vector(py, v);
    for (j, n) in PARAMS.iter().enumerate() {
        d.set_item(
            *n,
            vector(sol.sources.iter().map(|s| s.params[j]).collect()),
        )?;
        d.set_item(
            format!("sigma_{n}"),
            vector(sol.sources.iter().map(|s| s.sigma[j]).collect()),
        )?;
    }
    d.set_item(
        "observations",
        vector(sol.sources.iter().map(|s| s.observations as f64).collect()),
    )?;
    d.set_item("chi2", vector(sol.sources.iter().map(|s| s.chi2).collect()))?;
    d.set_item("p", vector(sol.attitudes.iter().map(|a| a.p).collect()))?;
    d.set_item("q", vector(sol.attitudes.iter().map(|a| a.q).collect()))?;
    d.set_item(
        "offset_xi_mas",
        vector(sol.attitudes.iter().map(|a| a.offset_mas[0]).collect()),
    )?;
    d.set_item(
        "offset_eta_mas",
        vector(sol.attitudes.iter().map(|a| a.offset_mas[1]).collect()),
    )?;
    d.set_item("skipped_exposures", sol.skipped_exposures)?;
    d.set_item("iterations", sol.iterations)?;
    d.set_item("converged", sol.converged)?;
    d.set_item("rejected", sol.rejected)?;
    d.set_item("chi2_per_dof", sol.chi2_per_dof)?;
    d.set_item(
        "excess_tau_mas",
        vector(sol.excess.iter().map(|b| b.tau_mas).collect()),
    )?;
    d.set_item(
        "excess_sigma_obs_mas",
        vector(sol.excess.iter().map(|b| b.sigma_obs_mas).collect()),
    )?;
    Ok(d)
}

/// `jsim.solve_sequence(sequence, *, exposures=None, out=None, model="auto", method="cg", every=1,
/// excess_noise="none")`:
/// what `jsim solve` does (`engine::studies::sequence::solve_study`): the solution of a sequence that has run, from its products,
/// for the first N exposures of each N in `exposures` (default: all that have run), scored against its truth,
/// its files written to `out` (default `solution/` in the sequence's directory). Returns `solution.json`'s
/// summaries (one dict per N) and the output directory. Bad input is a `ValueError` naming it.
#[pyfunction]
#[pyo3(signature = (sequence, *, exposures = None, out = None, model = "auto", method = "cg", every = 1, excess_noise = "none"))]
pub fn solve_sequence<'py>(
    py: Python<'py>,
    sequence: std::path::PathBuf,
    exposures: Option<Vec<usize>>,
    out: Option<std::path::PathBuf>,
    model: &str,
    method: &str,
    every: usize,
    excess_noise: &str,
) -> PyResult<Bound<'py, PyDict>> {
    use engine::studies::sequence::{solution as sq, solve_study as study};
    let model = SourceModel::parse_or_auto(model)
        .map_err(|e| PyValueError::new_err(format!("model = {e}")))?;
    let method = method_of(method)?;
    let excess = engine::solution::ExcessNoise::parse(excess_noise)
        .map_err(|e| PyValueError::new_err(format!("excess_noise: {e}")))?;
    let err = |e: engine::studies::sequence::SequenceError| PyValueError::new_err(e.to_string());
    let p = sq::read_products_every(&sequence, every).map_err(err)?;
    let req = study::Request {
        exposures: study::exposures_to_solve(&exposures.unwrap_or_default(), p.exposures_run)
            .map_err(err)?,
        spec: sq::SolveSpec {
            model,
            method,
            excess,
            ..Default::default()
        },
        checkpoint: None,
        out: out.unwrap_or_else(|| sequence.join("solution")),
    };
    // the solution runs without the GIL
    let done = py
        .detach(|| {
            let truth = sq::read_truth(&sequence, &p)?;
            study::run(&p, &truth, &req, 1, &mut |_| {}, &mut |_| {})
        })
        .map_err(err)?;
    let text = serde_json::to_string(&done.summary)
        .map_err(|e| PyValueError::new_err(format!("solution.json: {e}")))?;
    let d = PyDict::new(py);
    d.set_item(
        "summary",
        py.import("json")?.call_method1("loads", (text,))?,
    )?;
    d.set_item("out", req.out.to_string_lossy().into_owned())?;
    Ok(d)
}
