//! Finding the stars: local maxima above the noise, their starting values, which of them may build the ePSF,
//! and the cross-match of positions to reference positions.

use crate::analysis::epsf::build::{self, StarStart};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::neighbours::{Neighbours, nearest_of};
use crate::numerics::stats;
use rayon::prelude::*;

/// Two peaks closer than this are one star's (a jitter-smeared star can show several), px.
pub const SAME_STAR_PX: f64 = 3.0;

/// Of positions sorted brightest first, those not within `d_px` of a brighter one kept before.
pub fn drop_close(sorted: impl IntoIterator<Item = (f64, f64)>, d_px: f64) -> Vec<(f64, f64)> {
    keep_first(sorted, d_px, |p, q| {
        (p.0 - q.0).powi(2) + (p.1 - q.1).powi(2) < d_px * d_px
    })
}

/// Of positions sorted brightest first, those that `same` ties to no brighter one kept before, where `same`
/// is true only of pairs within `reach_px`: O(N log N) with the k-d tree of every position (each asks its
/// neighbours within reach that were kept).
pub fn keep_first(
    sorted: impl IntoIterator<Item = (f64, f64)>,
    reach_px: f64,
    same: impl Fn((f64, f64), (f64, f64)) -> bool,
) -> Vec<(f64, f64)> {
    let pts: Vec<(f64, f64)> = sorted.into_iter().collect();
    keep_first_of(&pts, reach_px, |k, j| same(pts[k], pts[j]))
        .into_iter()
        .map(|k| pts[k])
        .collect()
}

/// [`keep_first`] by index: the indices of `sorted` (brightest first) that `same(k, j)` ties to no kept
/// brighter `j` within `reach_px`, in order.
pub fn keep_first_of(
    sorted: &[(f64, f64)],
    reach_px: f64,
    same: impl Fn(usize, usize) -> bool,
) -> Vec<usize> {
    let nb = Neighbours::new(sorted);
    let mut is_kept = vec![false; sorted.len()];
    let mut kept = Vec::new();
    for (k, &p) in sorted.iter().enumerate() {
        let tied = nb
            .near(p.0, p.1, reach_px)
            .into_iter()
            .any(|j| is_kept[j] && same(k, j));
        if !tied {
            is_kept[k] = true;
            kept.push(k);
        }
    }
    kept
}

/// Local maxima (5 × 5) above `nsigma` × the image's robust noise over its median; brightest first, closer
/// than [`SAME_STAR_PX`] to a brighter one dropped.
pub fn detect(img: &AnalysisImage, nsigma: f64) -> Vec<(f64, f64)> {
    let sn = SkyNoise::of(img);
    let thr_at = |i: usize| sn.sky + nsigma * sn.at(img, i);
    let (nx, ny) = (img.nx, img.ny);
    let rows: Vec<Vec<(f64, f64, f64)>> = (0..ny)
        .into_par_iter()
        .map(|y| {
            let mut v = Vec::new();
            for x in 0..nx {
                let i = y * nx + x;
                let p = img.e[i];
                let thr = thr_at(i);
                // saturated pixels count as peaks (their value is clipped, not low)
                if !(p > thr || img.bad[i] && p > thr * 0.5) {
                    continue;
                }
                let mut is_max = true;
                'n: for yy in y.saturating_sub(2)..=(y + 2).min(ny - 1) {
                    for xx in x.saturating_sub(2)..=(x + 2).min(nx - 1) {
                        let q = img.e[yy * nx + xx];
                        if q > p || (q == p && (yy * nx + xx) < i) {
                            is_max = false;
                            break 'n;
                        }
                    }
                }
                if is_max {
                    v.push((p, x as f64, y as f64));
                }
            }
            v
        })
        .collect();
    let mut peaks: Vec<(f64, f64, f64)> = rows
        .into_iter()
        .flatten()
        .map(|(p, x, y)| {
            let i = y as usize * nx + x as usize;
            if img.bad[i] {
                // a saturated core is a plateau: the star is at its centre, not at its first pixel
                let (cx, cy) = plateau_centre(img, x as usize, y as usize);
                (p, cx, cy)
            } else {
                (p, x, y)
            }
        })
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    drop_close(peaks.into_iter().map(|(_, x, y)| (x, y)), SAME_STAR_PX)
}

/// The image's sky level and pixel noise: median and MAD-σ of every 7th unmasked pixel (robust to the
/// stars as long as they cover less than half of the image).
pub fn sky_and_noise(img: &AnalysisImage) -> (f64, f64) {
    let good: Vec<f64> = img
        .e
        .iter()
        .zip(&img.bad)
        .filter(|(_, b)| !**b)
        .map(|(v, _)| *v)
        .step_by(7)
        .collect();
    (stats::median(&good), stats::mad_sigma(&good).max(1e-9))
}

/// The sky level and each pixel's noise. Where the read-noise floor is one value, the noise is
/// [`sky_and_noise`]'s; where it varies (amplifiers of different read noise), the MAD-σ of the pixels of
/// each floor apart, so that a noisy amplifier's half neither floods the detection with its noise peaks
/// nor raises the quiet half's threshold.
#[derive(Debug, Clone)]
pub struct SkyNoise {
    pub sky: f64,
    /// The image's noise over every pixel (the typical value).
    pub noise: f64,
    /// (floor e⁻², noise) of each floor's pixels, where the floor varies.
    by_floor: Vec<(f64, f64)>,
}

impl SkyNoise {
    pub fn of(img: &AnalysisImage) -> Self {
        let (sky, noise) = sky_and_noise(img);
        let mut by_floor = Vec::new();
        if let Some(map) = &img.var_floor_px_e2 {
            let mut floors: Vec<f64> = Vec::new();
            for f in map {
                // a floor per amplifier: a handful of values
                if !floors.contains(f) && floors.len() < MAX_FLOORS {
                    floors.push(*f);
                }
            }
            for f in floors {
                let good: Vec<f64> = (0..img.e.len())
                    .filter(|&i| !img.bad[i] && map[i] == f)
                    .step_by(7)
                    .map(|i| img.e[i])
                    .collect();
                if good.len() >= 16 {
                    by_floor.push((f, stats::mad_sigma(&good).max(1e-9)));
                }
            }
        }
        Self {
            sky,
            noise,
            by_floor,
        }
    }

    /// The noise of pixel `i`.
    #[inline]
    pub fn at(&self, img: &AnalysisImage, i: usize) -> f64 {
        if self.by_floor.is_empty() {
            return self.noise;
        }
        let f = img.floor_e2(i);
        self.by_floor
            .iter()
            .find(|b| b.0 == f)
            .map_or(self.noise, |b| b.1)
    }
}

/// The most distinct read-noise floors [`SkyNoise`] measures apart (one per amplifier: 4 at most on the
/// instruments read).
const MAX_FLOORS: usize = 8;

/// Centroid (unweighted) of the 4-connected region of masked pixels containing (x, y), within 40 px: the
/// centre of a saturated core.
pub(crate) fn plateau_centre(img: &AnalysisImage, x: usize, y: usize) -> (f64, f64) {
    const REACH: usize = 40;
    let (nx, ny) = (img.nx, img.ny);
    let mut seen = std::collections::HashSet::new();
    let mut stack = vec![(x, y)];
    let (mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0.0f64);
    while let Some((px, py)) = stack.pop() {
        if px.abs_diff(x) > REACH || py.abs_diff(y) > REACH || !seen.insert((px, py)) {
            continue;
        }
        if !img.bad[py * nx + px] {
            continue;
        }
        sx += px as f64;
        sy += py as f64;
        n += 1.0;
        if px > 0 {
            stack.push((px - 1, py));
        }
        if py > 0 {
            stack.push((px, py - 1));
        }
        if px + 1 < nx {
            stack.push((px + 1, py));
        }
        if py + 1 < ny {
            stack.push((px, py + 1));
        }
    }
    (sx / n.max(1.0), sy / n.max(1.0))
}

/// Whether the box of half-width `r_px` around (x, y) lies inside the image and holds no masked pixel
/// (the pixels a star's ePSF samples come from).
pub fn clear_box(img: &AnalysisImage, x: f64, y: f64, r_px: f64) -> bool {
    let inside =
        x - r_px >= 0.0 && y - r_px >= 0.0 && x + r_px < img.nx as f64 && y + r_px < img.ny as f64;
    inside
        && ((y - r_px).floor() as usize..=((y + r_px).ceil() as usize).min(img.ny - 1)).all(|py| {
            ((x - r_px).floor() as usize..=((x + r_px).ceil() as usize).min(img.nx - 1))
                .all(|px| !img.bad[py * img.nx + px])
        })
}

/// The relaxed test of an ePSF star's pixels, for an image whose flagged pixels are everywhere (a real
/// detector's hot pixels, cosmic rays flagged by its pipeline): the box of half-width `r_px` inside the
/// image, no masked pixel within [`CLEAR_CORE_PX`] of (x, y) — where a saturated or hit core would be —, and
/// at most a quarter of the box masked. The ePSF builder leaves the masked pixels out of its samples.
pub fn clear_core(img: &AnalysisImage, x: f64, y: f64, r_px: f64) -> bool {
    let inside =
        x - r_px >= 0.0 && y - r_px >= 0.0 && x + r_px < img.nx as f64 && y + r_px < img.ny as f64;
    if !inside {
        return false;
    }
    let (mut masked, mut total) = (0usize, 0usize);
    for py in (y - r_px).floor() as usize..=((y + r_px).ceil() as usize).min(img.ny - 1) {
        for px in (x - r_px).floor() as usize..=((x + r_px).ceil() as usize).min(img.nx - 1) {
            total += 1;
            if img.bad[py * img.nx + px] {
                if (px as f64 - x).hypot(py as f64 - y) <= CLEAR_CORE_PX {
                    return false;
                }
                masked += 1;
            }
        }
    }
    4 * masked <= total
}

/// Fewest isolated, unsaturated stars an ePSF is built from. Each star samples one sub-pixel phase per
/// pixel of the 4× oversampled table; the builder's smoothing (zeros at whole cycles per pixel) fills the
/// rest well from 9 stars (`engine/tests/cli.rs` analyses a 3 × 3 grid to a few mas), not from 4.
pub const MIN_EPSF_STARS: usize = 5;

/// The core of a star that [`clear_core`] keeps free of masked pixels, px.
pub const CLEAR_CORE_PX: f64 = 1.5;

/// Sky annulus used for every star (just outside the ePSF table).
pub fn sky_annulus(cfg: &AnalysisCfg) -> (f64, f64) {
    let r = cfg.epsf_radius_px as f64;
    (r + 1.0, r + 4.0)
}

/// Cross-match positions to reference positions: the common offset is the median displacement of the pairs
/// nearest within `search_px` (when at least 3 exist; else none), then each position takes the nearest
/// reference within `radius_px` of it minus that offset.
pub fn match_positions(
    pos: &[(f64, f64)],
    refs: &[(f64, f64)],
    search_px: f64,
    radius_px: f64,
) -> Vec<Option<usize>> {
    nearest_within(pos, refs, radius_px, common_offset(pos, refs, search_px))
}

/// The common offset of positions from reference positions: the median displacement of each position to
/// its nearest reference within `search_px`, when at least 3 such pairs exist; else none.
pub fn common_offset(pos: &[(f64, f64)], refs: &[(f64, f64)], search_px: f64) -> (f64, f64) {
    let coarse = nearest_within(pos, refs, search_px, (0.0, 0.0));
    let (dx, dy): (Vec<f64>, Vec<f64>) = pos
        .iter()
        .zip(&coarse)
        .filter_map(|(&(x, y), m)| m.map(|k| (x - refs[k].0, y - refs[k].1)))
        .unzip();
    if dx.len() >= 3 {
        (stats::median(&dx), stats::median(&dy))
    } else {
        (0.0, 0.0)
    }
}

/// [`common_offset`] from the `n` brightest positions alone (`flux[k]` of position k; bright stars are rarely
/// mismatched).
pub fn common_offset_of_brightest(
    pos: &[(f64, f64)],
    flux: &[f64],
    refs: &[(f64, f64)],
    n: usize,
    search_px: f64,
) -> (f64, f64) {
    let mut bright: Vec<usize> = (0..pos.len()).collect();
    bright.sort_by(|&a, &b| flux[b].total_cmp(&flux[a]));
    bright.truncate(n);
    let bpos: Vec<(f64, f64)> = bright.iter().map(|&k| pos[k]).collect();
    common_offset(&bpos, refs, search_px)
}

/// For each position, the index of the nearest reference position within `radius_px` of the position minus
/// `offset` (ties to the lowest index; the k-d tree of the references: O(n log n)).
pub fn nearest_within(
    pos: &[(f64, f64)],
    refs: &[(f64, f64)],
    radius_px: f64,
    offset: (f64, f64),
) -> Vec<Option<usize>> {
    let nb = Neighbours::new(refs);
    pos.iter()
        .map(|&(x, y)| {
            let (x, y) = (x - offset.0, y - offset.1);
            nearest_of(nb.near(x, y, radius_px), |k| refs[k], (x, y), radius_px).map(|b| b.0)
        })
        .collect()
}

/// The stars' starting values and which of them may build the ePSF (unflagged, inside, unsaturated,
/// isolated).
pub fn starts(
    img: &AnalysisImage,
    positions: &[(f64, f64)],
    cfg: &AnalysisCfg,
) -> (Vec<StarStart>, Vec<bool>) {
    let pd = img.pixels();
    let ann = sky_annulus(cfg);
    let s: Vec<StarStart> = positions
        .par_iter()
        .map(|&(x, y)| build::initial_start(&pd, x, y, ann))
        .collect();
    let r = cfg.epsf_radius_px as f64 + 1.0;
    let usable_with = |clean: &dyn Fn(f64, f64) -> bool| -> Vec<bool> {
        s.iter()
            .enumerate()
            .map(|(k, st)| {
                let isolated = s
                    .iter()
                    .enumerate()
                    .all(|(j, o)| j == k || (o.x - st.x).hypot(o.y - st.y) > 2.0 * r);
                clean(st.x, st.y) && isolated && st.flux > 0.0
            })
            .collect()
    };
    let usable = usable_with(&|x, y| clear_box(img, x, y, r));
    // too few stars with a clean box (flagged pixels everywhere): those with a clean core
    let usable = if usable.iter().filter(|u| **u).count() < MIN_EPSF_STARS {
        usable_with(&|x, y| clear_core(img, x, y, r))
    } else {
        usable
    };
    (s, usable)
}
