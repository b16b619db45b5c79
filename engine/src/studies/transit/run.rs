//! A transit stare end to end: simulate ([`super::observe`]), measure each plate's windows from the products
//! alone ([`crate::analysis::stare_photometry`]), decorrelate, search for the transit (a box search), and
//! score the light curve's precision against the noise budget ([`super::budget`]) and the recovered depth
//! against the injected one (the scoring step reads the truth; nothing before it does).

use super::budget::{self, Budget};
use super::observe::{Observation, StareError, StareReadout, observe};
pub use super::search::{MASK_MARGIN, box_mask, search};
use super::spec::{Decorrelation, PhotometryKind, Spec};
use crate::analysis::lightcurve::{BoxFit, binned_scatter_ppm};
use crate::analysis::stare_photometry::{self as phot, Setup, StarMeasure};
use crate::config::Config;
use crate::numerics::stats;
use rayon::prelude::*;

/// The target's light curve and what it was measured with.
#[derive(Debug, Clone, Default)]
pub struct LightCurve {
    /// Mid-plate times, days from the stare's start.
    pub t_days: Vec<f64>,
    /// The differential light curve of the chosen photometry, decorrelated (1 = its median out of the
    /// transit's mask).
    pub flux: Vec<f64>,
    /// … before decorrelation.
    pub flux_raw: Vec<f64>,
    /// Both photometries' differential light curves (not decorrelated; the aperture's at the radius chosen).
    pub aperture_rel: Vec<f64>,
    /// The aperture radius used, px, and its index among the spec's radii.
    pub aperture_px: f64,
    pub aperture_index: usize,
    pub psf_rel: Vec<f64>,
    /// The target's fitted place, detector px, and the sky per pixel, e⁻.
    pub x_px: Vec<f64>,
    pub y_px: Vec<f64>,
    pub sky_e: Vec<f64>,
    /// Telemetry of each plate, mas.
    pub telemetry_x_mas: Vec<f64>,
    pub telemetry_y_mas: Vec<f64>,
    pub telemetry_sigma_mas: Vec<f64>,
    /// Plates inside the transit box found, widened by [`MASK_MARGIN`] (left out of the decorrelation's fit
    /// and the precision).
    pub in_box: Vec<bool>,
    /// The decorrelation's regressors (one series per regressor; none without decorrelation).
    pub regressors: Vec<Vec<f64>>,
}

/// A light curve's measured scatter, ppm.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Precision {
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub plate_ppm: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub hour_ppm: f64,
    /// Whether the 1-h figure is measured (≥ 3 bins of 1 h out of the transit) or the plates' scatter over
    /// √(plates per hour).
    pub hour_measured: bool,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub six_and_half_hours_ppm: f64,
    /// Whether the 6.5-h figure is measured (≥ 3 bins of 6.5 h) or the 1-h one over √6.5 (white beyond 1 h).
    pub six_and_half_measured: bool,
}

/// The *predicted* single-transit significance of a depth at this precision (a forecast for the mission's
/// required depths, not a measurement: the injected transit's significance is [`Recovery::snr`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Detection {
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub depth: f64,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub duration_h: f64,
    /// depth / (σ_1h √(1 h / duration)).
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub snr: f64,
    /// At or above [`DETECTION_SNR`].
    pub detected: bool,
}

impl Detection {
    /// One line: `predicted for a 0.3 % transit of 1.58 h at the measured 1-h scatter: 38.6σ in one transit
    /// (detected)`.
    pub fn describe(&self) -> String {
        format!(
            "predicted for a {:.1} % transit of {:.2} h at the measured 1-h scatter: {:.1}σ in one transit ({})",
            100.0 * self.depth,
            self.duration_h,
            self.snr,
            if self.detected {
                "detected".to_string()
            } else {
                format!("below {DETECTION_SNR}σ")
            }
        )
    }
}

/// The significance a single transit needs to count as detected (Kepler's 7.1σ threshold, Jenkins et al.
/// 2010).
pub const DETECTION_SNR: f64 = 7.1;

/// The recovered transit and its score.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Recovery {
    pub t0_days: f64,
    pub duration_h: f64,
    pub depth: f64,
    /// The depth's 1σ error, from the scatter of the light curve out of the box ([`search`]).
    pub depth_sigma: f64,
    /// The transit's measured significance, depth / depth_sigma: the one the stare reports for it.
    pub snr: f64,
    /// Scoring (truth): the injected transit's mean depth over the plates of the box, and the pull
    /// (recovered − injected)/σ; whether the box overlaps the injected transit.
    pub injected_depth: f64,
    pub pull: f64,
    pub overlaps_injected: bool,
}

/// Everything a stare produced.
#[derive(Debug, Clone)]
pub struct StareResult {
    pub readout: StareReadout,
    pub lc: LightCurve,
    pub precision: Precision,
    pub precision_psf: Precision,
    pub budget: Budget,
    pub recovery: Option<Recovery>,
    /// Predictions for the required depths ([`REQUIRED_DEPTHS`]) at the measured precision, less the
    /// injected transit's depth when it was found (its significance is the recovery's).
    pub detections: Vec<Detection>,
    pub simulate_s: f64,
    pub analyse_s: f64,
    pub backend: String,
}

/// The depths whose detection the study reports: the mission's full (0.3 %) and extra (0.1 %) success.
pub const REQUIRED_DEPTHS: [f64; 2] = [0.003, 0.001];

/// The PSF fit's radius, px.
pub const FIT_RADIUS_PX: f64 = 4.0;

/// Each star's predicted place in its window in every plate, window px (`[star][plate]`): the reference
/// catalogue's position through the design WCS ([`Observation::catalogue_px`]) moved by the plate's
/// telemetered mean pointing (the stare's array is unrotated: a pointing offset of `(x, y)` mas moves the
/// stars by `(x, y)` / plate scale px), less the window's corner.
pub fn predicted_places(obs: &Observation) -> Vec<Vec<(f64, f64)>> {
    let scale_mas = obs.cfg.instrument.plate_scale_mas();
    obs.windows
        .iter()
        .zip(&obs.catalogue_px)
        .map(|(w, (cx, cy))| {
            obs.plates
                .iter()
                .map(|p| {
                    (
                        cx + p.telemetry_x_mas / scale_mas - w.x0 as f64,
                        cy + p.telemetry_y_mas / scale_mas - w.y0 as f64,
                    )
                })
                .collect()
        })
        .collect()
}

/// Measure every plate's windows, each from its predicted place recentred on the data: `[star][plate]`.
pub fn measure(obs: &Observation) -> Vec<Vec<StarMeasure>> {
    let d = &obs.cfg.detector;
    let setup = Setup {
        gain_e_per_adu: d.gain_e_per_adu,
        bias_adu: d.bias_adu * obs.readout.sub_exposures as f64,
        read_noise_e: obs.readout.read_noise_e,
        apertures_px: obs.spec.aperture_radii_px(),
        annulus_in_px: obs.spec.annulus_in_px,
        annulus_out_px: obs.spec.annulus_out_px,
        fit_radius_px: FIT_RADIUS_PX,
    };
    let places = predicted_places(obs);
    (0..obs.windows.len())
        .into_par_iter()
        .map(|k| {
            let w = &obs.windows[k];
            obs.plates
                .iter()
                .zip(&places[k])
                .map(|(p, &guess)| {
                    let mut m = phot::measure_window(
                        &p.windows_adu[k],
                        w.n,
                        &obs.calibration_flat[k],
                        &setup,
                        &obs.model_psf,
                        guess,
                    );
                    m.x_px += w.x0 as f64;
                    m.y_px += w.y0 as f64;
                    m
                })
                .collect()
        })
        .collect()
}

/// The light curve from the measurements: differential, decorrelated in two passes (all plates; then
/// without the plates of the box a first search found, when it is significant).
pub fn light_curve(obs: &Observation, m: &[Vec<StarMeasure>]) -> LightCurve {
    let radii = obs.spec.aperture_radii_px();
    let aperture_curves: Vec<Vec<f64>> = (0..radii.len())
        .map(|r| {
            phot::differential(
                &m.iter()
                    .map(|s| s.iter().map(|q| q.aperture_e[r]).collect())
                    .collect::<Vec<Vec<f64>>>(),
            )
        })
        .collect();
    let psf_rel = phot::differential(
        &m.iter()
            .map(|s| s.iter().map(|q| q.psf_e).collect())
            .collect::<Vec<Vec<f64>>>(),
    );
    let t_days: Vec<f64> = obs.plates.iter().map(|p| p.t_mid_days).collect();
    let x_px: Vec<f64> = m[0].iter().map(|s| s.x_px).collect();
    let y_px: Vec<f64> = m[0].iter().map(|s| s.y_px).collect();
    let tx: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_x_mas).collect();
    let ty: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_y_mas).collect();
    let ts: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_sigma_mas).collect();
    let place = match obs.spec.decorrelate {
        Decorrelation::None => None,
        Decorrelation::Centroid => Some(phot::centroid_regressors(&x_px, &y_px)),
        Decorrelation::Telemetry => Some(phot::centroid_regressors(&tx, &ty)),
    };
    let regressors: Vec<Vec<f64>> = match place {
        None => Vec::new(),
        Some(mut r) => {
            // the PSF's width (the telemetry's jitter σ): the aperture's losses grow with it, and the
            // stars' losses need not divide out exactly in the differential
            let ms = stats::mean(&ts);
            r.push(ts.iter().map(|s| s - ms).collect());
            // plate to plate only: the slow drift's share stays in the light curve (the budget's drift
            // term) rather than taking the light curve's own slow noise, and a transit's, with it
            let hour = (3600.0 / obs.readout.cadence_s).round().max(3.0) as usize;
            r.iter().map(|x| phot::high_pass(x, hour)).collect()
        }
    };
    let all = vec![true; psf_rel.len()];
    let decorrelated = |f: &[f64], use_plate: &[bool]| {
        if regressors.is_empty() {
            f.to_vec()
        } else {
            phot::decorrelate(f, &regressors, use_plate).0
        }
    };
    // the aperture whose decorrelated light curve scatters least from plate to plate
    let aperture_index = (0..radii.len())
        .map(|r| {
            (
                r,
                phot::point_to_point(&decorrelated(&aperture_curves[r], &all)),
            )
        })
        .filter(|(_, s)| s.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(r, _)| r);
    let aperture_rel = aperture_curves[aperture_index].clone();
    let flux_raw = match obs.spec.photometry {
        PhotometryKind::Aperture => aperture_rel.clone(),
        PhotometryKind::Psf => psf_rel.clone(),
    };
    let mut in_box = vec![false; flux_raw.len()];
    let mut flux = decorrelated(&flux_raw, &all);
    if let Some(b) = search(&t_days, &flux, obs.spec.duration_h)
        && b.snr >= DETECTION_SNR
    {
        in_box = box_mask(&t_days, &b, MASK_MARGIN);
        let out: Vec<bool> = in_box.iter().map(|b| !b).collect();
        flux = decorrelated(&flux_raw, &out);
    }
    // 1 = the median out of the transit
    let level: Vec<f64> = flux
        .iter()
        .zip(&in_box)
        .filter(|(v, b)| !**b && v.is_finite())
        .map(|(v, _)| *v)
        .collect();
    let out_level = stats::median(&level);
    if out_level.is_finite() && out_level > 0.0 {
        flux.iter_mut().for_each(|v| *v /= out_level);
    }
    LightCurve {
        t_days,
        flux,
        flux_raw,
        aperture_rel,
        aperture_px: radii[aperture_index],
        aperture_index,
        psf_rel,
        x_px,
        y_px,
        sky_e: m[0].iter().map(|s| s.sky_e).collect(),
        telemetry_x_mas: tx,
        telemetry_y_mas: ty,
        telemetry_sigma_mas: ts,
        in_box,
        regressors,
    }
}

/// The measured scatter of a light curve, leaving out the masked plates.
pub fn precision(t_days: &[f64], flux: &[f64], mask: &[bool]) -> Precision {
    let f: Vec<f64> = flux
        .iter()
        .zip(mask)
        .map(|(v, m)| if *m { f64::NAN } else { *v })
        .collect();
    let good: Vec<f64> = f.iter().cloned().filter(|v| v.is_finite()).collect();
    let level = stats::mean(&good);
    let plate_ppm = 1e6 * stats::std_dev(&good) / level;
    // too few whole hours out of the transit: the plates' scatter over √(plates per hour)
    let per_hour = match (t_days.first(), t_days.last()) {
        (Some(a), Some(b)) if t_days.len() > 1 => (t_days.len() - 1) as f64 / (24.0 * (b - a)),
        _ => 1.0,
    };
    let (hour_ppm, hour_measured) = match binned_scatter_ppm(t_days, &f, 1.0 / 24.0) {
        Some(v) => (v, true),
        None => (plate_ppm / per_hour.max(1.0).sqrt(), false),
    };
    let (six_and_half_hours_ppm, six_and_half_measured) =
        match binned_scatter_ppm(t_days, &f, 6.5 / 24.0) {
            Some(v) => (v, true),
            None => (hour_ppm / 6.5f64.sqrt(), false),
        };
    Precision {
        plate_ppm,
        hour_ppm,
        hour_measured,
        six_and_half_hours_ppm,
        six_and_half_measured,
    }
}

/// The predicted single-transit significance of each required depth at a 1-h precision, for the spec's
/// transit shape: `depth / (σ_1h √(1 h / duration))`.
pub fn detections(spec: &Spec, hour_ppm: f64) -> Vec<Detection> {
    REQUIRED_DEPTHS
        .iter()
        .map(|&depth| {
            let s = Spec {
                depth,
                ..spec.clone()
            };
            let duration_h = s.transit().map_or(0.0, |t| 24.0 * t.duration_days());
            let snr = depth / (1e-6 * hour_ppm * (1.0 / duration_h.max(1e-9)).sqrt());
            Detection {
                depth,
                duration_h,
                snr,
                detected: snr >= DETECTION_SNR,
            }
        })
        .collect()
}

/// Analyse an observation (products only) and score it (truth).
pub fn analyse(obs: &Observation) -> StareResult {
    let t = std::time::Instant::now();
    let m = measure(obs);
    let lc = light_curve(obs, &m);
    let precision_psf = precision(&lc.t_days, &lc.psf_rel, &lc.in_box);
    let precision = precision(&lc.t_days, &lc.flux, &lc.in_box);
    let analyse_s = t.elapsed().as_secs_f64();
    let recovery = (obs.spec.depth > 0.0)
        .then(|| search(&lc.t_days, &lc.flux, obs.spec.duration_h))
        .flatten()
        .map(|b| score(obs, &lc, &b));
    // the injected transit, found, has its measured significance: no prediction of another for its depth
    let detections = detections(&obs.spec, precision.hour_ppm)
        .into_iter()
        .filter(|d| recovery.is_none() || (d.depth - obs.spec.depth).abs() > 1e-9)
        .collect();
    StareResult {
        readout: obs.readout,
        detections,
        precision,
        precision_psf,
        budget: budget::predict(obs, lc.aperture_index, &lc.regressors, &lc.in_box),
        recovery,
        lc,
        simulate_s: obs.simulate_s,
        analyse_s,
        backend: obs.backend.clone(),
    }
}

/// Score a found box against the injected transit (the truth).
fn score(obs: &Observation, lc: &LightCurve, b: &BoxFit) -> Recovery {
    let inside = box_mask(&lc.t_days, b, 0.0);
    let depths: Vec<f64> = obs
        .truth
        .iter()
        .zip(&inside)
        .filter(|(_, i)| **i)
        .map(|(t, _)| 1.0 - t.transit_flux)
        .collect();
    let injected = stats::mean(&depths);
    let overlaps = depths.iter().any(|d| *d > 0.0);
    Recovery {
        t0_days: b.t0_days,
        duration_h: 24.0 * b.duration_days,
        depth: b.depth,
        depth_sigma: b.depth_sigma,
        snr: b.snr,
        injected_depth: injected,
        pull: (b.depth - injected) / b.depth_sigma,
        overlaps_injected: overlaps,
    }
}

/// Simulate and analyse a stare.
pub fn run(cfg: &Config, spec: &Spec) -> Result<(Observation, StareResult), StareError> {
    let obs = observe(cfg, spec)?;
    let r = analyse(&obs);
    Ok((obs, r))
}
