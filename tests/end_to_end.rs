//! End to end: config → simulate → FITS on disk → read back → analyse, and reproducibility.

mod common;

use common::{small_config, temp_dir};
use engine::analysis::AnalysisImage;
use engine::analysis::pipeline::Options;
use engine::config::AceCase;
use engine::io::{analysis_input, exposure, fits};
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
    assert_eq!(back.facts.gain_e_per_adu, 3.0);
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
    let (mut from_file, assumed) =
        analysis_input::read_analysis_image(&files.image, cfg.instrument.plate_scale_mas())
            .expect("image");
    // the reader gives the raw image; the pipeline flat-fields it as the configuration says
    from_file.flat_field(&cfg, cfg.analysis.flat_field);
    assert!(
        assumed.is_empty(),
        "a jsim image says everything: {assumed:?}"
    );
    let in_memory = AnalysisImage::from_detector(&cfg, &exp.image);
    let o = Options::new(&cfg.analysis);
    let a = common::analyze_scored(&from_file, &truth_csv, &o).expect("analysis");
    let b = common::analyze_scored(&in_memory, &exp.truth, &o).expect("analysis");
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

/// Flux bookkeeping: with the stamp following the kernel's reach (the default), every star's noise-free
/// light in the image is the truth's `flux_e × psf_fraction` to 1e-4, static and under the realistic ACE
/// with the rolling readout; and the flux the predictor's fit model assumes, spread by the kernel it uses,
/// is what the image holds. With a stamp truncated inside the reach the image loses light the truth does
/// not count — the failure the default avoids.
#[test]
fn the_image_holds_the_light_the_truth_and_the_predictor_count() {
    let image_total = |c: &engine::config::Config| {
        let sim = Simulator::new(c).expect("sim");
        let exp = sim.exposure(0).expect("exposure");
        let image: f64 = exp.star_e.iter().sum();
        let truth: f64 = exp
            .truth
            .iter()
            .map(|t| t.flux_e * t.modelled_fraction)
            .sum();
        (sim, image, truth)
    };
    for ace in [AceCase::Gaussian, AceCase::Realistic] {
        let mut c = small_config();
        c.ace.case = ace;
        // the default subpixel sampling (8 per axis: the kernel's pixel sum is then the same at every
        // sub-pixel phase; 4 leaves a 2e-4 phase ripple, the subpixel knob's own error)
        c.fidelity.subpixels = 8;
        let (sim, image, truth) = image_total(&c);
        eprintln!("{ace:?}: image / truth = {:.7}", image / truth);
        assert!(
            (image / truth - 1.0).abs() < 1e-4,
            "{ace:?}: image {image} e⁻ vs truth {truth} e⁻"
        );
        if ace == AceCase::Realistic {
            // the predictor's model of a star: FitNoise's flux × the pixel sum of the (unblurred) kernel its
            // fit response is built on
            let noise = engine::session::source::simulation_fit_noise(&sim, 2.5);
            let k = sim.optical_kernel().expect("kernel");
            let per_star = image / sim.stars.len() as f64;
            let model = noise.flux_e * k.pixel_sum(0.0, 0.0);
            assert!(
                (model / per_star - 1.0).abs() < 1e-4,
                "predictor's star {model} e⁻ vs the image's {per_star} e⁻"
            );
        }
    }
    let mut c = small_config();
    c.ace.case = AceCase::Gaussian;
    c.fidelity.subpixels = 8;
    c.fidelity.stamp_radius_px = 4;
    let (_, image, truth) = image_total(&c);
    assert!(
        image / truth < 1.0 - 1e-3,
        "a 4-px stamp drops the wings: image / truth = {}",
        image / truth
    );
}

/// The analysis reads only what an instrument delivers: a copy of a jsim image with its TRUTH and CONFIG
/// extensions removed (primary image and DQ only, the same header cards), analysed with the calibration
/// flat product beside it, gives the same catalogue as the original — and the same as the analysis in
/// memory with the simulator's own calibration flat. Without the flat product the analysis says so.
#[test]
fn the_analysis_reads_no_truth_or_config_only_the_products() {
    use engine::analysis::countermeasures::Countermeasure;
    use engine::io::fits::{Hdu, Pixels};
    use engine::io::instrument;
    use engine::session::Session;
    let mut cfg = small_config();
    cfg.ace.case = AceCase::Gaussian;
    let sim = Simulator::new(&cfg).expect("simulator");
    let exp = sim.exposure(0).expect("exposure");
    let full = temp_dir("products-full");
    let files = exposure::write_exposure(&full, &sim, &exp).expect("write");
    let flat = instrument::write_calibration_flat(&full, &sim)
        .expect("flat")
        .expect("the default analysis is calibrated");
    // the flat product is the simulator's calibration flat, with its error in the header
    let read = instrument::read_calibration_flat(&flat, None).expect("read flat");
    assert_eq!(
        read.data,
        *sim.calibration_flat().expect("calibrated").as_ref()
    );
    assert_eq!(read.error, 0.002);
    // the stripped copy: the image's own header, image and DQ; no TRUTH, no CONFIG
    let bare = temp_dir("products-bare");
    let image = bare.join("image.fits");
    let stored = fits::read_image(&files.image).expect("read");
    fits::write(
        &image,
        &[
            Hdu::Image {
                name: "",
                nx: stored.nx,
                ny: stored.ny,
                pixels: Pixels::F32(&stored.data),
                cards: exposure::headers(&sim, &exp),
            },
            Hdu::U8Image {
                name: "DQ",
                nx: stored.nx,
                ny: stored.ny,
                data: &exp.image.dq,
            },
        ],
    )
    .expect("write the bare copy");
    std::fs::copy(&flat, bare.join(instrument::FLAT_NAME)).expect("copy flat");
    let refcat =
        instrument::write_reference_catalogue(&full, &sim, &instrument::SurveyModel::default())
            .expect("refcat");
    std::fs::copy(&refcat, bare.join(instrument::REFCAT_NAME)).expect("copy refcat");
    let session = Session::new();
    let analyse = |path: &std::path::Path| {
        let input = analysis_input::AnalysisInput::read(path, Some(&files.truth_csv), None, &cfg)
            .expect("input");
        let a = session
            .analyze_input(&cfg, &input, None, Countermeasure::None)
            .expect("analysis");
        (a, input.assumptions)
    };
    let (a_full, assumed_full) = analyse(&files.image);
    let (a_bare, assumed) = analyse(&image);
    let extra: Vec<&String> = assumed
        .iter()
        .filter(|a| !assumed_full.contains(a))
        .collect();
    assert!(
        extra.len() == 1 && extra[0].contains("CONFIG"),
        "only the missing simulation context (an oracle's) is said: {extra:?}"
    );
    assert_eq!(a_full.stars.len(), a_bare.stars.len());
    for (p, q) in a_full.stars.iter().zip(&a_bare.stars) {
        assert_eq!((p.x, p.y, p.flux_e, p.flags), (q.x, q.y, q.flux_e, q.flags));
    }
    let (x, y) = (a_full.report.accuracy_mas, a_bare.report.accuracy_mas);
    assert!((x - y).abs() <= 1e-9 * x, "{x} vs {y}");
    // in memory, with the simulator's calibration flat: the same fits
    let mem = engine::session::analysis_image(&sim, &exp.image);
    let m =
        common::analyze_scored(&mem, &exp.truth, &Options::new(&cfg.analysis)).expect("analysis");
    for (p, q) in m.stars.iter().zip(&a_full.stars) {
        assert_eq!((p.x, p.y), (q.x, q.y));
    }
    // without the product: not flat-fielded, and said
    std::fs::remove_file(bare.join(instrument::FLAT_NAME)).expect("remove");
    let (_, assumed) = analyse(&image);
    assert!(
        assumed.iter().any(|a| a.contains("no calibration flat")),
        "{assumed:?}"
    );
    // a flat of another detector size is refused, naming the product
    let small = temp_dir("products-small");
    let mut other = cfg.clone();
    other.instrument.detector_px = 256;
    other.instrument.photosensitive_px = 240;
    other.readout.channels = 2;
    other.readout.channel_width_px = 128;
    let osim = Simulator::new(&other).expect("simulator");
    let oflat = instrument::write_calibration_flat(&small, &osim)
        .expect("flat")
        .expect("calibrated");
    let e = analysis_input::AnalysisInput::read(&image, None, Some(&oflat), &cfg)
        .expect_err("another detector's flat");
    assert!(e.to_string().contains("calibration flat"), "{e}");
    for d in [full, bare, small] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// The attitude telemetry product: `jsim analyze`'s telemetry correction from the recorded file equals the
/// in-memory correction recorded from the series at the same quality (to 1e-9 px: the file's start time has
/// 15 digits), and a telemetry file of another exposure is refused by name.
#[test]
fn the_telemetry_product_corrects_as_the_in_memory_telemetry_does() {
    use engine::analysis::countermeasures::{Countermeasure, TelemetryQuality};
    use engine::io::instrument;
    use engine::session::Session;
    let mut cfg = small_config();
    cfg.ace.case = AceCase::Realistic;
    let sim = Simulator::new(&cfg).expect("simulator");
    let exp = sim.exposure(1).expect("exposure");
    let dir = temp_dir("telemetry-product");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("write");
    let q = TelemetryQuality::DEFAULT;
    instrument::write_calibration_flat(&dir, &sim).expect("flat");
    instrument::write_model_psf(&dir, &sim).expect("model PSF");
    instrument::write_telemetry(&dir, &sim, 1, &q)
        .expect("telemetry")
        .expect("a realistic ACE records telemetry");
    let session = Session::new();
    let input = analysis_input::AnalysisInput::read_products(
        &files.image,
        Some(&files.truth_csv),
        None,
        None,
        None,
        &cfg,
    )
    .expect("input");
    assert!(
        input.telemetry.is_some(),
        "telemetry_001.fits beside the image is found"
    );
    let cm = Countermeasure::Telemetry(q);
    let from_file = session
        .analyze_input(&cfg, &input, None, cm)
        .expect("analysis with the product");
    // in memory: the simulated instrument records the same telemetry; the pipeline corrects with it
    let plan = engine::analysis::countermeasures::Plan::new(vec![cm]).expect("plan");
    let in_memory = engine::session::Source::new(&sim, 1)
        .analyse_scored(
            &engine::session::analysis_image(&sim, &exp.image),
            Some(&exp.truth),
            &cfg,
            &plan,
            &Default::default(),
        )
        .expect("analysis from the simulation")
        .into_of(&cm)
        .expect("telemetry applies");
    // the analysis knobs may differ from the simulator's; the simulation may not: an image is analysed with
    // the configuration it was simulated with
    let src = engine::session::Source::new(&sim, 1);
    let img = engine::session::analysis_image(&sim, &exp.image);
    let mut knobs = cfg.clone();
    knobs.analysis.epsf_iterations += 1;
    assert!(
        src.analyse(&img, None, &knobs, &plan, &Default::default())
            .is_ok()
    );
    let mut other = cfg.clone();
    other.seed += 1;
    let e = src
        .analyse(&img, None, &other, &plan, &Default::default())
        .expect_err("another simulation's configuration");
    assert!(e.to_string().contains("simulated with"), "{e}");
    let moved = in_memory
        .stars
        .iter()
        .zip(&from_file.stars)
        .map(|(a, b)| (a.x - b.x).abs().max((a.y - b.y).abs()))
        .fold(0.0, f64::max);
    assert!(
        moved < 1e-9,
        "the product and the series differ by {moved} px"
    );
    // the correction did something: the telemetry moved the stars from the plain fit
    let none = session
        .analyze_input(&cfg, &input, None, Countermeasure::None)
        .expect("plain");
    assert!(
        none.stars
            .iter()
            .zip(&from_file.stars)
            .any(|(a, b)| (a.x - b.x).abs() > 1e-4),
        "the telemetry corrected nothing"
    );
    // without the product the correction has nothing to correct with: nothing moves, and it is said
    let mut bare = input.clone();
    bare.telemetry = None;
    let uncorrected = session
        .analyze_input(&cfg, &bare, None, cm)
        .expect("no telemetry");
    assert!(
        uncorrected
            .stars
            .iter()
            .zip(&none.stars)
            .all(|(a, b)| (a.x, a.y) == (b.x, b.y))
    );
    let without = analysis_input::AnalysisInput::read_products(
        &files.image,
        None,
        None,
        None,
        Some(&dir.join("absent.fits")),
        &cfg,
    );
    assert!(
        without.is_err(),
        "a named telemetry file that is absent is an error"
    );
    // another exposure's telemetry is refused
    let other = instrument::write_telemetry(&dir, &sim, 2, &q)
        .expect("telemetry")
        .expect("written");
    let e = analysis_input::AnalysisInput::read_products(
        &files.image,
        None,
        None,
        None,
        Some(&other),
        &cfg,
    )
    .expect_err("another exposure's telemetry");
    assert!(e.to_string().contains("exposure 2"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A reference catalogue of another pointing is refused by name: its stars' RA/Dec, seen through the image's
/// WCS, land hundreds of pixels from their pixel positions. The image's own catalogue passes.
#[test]
fn a_reference_catalogue_of_another_pointing_is_refused() {
    use engine::io::instrument;
    let cfg = small_config();
    let sim = Simulator::new(&cfg).expect("simulator");
    let exp = sim.exposure(0).expect("exposure");
    let dir = temp_dir("refcat-pointing");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("write");
    let survey = instrument::SurveyModel::default();
    let own = instrument::write_reference_catalogue(&dir, &sim, &survey).expect("refcat");
    let read = |refcat: &std::path::Path| {
        analysis_input::AnalysisInput::read_products(
            &files.image,
            None,
            None,
            Some(refcat),
            None,
            &cfg,
        )
    };
    assert!(read(&own).expect("its own catalogue").reference.is_some());
    let mut moved = cfg.clone();
    moved.sky.dec_deg += 0.05; // 180″: ≈ 380 px at 472 mas/px
    let other_sim = Simulator::new(&moved).expect("simulator");
    let other_dir = temp_dir("refcat-pointing-other");
    let other =
        instrument::write_reference_catalogue(&other_dir, &other_sim, &survey).expect("refcat");
    let e = read(&other).expect_err("another pointing");
    assert!(
        e.to_string().contains("another pointing") && e.to_string().contains("refcat"),
        "{e}"
    );
    for d in [dir, other_dir] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A seed of all 64 bits is written as itself: the header card as the FITS standard's text reads it (a
/// signed card would have held −1), and the `CONFIG` extension's seed with it.
#[test]
fn a_seed_beyond_two_to_the_63_is_written_as_itself() {
    let mut cfg = small_config();
    cfg.seed = u64::MAX;
    cfg.fidelity.images = 1;
    cfg.ace.case = AceCase::None;
    let sim = Simulator::new(&cfg).expect("simulator");
    let exp = sim.exposure(0).expect("exposure");
    let dir = temp_dir("e2e-big-seed");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("write");
    // the primary header: 80-character cards from the file's start, `KEY     = value / comment`
    let bytes = std::fs::read(&files.image).expect("file");
    let card = bytes
        .chunks(80)
        .take_while(|c| !c.starts_with(b"END "))
        .map(|c| String::from_utf8_lossy(c).into_owned())
        .find(|c| c.starts_with("SEED    ="))
        .expect("a SEED card");
    let value = card[10..].split('/').next().unwrap_or("").trim();
    assert_eq!(value, u64::MAX.to_string(), "{card}");
    let conf = fits::read_text(&files.image, "CONFIG").expect("CONFIG");
    let back = engine::config::Config::from_toml_str(&conf).expect("parses");
    assert_eq!(back.seed, u64::MAX);
}
