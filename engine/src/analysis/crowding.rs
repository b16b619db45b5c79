//! Crowding: a setting of the one analysis pipeline. `Off` analyses every star as isolated (detection, the
//! ePSF from isolated stars, one fit per star); `On` runs the crowded-field analysis
//! ([`crate::analysis::crowded`]: deblending, neighbour-subtracted ePSF, grouped fits, residual detection);
//! `Auto` (the default) decides from the image's measured source density.
//!
//! **The automatic choice.** The peaks of the image (local 3 × 3 maxima above `analysis.detect_sigma` ×
//! the robust noise; a peak within [`SAME_STAR_PX`] of a brighter one is that star's, as the isolated
//! detection has it: a star smeared by a large jitter shows several) are found, and those with another peak
//! within the link radius r of the grouped fits ([`crate::analysis::crowded::link_radius_px`]) counted. Above [`CROWDED_NEIGHBOUR_FRACTION`] of the
//! peaks with a neighbour, the isolated analysis would fit a measurable share of its stars with a
//! neighbour's light unmodelled, so the field is crowded. For stars scattered at random with ρ peaks per
//! pixel the fraction is `1 − exp(−ρπr²)` (Poisson; reported beside it): the paper's 400-star grid has
//! none within r, the mock bulge (≈ 2.5·10⁴ stars an array, ρπr² ≈ 0.5) about 40 %. The choice needs noise:
//! in a noise-free image (a test's) every ripple of a star's wings stands above the threshold, so set the
//! crowding explicitly there.

use crate::analysis::crowded::neighbours::Neighbours;
use crate::analysis::detection::{SAME_STAR_PX, drop_close, sky_and_noise};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use rayon::prelude::*;

/// Fraction of stars with a neighbour within the link radius above which `Auto` chooses the crowded
/// analysis.
pub const CROWDED_NEIGHBOUR_FRACTION: f64 = 0.05;

pub use crate::config::Crowding;

/// What the automatic choice measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Density {
    /// Local maxima above the detection threshold.
    pub peaks: usize,
    /// Peaks per pixel of unmasked image.
    pub per_px: f64,
    /// Fraction of stars scattered at random with a neighbour within the link radius, `1 − exp(−ρπr²)`
    /// (for comparison: a regular grid has none).
    pub poisson_fraction: f64,
    /// Measured fraction of the peaks with another peak within the link radius (what decides).
    pub neighbour_fraction: f64,
}

/// Measure the source density of an image and the fraction of its peaks with another peak within the link
/// radius: O(pixels + peaks log peaks), whatever the number of stars.
pub fn density(img: &AnalysisImage, cfg: &AnalysisCfg) -> Density {
    let (sky, noise) = sky_and_noise(img);
    let thr = sky + cfg.detect_sigma * noise;
    let (nx, ny) = (img.nx, img.ny);
    let mut peaks: Vec<(f64, f64, f64)> = (1..ny.saturating_sub(1))
        .into_par_iter()
        .flat_map_iter(|y| {
            (1..nx - 1)
                .filter(move |&x| {
                    let i = y * nx + x;
                    let p = img.e[i];
                    p > thr
                        && !img.bad[i]
                        && (-1i64..=1).all(|dy| {
                            (-1i64..=1).all(|dx| {
                                let j = ((y as i64 + dy) as usize) * nx + (x as i64 + dx) as usize;
                                j == i || img.e[j] < p || (img.e[j] == p && j > i)
                            })
                        })
                })
                .map(move |x| (img.e[y * nx + x], x as f64, y as f64))
        })
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    let peaks = drop_close(peaks.into_iter().map(|(_, x, y)| (x, y)), SAME_STAR_PX);
    let good = img.bad.iter().filter(|b| !**b).count().max(1);
    let per_px = peaks.len() as f64 / good as f64;
    let r = crate::analysis::crowded::link_radius_px(cfg);
    let nb = Neighbours::new(&peaks);
    let with_neighbour = peaks
        .iter()
        .filter(|&&(x, y)| nb.within(x, y, r).len() > 1)
        .count();
    Density {
        peaks: peaks.len(),
        per_px,
        poisson_fraction: 1.0 - (-per_px * std::f64::consts::PI * r * r).exp(),
        neighbour_fraction: if peaks.is_empty() {
            0.0
        } else {
            with_neighbour as f64 / peaks.len() as f64
        },
    }
}

/// Whether the image is analysed as a crowded field, and the density measured (with `Auto` only).
pub fn is_crowded(
    img: &AnalysisImage,
    cfg: &AnalysisCfg,
    crowding: Crowding,
) -> (bool, Option<Density>) {
    match crowding {
        Crowding::On => (true, None),
        Crowding::Off => (false, None),
        Crowding::Auto => {
            let d = density(img, cfg);
            (d.neighbour_fraction > CROWDED_NEIGHBOUR_FRACTION, Some(d))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Single-pixel "stars" of 1000 e⁻ on a faintly textured sky at the given positions.
    fn image(n: usize, stars: &[(usize, usize)]) -> AnalysisImage {
        let mut e: Vec<f64> = (0..n * n).map(|k| ((k * 7919) % 13) as f64 * 0.1).collect();
        for &(x, y) in stars {
            e[y * n + x] = 1000.0;
        }
        AnalysisImage {
            nx: n,
            ny: n,
            e,
            bad: vec![false; n * n],
            var_floor_e2: 1.0,
            flat_sigma: 0.0,
            plate_scale_mas: 471.0,
        }
    }

    fn grid(n: usize, step: usize) -> Vec<(usize, usize)> {
        (5..n - 5)
            .step_by(step)
            .flat_map(|y| (5..n - 5).step_by(step).map(move |x| (x, y)))
            .collect()
    }

    /// A grid with its neighbours beyond r is isolated however many stars it has; one with them inside r
    /// is crowded; every peak is counted.
    #[test]
    fn grids_are_judged_by_their_neighbours_not_their_count() {
        let cfg = crate::config::Config::default().analysis;
        let r = crate::analysis::crowded::link_radius_px(&cfg);
        let far = grid(400, (r.ceil() as usize) + 2);
        let d = density(&image(400, &far), &cfg);
        assert_eq!(d.peaks, far.len());
        assert_eq!(d.neighbour_fraction, 0.0);
        assert!(!is_crowded(&image(400, &far), &cfg, Crowding::Auto).0);
        let near = grid(200, (r.floor() as usize).max(3) - 1);
        let d = density(&image(200, &near), &cfg);
        assert_eq!(d.peaks, near.len());
        assert_eq!(d.neighbour_fraction, 1.0);
        assert!(is_crowded(&image(200, &near), &cfg, Crowding::Auto).0);
        assert!(is_crowded(&image(400, &far), &cfg, Crowding::On).0);
        assert!(!is_crowded(&image(200, &near), &cfg, Crowding::Off).0);
        assert!(
            Crowding::parse("sometimes")
                .expect_err("not a crowding")
                .contains("auto, on, off")
        );
    }

    /// A grid of stars each smeared by a large jitter into two peaks 2 px apart (the paper's scene in an
    /// exposure with a ≈ 1-arcsec drift) is isolated: the peaks of one star are one star's.
    #[test]
    fn a_smeared_star_is_one_star_not_a_crowd() {
        let cfg = crate::config::Config::default().analysis;
        let r = crate::analysis::crowded::link_radius_px(&cfg);
        let centres = grid(400, (r.ceil() as usize) + 4);
        let lobes: Vec<(usize, usize)> = centres
            .iter()
            .flat_map(|&(x, y)| [(x, y), (x + 2, y + 1)])
            .collect();
        let d = density(&image(400, &lobes), &cfg);
        assert_eq!(d.peaks, centres.len(), "{d:?}");
        assert!(!is_crowded(&image(400, &lobes), &cfg, Crowding::Auto).0);
    }

    /// Stars at random positions: the measured fraction with a neighbour is the Poisson
    /// `1 − exp(−ρπr²)` within its binomial error (3σ, plus 0.01 for the pairs closer than `SAME_STAR_PX`
    /// that count as one star).
    #[test]
    fn random_stars_have_the_poisson_fraction_of_neighbours() {
        let cfg = crate::config::Config::default().analysis;
        let n = 400;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let stars: Vec<(usize, usize)> = (0..600)
            .map(|_| (rng.random_range(2..n - 2), rng.random_range(2..n - 2)))
            .collect();
        let d = density(&image(n, &stars), &cfg);
        let f = d.poisson_fraction;
        let sigma = (f * (1.0 - f) / d.peaks as f64).sqrt();
        assert!(
            (d.neighbour_fraction - f).abs() < 3.0 * sigma + 0.01,
            "measured {} against Poisson {f} ± {sigma}",
            d.neighbour_fraction
        );
    }
}
