//! Scoring an astrometric solution against the truth: each solved source's position, proper motion and
//! parallax against its true star's (the star most of its detections were matched to), per magnitude bin,
//! beside the errors the solution reports; the solved calibration against the instrument's; and each solved
//! attitude against what the true stars say it should be.

use crate::solution::{ExposureGeometry, Observation, Params, Solution, SolvedSource};

/// A source's true parameters (on the solution's plane) and magnitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueSource {
    pub params: Params,
    pub hw: f64,
}

/// One magnitude bin's score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BinScore {
    pub hw_lo: f64,
    pub hw_hi: f64,
    /// Sources solved with all five parameters and a true star.
    pub sources: usize,
    /// Median observations per source.
    pub observations: f64,
    /// rms error per axis: position (mas), proper motion (mas/yr), parallax (mas); NaN without sources.
    pub position_rms_mas: f64,
    pub pm_rms_mas_per_yr: f64,
    pub parallax_rms_mas: f64,
    /// The position errors' robust scatter per axis (1.4826 × their median absolute deviation), mas, and
    /// the fraction of sources whose position is off by more than 5 of its σ on either axis (blends,
    /// mismatches: what makes the rms exceed the robust scatter).
    pub position_robust_mas: f64,
    pub outlier_fraction: f64,
    /// The solution's own errors, their rms per axis (what the rms errors should equal).
    pub position_sigma_mas: f64,
    pub pm_sigma_mas_per_yr: f64,
    pub parallax_sigma_mas: f64,
    /// The pulls, error / σ, their robust scatter (1.4826 × the median absolute deviation about their median,
    /// so that the frame's error common to all sources, which σ leaves out, does not count): per axis of the
    /// position, of the proper motion and of the parallax where solved; 1 where σ describes the errors. NaN
    /// without sources.
    pub position_pull: f64,
    pub pm_pull: f64,
    pub parallax_pull: f64,
}

/// Score `solved` sources against `truth` (per source; None: no true star), in bins of `edges`. A source
/// counts where its position is solved; its motions count where they are (finite σ).
pub fn score_sources(
    solved: &[SolvedSource],
    truth: &[Option<TrueSource>],
    edges: &[f64],
) -> Vec<BinScore> {
    edges
        .windows(2)
        .map(|w| {
            let (lo, hi) = (w[0], w[1]);
            let members: Vec<(&SolvedSource, &TrueSource)> = solved
                .iter()
                .zip(truth)
                .filter_map(|(s, t)| t.as_ref().map(|t| (s, t)))
                .filter(|(s, t)| {
                    t.hw >= lo && t.hw < hi && s.params[0].is_finite() && s.sigma[0].is_finite()
                })
                .collect();
            // rms over the members with parameters k solved: of the error, and of the σ
            let rms = |ks: &[usize], sigma: bool| -> f64 {
                let (mut sum, mut n) = (0.0, 0usize);
                for (s, t) in &members {
                    if ks.iter().all(|k| s.sigma[*k].is_finite()) {
                        for &k in ks {
                            let v = if sigma {
                                s.sigma[k]
                            } else {
                                s.params[k] - t.params[k]
                            };
                            sum += v * v;
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    (sum / n as f64).sqrt()
                } else {
                    f64::NAN
                }
            };
            let obs: Vec<f64> = members.iter().map(|(s, _)| s.observations as f64).collect();
            let errors: Vec<f64> = members
                .iter()
                .flat_map(|(s, t)| [s.params[0] - t.params[0], s.params[1] - t.params[1]])
                .collect();
            let pulls = |ks: &[usize]| -> f64 {
                let v: Vec<f64> = members
                    .iter()
                    .filter(|(s, _)| ks.iter().all(|k| s.sigma[*k].is_finite()))
                    .flat_map(|(s, t)| ks.iter().map(|&k| (s.params[k] - t.params[k]) / s.sigma[k]))
                    .collect();
                if v.is_empty() {
                    f64::NAN
                } else {
                    crate::numerics::stats::mad_sigma(&v)
                }
            };
            let outliers = members
                .iter()
                .filter(|(s, t)| {
                    (0..2).any(|k| ((s.params[k] - t.params[k]) / s.sigma[k]).abs() > 5.0)
                })
                .count();
            BinScore {
                hw_lo: lo,
                hw_hi: hi,
                sources: members.len(),
                observations: if obs.is_empty() {
                    f64::NAN
                } else {
                    crate::numerics::stats::median(&obs)
                },
                position_rms_mas: rms(&[0, 1], false),
                position_robust_mas: if errors.is_empty() {
                    f64::NAN
                } else {
                    crate::numerics::stats::mad_sigma(&errors)
                },
                outlier_fraction: if members.is_empty() {
                    f64::NAN
                } else {
                    outliers as f64 / members.len() as f64
                },
                pm_rms_mas_per_yr: rms(&[2, 3], false),
                parallax_rms_mas: rms(&[4], false),
                position_sigma_mas: rms(&[0, 1], true),
                pm_sigma_mas_per_yr: rms(&[2, 3], true),
                parallax_sigma_mas: rms(&[4], true),
                position_pull: pulls(&[0, 1]),
                pm_pull: pulls(&[2, 3]),
                parallax_pull: pulls(&[4]),
            }
        })
        .collect()
}

/// The difference of two calibration maps (solved − true, px, at the same points) with the gauge the
/// attitudes hold removed — a shift, turn and scale common to all points, fitted by least squares.
pub fn calibration_residuals(points: &[[f64; 2]], diff: &[[f64; 2]]) -> Vec<[f64; 2]> {
    // d ≈ (a_x + s u − r v, a_y + r u + s v)
    let (mut design, mut y) = (Vec::new(), Vec::new());
    for (p, d) in points.iter().zip(diff) {
        let (u, v) = (p[0] / 1e3, p[1] / 1e3);
        design.extend_from_slice(&[1.0, 0.0, u, -v]);
        y.push(d[0]);
        design.extend_from_slice(&[0.0, 1.0, v, u]);
        y.push(d[1]);
    }
    let w = vec![1.0; y.len()];
    let beta = crate::numerics::linalg::weighted_lstsq(&design, &y, &w, 4)
        .map(|(b, _)| b)
        .unwrap_or_else(|| vec![0.0; 4]);
    points
        .iter()
        .zip(diff)
        .map(|(p, d)| {
            let (u, v) = (p[0] / 1e3, p[1] / 1e3);
            [
                d[0] - (beta[0] + beta[2] * u - beta[3] * v),
                d[1] - (beta[1] + beta[3] * u + beta[2] * v),
            ]
        })
        .collect()
}

/// One exposure's attitude error: what its attitude should have been, given the solved calibration and the true
/// stars, minus what was solved (in the solution's gauge and frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeError {
    pub offset_mas: [f64; 2],
    pub roll_arcsec: f64,
    pub scale_ppm: f64,
    /// The matched stars it rests on.
    pub stars: usize,
}

/// Each exposure's attitude against the truth. Every observation of a source with a true star is modelled
/// with the star's true parameters through the solved attitude and calibration,
/// `o = c + A (s_true − c) + a + M Δf`; what is left, `r = o_obs − o`, is fitted per exposure by the
/// attitude's own similarity `δa + δA (s_true − c)` (weights 1/σ², one pass again without the points beyond
/// 5 × their robust scatter): δ is the attitude the true stars ask for minus the solved one. The frame's error
/// (the reference catalogue's, common to every source) is in every exposure's δ alike. `None` for an exposure
/// with fewer than 10 such stars.
pub fn attitude_errors(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    sol: &Solution,
    truths: &[Option<TrueSource>],
) -> Vec<Option<AttitudeError>> {
    let mut by_exposure: Vec<Vec<usize>> = vec![Vec::new(); exposures.len()];
    for (i, o) in obs.iter().enumerate() {
        if truths.get(o.source()).is_some_and(Option::is_some) && o.exposure() < exposures.len() {
            by_exposure[o.exposure()].push(i);
        }
    }
    by_exposure
        .iter()
        .enumerate()
        .map(|(e, mine)| {
            let g = &exposures[e];
            let a = sol.attitudes.get(e)?;
            // (s − c, residual, σ) of each star
            let rows: Vec<([f64; 2], [f64; 2], f64)> = mine
                .iter()
                .filter_map(|&i| {
                    let o = &obs[i];
                    let t = truths[o.source()].as_ref()?;
                    let s = g.place(&t.params);
                    let d = sol.calibration.correction_mas(o, g);
                    let m = a.apply(g.centre_mas, s);
                    let r = [o.xi_mas - d[0] - m[0], o.eta_mas - d[1] - m[1]];
                    let ds = [s[0] - g.centre_mas[0], s[1] - g.centre_mas[1]];
                    r.iter()
                        .all(|v| v.is_finite())
                        .then_some((ds, r, o.sigma_mas))
                })
                .collect();
            let fit = |keep: &dyn Fn(&([f64; 2], [f64; 2], f64)) -> bool| {
                let (mut design, mut y, mut w) = (Vec::new(), Vec::new(), Vec::new());
                let mut n = 0;
                for row in rows.iter().filter(|r| keep(r)) {
                    let (ds, r, sigma) = row;
                    // x: δa_x + δp dx − δq dy;  y: δa_y + δq dx + δp dy
                    design.extend_from_slice(&[1.0, 0.0, ds[0], -ds[1]]);
                    design.extend_from_slice(&[0.0, 1.0, ds[1], ds[0]]);
                    y.extend_from_slice(r);
                    w.extend_from_slice(&[1.0 / (sigma * sigma); 2]);
                    n += 1;
                }
                (n >= 10)
                    .then(|| crate::numerics::linalg::weighted_lstsq(&design, &y, &w, 4))
                    .flatten()
                    .map(|(b, _)| (b, n))
            };
            let (first, _) = fit(&|_| true)?;
            let left = |row: &([f64; 2], [f64; 2], f64)| {
                let (ds, r, _) = row;
                [
                    r[0] - first[0] - first[2] * ds[0] + first[3] * ds[1],
                    r[1] - first[1] - first[3] * ds[0] - first[2] * ds[1],
                ]
            };
            let spread: Vec<f64> = rows.iter().flat_map(&left).collect();
            let cut = 5.0 * crate::numerics::stats::mad_sigma(&spread).max(1e-9);
            let (b, n) = fit(&|row| left(row).iter().all(|v| v.abs() <= cut))?;
            // the solved attitude's A = [[p, −q], [q, p]]: δp, δq are a scale and a turn on it
            Some(AttitudeError {
                offset_mas: [b[0], b[1]],
                roll_arcsec: b[3] * 206_264.806,
                scale_ppm: b[2] * 1e6,
                stars: n,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_common_shift_turn_and_scale_leave_no_residual_and_a_shear_stays() {
        let pts: Vec<[f64; 2]> = (0..25)
            .map(|i| {
                [
                    (i % 5) as f64 * 500.0 - 1000.0,
                    (i / 5) as f64 * 500.0 - 1000.0,
                ]
            })
            .collect();
        let gauge: Vec<[f64; 2]> = pts
            .iter()
            .map(|p| {
                [
                    0.3 + 1e-4 * p[0] - 2e-4 * p[1],
                    -0.1 + 2e-4 * p[0] + 1e-4 * p[1],
                ]
            })
            .collect();
        let r = calibration_residuals(&pts, &gauge);
        assert!(r.iter().all(|d| d[0].abs() < 1e-12 && d[1].abs() < 1e-12));
        let shear: Vec<[f64; 2]> = pts.iter().map(|p| [1e-4 * p[1], 0.0]).collect();
        let r = calibration_residuals(&pts, &shear);
        let rms = (r.iter().map(|d| d[0] * d[0] + d[1] * d[1]).sum::<f64>() / 25.0).sqrt();
        // half the shear is a turn (removed), half stays: rms 0.5e-4 × rms(v) × √2 / √2
        assert!(rms > 0.03 && rms < 0.06, "{rms}");
    }

    /// The pulls of sources whose errors are drawn as N(0, σ²), σ different from source to source: their
    /// robust scatter is 1 within its standard error (≈ 1.17/√n: 0.012 for the positions' 2 × 5000, 0.017
    /// for the parallaxes' 5000; asserted to 4 of them); σ half the true scatter gives pulls of 2.
    #[test]
    fn the_pulls_are_one_when_sigma_describes_the_errors() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut r = rand::rngs::StdRng::seed_from_u64(7);
        let n = 5000;
        let (mut solved, mut truth) = (Vec::new(), Vec::new());
        for i in 0..n {
            let sigma = 0.5 + (i % 10) as f64 * 0.3;
            let mut s = SolvedSource {
                params: [0.0; 5],
                sigma: [sigma; 5],
                observations: 10,
                chi2: 0.0,
            };
            for k in 0..5 {
                let z: f64 = StandardNormal.sample(&mut r);
                s.params[k] = sigma * z;
            }
            solved.push(s);
            truth.push(Some(TrueSource {
                params: [0.0; 5],
                hw: 12.5,
            }));
        }
        let b = score_sources(&solved, &truth, &[12.0, 13.0])[0];
        assert!((b.position_pull - 1.0).abs() < 0.048, "{}", b.position_pull);
        assert!((b.pm_pull - 1.0).abs() < 0.048, "{}", b.pm_pull);
        assert!((b.parallax_pull - 1.0).abs() < 0.068, "{}", b.parallax_pull);
        for s in &mut solved {
            s.sigma = s.sigma.map(|v| v / 2.0);
        }
        let b = score_sources(&solved, &truth, &[12.0, 13.0])[0];
        assert!((b.position_pull - 2.0).abs() < 0.096, "{}", b.position_pull);
    }
}
