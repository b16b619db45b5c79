//! The transit stare simulated: one target and its comparison stars, each read in a small window, plate
//! after plate, the ACE jitter and the slow drift moving them over the pixels.
//!
//! **Readout modelled: windowed, co-added sub-exposures.** Each plate (`plate_s`, 12.5 s by default) is
//! `n` sub-exposures of `exposure_s = plate_s / n`, each a reset and a correlated double sampling of only
//! the stars' windows, summed on board. The signal integrates the whole plate (a window of 23² pixels reads
//! in 2.6 ms at 5 µs per pixel: the gaps are neglected), the read noise enters n times
//! (σ = σ_image √n), and saturation is each sub-exposure's: `n` is the smallest whose sub-exposure keeps
//! every star's peak pixel (centred on a pixel, no jitter, the design's PSF) below the full well. Every pixel of a window
//! shares the plate's window (sample-and-hold timing), the cadence is `plate_s + readout.t_overhead_s`. The
//! choice is ours: JASMINE's readout for targets brighter than Hw ≈ 9.5 was not found; co-adding keeps the
//! cadence and the jitter averaging of a 12.5-s plate for every magnitude.
//!
//! **Jitter.** The ACE series of `[ace]` is generated in chunks of `ace.span_s` (each its own stream) and cut
//! into plates; the chunks are independent (the PSD's knee at 0.1 Hz gives a correlation time of 1.6 s, far
//! below a chunk). **Drift**: `drift_mas_per_h` along `drift_angle_deg`, plus `orbital_drift_mas` per axis at
//! `orbital_period_min` (x as a sine, y as a cosine), added to the whole plate. **Telemetry**: each plate's
//! mean pointing (ACE + drift) with a Gaussian error of `telemetry_error_mas`, and its jitter σ computed
//! from the attitude record over the plate ([`TelemetryRecord::record`] at the project's default quality,
//! [`TelemetryQuality::DEFAULT`]: 1 kHz, 20 mas of white noise a sample, 5 mas correlated), never from the
//! true series. **Windows**: placed on the array at the reference catalogue's positions (the survey's
//! errors, [`SurveyModel`]) through the design WCS — where the instrument would be told to read — not at
//! the stars' true places.

use super::spec::Spec;
use crate::analysis::countermeasures::TelemetryQuality;
use crate::analysis::countermeasures::telemetry::TelemetryRecord;
use crate::analysis::lightcurve::aperture_fluxes;
use crate::config::{AceCase, Config, IntraPixel, ReadoutOrder};
pub use crate::detector::window::Window;
use crate::detector::window::WindowReadout;
use crate::integrate::StarJob;
use crate::integrate::track::Track;
use crate::io::instrument::{SurveyModel, reference_catalogue};
use crate::jitter::AceSeries;
use crate::rng::{self, Stream};
use crate::scene::Star;
use crate::simulate::{ArrayPlace, ArraySpec, SimError, Simulator};
use rand::RngExt;
use rand_distr::{Distribution, Normal};
use std::sync::Arc;

/// The chosen readout of the stare.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StareReadout {
    /// Each plate's integration and its sub-exposures.
    pub plate_s: f64,
    pub sub_exposures: usize,
    pub exposure_s: f64,
    /// The longest sub-exposure at which no star's peak pixel fills the well.
    pub longest_safe_s: f64,
    /// Start-to-start time of plates, s.
    pub cadence_s: f64,
    /// A window's read noise per plate, e⁻ (σ_image √n).
    pub read_noise_e: f64,
}

/// One plate: the windows as read (ADU, co-added) and what the telemetry says.
#[derive(Debug, Clone)]
pub struct Plate {
    /// Mid-plate time, days from the stare's start.
    pub t_mid_days: f64,
    /// One window per star (row-major `n × n`), ADU.
    pub windows_adu: Vec<Vec<f32>>,
    /// Telemetry: the mean pointing (ACE + drift) over the plate with its error, and the jitter σ from the
    /// attitude record ([`record_sigma_mas`]), mas.
    pub telemetry_x_mas: f64,
    pub telemetry_y_mas: f64,
    pub telemetry_sigma_mas: f64,
}

/// The truth of one plate (for scoring and the noise budget only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateTruth {
    /// The target's relative flux (the transit averaged over the plate).
    pub transit_flux: f64,
    /// The drift and the ACE's mean offset over the plate, px.
    pub drift_px: (f64, f64),
    pub jitter_mean_px: (f64, f64),
    /// The ACE's true σ over the plate (per axis, both averaged), px.
    pub jitter_sigma_px: f64,
}

/// The observation: what the instrument delivers and, apart, the truth.
pub struct Observation {
    pub spec: Spec,
    /// The configuration the stare ran with (windowed timing, the spec's intra-pixel response).
    pub cfg: Config,
    pub readout: StareReadout,
    /// Truth: the stars (star 0 is the target). The analysis never reads them: it has
    /// [`Observation::catalogue_px`].
    pub stars: Vec<Star>,
    /// Each star's place on the array as the reference catalogue gives it (its sky position, with the
    /// survey's error, through the design WCS), detector px: where the windows were placed and where the
    /// analysis looks first.
    pub catalogue_px: Vec<(f64, f64)>,
    pub windows: Vec<Window>,
    /// The calibration flat cut to each window (1 where the analysis is uncalibrated).
    pub calibration_flat: Vec<Vec<f32>>,
    pub plates: Vec<Plate>,
    /// Truth: each plate's, and each window's noise-free pixel fractions' sums Σp and Σp² over the plates
    /// (the flat residual's budget).
    pub truth: Vec<PlateTruth>,
    pub pixel_moments: Vec<(Vec<f64>, Vec<f64>)>,
    /// Truth: the same pixel fractions summed over consecutive bins of 1 h and 6.5 h (the flat residual's
    /// budget binned: the drift moves the stars over the flat's errors slowly).
    pub binned_fractions: Vec<BinnedFractions>,
    /// Truth: each star's noise-free aperture flux per plate (`[radius][star][plate]`, e⁻, at each of
    /// `spec.aperture_radii_px()`; the aperture at the star's true place in the plate, a perfect flat, the
    /// target's transit divided out): what the pointing alone does to the photometry.
    pub clean_aperture_e: Vec<Vec<Vec<f64>>>,
    /// The model PSF the analysis fits: the design PSF blurred by the telemetry's median jitter σ.
    pub model_psf: crate::analysis::epsf::Epsf,
    /// Seconds spent simulating.
    pub simulate_s: f64,
    pub backend: String,
}

/// Each window's noise-free pixel fractions summed over consecutive bins of `bin_h` hours.
#[derive(Debug, Clone, Default)]
pub struct BinnedFractions {
    pub bin_h: f64,
    /// `[star][bin · n² + pixel]`.
    pub sums: Vec<Vec<f64>>,
    /// Plates per bin.
    pub counts: Vec<usize>,
}

impl BinnedFractions {
    fn add(&mut self, star: usize, t_h: f64, q: &[f64]) {
        let b = (t_h / self.bin_h).floor().max(0.0) as usize;
        let npx = q.len();
        if self.sums.len() <= star {
            self.sums.resize(star + 1, Vec::new());
        }
        let s = &mut self.sums[star];
        if s.len() < (b + 1) * npx {
            s.resize((b + 1) * npx, 0.0);
        }
        for (o, v) in s[b * npx..(b + 1) * npx].iter_mut().zip(q) {
            *o += v;
        }
        if star == 0 {
            if self.counts.len() <= b {
                self.counts.resize(b + 1, 0);
            }
            self.counts[b] += 1;
        }
    }
}

/// Errors of a stare.
#[derive(Debug, thiserror::Error)]
pub enum StareError {
    #[error("{0}")]
    Spec(String),
    #[error(
        "transit.exposure_s = {exposure_s} s: the {who} (Hw {hw:.2}) saturates, its peak pixel reaching {peak_e:.0} e⁻ \
         of a {well_e:.0}-e⁻ well; the longest exposure that does not is {longest_s:.3} s (set exposure_s = 0 \
         for the longest plate_s / n below it)"
    )]
    Saturates {
        exposure_s: f64,
        who: String,
        hw: f64,
        peak_e: f64,
        well_e: f64,
        longest_s: f64,
    },
    #[error("transit telemetry: {0}")]
    Telemetry(String),
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// The configuration of a stare: `cfg` with sample-and-hold windows of one plate, back to back, the spec's
/// intra-pixel response, and the ACE generated by the stare itself (the simulator sees a still telescope).
pub fn stare_config(cfg: &Config, spec: &Spec) -> Config {
    let mut c = cfg.clone();
    c.readout.order = ReadoutOrder::SampleHold;
    c.detector.exposure_s = spec.plate_s;
    c.readout.exposure_cadence_s = spec.plate_s + c.readout.t_overhead_s;
    c.fidelity.images = 1;
    if spec.intra_pixel_amplitude == 0.0 {
        c.detector.intra_pixel = IntraPixel::Uniform;
    } else if spec.intra_pixel_amplitude > 0.0 {
        c.detector.intra_pixel = IntraPixel::Parabolic {
            amplitude: spec.intra_pixel_amplitude,
        };
    }
    c
}

/// The target (star 0, near the detector's centre at a random pixel phase) and the comparison stars, at
/// least 1.5 windows from each other, within `field_radius_px` of the target and one window inside the
/// detector's edge; an error when they do not all fit.
pub fn field(cfg: &Config, spec: &Spec) -> Result<Vec<Star>, StareError> {
    let mut r = rng::stream(cfg.seed, Stream::Transit, u64::MAX);
    let c = cfg.instrument.detector_px as f64 / 2.0;
    let mut stars = vec![Star {
        id: 0,
        x_px: c + r.random_range(-0.5..0.5),
        y_px: c + r.random_range(-0.5..0.5),
        mag_hw: spec.target_hw,
        j_minus_h: spec.target_j_minus_h,
        in_truth: true,
    }];
    let min_sep = 1.5 * spec.window_px as f64;
    let reach = spec.field_radius_px.min(c - spec.window_px as f64);
    let mut tries = 0;
    while stars.len() <= spec.comparisons && tries < 100_000 {
        tries += 1;
        let rad = reach.max(0.0) * r.random::<f64>().sqrt();
        let ang = std::f64::consts::TAU * r.random::<f64>();
        let (x, y) = (c + rad * ang.cos(), c + rad * ang.sin());
        if stars
            .iter()
            .any(|s| (s.x_px - x).hypot(s.y_px - y) < min_sep)
        {
            continue;
        }
        let dm = spec.comparison_dmag_min
            + (spec.comparison_dmag_max - spec.comparison_dmag_min) * r.random::<f64>();
        stars.push(Star {
            id: stars.len(),
            x_px: x,
            y_px: y,
            mag_hw: spec.target_hw + dm,
            j_minus_h: spec.target_j_minus_h
                + spec.comparison_jh_spread * (2.0 * r.random::<f64>() - 1.0),
            in_truth: true,
        });
    }
    if stars.len() <= spec.comparisons {
        return Err(StareError::Spec(format!(
            "transit.comparisons = {}: only {} fit within {reach:.0} px of the target (field_radius_px, and one \
             window inside the {}-px detector) at 1.5 windows apart: lower comparisons or window_px",
            spec.comparisons,
            stars.len() - 1,
            cfg.instrument.detector_px
        )));
    }
    Ok(stars)
}

/// Each star's peak pixel rate as the design predicts it, e⁻/s: its rate times the share of a still star's
/// light the brightest pixel takes — the star's design pixel kernel ([`Simulator::design_psf_for`], the
/// as-built optics only under the oracle control) at the pixel's centre, the intra-pixel response
/// included. A mission chooses its readout from the design, before it knows the instrument as built.
pub fn design_peak_rates_e_per_s(
    sim: &Simulator,
    stars: &[Star],
    jobs: &[StarJob],
) -> Result<Vec<f64>, SimError> {
    stars
        .iter()
        .zip(jobs)
        .map(|(s, j)| {
            let kernel = sim.kernel_for(&sim.design_psf_for(s))?;
            Ok(j.star.rate_e_per_s * kernel.eval(0.0, 0.0))
        })
        .collect()
}

/// Choose the sub-exposure: the spec's, checked, or the longest `plate_s / n` that keeps every star's peak
/// pixel (`peak_e_per_s`, from [`design_peak_rates_e_per_s`]) below the full well (and the ADC's range).
pub fn choose_readout(
    cfg: &Config,
    spec: &Spec,
    stars: &[Star],
    peak_e_per_s: &[f64],
) -> Result<StareReadout, StareError> {
    let d = &cfg.detector;
    let well = d
        .full_well_e
        .min((2f64.powi(d.adc_bits as i32) - 1.0 - d.bias_adu) * d.gain_e_per_adu);
    let flat_max = 1.0 + 4.0 * d.inter_pixel_flat_sigma;
    // the peak pixel's rate through a pixel 4σ more sensitive than most
    let (worst, peak_rate) = stars
        .iter()
        .zip(peak_e_per_s)
        .map(|(s, p)| (s, p * flat_max))
        .fold((&stars[0], 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let longest = well / (peak_rate + d.dark_e_per_s);
    let exposure = if spec.exposure_s > 0.0 {
        if spec.exposure_s > longest {
            return Err(StareError::Saturates {
                exposure_s: spec.exposure_s,
                who: if worst.id == 0 {
                    "target".into()
                } else {
                    format!("comparison star {}", worst.id)
                },
                hw: worst.mag_hw,
                peak_e: (peak_rate + d.dark_e_per_s) * spec.exposure_s,
                well_e: well,
                longest_s: longest,
            });
        }
        spec.exposure_s
    } else {
        let n = (spec.plate_s / longest).ceil().max(1.0);
        spec.plate_s / n
    };
    let n = (spec.plate_s / exposure).round().max(1.0) as usize;
    Ok(StareReadout {
        plate_s: spec.plate_s,
        sub_exposures: n,
        exposure_s: exposure,
        longest_safe_s: longest,
        cadence_s: cfg.exposure_cadence_s(),
        read_noise_e: d.image_read_noise_e() * (n as f64).sqrt(),
    })
}

/// The drift at `t_s` from the stare's start, mas.
pub fn drift_mas(spec: &Spec, t_s: f64) -> (f64, f64) {
    let lin = spec.drift_mas_per_h * t_s / 3600.0;
    let a = spec.drift_angle_deg.to_radians();
    let ph = std::f64::consts::TAU * t_s / (spec.orbital_period_min * 60.0);
    (
        lin * a.cos() + spec.orbital_drift_mas * ph.sin(),
        lin * a.sin() + spec.orbital_drift_mas * ph.cos(),
    )
}

/// Simulate the stare of `spec` with `cfg`'s instrument.
pub fn observe(cfg: &Config, spec: &Spec) -> Result<Observation, StareError> {
    let t_start = std::time::Instant::now();
    let mut c = stare_config(cfg, spec);
    let cadence = c.exposure_cadence_s();
    spec.validate(cadence).map_err(StareError::Spec)?;
    let realistic = c.ace.case == AceCase::Realistic;
    let (stars, sim) = stare_simulator(&c, spec, realistic)?;
    let jobs = sim.jobs()?;
    let peaks = design_peak_rates_e_per_s(&sim, &stars, &jobs)?;
    let readout = choose_readout(&c, spec, &stars, &peaks)?;
    let plates_n = spec.plates(cadence);
    let transit = spec.transit();
    let n = c.instrument.detector_px;
    let catalogue_px = catalogue_places(&sim, &stars);
    let windows = place_windows(&catalogue_px, spec.window_px, n)?;
    let flat_w: Vec<Vec<f32>> = windows.iter().map(|w| w.cut(sim.flat(), n)).collect();
    let calibration_flat = match sim.calibration_flat() {
        Some(f) => windows.iter().map(|w| w.cut(&f, n)).collect(),
        None => windows.iter().map(|w| vec![1.0; w.n * w.n]).collect(),
    };
    // the ACE in chunks of whole plates
    c.ace.span_s = c.ace.span_s.max(cadence + 1.0);
    let per_chunk = ((c.ace.span_s - 1.0) / cadence).floor().max(1.0) as usize;
    c.ace.span_s = per_chunk as f64 * cadence + 1.0;
    let plate_scale = c.instrument.plate_scale_mas();
    let span = c.readout.t_overhead_s + spec.plate_s;
    let detector = WindowReadout::new(
        &c.detector,
        spec.plate_s,
        readout.sub_exposures,
        readout.read_noise_e,
    );
    let mut plates = Vec::with_capacity(plates_n);
    let mut truth = Vec::with_capacity(plates_n);
    let radii = spec.aperture_radii_px();
    let mut sums = CleanSums::new(&windows, radii.len(), plates_n);
    let mut ace = AceChunks {
        per_chunk,
        plates_n,
        series: None,
        next: None,
    };
    for p in 0..plates_n {
        let t0 = p as f64 * cadence;
        let t_mid = t0 + c.readout.t_overhead_s + 0.5 * spec.plate_s;
        let drift = drift_mas(spec, t_mid);
        let (mut track, sigma_mas) = if realistic {
            ace.track(&c, spec, p, span)?
        } else {
            (Track::still(span, 1e-3), 0.0)
        };
        let w = track.window(c.readout.t_overhead_s, span);
        let jitter_mean = track.window_mean(&w);
        let jitter_sigma_px = {
            let (mut s2, mut tw) = (0.0, 0.0);
            for j in w.first..=w.last.min(track.len().saturating_sub(1)) {
                let wt = w.weight(j);
                s2 += wt
                    * ((track.dx_px[j] - jitter_mean.0).powi(2)
                        + (track.dy_px[j] - jitter_mean.1).powi(2))
                    / 2.0;
                tw += wt;
            }
            (s2 / tw.max(1e-300)).sqrt()
        };
        let (dxp, dyp) = (drift.0 / plate_scale, drift.1 / plate_scale);
        track.dx_px.iter_mut().for_each(|v| *v += dxp);
        track.dy_px.iter_mut().for_each(|v| *v += dyp);
        let tf = transit.map_or(1.0, |tr| {
            tr.mean_flux(
                (t0 + c.readout.t_overhead_s) / 86_400.0,
                spec.plate_s / 86_400.0,
                7,
            )
        });
        let mut pj = jobs.clone();
        pj[0].star.rate_e_per_s *= tf;
        let mut r = rng::stream(c.seed, Stream::Transit, p as u64);
        let Some(reads) = sim.read_windows(&pj, &track, &windows, &flat_w, &detector, &mut r)?
        else {
            return Err(StareError::Spec(
                "transit.drift_mas_per_h: the drift took a star off the detector".into(),
            ));
        };
        let mut windows_adu = Vec::with_capacity(windows.len());
        for (k, (wdw, read)) in windows.iter().zip(reads).enumerate() {
            // the aperture at the star's true place in this plate (its nominal place, the drift and the
            // jitter's mean); the target's without its transit (a factor on its rate): the pointing's part
            let place = (
                stars[k].x_px + dxp + jitter_mean.0 - wdw.x0 as f64,
                stars[k].y_px + dyp + jitter_mean.1 - wdw.y0 as f64,
            );
            let unit = if k == 0 { tf } else { 1.0 };
            sums.add(
                k,
                &read.clean_e,
                wdw.n,
                place,
                unit,
                &radii,
                spec,
                t_mid / 3600.0,
            );
            windows_adu.push(read.adu);
        }
        let tel = Normal::new(0.0, spec.telemetry_error_mas.max(1e-300)).ok();
        let mut tel_err = || tel.as_ref().map_or(0.0, |t| t.sample(&mut r));
        plates.push(Plate {
            t_mid_days: t_mid / 86_400.0,
            windows_adu,
            telemetry_x_mas: (jitter_mean.0 + dxp) * plate_scale + tel_err(),
            telemetry_y_mas: (jitter_mean.1 + dyp) * plate_scale + tel_err(),
            telemetry_sigma_mas: sigma_mas,
        });
        truth.push(PlateTruth {
            transit_flux: tf,
            drift_px: (dxp, dyp),
            jitter_mean_px: jitter_mean,
            jitter_sigma_px,
        });
    }
    let sigmas: Vec<f64> = plates.iter().map(|p| p.telemetry_sigma_mas).collect();
    let blur_px = crate::numerics::stats::median(&sigmas) / plate_scale;
    let kernel = sim.design_kernel_with_blur(if blur_px.is_finite() { blur_px } else { 0.0 })?;
    let half_psf = (spec.window_px / 2).max(4);
    let model_psf = crate::analysis::epsf::Epsf::from_fn(4, half_psf, |x, y| kernel.eval(x, y));
    Ok(Observation {
        clean_aperture_e: sums.clean_ap,
        model_psf,
        spec: spec.clone(),
        readout,
        stars,
        catalogue_px,
        windows,
        calibration_flat,
        plates,
        truth,
        pixel_moments: sums.moments,
        binned_fractions: sums.binned,
        simulate_s: t_start.elapsed().as_secs_f64(),
        backend: sim.backend_name(),
        cfg: c,
    })
}

/// The stare's field and its simulator: it sees a still telescope (the stare cuts its own tracks; a
/// Gaussian ACE stays a blur), the target's colour.
fn stare_simulator(
    c: &Config,
    spec: &Spec,
    realistic: bool,
) -> Result<(Vec<Star>, Simulator), StareError> {
    let mut sim_cfg = c.clone();
    if realistic {
        sim_cfg.ace.case = AceCase::None;
    }
    sim_cfg.scene.j_minus_h = spec.target_j_minus_h;
    sim_cfg.validate().map_err(|e| StareError::Sim(e.into()))?;
    let stars = field(&sim_cfg, spec)?;
    let (integrator, _) = crate::integrate::Integrator::choose(sim_cfg.fidelity.backend);
    let sim = Simulator::build_array(
        &sim_cfg,
        ArraySpec {
            place: ArrayPlace {
                index: 0,
                rotation_deg: 0.0,
                seed: sim_cfg.seed,
            },
            stars: stars.clone(),
        },
        None,
        Arc::new(crate::optics::PsfBank::new(&sim_cfg)),
        Arc::new(Default::default()),
        integrator,
        None,
    )?;
    Ok((stars, sim))
}

/// A window of `n` pixels around each catalogue place, all on a detector of `detector_px`.
fn place_windows(
    catalogue_px: &[(f64, f64)],
    n: usize,
    detector_px: usize,
) -> Result<Vec<Window>, StareError> {
    let half = (n / 2) as i64;
    let windows: Vec<Window> = catalogue_px
        .iter()
        .map(|(x, y)| Window {
            x0: x.round() as i64 - half,
            y0: y.round() as i64 - half,
            n,
        })
        .collect();
    let off = |w: &Window| {
        w.x0 < 0
            || w.y0 < 0
            || w.x0 as usize + w.n > detector_px
            || w.y0 as usize + w.n > detector_px
    };
    if windows.iter().any(off) {
        return Err(StareError::Spec(
            "transit.field_radius_px: a catalogue position puts a window off the detector".into(),
        ));
    }
    Ok(windows)
}

/// What the noise-free windows give the scoring and the budget (truth), summed plate by plate: each
/// star's aperture flux at its true place, its pixel fractions' Σp and Σp², and those binned in time.
struct CleanSums {
    clean_ap: Vec<Vec<Vec<f64>>>,
    moments: Vec<(Vec<f64>, Vec<f64>)>,
    binned: Vec<BinnedFractions>,
}

impl CleanSums {
    fn new(windows: &[Window], radii: usize, plates_n: usize) -> Self {
        Self {
            clean_ap: vec![vec![Vec::with_capacity(plates_n); windows.len()]; radii],
            moments: windows
                .iter()
                .map(|w| (vec![0.0; w.n * w.n], vec![0.0; w.n * w.n]))
                .collect(),
            binned: [1.0, 6.5]
                .iter()
                .map(|&bin_h| BinnedFractions {
                    bin_h,
                    ..Default::default()
                })
                .collect(),
        }
    }

    /// Star `k`'s clean window (`n` × `n`, e⁻) of a plate at `t_h` hours: its aperture fluxes at `place`
    /// (window px) ÷ `unit`, and its pixel fractions.
    #[allow(clippy::too_many_arguments)]
    fn add(
        &mut self,
        k: usize,
        clean: &[f64],
        n: usize,
        place: (f64, f64),
        unit: f64,
        radii: &[f64],
        spec: &Spec,
        t_h: f64,
    ) {
        let fluxes = aperture_fluxes(
            clean,
            n,
            n,
            place.0,
            place.1,
            radii,
            spec.annulus_in_px,
            spec.annulus_out_px,
        );
        for (series, a) in self.clean_ap.iter_mut().zip(&fluxes) {
            series[k].push(a.map_or(f64::NAN, |a| a.flux / unit));
        }
        let total: f64 = clean.iter().sum::<f64>().max(1e-300);
        let (s1, s2) = &mut self.moments[k];
        let q: Vec<f64> = clean.iter().map(|v| v / total).collect();
        for (i, q) in q.iter().enumerate() {
            s1[i] += q;
            s2[i] += q * q;
        }
        for b in &mut self.binned {
            b.add(k, t_h, &q);
        }
    }
}

/// The realistic ACE of a stare, generated in chunks of whole plates (two at a time, one per core; each
/// chunk's series is its own stream), and each plate's track cut from its chunk.
struct AceChunks {
    per_chunk: usize,
    plates_n: usize,
    series: Option<(usize, AceSeries)>,
    next: Option<(usize, AceSeries)>,
}

impl AceChunks {
    /// Plate `p`'s track over `span` seconds and its attitude record's jitter σ (mas).
    fn track(
        &mut self,
        c: &Config,
        spec: &Spec,
        p: usize,
        span: f64,
    ) -> Result<(Track, f64), StareError> {
        let cadence = c.exposure_cadence_s();
        let chunk = p / self.per_chunk;
        if self.series.as_ref().map(|s| s.0) != Some(chunk) {
            self.series = match self.next.take() {
                Some(s) if s.0 == chunk => Some(s),
                _ => {
                    let more = (chunk + 1) * self.per_chunk < self.plates_n;
                    let (a, b) = rayon::join(
                        || AceSeries::generate(c, c.seed, 1 + chunk as u64),
                        || more.then(|| AceSeries::generate(c, c.seed, 2 + chunk as u64)),
                    );
                    self.next = b.map(|b| (chunk + 1, b));
                    Some((chunk, a))
                }
            };
        }
        let Some((_, s)) = self.series.as_ref() else {
            return Err(StareError::Spec(
                "the ACE series of a chunk was not generated".into(),
            ));
        };
        let start_s = (p % self.per_chunk) as f64 * cadence + c.readout.t_overhead_s;
        let sigma_mas = record_sigma_mas(
            s,
            start_s,
            spec.plate_s,
            crate::rng::derive_seed(c.seed, &[chunk as u64]),
        )?;
        let track = Track::from_series(
            s,
            (p % self.per_chunk) as f64 * cadence,
            span,
            c.fidelity.time_stride,
            c.instrument.plate_scale_mas(),
        );
        Ok((track, sigma_mas))
    }
}

/// Each star's place on the array from the reference catalogue (every star of the stare is in it: the
/// target and its comparisons are chosen from it): its sky position, drawn with the survey's error
/// ([`SurveyModel::default`]: 2 mas per axis brighter than Hw 14), through the array's design WCS; the
/// catalogue's pixel position where there is no WCS.
fn catalogue_places(sim: &Simulator, stars: &[Star]) -> Vec<(f64, f64)> {
    let survey = SurveyModel {
        completeness: 1.0,
        limit_hw: f64::INFINITY,
        ..SurveyModel::default()
    };
    let cat = reference_catalogue(sim, &survey, 0);
    stars
        .iter()
        .map(|s| match cat.iter().find(|c| c.id == s.id) {
            Some(c) => sim
                .design_wcs()
                .and_then(|w| w.sky_to_pixel(c.ra_deg, c.dec_deg))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .unwrap_or((c.x_px, c.y_px)),
            None => (s.x_px, s.y_px),
        })
        .collect()
}

/// A plate's jitter σ as the attitude telemetry gives it, mas: the record of the plate
/// ([`TelemetryRecord::record`] at [`TelemetryQuality::DEFAULT`], over `span_s` from `start_s` of the ACE
/// series) less its stated white noise, `σ² = (var x + var y)/2 − σ_n²` over the samples within the plate
/// (floored at 0). The record's correlated error (5 mas) stays in: under 0.1 % of a jitter of 100s of mas.
pub fn record_sigma_mas(
    series: &crate::jitter::AceSeries,
    start_s: f64,
    span_s: f64,
    seed: u64,
) -> Result<f64, StareError> {
    let q = TelemetryQuality::DEFAULT;
    let rec = TelemetryRecord::record(series, span_s, start_s, &q, seed)
        .map_err(|e| StareError::Telemetry(e.to_string()))?;
    let inside: Vec<usize> = (0..rec.x_mas.len())
        .filter(|&k| {
            let t = rec.t0_s + k as f64 * rec.dt_s;
            t >= start_s && t <= start_s + span_s
        })
        .collect();
    if inside.len() < 2 {
        return Err(StareError::Telemetry(format!(
            "{} samples within the plate of {span_s} s",
            inside.len()
        )));
    }
    let var = |v: &[f64]| {
        let s: Vec<f64> = inside.iter().map(|&k| v[k]).collect();
        crate::numerics::stats::std_dev(&s).powi(2)
    };
    let noise = rec.stated_noise_mas.unwrap_or(0.0);
    Ok((0.5 * (var(&rec.x_mas) + var(&rec.y_mas)) - noise * noise)
        .max(0.0)
        .sqrt())
}
