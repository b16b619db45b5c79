//! `jsim solve-synthetic`: the benchmark's synthetic sequence (N sources × E exposures, the survey's overlap,
//! the instrument's calibration drawn and solved) solved and written — the distributed solution's check and
//! its scaling (`mpirun -np 4 jsim-mpi solve-synthetic …`: the ranks solve it together, rank 0 writes).
//! Engine side: [`engine::studies::bench_solution::solve_synthetic`].

use crate::bench_cmd::SolutionCalibration;
use crate::solve_cmd::IterationMethod;
use anyhow::Result;
use clap::Args;
use engine::io::csv::Cell;
use engine::studies::sequence::solution as sq;
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
pub struct SyntheticArgs {
    /// Sources, 100 … 2·10⁶.
    #[arg(long, default_value_t = 2000)]
    pub sources: usize,
    /// Exposures, a multiple of 25 (the 5 × 5 pointing pattern per epoch) up to 10 000.
    #[arg(long, default_value_t = 100)]
    pub exposures: usize,
    /// The instrument's calibration drawn and solved: full (four arrays' own terms and a cubic distortion)
    /// or none.
    #[arg(long, value_enum, default_value_t = SolutionCalibration::Full)]
    pub calibration: SolutionCalibration,
    /// How the solution iterates: cg or block (one rank only).
    #[arg(long, value_enum, default_value_t = IterationMethod::Cg)]
    pub method: IterationMethod,
    /// The draw's seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Resume from this checkpoint if it is there, write it as the solution goes (each relinearisation,
    /// every 20 steps of the gradients, each rejection round), remove it when done: a run killed midway is
    /// rerun with the same options to the same solution.
    #[arg(long, value_name = "FILE")]
    pub checkpoint: Option<PathBuf>,
    /// Output directory: sources.csv, attitudes.csv, solution.json.
    #[arg(long, default_value = "out/solve-synthetic")]
    pub out: PathBuf,
}

pub fn solve_synthetic(a: &SyntheticArgs) -> Result<()> {
    let world = engine::solution::ranks::world();
    let run = engine::studies::bench_solution::solve_synthetic(
        a.sources,
        a.exposures,
        a.calibration.model(),
        a.method.method(),
        a.seed,
        a.checkpoint.as_deref(),
    )?;
    // every rank holds the same solution: rank 0 alone writes it
    if world.rank() != 0 {
        return Ok(());
    }
    let sol = &run.sol;
    let mut outputs = crate::outputs::Outputs::in_dir(&a.out)?;
    let rows: Vec<Vec<Cell>> = sol
        .sources
        .iter()
        .enumerate()
        .map(|(s, v)| [vec![Cell::I(s as i64)], sq::source_cells(v)].concat())
        .collect();
    let header: Vec<&str> = ["source"].into_iter().chain(sq::SOURCE_COLUMNS).collect();
    engine::io::csv::write(
        &outputs.path(engine::io::products::files::SOURCES_CSV),
        &header,
        &rows,
    )?;
    let rows: Vec<Vec<Cell>> = sol
        .attitudes
        .iter()
        .enumerate()
        .map(|(e, t)| {
            vec![
                Cell::I(e as i64),
                Cell::F(t.p),
                Cell::F(t.q),
                Cell::F(t.offset_mas[0]),
                Cell::F(t.offset_mas[1]),
            ]
        })
        .collect();
    engine::io::csv::write(
        &outputs.path(engine::io::products::files::ATTITUDES_CSV),
        &["exposure", "p", "q", "offset_xi_mas", "offset_eta_mas"],
        &rows,
    )?;
    let summary = serde_json::json!({
        "sources": a.sources,
        "exposures": a.exposures,
        "observations": run.syn.obs.len(),
        "seed": a.seed,
        "ranks": world.size(),
        "method": format!("{:?}", a.method).to_lowercase(),
        "iterations": sol.iterations,
        "converged": sol.converged,
        "rejected": sol.rejected,
        "chi2_per_dof": sol.chi2_per_dof,
        "solve_s": run.time_s,
        "position_error_over_sigma": run.error_over_sigma,
        "position_rms_mas": run.rms_mas,
        "peak_memory_mib_rank0": engine::studies::bench_solution::peak_memory_mib(),
    });
    engine::io::write_atomic(
        &outputs.path(engine::io::products::files::SOLUTION_JSON),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    outputs.keep();
    eprintln!(
        "{} sources × {} exposures ({} observations) on {} rank(s): {} iterations{}, χ²/dof {:.3}, {:.1} s; \
         positions {:.3} of their σ; wrote {}",
        a.sources,
        a.exposures,
        run.syn.obs.len(),
        world.size(),
        sol.iterations,
        if sol.converged {
            ""
        } else {
            " (not converged)"
        },
        sol.chi2_per_dof,
        run.time_s,
        run.error_over_sigma,
        a.out.display()
    );
    Ok(())
}
