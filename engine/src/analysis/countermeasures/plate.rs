//! The plate models: per exposure, a smooth transformation of the fitted positions onto reference positions,
//! fitted by least squares over all stars as an astrometric pipeline does against a reference catalogue.

use super::CountermeasureError;
use crate::analysis::report::StarResult;
use crate::numerics::linalg;

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

    /// The monomials u^p v^q (p, q) of its basis: a set closed downwards, so its span does not depend on
    /// where u and v are counted from.
    pub fn monomials(&self) -> Vec<(usize, usize)> {
        match *self {
            PlateModel::Affine => vec![(0, 0), (1, 0), (0, 1)],
            PlateModel::PolyY(n) => {
                let mut m = vec![(0, 0), (1, 0)];
                m.extend((1..=n).map(|k| (0, k)));
                m
            }
        }
    }

    /// Parameters per axis this model and a catalogue registration of `registration_parameters` per axis
    /// (1: a shift, 3: affine, 6: the full quadratic; `analysis::registration`) absorb together: the
    /// dimension of the union of their polynomial spaces. The registration is fitted first to the same
    /// differences, so the plate model's terms it shares fit nothing more (affine after a quadratic
    /// registration adds nothing; the cubic in y adds y³ to the quadratic's six: 7).
    pub fn n_params_with_registration(&self, registration_parameters: usize) -> usize {
        self.union_monomials(registration_parameters).len()
    }

    /// The monomials of the model and of a registration of `registration_parameters` per axis, once each.
    fn union_monomials(&self, registration_parameters: usize) -> Vec<(usize, usize)> {
        let registration: &[(usize, usize)] = match registration_parameters {
            0 | 1 => &[(0, 0)],
            2..=5 => &[(0, 0), (1, 0), (0, 1)],
            _ => &[(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)],
        };
        let mut all = self.monomials();
        all.extend_from_slice(registration);
        all.sort_unstable();
        all.dedup();
        all
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
        let design: Vec<f64> = positions
            .iter()
            .flat_map(|&(x, y)| self.basis(x, y))
            .collect();
        residuals_of(&design, self.n_params(), values)
    }

    /// [`Self::residuals`] of the model and a catalogue registration of `registration_parameters` per axis
    /// fitted together ([`Self::n_params_with_registration`]: the union of their polynomial spaces) — what a
    /// plate model referenced to the catalogue leaves of a displacement field.
    pub fn residuals_with_registration(
        &self,
        registration_parameters: usize,
        positions: &[(f64, f64)],
        values: &[f64],
    ) -> Option<Vec<f64>> {
        let monomials = self.union_monomials(registration_parameters);
        let design: Vec<f64> = positions
            .iter()
            .flat_map(|&(x, y)| {
                let (u, v) = (x / 1000.0 - 1.0, y / 1000.0 - 1.0);
                monomials
                    .iter()
                    .map(move |&(p, q)| u.powi(p as i32) * v.powi(q as i32))
            })
            .collect();
        residuals_of(&design, monomials.len(), values)
    }
}

/// The residuals of an unweighted least-squares fit of `values` on the rows of `design` (`p` a row).
fn residuals_of(design: &[f64], p: usize, values: &[f64]) -> Option<Vec<f64>> {
    let w = vec![1.0; values.len()];
    let (c, _) = linalg::weighted_lstsq(design, values, &w, p)?;
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

    /// Move every star by the correction at its position.
    pub fn apply(&self, stars: &mut [StarResult]) {
        for s in stars.iter_mut() {
            let (ddx, ddy) = self.at(s.x, s.y);
            s.x += ddx;
            s.y += ddy;
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

/// Fit the plate model onto a reference catalogue product (positions in the image's pixels through the
/// header's design WCS), in the catalogue's frame. The header does not know the instrument as built (its
/// pointing and roll errors, the arrays' placement, the distortion beyond the design), so the catalogue is
/// first registered onto the usable fits (`analysis::registration`, the plate solution against the
/// catalogue: an offset by votes, then a 2-D quadratic map R); each fit is matched to the nearest registered
/// catalogue star within 1 px, the model is fitted over the matched pairs onto the registered positions and
/// subtracted from every star, and every star is taken back through R⁻¹ into the catalogue's frame. The
/// whole correction is the model plus R's 2-D quadratic; returns the parameters the two absorb together
/// ([`PlateModel::n_params_with_registration`], both axes). No truth.
pub fn plate_fit_to_catalogue(
    stars: &mut [StarResult],
    reference: &[(f64, f64)],
    model: PlateModel,
    what: &str,
) -> Result<usize, CountermeasureError> {
    let usable: Vec<usize> = (0..stars.len()).filter(|&k| stars[k].is_usable()).collect();
    let pos: Vec<(f64, f64)> = usable.iter().map(|&k| (stars[k].x, stars[k].y)).collect();
    let flux: Vec<f64> = usable.iter().map(|&k| stars[k].flux_e).collect();
    let reg = crate::analysis::registration::register(&pos, &flux, reference);
    let moved: Vec<(f64, f64)> = reference.iter().map(|&r| reg.apply(r)).collect();
    let m = crate::analysis::detection::nearest_within(&pos, &moved, 1.0, (0.0, 0.0));
    let (p, target): (Vec<(f64, f64)>, Vec<(f64, f64)>) = pos
        .iter()
        .zip(&m)
        .filter_map(|(p, k)| k.map(|k| (*p, moved[k])))
        .unzip();
    let c = fit_correction(model, &p, &target, what)?;
    c.apply(stars);
    for s in stars
        .iter_mut()
        .filter(|s| s.x.is_finite() && s.y.is_finite())
    {
        (s.x, s.y) = reg.invert((s.x, s.y));
    }
    Ok(2 * model.n_params_with_registration(reg.parameters))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A star truly at (x, y), fitted at (x + dx, y + dy).
    fn star(x: f64, y: f64, dx: f64, dy: f64) -> StarResult {
        crate::testkit::star_result(x + dx, y + dy)
    }

    /// Largest |fitted − true| of corrected stars, px.
    fn worst(stars: &[StarResult], pos: &[(f64, f64)]) -> f64 {
        stars
            .iter()
            .zip(pos)
            .map(|(s, p)| (s.x - p.0).abs().max((s.y - p.1).abs()))
            .fold(0.0, f64::max)
    }

    /// The fit onto a catalogue (matched by position) corrects as well as the least-squares fit over the known
    /// pairs when the catalogue holds every star — the cross-match finds them all — puts the stars in the
    /// catalogue's frame when the header's frame is not the image's, and leaves stars missing from it and
    /// rejected fits out of the fit but corrects them.
    #[test]
    fn the_catalogue_fit_corrects_as_the_fit_over_known_pairs() {
        let pos: Vec<(f64, f64)> = (0..120)
            .map(|k| {
                (
                    50.0 + (k % 12) as f64 * 160.0 + 0.3 * (k / 12) as f64,
                    40.0 + (k / 12) as f64 * 190.0,
                )
            })
            .collect();
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
                    star(x, y, dx + e, dy - e)
                })
                .collect()
        };
        let mut by_pairs = make();
        let fitted: Vec<(f64, f64)> = by_pairs.iter().map(|s| (s.x, s.y)).collect();
        fit_correction(PlateModel::PolyY(3), &fitted, &pos, "plate-poly:3")
            .expect("pairs fit")
            .apply(&mut by_pairs);
        let mut by_catalogue = make();
        plate_fit_to_catalogue(
            &mut by_catalogue,
            &pos,
            PlateModel::PolyY(3),
            "plate-poly:3",
        )
        .expect("catalogue fit");
        // the catalogue fit adds the registration's 2-D quadratic to the model: as good as the fit over the
        // known pairs, to the per-star error (0.003 px)
        let (wp, wc) = (worst(&by_pairs, &pos), worst(&by_catalogue, &pos));
        assert!(wc <= 1.1 * wp + 5e-4 && wc < 0.005, "{wc} against {wp} px");
        // a catalogue in another frame (the header's: an 8-px offset, a 0.05° turn and a quadratic the
        // design does not know): the corrected stars come out in the catalogue's frame, as well
        let (sn, cs) = 0.05f64.to_radians().sin_cos();
        let frame = |p: (f64, f64)| {
            let (u, v) = (p.0 - 1000.0, p.1 - 1000.0);
            (
                1000.0 + 8.0 + cs * u - sn * v + 2e-8 * u * u,
                1000.0 - 5.0 + sn * u + cs * v - 1.5e-8 * u * v,
            )
        };
        let catalogue: Vec<(f64, f64)> = pos.iter().map(|&p| frame(p)).collect();
        let mut moved = make();
        plate_fit_to_catalogue(&mut moved, &catalogue, PlateModel::PolyY(3), "plate-poly:3")
            .expect("a catalogue in another frame");
        let w = worst(&moved, &catalogue);
        assert!(w < 0.005, "{w} px from the catalogue's frame");
        // a catalogue missing two thirds of the stars, with one rejected fit: still a good correction
        let partial: Vec<(f64, f64)> = pos.iter().step_by(3).copied().collect();
        let mut stars = make();
        stars[1].flags = crate::analysis::epsf::fit::flags::NOT_CONVERGED;
        plate_fit_to_catalogue(&mut stars, &partial, PlateModel::PolyY(3), "plate-poly:3")
            .expect("partial catalogue");
        let w = worst(&stars, &pos);
        assert!(w < 0.01, "residual {w} px");
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
            .map(|&(x, y)| {
                let (dx, dy) = field(x, y);
                star(x, y, dx, dy)
            })
            .collect();
        let dof = plate_fit_to_catalogue(&mut stars, &pos, PlateModel::PolyY(3), "plate-poly:3")
            .expect("fit");
        // the cubic in y (1, u, v, v², v³) and the registration's quadratic (1, u, v, u², uv, v²): 7 an axis
        assert_eq!(dof, 14);
        // the field is a polynomial of the true positions and the model one of the measured positions: the
        // difference is second order in the field (here < 1e-6 px = 5e-4 mas)
        let w = worst(&stars, &pos);
        assert!(w < 1e-6, "{w}");
    }

    /// The catalogue fit absorbs the union of the registration's and the model's polynomial spaces, not
    /// their sum: on pure noise (σ per axis, catalogue at the true places) the corrected positions keep
    /// (1 − p/n) of its variance with p = 7 an axis for `plate-poly:3` (1, u, v, u², uv, v², v³), where the
    /// sum, 5 + 6, would leave 1 − 11/n. n = 60 stars, 300 draws: the mean ratio within 4 of its standard
    /// errors of (n − 7)/n = 0.883, while (n − 11)/n = 0.817 lies ≈ 9 of them away.
    #[test]
    fn the_catalogue_fit_absorbs_the_union_of_its_two_models() {
        use rand::{RngExt, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let mut r = rand::rngs::StdRng::seed_from_u64(3);
        let (n, sigma) = (60usize, 0.01);
        let mut ratios = Vec::new();
        for _ in 0..300 {
            let pos: Vec<(f64, f64)> = (0..n)
                .map(|_| (r.random_range(0.0..2000.0), r.random_range(0.0..2000.0)))
                .collect();
            let noise: Vec<(f64, f64)> = (0..n)
                .map(|_| {
                    let (a, b): (f64, f64) =
                        (StandardNormal.sample(&mut r), StandardNormal.sample(&mut r));
                    (sigma * a, sigma * b)
                })
                .collect();
            let mut stars: Vec<StarResult> = pos
                .iter()
                .zip(&noise)
                .map(|(&(x, y), &(dx, dy))| star(x, y, dx, dy))
                .collect();
            let dof =
                plate_fit_to_catalogue(&mut stars, &pos, PlateModel::PolyY(3), "plate-poly:3")
                    .expect("fit");
            assert_eq!(dof, 14);
            let left: f64 = stars
                .iter()
                .zip(&pos)
                .map(|(s, p)| (s.x - p.0).powi(2) + (s.y - p.1).powi(2))
                .sum();
            let drawn: f64 = noise.iter().map(|(a, b)| a * a + b * b).sum();
            ratios.push(left / drawn);
        }
        let m = ratios.iter().sum::<f64>() / ratios.len() as f64;
        let sd = (ratios.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (ratios.len() - 1) as f64)
            .sqrt();
        let se = sd / (ratios.len() as f64).sqrt();
        let (union, sum) = ((n - 7) as f64 / n as f64, (n - 11) as f64 / n as f64);
        assert!(
            (m - union).abs() < 4.0 * se,
            "mean {m} ± {se}, union {union}"
        );
        assert!((m - sum).abs() > 6.0 * se, "mean {m} ± {se}, sum {sum}");
    }

    /// An affine plate fit of stars in one row at `spacing_px`, each displaced by 0.1 px in x.
    fn affine_fit_of_a_row(
        n: usize,
        spacing_px: f64,
    ) -> (Result<usize, CountermeasureError>, Vec<StarResult>) {
        let pos: Vec<(f64, f64)> = (0..n).map(|k| (k as f64 * spacing_px, 500.0)).collect();
        let mut stars: Vec<StarResult> = pos.iter().map(|&(x, y)| star(x, y, 0.1, 0.0)).collect();
        let r = plate_fit_to_catalogue(&mut stars, &pos, PlateModel::Affine, "plate-affine");
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
        assert!(stars.iter().all(|s| s.x.is_finite()));
    }
}
