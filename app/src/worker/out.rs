//! Where a running job reports to, and how it stops early: its messages go to the UI (each followed by a
//! repaint), and [`Out::check`] abandons the job as soon as a newer generation exists.

use super::protocol::{Msg, Stage};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::Sender;

/// Why a job stopped early.
#[derive(Debug)]
pub enum Stop {
    Cancelled,
    Failed(Stage, String),
}

pub type StageResult<T> = Result<T, Stop>;

/// Turn an engine error into a failure of `stage`.
pub fn failed<E: std::fmt::Display>(stage: Stage) -> impl Fn(E) -> Stop {
    move |e| Stop::Failed(stage, e.to_string())
}

/// Where a job reports to.
pub struct Out<'a> {
    pub tx: &'a Sender<Msg>,
    pub ctx: &'a egui::Context,
    pub latest: &'a AtomicU64,
    pub generation: u64,
}

impl Out<'_> {
    pub fn send(&self, m: Msg) {
        // a closed channel means the UI is gone: the next check ends the job
        let _ = self.tx.send(m);
        self.ctx.request_repaint();
    }

    /// Abandon the job if a newer generation exists.
    pub fn check(&self) -> StageResult<()> {
        if self.latest.load(Ordering::Acquire) == self.generation {
            Ok(())
        } else {
            Err(Stop::Cancelled)
        }
    }

    pub fn progress(&self, stage: Stage, done: usize, total: usize, note: impl Into<String>) {
        self.send(Msg::Progress {
            generation: self.generation,
            stage,
            done,
            total,
            note: note.into(),
        });
    }
}
