//! `jsim transit`: a transit-monitoring stare — one bright target and its comparison stars read in windows
//! plate after plate, the differential light curve measured from the products alone, decorrelated, searched
//! for the transit, its precision against the noise budget; with `--magnitudes`, the precision and the
//! detection of 0.3 % and 0.1 % transits against the target's magnitude. Engine side:
//! [`engine::studies::transit`].

use crate::options::{AceArg, BaseArgs, ConfigArgs, IntegrationArgs, SeedArg};
use anyhow::{Context, Result};
use clap::Args;
use engine::studies::transit::{self, Spec, outputs, precision as study};
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
pub struct TransitArgs {
    #[command(flatten)]
    pub base: BaseArgs,
    #[command(flatten)]
    pub seed: SeedArg,
    #[command(flatten)]
    pub ace: AceArg,
    #[command(flatten)]
    pub integration: IntegrationArgs,
    /// The stare's file (`[transit]`: target, comparisons, duration, plate and sub-exposure, window, drift,
    /// intra-pixel amplitude, photometry, decorrelation, injected transit); its fields can also be set with
    /// --set transit.FIELD=VALUE. Default: a Hw 9.7 M dwarf, 20 comparison stars, 6.5 h of 12.5-s plates, a
    /// 0.3 % transit mid-stare.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// The target's Hw magnitude (transit.target_hw).
    #[arg(long)]
    pub hw: Option<f64>,
    /// The stare's length, hours (transit.duration_h).
    #[arg(long)]
    pub hours: Option<f64>,
    /// The injected transit's depth, (Rp/R★)²; 0 = none (transit.depth).
    #[arg(long)]
    pub depth: Option<f64>,
    /// The precision study: a stare without a transit at each of these target magnitudes (precision.csv,
    /// precision.png, the detection of 0.3 % and 0.1 % transits), instead of the one stare.
    #[arg(long, value_delimiter = ',')]
    pub magnitudes: Vec<f64>,
    /// Also write the instrument's products for an outside tool: windows.fits (every window of every plate,
    /// the calibration flat over each window, the model PSF) and telemetry.ecsv.
    #[arg(long)]
    pub write_products: bool,
    /// Output directory: lightcurve.ecsv, truth.ecsv, transit.json, lightcurve.png (with --magnitudes:
    /// precision.csv, precision.png, precision.json and one directory per magnitude).
    #[arg(long, default_value = "out/transit")]
    pub out: PathBuf,
}

/// The configuration and the stare these options describe: the file, the shortcuts, then each --set
/// (`transit.*` to the stare, the rest to the configuration); the stare is validated once, when it runs.
pub fn load(a: &TransitArgs) -> Result<(engine::config::Config, Spec)> {
    let (spec_sets, cfg_sets): (Vec<String>, Vec<String>) = a
        .base
        .set
        .iter()
        .cloned()
        .partition(|s| s.starts_with("transit."));
    let cfg = ConfigArgs {
        base: BaseArgs {
            config: a.base.config.clone(),
            set: cfg_sets,
            instrument: a.base.instrument,
        },
        seed: a.seed.clone(),
        ace: a.ace.clone(),
        integration: a.integration.clone(),
        ..Default::default()
    }
    .load()?;
    let mut spec = match &a.spec {
        Some(p) => Spec::load(p).map_err(anyhow::Error::msg)?,
        None => Spec::default(),
    };
    if let Some(v) = a.hw {
        spec.target_hw = v;
    }
    if let Some(v) = a.hours {
        spec.duration_h = v;
    }
    if let Some(v) = a.depth {
        spec.depth = v;
    }
    for s in &spec_sets {
        spec = set_field(&spec, s)?;
    }
    Ok((cfg, spec))
}

/// Apply `transit.FIELD=VALUE` (VALUE as TOML, else a string) to the stare.
fn set_field(spec: &Spec, assignment: &str) -> Result<Spec> {
    let (key, value) = assignment
        .split_once('=')
        .with_context(|| format!("--set {assignment}: expected transit.FIELD=VALUE"))?;
    spec.set(key, value)
        .map_err(|e| anyhow::anyhow!("--set {assignment}: {e}"))
}

pub fn transit(a: &TransitArgs) -> Result<()> {
    let (cfg, spec) = load(a)?;
    if !a.magnitudes.is_empty() {
        let rows = study::run(&cfg, &spec, &a.magnitudes, &a.out)?;
        for line in study::table_lines(&rows) {
            println!("{line}");
        }
        println!("wrote {}", a.out.display());
        return Ok(());
    }
    let (obs, r) = transit::run::run(&cfg, &spec)?;
    outputs::write(&a.out, &obs, &r)?;
    if a.write_products {
        outputs::write_products(&a.out, &obs)?;
    }
    println!(
        "Hw {:.1} target, {} comparison stars: {} plates of {} s ({} × {:.3} s windowed sub-exposures; the \
         longest safe {:.2} s), cadence {:.2} s",
        spec.target_hw,
        obs.stars.len() - 1,
        obs.plates.len(),
        r.readout.plate_s,
        r.readout.sub_exposures,
        r.readout.exposure_s,
        r.readout.longest_safe_s,
        r.readout.cadence_s
    );
    for line in outputs::budget_lines(&r) {
        println!("{line}");
    }
    if let Some(rec) = &r.recovery {
        println!(
            "transit found at {:.2} h, {:.2} h long: depth {:.0} ± {:.0} ppm (the error from the scatter out \
             of the transit), measured significance {:.1}σ; injected {:.0} ppm over the box (pull {:+.2})",
            24.0 * rec.t0_days,
            rec.duration_h,
            1e6 * rec.depth,
            1e6 * rec.depth_sigma,
            rec.snr,
            1e6 * rec.injected_depth,
            rec.pull
        );
    }
    for d in &r.detections {
        println!("{}", d.describe());
    }
    println!(
        "simulated in {:.1} s, analysed in {:.1} s ({}); wrote {}",
        r.simulate_s,
        r.analyse_s,
        r.backend,
        a.out.display()
    );
    Ok(())
}
