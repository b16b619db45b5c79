//! A sequence's plan as files, written before any exposure runs (and again, identically, on a rerun):
//! `plan.csv` (the planned pointings: what the pipeline knows), `plan_truth.csv` (the pointings as flown: the
//! scoring's side), `coverage.csv` and `coverage.png` (exposures per sky cell), `sequence.json` (the plan's
//! summary). `jsim sequence` calls [`write`].

use super::{Coverage, Plan, SequenceError, Spec};
use crate::io::csv::{self, Cell};
use crate::io::sequence_view::{COVERAGE_NAME, PLAN_NAME};
use std::path::Path;

/// Columns of `plan.csv`: each exposure's planned stare, pointing (ICRS, degrees), start and seed.
pub const PLAN_COLUMNS: [&str; 12] = [
    "exposure",
    "stare",
    "visit",
    "l_deg",
    "b_deg",
    "ra_deg",
    "dec_deg",
    "pa_deg",
    "date_obs",
    "mjd_tdb",
    "seed",
    "orbit_phase_deg",
];

/// Columns of `plan_truth.csv`: each exposure's pointing as flown (the plan plus its pointing and roll errors).
pub const PLAN_TRUTH_COLUMNS: [&str; 4] = ["exposure", "ra_deg", "dec_deg", "pa_deg"];

/// Columns of `coverage.csv`: each sky cell's centre and the exposures that see it.
pub const COVERAGE_COLUMNS: [&str; 3] = ["l_deg", "b_deg", "exposures"];

/// What the coverage map says, for the log and `sequence.json`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoverageSummary {
    /// The area of the cells some exposure sees, deg².
    pub covered_deg2: f64,
    /// Exposures per covered cell: the median and the most.
    pub median: u32,
    pub max: u32,
}

/// The median and largest count over the covered cells, and their area.
pub fn summarise(coverage: &Coverage) -> CoverageSummary {
    let mut covered: Vec<u32> = coverage.counts.iter().copied().filter(|c| *c > 0).collect();
    covered.sort_unstable();
    CoverageSummary {
        covered_deg2: covered.len() as f64 * coverage.cell_deg * coverage.cell_deg,
        median: covered.get(covered.len() / 2).copied().unwrap_or(0),
        max: covered.last().copied().unwrap_or(0),
    }
}

/// Write the plan's files into `dir` (`will_write` is told each before it is written, so that a front end can
/// remove them if the run fails); returns the coverage's summary.
pub fn write(
    plan: &Plan,
    spec: &Spec,
    coverage: &Coverage,
    dir: &Path,
    will_write: &mut dyn FnMut(&Path),
) -> Result<CoverageSummary, SequenceError> {
    let mut at = |name: &str| {
        let path = dir.join(name);
        will_write(&path);
        path
    };
    let (mut plan_rows, mut flown_rows) = (Vec::new(), Vec::new());
    for e in &plan.exposures {
        let s = &plan.stares[e.stare];
        let (ra, dec, pa) = s.planned();
        plan_rows.push(vec![
            Cell::I(e.index as i64),
            Cell::I(e.stare as i64),
            Cell::I(s.visit as i64),
            Cell::F(s.l_deg),
            Cell::F(s.b_deg),
            Cell::F(ra),
            Cell::F(dec),
            Cell::F(pa),
            Cell::S(e.start.utc_iso()),
            Cell::F(e.start.tdb_mjd()),
            Cell::S(e.seed.to_string()), // unsigned: a u64 seed ≥ 2⁶³ is no i64
            Cell::F(e.orbit_phase_deg),
        ]);
        flown_rows.push(vec![
            Cell::I(e.index as i64),
            Cell::F(s.ra_deg),
            Cell::F(s.dec_deg),
            Cell::F(s.pa_deg),
        ]);
    }
    csv::write(&at(PLAN_NAME), &PLAN_COLUMNS, &plan_rows)?;
    csv::write(
        &at(crate::io::products::files::PLAN_TRUTH_CSV),
        &PLAN_TRUTH_COLUMNS,
        &flown_rows,
    )?;
    let cov_rows: Vec<Vec<Cell>> = (0..coverage.rows)
        .flat_map(|j| (0..coverage.columns).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (l, b) = coverage.centre(i, j);
            vec![
                Cell::F(l),
                Cell::F(b),
                Cell::I(i64::from(coverage.counts[j * coverage.columns + i])),
            ]
        })
        .collect();
    csv::write(&at(COVERAGE_NAME), &COVERAGE_COLUMNS, &cov_rows)?;
    crate::io::plot::count_map(
        &at(crate::io::products::files::COVERAGE_PNG),
        &format!(
            "{} exposures: {} stares × {} per stare × {} visits",
            plan.exposures.len(),
            plan.stares.len() / spec.visits_utc.len(),
            spec.exposures_per_stare,
            spec.visits_utc.len()
        ),
        "Galactic longitude l [deg]",
        "Galactic latitude b [deg]",
        crate::io::plot::CountGrid {
            counts: &coverage.counts,
            columns: coverage.columns,
            rows: coverage.rows,
            x0: coverage.l0_deg,
            y0: coverage.b0_deg,
            cell: coverage.cell_deg,
            x_reversed: true,
        },
    )
    .map_err(crate::io::IoError::from)?;
    let summary = summarise(coverage);
    let json = serde_json::json!({
        "spec": spec,
        "exposures": plan.exposures.len(),
        "stares": plan.stares.len(),
        "field_deg": plan.field_deg,
        "covered_deg2": summary.covered_deg2,
        "median_exposures_per_covered_cell": summary.median,
        "max_exposures_per_cell": summary.max,
        "coverage_cell_deg": coverage.cell_deg,
        "jsim_version": crate::VERSION,
    });
    let text = serde_json::to_string_pretty(&json)
        .map_err(|e| SequenceError::Invalid(format!("sequence.json: {e}")))?;
    crate::io::write_atomic(
        &at(crate::io::products::files::SEQUENCE_JSON),
        text.as_bytes(),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_counts_only_covered_cells() {
        // 4 × 1 cells of 0.1°: counts 0, 3, 1, 5 → three covered cells (0.03 deg²), median 3, most 5
        let c = Coverage {
            counts: vec![0, 3, 1, 5],
            columns: 4,
            rows: 1,
            l0_deg: 0.0,
            b0_deg: 0.0,
            cell_deg: 0.1,
        };
        let s = summarise(&c);
        assert!((s.covered_deg2 - 0.03).abs() < 1e-12);
        assert_eq!((s.median, s.max), (3, 5));
        let none = summarise(&Coverage {
            counts: vec![0; 4],
            ..c
        });
        assert_eq!((none.covered_deg2, none.median, none.max), (0.0, 0, 0));
    }
}
