//! The instrument's calibration unknowns of the solution: each array's affine offsets and a global
//! distortion polynomial, both in focal-plane pixels (the mission's plate model: per-detector offset and
//! rotation, a global distortion without affine terms — JASMINE-Mission/jasmine_warpfield).
//!
//! An observation's measured place on the plane came through the **design** model of the focal plane
//! (nominal array positions, the design distortion); what the instrument does differently is
//!
//! ```text
//! Δf = b_k + B_k f/L + Σ_{2 ≤ p+q ≤ n} d_pq (f_x/L)^p (f_y/L)^q      (focal-plane px)
//! ```
//!
//! for a detection at design focal-plane position f (px from the optical axis) on array k, L =
//! [`FOCAL_NORM_PX`]; on the plane it is `M_e Δf`, M_e the exposure's focal-plane-to-plane matrix. With the
//! sources and attitudes held, (b, B, d) is one linear least-squares fit of every residual turned back into
//! focal-plane pixels (x and y apart: they share no parameter).
//!
//! **The gauge.** A shift common to every array, and the similarity part (turn and scale) of their B's
//! mean, is what each exposure's attitude does already: after every fit it is handed to the attitudes
//! (removed here; the next attitude step takes it up), so the arrays' offsets are reported about their
//! mean, and their turns and scales about their mean too.

use super::{ExposureGeometry, Observation};

/// Normalising length of the focal-plane coordinates, px: about the quad focal plane's corner radius.
pub const FOCAL_NORM_PX: f64 = 3000.0;

/// Which calibration unknowns the solution solves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CalibrationModel {
    /// Arrays with affine offsets of their own (0: none; the observations are taken as they are).
    pub arrays: usize,
    /// Order of the global distortion polynomial (0: none, else 2 … [`MAX_DISTORTION_ORDER`]).
    pub distortion_order: usize,
}

/// The highest distortion order solved (the mission's plate model goes to 5).
pub const MAX_DISTORTION_ORDER: usize = 5;

impl CalibrationModel {
    pub const NONE: CalibrationModel = CalibrationModel {
        arrays: 0,
        distortion_order: 0,
    };

    /// Does it solve anything?
    pub fn solves(&self) -> bool {
        self.arrays > 0 || self.distortion_order > 0
    }

    /// The distortion's monomials (p, q), 2 ≤ p + q ≤ order.
    pub fn monomials(&self) -> Vec<(i32, i32)> {
        (2..=self.distortion_order as i32)
            .flat_map(|n| (0..=n).map(move |q| (n - q, q)))
            .collect()
    }

    /// Unknowns per axis: 3 per array (offset and a row of B), one per monomial.
    fn per_axis(&self) -> usize {
        3 * self.arrays + self.monomials().len()
    }

    /// Unknowns in all, less the gauge the attitudes hold (2 shifts, a turn and a scale).
    pub fn unknowns(&self) -> usize {
        let gauge = if self.arrays > 0 { 4 } else { 0 };
        (2 * self.per_axis()).saturating_sub(gauge)
    }
}

/// A solved (or true) calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub model: CalibrationModel,
    /// Per array `[b_x, b_y, B_xx, B_xy, B_yx, B_yy]`: px, and px per L of focal-plane position.
    pub arrays: Vec<[f64; 6]>,
    /// `d_pq` per axis, in the order of [`CalibrationModel::monomials`], px.
    pub distortion: [Vec<f64>; 2],
}

impl Calibration {
    /// Nothing to correct.
    pub fn zero(model: CalibrationModel) -> Self {
        let m = model.monomials().len();
        Self {
            model,
            arrays: vec![[0.0; 6]; model.arrays],
            distortion: [vec![0.0; m], vec![0.0; m]],
        }
    }

    /// Δf at design focal-plane position `f_px` on array `array`, px.
    pub fn correction_px(&self, array: usize, f_px: [f64; 2]) -> [f64; 2] {
        let (u, v) = (f_px[0] / FOCAL_NORM_PX, f_px[1] / FOCAL_NORM_PX);
        let mut d = [0.0; 2];
        if let Some(a) = self.arrays.get(array) {
            d = [a[0] + a[2] * u + a[3] * v, a[1] + a[4] * u + a[5] * v];
        }
        for (m, (p, q)) in self.model.monomials().into_iter().enumerate() {
            let t = u.powi(p) * v.powi(q);
            d[0] += self.distortion[0][m] * t;
            d[1] += self.distortion[1][m] * t;
        }
        d
    }

    /// The same on the plane of exposure `g`, mas.
    pub fn correction_mas(&self, o: &Observation, g: &ExposureGeometry) -> [f64; 2] {
        if !self.model.solves() {
            return [0.0; 2];
        }
        let d = self.correction_px(o.array, o.focal_px);
        let m = &g.to_plane;
        [m[0] * d[0] + m[1] * d[1], m[2] * d[0] + m[3] * d[1]]
    }

    /// The largest change of Δf between two calibrations anywhere within L of the axis, px (a bound: the sum
    /// of the coefficients' changes).
    pub fn moved_px(&self, other: &Calibration) -> f64 {
        let arrays = self
            .arrays
            .iter()
            .zip(&other.arrays)
            .map(|(a, b)| {
                let d: Vec<f64> = (0..6).map(|i| (a[i] - b[i]).abs()).collect();
                (d[0] + d[2] + d[3]).max(d[1] + d[4] + d[5])
            })
            .fold(0.0f64, f64::max);
        let dist = (0..2)
            .map(|ax| {
                self.distortion[ax]
                    .iter()
                    .zip(&other.distortion[ax])
                    .map(|(a, b)| (a - b).abs())
                    .sum::<f64>()
            })
            .fold(0.0f64, f64::max);
        arrays + dist
    }

    /// Hand the gauge to the attitudes: remove the arrays' mean offset and the similarity part (turn and
    /// scale) of their mean B.
    pub fn remove_gauge(&mut self) {
        let n = self.arrays.len();
        if n == 0 {
            return;
        }
        let mean = |i: usize| self.arrays.iter().map(|a| a[i]).sum::<f64>() / n as f64;
        let (bx, by) = (mean(0), mean(1));
        let s = (mean(2) + mean(5)) / 2.0;
        let r = (mean(4) - mean(3)) / 2.0;
        for a in &mut self.arrays {
            a[0] -= bx;
            a[1] -= by;
            a[2] -= s;
            a[5] -= s;
            a[4] -= r;
            a[3] += r;
        }
    }
}

/// The inverse of a 2 × 2 row-major matrix (None when singular).
pub fn inverse2(m: &[f64; 4]) -> Option<[f64; 4]> {
    let det = m[0] * m[3] - m[1] * m[2];
    (det.abs() > 0.0 && det.is_finite()).then(|| [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det])
}

/// The calibration block: with the sources and attitudes held, (b, B, d) from every kept observation's
/// residual `r` (plane, mas, observed minus modelled without calibration) turned back into focal-plane px.
/// `None` when the fit is singular (an array without observations, a distortion the pattern cannot see).
pub fn fit(
    model: CalibrationModel,
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    residuals: &[Option<[f64; 2]>],
    active: &[bool],
) -> Option<Calibration> {
    use rayon::prelude::*;
    let mono = model.monomials();
    let n = model.per_axis();
    let inv: Vec<Option<[f64; 4]>> = exposures.iter().map(|g| inverse2(&g.to_plane)).collect();
    // (normal matrix, right-hand side) per axis; each row touches 3 + monomials entries
    let zero = || {
        (
            vec![0.0; n * n],
            vec![0.0; n],
            vec![0.0; n * n],
            vec![0.0; n],
        )
    };
    let (nx, rx, ny, ry) = obs
        .par_iter()
        .zip(residuals.par_iter())
        .zip(active.par_iter())
        .fold(zero, |mut acc, ((o, r), on)| {
            let (Some(r), Some(m), true) = (r, inv[o.exposure], *on) else {
                return acc;
            };
            let g = &exposures[o.exposure];
            let det = (g.to_plane[0] * g.to_plane[3] - g.to_plane[1] * g.to_plane[2]).abs();
            // σ in px: the plane's mas per px is √|det M|
            let w = det / (o.sigma_mas * o.sigma_mas);
            let d = [m[0] * r[0] + m[1] * r[1], m[2] * r[0] + m[3] * r[1]];
            let (u, v) = (o.focal_px[0] / FOCAL_NORM_PX, o.focal_px[1] / FOCAL_NORM_PX);
            let mut idx: Vec<(usize, f64)> = Vec::with_capacity(3 + mono.len());
            if model.arrays > 0 {
                let k = 3 * o.array;
                idx.extend([(k, 1.0), (k + 1, u), (k + 2, v)]);
            }
            let base = 3 * model.arrays;
            idx.extend(
                mono.iter()
                    .enumerate()
                    .map(|(j, (p, q))| (base + j, u.powi(*p) * v.powi(*q))),
            );
            for (axis, (nm, rhs)) in [(&mut acc.0, &mut acc.1), (&mut acc.2, &mut acc.3)]
                .into_iter()
                .enumerate()
            {
                for &(i, xi) in &idx {
                    rhs[i] += w * xi * d[axis];
                    for &(j, xj) in &idx {
                        nm[i * n + j] += w * xi * xj;
                    }
                }
            }
            acc
        })
        .reduce(zero, |mut a, b| {
            for (x, y) in a.0.iter_mut().zip(&b.0) {
                *x += y;
            }
            for (x, y) in a.1.iter_mut().zip(&b.1) {
                *x += y;
            }
            for (x, y) in a.2.iter_mut().zip(&b.2) {
                *x += y;
            }
            for (x, y) in a.3.iter_mut().zip(&b.3) {
                *x += y;
            }
            a
        });
    let bx = crate::numerics::linalg::solve(&nx, &rx, n)?;
    let by = crate::numerics::linalg::solve(&ny, &ry, n)?;
    let mut c = Calibration::zero(model);
    for (k, a) in c.arrays.iter_mut().enumerate() {
        *a = [
            bx[3 * k],
            by[3 * k],
            bx[3 * k + 1],
            bx[3 * k + 2],
            by[3 * k + 1],
            by[3 * k + 2],
        ];
    }
    let base = 3 * model.arrays;
    c.distortion = [bx[base..].to_vec(), by[base..].to_vec()];
    c.remove_gauge();
    Some(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_of_order_three_are_the_seven_terms_without_affine_ones() {
        let m = CalibrationModel {
            arrays: 4,
            distortion_order: 3,
        };
        assert_eq!(
            m.monomials(),
            vec![(2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3)]
        );
        // 4 arrays × 6 + 2 × 7, less the gauge's 4
        assert_eq!(m.unknowns(), 24 + 14 - 4);
    }

    #[test]
    fn the_gauge_leaves_no_common_shift_turn_or_scale() {
        let mut c = Calibration::zero(CalibrationModel {
            arrays: 3,
            distortion_order: 0,
        });
        c.arrays = vec![
            [1.0, 2.0, 0.1, -0.2, 0.3, 0.05],
            [-4.0, 0.5, 0.0, 0.01, 0.02, 0.0],
            [0.7, -3.0, 0.2, 0.0, -0.1, 0.3],
        ];
        c.remove_gauge();
        let mean = |i: usize| c.arrays.iter().map(|a| a[i]).sum::<f64>() / 3.0;
        assert!(mean(0).abs() < 1e-15 && mean(1).abs() < 1e-15);
        assert!((mean(2) + mean(5)).abs() < 1e-15, "scale");
        assert!((mean(4) - mean(3)).abs() < 1e-15, "turn");
    }
}
