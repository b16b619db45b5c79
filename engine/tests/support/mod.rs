//! What the tests share (engine/tests/mpi.rs, slurm.rs, sequence.rs, long_jobs.rs): the CI rule, `mpirun`,
//! the `jsim-mpi` binary built beside the tests' `jsim`, the small sequence's configuration, the solutions'
//! comparison and the kill loop of the resumable jobs.
#![allow(dead_code)] // each test file uses its share

use std::path::{Path, PathBuf};
use std::process::Command;

/// Whether this is CI (`CI` set and not `0`/`false`): a missing tool then fails the test instead of
/// skipping it.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "0" && v != "false")
}

/// `mpirun`, or None with a note outside CI (in CI a missing mpirun fails the test).
pub fn mpirun_or_skip() -> Option<PathBuf> {
    let found = mpirun();
    if found.is_none() {
        assert!(
            !in_ci(),
            "mpirun is missing and CI is set: .ci/run installs openmpi-bin and libopenmpi-dev"
        );
        eprintln!(
            "SKIPPED: mpirun not found (apt-get install libopenmpi-dev openmpi-bin libclang-dev)"
        );
    }
    found
}

/// `mpirun` on the PATH (or in /usr/bin).
fn mpirun() -> Option<PathBuf> {
    std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .unwrap_or_default()
        .into_iter()
        .chain([PathBuf::from("/usr/bin")])
        .map(|d| d.join("mpirun"))
        .find(|p| p.is_file())
}

/// Build `jsim-mpi` (feature `mpi`) beside this test's `jsim`: the same profile and target directory.
pub fn build_jsim_mpi() -> PathBuf {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args([
        "build",
        "-p",
        "engine",
        "--features",
        "mpi",
        "--bin",
        "jsim-mpi",
    ]);
    if !cfg!(debug_assertions) {
        cmd.arg("--release");
    }
    let out = cmd
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "building jsim-mpi (feature mpi) failed — are libopenmpi-dev and libclang-dev installed?\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Path::new(env!("CARGO_BIN_EXE_jsim")).with_file_name("jsim-mpi")
}

/// Small arrays, a static Gaussian ACE, a sparse field: seconds per exposure of a sequence (`--set` each).
pub const SMALL_SEQUENCE: [&str; 15] = [
    "ace.case=\"gaussian\"",
    "instrument.detector_px=256",
    "instrument.photosensitive_px=240",
    "readout.channels=2",
    "readout.channel_width_px=128",
    "optics.pupil_samples=64",
    "optics.psf_oversampling=8",
    "optics.psf_radius_px=8",
    "band.wavelength_step_um=0.1",
    "fidelity.subpixels=4",
    "fidelity.stamp_radius_px=8",
    "fidelity.backend=\"cpu\"",
    "ace.span_s=60.0",
    "focal_plane.gap_px=40.0",
    "scene.bulge.density_per_arcmin2=40.0",
];

/// Every number of a CSV table, row by row (NaN where a cell is not one).
pub fn numbers(path: &Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .skip(1)
        .flat_map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().unwrap_or(f64::NAN))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The largest relative difference of two tables' numbers (NaN against NaN: none; lengths must agree).
pub fn max_relative(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "the tables differ in size");
    a.iter()
        .zip(b)
        .filter(|(x, y)| !(x.is_nan() && y.is_nan()))
        .map(|(x, y)| (x - y).abs() / x.abs().max(y.abs()).max(1e-300))
        .fold(0.0, f64::max)
}

/// Every file under `dir`, by its path relative to it.
pub fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).expect("read_dir").flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p);
            } else {
                out.push(
                    p.strip_prefix(dir)
                        .expect("under")
                        .to_string_lossy()
                        .to_string(),
                );
            }
        }
    }
    out.sort();
    out
}

/// Start the job `command` builds five times, killing each start outright (SIGKILL: no handler runs) at
/// 1/7 … 5/7 of `whole_s` (an uninterrupted run's time), each start resuming what the last left; `after`
/// runs after each. Returns how many starts were still running when their kill came.
pub fn kill_five_times(
    mut command: impl FnMut() -> Command,
    whole_s: f64,
    mut after: impl FnMut(),
) -> usize {
    let mut kills = 0;
    for k in 1..=5 {
        let mut child = command()
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("spawn");
        std::thread::sleep(std::time::Duration::from_secs_f64(whole_s * k as f64 / 7.0));
        if child.try_wait().expect("wait").is_none() {
            child.kill().expect("SIGKILL");
            kills += 1;
        }
        let _ = child.wait();
        after();
    }
    kills
}
