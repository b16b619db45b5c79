//! Light curves of transit photometry: a star's flux in a circular aperture with the sky from an annulus
//! ([`aperture_flux`]); the scatter of a light curve binned over a time (the combined
//! differential photometric precision habit of Kepler and TESS: the rms of the means of consecutive bins), and
//! the search for a transit by box least squares (Kovács, Zucker & Mazeh 2002): for each trial period the
//! light curve folded into phase bins, and for each trial duration and start the weighted mean in the box
//! against the mean out of it.

/// The rms of the means of consecutive `bin_days` bins of a light curve (bins at least half full, at least
/// three of them), relative to the light curve's weighted mean, in parts per million. `None` when fewer than
/// three bins qualify.
pub fn binned_scatter_ppm(t_days: &[f64], flux: &[f64], bin_days: f64) -> Option<f64> {
    if t_days.len() != flux.len() || t_days.is_empty() || !(bin_days > 0.0) {
        return None;
    }
    let t0 = t_days.iter().cloned().fold(f64::INFINITY, f64::min);
    let t1 = t_days.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let cadence = (t1 - t0) / (t_days.len().max(2) - 1) as f64;
    let bins = ((t1 - t0) / bin_days).floor() as usize + 1;
    let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
    for (t, f) in t_days.iter().zip(flux) {
        if f.is_finite() {
            let b = (((t - t0) / bin_days) as usize).min(bins - 1);
            sum[b] += f;
            count[b] += 1;
        }
    }
    let full = if cadence > 0.0 {
        (0.5 * bin_days / cadence).max(1.0) as usize
    } else {
        1
    };
    let means: Vec<f64> = sum
        .iter()
        .zip(&count)
        .filter(|(_, c)| **c >= full)
        .map(|(s, c)| s / *c as f64)
        .collect();
    if means.len() < 3 {
        return None;
    }
    let level = flux.iter().filter(|f| f.is_finite()).sum::<f64>()
        / flux.iter().filter(|f| f.is_finite()).count().max(1) as f64;
    let m = means.iter().sum::<f64>() / means.len() as f64;
    let var = means.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (means.len() - 1) as f64;
    Some(1e6 * var.sqrt() / level)
}

/// A star's flux in a circular aperture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ApertureFlux {
    /// Summed signal in the aperture less the sky, in the image's units.
    pub flux: f64,
    /// The sky per pixel: the median of the annulus' pixels.
    pub sky_per_px: f64,
    /// The aperture's area, px² (its pixels' covered fractions summed: πr² within the sampling).
    pub area_px: f64,
    /// Annulus pixels used.
    pub sky_pixels: usize,
}

/// Sub-samples per pixel axis for the aperture's edge pixels (their covered fraction to ≈ 10⁻³).
const EDGE_SAMPLES: usize = 16;

/// Aperture photometry on a row-major `nx × ny` image (pixel (i, j) covers [i − ½, i + ½] × [j − ½, j + ½]):
/// the signal within radius `r_px` of (x, y), each pixel weighted by the fraction of it the circle covers,
/// less the median of the pixels whose centres lie between `r_in_px` and `r_out_px` times the area. `None`
/// when the aperture leaves the image, the radii are not 0 < r ≤ r_in < r_out, or no sky pixel is left.
pub fn aperture_flux(
    image: &[f64],
    nx: usize,
    ny: usize,
    x: f64,
    y: f64,
    r_px: f64,
    r_in_px: f64,
    r_out_px: f64,
) -> Option<ApertureFlux> {
    aperture_fluxes(image, nx, ny, x, y, &[r_px], r_in_px, r_out_px)
        .pop()
        .flatten()
}

/// [`aperture_flux`] at each of `radii_px` around the same place, the annulus' median taken once.
#[allow(clippy::too_many_arguments)]
pub fn aperture_fluxes(
    image: &[f64],
    nx: usize,
    ny: usize,
    x: f64,
    y: f64,
    radii_px: &[f64],
    r_in_px: f64,
    r_out_px: f64,
) -> Vec<Option<ApertureFlux>> {
    let sky = (image.len() == nx * ny && r_in_px < r_out_px)
        .then(|| annulus_sky(image, nx, ny, x, y, r_in_px, r_out_px))
        .flatten();
    radii_px
        .iter()
        .map(|&r| {
            let (sky_per_px, sky_pixels) = sky?;
            if !(r > 0.0 && r <= r_in_px) {
                return None;
            }
            if !(x - r >= -0.5
                && y - r >= -0.5
                && x + r <= nx as f64 - 0.5
                && y + r <= ny as f64 - 0.5)
            {
                return None;
            }
            let (sum, area) = covered_sum(image, nx, ny, x, y, r);
            Some(ApertureFlux {
                flux: sum - sky_per_px * area,
                sky_per_px,
                area_px: area,
                sky_pixels,
            })
        })
        .collect()
}

/// The median of the finite pixels whose centres lie between `r_in_px` and `r_out_px` of (x, y), and how many
/// there are (`analysis::sky`, the one estimator); `None` when there is none.
pub fn annulus_sky(
    image: &[f64],
    nx: usize,
    ny: usize,
    x: f64,
    y: f64,
    r_in_px: f64,
    r_out_px: f64,
) -> Option<(f64, usize)> {
    crate::analysis::sky::annulus(
        nx,
        ny,
        x,
        y,
        r_in_px,
        r_out_px,
        |i| image.get(i).copied().filter(|v| v.is_finite()),
        crate::analysis::sky::SkyStatistic::Median,
        1,
    )
    .map(|s| (s.value, s.pixels))
}

/// The signal within radius `r_px` of (x, y), each pixel weighted by the fraction of it the circle covers, and
/// that area (the caller keeps the circle inside the image).
fn covered_sum(image: &[f64], nx: usize, ny: usize, x: f64, y: f64, r_px: f64) -> (f64, f64) {
    let reach = r_px.ceil() as i64 + 1;
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let (mut sum, mut area) = (0.0, 0.0);
    for j in (cy - reach).max(0)..=(cy + reach).min(ny as i64 - 1) {
        for i in (cx - reach).max(0)..=(cx + reach).min(nx as i64 - 1) {
            let (dx, dy) = (i as f64 - x, j as f64 - y);
            let d = dx.hypot(dy);
            // the covered fraction: 1 or 0 away from the edge, sub-sampled across it (a pixel's corners lie
            // within √½ of its centre)
            let f = if d + std::f64::consts::FRAC_1_SQRT_2 <= r_px {
                1.0
            } else if d - std::f64::consts::FRAC_1_SQRT_2 >= r_px {
                0.0
            } else {
                let n = EDGE_SAMPLES;
                let mut inside = 0usize;
                for b in 0..n {
                    for a in 0..n {
                        let sx = dx - 0.5 + (a as f64 + 0.5) / n as f64;
                        let sy = dy - 0.5 + (b as f64 + 0.5) / n as f64;
                        inside += usize::from(sx * sx + sy * sy <= r_px * r_px);
                    }
                }
                inside as f64 / (n * n) as f64
            };
            if f > 0.0 {
                sum += f * image[j as usize * nx + i as usize];
                area += f;
            }
        }
    }
    (sum, area)
}

/// The best box found by [`box_least_squares`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxFit {
    pub period_days: f64,
    /// Mid-transit time of the box, days (within the first period after the light curve's start).
    pub t0_days: f64,
    pub duration_days: f64,
    /// Relative depth: 1 − (mean in the box) / (mean out of it).
    pub depth: f64,
    /// Its 1σ error from the points' errors.
    pub depth_sigma: f64,
    /// depth / depth_sigma: the detection's significance.
    pub snr: f64,
    /// Points in the box.
    pub points_in: usize,
}

/// Box least squares over `periods_days` × `durations_days`, each box start on a phase grid of a quarter of
/// the shortest duration: the box of largest significance (depth over its error, with weights 1/σ²). `None`
/// when no box holds a point, or the inputs disagree in length.
pub fn box_least_squares(
    t_days: &[f64],
    flux: &[f64],
    sigma: &[f64],
    periods_days: &[f64],
    durations_days: &[f64],
) -> Option<BoxFit> {
    let n = t_days.len();
    if flux.len() != n || sigma.len() != n || n == 0 {
        return None;
    }
    let shortest = durations_days
        .iter()
        .cloned()
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !shortest.is_finite() {
        return None;
    }
    let t_start = t_days.iter().cloned().fold(f64::INFINITY, f64::min);
    let good: Vec<usize> = (0..n)
        .filter(|&i| flux[i].is_finite() && sigma[i] > 0.0 && sigma[i].is_finite())
        .collect();
    let (mut w_all, mut wf_all) = (0.0, 0.0);
    for &i in &good {
        let w = 1.0 / (sigma[i] * sigma[i]);
        w_all += w;
        wf_all += w * flux[i];
    }
    let mut best: Option<BoxFit> = None;
    for &period in periods_days.iter().filter(|p| **p > 0.0) {
        let bins = ((4.0 * period / shortest).ceil() as usize).max(1);
        let bin_days = period / bins as f64;
        let (mut w, mut wf, mut k) = (vec![0.0; bins], vec![0.0; bins], vec![0usize; bins]);
        for &i in &good {
            let phase = (t_days[i] - t_start).rem_euclid(period);
            let b = ((phase / bin_days) as usize).min(bins - 1);
            let wi = 1.0 / (sigma[i] * sigma[i]);
            w[b] += wi;
            wf[b] += wi * flux[i];
            k[b] += 1;
        }
        for &duration in durations_days.iter().filter(|d| **d > 0.0 && **d < period) {
            let span = ((duration / bin_days).round() as usize).clamp(1, bins);
            // the window's sums, slid around the folded light curve
            let (mut sw, mut swf, mut sk) = (0.0, 0.0, 0usize);
            for b in 0..span {
                sw += w[b];
                swf += wf[b];
                sk += k[b];
            }
            for start in 0..bins {
                let (w_out, wf_out) = (w_all - sw, wf_all - swf);
                if sw > 0.0 && w_out > 0.0 {
                    let (m_in, m_out) = (swf / sw, wf_out / w_out);
                    let depth = 1.0 - m_in / m_out;
                    let depth_sigma = (1.0 / sw + 1.0 / w_out).sqrt() / m_out.abs();
                    let snr = depth / depth_sigma;
                    if best.is_none_or(|b| snr > b.snr) {
                        best = Some(BoxFit {
                            period_days: period,
                            t0_days: t_start + (start as f64 + span as f64 / 2.0) * bin_days,
                            duration_days: span as f64 * bin_days,
                            depth,
                            depth_sigma,
                            snr,
                            points_in: sk,
                        });
                    }
                }
                // slide by one bin (wrapping around the phase)
                let (out_b, in_b) = (start, (start + span) % bins);
                sw += w[in_b] - w[out_b];
                swf += wf[in_b] - wf[out_b];
                sk = sk + k[in_b] - k[out_b];
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn noise(n: usize, sigma: f64, seed: u64) -> Vec<f64> {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let d = Normal::new(0.0, sigma).expect("normal");
        (0..n).map(|_| d.sample(&mut r)).collect()
    }

    /// White noise binned over m points scatters as σ/√m: the measured binned scatter within 4 of its own
    /// sampling errors (a scatter from K bins has a relative error of 1/√(2(K − 1))).
    #[test]
    fn white_noise_bins_down_as_the_square_root_of_the_points() {
        let (n, sigma, cadence) = (20_000, 1e-3, 20.0 / 86_400.0);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * cadence).collect();
        let f: Vec<f64> = noise(n, sigma, 1).iter().map(|e| 1.0 + e).collect();
        for bin_points in [1usize, 180, 1170] {
            let bin = bin_points as f64 * cadence;
            let got = binned_scatter_ppm(&t, &f, bin * 0.999_999).expect("scatter");
            let k = n / bin_points;
            let expect = 1e6 * sigma / (bin_points as f64).sqrt();
            let rel = 1.0 / (2.0 * (k - 1) as f64).sqrt();
            assert!(
                (got / expect - 1.0).abs() < 4.0 * rel,
                "{bin_points} points per bin: {got} ppm vs {expect} (± {:.1} %)",
                100.0 * rel
            );
        }
    }

    /// A box of known depth in white noise: found at its period, phase and duration, its depth within 4σ of
    /// the truth with σ what the fit says, and its significance as the points in the box predict.
    #[test]
    fn an_injected_box_is_found_with_its_depth_and_significance() {
        let (n, sigma) = (6000, 1e-3);
        let (period, t0, duration, depth) = (2.7, 0.9, 0.12, 1.2e-3);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 10.0 / n as f64).collect();
        let e = noise(n, sigma, 7);
        let f: Vec<f64> = t
            .iter()
            .zip(&e)
            .map(|(t, e)| {
                let ph = (t - t0 + 0.5 * period).rem_euclid(period) - 0.5 * period;
                (if ph.abs() < duration / 2.0 {
                    1.0 - depth
                } else {
                    1.0
                }) + e
            })
            .collect();
        let s = vec![sigma; n];
        let periods: Vec<f64> = (0..400).map(|k| 1.0 + k as f64 * 0.01).collect();
        let fit = box_least_squares(&t, &f, &s, &periods, &[0.06, 0.12, 0.24]).expect("fit");
        assert!((fit.period_days - period).abs() < 0.011, "{fit:?}");
        assert!((fit.duration_days - duration).abs() < 0.04, "{fit:?}");
        assert!(((fit.t0_days - t0 + 0.5 * period).rem_euclid(period) - 0.5 * period).abs() < 0.04);
        assert!((fit.depth - depth).abs() < 4.0 * fit.depth_sigma, "{fit:?}");
        let expect_snr = depth / sigma * (fit.points_in as f64).sqrt();
        assert!(
            (fit.snr / expect_snr - 1.0).abs() < 0.5,
            "{fit:?} vs {expect_snr}"
        );
    }

    /// A Gaussian star of known flux (each pixel its integral over the pixel) on a flat sky: a wide aperture
    /// returns the analytic enclosed flux F (1 − e^(−r²/2σ²)) and the sky; a narrow one the pixelated image's
    /// integral over the circle (the fractional-pixel method's own answer, computed by brute force); the area
    /// is πr².
    #[test]
    fn a_gaussian_star_gives_its_enclosed_flux_and_the_sky() {
        let (nx, ny, sig, flux, sky) = (64usize, 64usize, 1.6, 1.0e5, 40.0);
        let (x0, y0) = (31.3, 32.6);
        // each pixel the integral of the Gaussian over it (erf differences)
        let cdf = |u: f64| 0.5 * (1.0 + crate::testkit::erf(u / (sig * std::f64::consts::SQRT_2)));
        let mut img = vec![0.0; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let fx = cdf(i as f64 + 0.5 - x0) - cdf(i as f64 - 0.5 - x0);
                let fy = cdf(j as f64 + 0.5 - y0) - cdf(j as f64 - 0.5 - y0);
                img[j * nx + i] = sky + flux * fx * fy;
            }
        }
        // far out the pixels' shape no longer matters: the analytic enclosed flux
        let a = aperture_flux(&img, nx, ny, x0, y0, 7.0, 12.0, 18.0).expect("aperture");
        let enclosed = flux * (1.0 - (-49.0 / (2.0 * sig * sig)).exp());
        assert!(
            (a.flux / enclosed - 1.0).abs() < 1e-3,
            "{} vs {enclosed}",
            a.flux
        );
        assert!((a.sky_per_px - sky).abs() < 1e-6);
        // close in, against the same sum done another way: the pixelated image integrated over the circle by
        // brute force (100 × 100 samples in every pixel, each taking its pixel's value)
        for r in [2.0f64, 4.0] {
            let a = aperture_flux(&img, nx, ny, x0, y0, r, 12.0, 18.0).expect("aperture");
            let n = 100;
            let mut direct = 0.0;
            for j in 20..45usize {
                for i in 20..45usize {
                    let mut k = 0usize;
                    for b in 0..n {
                        for c in 0..n {
                            let sx = i as f64 - 0.5 + (c as f64 + 0.5) / n as f64 - x0;
                            let sy = j as f64 - 0.5 + (b as f64 + 0.5) / n as f64 - y0;
                            k += usize::from(sx * sx + sy * sy <= r * r);
                        }
                    }
                    direct += (img[j * nx + i] - sky) * k as f64 / (n * n) as f64;
                }
            }
            assert!(
                (a.flux / direct - 1.0).abs() < 2e-3,
                "r {r}: {} vs {direct}",
                a.flux
            );
            assert!((a.area_px / (std::f64::consts::PI * r * r) - 1.0).abs() < 2e-3);
        }
        // off the image: none
        assert!(aperture_flux(&img, nx, ny, 1.0, 30.0, 4.0, 12.0, 18.0).is_none());
        assert!(aperture_flux(&img, nx, ny, 30.0, 30.0, 4.0, 3.0, 18.0).is_none());
    }

    #[test]
    fn nothing_to_search_is_none() {
        assert!(box_least_squares(&[], &[], &[], &[1.0], &[0.1]).is_none());
        assert!(box_least_squares(&[0.0, 1.0], &[1.0, 1.0], &[1.0], &[1.0], &[0.1]).is_none());
        assert!(binned_scatter_ppm(&[0.0, 1.0], &[1.0, 1.0], 1.0).is_none());
    }
}
