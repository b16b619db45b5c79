//! The long jobs' reliability as a user meets it: a transit precision study and a solution with its
//! checkpoint, each killed outright (SIGKILL: no handler runs) five times and rerun, end where one
//! uninterrupted run ends, byte for byte, with no temporary file left; a sequence and a transit study on a
//! full disk (a small tmpfs, mounted in a private mount namespace by `unshare`) stop with an error that
//! says the disk is full, leave no partial file, and resume to the same bytes once there is room.
//! (The sequence's own kill test is in sequence.rs.)

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

mod support;
use support::{SMALL_SEQUENCE, files_under, in_ci, kill_five_times};

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

/// A fresh scratch directory in Cargo's scratch area for integration tests.
fn temp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("jsim-long-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp");
    d
}

/// The precision study's arguments: four magnitudes' 1-h stares on a small array.
fn transit_args() -> Vec<String> {
    let mut a: Vec<String> = [
        "transit",
        "--hours",
        "1",
        "--depth",
        "0",
        "--magnitudes",
        "9,10,11,12",
    ]
    .map(String::from)
    .to_vec();
    // the small sequence's instrument on a 512-px array of four channels, a 200-s ACE, three comparisons
    for s in SMALL_SEQUENCE.iter().chain(&[
        "instrument.detector_px=512",
        "instrument.photosensitive_px=496",
        "readout.channels=4",
        "ace.span_s=200.0",
        "transit.comparisons=3",
        "transit.field_radius_px=150.0",
    ]) {
        a.push("--set".into());
        a.push(s.to_string());
    }
    a
}

fn solve_args() -> Vec<String> {
    ["solve-synthetic", "--sources", "20000", "--exposures", "50"]
        .map(String::from)
        .to_vec()
}

/// The small sequence's arguments (four exposures), its spec written into `dir`.
fn sequence_args(dir: &Path) -> Vec<String> {
    let spec = dir.join("seq.toml");
    std::fs::write(
        &spec,
        "[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\nvisits_utc = [\"2031-03-21T00:00:00\"]\n\
         visit_dither_px = 0.0\n",
    )
    .expect("write");
    let mut a: Vec<String> = ["sequence", "--countermeasure", "none", "--spec"]
        .map(String::from)
        .to_vec();
    a.push(spec.display().to_string());
    for s in SMALL_SEQUENCE {
        a.push("--set".into());
        a.push(s.into());
    }
    a
}

/// `jsim ARGS --out OUT`, run to its end; it must succeed.
fn run_ok(args: &[String], out: &Path) -> f64 {
    let t = std::time::Instant::now();
    let o = jsim()
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run");
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    t.elapsed().as_secs_f64()
}

/// The same files in `a` and `b`, none temporary, and those `compared` accepts equal byte for byte.
fn same_results(a: &Path, b: &Path, compared: impl Fn(&str) -> bool) -> usize {
    let (fa, fb) = (files_under(a), files_under(b));
    assert_eq!(fa, fb, "the same files");
    let mut n = 0;
    for f in &fa {
        assert!(!f.contains(".tmp"), "a temporary file is left: {f}");
        if compared(f) {
            assert!(
                std::fs::read(a.join(f)).expect("a") == std::fs::read(b.join(f)).expect("b"),
                "{f} differs between {} and {}",
                a.display(),
                b.display()
            );
            n += 1;
        }
    }
    n
}

/// `jsim ARGS EXTRA --out OUT`.
fn jsim_into(args: &[String], extra: &[String], out: &Path) -> Command {
    let mut c = jsim();
    c.args(args).args(extra).arg("--out").arg(out);
    c
}

/// The precision study killed five times resumes from its finished stares (`hw_M/row.json`, kept as
/// they were) to the uninterrupted run's `precision.csv`, figure and light curves; a rerun with another
/// seed into the same directory runs every stare again.
#[test]
fn a_transit_study_killed_five_times_resumes_to_the_same_bytes() {
    let dir = temp("transit-kill");
    let args = transit_args();
    let whole = dir.join("whole");
    let whole_s = run_ok(&args, &whole);
    let killed = dir.join("killed");
    let kills = kill_five_times(|| jsim_into(&args, &[], &killed), whole_s, || {});
    assert!(kills >= 3, "only {kills} of the 5 runs were killed running");
    // the stares finished before the last kill, as they were left
    let rows = |d: &Path| -> Vec<(String, Vec<u8>)> {
        files_under(d)
            .into_iter()
            .filter(|f| f.ends_with("row.json"))
            .map(|f| {
                let b = std::fs::read(d.join(&f)).expect("row");
                (f, b)
            })
            .collect()
    };
    let finished = rows(&killed);
    assert!(
        !finished.is_empty(),
        "no stare finished before the last kill"
    );
    run_ok(&args, &killed);
    let after = rows(&killed);
    for (f, b) in &finished {
        let kept = after.iter().find(|(g, _)| g == f).expect("kept");
        assert_eq!(&kept.1, b, "{f}: a finished stare was run again");
    }
    let compared = same_results(&whole, &killed, |f| {
        f.starts_with("precision.") && !f.ends_with(".json")
            || f.ends_with("lightcurve.ecsv")
            || f.ends_with("truth.ecsv")
    });
    assert_eq!(
        compared,
        2 + 2 * 4,
        "precision.csv/.png and 4 stares' files"
    );
    // another seed: nothing is taken from the other run
    let o = jsim()
        .args(&args)
        .args(["--set", "seed=7"])
        .arg("--out")
        .arg(&killed)
        .output()
        .expect("run");
    assert!(o.status.success());
    assert!(
        std::fs::read(whole.join("precision.csv")).expect("a")
            != std::fs::read(killed.join("precision.csv")).expect("b"),
        "a rerun with another seed took the old rows"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A solution with a checkpoint killed five times is rerun with the same options to the uninterrupted
/// run's catalogues, bit for bit, and leaves no checkpoint once done.
#[test]
fn a_solution_killed_five_times_resumes_from_its_checkpoint_to_the_same_bytes() {
    let dir = temp("solve-kill");
    let args = solve_args();
    let whole = dir.join("whole");
    let whole_s = run_ok(&args, &whole);
    let killed = dir.join("killed");
    let ck = dir.join("solution.checkpoint");
    let with_ck = ["--checkpoint".to_string(), ck.display().to_string()];
    let mut checkpointed = 0;
    let kills = kill_five_times(
        || jsim_into(&args, &with_ck, &killed),
        whole_s,
        || checkpointed += usize::from(ck.exists()),
    );
    assert!(kills >= 3, "only {kills} runs were killed running");
    assert!(
        checkpointed >= 1,
        "no kill left a checkpoint to resume from"
    );
    let mut all = args.clone();
    all.extend(with_ck.iter().cloned());
    run_ok(&all, &killed);
    assert!(!ck.exists(), "the checkpoint is removed once done");
    let compared = same_results(&whole, &killed, |f| f.ends_with(".csv"));
    assert_eq!(compared, 2, "sources.csv and attitudes.csv");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Whether `unshare -rm` (a private user and mount namespace, where a tmpfs can be mounted without
/// privileges) works here. In CI it must: the full-disk tests fail without it.
fn unshare_works() -> bool {
    let ok = Command::new("unshare")
        .args(["-rm", "true"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            !in_ci(),
            "`unshare -rm` does not work and CI is set: the full-disk tests need a private mount namespace \
             (util-linux's unshare and unprivileged user namespaces, or root)"
        );
        eprintln!("SKIPPED: `unshare -rm` does not work here; the full-disk tests need it");
    }
    ok
}

/// `jsim ARGS` into a tmpfs of `size_kib` that fills up, then into the same tmpfs grown to 64 MiB (the
/// same command, rerun): returns (the first run's exit code and stderr, the temporary files it left, the
/// rerun's exit code and stderr), the tmpfs's final content copied to `keep`.
fn on_a_full_disk(
    args: &[String],
    size_kib: u64,
    dir: &Path,
    keep: &Path,
) -> (i32, String, String, i32, String) {
    fn q(w: impl AsRef<std::ffi::OsStr>) -> String {
        engine::io::shell_quote(w)
    }
    let mount = dir.join("mnt");
    std::fs::create_dir_all(&mount).expect("mount point");
    let command = |log: &str| {
        let mut c = q(env!("CARGO_BIN_EXE_jsim"));
        for a in args {
            c.push(' ');
            c.push_str(&q(a));
        }
        format!(
            "{c} --out {} > /dev/null 2> {}; echo $? > {}.rc",
            q(mount.join("out")),
            q(dir.join(log)),
            q(dir.join(log))
        )
    };
    let script = format!(
        "set -u\nmount -t tmpfs -o size={size_kib}k tmpfs {m}\n{first}\nfind {m} -name '*.tmp*' > {tmps}\n\
         mount -o remount,size=64m {m}\n{second}\ncp -r {out} {keep}\n",
        m = q(&mount),
        first = command("full.log"),
        second = command("room.log"),
        tmps = q(dir.join("tmps.txt")),
        out = q(mount.join("out")),
        keep = q(keep),
    );
    let st = Command::new("unshare")
        .args(["-rm", "sh", "-c", &script])
        .status()
        .expect("unshare");
    assert!(st.success(), "the namespace's script failed");
    let read = |n: &str| std::fs::read_to_string(dir.join(n)).expect(n);
    let rc = |n: &str| read(n).trim().parse::<i32>().expect("rc");
    (
        rc("full.log.rc"),
        read("full.log"),
        read("tmps.txt"),
        rc("room.log.rc"),
        read("room.log"),
    )
}

/// The bytes of every file under `dir`.
fn bytes_under(dir: &Path) -> u64 {
    files_under(dir)
        .iter()
        .map(|f| std::fs::metadata(dir.join(f)).map(|m| m.len()).unwrap_or(0))
        .sum()
}

/// A sequence whose disk fills up midway stops with an error that says so (exit 1), leaves no partial
/// file, keeps the exposures it finished, and resumes once there is room to the catalogue of a run that
/// never met a full disk.
#[test]
fn a_sequence_on_a_full_disk_stops_named_and_resumes_to_the_same_bytes() {
    if !unshare_works() {
        return;
    }
    let dir = temp("seq-full");
    let args = sequence_args(&dir);
    let whole = dir.join("whole");
    run_ok(&args, &whole);
    // room for the setup and about half the exposures
    let size_kib = (bytes_under(&whole) * 13 / 20) / 1024;
    let resumed = dir.join("resumed");
    let (rc, err, tmps, rc2, err2) = on_a_full_disk(&args, size_kib, &dir, &resumed);
    assert_eq!(rc, 1, "{err}");
    assert!(err.contains("the disk is full"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(tmps.trim().is_empty(), "partial files left: {tmps}");
    assert_eq!(rc2, 0, "{err2}");
    assert!(
        err2.contains("already written"),
        "the rerun redid every exposure: {err2}"
    );
    let compared = same_results(&whole, &resumed, |f| {
        f == "catalogue.fits" || f.starts_with("exposures/")
    });
    assert_eq!(compared, 1 + 2 * 4, "catalogue.fits and 4 exposures' files");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The transit study on a disk that fills up midway: a named error, no partial file, and a rerun with
/// room gives the uninterrupted study's precision.csv.
#[test]
fn a_transit_study_on_a_full_disk_stops_named_and_resumes_to_the_same_bytes() {
    if !unshare_works() {
        return;
    }
    let dir = temp("transit-full");
    let args = transit_args();
    let whole = dir.join("whole");
    run_ok(&args, &whole);
    let size_kib = (bytes_under(&whole) * 11 / 20) / 1024;
    let resumed = dir.join("resumed");
    let (rc, err, tmps, rc2, err2) = on_a_full_disk(&args, size_kib, &dir, &resumed);
    assert_eq!(rc, 1, "{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(tmps.trim().is_empty(), "partial files left: {tmps}");
    assert_eq!(rc2, 0, "{err2}");
    let compared = same_results(&whole, &resumed, |f| {
        f == "precision.csv" || f.ends_with("lightcurve.ecsv")
    });
    assert_eq!(compared, 1 + 4);
    let _ = std::fs::remove_dir_all(&dir);
}
