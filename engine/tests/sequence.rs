//! `jsim sequence` as a user meets it: a small step-stare sequence planned, every exposure simulated and
//! analysed, the catalogues gathered into one FITS table; a rerun resumes (nothing redone, a lost exposure
//! redone identically), two shards give the same table as one run, and bad input is named.

use std::path::{Path, PathBuf};
use std::process::Command;

mod support;
use support::SMALL_SEQUENCE as SMALL;
use support::files_under;

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("jsim-seq-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp");
    d
}

fn spec(dir: &Path) -> PathBuf {
    let p = dir.join("seq.toml");
    std::fs::write(
        &p,
        "[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\nvisits_utc = [\"2031-03-21T00:00:00\"]\n\
         visit_dither_px = 0.0\n",
    )
    .expect("write");
    p
}

/// `jsim sequence` of `spec` on the small configuration into `out`.
fn command(out: &Path, spec: &Path, extra: &[&str]) -> Command {
    let mut c = jsim();
    c.args(["sequence", "--countermeasure", "none", "--spec"])
        .arg(spec);
    for s in SMALL {
        c.args(["--set", s]);
    }
    c.args(extra).arg("--out").arg(out);
    c
}

fn run(out: &Path, spec: &Path, extra: &[&str]) -> std::process::Output {
    command(out, spec, extra).output().expect("run")
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn table(path: &Path) -> Vec<Vec<f64>> {
    engine::io::fits::read_table(
        path,
        "CATALOGUE",
        &engine::studies::sequence::run::CATALOGUE_HEADER,
    )
    .expect("catalogue.fits")
}

#[test]
fn a_sequence_runs_resumes_and_shards_to_the_same_catalogue() {
    let dir = temp("run");
    let spec = spec(&dir);
    let out = dir.join("all");
    let o = run(&out, &spec, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let plan = std::fs::read_to_string(out.join("plan.csv")).expect("plan");
    assert_eq!(plan.lines().count(), 1 + 4, "{plan}");
    let t = table(&out.join("catalogue.fits"));
    let exposure = &t[0];
    assert!(exposure.len() > 50, "{} stars", exposure.len());
    for e in 0..4 {
        assert!(exposure.contains(&(e as f64)), "exposure {e} has stars");
    }
    // the measured sky positions are where the field's stars are: the scoring's matched errors are
    // mas-level (the stars are Hw 8 … 17 in a sparse field)
    let truth = std::fs::read_to_string(out.join("exposures/00000_truth.csv")).expect("truth");
    let dx: Vec<f64> = truth
        .lines()
        .skip(1)
        .filter_map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (c[2] != "-1").then(|| c[3].parse::<f64>().ok()).flatten()
        })
        .collect();
    let median = engine::numerics::stats::median(&dx.iter().map(|v| v.abs()).collect::<Vec<_>>());
    assert!(
        dx.len() > 20 && median < 50.0,
        "{} matched, median |dx| {median} mas",
        dx.len()
    );
    // a rerun redoes nothing; a lost exposure is redone, identically (its own seed)
    let kept = std::fs::read_to_string(out.join("exposures/00002.csv")).expect("exposure 2");
    let o = run(&out, &spec, &[]);
    assert!(o.status.success());
    assert_eq!(
        stderr(&o).matches("already written").count(),
        4,
        "{}",
        stderr(&o)
    );
    std::fs::remove_file(out.join("exposures/00002.csv")).expect("rm");
    let o = run(&out, &spec, &[]);
    assert_eq!(
        stderr(&o).matches("already written").count(),
        3,
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(out.join("exposures/00002.csv")).expect("redone"),
        kept
    );
    // a rerun resumes only this sequence: another seed, or files of another jsim, are refused and nothing
    // is written (the kept exposures would otherwise mix two sequences)
    let plan_bytes = std::fs::read(out.join("plan.csv")).expect("plan");
    let o = run(&out, &spec, &["--set", "seed=7"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("holds another sequence (its config.toml is another configuration's)"),
        "{}",
        stderr(&o)
    );
    let json = out.join("sequence.json");
    let text = std::fs::read_to_string(&json).expect("sequence.json");
    let version = format!("\"jsim_version\": \"{}\"", engine::VERSION);
    assert!(text.contains(&version), "{text}");
    std::fs::write(&json, text.replace(&version, "\"jsim_version\": \"0.0.0\"")).expect("write");
    let o = run(&out, &spec, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("it was written by jsim 0.0.0"),
        "{}",
        stderr(&o)
    );
    std::fs::write(&json, text).expect("write");
    assert_eq!(
        std::fs::read(out.join("plan.csv")).expect("plan"),
        plan_bytes
    );
    assert_eq!(
        std::fs::read_to_string(out.join("exposures/00002.csv")).expect("kept"),
        kept
    );
    // two shards (two Slurm array tasks) into one directory: the same table
    let sharded = dir.join("sharded");
    let o = run(&sharded, &spec, &["--shard", "0/2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("not every exposure has run yet"));
    assert!(!sharded.join("catalogue.fits").exists());
    // the second shard keeps its images: the same table, and each image's orbit phase is plan.csv's
    let o = run(&sharded, &spec, &["--shard", "1/2", "--keep-images"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(table(&sharded.join("catalogue.fits")), t);
    let (h, rows) = engine::io::csv::read(&sharded.join("plan.csv")).expect("plan");
    let phase = engine::io::csv::column_f64(Path::new("plan.csv"), &h, &rows, "orbit_phase_deg")
        .expect("orbit_phase_deg");
    assert!(phase.iter().all(|p| (0.0..360.0).contains(p)), "{phase:?}");
    // the phase advances 360° per 96.7-min orbit (600 km) between exposures
    let mjd =
        engine::io::csv::column_f64(Path::new("plan.csv"), &h, &rows, "mjd_tdb").expect("mjd");
    let dt_s = (mjd[1] - mjd[0]) * 86_400.0;
    let advance = (phase[1] - phase[0]).rem_euclid(360.0);
    assert!(
        dt_s > 0.0 && (advance / (360.0 * dt_s / 5802.0) - 1.0).abs() < 0.01,
        "{advance}° in {dt_s} s"
    );
    for e in 0..4 {
        let image = engine::studies::sequence::run::image_path(&sharded, e);
        assert_eq!(image.exists(), e % 2 == 1, "{}", image.display());
        if e % 2 == 1 {
            for array in ["ARRAY1", "ARRAY4"] {
                let k = engine::io::fits::read_f64_key_in(&image, Some(array), "ORBPHASE")
                    .expect("ORBPHASE");
                assert!(
                    (k - phase[e]).abs() < 1e-6,
                    "{array}: {k} against {}",
                    phase[e]
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_slurm_scripts_run_the_same_sequence() {
    // --emit-slurm writes the configuration, the sequence file, the field and the scripts; running the
    // array script as tasks 0 and 1 (what Slurm would do) and then the gathering job gives the table of one
    // local run
    let dir = temp("slurm");
    let spec = spec(&dir);
    let local = dir.join("local");
    assert!(run(&local, &spec, &[]).status.success());
    let out = dir.join("cluster");
    let o = run(
        &out,
        &spec,
        &["--emit-slurm", "--shards", "2", "--time", "10:00"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "config.toml",
        "sequence.toml",
        "field.csv",
        "slurm/array.sbatch",
        "slurm/gather.sbatch",
        "slurm/submit.sh",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    assert!(!out.join("exposures").exists(), "nothing ran");
    for task in ["0", "1"] {
        let o = Command::new("bash")
            .arg(out.join("slurm/array.sbatch"))
            .env("SLURM_ARRAY_TASK_ID", task)
            .output()
            .expect("task");
        assert!(o.status.success(), "task {task}: {}", stderr(&o));
    }
    let o = Command::new("bash")
        .arg(out.join("slurm/gather.sbatch"))
        .output()
        .expect("gather");
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        table(&out.join("catalogue.fits")),
        table(&local.join("catalogue.fits"))
    );
    // bad cluster options are named, nothing written
    let bad = dir.join("bad");
    for (extra, needle) in [
        (vec!["--emit-slurm", "--shards", "0"], "--shards 0"),
        (vec!["--emit-slurm", "--time", "soon"], "--time"),
        (vec!["--emit-slurm", "--exposures", "2"], "drop --exposures"),
    ] {
        let o = run(&bad, &spec, &extra);
        assert_eq!(o.status.code(), Some(1), "{extra:?}");
        assert!(stderr(&o).contains(needle), "{extra:?}: {}", stderr(&o));
        assert!(!bad.join("slurm").exists(), "{extra:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_sequences_are_named_and_write_nothing() {
    let dir = temp("bad");
    let out = dir.join("out");
    let bad = dir.join("bad.toml");
    for (text, needle) in [
        ("[sequence]\nstares_l = 0\n", "sequence.stares_l = 0"),
        (
            "[sequence]\nvisits_utc = [\"2031-13-01\"]\n",
            "sequence.visits_utc[0]",
        ),
        ("[sequence]\nstars_l = 2\n", "stars_l"),
    ] {
        std::fs::write(&bad, text).expect("write");
        let o = run(&out, &bad, &["--plan-only"]);
        assert_eq!(o.status.code(), Some(1), "{text}");
        assert!(stderr(&o).contains(needle), "{text}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"));
        assert!(!out.exists(), "{text}: wrote its output directory");
    }
    let o = run(&out, &spec(&dir), &["--exposures", "0"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--exposures 0"), "{}", stderr(&o));
    let o = run(&out, &spec(&dir), &["--shard", "2/2"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn persistence_along_a_sequence_is_the_same_straight_or_sharded() {
    // each exposure's persistence is what the earlier exposures' charge releases, that charge remade from
    // the plan and the field where this process did not make it: two shards (each missing the other's
    // exposures) give the table a straight run gives — with every star filling traps (the default
    // threshold: a straight run keeps each exposure's own charge) and with the bright ones only (a higher
    // threshold: a remake of those). The first exposure has nothing before it; the later ones collect what
    // the earlier ones left.
    let dir = temp("persistence");
    let spec = spec(&dir);
    let off = dir.join("off");
    let o = run(&off, &spec, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let without = table(&off.join("catalogue.fits"));
    // exposure e's rows, all columns but the sequence's identity (its configuration differs between runs)
    let id_column = engine::studies::sequence::run::CATALOGUE_HEADER
        .iter()
        .position(|c| *c == "sequence_id")
        .expect("the identity column");
    let rows = |t: &Vec<Vec<f64>>, e: f64| -> Vec<Vec<f64>> {
        t.iter()
            .enumerate()
            .filter(|(k, _)| *k != id_column)
            .map(|(_, c)| {
                c.iter()
                    .zip(&t[0])
                    .filter(|(_, x)| **x == e)
                    .map(|(v, _)| *v)
                    .collect()
            })
            .collect()
    };
    for (name, threshold, bright_file) in [("all", "200.0", false), ("bright", "20000.0", true)] {
        let set = format!("detector.persistence.threshold_e={threshold}");
        let args = [
            "--set",
            "detector.persistence.enabled=true",
            "--set",
            set.as_str(),
        ];
        let out = dir.join(format!("{name}-straight"));
        let o = run(&out, &spec, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        // a straight run remakes nothing when it keeps its own charge; the bright stars' remakes else
        assert_eq!(
            stderr(&o).contains("the bright light of 3 exposures remade"),
            bright_file,
            "{name}: {}",
            stderr(&o)
        );
        assert_eq!(out.join("field_bright.csv").exists(), bright_file, "{name}");
        let with = table(&out.join("catalogue.fits"));
        let sharded = dir.join(format!("{name}-sharded"));
        for s in ["0/2", "1/2"] {
            let mut a = args.to_vec();
            a.extend(["--shard", s]);
            let o = run(&sharded, &spec, &a);
            assert!(o.status.success(), "{}", stderr(&o));
            assert!(stderr(&o).contains("remade"), "{name} {s}: {}", stderr(&o));
        }
        assert_eq!(table(&sharded.join("catalogue.fits")), with, "{name}");
        assert_eq!(
            rows(&with, 0.0),
            rows(&without, 0.0),
            "{name}: exposure 0 has no past"
        );
        for e in 1..4 {
            assert_ne!(
                rows(&with, e as f64),
                rows(&without, e as f64),
                "{name}: exposure {e}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two stares a half field apart, two exposures each, in spring and autumn (a small visit dither): 8
/// exposures of the small arrays — enough for the solution's five parameters, the arrays' own terms and a
/// cubic distortion.
fn two_visits(dir: &Path) -> PathBuf {
    let p = dir.join("seq2.toml");
    std::fs::write(
        &p,
        "[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\nvisit_dither_px = 20.0\n",
    )
    .expect("write");
    p
}

fn csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).expect("csv");
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(String::from)
        .collect();
    let rows = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    (header, rows)
}

#[test]
fn a_sequence_is_solved_from_its_products_and_scored() {
    let dir = temp("solve");
    let spec = two_visits(&dir);
    let out = dir.join("seq");
    let o = run(&out, &spec, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bare = products_alone_are_what_the_solution_reads(&dir, &out);
    a_catalogue_of_another_sequence_is_refused(&dir, &bare);
    an_exposure_of_flagged_stars_is_left_out(&dir, &out);
    let sol = dir.join("solution");
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(&out)
        .args(["--exposures", "4,8", "--out"])
        .arg(&sol)
        .output()
        .expect("solve");
    assert!(o.status.success(), "{}", stderr(&o));
    the_sources_scatter_as_their_errors_say(&sol);
    the_assembly_and_the_attitudes_are_solved(&sol);
    bad_solve_input_is_named(&dir, &out);
    every_other_exposure_of_each_stare_is_solved(&dir, &out);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The sequence's products, copied without a truth file: the solution reads them all (returns their directory).
fn products_alone_are_what_the_solution_reads(dir: &Path, out: &Path) -> PathBuf {
    // the products the solution reads, and nothing of the truth among them: the instrument as designed
    // (the arrays where they were designed), where the simulation's config.toml has them as assembled
    for f in ["design.toml", "sequence.toml", "reference.csv", "plan.csv"] {
        assert!(out.join(f).exists(), "{f}");
    }
    let design = engine::config::Config::load(&out.join("design.toml")).expect("design");
    let built = engine::config::Config::load(&out.join("config.toml")).expect("config");
    assert_eq!(design.focal_plane.array_offsets_px, [[0.0; 2]; 4]);
    assert!(built.focal_plane.array_offsets_px[1][0].abs() > 0.1);
    // by construction: the products alone, every truth file moved away, are what the solution reads
    let bare = dir.join("products-only");
    std::fs::create_dir_all(bare.join("exposures")).expect("mkdir");
    for f in ["design.toml", "sequence.toml", "reference.csv", "plan.csv"] {
        std::fs::copy(out.join(f), bare.join(f)).expect("copy");
    }
    for e in std::fs::read_dir(out.join("exposures")).expect("exposures") {
        let path = e.expect("entry").path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        if !name.contains("truth") {
            std::fs::copy(&path, bare.join("exposures").join(&name)).expect("copy");
        }
    }
    let products =
        engine::studies::sequence::solution::read_products(&bare).expect("products alone");
    assert_eq!(products.exposures_run, 8);
    bare
}

/// A catalogue of another sequence mixed into `bare`'s products is refused by name; nothing is written.
fn a_catalogue_of_another_sequence_is_refused(dir: &Path, bare: &Path) {
    // a catalogue of another sequence (another plan: one visit, other times) mixed in is refused by name,
    // and nothing is written
    let other = dir.join("other");
    let one_visit = self::spec(dir);
    let o = run(&other, &one_visit, &["--exposures", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mixed = dir.join("mixed");
    std::fs::create_dir_all(mixed.join("exposures")).expect("mkdir");
    for e in std::fs::read_dir(bare).expect("bare").flatten() {
        if e.path().is_file() {
            std::fs::copy(e.path(), mixed.join(e.file_name())).expect("copy");
        }
    }
    for e in std::fs::read_dir(bare.join("exposures"))
        .expect("exposures")
        .flatten()
    {
        std::fs::copy(e.path(), mixed.join("exposures").join(e.file_name())).expect("copy");
    }
    std::fs::copy(
        other.join("exposures/00001.csv"),
        mixed.join("exposures/00001.csv"),
    )
    .expect("copy");
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(&mixed)
        .output()
        .expect("solve");
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("00001.csv") && err.contains("another sequence"),
        "{err}"
    );
    assert!(
        !mixed.join("solution").exists(),
        "nothing is written on error"
    );
}

/// An exposure whose every star is flagged is reported and left out; the rest is solved.
fn an_exposure_of_flagged_stars_is_left_out(dir: &Path, out: &Path) {
    // an exposure whose every star is flagged (saturated, say) is reported and left out; the rest is solved
    let flagged = dir.join("flagged");
    std::fs::create_dir_all(flagged.join("exposures")).expect("mkdir");
    for (from, to) in [
        (&out.to_path_buf(), &flagged),
        (&out.join("exposures"), &flagged.join("exposures")),
    ] {
        for e in std::fs::read_dir(from).expect("dir").flatten() {
            if e.path().is_file() {
                std::fs::copy(e.path(), to.join(e.file_name())).expect("copy");
            }
        }
    }
    let cat = flagged.join("exposures/00003.csv");
    let text = std::fs::read_to_string(&cat).expect("catalogue");
    let mut lines = text.lines();
    let head = lines.next().expect("header");
    let f = head.split(',').position(|c| c == "flags").expect("flags");
    let mut all_flagged = vec![head.to_string()];
    for l in lines {
        let mut cells: Vec<&str> = l.split(',').collect();
        cells[f] = "4";
        all_flagged.push(cells.join(","));
    }
    std::fs::write(&cat, all_flagged.join("\n") + "\n").expect("write");
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(&flagged)
        .args(["--exposures", "8", "--out"])
        .arg(dir.join("flagged-solution"))
        .output()
        .expect("solve");
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("left out") && err.contains("[3]"), "{err}");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("flagged-solution/solution.json")).expect("json"),
    )
    .expect("parse");
    assert_eq!(summary[0]["skipped_exposures"], serde_json::json!([3]));
}

/// The solution's positions scatter about the truth as its own errors say.
fn the_sources_scatter_as_their_errors_say(sol: &Path) {
    let (h, rows) = csv(&sol.join("sources.csv"));
    assert!(
        h.contains(&"parallax".to_string()) && rows.len() > 100,
        "{} sources",
        rows.len()
    );
    // the positions scatter about the truth as the solution's own errors say: the rms of the pulls of the
    // sources seen in all 8 exposures (≈ 80, along ξ) within 4σ of 1, σ = 1/√(2n) its sampling error
    // (measured: 1.035 over 80)
    let (h, rows) = csv(&sol.join("score_sources.csv"));
    let col = |n: &str| h.iter().position(|c| c == n).expect(n);
    let (dx, sx, nobs) = (col("d_xi_mas"), col("xi_error"), col("observations"));
    let pulls: Vec<f64> = rows
        .iter()
        .filter(|r| r[nobs] >= 8.0 && r[sx].is_finite())
        .map(|r| r[dx] / r[sx])
        .collect();
    let rms = (pulls.iter().map(|p| p * p).sum::<f64>() / pulls.len() as f64).sqrt();
    eprintln!("{} sources seen 8 times: rms pull {rms:.3}", pulls.len());
    let tol = 4.0 / (2.0 * pulls.len() as f64).sqrt();
    assert!(
        pulls.len() > 30 && (rms - 1.0).abs() < tol,
        "{} pulls, rms {rms} (1 ± {tol})",
        pulls.len()
    );
}

/// The arrays' assembly and every exposure's attitude are solved.
fn the_assembly_and_the_attitudes_are_solved(sol: &Path) {
    // the arrays' assembly (offsets of ≈ 10 px, turns of 0.1°) is solved: what is left of it on the arrays
    // is below 1 % of it (measured: 0.0095 of 6.1 px rms, from ≈ 400 reference stars of 3–40 mas and ≈ 650
    // sources)
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sol.join("solution.json")).expect("json"))
            .expect("parse");
    let last = &summary[1];
    let res = last["calibration_residual_rms_px"][0]
        .as_f64()
        .expect("residual");
    let (h, rows) = csv(&sol.join("calibration_map.csv"));
    let t = h.iter().position(|c| c == "true_dx_px").expect("true");
    let truth = (rows.iter().map(|r| r[t] * r[t]).sum::<f64>() / rows.len() as f64).sqrt();
    eprintln!("calibration: {res:.4} px left of {truth:.3} px");
    assert!(
        truth > 1.0 && res < 0.01 * truth,
        "residual {res} px of {truth} px"
    );
    assert_eq!(last["exposures"], 8);
    // every attitude against what the true stars ask of it: the solved attitudes took seconds of arc (pointing
    // errors of 2″, rolls of 10″, the aberration); what they missed is below a milliarcsecond (measured:
    // 0.75/0.42 mas and 0.93″ rms over the 8 exposures of 256-px arrays)
    let (h, rows) = csv(&sol.join("attitudes.csv"));
    let c = h
        .iter()
        .position(|x| x == "offset_eta_mas")
        .expect("offset");
    assert!(
        rows.iter().all(|r| r[c].abs() > 1000.0),
        "the attitudes moved by arcseconds"
    );
    let (h, rows) = csv(&sol.join("score_attitudes.csv"));
    assert_eq!(rows.len(), 8, "an attitude error per exposure");
    let rms = |name: &str| {
        let c = h.iter().position(|x| x == name).expect(name);
        (rows.iter().map(|r| r[c] * r[c]).sum::<f64>() / rows.len() as f64).sqrt()
    };
    let (dx, dy, roll) = (
        rms("d_offset_xi_mas"),
        rms("d_offset_eta_mas"),
        rms("d_roll_arcsec"),
    );
    eprintln!("attitudes: {dx:.3}/{dy:.3} mas, {roll:.4}″ rms");
    assert!(dx < 2.0 && dy < 2.0 && roll < 3.0, "{dx} {dy} mas, {roll}″");
}

/// Bad input to solve (not a sequence, too many exposures) is named; nothing is written.
fn bad_solve_input_is_named(dir: &Path, out: &Path) {
    // bad input: not a sequence, too many exposures — named, nothing written
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("dir");
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(&empty)
        .args(["--out"])
        .arg(dir.join("no1"))
        .output()
        .expect("solve");
    assert!(
        !o.status.success() && stderr(&o).contains("design.toml"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("no1").exists());
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(out)
        .args(["--exposures", "9", "--out"])
        .arg(dir.join("no2"))
        .output()
        .expect("solve");
    assert!(
        !o.status.success() && stderr(&o).contains("allowed 1 … 8"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("no2").exists());
}

/// `--every 2` keeps the first exposure of each of the four stares (of two each): the attitudes are those of
/// exposures 0, 2, 4, 6 by their own numbers; with `--excess-noise per-visit` the summary says so. A thinning
/// beyond the exposures per stare, or an excess of no known kind, is named and writes nothing.
fn every_other_exposure_of_each_stare_is_solved(dir: &Path, out: &Path) {
    let sol = dir.join("every2");
    let o = jsim()
        .args(["solve", "--sequence"])
        .arg(out)
        .args(["--every", "2", "--excess-noise", "per-visit", "--out"])
        .arg(&sol)
        .output()
        .expect("solve");
    assert!(o.status.success(), "{}", stderr(&o));
    let (h, rows) = csv(&sol.join("attitudes.csv"));
    let e = h
        .iter()
        .position(|c| c == "exposure")
        .expect("exposure column");
    let exposures: Vec<f64> = rows.iter().map(|r| r[e]).collect();
    assert_eq!(exposures, vec![0.0, 2.0, 4.0, 6.0]);
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(sol.join("solution.json")).expect("solution.json"),
    )
    .expect("json");
    assert_eq!(summary[0]["exposures"], 4);
    assert_eq!(summary[0]["excess_noise"], "per-visit");
    for (args, says, name) in [
        (["--every", "3"], "every 3: allowed 1 … 2", "no3"),
        (
            ["--excess-noise", "lots"],
            "allowed none, per-stare or per-visit",
            "no4",
        ),
    ] {
        let o = jsim()
            .args(["solve", "--sequence"])
            .arg(out)
            .args(args)
            .arg("--out")
            .arg(dir.join(name))
            .output()
            .expect("solve");
        assert!(
            !o.status.success() && stderr(&o).contains(says),
            "{}",
            stderr(&o)
        );
        assert!(!dir.join(name).exists());
    }
}

/// plan.csv's seeds are the exposures' u64 seeds, unsigned (2⁶³ and above without a minus sign), so one
/// copied back with `--set seed=…` is that exposure's; a master seed near 2⁶⁴ is accepted.
#[test]
fn plan_csv_seeds_parse_back_as_the_exposures_u64_seeds() {
    let dir = temp("seeds");
    let spec = spec(&dir);
    let seq = engine::studies::sequence::Spec::load(&spec).expect("spec");
    let mut base = engine::Config::default();
    for s in SMALL {
        let (k, v) = s.split_once('=').expect("k=v");
        base = base.with_override(k, v).expect("override");
    }
    // the first master seed from 2⁶⁴ − 1 down whose plan has an exposure seed ≥ 2⁶³
    let (master, expected) = (0..64)
        .map(|k| {
            let m = u64::MAX - k;
            let cfg = base.with_override("seed", &m.to_string()).expect("seed");
            assert_eq!(cfg.seed, m);
            let plan = engine::studies::sequence::plan(&seq, &cfg).expect("plan");
            (
                m,
                plan.exposures.iter().map(|e| e.seed).collect::<Vec<u64>>(),
            )
        })
        .find(|(_, s)| s.iter().any(|s| *s >= 1 << 63))
        .expect("a plan with a seed ≥ 2⁶³");
    let out = dir.join("plan");
    let o = run(
        &out,
        &spec,
        &["--plan-only", "--set", &format!("seed={master}")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(out.join("plan.csv")).expect("plan");
    let header: Vec<&str> = text.lines().next().expect("header").split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == "seed")
        .expect("seed column");
    let seeds: Vec<u64> = text
        .lines()
        .skip(1)
        .map(|l| {
            let cell = l.split(',').nth(col).expect("seed cell");
            cell.parse::<u64>()
                .unwrap_or_else(|e| panic!("seed {cell:?}: {e}"))
        })
        .collect();
    assert_eq!(seeds, expected);
}

/// A sequence killed outright (SIGKILL: no handler runs) at five moments of its run, each rerun resuming the
/// last, then run to its end, gives what one uninterrupted run gives — every exposure's catalogue and the
/// gathered `catalogue.fits` byte for byte — and leaves no temporary file behind. The kills land at fractions
/// of the uninterrupted run's time, so they fall in the setup, the exposures and the gathering alike.
#[test]
fn a_sequence_killed_five_times_resumes_to_the_same_bytes() {
    let dir = temp("kill");
    let spec = spec(&dir);
    let whole = dir.join("whole");
    let t = std::time::Instant::now();
    let o = run(&whole, &spec, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let whole_s = t.elapsed().as_secs_f64();
    let killed = dir.join("killed");
    let kills = support::kill_five_times(|| command(&killed, &spec, &[]), whole_s, || {});
    assert!(
        kills >= 3,
        "only {kills} of the 5 runs were still running when killed"
    );
    let o = run(&killed, &spec, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (a, b) = (files_under(&whole), files_under(&killed));
    assert_eq!(a, b, "the same files");
    for f in &a {
        let name = f.as_str();
        assert!(!name.contains(".tmp"), "a temporary file is left: {name}");
        // the catalogues and the gathered table are the run's results: byte for byte (the timing reports
        // and figures may differ)
        if name.ends_with(".csv") && name.starts_with("exposures/") || name == "catalogue.fits" {
            assert_eq!(
                std::fs::read(whole.join(f)).expect("whole"),
                std::fs::read(killed.join(f)).expect("killed"),
                "{name} differs after the kills"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
