//! The paper's experiment (SPEC §6, §8): datasets of images per (ACE case, readout order, magnitude), each
//! image analysed with the ePSF method and every requested countermeasure, on the same images.
//!
//! A dataset reports, per countermeasure, the mean over its images of the per-image accuracy and the
//! standard error of that mean (the paper's figure), the median Cramér–Rao bound, and the accuracy the
//! instant predictor expects ([`crate::analysis::predict`]).

use crate::analysis::astrometry::{self, AnalysisImage, Options, Report};
use crate::analysis::countermeasures::{Countermeasure, CountermeasureError, Telemetry};
use crate::analysis::epsf::Epsf;
use crate::analysis::response::FitResponse;
use crate::config::{AceCase, Config, ReadoutOrder};
use crate::integrate::gpu::GpuIntegrator;
use crate::integrate::kernel::PixelKernel;
use crate::numerics::stats;
use crate::optics::PsfBank;
use crate::simulate::{SimError, Simulator};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Astrometry(#[from] astrometry::AstrometryError),
    #[error(transparent)]
    Countermeasure(#[from] CountermeasureError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
}

/// Telemetry quality for the `telemetry` countermeasure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TelemetrySpec {
    pub noise_mas: f64,
    pub rate_hz: f64,
    pub latency_s: f64,
}

impl Default for TelemetrySpec {
    fn default() -> Self {
        Self {
            noise_mas: 0.0,
            rate_hz: 1000.0,
            latency_s: 0.0,
        }
    }
}

/// What to compute on each image.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Countermeasure names (`none`, `yzones`, `yzones-shared`, `plate-affine`, `plate-poly:N`,
    /// `telemetry`), plus `exact-epsf` — the control fit with the exact ePSF (static ACE cases only).
    pub countermeasures: Vec<String>,
    pub telemetry: TelemetrySpec,
    /// Error of the reference catalogue used by the plate models, mas.
    pub reference_error_mas: f64,
}

impl Default for Plan {
    fn default() -> Self {
        Self {
            countermeasures: vec!["none".into()],
            telemetry: TelemetrySpec::default(),
            reference_error_mas: 0.0,
        }
    }
}

/// Result of one countermeasure on one image.
#[derive(Debug, Clone, Serialize)]
pub struct Measured {
    pub countermeasure: String,
    pub report: Report,
}

/// One image's results.
#[derive(Debug, Clone, Serialize)]
pub struct ImageResult {
    pub index: usize,
    pub ace_sigma_mas: f64,
    pub ace_drift_mas: f64,
    pub simulate_s: f64,
    pub analyse_s: f64,
    pub measured: Vec<Measured>,
    /// The star results of the plain global-ePSF analysis (kept for image 0, for the vector map).
    #[serde(skip)]
    pub stars: Option<Vec<astrometry::StarResult>>,
}

/// A dataset summary row per countermeasure.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub ace: String,
    pub readout: String,
    pub countermeasure: String,
    pub mag: f64,
    pub accuracy_mas: f64,
    pub sem_mas: f64,
    pub crlb_mas: f64,
    pub predicted_mas: f64,
    pub n_images: usize,
    pub time_s: f64,
}

/// The header of `experiment.csv`.
pub const CSV_HEADER: [&str; 10] = [
    "ace",
    "readout",
    "countermeasure",
    "mag",
    "accuracy_mas",
    "sem_mas",
    "crlb_mas",
    "predicted_mas",
    "n_images",
    "time_s",
];

/// The exact ePSF of a static simulation: its pixel kernel (PSF ⊛ Gaussian ACE ⊛ pixel) sampled at 8 nodes
/// per pixel. Only meaningful when every star shares one kernel and the ACE is static.
pub fn exact_epsf(kernel: &PixelKernel, half_px: usize) -> Epsf {
    let mut e = Epsf::from_fn(8, half_px, |x, y| kernel.eval(x, y));
    e.normalise();
    e
}

/// Attach to an analysis of exposure `index` the fit displacement the true ACE predicts for every star
/// (realistic ACE only; the mechanism, shown beside the measured errors) and refresh its report.
pub fn attach_ace_prediction(
    sim: &Simulator,
    index: usize,
    truth: &[crate::simulate::TruthRow],
    analysis: &mut astrometry::Analysis,
    plate_scale_mas: f64,
) -> Result<(), SimError> {
    if let Some(track) = sim.track(index) {
        let resp = FitResponse::build(
            &*sim.optical_kernel()?,
            &track,
            &sim.nominal_window(&track),
            &sim.fit_noise(),
        );
        let pos: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
        let pred = resp.displacements(&track, &sim.timing, &pos);
        astrometry::attach_fit_prediction(&mut analysis.stars, &pred);
        astrometry::summarise(
            &analysis.stars,
            Some(truth),
            plate_scale_mas,
            &mut analysis.report,
        );
    }
    Ok(())
}

/// The telemetry countermeasure of an exposure starting at `t_start_s`, or `None` for a static ACE (nothing
/// to correct).
pub fn telemetry_countermeasure(
    sim: &Simulator,
    t_start_s: f64,
    spec: &TelemetrySpec,
) -> Result<Option<Countermeasure>, ExperimentError> {
    let Some(series) = sim.series() else {
        return Ok(None);
    };
    let tel = Telemetry::from_series(
        series,
        sim.timing,
        t_start_s,
        sim.cfg.instrument.plate_scale_mas(),
        spec.noise_mas,
        spec.rate_hz,
        spec.latency_s,
        sim.cfg.seed,
        &*sim.optical_kernel()?,
        &sim.fit_noise(),
    )?;
    Ok(Some(Countermeasure::Telemetry(Arc::new(tel))))
}

/// Run the analyses of `plan` on one simulated image.
pub fn analyse_image(
    sim: &Simulator,
    index: usize,
    plan: &Plan,
) -> Result<ImageResult, ExperimentError> {
    let t0 = Instant::now();
    let exp = sim.exposure(index)?;
    let t1 = Instant::now();
    let img = AnalysisImage::from_detector(&sim.cfg, &exp.image);
    let base = Options::new(&sim.cfg.analysis);
    let mut measured = Vec::new();
    // one detection and global ePSF build, shared by every countermeasure that starts from it
    let (plain, prepared) = astrometry::analyze_prepared(&img, Some(&exp.truth), &base)?;
    let apply = |cm: &Countermeasure| {
        astrometry::with_countermeasure(&img, Some(&exp.truth), &plain, &prepared, cm)
    };
    let mut global = plain.clone();
    // the fit displacement the true ACE predicts for every star (the mechanism, shown beside the errors)
    attach_ace_prediction(sim, index, &exp.truth, &mut global, img.plate_scale_mas)?;
    for name in &plan.countermeasures {
        let report = match name.as_str() {
            "none" => global.report.clone(),
            "exact-epsf" => {
                if sim.cfg.ace.case == AceCase::Realistic {
                    continue;
                }
                let jobs = sim.jobs()?;
                let Some(j) = jobs.first() else { continue };
                let mut o = base.clone();
                o.fixed_epsf = Some(exact_epsf(&j.kernel, sim.cfg.analysis.epsf_radius_px));
                astrometry::analyze(&img, Some(&exp.truth), &o)?.report
            }
            "telemetry" => match telemetry_countermeasure(sim, exp.t_start_s, &plan.telemetry)? {
                // a static ACE has nothing to correct: the telemetry countermeasure is the plain result
                None => global.report.clone(),
                Some(cm) => apply(&cm)?.report,
            },
            other => {
                let cm = Countermeasure::parse(other, sim.cfg.analysis.epsf_zones.max(2))?
                    .with_reference_error(plan.reference_error_mas, sim.cfg.seed);
                apply(&cm)?.report
            }
        };
        measured.push(Measured {
            countermeasure: name.clone(),
            report,
        });
    }
    Ok(ImageResult {
        index,
        ace_sigma_mas: ((exp.ace.sigma_x_mas.powi(2) + exp.ace.sigma_y_mas.powi(2)) / 2.0).sqrt(),
        ace_drift_mas: exp.ace.drift_mas,
        simulate_s: (t1 - t0).as_secs_f64(),
        analyse_s: t1.elapsed().as_secs_f64(),
        measured,
        stars: (index == 0).then(|| global.stars.clone()),
    })
}

/// Summarise a dataset into one row per countermeasure.
pub fn summarise(
    cfg: &Config,
    images: &[ImageResult],
    predicted: &dyn Fn(&str) -> f64,
    time_s: f64,
) -> Vec<Row> {
    let mut names: Vec<String> = Vec::new();
    for im in images {
        for m in &im.measured {
            if !names.contains(&m.countermeasure) {
                names.push(m.countermeasure.clone());
            }
        }
    }
    names
        .iter()
        .map(|name| {
            let acc: Vec<f64> = images
                .iter()
                .flat_map(|im| {
                    im.measured
                        .iter()
                        .filter(|m| &m.countermeasure == name)
                        .map(|m| m.report.accuracy_mas)
                })
                .filter(|v| v.is_finite() && *v > 0.0)
                .collect();
            let crlb: Vec<f64> = images
                .iter()
                .flat_map(|im| {
                    im.measured
                        .iter()
                        .filter(|m| &m.countermeasure == name)
                        .map(|m| m.report.crlb_median_mas)
                })
                .collect();
            Row {
                ace: cfg.ace.case.name().into(),
                readout: cfg.readout.order.name().into(),
                countermeasure: name.clone(),
                mag: cfg.scene.mag_hw,
                accuracy_mas: stats::mean(&acc),
                sem_mas: stats::sem(&acc),
                crlb_mas: stats::median(&crlb),
                predicted_mas: predicted(name),
                n_images: acc.len(),
                time_s,
            }
        })
        .collect()
}

/// One dataset: `cfg.fidelity.images` images of `cfg`, analysed per `plan`. `on_image` is called after each.
pub fn run_dataset(
    cfg: &Config,
    plan: &Plan,
    bank: Option<Arc<PsfBank>>,
    gpu: Option<Arc<GpuIntegrator>>,
    on_image: &mut dyn FnMut(&ImageResult),
) -> Result<(Vec<Row>, Vec<ImageResult>), ExperimentError> {
    let t0 = Instant::now();
    let sim = Simulator::with_bank(
        cfg,
        bank.unwrap_or_else(|| Arc::new(PsfBank::new(cfg))),
        gpu,
    )?;
    let pred = crate::analysis::predict::Predictor::new(&sim)?;
    let mut images = Vec::with_capacity(cfg.fidelity.images);
    for i in 0..cfg.fidelity.images {
        let r = analyse_image(&sim, i, plan)?;
        on_image(&r);
        images.push(r);
    }
    let predicted = |name: &str| pred.predict(name, plan).unwrap_or(f64::NAN);
    let rows = summarise(cfg, &images, &predicted, t0.elapsed().as_secs_f64());
    Ok((rows, images))
}

/// The datasets of an experiment: every (ACE case, readout, magnitude) with the base configuration.
pub fn grid(
    base: &Config,
    aces: &[AceCase],
    readouts: &[ReadoutOrder],
    mags: &[f64],
) -> Vec<Config> {
    let mut out = Vec::new();
    for &a in aces {
        for &r in readouts {
            // readout orders make no difference to static ACE: simulate those once
            if a != AceCase::Realistic && r != readouts[0] {
                continue;
            }
            for &m in mags {
                let mut c = base.clone();
                c.ace.case = a;
                c.readout.order = r;
                c.scene.mag_hw = m;
                out.push(c);
            }
        }
    }
    out
}
