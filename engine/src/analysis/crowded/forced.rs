//! Forced catalogue stars: the reference catalogue's stars that the detection missed, held at their
//! catalogue positions with a fitted flux, so that their light is subtracted from their neighbours' fits.
//!
//! In a crowded field the light of stars below the detection's reach is what a bright star's fit has beyond
//! its photon noise (`scoring::undetected` measures it star by star: on the mock bulge it explains the
//! isolated stars' 1.17–1.21 × their bound). The reference catalogue (an instrument product, a survey's
//! positions to Hw 16.5) knows many of them. Each star of the model claims its nearest catalogue star within
//! [`FORCED_MATCH_PX`] (after the catalogue's common offset from the brightest fits); each unclaimed one
//! becomes a star of the model. It starts with the weighted least-squares amplitude of the ePSF at its
//! position in the residual image (image − model of every star found, less the annulus sky),
//! `f = Σ wᵢ ψᵢ rᵢ / Σ wᵢ ψᵢ²` over the fit radius (at least 1 e⁻: a neighbour's fit may have taken its
//! light); in the last pass its flux is fitted with its group, its position held. It is never reported and
//! never a neighbour that flags a blend. Off by default (`analysis.crowded_forced_catalogue`).

use super::group_fit::Member;
use super::neighbours::Neighbours;
use super::pass::model_image;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::fit::{PixelData, annulus_sky, pixel_variance, select_disc};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use rayon::prelude::*;

/// The least start flux of a forced star, e⁻ (its group's fit sets the flux).
const MIN_START_FLUX_E: f64 = 1.0;
/// A catalogue star this close to a star of the model (after the common offset) is that star (px).
pub const FORCED_MATCH_PX: f64 = 1.0;
/// The common offset of the catalogue from the fits is found with this many of the brightest fits …
const OFFSET_STARS: usize = 500;
/// … each matched to its nearest catalogue star within this distance (px: a pointing error of ≈ 10″).
const OFFSET_SEARCH_PX: f64 = 20.0;

/// The forced stars of `catalogue` (its positions in this image's pixels, as the design WCS puts them) for
/// the model `stars` (see the module's documentation).
pub fn forced_members(
    img: &AnalysisImage,
    epsf: &Epsf,
    stars: &[Member],
    catalogue: &[(f64, f64)],
    cfg: &AnalysisCfg,
) -> Vec<Member> {
    if catalogue.is_empty() || stars.is_empty() {
        return Vec::new();
    }
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let flux: Vec<f64> = stars.iter().map(|s| s.flux).collect();
    let off = crate::analysis::detection::common_offset_of_brightest(
        &pos,
        &flux,
        catalogue,
        OFFSET_STARS,
        OFFSET_SEARCH_PX,
    );
    let (w, h) = (img.nx as f64, img.ny as f64);
    let cat: Vec<(f64, f64)> = catalogue
        .iter()
        .map(|&(x, y)| (x + off.0, y + off.1))
        .filter(|&(x, y)| x >= -0.5 && y >= -0.5 && x < w - 0.5 && y < h - 0.5)
        .collect();
    // each star of the model claims its nearest catalogue star within the match radius; the unclaimed
    // are missed (a faint companion under a bright star's fit included)
    let nb = Neighbours::new(&cat);
    let mut claimed = vec![false; cat.len()];
    for s in stars {
        let near = nb.within(s.x, s.y, FORCED_MATCH_PX);
        let d2 = |k: usize| (cat[k].0 - s.x).powi(2) + (cat[k].1 - s.y).powi(2);
        if let Some(k) = near.into_iter().min_by(|&a, &b| d2(a).total_cmp(&d2(b))) {
            claimed[k] = true;
        }
    }
    let missed: Vec<(f64, f64)> = cat
        .iter()
        .zip(&claimed)
        .filter(|(_, c)| !**c)
        .map(|(p, _)| *p)
        .collect();
    if missed.is_empty() {
        return Vec::new();
    }
    let model = model_image(epsf, stars, img.nx, img.ny);
    let resid: Vec<f64> = img.e.iter().zip(&model).map(|(e, m)| e - m).collect();
    let rd = PixelData {
        e: &resid,
        ..img.pixels()
    };
    let (r_in, r_out) = crate::analysis::detection::sky_annulus(cfg);
    missed
        .par_iter()
        .filter_map(|&(x, y)| {
            let sky = annulus_sky(&rd, x, y, r_in, r_out)?;
            let f = amplitude(&rd, &model, epsf, (x, y), sky, cfg.fit_radius_px)?;
            // a neighbour's fit may have taken its light (the residual there ≤ 0): it starts faint, and its
            // group's fit shares the light out
            Some(Member {
                forced: true,
                ..Member::new(x, y, f.max(MIN_START_FLUX_E))
            })
        })
        .collect()
}

/// `Σ wᵢ ψᵢ (rᵢ − s) / Σ wᵢ ψᵢ²` over the usable pixels within `radius_px` of (x, y) of the residual `rd`,
/// weights from the image's model `model + s` (the star's own light is faint beside it); `None` without a
/// pixel.
fn amplitude(
    rd: &PixelData<'_>,
    model: &[f64],
    epsf: &Epsf,
    (x, y): (f64, f64),
    sky: f64,
    radius_px: f64,
) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for (i, px, py) in select_disc(rd, x, y, radius_px).0 {
        let psi = epsf.value(px - x, py - y);
        let wgt = 1.0 / pixel_variance(model[i] + sky, 0.0, rd.var_floor_e2, 0.0);
        num += wgt * psi * (rd.e[i] - sky);
        den += wgt * psi * psi;
    }
    (den > 0.0).then(|| num / den)
}
