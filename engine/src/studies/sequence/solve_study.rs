//! The solution of a sequence that has run, as a study: for each N asked, the solution of the first N exposures
//! from the sequence's products alone ([`solution::solve_first`], the `crate::solution` stage), then scored
//! against the truth apart from it; the precision against N, and the files that report it. `jsim solve` parses
//! its options and calls [`run`]; so does Python's `jsim.solve_sequence`.

use super::SequenceError;
use super::solution::{self as sq, PrecisionRow, Products, SolveSpec, Truth};
use crate::io::csv::{self, Cell};
use crate::io::plot::{Scale, Series};
use crate::scoring::solution::{AttitudeError, BinScore, TrueSource};
use crate::solution::SourceModel;
use crate::solution::feed::Fed;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to solve and where to write it.
#[derive(Debug, Clone)]
pub struct Request {
    /// The first N exposures for each N (sorted, distinct, each 1 … the exposures that have run:
    /// [`exposures_to_solve`]).
    pub exposures: Vec<usize>,
    pub spec: SolveSpec,
    /// Resume from and write this checkpoint (suffixed `.N` when several N are solved: [`checkpoint_for`]).
    pub checkpoint: Option<PathBuf>,
    /// The output directory (`solution/` in the sequence's by default).
    pub out: PathBuf,
}

/// What a study measured: the precision table of every N, and one summary per N (`solution.json`).
#[derive(Debug, Clone)]
pub struct Study {
    pub table: Vec<PrecisionRow>,
    pub summary: Vec<serde_json::Value>,
}

/// The N to solve: those asked, sorted and distinct, or all that have run when none is asked; an N of 0 or
/// beyond the exposures that have run is an error naming the range.
pub fn exposures_to_solve(asked: &[usize], run: usize) -> Result<Vec<usize>, SequenceError> {
    let mut ns = asked.to_vec();
    if ns.is_empty() {
        ns.push(run);
    }
    ns.sort_unstable();
    ns.dedup();
    if let Some(n) = ns.iter().find(|n| **n == 0 || **n > run) {
        return Err(SequenceError::Invalid(format!(
            "exposures {n}: allowed 1 … {run} (the exposures that have run)"
        )));
    }
    Ok(ns)
}

/// The checkpoint of the solution of the first `n` exposures: `base`, suffixed `.n` when several are solved.
pub fn checkpoint_for(base: Option<&Path>, n: usize, ns: &[usize]) -> Option<PathBuf> {
    let path = base?;
    Some(if ns.len() > 1 {
        let mut p = path.as_os_str().to_owned();
        p.push(format!(".{n}"));
        PathBuf::from(p)
    } else {
        path.to_path_buf()
    })
}

/// The solutions alone, unscored and unwritten: what an MPI rank other than 0 computes beside rank 0.
pub fn solve_only(p: &Products, req: &Request) -> Result<(), SequenceError> {
    for &n in &req.exposures {
        let cp = checkpoint_for(req.checkpoint.as_deref(), n, &req.exposures);
        sq::solve_first(p, n, &req.spec, cp.as_deref())?;
    }
    Ok(())
}

/// Solve, score and write: the largest N's solution (`sources.csv`, `attitudes.csv`, `calibration.csv`), its
/// scoring (`score_sources.csv`, `score_attitudes.csv`, `calibration_map.csv`), the precision against N
/// (`precision_vs_n.csv`, `.png`) and `solution.json`. `log` receives the progress lines; `will_write` is told
/// each file before it is written (a front end removes them if the run fails).
pub fn run(
    p: &Products,
    truth: &Truth,
    req: &Request,
    ranks: usize,
    log: &mut dyn FnMut(&str),
    will_write: &mut dyn FnMut(&Path),
) -> Result<Study, SequenceError> {
    let (lo, hi) = (p.cfg.scene.bulge.hw_min, p.cfg.scene.bulge.hw_max);
    let edges = crate::scoring::crowded::edges(lo, hi, 1.0);
    let ns = &req.exposures;
    let mut table: Vec<PrecisionRow> = Vec::new();
    let mut summary = Vec::new();
    for (k, &n) in ns.iter().enumerate() {
        let t = Instant::now();
        let cp = checkpoint_for(req.checkpoint.as_deref(), n, ns);
        let (fed, opt, sol) = sq::solve_first(p, n, &req.spec, cp.as_deref())?;
        let solve_s = t.elapsed().as_secs_f64();
        let true_all = sq::true_sources(&fed, truth);
        // positions only: scored at the epoch of each source's observations (what its σ describes)
        let (scored, truths) = if opt.model == SourceModel::Position {
            sq::at_mean_epoch(&fed, &sol, &true_all)
        } else {
            (sol.sources.clone(), true_all.clone())
        };
        let bins = crate::scoring::solution::score_sources(&scored, &truths, &edges);
        let single = sq::single_exposure_errors(p, truth, n, &edges);
        log(&format!(
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
        ));
        for b in &sol.excess {
            log(&format!(
                "  excess noise ({}): σ {:.3} mas per detection → τ {:.3} mas ({} sources seen in two groups or more)",
                opt.excess.name(),
                b.sigma_obs_mas,
                b.tau_mas,
                b.sources
            ));
        }
        if !sol.skipped_exposures.is_empty() {
            log(&format!(
                "  {} exposure(s) left out, tied to nothing else (fewer than 2 sources shared with the rest and \
                 the reference catalogue): {:?}",
                sol.skipped_exposures.len(),
                sol.skipped_exposures
            ));
        }
        for (b, s) in bins.iter().zip(&single) {
            if b.sources > 0 {
                log(&bin_line(b, s));
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
            "excess_noise": opt.excess.name(),
            "excess_bins": sol.excess.iter().map(|b| serde_json::json!({
                "sigma_obs_mas": b.sigma_obs_mas,
                "tau_mas": b.tau_mas,
                "sources": b.sources,
            })).collect::<Vec<_>>(),
            "solve_s": solve_s,
        }));
        // the last (largest) solution's files
        if k + 1 == ns.len()
            && let Some(last) = summary.last_mut()
        {
            let solved = Solved {
                fed: &fed,
                sol: &sol,
                scored: &scored,
                truths: &truths,
                true_all: &true_all,
            };
            write_last(p, truth, req, &solved, last, log, will_write)?;
        }
    }
    let path = req.out.join(crate::io::sequence_view::PRECISION_NAME);
    will_write(&path);
    write_precision(&path, &table)?;
    plot_precision(
        &req.out.join(crate::io::products::files::PRECISION_VS_N_PNG),
        &table,
        &edges,
        will_write,
    )?;
    let path = req.out.join(crate::io::products::files::SOLUTION_JSON);
    will_write(&path);
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| SequenceError::Invalid(format!("solution.json: {e}")))?;
    crate::io::write_atomic(&path, text.as_bytes())?;
    Ok(Study { table, summary })
}

/// The largest N's solution and its scoring, for [`write_last`].
struct Solved<'a> {
    fed: &'a Fed,
    sol: &'a crate::solution::Solution,
    /// The sources as scored (at their mean epoch for a positions-only model) and their true stars.
    scored: &'a [crate::solution::SolvedSource],
    truths: &'a [Option<TrueSource>],
    true_all: &'a [Option<TrueSource>],
}

/// The largest N's files: its solution (`sources.csv`, `attitudes.csv`, `calibration.csv`) and its scoring
/// (`score_sources.csv`, `score_attitudes.csv`, `calibration_map.csv`), the attitude and calibration residuals
/// added to its summary `last`.
fn write_last(
    p: &Products,
    truth: &Truth,
    req: &Request,
    s: &Solved<'_>,
    last: &mut serde_json::Value,
    log: &mut dyn FnMut(&str),
    will_write: &mut dyn FnMut(&Path),
) -> Result<(), SequenceError> {
    let mut at = |name: &str| {
        let path = req.out.join(name);
        will_write(&path);
        path
    };
    for f in [
        crate::io::products::files::SOURCES_CSV,
        crate::io::products::files::ATTITUDES_CSV,
        crate::io::products::files::CALIBRATION_CSV,
    ] {
        at(f);
    }
    sq::write_solution(&req.out, p, s.fed, s.sol)?;
    write_score_sources(
        &at(crate::io::products::files::SCORE_SOURCES_CSV),
        s.fed,
        s.scored,
        s.truths,
    )?;
    let att =
        crate::scoring::solution::attitude_errors(&s.fed.obs, &s.fed.exposures, s.sol, s.true_all);
    write_score_attitudes(&at(crate::io::products::files::SCORE_ATTITUDES_CSV), &att)?;
    let att_rms = attitude_rms(&att);
    log(&format!(
        "attitudes against the truth ({} exposures): offset {:.3}/{:.3} mas, roll {:.4}″, scale {:.3} ppm rms",
        att.iter().flatten().count(),
        att_rms[0],
        att_rms[1],
        att_rms[2],
        att_rms[3]
    ));
    let map = sq::calibration_map(p, truth, s.sol)?;
    let rms =
        |c: usize| (map.iter().map(|r| r[c] * r[c]).sum::<f64>() / map.len().max(1) as f64).sqrt();
    let scale = p.cfg.instrument.plate_scale_mas();
    log(&format!(
        "calibration: the instrument's correction {:.3}/{:.3} px rms (x/y), the solved one's residual \
         {:.4}/{:.4} px = {:.2}/{:.2} mas rms over the arrays",
        rms(5),
        rms(6),
        rms(9),
        rms(10),
        rms(9) * scale,
        rms(10) * scale
    ));
    let rows: Vec<Vec<Cell>> = map
        .iter()
        .map(|r| r.iter().map(|v| Cell::F(*v)).collect())
        .collect();
    csv::write(
        &at(crate::io::sequence_view::CALIBRATION_MAP_NAME),
        &crate::io::sequence_view::CALIBRATION_MAP_COLUMNS,
        &rows,
    )?;
    last["attitude_error_rms"] = serde_json::json!({
        "offset_mas": [att_rms[0], att_rms[1]],
        "roll_arcsec": att_rms[2],
        "scale_ppm": att_rms[3],
    });
    last["calibration_residual_rms_px"] = serde_json::json!([rms(9), rms(10)]);
    Ok(())
}

/// One magnitude bin's line of the progress report.
fn bin_line(b: &BinScore, s: &sq::SingleExposure) -> String {
    format!(
        "  Hw {:.0}–{:.0}: {:>6} sources, {:>4.0} obs; position {:.3} mas rms, {:.3} robust, {:.1} % beyond 5σ \
         (σ {:.3}, pull {:.2}; single {:.2} rms, {:.2} robust → √N {:.3}); pm {:.3} mas/yr (σ {:.3}, pull {:.2}); \
         parallax {:.3} mas (σ {:.3}, pull {:.2})",
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
        b.pm_pull,
        b.parallax_rms_mas,
        b.parallax_sigma_mas,
        b.parallax_pull
    )
}

/// Columns of `score_sources.csv`: each source against its true star (fitted − true of the five parameters,
/// their formal errors, observations, whether the reference catalogue holds it).
pub const SCORE_SOURCES_COLUMNS: [&str; 14] = [
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
];

fn write_score_sources(
    path: &Path,
    fed: &Fed,
    scored: &[crate::solution::SolvedSource],
    truths: &[Option<TrueSource>],
) -> Result<(), SequenceError> {
    let rows: Vec<Vec<Cell>> = scored
        .iter()
        .zip(truths)
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
    Ok(csv::write(path, &SCORE_SOURCES_COLUMNS, &rows)?)
}

/// Columns of `score_attitudes.csv`: each exposure's attitude against what the true stars ask of it.
pub const SCORE_ATTITUDES_COLUMNS: [&str; 6] = [
    "exposure",
    "d_offset_xi_mas",
    "d_offset_eta_mas",
    "d_roll_arcsec",
    "d_scale_ppm",
    "stars",
];

fn write_score_attitudes(path: &Path, att: &[Option<AttitudeError>]) -> Result<(), SequenceError> {
    let rows: Vec<Vec<Cell>> = att
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
    Ok(csv::write(path, &SCORE_ATTITUDES_COLUMNS, &rows)?)
}

/// The rms over the scored exposures of the attitude errors: offset ξ, η (mas), roll (″), scale (ppm); NaN
/// (null in `solution.json`), never 0, when no exposure was scored.
fn attitude_rms(att: &[Option<AttitudeError>]) -> [f64; 4] {
    let scored: Vec<&AttitudeError> = att.iter().flatten().collect();
    let rms = |f: &dyn Fn(&AttitudeError) -> f64| {
        if scored.is_empty() {
            f64::NAN
        } else {
            (scored.iter().map(|a| f(a).powi(2)).sum::<f64>() / scored.len() as f64).sqrt()
        }
    };
    [
        rms(&|a| a.offset_mas[0]),
        rms(&|a| a.offset_mas[1]),
        rms(&|a| a.roll_arcsec),
        rms(&|a| a.scale_ppm),
    ]
}

/// Columns of `precision_vs_n.csv`: per N and magnitude bin, the solved precision beside the single exposure's.
pub const PRECISION_COLUMNS: [&str; 19] = [
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
    "pm_pull",
];

fn write_precision(path: &Path, table: &[PrecisionRow]) -> Result<(), SequenceError> {
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
                Cell::F(b.pm_pull),
            ]
        })
        .collect();
    Ok(csv::write(path, &PRECISION_COLUMNS, &rows)?)
}

/// The precision against N per magnitude bin, each beside its √N line (dashed, in its colour); whether there
/// was a bin to draw.
fn plot_precision(
    path: &Path,
    table: &[PrecisionRow],
    edges: &[f64],
    will_write: &mut dyn FnMut(&Path),
) -> Result<bool, SequenceError> {
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
    if series.is_empty() {
        return Ok(false);
    }
    will_write(path);
    crate::io::plot::line_plot_with_guides(
        path,
        "Solved position error against N (dashed: single exposure, robust / √observations)",
        "exposures N",
        "position error per axis, robust [mas]",
        &series,
        &guides,
        &[],
        Scale::Log,
        Scale::Log,
    )
    .map_err(crate::io::IoError::from)?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exposures_asked_are_sorted_deduplicated_and_bounded() {
        assert_eq!(exposures_to_solve(&[], 7).expect("all"), vec![7]);
        assert_eq!(exposures_to_solve(&[5, 2, 5], 7).expect("two"), vec![2, 5]);
        for bad in [0, 8] {
            let e = exposures_to_solve(&[3, bad], 7).expect_err("out of range");
            assert!(
                e.to_string()
                    .contains(&format!("exposures {bad}: allowed 1 … 7")),
                "{e}"
            );
        }
    }

    #[test]
    fn several_solutions_checkpoint_to_one_file_each() {
        let base = Path::new("run/cp");
        assert_eq!(checkpoint_for(None, 3, &[3]), None);
        assert_eq!(
            checkpoint_for(Some(base), 3, &[3]),
            Some(base.to_path_buf())
        );
        assert_eq!(
            checkpoint_for(Some(base), 3, &[3, 6]),
            Some(PathBuf::from("run/cp.3"))
        );
    }
}
