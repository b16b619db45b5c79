//! The sweep's error type: every failure names the file, field, unit or directory at fault.

use crate::io::{IoError, plot};
use std::path::{Path, PathBuf};

/// A sweep problem, always naming the file, field, unit or directory at fault.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("sweep file {path}: {message}")]
    File { path: PathBuf, message: String },
    #[error("sweep file {path}: grid parameter `{field}`: {message}")]
    Grid {
        path: PathBuf,
        field: String,
        message: String,
    },
    #[error("--shard {spec}: {message}")]
    Shard { spec: String, message: String },
    #[error(
        "output directory {dir} holds another sweep (hash {found} in sweep.json; this sweep is {expected}): choose another --out or remove that directory"
    )]
    OtherSweep {
        dir: PathBuf,
        found: String,
        expected: String,
    },
    #[error(
        "{dir} is not a sweep directory (no readable sweep.json: {message}); run `jsim sweep` first"
    )]
    NotASweep { dir: PathBuf, message: String },
    #[error("mixed sweeps in {dir}: {message}")]
    Mixed { dir: PathBuf, message: String },
    #[error(
        "{missing} of {total} units are missing: {list}. Rerun `jsim sweep` with the same arguments (or resubmit) to compute them"
    )]
    Missing {
        missing: usize,
        total: usize,
        list: String,
        units: Vec<usize>,
    },
    #[error("unit {unit} (point {point}, exposure {exposure}): {message}")]
    Unit {
        unit: usize,
        point: usize,
        exposure: usize,
        message: String,
    },
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Io(#[from] IoError),
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
}

pub(super) fn io_err(path: &Path, e: std::io::Error) -> SweepError {
    SweepError::Io(IoError::io(path, e))
}
