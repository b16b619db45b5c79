//! `jsim sweep`, `jsim merge`, `jsim report`: Monte Carlo sweeps, sharded, resumable, and their reports.
//! The work is in [`engine::studies::sweep`] (whose docs describe the sweep file, the output directory and the
//! Slurm scripts); here we parse options, show progress and print summaries.

use anyhow::{Context, Result, bail};
use clap::Args;
use engine::studies::sweep::{self, Event, Shard, Sweep};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `jsim sweep`
#[derive(Args, Clone, Debug)]
pub struct SweepArgs {
    /// Sweep file (TOML): base config, parameter grid, countermeasures, exposures per point, seed.
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory (points.csv, shards/, sweep.json; merged.csv and report/ after merge and report).
    #[arg(long, default_value = "out/sweep")]
    pub out: PathBuf,
    /// Run only shard I of N (0-based, 0 ≤ I < N): the units u with u mod N = I. Default: all units (0/1).
    #[arg(long, value_name = "I/N", conflicts_with = "emit_slurm")]
    pub shard: Option<String>,
    /// Units computed concurrently in this process.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Stop after computing this many new units (a time-limited chunk); rerun to continue.
    #[arg(long, value_name = "K")]
    pub max_units: Option<usize>,
    /// Write Slurm scripts (DIR/slurm/array.sbatch, merge.sbatch, submit.sh) instead of running.
    #[arg(long)]
    pub emit_slurm: bool,
    /// Array tasks (shards) of the Slurm job.
    #[arg(long, default_value_t = 16, requires = "emit_slurm")]
    pub shards: usize,
    /// Slurm partition (default: the cluster's default partition).
    #[arg(long, requires = "emit_slurm")]
    pub partition: Option<String>,
    /// Wall-clock limit of each Slurm task.
    #[arg(long, default_value = "04:00:00", requires = "emit_slurm")]
    pub time: String,
    /// CPUs per Slurm task (sets RAYON_NUM_THREADS in the task).
    #[arg(long, default_value_t = 1, requires = "emit_slurm")]
    pub cpus_per_task: usize,
    /// The jsim binary the Slurm jobs run (default: this one).
    #[arg(long, value_name = "PATH", requires = "emit_slurm")]
    pub jsim: Option<PathBuf>,
    /// Threshold the Slurm merge job's report uses (default: the sweep's threshold_mas).
    #[arg(long = "threshold-mas", requires = "emit_slurm")]
    pub threshold_mas: Option<f64>,
}

/// `jsim merge`
#[derive(Args, Clone, Debug)]
pub struct MergeArgs {
    /// Sweep output directory.
    pub dir: PathBuf,
    /// Write merged.csv even if units are missing (they are still listed; exit status 0).
    #[arg(long)]
    pub allow_missing: bool,
}

/// `jsim report`
#[derive(Args, Clone, Debug)]
pub struct ReportArgs {
    /// Sweep output directory (after `jsim merge`).
    pub dir: PathBuf,
    /// Accuracy threshold, mas (default: the sweep file's threshold_mas, 4 unless set).
    #[arg(long = "threshold-mas")]
    pub threshold_mas: Option<f64>,
    /// Column thresholded: accuracy_mas (per-axis accuracy, √((σx² + σy²)/2) over the stars), accuracy_x_mas or
    /// accuracy_y_mas.
    #[arg(long, default_value = "accuracy_mas")]
    pub metric: String,
    /// Grid field on the x axis of the fraction plot (default: the first numeric field with several values).
    #[arg(long)]
    pub x: Option<String>,
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).with_context(|| format!("cannot resolve {}", p.display()))
}

fn hms(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
}

pub fn sweep(a: &SweepArgs) -> Result<()> {
    let shard = match &a.shard {
        Some(s) => Shard::parse(s)?,
        None => Shard::ALL,
    };
    if a.jobs == 0 {
        bail!("--jobs 0: must be ≥ 1");
    }
    let sw = Sweep::load(&a.config)?;
    sweep::check_dir(&sw, &a.out)?;

    if a.emit_slurm {
        let out = absolute(&a.out)?;
        let jsim = match &a.jsim {
            Some(p) => absolute(p)?,
            None => std::env::current_exe().context("cannot find the jsim binary; give --jsim")?,
        };
        let opts = sweep::SlurmOptions {
            shards: a.shards,
            partition: a.partition.clone(),
            time: a.time.clone(),
            cpus_per_task: a.cpus_per_task,
            jsim,
            sweep_file: absolute(&a.config)?,
            threshold_mas: a.threshold_mas,
        };
        // validate the options before anything is written
        opts.validate(&out)?;
        sweep::prepare_dir(&sw, &out)?;
        let files = sweep::emit_slurm(&sw, &out, &opts)?;
        println!(
            "sweep `{}` ({}): {} units = {} points × {} exposures, in {} array tasks",
            sw.name,
            sw.hash,
            sw.n_units(),
            sw.n_points(),
            sw.exposures,
            a.shards
        );
        for f in &files {
            println!("wrote {}", f.display());
        }
        println!(
            "submit with: {}   (rerun it to resume after a failure)",
            out.join(engine::io::products::files::SLURM_SUBMIT_SH)
                .display()
        );
        return Ok(());
    }

    let t0 = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let mut pb: Option<indicatif::ProgressBar> = None;
    let mut total = 0usize;
    let mut done = 0usize;
    let mut todo = 0usize;
    let mut new = 0usize;
    let opts = sweep::RunOptions {
        shard,
        jobs: a.jobs,
        max_units: a.max_units,
    };
    let session = engine::session::Session::new();
    let summary = sweep::run_shard(&session, &sw, &a.out, &opts, &mut |ev| match ev {
        Event::Salvaged(note) => eprintln!("jsim: resuming from a damaged shard file: {note}"),
        Event::Plan {
            shard_units,
            done: d,
            elsewhere,
            todo: t,
        } => {
            total = shard_units;
            done = d;
            todo = t.min(a.max_units.unwrap_or(usize::MAX));
            let extra = if elsewhere > 0 {
                format!(" ({elsewhere} of them in other shard files)")
            } else {
                String::new()
            };
            eprintln!(
                "jsim sweep `{}` ({}): shard {shard}: {shard_units} of {} units, {d} already done{extra}, {t} to do",
                sw.name,
                sw.hash,
                sw.n_units()
            );
            if tty {
                let bar = crate::cmd::progress(shard_units as u64, "sweep");
                bar.set_position(d as u64);
                bar.reset_eta();
                pb = Some(bar);
            }
        }
        Event::UnitDone {
            unit,
            point,
            exposure,
            seconds,
            accuracy_mas,
        } => {
            done += 1;
            new += 1;
            if let Some(bar) = &pb {
                bar.inc(1);
            } else {
                let elapsed = t0.elapsed().as_secs_f64();
                let eta = elapsed / new as f64 * (todo.saturating_sub(new)) as f64;
                eprintln!(
                    "unit {unit} (point {point}, exposure {exposure}): {seconds:.1} s, accuracy {accuracy_mas:.2} mas; {done}/{total} done, ETA {}",
                    hms(eta)
                );
            }
        }
    });
    if let Some(bar) = &pb {
        bar.finish_and_clear();
    }
    let s = summary?;
    println!(
        "shard {}: {} units ({} done before, {} computed now in {:.1} s{}), {}",
        s.shard,
        s.shard_units,
        s.done_before,
        s.computed,
        s.seconds,
        if s.computed > 0 {
            format!(", {:.2} s/unit", s.seconds / s.computed as f64)
        } else {
            String::new()
        },
        s.file.display()
    );
    if s.remaining > 0 {
        println!(
            "{} units of this shard remain (--max-units): rerun the same command to continue",
            s.remaining
        );
    } else {
        println!(
            "shard complete; when every shard is: jsim merge {} && jsim report {}",
            a.out.display(),
            a.out.display()
        );
    }
    Ok(())
}

pub fn merge(a: &MergeArgs) -> Result<()> {
    let r = sweep::merge(
        &a.dir,
        &sweep::MergeOptions {
            allow_missing: a.allow_missing,
        },
    );
    let r = match r {
        Ok(r) => r,
        Err(e @ sweep::SweepError::Missing { .. }) => {
            bail!("{e} (or pass --allow-missing to merge what is there)")
        }
        Err(e) => return Err(e.into()),
    };
    for n in &r.notes {
        eprintln!("jsim: damaged shard file: {n}; rerun `jsim sweep` to redo what was lost");
    }
    if !r.duplicates.is_empty() {
        eprintln!(
            "jsim: {} unit(s) were recorded in more than one shard file (identical apart from timing; kept one): {}",
            r.duplicates.len(),
            r.duplicates
                .iter()
                .take(20)
                .map(|u| u.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if r.extra > 0 {
        eprintln!(
            "jsim: {} unit(s) beyond the sweep's current points × exposures were left out",
            r.extra
        );
    }
    if !r.missing.is_empty() {
        eprintln!(
            "jsim: {} unit(s) missing (merged anyway, --allow-missing)",
            r.missing.len()
        );
    }
    println!(
        "merged {} units ({} rows) from {} shard file(s) into {}",
        r.units,
        r.rows,
        r.files,
        r.path.display()
    );
    Ok(())
}

pub fn report(a: &ReportArgs) -> Result<()> {
    let s = sweep::report(
        &a.dir,
        &sweep::ReportOptions {
            threshold_mas: a.threshold_mas,
            metric: a.metric.clone(),
            x: a.x.clone(),
        },
    )?;
    print!("{}", sweep::render_report(&s));
    println!(
        "wrote {} and {} figure(s) in {}",
        a.dir
            .join(engine::io::products::files::REPORT_CSV)
            .display(),
        s.files.len() - 1,
        a.dir.join("report").display()
    );
    Ok(())
}
