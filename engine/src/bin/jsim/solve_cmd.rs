//! `jsim solve`: the astrometric solution of a sequence that has run (its products only), then its scoring
//! against the truth and the precision against the number of exposures. Engine side:
//! [`engine::studies::sequence::solution`].

use anyhow::{Result, bail};
use clap::Args;
use engine::solution::SourceModel;
use engine::studies::sequence::budget::MissionPattern;
use engine::studies::sequence::solution as sq;
use engine::studies::sequence::solve_study as study;
use std::path::PathBuf;
use std::time::Instant;

/// `--method`'s values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum IterationMethod {
    Cg,
    Block,
}

impl IterationMethod {
    /// The engine's name for it.
    pub fn method(self) -> engine::solution::Method {
        match self {
            IterationMethod::Cg => engine::solution::Method::ConjugateGradient,
            IterationMethod::Block => engine::solution::Method::Block,
        }
    }
}

#[derive(Args, Clone, Debug)]
pub struct SolveArgs {
    /// The sequence's directory (`jsim sequence --out`): config.toml, sequence.toml, reference.csv,
    /// exposures/.
    #[arg(long, default_value = "out/sequence")]
    pub sequence: PathBuf,
    /// Solve the first N exposures of those that have run, for each N given (the precision against N);
    /// default: all that have run.
    #[arg(long, value_delimiter = ',')]
    pub exposures: Vec<usize>,
    /// Keep every K-th exposure of each stare (its 1st, (K + 1)-th, …), before --exposures: every stare and
    /// season kept with fewer exposures in each (the precision against the exposures per star over the
    /// sequence's whole time span); 1 … the exposures per stare.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// The sources' model: position, full (position, proper motion, parallax), or auto (full where the
    /// exposures span ≥ 0.1 yr).
    #[arg(long, default_value = "auto")]
    pub model: String,
    /// Order of the global distortion solved (0: none; 2 … 5); default: 3 where the exposures point at two
    /// places or more, else 0.
    #[arg(long)]
    pub distortion_order: Option<usize>,
    /// How the solution iterates: cg (conjugate gradients preconditioned by the blocks, to 10⁻³ of each
    /// unknown's formal error) or block (the block iteration, the reference).
    #[arg(long, value_enum, default_value_t = IterationMethod::Cg)]
    pub method: IterationMethod,
    /// Added in quadrature to each detection's Cramér–Rao bound as its σ, mas.
    #[arg(long, default_value_t = 1.0)]
    pub sigma_floor_mas: f64,
    /// The error beyond each detection's σ that the sources' σ carry: none, per-stare (an error a source's
    /// detections share within a stare, measured per bin of σ from the residuals between stares) or
    /// per-visit (shared within a visit, measured between visits).
    #[arg(long, default_value = "none")]
    pub excess_noise: String,
    /// A detection is a source's when within this of it after the alignment, mas.
    #[arg(long, default_value_t = 200.0)]
    pub match_radius_mas: f64,
    /// The mission's exposures per star, for its error budget (written where the exposures asked for
    /// include the sequence's exposures per stare: mission_budget.csv).
    #[arg(long, default_value_t = 67_000)]
    pub mission_exposures: usize,
    /// The mission's exposures per stare (the toolkit's 26 at six fields per orbit).
    #[arg(long, default_value_t = 26)]
    pub mission_stare_exposures: usize,
    /// The mission's length, years.
    #[arg(long, default_value_t = 3.0)]
    pub mission_years: f64,
    /// Half-width of each Galactic-centre season (centred on the equinoxes), days.
    #[arg(long, default_value_t = 45.0)]
    pub season_half_width_days: f64,
    /// Output directory (default: solution/ in the sequence's directory): sources.csv, attitudes.csv,
    /// calibration.csv, calibration_map.csv, score_sources.csv, score_attitudes.csv, precision_vs_n.csv and
    /// .png, mission_budget.csv, solution.json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Resume from this checkpoint if it is there, write it as the solution goes (each relinearisation,
    /// every 20 steps of the gradients, each rejection round), remove it when done: a run killed midway is
    /// rerun with the same options to the same solution (with several --exposures, one file each: FILE.N).
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<PathBuf>,
    /// Write a Slurm job instead of solving: slurm/solve.sbatch in the sequence's directory (the solution on
    /// --ranks MPI ranks, `srun jsim-mpi solve …` with these options) and submit-solve.sh; the sequence's own
    /// submit.sh (`jsim sequence --emit-slurm`) then chains it after its array and gathering jobs.
    #[arg(long)]
    pub emit_slurm: bool,
    /// MPI ranks of the Slurm job (a power of two, 1 … 64).
    #[arg(long, default_value_t = 2, requires = "emit_slurm")]
    pub ranks: usize,
    /// Nodes the ranks spread over.
    #[arg(long, default_value_t = 1, requires = "emit_slurm")]
    pub nodes: usize,
    /// Threads per rank.
    #[arg(long, default_value_t = 1, requires = "emit_slurm")]
    pub cpus_per_rank: usize,
    /// The job's wall-clock limit.
    #[arg(long, default_value = "04:00:00", requires = "emit_slurm")]
    pub time: String,
    /// Slurm partition.
    #[arg(long, requires = "emit_slurm")]
    pub partition: Option<String>,
    /// The `jsim-mpi` binary the ranks run (default: beside this jsim; build it with `cargo build --release
    /// -p engine --features mpi`).
    #[arg(long, requires = "emit_slurm")]
    pub jsim_mpi: Option<PathBuf>,
}

/// `jsim solve --emit-slurm`: the job script of this solution on MPI ranks.
fn emit_slurm(a: &SolveArgs) -> Result<()> {
    let here = std::env::current_exe()?;
    let jsim_mpi = match &a.jsim_mpi {
        Some(p) => std::path::absolute(p)?,
        None => here.with_file_name("jsim-mpi"),
    };
    if !jsim_mpi.is_file() {
        bail!(
            "--jsim-mpi {}: no such binary (build it with `cargo build --release -p engine --features mpi`, or \
             name it)",
            jsim_mpi.display()
        );
    }
    let sequence = std::path::absolute(&a.sequence)?;
    if !sequence
        .join(engine::io::products::files::SEQUENCE_TOML)
        .is_file()
    {
        bail!(
            "--sequence {}: no sequence planned there (run `jsim sequence --emit-slurm --out DIR` first)",
            sequence.display()
        );
    }
    let mut args: Vec<String> = vec!["--sequence".into(), sequence.display().to_string()];
    let mut opt = |k: &str, v: String| {
        args.push(k.into());
        args.push(v);
    };
    if !a.exposures.is_empty() {
        let ns: Vec<String> = a.exposures.iter().map(|n| n.to_string()).collect();
        opt("--exposures", ns.join(","));
    }
    if a.every != 1 {
        opt("--every", a.every.to_string());
    }
    opt("--model", a.model.clone());
    if let Some(d) = a.distortion_order {
        opt("--distortion-order", d.to_string());
    }
    opt("--method", format!("{:?}", a.method).to_lowercase());
    opt("--sigma-floor-mas", a.sigma_floor_mas.to_string());
    if a.excess_noise != engine::solution::ExcessNoise::None.name() {
        opt("--excess-noise", a.excess_noise.clone());
    }
    opt("--match-radius-mas", a.match_radius_mas.to_string());
    opt("--mission-exposures", a.mission_exposures.to_string());
    opt(
        "--mission-stare-exposures",
        a.mission_stare_exposures.to_string(),
    );
    opt("--mission-years", a.mission_years.to_string());
    opt(
        "--season-half-width-days",
        a.season_half_width_days.to_string(),
    );
    if let Some(o) = &a.out {
        opt("--out", std::path::absolute(o)?.display().to_string());
    }
    // a job that is cut off (its time limit, a node lost) resumes when resubmitted
    let ck = match &a.checkpoint {
        Some(c) => std::path::absolute(c)?,
        None => sequence.join("slurm").join("solution.checkpoint"),
    };
    opt("--checkpoint", ck.display().to_string());
    let job = engine::studies::sequence::slurm::SolveJob {
        ranks: a.ranks,
        nodes: a.nodes,
        cpus_per_rank: a.cpus_per_rank,
        partition: a.partition.clone(),
        time: a.time.clone(),
        jsim_mpi,
    };
    let scripts = engine::studies::sequence::slurm::emit_solve(&sequence, &job, &args)
        .map_err(anyhow::Error::msg)?;
    eprintln!(
        "wrote {} and {} (the sequence's submit.sh chains the solution after its jobs)",
        scripts[0].display(),
        scripts[1].display()
    );
    Ok(())
}

pub fn solve(a: &SolveArgs) -> Result<()> {
    let model = SourceModel::parse_or_auto(&a.model).map_err(|e| anyhow::anyhow!("--model {e}"))?;
    let excess = engine::solution::ExcessNoise::parse(&a.excess_noise)
        .map_err(|e| anyhow::anyhow!("--excess-noise: {e}"))?;
    let spec = sq::SolveSpec {
        model,
        distortion_order: a.distortion_order,
        method: a.method.method(),
        excess,
        feed: engine::solution::feed::FeedOptions {
            match_radius_mas: a.match_radius_mas,
            sigma_floor_mas: a.sigma_floor_mas,
            ..Default::default()
        },
    };
    let mission = MissionPattern {
        exposures_per_star: a.mission_exposures,
        exposures_per_stare: a.mission_stare_exposures,
        years: a.mission_years,
        season_half_width_days: a.season_half_width_days,
        ..MissionPattern::default()
    };
    mission.validate().map_err(anyhow::Error::msg)?;
    if a.emit_slurm {
        return emit_slurm(a);
    }
    let t = Instant::now();
    let p = sq::read_products_every(&a.sequence, a.every)?;
    let req = study::Request {
        exposures: study::exposures_to_solve(&a.exposures, p.exposures_run)?,
        spec,
        checkpoint: a.checkpoint.clone(),
        out: a.out.clone().unwrap_or_else(|| a.sequence.join("solution")),
    };
    let world = engine::solution::ranks::world();
    if world.rank() != 0 {
        // another MPI rank (jsim-mpi): the same solutions, rank 0 alone scores, prints and writes them
        return Ok(study::solve_only(&p, &req)?);
    }
    eprintln!(
        "read {} exposures' {} detections and {} reference stars in {:.1} s",
        p.exposures_run,
        p.detections.len(),
        p.references.len(),
        t.elapsed().as_secs_f64()
    );
    let mut outputs = crate::outputs::Outputs::in_dir(&req.out)?;
    // the scoring reads the truth, apart from the solution
    let truth = sq::read_truth(&a.sequence, &p)?;
    let done = study::run(
        &p,
        &truth,
        &req,
        world.size(),
        &mut |line| eprintln!("{line}"),
        &mut |path| outputs.add(path),
    )?;
    crate::budget_out::write_budget(
        &mut outputs,
        &mission,
        &done.table,
        p.plan.spec.exposures_per_stare,
    )?;
    outputs.keep();
    eprintln!("wrote {}", req.out.display());
    Ok(())
}
