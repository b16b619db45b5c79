//! Two instruments, guarded by construction: with the as-built deviations on, no product beside the images
//! equals its as-built counterpart — the model PSF, the header's distortion, gain and read noise, the
//! reference catalogue's pixel columns — while the oracle control (`as_built.knowledge = "as-built"`), asked
//! for by name, hands over exactly the as-built ones.

mod common;

use common::small_config;
use engine::analysis::pipeline::exact_epsf;
use engine::config::{AsBuilt, Config, Knowledge};
use engine::io::fits;
use engine::io::instrument::{SurveyModel, model_psf, reference_catalogue};
use engine::simulate::Simulator;

fn deviating(knowledge: Knowledge, field_rms_nm: f64) -> Config {
    let mut c = small_config();
    c.fidelity.images = 1;
    c.as_built = AsBuilt {
        seed: 3,
        wavefront_rms_nm: 30.0,
        wavefront_field_rms_nm: field_rms_nm,
        distortion_px: 0.05,
        gain_error: 0.02,
        read_noise_error: 0.05,
        knowledge,
        ..AsBuilt::design()
    };
    c.validate().expect("valid");
    c
}

/// The header keys of a written exposure: GAIN, RNREAD and the distortion's A_2_0 (absent: NaN).
fn header_of(sim: &Simulator, name: &str) -> (f64, f64, f64) {
    let dir = engine::testkit::temp_dir(name);
    let exp = sim.exposure(0).expect("exposure");
    let files = engine::io::exposure::write_exposure(&dir, sim, &exp).expect("write");
    let key = |k: &str| fits::read_f64_key_in(&files.image, None, k).unwrap_or(f64::NAN);
    (key("GAIN"), key("RNREAD"), key("A_2_0"))
}

#[test]
fn with_deviations_on_no_product_is_the_as_built_instrument() {
    let cfg = deviating(Knowledge::Design, 10.0);
    let sim = Simulator::new(&cfg).expect("sim");
    let built = sim.as_built_oracle().clone();
    let radius = cfg.analysis.epsf_radius_px;

    // the model PSF: the design wavefront's, not the one that made the image (30 nm rms apart)
    let design_psf = model_psf(&sim).expect("model PSF");
    let true_psf = exact_epsf(&sim.optical_kernel().expect("kernel"), radius);
    let peak = true_psf.data.iter().cloned().fold(0.0, f64::max);
    let worst = design_psf
        .data
        .iter()
        .zip(&true_psf.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst > 1e-3 * peak,
        "model PSF = as-built PSF ({worst} of {peak})"
    );

    // the header: the design's gain, read noise and distortion (no quadratic term), not the as-built ones
    let (gain, rn, a20) = header_of(&sim, "two-instruments-design");
    assert_eq!(gain, cfg.detector.gain_e_per_adu);
    assert_ne!(gain, built.detector.gain_e_per_adu);
    assert_eq!(rn, cfg.detector.read_noise_per_read_e);
    assert_ne!(rn, built.detector.read_noise_per_read_e);
    assert!(
        a20.is_nan(),
        "the header carries an as-built distortion term: {a20}"
    );
    assert!(built.focal_plane.sip_a.iter().any(|t| (t.p, t.q) == (2, 0)));

    // the reference catalogue: a sky catalogue whose pixel columns come through the header's (design) WCS —
    // where the design puts each star's RA/Dec, not where the as-built instrument images it
    let design_wcs = sim.design_wcs().expect("design WCS");
    let true_wcs = sim.wcs().expect("as-built WCS");
    let cat = reference_catalogue(&sim, &SurveyModel::default(), 0);
    assert!(!cat.is_empty());
    let mut largest_offset_px: f64 = 0.0;
    for s in &cat {
        let (xd, yd) = design_wcs
            .sky_to_pixel(s.ra_deg, s.dec_deg)
            .expect("design pixel");
        assert!(
            (xd - s.x_px).abs() < 1e-6 && (yd - s.y_px).abs() < 1e-6,
            "{s:?}"
        );
        let (xt, yt) = true_wcs
            .sky_to_pixel(s.ra_deg, s.dec_deg)
            .expect("true pixel");
        largest_offset_px = largest_offset_px.max((xt - s.x_px).hypot(yt - s.y_px));
    }
    // the quadratic distortion beyond the design: 0.05 px rms at the corners, ≳ 0.01 px over the grid
    assert!(largest_offset_px > 0.01, "{largest_offset_px}");
}

#[test]
fn the_oracle_asked_for_by_name_hands_over_the_as_built_instrument() {
    // no field variation: the as-built PSF is the same at every star, so the model PSF must be it exactly
    let cfg = deviating(Knowledge::AsBuilt, 0.0);
    let sim = Simulator::new(&cfg).expect("sim");
    let built = sim.as_built_oracle().clone();
    let radius = cfg.analysis.epsf_radius_px;
    let model = model_psf(&sim).expect("model PSF");
    let truth = exact_epsf(&sim.optical_kernel().expect("kernel"), radius);
    assert_eq!(model.data, truth.data);
    let (gain, rn, a20) = header_of(&sim, "two-instruments-oracle");
    // the header's text keeps 15 significant digits
    let same = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    assert!(same(gain, built.detector.gain_e_per_adu), "{gain}");
    assert!(same(rn, built.detector.read_noise_per_read_e), "{rn}");
    let built_a20 = built
        .focal_plane
        .sip_a
        .iter()
        .find(|t| (t.p, t.q) == (2, 0))
        .map(|t| t.value)
        .expect("as-built term");
    assert!(same(a20, built_a20), "{a20} {built_a20}");
}

#[test]
fn without_deviations_the_products_are_the_instruments_own() {
    let cfg = small_config();
    let sim = Simulator::new(&cfg).expect("sim");
    assert_eq!(sim.as_built_oracle(), &cfg);
    assert!(!sim.wcs_deviates());
    let model = model_psf(&sim).expect("model PSF");
    let truth = exact_epsf(
        &sim.optical_kernel().expect("kernel"),
        cfg.analysis.epsf_radius_px,
    );
    assert_eq!(model.data, truth.data);
}

/// The design PSF corrected by exposure 0's stars (`design-fitted`: the Z4–Z11 terms fitted through the
/// design's derivative planes, each star through its ideal telemetry), and the design PSF it started from.
fn design_fitted(
    sim: &Simulator,
    cfg: &Config,
) -> (
    engine::analysis::countermeasures::wavefront::WavefrontFit,
    engine::analysis::epsf::Epsf,
) {
    let (img, plain, tel) = common::with_ideal_telemetry(sim, cfg);
    let psi0 = engine::io::instrument::model_psf_product(sim).expect("model PSF");
    let terms = engine::io::instrument::model_psf_terms(sim).expect("terms");
    let w = engine::analysis::countermeasures::wavefront::fit(
        &img,
        &plain.stars,
        &psi0,
        &terms,
        &tel,
        &engine::analysis::pipeline::build_options(&cfg.analysis).fit,
    )
    .expect("a fit");
    (w, psi0)
}

/// The analysis learns the as-built wavefront from the stars: on a noise-free rolling image (450-mas realistic
/// ACE, ideal telemetry) of an instrument 50 nm rms off its design, the Z4–Z11 coefficients fitted through the
/// design's derivative planes, each star seen through its own windows' jitter
/// (`analysis.telemetry_kernel = "design-fitted"`), recover the drawn deviation — the truth this test alone
/// reads: its odd terms within 3 nm — and the corrected profile lies 2.8 times closer to the as-built PSF than
/// the design PSF does (0.0045 against 0.0124 of the peak, rms over the inner 2 px; held below half). What is
/// left is the PSF's second-order change over 50 nm (the planes are first derivatives at the design).
#[test]
fn the_stars_teach_the_design_psf_the_as_built_wavefront() {
    use engine::analysis::epsf::Epsf;
    let mut c = common::noise_free_rolling();
    c.as_built.wavefront_rms_nm = 50.0;
    let sim = Simulator::new(&c).expect("sim");
    let (w, psi0) = design_fitted(&sim, &c);

    // the drawn deviation, nm rms per term (the truth: read by this test alone)
    let built = engine::instrument::realise(&c).expect("as built");
    let to_um = |f: &[f64]| engine::optics::to_um(&c.optics, f);
    let (b, d) = (
        to_um(&built.optics.field_table[0].fringe),
        to_um(&c.optics.fringe),
    );
    let truth: Vec<f64> = engine::simulate::DESIGN_TERMS
        .iter()
        .map(|&j| (b[j - 1] - d[j - 1]) * 1e3 * engine::optics::zernike::fringe_norm(j).sqrt())
        .collect();
    let miss = truth
        .iter()
        .zip(&w.coefficients_nm)
        .map(|(t, f)| (t - f).powi(2))
        .sum::<f64>()
        .sqrt();
    eprintln!(
        "drawn {truth:.2?} nm\nfitted {:.2?} nm (± {:.3?}), {} stars; off by {miss:.2} nm rms",
        w.coefficients_nm, w.sigma_nm, w.stars
    );
    // the odd terms (coma Z7, Z8 and trefoil Z10, Z11: they move a star's centroid, so they matter most to
    // astrometry) change the PSF to first order and come back within 3 nm (measured ≤ 1.7); the even ones
    // (focus, astigmatism, spherical) change it mostly to second order about this design and trade off against
    // each other (focus with spherical: their formal errors are 4.6 and 22 nm here), so only the profile they
    // make together is held below
    for (k, j) in engine::simulate::DESIGN_TERMS.iter().enumerate() {
        if [7, 8, 10, 11].contains(j) {
            let off = (w.coefficients_nm[k] - truth[k]).abs();
            assert!(
                off < 3.0,
                "Z{j}: fitted {} for {} nm",
                w.coefficients_nm[k],
                truth[k]
            );
        }
    }
    assert!(
        miss < 60.0,
        "the fit misses the drawn wavefront by {miss} nm rms"
    );

    let kernel = sim.optical_kernel().expect("as-built kernel");
    let mut truth_psf = Epsf::from_fn(8, c.analysis.epsf_radius_px, |x, y| kernel.eval(x, y));
    truth_psf.normalise();
    let rms = |e: &Epsf| common::profile_rms_of_peak(e, &truth_psf);
    let (before, after) = (rms(&psi0), rms(&w.profile));
    eprintln!("rms from the as-built PSF (of its peak): design {before:.4}, fitted {after:.4}");
    assert!(after < 0.5 * before, "{after} vs {before}");
}

/// The design model PSF's derivative planes are a file product an outside tool can read: written as `DZ4` …
/// `DZ11` of `psf_model.fits` when the analysis corrects the design PSF by the stars, read back bit for bit;
/// a file without them has none.
#[test]
fn the_derivative_planes_round_trip_through_the_model_psf_file() {
    use engine::io::instrument::{model_psf_terms, read_model_psf_terms, write_model_psf};
    let mut c = small_config();
    c.analysis.telemetry_kernel = engine::config::TelemetryKernel::DesignFitted;
    let sim = Simulator::new(&c).expect("sim");
    let dir = engine::testkit::temp_dir("derivative-planes");
    let path = write_model_psf(&dir, &sim).expect("write");
    let read = read_model_psf_terms(&path).expect("read").expect("planes");
    let made = model_psf_terms(&sim).expect("terms");
    assert_eq!(read.len(), 8);
    for (r, m) in read.iter().zip(&made) {
        assert_eq!(r.data, m.data);
    }
    let plain = Simulator::new(&small_config()).expect("sim");
    let other = engine::testkit::temp_dir("no-derivative-planes");
    let path = write_model_psf(&other, &plain).expect("write");
    assert!(read_model_psf_terms(&path).expect("read").is_none());
}

/// The pointing and roll offsets and the quad's array placement: the header's WCS is the plan's (the
/// planned axis, the arrays at their drawn places), the stars land through the as-built one, and the plate
/// solution against the catalogue (`analysis::registration`) recovers the difference from the stars.
#[test]
fn the_header_points_where_planned_and_the_catalogue_registration_finds_where_the_stars_are() {
    use engine::analysis::registration::register;
    use engine::config::Layout;
    let mut cfg = small_config();
    cfg.fidelity.images = 1;
    cfg.focal_plane.layout = Layout::Quad;
    cfg.focal_plane.gap_px = 60.0;
    cfg.as_built.pointing_offset_arcsec = [2.5, -1.75];
    cfg.as_built.roll_offset_arcsec = 40.0;
    cfg.validate().expect("valid");
    let built = engine::instrument::realise(&cfg).expect("as built");
    let design = engine::instrument::design_of(&cfg);
    // the design: the planned axis and nominal arrays; the as-built: the sky moved by the offset
    assert_eq!(design.sky, cfg.sky);
    assert_eq!(design.focal_plane.array_offsets_px, [[0.0; 2]; 4]);
    let moved = engine::sky::apparent::offset_mas(
        (cfg.sky.ra_deg, cfg.sky.dec_deg),
        (built.sky.ra_deg, built.sky.dec_deg),
    );
    assert!(
        (moved.0 - 2500.0).abs() < 1e-6 && (moved.1 + 1750.0).abs() < 1e-6,
        "{moved:?}"
    );
    assert!((built.sky.pa_deg - cfg.sky.pa_deg - 40.0 / 3600.0).abs() < 1e-12);

    let n = cfg.instrument.detector_px as f64;
    for k in 0..4 {
        let truth = engine::sky::array_wcs(&built, k).expect("as-built WCS");
        let header = engine::sky::array_wcs(&design, k).expect("design WCS");
        // stars on a grid: where they land (truth) and where the header puts their sky places (catalogue)
        let mut landed = Vec::new();
        let mut catalogue = Vec::new();
        for i in 0..30 {
            for j in 0..30 {
                let p = (
                    10.0 + i as f64 * (n - 20.0) / 29.0,
                    10.0 + j as f64 * (n - 20.0) / 29.0,
                );
                let (ra, dec) = truth.pixel_to_sky(p.0, p.1).expect("sky");
                landed.push(p);
                catalogue.push(header.sky_to_pixel(ra, dec).expect("pixel"));
            }
        }
        // the header misses by the pointing offset (≈ 6.5 px) plus the array's assembly offset (≈ 10 px,
        // in any direction: at least a pixel everywhere)
        let miss = landed
            .iter()
            .zip(&catalogue)
            .map(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1))
            .fold(f64::INFINITY, f64::min);
        assert!(miss > 1.0, "array {k}: {miss} px");
        // the registration from the stars alone puts every catalogue star where it landed, to 0.01 px
        let flux: Vec<f64> = (0..landed.len()).map(|i| 1.0 + i as f64).collect();
        let reg = register(&landed, &flux, &catalogue);
        // the 500 brightest fits pair, less those the 3σ clip leaves out
        assert!(reg.pairs >= 450, "array {k}: {reg:?}");
        let worst = landed
            .iter()
            .zip(&catalogue)
            .map(|(a, &c)| {
                let r = reg.apply(c);
                (a.0 - r.0).hypot(a.1 - r.1)
            })
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "array {k}: {worst} px after registration");
    }
}

/// A simulated exposure with a pointing offset: the header's reference pixel points at the planned axis,
/// the reference catalogue's pixel columns are the header's, and the stars are imaged elsewhere.
#[test]
fn a_pointing_offset_moves_the_stars_and_not_the_header() {
    let mut cfg = small_config();
    cfg.fidelity.images = 1;
    cfg.scene.kind = engine::config::SceneKind::Bulge;
    cfg.scene.bulge.density_per_arcmin2 = 20.0;
    cfg.as_built.pointing_offset_arcsec = [3.0, 0.0];
    cfg.validate().expect("valid");
    let sim = Simulator::new(&cfg).expect("sim");
    let mut plain = cfg.clone();
    plain.as_built = AsBuilt::design();
    let plan = Simulator::new(&plain).expect("sim");
    // the header is the plan's, bit for bit
    let (h, p) = (
        sim.design_wcs().expect("header"),
        plan.design_wcs().expect("plan"),
    );
    assert_eq!(h.keywords(), p.keywords());
    // the same sky (the mock bulge is drawn where the telescope was meant to point) …
    let ids = |s: &Simulator| s.stars.iter().map(|t| t.id).collect::<Vec<_>>();
    let common: Vec<usize> = ids(&sim)
        .into_iter()
        .filter(|i| ids(&plan).contains(i))
        .collect();
    assert!(common.len() > 20, "{}", common.len());
    // … seen from an axis 3″ further east: a star moves 3″/scale towards +x, west (east is −x at PA 0; the
    // distortion, evaluated 6 px away, changes it by < 0.01 px)
    let shift = 3000.0 / cfg.instrument.plate_scale_mas();
    for id in common {
        let a = sim.stars.iter().find(|s| s.id == id).expect("star");
        let b = plan.stars.iter().find(|s| s.id == id).expect("star");
        assert!(
            (a.x_px - b.x_px - shift).abs() < 0.01 && (a.y_px - b.y_px).abs() < 0.01,
            "star {id}: {:?} against {:?}",
            (a.x_px, a.y_px),
            (b.x_px, b.y_px)
        );
    }
    // the catalogue's pixel columns are the header's: they miss the stars by the offset
    let cat = reference_catalogue(&sim, &SurveyModel::default(), 0);
    let planned = reference_catalogue(&plan, &SurveyModel::default(), 0);
    assert!(!cat.is_empty());
    for c in &cat {
        if let Some(q) = planned.iter().find(|q| q.id == c.id) {
            // the survey's errors are the same draws; the pixel columns are where the plan puts the star
            assert!(
                (c.x_px - q.x_px).abs() < 1e-3 && (c.y_px - q.y_px).abs() < 1e-3,
                "{c:?} against {q:?}"
            );
        }
    }
}

/// The orbit's focus breathing is tracked exposure by exposure: two exposures half an orbit apart see the
/// as-built focus at +A and −A (60 nm of Z4 breathing about the design), and the design PSF corrected by each
/// exposure's own stars (`design-fitted`) lies closer to that exposure's as-built PSF than to the other's
/// (by at least half), and closer than the design PSF itself.
#[test]
fn the_design_fitted_psf_follows_the_focus_breathing() {
    use engine::analysis::epsf::Epsf;
    let mut c = common::noise_free_rolling();
    c.as_built.focus_breathing_nm = 60.0;
    // the drawn phase: of two starts a quarter orbit apart, the one where the focus is furthest off (≥ A/√2)
    let focus_nm = |c: &Config| {
        let built = engine::instrument::realise(c).expect("as built");
        let um = |f: &[f64]| engine::optics::to_um(&c.optics, f)[3];
        (um(&built.optics.field_table[0].fringe) - um(&c.optics.fringe))
            * 1e3
            * engine::optics::zernike::fringe_norm(4).sqrt()
    };
    let at = |start: &str| {
        let mut d = c.clone();
        d.observation.start_utc = start.into();
        d
    };
    let [a, b] = [
        ["2031-03-21T00:00:00", "2031-03-21T00:48:21"],
        ["2031-03-21T00:24:10.5", "2031-03-21T01:12:31.5"],
    ]
    .into_iter()
    .map(|[x, y]| [at(x), at(y)])
    .max_by(|p, q| focus_nm(&p[0]).abs().total_cmp(&focus_nm(&q[0]).abs()))
    .expect("a pair");
    let (fa, fb) = (focus_nm(&a), focus_nm(&b));
    eprintln!("as-built focus: {fa:.1} and {fb:.1} nm rms");
    assert!(fa.abs() > 40.0 && (fa + fb).abs() < 1.0, "{fa} {fb}");
    let fitted_and_truth = |cfg: &Config| {
        let sim = Simulator::new(cfg).expect("sim");
        let (w, psi0) = design_fitted(&sim, cfg);
        let kernel = sim.optical_kernel().expect("as-built kernel");
        let mut truth = Epsf::from_fn(8, cfg.analysis.epsf_radius_px, |x, y| kernel.eval(x, y));
        truth.normalise();
        (w.profile, truth, psi0)
    };
    let (pa, ta, design) = fitted_and_truth(&a);
    let (pb, tb, _) = fitted_and_truth(&b);
    let d = common::profile_rms_of_peak;
    let (aa, ab, bb, ba) = (d(&pa, &ta), d(&pa, &tb), d(&pb, &tb), d(&pb, &ta));
    let (design_a, design_b) = (d(&design, &ta), d(&design, &tb));
    eprintln!(
        "fitted at the first: {aa:.4} from its own, {ab:.4} from the other's; at the second: {bb:.4}, {ba:.4}; the design: \
         {design_a:.4}, {design_b:.4}"
    );
    assert!(aa < 0.5 * ab && bb < 0.5 * ba, "{aa} {ab} {bb} {ba}");
    assert!(
        aa < design_a && bb < design_b,
        "{aa} {design_a} {bb} {design_b}"
    );
}

/// A plate model referenced to the catalogue gives positions in the catalogue's frame (the header's design
/// WCS), and is scored in it: with the as-built pointing 3″ off and turned 60″, which the header does not
/// know, `plate-poly:3@catalogue` under a static jitter is as good as the fits it corrects (within 10 %: 3.04
/// against 3.24 mas; scored in the image's frame it read 18.6 mas).
#[test]
fn the_catalogue_plate_model_is_scored_in_the_catalogues_frame() {
    use engine::analysis::countermeasures::Plan;
    let mut c = small_config();
    c.ace.case = engine::config::AceCase::Gaussian;
    c.fidelity.images = 2;
    c.as_built.pointing_offset_arcsec = [3.0, -2.0];
    c.as_built.roll_offset_arcsec = 60.0;
    c.validate().expect("valid");
    let plan = Plan::new(vec![
        "none".parse().expect("none"),
        "plate-poly:3@catalogue".parse().expect("plate"),
    ])
    .expect("plan");
    let sim = Simulator::new(&c).expect("sim");
    let (rows, _) = engine::studies::experiment::run_dataset(&sim, &plan, &mut |_| {
        std::ops::ControlFlow::Continue(())
    })
    .expect("dataset");
    let acc = |cm: &str| {
        rows.iter()
            .find(|r| r.countermeasure == cm)
            .map(|r| r.accuracy_mas)
            .expect("a row")
    };
    let (none, plate) = (acc("none"), acc("plate-poly:3@catalogue"));
    eprintln!("none {none:.3} mas, plate-poly:3@catalogue {plate:.3} mas");
    assert!(plate < 1.1 * none, "{plate} against {none} mas");
}

/// The design's PSFs — the model PSF and its derivative planes — are computed once for all the exposures of
/// a sequence, though each exposure's as-built focus is its own (the breathing over the orbit): a PSF is
/// keyed by its wavefront, and the design's bank shares the images' store (it had one of its own per
/// simulator, so every exposure of a sequence and every array of a focal plane computed them again: a third
/// of a sequence's time, in the PSF's matrix products).
#[test]
fn the_exposures_of_a_sequence_compute_the_design_psfs_once() {
    let mut cfg = deviating(Knowledge::Design, 0.0);
    cfg.as_built.focus_breathing_nm = 10.0;
    cfg.optics.pupil_samples = 64;
    cfg.ace.case = engine::config::AceCase::Gaussian;
    let mut later = cfg.clone();
    // a quarter of an orbit on: the breathing has moved the focus
    later.ace.first_exposure_start_s += 1450.0;
    let optics = |c: &Config| engine::instrument::realise(c).expect("as built").optics;
    assert!(
        optics(&cfg) != optics(&later),
        "the two exposures' as-built wavefronts differ"
    );
    let session = engine::session::Session::new();
    let first = session.new_simulator(&cfg).expect("first exposure");
    let second = session.new_simulator(&later).expect("second exposure");
    let store = first.bank();
    assert!(store.shares_with(&second.bank()));
    let before = store.monochromatic_sets_built();
    let kernel = first.design_kernel().expect("design kernel");
    let terms = first.design_term_kernels().expect("term kernels").len();
    let built = store.monochromatic_sets_built() - before;
    assert_eq!(
        built,
        1 + 2 * terms,
        "the design PSF and its ± term PSFs go into the images' store"
    );
    let again = second.design_kernel().expect("design kernel");
    second.design_term_kernels().expect("term kernels");
    assert_eq!(
        store.monochromatic_sets_built() - before,
        built,
        "the second exposure computes no design PSF"
    );
    assert_eq!(kernel.data, again.data);
}
