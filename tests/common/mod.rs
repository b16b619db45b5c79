//! Shared helpers of the workspace tests: a reduced but physical configuration that runs in seconds in
//! the dev profile.
#![allow(dead_code, unused_imports)] // each test crate uses a different subset

pub use engine::testkit::{small_config, temp_dir};

/// An image (electrons) of stars drawn from a pixel-integrated circular Gaussian of σ px, on a flat sky,
/// with Poisson and read noise when `seed` is given. Returns the analysis image and the truth.
pub fn gaussian_image(
    n: usize,
    stars: &[(f64, f64, f64)],
    sky: f64,
    sigma_px: f64,
    seed: Option<u64>,
) -> (
    engine::analysis::AnalysisImage,
    Vec<engine::simulate::TruthRow>,
) {
    use rand_distr::{Distribution, Normal, Poisson};
    let s2 = 2.0 * sigma_px * sigma_px;
    let pix = |d: f64| -> f64 {
        (0..32)
            .map(|k| (-(d + (k as f64 + 0.5) / 32.0 - 0.5).powi(2) / s2).exp())
            .sum::<f64>()
            / 32.0
    };
    let norm = 1.0 / (std::f64::consts::PI * s2);
    let mut e = vec![sky; n * n];
    for &(x, y, f) in stars {
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        for py in (cy - 10).max(0)..(cy + 11).min(n as i64) {
            let wy = pix(py as f64 - y);
            for px in (cx - 10).max(0)..(cx + 11).min(n as i64) {
                e[py as usize * n + px as usize] += f * norm * wy * pix(px as f64 - x);
            }
        }
    }
    if let Some(seed) = seed {
        let mut r = engine::rng::stream(seed, engine::rng::Stream::Test, 7);
        let rn = Normal::new(0.0, 15.0).expect("normal");
        for v in e.iter_mut() {
            let p: f64 = Poisson::new(v.max(1e-9))
                .map(|d| d.sample(&mut r))
                .unwrap_or(*v);
            *v = p + rn.sample(&mut r);
        }
    }
    let truth = stars
        .iter()
        .enumerate()
        .map(|(k, &(x, y, f))| engine::simulate::TruthRow {
            id: k,
            x_px: x,
            y_px: y,
            mag_hw: 0.0,
            j_minus_h: 0.0,
            flux_e: f,
            modelled_fraction: 1.0,
            t_start_s: 0.0,
            exptime_s: 1.0,
            jitter_dx_px: 0.0,
            jitter_dy_px: 0.0,
        })
        .collect();
    let img = engine::analysis::AnalysisImage {
        nx: n,
        ny: n,
        e,
        bad: vec![false; n * n],
        var_floor_e2: 225.0,
        var_floor_px_e2: None,
        flat_sigma: 0.0,
        plate_scale_mas: 472.0,
    };
    (img, truth)
}

/// A jittered grid of stars: (x, y, flux).
pub fn grid_stars(n_side: usize, spacing: f64, flux: f64, seed: u64) -> Vec<(f64, f64, f64)> {
    use rand::RngExt;
    let mut r = engine::rng::stream(seed, engine::rng::Stream::Test, 11);
    let mut v = Vec::new();
    for j in 0..n_side {
        for i in 0..n_side {
            v.push((
                20.0 + i as f64 * spacing + r.random::<f64>(),
                20.0 + j as f64 * spacing + r.random::<f64>(),
                flux,
            ));
        }
    }
    v
}

/// Every exposure of `sim` through the pipeline under countermeasure `cm`
/// (`engine::studies::experiment::analyse_exposure`): the per-axis accuracy pooled over all images' used
/// stars divided by the median of the images' bounds, and the mean of the per-image accuracies (mas).
pub fn pooled_accuracy_over_bound(
    sim: &engine::simulate::Simulator,
    cm: engine::analysis::countermeasures::Countermeasure,
) -> (f64, f64) {
    let plan = engine::analysis::countermeasures::Plan::new(vec![cm]).expect("plan");
    let (mut sq, mut n, mut bound, mut acc) = (0.0, 0.0, Vec::new(), Vec::new());
    for i in 0..sim.cfg.fidelity.images {
        let r = engine::studies::experiment::analyse_exposure(sim, i, &plan).expect("analysis");
        let rep = &r
            .measured
            .first()
            .expect("the countermeasure applies")
            .report;
        sq += (rep.accuracy_x_mas.powi(2) + rep.accuracy_y_mas.powi(2)) * rep.n_used as f64;
        n += 2.0 * rep.n_used as f64;
        bound.push(rep.crlb_median_mas);
        acc.push(rep.accuracy_mas);
    }
    (
        (sq / n).sqrt() / engine::numerics::stats::median(&bound),
        acc.iter().sum::<f64>() / acc.len() as f64,
    )
}

/// The analysis of `img` (no truth enters), then scored against `truth`.
pub fn analyze_scored(
    img: &engine::analysis::AnalysisImage,
    truth: &[engine::truth::TruthRow],
    opts: &engine::analysis::Options,
) -> Result<engine::scoring::image::Scored, engine::analysis::AnalysisError> {
    let a = engine::analysis::pipeline::analyze(img, opts)?;
    Ok(engine::scoring::image::score(
        &a,
        Some(truth),
        img.plate_scale_mas,
    ))
}

/// The small scene under a strong realistic ACE (450 mas) with the rolling readout, noise- and flat-free:
/// the only position errors are what the jitter did.
pub fn noise_free_rolling() -> engine::config::Config {
    let mut c = small_config();
    c.ace.sigma_mas = 450.0;
    c.detector.shot_noise = false;
    c.detector.read_noise = false;
    c.detector.digitise = false;
    c.detector.inter_pixel_flat_sigma = 0.0;
    // no flat, so no calibration flat either (its 0.2 % error would be the only noise)
    c.analysis.flat_field = engine::config::FlatField::Uncalibrated;
    // the isolated-star analysis: without noise every ripple of a star's wings is a significant peak, so the
    // automatic choice (which measures the density of peaks above the noise) would call the grid crowded
    c.analysis.crowding = engine::config::Crowding::Off;
    c
}

/// Exposure 0 of `sim` analysed plainly, and its telemetry with perfect (`IDEAL`) recording as the analysis
/// applies it: the image, the plain analysis and the telemetry (a realistic ACE).
pub fn with_ideal_telemetry(
    sim: &engine::simulate::Simulator,
    cfg: &engine::config::Config,
) -> (
    engine::analysis::AnalysisImage,
    engine::analysis::pipeline::Analysis,
    engine::analysis::countermeasures::Telemetry,
) {
    use engine::analysis::countermeasures::TelemetryQuality;
    use engine::analysis::countermeasures::telemetry::ExposureReadout;
    use engine::analysis::pipeline::{Options, Supplied, analyze_prepared, telemetry_for};
    let e = sim.exposure(0).expect("exposure");
    let img = engine::session::source::analysis_image(sim, &e.image);
    let (plain, _) = analyze_prepared(&img, &Options::new(&cfg.analysis)).expect("analysis");
    let rec = engine::session::source::Source::new(sim, 0)
        .telemetry_record(&TelemetryQuality::IDEAL)
        .expect("record")
        .expect("telemetry");
    let supplied = Supplied {
        telemetry: Some(&rec),
        readout: Some(ExposureReadout {
            timing: sim.timing,
            rotation_deg: 0.0,
        }),
        ..Default::default()
    };
    let tel = telemetry_for(
        &TelemetryQuality::IDEAL,
        &supplied,
        &img,
        &plain,
        &cfg.analysis,
    )
    .expect("telemetry")
    .expect("a realistic ACE has telemetry");
    (img, plain, tel)
}

/// RMS difference of profile `e` from `truth` over the inner 2 px (a 17 × 17 grid of ¼-px steps), as a fraction
/// of `truth`'s central value: how far an ePSF lies from a reference profile.
pub fn profile_rms_of_peak(
    e: &engine::analysis::epsf::Epsf,
    truth: &engine::analysis::epsf::Epsf,
) -> f64 {
    let (mut s, mut n) = (0.0, 0);
    for k in 0..=16 {
        for j in 0..=16 {
            let (x, y) = (-2.0 + 0.25 * j as f64, -2.0 + 0.25 * k as f64);
            s += (e.value(x, y) - truth.value(x, y)).powi(2);
            n += 1;
        }
    }
    (s / n as f64).sqrt() / truth.value(0.0, 0.0)
}
