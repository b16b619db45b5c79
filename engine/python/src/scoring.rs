//! `jsim.score`: the scoring step (`jsim score`) on arrays — the only call of the module that reads a truth.

use engine::scoring::{self, Measured, ScoreOptions, TrueStar};
use numpy::PyReadonlyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A 1-D float array (or sequence) as a vector, named in errors.
pub fn column(v: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<f64>> {
    let np = v.py().import("numpy")?;
    let a = np.call_method1("asarray", (v, "float64"))?;
    let a: PyReadonlyArray1<'_, f64> = a
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{name}: a 1-D array of numbers")))?;
    Ok(a.as_array().to_vec())
}

/// Score measured positions against a truth list: `measured` and `truth` are dicts of 1-D arrays, `x, y`
/// (pixels; `flags` optional in `measured`: a nonzero rejection bit keeps a star out of the accuracy,
/// not out of the completeness; `array` optional in both) and `mag` (or `mag_hw`) in `truth`. Returns a
/// dict: `bins` (a list of dicts: `mag_lo, mag_hi, n_true, n_matched, n_scored, completeness,
/// accuracy_mas, …`; an accuracy with fewer than 2 scored stars is None, never 0), `all`, `n_measured`,
/// `false_detections`, `offset_x_px`, `offset_y_px` — what `jsim score` writes to `score.json`.
#[pyfunction]
#[pyo3(signature = (measured, truth, *, plate_scale_mas, match_radius_px = scoring::DEFAULT_MATCH_RADIUS_PX, offset_search_px = scoring::DEFAULT_OFFSET_SEARCH_PX, bin_mag = 1.0))]
pub fn score<'py>(
    py: Python<'py>,
    measured: &Bound<'py, PyDict>,
    truth: &Bound<'py, PyDict>,
    plate_scale_mas: f64,
    match_radius_px: f64,
    offset_search_px: f64,
    bin_mag: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let get = |d: &Bound<'py, PyDict>, what: &str, names: &[&str]| -> PyResult<Option<Vec<f64>>> {
        for n in names {
            if let Some(v) = d.get_item(n)? {
                return column(&v, &format!("{what}[{n:?}]")).map(Some);
            }
        }
        Ok(None)
    };
    let need = |d: &Bound<'py, PyDict>, what: &str, names: &[&str]| -> PyResult<Vec<f64>> {
        get(d, what, names)?.ok_or_else(|| {
            PyValueError::new_err(format!("{what}: needs a column {}", names.join(" or ")))
        })
    };
    let (mx, my) = (
        need(measured, "measured", &["x"])?,
        need(measured, "measured", &["y"])?,
    );
    let mf = get(measured, "measured", &["flags"])?;
    let ma = get(measured, "measured", &["array"])?;
    let (tx, ty) = (need(truth, "truth", &["x"])?, need(truth, "truth", &["y"])?);
    let tm = need(truth, "truth", &["mag", "mag_hw", "hw"])?;
    let ta = get(truth, "truth", &["array"])?;
    let same = |n: usize, v: &Option<Vec<f64>>, what: &str| match v {
        Some(v) if v.len() != n => Err(PyValueError::new_err(format!(
            "{what}: {} values, x has {n}",
            v.len()
        ))),
        _ => Ok(()),
    };
    same(mx.len(), &Some(my.clone()), "measured[\"y\"]")?;
    same(mx.len(), &mf, "measured[\"flags\"]")?;
    same(mx.len(), &ma, "measured[\"array\"]")?;
    same(tx.len(), &Some(ty.clone()), "truth[\"y\"]")?;
    same(tx.len(), &Some(tm.clone()), "truth[\"mag\"]")?;
    same(tx.len(), &ta, "truth[\"array\"]")?;
    let reject = engine::analysis::epsf::fit::flags::REJECT;
    let m: Vec<Measured> = (0..mx.len())
        .map(|k| Measured {
            x_px: mx[k],
            y_px: my[k],
            array: ma.as_ref().map(|a| a[k] as u32).unwrap_or(0),
            usable: mf.as_ref().is_none_or(|f| (f[k] as u32) & reject == 0),
        })
        .collect();
    let t: Vec<TrueStar> = (0..tx.len())
        .map(|k| TrueStar {
            x_px: tx[k],
            y_px: ty[k],
            mag: tm[k],
            array: ta.as_ref().map(|a| a[k] as u32).unwrap_or(0),
        })
        .collect();
    let opts = ScoreOptions {
        match_radius_px,
        offset_search_px,
        bin_mag,
        plate_scale_mas,
    };
    let s = py
        .detach(|| scoring::score(&m, &t, &opts))
        .map_err(PyValueError::new_err)?;
    let json = serde_json::json!({
        "bins": s.bins,
        "all": s.all,
        "n_measured": s.n_measured,
        "false_detections": s.false_detections,
        "offset_x_px": s.offset_x_px,
        "offset_y_px": s.offset_y_px,
    });
    // an absent accuracy (NaN) is `null` in JSON and None in Python, as in `Analysis.summary`
    crate::convert::json_to_py(py, &json)
}
