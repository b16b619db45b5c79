//! The blocks of the solution: what every iteration reads ([`Problem`]) and moves ([`State`]), each source's
//! fit with the instrument held, each exposure's attitude with the sources held — the block iteration's steps
//! and the conjugate gradients' preconditioner alike.

use super::calibration::Calibration;
use super::groups::Groups;
use super::{
    Attitude, ExposureGeometry, Observation, Options, Params, Reference, SolutionError,
    SolvedSource, SourceModel,
};
use crate::numerics::linalg::weighted_lstsq;
use rayon::prelude::*;

/// What every iteration reads: the observations, their exposures, who sees what, the priors, the knobs.
pub(super) struct Problem<'a> {
    pub obs: &'a [Observation],
    pub exposures: &'a [ExposureGeometry],
    pub by_source: &'a Groups,
    pub by_exposure: &'a Groups,
    pub prior: &'a [Option<&'a Reference>],
    pub opt: &'a Options,
    /// mas per focal-plane px (for the calibration's share of the block iteration's convergence test).
    pub mas_per_px: f64,
}

impl Problem<'_> {
    /// Observation `i`'s place with the calibration's correction removed, mas (computed where it is needed,
    /// not held: 16 bytes an observation saved).
    pub fn place_at(&self, cal: &Calibration, i: usize) -> [f64; 2] {
        corrected_at(self.obs, self.exposures, cal, i)
    }
}

/// Observation `i`'s place with the calibration's correction removed, mas.
pub(super) fn corrected_at(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    cal: &Calibration,
    i: usize,
) -> [f64; 2] {
    let o = &obs[i];
    if !cal.model.solves() {
        return [o.xi_mas, o.eta_mas];
    }
    let d = cal.correction_mas(o, &exposures[o.exposure()]);
    [o.xi_mas - d[0], o.eta_mas - d[1]]
}

/// What the iterations move: the sources, the attitudes and the calibration.
pub(super) struct State {
    pub sources: Vec<SolvedSource>,
    pub attitudes: Vec<Attitude>,
    pub cal: Calibration,
}

/// Every source's block with the attitudes and the calibration held.
pub(super) fn source_pass(p: &Problem, state: &State, active: &[bool]) -> Vec<SolvedSource> {
    (0..p.by_source.len())
        .into_par_iter()
        .map(|s| fit_source(p, state, active, s))
        .collect()
}

/// Source `s`'s block with the attitudes and the calibration held.
pub(super) fn fit_source(p: &Problem, state: &State, active: &[bool], s: usize) -> SolvedSource {
    source_block(
        &state.cal,
        p.obs,
        p.by_source.get(s),
        p.exposures,
        &state.attitudes,
        p.prior[s],
        active,
        p.opt.model,
    )
}

/// Does a reference error `sigma` constrain its parameter?
pub(super) fn anchors(sigma: f64) -> bool {
    sigma > 0.0 && sigma.is_finite()
}

pub(super) fn unsolved() -> SolvedSource {
    SolvedSource {
        params: [f64::NAN; 5],
        sigma: [f64::NAN; 5],
        observations: 0,
        chi2: 0.0,
    }
}

/// Observed (at `p`, the calibration removed) minus modelled, mas (None for an unsolved source).
pub(super) fn residual(
    p: [f64; 2],
    g: &ExposureGeometry,
    a: &Attitude,
    s: &SolvedSource,
) -> Option<(f64, f64)> {
    if !s.params[0].is_finite() {
        return None;
    }
    let m = a.apply(g.centre_mas, g.place(&s.params));
    Some((p[0] - m[0], p[1] - m[1]))
}

/// Observation `i`'s source place at its exposure's epoch, mas; None where its source has no parameters.
pub(super) fn places_of(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    params: &[Option<Params>],
    i: usize,
) -> Option<[f64; 2]> {
    let o = &obs[i];
    params[o.source()]
        .as_ref()
        .map(|p| exposures[o.exposure()].place(p))
}

/// The error of a calibration that cannot be fitted: the first array with fewer than 3 kept observations,
/// else `arrays` (a distortion term).
pub(super) fn unconstrained(obs: &[Observation], active: &[bool], arrays: usize) -> SolutionError {
    let mut n = vec![0usize; arrays];
    for (o, on) in obs.iter().zip(active) {
        if *on && o.array() < arrays {
            n[o.array()] += 1;
        }
    }
    SolutionError::CalibrationUnconstrained(n.iter().position(|c| *c < 3).unwrap_or(arrays))
}

/// The derivatives of a source's place along `axis` at exposure `g`'s epoch with respect to its five
/// parameters (ξ₀, η₀, μ_ξ, μ_η, ϖ): `(1, 0, t, 0, P_ξ)` or `(0, 1, 0, t, P_η)`.
pub(super) fn design_row(g: &ExposureGeometry, axis: usize) -> [f64; 5] {
    [
        if axis == 0 { 1.0 } else { 0.0 },
        if axis == 1 { 1.0 } else { 0.0 },
        if axis == 0 { g.t_yr } else { 0.0 },
        if axis == 1 { g.t_yr } else { 0.0 },
        g.parallax_factor[axis],
    ]
}

/// One source's parameters from its observations (each turned back through its exposure's attitude) and its
/// reference entry; a source whose full model is singular (too few epochs) gets its position only, with the
/// reference's (or zero) motion.
pub(super) fn source_block(
    cal: &Calibration,
    obs: &[Observation],
    mine: &[u32],
    exposures: &[ExposureGeometry],
    attitudes: &[Attitude],
    prior: Option<&Reference>,
    active: &[bool],
    model: SourceModel,
) -> SolvedSource {
    // the normal equations accumulated in place (no per-source buffers: this runs for every source in every
    // iteration), row by row in the order weighted least squares would take them
    let fit = |n: usize, fixed: &Params| -> Option<SolvedSource> {
        let (mut ata, mut atb, mut rows) = ([0.0; 25], [0.0; 5], 0usize);
        let mut add = |row: &[f64], y: f64, w: f64| {
            for a in 0..n {
                atb[a] += w * row[a] * y;
                for b in 0..n {
                    ata[a * n + b] += w * row[a] * row[b];
                }
            }
            rows += 1;
        };
        let mut used = 0;
        for i in mine.iter().map(|i| *i as usize).filter(|i| active[*i]) {
            let o = &obs[i];
            let g = &exposures[o.exposure()];
            let a = &attitudes[o.exposure()];
            let s = a.invert(g.centre_mas, corrected_at(obs, exposures, cal, i));
            let weight = (a.p * a.p + a.q * a.q) / (o.sigma_mas * o.sigma_mas);
            for axis in 0..2 {
                let full = design_row(g, axis);
                // the parameters this model does not solve are moved to the left-hand side
                let known: f64 = (n..5).map(|k| full[k] * fixed[k]).sum();
                add(&full[..n], s[axis] - known, weight);
            }
            used += 1;
        }
        if let Some(r) = prior {
            for k in 0..n {
                if anchors(r.sigma[k]) {
                    let mut row = [0.0; 5];
                    row[k] = 1.0;
                    add(&row[..n], r.params[k], 1.0 / (r.sigma[k] * r.sigma[k]));
                }
            }
        }
        if rows < n {
            return None;
        }
        let normal = &ata[..n * n];
        let beta = crate::numerics::linalg::solve(normal, &atb[..n], n)?;
        let cov = crate::numerics::linalg::inverse(normal, n)?;
        let mut params = *fixed;
        let mut sigma = [f64::NAN; 5];
        for k in 0..n {
            params[k] = beta[k];
            sigma[k] = cov[k * n + k].max(0.0).sqrt();
        }
        Some(SolvedSource {
            params,
            sigma,
            observations: used,
            chi2: 0.0,
        })
    };
    let fixed = prior.map_or([0.0; 5], |r| {
        let mut f = [0.0; 5];
        f[2..].copy_from_slice(&r.params[2..]);
        f
    });
    // what its epochs can give: five parameters from three epochs or more (clusters of observations more
    // than EPOCH_GAP_YR apart), position and proper motion from two (the parallax then its reference's, or
    // 0), position alone from one
    // in the full model a reference with motions enters as priors on all five, whatever the epochs: its
    // proper motion and parallax then carry their errors into the reference-epoch position instead of being
    // taken as exact (the position model takes them as they are: its position is the observations' epoch's,
    // carried back by them)
    let priors_on_motion = prior.is_some_and(|r| (2..5).all(|k| anchors(r.sigma[k])));
    let n = match (model, priors_on_motion) {
        (SourceModel::Position, _) => 2,
        (SourceModel::Full, true) => 5,
        (SourceModel::Full, false) => match epochs(mine, obs, exposures, active) {
            0 | 1 => 2,
            2 => 4,
            _ => 5,
        },
    };
    fit(n, &fixed)
        .or_else(|| (n > 2).then(|| fit(2, &fixed)).flatten())
        .unwrap_or_else(unsolved)
}

/// Observations further apart in time than this belong to different epochs, years (≈ 18 days: a visit's
/// exposures are hours to days apart, visits months).
const EPOCH_GAP_YR: f64 = 0.05;

/// How many epochs a source's kept observations span.
fn epochs(
    mine: &[u32],
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    active: &[bool],
) -> usize {
    let mut t: Vec<f64> = mine
        .iter()
        .map(|i| *i as usize)
        .filter(|i| active[*i])
        .map(|i| exposures[obs[i].exposure()].t_yr)
        .collect();
    if t.is_empty() {
        return 0;
    }
    t.sort_by(f64::total_cmp);
    1 + t.windows(2).filter(|w| w[1] - w[0] > EPOCH_GAP_YR).count()
}

/// One exposure's attitude from the sources it sees (those with parameters), by linear least squares in
/// (p, q, a_ξ, a_η); the lever arms are scaled to order 1 for the conditioning.
pub(super) fn attitude_block(
    cal: &Calibration,
    obs: &[Observation],
    mine: &[u32],
    g: &ExposureGeometry,
    params: &[Option<Params>],
    active: &[bool],
) -> Option<Attitude> {
    let mut pairs = Vec::with_capacity(mine.len());
    for i in mine.iter().map(|i| *i as usize).filter(|i| active[*i]) {
        let o = &obs[i];
        if let Some(p) = &params[o.source()] {
            let s = g.place(p);
            let d = cal.correction_mas(o, g);
            pairs.push((
                [s[0] - g.centre_mas[0], s[1] - g.centre_mas[1]],
                [
                    o.xi_mas - d[0] - g.centre_mas[0],
                    o.eta_mas - d[1] - g.centre_mas[1],
                ],
                1.0 / (o.sigma_mas * o.sigma_mas),
            ));
        }
    }
    if pairs.len() < 2 {
        return None;
    }
    let scale = pairs
        .iter()
        .map(|(d, _, _)| d[0].abs().max(d[1].abs()))
        .fold(1.0f64, f64::max);
    let (mut design, mut y, mut w) = (Vec::new(), Vec::new(), Vec::new());
    for (d, o, weight) in &pairs {
        let (dx, dy) = (d[0] / scale, d[1] / scale);
        design.extend_from_slice(&[dx, -dy, 1.0, 0.0]);
        y.push(o[0]);
        w.push(*weight);
        design.extend_from_slice(&[dy, dx, 0.0, 1.0]);
        y.push(o[1]);
        w.push(*weight);
    }
    let (beta, _) = weighted_lstsq(&design, &y, &w, 4)?;
    Some(Attitude {
        p: beta[0] / scale,
        q: beta[1] / scale,
        offset_mas: [beta[2], beta[3]],
    })
}
