//! The plate solution against a reference catalogue: the affine map that puts the catalogue's positions
//! (its pixel columns, through the header's design WCS) onto the stars fitted in this image.
//!
//! The header's WCS is the design at the planned pointing. The instrument as built points a little
//! elsewhere (the pointing and roll errors), its arrays sit a little off their drawn places (assembly
//! offsets of ≈ 10 px, turns of ≈ 0.1°: up to ≈ 2 px at an array's edge) and its distortion departs from
//! the design by a few hundredths of a pixel. An analysis that holds catalogue stars at their catalogue
//! positions (the forced stars of a crowded field) or matches its fits to them (`plate-*@catalogue`) first
//! registers the catalogue:
//!
//! 1. **Offset by votes**: each of the [`REGISTRATION_STARS`] brightest fits votes for its displacement to
//!    every catalogue star within [`SEARCH_PX`] of it, in cells of [`VOTE_CELL_PX`]; the cell with the most
//!    votes (with its eight neighbours) is the offset. Unlike the median of nearest neighbours, the vote is
//!    not fooled when the offset exceeds the catalogue's mean star spacing (≈ 8 px on the bulge at Hw 16.5).
//! 2. **Refinement**: the fits matched to the nearest catalogue star through the map within 3, 1.5, then
//!    1 px, and the map refitted by least squares after each: affine (`numerics::affine`; a shift with
//!    fewer than [`MIN_AFFINE_PAIRS`]), then, with at least [`MIN_QUADRATIC_PAIRS`] pairs, a full quadratic in each axis
//!    (`x' = Σ c_pq u^p v^q`, p + q ≤ 2, u, v the catalogue position from the pairs' centre in units of
//!    1000 px) — the low-order distortion beyond the design that the as-built instrument has. The last fit
//!    is made again without the pairs beyond 3 × its residual rms in either axis (blends, saturated cores).
//!
//! The registration reports its pairs and the rms of their residuals per axis (σ: the catalogue's error and
//! the fit's, in quadrature). A least-squares map of P parameters per axis over N pairs is itself wrong at
//! those pairs by σ √(P/N) per axis, rms (the mean leverage is P/N): [`Registration::predicted_error_px`],
//! what every registered position keeps. `scoring` measures the map's true error against it.

use crate::numerics::affine::{self, MIN_AFFINE_PAIRS};
use crate::numerics::neighbours::Neighbours;

/// The brightest fits that register the catalogue (bright stars are rarely mismatched).
pub const REGISTRATION_STARS: usize = 500;
/// How far the vote looks for the catalogue's offset, px (≈ 9″ of pointing error; the arrays' assembly
/// offsets are ≤ 15 px).
pub const SEARCH_PX: f64 = 20.0;
/// The vote's cell, px (a turn of 0.1° spreads an array's offsets over ±1.7 px).
pub const VOTE_CELL_PX: f64 = 2.0;
/// The match radii of the affine refinement, px.
const REFINE_RADII_PX: [f64; 3] = [3.0, 1.5, 1.0];
/// Fewest votes that make an offset; fewer leave the catalogue where it is.
const MIN_VOTES: u32 = 3;
/// The last fit leaves out pairs whose residual exceeds this many times the rms of the fit before.
const CLIP_SIGMA: f64 = 3.0;
/// Fewest pairs for the quadratic map (12 parameters); fewer keep the affine one.
pub const MIN_QUADRATIC_PAIRS: usize = 30;
/// Parameters per axis of the map a registration over `pairs` matched fits ends with when nothing fails
/// ([`Registration::parameters`]): the full quadratic from [`MIN_QUADRATIC_PAIRS`], affine from 6, else a
/// shift — what a planner expects it to absorb.
pub fn parameters_for(pairs: usize) -> usize {
    if pairs >= MIN_QUADRATIC_PAIRS {
        6
    } else if pairs >= MIN_AFFINE_PAIRS {
        3
    } else {
        1
    }
}

/// The quadratic map's unit of length, px.
const UNIT_PX: f64 = 1000.0;

/// The registration of a catalogue onto an image's fits.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Registration {
    /// Catalogue pixels ↦ this image's pixels, affine part (`numerics::affine`) …
    pub map: [f64; 6],
    /// … plus the quadratic one: x and y each `Σ q[axis][j] b_j(u, v)` over b = (u², u v, v²), u, v the
    /// catalogue position less `centre_px`, over 1000 px (zero for an affine map).
    pub quadratic: [[f64; 3]; 2],
    pub centre_px: (f64, f64),
    /// Fits matched in the last refinement.
    pub pairs: usize,
    /// Parameters per axis of the map fitted last (1: a shift, 3: affine, 6: quadratic).
    pub parameters: usize,
    /// Rms of the matched pairs' residuals per axis after the map, px.
    pub rms_px: f64,
}

impl Registration {
    /// No registration: the catalogue where its pixel columns put it.
    pub const NONE: Registration = Registration {
        map: affine::IDENTITY,
        quadratic: [[0.0; 3]; 2],
        centre_px: (0.0, 0.0),
        pairs: 0,
        parameters: 0,
        rms_px: f64::NAN,
    };

    /// Where the map puts a catalogue position.
    pub fn apply(&self, p: (f64, f64)) -> (f64, f64) {
        let [x, y] = affine::apply(&self.map, [p.0, p.1]);
        let b = quadratic_basis(p, self.centre_px);
        let q = |a: usize| (0..3).map(|j| self.quadratic[a][j] * b[j]).sum::<f64>();
        (x + q(0), y + q(1))
    }

    /// The catalogue position the map puts at image position `q`: the inverse, by fixed-point iteration from
    /// the inverse of the affine part (the quadratic part is ≪ 1 px: four steps leave ≲ 1e-12 px).
    pub fn invert(&self, q: (f64, f64)) -> (f64, f64) {
        let m = &self.map;
        let det = m[1] * m[5] - m[2] * m[4];
        if self.pairs == 0 || det.abs() < 1e-12 {
            return q;
        }
        let affine_inverse = |r: (f64, f64)| {
            let (u, v) = (r.0 - m[0], r.1 - m[3]);
            ((m[5] * u - m[2] * v) / det, (m[1] * v - m[4] * u) / det)
        };
        let mut p = affine_inverse(q);
        for _ in 0..6 {
            let b = quadratic_basis(p, self.centre_px);
            let qx: f64 = (0..3).map(|j| self.quadratic[0][j] * b[j]).sum();
            let qy: f64 = (0..3).map(|j| self.quadratic[1][j] * b[j]).sum();
            p = affine_inverse((q.0 - qx, q.1 - qy));
        }
        p
    }

    /// The map's own rms error per axis at the pairs it was fitted on, px: σ √(P/N) (see the module's
    /// documentation); NaN without a fit.
    pub fn predicted_error_px(&self) -> f64 {
        if self.pairs == 0 {
            return f64::NAN;
        }
        self.rms_px * (self.parameters as f64 / self.pairs as f64).sqrt()
    }

    /// The map's shift at `p` (image − catalogue), px.
    pub fn shift_at(&self, p: (f64, f64)) -> (f64, f64) {
        let q = self.apply(p);
        (q.0 - p.0, q.1 - p.1)
    }
}

/// Register `catalogue` (positions in this image's pixels through the header's WCS) onto the fitted
/// positions `fits` (with their fluxes): see the module's documentation. Too few votes or pairs: [`Registration::NONE`]
/// with the offset alone, or nothing.
pub fn register(fits: &[(f64, f64)], flux: &[f64], catalogue: &[(f64, f64)]) -> Registration {
    let mut bright: Vec<usize> = (0..fits.len())
        .filter(|&k| fits[k].0.is_finite() && fits[k].1.is_finite())
        .collect();
    bright.sort_by(|&a, &b| flux[b].total_cmp(&flux[a]));
    bright.truncate(REGISTRATION_STARS);
    let bpos: Vec<(f64, f64)> = bright.iter().map(|&k| fits[k]).collect();
    let cat: Vec<usize> = (0..catalogue.len())
        .filter(|&k| catalogue[k].0.is_finite() && catalogue[k].1.is_finite())
        .collect();
    let cpos: Vec<(f64, f64)> = cat.iter().map(|&k| catalogue[k]).collect();
    let Some(offset) = voted_offset(&bpos, &cpos) else {
        return Registration::NONE;
    };
    let mut reg = Registration {
        map: [offset.0, 1.0, 0.0, offset.1, 0.0, 1.0],
        parameters: 1,
        ..Registration::NONE
    };
    for (i, radius) in REFINE_RADII_PX.iter().enumerate() {
        let mut pairs = matched_pairs(&bpos, &cpos, &reg, *radius);
        let last = i + 1 == REFINE_RADII_PX.len();
        // the last fit twice: the second without the pairs beyond CLIP_SIGMA of the first (a blend, a
        // saturated core, a catalogue star that moved)
        for clip in [false, last] {
            if clip {
                // (a floor: a map that fits exactly keeps its pairs)
                let limit = (CLIP_SIGMA * reg.rms_px).max(1e-6);
                pairs.retain(|(c, f)| {
                    let p = reg.apply((c[0], c[1]));
                    (p.0 - f[0]).abs() <= limit && (p.1 - f[1]).abs() <= limit
                });
            }
            if pairs.len() < MIN_VOTES as usize {
                return reg;
            }
            reg = if last && parameters_for(pairs.len()) == 6 {
                fit_quadratic(&pairs).unwrap_or_else(|| affine_of(&pairs))
            } else {
                affine_of(&pairs)
            };
            let ss: f64 = pairs
                .iter()
                .map(|(c, f)| {
                    let p = reg.apply((c[0], c[1]));
                    (p.0 - f[0]).powi(2) + (p.1 - f[1]).powi(2)
                })
                .sum();
            reg.pairs = pairs.len();
            reg.rms_px = (ss / (2.0 * pairs.len() as f64)).sqrt();
        }
    }
    reg
}

/// (u², u v, v²) of `p` about `centre` in units of [`UNIT_PX`].
fn quadratic_basis(p: (f64, f64), centre: (f64, f64)) -> [f64; 3] {
    let (u, v) = ((p.0 - centre.0) / UNIT_PX, (p.1 - centre.1) / UNIT_PX);
    [u * u, u * v, v * v]
}

/// The affine registration of `pairs` (catalogue, fit).
fn affine_of(pairs: &[([f64; 2], [f64; 2])]) -> Registration {
    Registration {
        map: affine::fit(pairs),
        parameters: parameters_for(pairs.len()).min(3),
        ..Registration::NONE
    }
}

/// The quadratic registration of `pairs`: per axis, least squares over (1, u, v, u², u v, v²) about the
/// pairs' centre; `None` when degenerate.
fn fit_quadratic(pairs: &[([f64; 2], [f64; 2])]) -> Option<Registration> {
    let n = pairs.len() as f64;
    let centre = (
        pairs.iter().map(|p| p.0[0]).sum::<f64>() / n,
        pairs.iter().map(|p| p.0[1]).sum::<f64>() / n,
    );
    let mut design = Vec::with_capacity(pairs.len() * 6);
    for (c, _) in pairs {
        let (u, v) = ((c[0] - centre.0) / UNIT_PX, (c[1] - centre.1) / UNIT_PX);
        design.extend_from_slice(&[1.0, u, v, u * u, u * v, v * v]);
    }
    let w = vec![1.0; pairs.len()];
    let axis = |a: usize| {
        let y: Vec<f64> = pairs.iter().map(|(_, f)| f[a]).collect();
        crate::numerics::linalg::weighted_lstsq(&design, &y, &w, 6).map(|(b, _)| b)
    };
    let (bx, by) = (axis(0)?, axis(1)?);
    // the affine part in catalogue pixels: b0 + b1 (x − cx)/L + b2 (y − cy)/L
    let affine_part = |b: &[f64]| {
        let (s1, s2) = (b[1] / UNIT_PX, b[2] / UNIT_PX);
        [b[0] - s1 * centre.0 - s2 * centre.1, s1, s2]
    };
    let (ax, ay) = (affine_part(&bx), affine_part(&by));
    Some(Registration {
        map: [ax[0], ax[1], ax[2], ay[0], ay[1], ay[2]],
        quadratic: [[bx[3], bx[4], bx[5]], [by[3], by[4], by[5]]],
        centre_px: centre,
        parameters: 6,
        ..Registration::NONE
    })
}

/// The catalogue's offset (fit − catalogue) by the vote of step 1, or none with fewer than [`MIN_VOTES`].
fn voted_offset(fits: &[(f64, f64)], catalogue: &[(f64, f64)]) -> Option<(f64, f64)> {
    let nb = Neighbours::new(catalogue);
    let mut votes: std::collections::HashMap<(i64, i64), (u32, f64, f64)> =
        std::collections::HashMap::new();
    for &(x, y) in fits {
        for k in nb.within(x, y, SEARCH_PX) {
            let d = (x - catalogue[k].0, y - catalogue[k].1);
            let cell = (
                (d.0 / VOTE_CELL_PX).floor() as i64,
                (d.1 / VOTE_CELL_PX).floor() as i64,
            );
            let v = votes.entry(cell).or_default();
            v.0 += 1;
            v.1 += d.0;
            v.2 += d.1;
        }
    }
    // the cell whose 3 × 3 neighbourhood holds the most votes (ties: the smallest cell, for determinism)
    let around = |c: (i64, i64)| {
        let mut t = (0u32, 0.0, 0.0);
        for dy in -1..=1 {
            for dx in -1..=1 {
                if let Some(v) = votes.get(&(c.0 + dx, c.1 + dy)) {
                    t = (t.0 + v.0, t.1 + v.1, t.2 + v.2);
                }
            }
        }
        t
    };
    let best = votes
        .keys()
        .map(|&c| (around(c), c))
        .max_by(|a, b| a.0.0.cmp(&b.0.0).then(b.1.cmp(&a.1)))?;
    let ((n, sx, sy), _) = best;
    (n >= MIN_VOTES).then(|| (sx / n as f64, sy / n as f64))
}

/// (catalogue, fit) pairs: each fit with its nearest catalogue star through `reg` within `radius_px`.
fn matched_pairs(
    fits: &[(f64, f64)],
    catalogue: &[(f64, f64)],
    reg: &Registration,
    radius_px: f64,
) -> Vec<([f64; 2], [f64; 2])> {
    let moved: Vec<(f64, f64)> = catalogue.iter().map(|&c| reg.apply(c)).collect();
    let nb = Neighbours::new(&moved);
    fits.iter()
        .filter_map(|&(x, y)| {
            let d2 = |k: usize| (moved[k].0 - x).powi(2) + (moved[k].1 - y).powi(2);
            nb.within(x, y, radius_px)
                .into_iter()
                .min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
                .map(|k| ([catalogue[k].0, catalogue[k].1], [x, y]))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, StandardNormal};

    /// A crowded catalogue (one star per 100 px², denser than the bulge's at Hw 16.5), the image's fits
    /// the catalogue's brightest third moved by a known affine map (a 12-px offset and a 0.1° turn) plus
    /// noise.
    fn field(
        map: &[f64; 6],
        noise_px: f64,
    ) -> (Vec<(f64, f64)>, Vec<f64>, Vec<(f64, f64)>, Vec<(f64, f64)>) {
        let mut r = rand::rngs::StdRng::seed_from_u64(5);
        let n = 1968.0;
        let cat: Vec<(f64, f64)> = (0..38_000)
            .map(|_| (r.random::<f64>() * n, r.random::<f64>() * n))
            .collect();
        let mut fits = Vec::new();
        let mut flux = Vec::new();
        let mut truth = Vec::new();
        for (k, &c) in cat.iter().enumerate().step_by(3) {
            let [x, y] = affine::apply(map, [c.0, c.1]);
            let (zx, zy): (f64, f64) =
                (StandardNormal.sample(&mut r), StandardNormal.sample(&mut r));
            fits.push((x + noise_px * zx, y + noise_px * zy));
            flux.push(1e6 / (1.0 + k as f64));
            truth.push((x, y));
        }
        (fits, flux, cat, truth)
    }

    fn turned(offset: (f64, f64), deg: f64) -> [f64; 6] {
        let (s, c) = deg.to_radians().sin_cos();
        // about the array's centre
        let m = 983.5;
        [
            offset.0 + m - c * m + s * m,
            c,
            -s,
            offset.1 + m - s * m - c * m,
            s,
            c,
        ]
    }

    #[test]
    fn an_offset_beyond_the_star_spacing_and_a_turn_are_registered() {
        let map = turned((12.0, -9.5), 0.1);
        let (fits, flux, cat, _) = field(&map, 0.02);
        let reg = register(&fits, &flux, &cat);
        // every bright fit paired, less the few beyond 3σ (0.5 % of a Gaussian's per axis)
        assert!(reg.pairs >= REGISTRATION_STARS - 15, "{reg:?}");
        // the map's error at the array's corners and centre: ≪ the noise
        for p in [
            (0.0, 0.0),
            (1967.0, 0.0),
            (0.0, 1967.0),
            (1967.0, 1967.0),
            (983.5, 983.5),
        ] {
            let a = reg.apply(p);
            let [x, y] = affine::apply(&map, [p.0, p.1]);
            let e = (a.0 - x).hypot(a.1 - y);
            assert!(e < 0.01, "{e} px at {p:?}: {reg:?}");
        }
        // the residual rms is the noise (500 pairs: ±3 %, checked to 4σ)
        assert!((reg.rms_px / 0.02 - 1.0).abs() < 0.13, "{}", reg.rms_px);
    }

    #[test]
    fn the_median_of_nearest_neighbours_fails_where_the_vote_does_not() {
        // the offset this registration replaces: at a 12-px offset the nearest catalogue star is mostly
        // another star, and the median displacement is not the offset
        let map = turned((12.0, -9.5), 0.0);
        let (fits, flux, cat, _) = field(&map, 0.02);
        let bright: Vec<(f64, f64)> = fits.iter().take(REGISTRATION_STARS).copied().collect();
        let median = crate::analysis::detection::common_offset(&bright, &cat, SEARCH_PX);
        assert!(
            (median.0 - 12.0).hypot(median.1 + 9.5) > 1.0,
            "the median found the offset: {median:?}"
        );
        let reg = register(&fits, &flux, &cat);
        let s = reg.shift_at((983.5, 983.5));
        assert!((s.0 - 12.0).hypot(s.1 + 9.5) < 0.01, "{reg:?}");
    }

    #[test]
    fn a_quadratic_distortion_beyond_the_design_is_registered() {
        // 0.05 px of x² and y v at the array's corners (≈ 1000 px from its centre), on a turned offset
        let map = turned((-6.0, 4.0), -0.05);
        let quad = |p: (f64, f64)| {
            let (u, v) = ((p.0 - 983.5) / 983.5, (p.1 - 983.5) / 983.5);
            (0.05 * u * u, 0.05 * u * v)
        };
        let (mut fits, flux, cat, _) = field(&map, 0.0);
        for (f, c) in fits.iter_mut().zip(cat.iter().step_by(3)) {
            let d = quad(*c);
            *f = (f.0 + d.0, f.1 + d.1);
        }
        let reg = register(&fits, &flux, &cat);
        assert_eq!(reg.parameters, 6);
        let worst = cat
            .iter()
            .step_by(97)
            .map(|&c| {
                let [x, y] = affine::apply(&map, [c.0, c.1]);
                let d = quad(c);
                let r = reg.apply(c);
                (r.0 - x - d.0).hypot(r.1 - y - d.1)
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-3, "{worst} px");
    }

    /// The map's predicted error σ √(P/N) against its true error over many noisy catalogues: the mean of
    /// the squared errors over 100 trials of 500 pairs (12 degrees of freedom each) is known to ≈ 4 %, so
    /// the rms ratio to 2 %: 0.9 … 1.1 is ≥ 5σ.
    #[test]
    fn the_predicted_error_of_the_map_is_its_error() {
        let map = turned((3.0, 2.0), 0.02);
        let mut r = rand::rngs::StdRng::seed_from_u64(11);
        let sigma = 0.05;
        let (mut actual, mut predicted) = (0.0, 0.0);
        let trials = 100;
        for _ in 0..trials {
            // 500 stars ≥ 40 px apart on a jittered grid: every match unambiguous
            let cat: Vec<(f64, f64)> = (0..500)
                .map(|k| {
                    let (i, j) = ((k % 25) as f64, (k / 25) as f64);
                    (
                        40.0 + 76.0 * i + 20.0 * r.random::<f64>(),
                        40.0 + 90.0 * j + 20.0 * r.random::<f64>(),
                    )
                })
                .collect();
            let fits: Vec<(f64, f64)> = cat
                .iter()
                .map(|&c| {
                    let [x, y] = affine::apply(&map, [c.0, c.1]);
                    let (zx, zy): (f64, f64) =
                        (StandardNormal.sample(&mut r), StandardNormal.sample(&mut r));
                    (x + sigma * zx, y + sigma * zy)
                })
                .collect();
            let flux = vec![1.0; fits.len()];
            let reg = register(&fits, &flux, &cat);
            assert!(reg.pairs >= 485 && reg.parameters == 6, "{reg:?}");
            let ss: f64 = cat
                .iter()
                .map(|&c| {
                    let [x, y] = affine::apply(&map, [c.0, c.1]);
                    let p = reg.apply(c);
                    (p.0 - x).powi(2) + (p.1 - y).powi(2)
                })
                .sum();
            actual += ss / (2.0 * cat.len() as f64);
            predicted += reg.predicted_error_px().powi(2);
        }
        let ratio = (actual / predicted).sqrt();
        assert!((0.9..=1.1).contains(&ratio), "true ÷ predicted {ratio}");
        // and it is the formula: σ √(6/N), N ≈ 497 after the clip (whose 3σ cut takes 1.3 % off the rms)
        let expected = sigma * (6.0f64 / 497.0).sqrt();
        let mean = (predicted / trials as f64).sqrt();
        assert!(
            (mean / expected - 1.0).abs() < 0.03,
            "{mean} against {expected}"
        );
    }

    #[test]
    fn nothing_to_register_leaves_the_catalogue_where_it_is() {
        let none = register(&[], &[], &[(1.0, 1.0)]);
        assert_eq!((none.map, none.pairs), (affine::IDENTITY, 0));
        // two stars cannot out-vote chance
        let reg = register(
            &[(5.0, 5.0), (50.0, 50.0)],
            &[1.0, 2.0],
            &[(6.0, 5.0), (51.0, 50.0)],
        );
        assert_eq!(reg.map, affine::IDENTITY);
    }
}
