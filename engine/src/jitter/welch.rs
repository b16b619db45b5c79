//! Welch's averaged, Hann-windowed periodogram (one-sided, units² per Hz), to compare a generated series
//! with the PSD it came from.

use rustfft::{FftPlanner, num_complex::Complex64};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, SigmaConvention};
    use crate::jitter::{AceSeries, Psd};

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
}
