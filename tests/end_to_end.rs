//! End to end: config → simulate → FITS on disk → read back → analyse, and reproducibility.

mod common;

use common::{small_config, temp_dir};
use engine::analysis::AnalysisImage;
use engine::analysis::pipeline::{self as astrometry, Options};
use engine::config::AceCase;
use engine::io::{exposure, fits};
use engine::simulate::Simulator;

#[test]
fn simulate_write_read_analyse_round_trip() {
    let mut cfg = small_config();
    cfg.ace.case = AceCase::Gaussian;
    let sim = Simulator::new(&cfg).expect("simulator");
    let exp = sim.exposure(0).expect("exposure");
    let dir = temp_dir("e2e");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("write");
    // the FITS file holds what was simulated, with its provenance
    let back = fits::read_image(&files.image).expect("read");
    assert_eq!((back.nx, back.ny), (512, 512));
    assert!(back.data.iter().zip(&exp.image.adu).all(|(a, b)| a == b));
    assert_eq!(back.gain_e_per_adu, 3.0);
    assert_eq!(
        fits::read_f64_key(&files.image, "SEED").expect("SEED") as u64,
        cfg.seed
    );
    assert_eq!(
        fits::read_string_key(&files.image, "READOUT").expect("READOUT"),
        "rolling"
    );
    assert_eq!(
        fits::read_string_key(&files.image, "CONFHASH").expect("hash"),
        cfg.hash_hex()
    );
    let conf = fits::read_text(&files.image, "CONFIG").expect("CONFIG");
    assert_eq!(
        engine::config::Config::from_toml_str(&conf).expect("parses"),
        cfg
    );
    let truth_csv = exposure::read_truth(&files.truth_csv).expect("truth csv");
    let truth_fits = exposure::read_truth(&files.image).expect("truth fits");
    assert_eq!(truth_csv.len(), 64);
    assert_eq!(truth_csv, truth_fits);
    // the analysis of the file equals the analysis in memory
    let (from_file, assumed) =
        exposure::read_analysis_image(&files.image, cfg.instrument.plate_scale_mas())
            .expect("image");
    assert!(
        assumed.is_empty(),
        "a jsim image says everything: {assumed:?}"
    );
    let in_memory = AnalysisImage::from_detector(&cfg, &exp.image);
    let o = Options::new(&cfg.analysis);
    let a = astrometry::analyze(&from_file, Some(&truth_csv), &o).expect("analysis");
    let b = astrometry::analyze(&in_memory, Some(&exp.truth), &o).expect("analysis");
    assert_eq!(a.report, b.report);
    assert_eq!(a.report.n_used, 64);
    // a 12.5-mag Gaussian-ACE image: a few mas, near the bound
    assert!(
        a.report.accuracy_mas > 2.0 && a.report.accuracy_mas < 6.0,
        "{:?}",
        a.report
    );
    assert!(a.report.accuracy_over_crlb < 1.5, "{:?}", a.report);
    // nothing temporary left behind
    let names: Vec<String> = std::fs::read_dir(&dir)
        .expect("dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp")), "{names:?}");
}

#[test]
fn same_seed_same_image_and_different_seed_differs() {
    let cfg = small_config();
    let a = Simulator::new(&cfg).expect("sim").exposure(1).expect("exp");
    let b = Simulator::new(&cfg).expect("sim").exposure(1).expect("exp");
    assert_eq!(a.image, b.image);
    assert_eq!(a.truth, b.truth);
    let mut other = cfg.clone();
    other.seed += 1;
    let c = Simulator::new(&other)
        .expect("sim")
        .exposure(1)
        .expect("exp");
    assert_ne!(a.image.adu, c.image.adu);
}

#[test]
fn gaussian_and_realistic_close_ups_differ_and_sample_hold_equals_common_window() {
    let mut g = small_config();
    g.ace.case = AceCase::Gaussian;
    g.detector.shot_noise = false;
    g.detector.read_noise = false;
    let r = {
        let mut r = g.clone();
        r.ace.case = AceCase::Realistic;
        r
    };
    let eg = Simulator::new(&g).expect("sim").exposure(0).expect("exp");
    let er = Simulator::new(&r).expect("sim").exposure(0).expect("exp");
    // the same star, two ACE models: different images, same flux within the modelled fraction
    let t = &eg.truth[27];
    let (cx, cy) = (t.x_px.round() as usize, t.y_px.round() as usize);
    let n = eg.image.n;
    let sum = |img: &[f64]| -> f64 {
        let mut s = 0.0;
        for y in cy - 6..=cy + 6 {
            for x in cx - 6..=cx + 6 {
                s += img[y * n + x];
            }
        }
        s
    };
    let diff: f64 = (cy - 3..=cy + 3)
        .flat_map(|y| (cx - 3..=cx + 3).map(move |x| (y, x)))
        .map(|(y, x)| (eg.star_e[y * n + x] - er.star_e[y * n + x]).abs())
        .sum();
    assert!(
        diff > 0.05 * sum(&eg.star_e),
        "close-ups should differ visibly: {diff}"
    );
    assert!((sum(&eg.star_e) / sum(&er.star_e) - 1.0).abs() < 0.05);
    // sample-and-hold: every pixel shares the exposure window, so the image equals the integration of the
    // common window for every star (the fast method's shared part alone)
    let mut sh = r.clone();
    sh.readout.order = engine::config::ReadoutOrder::SampleHold;
    let sim = Simulator::new(&sh).expect("sim");
    let jobs = sim.jobs().expect("jobs");
    let track = sim.track(0).expect("track");
    let window = track.window(
        sim.timing.t_overhead_s,
        sim.timing.t_overhead_s + sim.timing.exposure_s,
    );
    for j in jobs.iter().take(5) {
        let b = engine::integrate::cpu::stamp_bounds(
            j.star.x_px,
            j.star.y_px,
            Some(&track),
            sh.fidelity.stamp_radius_px,
            512,
        )
        .expect("on");
        let hist = engine::integrate::cpu::Histogram::deposit(
            &j.star,
            &track,
            &window,
            (b.0, b.1),
            j.kernel.nodes_per_px,
        )
        .expect("hist");
        let runs = hist.row_runs();
        let stamp = engine::integrate::cpu::fast_stamp(&j.star, &j.kernel, &track, &sim.timing, b);
        let g = j.kernel.nodes_per_px as i64;
        for iy in 0..b.3 {
            for ix in 0..b.2 {
                let common = hist.convolve_at(&j.kernel, &runs, ix as i64 * g, iy as i64 * g)
                    * j.star.rate_e_per_s
                    * track.dt_s;
                let v = stamp.data[iy * b.2 + ix];
                assert!(
                    (v - common).abs() <= 1e-9 * v.abs().max(1.0),
                    "pixel ({ix},{iy}): {v} vs {common}"
                );
            }
        }
    }
}
