//! The solution: validation, the start, the iteration (the block iteration here, the conjugate gradients in
//! [`super::cg`]), rejection and χ² (see the module's documentation).

use super::blocks::{
    Problem, State, anchors, attitude_block, places_of, residual, source_pass, unconstrained,
    unsolved,
};
use super::calibration::{self, Calibration};
use super::checkpoint;
use super::groups::Groups;
use super::ranks::Ranks;
use super::{
    Attitude, ExposureGeometry, Method, Observation, Options, Params, Reference, Solution,
    SolutionError, SourceModel,
};
use rayon::prelude::*;

/// How far a converged calibration's correction still moves from step to step: its rounding, mas.
const CALIBRATION_ROUNDING_MAS: f64 = 1e-5;

/// Solve `n_sources` sources and every exposure's attitude from `obs`, anchored by `refs` — on this thread's
/// ranks ([`super::ranks::world`]: this process alone unless the `jsim-mpi` binary set MPI's).
pub fn solve(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> Result<Solution, SolutionError> {
    solve_on(
        obs,
        exposures,
        refs,
        n_sources,
        opt,
        &*super::ranks::world(),
    )
}

/// [`solve`] on `ranks` (every rank calls it with the same input): the conjugate gradients share the sources
/// out by sky tile ([`super::ranks`]); every rank returns the same solution, the same bits as one process's.
/// The block iteration runs on one rank only.
pub fn solve_on(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
    ranks: &dyn Ranks,
) -> Result<Solution, SolutionError> {
    solve_with(obs, exposures, refs, n_sources, opt, ranks, None)
}

/// A solution's checkpoint ([`super::checkpoint`]): where it is kept and resumed from (a file:
/// `io::checkpoint::FileStore`).
#[derive(Clone, Copy)]
pub struct Checkpointing<'a> {
    pub store: &'a dyn checkpoint::CheckpointStore,
    /// Stop with [`SolutionError::Interrupted`] after writing this many checkpoints (None: never) — how the
    /// tests interrupt a solution where they choose.
    pub interrupt_after: Option<usize>,
}

/// Writes the checkpoints of one solution (rank 0 writes; every rank counts).
struct Saver<'a> {
    ck: Checkpointing<'a>,
    fingerprint: u64,
    writes: bool,
    saved: usize,
}

impl Saver<'_> {
    fn save(
        &mut self,
        at: checkpoint::At,
        state: &State,
        active: &[bool],
        steps: Option<&super::cg::Steps>,
    ) -> Result<(), SolutionError> {
        if self.writes {
            let bytes = checkpoint::encode(self.fingerprint, &at, state, active, steps);
            self.ck
                .store
                .save(&bytes)
                .map_err(|e| checkpoint::checkpoint_error(&self.ck.store.name(), &e))?;
        }
        self.saved += 1;
        if self.ck.interrupt_after == Some(self.saved) {
            return Err(SolutionError::Interrupted(self.saved));
        }
        Ok(())
    }

    /// The checkpoint of this very input, if one was saved (another input's is a named error).
    fn load(&self, opt: &Options) -> Result<Option<checkpoint::Saved>, SolutionError> {
        let name = self.ck.store.name();
        self.ck
            .store
            .load()
            .map_err(|e| checkpoint::checkpoint_error(&name, &e))?
            .map(|bytes| {
                let template = Calibration::zero(opt.calibration, opt.focal_norm_px);
                checkpoint::decode(&bytes, &name, self.fingerprint, &template)
            })
            .transpose()
    }
}

/// [`solve_on`] with a checkpoint: resumed from it when it is there (of this very input: else a named
/// error), written at each relinearisation and each rejection round, removed when the solution is done.
pub fn solve_with(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
    ranks: &dyn Ranks,
    checkpointing: Option<Checkpointing>,
) -> Result<Solution, SolutionError> {
    super::ranks::check(ranks.size())?;
    if ranks.size() > 1 && opt.method == Method::Block {
        return Err(SolutionError::Knob {
            field: "ranks (with the block iteration)",
            value: ranks.size() as f64,
            allowed: "1: the block iteration, the reference, runs on one rank (conjugate gradients on several)",
        });
    }
    validate(obs, exposures, refs, n_sources, opt)?;
    let skipped = unlinked_exposures(obs, exposures.len(), refs, n_sources)?;
    anchored_groups(obs, exposures.len(), refs, n_sources, &skipped)?;
    let by_source = Groups::new(n_sources, obs.len(), |i| obs[i].source());
    let by_exposure = Groups::new(exposures.len(), obs.len(), |i| obs[i].exposure());
    no_duplicates(obs, &by_source)?;
    let mut prior: Vec<Option<&Reference>> = vec![None; n_sources];
    for r in refs {
        prior[r.source] = Some(r);
    }
    // an exposure tied to nothing else is reported and left out: its observations are not used
    let mut left_out = vec![false; exposures.len()];
    for &e in &skipped {
        left_out[e] = true;
    }
    let mut active: Vec<bool> = obs.iter().map(|o| !left_out[o.exposure()]).collect();
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
    let (mut iterations, mut rejected) = (0, 0);
    let mut converged = true;
    let mut saver = checkpointing.map(|ck| Saver {
        ck,
        fingerprint: checkpoint::fingerprint(obs, exposures, refs, n_sources, opt),
        writes: ranks.rank() == 0,
        saved: 0,
    });
    let (mut first_round, mut resume) = (0, None);
    let saved = match &saver {
        Some(sv) => sv.load(opt)?,
        None => None,
    };
    // from the checkpoint where there is one, else the start from the references
    let mut state = match saved {
        Some(back) => {
            active = back.active;
            (iterations, rejected) = (back.at.iterations_before, back.at.rejected);
            first_round = back.at.round;
            resume = back.at.in_round.map(|k| (k, back.steps));
            back.state
        }
        None => {
            let (attitudes, cal) = start(obs, exposures, &by_exposure, &prior, opt, &active);
            State {
                sources: vec![unsolved(); n_sources],
                attitudes,
                cal,
            }
        }
    };
    for round in first_round..opt.max_rejection_rounds.max(1) {
        let (its, this_round) = match opt.method {
            Method::Block => block_iterate(&problem, &mut state, &active)?,
            Method::ConjugateGradient => {
                let before = (iterations, rejected);
                let active = &active;
                let mut save = saver.as_mut().map(|sv| {
                    move |st: &State, k: usize, steps: Option<&super::cg::Steps>| {
                        let at = checkpoint::At {
                            round,
                            iterations_before: before.0,
                            rejected: before.1,
                            in_round: Some(k),
                        };
                        sv.save(at, st, active, steps)
                    }
                });
                let save = save.as_mut().map(|f| f as &mut super::cg::SaveFn);
                super::cg::iterate(&problem, &mut state, active, ranks, resume.take(), save)?
            }
        };
        iterations += its;
        converged = this_round;
        if opt.clip_sigma <= 0.0 {
            break;
        }
        let (changed, now_rejected) =
            reject(&problem, &state, &mut active, &left_out, opt.clip_sigma);
        rejected = now_rejected;
        if changed == 0 {
            break;
        }
        if let Some(sv) = saver.as_mut() {
            let next = checkpoint::At {
                round: round + 1,
                iterations_before: iterations,
                rejected,
                in_round: None,
            };
            sv.save(next, &state, &active, None)?;
        }
    }
    if let Some(sv) = &saver
        && sv.writes
    {
        // done: nothing to resume
        sv.ck.store.clear();
    }
    Ok(solution_of(
        &problem,
        state,
        &active,
        refs,
        skipped,
        (iterations, converged, rejected),
    ))
}

/// The solution from the final state: a left-out exposure's attitude NaN, and χ² per degree of freedom
/// counting the references' anchoring priors (NaN without a degree of freedom left).
fn solution_of(
    problem: &Problem<'_>,
    mut state: State,
    active: &[bool],
    refs: &[Reference],
    skipped: Vec<usize>,
    (iterations, converged, rejected): (usize, bool, usize),
) -> Solution {
    let opt = problem.opt;
    let n_sources = problem.prior.len();
    let (chi2_total, n_terms) = chi2(problem, &mut state, active);
    let excess = match opt.excess {
        super::ExcessNoise::None => Vec::new(),
        super::ExcessNoise::PerStare | super::ExcessNoise::PerVisit => {
            super::excess::apply(problem, &mut state, active)
        }
    };
    let priors: usize = refs
        .iter()
        .map(|r| r.sigma.iter().filter(|s| anchors(**s)).count())
        .sum();
    let unknowns = n_sources * opt.model.len()
        + 4 * (problem.exposures.len() - skipped.len())
        + opt.calibration.unknowns();
    // a left-out exposure has no attitude
    for &e in &skipped {
        state.attitudes[e] = Attitude {
            p: f64::NAN,
            q: f64::NAN,
            offset_mas: [f64::NAN; 2],
        };
    }
    // no degree of freedom left: no χ² to report
    let dof = (n_terms + priors).saturating_sub(unknowns);
    Solution {
        sources: state.sources,
        attitudes: state.attitudes,
        skipped_exposures: skipped,
        calibration: state.cal,
        iterations,
        converged,
        rejected,
        chi2_per_dof: if dof > 0 {
            chi2_total / dof as f64
        } else {
            f64::NAN
        },
        excess,
    }
}

/// The start: every exposure's attitude from the reference sources alone (the frame right from the start),
/// then, with a calibration, the instrument's from them too, and the attitudes again.
fn start(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    by_exposure: &Groups,
    prior: &[Option<&Reference>],
    opt: &Options,
    active: &[bool],
) -> (Vec<Attitude>, Calibration) {
    let ref_params: Vec<Option<Params>> = prior.iter().map(|r| r.map(|r| r.params)).collect();
    let mut cal = Calibration::zero(opt.calibration, opt.focal_norm_px);
    let mut attitudes: Vec<Attitude> = (0..exposures.len())
        .map(|e| {
            attitude_block(
                &cal,
                obs,
                by_exposure.get(e),
                &exposures[e],
                &ref_params,
                active,
            )
            .unwrap_or(Attitude::IDENTITY)
        })
        .collect();
    if opt.calibration.solves() {
        // the arrays' affine terms alone from the references: a start the full model refines
        let start = calibration::CalibrationModel {
            array_order: 1,
            distortion_order: 0,
            ..opt.calibration
        };
        if let Some((c, att)) = calibration::fit_with_attitudes(
            start,
            opt.focal_norm_px,
            obs,
            exposures,
            by_exposure,
            |i| places_of(obs, exposures, &ref_params, i),
            active,
        ) {
            cal = c.extended_to(opt.calibration);
            for (a, n) in attitudes.iter_mut().zip(att) {
                if let Some(n) = n {
                    *a = n;
                }
            }
        }
    }
    (attitudes, cal)
}

/// Each source's χ² (added to it) and the total over the observations kept, with its count of terms.
fn chi2(p: &Problem, state: &mut State, active: &[bool]) -> (f64, usize) {
    let mut chi2_total = 0.0;
    let mut n_terms = 0usize;
    for (i, o) in p.obs.iter().enumerate() {
        if !active[i] {
            continue;
        }
        if let Some((rx, ry)) = residual(
            p.place_at(&state.cal, i),
            &p.exposures[o.exposure()],
            &state.attitudes[o.exposure()],
            &state.sources[o.source()],
        ) {
            let c = (rx * rx + ry * ry) / (o.sigma_mas * o.sigma_mas);
            state.sources[o.source()].chi2 += c;
            chi2_total += c;
            n_terms += 2;
        }
    }
    (chi2_total, n_terms)
}

/// One round of rejection: each source's worst kept observation beyond `clip` σ goes (one per round: an
/// outlier drags its source, and with it the residuals of the source's good observations), and a rejected
/// one that now fits returns. The observations of a left-out exposure (`left_out`) are neither: they stay out.
/// Returns the observations that changed and those now rejected.
fn reject(
    p: &Problem,
    state: &State,
    active: &mut [bool],
    left_out: &[bool],
    clip: f64,
) -> (usize, usize) {
    let mut worst: Vec<Option<(usize, f64)>> = vec![None; p.by_source.len()];
    let mut changed = 0;
    for (i, o) in p.obs.iter().enumerate() {
        if left_out[o.exposure()] {
            continue;
        }
        let Some((rx, ry)) = residual(
            p.place_at(&state.cal, i),
            &p.exposures[o.exposure()],
            &state.attitudes[o.exposure()],
            &state.sources[o.source()],
        ) else {
            continue;
        };
        let z = rx.abs().max(ry.abs()) / o.sigma_mas;
        if !active[i] {
            if z <= clip {
                active[i] = true;
                changed += 1;
            }
        } else if z > clip && worst[o.source()].is_none_or(|(_, w)| z > w) {
            worst[o.source()] = Some((i, z));
        }
    }
    for (i, _) in worst.into_iter().flatten() {
        active[i] = false;
        changed += 1;
    }
    let rejected = p
        .obs
        .iter()
        .zip(active.iter())
        .filter(|(o, on)| !**on && !left_out[o.exposure()])
        .count();
    (changed, rejected)
}

/// A source seen twice by one exposure is a named error (each source's exposures sorted: no hash set of
/// every pair).
fn no_duplicates(obs: &[Observation], by_source: &Groups) -> Result<(), SolutionError> {
    let found = (0..by_source.len()).into_par_iter().find_map_first(|s| {
        let mut e: Vec<usize> = by_source
            .get(s)
            .iter()
            .map(|&i| obs[i as usize].exposure())
            .collect();
        e.sort_unstable();
        e.windows(2).find(|w| w[0] == w[1]).map(|w| (s, w[0]))
    });
    match found {
        Some((source_id, exposure)) => Err(SolutionError::Duplicate {
            source_id,
            exposure,
        }),
        None => Ok(()),
    }
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
            let (c, att) = calibration::fit_with_attitudes(
                opt.calibration,
                opt.focal_norm_px,
                obs,
                exposures,
                p.by_exposure,
                |i| places_of(obs, exposures, &params, i),
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
                        &state.cal,
                        obs,
                        p.by_exposure.get(e),
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

/// The exposures that see fewer than two sources tied to something beyond them (the reference catalogue, or
/// another exposure), in rising order: their attitudes are undetermined, so they are reported and left out —
/// and with them what only they tied, until nothing changes. Every exposure unlinked is an error.
fn unlinked_exposures(
    obs: &[Observation],
    n_exposures: usize,
    refs: &[Reference],
    n_sources: usize,
) -> Result<Vec<usize>, SolutionError> {
    let mut anchored = vec![false; n_sources];
    for r in refs {
        if r.source < n_sources && anchors(r.sigma[0]) && anchors(r.sigma[1]) {
            anchored[r.source] = true;
        }
    }
    let mut skipped = vec![false; n_exposures];
    loop {
        let mut seen = vec![0usize; n_sources];
        for o in obs.iter().filter(|o| !skipped[o.exposure()]) {
            seen[o.source()] += 1;
        }
        let mut tied = vec![0usize; n_exposures];
        for o in obs.iter().filter(|o| !skipped[o.exposure()]) {
            if anchored[o.source()] || seen[o.source()] >= 2 {
                tied[o.exposure()] += 1;
            }
        }
        let newly: Vec<usize> = (0..n_exposures)
            .filter(|e| !skipped[*e] && tied[*e] < 2)
            .collect();
        if newly.is_empty() {
            break;
        }
        for e in newly {
            skipped[e] = true;
        }
    }
    if n_exposures > 0 && skipped.iter().all(|s| *s) {
        return Err(SolutionError::NoOverlap(n_exposures));
    }
    Ok((0..n_exposures).filter(|e| skipped[*e]).collect())
}

/// Every group of exposures tied together (through the sources they share) must hold at least two anchored
/// reference sources: a group tied to no reference — a patch of sky whose reference stars are missing — has
/// its own frame (shift, turn, scale, and with time their rates) undetermined, a singular gauge. Such a group
/// is a named error listing its exposures (the left-out `skipped` ones aside).
fn anchored_groups(
    obs: &[Observation],
    n_exposures: usize,
    refs: &[Reference],
    n_sources: usize,
    skipped: &[usize],
) -> Result<(), SolutionError> {
    // union–find over exposures (0 … E − 1) and sources (E …)
    let mut parent: Vec<usize> = (0..n_exposures + n_sources).collect();
    fn root(parent: &mut [usize], mut k: usize) -> usize {
        while parent[k] != k {
            parent[k] = parent[parent[k]];
            k = parent[k];
        }
        k
    }
    let mut left_out = vec![false; n_exposures];
    for &e in skipped {
        left_out[e] = true;
    }
    for o in obs.iter().filter(|o| !left_out[o.exposure()]) {
        let (a, b) = (
            root(&mut parent, o.exposure()),
            root(&mut parent, n_exposures + o.source()),
        );
        if a != b {
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut anchors_in = vec![0usize; n_exposures + n_sources];
    for r in refs {
        if r.source < n_sources && anchors(r.sigma[0]) && anchors(r.sigma[1]) {
            let g = root(&mut parent, n_exposures + r.source);
            anchors_in[g] += 1;
        }
    }
    let mut members: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for e in (0..n_exposures).filter(|e| !left_out[*e]) {
        let g = root(&mut parent, e);
        members.entry(g).or_default().push(e);
    }
    if members.len() < 2 {
        // one group: the overall count of references is validate's to check
        return Ok(());
    }
    match members.iter().find(|(g, _)| anchors_in[**g] < 2) {
        Some((g, exposures)) => Err(SolutionError::UnanchoredGroup {
            exposures: exposures.clone(),
            anchors: anchors_in[*g],
        }),
        None => Ok(()),
    }
}

/// Every input checked before anything is solved.
fn validate(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> Result<(), SolutionError> {
    validate_options(exposures, opt)?;
    validate_observations(obs, exposures, n_sources, opt)?;
    validate_anchors(exposures, refs, n_sources, opt)
}

/// The knobs, the calibration model, and whether the exposures' pointings can constrain a distortion.
fn validate_options(exposures: &[ExposureGeometry], opt: &Options) -> Result<(), SolutionError> {
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
    Ok(())
}

/// Each observation: finite, with its σ, and naming an exposure and a source that exist.
fn validate_observations(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    n_sources: usize,
    opt: &Options,
) -> Result<(), SolutionError> {
    let cm = opt.calibration;
    if obs.len() > u32::MAX as usize {
        return Err(SolutionError::Knob {
            field: "observations (count)",
            value: obs.len() as f64,
            allowed: "at most 2³² − 1 in one solution",
        });
    }
    for (index, o) in obs.iter().enumerate() {
        // the focal-plane position only where a calibration reads it
        let focal: &[(&'static str, f64)] = if cm.solves() {
            &[
                ("focal_px[0]", o.focal_px()[0]),
                ("focal_px[1]", o.focal_px()[1]),
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
        if cm.arrays > 0 && o.array() >= cm.arrays {
            return Err(SolutionError::OutOfRange {
                index,
                what: "array",
                value: o.array(),
                limit: cm.arrays - 1,
            });
        }
        if o.exposure() >= exposures.len() {
            return Err(SolutionError::OutOfRange {
                index,
                what: "exposure",
                value: o.exposure(),
                limit: exposures.len().saturating_sub(1),
            });
        }
        if o.source() >= n_sources {
            return Err(SolutionError::OutOfRange {
                index,
                what: "source",
                value: o.source(),
                limit: n_sources.saturating_sub(1),
            });
        }
    }
    Ok(())
}

/// The frame's anchor: at least two reference sources with a usable σ, and, for five parameters, two with their
/// motions, over exposures that span time.
fn validate_anchors(
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> Result<(), SolutionError> {
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
