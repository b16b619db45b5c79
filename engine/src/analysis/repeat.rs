//! Exposures of one pointing, read together: cosmic rays rejected by comparison, and the repeatability of
//! the fitted positions against their Cramér–Rao bounds — what a real image allows without a truth.
//!
//! **Rejection by comparison** (as STScI's `crrej` does for CR-split exposures): the exposures are on the same
//! pixel grid (the caller checks the pointing). For every pixel the clean estimate is the minimum of the
//! unmasked exposures (two) or their median (three or more), m; exposure k's value e_k is a cosmic ray when
//! `e_k − m > t·σ_k`, with `σ_k² = 2(floor_k + max(m, 0)) + (s·m)²` (the noise of a difference of two
//! exposures: the read-noise floor and the photons of each; and a fraction s of the signal for the star cores
//! that the exposures' jitter moves by a little). Its 8 neighbours
//! are rejected at the lower threshold `t_grow` (a hit's faint edge). Defaults: t = 5, t_grow = 2.5,
//! s = 0.05 — knobs, with their costs measured in docs/real-images.md.
//!
//! **Repeatability**: the stars fitted alone in two exposures (no flag) are matched (within `match_px`), their common offset
//! (the median difference) removed, and the differences per axis divided by √2 — each exposure's own error
//! when the two are alike — compared per flux bin with the median bound of the pair, √((σ₁² + σ₂²)/2).

use super::AnalysisImage;
use super::report::StarResult;
use crate::numerics::neighbours::Neighbours;
use serde::Serialize;

/// The knobs of the rejection by comparison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rejection {
    pub threshold_sigma: f64,
    pub grow_sigma: f64,
    /// The fraction of the signal allowed as a difference between the exposures.
    pub scale_noise: f64,
}

impl Default for Rejection {
    fn default() -> Self {
        Self {
            threshold_sigma: 5.0,
            grow_sigma: 2.5,
            scale_noise: 0.05,
        }
    }
}

/// Mask the cosmic rays of exposures of one pointing by comparing them pixel by pixel; the pixels rejected
/// in each exposure are returned (already masked in `images`). Images of different sizes, or fewer than two,
/// are left as they are.
pub fn reject_by_comparison(images: &mut [AnalysisImage], r: &Rejection) -> Vec<usize> {
    let k = images.len();
    if k < 2
        || images
            .iter()
            .any(|i| (i.nx, i.ny) != (images[0].nx, images[0].ny))
    {
        return vec![0; k];
    }
    let (nx, ny) = (images[0].nx, images[0].ny);
    // the clean estimate of every pixel from the exposures that see it
    let clean: Vec<f64> = (0..nx * ny)
        .map(|p| {
            let mut v: Vec<f64> = images
                .iter()
                .filter(|i| !i.bad[p])
                .map(|i| i.e[p])
                .collect();
            match v.len() {
                0 => f64::NAN,
                1 => v[0],
                2 => v[0].min(v[1]),
                n => {
                    v.sort_by(f64::total_cmp);
                    v[n / 2]
                }
            }
        })
        .collect();
    let excess = |img: &AnalysisImage, p: usize| {
        let m = clean[p];
        // the noise of a difference of two exposures (the estimate is one of them, or their median)
        let var = 2.0 * (img.floor_e2(p) + m.max(0.0)) + (r.scale_noise * m).powi(2);
        (img.e[p] - m) / var.sqrt()
    };
    let mut counts = Vec::with_capacity(k);
    for img in images.iter_mut() {
        let hits: Vec<usize> = (0..nx * ny)
            .filter(|&p| !img.bad[p] && clean[p].is_finite() && excess(img, p) > r.threshold_sigma)
            .collect();
        let mut rejected = vec![false; nx * ny];
        for &p in &hits {
            rejected[p] = true;
            let (x, y) = ((p % nx) as i64, (p / nx) as i64);
            for (dx, dy) in (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))) {
                let (u, v) = (x + dx, y + dy);
                if u < 0 || v < 0 || u >= nx as i64 || v >= ny as i64 {
                    continue;
                }
                let q = v as usize * nx + u as usize;
                if !img.bad[q] && clean[q].is_finite() && excess(img, q) > r.grow_sigma {
                    rejected[q] = true;
                }
            }
        }
        let mut n = 0;
        for (b, rej) in img.bad.iter_mut().zip(&rejected) {
            if *rej && !*b {
                *b = true;
                n += 1;
            }
        }
        counts.push(n);
    }
    counts
}

/// One flux bin of the repeatability of two exposures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RepeatBin {
    /// The bin's edges: the geometric mean of the two fluxes, e⁻.
    pub flux_min_e: f64,
    pub flux_max_e: f64,
    pub n: usize,
    /// The rms of the differences ÷ √2 per axis, px (each exposure's error when the two are alike).
    pub repeat_x_px: f64,
    pub repeat_y_px: f64,
    /// The median bound of the pairs, √((σ₁² + σ₂²)/2), per axis, px.
    pub crlb_x_px: f64,
    pub crlb_y_px: f64,
    /// repeat ÷ bound per axis, and the ratio's statistical error, 1/√(2(n − 1)).
    pub ratio_x: f64,
    pub ratio_y: f64,
    pub ratio_error: f64,
}

/// The repeatability of two exposures' fits, per half-decade of flux (bins with fewer than `min_stars` left
/// out), and the common offset removed (px): the stars of `a` and `b` fitted alone without a flag (the bound
/// is a single star's), matched within `match_px`, each to its nearest and only when it is the other's
/// nearest too.
pub fn repeatability(
    a: &[StarResult],
    b: &[StarResult],
    match_px: f64,
    min_stars: usize,
) -> (Vec<RepeatBin>, (f64, f64)) {
    // stars fitted alone and cleanly: the bound is a single star's (a blended or grouped star's error holds
    // its neighbours' too)
    let usable = |s: &&StarResult| s.flags == 0 && s.is_usable() && s.flux_e > 0.0;
    let a: Vec<&StarResult> = a.iter().filter(usable).collect();
    let b: Vec<&StarResult> = b.iter().filter(usable).collect();
    let tb = Neighbours::new(&b.iter().map(|s| (s.x, s.y)).collect::<Vec<_>>());
    let ta = Neighbours::new(&a.iter().map(|s| (s.x, s.y)).collect::<Vec<_>>());
    let nearest = |t: &Neighbours, stars: &[&StarResult], x: f64, y: f64| {
        t.within(x, y, match_px).into_iter().min_by(|&i, &j| {
            let d = |k: usize| (stars[k].x - x).hypot(stars[k].y - y);
            d(i).total_cmp(&d(j))
        })
    };
    let pairs: Vec<(&StarResult, &StarResult)> = a
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let j = nearest(&tb, &b, s.x, s.y)?;
            (nearest(&ta, &a, b[j].x, b[j].y) == Some(i)).then_some((*s, b[j]))
        })
        .collect();
    let median = |v: Vec<f64>| crate::numerics::stats::median(&v);
    let off = (
        median(pairs.iter().map(|(p, q)| p.x - q.x).collect()),
        median(pairs.iter().map(|(p, q)| p.y - q.y).collect()),
    );
    let mut bins = Vec::new();
    // the first half-decade edge at or below the faintest pair's flux
    let faintest = pairs
        .iter()
        .map(|(p, q)| (p.flux_e * q.flux_e).sqrt().log10())
        .fold(f64::INFINITY, f64::min);
    let mut lo = 10f64.powf((2.0 * faintest).floor() / 2.0);
    while pairs
        .iter()
        .any(|(p, q)| (p.flux_e * q.flux_e).sqrt() >= lo)
    {
        let hi = lo * 10f64.sqrt();
        let sel: Vec<&(&StarResult, &StarResult)> = pairs
            .iter()
            .filter(|(p, q)| (lo..hi).contains(&(p.flux_e * q.flux_e).sqrt()))
            .collect();
        if sel.len() >= min_stars.max(2) {
            let rms = |d: &dyn Fn(&StarResult, &StarResult) -> f64| {
                (sel.iter().map(|(p, q)| d(p, q).powi(2)).sum::<f64>() / (sel.len() - 1) as f64)
                    .sqrt()
                    / 2f64.sqrt()
            };
            let rx = rms(&|p, q| p.x - q.x - off.0);
            let ry = rms(&|p, q| p.y - q.y - off.1);
            let bound = |c: &dyn Fn(&StarResult) -> f64| {
                median(
                    sel.iter()
                        .map(|(p, q)| ((c(p).powi(2) + c(q).powi(2)) / 2.0).sqrt())
                        .collect(),
                )
            };
            let cx = bound(&|s| s.crlb_x_px);
            let cy = bound(&|s| s.crlb_y_px);
            bins.push(RepeatBin {
                flux_min_e: lo,
                flux_max_e: hi,
                n: sel.len(),
                repeat_x_px: rx,
                repeat_y_px: ry,
                crlb_x_px: cx,
                crlb_y_px: cy,
                ratio_x: rx / cx,
                ratio_y: ry / cy,
                ratio_error: 1.0 / (2.0 * (sel.len() - 1) as f64).sqrt(),
            });
        }
        lo = hi;
    }
    (bins, off)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;
    use rand_distr::{Distribution, StandardNormal};

    fn image(n: usize, value: f64) -> AnalysisImage {
        AnalysisImage {
            nx: n,
            ny: n,
            e: vec![value; n * n],
            bad: vec![false; n * n],
            var_floor_e2: 25.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
            plate_scale_mas: 1.0,
        }
    }

    /// Two exposures of 200 e⁻ of sky with noise and a bright star in both, cosmic rays of 30–3000 e⁻ in each:
    /// every hit above 10σ is masked, the star is not, and the false rejections are ≤ 1e-4 of the pixels.
    #[test]
    fn comparison_masks_the_hits_and_leaves_the_stars() {
        let n = 200;
        let mut r = crate::rng::stream(9, crate::rng::Stream::Test, 2);
        let mut images = vec![image(n, 0.0), image(n, 0.0)];
        // the star moves by 0.02 px between the exposures (the jitter)
        let star = |x: usize, y: usize, shift: f64| {
            let d2 = (x as f64 - 100.3 - shift).powi(2) + (y as f64 - 80.6).powi(2);
            2e5 * (-d2 / 2.0).exp() / std::f64::consts::TAU
        };
        let mut hits: Vec<Vec<usize>> = vec![Vec::new(), Vec::new()];
        for (k, img) in images.iter_mut().enumerate() {
            for p in 0..n * n {
                let (x, y) = (p % n, p / n);
                let truth = 200.0 + star(x, y, 0.02 * k as f64);
                let z: f64 = StandardNormal.sample(&mut r);
                img.e[p] = truth + (truth + 25.0).sqrt() * z;
            }
            for _ in 0..300 {
                let p = r.random_range(0..n * n);
                let (x, y) = (p % n, p / n);
                if (x as f64 - 100.3).hypot(y as f64 - 80.6) < 4.0 {
                    continue;
                }
                img.e[p] += 30.0 * 100f64.powf(r.random::<f64>());
                hits[k].push(p);
            }
        }
        let counts = reject_by_comparison(&mut images, &Rejection::default());
        for (k, img) in images.iter().enumerate() {
            // every hit whose excess is ≥ 10σ of the sky's noise (≈ 15 e⁻) is masked
            let strong: Vec<&usize> = hits[k]
                .iter()
                .filter(|&&p| img.e[p] - 200.0 > 150.0)
                .collect();
            assert!(strong.iter().all(|&&p| img.bad[p]), "exposure {k}");
            let core = 80 * n + 100;
            assert!(!img.bad[core] && !img.bad[core + 1] && !img.bad[core + n]);
            // the rejected pixels beyond the hits and their neighbours
            let near_hit = |p: usize| {
                hits[k].iter().any(|&h| {
                    ((h % n) as i64 - (p % n) as i64).abs() <= 1
                        && ((h / n) as i64 - (p / n) as i64).abs() <= 1
                })
            };
            let false_rej = (0..n * n).filter(|&p| img.bad[p] && !near_hit(p)).count();
            assert!(false_rej <= 4, "exposure {k}: {false_rej} false rejections");
            assert!(counts[k] >= strong.len());
        }
    }

    /// Fits whose errors are drawn at their bounds repeat at the bound: every bin's ratio within 3 of its
    /// statistical errors of 1, and a common offset comes back.
    #[test]
    fn fits_drawn_at_their_bounds_repeat_at_the_bound() {
        let mut r = crate::rng::stream(4, crate::rng::Stream::Test, 3);
        let mut z = move || -> f64 { StandardNormal.sample(&mut r) };
        let mut a = Vec::new();
        let mut b = Vec::new();
        for i in 0..3000 {
            let (x, y) = ((i % 60) as f64 * 15.0 + 3.3, (i / 60) as f64 * 15.0 + 7.1);
            let flux = 10f64.powf(2.0 + 3.0 * (i as f64 / 3000.0));
            let s = 0.2 * (300.0 / flux).sqrt().min(1.0);
            let star = |x: f64, y: f64| StarResult {
                x,
                y,
                flux_e: flux,
                sky_e: 0.0,
                crlb_x_px: s,
                crlb_y_px: 1.5 * s,
                flags: 0,
            };
            a.push(star(x + s * z(), y + 1.5 * s * z()));
            b.push(star(x + 0.3 + s * z(), y - 0.1 + 1.5 * s * z()));
        }
        let (bins, off) = repeatability(&a, &b, 2.0, 50);
        assert!(
            (off.0 + 0.3).abs() < 0.02 && (off.1 - 0.1).abs() < 0.02,
            "{off:?}"
        );
        assert!(bins.len() >= 5, "{bins:?}");
        for bin in &bins {
            for ratio in [bin.ratio_x, bin.ratio_y] {
                assert!(
                    (ratio - 1.0).abs() < 3.0 * bin.ratio_error + 0.02,
                    "{bin:?}"
                );
            }
        }
    }
}
