//! The astrometric solution (`engine::solution`) on synthetic sequences (drawn by
//! `studies::bench_solution::synthetic`, not simulated): sources with known positions, proper motions and
//! parallaxes, exposures with known attitude errors on a 3 × 3 step pattern over four epochs, a reference
//! catalogue with a survey's errors. Noise-free it recovers
//! everything to the solver's tolerance; with noise its own covariance describes its scatter (pulls and χ²
//! at 4σ of their sampling error); outliers are rejected; bad input is named.

use engine::solution::{
    CalibrationModel, Checkpointing, ExposureGeometry, Method, Observation, Options, Params, Ranks,
    Reference, Single, Solution, SolutionError, SourceModel, solve, solve_on, solve_with,
};
use engine::studies::bench_solution::CALIBRATED;
use engine::studies::bench_solution::{Synthetic, SyntheticSpec, synthetic};

/// `n` sources, a 3 × 3 pattern of pointings a third of a field apart at epochs 0, 0.5, 1, 1.5 yr, attitude
/// errors of 200 mas, 10″ roll and 2 ppm scale; every 8th source in a reference catalogue with errors
/// `ref_sigma`; measurements with noise `obs_sigma_mas` (0: exact).
fn sequence(n: usize, obs_sigma_mas: f64, ref_sigma: Params, seed: u64) -> Synthetic {
    synthetic(&SyntheticSpec {
        sources: n,
        pointings_per_side: 3,
        epochs: 4,
        obs_sigma_mas,
        ref_sigma,
        calibration: CalibrationModel::NONE,
        seed,
    })
}

/// The position-only model with the default knobs.
fn pos_only() -> Options {
    Options {
        model: SourceModel::Position,
        ..Options::default()
    }
}

/// Every solved parameter within `tol` (mas, mas/yr) of the truth.
fn assert_sources_within(sol: &Solution, truth: &[Params], tol: f64) {
    for (s, truth) in sol.sources.iter().zip(truth) {
        for k in 0..5 {
            assert!(
                (s.params[k] - truth[k]).abs() < tol,
                "parameter {k}: {} vs {}",
                s.params[k],
                truth[k]
            );
        }
    }
}

#[test]
fn noise_free_it_recovers_sources_attitudes_and_motions() {
    let t = sequence(400, 0.0, [0.0; 5], 1);
    let sol = solve(&t.obs, &t.exposures, &t.refs, 400, &Options::default()).expect("solved");
    assert_sources_within(&sol, &t.params, 1e-5);
    for (a, truth) in sol.attitudes.iter().zip(&t.attitudes) {
        assert!((a.offset_mas[0] - truth.offset_mas[0]).abs() < 1e-5);
        assert!((a.offset_mas[1] - truth.offset_mas[1]).abs() < 1e-5);
        assert!((a.roll_rad() - truth.roll_rad()).abs() < 1e-11);
        assert!((a.scale_error() - truth.scale_error()).abs() < 1e-11);
    }
    assert_eq!(sol.rejected, 0);
    assert!(sol.converged, "{} iterations", sol.iterations);
}

#[test]
fn with_noise_its_own_covariance_describes_its_scatter_and_outliers_go() {
    let n = 1200;
    let mut t = sequence(n, 1.0, [0.3, 0.3, 0.1, 0.1, 0.05], 2);
    // 12 gross outliers (a blend, a cosmic ray): 80 mas off, each in a source observed ≥ 8 times (with
    // fewer, five astrometric parameters absorb much of one bad observation: stated in the docs)
    let mut count = vec![0usize; n];
    for o in &t.obs {
        count[o.source()] += 1;
    }
    let mut hit = std::collections::HashSet::new();
    let mut k = 0;
    for i in (0..t.obs.len()).step_by(997) {
        let s = t.obs[i].source();
        if count[s] >= 8 && hit.insert(s) && k < 12 {
            t.obs[i].xi_mas += 80.0;
            k += 1;
        }
    }
    assert_eq!(k, 12);
    let sol = solve(&t.obs, &t.exposures, &t.refs, n, &Options::default()).expect("solved");
    println!(
        "{} observations, {} iterations, {} rejected, χ²/dof {:.4}",
        t.obs.len(),
        sol.iterations,
        sol.rejected,
        sol.chi2_per_dof
    );
    assert!(sol.converged);
    // the 12 and nothing else (a 5σ excursion among ≈ 10⁵ Gaussian terms: 0.06 expected)
    assert!(
        sol.rejected >= 12 && sol.rejected <= 13,
        "{} rejected",
        sol.rejected
    );
    // χ² per degree of freedom within 4σ of 1 (its sampling error √(2/dof) for Gaussian errors; the 5σ
    // clipping removes ≈ 6 × 10⁻⁷ of a Gaussian's variance)
    let dof = 2.0 * (t.obs.len() - sol.rejected) as f64;
    let tol = 4.0 * (2.0 / dof).sqrt();
    assert!(
        (sol.chi2_per_dof - 1.0).abs() < tol,
        "χ²/dof {}",
        sol.chi2_per_dof
    );
    // the pulls (solved − true)/σ of the sources not in the reference catalogue, around their mean (the
    // frame's common error, which the block covariance leaves out): unit variance within 4σ
    for k in 0..5 {
        let (var, count, m) = pull_variance(&sol, &t.params, k);
        let tol = 4.0 * (2.0 / count as f64).sqrt();
        println!("parameter {k}: pull variance {var:.3} (±{tol:.3}), mean {m:.3}");
        assert!(
            (var - 1.0).abs() < tol,
            "parameter {k}: pull variance {var} over {count} sources (±{tol})"
        );
    }
}

/// Every exposure of the synthetic sequence made a stare of `per_stare` exposures on the same attitude, each
/// observation of a source in a stare sharing one offset N(0, τ²) per axis and carrying its own N(0, σ²),
/// σ told.
fn in_stares(
    t: &Synthetic,
    per_stare: usize,
    sigma_mas: f64,
    tau_mas: f64,
    seed: u64,
) -> Synthetic {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).expect("a unit normal");
    let mut out = t.clone();
    out.exposures = t
        .exposures
        .iter()
        .enumerate()
        .flat_map(|(e, g)| (0..per_stare).map(move |_| ExposureGeometry { stare: e, ..*g }))
        .collect();
    out.attitudes = t
        .attitudes
        .iter()
        .flat_map(|a| std::iter::repeat_n(*a, per_stare))
        .collect();
    out.obs.clear();
    for o in &t.obs {
        let shared = [unit.sample(&mut r) * tau_mas, unit.sample(&mut r) * tau_mas];
        for m in 0..per_stare {
            let xi_mas = o.xi_mas + shared[0] + unit.sample(&mut r) * sigma_mas;
            let eta_mas = o.eta_mas + shared[1] + unit.sample(&mut r) * sigma_mas;
            let mut seen = o.with_exposure(o.exposure() * per_stare + m);
            (seen.xi_mas, seen.eta_mas, seen.sigma_mas) = (xi_mas, eta_mas, sigma_mas);
            out.obs.push(seen);
        }
    }
    out
}

/// The variance of the pulls (solved − true)/σ of parameter `k` over the sources outside the reference
/// catalogue, about their mean; their count and their mean.
fn pull_variance(sol: &Solution, truth: &[Params], k: usize) -> (f64, usize, f64) {
    let pulls: Vec<f64> = sol
        .sources
        .iter()
        .zip(truth)
        .enumerate()
        .filter(|(s, _)| s % 8 != 0)
        .map(|(_, (s, t))| (s.params[k] - t[k]) / s.sigma[k])
        .filter(|p| p.is_finite())
        .collect();
    let m = pulls.iter().sum::<f64>() / pulls.len() as f64;
    let var = pulls.iter().map(|p| (p - m).powi(2)).sum::<f64>() / (pulls.len() - 1) as f64;
    (var, pulls.len(), m)
}

/// An error shared within each stare (τ = 0.8 mas against σ = 1 mas in each of 4 exposures: the stare's
/// mean is 3.6 × noisier than σ/√4 says): the observations' σ alone give pulls of variance ≈ 3.6 in every
/// parameter; the per-stare excess measures τ from the residuals between stares (within 10 % in every bin)
/// and brings every parameter's pull variance to 1 within 4σ of its sampling error, without moving the
/// solution. With τ = 0 it measures ≈ 0 and leaves the σ as they were (within 2 %).
#[test]
fn an_error_shared_within_a_stare_is_measured_and_carried_into_the_sigmas() {
    use engine::solution::ExcessNoise;
    let n = 1200;
    let exact = sequence(n, 0.0, [0.3, 0.3, 0.1, 0.1, 0.05], 7);
    let per_stare = Options {
        excess: ExcessNoise::PerStare,
        ..Options::default()
    };
    let t = in_stares(&exact, 4, 1.0, 0.8, 8);
    let plain = solve(&t.obs, &t.exposures, &t.refs, n, &Options::default()).expect("solved");
    let with = solve(&t.obs, &t.exposures, &t.refs, n, &per_stare).expect("solved");
    assert!(plain.excess.is_empty());
    assert!(!with.excess.is_empty());
    for b in &with.excess {
        println!(
            "σ_obs {:.3} mas: τ {:.3} mas over {} sources",
            b.sigma_obs_mas, b.tau_mas, b.sources
        );
        assert!(
            (b.tau_mas - 0.8).abs() < 0.08,
            "τ {} mas, 0.8 drawn",
            b.tau_mas
        );
    }
    for (a, b) in plain.sources.iter().zip(&with.sources) {
        assert_eq!(a.params, b.params, "the solution itself does not move");
    }
    for k in 0..5 {
        let (before, _, _) = pull_variance(&plain, &exact.params, k);
        let (after, count, _) = pull_variance(&with, &exact.params, k);
        let tol = 4.0 * (2.0 / count as f64).sqrt();
        println!("parameter {k}: pull variance {before:.3} → {after:.3} (±{tol:.3})");
        assert!(before > 2.5, "parameter {k}: {before} without the excess");
        assert!((after - 1.0).abs() < tol, "parameter {k}: {after} (±{tol})");
    }
    // nothing shared: τ ≈ 0 and the σ as they were
    let t0 = in_stares(&exact, 4, 1.0, 0.0, 9);
    let plain0 = solve(&t0.obs, &t0.exposures, &t0.refs, n, &Options::default()).expect("solved");
    let with0 = solve(&t0.obs, &t0.exposures, &t0.refs, n, &per_stare).expect("solved");
    for b in &with0.excess {
        assert!(b.tau_mas < 0.1, "τ {} mas, none drawn", b.tau_mas);
    }
    for (a, b) in plain0.sources.iter().zip(&with0.sources) {
        for k in 0..5 {
            if a.sigma[k].is_finite() {
                assert!(
                    (b.sigma[k] / a.sigma[k] - 1.0).abs() < 0.02,
                    "{} vs {}",
                    b.sigma[k],
                    a.sigma[k]
                );
            }
        }
    }
}

#[test]
fn bad_input_is_named() {
    let t = sequence(200, 0.0, [0.0; 5], 3);
    let opt = Options::default();
    let run = |obs: &[Observation], ex: &[ExposureGeometry], refs: &[Reference], opt: &Options| {
        solve(obs, ex, refs, 200, opt).err()
    };
    let mut bad = t.obs.clone();
    bad[5].eta_mas = f64::NAN;
    assert!(matches!(
        run(&bad, &t.exposures, &t.refs, &opt),
        Some(SolutionError::NotFinite {
            index: 5,
            field: "eta_mas",
            ..
        })
    ));
    let mut dup = t.obs.clone();
    dup.push(dup[7]);
    assert!(matches!(
        run(&dup, &t.exposures, &t.refs, &opt),
        Some(SolutionError::Duplicate { .. })
    ));
    // one epoch cannot give motions
    let first: Vec<Observation> = t
        .obs
        .iter()
        .filter(|o| o.exposure() == 0)
        .copied()
        .collect();
    let e = run(&first, &t.exposures[..1], &t.refs, &opt);
    assert!(matches!(e, Some(SolutionError::Degenerate { .. })), "{e:?}");
    // … but positions, yes
    let pos = Options {
        model: SourceModel::Position,
        ..opt
    };
    let refs0: Vec<Reference> = t.refs.clone();
    assert!(solve(&first, &t.exposures[..1], &refs0, 200, &pos).is_ok());
    // the frame needs two anchors, and a multi-epoch one their motions
    assert!(matches!(
        run(&t.obs, &t.exposures, &t.refs[..1], &opt),
        Some(SolutionError::TooFewReferences(1))
    ));
    let no_motion: Vec<Reference> = t
        .refs
        .iter()
        .map(|r| Reference {
            sigma: [1.0, 1.0, 0.0, 0.0, 0.0],
            ..*r
        })
        .collect();
    assert!(matches!(
        run(&t.obs, &t.exposures, &no_motion, &opt),
        Some(SolutionError::FrameUnanchored(_))
    ));
    // the criterion is a fraction of the formal error
    for tol in [0.0, 1.0, f64::NAN] {
        let e = run(
            &t.obs,
            &t.exposures,
            &t.refs,
            &Options {
                tolerance_sigma: tol,
                ..opt
            },
        );
        assert!(
            matches!(
                e,
                Some(SolutionError::Knob {
                    field: "tolerance_sigma",
                    ..
                })
            ),
            "{e:?}"
        );
    }
}

/// An exposure whose sources nobody else sees and no reference names is left out and reported; the rest is
/// solved as without it.
#[test]
fn an_exposure_tied_to_nothing_is_left_out() {
    let t = sequence(200, 0.0, [0.0; 5], 3);
    let opt = Options::default();
    // an exposure whose sources nobody else sees and no reference names: no overlap
    let mut lonely = t.obs.clone();
    let mut ex = t.exposures.clone();
    ex.push(ExposureGeometry {
        t_yr: 0.2,
        parallax_factor: [0.0, 0.0],
        centre_mas: [5e6, 5e6],
        to_plane: [1.0, 0.0, 0.0, 1.0],
        stare: ex.len(),
        visit: ex.len(),
    });
    for k in 0..5 {
        lonely.push(Observation::new(
            ex.len() - 1,
            190 + k,
            [5e6 + k as f64, 5e6],
            1.0,
            0,
            [0.0, 0.0],
        ));
    }
    // sources 190… are seen elsewhere too: give the lonely exposure fresh ones instead
    let n = 205;
    for (k, o) in lonely.iter_mut().rev().take(5).enumerate() {
        *o = o.with_source(200 + k);
    }
    // … it is left out and reported, its attitude undetermined, its sources unsolved; the rest is solved
    let sol = solve(&lonely, &ex, &t.refs, n, &opt).expect("the rest solved");
    assert_eq!(sol.skipped_exposures, vec![36]);
    // its observations are left out, not rejected as outliers (and never brought back by the rejection)
    assert_eq!(sol.rejected, 0);
    assert!(sol.attitudes[36].p.is_nan() && sol.attitudes[36].offset_mas[0].is_nan());
    assert!(sol.sources[200..].iter().all(|s| s.params[0].is_nan()));
    assert!(sol.sources[..200].iter().all(|s| s.params[0].is_finite()));
    let alone = solve(&t.obs, &t.exposures, &t.refs, 200, &opt).expect("without it");
    assert_eq!(sol.sources[..200], alone.sources[..]);
}

/// Exposures tied to nothing, or a patch of sky tied to no reference star: named errors; with its own
/// reference stars the patch is solved.
#[test]
fn unconnected_exposures_and_patches_are_named() {
    let t = sequence(200, 0.0, [0.0; 5], 3);
    let opt = Options::default();
    // with no exposure tied to another or to the catalogue (every source seen once, no reference seen)
    // nothing can be solved: a named error
    let once: Vec<Observation> = (0..4)
        .map(|k| t.obs[0].with_exposure(k / 2).with_source(10 + k))
        .collect();
    let e = solve(&once, &t.exposures[..2], &t.refs, 200, &pos_only()).err();
    assert!(matches!(e, Some(SolutionError::NoOverlap(2))), "{e:?}");
    // a second patch of sky — its own exposures and sources, tied to one another but not to the first — with
    // no reference star: its frame is undetermined, a named error listing its exposures (36 … 71)
    let e0 = t.exposures.len();
    let mut two = t.obs.clone();
    two.extend(t.obs.iter().map(|o| {
        let mut far = o
            .with_exposure(o.exposure() + e0)
            .with_source(o.source() + 200);
        far.xi_mas += 1e8;
        far
    }));
    let mut ex2 = t.exposures.clone();
    ex2.extend(t.exposures.iter().map(|g| ExposureGeometry {
        centre_mas: [g.centre_mas[0] + 1e8, g.centre_mas[1]],
        stare: g.stare + e0,
        visit: g.visit + e0,
        ..*g
    }));
    let e = solve(&two, &ex2, &t.refs, 400, &opt).expect_err("a singular gauge");
    match &e {
        SolutionError::UnanchoredGroup { exposures, anchors } => {
            assert_eq!(exposures, &(e0..2 * e0).collect::<Vec<_>>());
            assert_eq!(*anchors, 0);
        }
        other => panic!("{other:?}"),
    }
    let msg = e.to_string();
    assert!(
        msg.contains("36, 37") && msg.contains("(36 in all)") && msg.contains("singular gauge"),
        "{msg}"
    );
    // with its own reference stars it is solved
    let mut refs2 = t.refs.clone();
    refs2.extend(t.refs.iter().map(|r| Reference {
        source: r.source + 200,
        params: [
            r.params[0] + 1e8,
            r.params[1],
            r.params[2],
            r.params[3],
            r.params[4],
        ],
        ..*r
    }));
    assert!(solve(&two, &ex2, &refs2, 400, &opt).is_ok());
}

/// Four arrays with offsets of 10 px and turns of 0.1° (the plate model's priors) and a third-order
/// distortion of 1 px terms, on the 3 × 3 pattern.
#[test]
fn noise_free_it_recovers_the_arrays_offsets_and_the_distortion() {
    let t = synthetic(&SyntheticSpec {
        sources: 600,
        pointings_per_side: 3,
        epochs: 4,
        obs_sigma_mas: 0.0,
        ref_sigma: [0.0; 5],
        calibration: CALIBRATED,
        seed: 4,
    });
    // noise-free: the criterion far below the errors a noisy set would have
    let opt = Options {
        calibration: CALIBRATED,
        max_iterations: 5000,
        tolerance_sigma: 1e-7,
        ..Options::default()
    };
    // without the calibration unknowns the sources are wrong by the arrays' offsets (mas …)
    let plain = solve(&t.obs, &t.exposures, &t.refs, 600, &Options::default()).expect("plain");
    let worst = |sol: &Solution| {
        sol.sources
            .iter()
            .zip(&t.params)
            .map(|(s, p)| (s.params[0] - p[0]).abs().max((s.params[1] - p[1]).abs()))
            .fold(0.0f64, f64::max)
    };
    assert!(worst(&plain) > 100.0, "{}", worst(&plain));
    // … with them, right to the solver's tolerance
    let sol = solve(&t.obs, &t.exposures, &t.refs, 600, &opt).expect("solved");
    assert!(sol.converged, "{} iterations", sol.iterations);
    assert_sources_within(&sol, &t.params, 1e-4);
    // the calibration against the drawn one, both in the gauge the attitudes leave (px)
    let mut truth = t.calibration.clone();
    truth.remove_gauge();
    for (a, b) in sol.calibration.arrays.iter().zip(&truth.arrays) {
        for axis in 0..2 {
            for (x, y) in a[axis].iter().zip(&b[axis]) {
                assert!((x - y).abs() < 1e-6, "array term: {x} vs {y}");
            }
        }
    }
    for axis in 0..2 {
        for (a, b) in sol.calibration.distortion[axis]
            .iter()
            .zip(&truth.distortion[axis])
        {
            assert!((a - b).abs() < 1e-6, "distortion: {a} vs {b}");
        }
    }
}

#[test]
fn a_distortion_a_single_pointing_cannot_see_is_named() {
    let t = synthetic(&SyntheticSpec {
        sources: 200,
        pointings_per_side: 1,
        epochs: 2,
        obs_sigma_mas: 0.0,
        ref_sigma: [0.0; 5],
        calibration: CALIBRATED,
        seed: 5,
    });
    let opt = Options {
        calibration: CALIBRATED,
        ..Options::default()
    };
    let e = solve(&t.obs, &t.exposures, &t.refs, 200, &opt).err();
    assert!(
        matches!(e, Some(SolutionError::DistortionUnconstrained { .. })),
        "{e:?}"
    );
    // an array index beyond the model, a distortion order of 1
    let mut bad = t.obs.clone();
    bad[3] = bad[3].with_array(4);
    let arrays_only = Options {
        calibration: CalibrationModel {
            distortion_order: 0,
            ..CALIBRATED
        },
        ..Options::default()
    };
    let e = solve(&bad, &t.exposures, &t.refs, 200, &arrays_only).err();
    assert!(
        matches!(e, Some(SolutionError::OutOfRange { what: "array", .. })),
        "{e:?}"
    );
    let order1 = Options {
        calibration: CalibrationModel {
            distortion_order: 1,
            ..CALIBRATED
        },
        ..Options::default()
    };
    let e = solve(&t.obs, &t.exposures, &t.refs, 200, &order1).err();
    assert!(
        matches!(
            e,
            Some(SolutionError::CalibrationModel {
                field: "distortion_order",
                ..
            })
        ),
        "{e:?}"
    );
}

/// `n` sources on a `side` × `side` pattern over four epochs, 1-mas measurements, the survey's reference
/// errors, the instrument's calibration drawn.
fn noisy_calibrated(n: usize, side: usize, seed: u64) -> Synthetic {
    synthetic(&SyntheticSpec {
        sources: n,
        pointings_per_side: side,
        epochs: 4,
        obs_sigma_mas: 1.0,
        ref_sigma: [0.3, 0.3, 0.1, 0.1, 0.05],
        calibration: CALIBRATED,
        seed,
    })
}

/// The conjugate gradients (the default) and the block iteration solve one least-squares problem: on a noisy
/// sequence with the instrument's calibration, their solutions agree to a small fraction of the formal
/// errors — the gradients in fewer than half the passes over the observations.
#[test]
fn conjugate_gradients_and_the_block_iteration_reach_one_solution() {
    let t = noisy_calibrated(1000, 5, 11);
    let run = |method: Method| {
        let opt = Options {
            calibration: CALIBRATED,
            method,
            max_iterations: 5000,
            ..Options::default()
        };
        solve(&t.obs, &t.exposures, &t.refs, 1000, &opt).expect("solved")
    };
    let (cg, block) = (run(Method::ConjugateGradient), run(Method::Block));
    assert!(cg.converged && block.converged);
    assert_eq!(cg.rejected, block.rejected);
    let mut worst = 0.0f64;
    for (a, b) in cg.sources.iter().zip(&block.sources) {
        for k in 0..5 {
            if a.sigma[k].is_finite() {
                worst = worst.max((a.params[k] - b.params[k]).abs() / a.sigma[k]);
            }
        }
    }
    // the criterion stops each step at 10⁻³ σ; what remains after it is of that order
    assert!(worst < 0.01, "largest difference {worst} σ");
    assert!(
        2 * cg.iterations < block.iterations,
        "{} against {}",
        cg.iterations,
        block.iterations
    );
    assert!((cg.chi2_per_dof - block.chi2_per_dof).abs() < 1e-6);
}

/// The gauge is the reference catalogue's: the same observations seen in a frame turned by 20″ and spinning
/// at 2 mas/yr over the field (every exposure's attitude takes it up) give the same sources, in the
/// catalogue's frame.
#[test]
fn a_turned_and_spinning_input_frame_comes_back_in_the_catalogues() {
    let mut t = sequence(400, 0.0, [0.0; 5], 5);
    let turn_rad = 20.0 / 206_264.8;
    // 2 mas/yr at the pattern's corner (≈ 3 × 10⁵ mas from the origin)
    let spin_rad_per_yr = 2.0 / 3.0e5;
    for o in &mut t.obs {
        let phi = turn_rad + spin_rad_per_yr * t.exposures[o.exposure()].t_yr;
        let (s, c) = phi.sin_cos();
        (o.xi_mas, o.eta_mas) = (c * o.xi_mas - s * o.eta_mas, s * o.xi_mas + c * o.eta_mas);
    }
    let opt = Options {
        tolerance_sigma: 1e-7,
        ..Options::default()
    };
    let sol = solve(&t.obs, &t.exposures, &t.refs, 400, &opt).expect("solved");
    assert!(sol.converged);
    assert_sources_within(&sol, &t.params, 1e-5);
    // the frame the observations carried is in the attitudes: each one's roll is the truth's plus the turn
    for (a, (truth, g)) in sol
        .attitudes
        .iter()
        .zip(t.attitudes.iter().zip(&t.exposures))
    {
        let want = truth.roll_rad() + turn_rad + spin_rad_per_yr * g.t_yr;
        assert!(
            (a.roll_rad() - want).abs() < 1e-11,
            "{} vs {want}",
            a.roll_rad()
        );
    }
}

/// The solution does not depend on the machine: its sums run over chunks fixed by the problem, added in
/// their order, so one thread and two give the same solution bit for bit.
#[test]
fn one_thread_and_two_give_the_same_solution_bit_for_bit() {
    let t = noisy_calibrated(600, 3, 12);
    let opt = Options {
        calibration: CALIBRATED,
        ..Options::default()
    };
    let with = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool")
            .install(|| solve(&t.obs, &t.exposures, &t.refs, 600, &opt).expect("solved"))
    };
    let (one, two) = (with(1), with(2));
    assert_eq!(one, two);
    assert!(one.converged);
}

/// The distributed solution (each rank solving its own sky tiles, the rest reduced along one fixed tree)
/// gives one process's solution bit for bit, on 2 and 4 ranks — here threads talking over channels, as MPI
/// ranks do (the MPI build's own test, `engine/tests/mpi.rs`, runs `mpirun`).
#[test]
fn two_and_four_ranks_give_one_process_solution_bit_for_bit() {
    let t = noisy_calibrated(600, 3, 12);
    let opt = Options {
        calibration: CALIBRATED,
        ..Options::default()
    };
    let one = solve(&t.obs, &t.exposures, &t.refs, 600, &opt).expect("solved");
    assert!(one.converged && one.iterations > 20, "{}", one.iterations);
    for size in [2, 4] {
        let all = engine::testkit::on_thread_ranks(size, |r| {
            solve_on(&t.obs, &t.exposures, &t.refs, 600, &opt, r).expect("solved")
        });
        for (rank, got) in all.iter().enumerate() {
            assert_eq!(got, &one, "rank {rank} of {size}");
        }
    }
    // three ranks (not a power of two) and the block iteration on two are named errors
    let three = engine::testkit::thread_ranks(3);
    let e = solve_on(&t.obs, &t.exposures, &t.refs, 600, &opt, &three[0]).expect_err("refused");
    assert!(e.to_string().contains("ranks"), "{e}");
    let two = engine::testkit::thread_ranks(2);
    let block = Options {
        method: Method::Block,
        ..opt
    };
    let e = solve_on(&t.obs, &t.exposures, &t.refs, 600, &block, &two[0]).expect_err("refused");
    assert!(e.to_string().contains("block"), "{e}");
}

/// An interrupted solution resumes from its checkpoint and ends with the bits of one never interrupted —
/// interrupted at every checkpoint in turn (each relinearisation and each rejection round), resumed on one
/// rank and on two; a checkpoint of another input is a named error; none is left once done.
#[test]
fn an_interrupted_solution_resumes_from_its_checkpoint_to_the_same_bits() {
    let t = noisy_calibrated(600, 3, 12);
    let opt = Options {
        calibration: CALIBRATED,
        ..Options::default()
    };
    let whole = solve(&t.obs, &t.exposures, &t.refs, 600, &opt).expect("solved");
    let dir = std::env::temp_dir().join(format!("jsim-resume-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("solution.checkpoint");
    let store = engine::io::checkpoint::FileStore::new(&path);
    let ck = |interrupt_after| Checkpointing {
        store: &store,
        interrupt_after,
    };
    // the solution on `ranks`, checkpointed (interrupted after that many checkpoints, if given)
    let run = |ranks: &dyn Ranks, interrupt_after| {
        solve_with(
            &t.obs,
            &t.exposures,
            &t.refs,
            600,
            &opt,
            ranks,
            Some(ck(interrupt_after)),
        )
    };
    let mut interruptions = 0;
    for k in 1.. {
        let _ = std::fs::remove_file(&path);
        match run(&Single, Some(k)) {
            Err(SolutionError::Interrupted(n)) => assert_eq!(n, k),
            Ok(done) => {
                // fewer checkpoints than k: it ran to the end, as the whole one
                assert_eq!(done, whole);
                assert!(!path.exists(), "no checkpoint is left once done");
                break;
            }
            Err(e) => panic!("{e}"),
        }
        assert!(path.exists(), "checkpoint {k} written");
        interruptions += 1;
        // resumed on one process …
        let resumed = run(&Single, None).expect("resumed");
        assert_eq!(resumed, whole, "resumed after checkpoint {k}");
        assert!(!path.exists());
        // … and, from the same checkpoint, on two ranks
        let _ = run(&Single, Some(k));
        let two = engine::testkit::on_thread_ranks(2, |r| run(r, None).expect("resumed"));
        assert!(
            two.iter().all(|s| *s == whole),
            "two ranks after checkpoint {k}"
        );
        // interrupted on two ranks (rank 0 writes), resumed on one
        for e in engine::testkit::on_thread_ranks(2, |r| run(r, Some(k))) {
            assert!(matches!(e, Err(SolutionError::Interrupted(_))), "{e:?}");
        }
        let resumed = run(&Single, None).expect("resumed");
        assert_eq!(
            resumed, whole,
            "written on two ranks, resumed on one, after checkpoint {k}"
        );
    }
    eprintln!("interrupted and resumed at each of {interruptions} checkpoints");
    assert!(interruptions >= 4, "{interruptions} checkpoints");
    // a checkpoint of another input is refused by name
    let _ = run(&Single, Some(1));
    let other = Options {
        clip_sigma: 4.0,
        ..opt
    };
    let e = solve_with(
        &t.obs,
        &t.exposures,
        &t.refs,
        600,
        &other,
        &Single,
        Some(ck(None)),
    )
    .expect_err("another input");
    assert!(
        matches!(e, SolutionError::Checkpoint { .. }) && e.to_string().contains("another input"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
