//! The explorer: its [`Settings`] (persisted) and [`Runtime`] (the worker handle, the results, the
//! textures; never persisted).
//!
//! Each frame: take the worker's messages (dropping those of old generations), draw the panels (the controls
//! edit the settings in place; the other panels read the state and return [`Action`]s), perform the
//! actions, then compare what is on screen with what was last requested and, if it changed, start a new
//! generation of work with only the stages that the change invalidates. The sequence view reads a sequence's
//! products on Open sequence (small files, read at once) and starts no work.

use crate::action::Action;
use crate::panels;
use crate::reproduce;
use crate::settings::{CentralView, Settings, format_mags, parse_mags};
use crate::state::{Note, OnScreen, Progress, Results, Status};
use crate::worker::{Job, Msg, Request, Stages, Worker};
use engine::config::Config;
use std::path::{Path, PathBuf};

/// The explorer app.
pub struct ExplorerApp {
    pub settings: Settings,
    pub rt: Runtime,
}

impl Default for ExplorerApp {
    fn default() -> Self {
        Self::new(Config::default())
    }
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
    pub status: Status,
    pub results: Results,
    /// Text of the magnitude list, as typed.
    pub mags_text: String,
    pub mags_error: Option<String>,
    pub textures: panels::image::Textures,
    /// The sequence read by the last Open sequence, or why it could not be.
    pub sequence: panels::sequence::Loaded,
    /// Number of jobs sent (for tests and the status line).
    pub jobs_sent: u64,
    /// The transit view's stares.
    pub transit: crate::worker::transit::TransitRunner,
}

impl ExplorerApp {
    /// An app on `cfg`; the worker thread starts with the first frame (so no window is needed to build one).
    pub fn new(cfg: Config) -> Self {
        Self::with_settings(Settings::new(cfg))
    }

    pub fn with_settings(settings: Settings) -> Self {
        let rt = Runtime {
            mags_text: format_mags(&settings.mags),
            ..Default::default()
        };
        Self { settings, rt }
    }

    /// The app for the command line `jsim-app [CONFIG.toml] [--sequence DIR]`: the settings of the last
    /// session (from `storage`) or the defaults, then the file given, if any (a file that cannot be loaded is
    /// reported in the window), then the sequence given (shown in the sequence view) — or, without one, the
    /// last session's sequence where it left the sequence view on.
    pub fn from_args(
        storage: Option<&dyn eframe::Storage>,
        args: impl Iterator<Item = std::ffi::OsString>,
    ) -> Self {
        let settings = storage.and_then(Settings::load).unwrap_or_default();
        let mut app = Self::with_settings(settings);
        let cli = match CliArgs::parse(args) {
            Ok(c) => c,
            Err(e) => {
                app.error(e);
                CliArgs::default()
            }
        };
        if let Some(p) = cli.config {
            app.settings.config_path = p.to_string_lossy().into_owned();
            app.open_config();
        }
        if let Some(d) = cli.sequence {
            app.settings.sequence_dir = d.to_string_lossy().into_owned();
            app.open_sequence();
        } else if app.settings.view.central == CentralView::Sequence
            && !app.settings.sequence_dir.trim().is_empty()
        {
            app.open_sequence();
        }
        app
    }

    /// Set the curve's magnitudes (also the text field).
    pub fn set_mags(&mut self, mags: Vec<f64>) {
        self.rt.mags_text = format_mags(&mags);
        self.settings.mags = mags;
    }

    /// True when no work is queued or running.
    pub fn is_idle(&self) -> bool {
        !self.rt.status.busy && self.rt.pending.is_none()
    }

    /// Draw the whole app into `ui` (the root ui of a frame) and start work as needed.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        self.ensure_worker(&ctx);
        self.receive();

        let mut actions = Vec::new();
        egui::Panel::top("toolbar").show(ui, |ui| {
            panels::toolbar::toolbar_ui(
                ui,
                &mut self.settings.config_path,
                &mut self.settings.view.central,
                &self.rt.status,
                &mut actions,
            );
        });
        if self.settings.view.central == CentralView::Transit {
            self.show_transit(ui, &ctx);
            for a in actions {
                self.perform(a, &ctx);
            }
            self.flush(&ctx);
            return;
        }
        if self.settings.view.central == CentralView::Sequence {
            self.show_sequence(ui, &mut actions);
            for a in actions {
                self.perform(a, &ctx);
            }
            // nothing new starts for the exposure while the sequence is shown; a queued job still goes
            self.flush(&ctx);
            return;
        }
        let screen = OnScreen::of(&self.settings);
        egui::Panel::bottom("summary").show(ui, |ui| {
            panels::summary::summary_ui(ui, &screen, &self.rt.results);
        });
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                let s = &mut self.settings;
                panels::controls::controls_ui(
                    ui,
                    &mut s.cfg,
                    &mut s.countermeasure,
                    &mut s.view,
                    &mut self.rt.mags_text,
                    self.rt.mags_error.as_deref(),
                );
            });
        // the controls may have changed the settings
        let screen = OnScreen::of(&self.settings);
        egui::CentralPanel::default().show(ui, |ui| {
            panels::central_ui(
                ui,
                &screen,
                &mut self.settings.view,
                &self.rt.results,
                &mut self.rt.textures,
                &mut actions,
            );
        });

        for a in actions {
            self.perform(a, &ctx);
        }
        self.sync(&ctx);
    }

    /// The sequence view: its directory and what was read on the left, the products in the centre.
    fn show_sequence(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        egui::Panel::left("sequence_controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                panels::sequence::controls_ui(
                    ui,
                    &mut self.settings.sequence_dir,
                    &self.rt.sequence,
                    actions,
                );
            });
        egui::CentralPanel::default().show(ui, |ui| {
            panels::sequence::central_ui(ui, &self.rt.sequence);
        });
    }

    /// The transit view: the stare's controls on the left, its light curve and budget in the centre; a
    /// change of the controls (or of the configuration) reruns the stare.
    fn show_transit(&mut self, ui: &mut egui::Ui, ctx: &egui::Context) {
        let t = &mut self.rt.transit;
        t.update(&self.settings.cfg, &self.settings.transit, ctx);
        egui::Panel::left("transit_controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                panels::transit::controls_ui(ui, &mut self.settings.transit, t.busy);
            });
        let stale = t.stale(&self.settings.cfg, &self.settings.transit);
        egui::CentralPanel::default().show(ui, |ui| {
            panels::transit::central_ui(ui, t.shown.as_ref(), stale);
        });
    }

    fn ensure_worker(&mut self, ctx: &egui::Context) {
        if self.rt.worker.is_none() {
            match Worker::spawn(ctx.clone()) {
                Ok(w) => self.rt.worker = Some(w),
                Err(e) => self.error(format!("cannot start the engine thread: {e}")),
            }
        }
    }

    /// Apply the worker's messages of the current generation.
    fn receive(&mut self) {
        let Some(w) = &self.rt.worker else { return };
        let (status, results) = (&mut self.rt.status, &mut self.rt.results);
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
                    status.progress = Some(Progress {
                        stage,
                        done,
                        total,
                        note,
                    })
                }
                Msg::Prediction(p) => results.prediction = Some(*p),
                Msg::Series(s) => results.series = Some(*s),
                Msg::Frame(f) => {
                    if self.settings.view.star >= f.truth_xy.len() {
                        self.settings.view.star = 0;
                    }
                    results.frame = Some(*f);
                    results.frame_serial += 1;
                }
                Msg::Twin(t) => {
                    results.twin = Some(*t);
                    results.twin_serial += 1;
                }
                Msg::FocalPlane(f) => {
                    results.focal_plane = Some(*f);
                    results.focal_plane_serial += 1;
                }
                Msg::Crowded(c) => {
                    results.crowded = Some(*c);
                    results.crowded_serial += 1;
                }
                Msg::Curve(c) => results.merge_curve(*c),
                Msg::Done { elapsed_s, .. } => {
                    status.busy = false;
                    self.rt.in_flight = Stages::default();
                    status.progress = None;
                    status.last_job_s = Some(elapsed_s);
                }
                Msg::Cancelled { .. } => {
                    status.busy = false;
                    status.progress = None;
                }
                Msg::Error { stage, message, .. } => {
                    status.busy = false;
                    self.rt.in_flight = Stages::default();
                    status.progress = None;
                    status.note = Some(Note {
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
                if m != self.settings.mags {
                    self.settings.mags = m;
                }
            }
            Err(e) => self.rt.mags_error = Some(e),
        }
        let images = self.settings.cfg.fidelity.images;
        if self.settings.view.image_index >= images {
            self.settings.view.image_index = images.saturating_sub(1);
        }
        let req = self.settings.request();
        self.rt.status.invalid = req
            .cfg
            .validate()
            .err()
            .map(|e| e.to_string())
            .or_else(|| req.plan().err().map(|e| e.to_string()));
        let auto_curve = self.settings.view.auto_curve;
        let changed =
            self.rt.last_request.as_ref() != Some(&req) || (auto_curve && !self.rt.last_auto_curve);
        if changed && self.rt.status.invalid.is_none() {
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
        if self.rt.status.busy {
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
            let key = req.curve_key();
            if self.rt.results.curve_key.as_deref() != Some(key.as_str()) {
                self.rt.results.curve.clear();
                self.rt.results.curve_key = Some(key);
            }
        }
        if self.rt.status.note.as_ref().is_some_and(|n| n.is_error) {
            self.rt.status.note = None;
        }
        self.rt.in_flight = stages;
        self.rt.status.busy = true;
        self.rt.status.progress = None;
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
            Action::OpenSequence => self.open_sequence(),
            Action::Save => match self.save_config() {
                Ok(path) => self.info(format!("saved {}", path.display())),
                Err(e) => self.error(e),
            },
            Action::CopyExperimentCli | Action::CopySimulateCli => match self.save_config() {
                Ok(path) => {
                    let cmd = if a == Action::CopyExperimentCli {
                        reproduce::experiment_cli(&self.settings, &path)
                    } else {
                        reproduce::simulate_cli(&path)
                    };
                    ctx.copy_text(cmd.clone());
                    self.info(format!("copied: {cmd}"));
                }
                Err(e) => self.error(e),
            },
            Action::Cancel => self.cancel(),
            Action::RunAll | Action::RunCurve => {
                let req = self.settings.request();
                if self.rt.status.invalid.is_none() {
                    let stages = if a == Action::RunAll {
                        Stages {
                            curve: self.settings.view.auto_curve,
                            ..Stages::ALL
                        }
                    } else {
                        Stages {
                            curve: true,
                            ..Default::default()
                        }
                    };
                    self.submit(req, stages);
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
        self.rt.status.busy = false;
        self.rt.in_flight = Stages::default();
        self.rt.status.progress = None;
        self.info("cancelled".into());
    }

    fn info(&mut self, text: String) {
        self.rt.status.note = Some(Note {
            text,
            is_error: false,
        });
    }

    fn error(&mut self, text: String) {
        self.rt.status.note = Some(Note {
            text,
            is_error: true,
        });
    }

    /// Load the configuration at `config_path` (errors are shown, the current parameters stay).
    pub fn open_config(&mut self) {
        let path = PathBuf::from(self.settings.config_path.trim());
        match reproduce::load_config(&path) {
            Ok(loaded) => {
                self.settings.cfg = loaded.cfg;
                if let Some(cm) = loaded.countermeasure {
                    self.settings.countermeasure = cm;
                }
                if let Some(m) = loaded.mags {
                    self.set_mags(m);
                }
                self.info(format!("loaded {}", path.display()));
            }
            Err(e) => self.error(e),
        }
    }

    /// Read the sequence directory at `sequence_dir` and show it in the sequence view (an error is shown
    /// there, in place of the panels).
    pub fn open_sequence(&mut self) {
        let dir = PathBuf::from(self.settings.sequence_dir.trim());
        self.settings.view.central = CentralView::Sequence;
        self.rt.sequence = Some(if dir.as_os_str().is_empty() {
            Err("give the directory of a sequence (`jsim sequence --out DIR`)".into())
        } else {
            engine::io::sequence_view::read_sequence_view(&dir).map_err(|e| e.to_string())
        });
    }

    /// Write the configuration of what is on screen to `config_path`; returns the absolute path written.
    pub fn save_config(&self) -> Result<PathBuf, String> {
        reproduce::save_config(&self.settings, Path::new(&self.settings.config_path))
    }
}

/// The command line: `[CONFIG.toml] [--sequence DIR]` (`--sequence=DIR` too), in any order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CliArgs {
    pub config: Option<std::ffi::OsString>,
    pub sequence: Option<std::ffi::OsString>,
}

impl CliArgs {
    /// The arguments after the program's name; an unknown option, a missing directory or a second
    /// configuration is an error (in words, for the terminal or the window).
    pub fn parse(mut args: impl Iterator<Item = std::ffi::OsString>) -> Result<Self, String> {
        let mut cli = CliArgs::default();
        while let Some(a) = args.next() {
            let text = a.to_string_lossy();
            if text == "--sequence" {
                let dir = args
                    .next()
                    .ok_or_else(|| "--sequence needs a directory".to_string())?;
                cli.sequence = Some(dir);
            } else if let Some(dir) = text.strip_prefix("--sequence=") {
                cli.sequence = Some(dir.into());
            } else if text.starts_with('-') {
                return Err(format!("unknown option {text}"));
            } else if cli.config.is_some() {
                return Err(format!(
                    "one configuration file at most (a second one: {text})"
                ));
            } else {
                cli.config = Some(a);
            }
        }
        Ok(cli)
    }
}

impl eframe::App for ExplorerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        self.settings.save(storage);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_line_takes_a_config_and_a_sequence() {
        let parse = |a: &[&str]| CliArgs::parse(a.iter().map(std::ffi::OsString::from));
        assert_eq!(parse(&[]), Ok(CliArgs::default()));
        let both = parse(&["a.toml", "--sequence", "out/seq"]).expect("ok");
        assert_eq!(both.config.as_deref(), Some("a.toml".as_ref()));
        assert_eq!(both.sequence.as_deref(), Some("out/seq".as_ref()));
        let eq = parse(&["--sequence=out/seq"]).expect("ok");
        assert_eq!(eq.sequence.as_deref(), Some("out/seq".as_ref()));
        assert!(eq.config.is_none());
        assert!(parse(&["--sequence"]).is_err_and(|e| e.contains("needs a directory")));
        assert!(parse(&["--bogus"]).is_err_and(|e| e == "unknown option --bogus"));
        assert!(parse(&["a.toml", "b.toml"]).is_err_and(|e| e.contains("b.toml")));
    }

    #[test]
    fn only_invalidated_stages_rerun() {
        let a = Settings::default().request();
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
        app.settings.view.auto_curve = false;
        let ctx = egui::Context::default();
        app.sync(&ctx);
        assert!(
            app.rt.status.busy,
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
        app.rt.status.busy = false;
        app.rt.pending = None;
        app.rt.in_flight = Stages::default();
        let generation = app.rt.generation;
        app.rt.mags_text = "12, 13".into();
        app.sync(&ctx);
        assert_eq!(app.settings.mags, vec![12.0, 13.0]);
        assert_eq!(
            app.rt.generation, generation,
            "no curve is wanted: nothing starts"
        );
        assert!(app.is_idle());
        // an invalid parameter is reported and not run
        app.settings.cfg.ace.sigma_mas = -1.0;
        app.sync(&ctx);
        assert!(
            app.rt
                .status
                .invalid
                .as_deref()
                .is_some_and(|e| e.contains("ace.sigma_mas"))
        );
        assert!(app.is_idle());
    }
}
