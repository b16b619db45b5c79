//! What the analysis of an image reports about itself — no truth enters: each star's fit ([`StarResult`]) and
//! how the analysis went ([`Report`]: detections, rejections, the ePSF and how it was made, the countermeasure
//! and the parameters it absorbed). What the fits are worth against a truth is the scoring's
//! (`scoring::image`, the next layer).

use crate::analysis::epsf::fit::{StarFit, flags};
use serde::Serialize;

/// One star's measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StarResult {
    pub x: f64,
    pub y: f64,
    pub flux_e: f64,
    pub sky_e: f64,
    /// Cramér–Rao bound of the position per axis ([`crate::analysis::epsf::fit`]), px.
    pub crlb_x_px: f64,
    pub crlb_y_px: f64,
    /// [`flags`] of the fit.
    pub flags: u32,
}

impl StarResult {
    /// The measurement of a fit.
    pub fn of(f: &StarFit) -> Self {
        Self {
            x: f.x,
            y: f.y,
            flux_e: f.flux,
            sky_e: f.sky,
            crlb_x_px: f.crlb_x,
            crlb_y_px: f.crlb_y,
            flags: f.flags,
        }
    }

    /// Whether the position is usable: no rejection flag, finite.
    pub fn is_usable(&self) -> bool {
        self.flags & flags::REJECT == 0 && self.x.is_finite() && self.y.is_finite()
    }
}

/// Turn fits into star results.
pub fn star_results(fits: &[StarFit]) -> Vec<StarResult> {
    fits.iter().map(StarResult::of).collect()
}

/// How the analysis of an image went.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Report {
    pub n_detected: usize,
    /// Fits flagged for rejection (saturated, poorly fitted, blended, off the image).
    pub n_rejected: usize,
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
    /// Exposures of the stare whose stack referenced a plate model: 1 when the image stood alone (a stare
    /// of one, its own stack: nothing corrected), K for a stare of K; absent (`null`) when no plate model
    /// referenced to the stack was asked for.
    pub stare_exposures: Option<usize>,
    /// The static profile a telemetry countermeasure saw each star through, when it was not the design
    /// model PSF or the image's ePSF as configured: the design PSF corrected by the stars (its fitted terms and
    /// their errors, nm rms). Left out of the JSON when empty.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub static_profile: String,
}

impl Report {
    /// Count the rejected fits of `stars`.
    pub fn count(&mut self, stars: &[StarResult]) {
        self.n_rejected = stars.iter().filter(|s| !s.is_usable()).count();
    }
}
