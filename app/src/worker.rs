//! The engine worker: one named thread owns every engine object (PSF bank, simulators, cached exposures) and
//! runs the jobs the UI sends over a bounded channel, cheapest preview first:
//!
//! 1. **predict** — the instant accuracy predictor for the current configuration (no image simulated);
//! 2. **image** — one simulated frame, its ePSF analysis (with the chosen countermeasure), the ACE series
//!    around that exposure with a Welch PSD of the generated series, and the Gaussian-ACE twin frame;
//! 3. **curve** — the accuracy-vs-magnitude curve: the predictor at every magnitude first, then the Monte
//!    Carlo datasets (`fidelity.images` images per magnitude, as `jsim experiment` runs them).
//!
//! Every job carries a generation number. The UI bumps the shared `latest` generation whenever a control
//! moves (or Cancel is pressed); the worker checks it between engine calls and abandons stale work, and the
//! UI drops any message of an old generation. Results go back over a channel, followed by
//! `ctx.request_repaint()`. No physics here: everything is an engine call.

use engine::analysis::astrometry::{self, Analysis, AnalysisImage, Options, Report, StarResult};
use engine::analysis::countermeasures::Countermeasure;
use engine::analysis::epsf::Epsf;
use engine::analysis::predict::Predictor;
use engine::config::{AceCase, Config, ReadoutOrder};
use engine::optics::PsfBank;
use engine::simulate::{AceStats, Exposure, Simulator};
use engine::studies::experiment::{self, ImageResult as DatasetImage, Plan, Row};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender, TrySendError};
use std::time::Instant;

/// Countermeasures offered in the UI (names as the engine and `jsim` spell them).
pub const COUNTERMEASURES: [&str; 5] = [
    "none",
    "yzones",
    "plate-affine",
    "plate-poly:3",
    "telemetry",
];

/// Generation value that tells the worker to stop for good.
const SHUTDOWN: u64 = u64::MAX;

/// What the UI wants computed: everything the results depend on.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub cfg: Config,
    pub countermeasure: String,
    /// Which exposure of the dataset the frame panels show.
    pub image_index: usize,
    /// Magnitudes of the accuracy curve.
    pub mags: Vec<f64>,
}

impl Request {
    /// The experiment plan of this request: the plain analysis plus the chosen countermeasure.
    pub fn plan(&self) -> Plan {
        let mut names = vec!["none".to_string()];
        if self.countermeasure != "none" {
            names.push(self.countermeasure.clone());
        }
        Plan {
            countermeasures: names,
            ..Plan::default()
        }
    }
}

/// Which stages a job runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stages {
    pub predict: bool,
    pub image: bool,
    pub curve: bool,
}

impl Stages {
    pub const ALL: Stages = Stages {
        predict: true,
        image: true,
        curve: true,
    };
    pub fn union(self, o: Stages) -> Stages {
        Stages {
            predict: self.predict || o.predict,
            image: self.image || o.image,
            curve: self.curve || o.curve,
        }
    }
    pub fn any(self) -> bool {
        self.predict || self.image || self.curve
    }
}

/// One unit of work.
#[derive(Debug, Clone)]
pub struct Job {
    pub generation: u64,
    pub request: Request,
    pub stages: Stages,
}

/// The stage a message or progress report belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Predict,
    Image,
    Twin,
    Curve,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Predict => "prediction",
            Stage::Image => "frame + analysis",
            Stage::Twin => "Gaussian twin",
            Stage::Curve => "magnitude curve",
        }
    }
}

/// The instant predictor's answer for the current configuration.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub generation: u64,
    pub cfg_hash: String,
    pub countermeasure: String,
    pub image_index: usize,
    /// Dataset mean of the predicted single-image accuracy (mas), chosen countermeasure and `none`.
    pub dataset_mas: f64,
    pub dataset_none_mas: f64,
    /// Predicted accuracy of the displayed image (mas).
    pub image_mas: f64,
    /// Noise floor (phase-averaged CRLB per axis) of a star blurred by the displayed image's ACE σ, mas.
    pub noise_floor_mas: f64,
    pub elapsed_s: f64,
}

/// The ACE series around the displayed exposure and a Welch estimate of the generated series' PSD.
#[derive(Debug, Clone)]
pub struct SeriesView {
    pub generation: u64,
    pub cfg_hash: String,
    pub image_index: usize,
    /// Min/max envelope of x and y (mas) over the exposure cycle, times relative to the exposure start (s).
    pub x: Vec<[f64; 2]>,
    pub y: Vec<[f64; 2]>,
    /// Welch PSD of the x series, log-binned: `[log10 f, log10 psd]`, divided by `psd_scale` so that it
    /// overlays the model PSD (which the engine defines in arbitrary units).
    pub welch_log: Vec<[f64; 2]>,
    pub psd_scale: f64,
    /// Achieved σ of the series under its convention (mas).
    pub achieved_sigma_mas: (f64, f64),
}

/// One simulated frame and its analysis.
#[derive(Debug, Clone)]
pub struct FrameResult {
    pub generation: u64,
    /// Hash of the configuration this frame was computed with ([`Config::hash_hex`]).
    pub cfg_hash: String,
    pub readout: ReadoutOrder,
    pub ace_case: AceCase,
    pub mag: f64,
    pub image_index: usize,
    pub countermeasure: String,
    pub n: usize,
    pub adu: Vec<f32>,
    pub dq: Vec<u8>,
    /// Display limits: a low quantile (≈ sky) and the maximum, ADU.
    pub lo_adu: f32,
    pub hi_adu: f32,
    /// Sky noise estimate (ADU), for the asinh/log softening.
    pub noise_adu: f32,
    /// True star positions (px).
    pub truth_xy: Vec<(f64, f64)>,
    /// Report and star results under the chosen countermeasure.
    pub report: Report,
    pub stars: Vec<StarResult>,
    /// Report of the plain analysis (global ePSF, no countermeasure), with the fit-response predictions.
    pub report_none: Report,
    pub stars_none: Vec<StarResult>,
    pub epsf: Epsf,
    pub ace: AceStats,
    pub t_start_s: f64,
    pub backend: String,
    pub gpu_note: Option<String>,
    pub simulate_s: f64,
    pub analyse_s: f64,
}

/// The Gaussian-ACE twin of the displayed frame (same configuration, `ace.case = gaussian`).
#[derive(Debug, Clone)]
pub struct TwinResult {
    pub generation: u64,
    /// Hash of the main configuration the twin belongs to.
    pub cfg_hash: String,
    pub image_index: usize,
    pub n: usize,
    pub adu: Vec<f32>,
    pub report: Option<Report>,
}

/// One magnitude of the accuracy curve.
#[derive(Debug, Clone)]
pub struct CurvePoint {
    pub generation: u64,
    pub mag: f64,
    /// Predictor: dataset mean for the chosen countermeasure and for `none`, and the noise floor.
    pub predicted_mas: Option<f64>,
    pub predicted_none_mas: Option<f64>,
    /// Monte Carlo rows (one per countermeasure of the plan), when the dataset is done.
    pub rows: Option<Vec<Row>>,
}

/// Messages from the worker.
#[derive(Debug, Clone)]
pub enum Msg {
    Progress {
        generation: u64,
        stage: Stage,
        done: usize,
        total: usize,
        note: String,
    },
    Prediction(Box<Prediction>),
    Series(Box<SeriesView>),
    Frame(Box<FrameResult>),
    Twin(Box<TwinResult>),
    Curve(Box<CurvePoint>),
    /// The job ran to the end.
    Done {
        generation: u64,
        elapsed_s: f64,
    },
    /// The job was abandoned because a newer generation exists.
    Cancelled {
        generation: u64,
    },
    /// The engine refused or failed; the job stopped at this stage.
    Error {
        generation: u64,
        stage: Stage,
        message: String,
    },
}

impl Msg {
    pub fn generation(&self) -> u64 {
        match self {
            Msg::Progress { generation, .. }
            | Msg::Done { generation, .. }
            | Msg::Cancelled { generation }
            | Msg::Error { generation, .. } => *generation,
            Msg::Prediction(p) => p.generation,
            Msg::Series(s) => s.generation,
            Msg::Frame(f) => f.generation,
            Msg::Twin(t) => t.generation,
            Msg::Curve(c) => c.generation,
        }
    }
}

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

/// Why a job stopped early.
enum Stop {
    Cancelled,
    Failed(Stage, String),
}

type StageResult<T> = Result<T, Stop>;

fn failed<E: std::fmt::Display>(stage: Stage) -> impl Fn(E) -> Stop {
    move |e| Stop::Failed(stage, e.to_string())
}

/// Where a job reports to.
struct Out<'a> {
    tx: &'a Sender<Msg>,
    ctx: &'a egui::Context,
    latest: &'a AtomicU64,
    generation: u64,
}

impl Out<'_> {
    fn send(&self, m: Msg) {
        // a closed channel means the UI is gone: the next check ends the job
        let _ = self.tx.send(m);
        self.ctx.request_repaint();
    }
    /// Abandon the job if a newer generation exists.
    fn check(&self) -> StageResult<()> {
        if self.latest.load(Ordering::Acquire) == self.generation {
            Ok(())
        } else {
            Err(Stop::Cancelled)
        }
    }
    fn progress(&self, stage: Stage, done: usize, total: usize, note: impl Into<String>) {
        self.send(Msg::Progress {
            generation: self.generation,
            stage,
            done,
            total,
            note: note.into(),
        });
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

/// A simulator and the configuration key it was built for.
struct CachedSim {
    key: String,
    sim: Simulator,
}

/// Engine objects kept between jobs.
#[derive(Default)]
struct EngineState {
    bank: Option<Arc<PsfBank>>,
    main: Option<CachedSim>,
    twin: Option<CachedSim>,
    /// Exposures by (simulator key, index); a handful at most.
    exposures: HashMap<(String, usize), Arc<Exposure>>,
    /// Curve results by (config hash, plan) and (config hash, countermeasure).
    curve_rows: HashMap<(String, String), Vec<Row>>,
    curve_pred: HashMap<(String, String), (f64, f64)>,
}

/// The key a simulator (and its exposures) depends on: the configuration without the analysis knobs.
fn sim_key(cfg: &Config) -> String {
    let mut c = cfg.clone();
    c.analysis = Default::default();
    c.hash_hex()
}

/// The Gaussian-ACE twin of a configuration.
pub fn twin_config(cfg: &Config) -> Config {
    let mut c = cfg.clone();
    c.ace.case = AceCase::Gaussian;
    c
}

impl EngineState {
    fn bank_for(&mut self, cfg: &Config) -> Arc<PsfBank> {
        match &self.bank {
            Some(b) if b.serves(cfg) => b.clone(),
            _ => {
                let b = Arc::new(PsfBank::new(cfg));
                self.bank = Some(b.clone());
                b
            }
        }
    }

    /// The simulator for `cfg` in slot `twin` (reused when only the analysis changed).
    fn simulator(&mut self, cfg: &Config, twin: bool, stage: Stage) -> StageResult<&Simulator> {
        let key = sim_key(cfg);
        let fresh = match if twin { &self.twin } else { &self.main } {
            Some(c) => c.key != key,
            None => true,
        };
        if fresh {
            let bank = self.bank_for(cfg);
            let sim = Simulator::with_bank(cfg, bank, None).map_err(failed(stage))?;
            let slot = Some(CachedSim {
                key: key.clone(),
                sim,
            });
            if twin {
                self.twin = slot;
            } else {
                self.main = slot;
            }
            // exposures of other configurations are no longer shown
            let keep: Vec<String> = [&self.main, &self.twin]
                .iter()
                .filter_map(|s| s.as_ref().map(|c| c.key.clone()))
                .collect();
            self.exposures.retain(|(k, _), _| keep.contains(k));
        }
        let slot = if twin { &mut self.twin } else { &mut self.main };
        let c = slot
            .as_mut()
            .ok_or_else(|| Stop::Failed(stage, "no simulator".into()))?;
        // only the analysis knobs may differ: the simulator reads them live (fit noise, analysis options)
        if c.sim.cfg != *cfg {
            c.sim.cfg = cfg.clone();
        }
        Ok(&c.sim)
    }

    /// Run `f` on a simulator of `cfg`: the cached one when it serves, else a temporary one.
    fn with_sim<T>(
        &mut self,
        cfg: &Config,
        f: impl FnOnce(&Simulator) -> StageResult<T>,
    ) -> StageResult<T> {
        let key = sim_key(cfg);
        if let Some(c) = self.main.as_mut().filter(|c| c.key == key) {
            if c.sim.cfg != *cfg {
                c.sim.cfg = cfg.clone();
            }
            return f(&c.sim);
        }
        let sim =
            Simulator::with_bank(cfg, self.bank_for(cfg), None).map_err(failed(Stage::Curve))?;
        f(&sim)
    }

    fn exposure(
        &mut self,
        cfg: &Config,
        twin: bool,
        index: usize,
        stage: Stage,
    ) -> StageResult<Arc<Exposure>> {
        let key = (sim_key(cfg), index);
        if let Some(e) = self.exposures.get(&key) {
            return Ok(e.clone());
        }
        let sim = self.simulator(cfg, twin, stage)?;
        let e = Arc::new(sim.exposure(index).map_err(failed(stage))?);
        self.exposures.insert(key, e.clone());
        Ok(e)
    }

    fn run(&mut self, job: &Job, out: &Out) -> StageResult<()> {
        let r = &job.request;
        r.cfg.validate().map_err(failed(Stage::Predict))?;
        if r.image_index >= r.cfg.fidelity.images {
            return Err(Stop::Failed(
                Stage::Image,
                format!(
                    "image {} does not exist: the dataset has fidelity.images = {}",
                    r.image_index, r.cfg.fidelity.images
                ),
            ));
        }
        if job.stages.predict {
            out.check()?;
            self.predict(r, out)?;
        }
        if job.stages.image {
            out.check()?;
            self.image(r, out)?;
            out.check()?;
            self.twin(r, out)?;
        }
        if job.stages.curve {
            out.check()?;
            self.curve(r, out)?;
        }
        Ok(())
    }

    fn predict(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let t0 = Instant::now();
        let need_psf = self.bank.as_ref().is_none_or(|b| !b.serves(&r.cfg));
        out.progress(
            Stage::Predict,
            0,
            1,
            if need_psf {
                "computing the PSF and the ACE series"
            } else {
                "generating the ACE series"
            },
        );
        let plan = r.plan();
        let sim = self.simulator(&r.cfg, false, Stage::Predict)?;
        out.check()?;
        let pred = Predictor::new(sim).map_err(failed(Stage::Predict))?;
        let image_mas = pred.predict_image(r.image_index, &r.countermeasure, &plan);
        let ace = sim.ace_stats(r.image_index);
        let (sx, sy) = match r.cfg.ace.case {
            AceCase::Gaussian => (r.cfg.ace.sigma_mas, r.cfg.ace.sigma_mas),
            AceCase::Realistic => (ace.sigma_x_mas, ace.sigma_y_mas),
            AceCase::None => (0.0, 0.0),
        };
        let noise_floor_mas = pred.noise_floor_mas(sx, sy);
        out.check()?;
        let dataset_mas = pred.predict(&r.countermeasure, &plan).unwrap_or(f64::NAN);
        let dataset_none_mas = pred.predict("none", &plan).unwrap_or(f64::NAN);
        out.send(Msg::Prediction(Box::new(Prediction {
            generation: out.generation,
            cfg_hash: r.cfg.hash_hex(),
            countermeasure: r.countermeasure.clone(),
            image_index: r.image_index,
            dataset_mas,
            dataset_none_mas,
            image_mas,
            noise_floor_mas,
            elapsed_s: t0.elapsed().as_secs_f64(),
        })));
        Ok(())
    }

    fn series_view(sim: &Simulator, r: &Request, generation: u64) -> Option<SeriesView> {
        let s = sim.series()?;
        let t0 = sim.exposure_start_s(r.image_index);
        let t1 = t0 + sim.timing.span_s();
        let a = ((t0 / s.dt_s).floor().max(0.0) as usize).min(s.len());
        let b = ((t1 / s.dt_s).ceil().max(0.0) as usize).min(s.len()).max(a);
        let x = envelope(&s.x_mas[a..b], s.dt_s, a as f64 * s.dt_s - t0, 2000);
        let y = envelope(&s.y_mas[a..b], s.dt_s, a as f64 * s.dt_s - t0, 2000);
        // Welch with segments of 1/8 of the series (frequency resolution 8/span), log-binned for display
        let seg = (s.len() / 8).max(16);
        let w = engine::jitter::welch::welch(&s.x_mas, s.dt_s, seg);
        let psd = engine::jitter::Psd::from_config(&sim.cfg.ace);
        let ratios: Vec<f64> = w
            .iter()
            .filter(|(f, p)| *f > 0.0 && *p > 0.0)
            .map(|(f, p)| p / psd.eval(*f))
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        let scale = median(ratios).unwrap_or(1.0);
        let welch_log = log_bin(&w, 160)
            .into_iter()
            .map(|[f, p]| [f.log10(), (p / scale).log10()])
            .filter(|v| v[0].is_finite() && v[1].is_finite())
            .collect();
        Some(SeriesView {
            generation,
            cfg_hash: r.cfg.hash_hex(),
            image_index: r.image_index,
            x,
            y,
            welch_log,
            psd_scale: scale,
            achieved_sigma_mas: s.achieved_sigma_mas,
        })
    }

    fn image(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let cfg = &r.cfg;
        let cached = self.exposures.contains_key(&(sim_key(cfg), r.image_index));
        out.progress(
            Stage::Image,
            0,
            2,
            if cached {
                "analysing the frame"
            } else {
                "simulating the frame"
            },
        );
        let t0 = Instant::now();
        let exp = self.exposure(cfg, false, r.image_index, Stage::Image)?;
        let simulate_s = t0.elapsed().as_secs_f64();
        out.check()?;
        let sim = self.simulator(cfg, false, Stage::Image)?;
        if let Some(view) = Self::series_view(sim, r, out.generation) {
            out.send(Msg::Series(Box::new(view)));
        }
        out.progress(Stage::Image, 1, 2, "ePSF analysis");
        let t1 = Instant::now();
        let img = AnalysisImage::from_detector(cfg, &exp.image);
        let base = Options::new(&cfg.analysis);
        // one detection and ePSF build; the countermeasure starts from its fits
        let (plain, prepared) = astrometry::analyze_prepared(&img, Some(&exp.truth), &base)
            .map_err(failed(Stage::Image))?;
        let apply = |cm: &Countermeasure| {
            astrometry::with_countermeasure(&img, Some(&exp.truth), &plain, &prepared, cm)
                .map_err(failed(Stage::Image))
        };
        let mut global: Analysis = plain.clone();
        // the fit displacement the true ACE predicts for every star (the mechanism, beside the errors)
        experiment::attach_ace_prediction(
            sim,
            r.image_index,
            &exp.truth,
            &mut global,
            img.plate_scale_mas,
        )
        .map_err(failed(Stage::Image))?;
        out.check()?;
        let with_cm = match r.countermeasure.as_str() {
            "none" => None,
            "telemetry" => {
                let spec = engine::studies::experiment::TelemetrySpec::default();
                match experiment::telemetry_countermeasure(sim, exp.t_start_s, &spec)
                    .map_err(failed(Stage::Image))?
                {
                    // a static ACE has nothing to correct: the plain result stands
                    None => None,
                    Some(cm) => Some(apply(&cm)?),
                }
            }
            other => {
                let cm = Countermeasure::parse(other, cfg.analysis.epsf_zones.max(2))
                    .map_err(failed(Stage::Image))?;
                Some(apply(&cm)?)
            }
        };
        let analyse_s = t1.elapsed().as_secs_f64();
        let (lo, hi, noise) = display_limits(&exp.image.adu, &exp.image.dq);
        let (report, stars) = match &with_cm {
            Some(a) => (a.report.clone(), a.stars.clone()),
            None => (global.report.clone(), global.stars.clone()),
        };
        out.send(Msg::Frame(Box::new(FrameResult {
            generation: out.generation,
            cfg_hash: cfg.hash_hex(),
            readout: cfg.readout.order,
            ace_case: cfg.ace.case,
            mag: cfg.scene.mag_hw,
            image_index: r.image_index,
            countermeasure: r.countermeasure.clone(),
            n: exp.image.n,
            adu: exp.image.adu.clone(),
            dq: exp.image.dq.clone(),
            lo_adu: lo,
            hi_adu: hi,
            noise_adu: noise,
            truth_xy: exp.truth.iter().map(|t| (t.x_px, t.y_px)).collect(),
            report,
            stars,
            report_none: global.report,
            stars_none: global.stars,
            epsf: global.epsf,
            ace: exp.ace,
            t_start_s: exp.t_start_s,
            backend: exp.backend.clone(),
            gpu_note: sim.gpu_note.clone(),
            simulate_s,
            analyse_s,
        })));
        Ok(())
    }

    fn twin(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let tcfg = twin_config(&r.cfg);
        out.progress(Stage::Twin, 0, 1, "simulating the Gaussian-ACE twin");
        let exp = if r.cfg.ace.case == AceCase::Gaussian {
            self.exposure(&r.cfg, false, r.image_index, Stage::Twin)?
        } else {
            self.exposure(&tcfg, true, r.image_index, Stage::Twin)?
        };
        out.check()?;
        let img = AnalysisImage::from_detector(&tcfg, &exp.image);
        let report = astrometry::analyze(&img, Some(&exp.truth), &Options::new(&tcfg.analysis))
            .ok()
            .map(|a| a.report);
        out.send(Msg::Twin(Box::new(TwinResult {
            generation: out.generation,
            cfg_hash: r.cfg.hash_hex(),
            image_index: r.image_index,
            n: exp.image.n,
            adu: exp.image.adu.clone(),
            report,
        })));
        Ok(())
    }

    fn curve(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let plan = r.plan();
        let plan_key = plan.countermeasures.join(",");
        let cfgs: Vec<Config> = r
            .mags
            .iter()
            .map(|&m| {
                let mut c = r.cfg.clone();
                c.scene.mag_hw = m;
                c
            })
            .collect();
        // 1. the predictor at every magnitude (cheap): the curve's first shape
        for c in &cfgs {
            out.check()?;
            let key = (c.hash_hex(), r.countermeasure.clone());
            let (p, p_none) = match self.curve_pred.get(&key) {
                Some(v) => *v,
                None => {
                    out.progress(
                        Stage::Curve,
                        0,
                        cfgs.len(),
                        format!("predicting Hw = {}", c.scene.mag_hw),
                    );
                    let v = self.with_sim(c, |sim| {
                        let pred = Predictor::new(sim).map_err(failed(Stage::Curve))?;
                        Ok((
                            pred.predict(&r.countermeasure, &plan).unwrap_or(f64::NAN),
                            pred.predict("none", &plan).unwrap_or(f64::NAN),
                        ))
                    })?;
                    self.curve_pred.insert(key, v);
                    v
                }
            };
            let rows = self
                .curve_rows
                .get(&(c.hash_hex(), plan_key.clone()))
                .cloned();
            out.send(Msg::Curve(Box::new(CurvePoint {
                generation: out.generation,
                mag: c.scene.mag_hw,
                predicted_mas: Some(p).filter(|v| v.is_finite()),
                predicted_none_mas: Some(p_none).filter(|v| v.is_finite()),
                rows,
            })));
        }
        // 2. the Monte Carlo datasets, image by image (cancellable between images)
        let images = r.cfg.fidelity.images;
        let total = images * cfgs.len();
        for (k, c) in cfgs.iter().enumerate() {
            let key = (c.hash_hex(), plan_key.clone());
            if self.curve_rows.contains_key(&key) {
                continue;
            }
            out.check()?;
            let t0 = Instant::now();
            let rows = self.with_sim(c, |sim| {
                let pred = Predictor::new(sim).map_err(failed(Stage::Curve))?;
                let mut results: Vec<DatasetImage> = Vec::with_capacity(images);
                for i in 0..images {
                    out.check()?;
                    out.progress(
                        Stage::Curve,
                        k * images + i,
                        total,
                        format!("Hw = {}: image {}/{}", c.scene.mag_hw, i + 1, images),
                    );
                    results.push(
                        experiment::analyse_image(sim, i, &plan).map_err(failed(Stage::Curve))?,
                    );
                }
                let predicted = |name: &str| pred.predict(name, &plan).unwrap_or(f64::NAN);
                Ok(experiment::summarise(
                    c,
                    &results,
                    &predicted,
                    t0.elapsed().as_secs_f64(),
                ))
            })?;
            self.curve_rows.insert(key, rows.clone());
            let p = self
                .curve_pred
                .get(&(c.hash_hex(), r.countermeasure.clone()))
                .copied();
            out.send(Msg::Curve(Box::new(CurvePoint {
                generation: out.generation,
                mag: c.scene.mag_hw,
                predicted_mas: p.map(|v| v.0).filter(|v| v.is_finite()),
                predicted_none_mas: p.map(|v| v.1).filter(|v| v.is_finite()),
                rows: Some(rows),
            })));
        }
        out.progress(Stage::Curve, total, total, "done");
        Ok(())
    }
}

/// Min/max envelope of a series in at most `buckets` buckets: points `[t, v]` (two per bucket).
fn envelope(v: &[f64], dt: f64, t_offset: f64, buckets: usize) -> Vec<[f64; 2]> {
    if v.is_empty() {
        return Vec::new();
    }
    let per = v.len().div_ceil(buckets.max(1)).max(1);
    let mut out = Vec::with_capacity(2 * buckets);
    for (b, chunk) in v.chunks(per).enumerate() {
        let (mut imin, mut imax) = (0, 0);
        for (i, x) in chunk.iter().enumerate() {
            if *x < chunk[imin] {
                imin = i;
            }
            if *x > chunk[imax] {
                imax = i;
            }
        }
        let base = b * per;
        let (first, second) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        for i in [first, second] {
            out.push([t_offset + (base + i) as f64 * dt, chunk[i]]);
        }
    }
    out
}

/// Average `(f, p)` pairs into `bins` logarithmic frequency bins (f > 0 only).
fn log_bin(w: &[(f64, f64)], bins: usize) -> Vec<[f64; 2]> {
    let pos: Vec<&(f64, f64)> = w.iter().filter(|(f, p)| *f > 0.0 && *p > 0.0).collect();
    let (Some(first), Some(last)) = (pos.first(), pos.last()) else {
        return Vec::new();
    };
    let (la, lb) = (first.0.ln(), last.0.ln());
    if !(lb > la) {
        return pos.iter().map(|(f, p)| [*f, *p]).collect();
    }
    let mut acc = vec![(0.0, 0.0, 0usize); bins];
    for (f, p) in pos {
        let k = (((f.ln() - la) / (lb - la)) * bins as f64).floor() as usize;
        let a = &mut acc[k.min(bins - 1)];
        a.0 += f;
        a.1 += p;
        a.2 += 1;
    }
    acc.into_iter()
        .filter(|a| a.2 > 0)
        .map(|(f, p, n)| [f / n as f64, p / n as f64])
        .collect()
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    Some(*m)
}

/// Display limits of a frame: (low quantile ≈ sky, maximum, robust noise), from the photosensitive pixels.
fn display_limits(adu: &[f32], dq: &[u8]) -> (f32, f32, f32) {
    let border = engine::detector::dq::BORDER;
    let mut s: Vec<f32> = adu
        .iter()
        .zip(dq)
        .filter(|(_, q)| *q & border == 0)
        .map(|(v, _)| *v)
        .step_by(3)
        .collect();
    if s.is_empty() {
        return (0.0, 1.0, 1.0);
    }
    let hi = adu.iter().copied().fold(f32::MIN, f32::max);
    s.sort_unstable_by(|a, b| a.total_cmp(b));
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    let (q16, q50, q84) = (q(0.16), q(0.5), q(0.84));
    let noise = (0.5 * (q84 - q16)).max(1e-3);
    let lo = q50 - 2.0 * noise;
    (lo, hi.max(lo + 1.0), noise)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_extremes_in_time_order() {
        let v: Vec<f64> = (0..1000).map(|i| ((i as f64) * 0.1).sin()).collect();
        let e = envelope(&v, 0.01, 1.0, 10);
        assert_eq!(e.len(), 20);
        assert!(e.windows(2).all(|w| w[0][0] <= w[1][0]));
        let max = e.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
        assert!((max - 1.0).abs() < 1e-3);
        assert!((e[0][0] - 1.0).abs() < 0.2);
    }

    #[test]
    fn log_bins_average_power() {
        let w: Vec<(f64, f64)> = (0..1000).map(|k| (k as f64 * 0.01, 2.0)).collect();
        let b = log_bin(&w, 20);
        assert!(!b.is_empty() && b.len() <= 20);
        assert!(b.iter().all(|p| (p[1] - 2.0).abs() < 1e-12));
    }

    #[test]
    fn plan_always_has_the_plain_analysis() {
        let r = Request {
            cfg: Config::default(),
            countermeasure: "plate-poly:3".into(),
            image_index: 0,
            mags: vec![12.5],
        };
        assert_eq!(r.plan().countermeasures, vec!["none", "plate-poly:3"]);
    }
}
