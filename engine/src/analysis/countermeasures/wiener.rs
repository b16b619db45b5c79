//! The Wiener smoother of an attitude telemetry record (`analysis.telemetry_filter = "wiener"`): the
//! non-causal least-squares estimate of the attitude from samples with white noise (Wiener 1949; Press et
//! al., *Numerical Recipes*, §13.3 "optimal filtering").
//!
//! For a stationary attitude of spectrum S(f) seen through white noise N (σ² per sample), the filter of least
//! mean-square error is `H(f) = S(f) / (S(f) + N)`, and the error it leaves is `∫ S N / (S + N) df`. The
//! spectrum S is the ACE's over this exposure, which the record itself measures best: its periodogram `P`
//! smoothed over bands of relative width ≈ 2/[`BAND_FRACTION`] estimates `S + N`, so
//! `H = max(0, 1 − N / P̄)` (spectral subtraction). N is the record's stated noise (its product's `NOISEMAS`),
//! else the noise estimated from its second differences ([`super::telemetry::white_noise_mas`]). The design
//! ACE PSD is not an instrument product the analysis reads, and the record's spectrum over the exposure is
//! what the filter needs; a mission that knows its PSD better would put it in place of `P̄ − N`.
//!
//! The record is extended by its mirror image before the transform (an even, continuous periodic series:
//! no wrap-around step at its ends), and the boxcar's choice ([`super::telemetry::Smoothing`]) stays the
//! default; this filter keeps a vibration the boxcar would average away where the noise is below it.

use rustfft::{FftPlanner, num_complex::Complex64};

/// The periodogram is averaged over `±k / BAND_FRACTION` bins around bin k (at least ±[`MIN_BAND_BINS`]): a
/// band of ≈ 50 % in frequency. Narrower bands estimate the spectrum with more scatter (±k/8 left 1.18 × the
/// optimal error in the test below, ±k/16 1.31 ×); wider ones spread a vibration's line over frequencies
/// of noise alone (±k/2 no longer keeps the test's 40-Hz line).
pub const BAND_FRACTION: usize = 4;
/// The least half-width of the averaging band, bins.
pub const MIN_BAND_BINS: usize = 4;

/// `v` (samples of one axis with white noise `noise` per sample, in `v`'s units) Wiener-smoothed as the
/// module says; unchanged when the noise is 0 or the record has fewer than 8 samples.
pub fn smooth(v: &[f64], noise: f64) -> Vec<f64> {
    let n = v.len();
    if n < 8 || !(noise > 0.0) {
        return v.to_vec();
    }
    // the even extension, of period 2n
    let m = 2 * n;
    let mut x: Vec<Complex64> = v
        .iter()
        .chain(v.iter().rev())
        .map(|&a| Complex64::new(a, 0.0))
        .collect();
    let mut planner = FftPlanner::new();
    planner.plan_fft_forward(m).process(&mut x);
    // the power per bin in the units of one sample's variance: white noise σ² gives E[P_k] = σ²
    let power: Vec<f64> = (0..=n).map(|k| x[k].norm_sqr() / m as f64).collect();
    let mut cum = Vec::with_capacity(power.len() + 1);
    cum.push(0.0);
    for p in &power {
        cum.push(cum[cum.len() - 1] + p);
    }
    let n2 = noise * noise;
    let gain: Vec<f64> = (0..=n)
        .map(|k| {
            if k == 0 {
                return 1.0;
            }
            let h = (k / BAND_FRACTION).max(MIN_BAND_BINS);
            let (a, b) = (k.saturating_sub(h).max(1), (k + h).min(n));
            let mean = (cum[b + 1] - cum[a]) / (b + 1 - a) as f64;
            (1.0 - n2 / mean.max(1e-300)).max(0.0)
        })
        .collect();
    for (k, c) in x.iter_mut().enumerate() {
        // bin k and its mirror m − k share the gain of frequency min(k, m − k)
        *c *= gain[k.min(m - k)];
    }
    planner.plan_fft_inverse(m).process(&mut x);
    x[..n].iter().map(|c| c.re / m as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::smooth;
    use crate::analysis::countermeasures::telemetry::{Smoothing, TelemetryRecord, gauss_markov};
    use crate::rng::{self, Stream};
    use rand_distr::Distribution;

    /// The least mean-square error any linear filter leaves on a Gauss–Markov attitude (variance s², time
    /// constant τ: two-sided PSD `2 s² τ / (1 + (2π f τ)²)`) seen at rate `fs` through white noise σ² per
    /// sample (two-sided `σ² / fs`): `∫ S N / (S + N) df` over ±fs/2, integrated numerically from the
    /// formula — independent of the filter.
    fn wiener_bound(s: f64, tau: f64, sigma: f64, fs: f64) -> f64 {
        let steps = 200_000;
        let df = fs / steps as f64;
        let noise = sigma * sigma / fs;
        (0..steps)
            .map(|i| {
                let f = -fs / 2.0 + (i as f64 + 0.5) * df;
                let sf = 2.0 * s * s * tau / (1.0 + (std::f64::consts::TAU * f * tau).powi(2));
                sf * noise / (sf + noise) * df
            })
            .sum()
    }

    fn mse(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64
    }

    /// A 12.5-s record at 1 kHz of a Gauss–Markov attitude (100 mas rms, τ = 0.2 s) with 400 mas of white
    /// noise per sample, 20 records: the smoother's mean-square error is the optimal filter's analytic one
    /// within 20 % (its spectrum is estimated from each record, and the ends of a 12.5-s record lose a
    /// little; the 20 records' mean has a few % of scatter), and it beats the boxcar the default chooses.
    #[test]
    fn the_smoother_reaches_the_optimal_filters_error_on_a_known_spectrum() {
        let (dt, n, s, tau, sigma) = (1e-3, 12_500, 100.0, 0.2, 400.0);
        let bound = wiener_bound(s, tau, sigma, 1.0 / dt);
        let (mut wiener, mut boxcar, mut raw) = (0.0, 0.0, 0.0);
        let trials = 20;
        for t in 0..trials {
            let mut r = rng::stream(17, Stream::Test, t);
            let truth = gauss_markov(n, dt, s, tau, &mut r);
            let noisy: Vec<f64> = truth
                .iter()
                .map(|v| {
                    let z: f64 = rand_distr::StandardNormal.sample(&mut r);
                    v + sigma * z
                })
                .collect();
            wiener += mse(&smooth(&noisy, sigma), &truth) / trials as f64;
            let rec = TelemetryRecord {
                t0_s: 0.0,
                dt_s: dt,
                x_mas: noisy.clone(),
                y_mas: noisy.clone(),
                exposure_start_s: 0.0,
                stated_noise_mas: Some(sigma),
            };
            boxcar += mse(&rec.smoothed(&Smoothing::choose(&rec)).x_mas, &truth) / trials as f64;
            raw += mse(&noisy, &truth) / trials as f64;
        }
        assert!(
            wiener > 0.9 * bound && wiener < 1.2 * bound,
            "Wiener {wiener:.0} mas², optimal {bound:.0} mas² (raw {raw:.0})"
        );
        assert!(wiener < boxcar, "Wiener {wiener:.0}, boxcar {boxcar:.0}");
    }

    /// A 40-Hz vibration of 30 mas under 5 mas of noise is kept (the boxcar's band would be wider than its
    /// period at higher noise); no noise or a short record: the samples themselves.
    #[test]
    fn the_smoother_keeps_a_vibration_above_the_noise_and_leaves_a_clean_record() {
        let mut r = rng::stream(4, Stream::Test, 0);
        let truth: Vec<f64> = (0..12_500)
            .map(|k| 30.0 * (std::f64::consts::TAU * 40.0 * k as f64 * 1e-3).sin())
            .collect();
        let noisy: Vec<f64> = truth
            .iter()
            .map(|v| {
                let z: f64 = rand_distr::StandardNormal.sample(&mut r);
                v + 5.0 * z
            })
            .collect();
        let out = smooth(&noisy, 5.0);
        // the noise's 25 mas² falls to well under a tenth; the vibration's 450 mas² is kept
        assert!(mse(&out, &truth) < 2.5, "{}", mse(&out, &truth));
        assert_eq!(smooth(&truth, 0.0), truth);
        assert_eq!(smooth(&[1.0, 2.0, 3.0], 5.0), vec![1.0, 2.0, 3.0]);
        // through the record: each axis smoothed against the stated noise; a record that states none is
        // smoothed against the noise its second differences show (≈ 5 mas: the same error within 10 %)
        let mut rec = TelemetryRecord {
            t0_s: 0.0,
            dt_s: 1e-3,
            x_mas: noisy.clone(),
            y_mas: noisy.iter().rev().copied().collect(),
            exposure_start_s: 0.0,
            stated_noise_mas: Some(5.0),
        };
        let filter = crate::config::TelemetryFilter::Wiener;
        let m = rec.model_record(filter).expect("smoothed");
        assert_eq!(m.x_mas, out);
        assert_eq!(m.y_mas, smooth(&rec.y_mas, 5.0));
        rec.stated_noise_mas = None;
        let e = mse(&rec.model_record(filter).expect("smoothed").x_mas, &truth);
        assert!((e / mse(&out, &truth) - 1.0).abs() < 0.1, "{e}");
        rec.stated_noise_mas = Some(0.0);
        assert!(rec.model_record(filter).is_none());
    }
}
