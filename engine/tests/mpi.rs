//! The distributed astrometric solution on real MPI ranks: builds `jsim-mpi` (feature `mpi`, over the
//! distribution's OpenMPI) and solves one synthetic sequence — 1 200 sources × 50 exposures with the
//! instrument's calibration — with `mpirun -np 1`, `-np 2` and `-np 4`, and with the plain `jsim` on one
//! process. Every solved number (the sources' parameters and errors, the attitudes) agrees to 10⁻⁹ relative
//! (the design gives the same bits: engine::analysis::solution::ranks). Bad rank counts and commands that
//! would write from every rank are refused by name.
//!
//! Needs `mpirun` and the MPI headers (`apt-get install libopenmpi-dev openmpi-bin libclang-dev`). Outside
//! CI the test is skipped (with a note) when `mpirun` is missing; with the `CI` environment variable set it
//! fails instead.

use std::path::{Path, PathBuf};
use std::process::Command;

mod support;
use support::{build_jsim_mpi, max_relative, mpirun_or_skip, numbers};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("jsim-mpi-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `mpirun -np n jsim-mpi args…`: (success, stderr).
fn run_ranks(mpirun: &Path, bin: &Path, n: usize, args: &[&str]) -> (bool, String) {
    let out = Command::new(mpirun)
        .args(["--oversubscribe", "-np", &n.to_string()])
        .arg(bin)
        .args(args)
        // one thread per rank: 4 ranks on a 2-core machine stay 4 threads
        .env("RAYON_NUM_THREADS", "1")
        // CI containers run as root, which OpenMPI refuses unless told
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .output()
        .expect("mpirun starts");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn one_two_and_four_ranks_give_the_same_solution() {
    let Some(mpirun) = mpirun_or_skip() else {
        return;
    };
    let bin = build_jsim_mpi();
    let dir = scratch("ranks");
    let args = |out: &Path| -> Vec<String> {
        [
            "solve-synthetic",
            "--sources",
            "1200",
            "--exposures",
            "50",
            "--out",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([out.display().to_string()])
        .collect()
    };
    // the plain jsim, one process
    let single = dir.join("jsim");
    let out = Command::new(env!("CARGO_BIN_EXE_jsim"))
        .args(args(&single))
        .output()
        .expect("jsim runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want_sources = numbers(&single.join("sources.csv"));
    let want_attitudes = numbers(&single.join("attitudes.csv"));
    assert_eq!(want_sources.len(), 1200 * 13);
    for n in [1, 2, 4] {
        let here = dir.join(format!("np{n}"));
        let a = args(&here);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let (ok, err) = run_ranks(&mpirun, &bin, n, &a);
        assert!(ok, "mpirun -np {n}: {err}");
        assert!(err.contains(&format!("on {n} rank(s)")), "{err}");
        let s = max_relative(&want_sources, &numbers(&here.join("sources.csv")));
        let t = max_relative(&want_attitudes, &numbers(&here.join("attitudes.csv")));
        eprintln!("{n} rank(s): largest relative difference {s:e} (sources), {t:e} (attitudes)");
        assert!(s <= 1e-9 && t <= 1e-9, "{n} ranks: {s:e} {t:e}");
        let summary = std::fs::read_to_string(here.join("solution.json")).expect("solution.json");
        assert!(summary.contains(&format!("\"ranks\": {n}")), "{summary}");
        assert!(summary.contains("\"converged\": true"), "{summary}");
    }
    // three ranks: not a power of two, named, and nothing written
    let three = dir.join("np3");
    let a = args(&three);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (ok, err) = run_ranks(&mpirun, &bin, 3, &a);
    assert!(
        !ok && err.contains("ranks = 3") && err.contains("power of two"),
        "{err}"
    );
    assert!(!three.exists(), "nothing is written on error");
    // the block iteration on two ranks, named
    let block = dir.join("block");
    let mut a = args(&block);
    a.extend(["--method".into(), "block".into()]);
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (ok, err) = run_ranks(&mpirun, &bin, 2, &a);
    assert!(!ok && err.contains("block"), "{err}");
    // a command that would write from every rank
    let (ok, err) = run_ranks(&mpirun, &bin, 2, &["psf", "--out", "/nonexistent/psf.fits"]);
    assert!(!ok && err.contains("`psf` runs on one rank"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
