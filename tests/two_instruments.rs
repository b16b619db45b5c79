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
        ..AsBuilt::default()
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
