//! A solution's checkpoint kept in a file (`--checkpoint FILE`): written atomically, so that a run killed
//! while writing leaves the last whole one ([`crate::solution::checkpoint`] makes its bytes).

use crate::solution::CheckpointStore;
use std::path::PathBuf;

/// A checkpoint in the file at `path`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileStore {
    pub path: PathBuf,
}

impl FileStore {
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }
}

impl CheckpointStore for FileStore {
    fn load(&self) -> Result<Option<Vec<u8>>, String> {
        match std::fs::read(&self.path) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e.to_string()),
        }
    }

    fn save(&self, bytes: &[u8]) -> Result<(), String> {
        super::write_atomic(&self.path, bytes).map_err(|e| e.to_string())
    }

    fn clear(&self) {
        let _ = std::fs::remove_file(&self.path);
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }
}
