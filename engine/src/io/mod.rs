//! Input/output: FITS images and tables, CSV catalogues, PNG figures. Every file is written to a temporary
//! name and renamed into place, so an interrupted run never leaves a half-written output. [`shell_quote`] writes
//! a path as one shell word for the scripts and command lines we write or show.

pub mod analysis_input;
pub mod calibrated;
pub mod checkpoint;
pub mod crowded;
pub mod csv;
pub mod ecsv;
pub mod exposure;
pub mod fits;
pub mod focal_plane;
pub mod instrument;
pub mod plot;
pub mod products;
pub mod readout_header;
pub mod score;
pub mod sequence_view;
pub mod sky_reference;

use std::path::{Path, PathBuf};

/// An output or input problem, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The reason is part of the message and not a `source` too, so a chain of causes says it once.
    #[error("{path}: {}", reason_text(reason))]
    Io {
        path: PathBuf,
        reason: std::io::Error,
    },
    #[error("FITS file {path}: {message}")]
    Fits { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
}

/// An I/O error's text; a full disk or quota says what to do about it (the long jobs resume).
fn reason_text(e: &std::io::Error) -> String {
    use std::io::ErrorKind::{QuotaExceeded, StorageFull};
    match e.kind() {
        StorageFull | QuotaExceeded => format!(
            "the disk is full ({e}): free space and rerun the same command (a sequence, a sweep, a \
             solution with a checkpoint and a transit study resume where they stopped)"
        ),
        _ => e.to_string(),
    }
}

impl IoError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        IoError::Io {
            path: path.to_path_buf(),
            reason: source,
        }
    }
    pub fn fits(path: &Path, e: impl std::fmt::Display) -> Self {
        IoError::Fits {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

/// The temporary sibling a file is written to before the rename: `<name>.<pid>.tmp`.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(format!(".{}.tmp", std::process::id()));
    path.with_file_name(name)
}

/// Write `bytes` to `path` atomically (temporary file [`temp_path`] + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    // a failure names the file meant, not its temporary sibling (which is removed)
    write_via(path, &temp_path(path), |tmp| {
        std::fs::write(tmp, bytes).map_err(|e| IoError::io(path, e))
    })
}

/// Write `path` atomically through a writer that creates the file itself (an image encoder, say): `write`
/// writes the whole file at the temporary path it is given, which is then renamed into place. The
/// temporary path is [`temp_path`] with `path`'s extension appended again (`a.png` → `a.png.<pid>.tmp.png`),
/// for writers that choose the format from the extension. On any failure the temporary file is removed
/// and `path` is left as it was.
pub fn write_atomic_with<E: From<IoError>>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let mut tmp = temp_path(path).into_os_string();
    if let Some(ext) = path.extension() {
        tmp.push(".");
        tmp.push(ext);
    }
    write_via(path, Path::new(&tmp), write)
}

/// Run `write` on `tmp`, then rename it to `path`; remove `tmp` if either fails.
fn write_via<E: From<IoError>>(
    path: &Path,
    tmp: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let outcome = write(tmp)
        .and_then(|()| std::fs::rename(tmp, path).map_err(|e| E::from(IoError::io(path, e))));
    if outcome.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    outcome
}

/// Remove the temporary files ([`temp_path`], [`write_atomic_with`]) that a killed run left in `dir`:
/// `<name>.<pid>.tmp` and `<name>.<pid>.tmp.<ext>`, of another process than this one, for the names
/// `owned` accepts. Whoever calls it owns those names (no other live process writes them: a shard owns its
/// exposures, a study its directory). Returns how many went; a file that cannot be removed stays and is
/// tried again on the next run.
pub fn remove_stale_temps(dir: &Path, owned: impl Fn(&str) -> bool) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mine = std::process::id().to_string();
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        let Some((head, ext)) = name.rsplit_once(".tmp") else {
            continue;
        };
        let Some((base, pid)) = head.rsplit_once('.') else {
            continue;
        };
        let ext_ok = ext.is_empty()
            || Path::new(base)
                .extension()
                .is_some_and(|x| format!(".{}", x.to_string_lossy()) == ext);
        let is_pid = !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit());
        if ext_ok && is_pid && pid != mine && owned(base) && std::fs::remove_file(e.path()).is_ok()
        {
            removed += 1;
        }
    }
    removed
}

/// serde: an f64 read back from JSON, where serde_json wrote NaN (and ±∞) as `null`: `null` is NaN.
pub fn f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Create a directory (and parents), naming it in the error.
pub fn ensure_dir(dir: &Path) -> Result<(), IoError> {
    std::fs::create_dir_all(dir).map_err(|e| IoError::io(dir, e))
}

/// `word` as one POSIX shell word, for the scripts and command lines we write or show: always in single
/// quotes (so the result is one word whatever `word` holds, spaces, `$` and newlines included), each `'`
/// written as `'\''`. `/data/my run` → `'/data/my run'`, `it's` → `'it'\''s'`.
pub fn shell_quote(word: impl AsRef<std::ffi::OsStr>) -> String {
    format!(
        "'{}'",
        word.as_ref().to_string_lossy().replace('\'', r"'\''")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_words() {
        assert_eq!(shell_quote("/data/run"), "'/data/run'");
        assert_eq!(shell_quote(Path::new("/data/my run")), "'/data/my run'");
        assert_eq!(shell_quote("it's $HOME"), r"'it'\''s $HOME'");
    }

    #[test]
    fn a_killed_runs_temporary_files_are_removed_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("jsim-io-stale-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        ensure_dir(&dir).expect("dir");
        let me = std::process::id();
        let names = [
            "00001.csv.4242.tmp",        // a killed run's CSV: goes
            "lightcurve.png.77.tmp.png", // a killed image writer's: goes
            "00002.csv.4242.tmp",        // not owned: stays
            "00001.csv",                 // a finished file: stays
            "00001.csv.x42.tmp",         // not a pid: stays
            "00001.csv.4242.tmp.fits",   // not its writer's extension: stays
        ];
        for n in names {
            std::fs::write(dir.join(n), b"x").expect("write");
        }
        let ours = format!("00001.csv.{me}.tmp"); // this process's own, being written: stays
        std::fs::write(dir.join(&ours), b"x").expect("write");
        let removed =
            remove_stale_temps(&dir, |base| base == "00001.csv" || base == "lightcurve.png");
        assert_eq!(removed, 2);
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .expect("dir")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect();
        left.sort();
        let mut expected = vec![names[2], names[3], names[4], names[5], ours.as_str()];
        expected.sort();
        assert_eq!(left, expected);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn atomic_writes_leave_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("jsim-io-atomic-{}", std::process::id()));
        ensure_dir(&dir).expect("dir");
        let path = dir.join("a.png");
        write_atomic_with(&path, |tmp| {
            assert_eq!(tmp.extension().and_then(|e| e.to_str()), Some("png"));
            std::fs::write(tmp, b"x").map_err(|e| IoError::io(tmp, e))
        })
        .expect("written");
        assert_eq!(std::fs::read(&path).expect("read"), b"x");
        let failed: Result<(), IoError> = write_atomic_with(&dir.join("b.png"), |tmp| {
            std::fs::write(tmp, b"half").map_err(|e| IoError::io(tmp, e))?;
            Err(IoError::Format {
                path: tmp.to_path_buf(),
                message: "encoder failed".into(),
            })
        });
        assert!(failed.is_err());
        write_atomic(&dir.join("c.txt"), b"y").expect("written");
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .expect("list")
            .map(|e| e.expect("entry").file_name().to_string_lossy().to_string())
            .collect();
        names.sort();
        assert_eq!(names, ["a.png", "c.txt"]);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
