//! ACE time series from the PSD (SPEC §3), two independent axes.
//!
//! For N samples at interval Δt the one-sided frequencies are `f_k = k/(NΔt)`; each gets the Fourier
//! amplitude `s_k = √PSD(f_k)·(1 + a·z_k)` (z ~ N(0,1), `a = ace.amplitude_noise`) and a uniform random
//! phase; the spectrum is made Hermitian (DC = 0, Nyquist real) and inverse-FFT'd to a real series. The
//! series is then scaled to `ace.sigma_mas` under one of two conventions, recorded in every output:
//! the σ of the whole series, or the median over exposures of the per-exposure σ (the paper's realistic case).
//! A zero PSD or σ = 0 gives a still telescope (all zeros), never NaN.

use crate::config::{Config, SigmaConvention};
use crate::jitter::psd::Psd;
use crate::numerics::stats;
use crate::readout::ReadoutTiming;
use crate::rng::{self, Stream};
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use rustfft::{FftPlanner, num_complex::Complex64};

/// A two-axis ACE series in mas on a regular time grid starting at t = 0.
#[derive(Debug, Clone, PartialEq)]
pub struct AceSeries {
    pub dt_s: f64,
    pub x_mas: Vec<f64>,
    pub y_mas: Vec<f64>,
    /// The scaling convention that was applied.
    pub convention: SigmaConvention,
    /// The achieved σ under that convention, per axis (mas).
    pub achieved_sigma_mas: (f64, f64),
}

/// One axis: random Fourier amplitudes and phases, inverse FFT (unscaled).
pub fn raw_axis(
    psd: &Psd,
    n: usize,
    dt_s: f64,
    amplitude_noise: f64,
    rng: &mut rng::Rng,
) -> Vec<f64> {
    if n < 2 {
        return vec![0.0; n];
    }
    let df = 1.0 / (n as f64 * dt_s);
    let mut spec = vec![Complex64::default(); n];
    for k in 1..=n / 2 {
        let z: f64 = StandardNormal.sample(rng);
        let amp = psd.eval(k as f64 * df).max(0.0).sqrt() * (1.0 + amplitude_noise * z);
        let phase = rng.random::<f64>() * std::f64::consts::TAU;
        if 2 * k == n {
            spec[k] = Complex64::new(amp * phase.cos(), 0.0);
        } else {
            spec[k] = Complex64::from_polar(amp, phase);
            spec[n - k] = spec[k].conj();
        }
    }
    FftPlanner::<f64>::new()
        .plan_fft_inverse(n)
        .process(&mut spec);
    spec.into_iter().map(|c| c.re).collect()
}

/// Exposure windows (start index, length in samples) used for the per-exposure statistics: the nominal
/// `[t_start + t_overhead, + T]` window of every whole exposure cycle that fits in the series.
pub fn exposure_windows(cfg: &Config, n: usize, dt_s: f64) -> Vec<(usize, usize)> {
    let timing = ReadoutTiming::new(cfg);
    let cadence = timing.cadence_s();
    let len = (cfg.detector.exposure_s / dt_s).round() as usize;
    let mut out = Vec::new();
    let mut i = 0usize;
    loop {
        let t0 = cfg.ace.first_exposure_start_s + i as f64 * cadence + timing.t_overhead_s;
        let s = (t0 / dt_s).round() as usize;
        if s + len > n || len == 0 {
            break;
        }
        out.push((s, len));
        i += 1;
        if i > 1_000_000 {
            break;
        }
    }
    out
}

/// Median over exposure windows of the per-window standard deviation.
pub fn median_exposure_sigma(v: &[f64], windows: &[(usize, usize)]) -> f64 {
    let s: Vec<f64> = windows
        .iter()
        .map(|&(a, l)| stats::std_dev(&v[a..a + l]))
        .collect();
    stats::median(&s)
}

fn scale_axis(
    v: &mut [f64],
    target: f64,
    convention: SigmaConvention,
    windows: &[(usize, usize)],
) -> f64 {
    let current = match convention {
        SigmaConvention::WholeSeries => stats::std_dev(v),
        SigmaConvention::MedianExposure => median_exposure_sigma(v, windows),
    };
    if !(current > 0.0) || !(target > 0.0) {
        v.iter_mut().for_each(|x| *x = 0.0);
        return 0.0;
    }
    let f = target / current;
    v.iter_mut().for_each(|x| *x *= f);
    target
}

impl AceSeries {
    /// Generate the series of `cfg.ace` with the run seed and series index (0 for a plain run; sweeps
    /// use their unit index). x and y use independent streams.
    pub fn generate(cfg: &Config, seed: u64, index: u64) -> Self {
        let a = &cfg.ace;
        let dt = a.sample_interval_ms * 1e-3;
        let n = (a.span_s / dt).round() as usize;
        let psd = Psd::from_config(a);
        let mut x = raw_axis(
            &psd,
            n,
            dt,
            a.amplitude_noise,
            &mut rng::stream(seed, Stream::AceX, index),
        );
        let mut y = raw_axis(
            &psd,
            n,
            dt,
            a.amplitude_noise,
            &mut rng::stream(seed, Stream::AceY, index),
        );
        let windows = exposure_windows(cfg, n, dt);
        let sx = scale_axis(&mut x, a.sigma_mas, a.sigma_convention, &windows);
        let sy = scale_axis(&mut y, a.sigma_mas, a.sigma_convention, &windows);
        Self {
            dt_s: dt,
            x_mas: x,
            y_mas: y,
            convention: a.sigma_convention,
            achieved_sigma_mas: (sx, sy),
        }
    }

    /// A still telescope of `n` samples.
    pub fn still(dt_s: f64, n: usize) -> Self {
        Self {
            dt_s,
            x_mas: vec![0.0; n],
            y_mas: vec![0.0; n],
            convention: SigmaConvention::WholeSeries,
            achieved_sigma_mas: (0.0, 0.0),
        }
    }

    pub fn len(&self) -> usize {
        self.x_mas.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x_mas.is_empty()
    }

    /// Duration covered, seconds.
    pub fn span_s(&self) -> f64 {
        self.len() as f64 * self.dt_s
    }

    /// Mean and standard deviation of each axis over `[t0, t1)` (mas).
    pub fn window_stats(&self, t0_s: f64, t1_s: f64) -> ((f64, f64), (f64, f64)) {
        let a = ((t0_s / self.dt_s).round().max(0.0) as usize).min(self.len());
        let b = ((t1_s / self.dt_s).round().max(0.0) as usize)
            .min(self.len())
            .max(a);
        let (xs, ys) = (&self.x_mas[a..b], &self.y_mas[a..b]);
        (
            (stats::mean(xs), stats::std_dev(xs)),
            (stats::mean(ys), stats::std_dev(ys)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::AceCase;

    fn small_cfg() -> Config {
        let mut c = Config::default();
        c.ace.case = AceCase::Realistic;
        c.ace.sample_interval_ms = 1.0;
        c.ace.span_s = 300.0;
        c
    }

    #[test]
    fn same_seed_same_series_and_axes_independent() {
        let c = small_cfg();
        let a = AceSeries::generate(&c, 11, 0);
        let b = AceSeries::generate(&c, 11, 0);
        assert_eq!(a, b);
        let d = AceSeries::generate(&c, 12, 0);
        assert_ne!(a.x_mas, d.x_mas);
        assert!(stats::correlation(&a.x_mas, &a.y_mas).abs() < 0.5);
    }

    #[test]
    fn requested_sigma_reached() {
        let mut c = small_cfg();
        let a = AceSeries::generate(&c, 3, 0);
        // the exposures, from the SPEC's timing written out here (not the scaling's own windows): back to
        // back, each t_overhead + W·rows·t_pix + T long, integrating [start + t_overhead, + T)
        let (t_ov, t_exp) = (c.readout.t_overhead_s, c.detector.exposure_s);
        let sweep = 123.0 * 1968.0 * 5e-6; // W = 123 columns × 1968 rows × 5 µs
        assert!((sweep - c.frame_sweep_s()).abs() < 1e-12);
        let cadence = t_ov + sweep + t_exp;
        let mut sigmas = Vec::new();
        for k in 0.. {
            let t0 = c.ace.first_exposure_start_s + k as f64 * cadence + t_ov;
            let (i0, i1) = (
                (t0 / a.dt_s).round() as usize,
                ((t0 + t_exp) / a.dt_s).round() as usize,
            );
            if i1 > a.len() {
                break;
            }
            let x = &a.x_mas[i0..i1];
            let m = x.iter().sum::<f64>() / x.len() as f64;
            let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
            sigmas.push(var.sqrt());
        }
        assert!(sigmas.len() >= 20, "{} exposures", sigmas.len());
        sigmas.sort_by(f64::total_cmp);
        let n = sigmas.len();
        let median = if n % 2 == 1 {
            sigmas[n / 2]
        } else {
            0.5 * (sigmas[n / 2 - 1] + sigmas[n / 2])
        };
        assert!(
            (median / 300.0 - 1.0).abs() < 1e-9,
            "median exposure σ {median}"
        );
        c.ace.sigma_convention = SigmaConvention::WholeSeries;
        let b = AceSeries::generate(&c, 3, 0);
        let s = stats::std_dev(&b.y_mas);
        assert!((s / 300.0 - 1.0).abs() < 1e-9, "whole-series σ {s}");
    }

    #[test]
    fn zero_power_or_zero_sigma_is_still_not_nan() {
        let mut c = small_cfg();
        c.ace.sigma_mas = 0.0;
        let a = AceSeries::generate(&c, 1, 0);
        assert!(a.x_mas.iter().chain(&a.y_mas).all(|v| *v == 0.0));
        let mut c = small_cfg();
        c.ace.continuum_amplitude = 0.0;
        c.ace.modes.clear();
        let b = AceSeries::generate(&c, 1, 0);
        assert!(b.x_mas.iter().all(|v| *v == 0.0));
    }

    #[test]
    fn per_exposure_sigma_varies_around_the_median() {
        let c = small_cfg();
        let a = AceSeries::generate(&c, 5, 0);
        let w = exposure_windows(&c, a.len(), a.dt_s);
        let s: Vec<f64> = w
            .iter()
            .map(|&(i, l)| stats::std_dev(&a.x_mas[i..i + l]) / 300.0)
            .collect();
        let (lo, hi) = (stats::quantile(&s, 0.0), stats::quantile(&s, 1.0));
        assert!(
            lo < 0.95 && hi > 1.05,
            "per-exposure σ range {lo:.2}–{hi:.2} should spread around 1"
        );
    }
}
