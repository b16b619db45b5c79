//! `jsim sequence`: a step-stare observation sequence — its plan (stares, exposures, times), the coverage
//! it gives, and (unless `--plan-only`) each exposure simulated and analysed, resumable and shardable,
//! the catalogues gathered into one table. Engine side: [`engine::studies::sequence`].

use crate::TelemetryArgs;
use crate::options::CrowdedConfigArgs;
use anyhow::{Result, bail};
use clap::Args;
use engine::studies::sequence::{self, run};
use engine::studies::sweep::Shard;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Clone, Debug)]
pub struct SequenceArgs {
    #[command(flatten)]
    pub cfg: CrowdedConfigArgs,
    /// The sequence file (`[sequence]`: region, stares, exposures per stare, visits, pointing errors);
    /// default: the built-in sequence (3 × 2 stares at the Galactic centre, 26 exposures each, spring and
    /// autumn: 312 exposures).
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Plan only: the plan, the coverage map and its numbers; nothing simulated.
    #[arg(long)]
    pub plan_only: bool,
    /// Run only the first N exposures of the plan (the rest stay planned).
    #[arg(long)]
    pub exposures: Option<usize>,
    /// Run only shard I of N (0-based): the exposures e with e mod N = I (a Slurm array task each).
    #[arg(long)]
    pub shard: Option<String>,
    /// The countermeasure of every exposure's analysis.
    #[arg(long, default_value = "telemetry")]
    pub countermeasure: String,
    #[command(flatten)]
    pub tel: TelemetryArgs,
    /// Write Slurm job scripts (slurm/array.sbatch, gather.sbatch, submit.sh) for --shards array tasks, with
    /// the configuration and sequence file beside them and the field drawn, instead of running.
    #[arg(long)]
    pub emit_slurm: bool,
    /// Array tasks of the Slurm job.
    #[arg(long, default_value_t = 4)]
    pub shards: usize,
    /// Slurm partition.
    #[arg(long)]
    pub partition: Option<String>,
    /// Wall-clock limit per task.
    #[arg(long, default_value = "04:00:00")]
    pub time: String,
    /// CPUs per task.
    #[arg(long, default_value_t = 2)]
    pub cpus_per_task: usize,
    /// Keep each exposure's image (`exposures/fp_NNNNN.fits`, the focal plane's four arrays, as `jsim
    /// simulate` writes them; ≈ 31 MB each) beside its catalogue.
    #[arg(long)]
    pub keep_images: bool,
    /// Coverage map cell, degrees.
    #[arg(long, default_value_t = 0.01)]
    pub cell_deg: f64,
    /// Output directory: plan.csv, coverage.csv, coverage.png, sequence.json, field.csv, exposures/, and
    /// catalogue.fits once every exposure asked for has run. A rerun resumes: exposures already written are
    /// kept.
    #[arg(long, default_value = "out/sequence")]
    pub out: PathBuf,
}

pub fn sequence(a: &SequenceArgs) -> Result<()> {
    if !(a.cell_deg > 1e-4 && a.cell_deg <= 1.0) {
        bail!("--cell-deg {}: allowed (1e-4, 1]", a.cell_deg);
    }
    let cfg = a.cfg.load()?;
    let spec = match &a.spec {
        Some(p) => sequence::Spec::load(p).map_err(anyhow::Error::msg)?,
        None => sequence::Spec::default(),
    };
    let plan = sequence::plan(&spec, &cfg).map_err(anyhow::Error::msg)?;
    let n_run = a.exposures.unwrap_or(plan.exposures.len());
    if n_run == 0 || n_run > plan.exposures.len() {
        bail!(
            "--exposures {n_run}: allowed 1 … {} (the plan's exposures)",
            plan.exposures.len()
        );
    }
    let shard = match &a.shard {
        Some(s) => Shard::parse(s)?,
        None => Shard::ALL,
    };
    let cm = a.tel.plan(&[a.countermeasure.as_str()])?;
    engine::studies::crowded::check_plan(&cm)?;
    run::check_resumable(&plan, &cfg, &a.out)?;
    let t = Instant::now();
    let coverage = sequence::coverage(&plan, &cfg, a.cell_deg).map_err(anyhow::Error::msg)?;
    let coverage_s = t.elapsed().as_secs_f64();
    // the plan's files: made again identically on a rerun (same spec, same seed)
    let mut outputs = crate::outputs::Outputs::in_dir(&a.out)?;
    // the plan as the pipeline knows it (planned pointings), the pointings as flown beside it (only scoring
    // reads those), the coverage and the plan's summary
    let cov =
        sequence::plan_files::write(&plan, &spec, &coverage, &a.out, &mut |p| outputs.add(p))?;
    eprintln!(
        "sequence: {} exposures in {} stares over {:.3} deg²; a covered cell gets {} exposures \
         (median), at most {}; coverage in {coverage_s:.1} s",
        plan.exposures.len(),
        plan.stares.len(),
        cov.covered_deg2,
        cov.median,
        cov.max
    );
    if a.plan_only {
        outputs.keep();
        return Ok(());
    }
    if a.emit_slurm {
        return emit_slurm(a, &plan, &cfg, outputs);
    }
    // what it is planned with, for the solution (`jsim solve`) to read back
    for name in [
        engine::io::products::files::CONFIG_TOML,
        engine::io::products::files::SEQUENCE_TOML,
    ] {
        outputs.add(&a.out.join(name));
    }
    run::write_setup(&plan, &cfg, &a.out).map_err(anyhow::Error::msg)?;
    // the field and its reference catalogue: drawn once (the same seed draws them again identically on a
    // rerun)
    let field = a.out.join(run::FIELD_NAME);
    if !field.exists() {
        outputs.add(&field);
        outputs.add(&a.out.join(engine::io::sky_reference::REFERENCE_NAME));
        run::write_field(&plan, &cfg, &a.out)?;
    }
    let bright = a.out.join(sequence::persistence::BRIGHT_FIELD_NAME);
    if !bright.exists() {
        outputs.add(&bright);
    }
    let mut memory = sequence::persistence::Memory::new(&cfg, &a.out)?;
    // from here on, what is written is kept: each exposure whole, so a rerun resumes
    outputs.keep();
    let session = engine::session::Session::new();
    let mine: Vec<_> = plan.exposures[..n_run]
        .iter()
        .filter(|e| shard.contains(e.index))
        .collect();
    let (mut sim_s, mut an_s, mut done) = (0.0, 0.0, 0usize);
    let mut out = run::SequenceDir::open(&a.out)?;
    out.keep_images = a.keep_images;
    for (k, e) in mine.iter().enumerate() {
        crate::outputs::interrupted()?;
        let r = run::run_exposure(&session, &plan, &cfg, &field, e, &cm, &mut memory, &out)?;
        if r.skipped {
            eprintln!(
                "exposure {} ({}/{}): already written",
                e.index,
                k + 1,
                mine.len()
            );
        } else {
            done += 1;
            sim_s += r.simulate_s;
            an_s += r.analyse_s;
            eprintln!(
                "exposure {} ({}/{}): {} stars; simulated in {:.1} s, analysed in {:.1} s",
                e.index,
                k + 1,
                mine.len(),
                r.stars,
                r.simulate_s,
                r.analyse_s
            );
        }
    }
    if done > 0 {
        eprintln!(
            "ran {done} exposures: {:.1} s simulating and {:.1} s analysing per exposure",
            sim_s / done as f64,
            an_s / done as f64
        );
        if memory.made > 0 {
            eprintln!(
                "persistence: the bright light of {} exposures remade (in the simulating time)",
                memory.made
            );
        }
    }
    let all_there = plan.exposures[..n_run]
        .iter()
        .all(|e| run::exposure_path(&a.out, e.index).exists());
    if all_there {
        let mut sub = plan.clone();
        sub.exposures.truncate(n_run);
        let path = run::merge(&sub, &a.out)?;
        eprintln!("wrote {}", path.display());
    } else {
        eprintln!(
            "not every exposure has run yet: rerun (or the other shards) to gather catalogue.fits"
        );
    }
    Ok(())
}

/// `jsim sequence --emit-slurm`: the plan's files are written; the field drawn once and the job's scripts.
fn emit_slurm(
    a: &SequenceArgs,
    plan: &sequence::Plan,
    cfg: &engine::config::Config,
    mut outputs: crate::outputs::Outputs,
) -> Result<()> {
    if a.exposures.is_some() || a.shard.is_some() {
        bail!("--emit-slurm runs every exposure in --shards tasks: drop --exposures and --shard");
    }
    let dir = std::path::absolute(&a.out)?;
    let job = sequence::slurm::SlurmJob {
        shards: a.shards,
        partition: a.partition.clone(),
        time: a.time.clone(),
        cpus_per_task: a.cpus_per_task,
        jsim: std::env::current_exe()?,
        keep_images: a.keep_images,
    };
    for name in [
        engine::io::products::files::CONFIG_TOML,
        engine::io::products::files::SEQUENCE_TOML,
        run::FIELD_NAME,
        engine::io::sky_reference::REFERENCE_NAME,
    ] {
        outputs.add(&dir.join(name));
    }
    let scripts = sequence::slurm::emit(plan, cfg, &dir, &job).map_err(anyhow::Error::msg)?;
    // the field drawn once here, so that the tasks only read it
    run::write_field(plan, cfg, &a.out)?;
    for p in &scripts {
        outputs.add(p);
    }
    outputs.keep();
    eprintln!(
        "wrote {} (submit with {})",
        dir.join("slurm").display(),
        scripts[2].display()
    );
    Ok(())
}
