//! What the panels read besides the settings: the engine's latest results, the status of the work, and
//! what is on screen now (to tag results computed for other parameters as stale). Only `app.rs` writes
//! these; the panels take them by reference.

use crate::settings::{Settings, ViewSettings};
use crate::worker::{
    CrowdedResult, CurvePoint, FocalPlaneResult, FrameResult, Prediction, SeriesView, Stage,
    TwinResult,
};
use engine::analysis::countermeasures::Countermeasure;
use engine::config::Config;

/// A short message for the user.
#[derive(Debug, Clone, PartialEq)]
pub struct Note {
    pub text: String,
    pub is_error: bool,
}

/// Progress of the running job.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    pub stage: Stage,
    pub done: usize,
    pub total: usize,
    pub note: String,
}

/// The status of the work.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Status {
    /// Work is queued or running.
    pub busy: bool,
    pub progress: Option<Progress>,
    /// Latest user-facing note (file operations, engine errors).
    pub note: Option<Note>,
    /// Why the current parameters cannot be run (validation), if so.
    pub invalid: Option<String>,
    pub last_job_s: Option<f64>,
}

/// The engine's latest results, each tagged with the parameters it was computed for.
#[derive(Debug, Clone, Default)]
pub struct Results {
    pub prediction: Option<Prediction>,
    pub series: Option<SeriesView>,
    pub frame: Option<FrameResult>,
    pub twin: Option<TwinResult>,
    /// The quad focal plane's exposure (shown instead of the frame when the layout is quad).
    pub focal_plane: Option<FocalPlaneResult>,
    /// Its crowded-field analysis (the quad's vector maps and magnitude curve).
    pub crowded: Option<CrowdedResult>,
    /// Accuracy curve, by magnitude, and the request key it belongs to.
    pub curve: Vec<CurvePoint>,
    pub curve_key: Option<String>,
    /// Counters that change whenever a new frame / twin arrives (texture keys).
    pub frame_serial: u64,
    pub twin_serial: u64,
    pub focal_plane_serial: u64,
    pub crowded_serial: u64,
}

impl Results {
    /// Merge a point of the curve (a prediction first, its Monte Carlo rows later).
    pub fn merge_curve(&mut self, p: CurvePoint) {
        match self.curve.iter_mut().find(|c| (c.mag - p.mag).abs() < 1e-9) {
            Some(c) => {
                c.predicted_mas = p.predicted_mas.or(c.predicted_mas);
                c.predicted_none_mas = p.predicted_none_mas.or(c.predicted_none_mas);
                if p.rows.is_some() {
                    c.rows = p.rows;
                }
                c.generation = p.generation;
            }
            None => {
                self.curve.push(p);
                self.curve.sort_by(|a, b| a.mag.total_cmp(&b.mag));
            }
        }
    }
}

/// The parameters on screen, for the panels' stale tags and titles.
#[derive(Debug, Clone)]
pub struct OnScreen {
    pub cfg: Config,
    pub cfg_hash: String,
    pub countermeasure: Countermeasure,
    pub mags: Vec<f64>,
    /// [`Request::curve_key`](crate::worker::Request::curve_key) of the settings.
    pub curve_key: String,
}

impl OnScreen {
    pub fn of(s: &Settings) -> Self {
        Self {
            cfg: s.cfg.clone(),
            cfg_hash: s.cfg.hash_hex(),
            countermeasure: s.countermeasure,
            mags: s.mags.clone(),
            curve_key: s.request().curve_key(),
        }
    }
}

/// The pixel whose exposure window is shown: the clicked one, else the chosen star's centre.
pub fn chosen_pixel(view: &ViewSettings, frame: Option<&FrameResult>) -> Option<(usize, usize)> {
    if let Some(p) = view.pixel {
        return Some(p);
    }
    let f = frame?;
    let (x, y) = *f.truth_xy.get(view.star)?;
    let n = f.n.max(1) as f64;
    Some((
        x.round().clamp(0.0, n - 1.0) as usize,
        y.round().clamp(0.0, n - 1.0) as usize,
    ))
}
