//! Images jsim did not make, and bad input to the analysis: an outside image (written here with a
//! Gaussian PSF, not jsim's optics) is analysed with no truth — no accuracy is reported, never 0 — and
//! scored apart by `jsim score`; crowding is chosen from the measured density; malformed header cards,
//! NaN pixels and ambiguous catalogues are named.

use engine::io::fits::{self, Card, Hdu, Pixels};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, Poisson};
use std::path::{Path, PathBuf};
use std::process::Command;

fn jsim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim"))
}

fn temp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("jsim-outside-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp");
    d
}

const GAIN: f64 = 3.0;
const READ_NOISE_E: f64 = 21.2;
const BIAS_ADU: f64 = 1000.0;
const SIGMA_PX: f64 = 0.75;
const SKY_E: f64 = 100.0;

/// The flux fraction of a unit Gaussian star at (x, y) in pixel (px, py), by 10 × 10 sub-samples.
fn gaussian_pixel(px: usize, py: usize, x: f64, y: f64) -> f64 {
    let n = 10;
    let mut s = 0.0;
    for j in 0..n {
        for i in 0..n {
            let u = px as f64 - 0.5 + (i as f64 + 0.5) / n as f64 - x;
            let v = py as f64 - 0.5 + (j as f64 + 0.5) / n as f64 - y;
            s += (-(u * u + v * v) / (2.0 * SIGMA_PX * SIGMA_PX)).exp();
        }
    }
    s / (n * n) as f64 / (2.0 * std::f64::consts::PI * SIGMA_PX * SIGMA_PX)
}

/// Write an outside image of `stars` (x, y, electrons) with Poisson and read noise, headers as another
/// tool would write them (`extra` cards replace or add), and the truth CSV (x, y, mag).
fn write_outside(
    dir: &Path,
    n: usize,
    stars: &[(f64, f64, f64)],
    extra: Vec<Card>,
) -> (PathBuf, PathBuf) {
    let mut expected = vec![SKY_E; n * n];
    for &(x, y, f) in stars {
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        for py in (cy - 5).max(0)..=(cy + 5).min(n as i64 - 1) {
            for px in (cx - 5).max(0)..=(cx + 5).min(n as i64 - 1) {
                expected[py as usize * n + px as usize] +=
                    f * gaussian_pixel(px as usize, py as usize, x, y);
            }
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let read = Normal::new(0.0, READ_NOISE_E).expect("normal");
    let adu: Vec<f32> = expected
        .iter()
        .map(|&m| {
            let e = Poisson::new(m).expect("poisson").sample(&mut rng) + read.sample(&mut rng);
            (e / GAIN + BIAS_ADU).round() as f32
        })
        .collect();
    let mut cards = vec![
        Card::f("GAIN", GAIN, "[e-/ADU]"),
        Card::f("RDNOISE", READ_NOISE_E, "[e-]"),
        Card::f("BIASADU", BIAS_ADU, "[ADU]"),
        Card::f("EXPTIME", 12.5, "[s]"),
        Card::f("SATURATE", 51000.0, "[ADU]"),
        Card::f("PLTSCALE", 471.3, "[mas/pix]"),
    ];
    for c in extra {
        cards.retain(|k| k.key != c.key);
        cards.push(c);
    }
    let image = dir.join("image.fits");
    fits::write(
        &image,
        &[Hdu::Image {
            name: "",
            nx: n,
            ny: n,
            pixels: Pixels::F32(&adu),
            cards,
        }],
    )
    .expect("write image");
    let truth = dir.join("truth.csv");
    let mut text = String::from("x,y,mag\n");
    for &(x, y, f) in stars {
        let mag = -2.5 * (f / (5.8e8 * 12.5)).log10();
        text.push_str(&format!("{x},{y},{mag}\n"));
    }
    std::fs::write(&truth, text).expect("truth");
    (image, truth)
}

/// Stars on a jittered grid (isolated, `step` px apart) with fluxes of Hw 12–14.
fn grid_stars(n: usize, step: usize) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::new();
    let mut k = 0usize;
    for gy in (step / 2..n - step / 2).step_by(step) {
        for gx in (step / 2..n - step / 2).step_by(step) {
            let fx = ((k * 37) % 100) as f64 / 100.0 - 0.5;
            let fy = ((k * 61) % 100) as f64 / 100.0 - 0.5;
            let mag = 12.0 + 2.0 * ((k * 17) % 10) as f64 / 10.0;
            out.push((
                gx as f64 + fx,
                gy as f64 + fy,
                5.8e8 * 12.5 * 10f64.powf(-0.4 * mag),
            ));
            k += 1;
        }
    }
    out
}

/// A simulation of an `n`-pixel array (128-px channels) with coarse optics: for the products' tests.
fn coarse_config(n: usize) -> engine::Config {
    let mut cfg = engine::Config::default();
    cfg.instrument.detector_px = n;
    cfg.instrument.photosensitive_px = n - 16;
    cfg.readout.channels = n / 128;
    cfg.readout.channel_width_px = 128;
    cfg.optics.pupil_samples = 64;
    cfg.optics.psf_radius_px = 8;
    cfg.band.wavelength_step_um = 0.1;
    cfg.fidelity.backend = engine::config::Backend::Cpu;
    // the telescope as designed: these tests hold the products against the truth of the instrument that made them
    cfg.as_built = engine::config::AsBuilt::design();
    cfg
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("json")).expect("parse")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn an_outside_image_is_analysed_without_truth_and_scored_apart() {
    let dir = temp("score");
    let stars = grid_stars(320, 20);
    let (image, truth) = write_outside(&dir, 320, &stars, vec![]);
    let an = dir.join("an");
    let out = jsim()
        .args(["analyze", "--image"])
        .arg(&image)
        .arg("--out")
        .arg(&an)
        .output()
        .expect("run");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("no accuracy"), "{stdout}");
    let summary = json(&an.join("summary.json"));
    assert!(
        summary["report"]["accuracy_mas"].is_null(),
        "no truth: the accuracy is absent, not 0: {}",
        summary["report"]
    );
    assert_eq!(
        summary["report"]["crowded"], false,
        "a sparse grid is not crowded"
    );

    let sc = dir.join("score");
    let out = jsim()
        .args(["score", "--catalogue"])
        .arg(an.join("catalogue.csv"))
        .arg("--truth")
        .arg(&truth)
        .arg("--out")
        .arg(&sc)
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = json(&sc.join("score.json"));
    let all = &s["all"];
    assert_eq!(all["n_true"], stars.len());
    assert_eq!(all["n_matched"], stars.len(), "{all}");
    assert_eq!(s["false_detections"], 0);
    // the scored accuracy against the analysis' own Cramér–Rao bounds (an independent analytic figure for
    // this image: the Fisher information of its fits), per axis: within [0.8, 1.5] × the median bound
    let (h, rows) = engine::io::csv::read(&an.join("catalogue.csv")).expect("catalogue");
    let cx = engine::io::csv::column_f64(&an, &h, &rows, "crlb_x_mas").expect("crlb");
    let cy = engine::io::csv::column_f64(&an, &h, &rows, "crlb_y_mas").expect("crlb");
    let bound = median(
        cx.iter()
            .zip(&cy)
            .map(|(a, b)| ((a * a + b * b) / 2.0).sqrt())
            .collect(),
    );
    let acc = all["accuracy_mas"].as_f64().expect("an accuracy");
    assert!(
        acc > 0.8 * bound && acc < 1.5 * bound,
        "accuracy {acc:.2} mas against the median bound {bound:.2} mas"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_dense_outside_image_is_analysed_as_a_crowded_field() {
    let dir = temp("dense");
    let n = 200;
    // 1 star per 100 px² (the bulge field has ≈ 1 per 155): most stars have a neighbour within the link radius
    let mut k = 0u64;
    let stars: Vec<(f64, f64, f64)> = (0..400)
        .map(|_| {
            k = k
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (k >> 11) as f64 / (1u64 << 53) as f64;
            k = k
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = (k >> 11) as f64 / (1u64 << 53) as f64;
            (
                3.0 + u * (n as f64 - 6.0),
                3.0 + v * (n as f64 - 6.0),
                5.8e8 * 12.5 * 10f64.powf(-0.4 * (13.0 + 3.0 * u * v)),
            )
        })
        .collect();
    let (image, truth) = write_outside(&dir, n, &stars, vec![]);
    let an = dir.join("an");
    let out = jsim()
        .args(["analyze", "--image"])
        .arg(&image)
        .arg("--out")
        .arg(&an)
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = json(&an.join("summary.json"));
    assert_eq!(summary["report"]["crowded"], true, "{}", summary["report"]);
    let sc = dir.join("score");
    let out = jsim()
        .args(["score", "--catalogue"])
        .arg(an.join("catalogue.csv"))
        .arg("--truth")
        .arg(&truth)
        .arg("--out")
        .arg(&sc)
        .output()
        .expect("run");
    assert!(out.status.success());
    let s = json(&sc.join("score.json"));
    // the crowded analysis finds most of the Hw 13–14 stars in a field where every star has neighbours
    let bright = s["bins"]
        .as_array()
        .expect("bins")
        .iter()
        .find(|b| b["mag_lo"] == 13.0)
        .expect("the Hw 13–14 bin")
        .clone();
    assert!(
        bright["completeness"].as_f64().expect("completeness") > 0.85,
        "{bright}"
    );
    // forced isolated on the same image: the isolated analysis is used (and says so)
    let iso = dir.join("iso");
    let out = jsim()
        .args(["analyze", "--crowding", "off", "--image"])
        .arg(&image)
        .arg("--out")
        .arg(&iso)
        .output()
        .expect("run");
    assert!(out.status.success());
    assert_eq!(json(&iso.join("summary.json"))["report"]["crowded"], false);
    // in crowded mode a countermeasure that refits single stars, or whose reference is missing (no
    // truth for @oracle, no refcat.csv for @catalogue), is refused by name
    for cm in ["yzones", "plate-poly:3@oracle", "plate-affine@catalogue"] {
        let bad = dir.join(format!("bad-{}", cm.replace([':', '@'], "_")));
        let out = jsim()
            .args(["analyze", "--countermeasure", cm, "--image"])
            .arg(&image)
            .arg("--out")
            .arg(&bad)
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{cm}: {err}");
        assert!(
            err.contains(cm.split('@').next().unwrap_or(cm)),
            "{cm}: {err}"
        );
        assert!(!bad.exists(), "{cm}: the output directory was created");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_header_cards_are_errors_naming_the_card() {
    let dir = temp("cards");
    let stars = grid_stars(100, 25);
    for (card, needle) in [
        (Card::s("RDNOISE", "abc", "not a number"), "RDNOISE = 'abc'"),
        (Card::s("GAIN", "three", "not a number"), "GAIN = 'three'"),
        (Card::f("EXPTIME", 0.0, "no exposure"), "EXPTIME"),
        (Card::s("SAMPLING", "XYZ", "unknown"), "SAMPLING = 'XYZ'"),
    ] {
        let (image, _) = write_outside(&dir, 100, &stars, vec![card]);
        let an = dir.join("an");
        let out = jsim()
            .args(["analyze", "--image"])
            .arg(&image)
            .arg("--out")
            .arg(&an)
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{needle}: {err}");
        assert!(err.contains(needle), "{needle}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!an.exists(), "{needle}: the output directory was created");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn nan_pixels_are_masked_and_counted_with_or_without_a_dq_plane() {
    use engine::io::analysis_input::{AnalysisInput, ImageParts};
    let n = 16;
    let mut data = vec![100.0f32; n * n];
    data[5 * n + 7] = f32::NAN;
    data[9 * n + 2] = f32::INFINITY;
    let facts = fits::ImageFacts::from_keys(
        |k| match k {
            "GAIN" => Some(3.0),
            "RDNOISE" => Some(20.0),
            "BIASADU" => Some(0.0),
            "EXPTIME" => Some(12.5),
            _ => None,
        },
        |_| None,
    )
    .expect("facts");
    let dq = vec![0u8; n * n];
    for dq in [None, Some(dq.as_slice())] {
        let input = AnalysisInput::from_parts(
            ImageParts {
                nx: n,
                ny: n,
                data: &data,
                dq,
                facts: facts.clone(),
                plate_scale_header_mas: Some(471.3),
            },
            None,
            None,
            None,
            &engine::Config::default(),
        )
        .expect("input");
        assert!(input.img.bad[5 * n + 7] && input.img.bad[9 * n + 2]);
        assert_eq!(input.img.bad.iter().filter(|b| **b).count(), 2);
        assert!(
            input.assumptions.iter().any(|a| a.contains("2 non-finite")),
            "{:?}",
            input.assumptions
        );
    }
}

#[test]
fn a_catalogue_with_both_sky_and_pixel_columns_is_refused() {
    let dir = temp("cat");
    let p = dir.join("both.csv");
    std::fs::write(&p, "ra,dec,x,y,hw\n266.4,-29.0,10,10,12.5\n").expect("write");
    let e = engine::scene::catalogue::read(&p, 12.5, 2.0, 1968.0).expect_err("ambiguous");
    let msg = e.to_string();
    assert!(
        msg.contains("ra, dec") && msg.contains("x, y") && msg.contains("both"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A column jsim does not read is an error naming it and what is accepted — `mag` is not the Hw magnitude, and
/// would otherwise leave every star at the default Hw 12.5; identifiers are read past.
#[test]
fn a_catalogue_column_jsim_does_not_read_is_refused_by_name() {
    let dir = temp("cat-mag");
    let p = dir.join("mag.csv");
    std::fs::write(&p, "x,y,mag\n10,10,14.0\n").expect("write");
    let e = engine::scene::catalogue::read(&p, 12.5, 2.0, 1968.0).expect_err("mag");
    let msg = e.to_string();
    assert!(msg.contains("`mag`") && msg.contains("mag_hw"), "{msg}");
    let ok = dir.join("ok.csv");
    std::fs::write(&ok, "id,x,y,hw\n7,10,10,14.0\n").expect("write");
    assert!(engine::scene::catalogue::read(&ok, 12.5, 2.0, 1968.0).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_score_options_are_named_and_write_nothing() {
    let dir = temp("badscore");
    let cat = dir.join("catalogue.csv");
    std::fs::write(&cat, "x,y\n1,1\n").expect("write");
    let truth = dir.join("truth.csv");
    std::fs::write(&truth, "x,y,mag\n1,1,12\n").expect("write");
    let nomag = dir.join("nomag.csv");
    std::fs::write(&nomag, "x,y\n1,1\n").expect("write");
    let out_dir = dir.join("out");
    for (args, needle) in [
        (vec!["--match-radius-px", "0"], "--match-radius-px"),
        (vec!["--bin-mag=-1"], "--bin-mag"),
        (vec!["--plate-scale-mas", "nan"], "--plate-scale-mas"),
        (vec![], "--plate-scale-mas"),
    ] {
        let mut c = jsim();
        c.args(["score", "--catalogue"])
            .arg(&cat)
            .arg("--truth")
            .arg(&truth)
            .arg("--out")
            .arg(&out_dir)
            .args(&args);
        if !args.contains(&"--plate-scale-mas") && !args.is_empty() {
            c.args(["--plate-scale-mas", "471"]);
        }
        let out = c.output().expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!out_dir.exists());
    }
    let out = jsim()
        .args(["score", "--plate-scale-mas", "471", "--catalogue"])
        .arg(&cat)
        .arg("--truth")
        .arg(&nomag)
        .arg("--out")
        .arg(&out_dir)
        .output()
        .expect("run");
    assert!(String::from_utf8_lossy(&out.stderr).contains("magnitude"));
    assert!(!out_dir.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The reference catalogue product has the survey's statistics: per-axis errors of σ(Hw) (within 3 × the
/// statistical error of a standard deviation), the completeness (within 3 binomial σ), nothing beyond the
/// limit; written and read back unchanged; `jsim simulate` writes it and refuses a bad survey knob by name.
#[test]
fn the_reference_catalogue_has_the_survey_errors_completeness_and_limit() {
    use engine::io::instrument::{self, SurveyModel};
    let mut cfg = coarse_config(512);
    cfg.scene.grid_n = 30;
    cfg.scene.grid_spacing_px = 16.0;
    cfg.scene.mag_hw = 15.0;
    let sim = engine::simulate::Simulator::new(&cfg).expect("simulator");
    let survey = SurveyModel::default();
    let refs = instrument::reference_catalogue(&sim, &survey, 0);
    let n = sim.stars.iter().filter(|s| s.in_truth).count();
    let scale = cfg.instrument.plate_scale_mas();
    let f = refs.len() as f64 / n as f64;
    let sf = (survey.completeness * (1.0 - survey.completeness) / n as f64).sqrt();
    assert!(
        (f - survey.completeness).abs() < 3.0 * sf + 1e-9,
        "completeness {f}"
    );
    let by_id: std::collections::HashMap<usize, (f64, f64)> =
        sim.stars.iter().map(|s| (s.id, (s.x_px, s.y_px))).collect();
    let (dx, dy): (Vec<f64>, Vec<f64>) = refs
        .iter()
        .map(|r| {
            let t = by_id[&r.id];
            ((r.x_px - t.0) * scale, (r.y_px - t.1) * scale)
        })
        .unzip();
    let sigma = survey.sigma_mas(15.0);
    assert!((sigma - 2.0 * 10f64.powf(0.2)).abs() < 1e-12);
    for d in [&dx, &dy] {
        let m = d.iter().sum::<f64>() / d.len() as f64;
        let s = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (d.len() - 1) as f64).sqrt();
        let tol = 3.0 * sigma / (2.0 * (d.len() as f64 - 1.0)).sqrt();
        assert!((s - sigma).abs() < tol, "σ {s} against {sigma} ± {tol}");
    }
    assert!(
        refs.iter()
            .all(|r| r.ra_deg.is_finite() && r.dec_deg.is_finite())
    );
    // beyond the limit: none
    let faint = SurveyModel {
        limit_hw: 14.9,
        ..survey
    };
    assert!(instrument::reference_catalogue(&sim, &faint, 0).is_empty());
    // written and read back
    let dir = temp("refcat");
    let p = instrument::write_reference_catalogue(&dir, &sim, &survey).expect("write");
    let back = instrument::read_reference_catalogue(&p, 0).expect("read");
    assert_eq!(back.len(), refs.len());
    for (a, b) in back.iter().zip(&refs) {
        assert!((a.x_px - b.x_px).abs() < 1e-9 && (a.sigma_mas - b.sigma_mas).abs() < 1e-9);
    }
    // the CLI: a bad survey knob is named, nothing written
    let out_dir = dir.join("sim");
    let out = jsim()
        .args(["simulate", "--refcat-completeness", "1.5", "--out"])
        .arg(&out_dir)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("--refcat-completeness"), "{err}");
    assert!(!out_dir.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The design model PSF product: written and read back as the same ePSF table (to float precision), unit
/// normalised (a star's pixels sum to 1: the table's nodes sum to oversampling²), peaked at its origin.
#[test]
fn the_model_psf_product_round_trips_and_is_normalised() {
    use engine::io::instrument;
    let mut cfg = coarse_config(256);
    cfg.scene.grid_n = 2;
    let sim = engine::simulate::Simulator::new(&cfg).expect("simulator");
    let model = instrument::model_psf(&sim).expect("model");
    let dir = temp("model-psf");
    let p = instrument::write_model_psf(&dir, &sim).expect("write");
    let back = instrument::read_model_psf(&p, None).expect("read");
    assert_eq!(
        (back.oversampling, back.half_nodes),
        (model.oversampling, model.half_nodes)
    );
    for (a, b) in back.data.iter().zip(&model.data) {
        assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-6), "{a} vs {b}");
    }
    let sum: f64 = model.data.iter().sum();
    let os2 = (model.oversampling * model.oversampling) as f64;
    assert!((sum / os2 - 1.0).abs() < 1e-6, "sum {sum}");
    let n = model.n();
    let peak = model
        .data
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
        .expect("peak");
    let (px, py) = (peak % n, peak / n);
    let c = model.half_nodes;
    assert!(
        px.abs_diff(c) <= 1 && py.abs_diff(c) <= 1,
        "peak at ({px}, {py}), origin {c}"
    );
    // a table that is not square is refused by name
    let bad = dir.join("bad.fits");
    engine::io::fits::write(
        &bad,
        &[engine::io::fits::Hdu::Image {
            name: "",
            nx: 5,
            ny: 7,
            pixels: engine::io::fits::Pixels::F64(&[0.0; 35]),
            cards: vec![engine::io::fits::Card::i("OVERSAMP", 4, "")],
        }],
    )
    .expect("write bad");
    let e = instrument::read_model_psf(&bad, None).expect_err("not square");
    assert!(e.to_string().contains("square"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_linearity_correction_of_the_header_is_applied_and_a_bad_one_named() {
    // NLCORR (the pipeline's β̂) turns a measured 98 000 e⁻ (32 666.67 ADU at 3 e⁻/ADU) back into the
    // 100 000 e⁻ that bent to it under N − 2e-7·N²; absent, the detector is linear; out of range, named
    use engine::io::analysis_input::{AnalysisInput, ImageParts};
    let keys = |nl: Option<f64>| {
        fits::ImageFacts::from_keys(
            |k| match k {
                "GAIN" => Some(3.0),
                "RDNOISE" => Some(20.0),
                "BIASADU" => Some(0.0),
                "EXPTIME" => Some(12.5),
                "NLCORR" => nl,
                _ => None,
            },
            |_| None,
        )
    };
    let n = 8;
    let data = vec![(98_000.0 / 3.0) as f32; n * n];
    for (nl, expect) in [(Some(2e-7), 100_000.0), (None, 98_000.0)] {
        let facts = keys(nl).expect("facts");
        let input = AnalysisInput::from_parts(
            ImageParts {
                nx: n,
                ny: n,
                data: &data,
                dq: None,
                facts,
                plate_scale_header_mas: Some(472.1),
            },
            None,
            None,
            None,
            &engine::Config::default(),
        )
        .expect("input");
        let e = input.img.e[3 * n + 3];
        assert!((e - expect).abs() < 0.1, "{nl:?}: {e} vs {expect}");
    }
    let e = keys(Some(-1.0)).expect_err("negative");
    assert!(e.contains("NLCORR"), "{e}");
}
