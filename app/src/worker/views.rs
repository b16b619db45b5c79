//! What the panels draw of the engine's objects, reduced on the engine thread so the UI only paints: the ACE
//! series' envelope over one exposure cycle with the Welch estimate in the model PSD's units, and a frame's
//! display limits. Presentation only: the physics (the series, the Welch estimate and its units) is the
//! engine's.

use super::protocol::SeriesView;
use engine::config::Config;
use engine::jitter::welch::{self, Axis};
use engine::simulate::Simulator;

/// Points of each envelope drawn (two per bucket) and bins of the log-binned PSD.
const ENVELOPE_BUCKETS: usize = 2000;
const PSD_BINS: usize = 160;

/// The Welch estimate of a simulator's x series in the model PSD's units, log-binned for drawing
/// (`[log10 f, log10 psd]`), and the generator's factor (mas²/Hz per model unit); empty without a series.
pub type PsdEstimate = (Vec<[f64; 2]>, Option<f64>);

/// The Welch estimate of `sim`'s series, at its true amplitude in the model's units (see [`PsdEstimate`]).
pub fn psd_estimate(sim: &Simulator) -> PsdEstimate {
    let Some(s) = sim.series() else {
        return (Vec::new(), None);
    };
    // segments of 1/8 of the series (frequency resolution 8/span); a simulator generates its series with
    // (cfg.seed, index 0)
    let seg = (s.len() / 8).max(16);
    match welch::welch_in_model_units(&sim.cfg.ace, s, sim.cfg.seed, 0, Axis::X, seg) {
        Some((w, gain)) => {
            let binned = log_bin(&w, PSD_BINS)
                .into_iter()
                .map(|[f, p]| [f.log10(), p.log10()])
                .filter(|v| v[0].is_finite() && v[1].is_finite())
                .collect();
            (binned, Some(gain))
        }
        None => (Vec::new(), None),
    }
}

/// The series view of exposure `index` of `sim` (`cfg`: the request's configuration, which `sim` simulates;
/// `psd`: [`psd_estimate`] of `sim`).
pub fn series_view(
    sim: &Simulator,
    cfg: &Config,
    index: usize,
    psd: PsdEstimate,
    generation: u64,
) -> SeriesView {
    let (welch_log, model_gain) = psd;
    let mut view = SeriesView {
        generation,
        cfg: cfg.clone(),
        cfg_hash: cfg.hash_hex(),
        image_index: index,
        x: Vec::new(),
        y: Vec::new(),
        welch_log,
        model_gain,
        achieved_sigma_mas: (0.0, 0.0),
    };
    let Some(s) = sim.series() else {
        return view;
    };
    let t0 = sim.exposure_start_s(index);
    let t1 = t0 + sim.timing.span_s();
    let a = ((t0 / s.dt_s).floor().max(0.0) as usize).min(s.len());
    let b = ((t1 / s.dt_s).ceil().max(0.0) as usize).min(s.len()).max(a);
    let offset = a as f64 * s.dt_s - t0;
    view.x = envelope(&s.x_mas[a..b], s.dt_s, offset, ENVELOPE_BUCKETS);
    view.y = envelope(&s.y_mas[a..b], s.dt_s, offset, ENVELOPE_BUCKETS);
    view.achieved_sigma_mas = s.achieved_sigma_mas;
    view
}

/// Min/max envelope of a series in at most `buckets` buckets: points `[t, v]` (two per bucket).
pub fn envelope(v: &[f64], dt: f64, t_offset: f64, buckets: usize) -> Vec<[f64; 2]> {
    if v.is_empty() {
        return Vec::new();
    }
    let per = v.len().div_ceil(buckets.max(1)).max(1);
    let mut out = Vec::with_capacity(2 * buckets);
    for (b, chunk) in v.chunks(per).enumerate() {
        let (mut imin, mut imax) = (0, 0);
        for (i, x) in chunk.iter().enumerate() {
            if *x < chunk[imin] {
                imin = i;
            }
            if *x > chunk[imax] {
                imax = i;
            }
        }
        let base = b * per;
        let (first, second) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        for i in [first, second] {
            out.push([t_offset + (base + i) as f64 * dt, chunk[i]]);
        }
    }
    out
}

/// Average `(f, p)` pairs into `bins` logarithmic frequency bins (f > 0 only), for drawing.
pub fn log_bin(w: &[(f64, f64)], bins: usize) -> Vec<[f64; 2]> {
    let pos: Vec<&(f64, f64)> = w.iter().filter(|(f, p)| *f > 0.0 && *p > 0.0).collect();
    let (Some(first), Some(last)) = (pos.first(), pos.last()) else {
        return Vec::new();
    };
    let (la, lb) = (first.0.ln(), last.0.ln());
    if !(lb > la) {
        return pos.iter().map(|(f, p)| [*f, *p]).collect();
    }
    let mut acc = vec![(0.0, 0.0, 0usize); bins];
    for (f, p) in pos {
        let k = (((f.ln() - la) / (lb - la)) * bins as f64).floor() as usize;
        let a = &mut acc[k.min(bins - 1)];
        a.0 += f;
        a.1 += p;
        a.2 += 1;
    }
    acc.into_iter()
        .filter(|a| a.2 > 0)
        .map(|(f, p, n)| [f / n as f64, p / n as f64])
        .collect()
}

/// Display limits of a frame: (low quantile ≈ sky, maximum, robust spread), from the photosensitive pixels.
pub fn display_limits(adu: &[f32], dq: &[u8]) -> (f32, f32, f32) {
    let border = engine::detector::dq::BORDER;
    let mut s: Vec<f32> = adu
        .iter()
        .zip(dq)
        .filter(|(_, q)| *q & border == 0)
        .map(|(v, _)| *v)
        .step_by(3)
        .collect();
    if s.is_empty() {
        return (0.0, 1.0, 1.0);
    }
    let hi = adu.iter().copied().fold(f32::MIN, f32::max);
    s.sort_unstable_by(|a, b| a.total_cmp(b));
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    let (q16, q50, q84) = (q(0.16), q(0.5), q(0.84));
    let noise = (0.5 * (q84 - q16)).max(1e-3);
    let lo = q50 - 2.0 * noise;
    (lo, hi.max(lo + 1.0), noise)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_extremes_in_time_order() {
        let v: Vec<f64> = (0..1000).map(|i| ((i as f64) * 0.1).sin()).collect();
        let e = envelope(&v, 0.01, 1.0, 10);
        assert_eq!(e.len(), 20);
        assert!(e.windows(2).all(|w| w[0][0] <= w[1][0]));
        let max = e.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        assert!((max - 1.0).abs() < 1e-3);
        assert!((e[0][0] - 1.0).abs() < 0.2);
    }

    #[test]
    fn log_bins_average_power() {
        let w: Vec<(f64, f64)> = (0..1000).map(|k| (k as f64 * 0.01, 2.0)).collect();
        let b = log_bin(&w, 20);
        assert!(!b.is_empty() && b.len() <= 20);
        assert!(b.iter().all(|p| (p[1] - 2.0).abs() < 1e-12));
    }
}
