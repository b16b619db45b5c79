//! The single-transit box search of a stare's light curve and the depth's error.
//!
//! The box is found by box least squares ([`box_least_squares`], Kovács et al. 2002) with one trial period of
//! twice the stare; its depth's error is taken from the scatter of the residuals *outside* the box (the
//! transit's plates would inflate a scatter measured over the whole light curve: a deep transit makes a
//! whole-curve σ too large, and its depth's error with it).

use crate::analysis::lightcurve::{BoxFit, box_least_squares};
use crate::numerics::stats;

/// How much of its duration the transit's mask adds on each side, for the decorrelation, the precision and
/// the depth's error (a box is a little shorter than the transit it finds: its ingress and egress stay out
/// of it).
pub const MASK_MARGIN: f64 = 0.25;

/// The plates inside a box (its mid-time ± half its duration) widened by `margin` of its duration on each
/// side.
pub fn box_mask(t_days: &[f64], b: &BoxFit, margin: f64) -> Vec<bool> {
    t_days
        .iter()
        .map(|t| (t - b.t0_days).abs() <= (0.5 + margin) * b.duration_days)
        .collect()
}

/// The box search's durations: 15 min to half the stare in 15-min steps, days.
fn durations_days(stare_h: f64) -> Vec<f64> {
    (1..)
        .map(|k| 0.25 * k as f64)
        .take_while(|h| *h <= 0.5 * stare_h)
        .map(|h| h / 24.0)
        .collect()
}

/// A box search with every point's σ the light curve's robust scatter (`1.4826 MAD`, the transit included):
/// the box's place and duration, and a depth error that is too large when the transit is deep. The first
/// step of [`search`]; kept apart so that the two errors can be compared.
pub fn search_whole_curve_sigma(t_days: &[f64], flux: &[f64], stare_h: f64) -> Option<BoxFit> {
    let good: Vec<f64> = flux.iter().cloned().filter(|v| v.is_finite()).collect();
    let sigma = stats::mad_sigma(&good);
    if !(sigma > 0.0) {
        return None;
    }
    box_least_squares(
        t_days,
        flux,
        &vec![sigma; flux.len()],
        &[2.0 * stare_h / 24.0],
        &durations_days(stare_h),
    )
}

/// The scatter of the points outside a box widened by [`MASK_MARGIN`]: the standard deviation of the
/// out-of-transit residuals about their mean (finite values; NaN with fewer than 3).
pub fn out_of_box_sigma(t_days: &[f64], flux: &[f64], b: &BoxFit) -> f64 {
    let out: Vec<f64> = flux
        .iter()
        .zip(box_mask(t_days, b, MASK_MARGIN))
        .filter(|(v, m)| !m && v.is_finite())
        .map(|(v, _)| *v)
        .collect();
    if out.len() < 3 {
        return f64::NAN;
    }
    stats::std_dev(&out)
}

/// A single-transit box search: one trial period of twice the stare (no folding, no wrap-around), durations
/// from 15 min to half the stare in 15-min steps; the depth's error from the residuals out of the transit.
///
/// With one σ for every point, box least squares gives the depth `δ = 1 − m_in/m_out` (the box's mean over
/// the mean outside it) with the error `σ_δ = σ √(1/N_in + 1/N_out) / m_out` (Kovács et al. 2002's weighted
/// means); the box it picks does not depend on σ. The search runs once with σ the whole light curve's robust
/// scatter, then σ is replaced by `s_out`, the standard deviation of the points outside the box widened by
/// [`MASK_MARGIN`] on each side ([`out_of_box_sigma`]): `σ_δ = s_out √(1/N_in + 1/N_out) / m_out`, and the
/// significance `δ/σ_δ`. White noise is assumed (the plates' residuals scatter independently); noise
/// correlated over the transit's duration would make σ_δ too small.
pub fn search(t_days: &[f64], flux: &[f64], stare_h: f64) -> Option<BoxFit> {
    let first = search_whole_curve_sigma(t_days, flux, stare_h)?;
    let good: Vec<f64> = flux.iter().cloned().filter(|v| v.is_finite()).collect();
    let whole_sigma = stats::mad_sigma(&good);
    let out_sigma = out_of_box_sigma(t_days, flux, &first);
    if !(out_sigma > 0.0 && out_sigma.is_finite()) {
        return Some(first);
    }
    // σ_δ scales with σ: the same box, its error and significance rescaled
    let depth_sigma = first.depth_sigma * out_sigma / whole_sigma;
    Some(BoxFit {
        depth_sigma,
        snr: first.depth / depth_sigma,
        ..first
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::transit::Transit;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The default stare's sampling: 6.5 h at the 12.6-s cadence.
    const CADENCE_S: f64 = 12.6;
    const STARE_H: f64 = 6.5;

    /// The requirement's transit (0.3 %, P = 14 d, a/R★ = 71.5: 1.58 h) at `t0_h`.
    fn transit(depth: f64, t0_h: f64) -> Transit {
        Transit {
            t0_days: t0_h / 24.0,
            period_days: 14.0,
            rp_over_rs: depth.sqrt(),
            a_over_rs: 71.5,
            inclination_deg: 90.0,
            u1: 0.1,
            u2: 0.3,
        }
    }

    fn times() -> Vec<f64> {
        let n = (STARE_H * 3600.0 / CADENCE_S) as usize;
        (0..n)
            .map(|p| (p as f64 + 0.5) * CADENCE_S / 86_400.0)
            .collect()
    }

    /// A light curve with the stare's noise: white σ plus an AR(1) red part of `red` σ whose correlation
    /// falls by e every three plates, and the transit averaged over each plate (12.5 s, 7 instants).
    fn light_curve(
        t: &[f64],
        tr: &Transit,
        sigma: f64,
        red: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n01 = Normal::new(0.0, 1.0).expect("normal");
        let rho = (-1.0f64 / 3.0).exp();
        let mut ar = red * sigma * n01.sample(&mut r);
        let model: Vec<f64> = t
            .iter()
            .map(|t| tr.mean_flux(t - 6.25 / 86_400.0, 12.5 / 86_400.0, 7))
            .collect();
        let flux = model
            .iter()
            .map(|m| {
                ar = rho * ar + (1.0 - rho * rho).sqrt() * red * sigma * n01.sample(&mut r);
                m + sigma * n01.sample(&mut r) + ar
            })
            .collect();
        (flux, model)
    }

    /// The injected transit's mean depth over the box's plates (what the box's depth estimates).
    fn injected_over_box(t: &[f64], model: &[f64], b: &BoxFit) -> f64 {
        let d: Vec<f64> = model
            .iter()
            .zip(box_mask(t, b, 0.0))
            .filter(|(_, i)| *i)
            .map(|(m, _)| 1.0 - m)
            .collect();
        stats::mean(&d)
    }

    #[test]
    fn a_deep_transit_no_longer_inflates_its_depth_error() {
        // a 1 % transit in white noise of 1000 ppm: the whole-curve σ takes the transit's plates in and
        // overstates the error; the error now comes from the scatter out of the box
        let t = times();
        let (flux, _) = light_curve(&t, &transit(0.01, 3.25), 1e-3, 0.0, 11);
        let old = search_whole_curve_sigma(&t, &flux, STARE_H).expect("box");
        let new = search(&t, &flux, STARE_H).expect("box");
        assert_eq!(
            (old.t0_days, old.duration_days),
            (new.t0_days, new.duration_days)
        );
        assert_eq!(old.depth, new.depth);
        assert!(
            new.depth_sigma < 0.8 * old.depth_sigma,
            "whole curve {:e}, out of the box {:e}",
            old.depth_sigma,
            new.depth_sigma
        );
        // σ_δ = s_out √(1/N_in + 1/N_out) / m_out, from the plates out of the box
        let inside = box_mask(&t, &new, 0.0);
        let n_in = inside.iter().filter(|i| **i).count() as f64;
        let n_out = t.len() as f64 - n_in;
        let outside: Vec<f64> = flux
            .iter()
            .zip(&inside)
            .filter(|(_, i)| !**i)
            .map(|(f, _)| *f)
            .collect();
        let m_out = stats::mean(&outside);
        let want = out_of_box_sigma(&t, &flux, &new) * (1.0 / n_in + 1.0 / n_out).sqrt() / m_out;
        assert!(
            (new.depth_sigma / want - 1.0).abs() < 1e-9,
            "{:e} vs {want:e}",
            new.depth_sigma
        );
        // … which is the white noise's σ within its sampling error
        assert!((out_of_box_sigma(&t, &flux, &new) / 1e-3 - 1.0).abs() < 0.1);
        assert!((new.snr - new.depth / new.depth_sigma).abs() < 1e-9);
    }

    #[test]
    fn the_reported_depth_error_is_the_spread_of_the_depths_over_many_injections() {
        // 600 stares' light curves (the default stare's 1857 plates at 1209 ppm, its measured scatter, plus
        // a red part of 10 % correlated over 3 plates) with the requirement's 0.3 % transit at a random
        // mid-time: the spread of the recovered depths about the injected ones over the box, against the
        // median reported error. A standard deviation from N values scatters by 1/√(2N): 2.9 % for 600,
        // so the window 0.9–1.1 is 3.5σ of the statistic's own scatter.
        let t = times();
        let trials = 600;
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(2024);
        let (mut errors, mut reported) = (Vec::new(), Vec::new());
        for k in 0..trials {
            let t0_h = 1.5 + 3.5 * rand::RngExt::random::<f64>(&mut r);
            let tr = transit(0.003, t0_h);
            let (flux, model) = light_curve(&t, &tr, 1209e-6, 0.1, 100 + k);
            let b = search(&t, &flux, STARE_H).expect("box");
            assert!(
                box_mask(&t, &b, 0.0)
                    .iter()
                    .zip(&model)
                    .any(|(i, m)| *i && *m < 1.0)
            );
            errors.push(b.depth - injected_over_box(&t, &model, &b));
            reported.push(b.depth_sigma);
        }
        let ratio = stats::std_dev(&errors) / stats::median(&reported);
        assert!(
            (0.9..=1.1).contains(&ratio),
            "spread {:.1} ppm over a median reported error of {:.1} ppm: {ratio:.3}",
            1e6 * stats::std_dev(&errors),
            1e6 * stats::median(&reported)
        );
        // the mean error is small against the spread (the box's choice biases the depth a little)
        assert!(stats::mean(&errors).abs() < 0.3 * stats::std_dev(&errors));
    }
}
