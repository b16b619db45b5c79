//! Every file a command writes is declared in `engine::io::products::files` and described in docs/: each
//! command that writes a directory runs on a small scene (with the options that add files: --save-images,
//! --keep-images, persistence, --write-products, --magnitudes, --emit-slurm), every file it leaves is looked
//! up in the declared list for that command, every declared file is met at least once, and every part of every
//! declared name appears in the docs.

use engine::io::products::files::{self, Command as Cmd, OUTPUT_FILES};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

mod support;
use support::SMALL_SEQUENCE as SMALL;

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Runs `c` and fails with its stderr when it fails.
fn ok(mut c: Command) {
    let out = c.output().expect("run jsim");
    assert!(
        out.status.success(),
        "{c:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `jsim ARGS` with the small configuration's `--set`s.
fn small(args: &[&str]) -> Command {
    let mut c = jsim();
    c.args(args);
    for s in SMALL {
        c.args(["--set", s]);
    }
    c
}

/// Every file under `dir`, as paths relative to it with `/` between parts.
fn listing(dir: &Path) -> Vec<String> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                let rel = p.strip_prefix(base).expect("under the base");
                let parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect();
                out.push(parts.join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// `path` (under `dir`) must be declared for one of `by`: its pattern is added to `seen`.
fn expect_declared(dir: &Path, path: &str, by: &[Cmd], seen: &mut BTreeSet<&'static str>) {
    let d = by
        .iter()
        .find_map(|&c| files::declared(c, path))
        .unwrap_or_else(|| {
            panic!(
                "{}: {path} is not declared for {by:?} in io::products::files",
                dir.display()
            )
        });
    seen.insert(d.pattern);
}

/// Each file under `dir` must be declared for one of `by`; the patterns met are added to `seen`.
fn check(dir: &Path, by: &[Cmd], seen: &mut BTreeSet<&'static str>) {
    let found = listing(dir);
    assert!(!found.is_empty(), "{}: nothing written", dir.display());
    for path in found {
        expect_declared(dir, &path, by, seen);
    }
}

#[test]
fn every_file_written_is_declared_and_every_declared_file_is_written() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("jsim-output-files-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch");
    let mut seen = BTreeSet::new();
    simulate_analyse_and_score(&dir, &mut seen);
    experiment_and_crowded(&dir, &mut seen);
    sequence_and_solutions(&dir, &mut seen);
    transit_runs(&dir, &mut seen);
    sweep_runs(&dir, &mut seen);
    bench_run(&dir, &mut seen);
    let unseen: Vec<&str> = OUTPUT_FILES
        .iter()
        .map(|o| o.pattern)
        .filter(|p| !seen.contains(p))
        .collect();
    assert!(
        unseen.is_empty(),
        "declared but written by no run here: {unseen:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The path of one run's output under the scratch directory.
fn scratch(dir: &Path) -> impl Fn(&str) -> PathBuf + '_ {
    move |name: &str| dir.join(name)
}

/// The realistic ACE's span the runs that draw it need.
const LONG_ACE: &str = "ace.span_s=200.0";

/// simulate (one array, the focal plane), analyze (one array, the focal plane, HST and PANOPTES files) and score.
fn simulate_analyse_and_score(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // simulate: one array (two realistic-ACE exposures) and the focal plane
    let mut c = small(&["simulate", "--images", "2"]);
    c.args([
        "--set",
        LONG_ACE,
        "--set",
        "scene.grid_n=3",
        "--set",
        "scene.grid_spacing_px=70.0",
        "--out",
    ])
    .arg(d("sim"));
    c.args(["--set", "ace.case=\"realistic\""]);
    ok(c);
    check(&d("sim"), &[Cmd::Simulate], seen);
    let mut c = small(&["simulate", "--scene", "bulge", "--images", "1"]);
    c.arg("--out").arg(d("fp"));
    ok(c);
    check(&d("fp"), &[Cmd::Simulate], seen);

    // analyze: one array, the focal plane, a CR-split HST file, a waivered one and a tile-compressed raw frame;
    // then score
    for (image, out, extra) in [
        (d("sim/img_000.fits"), "an", &[][..]),
        (d("fp/fp_000.fits"), "fpan", &[][..]),
        (
            root().join("tests/data/hst_stis_m33_crsplit/o4k19a010_cutout_flt.fits"),
            "stis",
            &[][..],
        ),
        (
            root().join("tests/data/hst_wfpc2_omegacen/u40x010hm_cutout_c0f.fits"),
            "wfpc2",
            &["--read-noise-e", "5.3"][..],
        ),
        (
            root().join("tests/data/panoptes_pan001_kic8462852/solved.fits.fz"),
            "panoptes",
            &[
                "--electrons-per-unit",
                "0.84",
                "--read-noise-e",
                "5.3",
                "--bias-units",
                "2048",
            ][..],
        ),
    ] {
        let mut c = jsim();
        c.args(["analyze", "--image"])
            .arg(image)
            .args(extra)
            .arg("--out")
            .arg(d(out));
        ok(c);
        check(&d(out), &[Cmd::Analyze], seen);
    }
    let mut c = jsim();
    c.args(["score", "--catalogue"])
        .arg(d("an/catalogue.csv"))
        .arg("--truth")
        .arg(d("sim/img_000.fits"))
        .arg("--out")
        .arg(d("score"));
    ok(c);
    check(&d("score"), &[Cmd::Score], seen);
}

/// experiment and crowded (both ACE cases, their exposures saved).
fn experiment_and_crowded(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // experiment, crowded (both ACE cases, their exposures saved)
    let mut c = small(&[
        "experiment",
        "--mags",
        "12.5",
        "--aces",
        "gaussian",
        "--readouts",
        "rolling",
        "--countermeasures",
        "none",
    ]);
    c.args([
        "--set",
        "scene.grid_n=3",
        "--set",
        "scene.grid_spacing_px=70.0",
        "--set",
        "fidelity.images=2",
        "--out",
    ])
    .arg(d("experiment"));
    ok(c);
    check(&d("experiment"), &[Cmd::Experiment], seen);
    let mut c = small(&[
        "crowded",
        "--aces",
        "gaussian,realistic",
        "--countermeasures",
        "none",
        "--save-images",
    ]);
    c.args(["--set", LONG_ACE, "--out"]).arg(d("crowded"));
    ok(c);
    check(&d("crowded"), &[Cmd::Crowded], seen);
}

/// A sequence (persistence on, images kept), its Slurm job and the solution's; solve; solve-synthetic.
fn sequence_and_solutions(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // sequence (persistence on, images kept), its Slurm job and the solution's; solve; solve-synthetic
    let spec = d("seq.toml");
    std::fs::write(
        &spec,
        "[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\nvisits_utc = [\"2031-03-21T00:00:00\"]\n\
         visit_dither_px = 0.0\n",
    )
    .expect("spec");
    let mut c = small(&["sequence", "--countermeasure", "none", "--keep-images"]);
    c.args([
        "--set",
        "detector.persistence.enabled=true",
        "--set",
        "detector.persistence.threshold_e=1e4",
        "--spec",
    ])
    .arg(&spec)
    .arg("--out")
    .arg(d("sequence"));
    ok(c);
    check(&d("sequence"), &[Cmd::Sequence], seen);
    let mut c = small(&["sequence", "--countermeasure", "none", "--emit-slurm"]);
    c.arg("--spec")
        .arg(&spec)
        .arg("--out")
        .arg(d("sequence-slurm"));
    ok(c);
    let mut c = jsim();
    c.args(["solve", "--emit-slurm", "--sequence"])
        .arg(d("sequence-slurm"))
        .arg("--jsim-mpi")
        .arg(env!("CARGO_BIN_EXE_jsim"));
    ok(c);
    check(&d("sequence-slurm"), &[Cmd::Sequence, Cmd::Solve], seen);
    let mut c = jsim();
    // two of them: the sequence's exposures per stare among them, for the mission's budget
    c.args(["solve", "--exposures", "2,4", "--sequence"])
        .arg(d("sequence"))
        .arg("--out")
        .arg(d("solution"));
    ok(c);
    check(&d("solution"), &[Cmd::Solve], seen);
    let mut c = jsim();
    c.args([
        "solve-synthetic",
        "--sources",
        "100",
        "--exposures",
        "25",
        "--out",
    ])
    .arg(d("synthetic"));
    ok(c);
    check(&d("synthetic"), &[Cmd::SolveSynthetic], seen);
}

/// transit: a short stare with its products, and the precision study at one magnitude.
fn transit_runs(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // transit: a short stare with its products, and the precision study at one magnitude
    let transit = |extra: &[&str], out: &str| {
        let mut c = small(&["transit", "--hours", "0.3", "--depth", "0"]);
        c.args([
            "--set",
            LONG_ACE,
            "--set",
            "instrument.detector_px=512",
            "--set",
            "instrument.photosensitive_px=496",
            "--set",
            "readout.channels=4",
            "--set",
            "transit.comparisons=3",
            "--set",
            "transit.field_radius_px=150.0",
        ])
        .args(extra)
        .arg("--out")
        .arg(d(out));
        ok(c);
    };
    transit(&["--write-products"], "transit");
    check(&d("transit"), &[Cmd::Transit], seen);
    transit(&["--magnitudes", "9"], "precision");
    check(&d("precision"), &[Cmd::Transit], seen);
}

/// sweep, merge, report; and its Slurm job.
fn sweep_runs(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // sweep, merge, report; and its Slurm job
    let sweep_file = root().join("engine/sweeps/quick_sweep.toml");
    let mut c = jsim();
    c.arg("sweep")
        .arg("--config")
        .arg(&sweep_file)
        .arg("--out")
        .arg(d("sweep"));
    ok(c);
    let before: BTreeSet<String> = listing(&d("sweep")).into_iter().collect();
    for step in ["merge", "report"] {
        let mut c = jsim();
        c.arg(step).arg(d("sweep"));
        ok(c);
    }
    // what merge and report add is theirs; the sweep's own files were there before
    for path in listing(&d("sweep")) {
        let by: &[Cmd] = if before.contains(&path) {
            &[Cmd::Sweep]
        } else {
            &[Cmd::Merge, Cmd::Report]
        };
        expect_declared(&d("sweep"), &path, by, seen);
    }
    let mut c = jsim();
    c.arg("sweep")
        .arg("--config")
        .arg(&sweep_file)
        .arg("--emit-slurm")
        .arg("--out")
        .arg(d("sweep-slurm"));
    ok(c);
    check(&d("sweep-slurm"), &[Cmd::Sweep], seen);
}

/// bench: a knob sweep with a figure.
fn bench_run(dir: &Path, seen: &mut BTreeSet<&'static str>) {
    let d = scratch(dir);
    // bench: a knob sweep with a figure
    let mut c = small(&["bench", "--quick", "--parts", "knobs", "--ref-stars", "1"]);
    c.args([
        "--set",
        "scene.grid_n=3",
        "--set",
        "scene.grid_spacing_px=70.0",
        "--out",
    ])
    .arg(d("bench"));
    ok(c);
    check(&d("bench"), &[Cmd::Bench], seen);
}

#[test]
fn every_declared_file_is_described_in_the_docs() {
    let mut docs = std::fs::read_to_string(root().join("README.md")).expect("README");
    for e in std::fs::read_dir(root().join("docs")).expect("docs/") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "md") {
            docs.push_str(&std::fs::read_to_string(&p).expect("page"));
        }
    }
    let mut missing = Vec::new();
    for o in OUTPUT_FILES {
        let name = files::as_documented(o.pattern);
        let parts: Vec<&str> = name.split('/').collect();
        for (i, part) in parts.iter().enumerate() {
            // a directory is documented as `dir/`, a file by its name
            let text = if i + 1 < parts.len() {
                format!("{part}/")
            } else {
                part.to_string()
            };
            if !docs.contains(&text) {
                missing.push(format!("{} (`{text}`)", o.pattern));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "declared outputs described on no page of docs/: {missing:?}"
    );
}
