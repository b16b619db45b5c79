//! The instant accuracy predictor: what an exposure's single-image accuracy will be, without simulating it.
//!
//! `σ_pred² = σ_noise² + σ_disp²` per axis, averaged (as σ) over the exposures of a dataset:
//! * **σ_noise** — the Cramér–Rao bound of a star (x, y, flux; sky known) under the exact ePSF: the PSF blurred
//!   by a Gaussian with this exposure's ACE σ per axis (the Gaussian ACE σ, or the series' σ over the
//!   exposure), integrated over the pixel with the subpixel/intra-pixel model, averaged over pixel phases
//!   (as σ²), with the pixel variance `μ + RN² + g²/12 + (σ_flat·signal)²` — the inter-pixel flat is unknown
//!   to the fit and acts as noise. Plate models absorb p of the n stars' degrees of freedom: × (1 − p/n).
//! * **σ_disp** — the rms over stars (mean removed) of the displacement the ACE series predicts for each star:
//!   the mean jitter over its central pixel's window. After `plate-*`, the residual of the same least-squares
//!   model fitted to the displacements; after `telemetry`, the displacement minus the telemetry's prediction.
//!   The Y-zoned ePSFs cannot remove a displacement, so they predict what `none` does.
//!
//! Neglected (documented): the change of PSF *shape* along Y and the ePSF builder's own inefficiency.

use crate::config::{AceCase, Config};
use crate::countermeasures::Countermeasure;
use crate::experiment::Plan;
use crate::integrate::kernel::{IntraPixelMap, subpixel_sum};
use crate::integrate::track::Track;
use crate::numerics::{linalg, stats};
use crate::optics::psf::PsfTable;
use crate::photometry;
use crate::simulate::{SimError, Simulator};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Precomputed inputs of the predictor for one dataset configuration.
pub struct Predictor {
    cfg: Config,
    psf: Arc<PsfTable>,
    map: IntraPixelMap,
    stars: Vec<(f64, f64)>,
    rate_e_per_s: f64,
    /// Per image: the track (realistic ACE) and the ACE σ per axis (mas).
    images: Vec<(Option<Track>, f64, f64, f64)>,
    cache: Mutex<HashMap<(i64, i64), f64>>,
}

impl Predictor {
    pub fn new(sim: &Simulator) -> Result<Self, SimError> {
        let cfg = sim.cfg.clone();
        let psf = sim
            .stars
            .first()
            .map(|s| sim.psf_for(s))
            .unwrap_or_else(|| sim.bank().get(cfg.scene.j_minus_h, 0));
        let rates: Vec<f64> = sim
            .stars
            .iter()
            .map(|s| photometry::electrons_per_s(s.mag_hw, cfg.photometry.zero_point_e_per_s))
            .collect();
        let images = (0..cfg.fidelity.images)
            .map(|i| {
                let a = sim.ace_stats(i);
                let (sx, sy) = match cfg.ace.case {
                    AceCase::Gaussian => (cfg.ace.sigma_mas, cfg.ace.sigma_mas),
                    AceCase::Realistic => (a.sigma_x_mas, a.sigma_y_mas),
                    AceCase::None => (0.0, 0.0),
                };
                (sim.track(i), sx, sy, sim.exposure_start_s(i))
            })
            .collect();
        Ok(Self {
            map: IntraPixelMap::from_config(&cfg.detector, cfg.fidelity.subpixels)?,
            stars: sim.stars.iter().map(|s| (s.x_px, s.y_px)).collect(),
            rate_e_per_s: stats::median(&rates),
            psf,
            cfg,
            images,
            cache: Mutex::new(HashMap::new()),
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
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return *v;
        }
        let (sx, sy) = (key.0 as f64 * 5.0 / scale, key.1 as f64 * 5.0 / scale);
        let psf = self.psf.gaussian_blurred_xy(sx, sy);
        let d = &self.cfg.detector;
        let f = self.rate_e_per_s * d.exposure_s;
        let sky = d.dark_e_per_s * d.exposure_s;
        let floor = d.read_noise_e.powi(2) + d.gain_e_per_adu.powi(2) / 12.0;
        let flat = d.inter_pixel_flat_sigma;
        let r = self.cfg.analysis.fit_radius_px;
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
                        let mu = f * psi + sky;
                        let w = 1.0 / (mu + floor + (flat * f * psi).powi(2));
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
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, v);
        v
    }

    /// The displacement (px) the ACE predicts for every star in image `i` (zeros for static ACE).
    pub fn displacements(&self, i: usize) -> Vec<(f64, f64)> {
        let Some(Some(track)) = self.images.get(i).map(|im| im.0.as_ref()) else {
            return vec![(0.0, 0.0); self.stars.len()];
        };
        // prefix sums make every window mean O(1)
        let mut cx = vec![0.0; track.len() + 1];
        let mut cy = vec![0.0; track.len() + 1];
        for j in 0..track.len() {
            cx[j + 1] = cx[j] + track.dx_px[j];
            cy[j + 1] = cy[j] + track.dy_px[j];
        }
        let timing = crate::readout::ReadoutTiming::new(&self.cfg);
        let n = self.cfg.instrument.detector_px as f64;
        self.stars
            .iter()
            .map(|&(x, y)| {
                let (a, b) = timing.window_s(
                    x.round().clamp(0.0, n - 1.0) as usize,
                    y.round().clamp(0.0, n - 1.0) as usize,
                );
                let w = track.window(a, b);
                // interior samples by prefix sums, the two fractional ends explicitly
                let (mut sx, mut sy) = (0.0, 0.0);
                if w.last > w.first + 1 {
                    sx += cx[w.last] - cx[w.first + 1];
                    sy += cy[w.last] - cy[w.first + 1];
                }
                sx += w.w_first * track.dx_px[w.first];
                sy += w.w_first * track.dy_px[w.first];
                if w.last != w.first {
                    sx += w.w_last * track.dx_px[w.last];
                    sy += w.w_last * track.dy_px[w.last];
                }
                let t = w.total().max(1e-300);
                (sx / t, sy / t)
            })
            .collect()
    }

    /// Per-axis rms of what a countermeasure leaves of the displacements of image `i`, and the parameters it
    /// absorbs.
    fn residual_displacement(&self, i: usize, name: &str) -> (f64, usize) {
        let d = self.displacements(i);
        let rms = |v: &[(f64, f64)]| -> f64 {
            let x: Vec<f64> = v.iter().map(|p| p.0).collect();
            let y: Vec<f64> = v.iter().map(|p| p.1).collect();
            ((stats::std_dev(&x).powi(2) + stats::std_dev(&y).powi(2)) / 2.0).sqrt()
        };
        let basis: Option<Box<dyn Fn(f64, f64) -> Vec<f64>>> = match name {
            "plate-affine" => Some(Box::new(|x, y| {
                vec![1.0, x / 1000.0 - 1.0, y / 1000.0 - 1.0]
            })),
            s if s.starts_with("plate-poly:") => {
                let n: usize = s["plate-poly:".len()..].parse().unwrap_or(1);
                Some(Box::new(move |x, y| {
                    let yn = y / 1000.0 - 1.0;
                    let mut v = vec![1.0, x / 1000.0 - 1.0];
                    v.extend((1..=n).map(|k| yn.powi(k as i32)));
                    v
                }))
            }
            _ => None,
        };
        if let Some(b) = basis {
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
            return (rms(&r), 2 * p);
        }
        (rms(&d), 0)
    }

    /// Predicted per-image accuracy (mas) of image `i` under a countermeasure.
    pub fn predict_image(&self, i: usize, name: &str, plan: &Plan) -> f64 {
        let Some(&(_, sx, sy, _)) = self.images.get(i) else {
            return f64::NAN;
        };
        let noise = self.noise_floor_mas(sx, sy);
        let scale = self.cfg.instrument.plate_scale_mas();
        if name == "exact-epsf" {
            return noise;
        }
        let (disp_px, p) = if name == "telemetry" {
            self.telemetry_residual(i, plan)
        } else {
            self.residual_displacement(i, name)
        };
        let n = self.stars.len().max(1) as f64;
        let noise2 = noise * noise * (1.0 - (p as f64 / n).min(0.9));
        (noise2 + (disp_px * scale).powi(2)).sqrt()
    }

    /// Telemetry residual: the displacement minus the telemetry's own window mean, from the track resampled at
    /// the telemetry rate (linear), delayed, with noise entering as σ_noise/√(samples per window).
    fn telemetry_residual(&self, i: usize, plan: &Plan) -> (f64, usize) {
        let Some(Some(track)) = self.images.get(i).map(|im| im.0.as_ref()) else {
            return (0.0, 0);
        };
        let t = &plan.telemetry;
        let d = self.displacements(i);
        let timing = crate::readout::ReadoutTiming::new(&self.cfg);
        let dt_tel = 1.0 / t.rate_hz.max(1e-9);
        let lag = t.latency_s;
        let at = |tt: f64, v: &[f64]| -> f64 {
            let u = ((tt - track.t0_s) / track.dt_s).clamp(0.0, (v.len() - 1) as f64);
            v[u.round() as usize]
        };
        let tel_mean = |a: f64, b: f64| -> (f64, f64) {
            // piecewise-linear telemetry between samples at k·dt_tel, delayed by `lag`
            let m = 64;
            let (mut sx, mut sy) = (0.0, 0.0);
            for k in 0..m {
                let tt = a + (k as f64 + 0.5) / m as f64 * (b - a);
                let u = tt / dt_tel;
                let (k0, f) = (u.floor(), u - u.floor());
                let (t0, t1) = (k0 * dt_tel - lag, (k0 + 1.0) * dt_tel - lag);
                sx += (1.0 - f) * at(t0, &track.dx_px) + f * at(t1, &track.dx_px);
                sy += (1.0 - f) * at(t0, &track.dy_px) + f * at(t1, &track.dy_px);
            }
            (sx / m as f64, sy / m as f64)
        };
        let n = self.cfg.instrument.detector_px as f64;
        let r: Vec<(f64, f64)> = self
            .stars
            .iter()
            .zip(&d)
            .map(|(&(x, y), &(dx, dy))| {
                let (a, b) = timing.window_s(
                    x.round().clamp(0.0, n - 1.0) as usize,
                    y.round().clamp(0.0, n - 1.0) as usize,
                );
                let (px, py) = tel_mean(a, b);
                (dx - px, dy - py)
            })
            .collect();
        let xs: Vec<f64> = r.iter().map(|p| p.0).collect();
        let ys: Vec<f64> = r.iter().map(|p| p.1).collect();
        let sys = ((stats::std_dev(&xs).powi(2) + stats::std_dev(&ys).powi(2)) / 2.0).sqrt();
        // white telemetry noise averaged over a window of T·rate samples
        let scale = self.cfg.instrument.plate_scale_mas();
        let noise_px =
            t.noise_mas / scale / (self.cfg.detector.exposure_s * t.rate_hz).max(1.0).sqrt();
        ((sys * sys + noise_px * noise_px).sqrt(), 0)
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
    name == "exact-epsf" || name == "telemetry" || Countermeasure::parse(name, 4).is_ok()
}
