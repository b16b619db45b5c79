//! Countermeasures to the rolling-readout error, applied after the global ePSF fit of an image.
//!
//! * `yzones` / `yzones-shared` — position-dependent ePSF: K representative ePSFs for zones along Y,
//!   interpolated linearly in Y between zone centres (the paper's proposal). `yzones`: each zone's ePSF is
//!   built and re-centred on its own (centroid convention per zone). `yzones-shared`: each zone's ePSF is built
//!   with the stars held at their global-ePSF positions and not re-centred, so it stays in the global ePSF's
//!   centring frame. Neither can absorb a displacement common to the stars of a zone — an image translated
//!   by δ is fitted at its translated position by any ePSF with a fixed centring convention. The shared frame
//!   changes little; per-zone re-centring moves each zone's positions to its own (jitter-skewed) photocentre
//!   convention, so the zones disagree by what their stars' jitter did and the scatter grows. Displacements
//!   need a reference (plate model) or telemetry.
//! * `plate-affine`, `plate-poly:N` — per exposure, fit a smooth transformation of the fitted positions onto
//!   the reference positions (the truth, optionally with its own error) by least squares over all stars,
//!   as an astrometric pipeline does against a reference catalogue: affine (6 parameters) or
//!   `Δx = a₀ + a₁x + Σₖ₌₁..N bₖ yᵏ` and the same for Δy (2(N + 2) parameters). The parameters absorbed are
//!   reported (`dof_absorbed`): with n stars the residual variance of pure noise shrinks by (1 − p/n).
//! * `telemetry` — subtract, from each star, the displacement the attitude telemetry predicts for its fit:
//!   the ACE series sampled at `rate_hz`, delayed by `latency_s`, with Gaussian noise `noise_mas` per sample,
//!   linearly interpolated, and turned into each star's fitted shift through the fit's response to the jitter
//!   of its pixels' window ([`crate::analysis::response`]; the optical PSF is taken as known from calibration).

use crate::analysis::astrometry::{AnalysisImage, StarResult};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart};
use crate::analysis::epsf::fit::{PixelData, fit_star, flags};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::integrate::kernel::PixelKernel;
use crate::integrate::track::Track;
use crate::jitter::AceSeries;
use crate::numerics::linalg;
use crate::readout::ReadoutTiming;
use crate::rng::{self, Stream};
use crate::simulate::TruthRow;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::sync::Arc;

#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum CountermeasureError {
    #[error(
        "unknown countermeasure `{0}` (none, yzones, yzones-shared, plate-affine, plate-poly:N, telemetry)"
    )]
    Unknown(String),
    #[error("{what} needs at least {need} matched stars, found {have}")]
    TooFewStars {
        what: String,
        need: usize,
        have: usize,
    },
    #[error("{what}: the stars do not constrain the model (all in one row or column?)")]
    Degenerate { what: String },
    #[error("{0} needs the truth catalogue (reference positions)")]
    NeedsTruth(String),
    #[error("telemetry: {0}")]
    Telemetry(String),
}

/// Degraded attitude telemetry of one exposure, and the fit displacements it predicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Telemetry {
    /// Telemetry resampled (linearly) onto a regular grid, px, times relative to the exposure start.
    pub track: Track,
    pub timing: ReadoutTiming,
    /// The ePSF fit's response to jitter under this telemetry ([`crate::analysis::response`]).
    pub response: FitResponse,
}

impl Telemetry {
    /// Sample `series` at `rate_hz` with `noise_mas` Gaussian noise per sample (seeded), reporting at time t
    /// the attitude of time t − `latency_s`, over one exposure; interpolate linearly between samples; and
    /// build the fit response from the PSF's pixel kernel.
    #[allow(clippy::too_many_arguments)]
    pub fn from_series(
        series: &AceSeries,
        timing: ReadoutTiming,
        exposure_start_s: f64,
        plate_scale_mas: f64,
        noise_mas: f64,
        rate_hz: f64,
        latency_s: f64,
        seed: u64,
        kernel: &PixelKernel,
        noise: &FitNoise,
    ) -> Result<Self, CountermeasureError> {
        if !(noise_mas >= 0.0) || !noise_mas.is_finite() {
            return Err(CountermeasureError::Telemetry(format!(
                "noise {noise_mas} mas must be a finite number ≥ 0"
            )));
        }
        if !(rate_hz > 0.0) || !rate_hz.is_finite() {
            return Err(CountermeasureError::Telemetry(format!(
                "rate {rate_hz} Hz must be > 0"
            )));
        }
        if !latency_s.is_finite() {
            return Err(CountermeasureError::Telemetry(format!(
                "latency {latency_s} s must be finite"
            )));
        }
        if series.is_empty() {
            return Err(CountermeasureError::Telemetry(
                "the ACE series is empty (zero-length telemetry)".into(),
            ));
        }
        let dt = 1.0 / rate_hz;
        let span = timing.span_s();
        let (t0, t1) = (
            exposure_start_s - 2.0 * dt,
            exposure_start_s + span + 2.0 * dt,
        );
        let n = ((t1 - t0) / dt).ceil() as usize + 1;
        if n > 50_000_000 {
            return Err(CountermeasureError::Telemetry(format!(
                "{n} samples: rate too high"
            )));
        }
        let normal = Normal::new(0.0, noise_mas.max(0.0))
            .map_err(|e| CountermeasureError::Telemetry(e.to_string()))?;
        let mut r = rng::stream(seed, Stream::Telemetry, (exposure_start_s * 1e3) as u64);
        let at = |t: f64, v: &[f64]| -> f64 {
            let i = (t / series.dt_s).round().clamp(0.0, (v.len() - 1) as f64) as usize;
            v[i]
        };
        let (mut xs, mut ys) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for k in 0..n {
            let t = t0 + k as f64 * dt;
            xs.push(at(t - latency_s, &series.x_mas) + normal.sample(&mut r));
            ys.push(at(t - latency_s, &series.y_mas) + normal.sample(&mut r));
        }
        // resample on the integration grid (at most 1 ms, and no coarser than the series)
        let step = series.dt_s.max(dt.min(1e-3) / 4.0).min(1e-3);
        let m = (span / step).ceil() as usize + 2;
        let lin = |t_abs: f64, v: &[f64]| -> f64 {
            let u = ((t_abs - t0) / dt).clamp(0.0, (n - 1) as f64);
            let i = (u.floor() as usize).min(n.saturating_sub(2));
            let f = u - i as f64;
            if n < 2 {
                v[0]
            } else {
                v[i] * (1.0 - f) + v[i + 1] * f
            }
        };
        let track = Track::new(
            step,
            0.0,
            (0..m)
                .map(|j| lin(exposure_start_s + j as f64 * step, &xs) / plate_scale_mas)
                .collect(),
            (0..m)
                .map(|j| lin(exposure_start_s + j as f64 * step, &ys) / plate_scale_mas)
                .collect(),
        );
        let nominal = track.window(timing.t_overhead_s, timing.t_overhead_s + timing.exposure_s);
        let response = FitResponse::build(kernel, &track, &nominal, noise);
        Ok(Self {
            track,
            timing,
            response,
        })
    }

    /// The fit displacement (px) telemetry predicts for stars at these positions.
    pub fn predicted_px(&self, positions: &[(f64, f64)]) -> Vec<(f64, f64)> {
        self.response
            .displacements(&self.track, &self.timing, positions)
    }
}

/// A countermeasure.
#[derive(Debug, Clone, PartialEq)]
pub enum Countermeasure {
    None,
    YZones {
        zones: usize,
        shared: bool,
    },
    PlateAffine {
        reference_error_mas: f64,
        seed: u64,
    },
    PlatePoly {
        order: usize,
        reference_error_mas: f64,
        seed: u64,
    },
    Telemetry(Arc<Telemetry>),
}

impl Countermeasure {
    /// Parse a name (`telemetry` needs its data attached by the caller: see [`Countermeasure::Telemetry`]).
    pub fn parse(name: &str, zones: usize) -> Result<Self, CountermeasureError> {
        Ok(match name {
            "none" => Countermeasure::None,
            "yzones" => Countermeasure::YZones {
                zones,
                shared: false,
            },
            "yzones-shared" => Countermeasure::YZones {
                zones,
                shared: true,
            },
            "plate-affine" => Countermeasure::PlateAffine {
                reference_error_mas: 0.0,
                seed: 0,
            },
            s if s.starts_with("plate-poly:") => {
                let order: usize = s["plate-poly:".len()..]
                    .parse()
                    .map_err(|_| CountermeasureError::Unknown(s.into()))?;
                if !(1..=8).contains(&order) {
                    return Err(CountermeasureError::Unknown(format!("{s} (order 1..=8)")));
                }
                Countermeasure::PlatePoly {
                    order,
                    reference_error_mas: 0.0,
                    seed: 0,
                }
            }
            other => return Err(CountermeasureError::Unknown(other.to_string())),
        })
    }

    pub fn name(&self) -> String {
        match self {
            Countermeasure::None => "none".into(),
            Countermeasure::YZones { shared: false, .. } => "yzones".into(),
            Countermeasure::YZones { shared: true, .. } => "yzones-shared".into(),
            Countermeasure::PlateAffine { .. } => "plate-affine".into(),
            Countermeasure::PlatePoly { order, .. } => format!("plate-poly:{order}"),
            Countermeasure::Telemetry(_) => "telemetry".into(),
        }
    }

    /// Set the reference-catalogue error of a plate model.
    pub fn with_reference_error(self, mas: f64, seed: u64) -> Self {
        match self {
            Countermeasure::PlateAffine { .. } => Countermeasure::PlateAffine {
                reference_error_mas: mas,
                seed,
            },
            Countermeasure::PlatePoly { order, .. } => Countermeasure::PlatePoly {
                order,
                reference_error_mas: mas,
                seed,
            },
            other => other,
        }
    }
}

/// A Y-zoned ePSF: zone centres (px) and their tables, linearly interpolated in Y.
#[derive(Debug, Clone)]
pub struct ZonedEpsf {
    pub centres_y: Vec<f64>,
    pub zones: Vec<Epsf>,
}

impl ZonedEpsf {
    /// The ePSF at detector row y (clamped beyond the outer zone centres).
    pub fn at(&self, y: f64) -> Epsf {
        let c = &self.centres_y;
        if c.len() == 1 || y <= c[0] {
            return self.zones[0].clone();
        }
        if y >= c[c.len() - 1] {
            return self.zones[c.len() - 1].clone();
        }
        let k = c
            .windows(2)
            .position(|w| y >= w[0] && y < w[1])
            .unwrap_or(0);
        Epsf::lerp(
            &self.zones[k],
            &self.zones[k + 1],
            (y - c[k]) / (c[k + 1] - c[k]),
        )
    }
}

/// Build the zoned ePSF from the global one.
pub fn build_zoned(
    pd: &PixelData<'_>,
    ny: usize,
    starts: &[StarStart],
    usable: &[bool],
    bopt: &BuildOptions,
    global: &Epsf,
    global_pos: &[(f64, f64)],
    zones: usize,
    shared: bool,
) -> ZonedEpsf {
    let h = ny as f64 / zones as f64;
    let mut centres = Vec::new();
    let mut tables = Vec::new();
    for z in 0..zones {
        let (lo, hi) = (z as f64 * h, (z + 1) as f64 * h);
        let in_zone: Vec<bool> = starts
            .iter()
            .zip(usable)
            .map(|(s, u)| *u && s.y >= lo && s.y < hi)
            .collect();
        let ys: Vec<f64> = starts
            .iter()
            .zip(&in_zone)
            .filter(|(_, u)| **u)
            .map(|(s, _)| s.y)
            .collect();
        centres.push(if ys.is_empty() {
            0.5 * (lo + hi)
        } else {
            ys.iter().sum::<f64>() / ys.len() as f64
        });
        if ys.len() < 3 {
            tables.push(global.clone());
            continue;
        }
        let mut o = *bopt;
        o.recentre = !shared;
        let b = build::build(
            pd,
            starts,
            &in_zone,
            &o,
            Some(global),
            shared.then_some(global_pos),
        );
        tables.push(b.epsf);
    }
    ZonedEpsf {
        centres_y: centres,
        zones: tables,
    }
}

/// Reference positions: the truth, plus its own error when asked (seeded).
fn reference(truth: &[TruthRow], k: usize, err_px: f64, seed: u64) -> (f64, f64) {
    if err_px > 0.0 {
        let mut r = rng::stream(seed, Stream::ReferenceCatalogue, truth[k].id as u64);
        let n = Normal::new(0.0, err_px)
            .map(|n| (n.sample(&mut r), n.sample(&mut r)))
            .unwrap_or((0.0, 0.0));
        (truth[k].x_px + n.0, truth[k].y_px + n.1)
    } else {
        (truth[k].x_px, truth[k].y_px)
    }
}

/// Fit Δ = design · coefficients per axis over the matched, usable stars, subtract, and return the number of
/// parameters absorbed. `basis(x, y)` gives one design row (coordinates normalised to ~[−1, 1]).
fn plate_fit(
    stars: &mut [StarResult],
    truth: &[TruthRow],
    basis: &dyn Fn(f64, f64) -> Vec<f64>,
    what: &str,
    err_px: f64,
    seed: u64,
) -> Result<usize, CountermeasureError> {
    let idx: Vec<usize> = (0..stars.len())
        .filter(|&k| stars[k].truth.is_some() && stars[k].flags & flags::REJECT == 0)
        .collect();
    let p = basis(0.0, 0.0).len();
    if idx.len() <= p {
        return Err(CountermeasureError::TooFewStars {
            what: what.into(),
            need: p + 1,
            have: idx.len(),
        });
    }
    let mut design = Vec::with_capacity(idx.len() * p);
    let (mut rx, mut ry) = (Vec::new(), Vec::new());
    for &k in &idx {
        let s = &stars[k];
        let (xr, yr) = reference(truth, s.truth.unwrap_or(0), err_px, seed);
        design.extend(basis(s.x, s.y));
        // the correction maps fitted → reference: Δ = reference − fitted
        rx.push(xr - s.x);
        ry.push(yr - s.y);
    }
    let w = vec![1.0; idx.len()];
    let (cx, _) = linalg::weighted_lstsq(&design, &rx, &w, p)
        .ok_or_else(|| CountermeasureError::Degenerate { what: what.into() })?;
    let (cy, _) = linalg::weighted_lstsq(&design, &ry, &w, p)
        .ok_or_else(|| CountermeasureError::Degenerate { what: what.into() })?;
    for s in stars.iter_mut() {
        let b = basis(s.x, s.y);
        let (ddx, ddy) = (
            b.iter().zip(&cx).map(|(a, c)| a * c).sum::<f64>(),
            b.iter().zip(&cy).map(|(a, c)| a * c).sum::<f64>(),
        );
        s.x += ddx;
        s.y += ddy;
        s.dx_px += ddx;
        s.dy_px += ddy;
    }
    Ok(2 * p)
}

/// Apply a countermeasure to the star results of an image; returns the parameters absorbed per exposure.
#[allow(clippy::too_many_arguments)]
pub fn apply(
    cm: &Countermeasure,
    img: &AnalysisImage,
    pd: &PixelData<'_>,
    starts: &[StarStart],
    usable: &[bool],
    bopt: &BuildOptions,
    global: &Epsf,
    truth: Option<&[TruthRow]>,
    stars: &mut [StarResult],
) -> Result<usize, CountermeasureError> {
    let scale = 1000.0; // normalise detector coordinates for conditioning
    match cm {
        Countermeasure::None => Ok(0),
        Countermeasure::YZones { zones, shared } => {
            let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
            let z = build_zoned(
                pd, img.ny, starts, usable, bopt, global, &pos, *zones, *shared,
            );
            let refits: Vec<_> = stars
                .par_iter()
                .zip(starts)
                .map(|(s, st)| {
                    fit_star(
                        pd,
                        &z.at(s.y),
                        s.x,
                        s.y,
                        s.flux_e.max(1.0),
                        st.sky,
                        &bopt.fit,
                    )
                })
                .collect();
            for (s, f) in stars.iter_mut().zip(refits) {
                let (ddx, ddy) = (f.x - s.x, f.y - s.y);
                s.x = f.x;
                s.y = f.y;
                s.flux_e = f.flux;
                s.crlb_x_px = f.crlb_x;
                s.crlb_y_px = f.crlb_y;
                s.flags = f.flags;
                s.dx_px += ddx;
                s.dy_px += ddy;
            }
            Ok(0)
        }
        Countermeasure::PlateAffine {
            reference_error_mas,
            seed,
        } => {
            let t = truth.ok_or_else(|| CountermeasureError::NeedsTruth(cm.name()))?;
            let b = move |x: f64, y: f64| vec![1.0, x / scale - 1.0, y / scale - 1.0];
            plate_fit(
                stars,
                t,
                &b,
                "plate-affine",
                reference_error_mas / img.plate_scale_mas,
                *seed,
            )
        }
        Countermeasure::PlatePoly {
            order,
            reference_error_mas,
            seed,
        } => {
            let t = truth.ok_or_else(|| CountermeasureError::NeedsTruth(cm.name()))?;
            let n = *order;
            let b = move |x: f64, y: f64| {
                let yn = y / scale - 1.0;
                let mut v = vec![1.0, x / scale - 1.0];
                v.extend((1..=n).map(|k| yn.powi(k as i32)));
                v
            };
            plate_fit(
                stars,
                t,
                &b,
                &cm.name(),
                reference_error_mas / img.plate_scale_mas,
                *seed,
            )
        }
        Countermeasure::Telemetry(tel) => {
            let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
            for (s, (px, py)) in stars.iter_mut().zip(tel.predicted_px(&pos)) {
                s.x -= px;
                s.y -= py;
                s.dx_px -= px;
                s.dy_px -= py;
            }
            Ok(0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn star(x: f64, y: f64, dx: f64, dy: f64, k: usize) -> StarResult {
        StarResult {
            truth: Some(k),
            x: x + dx,
            y: y + dy,
            flux_e: 1e4,
            sky_e: 0.0,
            crlb_x_px: 0.01,
            crlb_y_px: 0.01,
            flags: 0,
            dx_px: dx,
            dy_px: dy,
            predicted_dx_px: 0.0,
            predicted_dy_px: 0.0,
            predicted_fit_dx_px: 0.0,
            predicted_fit_dy_px: 0.0,
        }
    }

    fn truth_at(pos: &[(f64, f64)]) -> Vec<TruthRow> {
        pos.iter()
            .enumerate()
            .map(|(k, &(x, y))| TruthRow {
                id: k,
                x_px: x,
                y_px: y,
                mag_hw: 12.5,
                j_minus_h: 2.0,
                flux_e: 1e4,
                modelled_fraction: 1.0,
                t_start_s: 0.0,
                exptime_s: 12.5,
                jitter_dx_px: 0.0,
                jitter_dy_px: 0.0,
            })
            .collect()
    }

    #[test]
    fn plate_poly_removes_a_displacement_field_of_matching_order() {
        let pos: Vec<(f64, f64)> = (0..100)
            .map(|k| {
                (
                    50.0 + (k % 10) as f64 * 190.0,
                    40.0 + (k / 10) as f64 * 195.0,
                )
            })
            .collect();
        let truth = truth_at(&pos);
        // a cubic displacement along Y, plus a shift and a rotation-like term
        let field = |x: f64, y: f64| {
            let yn = y / 1000.0 - 1.0;
            (
                0.02 + 0.01 * (x / 1000.0 - 1.0) + 0.05 * yn - 0.03 * yn.powi(3),
                -0.01 + 0.04 * yn * yn,
            )
        };
        let mut stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| {
                let (dx, dy) = field(x, y);
                star(x, y, dx, dy, k)
            })
            .collect();
        let b = |x: f64, y: f64| {
            let yn = y / 1000.0 - 1.0;
            vec![1.0, x / 1000.0 - 1.0, yn, yn * yn, yn * yn * yn]
        };
        let dof = plate_fit(&mut stars, &truth, &b, "plate-poly:3", 0.0, 0).expect("fit");
        assert_eq!(dof, 10);
        // the field is a polynomial of the true positions and the model one of the measured positions: the
        // difference is second order in the field (here < 1e-6 px = 5e-4 mas)
        for s in &stars {
            assert!(
                s.dx_px.abs() < 1e-6 && s.dy_px.abs() < 1e-6,
                "{} {}",
                s.dx_px,
                s.dy_px
            );
        }
    }

    #[test]
    fn plate_fit_degenerate_inputs_are_named_errors() {
        let pos: Vec<(f64, f64)> = (0..3).map(|k| (k as f64 * 100.0, 500.0)).collect();
        let truth = truth_at(&pos);
        let mut stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| star(x, y, 0.1, 0.0, k))
            .collect();
        let b = |x: f64, y: f64| vec![1.0, x / 1000.0 - 1.0, y / 1000.0 - 1.0];
        let e = plate_fit(&mut stars, &truth, &b, "plate-affine", 0.0, 0).expect_err("too few");
        assert!(matches!(e, CountermeasureError::TooFewStars { .. }), "{e}");
        // all stars in one row: y has no lever arm
        let pos: Vec<(f64, f64)> = (0..20).map(|k| (k as f64 * 90.0, 500.0)).collect();
        let truth = truth_at(&pos);
        let mut stars: Vec<StarResult> = pos
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| star(x, y, 0.1, 0.0, k))
            .collect();
        let e = plate_fit(&mut stars, &truth, &b, "plate-affine", 0.0, 0).expect_err("one row");
        assert!(matches!(e, CountermeasureError::Degenerate { .. }), "{e}");
        assert!(stars.iter().all(|s| s.dx_px.is_finite()));
    }

    #[test]
    fn telemetry_input_errors_are_named() {
        let cfg = crate::config::Config::default();
        let timing = ReadoutTiming::new(&cfg);
        let psf = crate::integrate::cpu::tests::test_psf(4, 4);
        let k = PixelKernel::build(&psf, &crate::integrate::kernel::IntraPixelMap::uniform(4))
            .expect("kernel");
        let nm = FitNoise {
            flux_e: 7e4,
            sky_e: 300.0,
            floor_e2: 226.0,
            radius_px: 2.5,
        };
        let empty = AceSeries::still(1e-3, 0);
        let e = Telemetry::from_series(&empty, timing, 0.0, 472.0, 1.0, 10.0, 0.0, 1, &k, &nm)
            .expect_err("empty");
        assert!(e.to_string().contains("zero-length"));
        let s = AceSeries::still(1e-3, 20_000);
        assert!(
            Telemetry::from_series(&s, timing, 0.0, 472.0, f64::NAN, 10.0, 0.0, 1, &k, &nm)
                .is_err()
        );
        assert!(Telemetry::from_series(&s, timing, 0.0, 472.0, 1.0, 0.0, 0.0, 1, &k, &nm).is_err());
        assert!(Countermeasure::parse("plate-poly:x", 4).is_err());
        assert_eq!(
            Countermeasure::parse("plate-poly:3", 4).expect("ok").name(),
            "plate-poly:3"
        );
    }
}
