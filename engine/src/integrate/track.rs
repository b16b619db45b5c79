//! The jitter track of one exposure on the integration time grid, and the weights of a pixel's window.
//!
//! Sample j represents the interval `[t₀ + (j − ½)Δt, t₀ + (j + ½)Δt)` (zero-order hold of the ACE series,
//! every `time_stride`-th sample). A window `[a, b)` gives sample j the weight
//! `w_j = |interval_j ∩ [a, b)| / Δt`, so Σ w_j Δt = b − a exactly: flux is conserved for any window.

use crate::jitter::AceSeries;

/// Star displacement (pixels) during one exposure, times relative to the exposure start.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    pub dt_s: f64,
    /// Centre time of sample 0, seconds from the exposure start.
    pub t0_s: f64,
    pub dx_px: Vec<f64>,
    pub dy_px: Vec<f64>,
    /// Mean and excursion, computed once on first use (every star's stamp needs them).
    summary: std::sync::OnceLock<TrackSummary>,
    /// Running sums `(Σ_{i<k} dx_i, Σ_{i<k} dy_i)`, k = 0..=len, made on first use: a window's mean in O(1)
    /// for every star's truth.
    prefix: std::sync::OnceLock<Vec<(f64, f64)>>,
}

/// Mean displacement and the largest excursion from it (px).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackSummary {
    pub mean_x: f64,
    pub mean_y: f64,
    pub excursion: f64,
    /// [`Track::extent`]: (min_x, max_x, min_y, max_y) over all samples, px.
    pub extent: (f64, f64, f64, f64),
}

/// The samples overlapping a window: `first..=last`, with fractional weights at both ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowWeights {
    pub first: usize,
    pub last: usize,
    pub w_first: f64,
    pub w_last: f64,
}

/// The weight of sample `j` in a window of samples `first ..= last` whose end samples weigh `w_first`, `w_last`
/// (the first's weight where they are one sample): generic so that a row's pixels can evaluate it side by side
/// on sample numbers held as `f64`.
#[inline(always)]
pub fn weight_in<T: PartialOrd>(j: T, first: T, last: T, w_first: f64, w_last: f64) -> f64 {
    if j < first || j > last {
        0.0
    } else if j == first {
        w_first
    } else if j == last {
        w_last
    } else {
        1.0
    }
}

impl WindowWeights {
    /// Weight of sample j.
    #[inline]
    pub fn weight(&self, j: usize) -> f64 {
        weight_in(j, self.first, self.last, self.w_first, self.w_last)
    }

    /// The samples where this window can weigh more than `inner` (a window it contains): the head
    /// `self.first..=inner.first` and the tail `inner.last..=self.last`, each sample in one of them.
    #[inline(always)]
    pub fn extra_ranges(
        &self,
        inner: &WindowWeights,
    ) -> (
        std::ops::RangeInclusive<usize>,
        std::ops::RangeInclusive<usize>,
    ) {
        let head_end = inner.first.min(self.last);
        let tail_start = inner.last.max(head_end + 1).max(self.first);
        (self.first..=head_end, tail_start..=self.last)
    }

    /// Every sample where this window weighs more than `inner` (a window it contains), with the difference
    /// ([`WindowWeights::extra_ranges`]).
    #[inline(always)]
    pub fn for_each_extra(&self, inner: &WindowWeights, mut f: impl FnMut(usize, f64)) {
        let (head, tail) = self.extra_ranges(inner);
        // one loop over both parts: `f` is called from one place, so it is inlined
        for j in head.chain(tail) {
            let e = self.weight(j) - inner.weight(j);
            if e != 0.0 {
                f(j, e);
            }
        }
    }

    /// Σ of the weights (window length / Δt).
    pub fn total(&self) -> f64 {
        if self.last == self.first {
            self.w_first
        } else {
            self.w_first + self.w_last + (self.last - self.first - 1) as f64
        }
    }
}

impl Track {
    /// A track from its samples.
    pub fn new(dt_s: f64, t0_s: f64, dx_px: Vec<f64>, dy_px: Vec<f64>) -> Self {
        Self {
            dt_s,
            t0_s,
            dx_px,
            dy_px,
            summary: std::sync::OnceLock::new(),
            prefix: std::sync::OnceLock::new(),
        }
    }

    /// Mean and largest excursion (cached).
    pub fn summary(&self) -> TrackSummary {
        *self.summary.get_or_init(|| {
            if self.is_empty() {
                return TrackSummary::default();
            }
            let n = self.len() as f64;
            let mx = self.dx_px.iter().sum::<f64>() / n;
            let my = self.dy_px.iter().sum::<f64>() / n;
            let (a, b, c, d) = self.extent();
            TrackSummary {
                mean_x: mx,
                mean_y: my,
                excursion: (mx - a).max(b - mx).max(my - c).max(d - my),
                extent: (a, b, c, d),
            }
        })
    }

    /// The track in the pixel axes of an array turned by `rotation_deg` on the sky: a focal-plane
    /// displacement d is R(−r)·d on the array (`sky::focal_plane`). Exact for multiples of 90°.
    pub fn turned_into_array(self, rotation_deg: f64) -> Self {
        if rotation_deg == 0.0 {
            return self;
        }
        let quarter = ((rotation_deg / 90.0).round() as i64).rem_euclid(4);
        let (c, s) = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][quarter as usize];
        let (dx, dy) = self
            .dx_px
            .iter()
            .zip(&self.dy_px)
            .map(|(&x, &y)| (c * x + s * y, -s * x + c * y))
            .unzip();
        Self::new(self.dt_s, self.t0_s, dx, dy)
    }

    /// Cut the exposure starting at absolute series time `t_start_s` and lasting `span_s` from the series,
    /// converting mas to pixels, keeping every `stride`-th sample.
    pub fn from_series(
        series: &AceSeries,
        t_start_s: f64,
        span_s: f64,
        stride: usize,
        plate_scale_mas: f64,
    ) -> Self {
        let stride = stride.max(1);
        let dt = series.dt_s * stride as f64;
        // first sample whose interval reaches the exposure start
        let j0 = ((t_start_s / dt) - 0.5).floor().max(0.0) as usize;
        let j1 = (((t_start_s + span_s) / dt) + 1.5).ceil() as usize;
        let mut dx = Vec::with_capacity(j1.saturating_sub(j0));
        let mut dy = Vec::with_capacity(j1.saturating_sub(j0));
        for j in j0..j1 {
            let i = (j * stride).min(series.len().saturating_sub(1));
            if series.is_empty() {
                dx.push(0.0);
                dy.push(0.0);
            } else {
                dx.push(series.x_mas[i] / plate_scale_mas);
                dy.push(series.y_mas[i] / plate_scale_mas);
            }
        }
        Self::new(dt, j0 as f64 * dt - t_start_s, dx, dy)
    }

    /// A still telescope over `[0, span_s)`, sampled every `dt_s`.
    pub fn still(span_s: f64, dt_s: f64) -> Self {
        let n = (span_s / dt_s).ceil() as usize + 2;
        Self::new(dt_s, 0.0, vec![0.0; n], vec![0.0; n])
    }

    pub fn len(&self) -> usize {
        self.dx_px.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dx_px.is_empty()
    }

    /// Weights of the window `[a, b)` (seconds from the exposure start).
    pub fn window(&self, a_s: f64, b_s: f64) -> WindowWeights {
        let n = self.len();
        if n == 0 || !(b_s > a_s) {
            return WindowWeights {
                first: 0,
                last: 0,
                w_first: 0.0,
                w_last: 0.0,
            };
        }
        // sample j covers [t0 + (j − ½)dt, t0 + (j + ½)dt)
        let ua = (a_s - self.t0_s) / self.dt_s + 0.5;
        let ub = (b_s - self.t0_s) / self.dt_s + 0.5;
        // ⌊ua⌋ and ⌈ub⌉ − 1 clamped to the samples, by truncation (the same values; `floor` and `ceil` are
        // library calls on the baseline x86-64 target, and every pixel of every stamp asks for its window)
        let first = if ua > 0.0 { ua as usize } else { 0 }.min(n - 1);
        let last = if ub > 1.0 {
            let t = ub as usize;
            if (t as f64) < ub { t } else { t - 1 }
        } else {
            0
        }
        .min(n - 1);
        if first == last {
            return WindowWeights {
                first,
                last,
                w_first: (ub - ua).max(0.0),
                w_last: (ub - ua).max(0.0),
            };
        }
        let w_first = (first as f64 + 1.0 - ua).clamp(0.0, 1.0);
        let w_last = (ub - last as f64).clamp(0.0, 1.0);
        WindowWeights {
            first,
            last,
            w_first,
            w_last,
        }
    }

    /// Range of the displacement over all samples: (min_x, max_x, min_y, max_y), px.
    pub fn extent(&self) -> (f64, f64, f64, f64) {
        let f = |v: &[f64]| {
            v.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let (a, b) = f(&self.dx_px);
        let (c, d) = f(&self.dy_px);
        if a.is_finite() {
            (a, b, c, d)
        } else {
            (0.0, 0.0, 0.0, 0.0)
        }
    }

    /// Weighted mean displacement over a window (px): the end samples by their weights, the interior from
    /// running sums.
    pub fn window_mean(&self, w: &WindowWeights) -> (f64, f64) {
        let total = w.total();
        if self.is_empty() || !(total > 0.0) {
            return (0.0, 0.0);
        }
        let mut sx = w.w_first * self.dx_px[w.first];
        let mut sy = w.w_first * self.dy_px[w.first];
        if w.last > w.first {
            let p = self.prefix.get_or_init(|| {
                let mut acc = (0.0, 0.0);
                let mut p = Vec::with_capacity(self.len() + 1);
                p.push(acc);
                for (x, y) in self.dx_px.iter().zip(&self.dy_px) {
                    acc = (acc.0 + x, acc.1 + y);
                    p.push(acc);
                }
                p
            });
            sx += p[w.last].0 - p[w.first + 1].0 + w.w_last * self.dx_px[w.last];
            sy += p[w.last].1 - p[w.first + 1].1 + w.w_last * self.dy_px[w.last];
        }
        (sx / total, sy / total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_weights_sum_to_window_length() {
        let t = Track::new(0.15e-3, -0.0001, vec![0.0; 100_000], vec![0.0; 100_000]);
        for (a, b) in [
            (0.1, 12.6),
            (0.100_003, 12.600_003),
            (1.31, 13.81),
            (0.0, 0.0001),
            (2.0, 2.00001),
        ] {
            let w = t.window(a, b);
            let total = w.total() * t.dt_s;
            assert!((total - (b - a)).abs() < 1e-12, "[{a}, {b}): {total}");
            let direct: f64 = (w.first..=w.last).map(|j| w.weight(j)).sum::<f64>() * t.dt_s;
            assert!((direct - (b - a)).abs() < 1e-12);
        }
    }

    #[test]
    fn window_mean_equals_the_weighted_sum() {
        let n = 50_000;
        let dx: Vec<f64> = (0..n)
            .map(|j| (j as f64 * 0.013).sin() * 0.7 + 0.2)
            .collect();
        let dy: Vec<f64> = (0..n).map(|j| (j as f64 * 0.007).cos() * 0.4).collect();
        let t = Track::new(0.15e-3, -0.0001, dx, dy);
        for (a, b) in [
            (0.1, 7.1),
            (0.100_003, 0.100_2),
            (1.31, 1.3101),
            (0.0, 7.4),
            (3.0, 3.0001),
        ] {
            let w = t.window(a, b);
            let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
            for j in w.first..=w.last {
                sx += w.weight(j) * t.dx_px[j];
                sy += w.weight(j) * t.dy_px[j];
                s += w.weight(j);
            }
            let (mx, my) = t.window_mean(&w);
            assert!(
                (mx - sx / s).abs() < 1e-11 && (my - sy / s).abs() < 1e-11,
                "[{a}, {b})"
            );
        }
    }

    #[test]
    fn series_cut_covers_the_exposure() {
        let s = AceSeries {
            dt_s: 1e-3,
            x_mas: (0..20_000).map(|i| i as f64).collect(),
            y_mas: vec![0.0; 20_000],
            convention: crate::config::SigmaConvention::WholeSeries,
            achieved_sigma_mas: (0.0, 0.0),
        };
        let t = Track::from_series(&s, 2.0, 13.81, 2, 472.0);
        let w = t.window(0.0, 13.81);
        assert!((w.total() * t.dt_s - 13.81).abs() < 1e-9);
        // sample j's time ↔ the series value at that time
        let j = 100;
        let time = 2.0 + t.t0_s + j as f64 * t.dt_s;
        assert!((t.dx_px[j] * 472.0 - time * 1e3).abs() < 1e-6);
    }
}
