//! The noise budget of a stare's differential light curve, predicted term by term (relative, per plate,
//! then binned), apart from the light curve it explains:
//!
//! * **photon**: the stars' own shot noise, `1/F_T + 1/ΣF_C` (F: the mean noise-free aperture flux, e⁻);
//! * **read (+ dark)**: per star `A (σ_r² + D t)(1 + π A / (2 N_sky))` over its flux² (A: the aperture's
//!   area; σ_r the plate's read noise, √n per sub-exposure; D the dark current; the sky's median from N_sky
//!   annulus pixels, of variance π/2 times a mean's);
//! * **flat residual**: the calibration flat's error ε (`analysis.flat_field`; the flat's own σ when
//!   uncalibrated) seen by a star moving over the pixels: `ε² Σᵢ var(pᵢ)` over the aperture's pixels, pᵢ the
//!   share of the star's light in pixel i in each plate — binned, the variance over the bins of each pixel's
//!   bin-mean share (the drift carries the stars over the flat's errors slowly: that part does not average);
//! * **jitter × intra-pixel** and **drift**: the noise-free differential aperture flux, plate by plate (the
//!   stars moving as the ACE and the drift move them, a perfect flat and no noise), decorrelated as the
//!   light curve is (its regressors, fitted out of the transit's box): its point-to-point
//!   scatter (`std(Δ)/√2`: white, from plate to plate: the jitter) and its slow part (the rms of its 1-h
//!   running mean: the drift moving the stars' pixel phases).
//!
//! A band-limited PSF collects the same total light at every pixel phase, whatever the intra-pixel map
//! (JASMINE's optical cut-off, D/λ, is 0.83 cycles per pixel at 0.99 µm: below the map's first harmonic), so
//! the jitter's noise is what the aperture cuts off: it grows as the aperture shrinks. Photon, read and
//! jitter bin as 1/√N; the drift at its running mean's rms over the bin; the flat over its bins' shares (as
//! 1/√N when fewer than two bins fit the stare).

use super::observe::Observation;
use crate::analysis::stare_photometry::{decorrelate, differential, point_to_point};
use crate::config::FlatField;
use crate::numerics::stats;

/// One bin's terms, ppm.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Terms {
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub photon_ppm: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub read_ppm: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub jitter_ppm: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub flat_ppm: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub drift_ppm: f64,
}

impl Terms {
    /// The terms in quadrature.
    pub fn total_ppm(&self) -> f64 {
        (self.photon_ppm.powi(2)
            + self.read_ppm.powi(2)
            + self.jitter_ppm.powi(2)
            + self.flat_ppm.powi(2)
            + self.drift_ppm.powi(2))
        .sqrt()
    }

    /// (name, ppm) pairs in the budget's order.
    pub fn named(&self) -> [(&'static str, f64); 5] {
        [
            ("photon", self.photon_ppm),
            ("read+dark", self.read_ppm),
            ("jitter x intra-pixel", self.jitter_ppm),
            ("flat residual", self.flat_ppm),
            ("drift", self.drift_ppm),
        ]
    }
}

/// The budget at one plate, 1 h and 6.5 h.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Budget {
    pub plate: Terms,
    pub hour: Terms,
    pub six_and_half_hours: Terms,
}

/// The rms of the running mean of `v` over `w` consecutive values (about the whole series' mean); 0 when
/// the series is not longer than the window.
pub fn running_mean_rms(v: &[f64], w: usize) -> f64 {
    let w = w.max(1);
    if v.len() <= w {
        return 0.0;
    }
    let m = stats::mean(v);
    let mut acc = v[..w].iter().sum::<f64>();
    let mut means = vec![acc / w as f64];
    for i in w..v.len() {
        acc += v[i] - v[i - w];
        means.push(acc / w as f64);
    }
    (means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / means.len() as f64).sqrt()
}

/// Predict the budget of an observation's differential aperture light curve, decorrelated with
/// `regressors` fitted over the plates outside `in_box` (the light curve's own), at the aperture of index
/// `aperture_index` among the spec's radii.
pub fn predict(
    obs: &Observation,
    aperture_index: usize,
    regressors: &[Vec<f64>],
    in_box: &[bool],
) -> Budget {
    let radius = obs.spec.aperture_radii_px()[aperture_index];
    let clean_e = &obs.clean_aperture_e[aperture_index];
    let spec = &obs.spec;
    let d = &obs.cfg.detector;
    let plates = obs.plates.len().max(1);
    let mean_flux: Vec<f64> = clean_e
        .iter()
        .map(|v| {
            let g: Vec<f64> = v.iter().cloned().filter(|x| x.is_finite()).collect();
            stats::mean(&g)
        })
        .collect();
    let (ft, fc) = (mean_flux[0], mean_flux[1..].iter().sum::<f64>());
    let photon = (1.0 / ft + 1.0 / fc).sqrt();
    let area = std::f64::consts::PI * radius.powi(2);
    let n_sky = std::f64::consts::PI * (spec.annulus_out_px.powi(2) - spec.annulus_in_px.powi(2));
    let pix_var = obs.readout.read_noise_e.powi(2) + d.dark_e_per_s * spec.plate_s;
    let star_read_var = area * pix_var * (1.0 + std::f64::consts::FRAC_PI_2 * area / n_sky);
    let n_comp = (mean_flux.len() - 1) as f64;
    let read = (star_read_var / (ft * ft) + n_comp * star_read_var / (fc * fc)).sqrt();
    // the flat residual, star by star over the aperture around the window's centre
    let eps = match obs.cfg.analysis.flat_field {
        FlatField::Calibrated { error } => error,
        FlatField::Uncalibrated => d.inter_pixel_flat_sigma,
    };
    let in_aperture = |w: &super::observe::Window, i: usize| {
        let c = (w.n / 2) as f64;
        let (x, y) = ((i % w.n) as f64, (i / w.n) as f64);
        (x - c).hypot(y - c) <= radius + 0.5
    };
    // the target's relative variance and the ensemble's (each comparison's weighted by its flux²)
    let differential_var = |var: &[f64]| {
        var[0]
            + var[1..]
                .iter()
                .zip(&mean_flux[1..])
                .map(|(v, f)| v * f * f)
                .sum::<f64>()
                / (fc * fc)
    };
    let flat_var: Vec<f64> = obs
        .pixel_moments
        .iter()
        .zip(&obs.windows)
        .map(|((s1, s2), w)| {
            let v: f64 = (0..w.n * w.n)
                .filter(|&i| in_aperture(w, i))
                .map(|i| {
                    let m = s1[i] / plates as f64;
                    (s2[i] / plates as f64 - m * m).max(0.0)
                })
                .sum();
            eps * eps * v
        })
        .collect();
    let flat = differential_var(&flat_var).sqrt();
    // binned: the variance over bins of each pixel's bin-mean fraction (the drift's slow share stays)
    let flat_binned = |bf: &super::observe::BinnedFractions| -> Option<f64> {
        let full = (0.5 * bf.bin_h * 3600.0 / obs.readout.cadence_s).max(1.0) as usize;
        let bins: Vec<usize> = (0..bf.counts.len())
            .filter(|&b| bf.counts[b] >= full)
            .collect();
        if bins.len() < 2 {
            return None;
        }
        let var: Vec<f64> = obs
            .windows
            .iter()
            .enumerate()
            .map(|(k, w)| {
                let npx = w.n * w.n;
                (0..npx)
                    .filter(|&i| in_aperture(w, i))
                    .map(|i| {
                        let m: Vec<f64> = bins
                            .iter()
                            .map(|&b| bf.sums[k][b * npx + i] / bf.counts[b] as f64)
                            .collect();
                        stats::std_dev(&m).powi(2)
                    })
                    .sum::<f64>()
                    * eps
                    * eps
            })
            .collect();
        Some(differential_var(&var).sqrt())
    };
    // the pointing alone: the noise-free differential light curve
    let clean = differential(clean_e);
    let clean = if regressors.is_empty() {
        clean
    } else {
        let out: Vec<bool> = in_box.iter().map(|b| !b).collect();
        decorrelate(&clean, regressors, &out).0
    };
    let good: Vec<f64> = clean.iter().cloned().filter(|v| v.is_finite()).collect();
    let jitter = point_to_point(&good);
    let per_hour = (3600.0 / obs.readout.cadence_s).round().max(1.0) as usize;
    let drift = running_mean_rms(&good, per_hour);
    let drift_65 = running_mean_rms(&good, (6.5 * per_hour as f64).round() as usize);
    let plate_terms = Terms {
        photon_ppm: 1e6 * photon,
        read_ppm: 1e6 * read,
        jitter_ppm: 1e6 * jitter,
        flat_ppm: 1e6 * flat,
        drift_ppm: 1e6
            * (stats::std_dev(&good).powi(2) - jitter * jitter)
                .max(0.0)
                .sqrt(),
    };
    let binned = |n: f64, drift: f64, flat: Option<f64>| Terms {
        photon_ppm: plate_terms.photon_ppm / n.sqrt(),
        read_ppm: plate_terms.read_ppm / n.sqrt(),
        jitter_ppm: plate_terms.jitter_ppm / n.sqrt(),
        flat_ppm: flat.map_or(plate_terms.flat_ppm / n.sqrt(), |f| 1e6 * f),
        drift_ppm: 1e6 * drift,
    };
    let flat_at = |h: f64| {
        obs.binned_fractions
            .iter()
            .find(|b| b.bin_h == h)
            .and_then(flat_binned)
    };
    Budget {
        plate: plate_terms,
        hour: binned(per_hour as f64, drift, flat_at(1.0)),
        six_and_half_hours: binned(6.5 * per_hour as f64, drift_65, flat_at(6.5)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_mean_of_white_noise_falls_as_root_n_and_of_a_constant_is_zero() {
        let mut r = crate::rng::stream(7, crate::rng::Stream::Test, 0);
        use rand_distr::{Distribution, StandardNormal};
        let v: Vec<f64> = (0..40_000).map(|_| StandardNormal.sample(&mut r)).collect();
        let s = running_mean_rms(&v, 100);
        // the running mean of 100 unit normals has σ 0.1; 400 independent windows: ±3.5 % (1σ)
        assert!((s - 0.1).abs() < 0.011, "{s}");
        assert_eq!(running_mean_rms(&[2.0; 50], 10), 0.0);
        assert_eq!(running_mean_rms(&[1.0, 2.0], 5), 0.0);
    }
}
