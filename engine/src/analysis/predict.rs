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
//!   star through the fit's response to the jitter of its window ([`crate::analysis::response`]). After `plate-*`, the
//!   residual of the same least-squares model fitted to those displacements; after `telemetry`, the
//!   displacement minus the telemetry's own prediction (its noise, rate and latency included). The Y-zoned
//!   ePSFs cannot remove a displacement, so they predict what `none` does.
//!
//! Neglected (documented): the change of PSF *shape* along Y and the ePSF builder's own inefficiency.
//! Cost: the bound is cached per 5-mas blur step (≈ 30 ms each); each realistic image costs one fit-response
//! table (≈ 30 ms).

use crate::analysis::countermeasures::Telemetry;
use crate::analysis::response::{FitNoise, FitResponse};
use crate::config::AceCase;
use crate::integrate::kernel::{IntraPixelMap, PixelKernel, subpixel_sum};
use crate::integrate::track::Track;
use crate::jitter::AceSeries;
use crate::numerics::{linalg, stats};
use crate::optics::psf::PsfTable;
use crate::readout::ReadoutTiming;
use crate::simulate::{SimError, Simulator};
use crate::studies::experiment::Plan;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// One exposure's inputs.
struct ImageInputs {
    track: Option<Track>,
    sigma_x_mas: f64,
    sigma_y_mas: f64,
    start_s: f64,
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
    disp_cache: Mutex<HashMap<usize, Arc<Vec<(f64, f64)>>>>,
}

fn rms2(v: &[(f64, f64)]) -> f64 {
    let x: Vec<f64> = v.iter().map(|p| p.0).collect();
    let y: Vec<f64> = v.iter().map(|p| p.1).collect();
    ((stats::std_dev(&x).powi(2) + stats::std_dev(&y).powi(2)) / 2.0).sqrt()
}

/// Design row of a plate model by name (`None` for other countermeasures).
pub fn plate_basis(name: &str) -> Option<Box<dyn Fn(f64, f64) -> Vec<f64> + Send + Sync>> {
    match name {
        "plate-affine" => Some(Box::new(|x, y| {
            vec![1.0, x / 1000.0 - 1.0, y / 1000.0 - 1.0]
        })),
        s if s.starts_with("plate-poly:") => {
            let n: usize = s["plate-poly:".len()..].parse().ok()?;
            Some(Box::new(move |x, y| {
                let yn = y / 1000.0 - 1.0;
                let mut v = vec![1.0, x / 1000.0 - 1.0];
                v.extend((1..=n).map(|k| yn.powi(k as i32)));
                v
            }))
        }
        _ => None,
    }
}

impl Predictor {
    pub fn new(sim: &Simulator) -> Result<Self, SimError> {
        let cfg = sim.cfg.clone();
        let psf = sim
            .stars
            .first()
            .map(|s| sim.psf_for(s))
            .unwrap_or_else(|| sim.bank().get(cfg.scene.j_minus_h, 0));
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
        Ok(Self {
            map: IntraPixelMap::from_config(&cfg.detector, cfg.fidelity.subpixels)?,
            kernel: sim.optical_kernel()?,
            noise: sim.fit_noise(),
            timing: sim.timing,
            series: sim.series_arc(),
            stars: sim.stars.iter().map(|s| (s.x_px, s.y_px)).collect(),
            psf,
            cfg,
            images,
            bound_cache: Mutex::new(HashMap::new()),
            disp_cache: Mutex::new(HashMap::new()),
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
        let flat = d.inter_pixel_flat_sigma;
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
                        let w = 1.0 / (mu + self.noise.floor_e2 + (flat * f * psi).powi(2));
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

    /// The fit displacement (px) the ACE predicts for every star in image `i` (zeros for static ACE).
    pub fn displacements(&self, i: usize) -> Arc<Vec<(f64, f64)>> {
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
                FitResponse::build(&self.kernel, track, &nominal, &self.noise).displacements(
                    track,
                    &self.timing,
                    &self.stars,
                )
            }
            None => vec![(0.0, 0.0); self.stars.len()],
        };
        let v = Arc::new(v);
        self.disp_cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(i, v.clone());
        v
    }

    /// Per-axis rms (px) of what a countermeasure leaves of image `i`'s displacements, and the parameters it
    /// absorbs.
    fn residual_displacement(&self, i: usize, name: &str, plan: &Plan) -> (f64, usize) {
        let d = self.displacements(i);
        if let Some(b) = plate_basis(name) {
            let p = b(0.0, 0.0).len();
            let design: Vec<f64> = self.stars.iter().flat_map(|&(x, y)| b(x, y)).collect();
            let w = vec![1.0; d.len()];
            let fit = |v: Vec<f64>| -> Vec<f64> {
                match linalg::weighted_lstsq(&design, &v, &w, p) {
                    Some((c, _)) => v
                        .iter()
                        .enumerate()
                        .map(|(k, y)| {
                            y - design[k * p..(k + 1) * p]
                                .iter()
                                .zip(&c)
                                .map(|(a, b)| a * b)
                                .sum::<f64>()
                        })
                        .collect(),
                    None => v,
                }
            };
            let rx = fit(d.iter().map(|p| p.0).collect());
            let ry = fit(d.iter().map(|p| p.1).collect());
            let r: Vec<(f64, f64)> = rx.into_iter().zip(ry).collect();
            return (rms2(&r), 2 * p);
        }
        if name == "telemetry"
            && let (Some(series), Some(im)) = (&self.series, self.images.get(i))
        {
            let t = &plan.telemetry;
            if let Ok(tel) = Telemetry::from_series(
                series,
                self.timing,
                im.start_s,
                self.cfg.instrument.plate_scale_mas(),
                t.noise_mas,
                t.rate_hz,
                t.latency_s,
                self.cfg.seed,
                &self.kernel,
                &self.noise,
            ) {
                let pred = tel.predicted_px(&self.stars);
                let r: Vec<(f64, f64)> = d
                    .iter()
                    .zip(pred)
                    .map(|(a, b)| (a.0 - b.0, a.1 - b.1))
                    .collect();
                return (rms2(&r), 0);
            }
        }
        (rms2(&d), 0)
    }

    /// Predicted per-image accuracy (mas) of image `i` under a countermeasure.
    pub fn predict_image(&self, i: usize, name: &str, plan: &Plan) -> f64 {
        let Some(im) = self.images.get(i) else {
            return f64::NAN;
        };
        let noise = self.noise_floor_mas(im.sigma_x_mas, im.sigma_y_mas);
        if name == "exact-epsf" {
            return noise;
        }
        let (disp_px, p) = self.residual_displacement(i, name, plan);
        let n = self.stars.len().max(1) as f64;
        // a plate model absorbs p of the n stars' noise, and projects its reference catalogue's error E onto
        // the stars through its p/2 − 1 non-constant parameters per axis (the constant one leaves the std)
        let absorbed = (p as f64 / n).min(0.9);
        let reference2 = if p > 0 {
            plan.reference_error_mas.powi(2) * ((p as f64 / 2.0 - 1.0).max(0.0) / n)
        } else {
            0.0
        };
        let noise2 = noise * noise * (1.0 - absorbed) + reference2;
        (noise2 + (disp_px * self.cfg.instrument.plate_scale_mas()).powi(2)).sqrt()
    }

    /// Predicted dataset accuracy (mean over its images) under a countermeasure.
    pub fn predict(&self, name: &str, plan: &Plan) -> Option<f64> {
        let v: Vec<f64> = (0..self.images.len())
            .map(|i| self.predict_image(i, name, plan))
            .filter(|v| v.is_finite())
            .collect();
        (!v.is_empty()).then(|| stats::mean(&v))
    }
}

/// Names of the countermeasures the predictor understands (the same as the analysis).
pub fn known(name: &str) -> bool {
    name == "exact-epsf"
        || name == "telemetry"
        || crate::analysis::countermeasures::Countermeasure::parse(name, 4).is_ok()
}
