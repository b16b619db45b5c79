//! The as-built instrument against independent measures: the wavefront deviation's rms integrated over the
//! unit disk (not from the polynomials' norms), the distortion's displacement evaluated through the SIP
//! polynomials, the gain's spread over many instruments against the log-normal's moments.

use super::*;
use crate::config::{AsBuilt, Knowledge};

fn deviating(a: AsBuilt) -> Config {
    let mut c = Config::default();
    c.as_built = a;
    c
}

/// RMS over the unit disk of a coefficient list (µm), by a midpoint polar quadrature of the wavefront.
fn rms_by_quadrature_um(coeffs: &[f64]) -> f64 {
    let (nr, nt) = (400, 256);
    let (mut s2, mut area) = (0.0, 0.0);
    for i in 0..nr {
        let rho = (i as f64 + 0.5) / nr as f64;
        for k in 0..nt {
            let th = std::f64::consts::TAU * (k as f64 + 0.5) / nt as f64;
            let w = crate::optics::zernike::wavefront(coeffs, rho, th);
            s2 += w * w * rho;
            area += rho;
        }
    }
    (s2 / area).sqrt()
}

/// The as-built minus the design wavefront (µm OPD) at a detector position.
fn deviation_um(design: &Config, built: &Config, x: f64, y: f64) -> Vec<f64> {
    let grid = crate::optics::field::grid_of(&built.optics)
        .expect("a grid")
        .expect("a table");
    let b = grid.at(x, y);
    let d = crate::optics::to_um(&design.optics, &design.optics.fringe);
    b.iter()
        .zip(d.iter().chain(std::iter::repeat(&0.0)))
        .map(|(b, d)| b - d)
        .collect()
}

#[test]
fn without_deviations_the_built_instrument_is_the_design_bit_for_bit() {
    let c = deviating(AsBuilt::design());
    assert_eq!(realise(&c).expect("realise"), c);
    let mut seeded = c.clone();
    seeded.as_built.seed = 77;
    assert_eq!(realise(&seeded).expect("realise"), seeded);
}

#[test]
fn the_wavefront_deviation_has_the_rms_asked_for_at_the_centre_and_across_the_field() {
    let design = deviating(AsBuilt {
        wavefront_rms_nm: 30.0,
        wavefront_field_rms_nm: 20.0,
        ..AsBuilt::design()
    });
    let built = realise(&design).expect("realise");
    let n = design.instrument.detector_px as f64;
    let c = (n - 1.0) / 2.0;
    let centre = rms_by_quadrature_um(&deviation_um(&design, &built, c, c)) * 1e3;
    assert!((centre - 30.0).abs() < 0.05, "centre: {centre} nm rms");
    // only Z4–Z11 change
    let dev = deviation_um(&design, &built, c, c);
    assert!(
        dev[..3].iter().chain(&dev[11..]).all(|v| *v == 0.0),
        "{dev:?}"
    );
    // the field part: the change from the centre, rms over the four corners, is the knob
    let ms = [
        (0.0, 0.0),
        (n - 1.0, 0.0),
        (0.0, n - 1.0),
        (n - 1.0, n - 1.0),
    ]
    .iter()
    .map(|&(x, y)| {
        let d: Vec<f64> = deviation_um(&design, &built, x, y)
            .iter()
            .zip(&dev)
            .map(|(a, b)| a - b)
            .collect();
        (rms_by_quadrature_um(&d) * 1e3).powi(2)
    })
    .sum::<f64>()
        / 4.0;
    assert!(
        (ms.sqrt() - 20.0).abs() < 0.05,
        "field: {} nm rms",
        ms.sqrt()
    );
}

#[test]
fn realising_twice_changes_nothing_and_the_seed_is_the_instruments_own() {
    let mut design = deviating(AsBuilt {
        wavefront_rms_nm: 30.0,
        focus_breathing_nm: 10.0,
        distortion_px: 0.03,
        gain_error: 0.01,
        read_noise_error: 0.05,
        ..AsBuilt::design()
    });
    let built = realise(&design).expect("realise");
    assert_eq!(realise(&built).expect("again"), built);
    assert_ne!(built.optics, design.optics);
    // another run seed (another exposure of a sequence): the same instrument
    design.seed += 1;
    let other = realise(&design).expect("realise");
    assert_eq!(other.optics, built.optics);
    assert_eq!(other.focal_plane, built.focal_plane);
    assert_eq!(other.detector, built.detector);
    // another instrument seed: another instrument
    design.as_built.seed += 1;
    assert_ne!(realise(&design).expect("realise").optics, built.optics);
}

#[test]
fn the_distortion_beyond_the_design_has_the_asked_length_at_the_corners() {
    let design = deviating(AsBuilt {
        distortion_px: 0.04,
        ..AsBuilt::design()
    });
    let built = realise(&design).expect("realise");
    let (d, b) = (
        crate::sky::distortion(&design).expect("design SIP"),
        crate::sky::distortion(&built).expect("built SIP"),
    );
    let h = (design.instrument.detector_px as f64 - 1.0) / 2.0;
    let ms = [(h, h), (-h, h), (h, -h), (-h, -h)]
        .iter()
        .map(|&(u, v)| {
            let dx = b.a.eval(u, v) - d.a.eval(u, v);
            let dy = b.b.eval(u, v) - d.b.eval(u, v);
            dx * dx + dy * dy
        })
        .sum::<f64>()
        / 4.0;
    assert!((ms.sqrt() - 0.04).abs() < 1e-9, "{}", ms.sqrt());
    // the design's own terms are kept
    for t in &design.focal_plane.sip_a {
        assert!(built.focal_plane.sip_a.contains(t), "{t:?}");
    }
}

#[test]
fn gains_of_many_instruments_spread_as_the_log_normal_asked_for() {
    // 2000 instruments: the standard deviation of ln(gain/design) estimates σ with a relative error of
    // 1/√(2·2000) = 1.6 %; the check allows 5 % (3σ)
    let sigma = 0.05;
    let logs: Vec<f64> = (0..2000)
        .map(|s| {
            let design = deviating(AsBuilt {
                seed: s,
                gain_error: sigma,
                ..AsBuilt::design()
            });
            let built = realise(&design).expect("realise");
            (built.detector.gain_e_per_adu / design.detector.gain_e_per_adu).ln()
        })
        .collect();
    let mean = logs.iter().sum::<f64>() / logs.len() as f64;
    let sd =
        (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (logs.len() - 1) as f64).sqrt();
    assert!((sd / sigma - 1.0).abs() < 0.05, "sd {sd}");
    assert!(
        mean.abs() < 3.0 * sigma / (logs.len() as f64).sqrt(),
        "mean {mean}"
    );
}

#[test]
fn the_focus_breathes_with_the_orbit() {
    let mut design = deviating(AsBuilt {
        focus_breathing_nm: 10.0,
        ..AsBuilt::design()
    });
    let z4_nm = |cfg: &Config| {
        let built = realise(cfg).expect("realise");
        let n = cfg.instrument.detector_px as f64;
        deviation_um(cfg, &built, n / 2.0, n / 2.0)[3] * 1e3 * (1.0f64 / 3.0).sqrt()
    };
    // sampled over one period: the rms of a sinusoid of amplitude A is A/√2, its mean 0
    let period = design.as_built.breathing_period_s;
    let samples: Vec<f64> = (0..32)
        .map(|k| {
            design.ace.first_exposure_start_s = period * k as f64 / 32.0;
            z4_nm(&design)
        })
        .collect();
    let rms = (samples.iter().map(|v| v * v).sum::<f64>() / 32.0).sqrt();
    let mean = samples.iter().sum::<f64>() / 32.0;
    assert!((rms - 10.0 / 2f64.sqrt()).abs() < 1e-3, "rms {rms}");
    assert!(mean.abs() < 1e-3, "mean {mean}");
}

#[test]
fn the_products_come_from_the_design_unless_the_oracle_is_asked_for_by_name() {
    let mut design = deviating(AsBuilt {
        wavefront_rms_nm: 30.0,
        ..AsBuilt::design()
    });
    let built = realise(&design).expect("realise");
    assert_eq!(products_config(&design, &built), design);
    design.as_built.knowledge = Knowledge::AsBuilt;
    let built = realise(&design).expect("realise");
    assert_eq!(products_config(&design, &built), built);
    assert_eq!(design_of(&design).as_built, AsBuilt::design());
}
