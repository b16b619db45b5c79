//! Effective PSF (Anderson & King 2000, PASP 112, 1360).
//!
//! The ePSF ψ(Δx, Δy) is the fraction of a star's flux that falls in a pixel whose centre lies at (Δx, Δy)
//! from the star: the optical PSF convolved with the pixel response (and, for jittered images, with the
//! jitter). Tabulated on a grid of `oversampling` nodes per pixel out to `half_px`; between nodes it is
//! interpolated with cubic convolution (Keys 1981, a = −½), which has a continuous first derivative.
//! Normalisation: Σ over all nodes = oversampling², i.e. the pixels of a star sum to 1 on average over
//! pixel phases. Centring: the flux-weighted centroid of ψ within [`CENTROID_RADIUS_PX`] is at the origin.
//!
//! * [`fit`]: weighted least-squares fit of one star (x, y, flux; sky from an annulus) and its Cramér–Rao bound;
//! * [`build`]: the iterative ePSF builder from the stars of an image;
//! * [`smooth`]: the smoothing kernels of the builder;
//! * [`varying`]: the ePSF with its change across the image (`analysis.epsf_variation`).

pub mod build;
pub mod fit;
pub mod smooth;
pub mod varying;

/// Radius within which the centroid convention is applied, pixels.
pub const CENTROID_RADIUS_PX: f64 = 2.0;

/// An ePSF table.
#[derive(Debug, Clone, PartialEq)]
pub struct Epsf {
    pub oversampling: usize,
    /// Nodes from the centre to the edge: the table is `(2·half_nodes + 1)²`.
    pub half_nodes: usize,
    /// Row-major `[iy * n + ix]`.
    pub data: Vec<f64>,
}

/// Keys' cubic convolution kernel (a = −½) and its derivative: the definition [`keys_weights`] evaluates in
/// closed form (the test holds them equal).
#[cfg(test)]
fn keys(t: f64) -> (f64, f64) {
    let a = -0.5;
    let x = t.abs();
    let s = t.signum();
    if x <= 1.0 {
        (
            (a + 2.0) * x * x * x - (a + 3.0) * x * x + 1.0,
            s * (3.0 * (a + 2.0) * x * x - 2.0 * (a + 3.0) * x),
        )
    } else if x < 2.0 {
        (
            a * x * x * x - 5.0 * a * x * x + 8.0 * a * x - 4.0 * a,
            s * (3.0 * a * x * x - 10.0 * a * x + 8.0 * a),
        )
    } else {
        (0.0, 0.0)
    }
}

/// The nodes an interpolation reads: four along a row from a flat index, or one.
trait Nodes {
    fn row4(&self, i: usize) -> [f64; 4];
    fn node(&self, i: usize) -> f64;
}

/// One table's nodes.
struct Table<'a>(&'a [f64]);

impl Nodes for Table<'_> {
    #[inline(always)]
    fn row4(&self, i: usize) -> [f64; 4] {
        let r = &self.0[i..i + 4];
        [r[0], r[1], r[2], r[3]]
    }
    #[inline]
    fn node(&self, i: usize) -> f64 {
        self.0[i]
    }
}

/// A table's nodes plus weighted others' on its grid.
struct Sum<'a> {
    base: &'a [f64],
    tables: &'a [(f64, &'a Epsf)],
}

impl Nodes for Sum<'_> {
    #[inline(always)]
    fn row4(&self, i: usize) -> [f64; 4] {
        let mut r = Table(self.base).row4(i);
        for (w, t) in self.tables {
            let q = Table(&t.data).row4(i);
            for (a, b) in r.iter_mut().zip(q) {
                *a += w * b;
            }
        }
        r
    }
    #[inline]
    fn node(&self, i: usize) -> f64 {
        self.tables
            .iter()
            .fold(self.base[i], |acc, (w, t)| acc + w * t.data[i])
    }
}

/// Keys' weights (a = −½) and their derivatives for the nodes at −1, 0, 1, 2 from a fractional offset
/// `f ∈ [0, 1)`: [`keys`] at `f + 1, f, f − 1, f − 2` in closed form (no branches).
#[inline]
fn keys_weights(f: f64) -> [(f64, f64); 4] {
    let (f2, f3) = (f * f, f * f * f);
    [
        (-0.5 * f3 + f2 - 0.5 * f, -1.5 * f2 + 2.0 * f - 0.5),
        (1.5 * f3 - 2.5 * f2 + 1.0, 4.5 * f2 - 5.0 * f),
        (-1.5 * f3 + 2.0 * f2 + 0.5 * f, -4.5 * f2 + 4.0 * f + 0.5),
        (0.5 * f3 - 0.5 * f2, 1.5 * f2 - f),
    ]
}

impl Epsf {
    /// An all-zero table.
    pub fn zeros(oversampling: usize, half_px: usize) -> Self {
        let half_nodes = oversampling * half_px;
        let n = 2 * half_nodes + 1;
        Self {
            oversampling,
            half_nodes,
            data: vec![0.0; n * n],
        }
    }

    pub fn n(&self) -> usize {
        2 * self.half_nodes + 1
    }

    /// Half-width in pixels.
    pub fn half_px(&self) -> f64 {
        self.half_nodes as f64 / self.oversampling as f64
    }

    /// Position (pixels) of node index `i` along an axis.
    pub fn node_px(&self, i: usize) -> f64 {
        (i as f64 - self.half_nodes as f64) / self.oversampling as f64
    }

    /// ψ and its derivatives (∂ψ/∂Δx, ∂ψ/∂Δy) at (Δx, Δy) pixels; zero beyond the table.
    pub fn eval(&self, dx: f64, dy: f64) -> (f64, f64, f64) {
        self.eval_nodes(dx, dy, &Table(&self.data))
    }

    /// As [`Epsf::eval`] of the table whose node `i` is `self`'s plus Σ wⱼ `tables[j]`'s (tables on this
    /// table's grid): the interpolation is linear in the nodes, so this is Σ of the tables' own evaluations,
    /// with the interpolation weights computed once.
    pub fn eval_sum(&self, tables: &[(f64, &Epsf)], dx: f64, dy: f64) -> (f64, f64, f64) {
        self.eval_nodes(
            dx,
            dy,
            &Sum {
                base: &self.data,
                tables,
            },
        )
    }

    /// Keys's cubic interpolation of the nodes `nodes` (on this table's grid) at (Δx, Δy).
    #[inline(always)]
    fn eval_nodes<N: Nodes>(&self, dx: f64, dy: f64, nodes: &N) -> (f64, f64, f64) {
        let os = self.oversampling as f64;
        let (u, v) = (
            dx * os + self.half_nodes as f64,
            dy * os + self.half_nodes as f64,
        );
        let (iu, iv) = (u.floor() as i64, v.floor() as i64);
        if iu < -2 || iv < -2 || iu > self.n() as i64 + 1 || iv > self.n() as i64 + 1 {
            return (0.0, 0.0, 0.0);
        }
        let (fu, fv) = (u - iu as f64, v - iv as f64);
        let (wu, wv) = (keys_weights(fu), keys_weights(fv));
        let (mut val, mut gx, mut gy) = (0.0, 0.0, 0.0);
        let n = self.n() as i64;
        if iu >= 1 && iv >= 1 && iu + 2 < n && iv + 2 < n {
            // inside the table: the 4 × 4 nodes without a bounds check each
            let n = n as usize;
            let base = (iv as usize - 1) * n + iu as usize - 1;
            for (j, &(wvj, dwvj)) in wv.iter().enumerate() {
                let (mut row, mut drow) = (0.0, 0.0);
                for (p, &(wui, dwui)) in nodes.row4(base + j * n).iter().zip(&wu) {
                    row += wui * p;
                    drow += dwui * p;
                }
                val += wvj * row;
                gx += wvj * drow;
                gy += dwvj * row;
            }
            return (val, gx * os, gy * os);
        }
        for (j, &(wvj, dwvj)) in wv.iter().enumerate() {
            let (mut row, mut drow) = (0.0, 0.0);
            for (i, &(wui, dwui)) in wu.iter().enumerate() {
                let (ix, iy) = (iu + i as i64 - 1, iv + j as i64 - 1);
                let p = if ix < 0 || iy < 0 || ix >= n || iy >= n {
                    0.0
                } else {
                    nodes.node((iy * n + ix) as usize)
                };
                row += wui * p;
                drow += dwui * p;
            }
            val += wvj * row;
            gx += wvj * drow;
            gy += dwvj * row;
        }
        (val, gx * os, gy * os)
    }

    /// Value only.
    pub fn value(&self, dx: f64, dy: f64) -> f64 {
        self.eval(dx, dy).0
    }

    /// Scale so that Σ nodes = oversampling² (a star's pixels sum to 1).
    pub fn normalise(&mut self) {
        let s: f64 = self.data.iter().sum();
        let target = (self.oversampling * self.oversampling) as f64;
        if s.abs() > 0.0 && s.is_finite() {
            self.data.iter_mut().for_each(|v| *v *= target / s);
        }
    }

    /// The sum and the first moments (Σψ, Σψ Δx, Σψ Δy) of the nodes within [`CENTROID_RADIUS_PX`]: the
    /// centring convention's moments.
    pub fn central_moments(&self) -> (f64, f64, f64) {
        let n = self.n();
        let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
        for iy in 0..n {
            let y = self.node_px(iy);
            for ix in 0..n {
                let x = self.node_px(ix);
                if x * x + y * y <= CENTROID_RADIUS_PX * CENTROID_RADIUS_PX {
                    let v = self.data[iy * n + ix];
                    sx += v * x;
                    sy += v * y;
                    s += v;
                }
            }
        }
        (s, sx, sy)
    }

    /// Flux-weighted centroid (pixels) of the nodes within [`CENTROID_RADIUS_PX`].
    pub fn centroid(&self) -> (f64, f64) {
        let (s, sx, sy) = self.central_moments();
        if s > 0.0 {
            (sx / s, sy / s)
        } else {
            (0.0, 0.0)
        }
    }

    /// The same function shifted by (−sx, −sy): ψ'(Δ) = ψ(Δ + s), resampled with the cubic interpolant.
    pub fn shifted(&self, sx: f64, sy: f64) -> Epsf {
        let n = self.n();
        let mut out = self.clone();
        for iy in 0..n {
            for ix in 0..n {
                out.data[iy * n + ix] = self.value(self.node_px(ix) + sx, self.node_px(iy) + sy);
            }
        }
        out
    }

    /// Re-centre (iteratively, as the centroid of a resampled table moves slightly) to the convention.
    pub fn recentred(&self) -> Epsf {
        // The centroid inside a fixed radius moves by less than the shift (≈ 0.85×), so accumulate the
        // shift of the original table until the resampled centroid is zero (a fixed-point iteration).
        let (mut sx, mut sy) = (0.0, 0.0);
        let mut e = self.clone();
        for _ in 0..60 {
            let (cx, cy) = e.centroid();
            if cx.abs() < 1e-9 && cy.abs() < 1e-9 {
                break;
            }
            sx += 1.15 * cx;
            sy += 1.15 * cy;
            e = self.shifted(sx, sy);
        }
        e
    }

    /// Sample a function ψ(Δx, Δy) on the grid (e.g. the exact ePSF from the simulator's pixel kernel).
    pub fn from_fn(oversampling: usize, half_px: usize, f: impl Fn(f64, f64) -> f64) -> Epsf {
        let mut e = Epsf::zeros(oversampling, half_px);
        let n = e.n();
        for iy in 0..n {
            for ix in 0..n {
                e.data[iy * n + ix] = f(e.node_px(ix), e.node_px(iy));
            }
        }
        e
    }

    /// `Σ_k c_k ψ(· − u_k)` tabulated on a grid of this table's oversampling and half-width `half_px`: the
    /// same numbers as [`Epsf::from_fn`] of the sum of [`Epsf::value`]s (to rounding), computed as one discrete
    /// convolution. Keys's interpolation is linear in the nodes and, for a shift `u`, its weights depend only
    /// on the fractional part of `u·oversampling` (the same at every output node), so each shift spreads its
    /// weight over 4 × 4 integer node offsets; the table is then correlated with that small kernel: the cost
    /// is (output nodes) × (kernel nodes), not × (shifts) × 16.
    pub fn shifted_sum(&self, half_px: usize, shifts: &[(f64, f64, f64)]) -> Epsf {
        let mut out = Epsf::zeros(self.oversampling, half_px);
        if shifts.is_empty() {
            return out;
        }
        let os = self.oversampling as f64;
        // shift (ux, uy) moves the sampled node by s = −u·os: taps at floor(s) − 1 … floor(s) + 2
        let taps: Vec<(i64, i64, [(f64, f64); 4], [(f64, f64); 4], f64)> = shifts
            .iter()
            .map(|&(ux, uy, c)| {
                let (su, sv) = (-ux * os, -uy * os);
                let (bu, bv) = (su.floor(), sv.floor());
                (
                    bu as i64,
                    bv as i64,
                    keys_weights(su - bu),
                    keys_weights(sv - bv),
                    c,
                )
            })
            .collect();
        let (lo_u, hi_u) = taps
            .iter()
            .fold((i64::MAX, i64::MIN), |(l, h), t| (l.min(t.0), h.max(t.0)));
        let (lo_v, hi_v) = taps
            .iter()
            .fold((i64::MAX, i64::MIN), |(l, h), t| (l.min(t.1), h.max(t.1)));
        let (ku, kv) = ((hi_u - lo_u + 4) as usize, (hi_v - lo_v + 4) as usize);
        let mut kernel = vec![0.0; ku * kv];
        for (bu, bv, wu, wv, c) in &taps {
            let (ou, ov) = ((bu - lo_u) as usize, (bv - lo_v) as usize);
            for (b, &(wvb, _)) in wv.iter().enumerate() {
                for (a, &(wua, _)) in wu.iter().enumerate() {
                    kernel[(ov + b) * ku + ou + a] += c * wua * wvb;
                }
            }
        }
        // out[iy][ix] = Σ kernel[b][a] · ψ[iy + off + lo_v − 1 + b][ix + off + lo_u − 1 + a]
        let (n_in, n_out) = (self.n() as i64, out.n());
        let off = self.half_nodes as i64 - out.half_nodes as i64;
        for (b, krow) in kernel.chunks(ku).enumerate() {
            for iy in 0..n_out {
                let sy = iy as i64 + off + lo_v - 1 + b as i64;
                if sy < 0 || sy >= n_in {
                    continue;
                }
                let src = &self.data[(sy * n_in) as usize..((sy + 1) * n_in) as usize];
                let dst = &mut out.data[iy * n_out..(iy + 1) * n_out];
                for (a, &k) in krow.iter().enumerate() {
                    if k == 0.0 {
                        continue;
                    }
                    let d = off + lo_u - 1 + a as i64;
                    // output nodes whose source node ix + d lies in the table
                    let first = (-d).max(0) as usize;
                    let last = (n_in - d).min(n_out as i64);
                    if last <= first as i64 {
                        continue;
                    }
                    let (s0, len) = ((first as i64 + d) as usize, last as usize - first);
                    for (o, &v) in dst[first..first + len].iter_mut().zip(&src[s0..s0 + len]) {
                        *o += k * v;
                    }
                }
            }
        }
        out
    }

    /// Linear interpolation between two tables of the same grid (zone interpolation): (1−t)·a + t·b.
    pub fn lerp(a: &Epsf, b: &Epsf, t: f64) -> Epsf {
        let mut out = a.clone();
        for (o, (x, y)) in out.data.iter_mut().zip(a.data.iter().zip(&b.data)) {
            *o = (1.0 - t) * x + t * y;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The convolution gives what the direct sum of evaluations gives (another method: node by node, shift by
    /// shift, through `value`), on a table of another half-width, shifts off the grid and beyond the edge.
    #[test]
    fn the_shifted_sum_is_the_sum_of_shifted_evaluations() {
        let psi = Epsf::from_fn(4, 6, |x, y| {
            (-(x * x + 0.7 * y * y) / 3.0).exp() * (1.0 + 0.2 * x - 0.1 * y * x)
        });
        let shifts: Vec<(f64, f64, f64)> = (0..37)
            .map(|k| {
                let t = k as f64;
                (
                    0.9 * (0.37 * t).sin() - 0.05,
                    0.6 * (0.23 * t).cos() + 0.013 * t,
                    0.2 + (t * 0.7).cos().abs(),
                )
            })
            .chain([(5.7, -6.3, 0.5), (-0.125, 0.25, 1.0)])
            .collect();
        for half in [6, 4, 8] {
            let fast = psi.shifted_sum(half, &shifts);
            let slow = Epsf::from_fn(4, half, |x, y| {
                shifts
                    .iter()
                    .map(|&(ux, uy, c)| c * psi.value(x - ux, y - uy))
                    .sum()
            });
            let peak = slow.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let worst = fast
                .data
                .iter()
                .zip(&slow.data)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(worst <= 1e-13 * peak, "half {half}: {worst:e} of {peak}");
        }
        assert!(psi.shifted_sum(6, &[]).data.iter().all(|v| *v == 0.0));
    }

    /// The interpolation is linear in the nodes: a weighted sum's evaluation, in the table, at its border
    /// and beyond it, is the sum of the tables' own (ψ and both derivatives).
    #[test]
    fn a_weighted_sum_of_tables_evaluates_as_the_sum_of_their_evaluations() {
        let a = Epsf::from_fn(4, 3, |x, y| (-(x * x + 0.5 * y * y)).exp());
        let b = Epsf::from_fn(4, 3, |x, y| x * (-(x * x + y * y)).exp());
        let c = Epsf::from_fn(4, 3, |x, y| (x * y - 0.3) * (-(x * x + y * y) / 2.0).exp());
        for (dx, dy) in [
            (0.13, -0.41),
            (1.7, 2.2),
            (2.95, -2.9),
            (3.4, 0.2),
            (9.0, 0.0),
        ] {
            let got = a.eval_sum(&[(0.7, &b), (-1.3, &c)], dx, dy);
            let (ea, eb, ec) = (a.eval(dx, dy), b.eval(dx, dy), c.eval(dx, dy));
            let want = (
                ea.0 + 0.7 * eb.0 - 1.3 * ec.0,
                ea.1 + 0.7 * eb.1 - 1.3 * ec.1,
                ea.2 + 0.7 * eb.2 - 1.3 * ec.2,
            );
            for (g, w) in [(got.0, want.0), (got.1, want.1), (got.2, want.2)] {
                assert!(
                    (g - w).abs() <= 1e-12 * (1.0 + w.abs()),
                    "({dx}, {dy}): {g} against {w}"
                );
            }
        }
        assert_eq!(a.eval_sum(&[], 0.3, 0.2), a.eval(0.3, 0.2));
    }

    #[test]
    fn closed_form_keys_weights_equal_the_kernel() {
        for k in 0..=100 {
            let f = k as f64 / 100.0 * 0.999_999;
            for (i, (w, dw)) in keys_weights(f).into_iter().enumerate() {
                let (v, d) = keys(f - (i as f64 - 1.0));
                assert!(
                    (w - v).abs() < 1e-14 && (dw - d).abs() < 1e-13,
                    "f {f} node {i}"
                );
            }
        }
    }

    fn gauss(os: usize) -> Epsf {
        let mut e = Epsf::from_fn(os, 5, |x, y| (-(x * x + y * y) / (2.0 * 0.8 * 0.8)).exp());
        e.normalise();
        e
    }

    #[test]
    fn interpolation_reproduces_nodes_and_derivatives() {
        let e = gauss(4);
        let n = e.n();
        for (ix, iy) in [(20, 20), (23, 18), (10, 30)] {
            let (v, _, _) = e.eval(e.node_px(ix), e.node_px(iy));
            assert!((v - e.data[iy * n + ix]).abs() < 1e-14);
        }
        // derivative against finite differences
        let (x, y) = (0.37, -0.61);
        let h = 1e-6;
        let (_, gx, gy) = e.eval(x, y);
        let fx = (e.value(x + h, y) - e.value(x - h, y)) / (2.0 * h);
        let fy = (e.value(x, y + h) - e.value(x, y - h)) / (2.0 * h);
        assert!(
            (gx - fx).abs() < 1e-6 && (gy - fy).abs() < 1e-6,
            "{gx} {fx} {gy} {fy}"
        );
    }

    #[test]
    fn shift_and_recentre() {
        let e = gauss(4);
        let s = e.shifted(0.3, -0.2); // ψ'(Δ) = ψ(Δ + s): the profile moves to −s
        let (cx, cy) = s.centroid();
        assert!(cx < -0.2 && cy > 0.15, "{cx} {cy}");
        let r = s.recentred();
        let (cx, cy) = r.centroid();
        assert!(cx.abs() < 1e-6 && cy.abs() < 1e-6);
        // re-centring brings back the symmetric original
        let peak = e.data.iter().cloned().fold(0.0, f64::max);
        let diff = r
            .data
            .iter()
            .zip(&e.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(diff < 2e-3 * peak, "{}", diff / peak);
        let mut t = gauss(4);
        t.data.iter_mut().for_each(|v| *v *= 3.0);
        t.normalise();
        assert!((t.data.iter().sum::<f64>() - 16.0).abs() < 1e-9);
    }
}
