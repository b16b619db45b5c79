//! Monte Carlo sweeps (`engine::studies::sweep`, `jsim sweep|merge|report`): results independent of sharding and
//! threads, resuming after lost, truncated or corrupted shard files, extending a sweep, merge diagnostics,
//! the report's fractions, the Slurm scripts, and bad input giving named errors with no files written.
//!
//! The sweep is `engine/sweeps/quick_sweep.toml` (2 points × 4 exposures of a reduced scene); its
//! single-process result is computed once and copied by the tests that start from it.

use engine::session::Session;
use engine::studies::sweep::{
    self, MergeOptions, ReportOptions, RunOptions, RunSummary, Shard, Sweep, SweepError,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn quick_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/quick_sweep.toml")
}

fn quick() -> Sweep {
    Sweep::load(&quick_path()).expect("quick_sweep.toml is valid")
}

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

/// A fresh, empty scratch directory for one test, in Cargo's scratch area for integration tests
/// (`target/tmp`: the quick sweep's reference is shared by several tests, so nothing removes it at a test's end).
fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("jsim-sweep-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

fn run(sw: &Sweep, dir: &Path, shard: Shard, jobs: usize, max_units: Option<usize>) -> RunSummary {
    sweep::run_shard(
        &Session::new(),
        sw,
        dir,
        &RunOptions {
            shard,
            jobs,
            max_units,
        },
        &mut |_| {},
    )
    .expect("sweep runs")
}

fn merged_text(dir: &Path) -> String {
    sweep::merge(dir, &MergeOptions::default()).expect("merge");
    std::fs::read_to_string(dir.join("merged.csv")).expect("merged.csv")
}

/// The single-process run of the quick sweep: (directory, merged CSV without timing columns).
fn reference() -> &'static (PathBuf, String) {
    static REF: OnceLock<(PathBuf, String)> = OnceLock::new();
    REF.get_or_init(|| {
        let dir = scratch("reference");
        let s = run(&quick(), &dir, Shard::ALL, 1, None);
        assert_eq!(s.computed, 8);
        assert_eq!(s.remaining, 0);
        let text = sweep::without_timing(&merged_text(&dir));
        (dir, text)
    })
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("read_dir").flatten() {
        let p = e.path();
        let t = to.join(e.file_name());
        if p.is_dir() {
            copy_dir(&p, &t);
        } else {
            std::fs::copy(&p, &t).expect("copy");
        }
    }
}

/// A copy of the reference directory holding only its shard file (no merged outputs).
fn reference_copy(name: &str) -> PathBuf {
    let (rdir, _) = reference();
    let d = scratch(name);
    copy_dir(rdir, &d);
    for f in ["merged.csv", "merged.json", "report.csv"] {
        let _ = std::fs::remove_file(d.join(f));
    }
    d
}

fn shard_csv(dir: &Path, s: Shard) -> PathBuf {
    sweep::shard_paths(dir, s).0
}

/// All files under `dir` (relative paths, sorted) with their contents.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    fn walk(root: &Path, d: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        if let Ok(entries) = std::fs::read_dir(d) {
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(root, &p, out);
                } else {
                    let rel = p.strip_prefix(root).unwrap_or(&p).to_path_buf();
                    out.insert(rel, std::fs::read(&p).unwrap_or_default());
                }
            }
        }
    }
    walk(dir, dir, &mut out);
    out
}

#[test]
fn units_do_not_depend_on_sharding_or_threads() {
    let (_, want) = reference();
    let dir = scratch("sharded");
    let sw = quick();
    // shard 0 of 2 on a 3-thread pool with two units in flight at once, shard 1 of 2 on one thread one
    // unit at a time, into one directory (the reference ran on the default pool)
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .expect("pool")
    };
    let a = pool(3).install(|| run(&sw, &dir, Shard::new(0, 2).expect("shard"), 2, None));
    let b = pool(1).install(|| run(&sw, &dir, Shard::new(1, 2).expect("shard"), 1, None));
    assert_eq!((a.shard_units, a.computed), (4, 4));
    assert_eq!((b.shard_units, b.computed), (4, 4));
    // unit u belongs to shard u mod N
    let rec = sweep::read_record(&dir).expect("record");
    let s0 = sweep::read_shard(&rec, &dir, Shard::new(0, 2).expect("shard")).expect("read");
    assert!(s0.intact);
    assert_eq!(
        s0.units.keys().copied().collect::<Vec<_>>(),
        vec![0, 2, 4, 6]
    );
    let got = sweep::without_timing(&merged_text(&dir));
    assert_eq!(
        &got, want,
        "merged CSV of shards 0/2 + 1/2 differs from the single-process run"
    );
    // byte-identical reports from identical results
    let (rdir, _) = reference();
    sweep::report(rdir, &ReportOptions::default()).expect("report");
    sweep::report(&dir, &ReportOptions::default()).expect("report");
    assert_eq!(
        std::fs::read(rdir.join("report.csv")).expect("report"),
        std::fs::read(dir.join("report.csv")).expect("report")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn resume_after_deleting_or_truncating_a_shard_file() {
    let (_, want) = reference();
    let sw = quick();
    let dir = reference_copy("resume");
    let csv = shard_csv(&dir, Shard::ALL);
    // rerunning a finished sweep computes nothing
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!((s.done_before, s.computed), (8, 0));

    // cut the file in the middle of its last row: only the last unit is redone
    let text = std::fs::read_to_string(&csv).expect("csv");
    std::fs::write(&csv, &text[..text.len() - 40]).expect("truncate");
    let mut salvaged = Vec::new();
    let s = sweep::run_shard(
        &Session::new(),
        &sw,
        &dir,
        &RunOptions::default(),
        &mut |e| {
            if let sweep::Event::Salvaged(n) = e {
                salvaged.push(n)
            }
        },
    )
    .expect("resume");
    assert_eq!((s.done_before, s.computed), (7, 1));
    assert_eq!(salvaged.len(), 1, "the damage is reported");
    assert!(salvaged[0].contains("SHA-256"), "{}", salvaged[0]);
    assert_eq!(&sweep::without_timing(&merged_text(&dir)), want);

    // cut at a row boundary inside a unit (the sidecar still says 24 rows): that unit is redone
    let text = std::fs::read_to_string(&csv).expect("csv");
    let keep: Vec<&str> = text.lines().take(1 + 3 * 5 + 1).collect();
    std::fs::write(&csv, keep.join("\n") + "\n").expect("truncate");
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!((s.done_before, s.computed), (5, 3));
    assert_eq!(&sweep::without_timing(&merged_text(&dir)), want);

    // a deleted shard file: everything is redone, in chunks (--max-units), then complete
    std::fs::remove_file(&csv).expect("rm");
    let s = run(&sw, &dir, Shard::ALL, 1, Some(3));
    assert_eq!((s.computed, s.remaining), (3, 5));
    let e = sweep::merge(&dir, &MergeOptions::default()).expect_err("units missing");
    assert!(matches!(e, SweepError::Missing { missing: 5, .. }), "{e}");
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!((s.done_before, s.computed, s.remaining), (3, 5, 0));
    assert_eq!(&sweep::without_timing(&merged_text(&dir)), want);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn corrupt_rows_are_detected_and_redone() {
    let (_, want) = reference();
    let sw = quick();
    let dir = reference_copy("corrupt");
    let csv = shard_csv(&dir, Shard::ALL);
    let rec = sweep::read_record(&dir).expect("record");

    // a missing sidecar alone loses nothing: every row verifies; the sidecar is rewritten
    let side = sweep::shard_paths(&dir, Shard::ALL).1;
    std::fs::remove_file(&side).expect("rm sidecar");
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!(s.computed, 0);
    assert!(side.exists());
    assert!(
        sweep::read_shard(&rec, &dir, Shard::ALL)
            .expect("read")
            .intact
    );

    // change one digit of unit 5's accuracy: the file fails its checksum and unit 5 its row check
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let k = lines
        .iter()
        .position(|l| l.starts_with("5,1,2,"))
        .expect("unit 5");
    let cells: Vec<&str> = lines[k].split(',').collect();
    let acc_col = rec
        .header(true)
        .iter()
        .position(|h| h == "accuracy_mas")
        .expect("col");
    let mut changed: Vec<String> = cells.iter().map(|s| s.to_string()).collect();
    changed[acc_col] = "1.0".into();
    lines[k] = changed.join(",");
    std::fs::write(&csv, lines.join("\n") + "\n").expect("write");
    let sf = sweep::read_shard(&rec, &dir, Shard::ALL).expect("read");
    assert!(!sf.intact);
    assert!(!sf.units.contains_key(&5));
    assert_eq!(sf.units.len(), 7);
    // merge refuses to pass the damaged unit off as data: it is missing, by name
    let e = sweep::merge(&dir, &MergeOptions::default()).expect_err("unit 5 missing");
    assert!(
        e.to_string().contains("unit 5 (point 1, exposure 2)"),
        "{e}"
    );
    assert!(!dir.join("merged.csv").exists(), "no merged.csv on error");
    // the sweep redoes exactly that unit
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!(s.computed, 1);
    assert_eq!(&sweep::without_timing(&merged_text(&dir)), want);

    // garbage appended (a torn write): dropped, and the file rewritten clean
    let mut text = std::fs::read_to_string(&csv).expect("csv");
    text.push_str("not,a,row\n\u{0}\u{1}binary");
    std::fs::write(&csv, text).expect("write");
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!(s.computed, 0);
    assert!(
        sweep::read_shard(&rec, &dir, Shard::ALL)
            .expect("read")
            .intact,
        "the salvaged file was rewritten clean"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn merge_reports_duplicates_and_refuses_mixed_sweeps() {
    let (_, want) = reference();
    let dir = reference_copy("merge");
    let rec = sweep::read_record(&dir).expect("record");
    let all = sweep::read_shard(&rec, &dir, Shard::ALL).expect("read");
    // the same units also recorded by a 2-shard run: identical duplicates are reported, one kept
    let s1 = Shard::new(1, 2).expect("shard");
    let odd: BTreeMap<_, _> = all
        .units
        .iter()
        .filter(|(u, _)| s1.contains(**u))
        .map(|(u, r)| (*u, r.clone()))
        .collect();
    sweep::write_shard(&rec, &dir, s1, &odd).expect("write");
    let m = sweep::merge(&dir, &MergeOptions::default()).expect("merge");
    assert_eq!(m.duplicates, vec![1, 3, 5, 7]);
    assert_eq!((m.units, m.rows, m.files), (8, 24, 2));
    assert_eq!(
        &sweep::without_timing(&std::fs::read_to_string(&m.path).expect("merged")),
        want
    );
    // a second run with another N skips units recorded anywhere in the directory
    let s = run(&quick(), &dir, Shard::new(0, 2).expect("shard"), 1, None);
    assert_eq!((s.elsewhere, s.computed), (4, 0));

    // a duplicate that disagrees is an error naming the unit
    let mut bad = odd.clone();
    let acc = rec
        .header(false)
        .iter()
        .position(|h| h == "accuracy_mas")
        .expect("col");
    bad.get_mut(&3).expect("unit 3")[0][acc] = "0.5".into();
    sweep::write_shard(&rec, &dir, s1, &bad).expect("write");
    let e = sweep::merge(&dir, &MergeOptions::default()).expect_err("conflict");
    assert!(e.to_string().contains("unit 3 differs"), "{e}");

    // a shard file of another sweep (another seed) in the directory: mixed sweeps
    let _ = std::fs::remove_file(sweep::shard_paths(&dir, s1).0);
    let _ = std::fs::remove_file(sweep::shard_paths(&dir, s1).1);
    let text = std::fs::read_to_string(quick_path()).expect("quick");
    let other = Sweep::from_toml_str(
        &text.replace("seed = 2024", "seed = 2025"),
        Path::new("other.toml"),
        Path::new("."),
    )
    .expect("other");
    let orec = other.record();
    sweep::write_shard(&orec, &dir, s1, &BTreeMap::new()).expect("write");
    let e = sweep::merge(&dir, &MergeOptions::default()).expect_err("mixed");
    assert!(e.to_string().contains("mixed sweeps"), "{e}");
    assert!(e.to_string().contains(&orec.hash), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn extending_exposures_keeps_existing_units() {
    let (_, want) = reference();
    let dir = reference_copy("extend");
    let text = std::fs::read_to_string(quick_path()).expect("quick");
    let more = Sweep::from_toml_str(
        &text.replace("exposures = 4", "exposures = 5"),
        &quick_path(),
        quick_path().parent().expect("dir"),
    )
    .expect("extended");
    assert_eq!(
        more.hash,
        quick().hash,
        "exposures are not part of the identity"
    );
    let s = run(&more, &dir, Shard::ALL, 1, None);
    assert_eq!((s.done_before, s.computed), (8, 2));
    let got = sweep::without_timing(&merged_text(&dir));
    assert!(
        got.starts_with(want.as_str()),
        "the first 8 units are unchanged"
    );
    assert_eq!(got.lines().count(), 1 + 10 * 3);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Independent recomputation of the report's numbers from merged.csv.
#[test]
fn report_fractions_match_the_merged_rows() {
    let dir = reference_copy("report");
    merged_text(&dir);
    let rec = sweep::read_record(&dir).expect("record");
    let text = std::fs::read_to_string(dir.join("merged.csv")).expect("merged");
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).expect("column");
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let accs: Vec<f64> = rows
        .iter()
        .map(|r| r[col("accuracy_mas")].parse().expect("f64"))
        .collect();
    let mut sorted = accs.clone();
    sorted.sort_by(f64::total_cmp);
    // thresholds that split the data, and the two extremes
    for thr in [sorted[5] + 1e-9, sorted[12] + 1e-9, 1e-3, 1e6] {
        let s = sweep::report(
            &dir,
            &ReportOptions {
                threshold_mas: Some(thr),
                ..Default::default()
            },
        )
        .expect("report");
        assert_eq!(s.rows.len(), rec.points * rec.countermeasures.len());
        for r in &s.rows {
            let vals: Vec<f64> = rows
                .iter()
                .filter(|x| {
                    x[col("point")] == r.point.to_string()
                        && x[col("countermeasure")] == r.countermeasure
                })
                .map(|x| x[col("accuracy_mas")].parse().expect("f64"))
                .collect();
            let k = vals.iter().filter(|&&v| v <= thr).count();
            assert_eq!((r.n, r.k, r.failed), (4, k, 0), "{r:?}");
            let (lo, hi) = engine::numerics::stats::wilson_interval(k, 4, 1.96);
            assert!((r.ci_low - lo).abs() < 1e-3 && (r.ci_high - hi).abs() < 1e-3);
            assert!(r.ci_low <= r.fraction && r.fraction <= r.ci_high);
            assert_eq!(r.values, rec.point_values[r.point]);
        }
        let report_csv = std::fs::read_to_string(dir.join("report.csv")).expect("report.csv");
        assert_eq!(report_csv.lines().count(), 1 + s.rows.len());
        assert!(
            report_csv.starts_with("point,ace.sigma_mas,countermeasure,metric,threshold_mas,n,k,")
        );
    }
    // one histogram + CDF per point and countermeasure, and the fraction plot
    for p in 0..2 {
        for cm in ["none", "plate-poly_3_catalogue", "telemetry"] {
            let f = dir.join(format!("report/dist_p{p:03}_{cm}.png"));
            assert!(
                std::fs::metadata(&f)
                    .map(|m| m.len() > 1000)
                    .unwrap_or(false),
                "{}",
                f.display()
            );
        }
    }
    assert!(dir.join("report/fraction.png").exists());
    // bad report options name themselves and write nothing new
    let before = snapshot(&dir);
    for (opts, needle) in [
        (
            ReportOptions {
                metric: "bogus".into(),
                ..Default::default()
            },
            "--metric bogus",
        ),
        (
            ReportOptions {
                threshold_mas: Some(-1.0),
                ..Default::default()
            },
            "--threshold-mas",
        ),
        (
            ReportOptions {
                x: Some("readout.order".into()),
                ..Default::default()
            },
            "--x readout.order",
        ),
    ] {
        let e = sweep::report(&dir, &opts).expect_err("bad option");
        assert!(e.to_string().contains(needle), "{e}");
    }
    assert_eq!(snapshot(&dir), before);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sweep_file_forms() {
    let d = scratch("forms");
    std::fs::write(d.join("base.toml"), "[scene]\ngrid_n = 4\n").expect("base");
    let text = r#"
seed = 3
exposures = 2
countermeasures = ["none", "exact-epsf"]
common_random_numbers = true
base = "base.toml"
[set]
"ace.span_s" = 60
scene.mag_hw = 13.0
[grid]
readout.order = ["rolling", "sample-hold"]
ace.modes.0.amplitude = [0.01, 0.02]
"#;
    let sw = Sweep::from_toml_str(text, &d.join("s.toml"), &d).expect("parses");
    let fields: Vec<&str> = sw.params.iter().map(|p| p.field.as_str()).collect();
    assert_eq!(fields, ["ace.modes.0.amplitude", "readout.order"]);
    assert_eq!(sw.n_points(), 4);
    let p3 = &sw.points[3].config;
    assert_eq!(p3.scene.grid_n, 4);
    assert_eq!(p3.scene.mag_hw, 13.0);
    assert_eq!(p3.ace.span_s, 60.0);
    assert_eq!(p3.ace.modes[0].amplitude, 0.02);
    assert_eq!(p3.readout.order.name(), "sample-hold");
    assert_eq!(sw.points[3].values, ["0.02", "sample-hold"]);
    // common random numbers: exposure e of every point shares its seed
    assert_eq!(sw.unit_seed(0), sw.unit_seed(3));
    assert_ne!(sw.unit_seed(0), sw.unit_seed(4));
    assert_eq!(sw.unit_config(5).fidelity.images, 1);
    // the same grid written with quoted keys is the same sweep
    let quoted = text
        .replace("readout.order =", "\"readout.order\" =")
        .replace("ace.modes.0.amplitude =", "\"ace.modes.0.amplitude\" =");
    let sw2 = Sweep::from_toml_str(&quoted, &d.join("s.toml"), &d).expect("parses");
    assert_eq!(sw2.hash, sw.hash);
    let _ = std::fs::remove_dir_all(&d);
}

/// The bad sweep files and options: (what, the sweep file's text, extra options, what the error names).
fn bad_cases(good: &str) -> Vec<(&'static str, String, Vec<&'static str>, &'static str)> {
    vec![
        (
            "unknown grid field",
            good.replace("\"ace.sigma_mas\"", "\"ace.sigma_mass\""),
            vec![],
            "ace.sigma_mass",
        ),
        (
            "bad grid value",
            good.replace("[150, 300]", "[150, -3]"),
            vec![],
            "ace.sigma_mas",
        ),
        (
            "empty grid",
            good.replace("\"ace.sigma_mas\" = [150, 300]", ""),
            vec![],
            "the grid is empty",
        ),
        (
            "empty value list",
            good.replace("[150, 300]", "[]"),
            vec![],
            "has no values",
        ),
        (
            "seed swept",
            good.replace("\"ace.sigma_mas\" = [150, 300]", "seed = [1, 2]"),
            vec![],
            "`seed` cannot be swept",
        ),
        (
            "no exposures",
            good.replace("exposures = 4", "exposures = 0"),
            vec![],
            "`exposures` = 0",
        ),
        (
            "unknown countermeasure",
            good.replace("\"telemetry\"]", "\"magic\"]"),
            vec![],
            "countermeasure `magic`",
        ),
        (
            "unknown sweep key",
            format!("exposurez = 3\n{good}"),
            vec![],
            "exposurez",
        ),
        ("N = 0", good.to_string(), vec!["--shard", "0/0"], "N = 0"),
        (
            "i ≥ N",
            good.to_string(),
            vec!["--shard", "3/3"],
            "out of range",
        ),
        (
            "not i/N",
            good.to_string(),
            vec!["--shard", "2"],
            "expected i/N",
        ),
        (
            "bad slurm time",
            good.to_string(),
            vec!["--emit-slurm", "--time", "4h"],
            "--time 4h",
        ),
        (
            "zero slurm shards",
            good.to_string(),
            vec!["--emit-slurm", "--shards", "0"],
            "--shards 0",
        ),
    ]
}

/// Bad input: each a clear error naming the problem, and no files written.
#[test]
fn bad_input_is_named_and_writes_nothing() {
    let d = scratch("bad");
    let good = std::fs::read_to_string(quick_path()).expect("quick");
    for (what, text, extra, needle) in bad_cases(&good) {
        let file = d.join("s.toml");
        std::fs::write(&file, text).expect("write");
        let out = d.join("out");
        let o = jsim()
            .args(["sweep", "--config"])
            .arg(&file)
            .arg("--out")
            .arg(&out)
            .args(&extra)
            .output()
            .expect("run jsim");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{what}: should fail");
        assert!(
            err.contains(needle),
            "{what}: `{err}` should name `{needle}`"
        );
        assert!(!out.exists(), "{what}: wrote {}", out.display());
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// An output directory holding another sweep: refused, nothing in it changes.
#[test]
fn another_sweeps_directory_is_refused_and_untouched() {
    let d = scratch("bad-other-file");
    let good = std::fs::read_to_string(quick_path()).expect("quick");
    let (rdir, _) = reference();
    let dir = scratch("bad-other");
    copy_dir(rdir, &dir);
    let before = snapshot(&dir);
    let file = d.join("other.toml");
    std::fs::write(&file, good.replace("seed = 2024", "seed = 99")).expect("write");
    for extra in [vec![], vec!["--emit-slurm"]] {
        let o = jsim()
            .args(["sweep", "--config"])
            .arg(&file)
            .arg("--out")
            .arg(&dir)
            .args(&extra)
            .output()
            .expect("run jsim");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains("holds another sweep"), "{err}");
        assert!(err.contains(&quick().hash), "{err}");
    }
    assert_eq!(
        snapshot(&dir),
        before,
        "the other sweep's directory is untouched"
    );
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&dir);
}

/// merge: not a sweep directory; missing units named with a non-zero exit and no merged.csv.
#[test]
fn merge_names_a_missing_directory_and_missing_units() {
    let d = scratch("bad-merge");
    let o = jsim()
        .arg("merge")
        .arg(d.join("nothing"))
        .output()
        .expect("jsim");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a sweep directory"));
    let part = scratch("bad-partial");
    let o = jsim()
        .args(["sweep", "--config"])
        .arg(quick_path())
        .arg("--out")
        .arg(&part)
        .args(["--shard", "1/4"])
        .output()
        .expect("jsim");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = jsim().arg("merge").arg(&part).output().expect("jsim");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("6 of 8 units are missing"), "{err}");
    assert!(err.contains("unit 0 (point 0, exposure 0)"), "{err}");
    assert!(!part.join("merged.csv").exists());
    let o = jsim()
        .arg("merge")
        .arg(&part)
        .arg("--allow-missing")
        .output()
        .expect("jsim");
    assert!(o.status.success());
    assert_eq!(
        std::fs::read_to_string(part.join("merged.csv"))
            .expect("merged")
            .lines()
            .count(),
        1 + 2 * 3
    );
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&part);
}

#[test]
fn emit_slurm_writes_an_array_a_merge_job_and_a_submit_script() {
    let dir = scratch("slurm-emit");
    let o = jsim()
        .args(["sweep", "--config"])
        .arg(quick_path())
        .arg("--out")
        .arg(&dir)
        .args([
            "--emit-slurm",
            "--shards",
            "5",
            "--partition",
            "short",
            "--time",
            "01:30:00",
            "--cpus-per-task",
            "2",
            "--threshold-mas",
            "3.5",
        ])
        .output()
        .expect("jsim");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |n: &str| std::fs::read_to_string(dir.join("slurm").join(n)).expect(n);
    let array = read("array.sbatch");
    for needle in [
        "#SBATCH --array=0-4",
        "#SBATCH --partition=short",
        "#SBATCH --time=01:30:00",
        "#SBATCH --cpus-per-task=2",
        "--shard \"${SLURM_ARRAY_TASK_ID}/5\"",
        env!("CARGO_BIN_EXE_jsim"),
        quick_path().to_str().expect("utf8"),
    ] {
        assert!(
            array.contains(needle),
            "array.sbatch lacks {needle}:\n{array}"
        );
    }
    let merge = read("merge.sbatch");
    assert!(merge.contains(" merge '"), "{merge}");
    assert!(
        merge.contains(" report '") && merge.contains("--threshold-mas 3.5"),
        "{merge}"
    );
    let submit = read("submit.sh");
    assert!(submit.contains("sbatch --parsable"), "{submit}");
    assert!(
        submit.contains("--dependency=afterok:\"$array\""),
        "{submit}"
    );
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(dir.join("slurm/submit.sh"))
            .expect("submit.sh")
            .permissions()
            .mode();
        assert_eq!(mode & 0o111, 0o111, "submit.sh is executable");
    }
    assert!(
        dir.join("slurm/logs").is_dir(),
        "Slurm needs the log directory to exist"
    );
    assert!(
        dir.join("sweep.json").exists(),
        "the directory is claimed for this sweep"
    );
    // the scripts are valid bash
    for f in ["array.sbatch", "merge.sbatch", "submit.sh"] {
        if let Ok(o) = Command::new("bash")
            .arg("-n")
            .arg(dir.join("slurm").join(f))
            .output()
        {
            assert!(
                o.status.success(),
                "{f}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_shard_runs_in_one_process_at_a_time() {
    let dir = reference_copy("lock");
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(dir.join("shards/shard-0000-of-0001.lock"))
        .expect("lock file");
    lock.try_lock().expect("lock");
    let e = sweep::run_shard(
        &Session::new(),
        &quick(),
        &dir,
        &RunOptions::default(),
        &mut |_| {},
    )
    .expect_err("the shard is locked");
    assert!(e.to_string().contains("another process"), "{e}");
    // other shards are free, and the lock goes with its holder
    let s = run(&quick(), &dir, Shard::new(1, 2).expect("shard"), 1, None);
    assert_eq!(s.computed, 0);
    lock.unlock().expect("unlock");
    drop(lock);
    let s = run(&quick(), &dir, Shard::ALL, 1, None);
    assert_eq!(s.computed, 0);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A sweep of stares: each unit is a stare of `stare_exposures` consecutive exposures on one ACE series, the
/// stack of which references the plate model. Rows come per exposure; the stack-referenced plate sits between
/// the uncorrected and the oracle-referenced one; a stack plate without a stare is a named error.
#[test]
fn a_sweep_of_stares_references_the_plate_to_each_stare_stack() {
    let text = std::fs::read_to_string(quick_path())
        .expect("quick sweep")
        .replace(
            "countermeasures = [\"none\", \"plate-poly:3@catalogue\", \"telemetry\"]",
            "countermeasures = [\"none\", \"plate-poly:3\", \"plate-poly:3@oracle\"]\nstare_exposures = 4",
        )
        .replace("\"ace.sigma_mas\" = [150, 300]", "\"ace.sigma_mas\" = [300]");
    let d = scratch("stares");
    let sw = Sweep::from_toml_str(&text, &d.join("s.toml"), &d).expect("parses");
    assert_eq!((sw.n_points(), sw.n_units(), sw.stare_exposures), (1, 1, 4));
    assert_eq!(sw.unit_config(0).fidelity.images, 4);
    let dir = d.join("out");
    let s = run(&sw, &dir, Shard::ALL, 1, None);
    assert_eq!(s.computed, 1);
    let merged = merged_text(&dir);
    let mut lines = merged.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (e_col, cm_col, acc_col) = (col("exposure"), col("countermeasure"), col("accuracy_mas"));
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert_eq!(rows.len(), 4 * 3, "one row per exposure and countermeasure");
    let mean = |cm: &str| {
        let v: Vec<f64> = rows
            .iter()
            .filter(|r| r[cm_col] == cm)
            .map(|r| r[acc_col].parse::<f64>().expect("accuracy"))
            .collect();
        assert_eq!(v.len(), 4, "{cm}: every exposure of the stare");
        v.iter().sum::<f64>() / 4.0
    };
    let exposures: Vec<&str> = rows.iter().map(|r| r[e_col].as_str()).collect();
    assert_eq!(exposures[..4], ["0", "0", "0", "1"]);
    let (none, stack, oracle) = (
        mean("none"),
        mean("plate-poly:3"),
        mean("plate-poly:3@oracle"),
    );
    eprintln!("stare of 4: none {none:.2}, stack {stack:.2}, oracle {oracle:.2} mas");
    assert!(
        oracle < stack && stack < none,
        "the stack sits between: {oracle} < {stack} < {none}"
    );
    // a stack reference needs a stare
    let single = text.replace("stare_exposures = 4", "stare_exposures = 1");
    let e = Sweep::from_toml_str(&single, &d.join("s.toml"), &d).expect_err("no stare");
    assert!(e.to_string().contains("stare_exposures"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// Every sweep shipped in `engine/sweeps/` loads, and one unit of each runs — on a reduced scene (16 stars,
/// coarse optics), with every countermeasure giving a row whose status is `ok` or `not applicable`.
#[test]
fn every_shipped_sweep_loads_and_runs_a_unit() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("engine/sweeps")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 3, "{files:?}");
    let session = Session::new();
    for f in files {
        let mut sw = Sweep::load(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        for p in &mut sw.points {
            let c = &mut p.config;
            c.scene.grid_n = 4;
            c.optics.pupil_samples = 64;
            c.optics.psf_radius_px = 8;
            c.band.wavelength_step_um = 0.1;
            c.fidelity.backend = engine::config::Backend::Cpu;
            c.validate().expect("the reduced configuration is valid");
        }
        let rows = sweep::compute_unit(&sw, 0, &session)
            .unwrap_or_else(|e| panic!("{}: unit 0: {e}", f.display()));
        assert_eq!(
            rows.len(),
            sw.stare_exposures * sw.countermeasures.len(),
            "{}",
            f.display()
        );
        let status = 3 + sw.params.len() + 1;
        for r in &rows {
            assert!(
                r[status] == "ok" || r[status] == "not applicable",
                "{}: {r:?}",
                f.display()
            );
        }
    }
}
