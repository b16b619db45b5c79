//! `jsim solve`'s mission error budget: each magnitude bin's end-of-mission parallax and proper-motion
//! precision, extrapolated from the sequence's own measurement ([`engine::studies::sequence::budget`]),
//! written as `mission_budget.csv` and printed beside the requirements.

use anyhow::Result;
use engine::io::csv::Cell;
use engine::studies::sequence::budget::{self, MissionPattern};
use engine::studies::sequence::solution::PrecisionRow;

/// Write the budget where the precision table holds the sequence's first full stare (N = `measured_stare`,
/// its exposures per stare); say why not otherwise.
pub fn write_budget(
    outputs: &mut crate::outputs::Outputs,
    mission: &MissionPattern,
    table: &[PrecisionRow],
    measured_stare: usize,
) -> Result<()> {
    let rows = budget::budget_from_precision(mission, table, measured_stare)
        .map_err(anyhow::Error::msg)?;
    if rows.is_empty() {
        eprintln!(
            "mission budget: not written (it needs the precision of one full stare: --exposures including {measured_stare})"
        );
        return Ok(());
    }
    let axes = |v: [f64; 2]| ((v[0] * v[0] + v[1] * v[1]) / 2.0).sqrt();
    eprintln!(
        "mission budget ({} exposures per star in stares of {}, {} yr, seasons ±{} d about the equinoxes):",
        mission.exposures_per_star,
        mission.exposures_per_stare,
        mission.years,
        mission.season_half_width_days
    );
    let mut cells = Vec::new();
    for r in &rows {
        let (plx_uas, pm_uas) = (1e3 * r.end.parallax_mas, 1e3 * axes(r.end.pm_mas_per_yr));
        eprintln!(
            "  Hw {:.0}–{:.0}: σ_e {:.2} mas, per stare {:.3} mas → parallax {plx_uas:.1} µas (need 40/25), proper \
             motion {pm_uas:.1} µas/yr (need 125/25)",
            r.hw_lo, r.hw_hi, r.errors.per_exposure_mas, r.errors.per_stare_mas
        );
        cells.push(vec![
            Cell::F(r.hw_lo),
            Cell::F(r.hw_hi),
            Cell::I(r.sources as i64),
            Cell::F(r.single_mas),
            Cell::F(r.one_stare_mas),
            Cell::F(r.errors.per_stare_mas),
            Cell::F(axes(r.end.position_mas)),
            Cell::F(axes(r.end.pm_mas_per_yr)),
            Cell::F(r.end.parallax_mas),
            Cell::I(i64::from(r.end.parallax_mas <= budget::PARALLAX_FULL_MAS)),
            Cell::I(i64::from(r.end.parallax_mas <= budget::PARALLAX_EXTRA_MAS)),
            Cell::I(i64::from(
                axes(r.end.pm_mas_per_yr) <= budget::PM_FULL_MAS_PER_YR,
            )),
            Cell::I(i64::from(
                axes(r.end.pm_mas_per_yr) <= budget::PM_EXTRA_MAS_PER_YR,
            )),
        ]);
    }
    engine::io::csv::write(
        &outputs.path(engine::io::products::files::MISSION_BUDGET_CSV),
        &[
            "hw_lo",
            "hw_hi",
            "sources",
            "single_exposure_mas",
            "one_stare_mas",
            "per_stare_mas",
            "position_mas",
            "pm_mas_per_yr",
            "parallax_mas",
            "parallax_full",
            "parallax_extra",
            "pm_full",
            "pm_extra",
        ],
        &cells,
    )?;
    Ok(())
}
