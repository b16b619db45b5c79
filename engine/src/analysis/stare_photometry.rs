//! Photometry of a transit stare from what the instrument delivers: each star's window per plate (ADU), the
//! calibration flat cut to the windows, the design PSF blurred by the telemetry's jitter, and the telemetry.
//!
//! Per window: electrons `e = (ADU − bias) g / flat_cal`; the star's place predicted (the reference
//! catalogue's position through the design WCS, shifted by the telemetry's mean pointing) and recentred on
//! the data ([`recentre`]: a sky-subtracted centroid within 3 px, iterated); the sky per pixel from the
//! annulus' median about that place; the star's position and flux by a PSF fit (x, y, flux; the sky fixed) with the blurred design PSF (Anderson &
//! King 2000's fit, [`crate::analysis::epsf::fit::fit_star`]); the aperture flux at the fitted position, at
//! each radius with one sky ([`crate::analysis::lightcurve::aperture_fluxes`]). The light curve is
//! differential: the target over the
//! sum of the comparison stars (an ensemble weighted by flux, which averages their noise down), each
//! normalised to its median. [`decorrelate`] removes what the measured centroid (or the telemetry) explains,
//! by linear least squares over the points out of the transit.

use super::epsf::Epsf;
use super::epsf::fit::{FitOptions, PixelData, fit_star};
use super::lightcurve::{annulus_sky, aperture_fluxes};
use crate::numerics::{linalg, stats};

/// How a window becomes electrons and where the flux is measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    pub gain_e_per_adu: f64,
    /// The co-added bias of a plate, ADU.
    pub bias_adu: f64,
    /// A pixel's read noise per plate, e⁻ (the PSF fit's weights).
    pub read_noise_e: f64,
    /// The aperture radii measured, px.
    pub apertures_px: Vec<f64>,
    pub annulus_in_px: f64,
    pub annulus_out_px: f64,
    /// The PSF fit's radius, px.
    pub fit_radius_px: f64,
}

/// One star in one plate, window pixel coordinates.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StarMeasure {
    pub x_px: f64,
    pub y_px: f64,
    /// Aperture fluxes (one per radius of the setup), the PSF-fit flux and the sky per pixel, e⁻ (NaN when a
    /// measurement failed).
    pub aperture_e: Vec<f64>,
    pub psf_e: f64,
    pub sky_e: f64,
}

/// The radius of the centroid that recentres a predicted place, px.
pub const RECENTRE_RADIUS_PX: f64 = 3.0;

/// How many times [`recentre`] moves its circle to the last centroid.
pub const RECENTRE_ITERATIONS: usize = 3;

/// Recentre a predicted place `(x, y)` (window px) on the data: the first moment of the sky-subtracted
/// electrons (negative values as 0) within [`RECENTRE_RADIUS_PX`] of the place, `x̄ = Σ (e − sky) x / Σ (e −
/// sky)`, the circle moved to it and the moment taken again, [`RECENTRE_ITERATIONS`] times. A place with no
/// light in its circle (or off the window) stays where it was predicted.
pub fn recentre(e: &[f64], n: usize, sky: f64, guess: (f64, f64)) -> (f64, f64) {
    let r2 = RECENTRE_RADIUS_PX * RECENTRE_RADIUS_PX;
    let inside = |v: f64| v.is_finite() && (0.0..n as f64).contains(&v);
    let mut at = guess;
    for _ in 0..RECENTRE_ITERATIONS {
        let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
        for y in 0..n {
            for x in 0..n {
                let (dx, dy) = (x as f64 - at.0, y as f64 - at.1);
                if dx * dx + dy * dy <= r2 {
                    let v = (e[y * n + x] - sky).max(0.0);
                    sx += v * x as f64;
                    sy += v * y as f64;
                    sw += v;
                }
            }
        }
        if !(sw > 0.0) {
            break;
        }
        let next = (sx / sw, sy / sw);
        if !(inside(next.0) && inside(next.1)) {
            break;
        }
        at = next;
    }
    at
}

/// Measure one star's window (`n × n`, ADU) with its calibration flat, starting from the star's predicted
/// place `guess` (window px: the catalogue's position through the WCS, moved by the telemetry's pointing).
pub fn measure_window(
    adu: &[f32],
    n: usize,
    flat: &[f32],
    setup: &Setup,
    psf: &Epsf,
    guess: (f64, f64),
) -> StarMeasure {
    let e: Vec<f64> = adu
        .iter()
        .zip(flat)
        .map(|(&a, &f)| (a as f64 - setup.bias_adu) * setup.gain_e_per_adu / (f as f64).max(1e-6))
        .collect();
    let c = (n / 2) as f64;
    let guess = if guess.0.is_finite() && guess.1.is_finite() {
        guess
    } else {
        (c, c)
    };
    // the sky about the predicted place, then the place recentred on the data;
    // no sky pixel: the centroid and the fit start from 0, the measurement reports no sky (NaN)
    let measured_sky = annulus_sky(
        &e,
        n,
        n,
        guess.0,
        guess.1,
        setup.annulus_in_px,
        setup.annulus_out_px,
    )
    .map(|(s, _)| s);
    let sky = measured_sky.unwrap_or(0.0);
    let (x0, y0) = recentre(&e, n, sky, guess);
    let bad = vec![false; n * n];
    let img = PixelData {
        nx: n,
        ny: n,
        e: &e,
        bad: &bad,
        var_floor_e2: setup.read_noise_e * setup.read_noise_e,
        var_floor_px_e2: None,
        flat_sigma: 0.0,
    };
    let f0 = e.iter().map(|v| v - sky).sum::<f64>().max(1.0);
    let fit = fit_star(
        &img,
        psf,
        x0,
        y0,
        f0,
        sky,
        &FitOptions {
            radius_px: setup.fit_radius_px,
            max_iter: 30,
            fit_sky: false,
        },
    );
    let (x, y, psf_e) = if fit.usable() {
        (fit.x, fit.y, fit.flux)
    } else {
        (x0, y0, f64::NAN)
    };
    let aperture_e = aperture_fluxes(
        &e,
        n,
        n,
        x,
        y,
        &setup.apertures_px,
        setup.annulus_in_px,
        setup.annulus_out_px,
    )
    .iter()
    .map(|a| a.map_or(f64::NAN, |a| a.flux))
    .collect();
    StarMeasure {
        x_px: x,
        y_px: y,
        aperture_e,
        psf_e,
        sky_e: measured_sky.unwrap_or(f64::NAN),
    }
}

/// The point-to-point scatter of a series, `std(Δ)/√2`: its white part, insensitive to slow trends and to a
/// transit (finite values only).
pub fn point_to_point(v: &[f64]) -> f64 {
    let g: Vec<f64> = v.iter().cloned().filter(|x| x.is_finite()).collect();
    let d: Vec<f64> = g.windows(2).map(|w| w[1] - w[0]).collect();
    stats::std_dev(&d) / std::f64::consts::SQRT_2
}

/// The differential light curve: `target / Σ comparisons`, normalised to its median. `fluxes[k][p]` is star
/// k's flux in plate p (star 0 the target); a plate where any flux is missing gives NaN.
pub fn differential(fluxes: &[Vec<f64>]) -> Vec<f64> {
    let Some((target, comps)) = fluxes.split_first() else {
        return Vec::new();
    };
    let raw: Vec<f64> = (0..target.len())
        .map(|p| {
            let c: f64 = comps.iter().map(|f| f[p]).sum();
            if target[p].is_finite() && c.is_finite() && c > 0.0 {
                target[p] / c
            } else {
                f64::NAN
            }
        })
        .collect();
    normalised(&raw)
}

/// `v` over the median of its finite values.
pub fn normalised(v: &[f64]) -> Vec<f64> {
    let good: Vec<f64> = v.iter().cloned().filter(|x| x.is_finite()).collect();
    let m = stats::median(&good);
    v.iter().map(|x| x / m).collect()
}

/// `v` less its centred running mean over `w` values (truncated at the ends; finite values only): what
/// changes from plate to plate, without the slow trend. Regressors high-passed this way let a
/// decorrelation remove the jitter's plate-to-plate noise without also removing the light curve's slow
/// variations (and the noise on the scale of a transit) along with the drift they follow.
pub fn high_pass(v: &[f64], w: usize) -> Vec<f64> {
    let h = w / 2;
    let (mut sum, mut cnt) = (vec![0.0; v.len() + 1], vec![0usize; v.len() + 1]);
    for (i, x) in v.iter().enumerate() {
        let ok = x.is_finite();
        sum[i + 1] = sum[i] + if ok { *x } else { 0.0 };
        cnt[i + 1] = cnt[i] + usize::from(ok);
    }
    (0..v.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(h), (i + h + 1).min(v.len()));
            let n = cnt[b] - cnt[a];
            if n == 0 {
                f64::NAN
            } else {
                v[i] - (sum[b] - sum[a]) / n as f64
            }
        })
        .collect()
}

/// The regressors of a centroid decorrelation from positions `(x, y)` per plate: x̃, ỹ, x̃², ỹ², x̃ỹ with
/// x̃ = x − mean.
pub fn centroid_regressors(x: &[f64], y: &[f64]) -> Vec<Vec<f64>> {
    let mean = |v: &[f64]| {
        let g: Vec<f64> = v.iter().cloned().filter(|a| a.is_finite()).collect();
        stats::mean(&g)
    };
    let (mx, my) = (mean(x), mean(y));
    let xs: Vec<f64> = x.iter().map(|v| v - mx).collect();
    let ys: Vec<f64> = y.iter().map(|v| v - my).collect();
    vec![
        xs.clone(),
        ys.clone(),
        xs.iter().map(|v| v * v).collect(),
        ys.iter().map(|v| v * v).collect(),
        xs.iter().zip(&ys).map(|(a, b)| a * b).collect(),
    ]
}

/// Remove from `flux` what the regressors explain: fit `flux = c₀ + Σ cₖ rₖ` by least squares over the
/// plates where `use_plate` is true (out of the transit), and return `flux / (1 + Σ cₖ rₖ / c₀)` with the
/// coefficients. Unchanged when the fit is singular or too few plates remain.
pub fn decorrelate(
    flux: &[f64],
    regressors: &[Vec<f64>],
    use_plate: &[bool],
) -> (Vec<f64>, Vec<f64>) {
    let m = regressors.len() + 1;
    let row = |p: usize| -> Vec<f64> {
        std::iter::once(1.0)
            .chain(regressors.iter().map(|r| r[p]))
            .collect()
    };
    let mut ata = vec![0.0; m * m];
    let mut atb = vec![0.0; m];
    let mut used = 0;
    for p in 0..flux.len() {
        let r = row(p);
        if !use_plate[p] || !flux[p].is_finite() || r.iter().any(|v| !v.is_finite()) {
            continue;
        }
        used += 1;
        for a in 0..m {
            atb[a] += r[a] * flux[p];
            for b in 0..m {
                ata[a * m + b] += r[a] * r[b];
            }
        }
    }
    if used < 2 * m {
        return (flux.to_vec(), Vec::new());
    }
    let Some(c) = linalg::solve(&ata, &atb, m) else {
        return (flux.to_vec(), Vec::new());
    };
    let out = (0..flux.len())
        .map(|p| {
            let r = row(p);
            let model: f64 = (1..m).map(|k| c[k] * r[k]).sum();
            flux[p] / (1.0 + model / c[0])
        })
        .collect();
    (out, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decorrelation_removes_a_linear_trend_in_the_regressor_and_keeps_the_masked_dip() {
        let n = 400;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 37) % 101) as f64 / 100.0 - 0.5)
            .collect();
        let y: Vec<f64> = (0..n)
            .map(|i| ((i * 53) % 97) as f64 / 96.0 - 0.5)
            .collect();
        let dip = |p: usize| if (180..220).contains(&p) { 0.99 } else { 1.0 };
        let flux: Vec<f64> = (0..n)
            .map(|p| dip(p) * (1.0 + 0.02 * x[p] - 0.01 * y[p] * y[p]))
            .collect();
        let mask: Vec<bool> = (0..n).map(|p| !(180..220).contains(&p)).collect();
        let (out, c) = decorrelate(&flux, &centroid_regressors(&x, &y), &mask);
        assert_eq!(c.len(), 6);
        for p in 0..n {
            let want = dip(p) * out[0] / dip(0);
            assert!(
                (out[p] - want).abs() < 1e-9,
                "plate {p}: {} vs {want}",
                out[p]
            );
        }
    }

    #[test]
    fn a_place_predicted_a_pixel_off_is_recentred_on_the_star() {
        // a Gaussian star (σ 1.2 px) at (15.3, 14.6) on a sky of 10 e⁻ in a 31² window, predicted 1.4 px
        // away: the iterated centroid lands within 0.05 px of it
        let n = 31;
        let (x0, y0, s) = (15.3, 14.6, 1.2);
        let e: Vec<f64> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64 - x0, (i / n) as f64 - y0);
                10.0 + 1e5 * (-(x * x + y * y) / (2.0 * s * s)).exp()
            })
            .collect();
        let (x, y) = recentre(&e, n, 10.0, (16.3, 13.6));
        assert!((x - x0).abs() < 0.05 && (y - y0).abs() < 0.05, "({x}, {y})");
        // no light: the prediction stays
        assert_eq!(
            recentre(&vec![10.0; n * n], n, 10.0, (16.3, 13.6)),
            (16.3, 13.6)
        );
    }

    #[test]
    fn high_pass_removes_a_slow_trend_and_keeps_a_fast_one() {
        let n = 2000;
        let fast = |i: usize| if i.is_multiple_of(2) { 1.0 } else { -1.0 };
        let v: Vec<f64> = (0..n).map(|i| 0.01 * i as f64 + fast(i)).collect();
        let hp = high_pass(&v, 101);
        for i in 60..n - 60 {
            // a linear trend is its own centred mean; the alternation's mean over 101 values is ±1/101
            assert!((hp[i] - fast(i)).abs() < 0.011, "{i}: {}", hp[i]);
        }
    }

    #[test]
    fn differential_light_curve_divides_out_what_all_stars_share() {
        let common: Vec<f64> = (0..50)
            .map(|i| 1.0 + 0.1 * (i as f64 * 0.3).sin())
            .collect();
        let target: Vec<f64> = common.iter().map(|c| 1000.0 * c).collect();
        let comps: Vec<Vec<f64>> = (1..4)
            .map(|k| common.iter().map(|c| 300.0 * k as f64 * c).collect())
            .collect();
        let mut all = vec![target];
        all.extend(comps);
        for v in differential(&all) {
            assert!((v - 1.0).abs() < 1e-12);
        }
    }
}
