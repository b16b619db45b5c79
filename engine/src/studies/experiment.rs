//! The paper's experiment (SPEC §6, §8): datasets of images per (ACE case, readout order, magnitude), each
//! image analysed with the ePSF method and every requested countermeasure, on the same images.
//!
//! A dataset reports, per countermeasure, the mean over its images of the per-image accuracy and the
//! standard error of that mean (the paper's figure), the median Cramér–Rao bound, and the accuracy the
//! instant predictor expects ([`crate::studies::predict`]).

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::Plan;
use crate::analysis::pipeline::{self, ImageAnalysis};
use crate::config::{AceCase, Config, ReadoutOrder};
use crate::numerics::stats;
pub use crate::scoring::dataset::{ImageResult, Measured, Row};
use crate::session::{Source, analysis_image};
use crate::simulate::{SimError, Simulator, TruthRow};
use crate::studies::predict::{PredictError, Predictor};
use std::ops::ControlFlow;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A simulated exposure's analysis (the simulation's products, the pipeline).
    #[error(transparent)]
    Source(#[from] crate::session::SourceError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// The caller's progress callback asked to stop (Ctrl-C in the CLI or in Python).
    #[error("stopped")]
    Stopped,
}

/// One exposure of a stare, analysed by the pipeline; the countermeasures that need the whole stare (plate
/// models referenced to the stack) are completed by [`finish_stare`].
pub struct StareImage {
    analysis: ImageAnalysis,
    exposure: ExposureInfo,
}

/// What a stare image's report needs of its exposure besides the analysis.
struct ExposureInfo {
    index: usize,
    truth: Vec<TruthRow>,
    ace_sigma_mas: f64,
    ace_drift_mas: f64,
    simulate_s: f64,
    analyse_s: f64,
}

/// Simulate exposure `index` of `sim` and run the analysis pipeline on it under `plan`.
pub fn analyse_in_stare(
    sim: &Simulator,
    index: usize,
    plan: &Plan,
) -> Result<StareImage, ExperimentError> {
    let t0 = Instant::now();
    let exp = sim.exposure(index)?;
    let t1 = Instant::now();
    let img = analysis_image(sim, &exp.image);
    let analysis = Source::new(sim, index).analyse(
        &img,
        Some(&exp.truth),
        &sim.cfg,
        plan,
        &Default::default(),
    )?;
    Ok(StareImage {
        analysis,
        exposure: ExposureInfo {
            index,
            truth: exp.truth,
            ace_sigma_mas: ((exp.ace.sigma_x_mas.powi(2) + exp.ace.sigma_y_mas.powi(2)) / 2.0)
                .sqrt(),
            ace_drift_mas: exp.ace.drift_mas,
            simulate_s: (t1 - t0).as_secs_f64(),
            analyse_s: t1.elapsed().as_secs_f64(),
        },
    })
}

/// Finish a stare's exposures (the stack reference over all of them) and report each.
pub fn finish_stare(
    sim: &Simulator,
    plan: &Plan,
    images: Vec<StareImage>,
) -> Result<Vec<ImageResult>, ExperimentError> {
    let t0 = Instant::now();
    let (mut analyses, exposures): (Vec<ImageAnalysis>, Vec<ExposureInfo>) = images
        .into_iter()
        .map(|im| (im.analysis, im.exposure))
        .unzip();
    pipeline::finish_stare(&mut analyses, plan)?;
    // the stack's cost, shared out over the stare's images
    let stack_s = t0.elapsed().as_secs_f64() / analyses.len().max(1) as f64;
    // then each exposure scored against its truth (only here does the truth enter)
    let scale = sim.cfg.instrument.plate_scale_mas();
    let scored = analyses
        .iter()
        .zip(&exposures)
        .map(|(a, e)| Source::new(sim, e.index).score(a, &e.truth, &sim.cfg.analysis, scale))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(scored
        .into_iter()
        .zip(exposures)
        .map(|(a, e)| ImageResult {
            index: e.index,
            ace_sigma_mas: e.ace_sigma_mas,
            ace_drift_mas: e.ace_drift_mas,
            simulate_s: e.simulate_s,
            analyse_s: e.analyse_s + stack_s,
            measured: a
                .measured
                .into_iter()
                .map(|(c, a)| Measured {
                    countermeasure: c.to_string(),
                    report: a.report,
                })
                .collect(),
            stars: (e.index == 0).then_some(a.global.stars),
        })
        .collect())
}

/// Exposures `indices` of `sim` as one stare, analysed under `plan`; `on_image` is called after each
/// exposure's own analysis (before the stare is finished) and stops the stare with
/// [`ExperimentError::Stopped`] by returning `Break`.
pub fn analyse_stare(
    sim: &Simulator,
    indices: std::ops::Range<usize>,
    plan: &Plan,
    on_image: &mut dyn FnMut(usize) -> ControlFlow<()>,
) -> Result<Vec<ImageResult>, ExperimentError> {
    let mut images = Vec::with_capacity(indices.len());
    for i in indices {
        images.push(analyse_in_stare(sim, i, plan)?);
        if on_image(i).is_break() {
            return Err(ExperimentError::Stopped);
        }
    }
    finish_stare(sim, plan, images)
}

/// Exposure `index` of `sim` alone through the pipeline under `plan` (a stare of one exposure: a
/// stack-referenced plate model has nothing to correct; [`analyse_stare`] runs a stare).
pub fn analyse_exposure(
    sim: &Simulator,
    index: usize,
    plan: &Plan,
) -> Result<ImageResult, ExperimentError> {
    let mut r = analyse_stare(sim, index..index + 1, plan, &mut |_| {
        ControlFlow::Continue(())
    })?;
    Ok(r.remove(0))
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

/// One dataset: the `cfg.fidelity.images` consecutive exposures of `sim` — one stare, whose stack is the
/// reference of the stack-referenced plate models — analysed per `plan`. `on_image` is called after each
/// exposure's analysis (`Break` stops the dataset with [`ExperimentError::Stopped`]).
pub fn run_dataset(
    sim: &Simulator,
    plan: &Plan,
    on_image: &mut dyn FnMut(usize) -> ControlFlow<()>,
) -> Result<(Vec<Row>, Vec<ImageResult>), ExperimentError> {
    let t0 = Instant::now();
    let cfg = &sim.cfg;
    let pred = Predictor::new(sim, &sim.cfg.analysis)?;
    let images = analyse_stare(sim, 0..cfg.fidelity.images, plan, on_image)?;
    let mut predicted = std::collections::HashMap::new();
    for c in &plan.countermeasures {
        predicted.insert(c.to_string(), pred.predict(c)?);
    }
    let rows = summarise(
        cfg,
        &images,
        &|name| predicted.get(name).copied().unwrap_or(f64::NAN),
        t0.elapsed().as_secs_f64(),
    );
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

/// The rows as a text table (what `jsim experiment` prints).
pub fn render_table(rows: &[Row]) -> String {
    let mut s = format!(
        "{:<10} {:<13} {:<14} {:>5} {:>10} {:>7} {:>8} {:>10}\n",
        "ace", "readout", "countermeasure", "mag", "acc [mas]", "±sem", "CRLB", "predicted"
    );
    for r in rows {
        s.push_str(&format!(
            "{:<10} {:<13} {:<14} {:>5.1} {:>10.2} {:>7.2} {:>8.2} {:>10.2}\n",
            r.ace,
            r.readout,
            r.countermeasure,
            r.mag,
            r.accuracy_mas,
            r.sem_mas,
            r.crlb_mas,
            r.predicted_mas
        ));
    }
    s
}
