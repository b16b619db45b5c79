//! Monte Carlo parameter sweeps: many single exposures per point of a parameter grid, sharded across
//! processes or cluster jobs, resumable, merged and reported as the fraction of exposures that meet an
//! accuracy threshold with a binomial confidence interval.
//!
//! The question this answers is statistical: *for this ACE spectrum, σ and readout order, what fraction
//! of single exposures reaches 4 mas at Hw 12.5, and with what confidence?*
//!
//! # The sweep file
//!
//! ```toml
//! name = "quick"                  # a label (optional)
//! seed = 2024                     # sweep seed: every unit's seed derives from it and the unit index
//! exposures = 4                   # exposures (work units) per grid point; raise it later to extend a sweep
//! countermeasures = ["none", "plate-poly:3", "telemetry"]   # default ["none"]
//! threshold_mas = 4.0             # default threshold of `jsim report` (default 4)
//! common_random_numbers = false   # true: exposure e of every point uses the same seed (paired comparison)
//!
//! # The base configuration: an inline [base] table as here, or a path, `base = "my_config.toml"` (relative
//! # to this file); absent = the built-in reference experiment (`jsim config --print-default`).
//! [base.scene]
//! grid_n = 5
//!
//! [set]                           # optional dotted overrides applied to the base (handy with a path base)
//! "scene.mag_hw" = 12.5
//!
//! [grid]                          # the grid: any config field by dotted path, a list of values each
//! "ace.sigma_mas" = [150, 300]
//! "readout.order" = ["rolling", "sample-hold"]
//! "ace.modes.0.amplitude" = [1e-2, 2e-2]   # array elements by index
//!
//! [telemetry]                     # optional: quality of the `telemetry` countermeasure, plate-model reference error
//! noise_mas = 0.0
//! rate_hz = 1000.0
//! latency_s = 0.0
//! reference_error_mas = 0.0
//! ```
//!
//! Grid keys may be written quoted (`"ace.sigma_mas" = [...]`) or as TOML dotted keys (`ace.sigma_mas = [...]`
//! under `[grid]`); both name the same field. Every value goes through [`Config::with_override`], so unknown
//! fields and out-of-range values are errors naming the field. `seed` and `fidelity.images` cannot be swept:
//! each unit sets them. The grid is the Cartesian product of the parameters taken **in field-name order**
//! (sorted, independent of the order in the file), the first parameter varying slowest; `DIR/points.csv`
//! lists the points and `DIR/points/point-NNN.toml` holds each point's full configuration.
//!
//! # Work units and reproducibility
//!
//! With P grid points and E exposures per point there are P·E work units. Unit `u` is exposure `u / P` of
//! point `u % P` (exposure-major, so raising `exposures` later appends units and leaves the existing ones,
//! and their results, unchanged). Each unit simulates image 0 of a one-image dataset of its point's
//! configuration with `seed = derive_seed(sweep seed, [Stream::Sweep, u])` (with `common_random_numbers`,
//! `u / P` instead of `u`), analyses it with every countermeasure, and predicts its accuracy with the instant
//! predictor. Its random streams therefore depend only on (sweep seed, unit index): results do not depend on
//! how units are split across processes, threads or machines (on the CPU backend; a GPU integrates in single
//! precision, so pin `fidelity.backend = "cpu"` in the base for bit-reproducible sweeps). PSFs are computed
//! on one thread ([`Session::warm`]) so that neither `RAYON_NUM_THREADS` nor `--jobs` changes a bit of the output.
//! `--jobs J` computes J units at once in one process; `--max-units K` stops after K new units (a chunk
//! that fits a time limit; rerun to continue).
//!
//! # Shards
//!
//! `--shard i/N` (0-based, `0 ≤ i < N`) runs only the units with `u mod N == i` (round-robin, so every
//! shard gets a mix of grid points and similar run time). Without `--shard` a process runs `0/1`, all
//! units. Shards of one sweep may use different N: a process skips units already recorded in *any* shard
//! file of the directory, and `merge` drops identical duplicates.
//!
//! # Output directory
//!
//! ```text
//! DIR/sweep.json                       the sweep's identity (hash), grid, countermeasures, base config
//! DIR/points.csv, DIR/points/*.toml    the grid points and their configurations
//! DIR/shards/shard-IIII-of-NNNN.csv    one row per (unit, countermeasure), rewritten atomically after each unit
//! DIR/shards/shard-IIII-of-NNNN.json   sidecar: sweep hash, row count, SHA-256 of the CSV (written after it)
//! DIR/shards/shard-IIII-of-NNNN.lock   advisory lock: one process per shard at a time
//! DIR/merged.csv, DIR/merged.json      `jsim merge`: all units sorted by unit index
//! DIR/report.csv, DIR/report/*.png     `jsim report`: fractions with 95 % Wilson intervals, distributions
//! ```
//!
//! Columns of the shard and merged CSVs: `unit, point, exposure`, one column per grid parameter (named by
//! its dotted path), `countermeasure, status, accuracy_mas, accuracy_x_mas, accuracy_y_mas, bias_x_mas,
//! bias_y_mas, crlb_mas, predicted_mas, n_used, ace_sigma_mas, ace_drift_mas, seed`, then the timing
//! columns [`TIMING_COLUMNS`] (`simulate_s, analyse_s, predict_s, unit_s`) and, in shard files only, `check`
//! (a per-row checksum). Everything before `simulate_s` is deterministic; [`without_timing`] strips the rest.
//! `accuracy_x_mas`/`accuracy_y_mas` are the standard deviations over the stars of measured − true position per
//! axis, `accuracy_mas = √((σx² + σy²)/2)` (per axis), `bias_*` their means, `crlb_mas` the median Cramér–Rao
//! bound, `predicted_mas` the instant predictor's expectation for this exposure ([`crate::analysis::predict`]),
//! `ace_sigma_mas`/`ace_drift_mas` the exposure's jitter σ and drift, `seed` the unit's master seed.
//! `status` is `ok`, `not applicable` (e.g. `exact-epsf` with a realistic ACE) or `error: …` (the analysis
//! failed for that exposure; its accuracy is NaN and counts as *not* meeting the threshold).
//!
//! # Resuming and corruption
//!
//! Rerunning the same command skips finished units. A shard file whose SHA-256 or row count disagrees with
//! its sidecar (a truncated or edited file, or a crash between the two renames) is salvaged row by row:
//! every row carries a checksum of its text and the sweep hash, and only units whose rows are all present
//! and verified are kept; the rest are redone. An output directory that holds another sweep (a different
//! hash in `sweep.json`) is refused before anything is written. The hash covers the seed, the base
//! configuration, the grid, the countermeasures and the telemetry settings, but not `exposures`,
//! `threshold_mas` or `name`.
//!
//! # Merge and report
//!
//! `jsim merge DIR` verifies every shard file, writes `DIR/merged.csv` (all units, sorted by unit index,
//! without `check`) and `DIR/merged.json` (its SHA-256, counts). It refuses shard files of another sweep
//! (`mixed sweeps`), names missing units and exits non-zero (`--allow-missing` merges what is there), reports
//! units recorded in more than one shard file (identical apart from timing: one is kept; different: an error).
//!
//! `jsim report DIR [--threshold-mas T] [--metric accuracy_mas|accuracy_x_mas|accuracy_y_mas] [--x FIELD]`
//! writes `DIR/report.csv`: per grid point and countermeasure the number of exposures n, those meeting the
//! threshold k, the fraction k/n with its 95 % Wilson score interval, mean/median/90th percentile of the
//! accuracy, the median CRLB and the predictor's mean and fraction; `DIR/report/dist_pNNN_<cm>.png`, the
//! histogram and empirical CDF of each point's accuracies with the threshold marked; and
//! `DIR/report/fraction.png`, the fraction against the swept numeric parameter (`--x`, default the first with
//! several values; else the point index), one curve per countermeasure and value of the other parameters.
//! The bars there are the Wilson intervals, drawn about their centres (`plot::Series` has symmetric bars
//! only), and curves sharing an x are offset by ±1 % of the x range so that their bars stay visible.
//!
//! # On a Slurm cluster
//!
//! ```text
//! jsim sweep --config study.toml --out /scratch/study --emit-slurm --shards 64 \
//!            --partition normal --time 04:00:00 [--cpus-per-task 1] [--jsim /path/to/jsim]
//! /scratch/study/slurm/submit.sh [extra sbatch options, e.g. --account=proj]
//! ```
//!
//! writes `DIR/slurm/array.sbatch` (a job array, task `i` runs `jsim sweep --config S --out DIR --shard i/N`),
//! `DIR/slurm/merge.sbatch` (`jsim merge DIR` then `jsim report DIR`) and `DIR/slurm/submit.sh`, which submits
//! the array with `sbatch --parsable` and then the merge job with `--dependency=afterok:<array job id>
//! --kill-on-invalid-dep=yes`, and records the job ids in `DIR/slurm/{array,merge}.jobid`. Logs go to
//! `DIR/slurm/logs/`. If a task fails, times out or is cancelled, the merge job is dropped; run `submit.sh`
//! again: finished units are skipped, so only the missing work is done. The output directory must be on a
//! file system the compute nodes share.

use crate::analysis::countermeasures::{DEFAULT_TELEMETRY_RATE_HZ, Plan, TelemetryQuality};
use crate::config::{Config, ConfigError};
use crate::io::{self, IoError, plot};
use crate::numerics::stats;
use crate::rng::{self, Stream};
use crate::session::Session;
use crate::studies::experiment;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// Format tag of `sweep.json`.
pub const FORMAT: &str = "jsim-sweep/1";
/// Format tag of a shard sidecar.
pub const SHARD_FORMAT: &str = "jsim-sweep-shard/1";
/// z of a two-sided 95 % interval.
pub const Z95: f64 = 1.959_963_984_540_054;

/// Leading columns of the unit CSVs (before the grid parameters).
pub const HEAD_COLUMNS: [&str; 3] = ["unit", "point", "exposure"];
/// Result columns (after the grid parameters), deterministic.
pub const RESULT_COLUMNS: [&str; 13] = [
    "countermeasure",
    "status",
    "accuracy_mas",
    "accuracy_x_mas",
    "accuracy_y_mas",
    "bias_x_mas",
    "bias_y_mas",
    "crlb_mas",
    "predicted_mas",
    "n_used",
    "ace_sigma_mas",
    "ace_drift_mas",
    "seed",
];
/// Timing columns: always last (before `check` in shard files), excluded from reproducibility comparisons.
pub const TIMING_COLUMNS: [&str; 4] = ["simulate_s", "analyse_s", "predict_s", "unit_s"];
/// Accuracy columns `jsim report` can threshold.
pub const METRICS: [&str; 3] = ["accuracy_mas", "accuracy_x_mas", "accuracy_y_mas"];

/// A sweep problem, always naming the file, field, unit or directory at fault.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("sweep file {path}: {message}")]
    File { path: PathBuf, message: String },
    #[error("sweep file {path}: grid parameter `{field}`: {message}")]
    Grid {
        path: PathBuf,
        field: String,
        message: String,
    },
    #[error("--shard {spec}: {message}")]
    Shard { spec: String, message: String },
    #[error(
        "output directory {dir} holds another sweep (hash {found} in sweep.json; this sweep is {expected}): choose another --out or remove that directory"
    )]
    OtherSweep {
        dir: PathBuf,
        found: String,
        expected: String,
    },
    #[error(
        "{dir} is not a sweep directory (no readable sweep.json: {message}); run `jsim sweep` first"
    )]
    NotASweep { dir: PathBuf, message: String },
    #[error("mixed sweeps in {dir}: {message}")]
    Mixed { dir: PathBuf, message: String },
    #[error(
        "{missing} of {total} units are missing: {list}. Rerun `jsim sweep` with the same arguments (or resubmit) to compute them"
    )]
    Missing {
        missing: usize,
        total: usize,
        list: String,
        units: Vec<usize>,
    },
    #[error("unit {unit} (point {point}, exposure {exposure}): {message}")]
    Unit {
        unit: usize,
        point: usize,
        exposure: usize,
        message: String,
    },
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Io(#[from] IoError),
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
}

fn io_err(path: &Path, e: std::io::Error) -> SweepError {
    SweepError::Io(IoError::io(path, e))
}

// ---------------------------------------------------------------------------------------------------------
// The sweep file
// ---------------------------------------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    name: Option<String>,
    seed: u64,
    exposures: i64,
    countermeasures: Option<Vec<String>>,
    threshold_mas: Option<f64>,
    common_random_numbers: Option<bool>,
    telemetry: Option<TelemetryFile>,
    base: Option<toml::Value>,
    set: Option<toml::Table>,
    grid: Option<toml::Table>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct TelemetryFile {
    noise_mas: Option<f64>,
    rate_hz: Option<f64>,
    latency_s: Option<f64>,
    reference_error_mas: Option<f64>,
}

/// One swept field and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Dotted config path (`ace.sigma_mas`).
    pub field: String,
    /// Each value as TOML (what [`Config::with_override`] receives).
    pub toml: Vec<String>,
    /// Each value as written in the CSV columns (strings unquoted).
    pub display: Vec<String>,
}

/// One grid point.
#[derive(Debug, Clone)]
pub struct Point {
    pub index: usize,
    /// Display values, one per [`Param`].
    pub values: Vec<String>,
    /// The point's configuration (`fidelity.images = 1`; the seed is set per unit).
    pub config: Config,
}

/// A parsed, validated sweep.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub name: String,
    pub source: PathBuf,
    pub seed: u64,
    pub exposures: usize,
    pub countermeasures: Vec<String>,
    pub threshold_mas: f64,
    pub common_random_numbers: bool,
    pub plan: Plan,
    /// The telemetry quality and plate reference error of the plan (recorded in `sweep.json`).
    pub telemetry: TelemetryQuality,
    pub reference_error_mas: f64,
    /// The base configuration after `[set]`.
    pub base: Config,
    /// Swept fields, sorted by name.
    pub params: Vec<Param>,
    pub points: Vec<Point>,
    /// 16 hex digits identifying the sweep (see the module docs for what it covers).
    pub hash: String,
}

/// Flatten nested TOML tables into dotted paths; `leaf` decides where to stop.
fn flatten(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
    for (k, v) in t {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(sub) => flatten(&path, sub, out),
            other => out.push((path, other.clone())),
        }
    }
}

/// How a grid value appears in the CSV: strings bare, numbers as Rust prints them, others as inline TOML.
fn display_value(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => f.to_string(),
        toml::Value::Boolean(b) => b.to_string(),
        other => other.to_string(),
    }
}

fn config_error_text(e: &ConfigError) -> String {
    match e {
        ConfigError::Parse { message, .. } => message.trim().to_string(),
        other => other.to_string(),
    }
}

impl Sweep {
    /// Read and validate a sweep file.
    pub fn load(path: &Path) -> Result<Sweep, SweepError> {
        let text = std::fs::read_to_string(path).map_err(|e| SweepError::File {
            path: path.to_path_buf(),
            message: format!("cannot read it: {e}"),
        })?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Self::from_toml_str(&text, path, dir)
    }

    /// Parse and validate sweep text; `source` names it in errors, `base_dir` resolves a relative `base` path.
    pub fn from_toml_str(text: &str, source: &Path, base_dir: &Path) -> Result<Sweep, SweepError> {
        let ferr = |message: String| SweepError::File {
            path: source.to_path_buf(),
            message,
        };
        let f: SweepFile =
            toml::from_str(text).map_err(|e| ferr(e.to_string().trim().to_string()))?;
        if f.exposures < 1 {
            return Err(ferr(format!(
                "`exposures` = {}: must be ≥ 1 (exposures per grid point)",
                f.exposures
            )));
        }
        let exposures = f.exposures as usize;
        if exposures > 100_000_000 {
            return Err(ferr(format!("`exposures` = {exposures}: must be ≤ 1e8")));
        }
        let threshold_mas = f.threshold_mas.unwrap_or(4.0);
        if !(threshold_mas > 0.0) || !threshold_mas.is_finite() {
            return Err(ferr(format!(
                "`threshold_mas` = {threshold_mas}: must be a finite number > 0"
            )));
        }

        // countermeasures: one plan, validated where every plan is
        let names = f.countermeasures.unwrap_or_else(|| vec!["none".into()]);
        let t = f.telemetry.unwrap_or_default();
        let telemetry = TelemetryQuality {
            noise_mas: t.noise_mas.unwrap_or(0.0),
            rate_hz: t.rate_hz.unwrap_or(DEFAULT_TELEMETRY_RATE_HZ),
            latency_s: t.latency_s.unwrap_or(0.0),
        };
        let reference_error_mas = t.reference_error_mas.unwrap_or(0.0);
        let plan = Plan::parse(&names, telemetry, reference_error_mas)
            .map_err(|e| ferr(format!("`countermeasures`/`[telemetry]`: {e}")))?;
        let countermeasures = plan.names();

        // base configuration
        let mut base = match &f.base {
            None => Config::default(),
            Some(toml::Value::String(p)) => {
                let p = Path::new(p);
                let full = if p.is_absolute() {
                    p.to_path_buf()
                } else {
                    base_dir.join(p)
                };
                Config::load(&full).map_err(|e| ferr(format!("base config: {e}")))?
            }
            Some(toml::Value::Table(t)) => {
                let text = toml::to_string(t).map_err(|e| ferr(format!("[base]: {e}")))?;
                Config::from_toml_str(&text)
                    .map_err(|e| ferr(format!("[base]: {}", config_error_text(&e))))?
            }
            Some(_) => {
                return Err(ferr(
                    "`base` must be a config file path (string) or a [base] table".into(),
                ));
            }
        };
        if let Some(set) = &f.set {
            let mut leaves = Vec::new();
            flatten("", set, &mut leaves);
            for (field, v) in leaves {
                base = base
                    .with_override(&field, &v.to_string())
                    .map_err(|e| ferr(format!("[set] `{field}`: {}", config_error_text(&e))))?;
            }
        }

        // grid
        let grid = f.grid.unwrap_or_default();
        let mut leaves = Vec::new();
        flatten("", &grid, &mut leaves);
        if leaves.is_empty() {
            return Err(ferr(
                "the grid is empty: give at least one parameter, e.g. [grid] \"ace.sigma_mas\" = [150, 300]"
                    .into(),
            ));
        }
        leaves.sort_by(|a, b| a.0.cmp(&b.0));
        let mut params = Vec::new();
        for (field, v) in leaves {
            let toml::Value::Array(values) = v else {
                return Err(ferr(format!(
                    "grid parameter `{field}` must be a list of values, e.g. `{field} = [a, b]`"
                )));
            };
            if values.is_empty() {
                return Err(ferr(format!("grid parameter `{field}` has no values")));
            }
            if field == "seed" || field == "fidelity.images" {
                return Err(ferr(format!(
                    "grid parameter `{field}` cannot be swept: every unit sets it (the seed from the sweep seed and the unit index, one image per unit); use `exposures` and `seed`"
                )));
            }
            let display: Vec<String> = values.iter().map(display_value).collect();
            for (k, d) in display.iter().enumerate() {
                if display[..k].contains(d) {
                    return Err(ferr(format!(
                        "grid parameter `{field}` lists the value {d} twice"
                    )));
                }
            }
            params.push(Param {
                field,
                toml: values.iter().map(|v| v.to_string()).collect(),
                display,
            });
        }
        let n_points: usize = params.iter().map(|p| p.toml.len()).product();
        if n_points > 1_000_000 {
            return Err(ferr(format!("the grid has {n_points} points: at most 1e6")));
        }
        let mut points = Vec::with_capacity(n_points);
        for index in 0..n_points {
            // first parameter slowest
            let mut rem = index;
            let mut idx = vec![0; params.len()];
            for (k, p) in params.iter().enumerate().rev() {
                idx[k] = rem % p.toml.len();
                rem /= p.toml.len();
            }
            let mut cfg = base.clone();
            for (k, p) in params.iter().enumerate() {
                cfg =
                    cfg.with_override(&p.field, &p.toml[idx[k]])
                        .map_err(|e| SweepError::Grid {
                            path: source.to_path_buf(),
                            field: p.field.clone(),
                            message: config_error_text(&e).replace('\n', " ").trim().to_string(),
                        })?;
            }
            cfg.fidelity.images = 1;
            cfg.validate().map_err(|e| {
                ferr(format!(
                    "grid point {index} ({}): {e}",
                    describe(&params, &idx)
                ))
            })?;
            points.push(Point {
                index,
                values: params
                    .iter()
                    .zip(&idx)
                    .map(|(p, &i)| p.display[i].clone())
                    .collect(),
                config: cfg,
            });
        }

        let common_random_numbers = f.common_random_numbers.unwrap_or(false);
        let mut canon = String::new();
        let _ = writeln!(canon, "{FORMAT}");
        let _ = writeln!(canon, "seed={}", f.seed);
        let _ = writeln!(canon, "common_random_numbers={common_random_numbers}");
        let _ = writeln!(canon, "countermeasures={}", countermeasures.join(";"));
        let _ = writeln!(
            canon,
            "telemetry={:?},{:?},{:?},{:?}",
            telemetry.noise_mas, telemetry.rate_hz, telemetry.latency_s, reference_error_mas
        );
        for p in &params {
            let _ = writeln!(canon, "grid {}={}", p.field, p.toml.join(" ; "));
        }
        let _ = writeln!(canon, "base:\n{}", base.to_toml());
        let hash = sha256_hex(canon.as_bytes())[..16].to_string();

        Ok(Sweep {
            name: f.name.unwrap_or_else(|| {
                source
                    .file_stem()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_else(|| "sweep".into())
            }),
            source: source.to_path_buf(),
            seed: f.seed,
            exposures,
            plan,
            telemetry,
            reference_error_mas,
            countermeasures,
            threshold_mas,
            common_random_numbers,
            base,
            params,
            points,
            hash,
        })
    }

    /// Number of grid points.
    pub fn n_points(&self) -> usize {
        self.points.len()
    }

    /// Number of work units (points × exposures).
    pub fn n_units(&self) -> usize {
        self.points.len() * self.exposures
    }

    /// (point, exposure) of unit `u`.
    pub fn unit(&self, u: usize) -> (usize, usize) {
        (u % self.points.len(), u / self.points.len())
    }

    /// The master seed of unit `u`.
    pub fn unit_seed(&self, u: usize) -> u64 {
        let k = if self.common_random_numbers {
            u / self.points.len()
        } else {
            u
        };
        rng::derive_seed(self.seed, &[Stream::Sweep as u64, k as u64])
    }

    /// The configuration of unit `u` (its point's, with the unit's seed and one image).
    pub fn unit_config(&self, u: usize) -> Config {
        let mut c = self.points[u % self.points.len()].config.clone();
        c.seed = self.unit_seed(u);
        c.fidelity.images = 1;
        c
    }

    /// The identity record written to `DIR/sweep.json`.
    pub fn record(&self) -> Record {
        Record {
            format: FORMAT.into(),
            hash: self.hash.clone(),
            name: self.name.clone(),
            seed: self.seed,
            exposures: self.exposures,
            points: self.points.len(),
            countermeasures: self.countermeasures.clone(),
            threshold_mas: self.threshold_mas,
            common_random_numbers: self.common_random_numbers,
            grid: self
                .params
                .iter()
                .map(|p| RecordParam {
                    field: p.field.clone(),
                    values: p.display.clone(),
                })
                .collect(),
            point_values: self.points.iter().map(|p| p.values.clone()).collect(),
            telemetry: RecordTelemetry {
                noise_mas: self.telemetry.noise_mas,
                rate_hz: self.telemetry.rate_hz,
                latency_s: self.telemetry.latency_s,
                reference_error_mas: self.reference_error_mas,
            },
            base_config: self.base.to_toml(),
            engine_version: crate::VERSION.into(),
        }
    }
}

fn describe(params: &[Param], idx: &[usize]) -> String {
    params
        .iter()
        .zip(idx)
        .map(|(p, &i)| format!("{} = {}", p.field, p.display[i]))
        .collect::<Vec<_>>()
        .join(", ")
}

// ---------------------------------------------------------------------------------------------------------
// The record (sweep.json)
// ---------------------------------------------------------------------------------------------------------

/// A swept field in `sweep.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordParam {
    pub field: String,
    pub values: Vec<String>,
}

/// Telemetry settings in `sweep.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordTelemetry {
    pub noise_mas: f64,
    pub rate_hz: f64,
    pub latency_s: f64,
    pub reference_error_mas: f64,
}

/// What `DIR/sweep.json` holds: everything `merge` and `report` need.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub format: String,
    pub hash: String,
    pub name: String,
    pub seed: u64,
    pub exposures: usize,
    pub points: usize,
    pub countermeasures: Vec<String>,
    pub threshold_mas: f64,
    pub common_random_numbers: bool,
    pub grid: Vec<RecordParam>,
    pub point_values: Vec<Vec<String>>,
    pub telemetry: RecordTelemetry,
    pub base_config: String,
    pub engine_version: String,
}

impl Record {
    pub fn n_units(&self) -> usize {
        self.points * self.exposures
    }

    /// Column names of the unit CSVs (`check` last when `with_check`).
    pub fn header(&self, with_check: bool) -> Vec<String> {
        let mut h: Vec<String> = HEAD_COLUMNS.iter().map(|s| s.to_string()).collect();
        h.extend(self.grid.iter().map(|p| p.field.clone()));
        h.extend(RESULT_COLUMNS.iter().map(|s| s.to_string()));
        h.extend(TIMING_COLUMNS.iter().map(|s| s.to_string()));
        if with_check {
            h.push("check".into());
        }
        h
    }

    fn col(&self, name: &str) -> usize {
        self.header(false)
            .iter()
            .position(|h| h == name)
            .unwrap_or(usize::MAX)
    }

    /// Index of the first timing column (everything before it is deterministic).
    pub fn first_timing_column(&self) -> usize {
        HEAD_COLUMNS.len() + self.grid.len() + RESULT_COLUMNS.len()
    }
}

/// Read `DIR/sweep.json`.
pub fn read_record(dir: &Path) -> Result<Record, SweepError> {
    let path = dir.join("sweep.json");
    let text = std::fs::read_to_string(&path).map_err(|e| SweepError::NotASweep {
        dir: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let r: Record = serde_json::from_str(&text).map_err(|e| SweepError::NotASweep {
        dir: dir.to_path_buf(),
        message: format!("{}: {e}", path.display()),
    })?;
    if r.format != FORMAT {
        return Err(SweepError::NotASweep {
            dir: dir.to_path_buf(),
            message: format!("format `{}`, expected `{FORMAT}`", r.format),
        });
    }
    if r.points == 0 || r.point_values.len() != r.points || r.countermeasures.is_empty() {
        return Err(SweepError::NotASweep {
            dir: dir.to_path_buf(),
            message: format!("{} is inconsistent", path.display()),
        });
    }
    Ok(r)
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn to_json(v: &impl Serialize) -> String {
    let mut s =
        serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    s.push('\n');
    s
}

/// Check that `dir` can hold `sweep` (empty, absent, or the same sweep) without writing anything.
pub fn check_dir(sweep: &Sweep, dir: &Path) -> Result<(), SweepError> {
    let rec_path = dir.join("sweep.json");
    if rec_path.exists() {
        let found = match read_record(dir) {
            Ok(r) => r.hash,
            Err(_) => "unreadable".to_string(),
        };
        if found != sweep.hash {
            return Err(SweepError::OtherSweep {
                dir: dir.to_path_buf(),
                found,
                expected: sweep.hash.clone(),
            });
        }
    } else if dir.join("shards").exists() {
        return Err(SweepError::OtherSweep {
            dir: dir.to_path_buf(),
            found: "unknown (shards/ without sweep.json)".into(),
            expected: sweep.hash.clone(),
        });
    }
    Ok(())
}

/// Create the output directory and write the sweep's record and points (after [`check_dir`]).
pub fn prepare_dir(sweep: &Sweep, dir: &Path) -> Result<(), SweepError> {
    check_dir(sweep, dir)?;
    io::ensure_dir(&dir.join("shards"))?;
    io::ensure_dir(&dir.join("points"))?;
    let rec = sweep.record();
    let rec_path = dir.join("sweep.json");
    let current = read_record(dir).ok();
    if current.as_ref() != Some(&rec) {
        io::write_atomic(&rec_path, to_json(&rec).as_bytes())?;
    }
    let mut header: Vec<String> = vec!["point".into()];
    header.extend(sweep.params.iter().map(|p| p.field.clone()));
    header.push("config_hash".into());
    let mut text = render_line(&header);
    text.push('\n');
    for p in &sweep.points {
        let mut cells = vec![p.index.to_string()];
        cells.extend(p.values.iter().cloned());
        cells.push(p.config.hash_hex());
        text.push_str(&render_line(&cells));
        text.push('\n');
        let path = dir
            .join("points")
            .join(format!("point-{:03}.toml", p.index));
        let body = format!(
            "# grid point {} of sweep {} ({}): {}\n# unit seeds are set per exposure; reproduce unit u with `jsim simulate --config {} --seed <seed column>`\n{}",
            p.index,
            sweep.name,
            sweep.hash,
            describe_values(&sweep.params, &p.values),
            path.display(),
            p.config.to_toml()
        );
        if std::fs::read_to_string(&path).ok().as_deref() != Some(body.as_str()) {
            io::write_atomic(&path, body.as_bytes())?;
        }
    }
    let points_csv = dir.join("points.csv");
    if std::fs::read_to_string(&points_csv).ok().as_deref() != Some(text.as_str()) {
        io::write_atomic(&points_csv, text.as_bytes())?;
    }
    Ok(())
}

fn describe_values(params: &[Param], values: &[String]) -> String {
    params
        .iter()
        .zip(values)
        .map(|(p, v)| format!("{} = {v}", p.field))
        .collect::<Vec<_>>()
        .join(", ")
}

// ---------------------------------------------------------------------------------------------------------
// CSV text: quoting, parsing, per-row checks
// ---------------------------------------------------------------------------------------------------------

fn quote(s: &str) -> String {
    if s.contains(',') || s.contains('"') || s.contains('\n') || s.contains('\r') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// One CSV line from cells (RFC 4180 quoting).
pub fn render_line(cells: &[String]) -> String {
    cells.iter().map(|c| quote(c)).collect::<Vec<_>>().join(",")
}

/// Split one CSV line into cells (RFC 4180 quotes); `None` for a malformed line.
pub fn parse_line(line: &str) -> Option<Vec<String>> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut chars = line.chars().peekable();
    let mut quoted = false;
    let mut at_start = true;
    while let Some(c) = chars.next() {
        if quoted {
            if c == '"' {
                if chars.peek() == Some(&'"') {
                    cur.push('"');
                    chars.next();
                } else {
                    quoted = false;
                    match chars.peek() {
                        None | Some(',') => {}
                        Some(_) => return None,
                    }
                }
            } else {
                cur.push(c);
            }
        } else if c == ',' {
            out.push(std::mem::take(&mut cur));
            at_start = true;
            continue;
        } else if c == '"' && at_start {
            quoted = true;
        } else if c == '"' {
            return None;
        } else {
            cur.push(c);
        }
        at_start = false;
    }
    if quoted {
        return None;
    }
    out.push(cur);
    Some(out)
}

fn row_check(hash: &str, line: &str) -> String {
    let mut h = Sha256::new();
    h.update(hash.as_bytes());
    h.update(b"\n");
    h.update(line.as_bytes());
    h.finalize()
        .iter()
        .take(8)
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A CSV's text with the timing columns (and `check`) removed: what must be identical between runs.
pub fn without_timing(csv_text: &str) -> String {
    let mut lines = csv_text.lines();
    let Some(header) = lines.next() else {
        return String::new();
    };
    let h = parse_line(header).unwrap_or_default();
    let cut = h
        .iter()
        .position(|c| c == TIMING_COLUMNS[0])
        .unwrap_or(h.len());
    let mut out = render_line(&h[..cut]);
    out.push('\n');
    for l in lines {
        let cells = parse_line(l).unwrap_or_else(|| vec![l.to_string()]);
        out.push_str(&render_line(&cells[..cut.min(cells.len())]));
        out.push('\n');
    }
    out
}

/// The rows (cells, without `check`) of one unit, in countermeasure order.
pub type UnitRows = Vec<Vec<String>>;

fn unit_rows_valid(rec: &Record, unit: usize, rows: &UnitRows) -> bool {
    let ncol = rec.header(false).len();
    let (p, e) = (unit % rec.points, unit / rec.points);
    let cm_col = HEAD_COLUMNS.len() + rec.grid.len();
    rows.len() == rec.countermeasures.len()
        && rows.iter().zip(&rec.countermeasures).all(|(r, cm)| {
            r.len() == ncol
                && r[0] == unit.to_string()
                && r[1] == p.to_string()
                && r[2] == e.to_string()
                && r[3..cm_col] == rec.point_values[p][..]
                && &r[cm_col] == cm
        })
}

/// What a unit CSV held: verified units, and what was wrong with the rest.
#[derive(Debug, Default)]
pub struct ParsedRows {
    pub units: BTreeMap<usize, UnitRows>,
    /// Lines (after the header) that were dropped: malformed, truncated, failed checks, incomplete units.
    pub dropped_lines: usize,
    pub header_ok: bool,
}

/// Parse a shard CSV, keeping only complete units whose rows all pass their checks.
pub fn parse_shard_text(rec: &Record, text: &str) -> ParsedRows {
    let mut out = ParsedRows::default();
    let header = render_line(&rec.header(true));
    let complete = text.ends_with('\n');
    let mut lines: Vec<&str> = text.split('\n').collect();
    if complete {
        lines.pop(); // the empty piece after the final newline
    }
    let n_lines = lines.len();
    let mut it = lines.into_iter().enumerate();
    match it.next() {
        Some((_, h)) if h == header && (n_lines > 1 || complete) => out.header_ok = true,
        Some(_) => {
            out.dropped_lines = n_lines.saturating_sub(1);
            return out;
        }
        None => return out,
    }
    let ncol = rec.header(true).len();
    let mut pending: BTreeMap<usize, UnitRows> = BTreeMap::new();
    let mut bad_units: BTreeSet<usize> = BTreeSet::new();
    let mut rows_seen: BTreeMap<usize, usize> = BTreeMap::new();
    for (k, line) in it {
        let last_truncated = !complete && k + 1 == n_lines;
        let cells = match parse_line(line) {
            Some(c) if c.len() == ncol && !last_truncated => c,
            _ => {
                out.dropped_lines += 1;
                // a damaged line may belong to a unit: that unit is incomplete anyway
                if let Some(u) = line.split(',').next().and_then(|s| s.parse::<usize>().ok()) {
                    bad_units.insert(u);
                }
                continue;
            }
        };
        let (body, check) = cells.split_at(ncol - 1);
        let line_text = render_line(body);
        let Ok(unit) = body[0].parse::<usize>() else {
            out.dropped_lines += 1;
            continue;
        };
        *rows_seen.entry(unit).or_default() += 1;
        if row_check(&rec.hash, &line_text) != check[0] {
            bad_units.insert(unit);
            continue;
        }
        pending.entry(unit).or_default().push(body.to_vec());
    }
    for (u, rows) in pending {
        if !bad_units.contains(&u) && unit_rows_valid(rec, u, &rows) {
            out.units.insert(u, rows);
        }
    }
    let kept: usize = out.units.values().map(|r| r.len()).sum();
    let seen: usize = rows_seen.values().sum();
    out.dropped_lines += seen - kept.min(seen);
    out
}

/// A shard sidecar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    pub format: String,
    pub sweep_hash: String,
    pub shard: usize,
    pub shards: usize,
    pub rows: usize,
    pub units: usize,
    pub sha256: String,
    pub engine_version: String,
}

/// A shard spec: shard `index` of `count` (0-based). Unit `u` belongs to shard `u mod count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Everything in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parse `i/N`.
    pub fn parse(spec: &str) -> Result<Shard, SweepError> {
        let bad = |message: &str| SweepError::Shard {
            spec: spec.to_string(),
            message: message.to_string(),
        };
        let (i, n) = spec
            .split_once('/')
            .ok_or_else(|| bad("expected i/N, e.g. 0/4 (shard i of N, numbered from 0)"))?;
        let n: usize = n
            .trim()
            .parse()
            .map_err(|_| bad("N must be a whole number ≥ 1"))?;
        let i: usize = i
            .trim()
            .parse()
            .map_err(|_| bad("i must be a whole number ≥ 0"))?;
        Shard::new(i, n).map_err(|e| match e {
            SweepError::Shard { message, .. } => bad(&message),
            other => other,
        })
    }

    pub fn new(index: usize, count: usize) -> Result<Shard, SweepError> {
        let spec = format!("{index}/{count}");
        if count == 0 {
            return Err(SweepError::Shard {
                spec,
                message: "N = 0: the number of shards must be ≥ 1".into(),
            });
        }
        if index >= count {
            return Err(SweepError::Shard {
                spec,
                message: format!(
                    "i = {index} is out of range: shards are numbered 0..{count} (0 ≤ i < N)"
                ),
            });
        }
        Ok(Shard { index, count })
    }

    pub fn contains(&self, unit: usize) -> bool {
        unit % self.count == self.index
    }

    /// `shard-IIII-of-NNNN`.
    pub fn stem(&self) -> String {
        format!("shard-{:04}-of-{:04}", self.index, self.count)
    }

    /// Parse a shard CSV file name back.
    pub fn from_file_name(name: &str) -> Option<Shard> {
        let rest = name.strip_prefix("shard-")?.strip_suffix(".csv")?;
        let (i, n) = rest.split_once("-of-")?;
        if i.is_empty()
            || n.is_empty()
            || !i.bytes().all(|b| b.is_ascii_digit())
            || !n.bytes().all(|b| b.is_ascii_digit())
        {
            return None;
        }
        let s = Shard::new(i.parse().ok()?, n.parse().ok()?).ok()?;
        (s.stem() + ".csv" == name).then_some(s)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Paths of shard `s`'s CSV and sidecar in `dir`.
pub fn shard_paths(dir: &Path, s: Shard) -> (PathBuf, PathBuf) {
    let d = dir.join("shards");
    (
        d.join(format!("{}.csv", s.stem())),
        d.join(format!("{}.json", s.stem())),
    )
}

/// A shard file as read back.
#[derive(Debug)]
pub struct ShardFile {
    pub shard: Shard,
    pub csv: PathBuf,
    pub units: BTreeMap<usize, UnitRows>,
    /// The CSV matched its sidecar and every line verified.
    pub intact: bool,
    /// What was wrong, if anything.
    pub note: Option<String>,
}

/// Read and verify one shard file. A sidecar naming another sweep is an error; anything else damaged is
/// salvaged (verified complete units kept) and described in `note`.
pub fn read_shard(rec: &Record, dir: &Path, shard: Shard) -> Result<ShardFile, SweepError> {
    let (csv, side) = shard_paths(dir, shard);
    let sidecar: Option<Result<Sidecar, String>> = match std::fs::read_to_string(&side) {
        Ok(t) => Some(serde_json::from_str::<Sidecar>(&t).map_err(|e| e.to_string())),
        Err(_) => None,
    };
    if let Some(Ok(s)) = &sidecar
        && s.sweep_hash != rec.hash
    {
        return Err(SweepError::Mixed {
            dir: dir.to_path_buf(),
            message: format!(
                "{} belongs to sweep {} but sweep.json is {}",
                side.display(),
                s.sweep_hash,
                rec.hash
            ),
        });
    }
    let bytes = match std::fs::read(&csv) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(ShardFile {
                shard,
                csv,
                units: BTreeMap::new(),
                intact: sidecar.is_none(),
                note: sidecar.map(|_| "the CSV is missing (its sidecar is there)".to_string()),
            });
        }
        Err(e) => return Err(io_err(&csv, e)),
    };
    let text = String::from_utf8_lossy(&bytes);
    let parsed = parse_shard_text(rec, &text);
    let rows: usize = parsed.units.values().map(|r| r.len()).sum();
    let mut problems = Vec::new();
    match &sidecar {
        None => problems.push("no sidecar (checksum) file".to_string()),
        Some(Err(e)) => problems.push(format!("unreadable sidecar ({e})")),
        Some(Ok(s)) => {
            if s.sha256 != sha256_hex(&bytes) {
                problems.push("SHA-256 differs from its sidecar".into());
            }
            if s.rows != rows {
                problems.push(format!("{rows} verified rows, its sidecar says {}", s.rows));
            }
        }
    }
    if !parsed.header_ok {
        problems.push("header does not match this sweep".into());
    }
    if parsed.dropped_lines > 0 {
        problems.push(format!(
            "{} damaged or incomplete line(s) dropped",
            parsed.dropped_lines
        ));
    }
    let intact = problems.is_empty();
    let note = (!intact).then(|| {
        format!(
            "{}: {}; kept {} verified unit(s)",
            csv.display(),
            problems.join(", "),
            parsed.units.len()
        )
    });
    Ok(ShardFile {
        shard,
        csv,
        units: parsed.units,
        intact,
        note,
    })
}

/// Write a shard's CSV (atomically), then its sidecar.
pub fn write_shard(
    rec: &Record,
    dir: &Path,
    shard: Shard,
    units: &BTreeMap<usize, UnitRows>,
) -> Result<(), SweepError> {
    let (csv, side) = shard_paths(dir, shard);
    let mut text = render_line(&rec.header(true));
    text.push('\n');
    let mut rows = 0;
    for r in units.values().flatten() {
        let line = render_line(r);
        let check = row_check(&rec.hash, &line);
        text.push_str(&line);
        text.push(',');
        text.push_str(&check);
        text.push('\n');
        rows += 1;
    }
    io::write_atomic(&csv, text.as_bytes())?;
    let s = Sidecar {
        format: SHARD_FORMAT.into(),
        sweep_hash: rec.hash.clone(),
        shard: shard.index,
        shards: shard.count,
        rows,
        units: units.len(),
        sha256: sha256_hex(text.as_bytes()),
        engine_version: crate::VERSION.into(),
    };
    io::write_atomic(&side, to_json(&s).as_bytes())?;
    Ok(())
}

/// The shard CSV files present in `dir/shards`.
pub fn list_shards(dir: &Path) -> Result<Vec<Shard>, SweepError> {
    let d = dir.join("shards");
    let mut out = Vec::new();
    let entries = match std::fs::read_dir(&d) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(io_err(&d, e)),
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if let Some(s) = Shard::from_file_name(&name) {
            out.push(s);
        } else if let Some(stem) = name.strip_suffix(".json") {
            // a sidecar whose CSV never arrived still counts (read_shard reports it)
            if let Some(s) = Shard::from_file_name(&format!("{stem}.csv")) {
                out.push(s);
            }
        }
    }
    out.sort_by_key(|s| (s.count, s.index));
    out.dedup();
    Ok(out)
}

// ---------------------------------------------------------------------------------------------------------
// Running units
// ---------------------------------------------------------------------------------------------------------

/// Options of [`run_shard`].
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub shard: Shard,
    /// Units computed concurrently in this process (each uses the engine's own parallelism too).
    pub jobs: usize,
    /// Stop after this many newly computed units (a time-limited chunk); rerun to continue.
    pub max_units: Option<usize>,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            shard: Shard::ALL,
            jobs: 1,
            max_units: None,
        }
    }
}

/// What happened while running a shard (for progress display).
#[derive(Debug, Clone)]
pub enum Event {
    /// A damaged shard file was salvaged.
    Salvaged(String),
    /// The plan: `shard_units` units belong to this shard, `done` are already recorded (`elsewhere` of
    /// them in other shard files), `todo` will be computed now.
    Plan {
        shard_units: usize,
        done: usize,
        elsewhere: usize,
        todo: usize,
    },
    /// A unit finished and is on disk.
    UnitDone {
        unit: usize,
        point: usize,
        exposure: usize,
        seconds: f64,
        /// accuracy_mas of the first countermeasure
        accuracy_mas: f64,
    },
}

/// The outcome of [`run_shard`].
#[derive(Debug, Clone)]
pub struct RunSummary {
    pub shard: Shard,
    pub shard_units: usize,
    pub done_before: usize,
    pub elsewhere: usize,
    pub computed: usize,
    /// Units of this shard still to do (non-zero after `max_units`).
    pub remaining: usize,
    pub seconds: f64,
    pub file: PathBuf,
}

/// A float as written in the CSVs: the shortest text that reads back to the same value (`1e-17`, `3.25`,
/// `NaN`, `inf`).
fn f(v: f64) -> String {
    format!("{v:?}")
}

/// Compute one unit: simulate, analyse with every countermeasure, predict. Configuration and simulator
/// errors are returned; an analysis failure of this exposure is recorded in the rows (`status`).
pub fn compute_unit(sweep: &Sweep, unit: usize, session: &Session) -> Result<UnitRows, SweepError> {
    let t0 = Instant::now();
    let (point, exposure) = sweep.unit(unit);
    let cfg = sweep.unit_config(unit);
    let uerr = |message: String| SweepError::Unit {
        unit,
        point,
        exposure,
        message,
    };
    let sim = session
        .new_simulator(&cfg)
        .map_err(|e| uerr(e.to_string()))?;
    session.warm(&sim);
    let analysed = experiment::analyse_exposure(&sim, 0, &sweep.plan);
    let tp = Instant::now();
    let predictor = crate::analysis::predict::Predictor::new(&sim).ok();
    // a prediction that cannot be made is recorded as NaN beside the measured row (the file has no other
    // place for the reason; `jsim predict` reports it)
    let predicted: Vec<f64> = sweep
        .plan
        .countermeasures
        .iter()
        .map(|c| {
            predictor
                .as_ref()
                .and_then(|p| p.predict_image(0, c).ok())
                .unwrap_or(f64::NAN)
        })
        .collect();
    let predict_s = tp.elapsed().as_secs_f64();
    let unit_s = t0.elapsed().as_secs_f64();
    let mut rows = Vec::with_capacity(sweep.countermeasures.len());
    for (k, cm) in sweep.countermeasures.iter().enumerate() {
        let mut r: Vec<String> = vec![unit.to_string(), point.to_string(), exposure.to_string()];
        r.extend(sweep.points[point].values.iter().cloned());
        r.push(cm.clone());
        let nan = f64::NAN;
        match &analysed {
            Ok(im) => {
                let m = im.measured.iter().find(|m| &m.countermeasure == cm);
                match m {
                    Some(m) => {
                        let rep = &m.report;
                        r.push("ok".into());
                        for v in [
                            rep.accuracy_mas,
                            rep.accuracy_x_mas,
                            rep.accuracy_y_mas,
                            rep.bias_x_mas,
                            rep.bias_y_mas,
                            rep.crlb_median_mas,
                            predicted[k],
                        ] {
                            r.push(f(v));
                        }
                        r.push(rep.n_used.to_string());
                    }
                    None => {
                        r.push("not applicable".into());
                        for v in [nan, nan, nan, nan, nan, nan, predicted[k]] {
                            r.push(f(v));
                        }
                        r.push("0".into());
                    }
                }
                r.push(f(im.ace_sigma_mas));
                r.push(f(im.ace_drift_mas));
                r.push(cfg.seed.to_string());
                r.push(f(im.simulate_s));
                r.push(f(im.analyse_s));
            }
            Err(e) => {
                let msg = format!("error: {e}").replace(['\n', '\r'], " ");
                r.push(msg);
                for v in [nan, nan, nan, nan, nan, nan, predicted[k]] {
                    r.push(f(v));
                }
                r.push("0".into());
                let a = sim.ace_stats(0);
                r.push(f(
                    ((a.sigma_x_mas.powi(2) + a.sigma_y_mas.powi(2)) / 2.0).sqrt()
                ));
                r.push(f(a.drift_mas));
                r.push(cfg.seed.to_string());
                r.push(f(nan));
                r.push(f(nan));
            }
        }
        r.push(f(predict_s));
        r.push(f(unit_s));
        rows.push(r);
    }
    Ok(rows)
}

/// Remove this shard's temporary files left by a killed run (`shard-….csv.<pid>.tmp`).
fn remove_stale_temps(dir: &Path, shard: Shard) {
    let d = dir.join("shards");
    let stem = shard.stem();
    let mine = format!(".{}.tmp", std::process::id());
    if let Ok(entries) = std::fs::read_dir(&d) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with(&format!("{stem}."))
                && name.ends_with(".tmp")
                && !name.ends_with(&mine)
            {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Run (or resume) one shard of a sweep into `dir`.
pub fn run_shard(
    session: &Session,
    sweep: &Sweep,
    dir: &Path,
    opts: &RunOptions,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunSummary, SweepError> {
    let t0 = Instant::now();
    let shard = opts.shard;
    prepare_dir(sweep, dir)?;
    let rec = sweep.record();
    // one process per shard: an advisory lock, released by the OS when the process ends however it ends
    let lock_path = dir.join("shards").join(format!("{}.lock", shard.stem()));
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .map_err(|e| io_err(&lock_path, e))?;
    /// Unlocks explicitly: a child forked meanwhile by another thread may hold a copy of the descriptor
    /// until it execs, and closing ours alone would not release the lock until then.
    struct Held(std::fs::File);
    impl Drop for Held {
        fn drop(&mut self) {
            let _ = self.0.unlock();
        }
    }
    match lock.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(SweepError::Invalid(format!(
                "shard {shard} of {} is being run by another process (it holds {}); wait for it or stop it",
                dir.display(),
                lock_path.display()
            )));
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(io_err(&lock_path, e)),
    }
    let lock = Held(lock);
    remove_stale_temps(dir, shard);
    let own = read_shard(&rec, dir, shard)?;
    let mut units: BTreeMap<usize, UnitRows> = own
        .units
        .into_iter()
        .filter(|(u, _)| shard.contains(*u))
        .collect();
    let own_dirty = !own.intact;
    if let Some(n) = own.note {
        on_event(Event::Salvaged(n));
    }
    // units recorded by other shard files (an earlier run with another N)
    let mut elsewhere_set = BTreeSet::new();
    for s in list_shards(dir)? {
        if s == shard {
            continue;
        }
        let other = read_shard(&rec, dir, s)?;
        elsewhere_set.extend(other.units.keys().copied().filter(|u| shard.contains(*u)));
    }
    let mine: Vec<usize> = (shard.index..sweep.n_units())
        .step_by(shard.count)
        .collect();
    let todo: Vec<usize> = mine
        .iter()
        .copied()
        .filter(|u| !units.contains_key(u) && !elsewhere_set.contains(u))
        .collect();
    let elsewhere = mine
        .iter()
        .filter(|u| !units.contains_key(u) && elsewhere_set.contains(u))
        .count();
    let done_before = mine.len() - todo.len();
    on_event(Event::Plan {
        shard_units: mine.len(),
        done: done_before,
        elsewhere,
        todo: todo.len(),
    });
    let (csv_path, _) = shard_paths(dir, shard);
    if own_dirty {
        write_shard(&rec, dir, shard, &units)?;
    }
    let limit = opts.max_units.unwrap_or(usize::MAX).min(todo.len());
    let jobs = opts.jobs.clamp(1, 256).min(limit.max(1));
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let mut computed = 0;
    let mut first_err: Option<SweepError> = None;
    std::thread::scope(|s| {
        let (tx, rx) = std::sync::mpsc::channel::<(usize, f64, Result<UnitRows, SweepError>)>();
        for _ in 0..jobs {
            let tx = tx.clone();
            let (next, stop, todo) = (&next, &stop, &todo);
            s.spawn(move || {
                loop {
                    if stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let k = next.fetch_add(1, Ordering::SeqCst);
                    if k >= limit {
                        break;
                    }
                    let u = todo[k];
                    let tu = Instant::now();
                    let r = compute_unit(sweep, u, session);
                    if tx.send((u, tu.elapsed().as_secs_f64(), r)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (u, secs, r) in rx {
            match r {
                Ok(rows) => {
                    let acc = rows
                        .first()
                        .and_then(|r| r.get(rec.col("accuracy_mas")))
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(f64::NAN);
                    units.insert(u, rows);
                    if let Err(e) = write_shard(&rec, dir, shard, &units) {
                        stop.store(true, Ordering::SeqCst);
                        first_err.get_or_insert(e);
                        break;
                    }
                    computed += 1;
                    let (point, exposure) = sweep.unit(u);
                    on_event(Event::UnitDone {
                        unit: u,
                        point,
                        exposure,
                        seconds: secs,
                        accuracy_mas: acc,
                    });
                }
                Err(e) => {
                    stop.store(true, Ordering::SeqCst);
                    first_err.get_or_insert(e);
                }
            }
        }
    });
    drop(lock);
    if let Some(e) = first_err {
        return Err(e);
    }
    Ok(RunSummary {
        shard,
        shard_units: mine.len(),
        done_before,
        elsewhere,
        computed,
        remaining: todo.len() - computed,
        seconds: t0.elapsed().as_secs_f64(),
        file: csv_path,
    })
}

// ---------------------------------------------------------------------------------------------------------
// Merge
// ---------------------------------------------------------------------------------------------------------

/// Options of [`merge`].
#[derive(Debug, Clone, Default)]
pub struct MergeOptions {
    /// Write `merged.csv` even when units are missing (they are still listed).
    pub allow_missing: bool,
}

/// The outcome of [`merge`].
#[derive(Debug, Clone)]
pub struct MergeSummary {
    pub path: PathBuf,
    pub units: usize,
    pub rows: usize,
    pub files: usize,
    /// Units recorded in more than one shard file (identical apart from timing; one kept).
    pub duplicates: Vec<usize>,
    pub missing: Vec<usize>,
    /// Units beyond `points × exposures` (from a run with more exposures), left out.
    pub extra: usize,
    /// Damaged shard files and what was kept of them.
    pub notes: Vec<String>,
}

/// Unit list as ranges with their (point, exposure): `3 (p1 e1), 5-7, …`.
pub fn describe_units(units: &[usize], points: usize, max: usize) -> String {
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for &u in units {
        match ranges.last_mut() {
            Some(r) if r.1 + 1 == u => r.1 = u,
            _ => ranges.push((u, u)),
        }
    }
    let mut parts: Vec<String> = ranges
        .iter()
        .take(max)
        .map(|&(a, b)| {
            if a == b {
                format!("unit {a} (point {}, exposure {})", a % points, a / points)
            } else {
                format!("units {a}-{b}")
            }
        })
        .collect();
    if ranges.len() > max {
        parts.push(format!("… ({} more ranges)", ranges.len() - max));
    }
    parts.join(", ")
}

/// Combine the shard files of `dir` into `dir/merged.csv` (sorted by unit index, without `check`).
pub fn merge(dir: &Path, opts: &MergeOptions) -> Result<MergeSummary, SweepError> {
    let rec = read_record(dir)?;
    let shards = list_shards(dir)?;
    if shards.is_empty() {
        return Err(SweepError::Invalid(format!(
            "no shard files in {}: run `jsim sweep` first",
            dir.join("shards").display()
        )));
    }
    let cut = rec.first_timing_column();
    let mut all: BTreeMap<usize, (UnitRows, PathBuf)> = BTreeMap::new();
    let mut duplicates = Vec::new();
    let mut notes = Vec::new();
    let mut files = 0;
    for s in shards {
        let sf = read_shard(&rec, dir, s)?;
        files += 1;
        if let Some(n) = sf.note {
            notes.push(n);
        }
        for (u, rows) in sf.units {
            match all.get(&u) {
                Some((prev, from)) => {
                    let same = prev.iter().zip(&rows).all(|(a, b)| a[..cut] == b[..cut]);
                    if !same {
                        return Err(SweepError::Mixed {
                            dir: dir.to_path_buf(),
                            message: format!(
                                "unit {u} differs between {} and {} (not a rerun of the same sweep, or a different engine build/backend)",
                                from.display(),
                                sf.csv.display()
                            ),
                        });
                    }
                    duplicates.push(u);
                }
                None => {
                    all.insert(u, (rows, sf.csv.clone()));
                }
            }
        }
    }
    duplicates.sort_unstable();
    duplicates.dedup();
    let total = rec.n_units();
    let missing: Vec<usize> = (0..total).filter(|u| !all.contains_key(u)).collect();
    let extra = all.range(total..).count();
    if !missing.is_empty() && !opts.allow_missing {
        return Err(SweepError::Missing {
            missing: missing.len(),
            total,
            list: describe_units(&missing, rec.points, 20),
            units: missing,
        });
    }
    let mut text = render_line(&rec.header(false));
    text.push('\n');
    let mut rows = 0;
    let mut units = 0;
    for (_, (rs, _)) in all.range(..total) {
        units += 1;
        for r in rs {
            text.push_str(&render_line(r));
            text.push('\n');
            rows += 1;
        }
    }
    let path = dir.join("merged.csv");
    io::write_atomic(&path, text.as_bytes())?;
    let meta = serde_json::json!({
        "format": "jsim-sweep-merged/1",
        "sweep_hash": rec.hash,
        "units": units,
        "rows": rows,
        "missing_units": missing.len(),
        "duplicate_units": duplicates.len(),
        "sha256": sha256_hex(text.as_bytes()),
    });
    io::write_atomic(&dir.join("merged.json"), to_json(&meta).as_bytes())?;
    Ok(MergeSummary {
        path,
        units,
        rows,
        files,
        duplicates,
        missing,
        extra,
        notes,
    })
}

// ---------------------------------------------------------------------------------------------------------
// Report
// ---------------------------------------------------------------------------------------------------------

/// Options of [`report`].
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// Threshold in mas (default: the sweep's `threshold_mas`).
    pub threshold_mas: Option<f64>,
    /// Which accuracy column is thresholded (one of [`METRICS`]).
    pub metric: String,
    /// Grid field on the x axis of the fraction plot (default: the first numeric one with several values).
    pub x: Option<String>,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            threshold_mas: None,
            metric: "accuracy_mas".into(),
            x: None,
        }
    }
}

/// One (grid point, countermeasure) line of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportRow {
    pub point: usize,
    pub values: Vec<String>,
    pub countermeasure: String,
    /// Exposures.
    pub n: usize,
    /// Exposures meeting the threshold.
    pub k: usize,
    /// Exposures whose analysis failed (counted as not meeting it).
    pub failed: usize,
    pub fraction: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    pub mean_mas: f64,
    pub median_mas: f64,
    pub q90_mas: f64,
    pub crlb_median_mas: f64,
    pub predicted_mean_mas: f64,
    /// Fraction of exposures the instant predictor expects to meet the threshold.
    pub predicted_fraction: f64,
}

/// The outcome of [`report`].
#[derive(Debug, Clone)]
pub struct ReportSummary {
    pub rows: Vec<ReportRow>,
    pub threshold_mas: f64,
    pub metric: String,
    /// Grid fields, in column order.
    pub fields: Vec<String>,
    /// The x axis of the fraction plot (`None`: grid point index).
    pub x_field: Option<String>,
    pub files: Vec<PathBuf>,
}

fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn fmt_num(v: f64) -> String {
    f(v)
}

/// Fractions meeting the threshold per grid point and countermeasure (95 % Wilson intervals), written to
/// `dir/report.csv`, with a histogram + CDF per point and countermeasure and the fraction against the swept
/// parameter in `dir/report/`.
pub fn report(dir: &Path, opts: &ReportOptions) -> Result<ReportSummary, SweepError> {
    let rec = read_record(dir)?;
    if !METRICS.contains(&opts.metric.as_str()) {
        return Err(SweepError::Invalid(format!(
            "--metric {}: expected one of {}",
            opts.metric,
            METRICS.join(", ")
        )));
    }
    let threshold = opts.threshold_mas.unwrap_or(rec.threshold_mas);
    if !(threshold > 0.0) || !threshold.is_finite() {
        return Err(SweepError::Invalid(format!(
            "--threshold-mas {threshold}: must be a finite number > 0"
        )));
    }
    let fields: Vec<String> = rec.grid.iter().map(|p| p.field.clone()).collect();
    let numeric = |k: usize| {
        rec.grid[k]
            .values
            .iter()
            .all(|v| v.trim().parse::<f64>().is_ok_and(|x| x.is_finite()))
    };
    let x_index = match &opts.x {
        Some(x) => {
            let k = fields.iter().position(|f| f == x).ok_or_else(|| {
                SweepError::Invalid(format!(
                    "--x {x}: not a grid parameter of this sweep ({})",
                    fields.join(", ")
                ))
            })?;
            if !numeric(k) {
                return Err(SweepError::Invalid(format!(
                    "--x {x}: its values ({}) are not numbers",
                    rec.grid[k].values.join(", ")
                )));
            }
            Some(k)
        }
        None => (0..fields.len()).find(|&k| numeric(k) && rec.grid[k].values.len() > 1),
    };
    let merged = dir.join("merged.csv");
    let text = std::fs::read_to_string(&merged).map_err(|e| {
        SweepError::Invalid(format!(
            "cannot read {}: {e}; run `jsim merge {}` first",
            merged.display(),
            dir.display()
        ))
    })?;
    let header = rec.header(false);
    let mut lines = text.lines();
    if lines.next().and_then(parse_line).as_deref() != Some(&header[..]) {
        return Err(SweepError::Invalid(format!(
            "{} does not match this sweep's columns: rerun `jsim merge {}`",
            merged.display(),
            dir.display()
        )));
    }
    let c_point = rec.col("point");
    let c_cm = rec.col("countermeasure");
    let c_metric = rec.col(&opts.metric);
    let c_crlb = rec.col("crlb_mas");
    let c_pred = rec.col("predicted_mas");
    // (point, countermeasure index) → (metric values, crlb, predicted)
    let mut groups: BTreeMap<(usize, usize), (Vec<f64>, Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for (k, l) in lines.enumerate() {
        let cells = parse_line(l)
            .filter(|c| c.len() == header.len())
            .ok_or_else(|| {
                SweepError::Invalid(format!(
                    "{} line {}: malformed; rerun `jsim merge`",
                    merged.display(),
                    k + 2
                ))
            })?;
        let point: usize = cells[c_point].parse().map_err(|_| {
            SweepError::Invalid(format!("{} line {}: bad point", merged.display(), k + 2))
        })?;
        let Some(ci) = rec.countermeasures.iter().position(|c| c == &cells[c_cm]) else {
            continue;
        };
        let num = |c: usize| cells[c].parse::<f64>().unwrap_or(f64::NAN);
        let g = groups.entry((point, ci)).or_default();
        g.0.push(num(c_metric));
        g.1.push(num(c_crlb));
        g.2.push(num(c_pred));
    }
    let mut rows = Vec::new();
    for p in 0..rec.points {
        for (ci, cm) in rec.countermeasures.iter().enumerate() {
            let (vals, crlb, pred) = groups.get(&(p, ci)).cloned().unwrap_or_default();
            let finite: Vec<f64> = vals.iter().copied().filter(|v| v.is_finite()).collect();
            let n = vals.len();
            let k = finite.iter().filter(|&&v| v <= threshold).count();
            let (lo, hi) = stats::wilson_interval(k, n, Z95);
            let crlb_f: Vec<f64> = crlb.into_iter().filter(|v| v.is_finite()).collect();
            let pred_f: Vec<f64> = pred.into_iter().filter(|v| v.is_finite()).collect();
            let nan_if_empty = |v: &[f64], x: f64| if v.is_empty() { f64::NAN } else { x };
            rows.push(ReportRow {
                point: p,
                values: rec.point_values[p].clone(),
                countermeasure: cm.clone(),
                n,
                k,
                failed: n - finite.len(),
                fraction: if n > 0 { k as f64 / n as f64 } else { f64::NAN },
                ci_low: lo,
                ci_high: hi,
                mean_mas: nan_if_empty(&finite, stats::mean(&finite)),
                median_mas: nan_if_empty(&finite, stats::median(&finite)),
                q90_mas: nan_if_empty(&finite, stats::quantile(&finite, 0.9)),
                crlb_median_mas: nan_if_empty(&crlb_f, stats::median(&crlb_f)),
                predicted_mean_mas: nan_if_empty(&pred_f, stats::mean(&pred_f)),
                predicted_fraction: if pred_f.is_empty() {
                    f64::NAN
                } else {
                    pred_f.iter().filter(|&&v| v <= threshold).count() as f64 / pred_f.len() as f64
                },
            });
        }
    }

    // report.csv
    let mut h: Vec<String> = vec!["point".into()];
    h.extend(fields.iter().cloned());
    for c in [
        "countermeasure",
        "metric",
        "threshold_mas",
        "n",
        "k",
        "n_failed",
        "fraction",
        "ci95_low",
        "ci95_high",
        "mean_mas",
        "median_mas",
        "q90_mas",
        "crlb_median_mas",
        "predicted_mean_mas",
        "predicted_fraction",
    ] {
        h.push(c.into());
    }
    let mut csv = render_line(&h);
    csv.push('\n');
    for r in &rows {
        let mut c = vec![r.point.to_string()];
        c.extend(r.values.iter().cloned());
        c.push(r.countermeasure.clone());
        c.push(opts.metric.clone());
        c.push(fmt_num(threshold));
        c.push(r.n.to_string());
        c.push(r.k.to_string());
        c.push(r.failed.to_string());
        for v in [
            r.fraction,
            r.ci_low,
            r.ci_high,
            r.mean_mas,
            r.median_mas,
            r.q90_mas,
            r.crlb_median_mas,
            r.predicted_mean_mas,
            r.predicted_fraction,
        ] {
            c.push(fmt_num(v));
        }
        csv.push_str(&render_line(&c));
        csv.push('\n');
    }
    let mut files = Vec::new();
    let plots = dir.join("report");
    io::ensure_dir(&plots)?;
    // distributions
    for p in 0..rec.points {
        for (ci, cm) in rec.countermeasures.iter().enumerate() {
            let vals = groups
                .get(&(p, ci))
                .map(|g| g.0.clone())
                .unwrap_or_default();
            let path = plots.join(format!("dist_p{p:03}_{}.png", slug(cm)));
            let desc = rec
                .grid
                .iter()
                .zip(&rec.point_values[p])
                .map(|(g, v)| format!("{}={v}", g.field))
                .collect::<Vec<_>>()
                .join(", ");
            plot::histogram_cdf(
                &path,
                &format!("point {p}: {desc}; {cm} (n = {})", vals.len()),
                &format!("{} [mas]", opts.metric),
                &vals,
                Some((threshold, format!("{threshold} mas"))),
            )?;
            files.push(path);
        }
    }
    // fraction against the swept parameter
    let mut series_keys: Vec<(Vec<String>, usize)> = Vec::new();
    for r in &rows {
        let others: Vec<String> = r
            .values
            .iter()
            .enumerate()
            .filter(|(k, _)| Some(*k) != x_index)
            .map(|(k, v)| format!("{}={v}", fields[k]))
            .collect();
        let ci = rec
            .countermeasures
            .iter()
            .position(|c| c == &r.countermeasure)
            .unwrap_or(0);
        if !series_keys.contains(&(others.clone(), ci)) {
            series_keys.push((others, ci));
        }
    }
    // series sharing an x are offset by ±1 % of the x range so that their bars stay visible
    let xs: Vec<f64> = rows
        .iter()
        .map(|r| match x_index {
            Some(k) => r.values[k].trim().parse().unwrap_or(f64::NAN),
            None => r.point as f64,
        })
        .filter(|v| v.is_finite())
        .collect();
    let span = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - xs.iter().copied().fold(f64::INFINITY, f64::min);
    let dodge = if span > 0.0 { 0.01 * span } else { 0.05 };
    let n_series = series_keys.len() as f64;
    let series: Vec<plot::Series> = series_keys
        .iter()
        .enumerate()
        .map(|(si, (others, ci))| {
            let shift = (si as f64 - (n_series - 1.0) / 2.0) * dodge;
            let pts: Vec<&ReportRow> = rows
                .iter()
                .filter(|r| {
                    r.countermeasure == rec.countermeasures[*ci]
                        && &r
                            .values
                            .iter()
                            .enumerate()
                            .filter(|(k, _)| Some(*k) != x_index)
                            .map(|(k, v)| format!("{}={v}", fields[k]))
                            .collect::<Vec<_>>()
                            == others
                })
                .collect();
            let x: Vec<f64> = pts
                .iter()
                .map(|r| match x_index {
                    Some(k) => r.values[k].trim().parse().unwrap_or(f64::NAN),
                    None => r.point as f64,
                } + shift)
                .collect();
            let mut label = rec.countermeasures[*ci].clone();
            if !others.is_empty() {
                label = format!("{label}, {}", others.join(", "));
            }
            plot::Series {
                label,
                x,
                // plot::Series has symmetric bars only: draw the (asymmetric) Wilson interval exactly, marker
                // at its centre (k + z²/2)/(n + z²); the observed fraction k/n is in report.csv and the table
                y: pts.iter().map(|r| 0.5 * (r.ci_low + r.ci_high)).collect(),
                yerr: Some(pts.iter().map(|r| 0.5 * (r.ci_high - r.ci_low)).collect()),
            }
        })
        .collect();
    let frac_path = plots.join("fraction.png");
    plot::line_plot(
        &frac_path,
        &format!(
            "Exposures with {} ≤ {threshold} mas: 95 % Wilson intervals",
            opts.metric
        ),
        match x_index {
            Some(k) => fields[k].as_str(),
            None => "grid point",
        },
        "fraction of exposures (interval centre ± half-width)",
        &series,
        &[],
        plot::Scale::Linear,
        plot::Scale::Linear,
    )?;
    files.push(frac_path);
    let report_csv = dir.join("report.csv");
    io::write_atomic(&report_csv, csv.as_bytes())?;
    files.insert(0, report_csv);
    Ok(ReportSummary {
        rows,
        threshold_mas: threshold,
        metric: opts.metric.clone(),
        fields,
        x_field: x_index.map(|k| rec.grid[k].field.clone()),
        files,
    })
}

/// The report as a text table (what `jsim report` prints).
pub fn render_report(s: &ReportSummary) -> String {
    let mut out = String::new();
    let mut widths: Vec<usize> = s.fields.iter().map(|f| f.len().max(6)).collect();
    for r in &s.rows {
        for (k, v) in r.values.iter().enumerate() {
            widths[k] = widths[k].max(v.len());
        }
    }
    let cmw = s
        .rows
        .iter()
        .map(|r| r.countermeasure.len())
        .max()
        .unwrap_or(0)
        .max(14);
    let _ = write!(out, "{:>5}", "point");
    for (k, f) in s.fields.iter().enumerate() {
        let _ = write!(out, "  {:<w$}", f, w = widths[k]);
    }
    let _ = writeln!(
        out,
        "  {:<cmw$} {:>7} {:>8}  {:<17} {:>8} {:>8} {:>9}",
        "countermeasure", "n", "fraction", "95 % Wilson", "median", "p90", "predicted"
    );
    for r in &s.rows {
        let _ = write!(out, "{:>5}", r.point);
        for (k, v) in r.values.iter().enumerate() {
            let _ = write!(out, "  {:<w$}", v, w = widths[k]);
        }
        let _ = writeln!(
            out,
            "  {:<cmw$} {:>7} {:>8.3}  [{:.3}, {:.3}]    {:>8.2} {:>8.2} {:>9.3}",
            r.countermeasure,
            format!("{}/{}", r.k, r.n),
            r.fraction,
            r.ci_low,
            r.ci_high,
            r.median_mas,
            r.q90_mas,
            r.predicted_fraction,
        );
    }
    let _ = writeln!(
        out,
        "fraction: exposures with {} ≤ {} mas (analysis failures count as misses); median/p90 in mas; predicted: the fraction the instant predictor expects",
        s.metric, s.threshold_mas
    );
    out
}

// ---------------------------------------------------------------------------------------------------------
// Slurm
// ---------------------------------------------------------------------------------------------------------

/// Options of [`emit_slurm`].
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// Array tasks (shards).
    pub shards: usize,
    pub partition: Option<String>,
    /// Wall-clock limit per task (`HH:MM:SS`, `D-HH:MM:SS`, `MM`…).
    pub time: String,
    pub cpus_per_task: usize,
    /// The `jsim` binary the jobs run (absolute).
    pub jsim: PathBuf,
    /// The sweep file (absolute).
    pub sweep_file: PathBuf,
    /// Threshold passed to `jsim report` (default: the sweep's).
    pub threshold_mas: Option<f64>,
}

fn sh_quote(p: &Path) -> Result<String, SweepError> {
    let s = p.to_string_lossy();
    if s.contains('\n') || s.contains('\'') {
        return Err(SweepError::Invalid(format!(
            "path {s:?}: quotes and newlines are not supported in Slurm scripts"
        )));
    }
    Ok(format!("'{s}'"))
}

fn valid_time(t: &str) -> bool {
    let (days, rest) = match t.split_once('-') {
        Some((d, r)) => (Some(d), r),
        None => (None, t),
    };
    let num = |s: &str| !s.is_empty() && s.len() <= 4 && s.bytes().all(|b| b.is_ascii_digit());
    if days.is_some_and(|d| !num(d)) {
        return false;
    }
    let parts: Vec<&str> = rest.split(':').collect();
    !parts.is_empty() && parts.len() <= 3 && parts.iter().all(|p| num(p))
}

impl SlurmOptions {
    /// Check the options (and that `dir` can appear in Slurm scripts) without writing anything.
    pub fn validate(&self, dir: &Path) -> Result<(), SweepError> {
        let o = self;
        if o.shards == 0 {
            return Err(SweepError::Invalid(
                "--shards 0: the number of array tasks must be ≥ 1".into(),
            ));
        }
        if o.cpus_per_task == 0 {
            return Err(SweepError::Invalid("--cpus-per-task 0: must be ≥ 1".into()));
        }
        if !valid_time(&o.time) {
            return Err(SweepError::Invalid(format!(
                "--time {}: expected a Slurm time limit such as 04:00:00, 90 or 1-12:00:00",
                o.time
            )));
        }
        if let Some(p) = &o.partition
            && (p.is_empty()
                || !p
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.,".contains(c)))
        {
            return Err(SweepError::Invalid(format!(
                "--partition {p:?}: expected a partition name (letters, digits, - _ . ,)"
            )));
        }
        let ds = dir.to_string_lossy();
        if ds.chars().any(|c| c.is_whitespace() || c == '%') {
            return Err(SweepError::Invalid(format!(
                "--out {ds}: Slurm log paths cannot contain spaces or %; choose another directory"
            )));
        }
        if let Some(t) = o.threshold_mas
            && (!(t > 0.0) || !t.is_finite())
        {
            return Err(SweepError::Invalid(format!(
                "--threshold-mas {t}: must be a finite number > 0"
            )));
        }
        sh_quote(&o.jsim)?;
        sh_quote(&o.sweep_file)?;
        sh_quote(dir)?;
        Ok(())
    }
}

/// Write `dir/slurm/{array.sbatch, merge.sbatch, submit.sh}` (and `logs/`) for `sweep`; `dir` must be
/// absolute and prepared ([`prepare_dir`]). Returns the written files.
pub fn emit_slurm(sweep: &Sweep, dir: &Path, o: &SlurmOptions) -> Result<Vec<PathBuf>, SweepError> {
    o.validate(dir)?;
    let jsim = sh_quote(&o.jsim)?;
    let sweep_file = sh_quote(&o.sweep_file)?;
    let out = sh_quote(dir)?;
    let sdir = dir.join("slurm");
    let logs = sdir.join("logs");
    io::ensure_dir(&logs)?;
    let n = o.shards;
    let tag = &sweep.hash[..8];
    let partition = o
        .partition
        .as_ref()
        .map(|p| format!("#SBATCH --partition={p}\n"))
        .unwrap_or_default();
    let array = format!(
        "#!/bin/bash
#SBATCH --job-name=jsim-sweep-{tag}
#SBATCH --array=0-{last}
#SBATCH --ntasks=1
#SBATCH --cpus-per-task={cpus}
#SBATCH --time={time}
{partition}#SBATCH --output={logs}/sweep-%A_%a.out
# Sweep `{name}` (hash {hash}): {units} units ({points} points × {exposures} exposures) in {n} shards.
# Task i runs shard i/{n}: the units u with u mod {n} == i. Generated by `jsim sweep --emit-slurm`.
# Resubmitting (submit.sh) is safe: finished units are skipped.
set -euo pipefail
export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-{cpus}}}\"
exec {jsim} sweep --config {sweep_file} --out {out} --shard \"${{SLURM_ARRAY_TASK_ID}}/{n}\"
",
        last = n - 1,
        cpus = o.cpus_per_task,
        time = o.time,
        logs = logs.display(),
        name = sweep.name,
        hash = sweep.hash,
        units = sweep.n_units(),
        points = sweep.n_points(),
        exposures = sweep.exposures,
    );
    let thr = o
        .threshold_mas
        .map(|t| format!(" --threshold-mas {t}"))
        .unwrap_or_default();
    let merge = format!(
        "#!/bin/bash
#SBATCH --job-name=jsim-merge-{tag}
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=1
#SBATCH --time={time}
{partition}#SBATCH --output={logs}/merge-%j.out
# Merge the shards of sweep {hash} and write its report (submitted by submit.sh after the array succeeds).
set -euo pipefail
export RAYON_NUM_THREADS=1
{jsim} merge {out}
{jsim} report {out}{thr}
",
        time = o.time,
        logs = logs.display(),
        hash = sweep.hash,
    );
    let submit = format!(
        "#!/bin/bash
# Submit sweep {hash}: the array of {n} shard tasks, then merge + report once every task succeeded.
# Usage: {sdir}/submit.sh [extra sbatch options for both jobs, e.g. --account=myproject]
# Safe to rerun after a failure, time-out or cancellation: finished units are skipped.
set -euo pipefail
here=\"$(cd \"$(dirname \"${{BASH_SOURCE[0]}}\")\" && pwd)\"
array=$(sbatch --parsable \"$@\" \"$here/array.sbatch\")
array=\"${{array%%;*}}\"
merge=$(sbatch --parsable \"$@\" --dependency=afterok:\"$array\" --kill-on-invalid-dep=yes \"$here/merge.sbatch\")
merge=\"${{merge%%;*}}\"
echo \"$array\" > \"$here/array.jobid\"
echo \"$merge\" > \"$here/merge.jobid\"
echo \"submitted sweep array job $array ({n} tasks) and merge job $merge (runs after every task succeeds)\"
echo \"watch: squeue -j $array,$merge    logs: $here/logs/    results: {dir}/report.csv\"
",
        hash = sweep.hash,
        sdir = sdir.display(),
        dir = dir.display(),
    );
    let mut written = Vec::new();
    for (name, body) in [
        ("array.sbatch", array),
        ("merge.sbatch", merge),
        ("submit.sh", submit),
    ] {
        let p = sdir.join(name);
        io::write_atomic(&p, body.as_bytes())?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))
                .map_err(|e| io_err(&p, e))?;
        }
        written.push(p);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUICK: &str = r#"
seed = 11
exposures = 3
countermeasures = ["none", "plate-poly:3"]
[base.scene]
grid_n = 5
[grid]
"ace.sigma_mas" = [150, 300]
readout.order = ["rolling", "sample-hold"]
"#;

    fn quick() -> Sweep {
        Sweep::from_toml_str(QUICK, Path::new("t.toml"), Path::new(".")).expect("parses")
    }

    #[test]
    fn grid_is_sorted_product_first_slowest() {
        let s = quick();
        assert_eq!(s.params.len(), 2);
        assert_eq!(s.params[0].field, "ace.sigma_mas");
        assert_eq!(s.params[1].field, "readout.order");
        assert_eq!(s.n_points(), 4);
        assert_eq!(s.points[1].values, vec!["150", "sample-hold"]);
        assert_eq!(s.points[2].values, vec!["300", "rolling"]);
        assert_eq!(s.points[2].config.ace.sigma_mas, 300.0);
        assert_eq!(s.points[1].config.readout.order.name(), "sample-hold");
        assert_eq!(s.points[0].config.scene.grid_n, 5);
        assert_eq!(s.n_units(), 12);
        assert_eq!(s.unit(5), (1, 1));
    }

    #[test]
    fn seeds_depend_only_on_sweep_seed_and_unit() {
        let s = quick();
        let mut t = quick();
        t.exposures = 10;
        for u in 0..s.n_units() {
            assert_eq!(s.unit_seed(u), t.unit_seed(u));
            assert_eq!(s.unit_config(u), t.unit_config(u));
        }
        assert_ne!(s.unit_seed(0), s.unit_seed(1));
        // the hash ignores exposures (so a sweep can be extended) but not the seed
        assert_eq!(s.hash, t.hash);
        let other = Sweep::from_toml_str(
            &QUICK.replace("seed = 11", "seed = 12"),
            Path::new("t"),
            Path::new("."),
        )
        .expect("parses");
        assert_ne!(other.hash, s.hash);
    }

    #[test]
    fn shard_specs() {
        assert_eq!(
            Shard::parse("1/3").expect("ok"),
            Shard { index: 1, count: 3 }
        );
        for bad in ["3/3", "0/0", "1", "a/2", "-1/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        assert!(
            Shard::parse("0/0")
                .expect_err("N=0")
                .to_string()
                .contains("N = 0")
        );
        assert!(
            Shard::parse("4/3")
                .expect_err("i≥N")
                .to_string()
                .contains("out of range")
        );
        let s = Shard::new(2, 12).expect("ok");
        assert_eq!(Shard::from_file_name(&format!("{}.csv", s.stem())), Some(s));
        assert_eq!(Shard::from_file_name("shard-0001-of-0003.csv.77.tmp"), None);
        assert_eq!(Shard::from_file_name("shard-3-of-3.csv"), None);
    }

    #[test]
    fn csv_lines_round_trip_with_quotes() {
        let cells: Vec<String> = ["a", "b,c", "say \"hi\"", "", "[1, 2]"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let line = render_line(&cells);
        assert_eq!(parse_line(&line), Some(cells));
        assert_eq!(parse_line("a,\"b"), None);
    }

    #[test]
    fn shard_text_salvage_keeps_only_verified_units() {
        let s = quick();
        let rec = s.record();
        let ncol = rec.header(false).len();
        let mut units = BTreeMap::new();
        for u in [0usize, 3, 6] {
            let (p, e) = s.unit(u);
            let rows: UnitRows = s
                .countermeasures
                .iter()
                .map(|cm| {
                    let mut r = vec![u.to_string(), p.to_string(), e.to_string()];
                    r.extend(s.points[p].values.iter().cloned());
                    r.push(cm.clone());
                    while r.len() < ncol {
                        r.push("1.5".into());
                    }
                    r
                })
                .collect();
            units.insert(u, rows);
        }
        let dir = std::env::temp_dir().join(format!("jsim-sweep-unit-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        io::ensure_dir(&dir.join("shards")).expect("dir");
        let shard = Shard::new(0, 3).expect("ok");
        write_shard(&rec, &dir, shard, &units).expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert!(back.intact, "{:?}", back.note);
        assert_eq!(back.units, units);
        // flip a digit in unit 3's second row: unit 3 is dropped, the others kept
        let (csv, _) = shard_paths(&dir, shard);
        let text = std::fs::read_to_string(&csv).expect("csv");
        let lines: Vec<&str> = text.lines().collect();
        let damaged = lines[4].replacen("1.5", "1.6", 1);
        let mut t2 = lines.clone();
        t2[4] = &damaged;
        std::fs::write(&csv, t2.join("\n") + "\n").expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert!(!back.intact);
        assert_eq!(back.units.keys().copied().collect::<Vec<_>>(), vec![0, 6]);
        // truncate mid-line: the last unit is incomplete
        std::fs::write(&csv, &text[..text.len() - 10]).expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert_eq!(back.units.keys().copied().collect::<Vec<_>>(), vec![0, 3]);
        assert!(back.note.expect("note").contains("SHA-256"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn without_timing_drops_trailing_columns() {
        let t = "unit,x,simulate_s,unit_s\n0,1,0.5,0.7\n";
        assert_eq!(without_timing(t), "unit,x\n0,1\n");
    }

    #[test]
    fn unit_ranges_are_compact() {
        assert_eq!(
            describe_units(&[1, 2, 3, 7], 2, 10),
            "units 1-3, unit 7 (point 1, exposure 3)"
        );
    }

    #[test]
    fn slurm_time_formats() {
        for ok in ["04:00:00", "90", "1-12:00:00", "30:00", "2-0"] {
            assert!(valid_time(ok), "{ok}");
        }
        for bad in ["", "4h", "1:2:3:4", "-1", "a-01:00"] {
            assert!(!valid_time(bad), "{bad}");
        }
    }
}
