//! Countermeasures on simulated images: the telemetry correction removes what the ACE displaced, a plate
//! model absorbs a smooth field, and the readout orders behave as hardware countermeasures should.

mod common;

use common::{noise_free_rolling, pooled_accuracy_over_bound, small_config};
use engine::analysis::AnalysisImage;
use engine::analysis::countermeasures::{Countermeasure, Plan, Telemetry, TelemetryQuality};
use engine::analysis::pipeline::Options;
use engine::config::{AceCase, ReadoutOrder};
use engine::numerics::stats;
use engine::simulate::Simulator;
use engine::studies::experiment::analyse_exposure;

fn rms_mas(v: &[(f64, f64)], scale: f64) -> f64 {
    let x: Vec<f64> = v.iter().map(|p| p.0 * scale).collect();
    let y: Vec<f64> = v.iter().map(|p| p.1 * scale).collect();
    ((stats::std_dev(&x).powi(2) + stats::std_dev(&y).powi(2)) / 2.0).sqrt()
}

/// The accuracy (mas) of exposure 0 of `c` analysed with `cm` alone.
fn accuracy(c: &engine::config::Config, cm: Countermeasure) -> f64 {
    let sim = Simulator::new(c).expect("sim");
    let plan = Plan::new(vec![cm]).expect("plan");
    analyse_exposure(&sim, 0, &plan).expect("analysis").measured[0]
        .report
        .accuracy_mas
}

/// The telemetry's predictions against what the fit actually measured: the position errors of a noise-free,
/// flat-free rolling-readout image (fitted with the ePSF built from it, as the pipeline does).
#[test]
fn telemetry_predicts_the_measured_errors_of_a_noise_free_image() {
    let c = noise_free_rolling();
    let sim = Simulator::new(&c).expect("sim");
    let e = sim.exposure(0).expect("exposure");
    let kernel = sim.optical_kernel().expect("kernel");
    let o = Options::new(&c.analysis);
    let a = common::analyze_scored(&AnalysisImage::from_detector(&c, &e.image), &e.truth, &o)
        .expect("analysis");
    let used: Vec<&engine::scoring::image::ScoredStar> =
        a.stars.iter().filter(|s| s.is_used()).collect();
    assert_eq!(used.len(), 64);
    let measured: Vec<(f64, f64)> = used.iter().map(|s| (s.dx_px, s.dy_px)).collect();
    let pos: Vec<(f64, f64)> = used.iter().map(|s| (s.x, s.y)).collect();
    let scale = c.instrument.plate_scale_mas();
    let noise = engine::session::source::simulation_fit_noise(&sim, c.analysis.fit_radius_px);
    let series = sim.series().expect("series");
    let tel_q = |q: TelemetryQuality| {
        Telemetry::from_series(
            series,
            sim.timing,
            sim.exposure_start_s(0),
            scale,
            0.0,
            &q,
            c.seed,
            &kernel,
            &noise,
        )
        .expect("telemetry")
        .predicted_px(&pos)
    };
    let tel = |noise_mas: f64, rate_hz: f64| {
        tel_q(TelemetryQuality {
            noise_mas,
            rate_hz,
            ..TelemetryQuality::IDEAL
        })
    };
    let resid = |p: &[(f64, f64)]| -> Vec<(f64, f64)> {
        measured
            .iter()
            .zip(p)
            .map(|(a, b)| (a.0 - b.0, a.1 - b.1))
            .collect()
    };
    let before = rms_mas(&measured, scale);
    let perfect = rms_mas(&resid(&tel(0.0, 1000.0)), scale);
    let noisy = rms_mas(&resid(&tel(200.0, 1000.0)), scale);
    let slow = rms_mas(&resid(&tel(0.0, 2.0)), scale);
    eprintln!(
        "measured error rms {before:.3} mas; after telemetry: perfect {perfect:.3}, 200-mas noise {noisy:.3}, \
         2 Hz {slow:.3} mas"
    );
    assert!(
        before > 1.0,
        "the test needs a displacement to remove ({before} mas)"
    );
    // what perfect telemetry leaves is the PSF-shape change its linear response does not model (measured,
    // deterministic on this noise-free image: 2.24 → 0.74 mas perfect, 1.17 with 200-mas noise, 3.37 at 2 Hz)
    assert!(
        perfect < 0.4 * before,
        "perfect telemetry leaves {perfect} of {before} mas"
    );
    // an error of the same rms that is correlated over the exposure (Gauss–Markov, τ = 2 s) does not
    // average away as the white one does: it leaves more
    let correlated = rms_mas(
        &resid(&tel_q(TelemetryQuality {
            correlated_mas: 200.0,
            correlation_time_s: 2.0,
            ..TelemetryQuality::IDEAL
        })),
        scale,
    );
    eprintln!("200-mas correlated error (τ 2 s): {correlated:.3} mas");
    assert!(
        correlated > noisy,
        "correlated {correlated} vs white {noisy} mas"
    );
    assert!(
        noisy > perfect && slow > perfect,
        "noisy {noisy}, slow {slow}"
    );
}

#[test]
fn telemetry_and_plate_model_fix_a_noise_free_rolling_image_and_sample_hold_needs_no_fix() {
    let c = noise_free_rolling();
    let parse = |n: &str| -> Countermeasure { n.parse().expect("name") };
    let none = accuracy(&c, Countermeasure::None);
    // the upper limits: the true attitude, the true positions
    let tel = accuracy(&c, Countermeasure::Telemetry(TelemetryQuality::IDEAL));
    let plate = accuracy(&c, parse("plate-poly:3@oracle"));
    // one image is a stare of one: its own stack, nothing to correct
    let alone = accuracy(&c, parse("plate-poly:3"));
    let mut sh = c.clone();
    sh.readout.order = ReadoutOrder::SampleHold;
    let hold = accuracy(&sh, Countermeasure::None);
    eprintln!(
        "noise-free rolling: none {none:.3}, ideal telemetry {tel:.3}, plate-poly:3@oracle {plate:.3}, \
         plate-poly:3 alone {alone:.3}; sample-hold {hold:.3} mas"
    );
    // measured: none 2.28, telemetry 0.91, plate-poly:3@oracle 0.62, sample-hold 0.38 mas (the floor of a
    // 64-star ePSF on a noise-free image; what telemetry leaves above it is the PSF-shape change the
    // linear response does not model)
    assert!(tel < 0.5 * none, "telemetry {tel} vs none {none}");
    assert!(plate < 0.5 * none, "plate {plate} vs none {none}");
    assert_eq!(alone, none, "a stack of one image corrects nothing");
    assert!(hold < 0.3 * none, "sample-hold {hold} vs rolling {none}");
}

/// The stack reference on noise-free stares of the small scene: it sits between the uncorrected fit and
/// the oracle reference, gets closer to the oracle as the stare grows (the stare's mean displacement field
/// shrinks as 1/√K). (The predictor's value is printed, not asserted: it counts the photon noise these
/// noise-free images lack.)
#[test]
fn the_stack_reference_approaches_the_oracle_as_the_stare_grows() {
    let mut c = noise_free_rolling();
    let plan = Plan::parse(
        &["none", "plate-poly:3", "plate-poly:3@oracle"],
        TelemetryQuality::IDEAL,
        0.0,
    )
    .expect("plan");
    let mut excess = Vec::new();
    for k in [2usize, 8] {
        c.fidelity.images = k;
        let sim = Simulator::new(&c).expect("sim");
        let (rows, _) = engine::studies::experiment::run_dataset(&sim, &plan, &mut |_| {
            std::ops::ControlFlow::Continue(())
        })
        .expect("stare");
        let acc = |n: &str| {
            rows.iter()
                .find(|r| r.countermeasure == n)
                .map(|r| (r.accuracy_mas, r.predicted_mas))
                .expect(n)
        };
        let (none, none_pred) = acc("none");
        let (stack, stack_pred) = acc("plate-poly:3");
        let (oracle, oracle_pred) = acc("plate-poly:3@oracle");
        eprintln!(
            "stare of {k}: none {none:.3}, stack {stack:.3}, oracle {oracle:.3} mas; predicted with photon \
             noise {none_pred:.3}, {stack_pred:.3}, {oracle_pred:.3}"
        );
        assert!(
            oracle < stack && stack < none,
            "K = {k}: {oracle} < {stack} < {none}"
        );
        excess.push((stack * stack - oracle * oracle).max(0.0).sqrt());
    }
    assert!(
        excess[1] < excess[0],
        "the stack's own error shrinks with the stare: {excess:?}"
    );
}

/// Every countermeasure of the plan, on one noise-free rolling-readout image of the small scene, through the
/// pipeline: what each must do (measured, deterministic: none 2.24 mas; the Y-zoned ePSFs keep the
/// displacement; the plate models and the telemetry remove most of it), and the exact-ePSF control on a
/// noisy Gaussian-ACE image sits at the bound.
#[test]
fn every_countermeasure_does_what_it_should_on_a_small_scene() {
    let c = noise_free_rolling();
    let names = [
        "none",
        "yzones",
        "yzones-shared",
        "plate-affine@oracle",
        "plate-poly:3@oracle",
        "telemetry",
        "exact-epsf",
    ];
    let plan = Plan::parse(&names, TelemetryQuality::IDEAL, 0.0).expect("plan");
    let sim = Simulator::new(&c).expect("sim");
    let r = analyse_exposure(&sim, 0, &plan).expect("analysis");
    let acc = |n: &str| {
        r.measured
            .iter()
            .find(|m| m.countermeasure == n)
            .map(|m| m.report.accuracy_mas)
            .unwrap_or(f64::NAN)
    };
    let got: Vec<String> = names.iter().map(|n| format!("{n} {:.3}", acc(n))).collect();
    eprintln!("noise-free rolling image: {}", got.join(", "));
    let none = acc("none");
    assert!(none > 1.5, "a displacement to remove: {none} mas");
    for zoned in ["yzones", "yzones-shared"] {
        assert!(
            acc(zoned) > 0.7 * none,
            "{zoned} cannot absorb a displacement: {} vs {none}",
            acc(zoned)
        );
    }
    assert!(
        acc("plate-affine@oracle") < 0.8 * none,
        "{}",
        acc("plate-affine@oracle")
    );
    assert!(
        acc("plate-poly:3@oracle") < acc("plate-affine@oracle"),
        "{}",
        acc("plate-poly:3@oracle")
    );
    assert!(acc("telemetry") < 0.5 * none, "{}", acc("telemetry"));
    // exact-epsf is the static-ACE control: it does not apply to a realistic-ACE image
    assert!(r.measured.iter().all(|m| m.countermeasure != "exact-epsf"));
    // on a noisy Gaussian-ACE image without flat it reaches the bound: 3 images × 64 stars × 2 axes, the
    // accuracy's relative standard error is 1/√(2·384) = 3.6 %, so ±12 % is 3.3 σ
    let mut g = small_config();
    g.ace.case = AceCase::Gaussian;
    g.detector.inter_pixel_flat_sigma = 0.0;
    let sim = Simulator::new(&g).expect("sim");
    let (ratio, _) = pooled_accuracy_over_bound(&sim, Countermeasure::ExactEpsf);
    eprintln!("exact-ePSF control: accuracy / bound = {ratio:.3}");
    assert!(
        (ratio - 1.0).abs() < 0.12,
        "exact-ePSF control at {ratio} × the bound"
    );
}

/// The telemetry forward model with perfect telemetry: each star fitted through the jitter its own pixels saw
/// removes what the linear shift response leaves (the shape change of a drift under the rolling readout). On
/// the noise-free rolling image it reaches the sample-and-hold readout's floor (the 64-star ePSF's own on a
/// noise-free image, the hardware fix), where the shift-only correction stays above it.
#[test]
fn the_telemetry_forward_model_reaches_the_sample_hold_floor() {
    let c = noise_free_rolling();
    let tel = accuracy(&c, Countermeasure::Telemetry(TelemetryQuality::IDEAL));
    let model = accuracy(&c, Countermeasure::TelemetryModel(TelemetryQuality::IDEAL));
    let mut sh = c.clone();
    sh.readout.order = ReadoutOrder::SampleHold;
    let hold = accuracy(&sh, Countermeasure::None);
    eprintln!(
        "noise-free rolling, ideal telemetry: shift {tel:.3}, forward model {model:.3}; sample-hold {hold:.3} mas"
    );
    // measured: shift 0.743, forward model 0.161, sample-hold 0.384 mas. The forward model recovers the
    // true positions (common offset removed) to 1e-3 px per axis; the shift-only correction is off by more.
    let px_mas = c.instrument.plate_scale_mas();
    assert!(model < 1e-3 * px_mas, "forward model {model} mas");
    assert!(tel > 1e-3 * px_mas, "shift-only {tel} mas");
    assert!(model < hold, "forward model {model} vs sample-hold {hold}");
}

/// The forward model and a plate model as one countermeasure: a telemetry whose error drifts linearly over the
/// exposure (60 mas from start to end, both axes: what a gyro's bias left after the star tracker would do)
/// leaves the forward model with a displacement that grows along Y (the rolling readout's windows start up to
/// ≈ 1.2 s apart) and a little shape error (the drift stretches the recorded jitter, so each star's modelled
/// kernel too). The plate model fitted to the forward model's refits removes the displacement (here
/// referenced to the true positions, the oracle, so that only the telemetry's error is left to remove); the
/// shape error stays. Noise-free rolling image under a 200-mas realistic ACE, measured: perfect telemetry
/// 0.070 mas; drifting 0.518 alone, 0.129 with the plate model.
#[test]
fn a_plate_model_after_the_forward_model_removes_a_telemetry_drift() {
    use engine::analysis::pipeline::Supplied;
    use engine::session::source::{Source, analysis_image};
    let mut c = noise_free_rolling();
    c.ace.sigma_mas = 200.0;
    let sim = Simulator::new(&c).expect("sim");
    let e = sim.exposure(0).expect("exposure");
    let src = Source::new(&sim, 0);
    let plan = Plan::parse(
        &["telemetry-model", "telemetry-model+plate-poly:3@oracle"],
        TelemetryQuality::IDEAL,
        1.0,
    )
    .expect("plan");
    let img = analysis_image(&sim, &e.image);
    let accuracies = |drift_mas: f64| -> (f64, f64) {
        let mut rec = src
            .telemetry_record(&TelemetryQuality::IDEAL)
            .expect("record")
            .expect("a realistic ACE has telemetry");
        let n = rec.x_mas.len() as f64;
        for (k, (x, y)) in rec.x_mas.iter_mut().zip(rec.y_mas.iter_mut()).enumerate() {
            *x += drift_mas * k as f64 / n;
            *y += drift_mas * k as f64 / n;
        }
        let supplied = Supplied {
            telemetry: Some(&rec),
            ..Default::default()
        };
        let r = src
            .analyse_scored(&img, Some(&e.truth), &c, &plan, &supplied)
            .expect("analysis");
        let acc = |k: usize| r.measured[k].1.report.accuracy_mas;
        (acc(0), acc(1))
    };
    let (ideal, _) = accuracies(0.0);
    let (alone, combined) = accuracies(60.0);
    eprintln!(
        "perfect telemetry {ideal:.3}; drifting: forward model {alone:.3}, with plate-poly:3@oracle \
         {combined:.3} mas"
    );
    assert!(
        alone > 5.0 * ideal,
        "the drift shows: {alone} vs {ideal} mas"
    );
    assert!(
        combined < 0.3 * alone && combined < 2.0 * ideal,
        "removed: {combined} mas (alone {alone}, perfect {ideal})"
    );
}

/// The image's own static profile for the forward model, without a design model: the ePSF rebuilt with each
/// star seen through its own windows' jitter (`analysis.telemetry_kernel = "epsf-deconvolved"`) moves from the
/// image's ePSF (which holds the exposure's mean jitter blur) towards the true static profile — here the
/// simulation's own pixel kernel at the field centre, the reference this test alone may read. Noise-free
/// rolling image under a 450-mas realistic ACE; rms difference over the ePSF's inner 2 px (measured: 0.19 of
/// the peak for the image's ePSF, 0.090 deconvolved in the default 8 iterations; a 1-px jitter damps the
/// profile's fine detail, which returns slowly).
#[test]
fn the_deconvolved_epsf_approaches_the_static_profile() {
    use engine::analysis::countermeasures::forward_epsf::build_deconvolved;
    use engine::analysis::epsf::Epsf;
    use engine::analysis::pipeline::build_options;
    let c = noise_free_rolling();
    let sim = Simulator::new(&c).expect("sim");
    let (img, plain, tel) = common::with_ideal_telemetry(&sim, &c);
    let deconvolved = build_deconvolved(
        &img,
        &plain.stars,
        &plain.epsf,
        &tel,
        &build_options(&c.analysis),
        c.analysis.telemetry_deconvolution_iterations,
    );
    let kernel = sim.design_kernel().expect("kernel");
    let mut truth = Epsf::from_fn(4, c.analysis.epsf_radius_px, |x, y| kernel.eval(x, y));
    truth.normalise();
    let truth = truth.recentred();
    let rms = |e: &Epsf| common::profile_rms_of_peak(e, &truth);
    let (blurred, decon) = (rms(&plain.epsf), rms(&deconvolved));
    eprintln!(
        "rms from the static profile (of its peak): image ePSF {blurred:.4}, deconvolved {decon:.4}"
    );
    assert!(decon < 0.55 * blurred, "{decon} vs {blurred}");
}
