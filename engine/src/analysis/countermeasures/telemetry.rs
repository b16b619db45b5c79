//! The `telemetry` countermeasure: the attitude telemetry of an exposure, degraded as the instrument would
//! record it, turned into each star's fitted shift through the fit's response to the jitter of its pixels'
//! window ([`crate::analysis::response`]; the optical PSF is taken as known from calibration).

use super::{CountermeasureError, TelemetryQuality};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::config::TelemetryFilter;
use crate::integrate::kernel::PixelKernel;
use crate::integrate::track::Track;
use crate::jitter::AceSeries;
use crate::readout::ReadoutTiming;
use crate::rng::{self, Stream};
use rand_distr::{Distribution, Normal};
use serde::Serialize;

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
    /// The track the forward model sees the profile through: the telemetry low-pass filtered
    /// ([`Smoothing::choose`]); `None`: [`Telemetry::track`] as recorded.
    pub model_track: Option<Track>,
    /// The low-order wavefront the stars corrected the design model PSF by (`design-fitted`), if fitted.
    pub wavefront: Option<super::wavefront::WavefrontFit>,
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
    /// The white noise per sample the recording states (mas; the product's `NOISEMAS`), if it does.
    pub stated_noise_mas: Option<f64>,
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
            stated_noise_mas: Some(noise_mas),
        })
    }

    /// The same record low-pass filtered by the boxcar `smoothing` chose (a copy; 1 sample: unchanged).
    pub fn smoothed(&self, smoothing: &Smoothing) -> Self {
        Self {
            x_mas: boxcar(&self.x_mas, smoothing.half_width),
            y_mas: boxcar(&self.y_mas, smoothing.half_width),
            ..self.clone()
        }
    }

    /// The record the forward model sees under `filter`: low-pass filtered by the boxcar [`Smoothing::choose`]
    /// picks (`auto`), or Wiener-smoothed against its white noise ([`super::wiener`]); `None` where that is
    /// the record itself (`off`, a boxcar of one sample, no noise).
    pub fn model_record(&self, filter: TelemetryFilter) -> Option<Self> {
        match filter {
            TelemetryFilter::Off => None,
            TelemetryFilter::Auto => {
                let smoothing = Smoothing::choose(self);
                (smoothing.half_width > 0).then(|| self.smoothed(&smoothing))
            }
            TelemetryFilter::Wiener => {
                let noise = self.noise_mas();
                (noise > 0.0).then(|| Self {
                    x_mas: super::wiener::smooth(&self.x_mas, noise),
                    y_mas: super::wiener::smooth(&self.y_mas, noise),
                    ..self.clone()
                })
            }
        }
    }

    /// The white noise per sample: as the record states it, else estimated from its second differences
    /// ([`white_noise_mas`], both axes in quadrature over √2).
    pub fn noise_mas(&self) -> f64 {
        self.stated_noise_mas.unwrap_or_else(|| {
            (white_noise_mas(&self.x_mas).powi(2) + white_noise_mas(&self.y_mas).powi(2)).sqrt()
                / 2f64.sqrt()
        })
    }
}

/// The low-pass filter of a telemetry record before the forward model sees a star through it: a centred boxcar
/// of `2 half_width + 1` samples, chosen per record.
///
/// The forward model takes every sample for a place the star was, so white noise σ per sample blurs its model
/// of each star by σ² (variance), where the shift correction only averages it. A boxcar of N samples leaves
/// σ²/N of it and removes the jitter's own variance above ≈ rate/N, `V_hf(N)`. Its estimate: the variance of
/// the record minus its boxcar, `V_res(N) = V_hf(N) + σ² (1 − 1/N)`. The choice minimises the blur error
/// `σ²/N + max(0, V_res(N) − σ²(1 − 1/N))` over N = 1, 3, 5, 9, 17, … ≤ a quarter of the record (both axes
/// summed). σ is the record's stated noise, or else estimated from its second differences
/// ([`white_noise_mas`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Smoothing {
    /// Half-width of the boxcar, samples (0: no filter).
    pub half_width: usize,
    /// The white noise per sample it was chosen for, mas.
    pub noise_mas: f64,
    /// The blur error it leaves (variance, mas², both axes summed), estimated as above.
    pub error_mas2: f64,
}

impl Smoothing {
    /// The boxcar that minimises the estimated blur error of `rec` ([`Smoothing`]).
    pub fn choose(rec: &TelemetryRecord) -> Self {
        let sigma = rec.noise_mas();
        let s2 = sigma * sigma;
        let n = rec.x_mas.len();
        let mut best = Self {
            half_width: 0,
            noise_mas: sigma,
            error_mas2: 2.0 * s2,
        };
        let mut h = 1;
        while 2 * h < n / 4 {
            let m = (2 * h + 1) as f64;
            let error: f64 = [&rec.x_mas, &rec.y_mas]
                .iter()
                .map(|v| {
                    let res: Vec<f64> = v.iter().zip(boxcar(v, h)).map(|(a, b)| a - b).collect();
                    let v_res = crate::numerics::stats::std_dev(&res).powi(2);
                    s2 / m + (v_res - s2 * (1.0 - 1.0 / m)).max(0.0)
                })
                .sum();
            if error < best.error_mas2 {
                best = Self {
                    half_width: h,
                    noise_mas: sigma,
                    error_mas2: error,
                };
            }
            h *= 2;
        }
        best
    }
}

/// The centred moving average of `v` over `2 h + 1` samples, the window shrunk symmetrically at the ends (so a
/// straight line stays straight).
pub fn boxcar(v: &[f64], h: usize) -> Vec<f64> {
    if h == 0 {
        return v.to_vec();
    }
    let mut cum = Vec::with_capacity(v.len() + 1);
    cum.push(0.0);
    for x in v {
        cum.push(cum[cum.len() - 1] + x);
    }
    let n = v.len();
    (0..n)
        .map(|i| {
            let r = h.min(i).min(n - 1 - i);
            (cum[i + r + 1] - cum[i - r]) / (2 * r + 1) as f64
        })
        .collect()
}

/// White noise per sample of a series (its units), estimated from its second differences: white noise σ gives
/// `x_{k+1} − 2x_k + x_{k−1}` a variance 6σ², a jitter smooth over a few samples almost none. Robust: the
/// median absolute second difference / 0.6745 / √6. Fewer than 3 samples: 0.
pub fn white_noise_mas(v: &[f64]) -> f64 {
    if v.len() < 3 {
        return 0.0;
    }
    let d: Vec<f64> = v
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    crate::numerics::stats::median(&d) / 0.6745 / 6f64.sqrt()
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
        let (dt, n, ys) = (rec.dt_s, rec.x_mas.len(), &rec.y_mas);
        if n == 0 || ys.len() != n || !(dt > 0.0) {
            return Err(CountermeasureError::Telemetry(format!(
                "a telemetry record of {n} x and {} y samples at {dt} s: needs ≥ 1 of each, dt > 0",
                ys.len()
            )));
        }
        let track = resample(rec, finest_s, &timing, plate_scale_mas, rotation_deg);
        let nominal = track.window(timing.t_overhead_s, timing.t_overhead_s + timing.exposure_s);
        let response = FitResponse::build(kernel, &track, &nominal, noise);
        Ok(Self {
            track,
            timing,
            response,
            profile: None,
            model_nodes_per_px: super::forward::DEFAULT_NODES_PER_PX,
            model_track: None,
            wavefront: None,
        })
    }

    /// The forward model of an image `detector_px` wide that sees `profile` through this telemetry (its filtered
    /// track where there is one, [`Telemetry::model_track`]).
    pub fn forward<'a>(
        &'a self,
        profile: &'a crate::analysis::epsf::Epsf,
        detector_px: usize,
    ) -> super::forward::Forward<'a> {
        super::forward::Forward::new(
            profile,
            self.model_track.as_ref().unwrap_or(&self.track),
            &self.timing,
            self.model_nodes_per_px,
            detector_px,
        )
    }

    /// The fit displacement (px) telemetry predicts for stars at these positions.
    pub fn predicted_px(&self, positions: &[(f64, f64)]) -> Vec<(f64, f64)> {
        self.response
            .displacements(&self.track, &self.timing, positions)
    }
}

/// A telemetry record interpolated linearly between samples onto a grid of step `min(1 ms, max(finest_s,
/// dt/4))` over the exposure, in px of this array's axes (times from the exposure start).
pub fn resample(
    rec: &TelemetryRecord,
    finest_s: f64,
    timing: &ReadoutTiming,
    plate_scale_mas: f64,
    rotation_deg: f64,
) -> Track {
    let (t0, dt, exposure_start_s) = (rec.t0_s, rec.dt_s, rec.exposure_start_s);
    let (xs, ys) = (&rec.x_mas, &rec.y_mas);
    let n = xs.len();
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
    track.turned_into_array(rotation_deg)
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

    /// A 12.5-s record at 1 kHz of a drift (a slow sine of 300 mas) plus a 40-Hz vibration of amplitude `vib`,
    /// with white noise `sigma` per sample; `stated`: whether the record states its noise.
    fn record(sigma: f64, vib: f64, stated: bool) -> (TelemetryRecord, Vec<f64>) {
        let mut r = crate::rng::stream(11, Stream::Test, 0);
        let n = 12_500;
        let truth: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * 1e-3;
                300.0 * (t / 4.0).sin() + vib * (2.0 * std::f64::consts::PI * 40.0 * t).sin()
            })
            .collect();
        let mut noisy = || -> Vec<f64> {
            truth
                .iter()
                .map(|v| {
                    let z: f64 = rand_distr::StandardNormal.sample(&mut r);
                    v + sigma * z
                })
                .collect::<Vec<f64>>()
        };
        let (x, y) = (noisy(), noisy());
        let rec = TelemetryRecord {
            t0_s: 0.0,
            dt_s: 1e-3,
            x_mas: x,
            y_mas: y,
            exposure_start_s: 0.0,
            stated_noise_mas: stated.then_some(sigma),
        };
        (rec, truth)
    }

    fn rms_from(v: &[f64], truth: &[f64]) -> f64 {
        (v.iter()
            .zip(truth)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / v.len() as f64)
            .sqrt()
    }

    #[test]
    fn the_boxcar_keeps_a_line_and_averages_white_noise_by_its_length() {
        let line: Vec<f64> = (0..50).map(|k| 3.0 + 0.5 * k as f64).collect();
        for (a, b) in boxcar(&line, 4).iter().zip(&line) {
            assert!((a - b).abs() < 1e-12);
        }
        // white noise of σ = 1 averaged over 2·8+1 = 17 samples: σ/√17 = 0.243 (± 0.7 % over 10⁵ samples)
        let mut r = crate::rng::stream(5, Stream::Test, 0);
        let w: Vec<f64> = (0..100_000)
            .map(|_| -> f64 { rand_distr::StandardNormal.sample(&mut r) })
            .collect();
        let sd = crate::numerics::stats::std_dev(&boxcar(&w, 8)[8..100_000 - 8]);
        assert!((sd * 17f64.sqrt() - 1.0).abs() < 0.03, "{sd}");
    }

    #[test]
    fn the_noise_is_estimated_from_the_record_when_it_is_not_stated() {
        // a 12 500-sample MAD estimate has a relative error ≈ 1.1 %; the drift and a 30-mas vibration add
        // ≈ (2π·40 Hz·1 ms)²·30/√6 ≈ 0.8 mas to the second differences: ≈ 2 % of 40 mas
        let (rec, _) = record(40.0, 30.0, false);
        let e = white_noise_mas(&rec.x_mas);
        assert!((e / 40.0 - 1.0).abs() < 0.06, "{e}");
        assert_eq!(white_noise_mas(&[1.0, 2.0]), 0.0);
    }

    #[test]
    fn the_filter_follows_the_noise_and_keeps_the_jitter() {
        // 400 mas per sample: a wide boxcar, the record close to the true attitude again
        let (rec, truth) = record(400.0, 30.0, true);
        let s = Smoothing::choose(&rec);
        assert!(s.half_width >= 8, "{s:?}");
        let f = rec.smoothed(&s);
        assert!(
            rms_from(&f.x_mas, &truth) < 0.15 * rms_from(&rec.x_mas, &truth),
            "{} from {}",
            rms_from(&f.x_mas, &truth),
            rms_from(&rec.x_mas, &truth)
        );
        // the same estimated from the record: the same choice within a factor 2
        let u = Smoothing::choose(&record(400.0, 30.0, false).0);
        assert!(u.half_width * 2 >= s.half_width && u.half_width <= 2 * s.half_width);
        // no noise: the record as it is; a small noise and a 200-mas vibration at 40 Hz (25 samples per
        // cycle): a boxcar narrow enough to keep the vibration (a 17-sample boxcar would remove 55 % of it)
        assert_eq!(Smoothing::choose(&record(0.0, 30.0, true).0).half_width, 0);
        let (rec, truth) = record(5.0, 200.0, true);
        let s = Smoothing::choose(&rec);
        assert!(s.half_width <= 2, "{s:?}");
        assert!(rms_from(&rec.smoothed(&s).x_mas, &truth) <= 5.2);
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
