//! `jsim` from Python: the engine session with numpy arrays in and out (PyO3, abi3: one wheel for every
//! CPython ≥ 3.9). Built by maturin as `jsim._jsim`; the package `jsim` (python/jsim) re-exports it, adds
//! the optional pandas view and carries the type stubs.
//!
//! Every number comes from the engine: the configuration is the engine's (`Config::with_override`, then
//! one validation), the simulation is a `Session` simulator, and the analysis is
//! `Session::analyze_input` — what `jsim analyze` runs. Tables have the CLI files' columns (truth CSV,
//! `catalogue.csv`, `experiment.csv`). The GIL is released while the engine works; long calls check for
//! Ctrl-C between images.

use pyo3::prelude::*;

mod config;
mod convert;
mod experiment;
mod exposure;
mod scoring;
mod session;
mod solution;
mod transit;

/// The engine's error as the Python exception a user expects: a bad configuration or argument is a
/// `ValueError` naming the field and its allowed range, a file problem an `OSError`, anything else a
/// `RuntimeError` (the engine's message, with its causes).
pub(crate) fn to_py(e: engine::Error) -> PyErr {
    use engine::Error as E;
    use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
    let mut msg = e.to_string();
    let mut source = std::error::Error::source(&e);
    while let Some(s) = source {
        let t = s.to_string();
        if !msg.contains(&t) {
            msg.push_str(": ");
            msg.push_str(&t);
        }
        source = s.source();
    }
    match e {
        E::Config(engine::config::ConfigError::Io { .. }) => PyOSError::new_err(msg),
        E::Config(_) | E::Countermeasure(_) | E::Scene(_) => PyValueError::new_err(msg),
        E::Io(_) | E::Plot(_) => PyOSError::new_err(msg),
        _ => PyRuntimeError::new_err(msg),
    }
}

/// `Result<T, E>` with an engine error into a Python result.
pub(crate) trait OrPy<T> {
    fn or_py(self) -> PyResult<T>;
}

impl<T, E: Into<engine::Error>> OrPy<T> for Result<T, E> {
    fn or_py(self) -> PyResult<T> {
        self.map_err(|e| to_py(e.into()))
    }
}

#[pymodule]
fn _jsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<config::PyConfig>()?;
    m.add_class::<session::PySession>()?;
    m.add_class::<exposure::PyExposure>()?;
    m.add_class::<session::PyAnalysis>()?;
    m.add_function(wrap_pyfunction!(experiment::experiment, m)?)?;
    m.add_function(wrap_pyfunction!(scoring::score, m)?)?;
    m.add_function(wrap_pyfunction!(solution::solve, m)?)?;
    m.add_function(wrap_pyfunction!(solution::solve_sequence, m)?)?;
    m.add_function(wrap_pyfunction!(transit::transit_flux, m)?)?;
    m.add_function(wrap_pyfunction!(transit::box_least_squares, m)?)?;
    m.add_function(wrap_pyfunction!(transit::transit, m)?)?;
    m.add("__version__", engine::VERSION)?;
    m.add("COUNTERMEASURES", engine::analysis::countermeasures::NAMES)?;
    Ok(())
}
