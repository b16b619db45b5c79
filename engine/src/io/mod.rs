//! Input/output: FITS images and tables, CSV catalogues, PNG figures. Every file is written to a temporary
//! name and renamed into place, so an interrupted run never leaves a half-written output.

pub mod csv;
pub mod exposure;
pub mod fits;
pub mod plot;
pub mod products;

use std::path::{Path, PathBuf};

/// An output or input problem, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("FITS file {path}: {message}")]
    Fits { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
}

impl IoError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        IoError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub fn fits(path: &Path, e: impl std::fmt::Display) -> Self {
        IoError::Fits {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

/// The temporary sibling a file is written to before the rename.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(format!(".{}.tmp", std::process::id()));
    path.with_file_name(name)
}

/// Write `bytes` to `path` atomically (temporary file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let tmp = temp_path(path);
    std::fs::write(&tmp, bytes).map_err(|e| IoError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        IoError::io(path, e)
    })
}

/// Create a directory (and parents), naming it in the error.
pub fn ensure_dir(dir: &Path) -> Result<(), IoError> {
    std::fs::create_dir_all(dir).map_err(|e| IoError::io(dir, e))
}
