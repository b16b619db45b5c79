//! The plate models: per exposure, a smooth transformation of the fitted positions onto reference positions,
//! fitted by least squares over all stars as an astrometric pipeline does against a reference catalogue.

use super::CountermeasureError;
use crate::analysis::report::StarResult;
use crate::numerics::linalg;
use crate::truth::TruthRow;

/// The model of a plate fit: its design row is the one basis shared by the countermeasure and the
/// predictor. Coordinates are normalised as `u = x/1000 − 1` (≈ [−1, 1] over the 1968-px array) for
/// conditioning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlateModel {
    /// `Δ = a₀ + a₁u + a₂v` per axis (6 parameters).
    Affine,
    /// `Δ = a₀ + a₁u + Σₖ₌₁..N bₖ vᵏ` per axis (2(N + 2) parameters): a polynomial in Y, the direction of the
    /// rolling readout's displacement pattern.
    PolyY(usize),
}

/// Largest order of `plate-poly:N`.
pub const MAX_PLATE_ORDER: usize = 8;

impl PlateModel {
    /// One design row at detector position (x, y) px.
    pub fn basis(&self, x: f64, y: f64) -> Vec<f64> {
        let (u, v) = (x / 1000.0 - 1.0, y / 1000.0 - 1.0);
        match *self {
            PlateModel::Affine => vec![1.0, u, v],
            PlateModel::PolyY(n) => {
                let mut row = vec![1.0, u];
                row.extend((1..=n).map(|k| v.powi(k as i32)));
                row
            }
        }
    }

    /// Parameters per axis.
    pub fn n_params(&self) -> usize {
        match *self {
            PlateModel::Affine => 3,
            PlateModel::PolyY(n) => n + 2,
        }
    }

    /// Fit the model to per-star displacements (one axis) by unweighted least squares and return the
    /// residuals; `None` when the positions do not constrain the model.
    pub fn residuals(&self, positions: &[(f64, f64)], values: &[f64]) -> Option<Vec<f64>> {
        let p = self.n_params();
        let design: Vec<f64> = positions
            .iter()
            .flat_map(|&(x, y)| self.basis(x, y))
            .collect();
        let w = vec![1.0; values.len()];
        let (c, _) = linalg::weighted_lstsq(&design, values, &w, p)?;
        Some(
            values
                .iter()
                .enumerate()
                .map(|(k, y)| {
                    y - design[k * p..(k + 1) * p]
                        .iter()
                        .zip(&c)
                        .map(|(a, b)| a * b)
                        .sum::<f64>()
                })
                .collect(),
        )
    }
}

/// Fit Δ = design · coefficients per axis over the matched, usable stars onto their true positions (the
/// `@oracle` reference: a control, never a default), subtract, and return the number of parameters absorbed.
pub fn plate_fit(
    stars: &mut [StarResult],
    truth: &[TruthRow],
    model: PlateModel,
    what: &str,
) -> Result<usize, CountermeasureError> {
    let (pos, target): (Vec<(f64, f64)>, Vec<(f64, f64)>) = stars
        .iter()
        .filter(|s| s.is_used())
        .filter_map(|s| {
            let t = truth.get(s.truth?)?;
            Some(((s.x, s.y), (t.x_px, t.y_px)))
        })
        .unzip();
    let c = fit_correction(model, &pos, &target, what)?;
    c.apply(stars);
    Ok(2 * model.n_params())
}

/// A fitted plate correction: Δx, Δy as functions of the position.
#[derive(Debug, Clone, PartialEq)]
pub struct Correction {
    pub model: PlateModel,
    pub cx: Vec<f64>,
    pub cy: Vec<f64>,
}

impl Correction {
    /// (Δx, Δy) at (x, y), px.
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        let b = self.model.basis(x, y);
        (
            b.iter().zip(&self.cx).map(|(a, c)| a * c).sum(),
            b.iter().zip(&self.cy).map(|(a, c)| a * c).sum(),
        )
    }

    /// Move every star (and its error against the truth) by the correction at its position.
    pub fn apply(&self, stars: &mut [StarResult]) {
        for s in stars.iter_mut() {
            let (ddx, ddy) = self.at(s.x, s.y);
            s.x += ddx;
            s.y += ddy;
            s.dx_px += ddx;
            s.dy_px += ddy;
        }
    }
}

/// The least-squares correction mapping `positions` onto `targets` (Δ = target − position per axis,
/// unweighted): a named error when there are too few stars or they do not constrain the model.
pub fn fit_correction(
    model: PlateModel,
    positions: &[(f64, f64)],
    targets: &[(f64, f64)],
    what: &str,
) -> Result<Correction, CountermeasureError> {
    let p = model.n_params();
    if positions.len() <= p {
        return Err(CountermeasureError::TooFewStars {
            what: what.into(),
            need: p + 1,
            have: positions.len(),
        });
    }
    let design: Vec<f64> = positions
        .iter()
        .flat_map(|&(x, y)| model.basis(x, y))
        .collect();
    let rx: Vec<f64> = positions
        .iter()
        .zip(targets)
        .map(|(a, t)| t.0 - a.0)
        .collect();
    let ry: Vec<f64> = positions
        .iter()
        .zip(targets)
        .map(|(a, t)| t.1 - a.1)
        .collect();
    let w = vec![1.0; positions.len()];
    let degenerate = || CountermeasureError::Degenerate { what: what.into() };
    let (cx, _) = linalg::weighted_lstsq(&design, &rx, &w, p).ok_or_else(degenerate)?;
    let (cy, _) = linalg::weighted_lstsq(&design, &ry, &w, p).ok_or_else(degenerate)?;
    Ok(Correction { model, cx, cy })
}

/// Fit the plate model onto a reference catalogue product (positions in the image's pixels): every usable
/// fit (no rejection flag) is cross-matched to the catalogue by position — the common offset (median
/// displacement to the nearest reference star within 20 px), then the nearest within 1 px — and the model is
/// fitted over the matched pairs, subtracted from every star; returns the parameters absorbed. No truth.
pub fn plate_fit_to_catalogue(
    stars: &mut [StarResult],
    reference: &[(f64, f64)],
    model: PlateModel,
    what: &str,
) -> Result<usize, CountermeasureError> {
    let usable: Vec<usize> = (0..stars.len())
        .filter(|&k| {
            stars[k].flags & crate::analysis::epsf::fit::flags::REJECT == 0
                && stars[k].x.is_finite()
                && stars[k].y.is_finite()
        })
        .collect();
    let pos: Vec<(f64, f64)> = usable.iter().map(|&k| (stars[k].x, stars[k].y)).collect();
    let m = crate::analysis::detection::match_positions(&pos, reference, 20.0, 1.0);
    let (p, target): (Vec<(f64, f64)>, Vec<(f64, f64)>) = pos
        .iter()
        .zip(&m)
        .filter_map(|(p, k)| k.map(|k| (*p, reference[k])))
        .unzip();
    let c = fit_correction(model, &p, &target, what)?;
    c.apply(stars);
    Ok(2 * model.n_params())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn star(x: f64, y: f64, dx: f64, dy: f64, k: usize) -> StarResult {
        crate::testkit::star_result(k, x, y, dx, dy)
    }

    fn truth_at(pos: &[(f64, f64)]) -> Vec<TruthRow> {
        pos.iter()
            .enumerate()
            .map(|(k, &(x, y))| TruthRow {
                id: k,
                x_px: x,
                y_px: y,
                mag_hw: 12.5,
                j_minus_h: 2.0,
                flux_e: 1e4,
                modelled_fraction: 1.0,
                t_start_s: 0.0,
                exptime_s: 12.5,
                jitter_dx_px: 0.0,
                jitter_dy_px: 0.0,
            })
            .collect()
    }

    /// The fit onto a catalogue product (matched by position, no truth) equals the fit onto the truth when the
    /// catalogue holds the true positions — another way to the same result — and leaves unmatched and
    /// rejected stars out of the fit but corrects them.
    #[test]
    fn the_catalogue_product_fit_equals_the_truth_fit_on_true_positions() {
        let pos: Vec<(f64, f64)> = (0..120)
            .map(|k| {
                (
                    50.0 + (k % 12) as f64 * 160.0 + 0.3 * (k / 12) as f64,
                    40.0 + (k / 12) as f64 * 190.0,
                )
            })
            .collect();
        let truth = truth_at(&pos);
        let field = |x: f64, y: f64| {
            let yn = y / 1000.0 - 1.0;
            (
                0.04 + 0.02 * (x / 1000.0 - 1.0) - 0.03 * yn.powi(3),
                -0.02 + 0.05 * yn * yn,
            )
        };
        let make = || -> Vec<StarResult> {
            pos.iter()
                .enumerate()
                .map(|(k, &(x, y))| {
                    let (dx, dy) = field(x, y);
                    // a small per-star error so the fit has residuals
                    let e = 0.003 * (((k * 37) % 11) as f64 - 5.0) / 5.0;
                    star(x, y, dx + e, dy - e, k)
                })
                .collect()
        };
        let mut by_truth = make();
        plate_fit(&mut by_truth, &truth, PlateModel::PolyY(3), "plate-poly:3").expect("truth fit");
        let mut by_catalogue = make();
        for s in &mut by_catalogue {
            s.truth = None; // the catalogue fit needs no truth
        }
        plate_fit_to_catalogue(
            &mut by_catalogue,
            &pos,
            PlateModel::PolyY(3),
            "plate-poly:3",
        )
        .expect("catalogue fit");
        for (a, b) in by_truth.iter().zip(&by_catalogue) {
            assert!(
                (a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9,
                "{a:?} {b:?}"
            );
        }
        // a catalogue missing a third of the stars, with one rejected fit: still a good correction
        let partial: Vec<(f64, f64)> = pos.iter().step_by(3).copied().collect();
        let mut stars = make();
        stars[1].flags = crate::analysis::epsf::fit::flags::NOT_CONVERGED;
        plate_fit_to_catalogue(&mut stars, &partial, PlateModel::PolyY(3), "plate-poly:3")
            .expect("partial catalogue");
        let worst = stars
            .iter()
            .map(|s| s.dx_px.abs().max(s.dy_px.abs()))
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "residual {worst} px");
    }

    #[test]
    fn plate_poly_removes_a_displacement_field_of_matching_order() {
        let pos: Vec<(f64, f64)> = (0..100)
            .map(|k| {
                (
                    50.0 + (k % 10) as f64 * 190.0,
                    40.0 + (k / 10) as f64 * 195.0,
                )
            })
            .collect();
        let truth = truth_at(&pos);
        // a cubic displacement along Y, plus a shift and a rotation-like term
        let field = |x: f64, y: f64| {
            let yn = y / 1000.0 - 1.0;
            (
                0.02 + 0.01 * (x / 1000.0 - 1.0) + 0.05 * yn - 0.03 * yn.powi(3),
                -0.01 + 0.04 * yn * yn,
            )
        };
        let mut stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| {
                let (dx, dy) = field(x, y);
                star(x, y, dx, dy, k)
            })
            .collect();
        let dof = plate_fit(&mut stars, &truth, PlateModel::PolyY(3), "plate-poly:3").expect("fit");
        assert_eq!(dof, 10);
        // the field is a polynomial of the true positions and the model one of the measured positions: the
        // difference is second order in the field (here < 1e-6 px = 5e-4 mas)
        for s in &stars {
            assert!(
                s.dx_px.abs() < 1e-6 && s.dy_px.abs() < 1e-6,
                "{} {}",
                s.dx_px,
                s.dy_px
            );
        }
    }

    /// An affine plate fit of stars in one row at `spacing_px`, each displaced by 0.1 px in x.
    fn affine_fit_of_a_row(
        n: usize,
        spacing_px: f64,
    ) -> (Result<usize, CountermeasureError>, Vec<StarResult>) {
        let pos: Vec<(f64, f64)> = (0..n).map(|k| (k as f64 * spacing_px, 500.0)).collect();
        let truth = truth_at(&pos);
        let mut stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| star(x, y, 0.1, 0.0, k))
            .collect();
        let r = plate_fit(&mut stars, &truth, PlateModel::Affine, "plate-affine");
        (r, stars)
    }

    #[test]
    fn plate_fit_degenerate_inputs_are_named_errors() {
        let (r, _) = affine_fit_of_a_row(3, 100.0);
        let e = r.expect_err("too few");
        assert!(matches!(e, CountermeasureError::TooFewStars { .. }), "{e}");
        // all stars in one row: y has no lever arm
        let (r, stars) = affine_fit_of_a_row(20, 90.0);
        let e = r.expect_err("one row");
        assert!(matches!(e, CountermeasureError::Degenerate { .. }), "{e}");
        assert!(stars.iter().all(|s| s.dx_px.is_finite()));
    }
}
