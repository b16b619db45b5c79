//! The `telemetry` countermeasure: the attitude telemetry of an exposure, degraded as the instrument would
//! record it, turned into each star's fitted shift through the fit's response to the jitter of its pixels'
//! window ([`crate::analysis::response`]; the optical PSF is taken as known from calibration).

use super::{CountermeasureError, TelemetryQuality};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::integrate::kernel::PixelKernel;
use crate::integrate::track::Track;
use crate::jitter::AceSeries;
use crate::readout::ReadoutTiming;
use crate::rng::{self, Stream};
use rand_distr::{Distribution, Normal};

/// Degraded attitude telemetry of one exposure, and the fit displacements it predicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Telemetry {
    /// Telemetry resampled (linearly) onto a regular grid, px, times relative to the exposure start.
    pub track: Track,
    pub timing: ReadoutTiming,
    /// The ePSF fit's response to jitter under this telemetry ([`crate::analysis::response`]).
    pub response: FitResponse,
    /// The static profile the response was built from (the design model PSF or the image's ePSF), which the
    /// forward model ([`super::forward`]) sees through the telemetry; `None`: the image's global ePSF.
    pub profile: Option<crate::analysis::epsf::Epsf>,
    /// Nodes per pixel of the forward model's jitter histograms.
    pub model_nodes_per_px: usize,
}

/// When each pixel of an exposure integrated (its readout timing) and how its array is turned on the sky:
/// what a telemetry record is applied with. From the image's headers (READOUT, ROWDIR, NCHAN, CHANWID,
/// PIXTIME, TOVERHD, EXPTIME, ROTANG), or from a simulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureReadout {
    pub timing: ReadoutTiming,
    /// The array's rotation on the sky (deg): the telemetry's attitude is the telescope's.
    pub rotation_deg: f64,
}

/// Attitude telemetry as the spacecraft records it over one exposure: samples at `dt_s` from `t0_s` (seconds
/// in the ACE series' time), the telescope's attitude in mas with the recording's errors and latency — the
/// instrument product (`telemetry_NNN.fits`), not the true series.
#[derive(Debug, Clone, PartialEq)]
pub struct TelemetryRecord {
    pub t0_s: f64,
    pub dt_s: f64,
    pub x_mas: Vec<f64>,
    pub y_mas: Vec<f64>,
    /// The exposure's start (the series' time) the record covers.
    pub exposure_start_s: f64,
}

impl TelemetryRecord {
    /// Record `series` at the quality's `rate_hz` with `noise_mas` Gaussian noise per sample (seeded),
    /// reporting at time t the attitude of time t − `latency_s`, plus the correlated (Gauss–Markov) error,
    /// over one exposure of span `span_s` starting at `exposure_start_s` (two samples of margin each side).
    pub fn record(
        series: &AceSeries,
        span_s: f64,
        exposure_start_s: f64,
        quality: &TelemetryQuality,
        seed: u64,
    ) -> Result<Self, CountermeasureError> {
        quality.validate()?;
        let TelemetryQuality {
            noise_mas,
            rate_hz,
            latency_s,
            correlated_mas,
            correlation_time_s,
        } = *quality;
        if series.is_empty() {
            return Err(CountermeasureError::Telemetry(
                "the ACE series is empty (zero-length telemetry)".into(),
            ));
        }
        let dt = 1.0 / rate_hz;
        let (t0, t1) = (
            exposure_start_s - 2.0 * dt,
            exposure_start_s + span_s + 2.0 * dt,
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
        if correlated_mas > 0.0 {
            // its own stream, so that the white noise of a telemetry without this term is unchanged
            let mut rc = rng::stream(
                seed,
                Stream::Telemetry,
                (exposure_start_s * 1e3) as u64 | 1 << 62,
            );
            for v in [&mut xs, &mut ys] {
                for (e, s) in gauss_markov(n, dt, correlated_mas, correlation_time_s, &mut rc)
                    .into_iter()
                    .zip(v.iter_mut())
                {
                    *s += e;
                }
            }
        }
        Ok(Self {
            t0_s: t0,
            dt_s: dt,
            x_mas: xs,
            y_mas: ys,
            exposure_start_s,
        })
    }
}

impl Telemetry {
    /// Sample `series` as [`TelemetryRecord::record`] does and build the telemetry from it
    /// ([`Telemetry::from_record`]).
    pub fn from_series(
        series: &AceSeries,
        timing: ReadoutTiming,
        exposure_start_s: f64,
        plate_scale_mas: f64,
        rotation_deg: f64,
        quality: &TelemetryQuality,
        seed: u64,
        kernel: &PixelKernel,
        noise: &FitNoise,
    ) -> Result<Self, CountermeasureError> {
        let rec =
            TelemetryRecord::record(series, timing.span_s(), exposure_start_s, quality, seed)?;
        // the integration grid need be no finer than the series it was recorded from
        Self::from_record(
            &rec,
            series.dt_s,
            timing,
            plate_scale_mas,
            rotation_deg,
            kernel,
            noise,
        )
    }

    /// The telemetry of a recorded exposure: interpolated linearly between samples onto a grid of step
    /// `min(1 ms, max(finest_s, dt/4))`, turned into this array's axes, and the fit response built from
    /// the PSF's pixel kernel.
    pub fn from_record(
        rec: &TelemetryRecord,
        finest_s: f64,
        timing: ReadoutTiming,
        plate_scale_mas: f64,
        rotation_deg: f64,
        kernel: &PixelKernel,
        noise: &FitNoise,
    ) -> Result<Self, CountermeasureError> {
        let (t0, dt, exposure_start_s) = (rec.t0_s, rec.dt_s, rec.exposure_start_s);
        let (xs, ys) = (&rec.x_mas, &rec.y_mas);
        let n = xs.len();
        if n == 0 || ys.len() != n || !(dt > 0.0) {
            return Err(CountermeasureError::Telemetry(format!(
                "a telemetry record of {n} x and {} y samples at {dt} s: needs ≥ 1 of each, dt > 0",
                ys.len()
            )));
        }
        let span = timing.span_s();
        // resample on the integration grid (at most 1 ms, and no coarser than the series)
        let step = finest_s.max(dt.min(1e-3) / 4.0).min(1e-3);
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
                .map(|j| lin(exposure_start_s + j as f64 * step, xs) / plate_scale_mas)
                .collect(),
            (0..m)
                .map(|j| lin(exposure_start_s + j as f64 * step, ys) / plate_scale_mas)
                .collect(),
        );
        // the attitude is the telescope's: turned into this array's pixel axes, as the simulated jitter is
        let track = track.turned_into_array(rotation_deg);
        let nominal = track.window(timing.t_overhead_s, timing.t_overhead_s + timing.exposure_s);
        let response = FitResponse::build(kernel, &track, &nominal, noise);
        Ok(Self {
            track,
            timing,
            response,
            profile: None,
            model_nodes_per_px: super::forward::DEFAULT_NODES_PER_PX,
        })
    }

    /// The fit displacement (px) telemetry predicts for stars at these positions.
    pub fn predicted_px(&self, positions: &[(f64, f64)]) -> Vec<(f64, f64)> {
        self.response
            .displacements(&self.track, &self.timing, positions)
    }
}

/// `n` samples at `dt` of a stationary first-order Gauss–Markov process of rms `sigma` and correlation time
/// `tau`: `e₀ ~ N(0, σ²)`, `eₖ = a eₖ₋₁ + √(1 − a²) σ zₖ` with `a = exp(−dt/τ)`, so that every sample has
/// variance σ² and the autocorrelation at lag τ is 1/e.
pub fn gauss_markov(n: usize, dt: f64, sigma: f64, tau: f64, r: &mut impl rand::Rng) -> Vec<f64> {
    let a = (-dt / tau).exp();
    let b = (1.0 - a * a).sqrt() * sigma;
    let mut out = Vec::with_capacity(n);
    let mut e = 0.0;
    for k in 0..n {
        let z: f64 = rand_distr::StandardNormal.sample(r);
        e = if k == 0 { sigma * z } else { a * e + b * z };
        out.push(e);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn telemetry_input_errors_are_named() {
        let cfg = crate::config::Config::default();
        let timing = ReadoutTiming::new(&cfg);
        let psf = crate::testkit::synthetic_psf(4, 4);
        let k = PixelKernel::build(&psf, &crate::integrate::kernel::IntraPixelMap::uniform(4))
            .expect("kernel");
        let nm = FitNoise {
            flux_e: 7e4,
            sky_e: 300.0,
            floor_e2: 226.0,
            radius_px: 2.5,
        };
        let q = |noise_mas, rate_hz| TelemetryQuality {
            noise_mas,
            rate_hz,
            ..TelemetryQuality::IDEAL
        };
        let empty = AceSeries::still(1e-3, 0);
        let e = Telemetry::from_series(&empty, timing, 0.0, 472.0, 0.0, &q(1.0, 10.0), 1, &k, &nm)
            .expect_err("empty");
        assert!(e.to_string().contains("zero-length"));
        let s = AceSeries::still(1e-3, 20_000);
        for (bad, what) in [
            (q(f64::NAN, 10.0), "noise"),
            (q(1.0, 0.0), "rate"),
            (q(1.0, 1e7), "rate"),
        ] {
            let e = Telemetry::from_series(&s, timing, 0.0, 472.0, 0.0, &bad, 1, &k, &nm)
                .expect_err(what);
            assert!(e.to_string().contains(what), "{e}");
        }
    }

    #[test]
    fn gauss_markov_has_its_variance_and_correlation_time() {
        // 400 s at 1 ms with τ = 0.5 s: the rms has a relative standard error √(τ/T) = 3.5 %, the lag-τ
        // autocorrelation (Bartlett's formula for this AR(1)) 0.027; the bounds are ≈ 3.3 σ
        let mut r = crate::rng::stream(3, Stream::Test, 0);
        let (dt, tau, sigma) = (1e-3, 0.5, 20.0);
        let e = gauss_markov(400_000, dt, sigma, tau, &mut r);
        let n = e.len() as f64;
        let mean = e.iter().sum::<f64>() / n;
        let var = e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        assert!(
            (var.sqrt() / sigma - 1.0).abs() < 0.12,
            "rms {}",
            var.sqrt()
        );
        let lag = (tau / dt) as usize;
        let cov = e
            .iter()
            .zip(&e[lag..])
            .map(|(a, b)| (a - mean) * (b - mean))
            .sum::<f64>()
            / (n - lag as f64);
        let rho = cov / var;
        assert!(
            (rho - (-1.0f64).exp()).abs() < 0.12,
            "autocorrelation at τ: {rho}"
        );
    }
}
