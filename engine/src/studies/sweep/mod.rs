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
//! bound, `predicted_mas` the instant predictor's expectation for this exposure ([`crate::studies::predict`]),
//! `ace_sigma_mas`/`ace_drift_mas` the exposure's jitter σ and drift, `seed` the unit's master seed.
//! `status` is `ok`, `not applicable` (e.g. `exact-epsf` with a realistic ACE), `failed: …` (fewer than
//! [`MIN_SWEEP_STARS`] stars scored, with the count) or `error: …` (the analysis failed for that exposure);
//! a failed or erroneous exposure's accuracy is NaN and counts as *not* meeting the threshold.
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
//!
//! # The code
//!
//! One file per job, each importing only from those before it: `error` (the error type), `record`
//! (`sweep.json`, the columns and line format of the unit CSVs, row checks), `spec` (the sweep file, its
//! units and the output directory it claims), `shard` (shard specs and files, verification, salvage), `run`
//! (computing units, running a shard), `merge`, `report` and `slurm`. Everything public is re-exported here.
//!
//! [`Config::with_override`]: crate::Config::with_override
//! [`Session::warm`]: crate::session::Session::warm

mod error;
mod merge;
mod record;
mod report;
mod run;
mod shard;
mod slurm;
mod spec;

pub use error::SweepError;
pub use merge::{MergeOptions, MergeSummary, describe_units, merge};
pub use record::{
    FORMAT, HEAD_COLUMNS, RESULT_COLUMNS, Record, RecordParam, RecordTelemetry, TIMING_COLUMNS,
    UnitRows, parse_line, read_record, render_line, without_timing,
};
pub use report::{METRICS, ReportOptions, ReportRow, ReportSummary, Z95, render_report, report};
pub use run::{Event, MIN_SWEEP_STARS, RunOptions, RunSummary, compute_unit, run_shard};
pub use shard::{
    ParsedRows, SHARD_FORMAT, Shard, ShardFile, Sidecar, list_shards, parse_shard_text, read_shard,
    shard_paths, write_shard,
};
pub use slurm::{SlurmOptions, emit_slurm};
pub use spec::{Param, Point, Sweep, check_dir, prepare_dir};
