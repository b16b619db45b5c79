//! How a profile (ePSF) fit responds to the jitter a star saw: the displacement model behind the
//! telemetry correction and the instant predictor.
//!
//! A star's image is `D(X) = Σ_t w_t K(X − x − d_t) / Σ w_t` over its window's jitter samples d_t. It is fitted
//! with the image-average ePSF `ψ̄(Δ) = Σ_t w̄_t K(Δ − d_t) / Σ w̄_t` (the nominal window). One Gauss–Newton step
//! of that fit (per axis; the cross terms vanish by symmetry) gives the position shift
//!
//! `s = Σᵢ wᵢ gᵢ (Dᵢ − ψ̄ᵢ) / Σᵢ wᵢ gᵢ²  =  ⟨R⟩_window − ⟨R⟩_nominal`,  `R(u) = Σᵢ wᵢ gᵢ K(Xᵢ − x − u) / Σᵢ wᵢ gᵢ²`
//!
//! with `gᵢ = −∂ψ̄/∂X` at pixel i and `wᵢ = 1/(f ψ̄ᵢ + sky + RN² + g²/12)` over the fit disc, averaged over
//! sub-pixel phases. Near the core R(u) ≈ u; for excursions beyond the core it flattens, because a profile fit
//! weighs the core: this is why the measured positions follow the *mean* jitter of a star's window with a
//! regression slope that differs from 1, and why this response — not the mean — predicts them.

use crate::analysis::epsf::fit::flags;
use crate::analysis::report::StarResult;
use crate::integrate::cpu::{Histogram, StarSpec};
use crate::integrate::kernel::PixelKernel;
use crate::integrate::track::{Track, WindowWeights};
use crate::numerics::stats;
use crate::readout::ReadoutTiming;

/// R_x and R_y tabulated on a grid of jitter offsets u (px).
#[derive(Debug, Clone, PartialEq)]
pub struct FitResponse {
    pub step_px: f64,
    pub u0: f64,
    pub v0: f64,
    pub nu: usize,
    pub nv: usize,
    pub rx: Vec<f64>,
    pub ry: Vec<f64>,
}

/// Noise parameters of the fit (electrons).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitNoise {
    pub flux_e: f64,
    pub sky_e: f64,
    pub floor_e2: f64,
    pub radius_px: f64,
}

impl FitNoise {
    /// Noise parameters of a typical star's fit measured on an image: the median fitted flux and sky of its
    /// stars that a fit did not reject, the image's read/quantisation floor `floor_e2`, and the analysis'
    /// fit radius (px). Without such a star: 10⁴ e⁻ on no sky.
    pub fn of_stars(stars: &[StarResult], floor_e2: f64, radius_px: f64) -> Self {
        let good: Vec<&StarResult> = stars
            .iter()
            .filter(|s| s.flags & flags::REJECT == 0 && s.flux_e.is_finite() && s.flux_e > 0.0)
            .collect();
        let med = |v: Vec<f64>, default: f64| {
            if v.is_empty() {
                default
            } else {
                stats::median(&v)
            }
        };
        FitNoise {
            flux_e: med(good.iter().map(|s| s.flux_e).collect(), 1e4),
            sky_e: med(good.iter().map(|s| s.sky_e.max(0.0)).collect(), 0.0),
            floor_e2,
            radius_px,
        }
    }
}

impl FitResponse {
    /// Build R for a kernel, a track and the nominal (image-average) window.
    pub fn build(
        kernel: &PixelKernel,
        track: &Track,
        nominal: &WindowWeights,
        noise: &FitNoise,
    ) -> Self {
        // ψ̄ through the exact histogram ⊛ K machinery: deposit the nominal window at offset 0
        let g = kernel.nodes_per_px;
        let margin = (noise.radius_px.ceil() as i64) + 8;
        let origin = (-margin, -margin);
        let star = StarSpec {
            x_px: 0.0,
            y_px: 0.0,
            rate_e_per_s: 1.0,
        };
        let hist = Histogram::deposit(&star, track, nominal, origin, g);
        let total = nominal.total().max(1e-300);
        let psi_bar = |dx: f64, dy: f64| -> f64 {
            // ψ̄(Δ) = Σ_u H(u) K(Δ − u)/W, Δ relative to the star; off-node Δ by bilinear K
            match &hist {
                Some(h) => {
                    let mut s = 0.0;
                    for r in 0..h.nv {
                        for c in 0..h.nu {
                            let w = h.data[r * h.nu + c];
                            if w != 0.0 {
                                let ux = (h.u0 + c as i64) as f64 / g as f64 + origin.0 as f64;
                                let uy = (h.v0 + r as i64) as f64 / g as f64 + origin.1 as f64;
                                s += w * kernel.eval(dx - ux, dy - uy);
                            }
                        }
                    }
                    s / total
                }
                None => kernel.eval(dx, dy),
            }
        };
        // pixels of the fit disc for a grid of phases: weights and gradients of ψ̄
        let phases: Vec<(f64, f64)> = (0..3)
            .flat_map(|j| {
                (0..3).map(move |i| (-1.0 / 3.0 + i as f64 / 3.0, -1.0 / 3.0 + j as f64 / 3.0))
            })
            .collect();
        let r = noise.radius_px;
        let ri = r.ceil() as i64 + 1;
        let h = 1e-3;
        struct Pix {
            x: f64,
            y: f64,
            wgx: f64,
            wgy: f64,
        }
        let mut per_phase: Vec<(Vec<Pix>, f64, f64)> = Vec::new();
        for &(px, py) in &phases {
            let mut pix = Vec::new();
            let (mut nx, mut ny) = (0.0, 0.0);
            for yy in -ri..=ri {
                for xx in -ri..=ri {
                    let (dx, dy) = (xx as f64 - px, yy as f64 - py);
                    if dx * dx + dy * dy > r * r {
                        continue;
                    }
                    let v = psi_bar(dx, dy);
                    let gx = -(psi_bar(dx + h, dy) - psi_bar(dx - h, dy)) / (2.0 * h);
                    let gy = -(psi_bar(dx, dy + h) - psi_bar(dx, dy - h)) / (2.0 * h);
                    let w = 1.0 / (noise.flux_e * v + noise.sky_e + noise.floor_e2).max(1e-9);
                    nx += w * gx * gx;
                    ny += w * gy * gy;
                    pix.push(Pix {
                        x: dx,
                        y: dy,
                        wgx: w * gx,
                        wgy: w * gy,
                    });
                }
            }
            per_phase.push((pix, nx.max(1e-300), ny.max(1e-300)));
        }
        // grid of jitter offsets covering the track
        let (a, b, c, d) = track.extent();
        let step = 1.0 / 8.0;
        let u0 = (a / step).floor() * step - step;
        let v0 = (c / step).floor() * step - step;
        let nu = (((b - u0) / step).ceil() as usize + 2).min(4096);
        let nv = (((d - v0) / step).ceil() as usize + 2).min(4096);
        let mut rx = vec![0.0; nu * nv];
        let mut ry = vec![0.0; nu * nv];
        for j in 0..nv {
            for i in 0..nu {
                let (ux, uy) = (u0 + i as f64 * step, v0 + j as f64 * step);
                let (mut sx, mut sy) = (0.0, 0.0);
                for (pix, nx, ny) in &per_phase {
                    let (mut ax, mut ay) = (0.0, 0.0);
                    for p in pix {
                        let k = kernel.eval(p.x - ux, p.y - uy);
                        ax += p.wgx * k;
                        ay += p.wgy * k;
                    }
                    sx += ax / nx;
                    sy += ay / ny;
                }
                rx[j * nu + i] = sx / per_phase.len() as f64;
                ry[j * nu + i] = sy / per_phase.len() as f64;
            }
        }
        Self {
            step_px: step,
            u0,
            v0,
            nu,
            nv,
            rx,
            ry,
        }
    }

    /// (R_x, R_y) at a jitter offset, bilinear.
    pub fn at(&self, ux: f64, uy: f64) -> (f64, f64) {
        let fu = ((ux - self.u0) / self.step_px).clamp(0.0, (self.nu - 1) as f64 - 1e-9);
        let fv = ((uy - self.v0) / self.step_px).clamp(0.0, (self.nv - 1) as f64 - 1e-9);
        let (i, j) = (fu.floor() as usize, fv.floor() as usize);
        let (tu, tv) = (fu - i as f64, fv - j as f64);
        let i1 = (i + 1).min(self.nu - 1);
        let j1 = (j + 1).min(self.nv - 1);
        let lerp = |t: &[f64]| {
            (1.0 - tv) * ((1.0 - tu) * t[j * self.nu + i] + tu * t[j * self.nu + i1])
                + tv * ((1.0 - tu) * t[j1 * self.nu + i] + tu * t[j1 * self.nu + i1])
        };
        (lerp(&self.rx), lerp(&self.ry))
    }

    /// Predicted fit displacement (px) of stars at `positions`, each from its central pixel's window:
    /// ⟨R⟩ over the window (prefix sums make each star O(1)); the constant ⟨R⟩_nominal is not subtracted
    /// (accuracy statistics remove the mean).
    pub fn displacements(
        &self,
        track: &Track,
        timing: &ReadoutTiming,
        positions: &[(f64, f64)],
    ) -> Vec<(f64, f64)> {
        let n = track.len();
        let mut cx = vec![0.0; n + 1];
        let mut cy = vec![0.0; n + 1];
        let vals: Vec<(f64, f64)> = (0..n)
            .map(|t| self.at(track.dx_px[t], track.dy_px[t]))
            .collect();
        for t in 0..n {
            cx[t + 1] = cx[t] + vals[t].0;
            cy[t + 1] = cy[t] + vals[t].1;
        }
        let rows = timing.rows as f64;
        positions
            .iter()
            .map(|&(x, y)| {
                let (a, b) = timing.window_s(
                    x.round().clamp(0.0, rows - 1.0) as usize,
                    y.round().clamp(0.0, rows - 1.0) as usize,
                );
                let w = track.window(a, b);
                let (mut sx, mut sy) = (0.0, 0.0);
                if w.last > w.first + 1 {
                    sx += cx[w.last] - cx[w.first + 1];
                    sy += cy[w.last] - cy[w.first + 1];
                }
                sx += w.w_first * vals[w.first].0;
                sy += w.w_first * vals[w.first].1;
                if w.last != w.first {
                    sx += w.w_last * vals[w.last].0;
                    sy += w.w_last * vals[w.last].1;
                }
                let tot = w.total().max(1e-300);
                (sx / tot, sy / tot)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::kernel::IntraPixelMap;
    use crate::optics::psf::PsfTable;

    #[test]
    fn response_is_linear_near_the_core_and_flattens_outside() {
        let (os, half) = (8usize, 6usize);
        let n = 2 * half * os + 1;
        let mut data = vec![0.0; n * n];
        for iy in 0..n {
            for ix in 0..n {
                let (x, y) = (
                    (ix as f64 - (half * os) as f64) / os as f64,
                    (iy as f64 - (half * os) as f64) / os as f64,
                );
                data[iy * n + ix] = (-(x * x + y * y) / (2.0 * 0.7f64.powi(2))).exp();
            }
        }
        let s: f64 = data.iter().sum();
        data.iter_mut().for_each(|v| *v /= s);
        let psf = PsfTable {
            oversampling: os,
            half_cells: half * os,
            data,
        };
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(4)).expect("kernel");
        let track = Track::new(1.0, 0.0, vec![-2.5, 0.0, 2.5], vec![0.0, 0.0, 0.0]);
        // nominal: the still middle sample only
        let nominal = WindowWeights {
            first: 1,
            last: 1,
            w_first: 1.0,
            w_last: 1.0,
        };
        let r = FitResponse::build(
            &k,
            &track,
            &nominal,
            &FitNoise {
                flux_e: 7e4,
                sky_e: 300.0,
                floor_e2: 226.0,
                radius_px: 2.5,
            },
        );
        let (r0, _) = r.at(0.0, 0.0);
        let (r1, _) = r.at(0.1, 0.0);
        let (r2, _) = r.at(2.4, 0.0);
        assert!(r0.abs() < 1e-3, "{r0}");
        assert!(
            ((r1 - r0) / 0.1 - 1.0).abs() < 0.03,
            "slope at the core {}",
            (r1 - r0) / 0.1
        );
        assert!(r2 < 1.5, "far excursions are down-weighted: R(2.4) = {r2}");
    }
}
