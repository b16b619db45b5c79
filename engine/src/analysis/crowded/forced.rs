//! Forced catalogue stars: the reference catalogue's stars that the detection missed, held at their
//! catalogue positions with a fitted flux, so that their light is subtracted from their neighbours' fits.
//!
//! In a crowded field the light of stars below the detection's reach is what a bright star's fit has beyond
//! its photon noise (`scoring::undetected` measures it star by star: on the mock bulge it explains the
//! isolated stars' 1.17–1.21 × their bound). The reference catalogue (an instrument product, a survey's
//! positions to Hw 16.5) knows many of them. Each star of the model claims its nearest catalogue star within
//! [`FORCED_MATCH_PX`] (after the catalogue's registration onto the fits, `analysis::registration`: the
//! header's design WCS misses the as-built pointing, array placement and distortion); each unclaimed one
//! becomes a star of the model. It starts at its catalogue flux (below) or, without one, with the weighted
//! least-squares amplitude of the ePSF at its position in the residual image (image − model of every star
//! found, less the annulus sky), `f = Σ wᵢ ψᵢ rᵢ / Σ wᵢ ψᵢ²` over the fit radius (at least 1 e⁻: a
//! neighbour's fit may have taken its light); in the last pass its flux is fitted with its group, its
//! position held. It is never reported and
//! never a neighbour that flags a blend. Off by default (`analysis.crowded_forced_catalogue`).
//!
//! Its flux carries the catalogue's photometry as a prior: `f_cat = Z · 10^(−0.4 Hw)`, with the image's zero
//! point Z the median of `f · 10^(0.4 Hw)` over the brightest unsaturated fits that claimed a catalogue star,
//! and σ = [`FORCED_FLUX_PRIOR_MAG`] (a survey's photometry, transformed to Hw) — so that a faint star held under a
//! bright star's core, whose free flux the fit can hardly tell from the bright star's, neither takes that
//! star's light nor leaves its own. The simulated product's Hw carry a 0.05-mag error
//! (`--refcat-phot-sigma-mag`); the prior is twice as wide. A catalogue without Hw (NaN) leaves the flux free.

use super::group_fit::{FluxPrior, Member};
use super::pass::model_image;
use crate::analysis::epsf::fit::{PixelData, annulus_sky, pixel_variance, select_disc};
use crate::analysis::epsf::varying::EpsfField;
use crate::analysis::image::AnalysisImage;
use crate::analysis::registration::{Registration, register};
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::neighbours::Neighbours;
use rayon::prelude::*;

/// The least start flux of a forced star, e⁻ (its group's fit sets the flux).
const MIN_START_FLUX_E: f64 = 1.0;
/// Width of a forced star's flux prior, mag: a survey's photometry transformed to Hw.
pub const FORCED_FLUX_PRIOR_MAG: f64 = 0.1;
/// The zero point is the median over at most this many of the brightest unsaturated matched fits …
const ZERO_POINT_STARS: usize = 500;
/// … and needs at least this many.
const ZERO_POINT_MIN_STARS: usize = 10;

/// One star of the reference catalogue as the analysis reads it: its position in this image's pixels (through
/// the design WCS) and its magnitude (NaN when the catalogue has none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CatalogueStar {
    pub x_px: f64,
    pub y_px: f64,
    pub hw: f64,
}
/// The positions (px) of catalogue stars.
pub fn positions_px(stars: &[CatalogueStar]) -> Vec<(f64, f64)> {
    stars.iter().map(|c| (c.x_px, c.y_px)).collect()
}

/// A catalogue star this close to a star of the model (after the registration) is that star (px).
pub const FORCED_MATCH_PX: f64 = 1.0;

/// The forced stars of `catalogue` (its positions in this image's pixels, as the design WCS puts them) for
/// the model `stars` (see the module's documentation), and the catalogue's registration onto them.
pub fn forced_members<E: EpsfField + ?Sized>(
    img: &AnalysisImage,
    epsf: &E,
    stars: &[Member],
    catalogue: &[CatalogueStar],
    cfg: &AnalysisCfg,
) -> (Vec<Member>, Registration) {
    if catalogue.is_empty() || stars.is_empty() {
        return (Vec::new(), Registration::NONE);
    }
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let flux: Vec<f64> = stars.iter().map(|s| s.flux).collect();
    let reg = register(&pos, &flux, &positions_px(catalogue));
    let (w, h) = (img.nx as f64, img.ny as f64);
    let cat: Vec<CatalogueStar> = catalogue
        .iter()
        .map(|c| {
            let (x_px, y_px) = reg.apply((c.x_px, c.y_px));
            CatalogueStar {
                x_px,
                y_px,
                hw: c.hw,
            }
        })
        .filter(|c| c.x_px >= -0.5 && c.y_px >= -0.5 && c.x_px < w - 0.5 && c.y_px < h - 0.5)
        .collect();
    // each star of the model claims its nearest catalogue star within the match radius; the unclaimed
    // are missed (a faint companion under a bright star's fit included)
    let nb = Neighbours::new(&positions_px(&cat));
    let mut claimed = vec![false; cat.len()];
    // (fit flux, catalogue Hw) of the unsaturated stars that claimed one: the zero point's sample
    let mut pairs: Vec<(f64, f64)> = Vec::new();
    for s in stars {
        let near = nb.within(s.x, s.y, FORCED_MATCH_PX);
        let d2 = |k: usize| (cat[k].x_px - s.x).powi(2) + (cat[k].y_px - s.y).powi(2);
        if let Some(k) = near.into_iter().min_by(|&a, &b| d2(a).total_cmp(&d2(b))) {
            claimed[k] = true;
            if !s.saturated && !s.fixed && s.flux > 0.0 && cat[k].hw.is_finite() {
                pairs.push((s.flux, cat[k].hw));
            }
        }
    }
    let zero_point = zero_point_e(&mut pairs);
    let missed: Vec<CatalogueStar> = cat
        .iter()
        .zip(&claimed)
        .filter(|(_, c)| !**c)
        .map(|(p, _)| *p)
        .collect();
    if missed.is_empty() {
        return (Vec::new(), reg);
    }
    let model = model_image(epsf, stars, img.nx, img.ny);
    let resid: Vec<f64> = img.e.iter().zip(&model).map(|(e, m)| e - m).collect();
    let rd = PixelData {
        e: &resid,
        ..img.pixels()
    };
    let (r_in, r_out) = crate::analysis::detection::sky_annulus(cfg);
    let members = missed
        .par_iter()
        .filter_map(|c| {
            let (x, y) = (c.x_px, c.y_px);
            let prior = zero_point
                .filter(|_| c.hw.is_finite())
                .map(|z| flux_prior(z, c.hw));
            let start = match prior {
                Some(q) => q.mean_e,
                None => {
                    let sky = annulus_sky(&rd, x, y, r_in, r_out)?;
                    amplitude(&rd, &model, epsf, (x, y), sky, cfg.fit_radius_px)?
                }
            };
            // without a prior a neighbour's fit may have taken its light (the residual there ≤ 0): it starts
            // faint, and its group's fit shares the light out
            Some(Member {
                forced: true,
                flux_prior: prior,
                ..Member::new(x, y, start.max(MIN_START_FLUX_E))
            })
        })
        .collect();
    (members, reg)
}

/// The image's zero point `Z` (e⁻ of a Hw = 0 star): the median of `f · 10^(0.4 Hw)` over the
/// [`ZERO_POINT_STARS`] brightest (fit flux, catalogue Hw) pairs; `None` with fewer than
/// [`ZERO_POINT_MIN_STARS`].
fn zero_point_e(pairs: &mut [(f64, f64)]) -> Option<f64> {
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let z: Vec<f64> = pairs
        .iter()
        .take(ZERO_POINT_STARS)
        .map(|&(f, hw)| f * 10f64.powf(0.4 * hw))
        .collect();
    (z.len() >= ZERO_POINT_MIN_STARS).then(|| crate::numerics::stats::median(&z))
}

/// A catalogue star's flux prior: `Z · 10^(−0.4 Hw)` with the relative width of [`FORCED_FLUX_PRIOR_MAG`]
/// (`σ_f / f = 0.4 ln 10 · σ_m`).
fn flux_prior(zero_point_e: f64, hw: f64) -> FluxPrior {
    let mean_e = zero_point_e * 10f64.powf(-0.4 * hw);
    FluxPrior {
        mean_e,
        sigma_e: mean_e * 0.4 * std::f64::consts::LN_10 * FORCED_FLUX_PRIOR_MAG,
    }
}

/// `Σ wᵢ ψᵢ (rᵢ − s) / Σ wᵢ ψᵢ²` over the usable pixels within `radius_px` of (x, y) of the residual `rd`,
/// weights from the image's model `model + s` (the star's own light is faint beside it); `None` without a
/// pixel.
fn amplitude<E: EpsfField + ?Sized>(
    rd: &PixelData<'_>,
    model: &[f64],
    epsf: &E,
    (x, y): (f64, f64),
    sky: f64,
    radius_px: f64,
) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for (i, px, py) in select_disc(rd, x, y, radius_px).0 {
        let psi = epsf.value_for(x, y, px - x, py - y);
        let wgt = 1.0 / pixel_variance(model[i] + sky, 0.0, rd.floor_e2(i), 0.0);
        num += wgt * psi * (rd.e[i] - sky);
        den += wgt * psi * psi;
    }
    (den > 0.0).then(|| num / den)
}
