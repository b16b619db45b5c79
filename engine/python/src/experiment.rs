//! `jsim.experiment`: the paper's experiment (what `jsim experiment` runs), rows as arrays.

use crate::config::PyConfig;
use crate::session::{plan_of, warn_notes};
use crate::{OrPy, convert};
use engine::config::{AceCase, ReadoutOrder};
use engine::io::products;
use engine::session::Session;
use engine::studies::experiment::{self as study, ExperimentError};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ops::ControlFlow;

/// Accuracy against magnitude per ACE case, readout order and countermeasure — the rows of
/// `experiment.csv` as a dict of arrays (`ace, readout, countermeasure, mag, accuracy_mas, sem_mas,
/// crlb_mas, predicted_mas, n_images, time_s`). Defaults as `jsim experiment`: both ACE cases, the rolling
/// readout, Hw 12–14.5. `progress(done, total)` is called after each image; Ctrl-C stops between images.
#[pyfunction]
#[pyo3(signature = (config = None, *, aces = None, readouts = None, mags = None, countermeasures = None, progress = None))]
pub fn experiment<'py>(
    py: Python<'py>,
    config: Option<PyConfig>,
    aces: Option<Vec<String>>,
    readouts: Option<Vec<String>>,
    mags: Option<Vec<f64>>,
    countermeasures: Option<&Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let base = config.map(|c| c.inner).unwrap_or_default();
    base.validate().or_py()?;
    let aces = aces
        .unwrap_or_else(|| vec!["gaussian".into(), "realistic".into()])
        .iter()
        .map(|a| AceCase::parse(a.trim()))
        .collect::<Result<Vec<_>, _>>()
        .or_py()?;
    let readouts = readouts
        .unwrap_or_else(|| vec!["rolling".into()])
        .iter()
        .map(|r| ReadoutOrder::parse(r.trim()))
        .collect::<Result<Vec<_>, _>>()
        .or_py()?;
    let mags = mags.unwrap_or_else(|| vec![12.0, 12.5, 13.0, 13.5, 14.0, 14.5]);
    if mags.is_empty() || mags.iter().any(|m| !m.is_finite()) {
        return Err(PyValueError::new_err(
            "mags: give finite magnitudes, e.g. [12, 12.5]",
        ));
    }
    let plan = match countermeasures {
        Some(c) => plan_of(c)?,
        None => plan_of(&pyo3::types::PyString::new(py, "none,yzones").into_any())?,
    };
    let datasets = study::grid(&base, &aces, &readouts, &mags);
    let total = datasets.len() * base.fidelity.images;
    let session = Session::new();
    let mut rows = Vec::new();
    let mut done = 0usize;
    let mut stop: Option<PyErr> = None;
    for cfg in &datasets {
        let sim = py.detach(|| session.new_simulator(cfg)).or_py()?;
        warn_notes(py, &session)?;
        let result = py.detach(|| {
            study::run_dataset(&sim, &plan, &mut |_| {
                done += 1;
                Python::attach(|py| {
                    let step = py.check_signals().and_then(|_| match &progress {
                        Some(cb) => cb.call1(py, (done, total)).map(|_| ()),
                        None => Ok(()),
                    });
                    match step {
                        Ok(()) => ControlFlow::Continue(()),
                        Err(e) => {
                            stop = Some(e);
                            ControlFlow::Break(())
                        }
                    }
                })
            })
        });
        match result {
            Ok((r, _)) => rows.extend(r),
            Err(ExperimentError::Stopped) => {
                return Err(stop
                    .unwrap_or_else(|| pyo3::exceptions::PyKeyboardInterrupt::new_err("stopped")));
            }
            Err(e) => return Err(crate::to_py(e.into())),
        }
    }
    convert::table(
        py,
        &products::EXPERIMENT_HEADER,
        &products::experiment_rows(&rows),
    )
}
