//! `jsim`: the command-line front of the engine. Every command takes the same configuration options
//! (`--config FILE`, shortcuts such as `--mag`, and `--set field=value` for any field); `jsim config
//! --print-default` writes the commented default configuration.

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use engine::config::{AceCase, Backend, Config, Method, ReadoutOrder};
use std::path::{Path, PathBuf};

mod cmd;

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

/// Configuration options shared by every command (applied in this order: file, shortcuts, --set).
#[derive(Args, Clone, Debug, Default)]
pub struct ConfigArgs {
    /// TOML configuration (default: the built-in reference experiment).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Master seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Hw magnitude of the grid stars.
    #[arg(long)]
    pub mag: Option<f64>,
    /// ACE model: gaussian, realistic or none.
    #[arg(long)]
    pub ace: Option<String>,
    /// Readout order: rolling, global-reset or sample-hold.
    #[arg(long)]
    pub readout: Option<String>,
    /// Number of images.
    #[arg(long)]
    pub images: Option<usize>,
    /// Integration backend: auto, cpu or gpu.
    #[arg(long)]
    pub backend: Option<String>,
    /// Integration method: fast, direct or reference.
    #[arg(long)]
    pub method: Option<String>,
    /// Set any field: --set ace.sigma_mas=150 (repeatable).
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    pub set: Vec<String>,
}

impl ConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        let mut cfg = match &self.config {
            Some(p) => Config::load(p)?,
            None => Config::default(),
        };
        if let Some(s) = self.seed {
            cfg.seed = s;
        }
        if let Some(m) = self.mag {
            cfg.scene.mag_hw = m;
        }
        if let Some(a) = &self.ace {
            cfg.ace.case = AceCase::parse(a)?;
        }
        if let Some(r) = &self.readout {
            cfg.readout.order = ReadoutOrder::parse(r)?;
        }
        if let Some(n) = self.images {
            cfg.fidelity.images = n;
        }
        if let Some(b) = &self.backend {
            cfg.fidelity.backend = match b.as_str() {
                "auto" => Backend::Auto,
                "cpu" => Backend::Cpu,
                "gpu" => Backend::Gpu,
                other => bail!("--backend {other}: expected auto, cpu or gpu"),
            };
        }
        if let Some(m) = &self.method {
            cfg.fidelity.method = match m.as_str() {
                "fast" => Method::Fast,
                "direct" => Method::Direct,
                "reference" => Method::Reference,
                other => bail!("--method {other}: expected fast, direct or reference"),
            };
        }
        for kv in &self.set {
            let (k, v) = kv
                .split_once('=')
                .with_context(|| format!("--set {kv}: expected FIELD=VALUE"))?;
            cfg = cfg.with_override(k.trim(), v.trim())?;
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

#[derive(Subcommand)]
enum Command {
    /// Print the commented default configuration, or check a file.
    Config {
        #[arg(long)]
        print_default: bool,
        /// Validate a configuration file and print it in canonical form.
        #[arg(long, value_name = "FILE")]
        check: Option<PathBuf>,
    },
    /// Compute the polychromatic PSF and write it as FITS.
    Psf {
        #[command(flatten)]
        cfg: ConfigArgs,
        #[arg(long, default_value = "psf.fits")]
        out: PathBuf,
    },
    /// Generate the ACE time series and write t_s, x_mas, y_mas as CSV.
    Ace {
        #[command(flatten)]
        cfg: ConfigArgs,
        #[arg(long, default_value = "ace.csv")]
        out: PathBuf,
        /// Keep every N-th sample (the full reference series has 2.4 million).
        #[arg(long, default_value_t = 1)]
        every: usize,
    },
    /// Simulate images (FITS + truth catalogues).
    Simulate {
        #[command(flatten)]
        cfg: ConfigArgs,
        #[arg(long, default_value = "out/simulate")]
        out: PathBuf,
    },
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("jsim: error: {e:#}");
        std::process::exit(1);
    }
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
        Command::Psf { cfg, out } => cmd::psf(&cfg.load()?, &out),
        Command::Ace { cfg, out, every } => cmd::ace(&cfg.load()?, &out, every),
        Command::Simulate { cfg, out } => cmd::simulate(&cfg.load()?, &out),
    }
}

/// Create an output directory, naming it in the error.
pub fn ensure_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create output directory {}", dir.display()))
}
