//! Fitting one star with an ePSF, and its Cramér–Rao bound.
//!
//! Model of pixel i: `μᵢ = f·ψ(Xᵢ − x, Yᵢ − y) + s` (electrons), over the pixels whose centres lie within
//! `radius_px` of the star. Sky s comes from a sigma-clipped annulus (or is fitted, `fit_sky`). Noise model
//! (SPEC §7): `σᵢ² = max(μᵢ, 0) + RN² + g²/12` in e⁻² — Poisson, read noise, quantisation.
//! Weighted least squares by Gauss–Newton with Levenberg damping, weights from the current model, at most
//! `max_iter` steps. The covariance `(JᵀWJ)⁻¹` at the solution is the Fisher-information inverse: its
//! diagonal is the Cramér–Rao bound of the star under this ePSF and noise model.

use super::Epsf;
use crate::numerics::linalg;

/// Pixels of an image in electrons, bias removed, with a mask of unusable pixels.
#[derive(Debug, Clone, Copy)]
pub struct PixelData<'a> {
    pub nx: usize,
    pub ny: usize,
    pub e: &'a [f64],
    /// true = do not use (saturated, non-photosensitive, ADC clipped).
    pub bad: &'a [bool],
    /// RN² + g²/12, e⁻² (the image's typical floor: its rms over the pixels where it varies).
    pub var_floor_e2: f64,
    /// Each pixel's own floor, e⁻², where it varies across the image (a chip read by amplifiers of
    /// different read noise); `None`: every pixel's is `var_floor_e2`.
    pub var_floor_px_e2: Option<&'a [f64]>,
    /// Relative flat-field error the weights count as noise: a pixel with star signal s has the extra
    /// variance (σ s)² (0: the flat is ignored).
    pub flat_sigma: f64,
}

impl PixelData<'_> {
    /// The read/quantisation floor of pixel `i`, e⁻².
    #[inline]
    pub fn floor_e2(&self, i: usize) -> f64 {
        self.var_floor_px_e2.map_or(self.var_floor_e2, |m| m[i])
    }
}

/// The variance of a pixel predicted to hold `mu` e⁻ of which `star` come from the star: Poisson + floor +
/// the flat error on the star's signal.
#[inline]
pub fn pixel_variance(mu: f64, star: f64, floor: f64, flat_sigma: f64) -> f64 {
    mu.max(0.0) + floor + (flat_sigma * star).powi(2)
}

/// Fit flags (bits).
pub mod flags {
    pub const NOT_CONVERGED: u32 = 1;
    pub const EDGE: u32 = 2;
    pub const SATURATED: u32 = 4;
    pub const MOVED: u32 = 8;
    pub const SINGULAR: u32 = 16;
    pub const NONPOSITIVE_FLUX: u32 = 32;
    pub const FEW_PIXELS: u32 = 64;
    /// χ²/dof far above the image's typical value (a blend, a cosmic, a bad pixel): see [`POOR_FIT_FACTOR`].
    pub const POOR_FIT: u32 = 128;
    /// Another detected star lies within [`blend_radius_px`] of this one: its light is in this star's fit
    /// pixels (reported, not rejected: a crowded-field analysis reports such stars separately).
    pub const BLENDED: u32 = 256;
    /// Fitted simultaneously with overlapping neighbours (the crowded-field analysis' groups).
    pub const GROUPED: u32 = 512;
    /// Found in the residual image after the first fits (a companion the first detection merged).
    pub const RESIDUAL_FOUND: u32 = 1024;
    /// Anything that makes a fit unusable for the accuracy statistics.
    pub const REJECT: u32 =
        NOT_CONVERGED | MOVED | SINGULAR | NONPOSITIVE_FLUX | FEW_PIXELS | POOR_FIT;
    /// A fit is poor when its χ²/dof exceeds this many times the median of the image's fits (and 2).
    pub const POOR_FIT_FACTOR: f64 = 5.0;

    /// The distance within which a neighbour blends into a star's fit: the fit radius plus 3 px (where the
    /// neighbour's PSF core has fallen below ≈ 1 % of its peak).
    pub fn blend_radius_px(fit_radius_px: f64) -> f64 {
        fit_radius_px + 3.0
    }

    /// Flag the fits with another fit within `radius_px` (the k-d tree of their positions: O(n log n)).
    pub fn mark_blends(fits: &mut [super::StarFit], radius_px: f64) {
        let pos: Vec<(f64, f64)> = fits.iter().map(|f| (f.x, f.y)).collect();
        let nb = crate::numerics::neighbours::Neighbours::new(&pos);
        let blended: Vec<bool> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| {
                nb.near(x, y, radius_px)
                    .into_iter()
                    .any(|j| j != k && (pos[j].0 - x).hypot(pos[j].1 - y) < radius_px)
            })
            .collect();
        for (f, b) in fits.iter_mut().zip(blended) {
            if b {
                f.flags |= BLENDED;
            }
        }
    }

    /// Flag the fits whose χ²/dof stands out from the median of the usable ones.
    pub fn mark_poor_fits(fits: &mut [super::StarFit]) {
        let c: Vec<f64> = fits
            .iter()
            .filter(|f| f.usable() && f.chi2_red.is_finite())
            .map(|f| f.chi2_red)
            .collect();
        let limit = (POOR_FIT_FACTOR * crate::numerics::stats::median(&c)).max(2.0);
        for f in fits.iter_mut() {
            if !(f.chi2_red <= limit) {
                f.flags |= POOR_FIT;
            }
        }
    }
}

/// Options of a star fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    pub radius_px: f64,
    pub max_iter: usize,
    pub fit_sky: bool,
}

/// Result of a star fit. Positions in pixels (0-based), fluxes in electrons.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StarFit {
    pub x: f64,
    pub y: f64,
    pub flux: f64,
    pub sky: f64,
    /// Cramér–Rao bounds (= the fit's standard errors), pixels and electrons.
    pub crlb_x: f64,
    pub crlb_y: f64,
    pub crlb_flux: f64,
    pub chi2_red: f64,
    pub n_pix: usize,
    pub iterations: usize,
    pub flags: u32,
}

impl StarFit {
    pub fn usable(&self) -> bool {
        self.flags & flags::REJECT == 0 && self.x.is_finite() && self.y.is_finite()
    }
}

/// The sky under a star to fit: the 3σ-clipped median of the unmasked pixels in the annulus [r_in, r_out] around
/// (x, y) (`analysis::sky`, the one estimator); `None` with fewer than 8 of them.
pub fn annulus_sky(img: &PixelData<'_>, x: f64, y: f64, r_in: f64, r_out: f64) -> Option<f64> {
    crate::analysis::sky::annulus(
        img.nx,
        img.ny,
        x,
        y,
        r_in,
        r_out,
        |i| (!img.bad[i]).then(|| img.e[i]),
        crate::analysis::sky::SkyStatistic::ClippedMedian { sigmas: 3.0 },
        8,
    )
    .map(|s| s.value)
}

/// The fit pixels (index, X, Y) around (x, y): the disc of `radius`, grown 1 px at a time (by at most
/// [`MAX_RADIUS_GROWTH_PX`]) while masked pixels (a saturated core) leave fewer good pixels than 80 % of the
/// unmasked disc's area (π·radius²), so a saturated star is fitted from its unsaturated wings. Returns the pixels
/// and whether the disc met the image edge or masked pixels.
pub(crate) fn select(
    img: &PixelData<'_>,
    x: f64,
    y: f64,
    radius: f64,
) -> (Vec<(usize, f64, f64)>, bool, bool) {
    let full = std::f64::consts::PI * radius * radius;
    let mut r = radius;
    loop {
        let (pix, edge, bad) = select_disc(img, x, y, r);
        if !bad || pix.len() as f64 >= 0.8 * full || r >= radius + MAX_RADIUS_GROWTH_PX {
            return (pix, edge, bad);
        }
        r += 1.0;
    }
}

/// Largest growth of a fit disc around a saturated core, px.
pub const MAX_RADIUS_GROWTH_PX: f64 = 8.0;

/// The usable pixels (index, X, Y) of the disc of `radius` around (x, y), and whether it met the image edge
/// or masked pixels.
pub(crate) fn select_disc(
    img: &PixelData<'_>,
    x: f64,
    y: f64,
    radius: f64,
) -> (Vec<(usize, f64, f64)>, bool, bool) {
    let mut out = Vec::new();
    let (mut edge, mut bad) = (false, false);
    let r = radius.ceil() as i64 + 1;
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    for py in cy - r..=cy + r {
        for px in cx - r..=cx + r {
            if (px as f64 - x).powi(2) + (py as f64 - y).powi(2) > radius * radius {
                continue;
            }
            if px < 0 || py < 0 || px >= img.nx as i64 || py >= img.ny as i64 {
                edge = true;
                continue;
            }
            let i = py as usize * img.nx + px as usize;
            if img.bad[i] {
                bad = true;
                continue;
            }
            out.push((i, px as f64, py as f64));
        }
    }
    (out, edge, bad)
}

/// What a star's pixels are fitted with: its normalised profile in pixel `i` (centre `(px, py)`) for a star at
/// `(x, y)`, and the profile's gradient with respect to the pixel's offset from the star (so the position
/// derivatives are its negatives). The ePSF is one ([`Epsf`]: a function of the offset alone); a profile that
/// follows each pixel's own exposure window is another (`analysis::countermeasures::forward`).
pub trait Profile: Sync {
    fn eval_at(&self, i: usize, px: f64, py: f64, x: f64, y: f64) -> (f64, f64, f64);
}

impl Profile for Epsf {
    #[inline]
    fn eval_at(&self, _i: usize, px: f64, py: f64, x: f64, y: f64) -> (f64, f64, f64) {
        self.eval(px - x, py - y)
    }
}

/// Fisher matrix of (x, y, f[, s]) for a star at (x, y) with flux f on sky s, over `pix`.
fn fisher<P: Profile + ?Sized>(
    epsf: &P,
    pix: &[(usize, f64, f64)],
    x: f64,
    y: f64,
    f: f64,
    s: f64,
    floor: impl Fn(usize) -> f64,
    flat_sigma: f64,
    fit_sky: bool,
) -> (Vec<f64>, usize) {
    let np = if fit_sky { 4 } else { 3 };
    let mut m = vec![0.0; np * np];
    for &(i, px, py) in pix {
        let (psi, gx, gy) = epsf.eval_at(i, px, py, x, y);
        let mu = f * psi + s;
        let w = 1.0 / pixel_variance(mu, f * psi, floor(i), flat_sigma);
        let j = [-f * gx, -f * gy, psi, 1.0];
        for a in 0..np {
            for b in 0..np {
                m[a * np + b] += w * j[a] * j[b];
            }
        }
    }
    (m, np)
}

/// Cramér–Rao bounds (σx, σy, σf) of a star with the given true parameters (no flat-field error).
pub fn crlb(
    img_shape: (usize, usize),
    epsf: &Epsf,
    x: f64,
    y: f64,
    f: f64,
    s: f64,
    floor: f64,
    radius: f64,
    fit_sky: bool,
) -> Option<(f64, f64, f64)> {
    let (nx, ny) = img_shape;
    let r = radius.ceil() as i64 + 1;
    let mut pix = Vec::new();
    for py in y.round() as i64 - r..=y.round() as i64 + r {
        for px in x.round() as i64 - r..=x.round() as i64 + r {
            if px >= 0
                && py >= 0
                && (px as usize) < nx
                && (py as usize) < ny
                && (px as f64 - x).powi(2) + (py as f64 - y).powi(2) <= radius * radius
            {
                pix.push((0, px as f64, py as f64));
            }
        }
    }
    let (m, np) = fisher(epsf, &pix, x, y, f, s, |_| floor, 0.0, fit_sky);
    let inv = linalg::inverse(&m, np)?;
    Some((
        inv[0].max(0.0).sqrt(),
        inv[np + 1].max(0.0).sqrt(),
        inv[2 * np + 2].max(0.0).sqrt(),
    ))
}

/// Fit one star starting from (x0, y0) with flux guess f0 and sky s0, with the profile `epsf` (an [`Epsf`], or
/// any [`Profile`]).
pub fn fit_star<P: Profile + ?Sized>(
    img: &PixelData<'_>,
    epsf: &P,
    x0: f64,
    y0: f64,
    f0: f64,
    s0: f64,
    opt: &FitOptions,
) -> StarFit {
    let mut out = StarFit {
        x: x0,
        y: y0,
        flux: f0,
        sky: s0,
        ..Default::default()
    };
    let (mut pix, mut edge, mut bad) = select(img, x0, y0, opt.radius_px);
    let np = if opt.fit_sky { 4 } else { 3 };
    let mut p = [x0, y0, f0.max(1.0), s0];
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut reselected = false;
    let mut iter = 0;
    while iter < opt.max_iter {
        iter += 1;
        if pix.len() < np + 2 {
            out.flags |= flags::FEW_PIXELS;
            break;
        }
        let normal = normal_equations(img, epsf, &pix, &p, np);
        match lm_step(&normal, &p, np, &mut lambda, |q| {
            chi2_of(img, epsf, q, &pix)
        }) {
            Some((q, small)) => {
                p = q;
                converged = small;
            }
            // no step lowers χ²: we are at the minimum to working precision
            None => converged = true,
        }
        if converged {
            // the pixel set was chosen around the start: choose again around the solution once
            if !reselected && ((p[0] - x0).abs() > 0.5 || (p[1] - y0).abs() > 0.5) {
                (pix, edge, bad) = select(img, p[0], p[1], opt.radius_px);
                reselected = true;
                converged = false;
                continue;
            }
            break;
        }
    }
    out.iterations = iter;
    out.n_pix = pix.len();
    for (on, flag) in [
        (edge, flags::EDGE),
        (bad, flags::SATURATED),
        (!converged, flags::NOT_CONVERGED),
        ((p[0] - x0).hypot(p[1] - y0) > 1.5, flags::MOVED),
        (!(p[2] > 0.0), flags::NONPOSITIVE_FLUX),
    ] {
        if on {
            out.flags |= flag;
        }
    }
    finish(&mut out, img, epsf, &pix, p, (x0, y0, f0), opt.fit_sky);
    out
}

/// χ² of the star `p` = (x, y, flux, sky) over the pixels `pix`.
fn chi2_of<P: Profile + ?Sized>(
    img: &PixelData<'_>,
    epsf: &P,
    p: &[f64; 4],
    pix: &[(usize, f64, f64)],
) -> f64 {
    pix.iter()
        .map(|&(i, px, py)| {
            let star = p[2] * epsf.eval_at(i, px, py, p[0], p[1]).0;
            let mu = star + p[3];
            (img.e[i] - mu).powi(2) / pixel_variance(mu, star, img.floor_e2(i), img.flat_sigma)
        })
        .sum()
}

/// The weighted normal equations at `p` over the first `np` parameters: (JᵀWJ, JᵀWr, χ²).
fn normal_equations<P: Profile + ?Sized>(
    img: &PixelData<'_>,
    epsf: &P,
    pix: &[(usize, f64, f64)],
    p: &[f64; 4],
    np: usize,
) -> (Vec<f64>, Vec<f64>, f64) {
    let mut jtj = vec![0.0; np * np];
    let mut jtr = vec![0.0; np];
    let mut chi2 = 0.0;
    for &(i, px, py) in pix {
        let (psi, gx, gy) = epsf.eval_at(i, px, py, p[0], p[1]);
        let mu = p[2] * psi + p[3];
        let w = 1.0 / pixel_variance(mu, p[2] * psi, img.floor_e2(i), img.flat_sigma);
        let r = img.e[i] - mu;
        chi2 += w * r * r;
        let j = [-p[2] * gx, -p[2] * gy, psi, 1.0];
        for a in 0..np {
            jtr[a] += w * j[a] * r;
            for b in 0..np {
                jtj[a * np + b] += w * j[a] * j[b];
            }
        }
    }
    (jtj, jtr, chi2)
}

/// A Levenberg–Marquardt step from `p`, the damping `lambda` raised until χ² (`chi2_of`) does not grow and
/// lowered after: the new parameters and whether the step was negligible, or `None` when no step lowers χ².
/// No step moves the star more than half a pixel.
fn lm_step(
    (jtj, jtr, chi2): &(Vec<f64>, Vec<f64>, f64),
    p: &[f64; 4],
    np: usize,
    lambda: &mut f64,
    chi2_of: impl Fn(&[f64; 4]) -> f64,
) -> Option<([f64; 4], bool)> {
    for _ in 0..12 {
        let mut a = jtj.clone();
        for k in 0..np {
            a[k * np + k] *= 1.0 + *lambda;
        }
        let Some(d) = linalg::solve(&a, jtr, np) else {
            *lambda *= 10.0;
            continue;
        };
        let mut q = *p;
        for k in 0..np {
            q[k] += d[k];
        }
        let jump = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if jump > 0.5 {
            q[0] = p[0] + d[0] * 0.5 / jump;
            q[1] = p[1] + d[1] * 0.5 / jump;
        }
        let c2 = chi2_of(&q);
        if c2.is_finite() && c2 <= chi2 * (1.0 + 1e-12) {
            let small =
                d[0].abs() < 1e-6 && d[1].abs() < 1e-6 && d[2].abs() < 1e-7 * p[2].abs().max(1.0);
            *lambda = (*lambda * 0.3).max(1e-9);
            return Some((q, small));
        }
        *lambda *= 10.0;
    }
    None
}

/// The fitted values, their Cramér–Rao bounds (flagged singular without them), the reduced χ², and the start
/// (`x0, y0, f0`) kept where the fit ran off to a non-finite value.
fn finish<P: Profile + ?Sized>(
    out: &mut StarFit,
    img: &PixelData<'_>,
    epsf: &P,
    pix: &[(usize, f64, f64)],
    p: [f64; 4],
    (x0, y0, f0): (f64, f64, f64),
    fit_sky: bool,
) {
    out.x = p[0];
    out.y = p[1];
    out.flux = p[2];
    out.sky = p[3];
    let (m, npar) = fisher(
        epsf,
        pix,
        p[0],
        p[1],
        p[2],
        p[3],
        |i| img.floor_e2(i),
        img.flat_sigma,
        fit_sky,
    );
    match linalg::inverse(&m, npar) {
        Some(inv) if inv[0] > 0.0 && inv[npar + 1] > 0.0 => {
            out.crlb_x = inv[0].sqrt();
            out.crlb_y = inv[npar + 1].sqrt();
            out.crlb_flux = inv[2 * npar + 2].max(0.0).sqrt();
        }
        _ => {
            out.flags |= flags::SINGULAR;
            out.crlb_x = f64::INFINITY;
            out.crlb_y = f64::INFINITY;
            out.crlb_flux = f64::INFINITY;
        }
    }
    let dof = pix.len().saturating_sub(npar).max(1) as f64;
    out.chi2_red = chi2_of(img, epsf, &p, pix) / dof;
    if !out.x.is_finite() || !out.y.is_finite() || !out.flux.is_finite() {
        out.x = x0;
        out.y = y0;
        out.flux = f0;
        out.flags |= flags::SINGULAR;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian ePSF and an image made from it exactly (noise-free): the fit must return the truth.
    fn setup(os: usize) -> Epsf {
        let s2 = 2.0 * 0.75f64.powi(2);
        // pixel-integrated Gaussian = product of error-function differences; tabulate by fine summation
        let mut e = Epsf::from_fn(os, 6, |x, y| {
            let m = 20;
            let mut acc = 0.0;
            for j in 0..m {
                for i in 0..m {
                    let (u, v) = (
                        x + (i as f64 + 0.5) / m as f64 - 0.5,
                        y + (j as f64 + 0.5) / m as f64 - 0.5,
                    );
                    acc += (-(u * u + v * v) / s2).exp();
                }
            }
            acc
        });
        e.normalise();
        e
    }

    #[test]
    fn noise_free_fit_is_exact() {
        let e = setup(8);
        let (nx, ny) = (40, 40);
        let (x, y, f, s) = (19.37, 21.81, 5.0e4, 300.0);
        let img: Vec<f64> = (0..nx * ny)
            .map(|i| f * e.value((i % nx) as f64 - x, (i / nx) as f64 - y) + s)
            .collect();
        let bad = vec![false; nx * ny];
        let pd = PixelData {
            nx,
            ny,
            e: &img,
            bad: &bad,
            var_floor_e2: 225.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
        };
        let opt = FitOptions {
            radius_px: 3.0,
            max_iter: 50,
            fit_sky: false,
        };
        let r = fit_star(&pd, &e, 19.0, 22.2, 4.0e4, s, &opt);
        assert!(r.usable(), "flags {}", r.flags);
        assert!(
            (r.x - x).abs() < 1e-6 && (r.y - y).abs() < 1e-6,
            "({}, {})",
            r.x,
            r.y
        );
        assert!((r.flux / f - 1.0).abs() < 1e-6);
        let sky = annulus_sky(&pd, x, y, 8.0, 11.0).expect("sky");
        assert!((sky - s).abs() < 1e-3);
    }

    #[test]
    fn degenerate_inputs_flag_not_nan() {
        let e = setup(4);
        let (nx, ny) = (20, 20);
        let img = vec![300.0; nx * ny];
        let bad = vec![false; nx * ny];
        let pd = PixelData {
            nx,
            ny,
            e: &img,
            bad: &bad,
            var_floor_e2: 225.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
        };
        let opt = FitOptions {
            radius_px: 2.5,
            max_iter: 30,
            fit_sky: false,
        };
        // no star at all: flux goes to ≤ 0 or the position wanders; flagged, finite
        let r = fit_star(&pd, &e, 10.0, 10.0, 1000.0, 300.0, &opt);
        assert!(!r.usable() || r.flux < 1.0, "{r:?}");
        assert!(r.x.is_finite() && r.y.is_finite());
        // a star off the image corner: too few pixels
        let r = fit_star(&pd, &e, -2.5, -2.5, 1000.0, 300.0, &opt);
        assert!(r.flags & (flags::FEW_PIXELS | flags::EDGE) != 0);
        assert!(r.x.is_finite());
        // everything masked
        let allbad = vec![true; nx * ny];
        let pd = PixelData {
            nx,
            ny,
            e: &img,
            bad: &allbad,
            var_floor_e2: 225.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
        };
        let r = fit_star(&pd, &e, 10.0, 10.0, 1000.0, 300.0, &opt);
        assert!(r.flags & flags::FEW_PIXELS != 0 && !r.usable());
    }
}
