//! The ePSF of a crowded image (Anderson & King 2000 §6 style): which stars build it
//! ([`epsf_candidates`]) and the builder that takes each one's samples with its neighbours' models
//! subtracted ([`build_epsf`]), and the planes of its change across the image (`analysis.epsf_variation`,
//! [`build_varying`]).

use super::group_fit::Member;
use super::link_radius_px;
use super::pass::{fit_pass, members_of, model_image};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::build_options;
use crate::analysis::epsf::build::{BuildOptions, update};
use crate::analysis::epsf::fit::{StarFit, flags};
use crate::analysis::epsf::varying::{self, EpsfField, VaryingEpsf};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::config::EpsfVariation;
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

/// What the crowded builder iterates: one ePSF for the image, or one with planes of change across it.
trait Iterated: EpsfField + Sized {
    /// The table whose nodes the samples fall on (the constant one, or the base).
    fn table(&self) -> &Epsf;
    /// The basis of a star at (x, y) (the constant first).
    fn basis_at(&self, x: f64, y: f64) -> [f64; 6];
    /// One step from the stars' (basis, samples); the new ePSF and the largest change of its table.
    fn step(
        &self,
        per_star: Vec<([f64; 6], Vec<(usize, f64)>)>,
        opts: &BuildOptions,
    ) -> (Self, f64);
}

impl Iterated for Epsf {
    fn table(&self) -> &Epsf {
        self
    }
    fn basis_at(&self, _x: f64, _y: f64) -> [f64; 6] {
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    }
    fn step(
        &self,
        per_star: Vec<([f64; 6], Vec<(usize, f64)>)>,
        opts: &BuildOptions,
    ) -> (Self, f64) {
        update(self, per_star.into_iter().map(|(_, v)| v).collect(), opts)
    }
}

impl Iterated for VaryingEpsf {
    fn table(&self) -> &Epsf {
        &self.base
    }
    fn basis_at(&self, x: f64, y: f64) -> [f64; 6] {
        self.basis(x, y)
    }
    fn step(
        &self,
        per_star: Vec<([f64; 6], Vec<(usize, f64)>)>,
        opts: &BuildOptions,
    ) -> (Self, f64) {
        varying::update(self, per_star, opts)
    }
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
    iterate(img, stars, candidates, seed, node_error, cfg)
}

/// The crowded ePSF with its planes of change across the image (`cfg.epsf_variation`, [`varying`]), built
/// from `seed` as [`build_epsf`] builds one: each star fitted with the table of its own place, each
/// candidate's samples `(P − s − M)/f` (M every star's own-place model, its own included) fitted node by
/// node on the basis. Candidates that cannot constrain the planes ([`varying::unconstrained`]) build one
/// ePSF instead. Returns the ePSF, the candidates that gave samples, the iterations made and why it was kept
/// constant (empty when it was not).
pub fn build_varying(
    img: &AnalysisImage,
    stars: &mut Vec<Member>,
    candidates: &[bool],
    seed: Epsf,
    node_error: f64,
    cfg: &AnalysisCfg,
) -> (VaryingEpsf, usize, usize, String) {
    let psi = VaryingEpsf::new(seed, cfg.epsf_variation, img.nx, img.ny);
    let positions: Vec<(f64, f64)> = stars
        .iter()
        .zip(candidates)
        .filter(|(_, c)| **c)
        .map(|(s, _)| (s.x, s.y))
        .collect();
    if let Some(why) = varying::unconstrained(&positions, cfg.epsf_variation, &psi) {
        let (e, used, done) = iterate(img, stars, candidates, psi.base, node_error, cfg);
        let constant = VaryingEpsf::new(e, EpsfVariation::Constant, img.nx, img.ny);
        return (constant, used, done, why);
    }
    let (psi, used, done) = iterate(img, stars, candidates, psi, node_error, cfg);
    (psi, used, done, String::new())
}

/// The builder's iterations, the fits refining `stars` as it goes.
fn iterate<B: Iterated>(
    img: &AnalysisImage,
    stars: &mut Vec<Member>,
    candidates: &[bool],
    seed: B,
    node_error: f64,
    cfg: &AnalysisCfg,
) -> (B, usize, usize) {
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
        let per_star: Vec<([f64; 6], Vec<(usize, f64)>)> = fits
            .par_iter()
            .zip(candidates)
            .map(|(f, c)| {
                if !*c || !f.usable() || !(f.flux > 0.0) || f.chi2_red > chi_limit {
                    return ([0.0; 6], Vec::new());
                }
                (
                    psi.basis_at(f.x, f.y),
                    residual_samples(img, &model, psi.table(), f),
                )
            })
            .collect();
        used = per_star.iter().filter(|(_, v)| !v.is_empty()).count();
        let peak = psi
            .table()
            .data
            .iter()
            .cloned()
            .fold(0.0, f64::max)
            .max(1e-300);
        let (next, max_delta) = psi.step(per_star, &opts);
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

#[cfg(test)]
mod tests {
    use crate::analysis::crowded::analyse;
    use crate::analysis::crowded::group_fit::{Member, Outsiders, fit_group_with};
    use crate::analysis::epsf::Epsf;
    use crate::analysis::epsf::build::build_options;
    use crate::analysis::epsf::varying::mixed_profile::{light, params};
    use crate::analysis::image::AnalysisImage;
    use crate::config::{Analysis, EpsfVariation};

    const FLUX_E: f64 = 1.0e6;
    const SKY_E: f64 = 100.0;
    const PAIR_DX_PX: f64 = 4.5;

    /// `k × k` pairs of stars 4.5 px apart (fitted together: closer than the link radius) (the second half as bright) on a grid 24 px apart, every profile
    /// the mix of [`light`] at its place, with seeded Gaussian noise of the sky's and a 5-e⁻ floor's.
    fn pairs(k: usize) -> (AnalysisImage, Vec<[(f64, f64, f64); 2]>) {
        let n = 24 * k;
        let mut state = 2024u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let truth: Vec<[(f64, f64, f64); 2]> = (0..k * k)
            .map(|i| {
                let (x, y) = (
                    10.0 + 24.0 * (i % k) as f64 + rnd() - 0.5,
                    12.0 + 24.0 * (i / k) as f64 + rnd() - 0.5,
                );
                [(x, y, FLUX_E), (x + PAIR_DX_PX, y + 0.3, 0.5 * FLUX_E)]
            })
            .collect();
        let mut e = vec![SKY_E; n * n];
        for &(x, y, f) in truth.iter().flatten() {
            let w = params(x, y, n);
            for py in (y as i64 - 8).max(0)..=(y as i64 + 8).min(n as i64 - 1) {
                for px in (x as i64 - 8).max(0)..=(x as i64 + 8).min(n as i64 - 1) {
                    e[py as usize * n + px as usize] += f * light(px as f64 - x, py as f64 - y, w);
                }
            }
        }
        for v in e.iter_mut() {
            // Box–Muller from the same stream
            let (u1, u2) = (rnd().max(1e-300), rnd());
            let g = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
            *v += g * (*v + 25.0).sqrt();
        }
        let img = AnalysisImage {
            nx: n,
            ny: n,
            e,
            bad: vec![false; n * n],
            var_floor_e2: 25.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
            plate_scale_mas: 100.0,
        };
        (img, truth)
    }

    /// The crowded analysis with a linear ePSF against another method: each pair fitted together with its
    /// two stars' own exact ePSFs (their true profiles tabulated at their places, re-centred to the builder's
    /// convention). One ePSF for the image is displaced from those fits by a trend across the field; the
    /// linear ePSF follows them, in the pairs' joint fits as in the isolated builder.
    #[test]
    fn a_crowded_linear_epsf_fits_each_pair_as_their_own_exact_epsfs_do() {
        let (img, truth) = pairs(12);
        let pd = img.pixels();
        let base = Analysis::default();
        let opts = build_options(&base);
        // the exact fits: each pair with its stars' own tables, started at the truth, nothing outside
        let exact: Vec<[(f64, f64); 2]> = truth
            .iter()
            .map(|pair| {
                let tables: Vec<Epsf> = pair
                    .iter()
                    .map(|&(x, y, _)| {
                        let w = params(x, y, img.nx);
                        let mut e =
                            Epsf::from_fn(opts.oversampling, opts.half_px, |u, v| light(u, v, w));
                        e.normalise();
                        e.recentred()
                    })
                    .collect();
                let members: Vec<Member> =
                    pair.iter().map(|&(x, y, f)| Member::new(x, y, f)).collect();
                let f = fit_group_with(
                    &pd,
                    &tables[0],
                    Some(&tables),
                    &members,
                    &Outsiders { stars: &[] },
                    SKY_E,
                    0.0,
                    &opts.fit,
                );
                [(f[0].x, f[0].y), (f[1].x, f[1].y)]
            })
            .collect();
        // per kind of star (the brighter of each pair, which builds the ePSF; the fainter, fitted with it):
        // the rms gap to the exact fits, and how many were found within 0.5 px of the truth
        let gap = |variation: EpsfVariation| -> ([f64; 2], usize, String) {
            let cfg = Analysis {
                epsf_variation: variation,
                ..base.clone()
            };
            let c = analyse(&img, &cfg, None, None);
            let mut d2 = [Vec::new(), Vec::new()];
            for (pair, ex) in truth.iter().zip(&exact) {
                for (j, (&(x, y, _), &(ex_x, ex_y))) in pair.iter().zip(ex).enumerate() {
                    let hit = c
                        .fits
                        .iter()
                        .filter(|f| (f.x - x).hypot(f.y - y) < 0.5)
                        .min_by(|a, b| {
                            (a.x - x)
                                .hypot(a.y - y)
                                .total_cmp(&(b.x - x).hypot(b.y - y))
                        });
                    if let Some(f) = hit {
                        d2[j].push((f.x - ex_x).powi(2) + (f.y - ex_y).powi(2));
                    }
                }
            }
            let rms = |v: &[f64]| (v.iter().sum::<f64>() / v.len().max(1) as f64).sqrt();
            (
                [rms(&d2[0]), rms(&d2[1])],
                d2[0].len() + d2[1].len(),
                c.variation,
            )
        };
        let (one, n_one, v_one) = gap(EpsfVariation::Constant);
        let (lin, n_lin, v_lin) = gap(EpsfVariation::Linear);
        eprintln!(
            "rms gap to the exact fits, brighter / fainter: one ePSF {:.2e} / {:.2e} px ({n_one} found), \
             linear {:.2e} / {:.2e} px ({n_lin} found)",
            one[0], one[1], lin[0], lin[1]
        );
        assert_eq!((v_one.as_str(), v_lin.as_str()), ("constant", "linear"));
        assert_eq!(
            n_lin,
            2 * truth.len(),
            "every star found with the linear ePSF"
        );
        // measured: 1.3e-1 / 8.5e-2 px with one ePSF, 2.2e-3 / 2.0e-2 px linear
        assert!(
            lin[0] < 5e-3 && lin[0] < 0.05 * one[0],
            "{lin:?} against {one:?}"
        );
        assert!(lin[1] < 0.35 * one[1], "{lin:?} against {one:?}");
    }

    /// Too few ePSF stars for a linear ePSF's three tables (9 pairs: 9 candidates, 10 a table wanted): one
    /// ePSF is built, its planes none, and the analysis says why.
    #[test]
    fn a_crowded_field_of_few_epsf_stars_keeps_one_epsf_and_says_why() {
        let (img, truth) = pairs(3);
        let cfg = Analysis {
            epsf_variation: EpsfVariation::Linear,
            ..Analysis::default()
        };
        let c = analyse(&img, &cfg, None, None);
        assert!(c.field.terms.is_empty());
        assert!(
            c.variation.contains("fewer than 30") && c.variation.contains("one ePSF"),
            "{}",
            c.variation
        );
        assert!(c.fits.len() >= 2 * truth.len() - 1, "{} fits", c.fits.len());
        // the one ePSF kept is the one-ePSF analysis's, node for node
        let one = analyse(&img, &Analysis::default(), None, None);
        assert_eq!(c.field.base, one.field.base);
    }
}
