//! What the undetected stars' light does to a fitted position: the shift it causes in the fit the pipeline
//! runs, predicted star by star from the truth (the scoring step's knowledge, which is why this lives here).
//!
//! A star fitted alone by weighted least squares (weights `W = D⁻¹`, `D = diag(σᵢ²)` the fit's noise model,
//! SPEC §7) over its pixels (centres within the fit radius), with Jacobian J of (x, y, f[, s]), answers an
//! extra signal r in its pixels by the linear shift `δ = (JᵀWJ)⁻¹ JᵀW r` (first order in r; the Gauss–Newton
//! step from the truth). Here `rᵢ = Σₖ fₖ ψ(pᵢ − uₖ) − b̄`: the light of the array's truth stars that no fit
//! matched, through the ePSF ψ, less its mean per pixel `b̄` (which the sky estimate absorbs). Over a bin of
//! stars the rms of δ is the error the undetected stars explain; with the photon bound σ the accuracy
//! should be `√(σ² + ⟨δ²⟩)` if nothing else adds. The same with only the undetected stars fainter than
//! the reference catalogue's limit: what would remain if the catalogue's stars were fitted too.

use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::fit::pixel_variance;
use crate::numerics::linalg;
use crate::numerics::neighbours::Neighbours;

/// One array's undetected stars and the fit's noise model.
pub struct Undetected {
    pub epsf: Epsf,
    /// RN² + g²/12, e⁻².
    pub var_floor_e2: f64,
    pub flat_sigma: f64,
    pub radius_px: f64,
    pub fit_sky: bool,
    /// Stars at least this faint (Hw) count in the `faint` shift too.
    pub faint_from_hw: f64,
    /// (x px, y px, flux e⁻, Hw) of the undetected stars.
    stars: Vec<(f64, f64, f64, f64)>,
    index: Neighbours,
    /// Their mean light per pixel, and that of those at least `faint_from_hw` faint, e⁻.
    mean_e: f64,
    mean_faint_e: f64,
}

/// The shifts (px) a star's fit takes from the undetected stars' light: all of them, and those fainter than
/// the reference catalogue's limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shift {
    pub all_px: (f64, f64),
    pub faint_px: (f64, f64),
}

impl Undetected {
    /// `stars`: (x px, y px, flux e⁻, Hw) of the undetected stars on an array of `area_px2`.
    pub fn new(
        epsf: Epsf,
        stars: Vec<(f64, f64, f64, f64)>,
        area_px2: f64,
        var_floor_e2: f64,
        flat_sigma: f64,
        radius_px: f64,
        fit_sky: bool,
        faint_from_hw: f64,
    ) -> Self {
        let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.0, s.1)).collect();
        let mean = |faint_only: bool| {
            if area_px2 > 0.0 {
                stars
                    .iter()
                    .filter(|s| !faint_only || s.3 >= faint_from_hw)
                    .map(|s| s.2)
                    .sum::<f64>()
                    / area_px2
            } else {
                0.0
            }
        };
        let (mean_e, mean_faint_e) = (mean(false), mean(true));
        Self {
            epsf,
            var_floor_e2,
            flat_sigma,
            radius_px,
            fit_sky,
            faint_from_hw,
            index: Neighbours::new(&pos),
            stars,
            mean_e,
            mean_faint_e,
        }
    }

    /// The shift of a star of flux `flux_e` on sky `sky_e` fitted at (x, y) px; `None` when its Fisher
    /// matrix is singular (no pixels, zero flux).
    pub fn star(&self, x: f64, y: f64, flux_e: f64, sky_e: f64) -> Option<Shift> {
        let r = self.radius_px.ceil() as i64 + 1;
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        let mut pix: Vec<(f64, f64)> = Vec::new();
        for py in cy - r..=cy + r {
            for px in cx - r..=cx + r {
                let (px, py) = (px as f64, py as f64);
                if (px - x).powi(2) + (py - y).powi(2) <= self.radius_px.powi(2) {
                    pix.push((px, py));
                }
            }
        }
        let near = self
            .index
            .within(x, y, self.radius_px + self.epsf.half_px() + 1.5);
        let np = if self.fit_sky { 4 } else { 3 };
        let mut m = vec![0.0; np * np];
        let (mut g_all, mut g_faint) = (vec![0.0; np], vec![0.0; np]);
        for &(px, py) in &pix {
            let (psi, gx, gy) = self.epsf.eval(px - x, py - y);
            let star = flux_e * psi;
            let w = 1.0 / pixel_variance(star + sky_e, star, self.var_floor_e2, self.flat_sigma);
            let j = [-flux_e * gx, -flux_e * gy, psi, 1.0];
            // each less the mean light the sky absorbs
            let (mut r_all, mut r_faint) = (-self.mean_e, -self.mean_faint_e);
            for &k in &near {
                let (u, v, f, hw) = self.stars[k];
                let light = f * self.epsf.value(px - u, py - v);
                r_all += light;
                if hw >= self.faint_from_hw {
                    r_faint += light;
                }
            }
            for a in 0..np {
                for b in 0..np {
                    m[a * np + b] += w * j[a] * j[b];
                }
                g_all[a] += w * j[a] * r_all;
                g_faint[a] += w * j[a] * r_faint;
            }
        }
        let inv = linalg::inverse(&m, np)?;
        let shift = |g: &[f64]| {
            let d = |p: usize| (0..np).map(|q| inv[p * np + q] * g[q]).sum::<f64>();
            (d(0), d(1))
        };
        Some(Shift {
            all_px: shift(&g_all),
            faint_px: shift(&g_faint),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::epsf::fit::{FitOptions, PixelData, fit_star};

    /// A pixel-integrated Gaussian ePSF of width σ (px): the product of two erf differences.
    fn gaussian_epsf(sigma: f64) -> Epsf {
        let cdf =
            |t: f64| 0.5 * (1.0 + crate::testkit::erf(t / (sigma * std::f64::consts::SQRT_2)));
        let pix = |d: f64| cdf(d + 0.5) - cdf(d - 0.5);
        Epsf::from_fn(4, 8, |dx, dy| pix(dx) * pix(dy))
    }

    /// The linear shift against the fitter itself: a star with one faint undetected neighbour, noise-free,
    /// fitted by the pipeline's own fit (white weights, sky held at the truth). The fit moves as predicted to
    /// second order in the neighbour's light (2 % of the star at 2 px: within 4 %, and the direction);
    /// a neighbour brighter than the faint limit moves only the `all` shift.
    #[test]
    fn the_predicted_shift_is_the_fits() {
        let e = gaussian_epsf(1.0);
        let (nx, ny) = (41usize, 41usize);
        let (x0, y0, flux, sky, floor) = (20.3, 20.6, 1e5, 50.0, 100.0);
        let (u, v, f) = (22.1, 19.7, 2e3);
        let mut img = vec![sky; nx * ny];
        for iy in 0..ny {
            for ix in 0..nx {
                let (p, q) = (ix as f64, iy as f64);
                img[iy * nx + ix] += flux * e.value(p - x0, q - y0) + f * e.value(p - u, q - v);
            }
        }
        let bad = vec![false; nx * ny];
        let data = PixelData {
            nx,
            ny,
            e: &img,
            bad: &bad,
            var_floor_e2: floor,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
        };
        let opt = FitOptions {
            radius_px: 2.5,
            max_iter: 30,
            fit_sky: false,
        };
        let fit = fit_star(&data, &e, x0, y0, flux, sky, &opt);
        let (dx, dy) = (fit.x - x0, fit.y - y0);
        // no mean to remove (an area so large the mean light is nil); the neighbour is Hw 16 against a limit
        // of 16.5: in `all`, not in `faint`
        let shift_of = |stars: Vec<(f64, f64, f64, f64)>| {
            Undetected::new(e.clone(), stars, 1e300, floor, 0.0, 2.5, false, 16.5)
                .star(x0, y0, flux, sky)
                .expect("shift")
        };
        let s = shift_of(vec![(u, v, f, 16.0)]);
        assert!(
            dx > 1e-3 && dy < -1e-4,
            "the fit moves towards the neighbour: {dx} {dy}"
        );
        assert!(
            (s.all_px.0 / dx - 1.0).abs() < 0.04,
            "{:?} vs ({dx}, {dy})",
            s.all_px
        );
        assert!(
            (s.all_px.1 / dy - 1.0).abs() < 0.04,
            "{:?} vs ({dx}, {dy})",
            s.all_px
        );
        assert!(
            s.faint_px.0.abs() < 1e-12 && s.faint_px.1.abs() < 1e-12,
            "{s:?}"
        );
        // as faint as the limit: both
        let t = shift_of(vec![(u, v, f, 16.5)]);
        assert_eq!(t.all_px, t.faint_px);
        // nothing undetected: no shift
        assert_eq!(shift_of(vec![]).all_px, (0.0, 0.0));
    }
}
