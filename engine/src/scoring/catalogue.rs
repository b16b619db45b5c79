//! A measured list against a truth list (`jsim score`): the positions an analysis measured (from any tool:
//! only `x, y` are needed) and a truth list (`x, y` and a magnitude), matches them by position and reports
//! per magnitude bin the completeness, the position accuracy and the false detections.
//!
//! **Matching** (documented defaults, both options of `jsim score`):
//! 0. Stars carry an array number (focal-plane files); each array is matched on its own.
//! 1. The common offset (the exposure's pointing error, a tool's centring convention) is the median
//!    displacement of each measured star to its nearest true star within `offset_search_px` (20 px), when at
//!    least three such pairs exist; else none ([`crate::analysis::detection::common_offset`]).
//! 2. Each measured star, shifted back by the offset, takes the nearest true star within `match_radius_px`
//!    (1 px, 471 mas for JASMINE; a measured star further off than a pixel is not a measurement of that star
//!    but a false detection or a blend). The match is **one-to-one**: of several measured stars that reach the
//!    same true star the closest keeps it and the others count as false detections.
//!
//! **Accuracy** of a bin (the convention of SPEC §7 and [`super::image`]): the standard deviation
//! over the bin's matched stars of measured − true per axis, in mas; `accuracy_mas = √((σx² + σy²)/2)`. It is
//! **absent** (NaN; `null` in JSON, empty in CSV) with fewer than [`MIN_SCORED`] matched stars or with no
//! truth — never 0.
//!
//! **Completeness** of a bin: matched true stars / true stars in the bin, whether or not the measurement is
//! usable (a detection its tool flagged — saturated, poorly fitted — still found the star); the accuracy
//! is over the usable ones (`n_scored`). **False detections**: measured stars matched to no true star (over
//! the whole image: a false detection has no true magnitude).

use crate::analysis::detection::{common_offset, nearest_within};
use crate::numerics::stats;
use serde::Serialize;

/// Fewest matched stars for an accuracy (a standard deviation needs two).
pub const MIN_SCORED: usize = 2;

/// Default match radius [px].
pub const DEFAULT_MATCH_RADIUS_PX: f64 = 1.0;

/// Default search radius of the common offset [px].
pub const DEFAULT_OFFSET_SEARCH_PX: f64 = 20.0;

/// A measured position (pixels of its array).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    pub x_px: f64,
    pub y_px: f64,
    /// The array it was measured on (focal-plane files: 1 … 4; 0 for a single image).
    pub array: u32,
    /// Whether its position counts in the accuracy (false: a fit its tool flagged as unusable — it is
    /// still a detection for the completeness).
    pub usable: bool,
}

/// A true star: position (pixels of its array), magnitude and array.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueStar {
    pub x_px: f64,
    pub y_px: f64,
    pub mag: f64,
    /// As [`Measured::array`].
    pub array: u32,
}

/// How to score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreOptions {
    /// Match radius [px], > 0.
    pub match_radius_px: f64,
    /// Search radius of the common offset [px], ≥ the match radius.
    pub offset_search_px: f64,
    /// Magnitude bin width, > 0.
    pub bin_mag: f64,
    /// Plate scale [mas/px], > 0: the accuracies in mas.
    pub plate_scale_mas: f64,
}

impl ScoreOptions {
    /// Check every option, naming the field and its allowed range.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |v: f64, name: &str, unit: &str| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(format!(
                    "{name} = {v}: must be a finite number > 0 [{unit}]"
                ))
            }
        };
        pos(self.match_radius_px, "match_radius_px", "px")?;
        pos(self.bin_mag, "bin_mag", "mag")?;
        pos(self.plate_scale_mas, "plate_scale_mas", "mas/px")?;
        if !(self.offset_search_px >= self.match_radius_px && self.offset_search_px <= 1000.0) {
            return Err(format!(
                "offset_search_px = {}: must lie in [match_radius_px = {}, 1000] px",
                self.offset_search_px, self.match_radius_px
            ));
        }
        Ok(())
    }
}

/// The score of one magnitude bin (or of all stars).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BinScore {
    pub mag_lo: f64,
    pub mag_hi: f64,
    /// True stars in the bin.
    pub n_true: usize,
    /// Of them, matched to a measured star.
    pub n_matched: usize,
    /// Of those, with a usable position: the stars the accuracy is over.
    pub n_scored: usize,
    /// n_matched / n_true (NaN for an empty bin).
    pub completeness: f64,
    pub accuracy_x_mas: f64,
    pub accuracy_y_mas: f64,
    pub accuracy_mas: f64,
    /// Mean measured − true after the common offset [mas].
    pub bias_x_mas: f64,
    pub bias_y_mas: f64,
}

/// One matched pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pair {
    pub measured: usize,
    pub truth: usize,
    /// measured − true − common offset [px].
    pub dx_px: f64,
    pub dy_px: f64,
}

/// The score of a measured list against the truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    pub bins: Vec<BinScore>,
    /// Every true star with a finite magnitude in one bin.
    pub all: BinScore,
    pub n_measured: usize,
    /// Measured stars matched to no true star.
    pub false_detections: usize,
    /// The common offset removed before matching [px] (the mean of the arrays' when there are several).
    pub offset_x_px: f64,
    pub offset_y_px: f64,
    pub pairs: Vec<Pair>,
    pub options: ScoreOptionsRecord,
}

/// The options, as recorded beside the score.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoreOptionsRecord {
    pub match_radius_px: f64,
    pub offset_search_px: f64,
    pub bin_mag: f64,
    pub plate_scale_mas: f64,
}

/// One-to-one matches: `m[i]` the true star of measured star `i`, the closest claimant keeping a true star
/// reached by several.
fn one_to_one(
    measured: &[(f64, f64)],
    truth: &[(f64, f64)],
    radius_px: f64,
    offset: (f64, f64),
) -> Vec<Option<usize>> {
    let mut m = nearest_within(measured, truth, radius_px, offset);
    let d2 = |i: usize, k: usize| {
        (measured[i].0 - offset.0 - truth[k].0).powi(2)
            + (measured[i].1 - offset.1 - truth[k].1).powi(2)
    };
    let mut owner: Vec<Option<usize>> = vec![None; truth.len()];
    for i in 0..m.len() {
        let Some(k) = m[i] else { continue };
        match owner[k] {
            Some(j) if d2(j, k) <= d2(i, k) => m[i] = None,
            Some(j) => {
                m[j] = None;
                owner[k] = Some(i);
            }
            None => owner[k] = Some(i),
        }
    }
    m
}

/// Accuracy statistics of the usable pairs `d` of a bin with `n_matched` matches (NaN below [`MIN_SCORED`]).
fn bin_score(
    mag_lo: f64,
    mag_hi: f64,
    n_true: usize,
    n_matched: usize,
    d: &[(f64, f64)],
    scale: f64,
) -> BinScore {
    let (dx, dy): (Vec<f64>, Vec<f64>) = d.iter().map(|p| (p.0 * scale, p.1 * scale)).unzip();
    let enough = d.len() >= MIN_SCORED;
    let or_nan = |v: f64| if enough { v } else { f64::NAN };
    let (sx, sy) = (or_nan(stats::std_dev(&dx)), or_nan(stats::std_dev(&dy)));
    BinScore {
        mag_lo,
        mag_hi,
        n_true,
        n_matched,
        n_scored: d.len(),
        completeness: if n_true > 0 {
            n_matched as f64 / n_true as f64
        } else {
            f64::NAN
        },
        accuracy_x_mas: sx,
        accuracy_y_mas: sy,
        accuracy_mas: ((sx * sx + sy * sy) / 2.0).sqrt(),
        bias_x_mas: or_nan(stats::mean(&dx)),
        bias_y_mas: or_nan(stats::mean(&dy)),
    }
}

/// Score measured positions against the truth (see the module's documentation).
pub fn score(
    measured: &[Measured],
    truth: &[TrueStar],
    opts: &ScoreOptions,
) -> Result<Score, String> {
    opts.validate()?;
    // each array on its own: its own common offset, matches only within it
    let mut arrays: Vec<u32> = measured
        .iter()
        .map(|m| m.array)
        .chain(truth.iter().map(|t| t.array))
        .collect();
    arrays.sort_unstable();
    arrays.dedup();
    let mut pairs: Vec<Pair> = Vec::new();
    let mut offsets = Vec::new();
    for a in arrays {
        let mi: Vec<usize> = (0..measured.len())
            .filter(|&i| measured[i].array == a)
            .collect();
        let ti: Vec<usize> = (0..truth.len()).filter(|&k| truth[k].array == a).collect();
        let pos: Vec<(f64, f64)> = mi
            .iter()
            .map(|&i| (measured[i].x_px, measured[i].y_px))
            .collect();
        let refs: Vec<(f64, f64)> = ti.iter().map(|&k| (truth[k].x_px, truth[k].y_px)).collect();
        let offset = common_offset(&pos, &refs, opts.offset_search_px);
        offsets.push(offset);
        let m = one_to_one(&pos, &refs, opts.match_radius_px, offset);
        pairs.extend(m.iter().enumerate().filter_map(|(i, k)| {
            k.map(|k| Pair {
                measured: mi[i],
                truth: ti[k],
                dx_px: pos[i].0 - offset.0 - refs[k].0,
                dy_px: pos[i].1 - offset.1 - refs[k].1,
            })
        }));
    }
    pairs.sort_by_key(|p| p.measured);
    // the offset reported: the mean over the arrays (one array: its own)
    let offset = if offsets.is_empty() {
        (0.0, 0.0)
    } else {
        (
            offsets.iter().map(|o| o.0).sum::<f64>() / offsets.len() as f64,
            offsets.iter().map(|o| o.1).sum::<f64>() / offsets.len() as f64,
        )
    };
    // per true star: matched, and its displacement when the measurement is usable
    let mut matched = vec![false; truth.len()];
    let mut matched_d: Vec<Option<(f64, f64)>> = vec![None; truth.len()];
    for p in &pairs {
        matched[p.truth] = true;
        if measured[p.measured].usable {
            matched_d[p.truth] = Some((p.dx_px, p.dy_px));
        }
    }
    let mags: Vec<f64> = truth
        .iter()
        .map(|t| t.mag)
        .filter(|v| v.is_finite())
        .collect();
    let scale = opts.plate_scale_mas;
    let mut bins = Vec::new();
    if let (Some(lo), Some(hi)) = (
        mags.iter().copied().reduce(f64::min),
        mags.iter().copied().reduce(f64::max),
    ) {
        let first = (lo / opts.bin_mag).floor() as i64;
        let last = (hi / opts.bin_mag).floor() as i64;
        for b in first..=last {
            let (a, z) = (b as f64 * opts.bin_mag, (b + 1) as f64 * opts.bin_mag);
            let inside: Vec<usize> = (0..truth.len())
                .filter(|&k| truth[k].mag >= a && truth[k].mag < z)
                .collect();
            let d: Vec<(f64, f64)> = inside.iter().filter_map(|&k| matched_d[k]).collect();
            let n_matched = inside.iter().filter(|&&k| matched[k]).count();
            bins.push(bin_score(a, z, inside.len(), n_matched, &d, scale));
        }
    }
    let finite: Vec<usize> = (0..truth.len())
        .filter(|&k| truth[k].mag.is_finite())
        .collect();
    let d_all: Vec<(f64, f64)> = finite.iter().filter_map(|&k| matched_d[k]).collect();
    let all = bin_score(
        mags.iter().copied().reduce(f64::min).unwrap_or(f64::NAN),
        mags.iter().copied().reduce(f64::max).unwrap_or(f64::NAN),
        finite.len(),
        finite.iter().filter(|&&k| matched[k]).count(),
        &d_all,
        scale,
    );
    Ok(Score {
        bins,
        all,
        n_measured: measured.len(),
        false_detections: measured.len() - pairs.len(),
        offset_x_px: offset.0,
        offset_y_px: offset.1,
        pairs,
        options: ScoreOptionsRecord {
            match_radius_px: opts.match_radius_px,
            offset_search_px: opts.offset_search_px,
            bin_mag: opts.bin_mag,
            plate_scale_mas: opts.plate_scale_mas,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn opts() -> ScoreOptions {
        ScoreOptions {
            match_radius_px: DEFAULT_MATCH_RADIUS_PX,
            offset_search_px: DEFAULT_OFFSET_SEARCH_PX,
            bin_mag: 1.0,
            plate_scale_mas: 100.0,
        }
    }

    /// Gaussian position errors of known σ are recovered within their statistical error (σ/√(2(n−1)) per
    /// axis; 3σ tolerance), the offset is removed, and missing or spurious stars are counted exactly.
    #[test]
    fn known_errors_offsets_losses_and_false_detections_are_recovered() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let sigma_px = 0.02;
        let noise = Normal::new(0.0, sigma_px).expect("normal");
        let truth: Vec<TrueStar> = (0..2000)
            .map(|k| TrueStar {
                x_px: 10.0 + 9.0 * (k % 45) as f64 + 0.37 * (k / 45) as f64,
                y_px: 10.0 + 9.0 * (k / 45) as f64,
                mag: if k % 2 == 0 { 12.3 } else { 13.6 },
                array: 0,
            })
            .collect();
        let mut measured: Vec<Measured> = truth
            .iter()
            .enumerate()
            // every fifth star of the faint bin (odd k ending in 1) is lost
            .filter(|(k, t)| !(t.mag > 13.0 && k % 10 == 1))
            .map(|(_, t)| Measured {
                x_px: t.x_px + 0.3 + noise.sample(&mut rng),
                y_px: t.y_px - 0.2 + noise.sample(&mut rng),
                array: 0,
                usable: true,
            })
            .collect();
        // five spurious detections far from every star, and a second detection next to star 0 (a duplicate)
        for k in 0..5 {
            measured.push(Measured {
                x_px: 10.0 + 4.5 + 0.3 + 9.0 * k as f64,
                y_px: 10.0 + 4.5 - 0.2,
                array: 0,
                usable: true,
            });
        }
        measured.push(Measured {
            x_px: truth[0].x_px + 0.3 + 0.6,
            y_px: truth[0].y_px - 0.2,
            array: 0,
            usable: true,
        });
        let s = score(&measured, &truth, &opts()).expect("score");
        assert!((s.offset_x_px - 0.3).abs() < 0.005 && (s.offset_y_px + 0.2).abs() < 0.005);
        assert_eq!(s.false_detections, 6);
        assert_eq!(s.bins.len(), 2);
        let (bright, faint) = (&s.bins[0], &s.bins[1]);
        assert_eq!((bright.n_true, bright.n_matched), (1000, 1000));
        assert_eq!((faint.n_true, faint.n_matched), (1000, 800));
        assert!((faint.completeness - 0.8).abs() < 1e-12);
        let expect = sigma_px * 100.0;
        for b in [bright, faint] {
            let tol = 3.0 * expect / (2.0 * (b.n_matched as f64 - 1.0)).sqrt();
            assert!(
                (b.accuracy_x_mas - expect).abs() < tol && (b.accuracy_y_mas - expect).abs() < tol,
                "{b:?}"
            );
        }
    }

    /// Two arrays with the same pixel positions: a star is matched only on its own array, each with its
    /// own offset.
    #[test]
    fn arrays_are_matched_apart() {
        let t = |x: f64, a: u32| TrueStar {
            x_px: x,
            y_px: 50.0,
            mag: 12.5,
            array: a,
        };
        let m = |x: f64, a: u32| Measured {
            x_px: x,
            y_px: 50.0,
            array: a,
            usable: true,
        };
        let truth = [
            t(10.0, 1),
            t(30.0, 1),
            t(50.0, 1),
            t(10.0, 2),
            t(30.0, 2),
            t(50.0, 2),
        ];
        // array 1 measured 0.3 px off, array 2 exactly; array 2 misses its star at 50
        let measured = [m(10.3, 1), m(30.3, 1), m(50.3, 1), m(10.0, 2), m(30.0, 2)];
        let s = score(&measured, &truth, &opts()).expect("score");
        assert_eq!(s.all.n_matched, 5);
        assert_eq!(s.false_detections, 0);
        for p in &s.pairs {
            assert_eq!(measured[p.measured].array, truth[p.truth].array);
            assert!(p.dx_px.abs() < 1e-12);
        }
    }

    /// A match whose measurement is flagged unusable counts for the completeness, not the accuracy.
    #[test]
    fn unusable_measurements_count_as_found_but_not_in_the_accuracy() {
        let truth: Vec<TrueStar> = (0..4)
            .map(|k| TrueStar {
                x_px: 10.0 + 10.0 * k as f64,
                y_px: 10.0,
                mag: 12.5,
                array: 0,
            })
            .collect();
        let measured: Vec<Measured> = truth
            .iter()
            .enumerate()
            .map(|(k, t)| Measured {
                // the unusable one is 0.5 px off: it would dominate the accuracy
                x_px: t.x_px + if k == 3 { 0.5 } else { 0.01 * k as f64 },
                y_px: t.y_px,
                array: 0,
                usable: k != 3,
            })
            .collect();
        let s = score(&measured, &truth, &opts()).expect("score");
        assert_eq!((s.all.n_matched, s.all.n_scored), (4, 3));
        assert_eq!(s.all.completeness, 1.0);
        // std of (0, 0.01, 0.02) px = 0.01 px = 1 mas at 100 mas/px
        assert!((s.all.accuracy_x_mas - 1.0).abs() < 1e-9, "{:?}", s.all);
    }

    #[test]
    fn fewer_than_two_matches_or_no_truth_leave_the_accuracy_absent() {
        let truth = [TrueStar {
            x_px: 5.0,
            y_px: 5.0,
            mag: 12.0,
            array: 0,
        }];
        let one = [Measured {
            x_px: 5.01,
            y_px: 5.0,
            array: 0,
            usable: true,
        }];
        let s = score(&one, &truth, &opts()).expect("score");
        assert_eq!(s.all.n_matched, 1);
        assert!(s.all.accuracy_mas.is_nan());
        let s = score(&one, &[], &opts()).expect("score");
        assert!(s.bins.is_empty());
        assert!(s.all.accuracy_mas.is_nan());
        assert_eq!(s.false_detections, 1);
    }

    #[test]
    fn bad_options_are_named() {
        let mut o = opts();
        o.match_radius_px = 0.0;
        let e = score(&[], &[], &o).expect_err("radius 0");
        assert!(e.contains("match_radius_px"), "{e}");
        let mut o = opts();
        o.offset_search_px = 0.5;
        let e = score(&[], &[], &o).expect_err("search < radius");
        assert!(e.contains("offset_search_px"), "{e}");
        let mut o = opts();
        o.plate_scale_mas = f64::NAN;
        assert!(
            score(&[], &[], &o)
                .expect_err("nan")
                .contains("plate_scale_mas")
        );
    }
}
