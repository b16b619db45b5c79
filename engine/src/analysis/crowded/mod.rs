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
//!    k-d tree ([`neighbours`]): O(N log N).
//! 4. **Residual detection**: peaks of image − model that no star accounts for (merged companions) are added
//!    and everything is fitted again (twice, so each group sees its neighbours' final models).
//!
//! Saturated cores are masked; such a star is fitted from its unsaturated wings and flagged, and never
//! builds the ePSF. With fewer than [`MIN_EPSF_STARS`] candidates the ePSF is not built: the instrument's
//! model PSF (or a Gaussian of the stars' second moment) stands in and [`Crowded::fallback`] says so.

pub mod detect;
pub mod group_fit;
pub mod neighbours;
pub mod report;

use crate::analysis::detection::sky_and_noise;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart, initial_start, update};
use crate::analysis::epsf::fit::{PixelData, StarFit, annulus_sky, flags};
use crate::analysis::image::AnalysisImage;
use crate::analysis::pipeline::{MIN_EPSF_STARS, build_options};
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::stats;
use group_fit::{MAX_GROUP_STARS, Member, Outsiders, fit_group};
use neighbours::Neighbours;
use rayon::prelude::*;

/// At most this many stars (the brightest candidates) build the ePSF of one image: ≈ 40 samples per node
/// of the 4× table already; more only cost time.
pub const MAX_EPSF_STARS: usize = 1500;
/// Most builder iterations of the crowded ePSF (`epsf_iterations = 0`: until converged, at most this).
pub const MAX_CROWDED_ITERATIONS: usize = 10;
/// A residual peak closer than this to a star already found is that star's misfit, not a new star (px).
pub const RESIDUAL_MIN_SEP_PX: f64 = 1.0;
/// Least S/N of an ePSF star's flux, `f/√(f + π r_fit² σ²)` (σ the image's pixel noise): the builder
/// wants stars whose every pixel sample is well measured (A&K 2000 use the brightest unsaturated stars).
pub const MIN_EPSF_SNR: f64 = 100.0;
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
    pub epsf: Epsf,
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
}

/// Model image `Σₖ fₖ ψ(X − xₖ, Y − yₖ)` of the stars (those with positive flux), over the ePSF table.
pub fn model_image(epsf: &Epsf, stars: &[Member], nx: usize, ny: usize) -> Vec<f64> {
    let h = epsf.half_px();
    let mut order: Vec<usize> = (0..stars.len())
        .filter(|&k| stars[k].flux > 0.0 && stars[k].x.is_finite() && stars[k].y.is_finite())
        .collect();
    order.sort_by(|&a, &b| stars[a].y.total_cmp(&stars[b].y));
    let ys: Vec<f64> = order.iter().map(|&k| stars[k].y).collect();
    let mut m = vec![0.0; nx * ny];
    const BAND: usize = 32;
    m.par_chunks_mut(BAND * nx)
        .enumerate()
        .for_each(|(b, band)| {
            let (y0, y1) = (b * BAND, (b * BAND + band.len() / nx) as f64);
            let lo = ys.partition_point(|&y| y < y0 as f64 - h);
            let hi = ys.partition_point(|&y| y < y1 + h);
            for &k in &order[lo..hi] {
                let s = stars[k];
                let (px0, px1) = (
                    (s.x - h).ceil().max(0.0) as usize,
                    ((s.x + h).floor().max(-1.0) + 1.0).min(nx as f64) as usize,
                );
                let (py0, py1) = (
                    ((s.y - h).ceil().max(y0 as f64)) as usize,
                    ((s.y + h).floor() + 1.0).clamp(y0 as f64, y1) as usize,
                );
                for py in py0..py1 {
                    let row = &mut band[(py - y0) * nx..(py - y0 + 1) * nx];
                    for (px, v) in row.iter_mut().enumerate().take(px1).skip(px0) {
                        *v += s.flux * epsf.value(px as f64 - s.x, py as f64 - s.y);
                    }
                }
            }
        });
    m
}

/// One pass of fits of every star with `epsf`: groups by [`link_radius_px`], each group fitted with the
/// light of the stars outside it (their current values in `stars`) subtracted, on a sky from the annulus of
/// the image minus the model of all stars (the median over the group's members). A [`Member::fixed`] star
/// is only subtracted: its fit is its current values.
pub fn fit_pass(
    img: &AnalysisImage,
    epsf: &Epsf,
    stars: &[Member],
    node_error: f64,
    cfg: &AnalysisCfg,
) -> (Vec<StarFit>, GroupStats) {
    let opts = build_options(cfg);
    let pd = img.pixels();
    let model = model_image(epsf, stars, img.nx, img.ny);
    let resid: Vec<f64> = img.e.iter().zip(&model).map(|(e, m)| e - m).collect();
    let rd = PixelData { e: &resid, ..pd };
    let (r_in, r_out) = crate::analysis::detection::sky_annulus(cfg);
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let nb = Neighbours::new(&pos);
    let free: Vec<usize> = (0..stars.len()).filter(|&k| !stars[k].fixed).collect();
    let free_pos: Vec<(f64, f64)> = free.iter().map(|&k| pos[k]).collect();
    let groups: Vec<Vec<usize>> = neighbours::groups(&free_pos, link_radius_px(cfg))
        .into_iter()
        .map(|g| g.into_iter().map(|i| free[i]).collect())
        .collect();
    let reach = cfg.fit_radius_px + epsf.half_px() + group_fit_reach_margin();
    let fitted: Vec<Vec<(usize, StarFit)>> = groups
        .par_iter()
        .map(|g| {
            let skies: Vec<f64> = g
                .iter()
                .filter_map(|&k| annulus_sky(&rd, stars[k].x, stars[k].y, r_in, r_out))
                .collect();
            let sky = if skies.is_empty() {
                0.0
            } else {
                stats::median(&skies)
            };
            let outside = |members: &[usize]| -> Vec<Member> {
                let mut o: Vec<usize> = members
                    .iter()
                    .flat_map(|&k| nb.within(stars[k].x, stars[k].y, reach))
                    .filter(|j| !members.contains(j))
                    .collect();
                o.sort_unstable();
                o.dedup();
                o.into_iter().map(|j| stars[j]).collect()
            };
            if g.len() <= MAX_GROUP_STARS {
                let members: Vec<Member> = g.iter().map(|&k| stars[k]).collect();
                let o = outside(g);
                let fits = fit_group(
                    &pd,
                    epsf,
                    &members,
                    &Outsiders { stars: &o },
                    sky,
                    node_error,
                    &opts.fit,
                );
                g.iter().copied().zip(fits).collect()
            } else {
                // a knot too large to fit at once: star by star, everything else subtracted
                g.iter()
                    .map(|&k| {
                        let o = outside(&[k]);
                        let mut f = fit_group(
                            &pd,
                            epsf,
                            &[stars[k]],
                            &Outsiders { stars: &o },
                            sky,
                            node_error,
                            &opts.fit,
                        )[0];
                        f.flags |= flags::GROUPED;
                        (k, f)
                    })
                    .collect()
            }
        })
        .collect();
    let mut fits: Vec<StarFit> = stars
        .iter()
        .map(|s| StarFit {
            x: s.x,
            y: s.y,
            flux: s.flux,
            crlb_x: f64::INFINITY,
            crlb_y: f64::INFINITY,
            crlb_flux: f64::INFINITY,
            ..Default::default()
        })
        .collect();
    for (k, f) in fitted.into_iter().flatten() {
        fits[k] = f;
    }
    let multi: Vec<usize> = groups.iter().map(Vec::len).filter(|&l| l > 1).collect();
    (
        fits,
        GroupStats {
            groups: multi.len(),
            largest: multi.iter().copied().max().unwrap_or(1),
        },
    )
}

/// How far beyond the fit disc an outsider's model is looked for: one pixel of slack for the step a member
/// may take during its fit.
fn group_fit_reach_margin() -> f64 {
    1.0
}

/// Groups of a pass.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroupStats {
    pub groups: usize,
    pub largest: usize,
}

/// The members of the next pass from fits: their fitted values, unless the fit failed (singular, too few
/// pixels, no flux) or left the image — then the previous values stay, so that a noise peak cannot walk
/// away over the passes. A fit that moved far or did not settle still updates: the next pass starts there.
fn members_of(fits: &[StarFit], prev: &[Member], nx: usize, ny: usize) -> Vec<Member> {
    let failed = flags::SINGULAR | flags::FEW_PIXELS | flags::NONPOSITIVE_FLUX;
    fits.iter()
        .zip(prev)
        .map(|(f, p)| {
            let inside = f.x >= 0.0 && f.y >= 0.0 && f.x < nx as f64 && f.y < ny as f64;
            if f.flags & failed == 0 && inside {
                Member {
                    saturated: f.flags & flags::SATURATED != 0,
                    ..Member::new(f.x, f.y, f.flux)
                }
            } else {
                *p
            }
        })
        .collect()
}

/// Which stars may build the ePSF: inside the image by the table's half-width plus one pixel, no masked
/// pixel there, positive flux, not outshone (no other star within the table's half-width with more flux)
/// and not closer than the link radius's half to another star (a pair too close to separate reliably).
/// Its flux S/N at least [`MIN_EPSF_SNR`]. The brightest [`MAX_EPSF_STARS`] of them.
pub fn epsf_candidates(
    img: &AnalysisImage,
    stars: &[Member],
    cfg: &AnalysisCfg,
    noise: f64,
) -> Vec<bool> {
    let r = cfg.epsf_radius_px as f64 + 1.0;
    let area = std::f64::consts::PI * cfg.fit_radius_px * cfg.fit_radius_px;
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let nb = Neighbours::new(&pos);
    let close = 0.5 * link_radius_px(cfg);
    let ok: Vec<bool> = stars
        .par_iter()
        .enumerate()
        .map(|(k, s)| {
            let snr = s.flux / (s.flux.max(0.0) + area * noise * noise).sqrt();
            if !(s.flux > 0.0) || snr < MIN_EPSF_SNR {
                return false;
            }
            let clean = crate::analysis::detection::clear_box(img, s.x, s.y, r);
            clean
                && nb.within(s.x, s.y, r - 1.0).into_iter().all(|j| {
                    j == k
                        || (stars[j].flux < s.flux
                            && (stars[j].x - s.x).hypot(stars[j].y - s.y) >= close)
                })
        })
        .collect();
    let mut order: Vec<usize> = (0..stars.len()).filter(|&k| ok[k]).collect();
    order.sort_by(|&a, &b| stars[b].flux.total_cmp(&stars[a].flux));
    let mut chosen = vec![false; stars.len()];
    for &k in order.iter().take(MAX_EPSF_STARS) {
        chosen[k] = true;
    }
    chosen
}

/// The crowded ePSF: iterate { fit every star with ψ; ψ ← ψ + the candidates' neighbour-subtracted residual
/// samples }. Returns ψ, the number of candidates that gave samples and the iterations made.
pub fn build_epsf(
    img: &AnalysisImage,
    stars: &mut Vec<Member>,
    candidates: &[bool],
    seed: Epsf,
    node_error: f64,
    cfg: &AnalysisCfg,
) -> (Epsf, usize, usize) {
    let opts: BuildOptions = build_options(cfg);
    let mut psi = seed;
    let iterations = if cfg.epsf_iterations == 0 {
        MAX_CROWDED_ITERATIONS
    } else {
        cfg.epsf_iterations.min(MAX_CROWDED_ITERATIONS)
    };
    let (mut done, mut used) = (0, 0);
    for _ in 0..iterations {
        done += 1;
        let (fits, _) = fit_pass(img, &psi, stars, node_error, cfg);
        *stars = members_of(&fits, stars, img.nx, img.ny);
        let model = model_image(&psi, stars, img.nx, img.ny);
        let chi: Vec<f64> = fits
            .iter()
            .zip(candidates)
            .filter(|(f, c)| **c && f.usable())
            .map(|(f, _)| f.chi2_red)
            .collect();
        let chi_limit = flags::POOR_FIT_FACTOR * stats::median(&chi).max(1.0);
        let per_star: Vec<Vec<(usize, f64)>> = fits
            .par_iter()
            .zip(candidates)
            .map(|(f, c)| {
                if !*c || !f.usable() || !(f.flux > 0.0) || f.chi2_red > chi_limit {
                    return Vec::new();
                }
                residual_samples(img, &model, &psi, f)
            })
            .collect();
        used = per_star.iter().filter(|v| !v.is_empty()).count();
        let peak = psi.data.iter().cloned().fold(0.0, f64::max).max(1e-300);
        let (next, max_delta) = update(&psi, per_star, &opts);
        psi = next;
        if cfg.epsf_iterations == 0 && max_delta < 1e-4 * peak {
            break;
        }
    }
    (psi, used, done)
}

/// Residual samples of one ePSF star with every other star's model subtracted: `(P − s − M)/f` binned to
/// the node nearest each pixel's offset (M includes the star itself, so this is the correction to ψ).
fn residual_samples(
    img: &AnalysisImage,
    model: &[f64],
    psi: &Epsf,
    f: &StarFit,
) -> Vec<(usize, f64)> {
    let n = psi.n() as i64;
    let os = psi.oversampling as f64;
    let h = psi.half_nodes as i64;
    let r = psi.half_px() - 0.5;
    let mut out = Vec::new();
    for py in (f.y - r).ceil() as i64..=(f.y + r).floor() as i64 {
        for px in (f.x - r).ceil() as i64..=(f.x + r).floor() as i64 {
            if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
                continue;
            }
            let i = py as usize * img.nx + px as usize;
            if img.bad[i] {
                continue;
            }
            let (dx, dy) = (px as f64 - f.x, py as f64 - f.y);
            let (u, v) = ((dx * os).round() as i64 + h, (dy * os).round() as i64 + h);
            if u < 0 || v < 0 || u >= n || v >= n {
                continue;
            }
            out.push(((v * n + u) as usize, (img.e[i] - f.sky - model[i]) / f.flux));
        }
    }
    out
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
pub fn analyse(img: &AnalysisImage, cfg: &AnalysisCfg, model_epsf: Option<&Epsf>) -> Crowded {
    let opts = build_options(cfg);
    let pd = img.pixels();
    let (sky, noise) = sky_and_noise(img);
    let det = detect::detect_smoothed(img, cfg.crowded_detect_sigma, sky, noise);
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
    let candidates = epsf_candidates(img, &stars, cfg, noise);
    let n_cand = candidates.iter().filter(|c| **c).count();
    // the ePSF's node error (the saturated stars' model term): from its stars, or none for a stand-in
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
    let (epsf, epsf_stars, epsf_iterations, fallback) = if stars.is_empty() {
        let e = model_epsf
            .cloned()
            .unwrap_or_else(|| build::gaussian_seed(&pd, &[], opts.oversampling, opts.half_px));
        (
            e,
            0,
            0,
            format!("no star detected above {} σ", cfg.crowded_detect_sigma),
        )
    } else if n_cand < MIN_EPSF_STARS {
        let (e, what) = match model_epsf {
            Some(m) => (m.clone(), "the instrument's model PSF"),
            None => (
                build::gaussian_seed(&pd, &starts, opts.oversampling, opts.half_px),
                "a Gaussian of the stars' mean second moment",
            ),
        };
        let why = format!(
            "{n_cand} unsaturated star(s) clear of brighter neighbours, fewer than {MIN_EPSF_STARS}: no \
             ePSF built; fitted with {what}"
        );
        (e, 0, 0, why)
    } else {
        let chosen: Vec<StarStart> = starts
            .iter()
            .zip(&candidates)
            .filter(|(_, c)| **c)
            .map(|(s, _)| *s)
            .collect();
        let seed = build::gaussian_seed(&pd, &chosen, opts.oversampling, opts.half_px);
        let (e, used, it) = build_epsf(img, &mut stars, &candidates, seed, node_error, cfg);
        (e, used, it, String::new())
    };
    if stars.is_empty() {
        return Crowded {
            fits: Vec::new(),
            epsf,
            epsf_stars,
            epsf_iterations,
            fallback,
            n_first: 0,
            n_residual: 0,
            n_groups: 0,
            largest_group: 0,
        };
    }
    // fit, look for what the model misses, fit again with the companions
    let (fits, _) = fit_pass(img, &epsf, &stars, node_error, cfg);
    stars = members_of(&fits, &stars, img.nx, img.ny);
    let model = model_image(&epsf, &stars, img.nx, img.ny);
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let extra = detect::detect_residual(
        img,
        &model,
        sky,
        noise,
        cfg.crowded_detect_sigma,
        &Neighbours::new(&pos),
        RESIDUAL_MIN_SEP_PX,
    );
    let mut from_residual = vec![false; stars.len()];
    let resid = residual(img, &model);
    let rd = PixelData { e: &resid, ..pd };
    // each new star's flux from a fit of it alone in the residual (every star found so far subtracted), as
    // photutils' IterativePSFPhotometry does, so that the joint fit starts it with its own flux, not with
    // its neighbour's light (with which it could swap places)
    let new: Vec<Member> = extra
        .par_iter()
        .map(|&(x, y)| {
            let s = initial_start(&rd, x, y, ann);
            let f = fit_group(
                &rd,
                &epsf,
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
        .collect();
    for m in new {
        stars.push(m);
        from_residual.push(true);
    }
    let (fits, _) = fit_pass(img, &epsf, &stars, node_error, cfg);
    stars = members_of(&fits, &stars, img.nx, img.ny);
    let keep = prune(&fits, &stars, &from_residual);
    let stars: Vec<Member> = keep.iter().map(|&k| stars[k]).collect();
    let from_residual: Vec<bool> = keep.iter().map(|&k| from_residual[k]).collect();
    // a bright star's wing, judged on these fits, is held in the last pass: it models light the table
    // leaves out without sharing a real neighbour's (which it could otherwise take over or keep from
    // settling), and is never reported
    let kept_fits: Vec<StarFit> = keep.iter().map(|&k| fits[k]).collect();
    let wing = wings(&kept_fits, &from_residual, &epsf);
    let stars: Vec<Member> = stars
        .into_iter()
        .zip(&wing)
        .map(|(s, w)| Member { fixed: *w, ..s })
        .collect();
    let (mut fits, groups) = fit_pass(img, &epsf, &stars, node_error, cfg);
    for (f, r) in fits.iter_mut().zip(&from_residual) {
        if *r {
            f.flags |= flags::RESIDUAL_FOUND;
        }
    }
    // a neighbour is a neighbour whether or not its own fit is reported — but a bright star's wing is not
    let mut stars_only: Vec<StarFit> = (0..fits.len())
        .filter(|&k| !wing[k])
        .map(|k| fits[k])
        .collect();
    flags::mark_blends(&mut stars_only, flags::blend_radius_px(cfg.fit_radius_px));
    for (k, f) in (0..fits.len()).filter(|&k| !wing[k]).zip(stars_only) {
        fits[k] = f;
    }
    // report what the fits confirm (see MIN_REPORT_SNR; a star detected on a saturated core always is),
    // never a bright star's wing (WING_VETO_RATIO)
    let confirmed: Vec<bool> = fits
        .iter()
        .zip(&stars)
        .zip(&wing)
        .map(|((f, s), w)| {
            !w && (s.saturated
                || (f.crlb_flux.is_finite() && f.flux >= MIN_REPORT_SNR * f.crlb_flux))
        })
        .collect();
    let from_residual: Vec<bool> = (0..fits.len())
        .filter(|&k| confirmed[k])
        .map(|k| from_residual[k])
        .collect();
    let fits: Vec<StarFit> = (0..fits.len())
        .filter(|&k| confirmed[k])
        .map(|k| fits[k])
        .collect();
    let mut fits = fits;
    flags::mark_poor_fits(&mut fits);
    Crowded {
        n_first: fits.len() - from_residual.iter().filter(|r| **r).count(),
        n_residual: from_residual.iter().filter(|r| **r).count(),
        fits,
        epsf,
        epsf_stars,
        epsf_iterations,
        fallback,
        n_groups: groups.groups,
        largest_group: groups.largest,
    }
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
