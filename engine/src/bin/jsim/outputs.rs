//! What a command writes, undone on failure: an [`Outputs`] guard remembers the files a run creates (and
//! the output directory, if the run created it) and removes them when dropped without [`Outputs::keep`] —
//! on an error, a panic or a Ctrl-C. A Ctrl-C only raises a flag ([`interrupted`]); long loops check it
//! between units of work, so no file is ever left half-written (every file is also written to a temporary
//! name and renamed).

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Route Ctrl-C (SIGINT, SIGTERM) to the flag; a second Ctrl-C exits at once.
pub fn install_interrupt_handler() {
    let _ = ctrlc::set_handler(|| {
        if INTERRUPTED.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!(
            "\njsim: interrupted — stopping after the current step and removing this run's output"
        );
    });
}

/// An error if Ctrl-C was pressed (call between units of work).
pub fn interrupted() -> Result<()> {
    if INTERRUPTED.load(Ordering::SeqCst) {
        bail!("interrupted");
    }
    Ok(())
}

/// The outputs of one run, removed unless kept.
pub struct Outputs {
    dir: PathBuf,
    created_dir: bool,
    files: Vec<PathBuf>,
    keep: bool,
}

impl Outputs {
    /// Create (if needed) the output directory `dir`.
    pub fn in_dir(dir: &Path) -> Result<Self> {
        let created_dir = !dir.exists();
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            created_dir,
            files: Vec::new(),
            keep: false,
        })
    }

    /// For one file: its parent directory is created if needed (and removed again on failure).
    pub fn for_file(path: &Path) -> Result<Self> {
        let parent = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let mut o = Self::in_dir(parent)?;
        o.add(path);
        Ok(o)
    }

    /// `dir/name`, recorded as an output of this run.
    pub fn path(&mut self, name: &str) -> PathBuf {
        let p = self.dir.join(name);
        self.add(&p);
        p
    }

    /// Record a file this run writes (only files that did not exist before are removed on failure).
    pub fn add(&mut self, path: &Path) {
        if !path.exists() {
            self.files.push(path.to_path_buf());
        }
    }

    /// The run succeeded: keep everything.
    pub fn keep(mut self) {
        self.keep = true;
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        if self.keep {
            return;
        }
        for f in &self.files {
            let _ = std::fs::remove_file(f);
        }
        if self.created_dir {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}
