//! `jsim solve`: the astrometric solution of a sequence that has run (its products only), then its scoring
//! against the truth and the precision against the number of exposures. Engine side:
//! [`engine::studies::sequence::solution`].

use anyhow::{Result, bail};
use clap::Args;
use engine::analysis::solution::SourceModel;
use engine::io::csv::Cell;
use engine::io::plot::{Scale, Series};
use engine::studies::sequence::budget::MissionPattern;
use engine::studies::sequence::solution::{self as sq, PrecisionRow};
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
    pub fn method(self) -> engine::analysis::solution::Method {
        match self {
            IterationMethod::Cg => engine::analysis::solution::Method::ConjugateGradient,
            IterationMethod::Block => engine::analysis::solution::Method::Block,
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

/// The checkpoint of the solution of the first `n` exposures: --checkpoint, suffixed `.n` when several are
/// solved.
fn checkpoint(a: &SolveArgs, n: usize, ns: &[usize]) -> Option<PathBuf> {
    let path = a.checkpoint.as_ref()?;
    Some(if ns.len() > 1 {
        let mut p = path.clone().into_os_string();
        p.push(format!(".{n}"));
        PathBuf::from(p)
    } else {
        path.clone()
    })
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
    if !sequence.join("sequence.toml").is_file() {
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
    opt("--model", a.model.clone());
    if let Some(d) = a.distortion_order {
        opt("--distortion-order", d.to_string());
    }
    opt("--method", format!("{:?}", a.method).to_lowercase());
    opt("--sigma-floor-mas", a.sigma_floor_mas.to_string());
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
    let model = match a.model.as_str() {
        "auto" => None,
        "position" => Some(SourceModel::Position),
        "full" => Some(SourceModel::Full),
        m => bail!("--model {m:?}: allowed auto, position, full"),
    };
    let spec = sq::SolveSpec {
        model,
        distortion_order: a.distortion_order,
        method: a.method.method(),
        feed: engine::analysis::solution::feed::FeedOptions {
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
    let p = sq::read_products(&a.sequence)?;
    let mut ns = a.exposures.clone();
    if ns.is_empty() {
        ns.push(p.exposures_run);
    }
    ns.sort_unstable();
    ns.dedup();
    if let Some(n) = ns.iter().find(|n| **n == 0 || **n > p.exposures_run) {
        bail!(
            "--exposures {n}: allowed 1 … {} (the exposures that have run)",
            p.exposures_run
        );
    }
    if engine::analysis::solution::ranks::world().rank() != 0 {
        // another MPI rank (jsim-mpi): the same solutions, rank 0 alone scores, prints and writes them
        for &n in &ns {
            sq::solve_first(&p, n, &spec, checkpoint(a, n, &ns).as_deref())?;
        }
        return Ok(());
    }
    eprintln!(
        "read {} exposures' {} detections and {} reference stars in {:.1} s",
        p.exposures_run,
        p.detections.len(),
        p.references.len(),
        t.elapsed().as_secs_f64()
    );
    let out = a.out.clone().unwrap_or_else(|| a.sequence.join("solution"));
    let mut outputs = crate::outputs::Outputs::in_dir(&out)?;
    // the scoring reads the truth, apart from the solution
    let truth = sq::read_truth(&a.sequence, &p)?;
    let (lo, hi) = (p.cfg.scene.bulge.hw_min, p.cfg.scene.bulge.hw_max);
    let edges = engine::scoring::crowded::edges(lo, hi, 1.0);
    let ranks = engine::analysis::solution::ranks::world().size();
    let mut table: Vec<PrecisionRow> = Vec::new();
    let mut summary = Vec::new();
    for (k, &n) in ns.iter().enumerate() {
        let t = Instant::now();
        let (fed, opt, sol) = sq::solve_first(&p, n, &spec, checkpoint(a, n, &ns).as_deref())?;
        let solve_s = t.elapsed().as_secs_f64();
        let true_all = sq::true_sources(&fed, &truth);
        // positions only: scored at the epoch of each source's observations (what its σ describes)
        let (scored, truths) = if opt.model == SourceModel::Position {
            sq::at_mean_epoch(&fed, &sol, &true_all)
        } else {
            (sol.sources.clone(), true_all.clone())
        };
        let bins = engine::scoring::solution::score_sources(&scored, &truths, &edges);
        let single = sq::single_exposure_errors(&p, &truth, n, &edges);
        eprintln!(
            "{n} exposures: {} observations of {} sources ({} in the reference catalogue), {} detections left \
             out, {} arrays unaligned; {:?} model, distortion order {}; {} iterations{}, {} rejected, χ²/dof \
             {:.3}; {solve_s:.1} s on {ranks} rank(s)",
            fed.obs.len(),
            fed.n_sources,
            fed.refs.len(),
            fed.left_out,
            fed.unaligned.len(),
            opt.model,
            opt.calibration.distortion_order,
            sol.iterations,
            if sol.converged {
                ""
            } else {
                " (not converged)"
            },
            sol.rejected,
            sol.chi2_per_dof
        );
        if !sol.skipped_exposures.is_empty() {
            eprintln!(
                "  {} exposure(s) left out, tied to nothing else (fewer than 2 sources shared with the rest and \
                 the reference catalogue): {:?}",
                sol.skipped_exposures.len(),
                sol.skipped_exposures
            );
        }
        for (b, s) in bins.iter().zip(&single) {
            if b.sources > 0 {
                eprintln!(
                    "  Hw {:.0}–{:.0}: {:>6} sources, {:>4.0} obs; position {:.3} mas rms, {:.3} robust, {:.1} % \
                     beyond 5σ (σ {:.3}, pull {:.2}; single {:.2} rms, {:.2} robust → √N {:.3}); pm {:.3} mas/yr \
                     (σ {:.3}); parallax {:.3} mas (σ {:.3}, pull {:.2})",
                    b.hw_lo,
                    b.hw_hi,
                    b.sources,
                    b.observations,
                    b.position_rms_mas,
                    b.position_robust_mas,
                    100.0 * b.outlier_fraction,
                    b.position_sigma_mas,
                    b.position_pull,
                    s.rms_mas,
                    s.robust_mas,
                    s.robust_mas / b.observations.sqrt(),
                    b.pm_rms_mas_per_yr,
                    b.pm_sigma_mas_per_yr,
                    b.parallax_rms_mas,
                    b.parallax_sigma_mas,
                    b.parallax_pull
                );
            }
            table.push(PrecisionRow {
                exposures: n,
                bin: *b,
                single: *s,
            });
        }
        summary.push(serde_json::json!({
            "exposures": n,
            "observations": fed.obs.len(),
            "sources": fed.n_sources,
            "references": fed.refs.len(),
            "left_out": fed.left_out,
            "unaligned_arrays": fed.unaligned.len(),
            "model": format!("{:?}", opt.model),
            "distortion_order": opt.calibration.distortion_order,
            "iterations": sol.iterations,
            "converged": sol.converged,
            "rejected": sol.rejected,
            "skipped_exposures": sol.skipped_exposures,
            "chi2_per_dof": sol.chi2_per_dof,
            "solve_s": solve_s,
        }));
        // the last (largest) solution's files
        if k + 1 == ns.len() {
            sq::write_solution(&out, &p, &fed, &sol)?;
            for f in ["sources.csv", "attitudes.csv", "calibration.csv"] {
                outputs.add(&out.join(f));
            }
            // each source against its true star (the scoring's per-source table)
            let rows: Vec<Vec<Cell>> = scored
                .iter()
                .zip(&truths)
                .enumerate()
                .filter_map(|(s, (v, t))| {
                    let t = t.as_ref()?;
                    let mut row = vec![Cell::I(s as i64), Cell::F(t.hw)];
                    row.extend((0..5).map(|k| Cell::F(v.params[k] - t.params[k])));
                    row.extend(v.sigma.iter().map(|x| Cell::F(*x)));
                    row.extend([
                        Cell::I(v.observations as i64),
                        Cell::I(i64::from(fed.reference[s].is_some())),
                    ]);
                    Some(row)
                })
                .collect();
            engine::io::csv::write(
                &outputs.path("score_sources.csv"),
                &[
                    "source",
                    "hw",
                    "d_xi_mas",
                    "d_eta_mas",
                    "d_pm_xi",
                    "d_pm_eta",
                    "d_parallax",
                    "xi_error",
                    "eta_error",
                    "pm_xi_error",
                    "pm_eta_error",
                    "parallax_error",
                    "observations",
                    "in_reference",
                ],
                &rows,
            )?;
            // each attitude against what the true stars ask of it
            let att = engine::scoring::solution::attitude_errors(
                &fed.obs,
                &fed.exposures,
                &sol,
                &true_all,
            );
            let att_rows: Vec<Vec<Cell>> = att
                .iter()
                .enumerate()
                .filter_map(|(e, a)| {
                    let a = a.as_ref()?;
                    Some(vec![
                        Cell::I(e as i64),
                        Cell::F(a.offset_mas[0]),
                        Cell::F(a.offset_mas[1]),
                        Cell::F(a.roll_arcsec),
                        Cell::F(a.scale_ppm),
                        Cell::I(a.stars as i64),
                    ])
                })
                .collect();
            engine::io::csv::write(
                &outputs.path("score_attitudes.csv"),
                &[
                    "exposure",
                    "d_offset_xi_mas",
                    "d_offset_eta_mas",
                    "d_roll_arcsec",
                    "d_scale_ppm",
                    "stars",
                ],
                &att_rows,
            )?;
            let scored_att: Vec<_> = att.iter().flatten().collect();
            // no exposure scored: no number (NaN, null in solution.json), never 0
            let k = scored_att.len() as f64;
            let rms_att = |f: &dyn Fn(&&engine::scoring::solution::AttitudeError) -> f64| {
                if scored_att.is_empty() {
                    f64::NAN
                } else {
                    (scored_att.iter().map(|a| f(a).powi(2)).sum::<f64>() / k).sqrt()
                }
            };
            let att_summary = [
                rms_att(&|a| a.offset_mas[0]),
                rms_att(&|a| a.offset_mas[1]),
                rms_att(&|a| a.roll_arcsec),
                rms_att(&|a| a.scale_ppm),
            ];
            eprintln!(
                "attitudes against the truth ({} exposures): offset {:.3}/{:.3} mas, roll {:.4}″, scale {:.3} ppm rms",
                scored_att.len(),
                att_summary[0],
                att_summary[1],
                att_summary[2],
                att_summary[3]
            );
            if let Some(last) = summary.last_mut() {
                last["attitude_error_rms"] = serde_json::json!({
                    "offset_mas": [att_summary[0], att_summary[1]],
                    "roll_arcsec": att_summary[2],
                    "scale_ppm": att_summary[3],
                });
            }
            let map = sq::calibration_map(&p, &truth, &sol)?;
            let rms = |c: usize| {
                (map.iter().map(|r| r[c] * r[c]).sum::<f64>() / map.len().max(1) as f64).sqrt()
            };
            let scale = p.cfg.instrument.plate_scale_mas();
            eprintln!(
                "calibration: the instrument's correction {:.3}/{:.3} px rms (x/y), the solved one's residual \
                 {:.4}/{:.4} px = {:.2}/{:.2} mas rms over the arrays",
                rms(5),
                rms(6),
                rms(9),
                rms(10),
                rms(9) * scale,
                rms(10) * scale
            );
            let rows: Vec<Vec<Cell>> = map
                .iter()
                .map(|r| r.iter().map(|v| Cell::F(*v)).collect())
                .collect();
            engine::io::csv::write(
                &outputs.path("calibration_map.csv"),
                &engine::io::sequence_view::CALIBRATION_MAP_COLUMNS,
                &rows,
            )?;
            if let Some(last) = summary.last_mut() {
                last["calibration_residual_rms_px"] = serde_json::json!([rms(9), rms(10)]);
            }
        }
    }
    let rows: Vec<Vec<Cell>> = table
        .iter()
        .map(|r| {
            let b = &r.bin;
            vec![
                Cell::I(r.exposures as i64),
                Cell::F(b.hw_lo),
                Cell::F(b.hw_hi),
                Cell::I(b.sources as i64),
                Cell::F(b.observations),
                Cell::F(b.position_rms_mas),
                Cell::F(b.position_robust_mas),
                Cell::F(b.outlier_fraction),
                Cell::F(b.position_sigma_mas),
                Cell::F(r.single.rms_mas),
                Cell::F(r.single.robust_mas),
                Cell::F(r.single.robust_mas / b.observations.sqrt()),
                Cell::F(b.pm_rms_mas_per_yr),
                Cell::F(b.pm_sigma_mas_per_yr),
                Cell::F(b.parallax_rms_mas),
                Cell::F(b.parallax_sigma_mas),
                Cell::F(b.position_pull),
                Cell::F(b.parallax_pull),
            ]
        })
        .collect();
    engine::io::csv::write(
        &outputs.path("precision_vs_n.csv"),
        &[
            "exposures",
            "hw_lo",
            "hw_hi",
            "sources",
            "observations",
            "position_rms_mas",
            "position_robust_mas",
            "outlier_fraction",
            "position_sigma_mas",
            "single_exposure_mas",
            "single_exposure_robust_mas",
            "sqrt_n_mas",
            "pm_rms_mas_per_yr",
            "pm_sigma_mas_per_yr",
            "parallax_rms_mas",
            "parallax_sigma_mas",
            "position_pull",
            "parallax_pull",
        ],
        &rows,
    )?;
    crate::budget_out::write_budget(
        &mut outputs,
        &mission,
        &table,
        p.plan.spec.exposures_per_stare,
    )?;
    // precision against N per magnitude bin, each beside its √N line (dashed, in its colour)
    let (mut series, mut guides) = (Vec::new(), Vec::new());
    for w in edges.windows(2) {
        let pts: Vec<&PrecisionRow> = table
            .iter()
            .filter(|r| r.bin.hw_lo == w[0] && r.bin.sources >= 5)
            .collect();
        // a bin whose error grows with the exposures is one whose identification fails (sources fainter than
        // the reference catalogue, mismatched): the table keeps it, the figure leaves it out
        let grows = pts.len() > 1
            && pts[pts.len() - 1].bin.position_robust_mas > 2.0 * pts[0].bin.position_robust_mas;
        if pts.is_empty() || grows {
            continue;
        }
        let x: Vec<f64> = pts.iter().map(|r| r.exposures as f64).collect();
        series.push(Series {
            label: format!("Hw {:.0}–{:.0}", w[0], w[1]),
            x: x.clone(),
            y: pts.iter().map(|r| r.bin.position_robust_mas).collect(),
            yerr: None,
            yerr_below: None,
        });
        guides.push(Series {
            label: String::new(),
            x,
            y: pts
                .iter()
                .map(|r| r.single.robust_mas / r.bin.observations.sqrt())
                .collect(),
            yerr: None,
            yerr_below: None,
        });
    }
    if !series.is_empty() {
        engine::io::plot::line_plot_with_guides(
            &outputs.path("precision_vs_n.png"),
            "Solved position error against N (dashed: single exposure, robust / √observations)",
            "exposures N",
            "position error per axis, robust [mas]",
            &series,
            &guides,
            &[],
            Scale::Log,
            Scale::Log,
        )?;
    }
    engine::io::write_atomic(
        &outputs.path("solution.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    outputs.keep();
    eprintln!("wrote {}", out.display());
    Ok(())
}
