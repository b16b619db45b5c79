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
    // sample-and-hold: every pixel shares the exposure window [t_overhead, t_overhead + T], so a star's image
    // is its pixel kernel averaged over the jitter samples of that one window. Computed here directly —
    // each sample weighted by its overlap with the window, no readout timing, no integration method —
    // and compared with the simulator's image of an isolated star.
    let mut sh = r.clone();
    sh.readout.order = engine::config::ReadoutOrder::SampleHold;
    let sim = Simulator::new(&sh).expect("sim");
    let e = sim.exposure(0).expect("exposure");
    let jobs = sim.jobs().expect("jobs");
    let track = sim.track(0).expect("track");
    let (a, b) = (
        sh.readout.t_overhead_s,
        sh.readout.t_overhead_s + sh.detector.exposure_s,
    );
    let j = &jobs[27];
    let (cx, cy) = (j.star.x_px.round() as i64, j.star.y_px.round() as i64);
    let mut peak: f64 = 0.0;
    let mut worst: f64 = 0.0;
    for y in cy - 5..=cy + 5 {
        for x in cx - 5..=cx + 5 {
            let mut v = 0.0;
            for (k, (dx, dy)) in track.dx_px.iter().zip(&track.dy_px).enumerate() {
                let tc = track.t0_s + k as f64 * track.dt_s;
                let overlap =
                    (b.min(tc + 0.5 * track.dt_s) - a.max(tc - 0.5 * track.dt_s)).max(0.0);
                if overlap > 0.0 {
                    v += overlap
                        * j.kernel
                            .eval(x as f64 - j.star.x_px - dx, y as f64 - j.star.y_px - dy);
                }
            }
            v *= j.star.rate_e_per_s;
            let got = e.star_e[y as usize * n + x as usize];
            peak = peak.max(v);
            worst = worst.max((got - v).abs());
        }
    }
    assert!(
        worst <= 1e-9 * peak,
        "sample-and-hold image vs the direct window integral: {worst} e⁻ of a {peak}-e⁻ peak"
    );
}
