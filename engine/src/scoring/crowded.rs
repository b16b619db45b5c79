//! Scoring a crowded exposure: the cross-match of fits to the truth, the class of each star, and
//! per-magnitude-bin statistics over the arrays.
//!
//! * **Match** ([`match_catalogue`]): the common offset as in [`crate::analysis::detection::match_positions`],
//!   then each fit takes the truth star within [`MATCH_RADIUS_PX`] that best agrees in position *and* flux
//!   (score `(d/0.5 px)² + (Δm/0.3 mag)²`, one-to-one, best scores first) — in a crowded field the nearest
//!   truth star is often a faint one under a bright star's fit.
//! * **Classes**: *isolated* — fitted alone (not [`flags::GROUPED`], not [`flags::BLENDED`]), unsaturated
//!   and not merged; *crowded* — fitted in a group or with a detected neighbour within the blend radius;
//!   *merged* — the truth has an undetected companion within [`MERGE_RADIUS_PX`] carrying ≥
//!   [`MERGE_FLUX_RATIO`] of the star's flux (the fit measured a blend as one star: only a simulation can
//!   tell); *saturated* — fitted from its wings.
//! * **Bins** ([`mag_bins`]): per bin of true Hw, over all arrays: the truth stars on the arrays, those
//!   found (completeness), the fraction of found stars flagged blended (or merged) or saturated, and per
//!   class the accuracy (std over stars of fitted − true per axis, combined as √((σx² + σy²)/2), mas; each
//!   array's own common offset — its median over used stars — removed first) with the median
//!   Cramér–Rao bound of the same stars.

use super::image::ScoredStar;
use super::undetected::Undetected;
use crate::analysis::epsf::fit::flags;
use crate::analysis::report::StarResult;
use crate::numerics::neighbours::Neighbours;
use crate::numerics::stats;
use crate::truth::TruthRow;
use serde::Serialize;

pub use super::matching::{MATCH_RADIUS_PX, match_catalogue};
/// An undetected truth star this close to a found star, px …
pub const MERGE_RADIUS_PX: f64 = 1.5;
/// … with at least this fraction of its flux makes the found star a merged blend.
pub const MERGE_FLUX_RATIO: f64 = 0.1;

/// Whether each star result is a merged blend: its truth star has a companion within [`MERGE_RADIUS_PX`]
/// with ≥ [`MERGE_FLUX_RATIO`] of its flux that no result matched.
pub fn merged(stars: &[ScoredStar], truth: &[TruthRow]) -> Vec<bool> {
    let refs: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
    let nb = Neighbours::new(&refs);
    let mut found = vec![false; truth.len()];
    for s in stars {
        if let Some(k) = s.truth {
            found[k] = true;
        }
    }
    stars
        .iter()
        .map(|s| {
            s.truth.is_some_and(|k| {
                nb.within(refs[k].0, refs[k].1, MERGE_RADIUS_PX)
                    .into_iter()
                    .any(|j| {
                        j != k && !found[j] && truth[j].flux_e >= MERGE_FLUX_RATIO * truth[k].flux_e
                    })
            })
        })
        .collect()
}

/// The class of a star in the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Class {
    Isolated,
    Crowded,
    Merged,
    Saturated,
}

/// A star's class (see the module's documentation).
pub fn class(s: &StarResult, merged: bool) -> Class {
    if s.flags & flags::SATURATED != 0 {
        Class::Saturated
    } else if merged {
        Class::Merged
    } else if s.flags & (flags::GROUPED | flags::BLENDED) != 0 {
        Class::Crowded
    } else {
        Class::Isolated
    }
}

/// One array's results for the bins: its star results (residuals against `truth`), its truth and its size.
pub struct ArrayStars<'a> {
    pub stars: &'a [ScoredStar],
    pub truth: &'a [TruthRow],
    pub n_px: usize,
    /// The array's undetected stars, for the shifts their light gives the isolated stars (none: not computed).
    pub undetected: Option<&'a Undetected>,
}

impl ArrayStars<'_> {
    /// (x px, y px, flux e⁻, Hw) of the truth stars on the array that no fit matched.
    pub fn unmatched(
        stars: &[ScoredStar],
        truth: &[TruthRow],
        n_px: usize,
    ) -> Vec<(f64, f64, f64, f64)> {
        let mut found = vec![false; truth.len()];
        for k in stars.iter().filter_map(|s| s.truth) {
            found[k] = true;
        }
        truth
            .iter()
            .zip(&found)
            .filter(|(t, f)| !**f && on_array(t, n_px))
            .map(|(t, _)| (t.x_px, t.y_px, t.flux_e, t.mag_hw))
            .collect()
    }
}

/// Whether a truth star lies on an array of `n_px`² pixels.
fn on_array(t: &TruthRow, n_px: usize) -> bool {
    t.x_px >= 0.0 && t.y_px >= 0.0 && t.x_px < n_px as f64 && t.y_px < n_px as f64
}

/// Accuracy and bound of one class in one bin (NaN with fewer than 3 stars).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct ClassStats {
    pub n: usize,
    pub accuracy_mas: f64,
    pub crlb_mas: f64,
}

impl ClassStats {
    /// Accuracy over the bound.
    pub fn ratio(&self) -> f64 {
        self.accuracy_mas / self.crlb_mas
    }
}

/// One magnitude bin of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MagBin {
    pub hw_lo: f64,
    pub hw_hi: f64,
    /// Truth stars on the arrays, and those a fit was matched to.
    pub n_true: usize,
    pub n_found: usize,
    pub completeness: f64,
    /// Fractions of the found stars flagged blended (a detected neighbour within the blend radius, or
    /// merged) and saturated.
    pub frac_blended: f64,
    pub frac_saturated: f64,
    pub isolated: ClassStats,
    pub crowded: ClassStats,
    pub merged: ClassStats,
    /// The rms shift the undetected stars' light gives the isolated stars' fits (per axis, mas;
    /// [`super::undetected`]): from all of them, and from those fainter than the reference catalogue's limit.
    /// NaN when not computed or with fewer than 3 stars.
    pub isolated_undetected_mas: f64,
    pub isolated_undetected_faint_mas: f64,
}

impl MagBin {
    /// The isolated stars' accuracy if only the photon noise (their bound) and the undetected stars' light
    /// acted: `√(bound² + undetected²)`, mas.
    pub fn isolated_predicted_mas(&self) -> f64 {
        self.isolated.crlb_mas.hypot(self.isolated_undetected_mas)
    }
}

fn class_stats(d: &[(f64, f64, f64)]) -> ClassStats {
    if d.len() < 3 {
        return ClassStats {
            n: d.len(),
            accuracy_mas: f64::NAN,
            crlb_mas: f64::NAN,
        };
    }
    let dx: Vec<f64> = d.iter().map(|v| v.0).collect();
    let dy: Vec<f64> = d.iter().map(|v| v.1).collect();
    let b: Vec<f64> = d.iter().map(|v| v.2).collect();
    ClassStats {
        n: d.len(),
        accuracy_mas: ((stats::std_dev(&dx).powi(2) + stats::std_dev(&dy).powi(2)) / 2.0).sqrt(),
        crlb_mas: stats::median(&b),
    }
}

/// `√(mean)` of squares (NaN for fewer than 3).
fn rms(sq: impl ExactSizeIterator<Item = f64>) -> f64 {
    let n = sq.len();
    if n < 3 {
        return f64::NAN;
    }
    (sq.sum::<f64>() / n as f64).sqrt()
}

/// Bins of true Hw `[edges[i], edges[i+1])` over the arrays (see the module's documentation).
pub fn mag_bins(arrays: &[ArrayStars<'_>], scale_mas: f64, edges: &[f64]) -> Vec<MagBin> {
    let nb = edges.len().saturating_sub(1);
    let bin_of = |hw: f64| (0..nb).find(|&b| hw >= edges[b] && hw < edges[b + 1]);
    let mut n_true = vec![0usize; nb];
    let mut n_found = vec![0usize; nb];
    let mut n_blend = vec![0usize; nb];
    let mut n_sat = vec![0usize; nb];
    let mut per: Vec<[Vec<(f64, f64, f64)>; 3]> = (0..nb).map(|_| Default::default()).collect();
    // the isolated stars' squared shifts from the undetected stars (all, faint), per axis, mas²
    let mut und: Vec<Vec<(f64, f64)>> = vec![Vec::new(); nb];
    for a in arrays {
        let on = |t: &TruthRow| on_array(t, a.n_px);
        for t in a.truth.iter().filter(|t| on(t)) {
            if let Some(b) = bin_of(t.mag_hw) {
                n_true[b] += 1;
            }
        }
        let m = merged(a.stars, a.truth);
        let used: Vec<&ScoredStar> = a.stars.iter().filter(|s| s.is_used()).collect();
        let ox = stats::median(&used.iter().map(|s| s.dx_px).collect::<Vec<_>>());
        let oy = stats::median(&used.iter().map(|s| s.dy_px).collect::<Vec<_>>());
        for (s, &mg) in a.stars.iter().zip(&m) {
            let Some(k) = s.truth else { continue };
            let t = &a.truth[k];
            let Some(b) = bin_of(t.mag_hw).filter(|_| on(t)) else {
                continue;
            };
            n_found[b] += 1;
            let c = class(s, mg);
            if mg || s.flags & flags::BLENDED != 0 {
                n_blend[b] += 1;
            }
            if c == Class::Saturated {
                n_sat[b] += 1;
            }
            if !s.is_used() {
                continue;
            }
            let v = (
                (s.dx_px - ox) * scale_mas,
                (s.dy_px - oy) * scale_mas,
                ((s.crlb_x_px.powi(2) + s.crlb_y_px.powi(2)) / 2.0).sqrt() * scale_mas,
            );
            match c {
                Class::Isolated => {
                    per[b][0].push(v);
                    // where the star lies among the undetected stars: its true place plus its error, in
                    // the truth's frame (a catalogue-referenced countermeasure reports its fit in the
                    // catalogue's frame, off the image's by the pointing and the arrays' assembly)
                    let (x, y) = (t.x_px + s.dx_px, t.y_px + s.dy_px);
                    if let Some(sh) = a.undetected.and_then(|u| u.star(x, y, s.flux_e, s.sky_e)) {
                        let sq =
                            |d: (f64, f64)| (d.0 * d.0 + d.1 * d.1) / 2.0 * scale_mas * scale_mas;
                        und[b].push((sq(sh.all_px), sq(sh.faint_px)));
                    }
                }
                Class::Crowded => per[b][1].push(v),
                Class::Merged => per[b][2].push(v),
                Class::Saturated => {}
            }
        }
    }
    (0..nb)
        .map(|b| {
            let frac = |k: usize| {
                if n_found[b] > 0 {
                    k as f64 / n_found[b] as f64
                } else {
                    f64::NAN
                }
            };
            MagBin {
                hw_lo: edges[b],
                hw_hi: edges[b + 1],
                n_true: n_true[b],
                n_found: n_found[b],
                completeness: if n_true[b] > 0 {
                    n_found[b] as f64 / n_true[b] as f64
                } else {
                    f64::NAN
                },
                frac_blended: frac(n_blend[b]),
                frac_saturated: frac(n_sat[b]),
                isolated: class_stats(&per[b][0]),
                crowded: class_stats(&per[b][1]),
                merged: class_stats(&per[b][2]),
                isolated_undetected_mas: rms(und[b].iter().map(|v| v.0)),
                isolated_undetected_faint_mas: rms(und[b].iter().map(|v| v.1)),
            }
        })
        .collect()
}

/// Bin edges every `step` magnitudes covering `[lo, hi]`.
pub fn edges(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let (a, b) = ((lo / step).floor() as i64, (hi / step).ceil() as i64);
    (a..=b.max(a + 1)).map(|k| k as f64 * step).collect()
}
