//! Robust and plain statistics over slices of f64 (NaN-free inputs assumed by the callers).

/// Arithmetic mean (0 for an empty slice).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Sample standard deviation (n − 1 in the denominator; 0 for fewer than two values).
pub fn std_dev(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// Standard error of the mean.
pub fn sem(v: &[f64]) -> f64 {
    if v.len() < 2 {
        0.0
    } else {
        std_dev(v) / (v.len() as f64).sqrt()
    }
}

/// Median (average of the two middle values for even lengths; 0 for empty).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    // selection, not a sort: O(n), and the same value (the k-th smallest is unique whatever the method)
    let mut s = v.to_vec();
    let n = s.len();
    let (lower, mid, _) = s.select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b));
    let mid = *mid;
    if n % 2 == 1 {
        mid
    } else {
        let below = lower
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, |a, b| match a.total_cmp(&b) {
                std::cmp::Ordering::Less => b,
                _ => a,
            });
        0.5 * (below + mid)
    }
}

/// Median absolute deviation scaled to σ for a Gaussian (×1.4826).
pub fn mad_sigma(v: &[f64]) -> f64 {
    let m = median(v);
    let d: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median(&d)
}

/// Iteratively sigma-clipped mean about the median: returns (mean, number kept).
pub fn clipped_mean(v: &[f64], nsigma: f64) -> (f64, usize) {
    if v.is_empty() {
        return (0.0, 0);
    }
    let mut kept: Vec<f64> = v.to_vec();
    for _ in 0..5 {
        let c = median(&kept);
        let mad = mad_sigma(&kept);
        let s = if mad > 0.0 { mad } else { std_dev(&kept) };
        if !(s > 0.0) {
            break;
        }
        let next: Vec<f64> = kept
            .iter()
            .copied()
            .filter(|x| (x - c).abs() <= nsigma * s)
            .collect();
        if next.len() == kept.len() || next.is_empty() {
            break;
        }
        kept = next;
    }
    (mean(&kept), kept.len())
}

/// Quantile by linear interpolation (q in [0, 1]).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let i = pos.floor() as usize;
    let f = pos - i as f64;
    if i + 1 < s.len() {
        s[i] * (1.0 - f) + s[i + 1] * f
    } else {
        s[i]
    }
}

/// Pearson correlation coefficient (0 when either side has no spread).
pub fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let (mx, my) = (mean(x), mean(y));
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let syy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
    if sxx > 0.0 && syy > 0.0 {
        sxy / (sxx * syy).sqrt()
    } else {
        0.0
    }
}

/// Least-squares slope of y on x (0 when x has no spread).
pub fn slope(x: &[f64], y: &[f64]) -> f64 {
    let (mx, my) = (mean(x), mean(y));
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

/// Wilson score interval for a binomial proportion k/n at `z` standard deviations (z = 1.96 → 95 %).
pub fn wilson_interval(k: usize, n: usize, z: f64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let nf = n as f64;
    let p = k as f64 / nf;
    let denom = 1.0 + z * z / nf;
    let centre = (p + z * z / (2.0 * nf)) / denom;
    let half = z * ((p * (1.0 - p) / nf + z * z / (4.0 * nf * nf)).sqrt()) / denom;
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The selection median equals the sorted-list median exactly, odd and even lengths, with ties.
    #[test]
    fn median_by_selection_equals_the_sorted_median() {
        for n in 1..40usize {
            let v: Vec<f64> = (0..n)
                .map(|k| ((k * 7919 + 13) % 17) as f64 * 0.25 - 1.0)
                .collect();
            let mut s = v.clone();
            s.sort_by(|a, b| a.total_cmp(b));
            let expect = if n % 2 == 1 {
                s[n / 2]
            } else {
                0.5 * (s[n / 2 - 1] + s[n / 2])
            };
            assert_eq!(median(&v).to_bits(), expect.to_bits(), "n = {n}");
        }
    }

    #[test]
    fn basics() {
        let v = [1.0, 2.0, 3.0, 4.0, 100.0];
        assert_eq!(median(&v), 3.0);
        assert!((mean(&v) - 22.0).abs() < 1e-12);
        let (m, k) = clipped_mean(&v, 3.0);
        assert_eq!(k, 4);
        assert!((m - 2.5).abs() < 1e-12);
        assert!((quantile(&[0.0, 10.0], 0.25) - 2.5).abs() < 1e-12);
        assert!((std_dev(&[1.0, 3.0]) - std::f64::consts::SQRT_2).abs() < 1e-12);
        assert!((correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]) - 1.0).abs() < 1e-12);
        assert!((slope(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn wilson_known_value() {
        // 8/10 at 95 %: (0.4902, 0.9433)
        let (lo, hi) = wilson_interval(8, 10, 1.959_963_985);
        assert!(
            (lo - 0.4902).abs() < 1e-3 && (hi - 0.9433).abs() < 1e-3,
            "{lo} {hi}"
        );
    }
}
