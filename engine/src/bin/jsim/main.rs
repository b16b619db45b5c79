//! `jsim`: the command-line front of the engine. Every command reads a configuration (`--config FILE`,
//! `--set field=value` for any field) and offers the shortcuts that apply to it, such as `--mag`
//! ([`options`]); `jsim config --print-default` writes the commented default configuration.

use anyhow::{Result, bail};
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use engine::analysis::countermeasures::{DEFAULT_CATALOGUE_ERROR_MAS, Plan, TelemetryQuality};
use engine::config::{AceCase, Config, ReadoutOrder};
use engine::session::Session;
use std::path::PathBuf;

pub(crate) mod bench_cmd;
pub(crate) mod budget_out;
pub(crate) mod calibrated_cmd;
pub(crate) mod cmd;
pub(crate) mod crowded_cmd;
pub(crate) mod options;
pub(crate) mod outputs;
pub(crate) mod sequence_cmd;
pub(crate) mod simulate_cmd;
pub(crate) mod solve_cmd;
pub(crate) mod sweep_cmd;
pub(crate) mod synthetic_cmd;
pub(crate) mod transit_cmd;

pub use options::{
    AceConfigArgs, AnalysisConfigArgs, ConfigArgs, ExperimentConfigArgs, PredictConfigArgs,
    PsfConfigArgs,
};

#[derive(Parser)]
#[command(
    name = "jsim",
    version,
    about = "JASMINE image simulator and ePSF astrometry explorer"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the commented default configuration, or check a file.
    Config {
        /// Print the built-in default configuration, every knob with its comment and source.
        #[arg(long)]
        print_default: bool,
        /// Validate a configuration file and print it in canonical form.
        #[arg(long, value_name = "FILE")]
        check: Option<PathBuf>,
    },
    /// Compute the polychromatic PSF and write it as FITS.
    Psf {
        #[command(flatten)]
        cfg: PsfConfigArgs,
        /// The PSF table's FITS file.
        #[arg(long, default_value = "psf.fits")]
        out: PathBuf,
    },
    /// Generate the ACE time series and write t_s, x_mas, y_mas as CSV.
    Ace {
        #[command(flatten)]
        cfg: AceConfigArgs,
        /// The ACE series' CSV file.
        #[arg(long, default_value = "ace.csv")]
        out: PathBuf,
        /// Keep every N-th sample (the full reference series has 2.4 million).
        #[arg(long, default_value_t = 1)]
        every: usize,
    },
    /// Simulate images (FITS + truth catalogues) and the instrument products (calibration flat, reference
    /// catalogue).
    Simulate {
        #[command(flatten)]
        cfg: ConfigArgs,
        #[command(flatten)]
        survey: SurveyArgs,
        /// Output directory (images, truth, the instrument products, config.toml, run.json).
        #[arg(long, default_value = "out/simulate")]
        out: PathBuf,
    },
    /// Measure positions in an image with the ePSF method: catalogue, ePSF, summary, vector map.
    Analyze {
        #[command(flatten)]
        cfg: AnalysisConfigArgs,
        /// Image to analyse (FITS from `jsim simulate`, or any image with GAIN/RDNOISE headers).
        #[arg(long)]
        image: PathBuf,
        /// Truth catalogue (CSV or FITS TRUTH table; default: the image's TRUTH extension). The analysis
        /// never reads it: it scores the result after (and is the `@oracle` control's reference); `jsim
        /// score` scores any catalogue apart.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Calibration flat (FITS; default: flat_cal.fits beside the image, if any; without one the image
        /// is not flat-fielded and the output says so).
        #[arg(long, value_name = "FITS")]
        flat: Option<PathBuf>,
        /// Reference astrometric catalogue for plate-*@catalogue (CSV with x_px, y_px, sigma_mas; default:
        /// refcat.csv beside the image, if any).
        #[arg(long, value_name = "CSV")]
        refcat: Option<PathBuf>,
        /// Attitude telemetry of the exposure (FITS table ATTITUDE; default: telemetry_NNN.fits beside the
        /// image, NNN its IMAGEIDX): what the telemetry correction corrects with (without it, nothing).
        #[arg(long, value_name = "FITS")]
        telemetry: Option<PathBuf>,
        /// Y zones of the position-dependent ePSF (with --countermeasure yzones|yzones-shared).
        #[arg(long = "epsf-zones")]
        epsf_zones: Option<usize>,
        #[command(flatten)]
        cm: CountermeasureArgs,
        /// auto (crowded when the measured source density puts more than 5 % of the stars within the
        /// grouped fits' link radius of a neighbour), on (crowded-field analysis) or off (isolated stars);
        /// default: the configuration's `analysis.crowding` (auto).
        #[arg(long, value_parser = parse_crowding)]
        crowding: Option<engine::analysis::crowding::Crowding>,
        #[command(flatten)]
        calibrated: options::CalibratedArgs,
        /// Output directory (catalogue.csv, epsf.fits, summary.json, vectors.csv, vectors.png).
        #[arg(long, default_value = "out/analyze")]
        out: PathBuf,
    },
    /// Score a measured catalogue against a truth list (the only command that reads the truth): match by
    /// position, then completeness, accuracy and false detections per magnitude bin.
    Score(cmd::ScoreArgs),
    /// The paper's experiment: accuracy vs magnitude for each ACE case, readout order and countermeasure.
    Experiment {
        #[command(flatten)]
        cfg: ExperimentConfigArgs,
        /// ACE cases (comma separated).
        #[arg(long, default_value = "gaussian,realistic", value_delimiter = ',')]
        aces: Vec<String>,
        /// Readout orders (comma separated).
        #[arg(long, default_value = "rolling", value_delimiter = ',')]
        readouts: Vec<String>,
        /// Magnitudes (comma separated).
        #[arg(long, default_value = "12,12.5,13,13.5,14,14.5", value_delimiter = ',')]
        mags: Vec<f64>,
        /// Countermeasures (comma separated): none, yzones[:K], yzones-shared[:K], plate-affine[@R],
        /// plate-poly:N[@R] (R, the plate model's reference: stack — the stare's own, default —, catalogue — the
        /// survey's reference catalogue —, oracle — the truth, a control), telemetry (the shift the
        /// telemetry predicts), telemetry-model (each star refitted through the jitter the telemetry records
        /// over its pixels' windows), telemetry-model+plate-…[@R] (the forward model, then a plate model on its
        /// fits), exact-epsf (control fit with the exact ePSF, static ACE only).
        #[arg(long, default_value = "none,yzones", value_delimiter = ',')]
        countermeasures: Vec<String>,
        #[command(flatten)]
        tel: TelemetryArgs,
        /// Output directory (experiment.csv, images.csv, accuracy.png, vector maps).
        #[arg(long, default_value = "out/experiment")]
        out: PathBuf,
    },
    /// Accuracy against magnitude from one crowded exposure of the focal plane (default: the mock bulge).
    Crowded(crowded_cmd::CrowdedArgs),
    /// A step-stare observation sequence: its plan and coverage map, and each exposure simulated and analysed
    /// (resumable, shardable), the catalogues gathered into one FITS table.
    Sequence(sequence_cmd::SequenceArgs),
    /// The astrometric solution of a sequence that has run, from its products: sources (positions, proper
    /// motions, parallaxes), attitudes and the instrument's calibration; scored against the truth, with the
    /// precision against the number of exposures.
    Solve(solve_cmd::SolveArgs),
    /// Solve a synthetic sequence (the benchmark's: N sources × E exposures, the calibration drawn and solved)
    /// and write its solution: the distributed solution's check and scaling (`mpirun -np 4 jsim-mpi
    /// solve-synthetic`).
    SolveSynthetic(synthetic_cmd::SyntheticArgs),
    /// Transit photometry: a bright target stared at for hours with its comparison stars (windowed,
    /// co-added reads), its differential light curve, precision against the noise budget and the transit
    /// recovered; --magnitudes for the precision and the 0.3 % / 0.1 % detection against magnitude.
    Transit(transit_cmd::TransitArgs),
    /// Monte Carlo sweep over a parameter grid (resumable, shardable; --emit-slurm for a cluster).
    Sweep(sweep_cmd::SweepArgs),
    /// Merge the shards of a sweep.
    Merge(sweep_cmd::MergeArgs),
    /// Report a merged sweep: fraction of exposures meeting a threshold, distributions, plots.
    Report(sweep_cmd::ReportArgs),
    /// Speed against error of every approximation knob, and the methods × backends.
    Bench(bench_cmd::BenchArgs),
    /// Predict the accuracy of a configuration per countermeasure, without simulating images.
    Predict {
        #[command(flatten)]
        cfg: PredictConfigArgs,
        /// Countermeasures to predict (comma separated; the names of `jsim experiment --countermeasures`).
        #[arg(
            long,
            default_value = "none,yzones,plate-affine,plate-poly:3,telemetry",
            value_delimiter = ','
        )]
        countermeasures: Vec<String>,
        #[command(flatten)]
        tel: TelemetryArgs,
    },
}

/// Telemetry quality and reference-catalogue error for the countermeasures (defaults: the engine's
/// `TelemetryQuality::DEFAULT`, a plausible attitude-determination system, and `DEFAULT_CATALOGUE_ERROR_MAS`).
#[derive(Args, Clone, Debug)]
pub struct TelemetryArgs {
    /// Telemetry white noise per sample, mas.
    #[arg(long = "telemetry-noise-mas", default_value_t = TelemetryQuality::DEFAULT.noise_mas)]
    pub noise_mas: f64,
    /// Telemetry sampling rate, Hz.
    #[arg(long = "telemetry-rate-hz", default_value_t = TelemetryQuality::DEFAULT.rate_hz)]
    pub rate_hz: f64,
    /// Telemetry latency, s.
    #[arg(long = "telemetry-latency-s", default_value_t = TelemetryQuality::DEFAULT.latency_s)]
    pub latency_s: f64,
    /// RMS of the telemetry's correlated (Gauss–Markov) error, mas.
    #[arg(long = "telemetry-correlated-mas", default_value_t = TelemetryQuality::DEFAULT.correlated_mas)]
    pub correlated_mas: f64,
    /// Correlation time of that error, s.
    #[arg(long = "telemetry-correlation-s", default_value_t = TelemetryQuality::DEFAULT.correlation_time_s)]
    pub correlation_time_s: f64,
    /// Error of the reference catalogue of the plate models named `…@catalogue`, mas.
    #[arg(long = "reference-error-mas", default_value_t = DEFAULT_CATALOGUE_ERROR_MAS)]
    pub reference_error_mas: f64,
}

impl TelemetryArgs {
    /// Each value in its range, whether or not a countermeasure uses it (the error names the option).
    pub fn validate(&self) -> Result<()> {
        use engine::analysis::countermeasures::{
            MAX_ERROR_MAS, MAX_TELEMETRY_LATENCY_S, MAX_TELEMETRY_RATE_HZ,
        };
        let checks = [
            (
                "--telemetry-noise-mas",
                self.noise_mas,
                (0.0..=MAX_ERROR_MAS).contains(&self.noise_mas),
                format!("[0, {MAX_ERROR_MAS}]"),
            ),
            (
                "--telemetry-rate-hz",
                self.rate_hz,
                self.rate_hz > 0.0 && self.rate_hz <= MAX_TELEMETRY_RATE_HZ,
                format!("(0, {MAX_TELEMETRY_RATE_HZ}]"),
            ),
            (
                "--telemetry-latency-s",
                self.latency_s,
                self.latency_s.abs() <= MAX_TELEMETRY_LATENCY_S,
                format!("[-{MAX_TELEMETRY_LATENCY_S}, {MAX_TELEMETRY_LATENCY_S}]"),
            ),
            (
                "--telemetry-correlated-mas",
                self.correlated_mas,
                (0.0..=MAX_ERROR_MAS).contains(&self.correlated_mas),
                format!("[0, {MAX_ERROR_MAS}]"),
            ),
            (
                "--telemetry-correlation-s",
                self.correlation_time_s,
                self.correlation_time_s > 0.0 && self.correlation_time_s <= 1e6,
                "(0, 1e6]".to_string(),
            ),
            (
                "--reference-error-mas",
                self.reference_error_mas,
                self.reference_error_mas > 0.0 && self.reference_error_mas <= MAX_ERROR_MAS,
                format!("(0, {MAX_ERROR_MAS}]"),
            ),
        ];
        for (option, value, ok, range) in checks {
            if !ok {
                bail!("{option} {value}: allowed {range}");
            }
        }
        Ok(())
    }

    /// The plan of these countermeasure names with this telemetry quality and reference error, validated
    /// by the engine (the one place a plan is checked).
    pub fn plan<S: AsRef<str>>(&self, names: &[S]) -> Result<Plan> {
        self.validate()?;
        let q = TelemetryQuality {
            noise_mas: self.noise_mas,
            rate_hz: self.rate_hz,
            latency_s: self.latency_s,
            correlated_mas: self.correlated_mas,
            correlation_time_s: self.correlation_time_s,
        };
        Ok(Plan::parse(names, q, self.reference_error_mas)?)
    }
}

/// The survey the reference catalogue product comes from (`engine::io::instrument::SurveyModel`).
#[derive(Args, Clone, Debug)]
pub struct SurveyArgs {
    /// Reference catalogue: position error floor per axis, mas (bright stars).
    #[arg(long = "refcat-floor-mas", default_value_t = engine::io::instrument::SurveyModel::default().floor_mas)]
    pub floor_mas: f64,
    /// Reference catalogue: magnitude from which the error grows as flux^-1/2.
    #[arg(long = "refcat-knee-hw", default_value_t = engine::io::instrument::SurveyModel::default().knee_hw)]
    pub knee_hw: f64,
    /// Reference catalogue: limiting magnitude (Hw).
    #[arg(long = "refcat-limit-hw", default_value_t = engine::io::instrument::SurveyModel::default().limit_hw)]
    pub limit_hw: f64,
    /// Reference catalogue: completeness above the limit, (0, 1].
    #[arg(long = "refcat-completeness", default_value_t = engine::io::instrument::SurveyModel::default().completeness)]
    pub completeness: f64,
    /// Reference catalogue: error of its magnitudes (Hw), mag.
    #[arg(long = "refcat-phot-sigma-mag", default_value_t = engine::io::instrument::SurveyModel::default().phot_sigma_mag)]
    pub phot_sigma_mag: f64,
}

impl SurveyArgs {
    /// The survey model, validated (the error names the option and its range).
    pub fn model(&self) -> Result<engine::io::instrument::SurveyModel> {
        let m = engine::io::instrument::SurveyModel {
            floor_mas: self.floor_mas,
            knee_hw: self.knee_hw,
            limit_hw: self.limit_hw,
            completeness: self.completeness,
            phot_sigma_mag: self.phot_sigma_mag,
        };
        m.validate().map_err(anyhow::Error::msg)?;
        Ok(m)
    }
}

/// The countermeasure of `jsim analyze`: its quality comes from the products (the telemetry file's own
/// recording, the reference catalogue's own errors), so there is no quality option to give.
#[derive(Args, Clone, Debug)]
pub struct CountermeasureArgs {
    /// none, yzones[:K], yzones-shared[:K], plate-affine[@R], plate-poly:N[@R] (R: stack, catalogue — the
    /// reference catalogue product —, oracle — the truth, a control), telemetry or telemetry-model (with the
    /// telemetry product) or exact-epsf (a control: the image's own simulation). A single image is a stare of one:
    /// the stack corrects nothing.
    #[arg(long, default_value = "none")]
    pub countermeasure: String,
}

/// The command line's entry (also `jsim-mpi`'s, once MPI is up).
pub(crate) fn main() {
    quiet_mesa();
    outputs::install_interrupt_handler();
    let cli = Cli::from_arg_matches(&command().get_matches()).unwrap_or_else(|e| e.exit());
    if let Err(e) = run(cli) {
        eprintln!("jsim: error: {}", message_of(&e));
        std::process::exit(1);
    }
}

/// The command line, where every option that takes a value accepts a negative number (`--latency -1`) as its
/// value, so that the option's own range check answers rather than clap's "unexpected argument".
fn command() -> clap::Command {
    fn allow_negative(c: clap::Command) -> clap::Command {
        c.mut_args(|a| {
            if a.get_action().takes_values() {
                a.allow_negative_numbers(true)
            } else {
                a
            }
        })
        .mut_subcommands(allow_negative)
    }
    allow_negative(Cli::command())
}

/// An error and its causes on one line, each cause said once: an engine error already quotes its source
/// ("cannot read config file F: No such file or directory"), which the chain would repeat.
fn message_of(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Command::Config {
            print_default,
            check,
        } => {
            if let Some(p) = check {
                let cfg = Config::load(&p)?;
                print!("{}", cfg.to_toml());
                eprintln!("{}: valid (config hash {})", p.display(), cfg.hash_hex());
            } else if print_default {
                print!("{}", engine::config::DEFAULT_TOML);
            } else {
                bail!("nothing to do: use --print-default or --check FILE");
            }
            Ok(())
        }
        Command::Psf { cfg, out } => cmd::psf(&Session::new(), &cfg.load()?, &out),
        Command::Ace { cfg, out, every } => cmd::ace(&cfg.load()?, &out, every),
        Command::Simulate { cfg, survey, out } => {
            let c = cfg.load()?;
            let s = survey.model()?;
            simulate_cmd::simulate(&Session::new(), &c, &out, &s)
        }
        Command::Analyze {
            cfg,
            image,
            truth,
            flat,
            refcat,
            telemetry,
            epsf_zones,
            cm,
            crowding,
            calibrated,
            out,
        } => {
            let cr_rejection = calibrated_cmd::rejection(calibrated.cr_reject_sigma)?;
            let lacosmic = calibrated_cmd::lacosmic_knob(calibrated.lacosmic_sigma)?;
            let calibrated = calibrated.options()?;
            let mut c = cfg.load()?;
            if let Some(k) = crowding {
                c.analysis.crowding = k;
            }
            let plan = Plan::parse(
                std::slice::from_ref(&cm.countermeasure),
                TelemetryQuality::DEFAULT,
                DEFAULT_CATALOGUE_ERROR_MAS,
            )?;
            if let Some(z) = epsf_zones
                && !(2..=64).contains(&z)
            {
                bail!("--epsf-zones {z}: allowed 2..=64");
            }
            cmd::analyze(
                &Session::new(),
                &c,
                &cmd::AnalyzeArgs {
                    image,
                    truth,
                    flat,
                    refcat,
                    telemetry,
                    zones: epsf_zones,
                    countermeasure: plan.countermeasures[0],
                    calibrated,
                    cr_rejection,
                    lacosmic,
                    out,
                },
            )
        }
        Command::Experiment {
            cfg,
            aces,
            readouts,
            mags,
            countermeasures,
            tel,
            out,
        } => {
            let c = cfg.load()?;
            let aces = aces
                .iter()
                .map(|a| AceCase::parse(a.trim()))
                .collect::<Result<Vec<_>, _>>()?;
            let readouts = readouts
                .iter()
                .map(|r| ReadoutOrder::parse(r.trim()))
                .collect::<Result<Vec<_>, _>>()?;
            if mags.is_empty() || mags.iter().any(|m| !m.is_finite()) {
                bail!("--mags: give finite magnitudes, e.g. 12,12.5");
            }
            let plan = tel.plan(&countermeasures)?;
            cmd::experiment(
                &Session::new(),
                &c,
                &cmd::ExperimentArgs {
                    aces,
                    readouts,
                    mags,
                    plan,
                    out,
                },
            )
        }
        Command::Score(a) => cmd::score(&a),
        Command::Crowded(a) => crowded_cmd::crowded(&a),
        Command::Sequence(a) => sequence_cmd::sequence(&a),
        Command::Solve(a) => solve_cmd::solve(&a),
        Command::SolveSynthetic(a) => synthetic_cmd::solve_synthetic(&a),
        Command::Transit(a) => transit_cmd::transit(&a),
        Command::Sweep(a) => sweep_cmd::sweep(&a),
        Command::Merge(a) => sweep_cmd::merge(&a),
        Command::Report(a) => sweep_cmd::report(&a),
        Command::Bench(a) => bench_cmd::bench(&a),
        Command::Predict {
            cfg,
            countermeasures,
            tel,
        } => {
            let c = cfg.load()?;
            let plan = tel.plan(&countermeasures)?;
            cmd::predict(&Session::new(), &c, &plan)
        }
    }
}

/// `--crowding`: one of [`engine::analysis::crowding::Crowding::NAMES`].
fn parse_crowding(s: &str) -> Result<engine::analysis::crowding::Crowding, String> {
    engine::analysis::crowding::Crowding::parse(s)
}

/// Mesa's Vulkan loader (its Wayland probe) prints "XDG_RUNTIME_DIR is invalid or not set" when probing for a
/// GPU without a session directory: harmless, but alarming. Its check is only that the variable names an
/// absolute path, so point it at the system temporary directory — nothing is created, nothing left behind.
/// Done before any thread exists.
#[allow(unsafe_code)]
fn quiet_mesa() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let dir = std::env::temp_dir();
        if dir.is_absolute() && dir.is_dir() {
            // SAFETY: called first thing in main, before any other thread is started.
            unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
        }
    }
}
