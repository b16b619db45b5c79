//! The explorer's state: one struct of persisted parameters (the engine [`Config`], the countermeasure,
//! the curve's magnitudes, view settings) plus runtime state (worker handle, results, textures) in
//! [`Runtime`], which is never persisted.
//!
//! Each frame: take the worker's messages (dropping those of old generations), draw the panels (the controls
//! edit the parameters in place), then compare what is on screen with what was last requested and, if it
//! changed, start a new generation of work with only the stages that the change invalidates.

use crate::panels;
use crate::view::{Colormap, Stretch};
use crate::worker::{
    CurvePoint, FrameResult, Job, Msg, Prediction, Request, SeriesView, Stage, Stages, TwinResult,
    Worker,
};
use engine::config::Config;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Default magnitudes of the accuracy curve (the paper's).
pub const DEFAULT_MAGS: [f64; 6] = [12.0, 12.5, 13.0, 13.5, 14.0, 14.5];

/// Marker of the app's own lines in a saved configuration (TOML comments: the engine ignores them).
const APP_TAG: &str = "# jsim-app";

/// View settings (persisted with the parameters; they change no result).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewSettings {
    pub stretch: Stretch,
    pub colormap: Colormap,
    pub show_channels: bool,
    pub show_stars: bool,
    /// Index of the displayed exposure within the dataset.
    pub image_index: usize,
    /// The chosen star (index into the scene) and pixel (for the exposure window).
    pub star: usize,
    pub pixel: Option<(usize, usize)>,
    pub closeup_radius_px: usize,
    /// Show the fit displacement the ACE predicts (the mechanism) beside the measured deviations.
    pub show_predicted_arrows: bool,
    /// Run the magnitude curve after every change.
    pub auto_curve: bool,
}

impl Default for ViewSettings {
    fn default() -> Self {
        Self {
            stretch: Stretch::Asinh,
            colormap: Colormap::Gray,
            show_channels: true,
            show_stars: false,
            image_index: 0,
            star: 0,
            pixel: None,
            closeup_radius_px: 8,
            show_predicted_arrows: true,
            auto_curve: true,
        }
    }
}

/// The explorer app.
#[derive(Serialize, Deserialize)]
#[serde(default)]
pub struct ExplorerApp {
    /// The engine configuration: every simulation and analysis knob on screen.
    pub cfg: Config,
    /// Countermeasure applied in the analysis (`none`, `yzones`, `plate-affine`, `plate-poly:3`, `telemetry`).
    pub countermeasure: String,
    /// Magnitudes of the accuracy curve.
    pub mags: Vec<f64>,
    pub view: ViewSettings,
    /// Path for Open / Save / Copy as CLI.
    pub config_path: String,
    /// Runtime state.
    #[serde(skip)]
    pub rt: Runtime,
}

impl Default for ExplorerApp {
    fn default() -> Self {
        Self::new(Config::default())
    }
}

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

/// Actions the panels ask the app to perform.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    Open,
    Save,
    CopyExperimentCli,
    CopySimulateCli,
    Cancel,
    RunAll,
    RunCurve,
}

/// Runtime state (never persisted).
#[derive(Default)]
pub struct Runtime {
    worker: Option<Worker>,
    /// The current generation: messages of any other are dropped.
    pub generation: u64,
    /// The request the current results (or the running job) belong to.
    pub last_request: Option<Request>,
    last_auto_curve: bool,
    pending: Option<Box<Job>>,
    /// Stages of the job in flight (not finished), for merging with the next job.
    in_flight: Stages,
    pub busy: bool,
    pub progress: Option<Progress>,
    /// Latest user-facing note (file operations, engine errors).
    pub note: Option<Note>,
    /// Why the current parameters cannot be run (validation), if so.
    pub invalid: Option<String>,
    /// Text of the magnitude list, as typed.
    pub mags_text: String,
    pub mags_error: Option<String>,
    pub prediction: Option<Prediction>,
    pub series: Option<SeriesView>,
    pub frame: Option<FrameResult>,
    pub twin: Option<TwinResult>,
    /// Accuracy curve, by magnitude, and the request key it belongs to.
    pub curve: Vec<CurvePoint>,
    pub curve_key: Option<String>,
    /// Counters that change whenever a new frame / twin arrives (texture keys).
    pub frame_serial: u64,
    pub twin_serial: u64,
    pub textures: panels::image::Textures,
    /// Number of jobs sent (for tests and the status line).
    pub jobs_sent: u64,
    pub last_job_s: Option<f64>,
}

impl ExplorerApp {
    /// An app on `cfg`; the worker thread starts with the first frame (so no window is needed to build one).
    pub fn new(cfg: Config) -> Self {
        let mags = DEFAULT_MAGS.to_vec();
        let rt = Runtime {
            mags_text: format_mags(&mags),
            ..Default::default()
        };
        Self {
            cfg,
            countermeasure: "none".into(),
            mags,
            view: ViewSettings::default(),
            config_path: "jsim-explorer.toml".into(),
            rt,
        }
    }

    /// The app for the command line `jsim-app [CONFIG.toml]`: the reference configuration, or the file given
    /// (a file that cannot be loaded is reported in the window, on the reference configuration).
    pub fn from_args(mut args: impl Iterator<Item = std::ffi::OsString>) -> Self {
        let mut app = Self::new(Config::default());
        if let Some(p) = args.next() {
            app.config_path = p.to_string_lossy().into_owned();
            app.open_config();
        }
        app
    }

    /// Set the curve's magnitudes (also the text field).
    pub fn set_mags(&mut self, mags: Vec<f64>) {
        self.rt.mags_text = format_mags(&mags);
        self.mags = mags;
    }

    /// The request that matches what is on screen.
    pub fn request(&self) -> Request {
        Request {
            cfg: self.cfg.clone(),
            countermeasure: self.countermeasure.clone(),
            image_index: self.view.image_index,
            mags: self.mags.clone(),
        }
    }

    /// True when no work is queued or running.
    pub fn is_idle(&self) -> bool {
        !self.rt.busy && self.rt.pending.is_none()
    }

    /// Draw the whole app into `ui` (the root ui of a frame) and start work as needed.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        self.ensure_worker(&ctx);
        self.receive();

        let mut actions = Vec::new();
        egui::Panel::top("toolbar").show(ui, |ui| {
            panels::toolbar::toolbar_ui(ui, self, &mut actions);
        });
        egui::Panel::bottom("summary").show(ui, |ui| {
            panels::summary::summary_ui(ui, self);
        });
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                panels::controls::controls_ui(
                    ui,
                    &mut self.cfg,
                    &mut self.countermeasure,
                    &mut self.view,
                    &mut self.rt.mags_text,
                    self.rt.mags_error.as_deref(),
                );
            });
        egui::CentralPanel::default().show(ui, |ui| {
            panels::central_ui(ui, self, &mut actions);
        });

        for a in actions {
            self.perform(a, &ctx);
        }
        self.sync(&ctx);
    }

    fn ensure_worker(&mut self, ctx: &egui::Context) {
        if self.rt.worker.is_none() {
            match Worker::spawn(ctx.clone()) {
                Ok(w) => self.rt.worker = Some(w),
                Err(e) => {
                    self.rt.note = Some(Note {
                        text: format!("cannot start the engine thread: {e}"),
                        is_error: true,
                    })
                }
            }
        }
    }

    /// Apply the worker's messages of the current generation.
    fn receive(&mut self) {
        let Some(w) = &self.rt.worker else { return };
        for m in w.poll() {
            if m.generation() != self.rt.generation {
                continue;
            }
            match m {
                Msg::Progress {
                    stage,
                    done,
                    total,
                    note,
                    ..
                } => {
                    self.rt.progress = Some(Progress {
                        stage,
                        done,
                        total,
                        note,
                    })
                }
                Msg::Prediction(p) => self.rt.prediction = Some(*p),
                Msg::Series(s) => self.rt.series = Some(*s),
                Msg::Frame(f) => {
                    if self.view.star >= f.truth_xy.len() {
                        self.view.star = 0;
                    }
                    self.rt.frame = Some(*f);
                    self.rt.frame_serial += 1;
                }
                Msg::Twin(t) => {
                    self.rt.twin = Some(*t);
                    self.rt.twin_serial += 1;
                }
                Msg::Curve(c) => merge_curve(&mut self.rt.curve, *c),
                Msg::Done { elapsed_s, .. } => {
                    self.rt.busy = false;
                    self.rt.in_flight = Stages::default();
                    self.rt.progress = None;
                    self.rt.last_job_s = Some(elapsed_s);
                }
                Msg::Cancelled { .. } => {
                    self.rt.busy = false;
                    self.rt.progress = None;
                }
                Msg::Error { stage, message, .. } => {
                    self.rt.busy = false;
                    self.rt.in_flight = Stages::default();
                    self.rt.progress = None;
                    self.rt.note = Some(Note {
                        text: format!("engine ({}): {message}", stage.name()),
                        is_error: true,
                    });
                }
            }
        }
    }

    /// Compare the parameters on screen with the last request and start the stages a change invalidates.
    fn sync(&mut self, ctx: &egui::Context) {
        match parse_mags(&self.rt.mags_text) {
            Ok(m) => {
                self.rt.mags_error = None;
                if m != self.mags {
                    self.mags = m;
                }
            }
            Err(e) => self.rt.mags_error = Some(e),
        }
        if self.view.image_index >= self.cfg.fidelity.images {
            self.view.image_index = self.cfg.fidelity.images.saturating_sub(1);
        }
        let req = self.request();
        self.rt.invalid = req.cfg.validate().err().map(|e| e.to_string());
        if self.rt.invalid.is_none()
            && !crate::worker::COUNTERMEASURES.contains(&req.countermeasure.as_str())
        {
            self.rt.invalid = Some(format!("unknown countermeasure `{}`", req.countermeasure));
        }
        let auto_curve = self.view.auto_curve;
        let changed =
            self.rt.last_request.as_ref() != Some(&req) || (auto_curve && !self.rt.last_auto_curve);
        if changed && self.rt.invalid.is_none() {
            let mut stages = stages_for(self.rt.last_request.as_ref(), &req, auto_curve);
            if auto_curve && !self.rt.last_auto_curve {
                stages.curve = true;
            }
            self.submit(req, stages);
        }
        self.rt.last_auto_curve = auto_curve;
        self.flush(ctx);
    }

    /// Start a new generation of work.
    fn submit(&mut self, req: Request, mut stages: Stages) {
        if self.rt.busy {
            // unfinished stages of the abandoned job still need doing (results are cached by the worker)
            stages = stages.union(self.rt.in_flight);
        }
        self.rt.last_request = Some(req.clone());
        if !stages.any() {
            // nothing to recompute (and, since not busy, nothing to abandon)
            return;
        }
        self.rt.generation += 1;
        if stages.curve {
            let key = curve_key(&req);
            if self.rt.curve_key.as_deref() != Some(key.as_str()) {
                self.rt.curve.clear();
                self.rt.curve_key = Some(key);
            }
        }
        if self.rt.note.as_ref().is_some_and(|n| n.is_error) {
            self.rt.note = None;
        }
        self.rt.in_flight = stages;
        self.rt.busy = true;
        self.rt.progress = None;
        self.rt.pending = Some(Box::new(Job {
            generation: self.rt.generation,
            request: req,
            stages,
        }));
        if let Some(w) = &self.rt.worker {
            w.set_generation(self.rt.generation);
        }
    }

    /// Hand the pending job to the worker (a full queue keeps it for the next frame).
    fn flush(&mut self, ctx: &egui::Context) {
        if let (Some(job), Some(w)) = (self.rt.pending.take(), &self.rt.worker) {
            match w.try_submit(job) {
                Ok(()) => self.rt.jobs_sent += 1,
                Err(job) => {
                    self.rt.pending = Some(job);
                    ctx.request_repaint_after(std::time::Duration::from_millis(30));
                }
            }
        }
    }

    fn perform(&mut self, a: Action, ctx: &egui::Context) {
        match a {
            Action::Open => self.open_config(),
            Action::Save => {
                let p = self.config_path.clone();
                match self.save_config(Path::new(&p)) {
                    Ok(path) => self.info(format!("saved {}", path.display())),
                    Err(e) => self.error(e),
                }
            }
            Action::CopyExperimentCli | Action::CopySimulateCli => {
                let p = self.config_path.clone();
                match self.save_config(Path::new(&p)) {
                    Ok(path) => {
                        let cmd = if a == Action::CopyExperimentCli {
                            self.experiment_cli(&path)
                        } else {
                            simulate_cli(&path)
                        };
                        ctx.copy_text(cmd.clone());
                        self.info(format!("copied: {cmd}"));
                    }
                    Err(e) => self.error(e),
                }
            }
            Action::Cancel => self.cancel(),
            Action::RunAll => {
                let req = self.request();
                if self.rt.invalid.is_none() {
                    let stages = Stages {
                        curve: self.view.auto_curve,
                        ..Stages::ALL
                    };
                    self.submit(req, stages);
                }
            }
            Action::RunCurve => {
                let req = self.request();
                if self.rt.invalid.is_none() {
                    self.submit(
                        req,
                        Stages {
                            curve: true,
                            ..Default::default()
                        },
                    );
                }
            }
        }
    }

    /// Abandon the running job (its results so far stay on screen).
    pub fn cancel(&mut self) {
        self.rt.generation += 1;
        if let Some(w) = &self.rt.worker {
            w.set_generation(self.rt.generation);
        }
        self.rt.pending = None;
        self.rt.busy = false;
        self.rt.in_flight = Stages::default();
        self.rt.progress = None;
        self.info("cancelled".into());
    }

    fn info(&mut self, text: String) {
        self.rt.note = Some(Note {
            text,
            is_error: false,
        });
    }

    fn error(&mut self, text: String) {
        self.rt.note = Some(Note {
            text,
            is_error: true,
        });
    }

    /// Load the configuration at `config_path` (errors are shown, the current parameters stay).
    pub fn open_config(&mut self) {
        let path = PathBuf::from(self.config_path.trim());
        match Config::load(&path) {
            Ok(cfg) => {
                self.cfg = cfg;
                // the app's own settings, if this file was saved by the app
                if let Ok(text) = std::fs::read_to_string(&path) {
                    for line in text.lines() {
                        if let Some(rest) = line.strip_prefix(APP_TAG) {
                            let rest = rest.trim();
                            if let Some(cm) = rest.strip_prefix("countermeasure =") {
                                let cm = cm.trim();
                                if crate::worker::COUNTERMEASURES.contains(&cm) {
                                    self.countermeasure = cm.to_string();
                                }
                            } else if let Some(m) = rest.strip_prefix("mags =")
                                && let Ok(m) = parse_mags(m)
                            {
                                self.set_mags(m);
                            }
                        }
                    }
                }
                self.info(format!("loaded {}", path.display()));
            }
            Err(e) => self.error(e.to_string()),
        }
    }

    /// The TOML that reproduces what is on screen: the engine configuration, with the app's choices and the
    /// equivalent commands as comments.
    pub fn config_text(&self, path: &Path) -> String {
        format!(
            "{APP_TAG} countermeasure = {}\n{APP_TAG} mags = {}\n# reproduce: {}\n#            {}\n\n{}",
            self.countermeasure,
            format_mags(&self.mags),
            self.experiment_cli(path),
            simulate_cli(path),
            self.cfg.to_toml()
        )
    }

    /// Write the configuration; returns the absolute path written.
    pub fn save_config(&self, path: &Path) -> Result<PathBuf, String> {
        if path.as_os_str().is_empty() {
            return Err("give a file name for the configuration".into());
        }
        self.cfg.validate().map_err(|e| format!("not saved: {e}"))?;
        let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        std::fs::write(&abs, self.config_text(&abs))
            .map_err(|e| format!("cannot write {}: {e}", abs.display()))?;
        Ok(abs)
    }

    /// `jsim experiment` for the curve on screen.
    pub fn experiment_cli(&self, path: &Path) -> String {
        let mut cms = vec!["none".to_string()];
        if self.countermeasure != "none" {
            cms.push(self.countermeasure.clone());
        }
        format!(
            "jsim experiment --config {} --aces {} --readouts {} --mags {} --countermeasures {} --out out/explorer",
            shell_quote(path),
            self.cfg.ace.case.name(),
            self.cfg.readout.order.name(),
            self.mags
                .iter()
                .map(|m| m.to_string())
                .collect::<Vec<_>>()
                .join(","),
            cms.join(",")
        )
    }
}

/// `jsim simulate` for the images on screen.
pub fn simulate_cli(path: &Path) -> String {
    format!(
        "jsim simulate --config {} --out out/explorer-images",
        shell_quote(path)
    )
}

fn shell_quote(p: &Path) -> String {
    let s = p.display().to_string();
    if s.chars()
        .all(|c| c.is_ascii_alphanumeric() || "/._-+:=,".contains(c))
    {
        s
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

impl eframe::App for ExplorerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }
}

/// The stages a change from `old` to `new` invalidates.
pub fn stages_for(old: Option<&Request>, new: &Request, auto_curve: bool) -> Stages {
    let Some(o) = old else {
        return Stages {
            curve: auto_curve,
            ..Stages::ALL
        };
    };
    if o.cfg != new.cfg || o.countermeasure != new.countermeasure {
        return Stages {
            curve: auto_curve,
            ..Stages::ALL
        };
    }
    let index = o.image_index != new.image_index;
    Stages {
        predict: index,
        image: index,
        curve: auto_curve && o.mags != new.mags,
    }
}

/// What the accuracy curve depends on (the magnitude of the single image excepted).
pub fn curve_key(r: &Request) -> String {
    let mut c = r.cfg.clone();
    c.scene.mag_hw = 0.0;
    format!(
        "{}|{}|{}",
        c.hash_hex(),
        r.countermeasure,
        format_mags(&r.mags)
    )
}

fn merge_curve(curve: &mut Vec<CurvePoint>, p: CurvePoint) {
    match curve.iter_mut().find(|c| (c.mag - p.mag).abs() < 1e-9) {
        Some(c) => {
            c.predicted_mas = p.predicted_mas.or(c.predicted_mas);
            c.predicted_none_mas = p.predicted_none_mas.or(c.predicted_none_mas);
            if p.rows.is_some() {
                c.rows = p.rows;
            }
            c.generation = p.generation;
        }
        None => {
            curve.push(p);
            curve.sort_by(|a, b| a.mag.total_cmp(&b.mag));
        }
    }
}

pub fn format_mags(m: &[f64]) -> String {
    m.iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Parse a list of magnitudes: numbers separated by commas or spaces, each in the engine's range.
pub fn parse_mags(s: &str) -> Result<Vec<f64>, String> {
    let mut v = Vec::new();
    for tok in s.split([',', ' ', ';']).filter(|t| !t.trim().is_empty()) {
        let m: f64 = tok
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a magnitude", tok.trim()))?;
        if !(-5.0..=40.0).contains(&m) {
            return Err(format!("magnitude {m} outside −5…40"));
        }
        v.push(m);
    }
    if v.is_empty() {
        return Err("give at least one magnitude".into());
    }
    if v.len() > 20 {
        return Err("at most 20 magnitudes".into());
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v.dedup();
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mags_parse_and_reject() {
        assert_eq!(
            parse_mags("13, 12.5 12").expect("ok"),
            vec![12.0, 12.5, 13.0]
        );
        assert!(parse_mags("12, x").is_err());
        assert!(parse_mags("").is_err());
        assert!(parse_mags("99").is_err());
    }

    #[test]
    fn only_invalidated_stages_rerun() {
        let a = ExplorerApp::new(Config::default()).request();
        let mut b = a.clone();
        b.image_index = 1;
        assert_eq!(
            stages_for(Some(&a), &b, true),
            Stages {
                predict: true,
                image: true,
                curve: false
            }
        );
        let mut c = a.clone();
        c.mags = vec![12.0];
        assert_eq!(
            stages_for(Some(&a), &c, true),
            Stages {
                predict: false,
                image: false,
                curve: true
            }
        );
        let mut d = a.clone();
        d.cfg.ace.sigma_mas = 150.0;
        assert_eq!(
            stages_for(Some(&a), &d, false),
            Stages {
                curve: false,
                ..Stages::ALL
            }
        );
        assert_eq!(stages_for(None, &a, true), Stages::ALL);
    }

    #[test]
    fn a_change_with_nothing_to_recompute_starts_no_work() {
        let mut app = ExplorerApp::new(Config::default());
        app.view.auto_curve = false;
        let ctx = egui::Context::default();
        app.sync(&ctx);
        assert!(
            app.rt.busy,
            "the first frame asks for the prediction and the image"
        );
        assert_eq!(
            app.rt.in_flight,
            Stages {
                curve: false,
                ..Stages::ALL
            }
        );
        // as if the worker had finished
        app.rt.busy = false;
        app.rt.pending = None;
        app.rt.in_flight = Stages::default();
        let generation = app.rt.generation;
        app.rt.mags_text = "12, 13".into();
        app.sync(&ctx);
        assert_eq!(app.mags, vec![12.0, 13.0]);
        assert_eq!(
            app.rt.generation, generation,
            "no curve is wanted: nothing starts"
        );
        assert!(app.is_idle());
        // an invalid parameter is reported and not run
        app.cfg.ace.sigma_mas = -1.0;
        app.sync(&ctx);
        assert!(
            app.rt
                .invalid
                .as_deref()
                .is_some_and(|e| e.contains("ace.sigma_mas"))
        );
        assert!(app.is_idle());
    }

    #[test]
    fn saved_config_reloads_identically() {
        let mut app = ExplorerApp::new(Config::default());
        app.cfg.ace.sigma_mas = 123.0;
        app.countermeasure = "plate-poly:3".into();
        app.set_mags(vec![12.0, 13.0]);
        let dir = std::env::temp_dir().join(format!("jsim-app-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("cfg with space.toml");
        let written = app.save_config(&path).expect("saved");
        let back = Config::load(&written).expect("loads");
        assert_eq!(back, app.cfg);
        let mut other = ExplorerApp::new(Config::default());
        other.config_path = written.display().to_string();
        other.open_config();
        assert_eq!(other.cfg, app.cfg);
        assert_eq!(other.countermeasure, "plate-poly:3");
        assert_eq!(other.mags, vec![12.0, 13.0]);
        assert!(
            app.experiment_cli(&written).contains("'"),
            "paths with spaces are quoted"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
