//! The accelerated solution: conjugate gradients on the normal equations of every unknown at once,
//! preconditioned by the blocks the block iteration solves one at a time (AGIS's scheme: Bombrun, Lindegren,
//! Hobbs et al. 2012, A&A 538, A77, §4).
//!
//! **The linear problem.** About the current sources s, attitudes (p, q, a) and calibration c, an
//! observation's residual `r = o − M Δf(c) − [c_e + A (x(s) − c_e) + a]` changes to first order by `J δ`, with
//! the columns
//!
//! ```text
//! ∂/∂(ξ₀, η₀, μ_ξ, μ_η, ϖ) = A b_k,  b = (1,0), (0,1), (t,0), (0,t), (P_ξ, P_η)
//! ∂/∂(p S, q S) = (d_x, d_y)/S, (−d_y, d_x)/S,  d = x(s) − c_e;   ∂/∂a = (1,0), (0,1)
//! ∂/∂c_x,j = M (φ_j, 0),  ∂/∂c_y,j = M (0, φ_j)
//! ```
//!
//! (S the exposure's lever arm, so that its four unknowns share a scale). The normal equations
//! `(Jᵀ W J + P) δ = Jᵀ W r + P (x_ref − x)` — P the reference catalogue's priors, and on the calibration the
//! four gauge rows the attitudes hold (see [`super::calibration`]) as a penalty — are solved by
//! preconditioned conjugate gradients. `N v` is never formed: one pass over the observations gives `J v`,
//! a pass over each source's and each exposure's observations gives `Jᵀ W (J v)`. The preconditioner is
//! block-diagonal: each source's n × n block (its own fit with everything else held), each exposure's 4 × 4,
//! the calibration's dense block.
//!
//! **Convergence is a criterion**: a step stops the gradients when no unknown moves by more than
//! `tolerance_sigma` of its formal error (its block's σ); the Gauss–Newton loop about them (the attitude's
//! A x(s) is bilinear) stops when a whole linear solution moves nothing by more than that. The sources are
//! then fitted once more with the instrument held, which gives their reported covariance (as the block
//! iteration's).

use super::blocks::{Problem, State, anchors, unconstrained};
use super::calibration::{Calibration, gauge_rows};
use super::ranks::{self, LEAVES, Ranks};
use super::tiles::Tiles;
use super::{Attitude, Params};
use crate::solution::SolutionError;
use rayon::prelude::*;

/// Relinearisations at most (the attitudes' bilinear term is of order 10⁻⁵: two or three suffice).
const MAX_OUTER: usize = 20;

/// Run the accelerated solution from `state` (its attitudes and calibration; the sources are fitted first)
/// on `ranks`: each solves its own sky tiles' sources, and every rank ends with all of them (the same bits
/// as one process: [`ranks`]). Returns the iterations (passes over the observations) and whether the
/// criterion was met.
///
/// `resume`: the iterations this round had made when its checkpoint was written (the state is the
/// checkpoint's, at a relinearisation: the sources are not fitted first). `save`, if given, is called at each
/// relinearisation with every source gathered to every rank and the iterations so far.
pub(super) fn iterate(
    p: &Problem,
    state: &mut State,
    active: &[bool],
    ranks: &dyn Ranks,
    resume: Option<(usize, Option<Steps>)>,
    mut save: Option<&mut SaveFn>,
) -> Result<(usize, bool), SolutionError> {
    let opt = p.opt;
    let tiles = Tiles::new(p, ranks);
    let lever: Vec<f64> = (0..p.exposures.len())
        .into_par_iter()
        .map(|e| {
            let g = &p.exposures[e];
            p.by_exposure
                .get(e)
                .iter()
                .map(|&i| {
                    let o = &p.obs[i as usize];
                    (o.xi_mas - g.centre_mas[0])
                        .abs()
                        .max((o.eta_mas - g.centre_mas[1]).abs())
                })
                .fold(1.0f64, f64::max)
        })
        .collect();
    let (mut iterations, mut steps_back) = match resume {
        Some((k, steps)) => (k, steps),
        None => {
            tiles.source_pass(p, state, active);
            (1, None)
        }
    };
    let budget = opt.max_iterations.max(1);
    let mut converged = false;
    for _ in 0..MAX_OUTER {
        if save.is_some() {
            // a checkpoint within this relinearisation holds the state it starts from: every source of it
            tiles.gather(state, ranks);
        }
        let mut lin = Linear::new(p, state, active, &lever, &tiles);
        let pre = lin.preconditioner(ranks)?;
        let b = lin.rhs(state, ranks);
        let start = steps_back.take().map(|g| lin.local(&g)).transpose()?;
        let (x, steps, inner_converged) = {
            let before = iterations;
            let (lin, st) = (&lin, &*state);
            let mut inner = save.as_mut().map(|f| {
                move |at: &Steps| -> Result<(), SolutionError> {
                    let whole = lin.whole(at, ranks);
                    f(st, before, Some(&whole))
                }
            });
            let inner = inner
                .as_mut()
                .map(|f| f as &mut dyn FnMut(&Steps) -> Result<(), SolutionError>);
            pcg(
                lin,
                &pre,
                &b,
                opt.tolerance_sigma,
                budget,
                ranks,
                start,
                inner,
            )?
        };
        iterations += steps;
        let moved = x
            .iter()
            .zip(&pre.sigma)
            .map(|(v, s)| if *s > 0.0 { v.abs() / s } else { 0.0 })
            .fold(0.0f64, f64::max);
        let moved = ranks::max_across(ranks, moved);
        lin.update(state, &x);
        if inner_converged && moved <= opt.tolerance_sigma {
            converged = true;
            break;
        }
        if iterations >= budget {
            break;
        }
        if let Some(save) = save.as_mut() {
            tiles.gather(state, ranks);
            save(state, iterations, None)?;
        }
    }
    tiles.source_pass(p, state, active);
    tiles.gather(state, ranks);
    Ok((iterations, converged))
}

/// Preconditioned conjugate gradients for `N x = b` from x = 0: the solution, the steps taken, and whether
/// the last step moved every unknown by less than `tol` of its σ (or the residual vanished).
///
/// `start`: where an interrupted run stood (this rank's share); `save`, if given, is called every
/// [`SAVE_STEPS`] steps with where it stands.
#[allow(clippy::too_many_arguments)]
fn pcg(
    lin: &Linear,
    pre: &Preconditioner,
    b: &[f64],
    tol: f64,
    budget: usize,
    ranks: &dyn Ranks,
    start: Option<Steps>,
    mut save: Option<&mut dyn FnMut(&Steps) -> Result<(), SolutionError>>,
) -> Result<(Vec<f64>, usize, bool), SolutionError> {
    let Steps {
        mut steps,
        mut x,
        mut r,
        mut d,
    } = start.unwrap_or_else(|| Steps {
        steps: 0,
        x: vec![0.0; b.len()],
        r: b.to_vec(),
        d: pre.apply(lin, b),
    });
    let mut z = pre.apply(lin, &r);
    let mut rz = lin.dot(&r, &z, ranks);
    while steps < budget {
        if !(rz > 0.0) {
            return Ok((x, steps, true));
        }
        steps += 1;
        let q = lin.apply(&d, ranks);
        let dq = lin.dot(&d, &q, ranks);
        if !(dq > 0.0) {
            return Ok((x, steps, true));
        }
        let alpha = rz / dq;
        let mut step = 0.0f64;
        for k in 0..x.len() {
            let dx = alpha * d[k];
            x[k] += dx;
            r[k] -= alpha * q[k];
            if pre.sigma[k] > 0.0 {
                step = step.max(dx.abs() / pre.sigma[k]);
            }
        }
        if ranks::max_across(ranks, step) <= tol {
            return Ok((x, steps, true));
        }
        z = pre.apply(lin, &r);
        let rz_new = lin.dot(&r, &z, ranks);
        let beta = rz_new / rz;
        rz = rz_new;
        for (dk, zk) in d.iter_mut().zip(&z) {
            *dk = zk + beta * *dk;
        }
        if let Some(save) = save.as_mut()
            && steps % SAVE_STEPS == 0
            && steps < budget
        {
            let at = Steps {
                steps,
                x: x.clone(),
                r: r.clone(),
                d: d.clone(),
            };
            save(&at)?;
        }
    }
    Ok((x, steps, false))
}

/// A checkpoint's writer: the state, the iterations before (within a relinearisation) or after it, and where
/// the gradients stand within one.
pub(super) type SaveFn<'a> =
    dyn FnMut(&State, usize, Option<&Steps>) -> Result<(), SolutionError> + 'a;

/// Steps of the gradients between two checkpoints within a relinearisation.
const SAVE_STEPS: usize = 20;

/// Where the gradients stand: the steps taken, the solution so far, the residual and the search direction
/// (in a rank's layout of the unknowns within [`pcg`], in the whole problem's in a checkpoint).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Steps {
    pub steps: usize,
    pub x: Vec<f64>,
    pub r: Vec<f64>,
    pub d: Vec<f64>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `Σ over leaves [lo, hi) of leaf(c, its part of the sources' segment)` along [`ranks::tree`]'s tree,
/// `part` being leaves [lo, hi)'s run of it (`starts[c]`: where leaf c's run begins).
fn tree_split<T: Send>(
    lo: usize,
    hi: usize,
    part: &mut [f64],
    starts: &[usize],
    leaf: &(impl Fn(usize, &mut [f64]) -> T + Sync),
    add: &(impl Fn(T, T) -> T + Sync),
) -> T {
    if hi - lo <= 1 {
        return leaf(lo, part);
    }
    let mid = (lo + hi) / 2;
    let (a, b) = part.split_at_mut(starts[mid] - starts[lo]);
    let (x, y) = rayon::join(
        || tree_split(lo, mid, a, starts, leaf, add),
        || tree_split(mid, hi, b, starts, leaf, add),
    );
    add(x, y)
}

fn add_vec(mut a: Vec<f64>, b: Vec<f64>) -> Vec<f64> {
    ranks::add_into(&mut a, &b);
    a
}

/// The problem linearised about one state: which unknown sits where, and the Jacobian's columns.
struct Linear<'a> {
    p: &'a Problem<'a>,
    active: &'a [bool],
    lever: &'a [f64],
    tiles: &'a Tiles,
    params: Vec<Params>,
    attitudes: Vec<Attitude>,
    /// Unknowns per source (0: not solved, or another rank's) and where its first one sits (the sources laid
    /// out in tile order).
    dims: Vec<usize>,
    src_off: Vec<usize>,
    /// Where each leaf's run of the sources' unknowns begins (and, last, where the sources' end).
    leaf_start: Vec<usize>,
    /// In the whole problem's layout (every rank's sources in tile order): where this rank's first source's
    /// unknowns sit, and the sources' unknowns in all.
    whole_before: usize,
    whole_sources: usize,
    att_off: usize,
    cal_off: usize,
    /// The calibration's unknowns per axis (0 when none is solved).
    cal_axis: usize,
    len: usize,
    /// The gauge rows' penalty weight (the heaviest diagonal term of the calibration's block).
    heavy: f64,
    cal_now: Vec<f64>,
}

/// A source's five columns and an exposure's four (each a 2-vector: the ξ and η rows).
type Columns = ([[f64; 2]; 5], [[f64; 2]; 4]);

impl<'a> Linear<'a> {
    fn new(
        p: &'a Problem<'a>,
        state: &State,
        active: &'a [bool],
        lever: &'a [f64],
        tiles: &'a Tiles,
    ) -> Self {
        let all_dims: Vec<usize> = state
            .sources
            .iter()
            .map(|s| s.sigma.iter().take_while(|v| v.is_finite()).count())
            .collect();
        let dims: Vec<usize> = all_dims
            .iter()
            .zip(&tiles.owned)
            .map(|(n, mine)| if *mine { *n } else { 0 })
            .collect();
        let first_mine = tiles.run(tiles.mine.clone()).start;
        let whole_before: usize = tiles.order[..first_mine].iter().map(|s| all_dims[*s]).sum();
        let whole_sources: usize = all_dims.iter().sum();
        let mut src_off = vec![0; dims.len()];
        let mut leaf_start = Vec::with_capacity(LEAVES + 1);
        let mut n = 0;
        for c in 0..LEAVES {
            leaf_start.push(n);
            for &s in tiles.leaf(c) {
                src_off[s] = n;
                n += dims[s];
            }
        }
        leaf_start.push(n);
        let cal_axis = if p.opt.calibration.solves() {
            p.opt.calibration.per_axis()
        } else {
            0
        };
        let att_off = n;
        let cal_off = att_off + 4 * p.exposures.len();
        Self {
            p,
            active,
            lever,
            tiles,
            params: state.sources.iter().map(|s| s.params).collect(),
            attitudes: state.attitudes.clone(),
            dims,
            src_off,
            leaf_start,
            whole_before,
            whole_sources,
            att_off,
            cal_off,
            cal_axis,
            len: cal_off + 2 * cal_axis,
            heavy: 0.0,
            cal_now: flatten(&state.cal),
        }
    }

    /// Observation `i`'s source and attitude columns, and its source's place less the exposure's centre.
    fn columns(&self, i: usize) -> Columns {
        let o = &self.p.obs[i];
        let g = &self.p.exposures[o.exposure()];
        let a = &self.attitudes[o.exposure()];
        let place = g.place(&self.params[o.source()]);
        let (dx, dy) = (place[0] - g.centre_mas[0], place[1] - g.centre_mas[1]);
        let b = [
            [1.0, 0.0],
            [0.0, 1.0],
            [g.t_yr, 0.0],
            [0.0, g.t_yr],
            g.parallax_factor,
        ];
        let src = b.map(|v| [a.p * v[0] - a.q * v[1], a.q * v[0] + a.p * v[1]]);
        let s = self.lever[o.exposure()];
        let att = [[dx / s, dy / s], [-dy / s, dx / s], [1.0, 0.0], [0.0, 1.0]];
        (src, att)
    }

    fn weight(&self, i: usize) -> f64 {
        let s = self.p.obs[i].sigma_mas;
        1.0 / (s * s)
    }

    /// φ of observation `i` (empty without a calibration).
    fn phi(&self, i: usize, out: &mut Vec<(usize, f64)>) {
        out.clear();
        if self.cal_axis > 0 {
            let o = &self.p.obs[i];
            self.p
                .opt
                .calibration
                .terms_at(o.array(), o.focal_px(), self.p.opt.focal_norm_px, out);
        }
    }

    /// `Σᵢ Jᵢᵀ uᵢ` with `uᵢ = f(i, Jᵢ's columns, φᵢ)`, in one pass over this rank's observations by source:
    /// each source's share written in place, the exposures' and the calibration's summed leaf by leaf and
    /// along the tree across the ranks (no per-observation buffer).
    fn accumulate(
        &self,
        f: impl Fn(usize, &Columns, &[(usize, f64)]) -> [f64; 2] + Sync,
        ranks: &dyn Ranks,
    ) -> Vec<f64> {
        let mut out = vec![0.0; self.len];
        let (src_part, rest) = out.split_at_mut(self.att_off);
        let ca = self.cal_axis;
        let shared = rest.len();
        let base = 4 * self.p.exposures.len();
        let (lo, hi) = (self.tiles.mine.start, self.tiles.mine.end);
        let leaf = |c: usize, part: &mut [f64]| {
            let mut acc = vec![0.0; shared];
            let mut phi = Vec::new();
            for &s in self.tiles.leaf(c) {
                let n = self.dims[s];
                if n == 0 {
                    continue;
                }
                let at = self.src_off[s] - self.leaf_start[c];
                let slice = &mut part[at..at + n];
                for i in self.p.by_source.get(s).iter().map(|i| *i as usize) {
                    if !self.active[i] {
                        continue;
                    }
                    let cols = self.columns(i);
                    self.phi(i, &mut phi);
                    let u = f(i, &cols, &phi);
                    let (src, att) = &cols;
                    for (k, x) in slice.iter_mut().enumerate() {
                        *x += src[k][0] * u[0] + src[k][1] * u[1];
                    }
                    let e = self.p.obs[i].exposure();
                    for k in 0..4 {
                        acc[4 * e + k] += att[k][0] * u[0] + att[k][1] * u[1];
                    }
                    if !phi.is_empty() {
                        let m = &self.p.exposures[e].to_plane;
                        let (gx, gy) = (m[0] * u[0] + m[2] * u[1], m[1] * u[0] + m[3] * u[1]);
                        for &(j, t) in &phi {
                            acc[base + j] += t * gx;
                            acc[base + ca + j] += t * gy;
                        }
                    }
                }
            }
            acc
        };
        let acc = tree_split(lo, hi, src_part, &self.leaf_start, &leaf, &add_vec);
        rest.copy_from_slice(&ranks::across(ranks, acc));
        out
    }

    /// Where the gradients stand in the whole problem's layout, from every rank's share (a gather).
    fn whole(&self, at: &Steps, ranks: &dyn Ranks) -> Steps {
        let joined = |v: &[f64]| -> Vec<f64> {
            let mut all: Vec<f64> = ranks
                .gather_all(&v[..self.att_off])
                .into_iter()
                .flatten()
                .collect();
            all.extend_from_slice(&v[self.att_off..]);
            all
        };
        Steps {
            steps: at.steps,
            x: joined(&at.x),
            r: joined(&at.r),
            d: joined(&at.d),
        }
    }

    /// This rank's share of where the gradients stand in the whole problem's layout (a checkpoint's that does
    /// not fit the problem is a named error).
    fn local(&self, whole: &Steps) -> Result<Steps, SolutionError> {
        let want = self.whole_sources + (self.len - self.att_off);
        if [&whole.x, &whole.r, &whole.d]
            .iter()
            .any(|v| v.len() != want)
        {
            return Err(SolutionError::Checkpoint {
                path: "(resumed)".into(),
                why: format!(
                    "its gradients hold {} unknowns where the problem has {want}",
                    whole.x.len()
                ),
            });
        }
        let mine = |v: &[f64]| -> Vec<f64> {
            let src = self.whole_before..self.whole_before + self.att_off;
            v[src]
                .iter()
                .chain(&v[self.whole_sources..])
                .copied()
                .collect()
        };
        Ok(Steps {
            steps: whole.steps,
            x: mine(&whole.x),
            r: mine(&whole.r),
            d: mine(&whole.d),
        })
    }

    /// `a · b` over all ranks' unknowns: the sources' share leaf by leaf along the tree, then the exposures'
    /// and the calibration's (every rank holds the same).
    fn dot(&self, a: &[f64], b: &[f64], ranks: &dyn Ranks) -> f64 {
        let (lo, hi) = (self.tiles.mine.start, self.tiles.mine.end);
        let leaf = |c: usize| {
            let r = self.leaf_start[c]..self.leaf_start[c + 1];
            dot(&a[r.clone()], &b[r])
        };
        let sources = ranks::tree(lo, hi, &leaf, &|x, y| x + y);
        let sources = ranks::across(ranks, vec![sources])[0];
        sources + dot(&a[self.att_off..], &b[self.att_off..])
    }

    /// `J v` of observation `i` from its columns.
    fn jv(&self, i: usize, cols: &Columns, phi: &[(usize, f64)], v: &[f64]) -> [f64; 2] {
        let o = &self.p.obs[i];
        let (src, att) = cols;
        let (so, n) = (self.src_off[o.source()], self.dims[o.source()]);
        let ao = self.att_off + 4 * o.exposure();
        let mut jv = [0.0; 2];
        for k in 0..n {
            jv[0] += src[k][0] * v[so + k];
            jv[1] += src[k][1] * v[so + k];
        }
        for k in 0..4 {
            jv[0] += att[k][0] * v[ao + k];
            jv[1] += att[k][1] * v[ao + k];
        }
        if !phi.is_empty() {
            let m = &self.p.exposures[o.exposure()].to_plane;
            let (cx, cy) = (self.cal_off, self.cal_off + self.cal_axis);
            let (mut fx, mut fy) = (0.0, 0.0);
            for &(j, f) in phi {
                fx += f * v[cx + j];
                fy += f * v[cy + j];
            }
            jv[0] += m[0] * fx + m[1] * fy;
            jv[1] += m[2] * fx + m[3] * fy;
        }
        jv
    }

    /// The priors' weights and the gauge penalty applied to `v`, added to `out`.
    fn add_priors(&self, v: &[f64], out: &mut [f64]) {
        for (s, r) in self.p.prior.iter().enumerate() {
            let Some(r) = r else { continue };
            for k in 0..self.dims[s] {
                if anchors(r.sigma[k]) {
                    out[self.src_off[s] + k] += v[self.src_off[s] + k] / (r.sigma[k] * r.sigma[k]);
                }
            }
        }
        if self.cal_axis > 0 {
            for row in gauge_rows(self.p.opt.calibration) {
                let g: f64 = row.iter().map(|&(j, w)| w * v[self.cal_off + j]).sum();
                for &(j, w) in &row {
                    out[self.cal_off + j] += self.heavy * w * g;
                }
            }
        }
    }

    /// `N v = Jᵀ W J v + P v`.
    fn apply(&self, v: &[f64], ranks: &dyn Ranks) -> Vec<f64> {
        let mut out = self.accumulate(
            |i, cols, phi| {
                let jv = self.jv(i, cols, phi, v);
                let w = self.weight(i);
                [w * jv[0], w * jv[1]]
            },
            ranks,
        );
        self.add_priors(v, &mut out);
        out
    }

    /// `Jᵀ W r + P (x_ref − x)`, the gauge rows pulling the calibration's gauge to zero.
    fn rhs(&self, state: &State, ranks: &dyn Ranks) -> Vec<f64> {
        let mut b = self.accumulate(
            |i, _, _| {
                let o = &self.p.obs[i];
                let g = &self.p.exposures[o.exposure()];
                let m = self.attitudes[o.exposure()]
                    .apply(g.centre_mas, g.place(&self.params[o.source()]));
                let at = self.p.place_at(&state.cal, i);
                let w = self.weight(i);
                [w * (at[0] - m[0]), w * (at[1] - m[1])]
            },
            ranks,
        );
        // P (x_ref − x): the negated prior term of the current values, plus the references' own
        let mut minus_x = vec![0.0; self.len];
        for (s, n) in self.dims.iter().enumerate() {
            for k in 0..*n {
                minus_x[self.src_off[s] + k] = -self.params[s][k];
            }
        }
        for (j, c) in self.cal_now.iter().enumerate() {
            minus_x[self.cal_off + j] = -c;
        }
        self.add_priors(&minus_x, &mut b);
        for (s, r) in self.p.prior.iter().enumerate() {
            let Some(r) = r else { continue };
            for k in 0..self.dims[s] {
                if anchors(r.sigma[k]) {
                    b[self.src_off[s] + k] += r.params[k] / (r.sigma[k] * r.sigma[k]);
                }
            }
        }
        b
    }

    /// The block-diagonal preconditioner (each block's inverse) and every unknown's formal error from it.
    /// Sets the gauge penalty's weight.
    fn preconditioner(&mut self, ranks: &dyn Ranks) -> Result<Preconditioner, SolutionError> {
        let sources: Vec<Vec<f64>> = (0..self.dims.len())
            .into_par_iter()
            .map(|s| {
                let n = self.dims[s];
                let mut blk = vec![0.0; n * n];
                if n == 0 {
                    return blk;
                }
                for i in self.p.by_source.get(s).iter().map(|i| *i as usize) {
                    if !self.active[i] {
                        continue;
                    }
                    let (src, _) = self.columns(i);
                    let w = self.weight(i);
                    for a in 0..n {
                        for b in 0..n {
                            blk[a * n + b] += w * (src[a][0] * src[b][0] + src[a][1] * src[b][1]);
                        }
                    }
                }
                if let Some(r) = self.p.prior[s] {
                    for k in 0..n {
                        if anchors(r.sigma[k]) {
                            blk[k * n + k] += 1.0 / (r.sigma[k] * r.sigma[k]);
                        }
                    }
                }
                inverse_scaled(&blk, n).unwrap_or_else(|| vec![0.0; n * n])
            })
            .collect();
        let ca = self.cal_axis;
        let n2 = 2 * ca;
        let n_exposures = self.p.exposures.len();
        // each exposure's 4 × 4 and its count of observations, then the calibration's block
        // Σ w (M φ)ᵀ (M φ), summed leaf by leaf over the sources and along the tree across the ranks
        let cal_at = 17 * n_exposures;
        let (lo, hi) = (self.tiles.mine.start, self.tiles.mine.end);
        let leaf = |c: usize| {
            let mut acc = vec![0.0; cal_at + n2 * n2];
            let mut phi = Vec::new();
            for &s in self.tiles.leaf(c) {
                if self.dims[s] == 0 {
                    continue;
                }
                for i in self.p.by_source.get(s).iter().map(|i| *i as usize) {
                    if !self.active[i] {
                        continue;
                    }
                    let e = self.p.obs[i].exposure();
                    let (_, cols) = self.columns(i);
                    let w = self.weight(i);
                    let att = &mut acc[17 * e..17 * e + 17];
                    for a in 0..4 {
                        for b in 0..4 {
                            att[a * 4 + b] +=
                                w * (cols[a][0] * cols[b][0] + cols[a][1] * cols[b][1]);
                        }
                    }
                    att[16] += 1.0;
                    self.phi(i, &mut phi);
                    let m = &self.p.exposures[e].to_plane;
                    let mtm = [
                        m[0] * m[0] + m[2] * m[2],
                        m[0] * m[1] + m[2] * m[3],
                        m[1] * m[0] + m[3] * m[2],
                        m[1] * m[1] + m[3] * m[3],
                    ];
                    let cal = &mut acc[cal_at..];
                    for &(j1, f1) in &phi {
                        for &(j2, f2) in &phi {
                            let t = w * f1 * f2;
                            for ax in 0..2 {
                                for ay in 0..2 {
                                    cal[(ax * ca + j1) * n2 + ay * ca + j2] += mtm[ax * 2 + ay] * t;
                                }
                            }
                        }
                    }
                }
            }
            acc
        };
        let sums = ranks::across(ranks, ranks::tree(lo, hi, &leaf, &add_vec));
        let exposures: Vec<[f64; 16]> = sums[..cal_at]
            .par_chunks(17)
            .map(|att| {
                let inv = (att[16] >= 2.0)
                    .then(|| inverse_scaled(&att[..16], 4))
                    .flatten();
                inv.map_or([0.0; 16], |v| {
                    let mut a = [0.0; 16];
                    a.copy_from_slice(&v);
                    a
                })
            })
            .collect();
        let mut cal = sums[cal_at..].to_vec();
        if ca > 0 {
            self.heavy = (0..n2)
                .map(|i| cal[i * n2 + i])
                .fold(0.0f64, f64::max)
                .max(1e-300);
            for row in gauge_rows(self.p.opt.calibration) {
                for &(i, a) in &row {
                    for &(j, b) in &row {
                        cal[i * n2 + j] += self.heavy * a * b;
                    }
                }
            }
        }
        let cal_inv = if ca > 0 {
            inverse_scaled(&cal, n2).ok_or_else(|| {
                unconstrained(self.p.obs, self.active, self.p.opt.calibration.arrays)
            })?
        } else {
            Vec::new()
        };
        let mut sigma = vec![0.0; self.len];
        for (s, inv) in sources.iter().enumerate() {
            let n = self.dims[s];
            for k in 0..n {
                sigma[self.src_off[s] + k] = inv[k * n + k].max(0.0).sqrt();
            }
        }
        for (e, inv) in exposures.iter().enumerate() {
            for k in 0..4 {
                sigma[self.att_off + 4 * e + k] = inv[k * 4 + k].max(0.0).sqrt();
            }
        }
        for k in 0..n2 {
            sigma[self.cal_off + k] = cal_inv[k * n2 + k].max(0.0).sqrt();
        }
        Ok(Preconditioner {
            sources,
            exposures,
            cal: cal_inv,
            sigma,
        })
    }

    /// Move the state by the linear solution `x`.
    fn update(&self, state: &mut State, x: &[f64]) {
        for (s, src) in state.sources.iter_mut().enumerate() {
            let o = self.src_off[s];
            for k in 0..self.dims[s] {
                src.params[k] += x[o + k];
            }
        }
        for (e, a) in state.attitudes.iter_mut().enumerate() {
            let o = self.att_off + 4 * e;
            a.p += x[o] / self.lever[e];
            a.q += x[o + 1] / self.lever[e];
            a.offset_mas[0] += x[o + 2];
            a.offset_mas[1] += x[o + 3];
        }
        if self.cal_axis > 0 {
            add_flat(&mut state.cal, &x[self.cal_off..]);
        }
    }
}

/// The preconditioner's blocks (inverted) and the formal error of every unknown.
struct Preconditioner {
    sources: Vec<Vec<f64>>,
    exposures: Vec<[f64; 16]>,
    cal: Vec<f64>,
    sigma: Vec<f64>,
}

impl Preconditioner {
    /// `M⁻¹ r`, block by block (the unknowns laid out as `lin` lays them).
    fn apply(&self, lin: &Linear, r: &[f64]) -> Vec<f64> {
        let mut z = vec![0.0; r.len()];
        let mul = |inv: &[f64], n: usize, o: usize, z: &mut [f64]| {
            for a in 0..n {
                z[o + a] = (0..n).map(|b| inv[a * n + b] * r[o + b]).sum();
            }
        };
        for (s, inv) in self.sources.iter().enumerate() {
            mul(inv, lin.dims[s], lin.src_off[s], &mut z);
        }
        for (e, inv) in self.exposures.iter().enumerate() {
            mul(inv, 4, lin.att_off + 4 * e, &mut z);
        }
        let n2 = r.len() - lin.cal_off;
        if n2 > 0 {
            mul(&self.cal, n2, lin.cal_off, &mut z);
        }
        z
    }
}

/// The inverse of a symmetric positive-definite block scaled by its diagonal first (so that the pivot test
/// sees correlations, not units); None when singular.
fn inverse_scaled(m: &[f64], n: usize) -> Option<Vec<f64>> {
    let d: Vec<f64> = (0..n).map(|i| m[i * n + i].sqrt()).collect();
    if d.iter().any(|v| !(*v > 0.0) || !v.is_finite()) {
        return None;
    }
    let scaled: Vec<f64> = (0..n * n).map(|k| m[k] / (d[k / n] * d[k % n])).collect();
    let inv = crate::numerics::linalg::inverse(&scaled, n)?;
    Some((0..n * n).map(|k| inv[k] / (d[k / n] * d[k % n])).collect())
}

/// A calibration's coefficients as one vector: x's per-axis terms (each array's, then the distortion's),
/// then y's.
fn flatten(c: &Calibration) -> Vec<f64> {
    if !c.model.solves() {
        return Vec::new();
    }
    let mut v = Vec::with_capacity(2 * c.model.per_axis());
    for axis in 0..2 {
        for a in &c.arrays {
            v.extend_from_slice(&a[axis]);
        }
        v.extend_from_slice(&c.distortion[axis]);
    }
    v
}

/// Add `dx` (in [`flatten`]'s order) to a calibration's coefficients.
fn add_flat(c: &mut Calibration, dx: &[f64]) {
    let mut k = 0;
    for axis in 0..2 {
        for a in c.arrays.iter_mut() {
            for v in a[axis].iter_mut() {
                *v += dx[k];
                k += 1;
            }
        }
        for v in c.distortion[axis].iter_mut() {
            *v += dx[k];
            k += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solution::calibration::CalibrationModel;

    #[test]
    fn flatten_and_add_flat_keep_one_order() {
        let model = CalibrationModel {
            arrays: 2,
            array_order: 1,
            distortion_order: 2,
        };
        let mut c = Calibration::zero(model, 3000.0);
        let n = 2 * model.per_axis();
        let dx: Vec<f64> = (0..n).map(|k| k as f64).collect();
        add_flat(&mut c, &dx);
        assert_eq!(flatten(&c), dx);
        // x: array 0's three terms, array 1's three, the distortion's three; then y
        assert_eq!(c.arrays[1][0], vec![3.0, 4.0, 5.0]);
        assert_eq!(c.distortion[1], vec![15.0, 16.0, 17.0]);
    }

    #[test]
    fn the_scaled_inverse_inverts_across_units() {
        // a 2 × 2 with diagonal terms 10¹² apart
        let m = [1e12, 3e5, 3e5, 1.0];
        let inv = inverse_scaled(&m, 2).expect("invertible");
        let det = 1e12 - 9e10;
        let want = [1.0 / det, -3e5 / det, -3e5 / det, 1e12 / det];
        for (a, b) in inv.iter().zip(want) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} {b}");
        }
    }
}
