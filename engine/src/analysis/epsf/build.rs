//! The iterative ePSF builder (Anderson & King 2000, §4):
//!
//! 1. start from a Gaussian matched to the stars' second moments (or a given ePSF);
//! 2. fit every usable star (x, y, flux) with the current ePSF;
//! 3. each pixel within the table of each star gives a residual sample `(P − s)/f − ψ(Δ)` at `Δ = (X − x, Y − y)`;
//!    samples are binned to the nearest node and combined by a sigma-clipped mean;
//! 4. ψ ← ψ + δψ, smoothed ([`super::smooth`]), re-centred (centroid at the origin), normalised;
//! 5. repeat `iterations` times (0: until the largest correction is below 1e-4 of the peak, at most 30).
//!
//! Nodes without samples keep their previous value, so few stars (or a small zone) still give a sane ePSF.

use super::Epsf;
use super::fit::{FitOptions, PixelData, StarFit, annulus_sky, fit_star};
use super::smooth;
use crate::config::Smoothing;
use crate::numerics::stats;
use rayon::prelude::*;

/// Starting values of a star.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StarStart {
    pub x: f64,
    pub y: f64,
    pub flux: f64,
    pub sky: f64,
}

/// Builder options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildOptions {
    pub oversampling: usize,
    pub half_px: usize,
    /// 0 = until converged (≤ 30).
    pub iterations: usize,
    pub smoothing: Smoothing,
    pub clip_sigma: f64,
    pub fit: FitOptions,
    /// Re-centre after every iteration (the centroid convention); `false` keeps the frame of the
    /// positions the samples were placed with.
    pub recentre: bool,
}

/// The ePSF builder's options from the analysis configuration.
pub fn build_options(cfg: &crate::config::Analysis) -> BuildOptions {
    BuildOptions {
        oversampling: cfg.epsf_oversampling,
        half_px: cfg.epsf_radius_px,
        iterations: cfg.epsf_iterations,
        smoothing: cfg.smoothing,
        clip_sigma: cfg.clip_sigma,
        fit: FitOptions {
            radius_px: cfg.fit_radius_px,
            max_iter: cfg.fit_max_iter,
            fit_sky: cfg.fit_sky,
        },
        recentre: true,
    }
}

/// The result of a build: the ePSF and the final fit of every star.
#[derive(Debug, Clone)]
pub struct Built {
    pub epsf: Epsf,
    pub fits: Vec<StarFit>,
    pub iterations: usize,
    /// Stars that contributed samples.
    pub used: Vec<bool>,
}

/// Initial position (sky-subtracted centroid in a 5 × 5 box around the brightest pixel), sky (annulus) and
/// flux (sum within 3 px) of a star near (x, y).
pub fn initial_start(img: &PixelData<'_>, x: f64, y: f64, sky_annulus: (f64, f64)) -> StarStart {
    let sky = annulus_sky(img, x, y, sky_annulus.0, sky_annulus.1).unwrap_or(0.0);
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let get = |px: i64, py: i64| -> Option<f64> {
        if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
            return None;
        }
        let i = py as usize * img.nx + px as usize;
        (!img.bad[i]).then(|| img.e[i] - sky)
    };
    let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
    for py in cy - 2..=cy + 2 {
        for px in cx - 2..=cx + 2 {
            if let Some(v) = get(px, py) {
                let v = v.max(0.0);
                sx += v * px as f64;
                sy += v * py as f64;
                s += v;
            }
        }
    }
    let (x0, y0) = if s > 0.0 { (sx / s, sy / s) } else { (x, y) };
    let mut flux = 0.0;
    for py in cy - 3..=cy + 3 {
        for px in cx - 3..=cx + 3 {
            if (px as f64 - x0).powi(2) + (py as f64 - y0).powi(2) <= 9.0 {
                flux += get(px, py).unwrap_or(0.0);
            }
        }
    }
    StarStart {
        x: x0,
        y: y0,
        flux: flux.max(1.0),
        sky,
    }
}

/// A Gaussian first guess whose width matches the stars' mean second moment within 3 px.
pub fn gaussian_seed(
    img: &PixelData<'_>,
    starts: &[StarStart],
    oversampling: usize,
    half_px: usize,
) -> Epsf {
    let mut m2 = Vec::new();
    for s in starts {
        let (mut acc, mut w) = (0.0, 0.0);
        for py in (s.y.round() as i64 - 3)..=(s.y.round() as i64 + 3) {
            for px in (s.x.round() as i64 - 3)..=(s.x.round() as i64 + 3) {
                if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
                    continue;
                }
                let i = py as usize * img.nx + px as usize;
                let r2 = (px as f64 - s.x).powi(2) + (py as f64 - s.y).powi(2);
                if r2 <= 9.0 && !img.bad[i] {
                    let v = (img.e[i] - s.sky).max(0.0);
                    acc += v * r2;
                    w += v;
                }
            }
        }
        if w > 0.0 {
            m2.push(acc / w);
        }
    }
    // ⟨r²⟩ = 2σ² (+ 1/6 from the pixel); a truncated moment, but only a starting point
    let sigma = ((stats::median(&m2) - 1.0 / 6.0) / 2.0)
        .max(0.16)
        .sqrt()
        .clamp(0.4, 3.0);
    let mut e = Epsf::from_fn(oversampling, half_px, |x, y| {
        (-(x * x + y * y) / (2.0 * sigma * sigma)).exp()
    });
    e.normalise();
    e
}

/// Residual samples of one star: (node index, residual).
fn samples(img: &PixelData<'_>, epsf: &Epsf, fit: &StarFit, x: f64, y: f64) -> Vec<(usize, f64)> {
    residual_samples(img, epsf, epsf, x, y, fit.flux, fit.sky)
}

/// Residual samples `(P − s)/f − model` of a star at (x, y) over `grid`'s reach, each binned to `grid`'s
/// nearest node: (node index, residual). `model` is the grid itself for the plain build, or the star's own
/// profile (the telemetry forward model's, for a deconvolved build).
pub fn residual_samples<P: super::fit::Profile + ?Sized>(
    img: &PixelData<'_>,
    grid: &Epsf,
    model: &P,
    x: f64,
    y: f64,
    flux: f64,
    sky: f64,
) -> Vec<(usize, f64)> {
    let n = grid.n() as i64;
    let os = grid.oversampling as f64;
    let h = grid.half_nodes as i64;
    let r = grid.half_px() - 0.5;
    let mut out = Vec::new();
    for py in (y - r).ceil() as i64..=(y + r).floor() as i64 {
        for px in (x - r).ceil() as i64..=(x + r).floor() as i64 {
            if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
                continue;
            }
            let i = py as usize * img.nx + px as usize;
            if img.bad[i] {
                continue;
            }
            let (dx, dy) = (px as f64 - x, py as f64 - y);
            let (u, v) = ((dx * os).round() as i64 + h, (dy * os).round() as i64 + h);
            if u < 0 || v < 0 || u >= n || v >= n {
                continue;
            }
            let m = model.eval_at(i, px as f64, py as f64, x, y).0;
            out.push(((v * n + u) as usize, (img.e[i] - sky) / flux - m));
        }
    }
    out
}

/// One step of the builder (steps 3–4 above): each node moves by the sigma-clipped mean of the residual
/// samples binned to it (`per_star`: (node, residual) of each star), then ψ is smoothed, re-centred (when
/// `opts.recentre`) and normalised. Returns the new ψ and the largest correction.
pub fn update(psi: &Epsf, per_star: Vec<Vec<(usize, f64)>>, opts: &BuildOptions) -> (Epsf, f64) {
    let n = psi.n();
    let mut buckets: Vec<Vec<f64>> = vec![Vec::new(); n * n];
    for v in per_star {
        for (node, r) in v {
            buckets[node].push(r);
        }
    }
    let delta: Vec<f64> = buckets
        .par_iter()
        .map(|b| {
            if b.is_empty() {
                0.0
            } else {
                stats::clipped_mean(b, opts.clip_sigma).0
            }
        })
        .collect();
    let max_delta = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    let mut next = psi.clone();
    for (p, d) in next.data.iter_mut().zip(&delta) {
        *p += d;
    }
    next = smooth::smooth(&next, opts.smoothing);
    if opts.recentre {
        next = next.recentred();
    }
    next.normalise();
    (next, max_delta)
}

/// Flux and sky-free linear fit at fixed position: f = Σ w ψ (d − s) / Σ w ψ².
fn fit_flux_at(
    img: &PixelData<'_>,
    epsf: &Epsf,
    x: f64,
    y: f64,
    s: f64,
    radius: f64,
    f0: f64,
) -> StarFit {
    let (mut num, mut den) = (0.0, 0.0);
    let r = radius.ceil() as i64 + 1;
    for py in y.round() as i64 - r..=y.round() as i64 + r {
        for px in x.round() as i64 - r..=x.round() as i64 + r {
            if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
                continue;
            }
            if (px as f64 - x).powi(2) + (py as f64 - y).powi(2) > radius * radius {
                continue;
            }
            let i = py as usize * img.nx + px as usize;
            if img.bad[i] {
                continue;
            }
            let psi = epsf.value(px as f64 - x, py as f64 - y);
            let w = 1.0
                / super::fit::pixel_variance(
                    f0 * psi + s,
                    f0 * psi,
                    img.floor_e2(i),
                    img.flat_sigma,
                );
            num += w * psi * (img.e[i] - s);
            den += w * psi * psi;
        }
    }
    let flux = if den > 0.0 { num / den } else { f0 };
    StarFit {
        x,
        y,
        flux,
        sky: s,
        ..Default::default()
    }
}

/// Most iterations of a build that iterates until converged (`iterations = 0`).
pub const MAX_BUILD_ITERATIONS: usize = 30;

/// The iterations a build makes at most: `opts.iterations`, or [`MAX_BUILD_ITERATIONS`] for 0 (until converged).
pub fn iteration_cap(opts: &BuildOptions) -> usize {
    match opts.iterations {
        0 => MAX_BUILD_ITERATIONS,
        n => n,
    }
}

/// The χ²/dof above which a star gives the builder no samples: [`super::fit::flags::POOR_FIT_FACTOR`] × the
/// median of the usable stars' (at least 1); none with fewer than 5 stars.
pub fn sample_chi_limit(chi: &[f64]) -> f64 {
    if chi.len() < 5 {
        f64::INFINITY
    } else {
        super::fit::flags::POOR_FIT_FACTOR * stats::median(chi).max(1.0)
    }
}

/// Build an ePSF from `starts`; `use_for_build[k]` selects the stars that contribute samples (all are fit).
/// With `fixed_positions`, star positions are held there while building (only fluxes are refit).
pub fn build(
    img: &PixelData<'_>,
    starts: &[StarStart],
    use_for_build: &[bool],
    opts: &BuildOptions,
    init: Option<&Epsf>,
    fixed_positions: Option<&[(f64, f64)]>,
) -> Built {
    let builders: Vec<StarStart> = starts
        .iter()
        .zip(use_for_build)
        .filter(|(_, u)| **u)
        .map(|(s, _)| *s)
        .collect();
    let mut psi = match init {
        Some(e) => e.clone(),
        None => gaussian_seed(
            img,
            if builders.is_empty() {
                starts
            } else {
                &builders
            },
            opts.oversampling,
            opts.half_px,
        ),
    };
    let mut done = 0;
    for _ in 0..iteration_cap(opts) {
        done += 1;
        let fitted: Vec<Option<(StarFit, f64, f64)>> = starts
            .par_iter()
            .enumerate()
            .map(|(k, s)| {
                if !use_for_build[k] {
                    return None;
                }
                Some(match fixed_positions {
                    Some(p) => {
                        let (x, y) = p[k];
                        (
                            fit_flux_at(img, &psi, x, y, s.sky, opts.fit.radius_px, s.flux),
                            x,
                            y,
                        )
                    }
                    None => {
                        let f = fit_star(img, &psi, s.x, s.y, s.flux, s.sky, &opts.fit);
                        (f, f.x, f.y)
                    }
                })
            })
            .collect();
        // stars that the current ePSF fits far worse than the others (blends, defects) give no samples
        let chi: Vec<f64> = fitted
            .iter()
            .flatten()
            .filter(|(f, _, _)| f.usable())
            .map(|(f, _, _)| f.chi2_red)
            .collect();
        let chi_limit = match fixed_positions {
            Some(_) => f64::INFINITY,
            None => sample_chi_limit(&chi),
        };
        let per_star: Vec<Vec<(usize, f64)>> = fitted
            .par_iter()
            .map(|o| match o {
                Some((f, x, y))
                    if (fixed_positions.is_some() || f.usable())
                        && f.flux > 0.0
                        && f.chi2_red <= chi_limit =>
                {
                    samples(img, &psi, f, *x, *y)
                }
                _ => Vec::new(),
            })
            .collect();
        let peak = psi.data.iter().cloned().fold(0.0, f64::max).max(1e-300);
        let (next, max_delta) = update(&psi, per_star, opts);
        psi = next;
        if opts.iterations == 0 && max_delta < 1e-4 * peak {
            break;
        }
    }
    let fits: Vec<StarFit> = starts
        .par_iter()
        .enumerate()
        .map(|(k, s)| match fixed_positions {
            Some(p) => {
                let mut f = fit_star(img, &psi, p[k].0, p[k].1, s.flux, s.sky, &opts.fit);
                if !f.usable() {
                    f = fit_flux_at(img, &psi, p[k].0, p[k].1, s.sky, opts.fit.radius_px, s.flux);
                }
                f
            }
            None => fit_star(img, &psi, s.x, s.y, s.flux, s.sky, &opts.fit),
        })
        .collect();
    Built {
        epsf: psi,
        fits,
        iterations: done,
        used: use_for_build.to_vec(),
    }
}
