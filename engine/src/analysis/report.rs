//! The accuracy report of an image (SPEC §7).
//!
//! * Position accuracy of an image = the standard deviation over stars of (fitted − true), per axis, in mas
//!   (a common offset of all stars does not count); "combined" is the quadratic mean of the two axes
//!   (`√((σx² + σy²)/2)`, a per-axis figure comparable to the per-axis bound).
//! * The Cramér–Rao bound of each star comes from its fit ([`crate::analysis::epsf::fit`]); the report
//!   gives the median and accuracy / bound.
//! * Pixel-phase bias: mean (fitted − true) in five bins of the star's sub-pixel phase; its largest excursion
//!   is the signature of a bad ePSF.

use crate::analysis::epsf::fit::{StarFit, flags};
use crate::numerics::stats;
use crate::truth::TruthRow;
use serde::Serialize;

/// One star's result.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StarResult {
    /// Index into the truth catalogue, if matched.
    pub truth: Option<usize>,
    pub x: f64,
    pub y: f64,
    pub flux_e: f64,
    pub sky_e: f64,
    pub crlb_x_px: f64,
    pub crlb_y_px: f64,
    pub flags: u32,
    /// fitted − true (px), after any countermeasure correction.
    pub dx_px: f64,
    pub dy_px: f64,
    /// The displacement the ACE series predicts for this star (px): the mean jitter over its window (truth).
    pub predicted_dx_px: f64,
    pub predicted_dy_px: f64,
    /// The fit displacement the ACE series predicts through the fit's response ([`crate::analysis::response`]), px.
    pub predicted_fit_dx_px: f64,
    pub predicted_fit_dy_px: f64,
}

impl StarResult {
    /// Whether the star counts in the accuracy statistics: matched to the truth, not rejected, finite.
    pub fn is_used(&self) -> bool {
        self.truth.is_some() && self.flags & flags::REJECT == 0 && self.dx_px.is_finite()
    }
}

/// Summary of an image's analysis (all angles in mas).
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Report {
    pub n_detected: usize,
    pub n_matched: usize,
    pub n_used: usize,
    pub n_rejected: usize,
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
    pub epsf_iterations: usize,
    /// Isolated, unsaturated stars the ePSF could be built from.
    pub epsf_stars: usize,
    /// Empty when the ePSF was built from the image; else what stood in for it and why (too few stars).
    pub epsf_fallback: String,
    pub countermeasure: String,
    /// Whether the crowded-field analysis measured the image ([`crate::analysis::crowding`]).
    pub crowded: bool,
    /// Parameters a countermeasure fitted per exposure (degrees of freedom absorbed).
    pub dof_absorbed: usize,
    /// Exposures of the stare whose stack referenced a plate model (1: the image alone, nothing to
    /// correct; 0: no stack reference).
    pub stare_exposures: usize,
}

/// Fewest scored stars (matched to the truth, not rejected) for an accuracy: a standard deviation needs two.
pub const MIN_SCORED_STARS: usize = 2;

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

/// Fill the accuracy statistics of a report from the star results.
pub fn summarise(
    stars: &[StarResult],
    truth: Option<&[TruthRow]>,
    scale: f64,
    report: &mut Report,
) {
    let used: Vec<&StarResult> = stars.iter().filter(|s| s.is_used()).collect();
    report.n_matched = stars.iter().filter(|s| s.truth.is_some()).count();
    report.n_used = used.len();
    report.n_rejected = stars.len() - used.len();
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
        return;
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
        0.0
    };
    // the phase bias needs the true positions' sub-pixel phases: absent without them
    report.phase_bias_x_mas = f64::NAN;
    report.phase_bias_y_mas = f64::NAN;
    if let Some(t) = truth {
        let px: Vec<f64> = used
            .iter()
            .map(|s| t[s.truth.unwrap_or(0)].x_px - t[s.truth.unwrap_or(0)].x_px.round())
            .collect();
        let py: Vec<f64> = used
            .iter()
            .map(|s| t[s.truth.unwrap_or(0)].y_px - t[s.truth.unwrap_or(0)].y_px.round())
            .collect();
        report.phase_bias_x_mas = phase_bias(&dx, &px);
        report.phase_bias_y_mas = phase_bias(&dy, &py);
    }
    let pdx: Vec<f64> = used.iter().map(|s| s.predicted_dx_px * scale).collect();
    let pdy: Vec<f64> = used.iter().map(|s| s.predicted_dy_px * scale).collect();
    report.predicted_corr_x = stats::correlation(&pdx, &dx);
    report.predicted_corr_y = stats::correlation(&pdy, &dy);
    report.predicted_slope_x = stats::slope(&pdx, &dx);
    report.predicted_slope_y = stats::slope(&pdy, &dy);
    report.predicted_rms_mas =
        ((stats::std_dev(&pdx).powi(2) + stats::std_dev(&pdy).powi(2)) / 2.0).sqrt();
    let rdx: Vec<f64> = used.iter().map(|s| s.predicted_fit_dx_px * scale).collect();
    let rdy: Vec<f64> = used.iter().map(|s| s.predicted_fit_dy_px * scale).collect();
    report.response_corr_x = stats::correlation(&rdx, &dx);
    report.response_corr_y = stats::correlation(&rdy, &dy);
    report.response_slope_x = stats::slope(&rdx, &dx);
    report.response_slope_y = stats::slope(&rdy, &dy);
    report.response_rms_mas =
        ((stats::std_dev(&rdx).powi(2) + stats::std_dev(&rdy).powi(2)) / 2.0).sqrt();
}

/// Attach per-truth-star fit-response predictions (px) to the star results.
pub fn attach_fit_prediction(stars: &mut [StarResult], per_truth: &[(f64, f64)]) {
    for s in stars.iter_mut() {
        if let Some(&(px, py)) = s.truth.and_then(|k| per_truth.get(k)) {
            s.predicted_fit_dx_px = px;
            s.predicted_fit_dy_px = py;
        }
    }
}

/// Turn fits into star results (residuals against the truth where matched).
pub fn star_results(
    fits: &[StarFit],
    matches: &[Option<usize>],
    truth: Option<&[TruthRow]>,
) -> Vec<StarResult> {
    fits.iter()
        .zip(matches)
        .map(|(f, m)| {
            let t = truth.and_then(|t| m.map(|k| t[k]));
            StarResult {
                truth: *m,
                x: f.x,
                y: f.y,
                flux_e: f.flux,
                sky_e: f.sky,
                crlb_x_px: f.crlb_x,
                crlb_y_px: f.crlb_y,
                flags: f.flags,
                dx_px: t.map(|t| f.x - t.x_px).unwrap_or(f64::NAN),
                dy_px: t.map(|t| f.y - t.y_px).unwrap_or(f64::NAN),
                predicted_dx_px: t.map(|t| t.jitter_dx_px).unwrap_or(0.0),
                predicted_dy_px: t.map(|t| t.jitter_dy_px).unwrap_or(0.0),
                predicted_fit_dx_px: 0.0,
                predicted_fit_dy_px: 0.0,
            }
        })
        .collect()
}

/// Result of one countermeasure on one image.
#[derive(Debug, Clone, Serialize)]
pub struct Measured {
    pub countermeasure: String,
    pub report: Report,
}

/// One image's results.
#[derive(Debug, Clone, Serialize)]
pub struct ImageResult {
    pub index: usize,
    pub ace_sigma_mas: f64,
    pub ace_drift_mas: f64,
    pub simulate_s: f64,
    pub analyse_s: f64,
    pub measured: Vec<Measured>,
    /// The star results of the plain global-ePSF analysis (kept for image 0, for the vector map).
    #[serde(skip)]
    pub stars: Option<Vec<StarResult>>,
}

/// A dataset summary row per countermeasure.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub ace: String,
    pub readout: String,
    pub countermeasure: String,
    pub mag: f64,
    pub accuracy_mas: f64,
    pub sem_mas: f64,
    pub crlb_mas: f64,
    pub predicted_mas: f64,
    pub n_images: usize,
    pub time_s: f64,
}
