//! The crowded-field analysis of a whole focal-plane exposure scored, as its results are kept and shown: each
//! array's scored stars with its truth and a summary of how it was analysed ([`ArrayAnalysis`]), its
//! deviation map in the focal plane's sky layout ([`ArrayAnalysis::binned_vectors`]), and the focal plane
//! under one countermeasure with its magnitude bins ([`FocalPlaneAnalysis`]). The study that fills them is
//! `studies::crowded`.

use super::crowded::MagBin;
use super::image::ScoredStar;
use crate::analysis::countermeasures::Countermeasure;
use crate::analysis::crowded::CrowdedSummary;
use crate::analysis::registration::Registration;
use crate::numerics::stats;
use crate::sky::focal_plane::FocalPlane;
use crate::truth::TruthRow;

/// One array's crowded analysis under one countermeasure.
#[derive(Debug, Clone)]
pub struct ArrayAnalysis {
    /// The array's index (0 … 3).
    pub index: usize,
    pub stars: Vec<ScoredStar>,
    pub truth: Vec<TruthRow>,
    pub n_px: usize,
    /// What the crowded analysis found and how (the fits are in `stars`).
    pub summary: CrowdedSummary,
    /// Reported stars matched to no true star: noise peaks, light from stars off the array's edge, or
    /// duplicates.
    pub n_unmatched: usize,
    /// The array's own ePSF.
    pub epsf: crate::analysis::epsf::Epsf,
    /// The catalogue registration's true error (NaN without one): [`registration_error_px`].
    pub registration_error_px: f64,
}

/// The true error of a catalogue's registration onto an array (`analysis::registration`), rms per axis over
/// the truth stars on the array, px: where the map puts each star's catalogue place without the survey's
/// error — its true sky place through the header's WCS, `to_header(x, y)` of its true pixel — against where
/// it lies. NaN without a registration or a star.
pub fn registration_error_px(
    reg: Option<&Registration>,
    truth: &[TruthRow],
    n_px: usize,
    to_header: impl Fn(f64, f64) -> Option<(f64, f64)>,
) -> f64 {
    let Some(reg) = reg.filter(|r| r.pairs > 0) else {
        return f64::NAN;
    };
    let n = n_px as f64;
    let (mut ss, mut count) = (0.0, 0usize);
    for t in truth {
        if !(t.x_px >= 0.0 && t.y_px >= 0.0 && t.x_px < n && t.y_px < n) {
            continue;
        }
        if let Some(c) = to_header(t.x_px, t.y_px) {
            let p = reg.apply(c);
            ss += (p.0 - t.x_px).powi(2) + (p.1 - t.y_px).powi(2);
            count += 1;
        }
    }
    if count == 0 {
        return f64::NAN;
    }
    (ss / (2.0 * count as f64)).sqrt()
}

/// Cells per array side of the binned vector maps.
pub const VECTOR_CELLS: usize = 12;

impl ArrayAnalysis {
    /// The array's deviation map in focal-plane axes (its sky layout): per cell of [`VECTOR_CELLS`]² with
    /// at least 3 used stars, the cell's centre and the inverse-variance (bound⁻²) weighted mean fitted −
    /// true of its stars (mas), the array's own median offset removed and the vector turned with the array.
    pub fn binned_vectors(&self, plane: &FocalPlane, scale_mas: f64) -> Vec<(f64, f64, f64, f64)> {
        let used: Vec<_> = self.stars.iter().filter(|s| s.is_used()).collect();
        let ox = stats::median(&used.iter().map(|s| s.dx_px).collect::<Vec<_>>());
        let oy = stats::median(&used.iter().map(|s| s.dy_px).collect::<Vec<_>>());
        let cell = self.n_px as f64 / VECTOR_CELLS as f64;
        // (Σ w dx, Σ w dy, Σ w, n) per cell
        let mut acc = vec![(0.0, 0.0, 0.0, 0usize); VECTOR_CELLS * VECTOR_CELLS];
        for s in &used {
            let var = (s.crlb_x_px.powi(2) + s.crlb_y_px.powi(2)) / 2.0;
            if !(var > 0.0 && var.is_finite()) {
                continue;
            }
            let (cx, cy) = (
                ((s.x / cell).max(0.0) as usize).min(VECTOR_CELLS - 1),
                ((s.y / cell).max(0.0) as usize).min(VECTOR_CELLS - 1),
            );
            let e = &mut acc[cy * VECTOR_CELLS + cx];
            e.0 += (s.dx_px - ox) / var;
            e.1 += (s.dy_px - oy) / var;
            e.2 += 1.0 / var;
            e.3 += 1;
        }
        acc.iter()
            .enumerate()
            .filter(|(_, e)| e.3 >= 3)
            .map(|(i, e)| {
                let (x, y) = (
                    ((i % VECTOR_CELLS) as f64 + 0.5) * cell,
                    ((i / VECTOR_CELLS) as f64 + 0.5) * cell,
                );
                let (dx, dy) = (e.0 / e.2, e.1 / e.2);
                let (fx, fy) = plane.to_focal_plane(self.index, x, y);
                // turned with the array: the difference of the mapped end points (the map is affine)
                let (gx, gy) = plane.to_focal_plane(self.index, x + dx, y + dy);
                (fx, fy, (gx - fx) * scale_mas, (gy - fy) * scale_mas)
            })
            .collect()
    }
}

/// The focal plane under one countermeasure.
#[derive(Debug, Clone)]
pub struct FocalPlaneAnalysis {
    pub countermeasure: Countermeasure,
    pub arrays: Vec<ArrayAnalysis>,
    pub bins: Vec<MagBin>,
    /// Wall-clock seconds of the whole analysis (all arrays, this countermeasure included).
    pub analyse_s: f64,
}
