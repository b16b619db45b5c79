//! `jsim bench --parts forward`: the telemetry forward model's speed against its error. On realistic-ACE,
//! rolling-readout images of the bench's scene, each with its default telemetry product: the plain ePSF fit and
//! the shift correction for scale, then the forward model at each node spacing of its jitter histograms
//! (`analysis.telemetry_model_nodes_per_px`), timed per image beyond the plain fit and compared, star by star,
//! with the finest spacing (the exact setting): the rms position difference (mas), beside each setting's
//! accuracy against the truth.

use super::bench::{BenchError, BenchRow, bench_config, position_rms_mas};
use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::{Countermeasure, Plan, TelemetryQuality};
use crate::config::{AceCase, Config, ReadoutOrder};
use crate::numerics::stats;
use crate::session::{Session, Source, analysis_image};
use std::time::Instant;

/// The node spacings benchmarked; the last is the reference.
pub const NODES_PER_PX: [usize; 4] = [4, 8, 16, 64];

/// The rows of the forward model's benchmark over `images` exposures.
pub fn forward_model(
    session: &Session,
    base: &Config,
    images: usize,
) -> Result<Vec<BenchRow>, BenchError> {
    let mut c = bench_config(base);
    c.ace.case = AceCase::Realistic;
    c.readout.order = ReadoutOrder::Rolling;
    c.fidelity.images = images.max(1);
    let sim = session.new_simulator(&c)?;
    let scale = c.instrument.plate_scale_mas();
    let exposures: Vec<_> = (0..c.fidelity.images)
        .map(|i| {
            sim.exposure(i)
                .map(|e| (analysis_image(&sim, &e.image), e.truth))
        })
        .collect::<Result<_, _>>()?;
    // one analysis per setting and image: (seconds, accuracy, positions of the countermeasure's stars)
    type Run = (f64, f64, Vec<Option<(f64, f64)>>);
    let run = |cfg: &Config, cm: Countermeasure| -> Result<Vec<Run>, BenchError> {
        let plan = Plan::new(vec![cm]).map_err(AnalysisError::from)?;
        exposures
            .iter()
            .enumerate()
            .map(|(index, (img, truth))| {
                let t0 = Instant::now();
                let s = Source::new(&sim, index).analyse_scored(
                    img,
                    Some(truth),
                    cfg,
                    &plan,
                    &Default::default(),
                )?;
                let secs = t0.elapsed().as_secs_f64();
                let a = s.into_of(&cm).ok_or_else(|| AnalysisError::NotApplicable {
                    countermeasure: cm.to_string(),
                })?;
                let pos = a.stars.iter().map(|s| Some((s.x, s.y))).collect();
                Ok((secs, a.report.accuracy_mas, pos))
            })
            .collect()
    };
    let q = TelemetryQuality::DEFAULT;
    let plain = run(&c, Countermeasure::None)?;
    let plain_s = stats::mean(&plain.iter().map(|r| r.0).collect::<Vec<_>>());
    let stars = sim.stars.len();
    let row = |setting: String, runs: &[Run], reference: Option<&[Run]>| {
        let time_s = stats::mean(&runs.iter().map(|r| r.0).collect::<Vec<_>>());
        let accuracy = stats::mean(&runs.iter().map(|r| r.1).collect::<Vec<_>>());
        let astro_mas = reference.map_or(f64::NAN, |rf| {
            stats::mean(
                &runs
                    .iter()
                    .zip(rf)
                    .map(|(a, b)| position_rms_mas(&a.2, &b.2, scale))
                    .collect::<Vec<_>>(),
            )
        });
        BenchRow {
            astro_mas,
            note: format!(
                "accuracy {accuracy:.2} mas; {:.2} ms per star beyond the plain fit (mean of {} images)",
                1e3 * (time_s - plain_s) / stars.max(1) as f64,
                runs.len()
            ),
            ..BenchRow::timing(
                "telemetry forward model",
                setting,
                "cpu".into(),
                stars,
                time_s,
                "",
            )
        }
    };
    let mut runs: Vec<(usize, Vec<Run>)> = Vec::new();
    for n in NODES_PER_PX {
        let mut cfg = c.clone();
        cfg.analysis.telemetry_model_nodes_per_px = n;
        runs.push((n, run(&cfg, Countermeasure::TelemetryModel(q))?));
    }
    let reference = runs.last().map(|(_, r)| r.clone()).unwrap_or_default();
    let mut rows = vec![
        row("plain ePSF fit (none)".into(), &plain, None),
        row(
            "shift correction (telemetry)".into(),
            &run(&c, Countermeasure::Telemetry(q))?,
            None,
        ),
    ];
    for (n, r) in &runs {
        let exact = *n == NODES_PER_PX[NODES_PER_PX.len() - 1];
        rows.push(row(
            format!("1/{n} px{}", if exact { " (exact)" } else { "" }),
            r,
            Some(&reference),
        ));
    }
    Ok(rows)
}
