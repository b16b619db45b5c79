//! The ePSF of a crowded image (Anderson & King 2000 §6 style): which stars build it
//! ([`epsf_candidates`]) and the builder that takes each one's samples with its neighbours' models
//! subtracted ([`build_epsf`]).

use super::group_fit::Member;
use super::link_radius_px;
use super::pass::{fit_pass, members_of, model_image};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::build_options;
use crate::analysis::epsf::build::{BuildOptions, update};
use crate::analysis::epsf::fit::{StarFit, flags};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::neighbours::Neighbours;
use crate::numerics::stats;
use rayon::prelude::*;

/// At most this many stars (the brightest candidates) build the ePSF of one image: ≈ 40 samples per node
/// of the 4× table already; more only cost time.
pub const MAX_EPSF_STARS: usize = 1500;
/// Most builder iterations of the crowded ePSF (`epsf_iterations = 0`: until converged, at most this).
pub const MAX_CROWDED_ITERATIONS: usize = 10;
/// Least S/N of an ePSF star's flux, `f/√(f + π r_fit² σ²)` (σ the image's pixel noise): the builder
/// wants stars whose every pixel sample is well measured (A&K 2000 use the brightest unsaturated stars).
pub const MIN_EPSF_SNR: f64 = 100.0;
/// How many candidates a loosened choice aims for (see [`epsf_candidates`]): a 4×-oversampled table of a 13-px box has ≈ 2700 nodes, and 50 stars give it ≈ 3
/// samples each.
pub const PREFERRED_EPSF_STARS: usize = 50;
/// The least S/N of an ePSF star when the choice loosens.
pub const RELAXED_EPSF_SNR: f64 = 30.0;

/// Which stars may build the ePSF: inside the image by the table's half-width plus one pixel, no masked
/// pixel there, positive flux, not outshone (no other star within the table's half-width with more flux)
/// and not closer than the link radius's half to another star (a pair too close to separate reliably).
/// Its flux S/N at least [`MIN_EPSF_SNR`]. When fewer than `MIN_EPSF_STARS` pass (no ePSF could be built),
/// the choice loosens until [`PREFERRED_EPSF_STARS`] stars pass or nothing is left to loosen: a star needs
/// only a clean core (no masked pixel within 1.5 px, at most a quarter of the box: `detection::clear_core`;
/// the builder leaves masked pixels out), then only S/N ≥ [`RELAXED_EPSF_SNR`]. The brightest
/// [`MAX_EPSF_STARS`] of them.
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
    let ok_with = |strict: bool, min_snr: f64| -> Vec<bool> {
        stars
            .par_iter()
            .enumerate()
            .map(|(k, s)| {
                let snr = s.flux / (s.flux.max(0.0) + area * noise * noise).sqrt();
                if !(s.flux > 0.0) || snr < min_snr {
                    return false;
                }
                let clean = if strict {
                    crate::analysis::detection::clear_box(img, s.x, s.y, r)
                } else {
                    crate::analysis::detection::clear_core(img, s.x, s.y, r)
                };
                clean
                    && nb.within(s.x, s.y, r - 1.0).into_iter().all(|j| {
                        j == k
                            || (stars[j].flux < s.flux
                                && (stars[j].x - s.x).hypot(stars[j].y - s.y) >= close)
                    })
            })
            .collect()
    };
    // a clean box and S/N ≥ MIN_EPSF_SNR; when that cannot build an ePSF, the first looser choice that gives
    // PREFERRED_EPSF_STARS, else the loosest (each holds the one before): a clean core (flagged pixels
    // everywhere, as on a real detector), then a clean core and S/N ≥ RELAXED_EPSF_SNR (few bright stars)
    let count = |ok: &[bool]| ok.iter().filter(|o| **o).count();
    let mut ok = ok_with(true, MIN_EPSF_SNR);
    if count(&ok) < crate::analysis::detection::MIN_EPSF_STARS {
        for (strict, min_snr) in [(false, MIN_EPSF_SNR), (false, RELAXED_EPSF_SNR)] {
            ok = ok_with(strict, min_snr);
            if count(&ok) >= PREFERRED_EPSF_STARS {
                break;
            }
        }
    }
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
