//! Finding the stars: local maxima above the noise, their starting values, which of them may build the ePSF,
//! and the match of detections to a truth catalogue.

use crate::analysis::epsf::build::{self, StarStart};
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::stats;
use crate::simulate::TruthRow;
use rayon::prelude::*;

/// Local maxima (5 × 5) above `nsigma` × the image's robust noise over its median; brightest first, closer
/// than 3 px to a brighter one dropped.
pub fn detect(img: &AnalysisImage, nsigma: f64) -> Vec<(f64, f64)> {
    let good: Vec<f64> = img
        .e
        .iter()
        .zip(&img.bad)
        .filter(|(_, b)| !**b)
        .map(|(v, _)| *v)
        .step_by(7)
        .collect();
    let sky = stats::median(&good);
    let noise = stats::mad_sigma(&good).max(1e-9);
    let thr = sky + nsigma * noise;
    let (nx, ny) = (img.nx, img.ny);
    let rows: Vec<Vec<(f64, f64, f64)>> = (0..ny)
        .into_par_iter()
        .map(|y| {
            let mut v = Vec::new();
            for x in 0..nx {
                let i = y * nx + x;
                let p = img.e[i];
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
    let mut peaks: Vec<(f64, f64, f64)> = rows.into_iter().flatten().collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut kept: Vec<(f64, f64)> = Vec::new();
    for (_, x, y) in peaks {
        if kept
            .iter()
            .all(|(kx, ky)| (kx - x).powi(2) + (ky - y).powi(2) >= 9.0)
        {
            kept.push((x, y));
        }
    }
    kept
}

/// Sky annulus used for every star (just outside the ePSF table).
pub fn sky_annulus(cfg: &AnalysisCfg) -> (f64, f64) {
    let r = cfg.epsf_radius_px as f64;
    (r + 1.0, r + 4.0)
}

/// Match detections to the truth: for each detection the nearest truth star within 2 px.
pub fn match_truth(pos: &[(f64, f64)], truth: &[TruthRow]) -> Vec<Option<usize>> {
    // bucket the truth on a 4-px grid
    let cell = 4.0;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    for (k, t) in truth.iter().enumerate() {
        grid.entry((
            (t.x_px / cell).floor() as i64,
            (t.y_px / cell).floor() as i64,
        ))
        .or_default()
        .push(k);
    }
    pos.iter()
        .map(|&(x, y)| {
            let (cx, cy) = ((x / cell).floor() as i64, (y / cell).floor() as i64);
            let mut best: Option<(usize, f64)> = None;
            for gy in cy - 1..=cy + 1 {
                for gx in cx - 1..=cx + 1 {
                    for &k in grid.get(&(gx, gy)).map(|v| v.as_slice()).unwrap_or(&[]) {
                        let d = (truth[k].x_px - x).powi(2) + (truth[k].y_px - y).powi(2);
                        if d <= 4.0 && best.is_none_or(|(_, bd)| d < bd) {
                            best = Some((k, d));
                        }
                    }
                }
            }
            best.map(|b| b.0)
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
    let usable: Vec<bool> = s
        .iter()
        .enumerate()
        .map(|(k, st)| {
            let inside = st.x - r >= 0.0
                && st.y - r >= 0.0
                && st.x + r < img.nx as f64
                && st.y + r < img.ny as f64;
            let clean = inside && {
                let mut ok = true;
                'p: for py in
                    (st.y - r).floor() as usize..=((st.y + r).ceil() as usize).min(img.ny - 1)
                {
                    for px in
                        (st.x - r).floor() as usize..=((st.x + r).ceil() as usize).min(img.nx - 1)
                    {
                        if img.bad[py * img.nx + px] {
                            ok = false;
                            break 'p;
                        }
                    }
                }
                ok
            };
            let isolated = s
                .iter()
                .enumerate()
                .all(|(j, o)| j == k || (o.x - st.x).hypot(o.y - st.y) > 2.0 * r);
            clean && isolated && st.flux > 0.0
        })
        .collect();
    (s, usable)
}
