//! Cosmic rays: charged particles crossing the detector during an exposure, each leaving charge along a
//! straight track (`detector.cosmic_ray_rate_per_cm2_s`; 0, the default, switches them off).
//!
//! * Hits: Poisson with mean `rate × A × T` (A the array's area, T the exposure), uniform over the array.
//!   The rate is a knob: the JWST/Roman value at L2 is 8 cm⁻² s⁻¹ (romanisim); in a 600-km sun-synchronous
//!   orbit outside the South Atlantic Anomaly and the polar horns HST sees a few cm⁻² s⁻¹ — 4 is this
//!   tool's suggested value (a choice), the Anomaly itself is orders of magnitude higher.
//! * Direction: isotropic particles crossing a plane, so cos θ = √u (the flux through a surface goes as
//!   cos θ), cut at cos θ ≥ 0.01; φ uniform. The path through the absorber (thickness t,
//!   `detector.absorber_thickness_um`) is t / cos θ (mean ≈ 2t), its projection on the pixels t·tan θ.
//! * Charge: path × `cosmic_ray_e_per_um` × a log-normal of σ = 0.35 and mean 1 (the Landau tail, coarsely),
//!   spread along the projected track in steps of ≤ 0.1 px. Every hit falls inside its pixels' integration
//!   windows (arrival times are not modelled), and reaches only photosensitive pixels.
//! * Flags: a pixel that gains more than 5 × the image's read noise is flagged [`super::dq::COSMIC_RAY`], as
//!   an up-the-ramp jump detection would; the analysis does not use flagged pixels. Smaller deposits stay,
//!   unflagged, in the image.

use crate::config::Config;
use crate::rng::{self, Stream};
use rand::RngExt;
use rand_distr::{Distribution, Poisson, StandardNormal};

/// Log-normal σ of a hit's charge.
pub const CHARGE_SIGMA: f64 = 0.35;
/// Smallest cos θ drawn (grazing tracks longer than 100 thicknesses are cut).
pub const MIN_COS_THETA: f64 = 0.01;

/// The charge the cosmic rays of image `image_index` leave in each pixel (row-major, electrons); `None`
/// when they are switched off.
pub fn deposits(cfg: &Config, image_index: u64) -> Option<Vec<f32>> {
    let d = &cfg.detector;
    if d.cosmic_ray_rate_per_cm2_s <= 0.0 {
        return None;
    }
    let n = cfg.instrument.detector_px;
    let side_cm = n as f64 * cfg.instrument.pixel_pitch_um * 1e-4;
    let mean_hits = d.cosmic_ray_rate_per_cm2_s * side_cm * side_cm * d.exposure_s;
    let mut r = rng::stream(cfg.seed, Stream::CosmicRays, image_index);
    let hits = Poisson::new(mean_hits)
        .map(|p| p.sample(&mut r) as usize)
        .unwrap_or(0);
    let mut out = vec![0.0f32; n * n];
    let t_px = d.absorber_thickness_um / cfg.instrument.pixel_pitch_um;
    for _ in 0..hits {
        let x0 = r.random::<f64>() * n as f64 - 0.5;
        let y0 = r.random::<f64>() * n as f64 - 0.5;
        let cos_t = r.random::<f64>().sqrt().max(MIN_COS_THETA);
        let phi = r.random::<f64>() * std::f64::consts::TAU;
        let z: f64 = StandardNormal.sample(&mut r);
        let path_um = d.absorber_thickness_um / cos_t;
        let charge = path_um
            * d.cosmic_ray_e_per_um
            * (CHARGE_SIGMA * z - CHARGE_SIGMA * CHARGE_SIGMA / 2.0).exp();
        let length_px = t_px * (1.0 - cos_t * cos_t).sqrt() / cos_t;
        let steps = ((length_px / 0.1).ceil() as usize).max(1);
        let per_step = (charge / steps as f64) as f32;
        let (dx, dy) = (phi.cos() * length_px, phi.sin() * length_px);
        for k in 0..steps {
            let f = (k as f64 + 0.5) / steps as f64 - 0.5;
            let (x, y) = ((x0 + f * dx).round(), (y0 + f * dy).round());
            if x < 0.0 || y < 0.0 || x >= n as f64 || y >= n as f64 {
                continue;
            }
            let (x, y) = (x as usize, y as usize);
            if super::photosensitive(cfg, x, y) {
                out[y * n + x] += per_step;
            }
        }
    }
    Some(out)
}

/// The charge above which a pixel is flagged as hit: 5 × the image's read noise.
pub fn flag_threshold_e(cfg: &Config) -> f64 {
    5.0 * cfg.detector.image_read_noise_e()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> Config {
        let mut c = Config::default();
        c.instrument.detector_px = 512;
        c.instrument.photosensitive_px = 512;
        c.detector.cosmic_ray_rate_per_cm2_s = 40.0;
        c
    }

    #[test]
    fn hits_charge_and_track_lengths_follow_the_model() {
        // 40 cm⁻² s⁻¹ × (0.512 cm)² × 12.5 s = 131 hits per image; over 40 images the total charge per hit
        // is e/µm × E[t / cos θ] = 100 × 10 µm × 1.99 (cos θ = √u cut at 0.01: 2(1 − 0.01) + 0.01)
        let c = cfg();
        let (mut total, mut hits_expected) = (0.0f64, 0.0);
        for i in 0..40 {
            let dep = deposits(&c, i).expect("on");
            total += dep.iter().map(|v| *v as f64).sum::<f64>();
            hits_expected += 40.0 * 0.512 * 0.512 * 12.5;
        }
        let per_hit = total / hits_expected;
        let expect = 100.0 * 10.0 * 1.99;
        // the sum's scatter: Poisson in the count (1/√N) and the charge's own spread (heavy: path and
        // log-normal), ≈ 2 % here; 4σ ≈ 8 %, plus the ≤ 1 % lost off the array's edges
        assert!(
            (per_hit / expect - 1.0).abs() < 0.09,
            "{per_hit} e per hit against {expect}"
        );
        // the same image index, the same hits; off by default
        assert_eq!(deposits(&c, 3), deposits(&c, 3));
        assert!(deposits(&Config::default(), 0).is_none());
    }

    #[test]
    fn a_grazing_track_is_long_and_a_normal_one_is_one_pixel() {
        // count the pixels each hit touches: hits near normal incidence (most) touch 1–2 pixels, the
        // mean projected length t·E[tan θ] is of order t (here 1 px) with a long tail
        let mut c = cfg();
        c.detector.cosmic_ray_rate_per_cm2_s = 4.0;
        let dep = deposits(&c, 7).expect("on");
        let touched = dep.iter().filter(|v| **v > 0.0).count();
        let hits = 4.0 * 0.512 * 0.512 * 12.5;
        let per_hit = touched as f64 / hits;
        assert!((1.0..=6.0).contains(&per_hit), "{per_hit} pixels per hit");
        assert!(flag_threshold_e(&c) > 100.0 && flag_threshold_e(&c) < 110.0);
    }
}
