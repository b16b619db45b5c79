//! The Python module's pytest suite (engine/python/tests), run by `cargo test --workspace` so that the one
//! test command covers Rust and Python alike.
//!
//! It makes a virtual environment under the target directory (once), installs what the suite needs
//! (maturin, numpy, pytest, astropy, and matplotlib and photutils for the docs' scripts:
//! `engine/python/pyproject.toml`'s `test` extra), builds the module's wheel with maturin in the dev profile
//! (incremental: the workspace's own target directory), installs it and runs pytest with `JSIM_BIN` pointing
//! at the `jsim` binary cargo built, for the CLI comparisons.
//! Without a Python 3 this test fails in CI (`CI` set) and says why elsewhere; a module that does not build
//! or import fails it everywhere.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Python packages the suite needs (the build backend and the `test` extra).
/// What the suite needs: the build tool, the test runner, numpy and astropy for the module's tests, batman
/// (the transit model's outside reference, GPL-3: used by the tests only, never linked), and matplotlib and
/// photutils for the docs' example and benchmark scripts (`test_docs_commands.py` runs them), and
/// astroscrappy (L.A.Cosmic: the outside reference of the single-exposure cosmic-ray detection), and scipy
/// (its least squares: the astrometric solution's outside reference).
const PACKAGES: [&str; 9] = [
    "maturin>=1.9,<2",
    "numpy>=1.21",
    "pytest>=7",
    "astropy>=5",
    "matplotlib>=3.5",
    "photutils>=1.9",
    "batman-package>=2.4",
    "astroscrappy>=1.1",
    "scipy>=1.7",
];

fn run(cmd: &mut Command, what: &str) {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: could not start {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}):\n--- stdout\n{}\n--- stderr\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn python3() -> Option<PathBuf> {
    let candidate = std::env::var_os("JSIM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("python3"));
    Command::new(&candidate)
        .args(["-c", "import sys, venv; assert sys.version_info >= (3, 9)"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|_| candidate)
}

#[test]
fn the_python_module_passes_its_pytest_suite() {
    let Some(python) = python3() else {
        let msg = "no Python ≥ 3.9 with venv (python3, or JSIM_PYTHON): the Python module's tests \
                   cannot run (Debian: apt-get install python3-venv)";
        if std::env::var_os("CI").is_some() {
            panic!("{msg}");
        }
        eprintln!("SKIPPED: {msg}");
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let venv = tmp.join("pyenv");
    let bin = venv.join("bin");
    if !bin.join("python").exists() {
        run(
            Command::new(&python).args(["-m", "venv"]).arg(&venv),
            "creating the virtual environment",
        );
    }
    let vpython = bin.join("python");
    let have_all = Command::new(&vpython)
        .args([
            "-c",
            "import maturin, numpy, pytest, astropy, matplotlib, photutils, batman, astroscrappy, scipy",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_all {
        run(
            Command::new(&vpython)
                .args(["-m", "pip", "install", "--quiet"])
                .args(PACKAGES),
            "installing the test requirements",
        );
    }
    let wheels = tmp.join("wheels");
    let _ = std::fs::remove_dir_all(&wheels);
    run(
        Command::new(bin.join("maturin"))
            .args(["build", "--profile", "dev", "--quiet", "-m"])
            .arg(root.join("engine/python/Cargo.toml"))
            .arg("--out")
            .arg(&wheels)
            .env("VIRTUAL_ENV", &venv),
        "building the jsim wheel (maturin)",
    );
    let wheel = std::fs::read_dir(&wheels)
        .expect("the wheel directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .expect("maturin wrote a wheel");
    run(
        Command::new(&vpython)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--force-reinstall",
                "--no-deps",
            ])
            .arg(&wheel),
        "installing the jsim wheel",
    );
    run(
        Command::new(&vpython)
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            // each test's time, for whoever looks into the suite's length (target/tmp/pytest.xml)
            .arg(format!("--junitxml={}", tmp.join("pytest.xml").display()))
            .arg(root.join("engine/python/tests"))
            .env("JSIM_BIN", env!("CARGO_BIN_EXE_jsim"))
            .current_dir(tmp),
        "the Python module's pytest suite",
    );
}
