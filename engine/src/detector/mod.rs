//! Detector and electronics (SPEC §1, §4), in this order, per pixel:
//!
//! 1. star electrons × inter-pixel flat (1 + σ·z, z ~ N(0,1), fixed per detector: seeded once);
//! 2. plus (dark + stray light) × the pixel's own integration window (T, or T + its delay under a global
//!    reset: later rows integrate up to one frame sweep longer) — only the photosensitive region sees
//!    light; the border of `(detector_px − photosensitive_px)/2` pixels holds no signal and is read for
//!    noise only;
//!    plus the charge traps release from earlier exposures' bright light ([`persistence`], along a
//!    sequence; not flat-fielded: it is released in the pixel itself);
//! 3. Poisson shot noise on the total, plus the charge of cosmic rays ([`cosmic_rays`], off by default);
//!    charge clipped at the full well (flagged);
//! 4. inter-pixel capacitance ([`ipc`], off by default): each pixel's node sees a fraction of its
//!    neighbours' charge; then the node's nonlinear response N − β N² (off by default; [`linearize`] is
//!    the pipeline's correction);
//! 5. plus Gaussian read noise of the image: √2 × the per-read noise for CDS (two reads differenced),
//!    √(2/N) × for Fowler-N ([`crate::config::Detector::image_read_noise_e`]);
//! 6. ÷ gain + bias, rounded, clipped to `[0, 2^bits − 1]` ADU (flagged).
//!
//! Every stage can be switched off (`shot_noise`, `read_noise`, `digitise`, σ_flat = 0). Noise streams are
//! per image and per row, so the result does not depend on threading.

pub mod chain;
pub mod cosmic_rays;
pub mod ipc;
pub mod persistence;
pub mod window;

use crate::config::Config;
use crate::readout::ReadoutTiming;
use crate::rng::{self, Stream};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

/// Data-quality bits.
pub mod dq {
    /// Outside the photosensitive region.
    pub const BORDER: u8 = 1;
    /// Charge reached the full well.
    pub const SATURATED: u8 = 2;
    /// ADC clipped at its maximum.
    pub const ADC_HIGH: u8 = 4;
    /// ADC clipped at zero.
    pub const ADC_LOW: u8 = 8;
    /// A cosmic ray left more than 5 × the read noise ([`super::cosmic_rays`]).
    pub const COSMIC_RAY: u8 = 16;
    /// The bits that make a pixel unusable for the analysis.
    pub const UNUSABLE: u8 = BORDER | SATURATED | ADC_HIGH | COSMIC_RAY;
}

/// The simulated detector image of one exposure.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorImage {
    pub n: usize,
    /// Pixel values in ADU (rounded when digitised), row-major.
    pub adu: Vec<f32>,
    pub dq: Vec<u8>,
}

/// The inter-pixel flat of the detector (mean 1, σ = `inter_pixel_flat_sigma`), fixed by the seed.
pub fn inter_pixel_flat(cfg: &Config) -> Vec<f32> {
    let n = cfg.instrument.detector_px;
    let sigma = cfg.detector.inter_pixel_flat_sigma;
    let mut flat = vec![1.0f32; n * n];
    if sigma > 0.0 {
        perturb(cfg, Stream::InterPixelFlat, &mut flat, |v, z| {
            (v as f64 * (1.0 + sigma * z)).max(0.0) as f32
        });
    }
    flat
}

/// Each pixel `v` of the `n × n` image replaced by `f(v, z)`, z ~ N(0, 1) from `stream`'s row of the run
/// seed (rows in parallel, the result independent of threading).
fn perturb(cfg: &Config, stream: Stream, image: &mut [f32], f: impl Fn(f32, f64) -> f32 + Sync) {
    let n = cfg.instrument.detector_px;
    image.par_chunks_mut(n).enumerate().for_each(|(y, row)| {
        let mut r = rng::stream(cfg.seed, stream, y as u64);
        for v in row.iter_mut() {
            let z: f64 = StandardNormal.sample(&mut r);
            *v = f(*v, z);
        }
    });
}

/// The calibration flat a pipeline would hold: the true flat with its own relative error `error` (1σ,
/// independent per pixel, from its own stream of the run seed).
pub fn calibration_flat(cfg: &Config, error: f64) -> Vec<f32> {
    calibration_flat_of(cfg, inter_pixel_flat(cfg), error)
}

/// [`calibration_flat`] from the true flat already at hand.
pub fn calibration_flat_of(cfg: &Config, true_flat: Vec<f32>, error: f64) -> Vec<f32> {
    let mut flat = true_flat;
    if error > 0.0 {
        perturb(cfg, Stream::CalibrationFlat, &mut flat, |v, z| {
            (v as f64 * (1.0 + error * z)).max(1e-6) as f32
        });
    }
    flat
}

/// The charge N whose measured value is `measured_e` under the response N − β N² (the smaller root; a
/// linear detector for β = 0): what a pipeline's linearity correction computes with its β̂.
pub fn linearize(measured_e: f64, beta_per_e: f64) -> f64 {
    if beta_per_e <= 0.0 || measured_e <= 0.0 {
        return measured_e;
    }
    let disc = (1.0 - 4.0 * beta_per_e * measured_e).max(0.0);
    // (1 − √disc)/(2β), written to keep precision when 4βm ≪ 1
    2.0 * measured_e / (1.0 + disc.sqrt())
}

/// Is pixel (x, y) photosensitive?
pub fn photosensitive(cfg: &Config, x: usize, y: usize) -> bool {
    let b = cfg.instrument.border_px();
    let n = cfg.instrument.detector_px;
    x >= b && y >= b && x < n - b && y < n - b
}

/// Turn noise-free star electrons into a detector image. `image_index` selects the noise streams;
/// `released_e` is the persistence each pixel collects (e⁻, row-major), if any.
pub fn expose(
    cfg: &Config,
    timing: &ReadoutTiming,
    star_e: &[f64],
    flat: &[f32],
    released_e: Option<&[f32]>,
    image_index: u64,
) -> DetectorImage {
    let n = cfg.instrument.detector_px;
    let d = &cfg.detector;
    let cosmic = cosmic_rays::deposits(cfg, image_index);
    let cosmic_flag_e = cosmic_rays::flag_threshold_e(cfg);
    let stream_index = |y: usize| image_index.wrapping_mul(1 << 20) + y as u64;
    // the charge each pixel collects: signal and dark with shot noise, cosmic rays, the full well
    let mut charge = vec![0.0f64; n * n];
    let mut dqv = vec![0u8; n * n];
    charge
        .par_chunks_mut(n)
        .zip(dqv.par_chunks_mut(n))
        .enumerate()
        .for_each(|(y, (out, dq_row))| {
            let mut shot_rng = rng::stream(cfg.seed, Stream::ShotNoise, stream_index(y));
            for x in 0..n {
                let i = y * n + x;
                let mut flags = 0u8;
                let mean_e = if photosensitive(cfg, x, y) {
                    star_e[i].max(0.0) * flat[i] as f64
                        + d.dark_e_per_s * timing.window_length_s(x, y)
                        + released_e.map_or(0.0, |r| r[i].max(0.0) as f64)
                } else {
                    flags |= dq::BORDER;
                    0.0
                };
                let mut e = chain::shot_e(d, mean_e, &mut shot_rng);
                if let Some(c) = &cosmic {
                    let hit = c[i] as f64;
                    e += hit;
                    if hit > cosmic_flag_e {
                        flags |= dq::COSMIC_RAY;
                    }
                }
                let (e, full) = chain::clip_full_well(e, d.full_well_e);
                if full {
                    flags |= dq::SATURATED;
                }
                out[x] = e;
                dq_row[x] = flags;
            }
        });
    // what each pixel's node sees of its neighbours' charge, and its response to it
    chain::respond(&mut charge, n, d);
    // read noise, gain, bias, the ADC
    let readout = chain::Readout::image(d);
    let mut adu = vec![0.0f32; n * n];
    adu.par_chunks_mut(n)
        .zip(dqv.par_chunks_mut(n))
        .enumerate()
        .for_each(|(y, (out, dq_row))| {
            let mut read_rng = rng::stream(cfg.seed, Stream::ReadNoise, stream_index(y));
            for x in 0..n {
                let (v, flags) = readout.adu(charge[y * n + x], &mut read_rng);
                out[x] = v;
                dq_row[x] |= flags;
            }
        });
    DetectorImage { n, adu, dq: dqv }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::stats;

    fn cfg(n: usize) -> Config {
        let mut c = Config::default();
        c.instrument.detector_px = n;
        c.instrument.photosensitive_px = n;
        c.detector.inter_pixel_flat_sigma = 0.0;
        c
    }

    /// An n × n detector without noise, rounding or dark: the signal alone.
    fn signal_only(n: usize) -> Config {
        let mut c = cfg(n);
        c.detector.shot_noise = false;
        c.detector.read_noise = false;
        c.detector.digitise = false;
        c.detector.dark_e_per_s = 0.0;
        c
    }

    fn expose(c: &Config, star_e: &[f64], flat: &[f32], index: u64) -> DetectorImage {
        super::expose(c, &ReadoutTiming::new(c), star_e, flat, None, index)
    }

    fn moments(img: &DetectorImage) -> (f64, f64) {
        let v: Vec<f64> = img.adu.iter().map(|x| *x as f64).collect();
        (stats::mean(&v), stats::std_dev(&v).powi(2))
    }

    #[test]
    fn noise_moments_match_theory_term_by_term() {
        let n = 400; // 160 000 pixels: σ(mean)/mean ≈ 0.2 %, σ(var)/var ≈ 0.35 %
        let g = 3.0;
        let dark = 24.5 * 12.5; // 306.25 e⁻
        let zero = vec![0.0; n * n];
        let flat = vec![1.0f32; n * n];
        // shot noise only, no rounding: mean = dark/g, var = dark/g²
        let mut c = cfg(n);
        c.detector.read_noise = false;
        c.detector.digitise = false;
        let (m, v) = moments(&expose(&c, &zero, &flat, 0));
        assert!(
            (m - dark / g).abs() < 4.0 * (dark.sqrt() / g) / n as f64,
            "shot mean {m}"
        );
        assert!((v / (dark / g / g) - 1.0).abs() < 0.015, "shot var {v}");
        // read noise only: var = (√2·15)²/g² (CDS: the difference of two reads)
        let mut c = cfg(n);
        c.detector.shot_noise = false;
        c.detector.digitise = false;
        let (m, v) = moments(&expose(&c, &zero, &flat, 1));
        assert!((m - dark / g).abs() < 4.0 * 5.0 / n as f64, "read mean {m}");
        assert!((v / (450.0 / g / g) - 1.0).abs() < 0.015, "read var {v}");
        // everything, digitised: var = (dark + 2·rn²)/g² + 1/12 (quantisation)
        let c = cfg(n);
        let (m, v) = moments(&expose(&c, &zero, &flat, 2));
        let expect = (dark + 450.0) / g / g + 1.0 / 12.0;
        assert!((m - dark / g).abs() < 0.05, "mean {m}");
        assert!((v / expect - 1.0).abs() < 0.015, "var {v} vs {expect}");
    }

    #[test]
    fn flat_field_has_the_requested_sigma_and_is_reproducible() {
        let mut c = cfg(300);
        c.detector.inter_pixel_flat_sigma = 0.01;
        let f = inter_pixel_flat(&c);
        let v: Vec<f64> = f.iter().map(|x| *x as f64).collect();
        assert!((stats::mean(&v) - 1.0).abs() < 1e-4);
        assert!((stats::std_dev(&v) / 0.01 - 1.0).abs() < 0.02);
        assert_eq!(f, inter_pixel_flat(&c));
    }

    #[test]
    fn saturation_clips_and_flags() {
        let n = 16;
        let mut c = cfg(n);
        c.detector.shot_noise = false;
        c.detector.read_noise = false;
        let mut star = vec![0.0; n * n];
        star[5 * n + 5] = 1e6;
        let img = expose(&c, &star, &vec![1.0; n * n], 0);
        assert_eq!(img.adu[5 * n + 5], (150_000.0f64 / 3.0).round() as f32);
        assert!(img.dq[5 * n + 5] & dq::SATURATED != 0);
        // a 12-bit ADC clips at 4095 and flags it
        c.detector.adc_bits = 12;
        let img = expose(&c, &star, &vec![1.0; n * n], 0);
        assert_eq!(img.adu[5 * n + 5], 4095.0);
        assert!(img.dq[5 * n + 5] & dq::ADC_HIGH != 0);
        assert_eq!(img.dq[0], 0);
    }

    #[test]
    fn border_sees_no_light_and_same_seed_same_image() {
        let mut c = cfg(40);
        c.instrument.photosensitive_px = 24;
        let star = vec![1000.0; 40 * 40];
        let flat = vec![1.0f32; 40 * 40];
        let a = expose(&c, &star, &flat, 3);
        assert!(a.dq[0] & dq::BORDER != 0 && a.dq[20 * 40 + 20] & dq::BORDER == 0);
        assert!(a.adu[0] < 30.0 && a.adu[20 * 40 + 20] > 300.0);
        assert_eq!(a, expose(&c, &star, &flat, 3));
        assert_ne!(a, expose(&c, &star, &flat, 4));
    }

    #[test]
    fn flux_conserved_before_noise() {
        let n = 32;
        let c = signal_only(n);
        let star: Vec<f64> = (0..n * n).map(|i| (i % 7) as f64 * 3.0).collect();
        let img = expose(&c, &star, &vec![1.0; n * n], 0);
        let tot: f64 = img.adu.iter().map(|v| *v as f64 * 3.0).sum();
        assert!((tot - star.iter().sum::<f64>()).abs() < 1e-3);
    }

    #[test]
    fn the_response_bends_as_stated_and_the_correction_undoes_it() {
        // noise-free pixels of 0 … 1.5e5 e⁻ under β = 2e-7: measured = N − βN² (2 % low at 1e5 e⁻, 3 % at
        // the full well); linearize with the same β gives N back to 1e-6 e⁻, with a 5 % wrong β̂ the
        // residual is 5 % of the bend (≈ 0.1 % at 1e5 e⁻)
        let n = 32;
        let mut c = signal_only(n);
        c.detector.nonlinearity_per_e = 2e-7;
        let star: Vec<f64> = (0..n * n)
            .map(|i| i as f64 / (n * n) as f64 * 1.5e5)
            .collect();
        let img = expose(&c, &star, &vec![1.0; n * n], 0);
        for (i, (a, s)) in img.adu.iter().zip(&star).enumerate() {
            let m = *a as f64 * 3.0;
            let expect = s - 2e-7 * s * s;
            assert!(
                (m - expect).abs() < 1e-6 * s.max(1.0) + 0.02,
                "pixel {i}: {m} vs {expect}"
            );
            let back = linearize(m, 2e-7);
            assert!((back - s).abs() < 1e-6 * s.max(1.0) + 0.03, "{back} vs {s}");
            let off = linearize(m, 2e-7 * 1.05);
            let bend = 2e-7 * s * s;
            assert!(
                (off - s - 0.05 * bend).abs() < 0.01 * bend + 0.05,
                "{off} vs {s}: {}",
                off - s
            );
        }
        assert_eq!(linearize(1234.5, 0.0), 1234.5);
    }

    #[test]
    fn dark_accumulates_over_each_pixels_own_window_under_a_global_reset() {
        // SPEC §4: under a global reset every pixel starts at t_overhead and stops at its first read + T, so
        // the pixel read last integrates (rows − 1)·W + (W − 1) pixel times longer than the first one
        let n = 64;
        let mut c = cfg(n);
        c.readout.channel_width_px = 16;
        c.detector.shot_noise = false;
        c.detector.read_noise = false;
        c.detector.digitise = false;
        c.detector.dark_e_per_s = 1000.0; // 15 pixel times = 0.075 e⁻, well above the f32 rounding
        let zero = vec![0.0; n * n];
        let flat = vec![1.0f32; n * n];
        let g = c.detector.gain_e_per_adu;
        let rate = c.detector.dark_e_per_s;
        let t_pix = c.readout.pixel_time_us * 1e-6;
        let bias = c.detector.bias_adu;
        // electrons back from the f32 ADU value (its rounding: ≤ 2e-3 e⁻ here)
        let dark_of =
            |img: &DetectorImage, x: usize, y: usize| (img.adu[y * n + x] as f64 - bias) * g;
        let rolling = expose(&c, &zero, &flat, 0);
        c.readout.order = crate::config::ReadoutOrder::GlobalReset;
        let global = expose(&c, &zero, &flat, 0);
        let t = c.detector.exposure_s;
        for (x, y) in [(0, 0), (15, 0), (16, 0), (3, 40), (15, 63)] {
            let r = dark_of(&rolling, x, y);
            assert!((r - rate * t).abs() < 4e-3, "rolling ({x}, {y}): {r}");
            let delay = ((y * 16 + x % 16) as f64) * t_pix;
            let got = dark_of(&global, x, y);
            assert!(
                (got - rate * (t + delay)).abs() < 4e-3,
                "({x}, {y}): {got} e⁻, expected {}",
                rate * (t + delay)
            );
        }
    }
}
