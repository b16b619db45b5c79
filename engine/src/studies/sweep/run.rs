//! Running units: [`compute_unit`] simulates, analyses and predicts one exposure; [`run_shard`] runs or
//! resumes one shard of a sweep, several units at once, writing the shard file after each.

use super::error::{SweepError, io_err};
use super::record::{UnitRows, float_cell};
use super::shard::{Shard, list_shards, read_shard, shard_paths, write_shard};
use super::spec::{Sweep, prepare_dir};
use crate::session::Session;
use crate::studies::experiment;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

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

/// Fewest scored stars (matched to the truth, not rejected) an exposure's analysis needs to count in a
/// sweep: the accuracy is a standard deviation over the stars, whose relative error is ≈ 1/√(2(n − 1)), so
/// below 10 stars it is uncertain by more than 24 % and the exposure is recorded as failed, with its reason.
pub const MIN_SWEEP_STARS: usize = 10;

/// Whether an analysis has an accuracy a sweep can count ([`MIN_SWEEP_STARS`] scored stars, finite).
fn scored(r: &crate::scoring::image::Report) -> bool {
    r.n_used >= MIN_SWEEP_STARS && r.accuracy_mas.is_finite()
}

/// Compute one unit: simulate its stare, analyse every exposure with every countermeasure (the stack of the
/// stare as the stack-referenced plate models' reference), predict. Configuration and simulator errors are
/// returned; an analysis failure is recorded in the rows (`status`) of every exposure of the stare.
pub fn compute_unit(sweep: &Sweep, unit: usize, session: &Session) -> Result<UnitRows, SweepError> {
    let t0 = Instant::now();
    let (point, first) = sweep.unit(unit);
    let cfg = sweep.unit_config(unit);
    let uerr = |message: String| SweepError::Unit {
        unit,
        point,
        exposure: first,
        message,
    };
    let sim = session
        .new_simulator(&cfg)
        .map_err(|e| uerr(e.to_string()))?;
    session.warm(&sim);
    let k_stare = sweep.stare_exposures;
    let analysed = experiment::analyse_stare(&sim, 0..k_stare, &sweep.plan, &mut |_| {
        std::ops::ControlFlow::Continue(())
    });
    let tp = Instant::now();
    let predictor = crate::studies::predict::Predictor::new(&sim, &cfg.analysis).ok();
    // a prediction that cannot be made is recorded as NaN beside the measured row (the file has no other
    // place for the reason; `jsim predict` reports it)
    let predicted: Vec<Vec<f64>> = (0..k_stare)
        .map(|i| {
            sweep
                .plan
                .countermeasures
                .iter()
                .map(|c| {
                    predictor
                        .as_ref()
                        .and_then(|p| p.predict_image(i, c).ok())
                        .unwrap_or(f64::NAN)
                })
                .collect()
        })
        .collect();
    let predict_s = tp.elapsed().as_secs_f64() / k_stare as f64;
    let unit_s = t0.elapsed().as_secs_f64() / k_stare as f64;
    let nan = f64::NAN;
    let mut rows = Vec::with_capacity(k_stare * sweep.countermeasures.len());
    for i in 0..k_stare {
        for (k, cm) in sweep.countermeasures.iter().enumerate() {
            let mut r: Vec<String> =
                vec![unit.to_string(), point.to_string(), (first + i).to_string()];
            r.extend(sweep.points[point].values.iter().cloned());
            r.push(cm.clone());
            match analysed.as_ref().map(|v| &v[i]) {
                Ok(im) => {
                    match im.measured.iter().find(|m| &m.countermeasure == cm) {
                        Some(m) if !scored(&m.report) => {
                            // too few scored stars: a failed exposure with its reason, never a pass
                            r.push(format!(
                                "failed: {} star(s) scored, fewer than {MIN_SWEEP_STARS}",
                                m.report.n_used
                            ));
                            for v in [nan, nan, nan, nan, nan, nan, predicted[i][k]] {
                                r.push(float_cell(v));
                            }
                            r.push(m.report.n_used.to_string());
                        }
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
                                predicted[i][k],
                            ] {
                                r.push(float_cell(v));
                            }
                            r.push(rep.n_used.to_string());
                        }
                        None => {
                            r.push("not applicable".into());
                            for v in [nan, nan, nan, nan, nan, nan, predicted[i][k]] {
                                r.push(float_cell(v));
                            }
                            r.push("0".into());
                        }
                    }
                    r.push(float_cell(im.ace_sigma_mas));
                    r.push(float_cell(im.ace_drift_mas));
                    r.push(cfg.seed.to_string());
                    r.push(float_cell(im.simulate_s));
                    r.push(float_cell(im.analyse_s));
                }
                Err(e) => {
                    let msg = format!("error: {e}").replace(['\n', '\r'], " ");
                    r.push(msg);
                    for v in [nan, nan, nan, nan, nan, nan, predicted[i][k]] {
                        r.push(float_cell(v));
                    }
                    r.push("0".into());
                    let a = sim.ace_stats(i);
                    r.push(float_cell(
                        ((a.sigma_x_mas.powi(2) + a.sigma_y_mas.powi(2)) / 2.0).sqrt(),
                    ));
                    r.push(float_cell(a.drift_mas));
                    r.push(cfg.seed.to_string());
                    r.push(float_cell(nan));
                    r.push(float_cell(nan));
                }
            }
            r.push(float_cell(predict_s));
            r.push(float_cell(unit_s));
            rows.push(r);
        }
    }
    Ok(rows)
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
    let lock = ShardLock::take(dir, shard)?;
    // this shard's temporary files left by a killed run (`shard-….csv.<pid>.tmp`)
    let stem = format!("{}.", shard.stem());
    crate::io::remove_stale_temps(&dir.join("shards"), |name| name.starts_with(&stem));
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
    let computed = compute_units(session, sweep, dir, opts, &todo, &mut units, on_event);
    drop(lock);
    let computed = computed?;
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

/// One process per shard: an advisory lock on `shards/<shard>.lock`, released by the OS when the process
/// ends however it ends, and explicitly when dropped: a child forked meanwhile by another thread may hold a
/// copy of the descriptor until it execs, and closing ours alone would not release the lock until then.
struct ShardLock(std::fs::File);

impl ShardLock {
    /// The shard's lock, or a named error when another process holds it.
    fn take(dir: &Path, shard: Shard) -> Result<Self, SweepError> {
        let lock_path = dir.join("shards").join(format!("{}.lock", shard.stem()));
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .map_err(|e| io_err(&lock_path, e))?;
        match lock.try_lock() {
            Ok(()) => Ok(Self(lock)),
            Err(std::fs::TryLockError::WouldBlock) => Err(SweepError::Invalid(format!(
                "shard {shard} of {} is being run by another process (it holds {}); wait for it or stop it",
                dir.display(),
                lock_path.display()
            ))),
            Err(std::fs::TryLockError::Error(e)) => Err(io_err(&lock_path, e)),
        }
    }
}

impl Drop for ShardLock {
    fn drop(&mut self) {
        let _ = self.0.unlock();
    }
}

/// Compute the units `todo` (at most `opts.max_units`) on `opts.jobs` threads, each written into the
/// shard's file as it finishes (the file rewritten whole: an interrupted run loses only the units in
/// flight); returns how many were computed, or the first error (the other threads stop).
fn compute_units(
    session: &Session,
    sweep: &Sweep,
    dir: &Path,
    opts: &RunOptions,
    todo: &[usize],
    units: &mut BTreeMap<usize, UnitRows>,
    on_event: &mut dyn FnMut(Event),
) -> Result<usize, SweepError> {
    let (shard, rec) = (opts.shard, sweep.record());
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
            let (next, stop) = (&next, &stop);
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
                    if let Err(e) = write_shard(&rec, dir, shard, units) {
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
    match first_err {
        Some(e) => Err(e),
        None => Ok(computed),
    }
}
