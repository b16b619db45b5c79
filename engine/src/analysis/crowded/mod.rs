//! Crowded-field ePSF astrometry of one array's image: what a Galactic-centre exposure needs beyond the
//! isolated-star analysis of [`crate::analysis::pipeline`].
//!
//! 1. **Detection** ([`detect`]): peaks of the matched-filtered image, deblended by prominence.
//! 2. **ePSF from a crowded image** (Anderson & King 2000 §6 style, [`build_epsf`]): the bright,
//!    unsaturated stars not outshone by a neighbour build it; every detected star is fitted with the
//!    current ePSF ([`fit_pass`]), so each ePSF star's residual samples are taken with its *neighbours'*
//!    current models subtracted (`(P − s − Σ_{j≠k} fⱼψⱼ)/fₖ − ψₖ = (P − s − M)/fₖ` with M the model of all
//!    stars); rebuild, iterate.
//! 3. **Grouped fits** ([`group_fit`]): stars closer than [`link_radius_px`] are fitted simultaneously
//!    (x, y, flux each, one sky), the light of the stars outside the group subtracted; groups come from a
//!    k-d tree ([`crate::numerics::neighbours`]): O(N log N).
//! 4. **Residual detection**: peaks of image − model that no star accounts for (merged companions) are added
//!    and everything is fitted again (twice, so each group sees its neighbours' final models).
//! 5. **Forced catalogue stars** ([`forced`]): before the last pass, the reference catalogue's stars that no
//!    star of the model claims join it, held at their catalogue positions, their fluxes fitted with their
//!    groups (never reported): a faint companion under a bright star's core no longer pulls its fit.
//!
//! Saturated cores are masked; such a star is fitted from its unsaturated wings and flagged, and never
//! builds the ePSF. With fewer than [`MIN_EPSF_STARS`] candidates the ePSF is not built: the instrument's
//! model PSF (or a Gaussian of the stars' second moment) stands in and [`Crowded::fallback`] says so.

pub mod detect;
pub mod epsf;
pub mod forced;
pub mod group_fit;
pub mod pass;
pub mod summary;

pub use epsf::{
    MAX_CROWDED_ITERATIONS, MAX_EPSF_STARS, MIN_EPSF_SNR, build_epsf, build_varying,
    epsf_candidates,
};
pub use pass::{GroupStats, fit_pass, model_image};
pub use summary::CrowdedSummary;

use crate::analysis::detection::MIN_EPSF_STARS;
use crate::analysis::detection::SkyNoise;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::build_options;
use crate::analysis::epsf::build::{self, StarStart, initial_start};
use crate::analysis::epsf::fit::{PixelData, StarFit, flags};
use crate::analysis::epsf::varying::{EpsfField, VaryingEpsf};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::config::EpsfVariation;
use crate::numerics::neighbours::Neighbours;
use crate::numerics::stats;
use group_fit::{Member, Outsiders, fit_group};
use pass::members_of;
use rayon::prelude::*;

/// A residual peak closer than this to a star already found is that star's misfit, not a new star (px).
pub const RESIDUAL_MIN_SEP_PX: f64 = 1.0;
/// Least S/N of a reported star's fitted flux (`flux / σ_flux` of its fit). A detection at
/// `crowded_detect_sigma` in the matched filter that its fit does not confirm at this level is kept in the
/// model (its light is subtracted from its neighbours) but not reported (a star detected on a saturated
/// core always is, flagged): in pure noise a 3σ threshold
/// finds ≈ 1 peak per 700 px², a 5σ flux ≈ 1 per 10⁷.
pub const MIN_REPORT_SNR: f64 = 5.0;
/// A star found in the residual is taken for a bright star's unmodelled wing (the rings and spider spikes
/// beyond the ePSF table) when a star within [`WING_VETO_REACH_PX`] of the table's edge is this many times
/// brighter than its fitted flux. Such a "star" is still fitted
/// — it models light the table leaves out, which helps its neighbours' fits — but never reported. Measured
/// on the bulge field: reported, they were 11 % of the stars, 6.6–8 px from a star above 2·10⁵ e⁻.
pub const WING_VETO_RATIO: f64 = 100.0;
pub const WING_VETO_REACH_PX: f64 = 4.0;

/// Two fitted stars closer than this are one star fitted twice: the fainter is dropped (px).
pub const DUPLICATE_SEP_PX: f64 = 0.5;

/// The distance below which two stars are fitted together: the fit radius plus 3 px, where a neighbour's
/// PSF core has fallen below ≈ 1 % of its peak ([`flags::blend_radius_px`]).
pub fn link_radius_px(cfg: &AnalysisCfg) -> f64 {
    flags::blend_radius_px(cfg.fit_radius_px)
}

/// The crowded-field analysis of one image.
#[derive(Debug, Clone)]
pub struct Crowded {
    /// One per star found, brightest detections first, then the residual detections.
    pub fits: Vec<StarFit>,
    /// The ePSF every star was fitted with: its table at the image's centre (`field.base`, the whole ePSF
    /// when it is constant) and its planes of change across the image (`analysis.epsf_variation`; none when
    /// constant).
    pub field: VaryingEpsf,
    /// How the ePSF varies (`constant`, `linear`, `quadratic`), or why a varying ePSF asked for was kept
    /// constant.
    pub variation: String,
    /// Stars that built the ePSF (0 with a fallback).
    pub epsf_stars: usize,
    pub epsf_iterations: usize,
    /// Empty when the ePSF was built from the image; else what stood in for it and why.
    pub fallback: String,
    /// Reported stars of the first detection and those added from the residual image.
    pub n_first: usize,
    pub n_residual: usize,
    /// Groups of more than one star in the final pass, and the largest group.
    pub n_groups: usize,
    pub largest_group: usize,
    /// Every star of the final model (reported or not: an unconfirmed detection and a bright star's wing
    /// still model light), at its final fit, and which of them each reported fit is.
    pub model: Vec<Member>,
    pub reported: Vec<usize>,
    /// The ePSF's node error the saturated stars' fits carry ([`group_fit::node_error`]).
    pub node_error: f64,
    /// The reference catalogue's registration onto the fits, when its stars were forced
    /// (`analysis::registration`).
    pub registration: Option<crate::analysis::registration::Registration>,
}

/// Refit the stars of a crowded analysis `c` in their groups, each through its own profile from the telemetry
/// forward model `forward` (neighbours subtracted with the image's ePSF), in `c.fits`' order: the
/// `telemetry-model` countermeasure of a crowded field. Flags of the analysis (blended, found in the
/// residual) are kept; poor fits are marked again.
pub fn refit_forward(
    img: &AnalysisImage,
    c: &Crowded,
    cfg: &AnalysisCfg,
    forward: &crate::analysis::countermeasures::forward::Forward<'_>,
) -> Vec<StarFit> {
    if c.model.is_empty() {
        return c.fits.clone();
    }
    let (all, _) = pass::fit_pass_with(img, &c.field, &c.model, c.node_error, cfg, Some(forward));
    let keep = flags::BLENDED | flags::RESIDUAL_FOUND;
    let mut fits: Vec<StarFit> = c
        .reported
        .iter()
        .zip(&c.fits)
        .map(|(&k, old)| {
            let mut f = all[k];
            f.flags = (f.flags & !flags::POOR_FIT) | (old.flags & keep);
            f
        })
        .collect();
    flags::mark_poor_fits(&mut fits);
    fits
}

/// Drop the stars that are not stars after a pass: a residual detection fitted to no flux, and the fainter
/// of two fits closer than [`DUPLICATE_SEP_PX`].
fn prune(fits: &[StarFit], stars: &[Member], from_residual: &[bool]) -> Vec<usize> {
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let nb = Neighbours::new(&pos);
    (0..stars.len())
        .filter(|&k| {
            if from_residual[k] && !(fits[k].flux > 0.0) {
                return false;
            }
            !nb.within(stars[k].x, stars[k].y, DUPLICATE_SEP_PX)
                .into_iter()
                .any(|j| {
                    j != k
                        && (stars[j].flux > stars[k].flux
                            || (stars[j].flux == stars[k].flux && j < k))
                })
        })
        .collect()
}

/// The crowded-field analysis of one image (see the module's steps). `model_epsf` stands in for the ePSF
/// when the image has fewer than [`MIN_EPSF_STARS`] candidates (else a Gaussian of the stars' second
/// moment). An image without a detected star gives no fits (and says so in `fallback`).
pub fn analyse(
    img: &AnalysisImage,
    cfg: &AnalysisCfg,
    model_epsf: Option<&Epsf>,
    catalogue: Option<&[forced::CatalogueStar]>,
) -> Crowded {
    let pd = img.pixels();
    let sn = SkyNoise::of(img);
    let noise = sn.noise;
    let det = detect::detect_smoothed(img, cfg.crowded_detect_sigma, &sn);
    let ann = crate::analysis::detection::sky_annulus(cfg);
    let starts: Vec<StarStart> = det
        .par_iter()
        .map(|&(x, y)| initial_start(&pd, x, y, ann))
        .collect();
    let mut stars: Vec<Member> = starts
        .iter()
        .map(|s| Member {
            saturated: on_masked(img, s.x, s.y),
            ..Member::new(s.x, s.y, s.flux)
        })
        .collect();
    let built = first_epsf(img, cfg, model_epsf, &starts, &mut stars, noise);
    let node_error = built.node_error;
    let crowded =
        |fits: Vec<StarFit>,
         n_residual: usize,
         groups: GroupStats,
         model: Vec<Member>,
         reported: Vec<usize>,
         registration: Option<crate::analysis::registration::Registration>| Crowded {
            n_first: fits.len() - n_residual,
            n_residual,
            fits,
            field: built.field.clone(),
            variation: built.variation.clone(),
            epsf_stars: built.stars,
            epsf_iterations: built.iterations,
            fallback: built.fallback.clone(),
            n_groups: groups.groups,
            largest_group: groups.largest,
            model,
            reported,
            node_error,
            registration,
        };
    if stars.is_empty() {
        let none = GroupStats {
            groups: 0,
            largest: 0,
        };
        return crowded(Vec::new(), 0, none, Vec::new(), Vec::new(), None);
    }
    // fit, look for what the model misses, fit again with the companions
    let field = &built.field;
    let (fits, _) = fit_pass(img, field, &stars, node_error, cfg);
    stars = members_of(&fits, &stars, img.nx, img.ny);
    let mut from_residual = vec![false; stars.len()];
    for m in residual_stars(img, field, &stars, &sn, node_error, cfg) {
        stars.push(m);
        from_residual.push(true);
    }
    let (fits, _) = fit_pass(img, field, &stars, node_error, cfg);
    stars = members_of(&fits, &stars, img.nx, img.ny);
    let keep = prune(&fits, &stars, &from_residual);
    let stars: Vec<Member> = keep.iter().map(|&k| stars[k]).collect();
    let mut from_residual: Vec<bool> = keep.iter().map(|&k| from_residual[k]).collect();
    // a bright star's wing, judged on these fits, is held in the last pass: it models light the table
    // leaves out without sharing a real neighbour's (which it could otherwise take over or keep from
    // settling), and is never reported
    let kept_fits: Vec<StarFit> = keep.iter().map(|&k| fits[k]).collect();
    let mut wing = wings(&kept_fits, &from_residual, &field.base);
    let mut stars: Vec<Member> = stars
        .into_iter()
        .zip(&wing)
        .map(|(s, w)| Member { fixed: *w, ..s })
        .collect();
    // the reference catalogue's stars the detection missed, held at their catalogue positions: their light
    // is subtracted from their neighbours' fits (forced; never reported)
    let mut registration = None;
    if let Some(cat) = catalogue.filter(|_| cfg.crowded_forced_catalogue) {
        let (forced, reg) = forced::forced_members(img, field, &stars, cat, cfg);
        stars.extend(forced);
        registration = Some(reg);
    }
    from_residual.resize(stars.len(), false);
    wing.resize(stars.len(), false);
    let (mut fits, groups) = fit_pass(img, field, &stars, node_error, cfg);
    for (f, r) in fits.iter_mut().zip(&from_residual) {
        if *r {
            f.flags |= flags::RESIDUAL_FOUND;
        }
    }
    // the final model: a wing held; a forced star stays forced (a refit, e.g. the telemetry forward model's,
    // fits its flux again with its group's own profiles)
    let model: Vec<Member> = members_of(&fits, &stars, img.nx, img.ny)
        .into_iter()
        .zip(&wing)
        .map(|(m, w)| Member { fixed: *w, ..m })
        .collect();
    // not a reported star nor a neighbour: a wing or a forced star
    let held: Vec<bool> = wing
        .iter()
        .zip(&stars)
        .map(|(w, s)| *w || s.forced)
        .collect();
    let reported = confirmed_stars(&mut fits, &stars, &held, cfg);
    let n_residual = reported.iter().filter(|&&k| from_residual[k]).count();
    let mut fits: Vec<StarFit> = reported.iter().map(|&k| fits[k]).collect();
    flags::mark_poor_fits(&mut fits);
    crowded(fits, n_residual, groups, model, reported, registration)
}

/// The image's ePSF as the crowded analysis builds it, and what it says of itself.
struct FirstEpsf {
    /// The constant ePSF, or it with its planes (`analysis.epsf_variation`).
    field: VaryingEpsf,
    variation: String,
    stars: usize,
    iterations: usize,
    fallback: String,
    /// The ePSF's node error (the saturated stars' model term): from its stars, or none for a stand-in.
    node_error: f64,
}

/// The ePSF of the detected `stars` (their positions refined as it is built), or its stand-in (`model_epsf`,
/// else a Gaussian of the stars' second moment) with fewer than [`MIN_EPSF_STARS`] candidates or no star.
fn first_epsf(
    img: &AnalysisImage,
    cfg: &AnalysisCfg,
    model_epsf: Option<&Epsf>,
    starts: &[StarStart],
    stars: &mut Vec<Member>,
    noise: f64,
) -> FirstEpsf {
    let opts = build_options(cfg);
    let pd = img.pixels();
    let candidates = epsf_candidates(img, stars, cfg, noise);
    let n_cand = candidates.iter().filter(|c| **c).count();
    let fluxes: Vec<f64> = stars
        .iter()
        .zip(&candidates)
        .filter(|(_, c)| **c)
        .map(|(s, _)| s.flux)
        .collect();
    let node_error = if n_cand >= MIN_EPSF_STARS {
        group_fit::node_error(noise, stats::median(&fluxes), n_cand, opts.oversampling)
    } else {
        0.0
    };
    // a stand-in is one table: a varying ePSF asked for says why it is not
    let stand_in_note = match cfg.epsf_variation {
        EpsfVariation::Constant => EpsfVariation::Constant.name().to_string(),
        _ => "no ePSF built: one ePSF for the image".to_string(),
    };
    let stand_in = |epsf: Epsf, fallback: String| FirstEpsf {
        field: VaryingEpsf::new(epsf, EpsfVariation::Constant, img.nx, img.ny),
        variation: stand_in_note.clone(),
        stars: 0,
        iterations: 0,
        fallback,
        node_error,
    };
    if stars.is_empty() {
        let e = model_epsf
            .cloned()
            .unwrap_or_else(|| build::gaussian_seed(&pd, &[], opts.oversampling, opts.half_px));
        return stand_in(
            e,
            format!("no star detected above {} σ", cfg.crowded_detect_sigma),
        );
    }
    if n_cand < MIN_EPSF_STARS {
        let (e, what) = match model_epsf {
            Some(m) => (m.clone(), "the instrument's model PSF"),
            None => (
                build::gaussian_seed(&pd, starts, opts.oversampling, opts.half_px),
                "a Gaussian of the stars' mean second moment",
            ),
        };
        let why = format!(
            "{n_cand} unsaturated star(s) clear of brighter neighbours, fewer than {MIN_EPSF_STARS}: no \
             ePSF built; fitted with {what}"
        );
        return stand_in(e, why);
    }
    let chosen: Vec<StarStart> = starts
        .iter()
        .zip(&candidates)
        .filter(|(_, c)| **c)
        .map(|(s, _)| *s)
        .collect();
    let seed = build::gaussian_seed(&pd, &chosen, opts.oversampling, opts.half_px);
    let (field, used, iterations, variation) = match cfg.epsf_variation {
        EpsfVariation::Constant => {
            let (epsf, used, iterations) =
                build_epsf(img, stars, &candidates, seed, node_error, cfg);
            let field = VaryingEpsf::new(epsf, cfg.epsf_variation, img.nx, img.ny);
            (
                field,
                used,
                iterations,
                cfg.epsf_variation.name().to_string(),
            )
        }
        v => {
            let (field, used, iterations, why) =
                build_varying(img, stars, &candidates, seed, node_error, cfg);
            let name = if why.is_empty() {
                v.name().to_string()
            } else {
                why
            };
            (field, used, iterations, name)
        }
    };
    FirstEpsf {
        field,
        variation,
        stars: used,
        iterations,
        fallback: String::new(),
        node_error,
    }
}

/// The stars the model of `stars` misses: detected in the residual (image − model), each started with the
/// flux of a fit of it alone in the residual (every star found so far subtracted), as photutils'
/// IterativePSFPhotometry does, so that the joint fit starts it with its own flux, not with its neighbour's
/// light (with which it could swap places).
fn residual_stars<E: EpsfField + ?Sized>(
    img: &AnalysisImage,
    epsf: &E,
    stars: &[Member],
    sn: &SkyNoise,
    node_error: f64,
    cfg: &AnalysisCfg,
) -> Vec<Member> {
    let opts = build_options(cfg);
    let model = model_image(epsf, stars, img.nx, img.ny);
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let extra = detect::detect_residual(
        img,
        &model,
        sn,
        cfg.crowded_detect_sigma,
        &Neighbours::new(&pos),
        RESIDUAL_MIN_SEP_PX,
    );
    let resid = residual(img, &model);
    let rd = PixelData {
        e: &resid,
        ..img.pixels()
    };
    let ann = crate::analysis::detection::sky_annulus(cfg);
    extra
        .par_iter()
        .map(|&(x, y)| {
            let s = initial_start(&rd, x, y, ann);
            let f = fit_group(
                &rd,
                epsf,
                &[Member::new(x, y, s.flux)],
                &Outsiders { stars: &[] },
                s.sky,
                node_error,
                &opts.fit,
            )[0];
            // the peak's position (a lone star fitted to the quadrupole a close pair leaves behind would
            // wander off it), the lone fit's flux when it found one
            Member::new(
                x,
                y,
                if f.usable() && f.flux > 0.0 {
                    f.flux
                } else {
                    s.flux
                },
            )
        })
        .collect()
}

/// Flag the blends among the fits that are stars (a neighbour is a neighbour whether or not its own fit is
/// reported — but a bright star's wing is not, nor a forced catalogue star: `held`), and return the stars
/// the fits confirm (see [`MIN_REPORT_SNR`]; a star detected on a saturated core always is), never a held
/// one.
fn confirmed_stars(
    fits: &mut [StarFit],
    stars: &[Member],
    held: &[bool],
    cfg: &AnalysisCfg,
) -> Vec<usize> {
    let mut stars_only: Vec<StarFit> = (0..fits.len())
        .filter(|&k| !held[k])
        .map(|k| fits[k])
        .collect();
    flags::mark_blends(&mut stars_only, flags::blend_radius_px(cfg.fit_radius_px));
    for (k, f) in (0..fits.len()).filter(|&k| !held[k]).zip(stars_only) {
        fits[k] = f;
    }
    (0..fits.len())
        .filter(|&k| {
            let (f, s) = (&fits[k], &stars[k]);
            !held[k]
                && (s.saturated
                    || (f.crlb_flux.is_finite() && f.flux >= MIN_REPORT_SNR * f.crlb_flux))
        })
        .collect()
}

/// Whether the pixel under (x, y) is masked (a detection on a saturated core).
fn on_masked(img: &AnalysisImage, x: f64, y: f64) -> bool {
    let (px, py) = (x.round(), y.round());
    px >= 0.0
        && py >= 0.0
        && (px as usize) < img.nx
        && (py as usize) < img.ny
        && img.bad[py as usize * img.nx + px as usize]
}

/// Which fits are a bright star's wing (see [`WING_VETO_RATIO`]), from their fitted fluxes: a residual
/// detection with a star within reach of the table's edge that many times brighter (judged on fits, not
/// on detection: a residual star may have taken the place of the real one its start was next to).
fn wings(fits: &[StarFit], from_residual: &[bool], epsf: &Epsf) -> Vec<bool> {
    let pos: Vec<(f64, f64)> = fits.iter().map(|f| (f.x, f.y)).collect();
    let nb = Neighbours::new(&pos);
    let reach = epsf.half_px() + WING_VETO_REACH_PX;
    fits.iter()
        .zip(from_residual)
        .map(|(f, r)| {
            *r && nb
                .within(f.x, f.y, reach)
                .into_iter()
                .any(|j| fits[j].flux >= WING_VETO_RATIO * f.flux.max(0.0))
        })
        .collect()
}

/// The image minus a model.
fn residual(img: &AnalysisImage, model: &[f64]) -> Vec<f64> {
    img.e.iter().zip(model).map(|(e, m)| e - m).collect()
}
