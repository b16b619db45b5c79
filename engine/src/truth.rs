//! The answer key of a simulation: where each star truly is in one exposure and what it delivered. The
//! simulator writes it (the TRUTH extension, `truth_NNN.csv`); the scoring step (layer 7) reads it;
//! the analysis never does (the `@oracle` plate control is handed the true positions as a reference catalogue
//! named so, by the session that simulated them).

/// The true parameters of one star in one exposure.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthRow {
    pub id: usize,
    /// True position (0-based pixels), without jitter.
    pub x_px: f64,
    pub y_px: f64,
    pub mag_hw: f64,
    pub j_minus_h: f64,
    /// Electrons the star delivered during its window (all light, modelled or not).
    pub flux_e: f64,
    /// Fraction of that light the PSF table models (the rest, beyond `psf_radius_px`, is dropped).
    pub modelled_fraction: f64,
    /// Integration window of the star's central pixel (s from the exposure start) and its length.
    pub t_start_s: f64,
    pub exptime_s: f64,
    /// Mean ACE displacement over the star's window (px): the photocentre shift the jitter predicts.
    pub jitter_dx_px: f64,
    pub jitter_dy_px: f64,
}
