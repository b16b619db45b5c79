//! The distributed astrometric solution on real MPI ranks: builds `jsim-mpi` (feature `mpi`, over the
//! distribution's OpenMPI) and solves one synthetic sequence — 1 200 sources × 50 exposures with the
//! instrument's calibration — with `mpirun -np 1`, `-np 2` and `-np 4`, and with the plain `jsim` on one
//! process. Every solved number (the sources' parameters and errors, the attitudes) agrees to 10⁻⁹ relative
//! (the design gives the same bits: engine::solution::ranks). Bad rank counts and commands that
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

/// The jsim-mpi ranks whose command line names `marker` (not mpirun's).
fn ranks_running(marker: &str) -> Vec<u32> {
    let mut pids = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let cmd = std::fs::read(e.path().join("cmdline")).unwrap_or_default();
        let args: Vec<String> = cmd
            .split(|b| *b == 0)
            .map(|a| String::from_utf8_lossy(a).into_owned())
            .collect();
        if args.first().is_some_and(|a| a.ends_with("jsim-mpi")) && args.iter().any(|a| a == marker)
        {
            pids.push(pid);
        }
    }
    pids
}

/// A rank killed mid-solve (SIGKILL, once the first checkpoint is on disk) leaves a resumable checkpoint:
/// the same command run again resumes from it and ends with the uninterrupted solution, and removes it.
#[test]
fn a_rank_killed_mid_solve_leaves_a_checkpoint_the_rerun_resumes_from() {
    let Some(mpirun) = mpirun_or_skip() else {
        return;
    };
    let bin = build_jsim_mpi();
    let dir = scratch("killed");
    std::fs::create_dir_all(&dir).expect("dir");
    // long enough to be killed midway in either profile
    let (sources, exposures) = if cfg!(debug_assertions) {
        ("3000", "100")
    } else {
        ("20000", "200")
    };
    let ck = dir.join("solution.checkpoint");
    let ck_arg = ck.display().to_string();
    let out = dir.join("solution");
    let args: Vec<String> = [
        "solve-synthetic",
        "--sources",
        sources,
        "--exposures",
        exposures,
        "--checkpoint",
        &ck_arg,
        "--out",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([out.display().to_string()])
    .collect();
    let mut child = Command::new(&mpirun)
        .args(["--oversubscribe", "-np", "2"])
        .arg(&bin)
        .args(&args)
        .env("RAYON_NUM_THREADS", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("mpirun starts");
    let t0 = std::time::Instant::now();
    while !ck.exists() {
        assert!(
            t0.elapsed().as_secs() < 300,
            "no checkpoint after 300 s (did the solve start?)"
        );
        assert!(
            child.try_wait().expect("mpirun").is_none(),
            "mpirun ended before its first checkpoint"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let victims = ranks_running(&ck_arg);
    assert_eq!(victims.len(), 2, "two ranks running: {victims:?}");
    let killed = Command::new("kill")
        .args(["-KILL", &victims[1].to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let status = child.wait().expect("mpirun ends");
    assert!(
        !status.success(),
        "the run finished before a rank could be killed: make the problem larger"
    );
    assert!(ck.exists(), "the killed run left its checkpoint");
    assert!(!out.join("sources.csv").exists());
    // rerun: resumed from the checkpoint, the uninterrupted solution, the checkpoint gone
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let (ok, err) = run_ranks(&mpirun, &bin, 2, &a);
    assert!(ok, "{err}");
    assert!(!ck.exists(), "the checkpoint is removed once done");
    let whole = dir.join("whole");
    let o = Command::new(env!("CARGO_BIN_EXE_jsim"))
        .args([
            "solve-synthetic",
            "--sources",
            sources,
            "--exposures",
            exposures,
            "--out",
        ])
        .arg(&whole)
        .output()
        .expect("jsim runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["sources.csv", "attitudes.csv"] {
        let worst = max_relative(&numbers(&whole.join(f)), &numbers(&out.join(f)));
        eprintln!(
            "{f}: killed and resumed against uninterrupted, largest relative difference {worst:e}"
        );
        assert!(worst <= 1e-9, "{f}: {worst:e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
