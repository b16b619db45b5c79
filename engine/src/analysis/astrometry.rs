//! Astrometric analysis of an image: detection, ePSF building and fitting (global or Y-zoned), matching to
//! the truth, and the accuracy report (SPEC §7).
//!
//! * Position accuracy of an image = the standard deviation over stars of (fitted − true), per axis, in mas
//!   (a common offset of all stars does not count); "combined" is the quadratic mean of the two axes
//!   (`√((σx² + σy²)/2)`, a per-axis figure comparable to the per-axis bound).
//! * The Cramér–Rao bound of each star comes from its fit ([`crate::analysis::epsf::fit`]); the report gives the
//!   median and accuracy / bound.
//! * Pixel-phase bias: mean (fitted − true) in five bins of the star's sub-pixel phase; its largest excursion
//!   is the signature of a bad ePSF.

use crate::analysis::countermeasures::{self, Countermeasure};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart};
use crate::analysis::epsf::fit::{FitOptions, PixelData, StarFit, fit_star, flags};
use crate::config::{Analysis as AnalysisCfg, Config};
use crate::detector::{DetectorImage, dq};
use crate::io::fits::ImageRead;
use crate::numerics::stats;
use crate::simulate::TruthRow;
use rayon::prelude::*;
use serde::Serialize;

#[derive(Debug, thiserror::Error)]
pub enum AstrometryError {
    #[error("no star detected above {0} σ")]
    NoStars(f64),
    #[error("image is {nx}×{ny} but holds {len} values")]
    Shape { nx: usize, ny: usize, len: usize },
    #[error("countermeasure: {0}")]
    Countermeasure(#[from] countermeasures::CountermeasureError),
}

/// An image ready for analysis: electrons with bias removed, a mask, the noise floor.
#[derive(Debug, Clone)]
pub struct AnalysisImage {
    pub nx: usize,
    pub ny: usize,
    pub e: Vec<f64>,
    pub bad: Vec<bool>,
    /// RN² + g²/12 (e⁻²).
    pub var_floor_e2: f64,
    pub plate_scale_mas: f64,
}

impl AnalysisImage {
    /// From a simulated detector image.
    pub fn from_detector(cfg: &Config, img: &DetectorImage) -> Self {
        let g = cfg.detector.gain_e_per_adu;
        let bad_bits = dq::BORDER | dq::SATURATED | dq::ADC_HIGH;
        Self {
            nx: img.n,
            ny: img.n,
            e: img
                .adu
                .iter()
                .map(|v| (*v as f64 - cfg.detector.bias_adu) * g)
                .collect(),
            bad: img.dq.iter().map(|d| d & bad_bits != 0).collect(),
            var_floor_e2: cfg.detector.read_noise_e.powi(2) + g * g / 12.0,
            plate_scale_mas: cfg.instrument.plate_scale_mas(),
        }
    }

    /// From a FITS image read back (GAIN, RDNOISE, BIASADU, SATURATE headers; DQ extension if present).
    pub fn from_fits(r: &ImageRead, plate_scale_mas: f64) -> Result<Self, AstrometryError> {
        if r.data.len() != r.nx * r.ny {
            return Err(AstrometryError::Shape {
                nx: r.nx,
                ny: r.ny,
                len: r.data.len(),
            });
        }
        let g = r.gain_e_per_adu;
        let sat = r.saturation_adu.unwrap_or(f64::INFINITY);
        let bad_bits = dq::BORDER | dq::SATURATED | dq::ADC_HIGH;
        let bad = match &r.dq {
            Some(d) => d.iter().map(|q| q & bad_bits != 0).collect(),
            None => r
                .data
                .iter()
                .map(|v| *v as f64 >= sat || !v.is_finite())
                .collect(),
        };
        Ok(Self {
            nx: r.nx,
            ny: r.ny,
            e: r.data
                .iter()
                .map(|v| {
                    if v.is_finite() {
                        (*v as f64 - r.bias_adu) * g
                    } else {
                        0.0
                    }
                })
                .collect(),
            bad,
            var_floor_e2: r.read_noise_e.powi(2) + g * g / 12.0,
            plate_scale_mas,
        })
    }

    pub fn pixels(&self) -> PixelData<'_> {
        PixelData {
            nx: self.nx,
            ny: self.ny,
            e: &self.e,
            bad: &self.bad,
            var_floor_e2: self.var_floor_e2,
        }
    }
}

/// Local maxima (5 × 5) above `nsigma` × the image's robust noise over its median; brightest first, closer
/// than 3 px to a brighter one dropped.
pub fn detect(img: &AnalysisImage, nsigma: f64) -> Vec<(f64, f64)> {
    let good: Vec<f64> = img
        .e
        .iter()
        .zip(&img.bad)
        .filter(|(_, b)| !**b)
        .map(|(v, _)| *v)
        .step_by(7)
        .collect();
    let sky = stats::median(&good);
    let noise = stats::mad_sigma(&good).max(1e-9);
    let thr = sky + nsigma * noise;
    let (nx, ny) = (img.nx, img.ny);
    let rows: Vec<Vec<(f64, f64, f64)>> = (0..ny)
        .into_par_iter()
        .map(|y| {
            let mut v = Vec::new();
            for x in 0..nx {
                let i = y * nx + x;
                let p = img.e[i];
                // saturated pixels count as peaks (their value is clipped, not low)
                if !(p > thr || img.bad[i] && p > thr * 0.5) {
                    continue;
                }
                let mut is_max = true;
                'n: for yy in y.saturating_sub(2)..=(y + 2).min(ny - 1) {
                    for xx in x.saturating_sub(2)..=(x + 2).min(nx - 1) {
                        let q = img.e[yy * nx + xx];
                        if q > p || (q == p && (yy * nx + xx) < i) {
                            is_max = false;
                            break 'n;
                        }
                    }
                }
                if is_max {
                    v.push((p, x as f64, y as f64));
                }
            }
            v
        })
        .collect();
    let mut peaks: Vec<(f64, f64, f64)> = rows.into_iter().flatten().collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut kept: Vec<(f64, f64)> = Vec::new();
    for (_, x, y) in peaks {
        if kept
            .iter()
            .all(|(kx, ky)| (kx - x).powi(2) + (ky - y).powi(2) >= 9.0)
        {
            kept.push((x, y));
        }
    }
    kept
}

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
    pub countermeasure: String,
    /// Parameters a countermeasure fitted per exposure (degrees of freedom absorbed).
    pub dof_absorbed: usize,
}

/// Everything the analysis of one image produced.
#[derive(Debug, Clone)]
pub struct Analysis {
    pub report: Report,
    pub stars: Vec<StarResult>,
    pub epsf: Epsf,
}

/// Analysis options: the configured knobs, a countermeasure, and an optional fixed ePSF (the control).
#[derive(Debug, Clone)]
pub struct Options {
    pub cfg: AnalysisCfg,
    pub countermeasure: Countermeasure,
    /// Fit with this ePSF instead of building one (e.g. the exact ePSF from the simulator).
    pub fixed_epsf: Option<Epsf>,
}

impl Options {
    pub fn new(cfg: &AnalysisCfg) -> Self {
        Self {
            cfg: cfg.clone(),
            countermeasure: Countermeasure::None,
            fixed_epsf: None,
        }
    }
    pub fn build_options(&self) -> BuildOptions {
        BuildOptions {
            oversampling: self.cfg.epsf_oversampling,
            half_px: self.cfg.epsf_radius_px,
            iterations: self.cfg.epsf_iterations,
            smoothing: self.cfg.smoothing,
            clip_sigma: self.cfg.clip_sigma,
            fit: FitOptions {
                radius_px: self.cfg.fit_radius_px,
                max_iter: self.cfg.fit_max_iter,
                fit_sky: self.cfg.fit_sky,
            },
            recentre: true,
        }
    }
}

/// Sky annulus used for every star (just outside the ePSF table).
pub fn sky_annulus(cfg: &AnalysisCfg) -> (f64, f64) {
    let r = cfg.epsf_radius_px as f64;
    (r + 1.0, r + 4.0)
}

/// Match detections to the truth: for each detection the nearest truth star within 2 px.
pub fn match_truth(pos: &[(f64, f64)], truth: &[TruthRow]) -> Vec<Option<usize>> {
    // bucket the truth on a 4-px grid
    let cell = 4.0;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    for (k, t) in truth.iter().enumerate() {
        grid.entry((
            (t.x_px / cell).floor() as i64,
            (t.y_px / cell).floor() as i64,
        ))
        .or_default()
        .push(k);
    }
    pos.iter()
        .map(|&(x, y)| {
            let (cx, cy) = ((x / cell).floor() as i64, (y / cell).floor() as i64);
            let mut best: Option<(usize, f64)> = None;
            for gy in cy - 1..=cy + 1 {
                for gx in cx - 1..=cx + 1 {
                    for &k in grid.get(&(gx, gy)).map(|v| v.as_slice()).unwrap_or(&[]) {
                        let d = (truth[k].x_px - x).powi(2) + (truth[k].y_px - y).powi(2);
                        if d <= 4.0 && best.is_none_or(|(_, bd)| d < bd) {
                            best = Some((k, d));
                        }
                    }
                }
            }
            best.map(|b| b.0)
        })
        .collect()
}

/// The stars' starting values and which of them may build the ePSF (unflagged, inside, unsaturated,
/// isolated).
pub fn starts(
    img: &AnalysisImage,
    positions: &[(f64, f64)],
    cfg: &AnalysisCfg,
) -> (Vec<StarStart>, Vec<bool>) {
    let pd = img.pixels();
    let ann = sky_annulus(cfg);
    let s: Vec<StarStart> = positions
        .par_iter()
        .map(|&(x, y)| build::initial_start(&pd, x, y, ann))
        .collect();
    let r = cfg.epsf_radius_px as f64 + 1.0;
    let usable: Vec<bool> = s
        .iter()
        .enumerate()
        .map(|(k, st)| {
            let inside = st.x - r >= 0.0
                && st.y - r >= 0.0
                && st.x + r < img.nx as f64
                && st.y + r < img.ny as f64;
            let clean = inside && {
                let mut ok = true;
                'p: for py in
                    (st.y - r).floor() as usize..=((st.y + r).ceil() as usize).min(img.ny - 1)
                {
                    for px in
                        (st.x - r).floor() as usize..=((st.x + r).ceil() as usize).min(img.nx - 1)
                    {
                        if img.bad[py * img.nx + px] {
                            ok = false;
                            break 'p;
                        }
                    }
                }
                ok
            };
            let isolated = s
                .iter()
                .enumerate()
                .all(|(j, o)| j == k || (o.x - st.x).hypot(o.y - st.y) > 2.0 * r);
            clean && isolated && st.flux > 0.0
        })
        .collect();
    (s, usable)
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

/// Fill the accuracy statistics of a report from the star results.
pub fn summarise(
    stars: &[StarResult],
    truth: Option<&[TruthRow]>,
    scale: f64,
    report: &mut Report,
) {
    let used: Vec<&StarResult> = stars
        .iter()
        .filter(|s| s.truth.is_some() && s.flags & flags::REJECT == 0 && s.dx_px.is_finite())
        .collect();
    report.n_matched = stars.iter().filter(|s| s.truth.is_some()).count();
    report.n_used = used.len();
    report.n_rejected = stars.len() - used.len();
    if used.len() < 2 {
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

/// What the global analysis of an image prepared: enough to apply further countermeasures to its fits
/// without detecting the stars and building the ePSF again.
#[derive(Debug, Clone)]
pub struct Prepared {
    pub starts: Vec<StarStart>,
    pub usable: Vec<bool>,
    pub build: BuildOptions,
}

/// Analyse one image: detect, build (or take) the ePSF, fit, apply the countermeasure, report.
pub fn analyze(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    opts: &Options,
) -> Result<Analysis, AstrometryError> {
    let (plain, prepared) = analyze_prepared(img, truth, opts)?;
    with_countermeasure(img, truth, &plain, &prepared, &opts.countermeasure)
}

/// The analysis without a countermeasure, and what it prepared for [`with_countermeasure`].
pub fn analyze_prepared(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    opts: &Options,
) -> Result<(Analysis, Prepared), AstrometryError> {
    let det = detect(img, opts.cfg.detect_sigma);
    if det.is_empty() {
        return Err(AstrometryError::NoStars(opts.cfg.detect_sigma));
    }
    let (starts, usable) = starts(img, &det, &opts.cfg);
    let initial: Vec<(f64, f64)> = starts.iter().map(|s| (s.x, s.y)).collect();
    let matches = match truth {
        Some(t) => match_truth(&initial, t),
        None => vec![None; initial.len()],
    };
    let bopt = opts.build_options();
    let pd = img.pixels();
    let (mut fits, epsf, iterations) = match &opts.fixed_epsf {
        Some(e) => {
            let fits: Vec<StarFit> = starts
                .par_iter()
                .map(|s| fit_star(&pd, e, s.x, s.y, s.flux, s.sky, &bopt.fit))
                .collect();
            (fits, e.clone(), 0)
        }
        None => {
            let built = build::build(&pd, &starts, &usable, &bopt, None, None);
            (built.fits, built.epsf, built.iterations)
        }
    };
    crate::analysis::epsf::fit::flags::mark_poor_fits(&mut fits);
    let stars = star_results(&fits, &matches, truth);
    let mut report = Report {
        n_detected: det.len(),
        epsf_iterations: iterations,
        countermeasure: Countermeasure::None.name(),
        ..Default::default()
    };
    summarise(&stars, truth, img.plate_scale_mas, &mut report);
    Ok((
        Analysis {
            report,
            stars,
            epsf,
        },
        Prepared {
            starts,
            usable,
            build: bopt,
        },
    ))
}

/// Apply a countermeasure to the plain analysis of an image (from [`analyze_prepared`]) and report.
pub fn with_countermeasure(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    plain: &Analysis,
    prepared: &Prepared,
    cm: &Countermeasure,
) -> Result<Analysis, AstrometryError> {
    let mut stars = plain.stars.clone();
    let mut report = Report {
        n_detected: plain.report.n_detected,
        epsf_iterations: plain.report.epsf_iterations,
        countermeasure: cm.name(),
        ..Default::default()
    };
    report.dof_absorbed = countermeasures::apply(
        cm,
        img,
        &img.pixels(),
        &prepared.starts,
        &prepared.usable,
        &prepared.build,
        &plain.epsf,
        truth,
        &mut stars,
    )?;
    summarise(&stars, truth, img.plate_scale_mas, &mut report);
    Ok(Analysis {
        report,
        stars,
        epsf: plain.epsf.clone(),
    })
}

// Tests against synthetic truths (noise-free exactness, the Cramér–Rao bound, hard cases) live in
// tests/astrometry_truth.rs.
