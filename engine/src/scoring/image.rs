//! One analysis of this engine scored against its exposure's truth (SPEC §7).
//!
//! * **Match** ([`match_stars`]): isolated fields — each fitted position, less the common offset (the median
//!   displacement to the nearest true star within [`OFFSET_SEARCH_PX`], when ≥ 3 such pairs exist), takes
//!   the nearest true star within [`MATCH_RADIUS_PX`]; crowded fields — position *and* flux
//!   ([`super::matching::match_catalogue`]). Every analysis of a plan holds the plain analysis' stars in
//!   the same order (a countermeasure corrects them; `exact-epsf` refits the same detections), so the plain
//!   analysis' match scores them all and each countermeasure is scored on the same stars.
//! * Position accuracy = the standard deviation over the used stars (matched, not rejected, finite) of
//!   fitted − true, per axis, in mas (a common offset of all stars does not count); "combined" is the
//!   quadratic mean of the two axes (`√((σx² + σy²)/2)`, a per-axis figure comparable to the per-axis bound).
//! * The Cramér–Rao bound of each star comes from its fit; the report gives the median over the used stars
//!   and accuracy / bound.
//! * Pixel-phase bias: mean (fitted − true) in five bins of the true position's sub-pixel phase; its largest
//!   excursion is the signature of a bad ePSF.
//! * Fewer than [`MIN_SCORED_STARS`] used stars, or no truth: every statistic is absent (NaN), never 0.

use crate::analysis::countermeasures::Countermeasure;
use crate::analysis::crowded::CrowdedSummary;
use crate::analysis::detection::match_positions;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::fit::flags;
use crate::analysis::pipeline::{Analysis, ImageAnalysis};
use crate::analysis::report::{Report as AnalysisReport, StarResult};
use crate::numerics::stats;
use crate::truth::TruthRow;
use serde::Serialize;
use std::ops::Deref;

/// Largest distance of an isolated star's fit from its true position (after the common offset), px.
pub const MATCH_RADIUS_PX: f64 = 2.0;
/// Search radius of the common offset, px.
pub const OFFSET_SEARCH_PX: f64 = 20.0;
/// Fewest used stars (matched to the truth, not rejected) for an accuracy: a standard deviation needs two.
pub const MIN_SCORED_STARS: usize = 2;

/// One star's measurement against the truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoredStar {
    #[serde(flatten)]
    pub fit: StarResult,
    /// Index into the truth, if matched.
    pub truth: Option<usize>,
    /// fitted − true (px), after any countermeasure correction (NaN unmatched).
    pub dx_px: f64,
    pub dy_px: f64,
    /// The displacement the ACE series predicts for this star (px): the mean jitter over its window (truth).
    pub predicted_dx_px: f64,
    pub predicted_dy_px: f64,
    /// The fit displacement the ACE series predicts through the fit's response
    /// ([`crate::analysis::response`]), px (0 where not computed).
    pub predicted_fit_dx_px: f64,
    pub predicted_fit_dy_px: f64,
}

impl Deref for ScoredStar {
    type Target = StarResult;
    fn deref(&self) -> &StarResult {
        &self.fit
    }
}

impl ScoredStar {
    /// Whether the star counts in the accuracy statistics: matched to the truth, not rejected, finite.
    pub fn is_used(&self) -> bool {
        self.truth.is_some() && self.fit.flags & flags::REJECT == 0 && self.dx_px.is_finite()
    }

    /// A measurement against its true star (if matched).
    pub fn new(fit: StarResult, truth: Option<(usize, &TruthRow)>) -> Self {
        Self {
            fit,
            truth: truth.map(|(k, _)| k),
            dx_px: truth.map(|(_, t)| fit.x - t.x_px).unwrap_or(f64::NAN),
            dy_px: truth.map(|(_, t)| fit.y - t.y_px).unwrap_or(f64::NAN),
            predicted_dx_px: truth.map(|(_, t)| t.jitter_dx_px).unwrap_or(0.0),
            predicted_dy_px: truth.map(|(_, t)| t.jitter_dy_px).unwrap_or(0.0),
            predicted_fit_dx_px: 0.0,
            predicted_fit_dy_px: 0.0,
        }
    }
}

/// An analysis' report with its accuracy against the truth (all angles in mas). The analysis' own figures
/// (detections, the ePSF, the countermeasure) are read through it.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Report {
    #[serde(flatten)]
    pub analysis: AnalysisReport,
    pub n_matched: usize,
    pub n_used: usize,
    pub accuracy_x_mas: f64,
    pub accuracy_y_mas: f64,
    pub accuracy_mas: f64,
    pub bias_x_mas: f64,
    pub bias_y_mas: f64,
    pub crlb_median_mas: f64,
    pub accuracy_over_crlb: f64,
    pub phase_bias_x_mas: f64,
    pub phase_bias_y_mas: f64,
    /// Correlation and slope of measured against ACE-predicted displacement, per axis.
    pub predicted_corr_x: f64,
    pub predicted_corr_y: f64,
    pub predicted_slope_x: f64,
    pub predicted_slope_y: f64,
    /// RMS over stars of the predicted displacement (mean removed), combined per axis.
    pub predicted_rms_mas: f64,
    /// The same against the fit-response prediction (slope ≈ 1 when the mechanism is understood).
    pub response_corr_x: f64,
    pub response_corr_y: f64,
    pub response_slope_x: f64,
    pub response_slope_y: f64,
    pub response_rms_mas: f64,
}

impl Deref for Report {
    type Target = AnalysisReport;
    fn deref(&self) -> &AnalysisReport {
        &self.analysis
    }
}

/// One analysis scored.
#[derive(Debug, Clone)]
pub struct Scored {
    pub report: Report,
    pub stars: Vec<ScoredStar>,
    pub epsf: Epsf,
}

/// One image's analyses under a plan, scored.
#[derive(Debug, Clone)]
pub struct ScoredImage {
    /// The plain (global-ePSF) analysis.
    pub global: Scored,
    /// One per countermeasure of the plan that applied, in plan order.
    pub measured: Vec<(Countermeasure, Scored)>,
    /// What the crowded-field analysis did, when it ran.
    pub crowded: Option<CrowdedSummary>,
    /// Reported stars of the plain analysis matched to no true star: noise peaks, light from stars off the
    /// array's edge, duplicates (`None` without a truth).
    pub n_unmatched: Option<usize>,
}

impl ScoredImage {
    /// The scored analysis of one countermeasure, if it applied.
    pub fn of(&self, cm: &Countermeasure) -> Option<&Scored> {
        self.measured.iter().find(|(c, _)| c == cm).map(|(_, a)| a)
    }

    /// The scored analysis of one countermeasure, if it applied, taken out.
    pub fn into_of(self, cm: &Countermeasure) -> Option<Scored> {
        self.measured
            .into_iter()
            .find(|(c, _)| c == cm)
            .map(|(_, a)| a)
    }
}

/// Largest |mean(d) − overall mean| over five bins of sub-pixel phase.
pub fn phase_bias(d: &[f64], phase: &[f64]) -> f64 {
    let m = stats::mean(d);
    let mut worst: f64 = 0.0;
    for b in 0..5 {
        let (lo, hi) = (-0.5 + 0.2 * b as f64, -0.3 + 0.2 * b as f64);
        let v: Vec<f64> = d
            .iter()
            .zip(phase)
            .filter(|(_, p)| **p >= lo && **p < hi)
            .map(|(x, _)| *x)
            .collect();
        if v.len() >= 3 {
            worst = worst.max((stats::mean(&v) - m).abs());
        }
    }
    worst
}

/// Match an analysis' stars to the truth (see the module's documentation); `crowded`: by position and flux.
pub fn match_stars(stars: &[StarResult], truth: &[TruthRow], crowded: bool) -> Vec<Option<usize>> {
    if crowded {
        return super::matching::match_catalogue(stars, truth);
    }
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let refs: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
    match_positions(&pos, &refs, OFFSET_SEARCH_PX, MATCH_RADIUS_PX)
}

/// Score one analysis whose stars are matched by `matches` (one per star) to `truth`.
pub fn score_matched(
    analysis: &Analysis,
    truth: Option<&[TruthRow]>,
    matches: &[Option<usize>],
    scale_mas: f64,
) -> Scored {
    let stars: Vec<ScoredStar> = analysis
        .stars
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let t = truth.and_then(|t| {
                let j = matches.get(k).copied().flatten()?;
                Some((j, t.get(j)?))
            });
            ScoredStar::new(*s, t)
        })
        .collect();
    let report = summarise(&stars, truth, scale_mas, &analysis.report);
    Scored {
        report,
        stars,
        epsf: analysis.epsf.clone(),
    }
}

/// Score one analysis against `truth` (none: every accuracy absent).
pub fn score(analysis: &Analysis, truth: Option<&[TruthRow]>, scale_mas: f64) -> Scored {
    let matches = match truth {
        Some(t) => match_stars(&analysis.stars, t, analysis.report.crowded),
        None => vec![None; analysis.stars.len()],
    };
    score_matched(analysis, truth, &matches, scale_mas)
}

/// Score every analysis of an image against `truth` on the plain analysis' match.
pub fn score_image(ia: &ImageAnalysis, truth: Option<&[TruthRow]>, scale_mas: f64) -> ScoredImage {
    score_image_in_frames(ia, truth, None, scale_mas)
}

/// [`score_image`], the countermeasures referenced to the reference catalogue (`plate-*@catalogue`, alone or
/// after the forward model) scored in the catalogue's frame: against `catalogue_truth`, the truth's stars
/// in the same order at their true sky places through the header's design WCS ([`in_header_frame`]). Their
/// positions are the catalogue's by construction (the plate model maps the fits onto it); where the header
/// misses the instrument as built (its pointing, roll, array placement, distortion) the catalogue's frame is
/// not the image's. `None`: the frames agree.
pub fn score_image_in_frames(
    ia: &ImageAnalysis,
    truth: Option<&[TruthRow]>,
    catalogue_truth: Option<&[TruthRow]>,
    scale_mas: f64,
) -> ScoredImage {
    let global = score(&ia.global, truth, scale_mas);
    let matches: Vec<Option<usize>> = global.stars.iter().map(|s| s.truth).collect();
    let measured = ia
        .measured
        .iter()
        .map(|(cm, a)| {
            let truth = if cm.is_catalogue_plate() {
                catalogue_truth.or(truth)
            } else {
                truth
            };
            // the same stars in the same order (see the module's documentation); else matched on their own
            let s = if a.stars.len() == matches.len() {
                score_matched(a, truth, &matches, scale_mas)
            } else {
                score(a, truth, scale_mas)
            };
            (*cm, s)
        })
        .collect();
    ScoredImage {
        n_unmatched: truth.map(|_| global.stars.iter().filter(|s| s.truth.is_none()).count()),
        global,
        measured,
        crowded: ia.crowded.clone(),
    }
}

/// The truth of a simulated array in its header's frame ([`in_header_frame`] through the simulator's WCS as
/// built and its design WCS), or `None` when the two agree (no pointing, roll, placement or distortion beyond
/// the design, or the oracle control): what [`score_image_in_frames`] scores the catalogue-referenced
/// countermeasures against.
pub fn catalogue_truth(
    sim: &crate::simulate::Simulator,
    truth: &[TruthRow],
) -> Option<Vec<TruthRow>> {
    if !sim.wcs_deviates() {
        return None;
    }
    Some(in_header_frame(truth, |x, y| sim.in_header_frame_px(x, y)))
}

/// `truth` with every star's position moved into the header's frame by `to_header(x, y)` (its true pixel →
/// its sky place through the WCS as built → the design WCS's pixel); NaN where it has none.
pub fn in_header_frame(
    truth: &[TruthRow],
    to_header: impl Fn(f64, f64) -> Option<(f64, f64)>,
) -> Vec<TruthRow> {
    truth
        .iter()
        .map(|t| {
            let (x_px, y_px) = to_header(t.x_px, t.y_px).unwrap_or((f64::NAN, f64::NAN));
            TruthRow { x_px, y_px, ..*t }
        })
        .collect()
}

/// Attach per-truth-star fit-response predictions (px) to a scored analysis and refresh its report.
pub fn attach_fit_prediction(
    scored: &mut Scored,
    per_truth: &[(f64, f64)],
    truth: &[TruthRow],
    scale_mas: f64,
) {
    for s in scored.stars.iter_mut() {
        if let Some(&(px, py)) = s.truth.and_then(|k| per_truth.get(k)) {
            s.predicted_fit_dx_px = px;
            s.predicted_fit_dy_px = py;
        }
    }
    scored.report = summarise(
        &scored.stars,
        Some(truth),
        scale_mas,
        &scored.report.analysis,
    );
}

/// The accuracy statistics of scored stars beside the analysis' report (`truth`: the truth their indices
/// point into, for the pixel-phase bias; without it that bias is absent).
pub fn summarise(
    stars: &[ScoredStar],
    truth: Option<&[TruthRow]>,
    scale: f64,
    analysis: &AnalysisReport,
) -> Report {
    let used: Vec<&ScoredStar> = stars.iter().filter(|s| s.is_used()).collect();
    let mut report = Report {
        analysis: analysis.clone(),
        n_matched: stars.iter().filter(|s| s.truth.is_some()).count(),
        n_used: used.len(),
        ..Default::default()
    };
    if used.len() < MIN_SCORED_STARS {
        // no accuracy without at least two scored stars (or without a truth to score against): absent
        // (NaN, `null` in JSON), never 0, so nothing downstream can count it as meeting a threshold
        // …and so is every statistic over the scored stars (the bound, the phase bias, the prediction's fit)
        for v in [
            &mut report.accuracy_x_mas,
            &mut report.accuracy_y_mas,
            &mut report.accuracy_mas,
            &mut report.bias_x_mas,
            &mut report.bias_y_mas,
            &mut report.crlb_median_mas,
            &mut report.accuracy_over_crlb,
            &mut report.phase_bias_x_mas,
            &mut report.phase_bias_y_mas,
            &mut report.predicted_corr_x,
            &mut report.predicted_corr_y,
            &mut report.predicted_slope_x,
            &mut report.predicted_slope_y,
            &mut report.predicted_rms_mas,
            &mut report.response_corr_x,
            &mut report.response_corr_y,
            &mut report.response_slope_x,
            &mut report.response_slope_y,
            &mut report.response_rms_mas,
        ] {
            *v = f64::NAN;
        }
        return report;
    }
    let dx: Vec<f64> = used.iter().map(|s| s.dx_px * scale).collect();
    let dy: Vec<f64> = used.iter().map(|s| s.dy_px * scale).collect();
    report.accuracy_x_mas = stats::std_dev(&dx);
    report.accuracy_y_mas = stats::std_dev(&dy);
    report.accuracy_mas =
        ((report.accuracy_x_mas.powi(2) + report.accuracy_y_mas.powi(2)) / 2.0).sqrt();
    report.bias_x_mas = stats::mean(&dx);
    report.bias_y_mas = stats::mean(&dy);
    let crlb: Vec<f64> = used
        .iter()
        .map(|s| ((s.crlb_x_px.powi(2) + s.crlb_y_px.powi(2)) / 2.0).sqrt() * scale)
        .filter(|v| v.is_finite())
        .collect();
    report.crlb_median_mas = stats::median(&crlb);
    report.accuracy_over_crlb = if report.crlb_median_mas > 0.0 {
        report.accuracy_mas / report.crlb_median_mas
    } else {
        f64::NAN
    };
    // the phase of each used star's true position (every used star is matched)
    (report.phase_bias_x_mas, report.phase_bias_y_mas) = match truth {
        Some(t) => {
            let phase = |f: fn(&TruthRow) -> f64| -> Vec<f64> {
                used.iter()
                    .filter_map(|s| t.get(s.truth?).map(|r| f(r) - f(r).round()))
                    .collect()
            };
            (
                phase_bias(&dx, &phase(|r| r.x_px)),
                phase_bias(&dy, &phase(|r| r.y_px)),
            )
        }
        None => (f64::NAN, f64::NAN),
    };
    let fit_line = |p: &[f64], d: &[f64]| (stats::correlation(p, d), stats::slope(p, d));
    let pdx: Vec<f64> = used.iter().map(|s| s.predicted_dx_px * scale).collect();
    let pdy: Vec<f64> = used.iter().map(|s| s.predicted_dy_px * scale).collect();
    (report.predicted_corr_x, report.predicted_slope_x) = fit_line(&pdx, &dx);
    (report.predicted_corr_y, report.predicted_slope_y) = fit_line(&pdy, &dy);
    report.predicted_rms_mas =
        ((stats::std_dev(&pdx).powi(2) + stats::std_dev(&pdy).powi(2)) / 2.0).sqrt();
    let rdx: Vec<f64> = used.iter().map(|s| s.predicted_fit_dx_px * scale).collect();
    let rdy: Vec<f64> = used.iter().map(|s| s.predicted_fit_dy_px * scale).collect();
    (report.response_corr_x, report.response_slope_x) = fit_line(&rdx, &dx);
    (report.response_corr_y, report.response_slope_y) = fit_line(&rdy, &dy);
    report.response_rms_mas =
        ((stats::std_dev(&rdx).powi(2) + stats::std_dev(&rdy).powi(2)) / 2.0).sqrt();
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth_at(pos: &[(f64, f64)]) -> Vec<TruthRow> {
        pos.iter()
            .map(|&(x, y)| TruthRow {
                x_px: x,
                y_px: y,
                ..Default::default()
            })
            .collect()
    }

    fn star(x: f64, y: f64) -> StarResult {
        StarResult {
            x,
            y,
            flux_e: 1e5,
            sky_e: 0.0,
            crlb_x_px: 0.01,
            crlb_y_px: 0.01,
            flags: 0,
        }
    }

    /// Known errors ±e on alternate stars: the per-axis accuracy is the standard deviation of ±e (sample
    /// convention), the bound the fits' own; with no truth, or one star, every statistic is absent.
    #[test]
    fn the_accuracy_is_the_scatter_of_known_errors_and_absent_without_truth() {
        let pos: Vec<(f64, f64)> = (0..20).map(|k| (10.0 + 7.0 * k as f64, 50.0)).collect();
        let truth = truth_at(&pos);
        let e = 0.02;
        let stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| star(x + if k % 2 == 0 { e } else { -e }, y))
            .collect();
        let analysis = Analysis {
            report: AnalysisReport::default(),
            stars,
            epsf: Epsf::from_fn(4, 2, |_, _| 0.0),
        };
        let s = score(&analysis, Some(&truth), 100.0);
        assert_eq!(s.report.n_used, 20);
        // the offset removed by the match is the median (0); the sample std of ±e over 20 stars
        let sx = e * 100.0 * (20.0f64 / 19.0).sqrt();
        assert!(
            (s.report.accuracy_x_mas - sx).abs() < 1e-9,
            "{}",
            s.report.accuracy_x_mas
        );
        assert!(s.report.accuracy_y_mas.abs() < 1e-9);
        assert!((s.report.accuracy_mas - sx / 2f64.sqrt()).abs() < 1e-9);
        assert!((s.report.crlb_median_mas - 1.0).abs() < 1e-9);
        let none = score(&analysis, None, 100.0);
        assert!(none.report.accuracy_mas.is_nan() && none.report.crlb_median_mas.is_nan());
        assert_eq!(none.report.n_matched, 0);
        let one = Analysis {
            stars: analysis.stars[..1].to_vec(),
            ..analysis.clone()
        };
        assert!(
            score(&one, Some(&truth), 100.0)
                .report
                .accuracy_mas
                .is_nan()
        );
    }

    /// A star 3 px from every true star is no match (beyond [`MATCH_RADIUS_PX`]) and never scored.
    #[test]
    fn a_fit_beyond_the_match_radius_is_unmatched() {
        let pos: Vec<(f64, f64)> = (0..5).map(|k| (20.0 * k as f64, 20.0)).collect();
        let truth = truth_at(&pos);
        let mut stars: Vec<StarResult> = pos.iter().map(|&(x, y)| star(x, y)).collect();
        stars.push(star(10.0, 23.0));
        let m = match_stars(&stars, &truth, false);
        assert_eq!(m[..5], [Some(0), Some(1), Some(2), Some(3), Some(4)]);
        assert_eq!(m[5], None);
    }
}
