//! Cosmic rays in a single exposure: L.A.Cosmic, the Laplacian edge detection of van Dokkum (2001, PASP 113,
//! 1420), as astroscrappy implements it (McCully et al. 2018).
//!
//! A hit is sharper than anything the optics deliver. Per iteration, on the image I in electrons:
//! - the Laplacian of I subsampled 2×2, `∇² = 4c − up − down − left − right`, negative values set to 0, and
//!   block-averaged back: L⁺;
//! - the noise N = √(med₅(I) + σ_RN²) (med₅ a 5 × 5 median, at least 10⁻⁵), and the significance
//!   S = L⁺ / (2N) less its own 5 × 5 median: S′ (the large structures gone);
//! - the fine structure F = (med₃(I) − med₇(med₃(I))) / N (at least 0.01), which a star's core has and a
//!   hit's does not: a candidate needs S′ > σ_lim and S′ / F > f_lim (the PSF's sharpness in the ratio; as
//!   van Dokkum's `lacos_im.cl` and astroscrappy compute it);
//! - the candidates' 3 × 3 neighbours with S′ > σ_lim, then theirs with S′ > σ_frac·σ_lim.
//!
//! The hits found are replaced by the 5 × 5 median of their clean neighbours and the next iteration runs on
//! that, until none is new or `iterations` have run. Masked pixels take the median of their clean
//! neighbours first and are never reported as hits.

use super::AnalysisImage;

/// The knobs (astroscrappy's defaults but `objlim`, whose 5 suits an undersampled PSF).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaCosmic {
    /// σ_lim: the significance of a hit's Laplacian.
    pub sigma_clip: f64,
    /// σ_frac: the faint edges' significance, a fraction of σ_lim.
    pub sigma_frac: f64,
    /// f_lim: how much sharper than the fine structure a hit is.
    pub objlim: f64,
    pub iterations: usize,
}

impl Default for LaCosmic {
    fn default() -> Self {
        Self {
            sigma_clip: 4.5,
            sigma_frac: 0.3,
            objlim: 5.0,
            iterations: 4,
        }
    }
}

/// The median of the finite values of `v`, NaN when none.
fn median_of(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let m = v.len() / 2;
    let (_, x, _) = v.select_nth_unstable_by(m, f64::total_cmp);
    *x
}

/// The (2r + 1)² median filter of `img` (nx × ny), edges reflected, `use_px` (when given) the pixels that
/// count.
fn median_filter(img: &[f64], nx: usize, ny: usize, r: usize, use_px: Option<&[bool]>) -> Vec<f64> {
    use rayon::prelude::*;
    let reflect = |i: i64, n: usize| -> usize {
        let n = n as i64;
        let mut i = i;
        if i < 0 {
            i = -i - 1;
        }
        if i >= n {
            i = 2 * n - i - 1;
        }
        i.clamp(0, n - 1) as usize
    };
    (0..nx * ny)
        .into_par_iter()
        .map_init(Vec::new, |buf, p| {
            let (x, y) = ((p % nx) as i64, (p / nx) as i64);
            buf.clear();
            for dy in -(r as i64)..=r as i64 {
                let yy = reflect(y + dy, ny);
                for dx in -(r as i64)..=r as i64 {
                    let q = yy * nx + reflect(x + dx, nx);
                    if use_px.is_none_or(|u| u[q]) {
                        buf.push(img[q]);
                    }
                }
            }
            median_of(buf)
        })
        .collect()
}

/// L⁺: the Laplacian of the 2 × 2-subsampled image, clipped at 0, block-averaged back.
fn laplacian_plus(img: &[f64], nx: usize, ny: usize) -> Vec<f64> {
    // on the subsampled grid pixel (2x + a, 2y + b) holds I(x, y); its 4 neighbours are either the same pixel
    // (inside the block) or the next one: the block average of the clipped Laplacian, sub-pixel by sub-pixel
    let at = |x: i64, y: i64| -> f64 {
        let xx = x.clamp(0, nx as i64 - 1) as usize;
        let yy = y.clamp(0, ny as i64 - 1) as usize;
        img[yy * nx + xx]
    };
    (0..nx * ny)
        .map(|p| {
            let (x, y) = ((p % nx) as i64, (p / nx) as i64);
            let c = at(x, y);
            let mut sum = 0.0;
            for (a, b) in [(0i64, 0i64), (1, 0), (0, 1), (1, 1)] {
                // sub-pixel (a, b): its left/right neighbour is outside the block on the side a points to
                let left = if a == 0 { at(x - 1, y) } else { c };
                let right = if a == 1 { at(x + 1, y) } else { c };
                let down = if b == 0 { at(x, y - 1) } else { c };
                let up = if b == 1 { at(x, y + 1) } else { c };
                sum += (4.0 * c - left - right - down - up).max(0.0);
            }
            sum / 4.0
        })
        .collect()
}

/// The hits L.A.Cosmic finds in `img` (true: a cosmic ray), never a pixel already masked.
pub fn detect(img: &AnalysisImage, p: &LaCosmic) -> Vec<bool> {
    let (nx, ny) = (img.nx, img.ny);
    let n = nx * ny;
    let good: Vec<bool> = img.bad.iter().map(|b| !b).collect();
    // masked pixels take their clean neighbours' median
    let fill = median_filter(&img.e, nx, ny, 2, Some(&good));
    let mut work: Vec<f64> = (0..n)
        .map(|i| if good[i] { img.e[i] } else { fill[i] })
        .map(|v| if v.is_finite() { v } else { 0.0 })
        .collect();
    let mut hits = vec![false; n];
    for _ in 0..p.iterations.max(1) {
        let lplus = laplacian_plus(&work, nx, ny);
        let med5 = median_filter(&work, nx, ny, 2, None);
        let s: Vec<f64> = (0..n)
            .map(|i| lplus[i] / (2.0 * (med5[i].max(1e-5) + img.floor_e2(i)).sqrt()))
            .collect();
        let s_med = median_filter(&s, nx, ny, 2, None);
        let sp: Vec<f64> = (0..n).map(|i| s[i] - s_med[i]).collect();
        let med3 = median_filter(&work, nx, ny, 1, None);
        let med7 = median_filter(&med3, nx, ny, 3, None);
        let cand: Vec<bool> = (0..n)
            .map(|i| {
                // as lacos_im.cl and astroscrappy: S′ / (F / N), F / N at least 0.01
                let noise = (med5[i].max(1e-5) + img.floor_e2(i)).sqrt();
                let f = ((med3[i] - med7[i]) / noise).max(0.01);
                good[i] && sp[i] > p.sigma_clip && sp[i] / f > p.objlim
            })
            .collect();
        let grow = |seed: &[bool], limit: f64| -> Vec<bool> {
            (0..n)
                .map(|i| {
                    let (x, y) = ((i % nx) as i64, (i / nx) as i64);
                    good[i]
                        && sp[i] > limit
                        && (-1..=1).any(|dy| {
                            (-1..=1).any(|dx| {
                                let (u, v) = (x + dx, y + dy);
                                u >= 0
                                    && v >= 0
                                    && u < nx as i64
                                    && v < ny as i64
                                    && seed[v as usize * nx + u as usize]
                            })
                        })
                })
                .collect()
        };
        let first = grow(&cand, p.sigma_clip);
        let last = grow(&first, p.sigma_frac * p.sigma_clip);
        let new: Vec<usize> = (0..n).filter(|&i| last[i] && !hits[i]).collect();
        if new.is_empty() {
            break;
        }
        for &i in &new {
            hits[i] = true;
        }
        let clean: Vec<bool> = (0..n).map(|i| good[i] && !hits[i]).collect();
        let repl = median_filter(&work, nx, ny, 2, Some(&clean));
        for &i in &new {
            if repl[i].is_finite() {
                work[i] = repl[i];
            }
        }
    }
    hits
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;
    use rand_distr::{Distribution, StandardNormal};

    /// Stars of an undersampled PSF (Gaussian σ 0.8 px, as HST's and JASMINE's) and hits of one to three
    /// pixels: the hits' strong pixels are found, no star's core is.
    #[test]
    fn the_hits_are_found_and_the_undersampled_stars_are_not() {
        let n = 160;
        let mut r = crate::rng::stream(21, crate::rng::Stream::Test, 5);
        let mut e = vec![100.0; n * n];
        let mut stars = Vec::new();
        for k in 0..40 {
            let (x0, y0) = (
                10.0 + (k % 8) as f64 * 19.0 + 0.37 * k as f64 % 1.0,
                12.0 + (k / 8) as f64 * 28.0,
            );
            let flux = 2e3 * 50f64.powf(r.random::<f64>());
            stars.push((x0, y0));
            for y in 0..n {
                for x in 0..n {
                    let d2 = (x as f64 - x0).powi(2) + (y as f64 - y0).powi(2);
                    if d2 < 64.0 {
                        e[y * n + x] +=
                            flux * (-d2 / (2.0 * 0.64)).exp() / (std::f64::consts::TAU * 0.64);
                    }
                }
            }
        }
        for v in e.iter_mut() {
            let z: f64 = StandardNormal.sample(&mut r);
            *v += (*v + 25.0).sqrt() * z;
        }
        let mut hits = Vec::new();
        while hits.len() < 60 {
            let (x, y) = (r.random_range(2..n - 3), r.random_range(2..n - 3));
            if stars
                .iter()
                .any(|(sx, sy)| (sx - x as f64).hypot(sy - y as f64) < 5.0)
            {
                continue;
            }
            let amp = 300.0 * 10f64.powf(r.random::<f64>());
            e[y * n + x] += amp;
            if r.random::<f64>() < 0.5 {
                e[y * n + x + 1] += 0.5 * amp;
            }
            hits.push(y * n + x);
        }
        let img = AnalysisImage {
            nx: n,
            ny: n,
            e,
            bad: vec![false; n * n],
            var_floor_e2: 25.0,
            var_floor_px_e2: None,
            flat_sigma: 0.0,
            plate_scale_mas: 1.0,
        };
        let found = detect(&img, &LaCosmic::default());
        let recovered = hits.iter().filter(|&&p| found[p]).count();
        assert!(
            recovered as f64 >= 0.95 * hits.len() as f64,
            "{recovered} of {}",
            hits.len()
        );
        for (sx, sy) in &stars {
            let core = sy.round() as usize * n + sx.round() as usize;
            assert!(
                !found[core],
                "a star's core at ({sx}, {sy}) taken for a hit"
            );
        }
    }
}
