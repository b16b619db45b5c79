//! What the crowded-field analysis of an array did, without its fits: detections per pass, groups, the ePSF
//! and the time it took (the truth-side counts — stars matched to no true star — are the scoring's).

use super::Crowded;

/// The crowded analysis of an array without its fits.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CrowdedSummary {
    pub n_first: usize,
    pub n_residual: usize,
    pub epsf_stars: usize,
    pub epsf_iterations: usize,
    pub fallback: String,
    pub n_groups: usize,
    pub largest_group: usize,
    /// Wall-clock seconds of the array's crowded analysis (detection, ePSF, grouped fits).
    pub analyse_s: f64,
    /// The reference catalogue's registration onto the fits (the plate solution against the catalogue),
    /// when its stars were forced.
    pub registration: Option<crate::analysis::registration::Registration>,
}

impl CrowdedSummary {
    /// The summary of `c`, analysed in `analyse_s` seconds.
    pub fn of(c: &Crowded, analyse_s: f64) -> Self {
        Self {
            n_first: c.n_first,
            n_residual: c.n_residual,
            epsf_stars: c.epsf_stars,
            epsf_iterations: c.epsf_iterations,
            fallback: c.fallback.clone(),
            n_groups: c.n_groups,
            largest_group: c.largest_group,
            analyse_s,
            registration: c.registration,
        }
    }
}
