//! The configuration options of the commands. Each command offers only the options that change what it does:
//! every one reads a configuration (`--config FILE`, `--set field=value`, `--instrument`, [`BaseArgs`]); the shortcuts —
//! `--seed`, `--mag`, `--scene`, `--ace`, `--readout`, `--images`, `--backend`, `--method` — are small groups
//! a command flattens where they apply. They are applied in one order (file, shortcuts, --set) and the result
//! is validated once ([`ConfigArgs::load`]), so the order on the command line never matters.

use anyhow::{Context, Result, bail};
use clap::Args;
use engine::config::{AceCase, Backend, Config, InstrumentModel, Method, ReadoutOrder};
use std::path::PathBuf;

/// `--config` and `--set`: the configuration of every command.
#[derive(Args, Clone, Debug, Default)]
pub struct BaseArgs {
    /// TOML configuration (default: the built-in reference experiment).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Set any field: --set ace.sigma_mas=150 (repeatable).
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    pub set: Vec<String>,
    /// The instrument that takes the images: as-built (the configuration's `[as_built]` deviations, by default
    /// the typical ones) or design (every deviation 0: the telescope exactly as designed, the control). Applied
    /// after the file and before `--set`.
    #[arg(long, value_enum, value_name = "as-built|design")]
    pub instrument: Option<InstrumentModel>,
}

impl BaseArgs {
    /// The configuration file (or the default) with `--instrument` applied; `--set` is applied by the caller.
    fn base_config(&self) -> Result<Config> {
        let mut cfg = match &self.config {
            Some(p) => Config::load(p)?,
            None => Config::default(),
        };
        if let Some(instrument) = self.instrument {
            cfg.as_built = cfg.as_built.for_instrument(instrument);
        }
        Ok(cfg)
    }
}

/// `--seed`.
#[derive(Args, Clone, Debug, Default)]
pub struct SeedArg {
    /// Master seed (every random draw; recorded in each output's header).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// `--mag`.
#[derive(Args, Clone, Debug, Default)]
pub struct MagArg {
    /// Hw magnitude of the grid stars.
    #[arg(long)]
    pub mag: Option<f64>,
}

/// `--scene`.
#[derive(Args, Clone, Debug, Default)]
pub struct SceneArg {
    /// Scene: grid (the paper's, one array), bulge (the mock Galactic-centre field on the quad focal plane:
    /// also sets focal_plane.layout = quad) or a catalogue file (CSV or FITS; x,y or ra,dec).
    #[arg(long, value_name = "grid|bulge|FILE")]
    pub scene: Option<String>,
}

/// `--ace`.
#[derive(Args, Clone, Debug, Default)]
pub struct AceArg {
    /// ACE model: gaussian, realistic or none.
    #[arg(long)]
    pub ace: Option<String>,
}

/// `--readout`.
#[derive(Args, Clone, Debug, Default)]
pub struct ReadoutArg {
    /// Readout order: rolling, global-reset or sample-hold.
    #[arg(long)]
    pub readout: Option<String>,
}

/// `--images`.
#[derive(Args, Clone, Debug, Default)]
pub struct ImagesArg {
    /// Number of images.
    #[arg(long)]
    pub images: Option<usize>,
}

/// `--backend` and `--method`: how the pixels are integrated.
#[derive(Args, Clone, Debug, Default)]
pub struct IntegrationArgs {
    /// Integration backend: auto, cpu or gpu.
    #[arg(long)]
    pub backend: Option<String>,
    /// Integration method: fast, direct or reference.
    #[arg(long)]
    pub method: Option<String>,
}

/// Every configuration option: the commands that simulate (`jsim simulate`, `jsim bench`).
#[derive(Args, Clone, Debug, Default)]
pub struct ConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub mag: MagArg,
    #[command(flatten)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub ace: AceArg,
    #[command(flatten)]
    pub readout: ReadoutArg,
    #[command(flatten)]
    pub images: ImagesArg,
    #[command(flatten)]
    pub integration: IntegrationArgs,
}

impl ConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        let mut cfg = self.base.base_config()?;
        if let Some(s) = self.seed.seed {
            cfg.seed = s;
        }
        if let Some(m) = self.mag.mag {
            cfg.scene.mag_hw = m;
        }
        match self.scene.scene.as_deref() {
            None => {}
            Some("grid") => cfg.scene.kind = engine::config::SceneKind::Grid,
            Some("bulge") => {
                cfg.scene.kind = engine::config::SceneKind::Bulge;
                cfg.focal_plane.layout = engine::config::Layout::Quad;
            }
            Some(file) => {
                cfg.scene.kind = engine::config::SceneKind::Catalogue;
                cfg.scene.catalogue = Some(PathBuf::from(file));
            }
        }
        if let Some(a) = &self.ace.ace {
            cfg.ace.case = AceCase::parse(a)?;
        }
        if let Some(r) = &self.readout.readout {
            cfg.readout.order = ReadoutOrder::parse(r)?;
        }
        if let Some(n) = self.images.images {
            cfg.fidelity.images = n;
        }
        if let Some(b) = &self.integration.backend {
            cfg.fidelity.backend = match b.as_str() {
                "auto" => Backend::Auto,
                "cpu" => Backend::Cpu,
                "gpu" => Backend::Gpu,
                other => bail!("--backend {other}: expected auto, cpu or gpu"),
            };
        }
        if let Some(m) = &self.integration.method {
            cfg.fidelity.method = match m.as_str() {
                "fast" => Method::Fast,
                "direct" => Method::Direct,
                "reference" => Method::Reference,
                other => bail!("--method {other}: expected fast, direct or reference"),
            };
        }
        for kv in &self.base.set {
            let (k, v) = kv
                .split_once('=')
                .with_context(|| format!("--set {kv}: expected FIELD=VALUE"))?;
            cfg = cfg.with_override(k.trim(), v.trim())?;
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

/// The options of `jsim psf`: the PSF depends on the optics and the band alone (set them in the file or with
/// `--set`).
#[derive(Args, Clone, Debug, Default)]
pub struct PsfConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
}

/// The options of `jsim ace`: the series depends on the ACE model, the seed and how many exposures it spans.
#[derive(Args, Clone, Debug, Default)]
pub struct AceConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub ace: AceArg,
    #[command(flatten)]
    pub images: ImagesArg,
}

/// The options of `jsim experiment`: its magnitudes, ACE cases and readout orders are lists of their own
/// (`--mags`, `--aces`, `--readouts`).
#[derive(Args, Clone, Debug, Default)]
pub struct ExperimentConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub images: ImagesArg,
    #[command(flatten)]
    pub integration: IntegrationArgs,
}

/// The options of `jsim crowded`: one exposure per ACE case of `--aces`, of the bulge field by default.
#[derive(Args, Clone, Debug, Default)]
pub struct CrowdedConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub readout: ReadoutArg,
    #[command(flatten)]
    pub integration: IntegrationArgs,
}

/// The options of `jsim predict`: it simulates nothing (no images, no integration).
#[derive(Args, Clone, Debug, Default)]
pub struct PredictConfigArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub mag: MagArg,
    #[command(flatten)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub ace: AceArg,
    #[command(flatten)]
    pub readout: ReadoutArg,
}

/// The configuration options of a command that simulates nothing (`jsim analyze`): the analysis knobs come
/// from a file or `--set analysis.…`; the scene, jitter, readout and backend options do not apply and are not
/// offered.
#[derive(Args, Clone, Debug, Default)]
pub struct AnalysisConfigArgs {
    /// TOML configuration: its `[analysis]` knobs (and, for an image whose header lacks them, the plate scale
    /// and readout timing assumed; default: the built-in configuration).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Set a field, e.g. --set analysis.detect_sigma=8 (repeatable).
    #[arg(long = "set", value_name = "FIELD=VALUE")]
    pub set: Vec<String>,
}

impl AnalysisConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        ConfigArgs {
            base: BaseArgs {
                config: self.config.clone(),
                set: self.set.clone(),
                instrument: None,
            },
            ..Default::default()
        }
        .load()
    }
}

impl PsfConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        ConfigArgs {
            base: self.base.clone(),
            ..Default::default()
        }
        .load()
    }
}

impl AceConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        ConfigArgs {
            base: self.base.clone(),
            seed: self.seed.clone(),
            ace: self.ace.clone(),
            images: self.images.clone(),
            ..Default::default()
        }
        .load()
    }
}

impl ExperimentConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        ConfigArgs {
            base: self.base.clone(),
            seed: self.seed.clone(),
            scene: self.scene.clone(),
            images: self.images.clone(),
            integration: self.integration.clone(),
            ..Default::default()
        }
        .load()
    }
}

impl CrowdedConfigArgs {
    /// The configuration these options describe, validated (the bulge field unless a file or `--scene`
    /// says otherwise).
    pub fn load(&self) -> Result<Config> {
        let mut scene = self.scene.clone();
        if scene.scene.is_none() && self.base.config.is_none() {
            scene.scene = Some("bulge".into());
        }
        ConfigArgs {
            base: self.base.clone(),
            seed: self.seed.clone(),
            scene,
            readout: self.readout.clone(),
            integration: self.integration.clone(),
            ..Default::default()
        }
        .load()
    }
}

impl PredictConfigArgs {
    /// The configuration these options describe, validated.
    pub fn load(&self) -> Result<Config> {
        ConfigArgs {
            base: self.base.clone(),
            seed: self.seed.clone(),
            mag: self.mag.clone(),
            scene: self.scene.clone(),
            ace: self.ace.clone(),
            readout: self.readout.clone(),
            ..Default::default()
        }
        .load()
    }
}

/// How a calibrated file of another observatory (HST, JWST) is read where its header is silent or wrong
/// (`engine::io::calibrated`).
#[derive(Args, Clone, Debug, Default)]
pub struct CalibratedArgs {
    /// Electrons per data unit of a calibrated file's SCI chips (default: from BUNIT, the gain and the
    /// exposure, or the VAR_POISSON plane).
    #[arg(long, value_name = "E_PER_UNIT")]
    electrons_per_unit: Option<f64>,
    /// Read noise of a calibrated file's pixels, e⁻ (default: RDNOISE, READNSE[A-D] of CCDAMP's amplifiers,
    /// VAR_RNOISE or the ERR plane).
    #[arg(long, value_name = "E")]
    read_noise_e: Option<f64>,
    /// DQ bits that do not mask a pixel of a calibrated file: bit values or sums, separated by commas or
    /// `+`; `~N` for all bits but N's (default: HST masks every flagged pixel, JWST only DO_NOT_USE and
    /// NON_SCIENCE).
    #[arg(long, value_name = "BITS")]
    dq_ignore: Option<String>,
    /// A raw frame's bias (pedestal), in its data units, subtracted before the gain is applied (default:
    /// none; a calibrated file's bias is removed by its pipeline).
    #[arg(long, value_name = "UNITS")]
    bias_units: Option<f64>,
    /// The level, in data units as stored, at and above which a pixel is saturated and masked (default: the
    /// header's SATURATE; none without it).
    #[arg(long, value_name = "UNITS")]
    saturate_units: Option<f64>,
    /// Exposures of one pointing in a calibrated file (a CR-split pair): a pixel more than this many σ above
    /// the others' is a cosmic ray, masked with its neighbours (0: off).
    #[arg(long, value_name = "SIGMA", default_value_t = 5.0)]
    pub cr_reject_sigma: f64,
    /// A calibrated file's single exposures: L.A.Cosmic's significance of a cosmic ray's Laplacian (van
    /// Dokkum 2001; 4.5 its usual value). Off (0) by default: on an undersampled, crowded field it also takes
    /// pixels of star cores, and the pipeline's DQ flags its cosmic rays.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
    pub lacosmic_sigma: f64,
}

impl CalibratedArgs {
    /// The options, checked: an impossible value is an error naming the option and its range.
    pub fn options(&self) -> Result<engine::io::calibrated::ReadOptions> {
        let dq_ignore = match &self.dq_ignore {
            Some(s) => Some(engine::io::calibrated::parse_dq_bits(s).map_err(anyhow::Error::msg)?),
            None => None,
        };
        let opts = engine::io::calibrated::ReadOptions {
            electrons_per_unit: self.electrons_per_unit,
            read_noise_e: self.read_noise_e,
            dq_ignore,
            bias_units: self.bias_units,
            saturate_units: self.saturate_units,
        };
        opts.validate().map_err(|e| {
            anyhow::anyhow!("--{} {}: {}", e.field.replace('_', "-"), e.value, e.rule)
        })?;
        Ok(opts)
    }
}
