//! The `jsim` binary as a user meets it: the default config round-trips, bad input is an error that names
//! the field or file (exit 1, no panic), and an invalid run leaves no output file behind.

use std::path::{Path, PathBuf};
use std::process::Command;

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

/// A fresh, empty scratch directory for one test, in Cargo's scratch area for integration tests (`target/tmp`).
fn temp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("jsim-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp");
    d
}

fn small_toml(dir: &Path) -> PathBuf {
    let p = dir.join("small.toml");
    std::fs::write(
        &p,
        "[instrument]\ndetector_px = 256\nphotosensitive_px = 240\n[readout]\nchannels = 2\nchannel_width_px = 128\n\
         [scene]\ngrid_n = 3\ngrid_spacing_px = 70.0\n[optics]\npupil_samples = 64\npsf_oversampling = 8\npsf_radius_px = 8\n\
         [band]\nwavelength_step_um = 0.1\n[fidelity]\nimages = 2\nsubpixels = 4\nstamp_radius_px = 8\nbackend = \"cpu\"\n[ace]\nspan_s = 60.0\n",
    )
    .expect("write");
    p
}

fn stderr_of(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).to_string()
}

#[test]
fn print_default_parses_to_the_builtin_default() {
    let out = jsim()
        .args(["config", "--print-default"])
        .output()
        .expect("run");
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).expect("utf8");
    assert_eq!(
        engine::config::Config::from_toml_str(&text).expect("parses"),
        engine::config::Config::default()
    );
}

#[test]
fn bad_values_are_named_errors_and_write_nothing() {
    let dir = temp("bad");
    let out_dir = dir.join("out");
    let simulate = [
        (
            vec!["--set", "detector.exposure_s=-1"],
            "detector.exposure_s",
        ),
        (vec!["--set", "ace.sigma_mas=nan"], "ace.sigma_mas"),
        (vec!["--set", "ace.sigma_mass=3"], "sigma_mass"),
        (vec!["--readout", "diagonal"], "readout.order"),
        (
            vec!["--set", "analysis.telemetry_model_nodes_per_px=0"],
            "analysis.telemetry_model_nodes_per_px",
        ),
        (
            vec!["--config", "/nonexistent/cfg.toml"],
            "/nonexistent/cfg.toml",
        ),
        (
            vec!["--set", "observation.start_utc=\"2031-02-30T00:00:00\""],
            "observation.start_utc",
        ),
        (
            vec!["--set", "observation.orbit_altitude_km=50"],
            "observation.orbit_altitude_km",
        ),
        (
            vec!["--set", "observation.catalogue_epoch_jyear=1000"],
            "observation.catalogue_epoch_jyear",
        ),
        (
            vec!["--set", "scene.bulge.distance_kpc=30"],
            "scene.bulge.distance_kpc",
        ),
        (
            vec!["--set", "detector.cosmic_ray_rate_per_cm2_s=-1"],
            "detector.cosmic_ray_rate_per_cm2_s",
        ),
        (
            vec!["--set", "detector.persistence.rho=[1e-3, 2e-3]"],
            "needs one density per time constant",
        ),
        (
            vec![
                "--set",
                "detector.persistence.tau_s=[1, 10, 0, 1000, 10000]",
            ],
            "detector.persistence.tau_s",
        ),
        (
            vec!["--set", "detector.persistence.lookback_s=1e6"],
            "detector.persistence.lookback_s",
        ),
    ];
    let cases = simulate
        .into_iter()
        .map(|(mut args, needle)| {
            args.insert(0, "simulate");
            (args, needle)
        })
        // a bench part that does not exist is named, not skipped; the crowded study's survey (one
        // catalogue for its plate models and held stars) is checked before anything is written
        .chain([
            (vec!["bench", "--parts", "methods,nope"], "--parts nope"),
            (
                vec!["crowded", "--refcat-limit-hw", "99"],
                "--refcat-limit-hw 99: allowed",
            ),
            (
                vec!["crowded", "--reference-error-mas", "5"],
                "--refcat-floor-mas 2 and --reference-error-mas 5",
            ),
            (
                vec!["solve", "--sequence", "/nonexistent", "--model", "proper"],
                "--model \"proper\": allowed auto, position, full",
            ),
            // the synthetic solution's sizes are named as its own options (not the bench's)
            (
                vec!["solve-synthetic", "--exposures", "40"],
                "--exposures 40: allowed multiples of 25",
            ),
            (
                vec!["solve-synthetic", "--sources", "10"],
                "--sources 10: allowed 100",
            ),
        ]);
    for (args, needle) in cases {
        let out = jsim()
            .args(&args)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .expect("run");
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = stderr_of(&out);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        // each cause said once (a missing file's reason is not repeated by the error chain)
        assert!(err.matches("os error").count() <= 1, "{err}");
        assert!(!out_dir.exists(), "{args:?} created its output directory");
    }
    let out = jsim()
        .args(["analyze", "--image", "/nonexistent/img.fits", "--out"])
        .arg(dir.join("an"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr_of(&out).contains("/nonexistent/img.fits"));
    // a control that applies to no dataset is an error, not an empty table
    let exp_dir = dir.join("exp");
    let out = jsim()
        .args([
            "experiment",
            "--aces",
            "realistic",
            "--countermeasures",
            "exact-epsf",
            "--out",
        ])
        .arg(&exp_dir)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr_of(&out).contains("static ACE"),
        "{}",
        stderr_of(&out)
    );
    assert!(!exp_dir.exists());
}

/// A run that probes for a GPU with no `XDG_RUNTIME_DIR` set prints no Mesa warning and leaves nothing in
/// the temporary directory (the CLI points the variable at it instead of creating a directory per run).
#[test]
fn a_gpu_probe_leaves_the_temporary_directory_as_it_was() {
    let dir = temp("xdg");
    let cfg = small_toml(&dir);
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).expect("tmp");
    let out = jsim()
        .env_remove("XDG_RUNTIME_DIR")
        .env("TMPDIR", &tmp)
        .args(["simulate", "--config"])
        .arg(&cfg)
        .args(["--images", "1", "--backend", "auto", "--out"])
        .arg(dir.join("sim"))
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    assert!(
        !stderr_of(&out).contains("XDG_RUNTIME_DIR"),
        "{}",
        stderr_of(&out)
    );
    let left: Vec<_> = std::fs::read_dir(&tmp)
        .expect("read tmp")
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert!(left.is_empty(), "left behind in TMPDIR: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn simulate_then_analyze_on_a_small_scene() {
    let dir = temp("run");
    let cfg = small_toml(&dir);
    let out = jsim()
        .args(["simulate", "--config"])
        .arg(&cfg)
        .args(["--ace", "gaussian", "--out"])
        .arg(dir.join("sim"))
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    // the configuration asks for the CPU: no word about GPU adapters
    assert!(!stderr_of(&out).contains("adapter"), "{}", stderr_of(&out));
    for f in [
        "img_000.fits",
        "img_001.fits",
        "truth_000.csv",
        "truth_001.csv",
        "run.json",
        "config.toml",
    ] {
        assert!(dir.join("sim").join(f).exists(), "{f}");
    }
    let out = jsim()
        .args(["analyze", "--image"])
        .arg(dir.join("sim/img_000.fits"))
        .arg("--out")
        .arg(dir.join("an"))
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("an/summary.json")).expect("summary"),
    )
    .expect("json");
    assert_eq!(summary["report"]["n_used"].as_u64(), Some(9));
    assert!(
        summary["report"]["accuracy_mas"]
            .as_f64()
            .expect("accuracy")
            < 10.0
    );
    for f in ["catalogue.csv", "epsf.fits", "vectors.csv", "vectors.png"] {
        assert!(dir.join("an").join(f).exists(), "{f}");
    }
    // same seed, same image (a second run into another directory)
    let out = jsim()
        .args(["simulate", "--config"])
        .arg(&cfg)
        .args(["--ace", "gaussian", "--out"])
        .arg(dir.join("sim2"))
        .output()
        .expect("run");
    assert!(out.status.success());
    let a = engine::io::fits::read_image(&dir.join("sim/img_001.fits")).expect("a");
    let b = engine::io::fits::read_image(&dir.join("sim2/img_001.fits")).expect("b");
    assert_eq!(a.data, b.data);
}

/// A run stopped by Ctrl-C (SIGINT) removes what it wrote: no directory, no image, no temporary file.
#[test]
fn an_interrupted_simulation_leaves_nothing() {
    let dir = temp("interrupt");
    let cfg = small_toml(&dir);
    let out_dir = dir.join("out");
    let mut child = jsim()
        .args(["simulate", "--config"])
        .arg(&cfg)
        .args(["--images", "200", "--set", "ace.span_s=3000", "--out"])
        .arg(&out_dir)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start jsim");
    // wait until the run has written its first files, then interrupt it
    let image0 = out_dir.join("img_000.fits");
    let t0 = std::time::Instant::now();
    while !image0.exists() {
        assert!(
            t0.elapsed().as_secs() < 300,
            "the simulation never wrote its first image"
        );
        assert!(
            child.try_wait().expect("poll").is_none(),
            "jsim ended before it could be interrupted"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(kill.success());
    let out = child.wait_with_output().expect("wait");
    assert!(!out.status.success(), "an interrupted run is a failure");
    assert!(
        stderr_of(&out).contains("interrupted"),
        "{}",
        stderr_of(&out)
    );
    assert!(
        !out_dir.exists(),
        "the interrupted run left {:?}",
        std::fs::read_dir(&out_dir).map(|d| d.count())
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `jsim crowded` is a study on top of the one pipeline: `jsim analyze` on the focal-plane exposure it
/// saved, reading only the file and the products beside it (flat, reference catalogue, model PSF,
/// telemetry), gives the same accuracy against magnitude, bin by bin, for each countermeasure.
#[test]
fn jsim_analyze_on_a_saved_crowded_exposure_gives_jsim_crowdeds_bins() {
    let dir = temp("crowded-analyze");
    let cfg = small_toml(&dir);
    let quad = [
        "--set",
        "focal_plane.layout=quad",
        "--set",
        "focal_plane.gap_px=60",
        "--set",
        "scene.bulge.density_per_arcmin2=25",
        "--set",
        "fidelity.images=1",
        // the catalogue's missed stars held, from the product: the study's survey (a shallower one than
        // the default, so that a study that read the default survey's would differ) is the one it saves
        "--set",
        "analysis.crowded_forced_catalogue=true",
    ];
    let study = dir.join("study");
    let out = jsim()
        .args(["crowded", "--config"])
        .arg(&cfg)
        .args(quad)
        .args([
            "--scene",
            "bulge",
            "--aces",
            "realistic",
            "--countermeasures",
            "none,telemetry,plate-affine@catalogue",
            "--refcat-limit-hw",
            "16",
            "--save-images",
            "--out",
        ])
        .arg(&study)
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    let saved = study.join("realistic");
    for f in [
        "fp_000.fits",
        "flat_cal.fits",
        "refcat.csv",
        "psf_model.fits",
        "telemetry_000.fits",
    ] {
        assert!(saved.join(f).exists(), "{f} saved");
    }
    let rows = |path: &Path, cm: &str| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(path).expect("bins");
        text.lines()
            .skip(1)
            // the case may be quoted with a comma inside: the columns after it split plainly
            .map(|l| match l.strip_prefix('"') {
                Some(rest) => {
                    let after = rest.split_once('"').map_or("", |(_, a)| a);
                    let mut c = vec!["case"];
                    c.extend(after.trim_start_matches(',').split(','));
                    c
                }
                None => l.split(',').collect::<Vec<_>>(),
            })
            .filter(|c| c[1] == cm)
            // the columns both write (the undetected stars' shifts that follow are `jsim crowded`'s alone)
            .map(|c| {
                c[2..19]
                    .iter()
                    .map(|v| v.parse::<f64>().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect()
    };
    // the undetected stars' light moves a catalogue-referenced fit as it moves the plain one: the shift is
    // evaluated where the star lies on the image (it was once taken at the fit's place in the catalogue's
    // frame, off the image's by the arrays' assembly: 3 × the plain one's on the bulge at Hw 14–15)
    let undetected = |cm: &str| -> Vec<(f64, f64)> {
        let text = std::fs::read_to_string(study.join("crowded_bins.csv")).expect("bins");
        let head: Vec<&str> = text.lines().next().expect("header").split(',').collect();
        let col = |n: &str| head.iter().position(|c| *c == n).expect(n) - 1;
        let (n_col, u_col) = (col("isolated_n"), col("isolated_undetected_mas"));
        text.lines()
            .skip(1)
            .filter_map(|l| {
                let after = l.strip_prefix('"')?.split_once('"')?.1;
                let c: Vec<&str> = after.trim_start_matches(',').split(',').collect();
                (c[0] == cm).then(|| {
                    let v = |k: usize| c[k].parse::<f64>().unwrap_or(f64::NAN);
                    (v(n_col), v(u_col))
                })
            })
            .collect()
    };
    let (plain, referenced) = (undetected("none"), undetected("plate-affine@catalogue"));
    assert!(!plain.is_empty() && plain.len() == referenced.len());
    for (p, r) in plain.iter().zip(&referenced) {
        if p.0 >= 10.0 && p.1 > 0.0 {
            assert!(
                (r.1 / p.1 - 1.0).abs() < 0.25,
                "undetected shift {} mas (catalogue) against {} (none)",
                r.1,
                p.1
            );
        }
    }
    for cm in ["none", "telemetry", "plate-affine@catalogue"] {
        let an = dir.join(format!("analyze-{}", cm.replace(['@', ':'], "-")));
        let out = jsim()
            .args(["analyze", "--config"])
            .arg(&cfg)
            .args(quad)
            .args(["--crowding", "on", "--countermeasure", cm, "--image"])
            .arg(saved.join("fp_000.fits"))
            .arg("--out")
            .arg(&an)
            .output()
            .expect("run");
        assert!(out.status.success(), "{cm}: {}", stderr_of(&out));
        let (a, b) = (
            rows(&study.join("crowded_bins.csv"), cm),
            rows(&an.join("crowded_bins.csv"), cm),
        );
        assert!(
            !a.is_empty() && a.len() == b.len(),
            "{cm}: {a:?} against {b:?}"
        );
        let used: f64 = a.iter().map(|r| r[7]).sum();
        assert!(used > 20.0, "{cm}: {used} isolated stars scored");
        for (p, q) in a.iter().zip(&b) {
            for (x, y) in p.iter().zip(q) {
                assert!(
                    (x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-6 * x.abs().max(1.0),
                    "{cm}: {p:?} against {q:?}"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The README's quick start, command by command, on the small scene (`small_toml`: a 256² array, 9 stars, 2
/// images — the reduced form of the default scene): each succeeds and writes what the README says.
#[test]
fn the_readmes_quick_start_runs_as_written() {
    let dir = temp("quick-start");
    let cfg = small_toml(&dir);
    let run = |args: &[&str]| {
        let out = jsim()
            .current_dir(&dir)
            .args(args)
            .args(["--config", cfg.to_str().expect("utf-8 path")])
            .output()
            .expect("run");
        assert!(out.status.success(), "{args:?}: {}", stderr_of(&out));
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let said = run(&["simulate", "--out", "out/reference"]);
    assert!(said.contains("wrote 2 images"), "{said}");
    for f in [
        "img_000.fits",
        "truth_000.csv",
        "flat_cal.fits",
        "refcat.csv",
        "psf_model.fits",
        "telemetry_000.fits",
    ] {
        assert!(dir.join("out/reference").join(f).exists(), "{f}");
    }
    let said = run(&[
        "analyze",
        "--image",
        "out/reference/img_000.fits",
        "--out",
        "out/analysis",
    ]);
    assert!(
        said.contains("accuracy") && said.contains("[none]"),
        "{said}"
    );
    assert!(dir.join("out/analysis/vectors.png").exists());
    let said = run(&[
        "analyze",
        "--image",
        "out/reference/img_000.fits",
        "--countermeasure",
        "telemetry",
        "--out",
        "out/analysis_telemetry",
    ]);
    assert!(said.contains("[telemetry]"), "{said}");
    let out = jsim()
        .current_dir(&dir)
        .args([
            "score",
            "--catalogue",
            "out/analysis/catalogue.csv",
            "--truth",
            "out/reference/truth_000.csv",
            "--out",
            "out/score",
        ])
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("9 matched"));
    let said = run(&[
        "experiment",
        "--mags",
        "12.5",
        "--aces",
        "realistic",
        "--countermeasures",
        "none,plate-poly:3,telemetry",
    ]);
    for cm in ["none", "plate-poly:3", "telemetry"] {
        assert!(said.contains(cm), "{cm}: {said}");
    }
    assert!(dir.join("out/experiment/experiment.csv").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every example catalogue shipped in `engine/catalogues/` (pixels and RA/Dec, CSV and FITS) simulates as
/// `jsim simulate --scene FILE` on the small scene, every one of its stars in the truth.
#[test]
fn every_shipped_catalogue_simulates() {
    let dir = temp("catalogues");
    let cfg = small_toml(&dir);
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("catalogues");
    let mut n = 0;
    for e in std::fs::read_dir(&shipped).expect("engine/catalogues") {
        let p = e.expect("entry").path();
        let out_dir = dir.join(p.file_stem().expect("name"));
        let out = jsim()
            .args(["simulate", "--images", "1", "--config"])
            .arg(&cfg)
            .arg("--scene")
            .arg(&p)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .expect("run");
        assert!(out.status.success(), "{}: {}", p.display(), stderr_of(&out));
        let said = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(said.contains("of 16 stars"), "{}: {said}", p.display());
        let truth = std::fs::read_to_string(out_dir.join("truth_000.csv")).expect("truth");
        assert_eq!(
            truth.lines().count(),
            17,
            "{}: 16 stars and a header",
            p.display()
        );
        n += 1;
    }
    assert_eq!(n, 3, "the shipped catalogues");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Each command offers only the options that change what it does: `--help` lists none that do not apply,
/// and one given anyway is refused by name (never accepted and ignored).
#[test]
fn each_command_offers_only_its_own_options() {
    // (command, options it must offer, options it must not)
    let cases: [(&str, &[&str], &[&str]); 7] = [
        (
            "psf",
            &["--config", "--set", "--out"],
            &[
                "--mag",
                "--images",
                "--scene",
                "--ace",
                "--readout",
                "--backend",
                "--seed",
            ],
        ),
        (
            "ace",
            &["--config", "--set", "--seed", "--ace", "--images"],
            &["--mag", "--scene", "--readout", "--backend", "--method"],
        ),
        (
            "analyze",
            &["--config", "--set", "--image", "--countermeasure"],
            &[
                "--mag",
                "--images",
                "--scene",
                "--ace",
                "--readout",
                "--backend",
                "--seed",
            ],
        ),
        (
            "experiment",
            &[
                "--config",
                "--mags",
                "--aces",
                "--readouts",
                "--images",
                "--backend",
            ],
            &["--mag ", "--ace ", "--readout "],
        ),
        (
            "crowded",
            &["--config", "--aces", "--scene", "--readout", "--backend"],
            &["--mag", "--ace ", "--images"],
        ),
        (
            "predict",
            &[
                "--config",
                "--mag",
                "--ace",
                "--readout",
                "--countermeasures",
            ],
            &["--images", "--backend", "--method"],
        ),
        (
            "simulate",
            &[
                "--config",
                "--mag",
                "--scene",
                "--ace",
                "--readout",
                "--images",
                "--backend",
            ],
            &[],
        ),
    ];
    for (cmd, offered, absent) in cases {
        let out = jsim().args([cmd, "--help"]).output().expect("run");
        assert!(out.status.success(), "{cmd} --help");
        let help = String::from_utf8_lossy(&out.stdout).to_string();
        for o in offered {
            assert!(help.contains(o), "jsim {cmd} --help lacks {o}:\n{help}");
        }
        for o in absent {
            assert!(
                !help.contains(o),
                "jsim {cmd} --help offers {o}, which does not apply:\n{help}"
            );
        }
    }
    let dir = temp("own-options");
    for args in [
        vec!["analyze", "--mag", "14", "--image", "x.fits"],
        vec!["psf", "--images", "3"],
        vec!["experiment", "--mag", "14"],
    ] {
        let out = jsim().current_dir(&dir).args(&args).output().expect("run");
        assert!(!out.status.success(), "{args:?} accepted");
        let err = stderr_of(&out);
        assert!(err.contains(args[1]), "{args:?}: {err}");
    }
    assert!(
        std::fs::read_dir(&dir).expect("dir").next().is_none(),
        "a refused command wrote something"
    );
}

/// A negative number is a value, not an unknown flag: the option's own range check answers, naming it and
/// its range, and nothing is written.
#[test]
fn a_negative_number_gets_the_options_range_error() {
    let dir = temp("negative");
    let cases: [(&[&str], &str, &str); 5] = [
        (
            &["crowded", "--reference-error-mas", "-1"],
            "--reference-error-mas",
            "(0, ",
        ),
        (
            &["crowded", "--telemetry-noise-mas", "-2"],
            "--telemetry-noise-mas",
            "[0, ",
        ),
        (&["crowded", "--bin-mag", "-0.5"], "--bin-mag", "0.1 … 2"),
        (
            &["crowded", "--telemetry-latency-s", "-61"],
            "--telemetry-latency-s",
            "[-60, 60]",
        ),
        (&["sequence", "--cell-deg", "-1"], "--cell-deg", "(1e-4, 1]"),
    ];
    for (k, (args, option, range)) in cases.iter().enumerate() {
        let out_dir = dir.join(format!("out{k}"));
        let out = jsim()
            .args(*args)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .expect("run");
        let err = stderr_of(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains(option) && err.contains(range) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
        assert!(!out_dir.exists(), "{args:?} wrote {}", out_dir.display());
    }
}

/// A real Hubble exposure (a cutout of ACS/HRC j8bt06nyq_flt, tests/data/hst_acs_hrc_47tuc): `jsim analyze`
/// reads its SCI chip in electrons, says where each value came from, masks its flagged pixels and writes
/// the chip's catalogue with RA/Dec; a negative --read-noise-e is a named error that writes nothing.
#[test]
fn a_real_hst_exposure_is_analysed_chip_by_chip_with_its_choices_stated() {
    let image = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/hst_acs_hrc_47tuc/j8bt06nyq_cutout_flt.fits");
    let dir = temp("hst");
    let out = jsim()
        .args(["analyze", "--image"])
        .arg(&image)
        .arg("--out")
        .arg(dir.join("an"))
        .output()
        .expect("run");
    let err = stderr_of(&out);
    assert!(out.status.success(), "{err}");
    for said in [
        "[SCI,1]: BUNIT ELECTRONS: 1 e⁻ per data unit",
        "read noise 4.71 e⁻ from READNSEC (the amplifier that read the chip)",
        "DQ: 117 flagged pixel(s) masked (44 saturated)",
        "TAN with SIP distortion",
    ] {
        assert!(err.contains(said), "{said} not in {err}");
    }
    let header =
        std::fs::read_to_string(dir.join("an/SCI1/catalogue.csv")).expect("chip catalogue");
    assert!(
        header
            .lines()
            .next()
            .unwrap_or("")
            .ends_with(",ra_deg,dec_deg")
    );
    let combined = std::fs::read_to_string(dir.join("an/catalogue.csv")).expect("catalogue");
    assert!(
        combined.lines().count() > 200,
        "{} stars",
        combined.lines().count()
    );
    let bad = jsim()
        .args(["analyze", "--read-noise-e", "-1", "--image"])
        .arg(&image)
        .arg("--out")
        .arg(dir.join("bad"))
        .output()
        .expect("run");
    assert!(!bad.status.success());
    assert!(stderr_of(&bad).contains("--read-noise-e -1: must be a finite number ≥ 0"));
    assert!(!dir.join("bad").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `jsim score` scores a catalogue referenced to the reference catalogue in that catalogue's frame (the
/// header's design WCS) when the image's header is not the instrument as built: the truth CSV and the
/// TRUTH extension carry `x_header, y_header`, `--frame auto` takes them for a `…@catalogue` analysis, and
/// the accuracy is then the one `jsim analyze` reports (it scores in that frame in memory). In the image's
/// frame the roll and distortion the header does not know count as error.
#[test]
fn jsim_score_scores_a_catalogue_referenced_analysis_in_the_headers_frame() {
    let dir = temp("score-frame");
    let cfg = small_toml(&dir);
    let deviations = [
        "--set",
        "scene.grid_n=5",
        "--set",
        "scene.grid_spacing_px=45.0",
        "--set",
        "fidelity.images=1",
        "--set",
        "as_built.pointing_offset_arcsec=[2.0, -1.0]",
        "--set",
        "as_built.roll_offset_arcsec=120.0",
        "--set",
        "as_built.distortion_px=0.03",
    ];
    let sim = dir.join("sim");
    let out = jsim()
        .args(["simulate", "--config"])
        .arg(&cfg)
        .args(deviations)
        .args(["--ace", "gaussian", "--out"])
        .arg(&sim)
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    let csv = std::fs::read_to_string(sim.join("truth_000.csv")).expect("truth");
    assert!(
        csv.lines()
            .next()
            .is_some_and(|h| h.ends_with(",x_header,y_header")),
        "{}",
        csv.lines().next().unwrap_or("")
    );
    let an = dir.join("an");
    let out = jsim()
        .args(["analyze", "--config"])
        .arg(&cfg)
        .args(deviations)
        .args(["--countermeasure", "plate-affine@catalogue", "--image"])
        .arg(sim.join("img_000.fits"))
        .arg("--out")
        .arg(&an)
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr_of(&out));
    let json = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).expect("json")).expect("json")
    };
    let analysed = json(&an.join("summary.json"))["report"]["accuracy_mas"]
        .as_f64()
        .expect("accuracy");
    let score = |truth: &str, frame: &str, name: &str| -> (f64, String) {
        let out = jsim()
            .args(["score", "--catalogue"])
            .arg(an.join("catalogue.csv"))
            .arg("--truth")
            .arg(sim.join(truth))
            .args(["--frame", frame, "--out"])
            .arg(dir.join(name))
            .output()
            .expect("run");
        assert!(out.status.success(), "{}", stderr_of(&out));
        let acc = json(&dir.join(name).join("score.json"))["all"]["accuracy_mas"]
            .as_f64()
            .expect("accuracy");
        (acc, String::from_utf8_lossy(&out.stdout).to_string())
    };
    let (auto, said) = score("truth_000.csv", "auto", "auto");
    assert!(said.contains("x_header, y_header"), "{said}");
    let (fits, _) = score("img_000.fits", "auto", "fits");
    let (image, said) = score("truth_000.csv", "image", "image");
    assert!(said.contains("truth's x, y"), "{said}");
    assert_eq!(
        auto, fits,
        "the CSV and the TRUTH extension hold the same frame"
    );
    assert!(
        (auto - analysed).abs() <= 1e-9 * analysed,
        "jsim score {auto} mas, jsim analyze {analysed} mas"
    );
    assert!(
        image > 2.0 * auto,
        "image frame {image}, header frame {auto}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Without deviations the truth has no header frame: asking for it is a named error, and `auto` scores a
/// catalogue-referenced analysis in the image's frame (the same frame).
#[test]
fn the_header_frame_of_a_truth_without_one_is_a_named_error() {
    let dir = temp("score-no-frame");
    let truth = dir.join("truth.csv");
    std::fs::write(&truth, "x,y,mag\n10,10,12\n20,20,12\n").expect("write");
    let cat = dir.join("catalogue.csv");
    std::fs::write(&cat, "x,y\n10.01,10\n20,20.01\n").expect("write");
    let out = jsim()
        .args([
            "score",
            "--plate-scale-mas",
            "472",
            "--frame",
            "header",
            "--catalogue",
        ])
        .arg(&cat)
        .arg("--truth")
        .arg(&truth)
        .arg("--out")
        .arg(dir.join("s"))
        .output()
        .expect("run");
    assert!(!out.status.success());
    let e = stderr_of(&out);
    assert!(
        e.contains("x_header, y_header") && e.contains("truth.csv"),
        "{e}"
    );
    assert!(!dir.join("s").exists(), "nothing written");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--instrument design` is the telescope exactly as designed: the same image as every `[as_built]` deviation set
/// to 0 by hand, and another than the default (as built), whose run names its deviations. Applied before `--set`:
/// `--instrument design --set as_built.wavefront_rms_nm=30` is the design with that one deviation, whatever the
/// order on the command line.
#[test]
fn the_instrument_option_chooses_the_design_or_the_instrument_as_built() {
    let dir = temp("instrument");
    let cfg = small_toml(&dir);
    let run = |name: &str, extra: &[&str]| {
        let out = jsim()
            .args(["simulate", "--config"])
            .arg(&cfg)
            .args(["--ace", "gaussian", "--images", "1"])
            .args(extra)
            .arg("--out")
            .arg(dir.join(name))
            .output()
            .expect("run");
        assert!(out.status.success(), "{name}: {}", stderr_of(&out));
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            stderr_of(&out)
        );
        let img = engine::io::fits::read_image(&dir.join(name).join("img_000.fits")).expect("img");
        (img.data, text)
    };
    let zeros: Vec<String> = [
        "wavefront_rms_nm=0",
        "wavefront_field_rms_nm=0",
        "focus_breathing_nm=0",
        "distortion_px=0",
        "gain_error=0",
        "read_noise_error=0",
        "pointing_offset_arcsec=[0.0,0.0]",
        "roll_offset_arcsec=0",
    ]
    .iter()
    .flat_map(|kv| ["--set".to_string(), format!("as_built.{kv}")])
    .collect();
    let zeros: Vec<&str> = zeros.iter().map(String::as_str).collect();
    let (design, design_text) = run("design", &["--instrument", "design"]);
    let (by_hand, _) = run("by-hand", &zeros);
    let (built, built_text) = run("built", &[]);
    assert_eq!(design, by_hand, "--instrument design = every deviation 0");
    assert_ne!(design, built, "the default is the instrument as built");
    assert!(
        !design_text.contains("the instrument as built"),
        "{design_text}"
    );
    assert!(
        built_text.contains("the instrument as built")
            && built_text.contains("30 nm rms wavefront"),
        "{built_text}"
    );
    let (_, one) = run(
        "one",
        &[
            "--set",
            "as_built.wavefront_rms_nm=30",
            "--instrument",
            "design",
        ],
    );
    assert!(
        one.contains("30 nm rms wavefront") && !one.contains("gain error"),
        "{one}"
    );
    let out = jsim()
        .args(["simulate", "--instrument", "perfect", "--out"])
        .arg(dir.join("bad"))
        .output()
        .expect("run");
    assert!(!out.status.success());
    assert!(
        stderr_of(&out).contains("--instrument"),
        "{}",
        stderr_of(&out)
    );
    assert!(!dir.join("bad").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
