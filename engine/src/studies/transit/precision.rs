//! The precision study: a stare without a transit at each target magnitude, its measured scatter at a plate,
//! 1 h and 6.5 h beside the noise budget's terms, and the single-transit significance of the mission's
//! 0.3 % and 0.1 % transits (`precision.csv`, `precision.png`, `precision.json`; each stare's own outputs in
//! `hw_<mag>/`). Each magnitude's stare runs with its own seed (the configuration's plus its index), so
//! that the rows' noise is independent.
//!
//! The study resumes: each finished stare leaves its row in `hw_<mag>/row.json`, written last and whole,
//! with a fingerprint of jsim's version, the configuration and the stare it ran. A rerun into the same
//! directory takes every row whose fingerprint is the rerun's own and runs the other stares again whole (a
//! stare is not cut into pieces: it is minutes at most). The gathered files are then the same bytes as an
//! uninterrupted run's; `precision.json`'s `seconds` keep each stare's first run.

use super::budget::Budget;
use super::observe::StareError;
use super::outputs;
use super::run::{self, Detection, Precision};
use super::spec::Spec;
use crate::config::Config;
use crate::io::csv::{self, Cell};
use crate::io::plot::{self, Scale, Series};
use crate::io::{IoError, write_atomic};
use std::path::Path;

/// One magnitude's stare.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct MagRow {
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub hw: f64,
    /// The stare's seed: the configuration's plus the magnitude's index (independent noise per row).
    pub seed: u64,
    pub sub_exposures: usize,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub exposure_s: f64,
    pub measured: Precision,
    pub budget: Budget,
    pub detections: Vec<Detection>,
    #[serde(deserialize_with = "crate::io::f64_or_nan")]
    pub seconds: f64,
}

/// Errors of the study.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Stare(#[from] StareError),
    #[error(transparent)]
    Io(#[from] IoError),
}

/// Run the study over `magnitudes` and write it into `dir`.
pub fn run(
    cfg: &Config,
    spec: &Spec,
    magnitudes: &[f64],
    dir: &Path,
) -> Result<Vec<MagRow>, StudyError> {
    let stares: Vec<Spec> = magnitudes
        .iter()
        .map(|&hw| Spec {
            target_hw: hw,
            depth: 0.0,
            ..spec.clone()
        })
        .collect();
    // every magnitude checked before any runs
    for s in &stares {
        s.validate(spec.plate_s + cfg.readout.t_overhead_s)
            .map_err(StareError::Spec)?;
    }
    let mut rows = Vec::new();
    for (k, s) in stares.iter().enumerate() {
        let hw = s.target_hw;
        let mut c = cfg.clone();
        c.seed = cfg.seed.wrapping_add(k as u64);
        let stare_dir = dir.join(format!("hw_{hw}"));
        let checkpoint = stare_dir.join(ROW_NAME);
        let print = fingerprint(&c, s);
        // what a run killed while writing this stare left (the study owns its directory)
        crate::io::remove_stale_temps(&stare_dir, |_| true);
        if let Some(row) = finished(&checkpoint, &print) {
            rows.push(row);
            continue;
        }
        let t = std::time::Instant::now();
        let (obs, r) = run::run(&c, s)?;
        outputs::write(&stare_dir, &obs, &r)?;
        let row = MagRow {
            hw,
            seed: c.seed,
            sub_exposures: r.readout.sub_exposures,
            exposure_s: r.readout.exposure_s,
            measured: r.precision,
            budget: r.budget,
            detections: run::detections(spec, r.precision.hour_ppm),
            seconds: t.elapsed().as_secs_f64(),
        };
        let done = Finished {
            fingerprint: print,
            row,
        };
        write_atomic(
            &checkpoint,
            serde_json::to_string_pretty(&done)
                .unwrap_or_default()
                .as_bytes(),
        )?;
        rows.push(done.row);
    }
    crate::io::remove_stale_temps(dir, |_| true);
    write(dir, &rows)?;
    Ok(rows)
}

/// A finished stare's file in its `hw_<mag>/` directory: its row, and what it was run with.
pub const ROW_NAME: &str = "row.json";

#[derive(serde::Serialize, serde::Deserialize)]
struct Finished {
    /// [`fingerprint`] of the configuration and stare it ran.
    fingerprint: String,
    row: MagRow,
}

/// SHA-256 (hex) over jsim's version and the JSON of the stare's configuration (its seed included) and its
/// spec: a rerun with anything changed, or by another jsim, runs the stare again.
fn fingerprint(cfg: &Config, spec: &Spec) -> String {
    let mut bytes = crate::VERSION.as_bytes().to_vec();
    bytes.push(0);
    bytes.extend(serde_json::to_vec(cfg).unwrap_or_default());
    bytes.push(0);
    bytes.extend(serde_json::to_vec(spec).unwrap_or_default());
    crate::digest::sha256_hex(&bytes)
}

/// The row a finished stare left at `path`, if it is there, whole and of this `fingerprint` (anything else:
/// the stare runs again).
fn finished(path: &Path, fingerprint: &str) -> Option<MagRow> {
    let bytes = std::fs::read(path).ok()?;
    let done: Finished = serde_json::from_slice(&bytes).ok()?;
    (done.fingerprint == fingerprint).then_some(done.row)
}

fn write(dir: &Path, rows: &[MagRow]) -> Result<(), IoError> {
    crate::io::ensure_dir(dir)?;
    let header = [
        "hw",
        "seed",
        "sub_exposures",
        "exposure_s",
        "plate_ppm",
        "hour_ppm",
        "six_and_half_hours_ppm",
        "six_and_half_measured",
        "budget_plate_ppm",
        "budget_hour_ppm",
        "budget_six_and_half_hours_ppm",
        "photon_hour_ppm",
        "read_hour_ppm",
        "jitter_hour_ppm",
        "flat_hour_ppm",
        "drift_hour_ppm",
        "snr_0.3pct",
        "snr_0.1pct",
    ];
    let table: Vec<Vec<Cell>> = rows
        .iter()
        .map(|r| {
            let h = &r.budget.hour;
            vec![
                Cell::F(r.hw),
                Cell::S(r.seed.to_string()), // unsigned: a u64 seed ≥ 2⁶³ is no i64
                Cell::I(r.sub_exposures as i64),
                Cell::F(r.exposure_s),
                Cell::F(r.measured.plate_ppm),
                Cell::F(r.measured.hour_ppm),
                Cell::F(r.measured.six_and_half_hours_ppm),
                Cell::I(i64::from(r.measured.six_and_half_measured)),
                Cell::F(r.budget.plate.total_ppm()),
                Cell::F(h.total_ppm()),
                Cell::F(r.budget.six_and_half_hours.total_ppm()),
                Cell::F(h.photon_ppm),
                Cell::F(h.read_ppm),
                Cell::F(h.jitter_ppm),
                Cell::F(h.flat_ppm),
                Cell::F(h.drift_ppm),
                Cell::F(r.detections[0].snr),
                Cell::F(r.detections[1].snr),
            ]
        })
        .collect();
    csv::write(
        &dir.join(crate::io::products::files::PRECISION_CSV),
        &header,
        &table,
    )?;
    write_atomic(
        &dir.join(crate::io::products::files::PRECISION_JSON),
        serde_json::to_string_pretty(rows)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    let hw: Vec<f64> = rows.iter().map(|r| r.hw).collect();
    let line = |label: &str, y: Vec<f64>| Series {
        label: label.into(),
        x: hw.clone(),
        y,
        yerr: None,
        yerr_below: None,
    };
    let hour = |f: fn(&MagRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    plot::line_plot(
        &dir.join(crate::io::products::files::PRECISION_PNG),
        "1-h scatter of the differential light curve",
        "target Hw (mag)",
        "ppm in 1 h",
        &[
            line("measured", hour(|r| r.measured.hour_ppm)),
            line("budget total", hour(|r| r.budget.hour.total_ppm())),
            line("photon", hour(|r| r.budget.hour.photon_ppm)),
            line("read+dark", hour(|r| r.budget.hour.read_ppm)),
            line("jitter x intra-pixel", hour(|r| r.budget.hour.jitter_ppm)),
            line("flat residual", hour(|r| r.budget.hour.flat_ppm)),
            line("drift", hour(|r| r.budget.hour.drift_ppm)),
        ],
        &[
            (3000.0 / 7.1, "0.3 % at 7.1σ in 1 h".into()),
            (1000.0 / 7.1, "0.1 % at 7.1σ in 1 h".into()),
        ],
        Scale::Linear,
        Scale::Log,
    )?;
    Ok(())
}

/// The study as a text table.
pub fn table_lines(rows: &[MagRow]) -> Vec<String> {
    let mut out = vec![format!(
        "{:>5} {:>4} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7} {:>7}",
        "Hw",
        "n",
        "plate",
        "1 h",
        "budget",
        "6.5 h",
        "budget",
        "photon",
        "read",
        "jitter",
        "flat",
        "drift",
        "0.3%σ",
        "0.1%σ"
    )];
    for r in rows {
        let h = &r.budget.hour;
        out.push(format!(
            "{:>5.1} {:>4} {:>8.0} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>7.1} {:>7.1} {:>7.1} {:>7.1} {:>7.1} {:>7.1} {:>7.1}",
            r.hw,
            r.sub_exposures,
            r.measured.plate_ppm,
            r.measured.hour_ppm,
            h.total_ppm(),
            r.measured.six_and_half_hours_ppm,
            r.budget.six_and_half_hours.total_ppm(),
            h.photon_ppm,
            h.read_ppm,
            h.jitter_ppm,
            h.flat_ppm,
            h.drift_ppm,
            r.detections[0].snr,
            r.detections[1].snr
        ));
    }
    out.push("ppm; n: sub-exposures co-added per plate; σ: one transit's significance from the measured 1-h scatter".into());
    out
}
