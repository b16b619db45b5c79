//! The astrometric solution's cost against its size (`jsim bench --parts solution`), and the synthetic
//! sequences it runs on (the solution's tests draw theirs here too): N sources × E exposures (5 × 5
//! pointings a third of a field apart, E / 25 epochs half a year apart; attitude errors of 200 mas, 10″
//! and 2 ppm; 1-mas measurements; every 8th source in a reference catalogue with a survey's errors; with
//! the instrument's calibration — four arrays' quadratic terms and a cubic distortion — drawn and solved,
//! or without), each solved with the default options. Each row's time is the solution's; its error the rms
//! of the solved positions against the synthetic truth over the rms of their own σ (1 when the covariance
//! describes the scatter), the note the observations, iterations, the inputs' memory and the process's
//! peak memory so far.

use super::bench::{BenchError, BenchRow};
use crate::rng::{self, Stream};
use crate::solution::{
    Attitude, Calibration, CalibrationModel, ExposureGeometry, Method, Observation, Options,
    Params, Reference,
};
use rand::RngExt;
use rand_distr::{Distribution, Normal};
use std::time::Instant;

/// How a synthetic sequence is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticSpec {
    pub sources: usize,
    /// Pointings per side of the square pattern, a third of a field (±0.125°) apart.
    pub pointings_per_side: usize,
    /// Epochs: seven seasons half a year apart (three years), more epochs revisiting them within a
    /// fortnight; each observes the whole pattern.
    pub epochs: usize,
    /// Measurement noise per axis, mas (0: exact; the σ the solution is told is then 1 mas).
    pub obs_sigma_mas: f64,
    /// The reference catalogue's errors (every 8th source), in `Params`' order.
    pub ref_sigma: Params,
    /// The instrument's calibration the observations carry (drawn: array offsets of 10 px and turns of
    /// 0.1° — the mission's plate-model priors — and distortion terms of 1 px, 1σ); NONE: none.
    pub calibration: CalibrationModel,
    pub seed: u64,
}

impl SyntheticSpec {
    /// The benchmark's sequences: 5 × 5 pointings over four epochs (100 exposures), 1-mas measurements, a
    /// reference catalogue with 0.3 mas, 0.1 mas/yr and 0.05 mas errors.
    pub fn bench(sources: usize, seed: u64) -> Self {
        Self {
            sources,
            pointings_per_side: 5,
            epochs: 4,
            obs_sigma_mas: 1.0,
            ref_sigma: [0.3, 0.3, 0.1, 0.1, 0.05],
            calibration: CalibrationModel::NONE,
            seed,
        }
    }
}

/// A synthetic sequence and the truth it was drawn from.
#[derive(Debug, Clone, PartialEq)]
pub struct Synthetic {
    pub params: Vec<Params>,
    pub attitudes: Vec<Attitude>,
    pub exposures: Vec<ExposureGeometry>,
    pub obs: Vec<Observation>,
    pub refs: Vec<Reference>,
    /// The calibration the observations carry.
    pub calibration: Calibration,
}

/// The synthetic focal plane's scale, mas per px (JASMINE's), and its map to the plane: east to the left.
pub const SYNTHETIC_MAS_PER_PX: f64 = 472.1;
const TO_PLANE: [f64; 4] = [-SYNTHETIC_MAS_PER_PX, 0.0, 0.0, SYNTHETIC_MAS_PER_PX];

/// Draw a synthetic sequence: sources uniform over the pattern's reach (never beyond a field's edge), proper
/// motions N(0, 5 mas/yr), parallaxes U(0.05, 1) mas; parallax factors (sin 2πt, 0.4 cos 2πt); attitude
/// errors of 200 mas per axis, 10″ roll and 2 ppm scale (1σ); each source measured in every exposure whose
/// field holds it.
pub fn synthetic(spec: &SyntheticSpec) -> Synthetic {
    let mut r = rng::stream(spec.seed, Stream::Solution, 0);
    let unit = Normal::new(0.0, 1.0).ok();
    let gauss = |r: &mut rand_chacha::ChaCha8Rng, s: f64| unit.map_or(0.0, |d| d.sample(r)) * s;
    let half_field = 0.125 * 3.6e6;
    let step = 2.0 * half_field / 3.0;
    let side = spec.pointings_per_side.max(1);
    let reach = (side - 1) as f64 * step / 2.0;
    let half_region = reach + half_field * 0.9;
    let params: Vec<Params> = (0..spec.sources)
        .map(|_| {
            [
                r.random_range(-half_region..half_region),
                r.random_range(-half_region..half_region),
                gauss(&mut r, 5.0),
                gauss(&mut r, 5.0),
                r.random_range(0.05..1.0),
            ]
        })
        .collect();
    let exposures = synthetic_exposures(spec, step, reach);
    let attitudes: Vec<Attitude> = exposures
        .iter()
        .map(|_| {
            let roll = gauss(&mut r, 10.0 / 206_264.8);
            let k = gauss(&mut r, 2e-6);
            Attitude {
                p: (1.0 + k) * roll.cos(),
                q: (1.0 + k) * roll.sin(),
                offset_mas: [gauss(&mut r, 200.0), gauss(&mut r, 200.0)],
            }
        })
        .collect();
    let mut calibration = Calibration::zero(
        spec.calibration,
        crate::solution::calibration::DEFAULT_FOCAL_NORM_PX,
    );
    for a in &mut calibration.arrays {
        let turn = gauss(&mut r, 0.1f64.to_radians())
            * crate::solution::calibration::DEFAULT_FOCAL_NORM_PX;
        let (bx, by) = (gauss(&mut r, 10.0), gauss(&mut r, 10.0));
        a[0][..3].copy_from_slice(&[bx, 0.0, -turn]);
        a[1][..3].copy_from_slice(&[by, turn, 0.0]);
        // higher terms (a displaced array's share of the distortion): 0.05 px
        for axis in a.iter_mut() {
            for c in axis.iter_mut().skip(3) {
                *c = gauss(&mut r, 0.05);
            }
        }
    }
    for axis in &mut calibration.distortion {
        for d in axis.iter_mut() {
            *d = gauss(&mut r, 1.0);
        }
    }
    let mut obs = Vec::new();
    for (e, g) in exposures.iter().enumerate() {
        for (s, p) in params.iter().enumerate() {
            let place = [
                p[0] + p[2] * g.t_yr + p[4] * g.parallax_factor[0],
                p[1] + p[3] * g.t_yr + p[4] * g.parallax_factor[1],
            ];
            if (place[0] - g.centre_mas[0]).abs() > half_field
                || (place[1] - g.centre_mas[1]).abs() > half_field
            {
                continue;
            }
            // written out here rather than through `Attitude::apply`, so that the tests check the solution
            // against a transform of their own: o = c + (1 + k) R(θ) (s − c) + a
            let a = &attitudes[e];
            let (d0, d1) = (place[0] - g.centre_mas[0], place[1] - g.centre_mas[1]);
            let (scale, (sin, cos)) = (a.p.hypot(a.q), a.q.atan2(a.p).sin_cos());
            // the design focal-plane position (east to the left), its array the quadrant, and what the
            // instrument adds there, written out
            let focal_px = [-d0 / SYNTHETIC_MAS_PER_PX, d1 / SYNTHETIC_MAS_PER_PX];
            let array = usize::from(focal_px[0] >= 0.0) + 2 * usize::from(focal_px[1] >= 0.0);
            let (u, v) = (
                focal_px[0] / crate::solution::calibration::DEFAULT_FOCAL_NORM_PX,
                focal_px[1] / crate::solution::calibration::DEFAULT_FOCAL_NORM_PX,
            );
            let dfx = instrument_px(spec, &calibration, array, (u, v));
            let o = [
                g.centre_mas[0] + scale * (cos * d0 - sin * d1) + a.offset_mas[0]
                    - SYNTHETIC_MAS_PER_PX * dfx[0],
                g.centre_mas[1]
                    + scale * (sin * d0 + cos * d1)
                    + a.offset_mas[1]
                    + SYNTHETIC_MAS_PER_PX * dfx[1],
            ];
            let plane_mas = [
                o[0] + gauss(&mut r, spec.obs_sigma_mas),
                o[1] + gauss(&mut r, spec.obs_sigma_mas),
            ];
            let sigma_mas = if spec.obs_sigma_mas > 0.0 {
                spec.obs_sigma_mas
            } else {
                1.0
            };
            obs.push(Observation::new(
                e, s, plane_mas, sigma_mas, array, focal_px,
            ));
        }
    }
    let refs = (0..spec.sources)
        .step_by(8)
        .map(|s| {
            let mut p = params[s];
            for (k, v) in p.iter_mut().enumerate() {
                *v += gauss(&mut r, spec.ref_sigma[k]);
            }
            Reference {
                source: s,
                params: p,
                sigma: spec.ref_sigma.map(|v| v.max(1e-6)),
            }
        })
        .collect();
    Synthetic {
        params,
        attitudes,
        exposures,
        obs,
        refs,
        calibration,
    }
}

/// The synthetic survey's exposures: `pointings_per_side`² pointings `step` mas apart, centred, per epoch;
/// epochs in seasons half a year apart (spring and autumn) over three years, the first seven one season each,
/// later ones revisiting the seasons, spread over a fortnight within each (one epoch in the solution's sense:
/// no gap of EPOCH_GAP_YR).
fn synthetic_exposures(spec: &SyntheticSpec, step: f64, reach: f64) -> Vec<ExposureGeometry> {
    let side = spec.pointings_per_side.max(1);
    let mut exposures = Vec::new();
    let visits = spec.epochs.div_ceil(7).max(1);
    for epoch in 0..spec.epochs {
        let (season, visit) = (epoch % 7, epoch / 7);
        for k in 0..side * side {
            let t = 0.5 * season as f64 + 0.04 * visit as f64 / visits as f64 + 0.002 * k as f64;
            let phase = std::f64::consts::TAU * t;
            exposures.push(ExposureGeometry {
                t_yr: t,
                parallax_factor: [phase.sin(), 0.4 * phase.cos()],
                centre_mas: [
                    (k % side) as f64 * step - reach,
                    (k / side) as f64 * step - reach,
                ],
                to_plane: TO_PLANE,
                // each exposure a pointing of its own epoch: a stare of one
                stare: exposures.len(),
                visit: epoch,
            });
        }
    }
    exposures
}

/// What the instrument adds at the normalised focal-plane position (u, v) of `array`, focal-plane px: the
/// array's own terms and the distortion, written out (not through the solution's calibration).
fn instrument_px(
    spec: &SyntheticSpec,
    calibration: &Calibration,
    array: usize,
    (u, v): (f64, f64),
) -> [f64; 2] {
    let mut dfx = [0.0; 2];
    if let Some(c) = calibration.arrays.get(array) {
        for (m, (p, q)) in spec.calibration.array_terms().into_iter().enumerate() {
            dfx[0] += c[0][m] * u.powi(p) * v.powi(q);
            dfx[1] += c[1][m] * u.powi(p) * v.powi(q);
        }
    }
    for (m, (p, q)) in spec.calibration.monomials().into_iter().enumerate() {
        dfx[0] += calibration.distortion[0][m] * u.powi(p) * v.powi(q);
        dfx[1] += calibration.distortion[1][m] * u.powi(p) * v.powi(q);
    }
    dfx
}

/// The instrument's calibration of the benchmark (and of the tests that solve one): four arrays with their
/// own terms to order 2 and a global distortion of order 3, as `jsim solve` solves a sequence's.
pub const CALIBRATED: CalibrationModel = CalibrationModel {
    arrays: 4,
    array_order: 2,
    distortion_order: 3,
};

/// The process's peak resident memory so far, MiB (Linux: `VmHWM` of /proc/self/status; NaN elsewhere).
pub fn peak_memory_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

/// The rows: one per source count and exposure count (a multiple of 25: the 5 × 5 pattern per epoch), with
/// the calibration `calibration` drawn and solved ([`CalibrationModel::NONE`]: none).
pub fn solution_scaling(
    counts: &[usize],
    exposures: &[usize],
    calibration: CalibrationModel,
    methods: &[Method],
    seed: u64,
) -> Result<Vec<BenchRow>, BenchError> {
    check_sizes(
        counts,
        exposures,
        "--solution-sources",
        "--solution-exposures",
    )?;
    let mut rows = Vec::new();
    for &n in counts {
        for &e in exposures {
            for &m in methods {
                rows.push(one_row(n, e, calibration, m, seed)?);
            }
        }
    }
    Ok(rows)
}

/// A synthetic sequence solved: the draw, its solution, the solution's time (s), the positions' rms error
/// over their rms σ and their rms error (mas) against the draw's truth.
pub struct SyntheticRun {
    pub syn: Synthetic,
    pub sol: crate::solution::Solution,
    pub time_s: f64,
    pub error_over_sigma: f64,
    pub rms_mas: f64,
}

/// Draw the benchmark's synthetic sequence of `n` sources × `n_exposures` (a multiple of 25) with the
/// calibration `calibration` and solve it by `method` (on this thread's ranks: [`crate::solution::ranks::world`]),
/// resumed from and checkpointed to `checkpoint` if given.
pub fn solve_synthetic(
    n: usize,
    n_exposures: usize,
    calibration: CalibrationModel,
    method: Method,
    seed: u64,
    checkpoint: Option<&std::path::Path>,
) -> Result<SyntheticRun, BenchError> {
    check_sizes(&[n], &[n_exposures], "--sources", "--exposures")?;
    let syn = synthetic(&SyntheticSpec {
        epochs: n_exposures / 25,
        calibration,
        ..SyntheticSpec::bench(n, seed)
    });
    let options = Options {
        calibration,
        method,
        // the block iteration's cap as the benchmark has always run it; the gradients stop at their
        // criterion well before theirs
        max_iterations: if method == Method::Block { 500 } else { 5000 },
        ..Options::default()
    };
    let t0 = Instant::now();
    let sol = super::sequence::solution::solve_checkpointed(
        &syn.obs,
        &syn.exposures,
        &syn.refs,
        n,
        &options,
        checkpoint,
    )?;
    let time_s = t0.elapsed().as_secs_f64();
    let (mut err2, mut sig2, mut m) = (0.0, 0.0, 0usize);
    for (s, p) in sol.sources.iter().zip(&syn.params) {
        if s.params[0].is_finite() && s.observations > 0 {
            err2 += (s.params[0] - p[0]).powi(2) + (s.params[1] - p[1]).powi(2);
            sig2 += s.sigma[0].powi(2) + s.sigma[1].powi(2);
            m += 1;
        }
    }
    // no source solved: nothing to report
    let (error_over_sigma, rms_mas) = if m > 0 {
        ((err2 / sig2).sqrt(), (err2 / (2 * m) as f64).sqrt())
    } else {
        (f64::NAN, f64::NAN)
    };
    Ok(SyntheticRun {
        syn,
        sol,
        time_s,
        error_over_sigma,
        rms_mas,
    })
}

/// The sizes' ranges; the errors name the options as the command calls them (`sources`, `exposures`).
fn check_sizes(
    counts: &[usize],
    exposures: &[usize],
    sources_option: &str,
    exposures_option: &str,
) -> Result<(), BenchError> {
    if let Some(e) = exposures
        .iter()
        .find(|e| **e == 0 || **e % 25 != 0 || **e > 10_000)
    {
        return Err(BenchError::Invalid(format!(
            "{exposures_option} {e}: allowed multiples of 25 (the 5 × 5 pattern per epoch) up to 10000"
        )));
    }
    if let Some(n) = counts.iter().find(|n| **n < 100 || **n > 2_000_000) {
        return Err(BenchError::Invalid(format!(
            "{sources_option} {n}: allowed 100 … 2·10⁶"
        )));
    }
    Ok(())
}

fn one_row(
    n: usize,
    n_exposures: usize,
    calibration: CalibrationModel,
    method: Method,
    seed: u64,
) -> Result<BenchRow, BenchError> {
    {
        let run = solve_synthetic(n, n_exposures, calibration, method, seed, None)?;
        let (exposures, obs, sol, time_s) =
            (&run.syn.exposures, &run.syn.obs, &run.sol, run.time_s);
        let (ratio, rms_mas) = (run.error_over_sigma, run.rms_mas);
        let input_mib = (obs.len() * std::mem::size_of::<Observation>()) as f64 / 1048576.0;
        Ok(BenchRow {
            rms_err: ratio,
            astro_mas: rms_mas,
            ..BenchRow::timing(
                "astrometric solution",
                format!(
                    "{n} sources × {} exposures{}, {}",
                    exposures.len(),
                    if calibration == CalibrationModel::NONE {
                        ""
                    } else {
                        ", calibration"
                    },
                    match method {
                        Method::Block => "block iteration",
                        Method::ConjugateGradient => "conjugate gradients",
                    }
                ),
                "cpu".into(),
                n,
                time_s,
                &format!(
                    "{} observations ({input_mib:.0} MiB), {} iterations{}, {} rejected, χ²/dof {:.3}, peak \
                     memory {:.0} MiB; rms error / rms σ of the positions in rms_err, their rms error (mas) in \
                     pos",
                    obs.len(),
                    sol.iterations,
                    if sol.converged {
                        ""
                    } else {
                        " (not converged)"
                    },
                    sol.rejected,
                    sol.chi2_per_dof,
                    peak_memory_mib()
                ),
            )
        })
    }
}
