//! The instant accuracy predictor: what an exposure's single-image accuracy will be, without simulating it.
//!
//! `σ_pred² = σ_noise² + σ_disp²` per axis, averaged (as σ) over the exposures of a dataset:
//! * **σ_noise** — the Cramér–Rao bound of a star (x, y, flux; sky known) under the exact ePSF: the PSF blurred
//!   by a Gaussian with this exposure's ACE σ per axis (the Gaussian ACE σ, or the series' σ over the
//!   exposure), integrated over the pixel with the subpixel/intra-pixel model, averaged over pixel phases
//!   (as σ²), with the pixel variance `μ + RN² + g²/12 + (σ_flat·signal)²` — the inter-pixel flat is unknown
//!   to the fit and acts as noise. Plate models absorb p of the n stars' degrees of freedom: × (1 − p/n),
//!   and add their reference catalogue's error E projected through the model: E²·(p/2 − 1)/n per axis.
//! * **σ_disp** — the rms over stars (mean removed) of the fit displacement the ACE series predicts for each
//!   star: through the fit's response to the jitter of its window ([`crate::analysis::response`], linear),
//!   plus the shape term ([`crate::studies::predict_shape`]: noise-free stamps of the stars through their own
//!   windows, run through the analysis' ePSF builder and fit — what the linear response misses when the star
//!   images change shape along Y, and how the builder's ePSF responds), its band mean in Y added to each star
//!   and its spread added in quadrature. After `plate-*`, the residual of the same least-squares model fitted
//!   to those displacements; after `telemetry`, the displacement minus the telemetry's own linear prediction
//!   (its noise, rate and latency included); after `telemetry-model` (and before its plate model), what the
//!   telemetry's errors move through the linear response (the forward model models the shape). The Y-zoned
//!   ePSFs cannot remove a displacement, so they predict what `none` does.
//!
//! The PSF is the design's (`Simulator::design_optical_kernel`): the predictor is a planner's tool and knows
//! what the products know; with an as-built instrument off its design it predicts what the design promises.
//!
//! Measured (paper grid, Hw 12.5, realistic ACE, rolling, ideal telemetry, 25 exposures): per-exposure
//! predictions within 0.13–0.16 mas rms of the measured accuracy for `none`, `telemetry` and
//! `telemetry-model` (the shift correction's 0.94-for-0.69 optimism came from the missing shape term).
//! Neglected (documented): the ePSF builder's own inefficiency under a static ACE.
//! Cost: the bound is cached per 5-mas blur step (≈ 30 ms each); each realistic image costs one fit-response
//! table (≈ 30 ms) and the shape term (≈ 0.7 s for 400 stars on 2 cores).

use crate::analysis::countermeasures::telemetry::TelemetryRecord;
use crate::analysis::countermeasures::{
    Countermeasure, CountermeasureError, Reference, Telemetry, TelemetryQuality,
};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::BuildOptions;
use crate::analysis::epsf::fit::pixel_variance;
use crate::analysis::response::{FitNoise, FitResponse};
use crate::config::AceCase;
use crate::config::TelemetryFilter;
use crate::integrate::kernel::{IntraPixelMap, PixelKernel, subpixel_sum};
use crate::integrate::track::Track;
use crate::jitter::AceSeries;
use crate::numerics::{linalg, stats};
use crate::optics::psf::PsfTable;
use crate::readout::ReadoutTiming;
use crate::simulate::{SimError, Simulator};
use crate::studies::predict_shape::ShapeTerm;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// One exposure's inputs.
struct ImageInputs {
    track: Option<Track>,
    sigma_x_mas: f64,
    sigma_y_mas: f64,
    start_s: f64,
}

/// The fit displacements of one exposure's stars: the linear response's and the shape term's.
struct Displacements {
    linear: Vec<(f64, f64)>,
    shape: ShapeTerm,
}

impl Displacements {
    /// Linear response plus the shape term's mean at each star's row.
    fn full(&self, stars: &[(f64, f64)]) -> Vec<(f64, f64)> {
        self.linear
            .iter()
            .zip(stars)
            .map(|(d, s)| {
                let t = self.shape.at(s.1);
                (d.0 + t.0, d.1 + t.1)
            })
            .collect()
    }
}

/// What a plate model or the residual is computed on.
#[derive(Debug, Clone, Copy)]
enum Before {
    /// The global fits: the full displacement (linear response and shape term).
    Fits,
    /// The global fits minus the telemetry's linear prediction (`telemetry`): the telemetry's error and the
    /// shape term.
    ShiftCorrected(TelemetryQuality),
    /// The forward model's fits: what the telemetry's errors move through the linear response (the shape is
    /// modelled).
    ForwardModel(TelemetryQuality),
}

/// Precomputed inputs of the predictor for one dataset configuration.
pub struct Predictor {
    cfg: crate::config::Config,
    psf: Arc<PsfTable>,
    kernel: Arc<PixelKernel>,
    map: IntraPixelMap,
    noise: FitNoise,
    timing: ReadoutTiming,
    series: Option<Arc<AceSeries>>,
    stars: Vec<(f64, f64)>,
    images: Vec<ImageInputs>,
    bound_cache: Mutex<HashMap<(i64, i64), f64>>,
    disp_cache: Mutex<HashMap<usize, Arc<Displacements>>>,
    /// The static profile (the optical kernel tabulated) the shape term sees through each window.
    psi: Epsf,
    /// The analysis' ePSF builder options (the shape term's build and fits).
    build: BuildOptions,
    /// The telemetry's linear prediction of each image's displacements, by (image, quality).
    telemetry_cache: Mutex<HashMap<(usize, String), Arc<Vec<(f64, f64)>>>>,
}

/// An rms (px) with a scatter (px² per axis) added in quadrature.
fn with_scatter(rms_px: f64, scatter_px2: f64) -> f64 {
    (rms_px * rms_px + scatter_px2).sqrt()
}

fn rms2(v: &[(f64, f64)]) -> f64 {
    let x: Vec<f64> = v.iter().map(|p| p.0).collect();
    let y: Vec<f64> = v.iter().map(|p| p.1).collect();
    ((stats::std_dev(&x).powi(2) + stats::std_dev(&y).powi(2)) / 2.0).sqrt()
}

/// Why a prediction could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    #[error(transparent)]
    Simulation(#[from] SimError),
    #[error(transparent)]
    Countermeasure(#[from] CountermeasureError),
    #[error("{0}: the star positions do not constrain the plate model")]
    Degenerate(String),
    #[error("no exposure to predict")]
    NoImages,
}

impl Predictor {
    /// The predictor of `sim`'s dataset analysed with `analysis` (passed explicitly: a session's cached
    /// simulator keeps the analysis settings it was built with).
    pub fn new(sim: &Simulator, analysis: &crate::config::Analysis) -> Result<Self, SimError> {
        let mut cfg = sim.cfg.clone();
        cfg.analysis = analysis.clone();
        // the design's PSF: what a planner (and the analysis' products) know, not the instrument as built
        let psf = match sim.stars.first() {
            Some(s) => sim.design_psf_for(s),
            None => sim.design_psf_for_colour(cfg.scene.j_minus_h),
        };
        let kernel = sim.design_optical_kernel()?;
        let images = (0..cfg.fidelity.images)
            .map(|i| {
                let a = sim.ace_stats(i);
                let (sx, sy) = match cfg.ace.case {
                    AceCase::Gaussian => (cfg.ace.sigma_mas, cfg.ace.sigma_mas),
                    AceCase::Realistic => (a.sigma_x_mas, a.sigma_y_mas),
                    AceCase::None => (0.0, 0.0),
                };
                ImageInputs {
                    track: sim.track(i),
                    sigma_x_mas: sx,
                    sigma_y_mas: sy,
                    start_s: sim.exposure_start_s(i),
                }
            })
            .collect();
        let psi = Epsf::from_fn(4, analysis.epsf_radius_px + 2, |x, y| kernel.eval(x, y));
        Ok(Self {
            map: IntraPixelMap::from_config(&cfg.detector, cfg.fidelity.subpixels)?,
            kernel,
            psi,
            build: crate::analysis::epsf::build::build_options(analysis),
            noise: crate::session::source::simulation_fit_noise(sim, analysis.fit_radius_px),
            timing: sim.timing,
            series: sim.series_arc(),
            stars: sim.stars.iter().map(|s| (s.x_px, s.y_px)).collect(),
            psf,
            cfg,
            images,
            bound_cache: Mutex::new(HashMap::new()),
            disp_cache: Mutex::new(HashMap::new()),
            telemetry_cache: Mutex::new(HashMap::new()),
        })
    }

    /// Phase-averaged per-axis Cramér–Rao bound (mas) of a star blurred by σx, σy (mas), flat noise included.
    pub fn noise_floor_mas(&self, sigma_x_mas: f64, sigma_y_mas: f64) -> f64 {
        let scale = self.cfg.instrument.plate_scale_mas();
        let key = (
            (sigma_x_mas / 5.0).round() as i64,
            (sigma_y_mas / 5.0).round() as i64,
        );
        if let Some(v) = self
            .bound_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return *v;
        }
        let psf = self
            .psf
            .gaussian_blurred_xy(key.0 as f64 * 5.0 / scale, key.1 as f64 * 5.0 / scale);
        let d = &self.cfg.detector;
        let f = self.noise.flux_e;
        // the flat error the fit leaves: the whole flat uncalibrated, the calibration flat's error calibrated
        let flat = match self.cfg.analysis.flat_field {
            crate::config::FlatField::Uncalibrated => d.inter_pixel_flat_sigma,
            crate::config::FlatField::Calibrated { error } => error,
        };
        let r = self.noise.radius_px;
        let h = 1e-3;
        let k = |x: f64, y: f64| subpixel_sum(&psf, &self.map, x, y);
        let mut var_sum = 0.0;
        let mut n = 0;
        for py in 0..5 {
            for px in 0..5 {
                let (x, y) = (-0.4 + 0.2 * px as f64, -0.4 + 0.2 * py as f64);
                let mut m = [0.0; 9];
                let ri = r.ceil() as i64 + 1;
                for yy in -ri..=ri {
                    for xx in -ri..=ri {
                        let (dx, dy) = (xx as f64 - x, yy as f64 - y);
                        if dx * dx + dy * dy > r * r {
                            continue;
                        }
                        let psi = k(dx, dy);
                        let gx = (k(dx + h, dy) - k(dx - h, dy)) / (2.0 * h);
                        let gy = (k(dx, dy + h) - k(dx, dy - h)) / (2.0 * h);
                        let mu = f * psi + self.noise.sky_e;
                        let w = 1.0 / pixel_variance(mu, f * psi, self.noise.floor_e2, flat);
                        let j = [-f * gx, -f * gy, psi];
                        for a in 0..3 {
                            for b in 0..3 {
                                m[a * 3 + b] += w * j[a] * j[b];
                            }
                        }
                    }
                }
                if let Some(inv) = linalg::inverse(&m, 3) {
                    var_sum += 0.5 * (inv[0] + inv[4]);
                    n += 1;
                }
            }
        }
        let v = if n > 0 {
            (var_sum / n as f64).sqrt() * scale
        } else {
            f64::INFINITY
        };
        self.bound_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, v);
        v
    }

    /// The fit displacements (px) the ACE predicts for every star in image `i` (zeros for static ACE): the
    /// linear response's and the shape term ([`crate::studies::predict_shape`]).
    fn displacements(&self, i: usize) -> Arc<Displacements> {
        if let Some(v) = self
            .disp_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&i)
        {
            return v.clone();
        }
        let v = match self.images.get(i).and_then(|im| im.track.as_ref()) {
            Some(track) => {
                let nominal = track.window(
                    self.timing.t_overhead_s,
                    self.timing.t_overhead_s + self.timing.exposure_s,
                );
                let response = FitResponse::build(&self.kernel, track, &nominal, &self.noise);
                Displacements {
                    linear: response.displacements(track, &self.timing, &self.stars),
                    shape: ShapeTerm::build(
                        &self.psi,
                        track,
                        &self.timing,
                        &response,
                        &self.noise,
                        &self.build,
                        self.cfg.instrument.detector_px,
                        &self.stars,
                    ),
                }
            }
            None => Displacements {
                linear: vec![(0.0, 0.0); self.stars.len()],
                shape: ShapeTerm::none(),
            },
        };
        let v = Arc::new(v);
        self.disp_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(i, v.clone());
        v
    }

    /// The displacement (px) of every star in image `i` that a plate model is fitted to, or that is left
    /// without one, and the scatter from star to star beside it (px², per axis: the shape term's spread over
    /// pixel phases, where the shape is not modelled).
    fn before_plate(
        &self,
        i: usize,
        before: Before,
    ) -> Result<(Arc<Vec<(f64, f64)>>, f64), PredictError> {
        let d = self.displacements(i);
        let (q, shape) = match before {
            Before::Fits => return Ok((Arc::new(d.full(&self.stars)), d.shape.scatter_px2)),
            Before::ShiftCorrected(q) => (q, true),
            Before::ForwardModel(q) => (q, false),
        };
        let scatter = if shape { d.shape.scatter_px2 } else { 0.0 };
        let base = if shape {
            d.full(&self.stars)
        } else {
            d.linear.clone()
        };
        let (Some(series), Some(im)) = (&self.series, self.images.get(i)) else {
            return Ok((Arc::new(base), scatter));
        };
        // the forward model sees the telemetry filtered as the analysis filters it
        let filter = match shape {
            true => TelemetryFilter::Off,
            false => self.cfg.analysis.telemetry_filter,
        };
        let key = (i, format!("{q:?} {filter:?}"));
        let cached = self
            .telemetry_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
            .cloned();
        let pred = match cached {
            Some(p) => p,
            None => {
                let rec = TelemetryRecord::record(
                    series,
                    self.timing.span_s(),
                    im.start_s,
                    &q,
                    self.cfg.seed,
                )?;
                let rec = rec.model_record(filter).unwrap_or(rec);
                let tel = Telemetry::from_record(
                    &rec,
                    series.dt_s,
                    self.timing,
                    self.cfg.instrument.plate_scale_mas(),
                    0.0,
                    &self.kernel,
                    &self.noise,
                )?;
                let p = Arc::new(tel.predicted_px(&self.stars));
                self.telemetry_cache
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(key, p.clone());
                p
            }
        };
        let r = base
            .iter()
            .zip(pred.iter())
            .map(|(a, b)| (a.0 - b.0, a.1 - b.1))
            .collect();
        Ok((Arc::new(r), scatter))
    }

    /// Per-axis rms (px) of what a countermeasure leaves of image `i`'s displacements, and the parameters it
    /// absorbs.
    fn residual_displacement(
        &self,
        i: usize,
        cm: &Countermeasure,
    ) -> Result<(f64, usize), PredictError> {
        match cm {
            Countermeasure::Plate {
                model,
                reference,
                forward,
            } => {
                let before = match forward {
                    Some(q) => Before::ForwardModel(*q),
                    None => Before::Fits,
                };
                let (d, scatter) = self.before_plate(i, before)?;
                // against a fixed reference the plate removes what the model holds of the displacement:
                // r = d − P d. Against the stare's stack it can only remove the departure from the stare's
                // mean field d̄, which stays (stack::stack_plate's fixed point): r = d − P (d − d̄).
                let mean = match reference {
                    Reference::Stack => Some(self.mean_before_plate(before)?),
                    _ => None,
                };
                // against the catalogue the registration's 2-D quadratic is fitted first to the same
                // differences: the two remove the union of their polynomial spaces
                let registration = match reference {
                    Reference::Catalogue { .. } => Some(
                        crate::analysis::registration::parameters_for(self.stars.len()),
                    ),
                    _ => None,
                };
                let fitted = |v: &[f64]| -> Result<Vec<f64>, PredictError> {
                    match registration {
                        Some(r) => model.residuals_with_registration(r, &self.stars, v),
                        None => model.residuals(&self.stars, v),
                    }
                    .ok_or_else(|| PredictError::Degenerate(cm.to_string()))
                };
                let axis = |a: fn(&(f64, f64)) -> f64| -> Result<Vec<f64>, PredictError> {
                    let v: Vec<f64> = match &mean {
                        Some(m) => d.iter().zip(m.iter()).map(|(p, q)| a(p) - a(q)).collect(),
                        None => d.iter().map(a).collect(),
                    };
                    let res = fitted(&v)?;
                    // residual of the fit = v − P v; the error left is d − P v = d − v + res
                    Ok(d.iter()
                        .zip(&v)
                        .zip(res)
                        .map(|((p, vi), ri)| a(p) - vi + ri)
                        .collect())
                };
                let rx = axis(|p| p.0)?;
                let ry = axis(|p| p.1)?;
                let r: Vec<(f64, f64)> = rx.into_iter().zip(ry).collect();
                // the phase scatter is each star's own: no smooth model absorbs it
                let p = match registration {
                    Some(reg) => model.n_params_with_registration(reg),
                    None => model.n_params(),
                };
                Ok((with_scatter(rms2(&r), scatter), 2 * p))
            }
            // the shift correction leaves the telemetry's error and the shape term; the forward model models
            // the shape and leaves what the telemetry's errors move
            Countermeasure::Telemetry(q) => {
                let (r, scatter) = self.before_plate(i, Before::ShiftCorrected(*q))?;
                Ok((with_scatter(rms2(&r), scatter), 0))
            }
            Countermeasure::TelemetryModel(q) => {
                let (r, _) = self.before_plate(i, Before::ForwardModel(*q))?;
                Ok((rms2(&r), 0))
            }
            _ => {
                let (r, scatter) = self.before_plate(i, Before::Fits)?;
                Ok((with_scatter(rms2(&r), scatter), 0))
            }
        }
    }

    /// The stare's mean, over all the predictor's images, of what each star's plate model is fitted to
    /// ([`Self::before_plate`]), px: the stack's field.
    fn mean_before_plate(&self, before: Before) -> Result<Vec<(f64, f64)>, PredictError> {
        let n = self.images.len().max(1) as f64;
        let mut m = vec![(0.0, 0.0); self.stars.len()];
        for i in 0..self.images.len() {
            for (a, d) in m.iter_mut().zip(self.before_plate(i, before)?.0.iter()) {
                a.0 += d.0 / n;
                a.1 += d.1 / n;
            }
        }
        Ok(m)
    }

    /// The displacement part σ_disp (mas, per axis) of image `i`'s prediction under a countermeasure: what the
    /// ACE leaves after it, without the noise floor.
    pub fn displacement_mas(&self, i: usize, cm: &Countermeasure) -> Result<f64, PredictError> {
        if self.images.get(i).is_none() {
            return Err(PredictError::NoImages);
        }
        let (disp_px, _) = self.residual_displacement(i, cm)?;
        Ok(disp_px * self.cfg.instrument.plate_scale_mas())
    }

    /// Predicted per-image accuracy (mas) of image `i` under a countermeasure.
    pub fn predict_image(&self, i: usize, cm: &Countermeasure) -> Result<f64, PredictError> {
        let Some(im) = self.images.get(i) else {
            return Err(PredictError::NoImages);
        };
        let noise = self.noise_floor_mas(im.sigma_x_mas, im.sigma_y_mas);
        if *cm == Countermeasure::ExactEpsf {
            return Ok(noise);
        }
        let (disp_px, p) = self.residual_displacement(i, cm)?;
        let n = self.stars.len().max(1) as f64;
        // a plate model absorbs p of the n stars' noise, and projects its reference catalogue's error E onto
        // the stars through its p/2 − 1 non-constant parameters per axis (the constant one leaves the std)
        let absorbed = (p as f64 / n).min(0.9);
        let reference_error_mas = match cm {
            Countermeasure::Plate {
                reference: Reference::Catalogue { error_mas },
                ..
            } => *error_mas,
            _ => 0.0,
        };
        let reference2 = if p > 0 {
            reference_error_mas.powi(2) * ((p as f64 / 2.0 - 1.0).max(0.0) / n)
        } else {
            0.0
        };
        let noise2 = noise * noise * (1.0 - absorbed) + reference2;
        Ok((noise2 + (disp_px * self.cfg.instrument.plate_scale_mas()).powi(2)).sqrt())
    }

    /// Predicted dataset accuracy (mean over its images) under a countermeasure.
    pub fn predict(&self, cm: &Countermeasure) -> Result<f64, PredictError> {
        let mut v = Vec::with_capacity(self.images.len());
        for i in 0..self.images.len() {
            let p = self.predict_image(i, cm)?;
            if p.is_finite() {
                v.push(p);
            }
        }
        if v.is_empty() {
            return Err(PredictError::NoImages);
        }
        Ok(stats::mean(&v))
    }
}
