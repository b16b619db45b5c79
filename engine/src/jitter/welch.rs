//! Welch's averaged, Hann-windowed periodogram (one-sided, units² per Hz), to compare a generated series
//! with the PSD it came from.
//!
//! The model PSD ([`crate::jitter::Psd`]) is in arbitrary units, and a series in mas: to put one on the
//! other, [`model_gain`] gives the factor (mas²/Hz per model unit) that the generator applied, and
//! [`welch_in_model_units`] the estimate divided by it. The factor comes from how the series was made, not
//! from fitting the estimate to the model, so a wrong amplitude in any band shows.

use crate::config::Ace;
use crate::jitter::psd::Psd;
use crate::jitter::series::{AceSeries, raw_axis};
use crate::rng::{self, Stream};
use rustfft::{FftPlanner, num_complex::Complex64};

/// One axis of an ACE series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    X,
    Y,
}

/// One-sided PSD estimate `(f_hz, psd)` with segments of `seg_len` samples, 50 % overlap, Hann window.
/// Normalised so that `Σ psd·Δf` equals the variance of the (mean-removed) series.
pub fn welch(x: &[f64], dt_s: f64, seg_len: usize) -> Vec<(f64, f64)> {
    let l = seg_len.min(x.len());
    if l < 4 {
        return Vec::new();
    }
    let hop = l / 2;
    let w: Vec<f64> = (0..l)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / l as f64).cos())
        .collect();
    let w2: f64 = w.iter().map(|v| v * v).sum();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(l);
    let mut acc = vec![0.0; l / 2 + 1];
    let mut count = 0usize;
    let mut start = 0usize;
    let mut buf = vec![Complex64::default(); l];
    while start + l <= x.len() {
        let seg = &x[start..start + l];
        let mean = seg.iter().sum::<f64>() / l as f64;
        for i in 0..l {
            buf[i] = Complex64::new((seg[i] - mean) * w[i], 0.0);
        }
        fft.process(&mut buf);
        for (k, a) in acc.iter_mut().enumerate() {
            *a += buf[k].norm_sqr();
        }
        count += 1;
        start += hop;
    }
    let fs = 1.0 / dt_s;
    let df = fs / l as f64;
    acc.iter()
        .enumerate()
        .map(|(k, a)| {
            let one_sided = if k == 0 || 2 * k == l { 1.0 } else { 2.0 };
            (k as f64 * df, one_sided * a / (count as f64 * fs * w2))
        })
        .collect()
}

/// The factor, in mas²/Hz per model unit, between the expected one-sided PSD of one axis of `series` and the
/// model PSD of `ace` it was generated from: `E[welch(axis)](f) = gain · Psd::from_config(ace).eval(f)`.
///
/// [`raw_axis`] gives frequency `f_k = k/(NΔt)` the Fourier amplitude `√PSD(f_k)·(1 + a·z_k)` (a =
/// `ace.amplitude_noise`, z ~ N(0, 1)) and inverse-transforms without normalisation, so by Parseval the
/// unscaled series has the one-sided PSD `2·N·Δt·(1 + a²)·PSD(f)` in expectation (the amplitude noise
/// raises the mean power by `1 + a²`). [`AceSeries::generate`] then multiplies the axis by
/// `s = σ / σ_raw` (σ under `ace.sigma_convention`), so
///
/// `gain = s² · 2·N·Δt · (1 + a²)`.
///
/// `s` is recovered exactly by generating the unscaled axis again from the same random stream (`seed`,
/// `index`: the arguments `series` was generated with; a simulator's series is `(cfg.seed, 0)`), which costs
/// one inverse FFT of the series' length. `None` when `series` is not `s ×` that axis (another seed, index
/// or configuration) or is still (σ = 0 or a zero PSD).
pub fn model_gain(ace: &Ace, series: &AceSeries, seed: u64, index: u64, axis: Axis) -> Option<f64> {
    let (v, stream) = match axis {
        Axis::X => (&series.x_mas, Stream::AceX),
        Axis::Y => (&series.y_mas, Stream::AceY),
    };
    let n = v.len();
    let raw = raw_axis(
        &Psd::from_config(ace),
        n,
        series.dt_s,
        ace.amplitude_noise,
        &mut rng::stream(seed, stream, index),
    );
    // least-squares scale, then check that the series is exactly that multiple of the raw axis
    let rr: f64 = raw.iter().map(|r| r * r).sum();
    let s = v.iter().zip(&raw).map(|(x, r)| x * r).sum::<f64>() / rr;
    let peak = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if !(s > 0.0) || !(peak > 0.0) {
        return None;
    }
    let worst = v
        .iter()
        .zip(&raw)
        .fold(0.0f64, |m, (x, r)| m.max((x - s * r).abs()));
    if !(worst <= 1e-9 * peak) {
        return None;
    }
    Some(s * s * 2.0 * n as f64 * series.dt_s * (1.0 + ace.amplitude_noise.powi(2)))
}

/// The Welch estimate ([`welch`], segments of `seg_len` samples) of one axis of `series`, in the model PSD's
/// units: each value divided by [`model_gain`], so that it overlays `Psd::from_config(ace).eval(f)` at its
/// true amplitude. `None` where [`model_gain`] is.
pub fn welch_in_model_units(
    ace: &Ace,
    series: &AceSeries,
    seed: u64,
    index: u64,
    axis: Axis,
    seg_len: usize,
) -> Option<(Vec<(f64, f64)>, f64)> {
    let gain = model_gain(ace, series, seed, index, axis)?;
    let v = match axis {
        Axis::X => &series.x_mas,
        Axis::Y => &series.y_mas,
    };
    let w = welch(v, series.dt_s, seg_len)
        .into_iter()
        .map(|(f, p)| (f, p / gain))
        .collect();
    Some((w, gain))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, SigmaConvention};
    use crate::jitter::Psd;

    #[test]
    fn white_noise_is_flat_and_parseval() {
        use rand_distr::{Distribution, StandardNormal};
        let mut r = crate::rng::stream(1, crate::rng::Stream::Test, 0);
        let x: Vec<f64> = (0..1 << 16)
            .map(|_| StandardNormal.sample(&mut r))
            .collect();
        let p = welch(&x, 0.01, 1024);
        let df = p[1].0;
        let var: f64 = p.iter().map(|(_, v)| v * df).sum();
        assert!((var - 1.0).abs() < 0.05, "{var}");
        // two-sided unit variance over 50 Hz one-sided band → 0.02 per Hz
        let mid: f64 = p[100..400].iter().map(|(_, v)| v).sum::<f64>() / 300.0;
        assert!((mid - 0.02).abs() < 0.002, "{mid}");
    }

    /// The generated series' Welch PSD matches the model PSD in every band, and the modes peak where
    /// they should.
    #[test]
    fn generated_series_matches_input_psd() {
        let mut cfg = Config::default();
        cfg.ace.sample_interval_ms = 1.0; // 500 Hz Nyquist, above the 160 Hz mode
        cfg.ace.span_s = 2000.0;
        cfg.ace.sigma_convention = SigmaConvention::WholeSeries;
        let s = AceSeries::generate(&cfg, 42, 0);
        let psd = Psd::from_config(&cfg.ace);
        let est = welch(&s.x_mas, s.dt_s, 1 << 15);
        let df = est[1].0;
        // overall scale: variance of the series / ∫ model (the amplitude noise and σ scaling are uniform)
        let fny = 0.5 / s.dt_s;
        let scale = crate::numerics::stats::std_dev(&s.x_mas).powi(2)
            / psd.integral(0.0, fny, |p, f| p.eval(f));
        let band = |f0: f64, f1: f64| -> (f64, f64) {
            let meas: f64 = est
                .iter()
                .filter(|(f, _)| *f >= f0 && *f < f1)
                .map(|(_, v)| v * df)
                .sum();
            let model = scale * psd.integral(f0, f1, |p, f| p.eval(f));
            (meas, model)
        };
        // continuum bands: the 2000-s series holds ≈ 200 cycles at 0.1 Hz, so the low bands scatter more
        for (f0, f1, tol) in [
            (0.05, 0.2, 0.35),
            (0.2, 1.0, 0.2),
            (1.0, 5.0, 0.12),
            (5.0, 15.0, 0.12),
            (170.0, 450.0, 0.12),
        ] {
            let (m, e) = band(f0, f1);
            assert!(
                (m / e - 1.0).abs() < tol,
                "band {f0}–{f1} Hz: measured/model = {:.3}",
                m / e
            );
        }
        // each mode: integrated power within ±2 Hz, and the peak frequency
        for mode in &cfg.ace.modes[..6] {
            let (m, e) = band(mode.freq_hz - 2.0, mode.freq_hz + 2.0);
            assert!(
                (m / e - 1.0).abs() < 0.35,
                "mode {} Hz: measured/model = {:.3}",
                mode.freq_hz,
                m / e
            );
            let peak = est
                .iter()
                .filter(|(f, _)| (*f - mode.freq_hz).abs() < 5.0)
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|p| p.0)
                .unwrap_or(0.0);
            assert!(
                (peak - mode.freq_hz).abs() <= 2.0 * df + mode.width_hz,
                "mode {} Hz peaks at {peak}",
                mode.freq_hz
            );
        }
    }

    /// The estimate in model units matches the model PSD band by band with the gain computed from the
    /// generation (nothing fitted), under both σ conventions, and only for the series it belongs to.
    /// Tolerances on the band power (estimate and model summed over the same bins): ±3 % above 1 Hz
    /// (hundreds of bins; measured ≤ 1 %, and tight enough to catch a missing `1 + a²` = 1.04), ±10 % at
    /// 0.1–1 Hz and ±25 % at 0.05–0.1 Hz (two bins; a 2000-s series holds few cycles there; measured ≤ 9 %),
    /// and the median bin ratio within 5 %.
    #[test]
    fn estimate_in_model_units_matches_the_model_without_a_fitted_scale() {
        for convention in [
            SigmaConvention::MedianExposure,
            SigmaConvention::WholeSeries,
        ] {
            let mut cfg = Config::default();
            cfg.ace.sample_interval_ms = 1.0;
            cfg.ace.span_s = 2000.0;
            cfg.ace.sigma_convention = convention;
            let s = AceSeries::generate(&cfg, 7, 0);
            let psd = Psd::from_config(&cfg.ace);
            for axis in [Axis::X, Axis::Y] {
                let (est, gain) =
                    welch_in_model_units(&cfg.ace, &s, 7, 0, axis, 1 << 15).expect("the gain");
                assert!(gain > 0.0 && gain.is_finite());
                for (f0, f1, tol) in [
                    (0.05, 0.1, 0.25),
                    (0.1, 1.0, 0.10),
                    (1.0, 10.0, 0.03),
                    (10.0, 100.0, 0.03),
                    (100.0, 499.0, 0.03),
                ] {
                    // the estimate and the model summed over the same bins
                    let (meas, model) = est
                        .iter()
                        .filter(|(f, _)| *f >= f0 && *f < f1)
                        .fold((0.0, 0.0), |(m, e), (f, v)| (m + v, e + psd.eval(*f)));
                    assert!(
                        (meas / model - 1.0).abs() < tol,
                        "{convention:?} {axis:?} band {f0}–{f1} Hz: estimate/model = {:.3}",
                        meas / model
                    );
                }
                let ratios: Vec<f64> = est
                    .iter()
                    .filter(|(f, _)| *f > 0.0)
                    .map(|(f, p)| p / psd.eval(*f))
                    .collect();
                let med = crate::numerics::stats::median(&ratios);
                // the median of a χ²₂ₖ/2k ratio sits slightly below 1 (k ≈ 2·8 averaged segments per bin)
                assert!(
                    (med - 1.0).abs() < 0.05,
                    "{convention:?} {axis:?}: median ratio {med}"
                );
            }
        }
        // another seed's series is not this generator's output: no gain
        let cfg = Config {
            ace: crate::config::Ace {
                sample_interval_ms: 1.0,
                span_s: 200.0,
                ..Default::default()
            },
            ..Default::default()
        };
        let s = AceSeries::generate(&cfg, 7, 0);
        assert!(model_gain(&cfg.ace, &s, 7, 0, Axis::X).is_some());
        assert!(model_gain(&cfg.ace, &s, 8, 0, Axis::X).is_none());
        assert!(model_gain(&cfg.ace, &s, 7, 1, Axis::X).is_none());
        let mut still = cfg.clone();
        still.ace.sigma_mas = 0.0;
        let z = AceSeries::generate(&still, 7, 0);
        assert!(model_gain(&still.ace, &z, 7, 0, Axis::X).is_none());
    }
}
