//! Engine values to Python: tables (the CLI files' columns) as dicts of numpy arrays, JSON values (the
//! reports `summary.json` holds) as Python objects, row-major planes as 2-D arrays handed over without a
//! copy.

use engine::io::csv::Cell;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A JSON value as the Python object `json.loads` gives.
pub fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).map_err(|e| PyValueError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Anything serialisable as the Python object of its JSON.
pub fn to_py_json<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let v = serde_json::to_value(v).map_err(|e| PyValueError::new_err(e.to_string()))?;
    json_to_py(py, &v)
}

/// A table as a dict of 1-D numpy arrays, one per column, in the header's order: float64 for real
/// columns, int64 for integer ones, a list of str for text.
pub fn table<'py>(
    py: Python<'py>,
    header: &[&str],
    rows: &[Vec<Cell>],
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (j, name) in header.iter().enumerate() {
        let cells = rows.iter().filter_map(|r| r.get(j));
        let kind = rows.first().and_then(|r| r.get(j));
        match kind {
            Some(Cell::I(_)) => {
                let v: Vec<i64> = cells
                    .map(|c| match c {
                        Cell::I(i) => *i,
                        Cell::F(f) => *f as i64,
                        Cell::S(_) => 0,
                    })
                    .collect();
                d.set_item(*name, PyArray1::from_vec(py, v))?;
            }
            Some(Cell::S(_)) => {
                let v: Vec<String> = cells.map(|c| c.to_string()).collect();
                d.set_item(*name, PyList::new(py, v)?)?;
            }
            _ => {
                let v: Vec<f64> = cells
                    .map(|c| match c {
                        Cell::F(f) => *f,
                        Cell::I(i) => *i as f64,
                        Cell::S(_) => f64::NAN,
                    })
                    .collect();
                d.set_item(*name, PyArray1::from_vec(py, v))?;
            }
        }
    }
    Ok(d)
}

/// A row-major plane `data[y * nx + x]` as a `(ny, nx)` array that owns the Rust buffer (no copy:
/// numpy's `flags.owndata` is false and `base` holds the buffer).
pub fn plane<'py, T: numpy::Element>(
    py: Python<'py>,
    data: Vec<T>,
    nx: usize,
    ny: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let a = Array2::from_shape_vec((ny, nx), data)
        .map_err(|e| PyValueError::new_err(format!("a {ny}×{nx} plane: {e}")))?;
    Ok(a.into_pyarray(py).into_any())
}

/// A 1-D float64 array.
pub fn vector<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}
