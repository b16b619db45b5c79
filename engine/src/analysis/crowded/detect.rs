//! Finding stars in a crowded image: peaks of the image smoothed by the 3 × 3 binomial kernel (a matched
//! filter for a PSF of ≈ 2 px FWHM), deblended by prominence, and — after the first fits — peaks of the
//! residual image (image − model of the stars found), the companions the first pass merged into a brighter
//! star (the iterative scheme of DAOPHOT's FIND/ALLSTAR and photutils' `IterativePSFPhotometry`).

use crate::analysis::detection::{SkyNoise, keep_first_of, plateau_centre};
use crate::analysis::image::AnalysisImage;
use rayon::prelude::*;

/// Noise of the 3 × 3 binomial smoothing of white noise of unit σ: √Σk² = √(6/16)² = 0.375.
pub const SMOOTHED_NOISE: f64 = 0.375;
/// A peak within this distance of a brighter one is a separate star only if it stands out from the saddle
/// between them by [`DEBLEND_SIGMA`] × the local noise of the smoothed image (px).
pub const DEBLEND_RADIUS_PX: f64 = 5.0;
pub const DEBLEND_SIGMA: f64 = 3.0;
/// Fraction of a star's model counted as model error when judging a residual peak (the ePSF is not
/// perfect): a residual must exceed this share of the model, not only the noise.
pub const MODEL_ERROR: f64 = 0.03;

/// `v` smoothed by (1 2 1)ᵀ(1 2 1)/16, the edge replicated.
pub fn smooth3(v: &[f64], nx: usize, ny: usize) -> Vec<f64> {
    let mut tmp = vec![0.0; v.len()];
    tmp.par_chunks_mut(nx).enumerate().for_each(|(y, row)| {
        let r = &v[y * nx..(y + 1) * nx];
        for x in 0..nx {
            let (l, c, rr) = (r[x.saturating_sub(1)], r[x], r[(x + 1).min(nx - 1)]);
            row[x] = 0.25 * l + 0.5 * c + 0.25 * rr;
        }
    });
    let mut out = vec![0.0; v.len()];
    out.par_chunks_mut(nx).enumerate().for_each(|(y, row)| {
        let (a, b, c) = (y.saturating_sub(1), y, (y + 1).min(ny - 1));
        for x in 0..nx {
            row[x] = 0.25 * tmp[a * nx + x] + 0.5 * tmp[b * nx + x] + 0.25 * tmp[c * nx + x];
        }
    });
    out
}

/// Local maxima (3 × 3, ties to the lower index) of `s` where `s > thr(i)`: (value, x, y), brightest first.
fn local_maxima(
    s: &[f64],
    nx: usize,
    ny: usize,
    thr: &(dyn Fn(usize) -> f64 + Sync),
) -> Vec<(f64, usize, usize)> {
    let mut peaks: Vec<(f64, usize, usize)> = (0..ny)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut v = Vec::new();
            for x in 0..nx {
                let i = y * nx + x;
                let p = s[i];
                if !(p > thr(i)) {
                    continue;
                }
                let mut is_max = true;
                'n: for yy in y.saturating_sub(1)..=(y + 1).min(ny - 1) {
                    for xx in x.saturating_sub(1)..=(x + 1).min(nx - 1) {
                        let j = yy * nx + xx;
                        if s[j] > p || (s[j] == p && j < i) {
                            is_max = false;
                            break 'n;
                        }
                    }
                }
                if is_max {
                    v.push((p, x, y));
                }
            }
            v
        })
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    peaks
}

/// Bilinear sample of `s` at (x, y).
fn bilinear(s: &[f64], nx: usize, ny: usize, x: f64, y: f64) -> f64 {
    let (x0, y0) = (
        (x.floor().max(0.0) as usize).min(nx - 1),
        (y.floor().max(0.0) as usize).min(ny - 1),
    );
    let (x1, y1) = ((x0 + 1).min(nx - 1), (y0 + 1).min(ny - 1));
    let (fx, fy) = (
        (x - x0 as f64).clamp(0.0, 1.0),
        (y - y0 as f64).clamp(0.0, 1.0),
    );
    let r0 = s[y0 * nx + x0] * (1.0 - fx) + s[y0 * nx + x1] * fx;
    let r1 = s[y1 * nx + x0] * (1.0 - fx) + s[y1 * nx + x1] * fx;
    r0 * (1.0 - fy) + r1 * fy
}

/// Keep the peaks (brightest first) that stand out from every brighter kept peak within
/// [`DEBLEND_RADIUS_PX`]: prominence (peak − lowest value on the segment between them) above
/// [`DEBLEND_SIGMA`] × `local_sigma(peak)`.
fn deblend(
    s: &[f64],
    nx: usize,
    ny: usize,
    peaks: &[(f64, usize, usize)],
    local_sigma: &dyn Fn(f64) -> f64,
) -> Vec<(usize, usize)> {
    // a peak asks the kept ones within reach (the k-d tree of every peak)
    let pos: Vec<(f64, f64)> = peaks
        .iter()
        .map(|&(_, x, y)| (x as f64, y as f64))
        .collect();
    let merged = |k: usize, j: usize| {
        let ((p, x, y), (_, bx, by)) = (peaks[k], peaks[j]);
        let d = (bx as f64 - x as f64).hypot(by as f64 - y as f64);
        if d > DEBLEND_RADIUS_PX {
            return false;
        }
        let steps = (4.0 * d).ceil().max(2.0) as usize;
        let saddle = (0..=steps)
            .map(|t| {
                let f = t as f64 / steps as f64;
                bilinear(
                    s,
                    nx,
                    ny,
                    x as f64 + f * (bx as f64 - x as f64),
                    y as f64 + f * (by as f64 - y as f64),
                )
            })
            .fold(f64::INFINITY, f64::min);
        // one star's when the dip between them is within the noise (NaN: separate, as before)
        p - saddle < DEBLEND_SIGMA * local_sigma(p)
    };
    keep_first_of(&pos, DEBLEND_RADIUS_PX, merged)
        .into_iter()
        .map(|k| (peaks[k].1, peaks[k].2))
        .collect()
}

/// No residual peak is taken within this many pixels of a masked pixel: the edge of a saturated core is
/// where its model is least certain, and a misfit there is not a star.
pub const MASK_CLEARANCE_PX: usize = 3;

fn near_masked(img: &AnalysisImage, x: usize, y: usize) -> bool {
    let r = MASK_CLEARANCE_PX;
    (y.saturating_sub(r)..=(y + r).min(img.ny - 1)).any(|yy| {
        (x.saturating_sub(r)..=(x + r).min(img.nx - 1)).any(|xx| img.bad[yy * img.nx + xx])
    })
}

/// A peak's position: its pixel, or the centre of the saturated plateau it sits on.
fn position(img: &AnalysisImage, x: usize, y: usize) -> (f64, f64) {
    if img.bad[y * img.nx + x] {
        plateau_centre(img, x, y)
    } else {
        (x as f64, y as f64)
    }
}

/// First detection: peaks of the smoothed image above `sky + nsigma · 0.375 · noise` (a peak of S/N
/// `nsigma` in the matched-filtered image; each pixel's noise), deblended. Positions in pixels, brightest
/// first.
pub fn detect_smoothed(img: &AnalysisImage, nsigma: f64, sn: &SkyNoise) -> Vec<(f64, f64)> {
    let s = smooth3(&img.e, img.nx, img.ny);
    let sky = sn.sky;
    let peaks = local_maxima(&s, img.nx, img.ny, &|i| {
        sky + nsigma * SMOOTHED_NOISE * sn.at(img, i)
    });
    let var0 = sn.noise * sn.noise;
    let sigma = |p: f64| SMOOTHED_NOISE * (var0 + (p - sky).max(0.0)).sqrt();
    deblend(&s, img.nx, img.ny, &peaks, &sigma)
        .into_iter()
        .map(|(x, y)| position(img, x, y))
        .collect()
}

/// Residual detection: peaks of the smoothed residual `img − sky − model` above `nsigma` × its local noise
/// (the sky's, the model's Poisson and [`MODEL_ERROR`] of the model), at least `min_sep_px` from every
/// star already found (`found`), not within [`MASK_CLEARANCE_PX`] of a masked pixel. Positions in pixels,
/// brightest first.
pub fn detect_residual(
    img: &AnalysisImage,
    model: &[f64],
    sn: &SkyNoise,
    nsigma: f64,
    found: &crate::numerics::neighbours::Neighbours,
    min_sep_px: f64,
) -> Vec<(f64, f64)> {
    let (nx, ny) = (img.nx, img.ny);
    let sky = sn.sky;
    let resid: Vec<f64> = img
        .e
        .iter()
        .zip(model)
        .zip(&img.bad)
        .map(|((e, m), b)| if *b { 0.0 } else { e - sky - m })
        .collect();
    let s = smooth3(&resid, nx, ny);
    let ms = smooth3(model, nx, ny);
    let local = |i: usize| {
        let m = ms[i].max(0.0);
        let n0 = sn.at(img, i);
        let var0 = n0 * n0;
        (SMOOTHED_NOISE * SMOOTHED_NOISE * (var0 + m) + (MODEL_ERROR * m).powi(2)).sqrt()
    };
    let peaks = local_maxima(&s, nx, ny, &|i| nsigma * local(i));
    peaks
        .into_iter()
        .filter(|&(_, x, y)| {
            !near_masked(img, x, y) && found.within(x as f64, y as f64, min_sep_px).is_empty()
        })
        .map(|(_, x, y)| (x as f64, y as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothing_keeps_sums_and_scales_white_noise_by_0_375() {
        let (nx, ny) = (64, 64);
        let mut s = 7u64;
        let v: Vec<f64> = (0..nx * ny)
            .map(|_| {
                // sum of 12 uniforms − 6: unit variance
                (0..12)
                    .map(|_| {
                        s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
                        (s >> 11) as f64 / (1u64 << 53) as f64
                    })
                    .sum::<f64>()
                    - 6.0
            })
            .collect();
        let sm = smooth3(&v, nx, ny);
        let inner: Vec<f64> = (2..ny - 2)
            .flat_map(|y| (2..nx - 2).map(move |x| y * nx + x))
            .map(|i| sm[i])
            .collect();
        let sd = crate::numerics::stats::std_dev(&inner);
        // 3600 samples, correlated over 3 × 3: the std is known to a few %
        assert!((sd / SMOOTHED_NOISE - 1.0).abs() < 0.06, "{sd}");
        // a delta spreads to the kernel: sum kept
        let mut d = vec![0.0; nx * ny];
        d[10 * nx + 10] = 16.0;
        let sd = smooth3(&d, nx, ny);
        assert!((sd.iter().sum::<f64>() - 16.0).abs() < 1e-12);
        assert_eq!(sd[10 * nx + 10], 4.0);
        assert_eq!(sd[11 * nx + 11], 1.0);
    }
}
