//! The instrument's calibration unknowns of the solution: each array's affine offsets and a global
//! distortion polynomial, both in focal-plane pixels (the mission's plate model: per-detector offset and
//! rotation, a global distortion without affine terms — JASMINE-Mission/jasmine_warpfield).
//!
//! An observation's measured place on the plane came through the **design** model of the focal plane
//! (nominal array positions, the design distortion); what the instrument does differently is
//!
//! ```text
//! Δf = Σ_{p+q ≤ m} a_k,pq (f_x/L)^p (f_y/L)^q + Σ_{m < p+q ≤ n} d_pq (f_x/L)^p (f_y/L)^q   (focal-plane px)
//! ```
//!
//! for a detection at design focal-plane position f (px from the optical axis) on array k, L =
//! [`FOCAL_NORM_PX`]: each array's own polynomial of order m (1: the offset b_k and affine B_k; 2 also the
//! quadratic terms a global distortion takes on an array displaced from its design place, ∇D · δ_k) and a
//! global one of orders m + 1 … n; on the plane it is `M_e Δf`, M_e the exposure's focal-plane-to-plane matrix. With the
//! sources and attitudes held, (a, d) is one linear least-squares fit of every residual turned back into
//! focal-plane pixels (x and y apart: they share no parameter).
//!
//! **The gauge.** A shift common to every array, and the similarity part (turn and scale) of their B's
//! mean, is what each exposure's attitude does already: after every fit it is handed to the attitudes
//! (removed here; the next attitude step takes it up), so the arrays' offsets are reported about their
//! mean, and their turns and scales about their mean too.

use super::{ExposureGeometry, Observation};

/// The default normalising length L of the focal-plane coordinates, px: about JASMINE's quad focal plane's
/// corner radius (`Options::focal_norm_px`: a focal plane's own keeps the terms of order 1).
pub const DEFAULT_FOCAL_NORM_PX: f64 = 3000.0;

/// Which calibration unknowns the solution solves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CalibrationModel {
    /// Arrays with terms of their own (0: none; the observations are taken as they are).
    pub arrays: usize,
    /// The order of each array's own polynomial: 1 affine (offset, turn, scale, shear), 2 quadratic too —
    /// what a global distortion becomes on an array that sits a little off its design place (its gradient
    /// times the offset).
    pub array_order: usize,
    /// The global distortion's highest order (0: none; else `array_order` + 1 … [`MAX_DISTORTION_ORDER`]):
    /// its terms start one order above the arrays' own.
    pub distortion_order: usize,
}

/// The highest distortion order solved (the mission's plate model goes to 5).
pub const MAX_DISTORTION_ORDER: usize = 5;

/// The monomials (p, q) with `lo ≤ p + q ≤ hi`, by order, then by falling p.
fn monomials_between(lo: usize, hi: usize) -> Vec<(i32, i32)> {
    (lo as i32..=hi as i32)
        .flat_map(|n| (0..=n).map(move |q| (n - q, q)))
        .collect()
}

impl CalibrationModel {
    pub const NONE: CalibrationModel = CalibrationModel {
        arrays: 0,
        array_order: 1,
        distortion_order: 0,
    };

    /// Does it solve anything?
    pub fn solves(&self) -> bool {
        self.arrays > 0 || self.distortion_order > 0
    }

    /// Each array's own monomials: (0, 0), (1, 0), (0, 1)[, (2, 0), (1, 1), (0, 2)].
    pub fn array_terms(&self) -> Vec<(i32, i32)> {
        if self.arrays == 0 {
            return Vec::new();
        }
        monomials_between(0, self.array_order)
    }

    /// The global distortion's monomials: orders above the arrays' own up to `distortion_order`.
    pub fn monomials(&self) -> Vec<(i32, i32)> {
        let lo = if self.arrays > 0 {
            self.array_order + 1
        } else {
            2
        };
        monomials_between(lo, self.distortion_order)
    }

    /// The terms φ_j (f/L) of a detection at design focal-plane position `f_px` on `array`, as (index
    /// within an axis's coefficients, value) pairs in rising index: its array's own, then the distortion's
    /// (no allocation beyond `out`'s: this runs for every observation in every pass).
    pub fn terms_at(
        &self,
        array: usize,
        f_px: [f64; 2],
        norm_px: f64,
        out: &mut Vec<(usize, f64)>,
    ) {
        out.clear();
        self.for_each_term(array, f_px, norm_px, |j, t| out.push((j, t)));
    }

    /// [`CalibrationModel::terms_at`]'s pairs handed to `f` one by one.
    pub fn for_each_term(
        &self,
        array: usize,
        f_px: [f64; 2],
        norm_px: f64,
        mut f: impl FnMut(usize, f64),
    ) {
        let (u, v) = (f_px[0] / norm_px, f_px[1] / norm_px);
        let top = self
            .distortion_order
            .max(self.array_order)
            .min(MAX_DISTORTION_ORDER);
        let (mut up, mut vp) = (
            [1.0; MAX_DISTORTION_ORDER + 1],
            [1.0; MAX_DISTORTION_ORDER + 1],
        );
        for k in 1..=top {
            up[k] = up[k - 1] * u;
            vp[k] = vp[k - 1] * v;
        }
        // monomials_between's order: by order, then by falling power of u
        let mut between = |lo: usize, hi: usize, first: usize| {
            let mut j = first;
            for n in lo..=hi {
                for q in 0..=n {
                    f(j, up[n - q] * vp[q]);
                    j += 1;
                }
            }
        };
        let per_array = self.per_array();
        if array < self.arrays {
            between(0, self.array_order, per_array * array);
        }
        let lo = if self.arrays > 0 {
            self.array_order + 1
        } else {
            2
        };
        if self.distortion_order >= lo {
            between(lo, self.distortion_order, per_array * self.arrays);
        }
    }

    /// Each array's own terms per axis (0 without arrays).
    pub fn per_array(&self) -> usize {
        if self.arrays == 0 {
            0
        } else {
            (self.array_order + 1) * (self.array_order + 2) / 2
        }
    }

    /// Unknowns per axis.
    pub fn per_axis(&self) -> usize {
        self.arrays * self.array_terms().len() + self.monomials().len()
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
    /// Per array, per axis (x, y): the coefficients of [`CalibrationModel::array_terms`] (px: the first the
    /// offset, the next two the affine B's row, per L of focal-plane position).
    pub arrays: Vec<[Vec<f64>; 2]>,
    /// `d_pq` per axis, in the order of [`CalibrationModel::monomials`], px.
    pub distortion: [Vec<f64>; 2],
    /// L: focal-plane positions are in units of it in every term, px.
    pub norm_px: f64,
}

impl Calibration {
    /// Nothing to correct.
    pub fn zero(model: CalibrationModel, norm_px: f64) -> Self {
        let (a, m) = (model.array_terms().len(), model.monomials().len());
        Self {
            model,
            arrays: vec![[vec![0.0; a], vec![0.0; a]]; model.arrays],
            distortion: [vec![0.0; m], vec![0.0; m]],
            norm_px,
        }
    }

    /// Δf at design focal-plane position `f_px` on array `array`, px.
    pub fn correction_px(&self, array: usize, f_px: [f64; 2]) -> [f64; 2] {
        let per = self.model.per_array();
        let n = self.model.arrays * per;
        let mut d = [0.0; 2];
        self.model.for_each_term(array, f_px, self.norm_px, |j, t| {
            let (x, y) = if j < n {
                (
                    self.arrays[j / per][0][j % per],
                    self.arrays[j / per][1][j % per],
                )
            } else {
                (self.distortion[0][j - n], self.distortion[1][j - n])
            };
            d[0] += x * t;
            d[1] += y * t;
        });
        d
    }

    /// The same on the plane of exposure `g`, mas.
    pub fn correction_mas(&self, o: &Observation, g: &ExposureGeometry) -> [f64; 2] {
        if !self.model.solves() {
            return [0.0; 2];
        }
        let d = self.correction_px(o.array(), o.focal_px());
        let m = &g.to_plane;
        [m[0] * d[0] + m[1] * d[1], m[2] * d[0] + m[3] * d[1]]
    }

    /// The largest change of Δf between two calibrations anywhere within L of the axis, px (a bound: the sum
    /// of the coefficients' changes).
    pub fn moved_px(&self, other: &Calibration) -> f64 {
        let change =
            |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>();
        let arrays = self
            .arrays
            .iter()
            .zip(&other.arrays)
            .map(|(a, b)| change(&a[0], &b[0]).max(change(&a[1], &b[1])))
            .fold(0.0f64, f64::max);
        let dist = change(&self.distortion[0], &other.distortion[0])
            .max(change(&self.distortion[1], &other.distortion[1]));
        arrays + dist
    }

    /// The same terms in a larger model (the new ones zero).
    pub fn extended_to(&self, model: CalibrationModel) -> Calibration {
        let mut c = Calibration::zero(model, self.norm_px);
        let terms = model.array_terms();
        for (a, old) in c.arrays.iter_mut().zip(&self.arrays) {
            for (m, t) in self.model.array_terms().into_iter().enumerate() {
                if let Some(j) = terms.iter().position(|x| *x == t) {
                    a[0][j] = old[0][m];
                    a[1][j] = old[1][m];
                }
            }
        }
        let mono = model.monomials();
        for (m, t) in self.model.monomials().into_iter().enumerate() {
            if let Some(j) = mono.iter().position(|x| *x == t) {
                c.distortion[0][j] = self.distortion[0][m];
                c.distortion[1][j] = self.distortion[1][m];
            }
        }
        c
    }

    /// Hand the gauge to the attitudes: remove the arrays' mean offset and the similarity part (turn and
    /// scale) of their mean affine B — the projection off [`gauge_rows`] (mutually orthogonal).
    pub fn remove_gauge(&mut self) {
        let t = self.model.array_terms().len();
        let n = self.model.per_axis();
        // coefficient index in the (x, y) layout of [`gauge_rows`]
        let at = |i: usize| (i / n, (i % n) / t, (i % n) % t);
        for row in gauge_rows(self.model) {
            let (dot, norm) = row.iter().fold((0.0, 0.0), |(d, m), &(i, w)| {
                let (axis, k, j) = at(i);
                (d + w * self.arrays[k][axis][j], m + w * w)
            });
            if norm > 0.0 {
                for &(i, w) in &row {
                    let (axis, k, j) = at(i);
                    self.arrays[k][axis][j] -= dot / norm * w;
                }
            }
        }
    }
}

/// The gauge the attitudes hold, as four linear constraints on the calibration's coefficients (indexed x
/// terms first, then y, each array's terms in turn): the arrays' mean offset in x and in y, and the
/// similarity part of their mean B — scale `x_u + y_v`, turn `y_u − x_v`. None without arrays.
pub(super) fn gauge_rows(model: CalibrationModel) -> Vec<Vec<(usize, f64)>> {
    if model.arrays == 0 {
        return Vec::new();
    }
    let (t, n) = (model.array_terms().len(), model.per_axis());
    let at = |axis: usize, k: usize, j: usize| axis * n + t * k + j;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); 4];
    for k in 0..model.arrays {
        rows[0].push((at(0, k, 0), 1.0));
        rows[1].push((at(1, k, 0), 1.0));
        rows[2].extend([(at(0, k, 1), 1.0), (at(1, k, 2), 1.0)]);
        rows[3].extend([(at(1, k, 1), 1.0), (at(0, k, 2), -1.0)]);
    }
    rows
}

/// Solve normal equations `N x = r` scaled by their diagonal (Jacobi), so that the singularity test sees
/// the terms' correlations, not their units: None where a term is unconstrained or is (to 1 part in 10⁹ of
/// its scale) a combination of the others.
fn solve_scaled(nm: &[f64], r: &[f64], n: usize) -> Option<Vec<f64>> {
    let d: Vec<f64> = (0..n).map(|i| nm[i * n + i].sqrt()).collect();
    if d.iter().any(|v| !(*v > 0.0) || !v.is_finite()) {
        return None;
    }
    let scaled: Vec<f64> = (0..n * n).map(|k| nm[k] / (d[k / n] * d[k % n])).collect();
    let rs: Vec<f64> = (0..n).map(|i| r[i] / d[i]).collect();
    // the pivot test of `linalg::solve` is relative to the largest entry (1 on the scaled diagonal): a
    // correlation beyond 1 − 10⁻⁹ fails it
    let x = crate::numerics::linalg::solve(&scaled, &rs, n)?;
    let mut min_pivot = f64::INFINITY;
    {
        // an LDLᵀ pass for the smallest pivot (the scaled matrix is symmetric positive semi-definite)
        let mut m = scaled.clone();
        for c in 0..n {
            let p = m[c * n + c];
            min_pivot = min_pivot.min(p);
            if !(p > 0.0) {
                return None;
            }
            for i in c + 1..n {
                let f = m[i * n + c] / p;
                for j in c..n {
                    m[i * n + j] -= f * m[c * n + j];
                }
            }
        }
    }
    (min_pivot > 1e-9).then(|| (0..n).map(|i| x[i] / d[i]).collect())
}

/// The inverse of a 2 × 2 row-major matrix (None when singular).
pub fn inverse2(m: &[f64; 4]) -> Option<[f64; 4]> {
    let det = m[0] * m[3] - m[1] * m[2];
    (det.abs() > 0.0 && det.is_finite()).then(|| [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det])
}

/// The instrument block: with the sources held, every exposure's attitude and the calibration together —
/// one linear least-squares fit, the attitudes eliminated exposure by exposure (each exposure's 4 × 4 block,
/// a Schur complement), so that what the two share (a shift, turn or scale common to the arrays: the gauge,
/// held at zero for the calibration by four penalty rows) never bounces between them. Every kept observation
/// with a place `places[i]` (its source's place at the exposure's epoch, mas) enters turned into the
/// focal-plane frame: `M⁻¹(o − c) = A′ M⁻¹(s − c) + a′ + Δf(f)`, A′ a similarity.
///
/// Returns the calibration and each exposure's attitude (None where it sees fewer than two placed sources),
/// or None when the calibration is unconstrained.
pub(super) fn fit_with_attitudes(
    model: CalibrationModel,
    norm_px: f64,
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    by_exposure: &super::groups::Groups,
    place: impl Fn(usize) -> Option<[f64; 2]> + Sync,
    active: &[bool],
) -> Option<(Calibration, Vec<Option<super::Attitude>>)> {
    use rayon::prelude::*;
    let n = model.per_axis();
    let n2 = 2 * n;
    let blocks: Vec<Option<Block>> = (0..exposures.len())
        .into_par_iter()
        .map(|e| {
            let mine = by_exposure.get(e).iter().map(|i| *i as usize);
            Block::of_exposure(model, norm_px, obs, &exposures[e], mine, &place, active)
        })
        .collect();
    let (mut sys, rhs, a_inv) = reduced_system(&blocks, n2);
    let t = model.array_terms().len();
    // the gauge, held at zero by penalty rows as heavy as the heaviest term
    let heavy = (0..n2)
        .map(|i| sys[i * n2 + i])
        .fold(0.0f64, f64::max)
        .max(1e-300);
    for row in gauge_rows(model) {
        for &(i, a) in &row {
            for &(j, b) in &row {
                sys[i * n2 + j] += heavy * a * b;
            }
        }
    }
    let x = solve_scaled(&sys, &rhs, n2)?;
    let mut cal = Calibration::zero(model, norm_px);
    for (k, a) in cal.arrays.iter_mut().enumerate() {
        *a = [
            x[t * k..t * (k + 1)].to_vec(),
            x[n + t * k..n + t * (k + 1)].to_vec(),
        ];
    }
    let base = t * model.arrays;
    cal.distortion = [x[base..n].to_vec(), x[n + base..].to_vec()];
    let attitudes = blocks
        .iter()
        .zip(&a_inv)
        .zip(exposures)
        .map(|((blk, ai), g)| attitude_of(blk.as_ref()?, ai.as_ref()?, g, &x))
        .collect();
    Some((cal, attitudes))
}

/// One exposure's share of the instrument block's normal equations: A (4 × 4, its attitude), B (4 × 2n,
/// attitude × calibration), its right-hand side rₐ (4), and its share of C (2n × 2n) and of the
/// calibration's right-hand side (2n).
struct Block {
    a: [f64; 16],
    b: Vec<f64>,
    ra: [f64; 4],
    c: Vec<f64>,
    rc: Vec<f64>,
    count: usize,
}

impl Block {
    /// The block of exposure `g` from its observations `mine` (the active ones with a place); None when its
    /// plane's matrix is singular.
    fn of_exposure(
        model: CalibrationModel,
        norm_px: f64,
        obs: &[Observation],
        g: &ExposureGeometry,
        mine: impl Iterator<Item = usize>,
        place: &(impl Fn(usize) -> Option<[f64; 2]> + Sync),
        active: &[bool],
    ) -> Option<Block> {
        let n = model.per_axis();
        let n2 = 2 * n;
        let m = inverse2(&g.to_plane)?;
        let det = (g.to_plane[0] * g.to_plane[3] - g.to_plane[1] * g.to_plane[2]).abs();
        let mut blk = Block {
            a: [0.0; 16],
            b: vec![0.0; 4 * n2],
            ra: [0.0; 4],
            c: vec![0.0; n2 * n2],
            rc: vec![0.0; n2],
            count: 0,
        };
        let to_focal = |p: [f64; 2]| {
            let d = [p[0] - g.centre_mas[0], p[1] - g.centre_mas[1]];
            [m[0] * d[0] + m[1] * d[1], m[2] * d[0] + m[3] * d[1]]
        };
        let mut phi: Vec<(usize, f64)> =
            Vec::with_capacity(model.array_terms().len() + model.monomials().len());
        // C's x block (the y block is the same: one φ, one weight per observation), upper triangle
        let mut cx = vec![0.0; n * n];
        for i in mine.filter(|i| active[*i]) {
            let o = &obs[i];
            let Some(place) = place(i) else { continue };
            blk.count += 1;
            // σ in px: the plane's mas per px is √|det M|
            let w = det / (o.sigma_mas * o.sigma_mas);
            let (y, sp) = (to_focal([o.xi_mas, o.eta_mas]), to_focal(place));
            model.terms_at(o.array(), o.focal_px(), norm_px, &mut phi);
            // x: p′ s′x − q′ s′y + a′x + Σ cx φ;  y: q′ s′x + p′ s′y + a′y + Σ cy φ
            for axis in 0..2 {
                let att = if axis == 0 {
                    [sp[0], -sp[1], 1.0, 0.0]
                } else {
                    [sp[1], sp[0], 0.0, 1.0]
                };
                let off = axis * n;
                for r in 0..4 {
                    let wa = w * att[r];
                    blk.ra[r] += wa * y[axis];
                    for c in 0..4 {
                        blk.a[r * 4 + c] += wa * att[c];
                    }
                    for &(j, x) in &phi {
                        blk.b[r * n2 + off + j] += wa * x;
                    }
                }
                for &(i1, x1) in &phi {
                    blk.rc[off + i1] += w * x1 * y[axis];
                }
            }
            // φ's indices rise (an array's terms, then the distortion's): the upper triangle is i1 ≤ j1
            for (a, &(i1, x1)) in phi.iter().enumerate() {
                let wx = w * x1;
                for &(j1, x2) in &phi[a..] {
                    cx[i1 * n + j1] += wx * x2;
                }
            }
        }
        for i1 in 0..n {
            for j1 in i1..n {
                let v = cx[i1 * n + j1];
                for off in [0, n] {
                    blk.c[(off + i1) * n2 + off + j1] = v;
                    blk.c[(off + j1) * n2 + off + i1] = v;
                }
            }
        }
        Some(blk)
    }
}

/// The reduced system for the calibration (2n unknowns), the attitudes eliminated: `C − Σ Bᵀ A⁻¹ B`,
/// `r − Σ Bᵀ A⁻¹ rₐ`, and each exposure's A⁻¹ (None where it sees fewer than two placed sources).
#[allow(clippy::type_complexity)]
fn reduced_system(
    blocks: &[Option<Block>],
    n2: usize,
) -> (Vec<f64>, Vec<f64>, Vec<Option<Vec<f64>>>) {
    let mut sys = vec![0.0; n2 * n2];
    let mut rhs = vec![0.0; n2];
    let mut a_inv: Vec<Option<Vec<f64>>> = Vec::with_capacity(blocks.len());
    for blk in blocks {
        let Some(blk) = blk else {
            a_inv.push(None);
            continue;
        };
        let ai = (blk.count >= 2)
            .then(|| crate::numerics::linalg::inverse(&blk.a, 4))
            .flatten();
        let Some(ai) = ai else {
            a_inv.push(None);
            continue;
        };
        for (x, y) in sys.iter_mut().zip(&blk.c) {
            *x += y;
        }
        for (x, y) in rhs.iter_mut().zip(&blk.rc) {
            *x += y;
        }
        // G = A⁻¹ B (4 × 2n), g = A⁻¹ rₐ
        let mut gm = vec![0.0; 4 * n2];
        let mut gv = [0.0; 4];
        for r in 0..4 {
            for k in 0..4 {
                let f = ai[r * 4 + k];
                gv[r] += f * blk.ra[k];
                for j in 0..n2 {
                    gm[r * n2 + j] += f * blk.b[k * n2 + j];
                }
            }
        }
        for i in 0..n2 {
            for r in 0..4 {
                let bri = blk.b[r * n2 + i];
                if bri == 0.0 {
                    continue;
                }
                rhs[i] -= bri * gv[r];
                for j in 0..n2 {
                    sys[i * n2 + j] -= bri * gm[r * n2 + j];
                }
            }
        }
        a_inv.push(Some(ai));
    }
    (sys, rhs, a_inv)
}

/// An exposure's attitude from the solved calibration `x`: `A⁻¹ (rₐ − B x)`, turned back onto the plane.
fn attitude_of(
    blk: &Block,
    ai: &[f64],
    g: &ExposureGeometry,
    x: &[f64],
) -> Option<super::Attitude> {
    let n2 = x.len();
    let mut r = blk.ra;
    for (k, rk) in r.iter_mut().enumerate() {
        *rk -= (0..n2).map(|j| blk.b[k * n2 + j] * x[j]).sum::<f64>();
    }
    let th: Vec<f64> = (0..4)
        .map(|i| (0..4).map(|k| ai[i * 4 + k] * r[k]).sum())
        .collect();
    let m = g.to_plane;
    let mi = inverse2(&m)?;
    // A = M A′ M⁻¹ (a similarity, with the sky's handedness), a = M a′
    let ap = [th[0], -th[1], th[1], th[0]];
    let mul = |a: &[f64; 4], b: &[f64; 4]| {
        [
            a[0] * b[0] + a[1] * b[2],
            a[0] * b[1] + a[1] * b[3],
            a[2] * b[0] + a[3] * b[2],
            a[2] * b[1] + a[3] * b[3],
        ]
    };
    let full = mul(&mul(&m, &ap), &mi);
    Some(super::Attitude {
        p: (full[0] + full[3]) / 2.0,
        q: (full[2] - full[1]) / 2.0,
        offset_mas: [m[0] * th[2] + m[1] * th[3], m[2] * th[2] + m[3] * th[3]],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_terms_of_arrays_and_distortion_do_not_overlap() {
        let m = CalibrationModel {
            arrays: 4,
            array_order: 1,
            distortion_order: 3,
        };
        assert_eq!(m.array_terms(), vec![(0, 0), (1, 0), (0, 1)]);
        assert_eq!(
            m.monomials(),
            vec![(2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3)]
        );
        // 4 arrays × 2 × 3 + 2 × 7, less the gauge's 4
        assert_eq!(m.unknowns(), 24 + 14 - 4);
        let q = CalibrationModel {
            array_order: 2,
            ..m
        };
        assert_eq!(q.array_terms().len(), 6);
        assert_eq!(q.monomials(), vec![(3, 0), (2, 1), (1, 2), (0, 3)]);
    }

    #[test]
    fn the_terms_at_a_place_are_the_listed_monomials() {
        let m = CalibrationModel {
            arrays: 4,
            array_order: 2,
            distortion_order: 5,
        };
        let (f, norm) = ([1234.0, -987.0], 3000.0);
        let (u, v) = (f[0] / norm, f[1] / norm);
        let mut got = Vec::new();
        m.terms_at(2, f, norm, &mut got);
        let per = m.array_terms().len();
        let mut want: Vec<(usize, f64)> = m
            .array_terms()
            .iter()
            .enumerate()
            .map(|(j, (p, q))| (2 * per + j, u.powi(*p) * v.powi(*q)))
            .collect();
        want.extend(
            m.monomials()
                .iter()
                .enumerate()
                .map(|(j, (p, q))| (4 * per + j, u.powi(*p) * v.powi(*q))),
        );
        assert_eq!(got.len(), want.len());
        for ((j, a), (k, b)) in got.iter().zip(&want) {
            assert_eq!(j, k);
            assert!((a - b).abs() <= 1e-15 * b.abs().max(1e-3), "{a} {b}");
        }
    }

    #[test]
    fn the_gauge_leaves_no_common_shift_turn_or_scale() {
        let mut c = Calibration::zero(
            CalibrationModel {
                arrays: 3,
                array_order: 1,
                distortion_order: 0,
            },
            DEFAULT_FOCAL_NORM_PX,
        );
        c.arrays = vec![
            [vec![1.0, 0.1, -0.2], vec![2.0, 0.3, 0.05]],
            [vec![-4.0, 0.0, 0.01], vec![0.5, 0.02, 0.0]],
            [vec![0.7, 0.2, 0.0], vec![-3.0, -0.1, 0.3]],
        ];
        c.remove_gauge();
        let mean = |axis: usize, i: usize| c.arrays.iter().map(|a| a[axis][i]).sum::<f64>() / 3.0;
        assert!(mean(0, 0).abs() < 1e-15 && mean(1, 0).abs() < 1e-15);
        assert!((mean(0, 1) + mean(1, 2)).abs() < 1e-15, "scale");
        assert!((mean(1, 1) - mean(0, 2)).abs() < 1e-15, "turn");
    }
}
