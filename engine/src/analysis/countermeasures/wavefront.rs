//! The design model PSF corrected by the image's own stars (`analysis.telemetry_kernel = "design-fitted"`): the
//! instrument as built departs from its design by a low-order wavefront the design does not know, and the
//! stars show it. The static profile is modelled as the design PSF plus its first-order change with each
//! low-order Fringe term,
//!
//! `ψ(a) = ψ₀ + Σ_j a_j D_j`,  `D_j = ∂ψ/∂a_j` (per nm rms of term j, at the design),
//!
//! where ψ₀ and the D_j are products of the design (`psf_model.fits` and its `DZ4` … `DZ11` planes). Each star is
//! seen through the jitter the telemetry records over its own pixels' windows ([`super::forward`]: linear in
//! ψ, so a star's model is `s + f (F_s ψ₀ + Σ a_j F_s D_j)`), and the coefficients a are fitted jointly with every
//! star's position and flux by Gauss–Newton on the pixels within the fit radius, each star's (x, y, f)
//! eliminated by its Schur complement (`M = Σ_s A_aa − A_an A_nn⁻¹ A_na`), weights the inverse of the model's
//! variance (Poisson + read noise + the flat's error). The formal error of a_j is `√(M⁻¹)_jj`. Low-order terms
//! change a star's shape over its whole core, so a few hundred stars fix them far better than an ePSF grid of
//! free nodes could (the rebuild's own floor, its binning and smoothing on a 4-node grid, is larger than the
//! difference a 50-nm deviation makes: docs/instrument-products.md).

use super::Telemetry;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::fit::{FitOptions, Profile, fit_star, flags, pixel_variance};
use crate::analysis::image::AnalysisImage;
use crate::analysis::report::StarResult;
use rayon::prelude::*;

/// Gauss–Newton steps of the joint fit (the model is linear in a; the steps settle the stars' positions).
pub const ITERATIONS: usize = 4;

/// The fitted wavefront correction.
#[derive(Debug, Clone, PartialEq)]
pub struct WavefrontFit {
    /// Each term's fitted coefficient, nm rms (in the order of the derivative planes: Z4 … Z11).
    pub coefficients_nm: Vec<f64>,
    /// Their formal 1σ errors, nm rms.
    pub sigma_nm: Vec<f64>,
    /// Stars the fit used.
    pub stars: usize,
    /// The corrected static profile ψ(a).
    pub profile: Epsf,
}

impl WavefrontFit {
    /// One line for a report: `design PSF + Z4…Z11 fitted from N stars: Z4 +3.1 ± 0.8, … nm rms`.
    pub fn describe(&self) -> String {
        let terms: Vec<String> = crate::optics::zernike::LOW_ORDER_TERMS
            .iter()
            .map(|j| format!("Z{j}"))
            .zip(self.coefficients_nm.iter().zip(&self.sigma_nm))
            .map(|(n, (a, s))| format!("{n} {a:+.1} ± {s:.1}"))
            .collect();
        format!(
            "design PSF corrected by {} stars: {} nm rms",
            self.stars,
            terms.join(", ")
        )
    }
}

/// ψ₀ + Σ a_j D_j on ψ₀'s grid (the planes share it: they are products of one table).
pub fn corrected(psi0: &Epsf, terms: &[Epsf], a: &[f64]) -> Epsf {
    let mut e = psi0.clone();
    for (t, &aj) in terms.iter().zip(a) {
        if t.data.len() == e.data.len() {
            for (v, d) in e.data.iter_mut().zip(&t.data) {
                *v += aj * d;
            }
        }
    }
    e
}

/// One star's state in the fit: position, flux, sky (held).
#[derive(Debug, Clone, Copy)]
struct StarState {
    x: f64,
    y: f64,
    f: f64,
    s: f64,
}

/// A star's normal-equation blocks: nuisance (x, y, f) × nuisance, × terms, terms × terms, and the right sides.
struct Blocks {
    nn: [f64; 9],
    na: Vec<f64>,
    aa: Vec<f64>,
    bn: [f64; 3],
    ba: Vec<f64>,
}

/// Fit the coefficients of `terms` (the design's derivative planes) that take `psi0` (the design model PSF) to
/// the image's `stars` seen through `tel`'s forward model; `None` with fewer stars than twice the terms or a
/// singular system. The stars are the plain analysis' usable ones (not rejected, blended or saturated).
pub fn fit(
    img: &AnalysisImage,
    stars: &[StarResult],
    psi0: &Epsf,
    terms: &[Epsf],
    tel: &Telemetry,
    opts: &FitOptions,
) -> Option<WavefrontFit> {
    let k = terms.len();
    if k == 0 || terms.iter().any(|t| t.data.len() != psi0.data.len()) {
        return None;
    }
    let pd = img.pixels();
    let reach = super::forward::fit_reach_px(opts);
    let term_forwards: Vec<_> = terms.iter().map(|t| tel.forward(t, img.nx)).collect();
    let mut a = vec![0.0; k];
    // the stars at their forward-model fits with the design PSF
    let fwd0 = tel.forward(psi0, img.nx);
    let mut state: Vec<StarState> = stars
        .par_iter()
        .filter(|s| {
            s.flags & (flags::REJECT | flags::BLENDED | flags::SATURATED) == 0
                && s.flux_e > 0.0
                && s.x.is_finite()
                && s.y.is_finite()
        })
        .filter_map(|s| {
            let p = fwd0.star(s.x, s.y, reach, img.nx, img.ny);
            let f = fit_star(&pd, &p, s.x, s.y, s.flux_e, s.sky_e, opts);
            (f.usable() && f.flux > 0.0).then_some(StarState {
                x: f.x,
                y: f.y,
                f: f.flux,
                s: f.sky,
            })
        })
        .collect();
    if state.len() < 2 * k {
        return None;
    }
    let mut sigma = vec![f64::NAN; k];
    for _ in 0..ITERATIONS {
        let psi = corrected(psi0, terms, &a);
        let fwd = tel.forward(&psi, img.nx);
        let blocks: Vec<Option<Blocks>> = state
            .par_iter()
            .map(|st| {
                let p = fwd.star(st.x, st.y, reach, img.nx, img.ny);
                star_blocks(&pd, &p, &term_forwards, st, opts.radius_px)
            })
            .collect();
        // the terms' normal equations with every star's (x, y, f) eliminated
        let mut m = vec![0.0; k * k];
        let mut rhs = vec![0.0; k];
        let mut kept = Vec::with_capacity(blocks.len());
        for b in blocks.iter() {
            let Some(b) = b else {
                kept.push(None);
                continue;
            };
            let Some(inv) = crate::numerics::linalg::inverse(&b.nn, 3) else {
                kept.push(None);
                continue;
            };
            // A_an A_nn⁻¹ (k × 3)
            let mut an_inv = vec![0.0; k * 3];
            for j in 0..k {
                for c in 0..3 {
                    an_inv[j * 3 + c] = (0..3).map(|r| b.na[r * k + j] * inv[r * 3 + c]).sum();
                }
            }
            for j in 0..k {
                for l in 0..k {
                    let schur: f64 = (0..3).map(|c| an_inv[j * 3 + c] * b.na[c * k + l]).sum();
                    m[j * k + l] += b.aa[j * k + l] - schur;
                }
                rhs[j] += b.ba[j] - (0..3).map(|c| an_inv[j * 3 + c] * b.bn[c]).sum::<f64>();
            }
            kept.push(Some(inv));
        }
        let da = crate::numerics::linalg::solve(&m, &rhs, k)?;
        if let Some(cov) = crate::numerics::linalg::inverse(&m, k) {
            sigma = (0..k).map(|j| cov[j * k + j].max(0.0).sqrt()).collect();
        }
        for (aj, d) in a.iter_mut().zip(&da) {
            *aj += d;
        }
        // each star's (x, y, f) step given the terms' step: A_nn⁻¹ (b_n − A_na Δa)
        for ((st, b), inv) in state.iter_mut().zip(&blocks).zip(&kept) {
            let (Some(b), Some(inv)) = (b, inv) else {
                continue;
            };
            let r: Vec<f64> = (0..3)
                .map(|c| b.bn[c] - (0..k).map(|j| b.na[c * k + j] * da[j]).sum::<f64>())
                .collect();
            let step: Vec<f64> = (0..3)
                .map(|c| (0..3).map(|d| inv[c * 3 + d] * r[d]).sum())
                .collect();
            st.x += step[0].clamp(-0.5, 0.5);
            st.y += step[1].clamp(-0.5, 0.5);
            st.f = (st.f + step[2]).max(1.0);
        }
    }
    Some(WavefrontFit {
        coefficients_nm: a.clone(),
        sigma_nm: sigma,
        stars: state.len(),
        profile: corrected(psi0, terms, &a),
    })
}

/// A star's blocks over the pixels within `radius_px`: the Jacobian of (x, y, f) is `(−f ∂ψ/∂x, −f ∂ψ/∂y, ψ)` of
/// its forward profile, of the terms `f · (F_s D_j)`; `None` without pixels.
fn star_blocks(
    pd: &crate::analysis::epsf::fit::PixelData<'_>,
    p: &super::forward::StarProfile<'_>,
    terms: &[super::forward::Forward<'_>],
    st: &StarState,
    radius_px: f64,
) -> Option<Blocks> {
    let k = terms.len();
    let mut b = Blocks {
        nn: [0.0; 9],
        na: vec![0.0; 3 * k],
        aa: vec![0.0; k * k],
        bn: [0.0; 3],
        ba: vec![0.0; k],
    };
    let r = radius_px.ceil() as i64;
    let (cx, cy) = (st.x.round() as i64, st.y.round() as i64);
    let mut used = 0;
    let mut ja = vec![0.0; k];
    for py in (cy - r).max(0)..=(cy + r).min(pd.ny as i64 - 1) {
        for px in (cx - r).max(0)..=(cx + r).min(pd.nx as i64 - 1) {
            let (fx, fy) = (px as f64, py as f64);
            if (fx - st.x).powi(2) + (fy - st.y).powi(2) > radius_px * radius_px {
                continue;
            }
            let i = py as usize * pd.nx + px as usize;
            if pd.bad[i] {
                continue;
            }
            let (v, gx, gy) = p.eval_at(i, fx, fy, st.x, st.y);
            let mu = st.s + st.f * v;
            let w = 1.0 / pixel_variance(mu, st.f * v, pd.floor_e2(i), pd.flat_sigma);
            let res = pd.e[i] - mu;
            let jn = [-st.f * gx, -st.f * gy, v];
            for (j, t) in terms.iter().enumerate() {
                ja[j] = st.f * p.eval_through(t, i, fx, fy, st.x, st.y).0;
            }
            for c in 0..3 {
                for d in 0..3 {
                    b.nn[c * 3 + d] += w * jn[c] * jn[d];
                }
                for j in 0..k {
                    b.na[c * k + j] += w * jn[c] * ja[j];
                }
                b.bn[c] += w * jn[c] * res;
            }
            for j in 0..k {
                for l in 0..k {
                    b.aa[j * k + l] += w * ja[j] * ja[l];
                }
                b.ba[j] += w * ja[j] * res;
            }
            used += 1;
        }
    }
    (used > 3).then_some(b)
}
