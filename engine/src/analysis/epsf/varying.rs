//! An ePSF that varies across the image, learned from its stars (`analysis.epsf_variation`).
//!
//! ψ(Δ; ξ, η) = ψ₀(Δ) + Σⱼ bⱼ(ξ, η) ψⱼ(Δ), with ξ = (x − cₓ)/hₓ and η = (y − c_y)/h_y the star's position scaled
//! to [−1, 1] across the image and bⱼ ∈ {ξ, η} (`linear`) or {ξ, η, ξ², ξη, η²} (`quadratic`): a lookup table
//! and its change over the frame, DAOPHOT's variable PSF (Stetson 1987, PASP 99, 191, §III.b) on the
//! oversampled grid of Anderson & King (2000). It is built as the constant ePSF is ([`super::build`]), except
//! that each node's residual samples `(P − s)/f − ψ(Δ; ξₖ, ηₖ)` from the stars k are fitted by least squares
//! with the same basis, `r ≈ δ₀ + Σⱼ bⱼ(ξₖ, ηₖ) δⱼ`, clipped once at `clip_sigma` × the MAD of its residuals.
//!
//! Conventions, held at every position: the planes ψⱼ sum to 0 (so Σ nodes of ψ(·; ξ, η) = oversampling²) and
//! have no first moment within [`super::CENTROID_RADIUS_PX`] (so ψ(·; ξ, η)'s centroid is at the origin
//! everywhere): after each step every plane loses its components along ψ₀, ∂ψ₀/∂Δx and ∂ψ₀/∂Δy that would
//! change those moments. A star's position is therefore its local profile's centroid, as with one ePSF; what
//! the varying ePSF removes is the displacement a wrong (mean) profile adds to it. The centroid's own change
//! over the field (a coma gradient moves the light) is no more separable from distortion than with one ePSF:
//! the plate or distortion solution takes it.
//!
//! The position dependence within one star's stamp (≈ 10⁻³ of the field) is neglected: a star is fitted with
//! the table of its starting position ([`VaryingEpsf::at`]).
//!
//! Few stars, or stars that do not spread over the image (an ξ or η spread below [`MIN_SPREAD`]), do not
//! constrain the planes: the build then keeps the constant ePSF and says so.

use super::Epsf;
use super::build::{
    BuildOptions, Built, StarStart, iteration_cap, residual_samples, sample_chi_limit,
};
use super::fit::{PixelData, StarFit, fit_star};
use super::smooth;
use crate::config::EpsfVariation;
use crate::numerics::{linalg, stats};
use rayon::prelude::*;

/// Fewest ePSF stars per basis function (the constant included) for a varying ePSF.
pub const MIN_STARS_PER_TERM: usize = 10;
/// Smallest standard deviation of the ePSF stars' ξ and η (the image spans [−1, 1]; a uniform spread gives
/// 0.58) for a varying ePSF.
pub const MIN_SPREAD: f64 = 0.2;

/// Position-dependent planes of this variation (the constant table not counted).
pub fn n_terms(v: EpsfVariation) -> usize {
    match v {
        EpsfVariation::Constant => 0,
        EpsfVariation::Linear => 2,
        EpsfVariation::Quadratic => 5,
    }
}

/// The basis [1, ξ, η, ξ², ξη, η²].
fn basis6(xi: f64, eta: f64) -> [f64; 6] {
    [1.0, xi, eta, xi * xi, xi * eta, eta * eta]
}

/// A field-varying ePSF: the table at the image centre and its planes of change.
#[derive(Debug, Clone, PartialEq)]
pub struct VaryingEpsf {
    pub base: Epsf,
    /// ψ_ξ, ψ_η (and ψ_ξξ, ψ_ξη, ψ_ηη): [`n_terms`] planes on the base's grid.
    pub terms: Vec<Epsf>,
    /// (cₓ, c_y), pixels.
    pub centre_px: (f64, f64),
    /// (hₓ, h_y), pixels.
    pub half_extent_px: (f64, f64),
}

impl VaryingEpsf {
    /// `base` with zero planes over an image of nx × ny pixels.
    pub fn new(base: Epsf, variation: EpsfVariation, nx: usize, ny: usize) -> Self {
        let zero = Epsf {
            data: vec![0.0; base.data.len()],
            ..base.clone()
        };
        Self {
            terms: vec![zero; n_terms(variation)],
            base,
            centre_px: (0.5 * (nx as f64 - 1.0), 0.5 * (ny as f64 - 1.0)),
            half_extent_px: (0.5 * (nx as f64).max(2.0), 0.5 * (ny as f64).max(2.0)),
        }
    }

    /// bⱼ(ξ, η) at pixel (x, y), the constant first.
    pub fn basis(&self, x: f64, y: f64) -> [f64; 6] {
        basis6(
            (x - self.centre_px.0) / self.half_extent_px.0,
            (y - self.centre_px.1) / self.half_extent_px.1,
        )
    }

    /// The ePSF table at pixel (x, y).
    pub fn at(&self, x: f64, y: f64) -> Epsf {
        let b = self.basis(x, y);
        let mut out = self.base.clone();
        for (t, bj) in self.terms.iter().zip(&b[1..]) {
            for (o, v) in out.data.iter_mut().zip(&t.data) {
                *o += bj * v;
            }
        }
        out
    }
}

/// An ePSF that may depend on where its star is: ψ at the offset (dx, dy) from a star at (x, y), as the
/// crowded fits and model images evaluate it (a constant [`Epsf`] ignores the star's place; a
/// [`VaryingEpsf`] sums its planes at the star's basis without building the star's table). The gradient is
/// the profile's at fixed (x, y): the basis changes by ≈ 1/half-extent per pixel, ≈ 10⁻³ of ψ's own change.
pub trait EpsfField: Sync {
    /// ψ and its gradient in (dx, dy).
    fn eval_for(&self, x: f64, y: f64, dx: f64, dy: f64) -> (f64, f64, f64);
    fn value_for(&self, x: f64, y: f64, dx: f64, dy: f64) -> f64 {
        self.eval_for(x, y, dx, dy).0
    }
    /// The table's half-width (px): beyond it ψ is 0.
    fn reach_px(&self) -> f64;
}

impl EpsfField for Epsf {
    #[inline]
    fn eval_for(&self, _x: f64, _y: f64, dx: f64, dy: f64) -> (f64, f64, f64) {
        self.eval(dx, dy)
    }
    fn reach_px(&self) -> f64 {
        self.half_px()
    }
}

impl EpsfField for VaryingEpsf {
    fn eval_for(&self, x: f64, y: f64, dx: f64, dy: f64) -> (f64, f64, f64) {
        if self.terms.is_empty() {
            return self.base.eval(dx, dy);
        }
        let b = self.basis(x, y);
        let mut w = [(0.0, &self.base); 5];
        for (k, (t, bj)) in self.terms.iter().zip(&b[1..]).enumerate() {
            w[k] = (*bj, t);
        }
        self.base.eval_sum(&w[..self.terms.len()], dx, dy)
    }
    fn reach_px(&self) -> f64 {
        self.base.half_px()
    }
}

/// The result of a varying build.
#[derive(Debug, Clone)]
pub struct BuiltVarying {
    pub epsf: VaryingEpsf,
    pub fits: Vec<StarFit>,
    pub iterations: usize,
    /// Why the planes were not built (the constant ePSF kept), or empty.
    pub kept_constant: String,
}

/// Why these ePSF stars cannot constrain `variation`'s planes, or `None` when they can.
pub fn unconstrained(
    positions: &[(f64, f64)],
    variation: EpsfVariation,
    frame: &VaryingEpsf,
) -> Option<String> {
    let m = 1 + n_terms(variation);
    let b: Vec<[f64; 6]> = positions.iter().map(|&(x, y)| frame.basis(x, y)).collect();
    if b.len() < MIN_STARS_PER_TERM * m {
        return Some(format!(
            "{} ePSF stars, fewer than {} for a {} ePSF ({MIN_STARS_PER_TERM} per table): one ePSF for the image",
            b.len(),
            MIN_STARS_PER_TERM * m,
            variation.name()
        ));
    }
    let spread = |k: usize| stats::std_dev(&b.iter().map(|v| v[k]).collect::<Vec<_>>());
    let (sx, sy) = (spread(1), spread(2));
    (sx < MIN_SPREAD || sy < MIN_SPREAD).then(|| {
        format!(
            "the ePSF stars spread over too little of the image (σ of ξ, η: {sx:.2}, {sy:.2}; at least \
             {MIN_SPREAD}) for a {} ePSF: one ePSF for the image",
            variation.name()
        )
    })
}

/// Least squares of one node's samples on the basis, clipped once: the coefficients (δ₀, δ₁, …), or `None`
/// where the samples do not determine them (the caller keeps a clipped mean).
fn node_fit(samples: &[(f64, [f64; 6])], m: usize, clip_sigma: f64) -> Option<Vec<f64>> {
    let solve = |keep: &dyn Fn(usize) -> bool| -> Option<Vec<f64>> {
        let (mut a, mut rhs, mut n) = (vec![0.0; m * m], vec![0.0; m], 0usize);
        for (k, (r, b)) in samples.iter().enumerate() {
            if !keep(k) {
                continue;
            }
            n += 1;
            for i in 0..m {
                rhs[i] += b[i] * r;
                for j in 0..m {
                    a[i * m + j] += b[i] * b[j];
                }
            }
        }
        (n > 2 * m).then_some(())?;
        linalg::solve(&a, &rhs, m).filter(|c| c.iter().all(|v| v.is_finite()))
    };
    let first = solve(&|_| true)?;
    let res: Vec<f64> = samples
        .iter()
        .map(|(r, b)| r - (0..m).map(|i| first[i] * b[i]).sum::<f64>())
        .collect();
    let sigma = stats::mad_sigma(&res);
    if !(sigma > 0.0) {
        return Some(first);
    }
    solve(&|k| res[k].abs() <= clip_sigma * sigma).or(Some(first))
}

/// The sum over all nodes (the normalisation), and the first moments within the centroid radius (the centring
/// convention: [`Epsf::central_moments`]), of a table.
fn moments(e: &Epsf) -> [f64; 3] {
    let (_, sx, sy) = e.central_moments();
    [e.data.iter().sum(), sx, sy]
}

/// Remove from each plane its components along ψ₀, ∂ψ₀/∂Δx, ∂ψ₀/∂Δy that give it a sum or a first moment (the
/// conventions of the module doc).
fn project_terms(base: &Epsf, terms: &mut [Epsf]) {
    let n = base.n();
    let mut gx = base.clone();
    let mut gy = base.clone();
    for iy in 0..n {
        for ix in 0..n {
            let (_, dx, dy) = base.eval(base.node_px(ix), base.node_px(iy));
            gx.data[iy * n + ix] = dx;
            gy.data[iy * n + ix] = dy;
        }
    }
    let cols = [moments(base), moments(&gx), moments(&gy)];
    // a[row = moment][col = plane]
    let a: Vec<f64> = (0..3)
        .flat_map(|r| (0..3).map(move |c| (r, c)))
        .map(|(r, c)| cols[c][r])
        .collect();
    for t in terms.iter_mut() {
        let Some(c) = linalg::solve(&a, &moments(t), 3) else {
            continue;
        };
        for (i, v) in t.data.iter_mut().enumerate() {
            *v -= c[0] * base.data[i] + c[1] * gx.data[i] + c[2] * gy.data[i];
        }
    }
}

/// One step of the varying builder: each node's planes move by the fit of its samples (`per_star`: each star's
/// basis and (node, residual) samples), then every plane is smoothed, the base re-centred and normalised and
/// the planes projected. Returns the new ePSF and the largest change of the base.
pub fn update(
    psi: &VaryingEpsf,
    per_star: Vec<([f64; 6], Vec<(usize, f64)>)>,
    opts: &BuildOptions,
) -> (VaryingEpsf, f64) {
    let m = 1 + psi.terms.len();
    let nodes = psi.base.data.len();
    let mut buckets: Vec<Vec<(f64, [f64; 6])>> = vec![Vec::new(); nodes];
    for (b, v) in per_star {
        for (node, r) in v {
            buckets[node].push((r, b));
        }
    }
    let delta: Vec<Vec<f64>> = buckets
        .par_iter()
        .map(|s| {
            if s.is_empty() {
                return vec![0.0; m];
            }
            node_fit(s, m, opts.clip_sigma).unwrap_or_else(|| {
                let r: Vec<f64> = s.iter().map(|(r, _)| *r).collect();
                let mut d = vec![0.0; m];
                d[0] = stats::clipped_mean(&r, opts.clip_sigma).0;
                d
            })
        })
        .collect();
    let max_delta = delta.iter().fold(0.0f64, |a, d| a.max(d[0].abs()));
    let mut next = psi.clone();
    for (i, d) in delta.iter().enumerate() {
        next.base.data[i] += d[0];
        for (t, dj) in next.terms.iter_mut().zip(&d[1..]) {
            t.data[i] += dj;
        }
    }
    next.base = smooth::smooth(&next.base, opts.smoothing);
    if opts.recentre {
        next.base = next.base.recentred();
    }
    next.base.normalise();
    for t in next.terms.iter_mut() {
        *t = smooth::smooth(t, opts.smoothing);
    }
    project_terms(&next.base, &mut next.terms);
    (next, max_delta)
}

/// Build a varying ePSF from the constant build `constant` (the plain build's): `opts.iterations` steps (0:
/// until the base's largest correction is below 1e-4 of its peak, at most [`super::build::MAX_BUILD_ITERATIONS`]), each star refitted from its
/// start with its own position's table; then every star fitted with it. Few or bunched ePSF stars keep the
/// constant ePSF and its fits ([`unconstrained`]).
pub fn build(
    img: &PixelData<'_>,
    starts: &[StarStart],
    use_for_build: &[bool],
    opts: &BuildOptions,
    variation: EpsfVariation,
    constant: &Built,
) -> BuiltVarying {
    let mut psi = VaryingEpsf::new(constant.epsf.clone(), variation, img.nx, img.ny);
    let fit_all = |psi: &VaryingEpsf| -> Vec<StarFit> {
        starts
            .par_iter()
            .map(|s| fit_star(img, &psi.at(s.x, s.y), s.x, s.y, s.flux, s.sky, &opts.fit))
            .collect()
    };
    let positions: Vec<(f64, f64)> = starts
        .iter()
        .zip(use_for_build)
        .filter(|(_, u)| **u)
        .map(|(s, _)| (s.x, s.y))
        .collect();
    if let Some(why) = unconstrained(&positions, variation, &psi) {
        psi.terms.clear();
        return BuiltVarying {
            fits: constant.fits.clone(),
            epsf: psi,
            iterations: 0,
            kept_constant: why,
        };
    }
    let mut done = 0;
    for _ in 0..iteration_cap(opts) {
        done += 1;
        let fitted: Vec<Option<(StarFit, Epsf)>> = starts
            .par_iter()
            .zip(use_for_build)
            .map(|(s, u)| {
                u.then(|| {
                    let local = psi.at(s.x, s.y);
                    (
                        fit_star(img, &local, s.x, s.y, s.flux, s.sky, &opts.fit),
                        local,
                    )
                })
            })
            .collect();
        let chi: Vec<f64> = fitted
            .iter()
            .flatten()
            .filter(|(f, _)| f.usable())
            .map(|(f, _)| f.chi2_red)
            .collect();
        let chi_limit = sample_chi_limit(&chi);
        let per_star: Vec<([f64; 6], Vec<(usize, f64)>)> = fitted
            .par_iter()
            .flatten()
            .filter(|(f, _)| f.usable() && f.flux > 0.0 && f.chi2_red <= chi_limit)
            .map(|(f, local)| {
                (
                    psi.basis(f.x, f.y),
                    residual_samples(img, local, local, f.x, f.y, f.flux, f.sky),
                )
            })
            .collect();
        let peak = psi
            .base
            .data
            .iter()
            .cloned()
            .fold(0.0, f64::max)
            .max(1e-300);
        let (next, max_delta) = update(&psi, per_star, opts);
        psi = next;
        if opts.iterations == 0 && max_delta < 1e-4 * peak {
            break;
        }
    }
    BuiltVarying {
        fits: fit_all(&psi),
        epsf: psi,
        iterations: done,
        kept_constant: String::new(),
    }
}

/// A profile whose ePSF changes linearly across the image, for the tests of the varying builders.
#[cfg(test)]
pub(crate) mod mixed_profile {
    /// A star's light in the pixel at offset (u, v) from its true position: the mix (1 − w) A + w B of two
    /// profiles, each two Gaussians of width σ and weights 1 − q and q, 1 px apart along x and placed so that
    /// the continuous centroid is the true position (pixel-integrated by 8 × 8 sub-samples). A: q = 0.1,
    /// σ = 0.8 px; B: q = 0.5, σ = 1.0 px. The mix w changes linearly across the field, so the true ePSF is
    /// linear in the position: a fit with one mean profile is displaced by an amount that changes with the
    /// star, and the linear ePSF can hold the profile exactly.
    pub(crate) fn light(u: f64, v: f64, w: f64) -> f64 {
        let pair = |q: f64, sigma: f64| {
            let s2 = 2.0 * sigma * sigma;
            let m = 8;
            let mut acc = 0.0;
            for j in 0..m {
                for i in 0..m {
                    let a = u + (i as f64 + 0.5) / m as f64 - 0.5;
                    let b = v + (j as f64 + 0.5) / m as f64 - 0.5;
                    acc += (1.0 - q) * (-((a + q).powi(2) + b * b) / s2).exp()
                        + q * (-((a - (1.0 - q)).powi(2) + b * b) / s2).exp();
                }
            }
            acc / (m * m) as f64 / (std::f64::consts::PI * s2)
        };
        (1.0 - w) * pair(0.1, 0.8) + w * pair(0.5, 1.0)
    }

    /// The mix at pixel (x, y) of an n × n image: linear in x and y.
    pub(crate) fn params(x: f64, y: f64, n: usize) -> f64 {
        let h = n as f64 / 2.0;
        0.5 + 0.3 * (x - h) / h + 0.15 * (y - h) / h
    }
}

#[cfg(test)]
mod tests {
    use super::mixed_profile::{light, params};
    use super::*;
    use crate::analysis::epsf::build::{self as constant_build, build_options};
    use crate::config::Analysis;

    struct Field {
        n: usize,
        img: Vec<f64>,
        bad: Vec<bool>,
        truth: Vec<(f64, f64)>,
        flux: f64,
        sky: f64,
    }

    /// `k × k` stars on a grid 20 px apart with seeded sub-pixel phases, noise-free.
    fn field(k: usize) -> Field {
        let n = 20 * k;
        let (flux, sky) = (2.0e5, 100.0);
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let truth: Vec<(f64, f64)> = (0..k * k)
            .map(|i| {
                let (gx, gy) = ((i % k) as f64, (i / k) as f64);
                (
                    10.0 + 20.0 * gx + rnd() - 0.5,
                    10.0 + 20.0 * gy + rnd() - 0.5,
                )
            })
            .collect();
        let mut img = vec![sky; n * n];
        for &(x, y) in &truth {
            let w = params(x, y, n);
            for py in (y as i64 - 7).max(0)..=(y as i64 + 7).min(n as i64 - 1) {
                for px in (x as i64 - 7).max(0)..=(x as i64 + 7).min(n as i64 - 1) {
                    img[py as usize * n + px as usize] +=
                        flux * light(px as f64 - x, py as f64 - y, w);
                }
            }
        }
        Field {
            n,
            img,
            bad: vec![false; n * n],
            truth,
            flux,
            sky,
        }
    }

    fn pixels(f: &Field) -> PixelData<'_> {
        PixelData {
            nx: f.n,
            ny: f.n,
            e: &f.img,
            bad: &f.bad,
            var_floor_e2: 25.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
        }
    }

    /// A field's starts and the constant build from `use_for_build` (every star: `None`).
    fn constant_from(
        f: &Field,
        opts: &BuildOptions,
        use_for_build: Option<Vec<bool>>,
    ) -> (Vec<StarStart>, Vec<bool>, constant_build::Built) {
        let s = starts(f);
        let used = use_for_build.unwrap_or_else(|| vec![true; s.len()]);
        let cst = constant_build::build(&pixels(f), &s, &used, opts, None, None);
        (s, used, cst)
    }

    fn starts(f: &Field) -> Vec<StarStart> {
        f.truth
            .iter()
            .map(|&(x, y)| StarStart {
                x: x + 0.07,
                y: y - 0.05,
                flux: f.flux,
                sky: f.sky,
            })
            .collect()
    }

    fn rms(v: &[f64]) -> f64 {
        (v.iter().map(|d| d * d).sum::<f64>() / v.len() as f64).sqrt()
    }

    /// The learned varying ePSF against another method: each star fitted with its own exact ePSF (its true
    /// profile tabulated at its position, re-centred to the same convention). One ePSF is displaced from
    /// those positions by a trend across the field; the linear ePSF follows them.
    #[test]
    fn a_linear_epsf_fits_each_star_as_its_own_exact_epsf_does() {
        let f = field(16);
        let pd = pixels(&f);
        let mut opts = build_options(&Analysis::default());
        opts.iterations = 6;
        let (s, all, cst) = constant_from(&f, &opts, None);
        let var = build(&pd, &s, &all, &opts, EpsfVariation::Linear, &cst);
        assert!(var.kept_constant.is_empty(), "{}", var.kept_constant);
        assert_eq!(var.epsf.terms.len(), 2);
        let exact: Vec<StarFit> = f
            .truth
            .iter()
            .zip(&s)
            .map(|(&(x, y), st)| {
                let w = params(x, y, f.n);
                let mut e = Epsf::from_fn(opts.oversampling, opts.half_px, |u, v| light(u, v, w));
                e.normalise();
                let e = e.recentred();
                fit_star(&pd, &e, st.x, st.y, st.flux, st.sky, &opts.fit)
            })
            .collect();
        let diff = |fits: &[StarFit]| -> (f64, f64) {
            let dx: Vec<f64> = fits.iter().zip(&exact).map(|(a, b)| a.x - b.x).collect();
            let dy: Vec<f64> = fits.iter().zip(&exact).map(|(a, b)| a.y - b.y).collect();
            let (mx, my) = (stats::mean(&dx), stats::mean(&dy));
            (
                rms(&dx.iter().map(|d| d - mx).collect::<Vec<_>>()),
                rms(&dy.iter().map(|d| d - my).collect::<Vec<_>>()),
            )
        };
        let (cx, cy) = diff(&cst.fits);
        let (vx, vy) = diff(&var.fits);
        // one ePSF: the profile's change displaces the stars by a trend (3.8e-3 px rms in x, 2.2e-3 in y)
        assert!(
            cx > 2e-3 && cy > 1e-3,
            "constant ePSF against the exact: {cx:.2e}, {cy:.2e} px"
        );
        // the linear ePSF holds the profile: what is left (3.9e-4, 3.8e-4 px) is the builder's own floor
        assert!(
            vx < 0.2 * cx && vx < 1e-3,
            "linear {vx:.2e} against constant {cx:.2e} px in x"
        );
        assert!(
            vy < 0.3 * cy && vy < 1e-3,
            "linear {vy:.2e} against constant {cy:.2e} px in y"
        );
    }

    /// The conventions hold at every position: each local table sums to oversampling² and has its centroid at
    /// the origin.
    #[test]
    fn every_local_table_is_normalised_and_centred() {
        let f = field(16);
        let opts = build_options(&Analysis::default());
        let (s, all, cst) = constant_from(&f, &opts, None);
        let var = build(&pixels(&f), &s, &all, &opts, EpsfVariation::Quadratic, &cst);
        assert_eq!(var.epsf.terms.len(), 5);
        let n = f.n as f64;
        for (x, y) in [(0.0, 0.0), (n, 0.0), (0.0, n), (n, n), (0.3 * n, 0.8 * n)] {
            let e = var.epsf.at(x, y);
            let sum: f64 = e.data.iter().sum();
            assert!((sum - 16.0).abs() < 1e-9, "Σ = {sum} at ({x}, {y})");
            let (cx, cy) = e.centroid();
            assert!(
                cx.abs() < 1e-9 && cy.abs() < 1e-9,
                "centroid ({cx}, {cy}) at ({x}, {y})"
            );
        }
        // and the planes learned something: the corners' tables differ
        let (a, b) = (var.epsf.at(0.0, 0.0), var.epsf.at(n, n));
        let d = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(d > 1e-3, "corner tables differ by {d:.2e}");
    }

    /// Few stars, or stars bunched in one part of the image, keep one ePSF and say why.
    #[test]
    fn few_or_bunched_stars_keep_one_epsf() {
        let f = field(4); // 16 stars: fewer than 10 per table for three tables
        let opts = build_options(&Analysis::default());
        let (s, all, cst) = constant_from(&f, &opts, None);
        let var = build(&pixels(&f), &s, &all, &opts, EpsfVariation::Linear, &cst);
        assert!(var.epsf.terms.is_empty());
        assert!(
            var.kept_constant.contains("16 ePSF stars, fewer than 30"),
            "{}",
            var.kept_constant
        );
        assert_eq!(var.epsf.base, cst.epsf);
        // 144 stars, but only those of the first four columns build the ePSF: ξ spreads too little (σ 0.19)
        let f = field(12);
        let left: Vec<bool> = f.truth.iter().map(|&(x, _)| x < 80.0).collect();
        let (s, left, cst) = constant_from(&f, &opts, Some(left));
        let var = build(&pixels(&f), &s, &left, &opts, EpsfVariation::Linear, &cst);
        assert!(var.epsf.terms.is_empty());
        assert!(
            var.kept_constant.contains("spread over too little"),
            "{}",
            var.kept_constant
        );
    }
}
