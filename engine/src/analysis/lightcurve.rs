//! Light curves of transit photometry: the scatter of a light curve binned over a time (the combined
//! differential photometric precision habit of Kepler and TESS: the rms of the means of consecutive bins), and
//! the search for a transit by box least squares (Kovács, Zucker & Mazeh 2002): for each trial period the
//! light curve folded into phase bins, and for each trial duration and start the weighted mean in the box
//! against the mean out of it.

/// The rms of the means of consecutive `bin_days` bins of a light curve (bins at least half full, at least
/// three of them), relative to the light curve's weighted mean, in parts per million. `None` when fewer than
/// three bins qualify.
pub fn binned_scatter_ppm(t_days: &[f64], flux: &[f64], bin_days: f64) -> Option<f64> {
    if t_days.len() != flux.len() || t_days.is_empty() || !(bin_days > 0.0) {
        return None;
    }
    let t0 = t_days.iter().cloned().fold(f64::INFINITY, f64::min);
    let t1 = t_days.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let cadence = (t1 - t0) / (t_days.len().max(2) - 1) as f64;
    let bins = ((t1 - t0) / bin_days).floor() as usize + 1;
    let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
    for (t, f) in t_days.iter().zip(flux) {
        if f.is_finite() {
            let b = (((t - t0) / bin_days) as usize).min(bins - 1);
            sum[b] += f;
            count[b] += 1;
        }
    }
    let full = if cadence > 0.0 {
        (0.5 * bin_days / cadence).max(1.0) as usize
    } else {
        1
    };
    let means: Vec<f64> = sum
        .iter()
        .zip(&count)
        .filter(|(_, c)| **c >= full)
        .map(|(s, c)| s / *c as f64)
        .collect();
    if means.len() < 3 {
        return None;
    }
    let level = flux.iter().filter(|f| f.is_finite()).sum::<f64>()
        / flux.iter().filter(|f| f.is_finite()).count().max(1) as f64;
    let m = means.iter().sum::<f64>() / means.len() as f64;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (means.len() - 1) as f64;
    Some(1e6 * var.sqrt() / level)
}

/// The best box found by [`box_least_squares`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxFit {
    pub period_days: f64,
    /// Mid-transit time of the box, days (within the first period after the light curve's start).
    pub t0_days: f64,
    pub duration_days: f64,
    /// Relative depth: 1 − (mean in the box) / (mean out of it).
    pub depth: f64,
    /// Its 1σ error from the points' errors.
    pub depth_sigma: f64,
    /// depth / depth_sigma: the detection's significance.
    pub snr: f64,
    /// Points in the box.
    pub points_in: usize,
}

/// Box least squares over `periods_days` × `durations_days`, each box start on a phase grid of a quarter of
/// the shortest duration: the box of largest significance (depth over its error, with weights 1/σ²). `None`
/// when no box holds a point, or the inputs disagree in length.
pub fn box_least_squares(
    t_days: &[f64],
    flux: &[f64],
    sigma: &[f64],
    periods_days: &[f64],
    durations_days: &[f64],
) -> Option<BoxFit> {
    let n = t_days.len();
    if flux.len() != n || sigma.len() != n || n == 0 {
        return None;
    }
    let shortest = durations_days
        .iter()
        .cloned()
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !shortest.is_finite() {
        return None;
    }
    let t_start = t_days.iter().cloned().fold(f64::INFINITY, f64::min);
    let good: Vec<usize> = (0..n)
        .filter(|&i| flux[i].is_finite() && sigma[i] > 0.0 && sigma[i].is_finite())
        .collect();
    let (mut w_all, mut wf_all) = (0.0, 0.0);
    for &i in &good {
        let w = 1.0 / (sigma[i] * sigma[i]);
        w_all += w;
        wf_all += w * flux[i];
    }
    let mut best: Option<BoxFit> = None;
    for &period in periods_days.iter().filter(|p| **p > 0.0) {
        let bins = ((4.0 * period / shortest).ceil() as usize).max(1);
        let bin_days = period / bins as f64;
        let (mut w, mut wf, mut k) = (vec![0.0; bins], vec![0.0; bins], vec![0usize; bins]);
        for &i in &good {
            let phase = (t_days[i] - t_start).rem_euclid(period);
            let b = ((phase / bin_days) as usize).min(bins - 1);
            let wi = 1.0 / (sigma[i] * sigma[i]);
            w[b] += wi;
            wf[b] += wi * flux[i];
            k[b] += 1;
        }
        for &duration in durations_days.iter().filter(|d| **d > 0.0 && **d < period) {
            let span = ((duration / bin_days).round() as usize).clamp(1, bins);
            // the window's sums, slid around the folded light curve
            let (mut sw, mut swf, mut sk) = (0.0, 0.0, 0usize);
            for b in 0..span {
                sw += w[b];
                swf += wf[b];
                sk += k[b];
            }
            for start in 0..bins {
                let (w_out, wf_out) = (w_all - sw, wf_all - swf);
                if sw > 0.0 && w_out > 0.0 {
                    let (m_in, m_out) = (swf / sw, wf_out / w_out);
                    let depth = 1.0 - m_in / m_out;
                    let depth_sigma = (1.0 / sw + 1.0 / w_out).sqrt() / m_out.abs();
                    let snr = depth / depth_sigma;
                    if best.is_none_or(|b| snr > b.snr) {
                        best = Some(BoxFit {
                            period_days: period,
                            t0_days: t_start + (start as f64 + span as f64 / 2.0) * bin_days,
                            duration_days: span as f64 * bin_days,
                            depth,
                            depth_sigma,
                            snr,
                            points_in: sk,
                        });
                    }
                }
                // slide by one bin (wrapping around the phase)
                let (out_b, in_b) = (start, (start + span) % bins);
                sw += w[in_b] - w[out_b];
                swf += wf[in_b] - wf[out_b];
                sk = sk + k[in_b] - k[out_b];
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn noise(n: usize, sigma: f64, seed: u64) -> Vec<f64> {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let d = Normal::new(0.0, sigma).expect("normal");
        (0..n).map(|_| d.sample(&mut r)).collect()
    }

    /// White noise binned over m points scatters as σ/√m: the measured binned scatter within 4 of its own
    /// sampling errors (a scatter from K bins has a relative error of 1/√(2(K − 1))).
    #[test]
    fn white_noise_bins_down_as_the_square_root_of_the_points() {
        let (n, sigma, cadence) = (20_000, 1e-3, 20.0 / 86_400.0);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * cadence).collect();
        let f: Vec<f64> = noise(n, sigma, 1).iter().map(|e| 1.0 + e).collect();
        for bin_points in [1usize, 180, 1170] {
            let bin = bin_points as f64 * cadence;
            let got = binned_scatter_ppm(&t, &f, bin * 0.999_999).expect("scatter");
            let k = n / bin_points;
            let expect = 1e6 * sigma / (bin_points as f64).sqrt();
            let rel = 1.0 / (2.0 * (k - 1) as f64).sqrt();
            assert!(
                (got / expect - 1.0).abs() < 4.0 * rel,
                "{bin_points} points per bin: {got} ppm vs {expect} (± {:.1} %)",
                100.0 * rel
            );
        }
    }

    /// A box of known depth in white noise: found at its period, phase and duration, its depth within 4σ of
    /// the truth with σ what the fit says, and its significance as the points in the box predict.
    #[test]
    fn an_injected_box_is_found_with_its_depth_and_significance() {
        let (n, sigma) = (6000, 1e-3);
        let (period, t0, duration, depth) = (2.7, 0.9, 0.12, 1.2e-3);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 10.0 / n as f64).collect();
        let e = noise(n, sigma, 7);
        let f: Vec<f64> = t
            .iter()
            .zip(&e)
            .map(|(t, e)| {
                let ph = (t - t0 + 0.5 * period).rem_euclid(period) - 0.5 * period;
                (if ph.abs() < duration / 2.0 {
                    1.0 - depth
                } else {
                    1.0
                }) + e
            })
            .collect();
        let s = vec![sigma; n];
        let periods: Vec<f64> = (0..400).map(|k| 1.0 + k as f64 * 0.01).collect();
        let fit = box_least_squares(&t, &f, &s, &periods, &[0.06, 0.12, 0.24]).expect("fit");
        assert!((fit.period_days - period).abs() < 0.011, "{fit:?}");
        assert!((fit.duration_days - duration).abs() < 0.04, "{fit:?}");
        assert!(((fit.t0_days - t0 + 0.5 * period).rem_euclid(period) - 0.5 * period).abs() < 0.04);
        assert!((fit.depth - depth).abs() < 4.0 * fit.depth_sigma, "{fit:?}");
        let expect_snr = depth / sigma * (fit.points_in as f64).sqrt();
        assert!(
            (fit.snr / expect_snr - 1.0).abs() < 0.5,
            "{fit:?} vs {expect_snr}"
        );
    }

    #[test]
    fn nothing_to_search_is_none() {
        assert!(box_least_squares(&[], &[], &[], &[1.0], &[0.1]).is_none());
        assert!(box_least_squares(&[0.0, 1.0], &[1.0, 1.0], &[1.0], &[1.0], &[0.1]).is_none());
        assert!(binned_scatter_ppm(&[0.0, 1.0], &[1.0, 1.0], 1.0).is_none());
    }
}
