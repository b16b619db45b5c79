//! Crowding: a setting of the one analysis pipeline. `Off` analyses every star as isolated (detection, the
//! ePSF from isolated stars, one fit per star); `On` runs the crowded-field analysis
//! ([`crate::analysis::crowded`]: deblending, neighbour-subtracted ePSF, grouped fits, residual detection);
//! `Auto` (the default) decides from the image's measured source density.
//!
//! **The automatic choice.** The peaks of the image (local 3 × 3 maxima above `analysis.detect_sigma` ×
//! the robust noise) are found, one per source — a peak within [`SAME_STAR_PX`] of a brighter one, or joined
//! to one by a ridge (no [`SADDLE_DEPTH`] valley between them), is that star's: a star smeared along a large
//! jitter track shows several — and those with another within the link radius r of the grouped fits
//! ([`crate::analysis::crowded::link_radius_px`]) counted. Above [`CROWDED_NEIGHBOUR_FRACTION`] of the
//! peaks with a neighbour, the isolated analysis would fit a measurable share of its stars with a
//! neighbour's light unmodelled, so the field is crowded. For stars scattered at random with ρ peaks per
//! pixel the fraction is `1 − exp(−ρπr²)` (Poisson; reported beside it): the paper's 400-star grid has
//! none within r, the mock bulge (≈ 2.5·10⁴ stars an array, ρπr² ≈ 0.5) about 40 %. The choice needs noise:
//! in a noise-free image (a test's) every ripple of a star's wings stands above the threshold, so set the
//! crowding explicitly there.

use crate::analysis::detection::{SAME_STAR_PX, SkyNoise, drop_close, keep_first};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::neighbours::Neighbours;
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
    let sn = SkyNoise::of(img);
    let sky = sn.sky;
    let (nx, ny) = (img.nx, img.ny);
    let sn = &sn;
    let mut peaks: Vec<(f64, f64, f64)> = (1..ny.saturating_sub(1))
        .into_par_iter()
        .flat_map_iter(|y| {
            (1..nx - 1)
                .filter(move |&x| {
                    let i = y * nx + x;
                    let p = img.e[i];
                    p > sky + cfg.detect_sigma * sn.at(img, i)
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
    let close = drop_close(peaks.iter().map(|&(_, x, y)| (x, y)), SAME_STAR_PX);
    let value = |x: f64, y: f64| img.e[y as usize * nx + x as usize];
    let r = crate::analysis::crowded::link_radius_px(cfg);
    let peaks = one_per_source(img, sky, &close, &value, r);
    let good = img.bad.iter().filter(|b| !**b).count().max(1);
    let per_px = peaks.len() as f64 / good as f64;
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

/// Fraction of the fainter peak's height above the sky that the image must fall between two peaks for them to
/// be two sources: a star smeared along its jitter track shows maxima joined by a ridge (a shallow saddle),
/// two stars a valley (two PSF cores 2 px apart dip to ≈ 20 % between them).
pub const SADDLE_DEPTH: f64 = 0.5;

/// Of peaks sorted brightest first, one per source: a peak joined to a brighter one within `reach_px` by a
/// ridge — the image between them never falls below [`SADDLE_DEPTH`] of the fainter's height above `sky` (its
/// nearest pixels sampled every ½ px along the segment) — is that source's ([`keep_first`]: O(N)).
fn one_per_source(
    img: &AnalysisImage,
    sky: f64,
    sorted: &[(f64, f64)],
    value: &dyn Fn(f64, f64) -> f64,
    reach_px: f64,
) -> Vec<(f64, f64)> {
    let ridge = |p: (f64, f64), q: (f64, f64)| {
        let fainter = value(p.0, p.1).min(value(q.0, q.1));
        let steps = ((q.0 - p.0).hypot(q.1 - p.1) * 2.0).ceil().max(1.0) as usize;
        let lowest = (1..steps)
            .map(|k| {
                let t = k as f64 / steps as f64;
                let (x, y) = (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1));
                let i = y.round() as usize * img.nx + x.round() as usize;
                if img.bad[i] { fainter } else { img.e[i] }
            })
            .fold(fainter, f64::min);
        fainter - lowest < (1.0 - SADDLE_DEPTH) * (fainter - sky)
    };
    keep_first(sorted.iter().copied(), reach_px.max(1.0), |p, q| {
        (q.0 - p.0).hypot(q.1 - p.1) <= reach_px && ridge(p, q)
    })
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
            var_floor_px_e2: None,
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

    /// Stars smeared along a 6-px jitter track that dwells at both ends (two local maxima ≈ 4 px apart,
    /// beyond `SAME_STAR_PX`) are one source each: their maxima are joined by a ridge. Two PSF cores 4 px
    /// apart are two.
    #[test]
    fn a_streak_is_one_source_and_a_pair_two() {
        let cfg = crate::config::Config::default().analysis;
        let n = 300;
        let sigma: f64 = 0.8;
        let mut e = vec![10.0; n * n];
        let mut add = |cx: f64, cy: f64, f: f64| {
            for py in (cy as usize).saturating_sub(5)..(cy as usize + 6).min(n) {
                for px in (cx as usize).saturating_sub(5)..(cx as usize + 6).min(n) {
                    let r2 = (px as f64 - cx).powi(2) + (py as f64 - cy).powi(2);
                    e[py * n + px] += f * (-r2 / (2.0 * sigma * sigma)).exp();
                }
            }
        };
        let centres: Vec<(f64, f64)> = (0..5)
            .flat_map(|j| (0..5).map(move |i| (30.0 + 55.0 * i as f64, 30.0 + 55.0 * j as f64)))
            .collect();
        for &(x, y) in &centres {
            for k in 0..600 {
                let t = k as f64 / 599.0;
                // the track runs 6 px and dwells at both ends: two maxima ≈ 4 px apart on one ridge
                let dwell =
                    1.0 + 3.0 * ((-(t / 0.04).powi(2)).exp() + (-((t - 1.0) / 0.04).powi(2)).exp());
                add(x + 5.75 * t, y + 1.7 * t, 4.0 * dwell);
            }
        }
        let img = AnalysisImage {
            nx: n,
            ny: n,
            e: e.clone(),
            bad: vec![false; n * n],
            var_floor_e2: 1.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
            plate_scale_mas: 471.0,
        };
        // each streak has two local maxima, further apart than SAME_STAR_PX
        let (sky, noise) = crate::analysis::detection::sky_and_noise(&img);
        let maxima = (1..n - 1)
            .flat_map(|y| (1..n - 1).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = e[y * n + x];
                p > sky + cfg.detect_sigma * noise
                    && (0..9).all(|k| {
                        let (xx, yy) = (x + k % 3 - 1, y + k / 3 - 1);
                        (xx, yy) == (x, y) || e[yy * n + xx] < p
                    })
            })
            .count();
        assert!(maxima >= 2 * centres.len(), "{maxima} maxima");
        let d = density(&img, &cfg);
        assert_eq!(d.peaks, centres.len(), "{d:?}");
        assert!(!is_crowded(&img, &cfg, Crowding::Auto).0);
        // a pair of cores 4 px apart: a valley between them, two sources
        let mut e2 = vec![10.0; n * n];
        for &(x, y) in &centres {
            for (dx, f) in [(0.0, 3000.0), (4.0, 2000.0)] {
                for py in (y as usize) - 5..(y as usize) + 6 {
                    for px in (x as usize) - 5..(x as usize) + 10 {
                        let r2 = (px as f64 - x - dx).powi(2) + (py as f64 - y).powi(2);
                        e2[py * n + px] += f * (-r2 / (2.0 * sigma * sigma)).exp();
                    }
                }
            }
        }
        let pairs = AnalysisImage { e: e2, ..img };
        assert_eq!(density(&pairs, &cfg).peaks, 2 * centres.len());
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
