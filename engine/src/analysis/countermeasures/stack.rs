//! The stack reference of a stare: in a stare the same stars are imaged in every exposure, so the natural
//! reference of a per-exposure plate model is the stack itself — each star's mean position over the
//! stare's exposures. Nothing of the simulation's truth enters.
//!
//! Iterated (reference → per-exposure plate → reference): the reference is the mean of the exposures'
//! *corrected* positions, each exposure's plate is refitted onto it, until the reference moves by less
//! than [`TOLERANCE_PX`]. For positions `x̂ₖ = x + Dₖ(x) + nₖ` (Dₖ the exposure's smooth displacement
//! field, nₖ the fit noise) and a model that holds Dₖ, the fixed point leaves each exposure at
//! `x + D̄(x) + nₖ − P nₖ + P n̄`: the stare's *mean* displacement field D̄ (≈ 1/√K of one exposure's, for
//! K exposures) stays in every exposure, because nothing in the stack can tell it from the sky. The
//! accuracy is measured against the truth, so that residual counts.
//!
//! Stars are cross-identified by position (offset-aware, [`match_positions`]) against the first exposure's
//! usable stars; a star seen in fewer than 2 exposures does not enter the reference.

use super::CountermeasureError;
use super::plate::{Correction, PlateModel, fit_correction};
use crate::analysis::detection::match_positions;
use crate::analysis::report::StarResult;

/// Largest distance (px) between a star's positions in two exposures of the stare, after their common
/// offset, for the two to be one star (a stare holds its pointing to ≪ 1 px; neighbours are ≥ 2 px apart
/// once blends are flagged).
pub const MATCH_RADIUS_PX: f64 = 1.0;
/// Search radius of the common offset between exposures, px.
pub const OFFSET_SEARCH_PX: f64 = 5.0;
/// The iteration stops when no reference position moves by more than this, px.
pub const TOLERANCE_PX: f64 = 1e-6;
/// Bound on the iterations (it converges in 2–3: the mean of the corrections is ≈ 0 from the start).
pub const MAX_ITERATIONS: usize = 20;

/// What the stack plate did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StackOutcome {
    /// Parameters absorbed per exposure.
    pub dof_absorbed: usize,
    /// Stars in the reference (seen in at least 2 exposures).
    pub reference_stars: usize,
    pub iterations: usize,
}

/// Correct every exposure of a stare (`exposures[k]` = its star results, as fitted) with `model` fitted onto
/// the stack reference, in place.
pub fn stack_plate(
    exposures: &mut [Vec<StarResult>],
    model: PlateModel,
    what: &str,
) -> Result<StackOutcome, CountermeasureError> {
    let Some(first) = exposures.first() else {
        return Err(CountermeasureError::ThinStack {
            what: what.into(),
            have: 0,
        });
    };
    let refs0: Vec<(f64, f64)> = first
        .iter()
        .filter(|s| s.is_usable())
        .map(|s| (s.x, s.y))
        .collect();
    // ids[e][k]: reference star of star k of exposure e
    let ids: Vec<Vec<Option<usize>>> = exposures
        .iter()
        .map(|stars| {
            let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
            match_positions(&pos, &refs0, OFFSET_SEARCH_PX, MATCH_RADIUS_PX)
                .into_iter()
                .zip(stars)
                .map(|(m, s)| m.filter(|_| s.is_usable()))
                .collect()
        })
        .collect();
    let mut seen = vec![0usize; refs0.len()];
    for e in &ids {
        for j in e.iter().flatten() {
            seen[*j] += 1;
        }
    }
    let reference_stars = seen.iter().filter(|&&n| n >= 2).count();
    if reference_stars <= model.n_params() {
        return Err(CountermeasureError::ThinStack {
            what: what.into(),
            have: reference_stars,
        });
    }
    let original: Vec<Vec<(f64, f64)>> = exposures
        .iter()
        .map(|st| st.iter().map(|s| (s.x, s.y)).collect())
        .collect();
    let mut corrected = original.clone();
    let mut reference: Vec<Option<(f64, f64)>> = vec![None; refs0.len()];
    let mut corrections: Vec<Option<Correction>> = vec![None; exposures.len()];
    let mut iterations = 0;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        // the reference: each star's mean corrected position over the exposures that saw it
        let mut sum = vec![(0.0, 0.0, 0usize); refs0.len()];
        for (e, idk) in ids.iter().enumerate() {
            for (k, j) in idk.iter().enumerate() {
                if let Some(j) = *j {
                    sum[j].0 += corrected[e][k].0;
                    sum[j].1 += corrected[e][k].1;
                    sum[j].2 += 1;
                }
            }
        }
        let next: Vec<Option<(f64, f64)>> = sum
            .iter()
            .map(|&(x, y, n)| (n >= 2).then(|| (x / n as f64, y / n as f64)))
            .collect();
        // how far the reference moved since the last pass (the same stars have one every pass)
        let moved = next
            .iter()
            .zip(&reference)
            .filter_map(|(a, b)| Some((a.as_ref()?, b.as_ref()?)))
            .map(|(a, b)| (a.0 - b.0).abs().max((a.1 - b.1).abs()))
            .fold(0.0, f64::max);
        reference = next;
        if iterations > 1 && moved < TOLERANCE_PX {
            break;
        }
        // each exposure's plate onto the reference, applied to its original positions
        for (e, idk) in ids.iter().enumerate() {
            let (pos, target): (Vec<(f64, f64)>, Vec<(f64, f64)>) = idk
                .iter()
                .enumerate()
                .filter_map(|(k, j)| j.and_then(|j| reference[j]).map(|r| (original[e][k], r)))
                .unzip();
            let c = fit_correction(model, &pos, &target, what)?;
            for (k, p) in original[e].iter().enumerate() {
                let (dx, dy) = c.at(p.0, p.1);
                corrected[e][k] = (p.0 + dx, p.1 + dy);
            }
            corrections[e] = Some(c);
        }
    }
    for (stars, c) in exposures.iter_mut().zip(&corrections) {
        if let Some(c) = c {
            c.apply(stars);
        }
    }
    Ok(StackOutcome {
        dof_absorbed: 2 * model.n_params(),
        reference_stars,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A star truly at (x, y), fitted at (x + dx, y + dy).
    fn star(x: f64, y: f64, dx: f64, dy: f64) -> StarResult {
        crate::testkit::star_result(x + dx, y + dy)
    }

    /// Exposures whose displacement fields the model holds, without noise: every exposure ends at the
    /// stare's mean field, D̄ (the analytic fixed point). With a star missing from one exposure the stack
    /// is fixed only up to a transformation the model holds (any common one is a fixed point too): it
    /// stays within 1e-3 px of D̄.
    #[test]
    fn a_noise_free_stare_ends_at_its_mean_displacement_field() {
        let grid: Vec<(f64, f64)> = (0..100)
            .map(|k| {
                (
                    100.0 + 180.0 * (k % 10) as f64,
                    100.0 + 180.0 * (k / 10) as f64,
                )
            })
            .collect();
        // field k: offset, a tilt in y and a cubic in y (plate-poly:3 holds it)
        let field = |k: usize, x: f64, y: f64| {
            let (u, v) = (x / 1000.0 - 1.0, y / 1000.0 - 1.0);
            let a = [0.3, -0.1, 0.05, 0.2][k];
            let b = [0.1, 0.2, -0.15, 0.0][k];
            let c = [0.02, -0.04, 0.01, 0.03][k];
            (a + 0.01 * u + b * v.powi(3), -a + c * v)
        };
        let exposures: Vec<Vec<StarResult>> = (0..4)
            .map(|k| {
                grid.iter()
                    .map(|&(x, y)| {
                        let (dx, dy) = field(k, x, y);
                        star(x, y, dx, dy)
                    })
                    .collect()
            })
            .collect();
        for (missing, tol) in [(false, 1e-9), (true, 1e-3)] {
            let mut exposures = exposures.clone();
            // the true positions of each exposure's stars
            let mut truths = vec![grid.clone(); 4];
            if missing {
                exposures[2].remove(17); // a star missed in one exposure
                truths[2].remove(17);
            }
            let out =
                stack_plate(&mut exposures, PlateModel::PolyY(3), "plate-poly:3").expect("fit");
            assert_eq!(out.reference_stars, 100);
            assert!(
                out.iterations < MAX_ITERATIONS,
                "converged: {} iterations",
                out.iterations
            );
            for (stars, truth) in exposures.iter().zip(&truths) {
                for (s, &(x, y)) in stars.iter().zip(truth) {
                    let (dx, dy) = (s.x - x, s.y - y);
                    let mean = (0..4)
                        .map(|k| field(k, x, y))
                        .fold((0.0, 0.0), |a, d| (a.0 + d.0 / 4.0, a.1 + d.1 / 4.0));
                    assert!(
                        (dx - mean.0).abs() < tol && (dy - mean.1).abs() < tol,
                        "error ({dx}, {dy}) vs the mean field ({}, {})",
                        mean.0,
                        mean.1
                    );
                }
            }
        }
    }

    #[test]
    fn a_stare_of_too_few_stars_is_a_named_error() {
        let mut one = vec![vec![star(10.0, 10.0, 0.0, 0.0); 1]; 3];
        let e = stack_plate(&mut one, PlateModel::Affine, "plate-affine").expect_err("thin");
        assert!(
            matches!(e, CountermeasureError::ThinStack { have: 1, .. }),
            "{e}"
        );
        let mut empty: Vec<Vec<StarResult>> = Vec::new();
        assert!(stack_plate(&mut empty, PlateModel::Affine, "plate-affine").is_err());
    }
}
