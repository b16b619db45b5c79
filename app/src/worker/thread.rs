//! The engine thread: [`Worker::spawn`] starts the named thread `jsim-engine`, which owns the engine state
//! and runs the newest job of the current generation; [`Worker::set_generation`] makes older work stale.
//! A panic in the engine is caught, reported as an error and followed by a fresh engine state.

use super::out::{Out, Stop};
use super::protocol::{Job, Msg, Stage};
use super::stages::EngineState;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender, TrySendError};
use std::time::Instant;

/// Generation value that tells the worker to stop for good.
const SHUTDOWN: u64 = u64::MAX;

/// The UI's handle on the worker thread.
pub struct Worker {
    jobs: SyncSender<Box<Job>>,
    results: Receiver<Msg>,
    latest: Arc<AtomicU64>,
}

impl Worker {
    /// Start the named worker thread. `ctx` is repainted whenever a message is sent.
    pub fn spawn(ctx: egui::Context) -> std::io::Result<Self> {
        let (job_tx, job_rx) = mpsc::sync_channel::<Box<Job>>(4);
        let (msg_tx, msg_rx) = mpsc::channel::<Msg>();
        let latest = Arc::new(AtomicU64::new(0));
        let shared = latest.clone();
        std::thread::Builder::new()
            .name("jsim-engine".into())
            .spawn(move || worker_loop(job_rx, msg_tx, shared, ctx))?;
        Ok(Self {
            jobs: job_tx,
            results: msg_rx,
            latest,
        })
    }

    /// Make `generation` the current one: work of any older generation is abandoned at its next check.
    pub fn set_generation(&self, generation: u64) {
        self.latest.store(generation, Ordering::Release);
    }

    /// Queue a job without blocking; a full queue hands the job back (send it again next frame).
    pub fn try_submit(&self, job: Box<Job>) -> Result<(), Box<Job>> {
        self.set_generation(job.generation);
        match self.jobs.try_send(job) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(j)) => Err(j),
            // the thread is gone (it only ends on shutdown): nothing to do
            Err(TrySendError::Disconnected(_)) => Ok(()),
        }
    }

    /// Every message waiting.
    pub fn poll(&self) -> Vec<Msg> {
        self.results.try_iter().collect()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        // stop the running job at its next check; the thread ends when the job channel closes
        self.latest.store(SHUTDOWN, Ordering::Release);
    }
}

fn worker_loop(
    rx: Receiver<Box<Job>>,
    tx: Sender<Msg>,
    latest: Arc<AtomicU64>,
    ctx: egui::Context,
) {
    let mut engine = EngineState::default();
    while let Ok(mut job) = rx.recv() {
        // only the newest queued job matters
        while let Ok(j) = rx.try_recv() {
            job = j;
        }
        let current = latest.load(Ordering::Acquire);
        if current == SHUTDOWN {
            break;
        }
        if job.generation != current {
            continue;
        }
        let out = Out {
            tx: &tx,
            ctx: &ctx,
            latest: &latest,
            generation: job.generation,
        };
        let t0 = Instant::now();
        let result =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| engine.run(&job, &out)));
        let msg = match result {
            Ok(Ok(())) => Msg::Done {
                generation: job.generation,
                elapsed_s: t0.elapsed().as_secs_f64(),
            },
            Ok(Err(Stop::Cancelled)) => Msg::Cancelled {
                generation: job.generation,
            },
            Ok(Err(Stop::Failed(stage, message))) => Msg::Error {
                generation: job.generation,
                stage,
                message,
            },
            Err(panic) => {
                // a bug in the engine: report it, and start again from a clean state
                engine = EngineState::default();
                let what = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "unknown panic".into());
                Msg::Error {
                    generation: job.generation,
                    stage: Stage::Image,
                    message: format!("the engine panicked: {what}"),
                }
            }
        };
        out.send(msg);
    }
}
