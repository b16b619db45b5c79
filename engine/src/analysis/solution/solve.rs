//! The block-iterative solution: validation, the two blocks, rejection (see the module's documentation).

use super::calibration::{self, Calibration};
use super::{
    Attitude, ExposureGeometry, Method, Observation, Options, Params, Reference, Solution,
    SolutionError, SolvedSource, SourceModel,
};
use crate::numerics::linalg::weighted_lstsq;
use rayon::prelude::*;

/// How far a converged calibration's correction still moves from step to step: its rounding, mas.
const CALIBRATION_ROUNDING_MAS: f64 = 1e-5;

/// Solve `n_sources` sources and every exposure's attitude from `obs`, anchored by `refs`.
pub fn solve(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> Result<Solution, SolutionError> {
    validate(obs, exposures, refs, n_sources, opt)?;
    let mut by_source = vec![Vec::new(); n_sources];
    let mut by_exposure = vec![Vec::new(); exposures.len()];
    for (i, o) in obs.iter().enumerate() {
        by_source[o.source].push(i);
        by_exposure[o.exposure].push(i);
    }
    let mut prior: Vec<Option<&Reference>> = vec![None; n_sources];
    for r in refs {
        prior[r.source] = Some(r);
    }
    let mut active = vec![true; obs.len()];
    // start: every exposure's attitude from the reference sources alone (the frame right from the start),
    // then, with a calibration, the instrument's from them too, and the attitudes again
    let ref_params: Vec<Option<Params>> = prior.iter().map(|r| r.map(|r| r.params)).collect();
    let mut cal = Calibration::zero(opt.calibration, opt.focal_norm_px);
    let mut pos: Vec<[f64; 2]> = obs.iter().map(|o| [o.xi_mas, o.eta_mas]).collect();
    let start_attitudes = |pos: &[[f64; 2]], previous: Option<&[Attitude]>| -> Vec<Attitude> {
        (0..exposures.len())
            .map(|e| {
                attitude_block(
                    pos,
                    obs,
                    &by_exposure[e],
                    &exposures[e],
                    &ref_params,
                    &active,
                )
                .or(previous.map(|p| p[e]))
                .unwrap_or(Attitude::IDENTITY)
            })
            .collect()
    };
    let mut attitudes = start_attitudes(&pos, None);
    if opt.calibration.solves() {
        // the arrays' affine terms alone from the references: a start the full model refines
        let start = calibration::CalibrationModel {
            array_order: 1,
            distortion_order: 0,
            ..opt.calibration
        };
        let places = places_of(obs, exposures, &ref_params);
        if let Some((c, att)) = calibration::fit_with_attitudes(
            start,
            opt.focal_norm_px,
            obs,
            exposures,
            &places,
            &active,
        ) {
            cal = c.extended_to(opt.calibration);
            pos = corrected(obs, exposures, &cal);
            for (a, n) in attitudes.iter_mut().zip(att) {
                if let Some(n) = n {
                    *a = n;
                }
            }
        }
    }
    // mas per focal-plane px (for the calibration's share of the convergence test)
    let mas_per_px = exposures.first().map_or(1.0, |g| {
        (g.to_plane[0] * g.to_plane[3] - g.to_plane[1] * g.to_plane[2])
            .abs()
            .sqrt()
    });
    let problem = Problem {
        obs,
        exposures,
        by_source: &by_source,
        by_exposure: &by_exposure,
        prior: &prior,
        opt,
        mas_per_px,
    };
    let mut state = State {
        sources: vec![unsolved(); n_sources],
        attitudes,
        cal,
        pos,
    };
    let (mut iterations, mut rejected) = (0, 0);
    let mut converged = true;
    for _round in 0..opt.max_rejection_rounds.max(1) {
        let (its, this_round) = match opt.method {
            Method::Block => block_iterate(&problem, &mut state, &active)?,
            Method::ConjugateGradient => super::cg::iterate(&problem, &mut state, &active)?,
        };
        iterations += its;
        converged = this_round;
        if opt.clip_sigma <= 0.0 {
            break;
        }
        // each source's worst observation beyond the clip goes (one per round: an outlier drags its source,
        // and with it the residuals of the source's good observations); a rejected one that now fits returns
        let mut worst: Vec<Option<(usize, f64)>> = vec![None; n_sources];
        let mut changed = 0;
        for (i, o) in obs.iter().enumerate() {
            let Some((rx, ry)) = residual(
                state.pos[i],
                &exposures[o.exposure],
                &state.attitudes[o.exposure],
                &state.sources[o.source],
            ) else {
                continue;
            };
            let z = rx.abs().max(ry.abs()) / o.sigma_mas;
            if !active[i] {
                if z <= opt.clip_sigma {
                    active[i] = true;
                    rejected -= 1;
                    changed += 1;
                }
            } else if z > opt.clip_sigma && worst[o.source].is_none_or(|(_, w)| z > w) {
                worst[o.source] = Some((i, z));
            }
        }
        for (i, _) in worst.into_iter().flatten() {
            active[i] = false;
            rejected += 1;
            changed += 1;
        }
        if changed == 0 {
            break;
        }
    }
    // χ² per source and overall
    let mut chi2_total = 0.0;
    let mut n_terms = 0usize;
    for (i, o) in obs.iter().enumerate() {
        if !active[i] {
            continue;
        }
        if let Some((rx, ry)) = residual(
            state.pos[i],
            &exposures[o.exposure],
            &state.attitudes[o.exposure],
            &state.sources[o.source],
        ) {
            let c = (rx * rx + ry * ry) / (o.sigma_mas * o.sigma_mas);
            state.sources[o.source].chi2 += c;
            chi2_total += c;
            n_terms += 2;
        }
    }
    let priors: usize = refs
        .iter()
        .map(|r| r.sigma.iter().filter(|s| anchors(**s)).count())
        .sum();
    let unknowns = n_sources * opt.model.len() + 4 * exposures.len() + opt.calibration.unknowns();
    // no degree of freedom left: no χ² to report
    let dof = (n_terms + priors).saturating_sub(unknowns);
    Ok(Solution {
        sources: state.sources,
        attitudes: state.attitudes,
        calibration: state.cal,
        iterations,
        converged,
        rejected,
        chi2_per_dof: if dof > 0 {
            chi2_total / dof as f64
        } else {
            f64::NAN
        },
    })
}

/// What every iteration reads: the observations, their exposures, who sees what, the priors, the knobs.
pub(super) struct Problem<'a> {
    pub obs: &'a [Observation],
    pub exposures: &'a [ExposureGeometry],
    pub by_source: &'a [Vec<usize>],
    pub by_exposure: &'a [Vec<usize>],
    pub prior: &'a [Option<&'a Reference>],
    pub opt: &'a Options,
    /// mas per focal-plane px (for the calibration's share of the block iteration's convergence test).
    pub mas_per_px: f64,
}

/// What the iterations move: the sources, the attitudes, the calibration, and every observation's place
/// with the calibration's correction removed (`pos`, mas).
pub(super) struct State {
    pub sources: Vec<SolvedSource>,
    pub attitudes: Vec<Attitude>,
    pub cal: Calibration,
    pub pos: Vec<[f64; 2]>,
}

/// Every source's block with the attitudes and the calibration held (`state.pos` already corrected).
pub(super) fn source_pass(p: &Problem, state: &State, active: &[bool]) -> Vec<SolvedSource> {
    (0..p.by_source.len())
        .into_par_iter()
        .map(|s| {
            source_block(
                &state.pos,
                p.obs,
                &p.by_source[s],
                p.exposures,
                &state.attitudes,
                p.prior[s],
                active,
                p.opt.model,
            )
        })
        .collect()
}

/// The block iteration (Gauss–Seidel over the blocks): sources with the instrument held, then the instrument
/// with the sources held, until no source and no exposure moves by more than `tolerance_mas`. Returns the
/// alternations and whether it reached the tolerance.
fn block_iterate(
    p: &Problem,
    state: &mut State,
    active: &[bool],
) -> Result<(usize, bool), SolutionError> {
    let (obs, exposures, opt) = (p.obs, p.exposures, p.opt);
    for iteration in 1..=opt.max_iterations.max(1) {
        let new_sources = source_pass(p, state, active);
        let params: Vec<Option<Params>> = new_sources
            .iter()
            .map(|s| s.params[0].is_finite().then_some(s.params))
            .collect();
        // the instrument: the attitudes alone, or with the calibration in one block
        let mut new_cal = None;
        let new_attitudes: Vec<Attitude> = if opt.calibration.solves() {
            let places = places_of(obs, exposures, &params);
            let (c, att) = calibration::fit_with_attitudes(
                opt.calibration,
                opt.focal_norm_px,
                obs,
                exposures,
                &places,
                active,
            )
            .ok_or_else(|| unconstrained(obs, active, opt.calibration.arrays))?;
            new_cal = Some(c);
            att.into_iter()
                .zip(&state.attitudes)
                .map(|(n, old)| n.unwrap_or(*old))
                .collect()
        } else {
            (0..exposures.len())
                .into_par_iter()
                .map(|e| {
                    attitude_block(
                        &state.pos,
                        obs,
                        &p.by_exposure[e],
                        &exposures[e],
                        &params,
                        active,
                    )
                    .unwrap_or(state.attitudes[e])
                })
                .collect()
        };
        let moved_sources = state
            .sources
            .iter()
            .zip(&new_sources)
            .map(|(a, b)| {
                (a.params[0] - b.params[0])
                    .abs()
                    .max((a.params[1] - b.params[1]).abs())
            })
            .fold(
                0.0f64,
                |m, v| if v.is_nan() { f64::INFINITY } else { m.max(v) },
            );
        let moved_attitudes = state
            .attitudes
            .iter()
            .zip(&new_attitudes)
            .map(|(a, b)| {
                // how far the change moves the exposure's farthest-reaching point: its offset, and the
                // turn and scale over 10⁶ mas (a focal plane's reach)
                let dpq = (a.p - b.p).abs() + (a.q - b.q).abs();
                (a.offset_mas[0] - b.offset_mas[0]).abs()
                    + (a.offset_mas[1] - b.offset_mas[1]).abs()
                    + dpq * 1e6
            })
            .fold(0.0f64, f64::max);
        state.sources = new_sources;
        state.attitudes = new_attitudes;
        let mut moved_calibration = 0.0;
        if let Some(c) = new_cal {
            moved_calibration = c.moved_px(&state.cal) * p.mas_per_px;
            state.cal = c;
            state.pos = corrected(obs, exposures, &state.cal);
        }
        // the calibration's terms settle to their rounding (≈ 10⁻¹⁰ of their size: 10⁻⁵ mas), which
        // can lie above the tolerance
        if moved_sources.max(moved_attitudes) <= opt.tolerance_mas
            && moved_calibration <= opt.tolerance_mas.max(CALIBRATION_ROUNDING_MAS)
        {
            return Ok((iteration, true));
        }
    }
    Ok((opt.max_iterations.max(1), false))
}

/// Does a reference error `sigma` constrain its parameter?
pub(super) fn anchors(sigma: f64) -> bool {
    sigma > 0.0 && sigma.is_finite()
}

fn unsolved() -> SolvedSource {
    SolvedSource {
        params: [f64::NAN; 5],
        sigma: [f64::NAN; 5],
        observations: 0,
        chi2: 0.0,
    }
}

/// Observed (at `p`, the calibration removed) minus modelled, mas (None for an unsolved source).
fn residual(
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

/// Every observation's place with the calibration's correction removed, mas.
pub(super) fn corrected(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    cal: &Calibration,
) -> Vec<[f64; 2]> {
    obs.par_iter()
        .map(|o| {
            let d = cal.correction_mas(o, &exposures[o.exposure]);
            [o.xi_mas - d[0], o.eta_mas - d[1]]
        })
        .collect()
}

/// Every observation's source place at its exposure's epoch, mas; None where its source has no parameters.
fn places_of(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    params: &[Option<Params>],
) -> Vec<Option<[f64; 2]>> {
    obs.par_iter()
        .map(|o| {
            params[o.source]
                .as_ref()
                .map(|p| exposures[o.exposure].place(p))
        })
        .collect()
}

/// The error of a calibration that cannot be fitted: the first array with fewer than 3 kept observations,
/// else `arrays` (a distortion term).
pub(super) fn unconstrained(obs: &[Observation], active: &[bool], arrays: usize) -> SolutionError {
    let mut n = vec![0usize; arrays];
    for (o, on) in obs.iter().zip(active) {
        if *on && o.array < arrays {
            n[o.array] += 1;
        }
    }
    SolutionError::CalibrationUnconstrained(n.iter().position(|c| *c < 3).unwrap_or(arrays))
}

/// One source's parameters from its observations (each turned back through its exposure's attitude) and its
/// reference entry; a source whose full model is singular (too few epochs) gets its position only, with the
/// reference's (or zero) motion.
fn source_block(
    pos: &[[f64; 2]],
    obs: &[Observation],
    mine: &[usize],
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
        for &i in mine.iter().filter(|i| active[**i]) {
            let o = &obs[i];
            let g = &exposures[o.exposure];
            let a = &attitudes[o.exposure];
            let s = a.invert(g.centre_mas, pos[i]);
            let weight = (a.p * a.p + a.q * a.q) / (o.sigma_mas * o.sigma_mas);
            for axis in 0..2 {
                let full = [
                    if axis == 0 { 1.0 } else { 0.0 },
                    if axis == 1 { 1.0 } else { 0.0 },
                    if axis == 0 { g.t_yr } else { 0.0 },
                    if axis == 1 { g.t_yr } else { 0.0 },
                    g.parallax_factor[axis],
                ];
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
    mine: &[usize],
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    active: &[bool],
) -> usize {
    let mut t: Vec<f64> = mine
        .iter()
        .filter(|i| active[**i])
        .map(|&i| exposures[obs[i].exposure].t_yr)
        .collect();
    if t.is_empty() {
        return 0;
    }
    t.sort_by(f64::total_cmp);
    1 + t.windows(2).filter(|w| w[1] - w[0] > EPOCH_GAP_YR).count()
}

/// One exposure's attitude from the sources it sees (those with parameters), by linear least squares in
/// (p, q, a_ξ, a_η); the lever arms are scaled to order 1 for the conditioning.
fn attitude_block(
    pos: &[[f64; 2]],
    obs: &[Observation],
    mine: &[usize],
    g: &ExposureGeometry,
    params: &[Option<Params>],
    active: &[bool],
) -> Option<Attitude> {
    let mut pairs = Vec::with_capacity(mine.len());
    for &i in mine.iter().filter(|i| active[**i]) {
        let o = &obs[i];
        if let Some(p) = &params[o.source] {
            let s = g.place(p);
            pairs.push((
                [s[0] - g.centre_mas[0], s[1] - g.centre_mas[1]],
                [pos[i][0] - g.centre_mas[0], pos[i][1] - g.centre_mas[1]],
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

/// Every input checked before anything is solved.
fn validate(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> Result<(), SolutionError> {
    let cm = opt.calibration;
    if !(opt.tolerance_sigma > 0.0 && opt.tolerance_sigma < 1.0) {
        return Err(SolutionError::Knob {
            field: "tolerance_sigma",
            value: opt.tolerance_sigma,
            allowed: "0 < tolerance_sigma < 1 (a fraction of each unknown's formal error)",
        });
    }
    if !(opt.tolerance_mas > 0.0 && opt.tolerance_mas.is_finite()) {
        return Err(SolutionError::Knob {
            field: "tolerance_mas",
            value: opt.tolerance_mas,
            allowed: "a finite step > 0 mas",
        });
    }
    if !(opt.focal_norm_px.is_finite() && opt.focal_norm_px > 0.0) {
        return Err(SolutionError::CalibrationModel {
            field: "focal_norm_px",
            value: opt.focal_norm_px,
            allowed: "a finite length > 0 px",
        });
    }
    if !(1..=2).contains(&cm.array_order) {
        return Err(SolutionError::CalibrationModel {
            field: "array_order",
            value: cm.array_order as f64,
            allowed: "1 (affine) or 2 (quadratic)",
        });
    }
    let lowest = if cm.arrays > 0 { cm.array_order + 1 } else { 2 };
    if cm.distortion_order != 0
        && (cm.distortion_order < lowest || cm.distortion_order > calibration::MAX_DISTORTION_ORDER)
    {
        return Err(SolutionError::CalibrationModel {
            field: "distortion_order",
            value: cm.distortion_order as f64,
            allowed: "0 (none), or from one above the arrays' own order to 5",
        });
    }
    if cm.arrays > 64 {
        return Err(SolutionError::CalibrationModel {
            field: "arrays",
            value: cm.arrays as f64,
            allowed: "0 … 64",
        });
    }
    if let Some(e) = exposures.iter().position(|g| {
        cm.solves()
            && (!g.to_plane.iter().all(|v| v.is_finite())
                || calibration::inverse2(&g.to_plane).is_none())
    }) {
        return Err(SolutionError::CalibrationModel {
            field: "to_plane (a singular or non-finite focal-plane map) of exposure",
            value: e as f64,
            allowed: "an invertible finite 2 × 2 matrix",
        });
    }
    if cm.distortion_order > 0 {
        let spread = |k: usize| {
            let (lo, hi) = exposures
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), g| {
                    (lo.min(g.centre_mas[k]), hi.max(g.centre_mas[k]))
                });
            hi - lo
        };
        let spread_mas = spread(0).max(spread(1));
        // a dither smaller than an arcsecond moves a source by ≈ 2 px over the focal plane: nothing to see
        if !(spread_mas >= 1000.0) {
            return Err(SolutionError::DistortionUnconstrained { spread_mas });
        }
    }
    let mut seen = std::collections::HashSet::with_capacity(obs.len());
    let mut observed = vec![0usize; n_sources];
    for (index, o) in obs.iter().enumerate() {
        // the focal-plane position only where a calibration reads it
        let focal: &[(&'static str, f64)] = if cm.solves() {
            &[
                ("focal_px[0]", o.focal_px[0]),
                ("focal_px[1]", o.focal_px[1]),
            ]
        } else {
            &[]
        };
        for &(field, value) in [("xi_mas", o.xi_mas), ("eta_mas", o.eta_mas)]
            .iter()
            .chain(focal)
        {
            if !value.is_finite() {
                return Err(SolutionError::NotFinite {
                    index,
                    field,
                    value,
                    extra: "",
                });
            }
        }
        if !(o.sigma_mas.is_finite() && o.sigma_mas > 0.0) {
            return Err(SolutionError::NotFinite {
                index,
                field: "sigma_mas",
                value: o.sigma_mas,
                extra: " and > 0",
            });
        }
        if cm.arrays > 0 && o.array >= cm.arrays {
            return Err(SolutionError::OutOfRange {
                index,
                what: "array",
                value: o.array,
                limit: cm.arrays - 1,
            });
        }
        if o.exposure >= exposures.len() {
            return Err(SolutionError::OutOfRange {
                index,
                what: "exposure",
                value: o.exposure,
                limit: exposures.len().saturating_sub(1),
            });
        }
        if o.source >= n_sources {
            return Err(SolutionError::OutOfRange {
                index,
                what: "source",
                value: o.source,
                limit: n_sources.saturating_sub(1),
            });
        }
        if !seen.insert((o.exposure, o.source)) {
            return Err(SolutionError::Duplicate {
                source_id: o.source,
                exposure: o.exposure,
            });
        }
        observed[o.source] += 1;
    }
    let anchored: Vec<bool> = {
        let mut a = vec![false; n_sources];
        for r in refs {
            if r.source < n_sources && anchors(r.sigma[0]) && anchors(r.sigma[1]) {
                a[r.source] = true;
            }
        }
        a
    };
    let n_anchored = anchored.iter().filter(|a| **a).count();
    if n_anchored < 2 {
        return Err(SolutionError::TooFewReferences(n_anchored));
    }
    // each exposure must see ≥ 2 sources tied to something beyond it
    let mut tied = vec![0usize; exposures.len()];
    for o in obs {
        if anchored[o.source] || observed[o.source] >= 2 {
            tied[o.exposure] += 1;
        }
    }
    if let Some(e) = tied.iter().position(|n| *n < 2) {
        return Err(SolutionError::NoOverlap(e));
    }
    if opt.model == SourceModel::Full {
        let (lo, hi) = exposures
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), g| {
                (lo.min(g.t_yr), hi.max(g.t_yr))
            });
        if !(hi - lo > 1e-3) {
            return Err(SolutionError::Degenerate { span_yr: hi - lo });
        }
        let with_motion = refs
            .iter()
            .filter(|r| (2..5).all(|k| anchors(r.sigma[k])))
            .count();
        if with_motion < 2 {
            return Err(SolutionError::FrameUnanchored(
                "the proper motions and parallaxes of a multi-epoch solution",
            ));
        }
    }
    Ok(())
}
