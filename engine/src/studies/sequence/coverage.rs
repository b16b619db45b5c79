//! How many exposures each sky position of a sequence gets: a grid of cells in Galactic (l, b) over the
//! region, each cell's centre put through every stare's four arrays (their WCS as assembled, distortion
//! included, at the catalogue place: the ≤ 0.2-px apparent-place shift is far below a cell) and counted
//! once per exposure of each stare whose photosensitive pixels it falls on (the gaps between the arrays
//! see nothing).

use super::plan::{Plan, exposure_config, galactic_to_icrs};
use crate::config::Config;
use rayon::prelude::*;

/// The coverage grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Coverage {
    /// Cell centres: l of column i = `l0_deg + (i + ½)·cell_deg`, b of row j likewise.
    pub l0_deg: f64,
    pub b0_deg: f64,
    pub cell_deg: f64,
    pub columns: usize,
    pub rows: usize,
    /// Exposures per cell, row-major (row 0 at the lowest b).
    pub counts: Vec<u32>,
}

impl Coverage {
    /// The cell's centre (l, b), degrees.
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.l0_deg + (i as f64 + 0.5) * self.cell_deg,
            self.b0_deg + (j as f64 + 0.5) * self.cell_deg,
        )
    }

    /// The fraction of cells with at least `n` exposures.
    pub fn fraction_at_least(&self, n: u32) -> f64 {
        self.counts.iter().filter(|c| **c >= n).count() as f64 / self.counts.len().max(1) as f64
    }
}

/// Count the exposures of `plan` over its region (the stares' extent plus half a field) in cells of
/// `cell_deg`.
pub fn coverage(plan: &Plan, base: &Config, cell_deg: f64) -> Result<Coverage, String> {
    if !(cell_deg > 1e-4 && cell_deg <= 1.0) {
        return Err(format!("coverage cell = {cell_deg}°: allowed (1e-4, 1]"));
    }
    let (l_lo, l_hi, b_lo, b_hi) = plan.extent_deg();
    let half = plan.field_deg / 2.0 * 1.05;
    let (l0, b0) = (l_lo - half, b_lo - half);
    let columns = (((l_hi + half - l0) / cell_deg).ceil() as usize).max(1);
    let rows = (((b_hi + half - b0) / cell_deg).ceil() as usize).max(1);
    if columns.saturating_mul(rows) > 4_000_000 {
        return Err(format!(
            "coverage cell = {cell_deg}°: {columns} × {rows} cells, at most 4e6 (a larger cell)"
        ));
    }
    // each stare's four arrays (through the configuration of its first exposure, at the catalogue place)
    let per_stare: Vec<u32> = plan
        .stares
        .iter()
        .map(|s| plan.exposures.iter().filter(|e| e.stare == s.index).count() as u32)
        .collect();
    let arrays: Vec<Vec<crate::sky::wcs::ArrayWcs>> = plan
        .stares
        .iter()
        .map(|s| {
            let e = plan
                .exposures
                .iter()
                .find(|e| e.stare == s.index)
                .ok_or_else(|| format!("stare {} has no exposure", s.index))?;
            let mut c = exposure_config(base, plan, e);
            c.observation.apparent_place = false;
            (0..4).map(|k| crate::sky::array_wcs(&c, k)).collect()
        })
        .collect::<Result<_, String>>()?;
    let n = base.instrument.detector_px as f64;
    let border = base.instrument.border_px() as f64;
    let on = |v: f64| v >= border - 0.5 && v < n - border - 0.5;
    let counts: Vec<u32> = (0..columns * rows)
        .into_par_iter()
        .map(|cell| {
            let (i, j) = (cell % columns, cell / columns);
            let l = l0 + (i as f64 + 0.5) * cell_deg;
            let b = b0 + (j as f64 + 0.5) * cell_deg;
            let (ra, dec) = galactic_to_icrs(l, b);
            arrays
                .iter()
                .zip(&per_stare)
                .filter(|(ws, _)| {
                    ws.iter()
                        .any(|w| w.sky_to_pixel(ra, dec).is_some_and(|(x, y)| on(x) && on(y)))
                })
                .map(|(_, m)| *m)
                .sum()
        })
        .collect();
    Ok(Coverage {
        l0_deg: l0,
        b0_deg: b0,
        cell_deg,
        columns,
        rows,
        counts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::studies::sequence::{plan::plan, spec::Spec};

    #[test]
    fn the_coverage_counts_what_the_geometry_says() {
        // one stare of one exposure: the covered area is the four arrays' photosensitive area (4 × 1952²
        // px of 472.1 mas), the centre (the cross-shaped gap) sees nothing
        let cfg = Config::default();
        let one = Spec {
            stares_l: 1,
            stares_b: 1,
            exposures_per_stare: 1,
            visits_utc: vec!["2031-03-21T00:00:00".into()],
            pointing_error_arcsec: 0.0,
            roll_error_arcsec: 0.0,
            ..Spec::default()
        };
        let p = plan(&one, &cfg).expect("plan");
        let cell = 0.004;
        let c = coverage(&p, &cfg, cell).expect("coverage");
        let covered = c.counts.iter().filter(|v| **v > 0).count() as f64 * cell * cell;
        let side = 1952.0 * cfg.instrument.plate_scale_mas() / 3.6e6;
        let expect = 4.0 * side * side;
        // cells along the edges are in or out whole: ± the perimeter × half a cell
        let tolerance = 16.0 * side * cell / 2.0;
        assert!(
            (covered - expect).abs() < tolerance,
            "{covered} vs {expect} ± {tolerance}"
        );
        let (ci, cj) = (c.columns / 2, c.rows / 2);
        assert_eq!(
            c.counts[cj * c.columns + ci],
            0,
            "the optical axis is in the gap"
        );
        // the default pattern: half-field steps cover the middle of the region up to four times per visit
        // and fill the single stare's cross-shaped gap
        let p = plan(&Spec::default(), &cfg).expect("plan");
        let c = coverage(&p, &cfg, 0.01).expect("coverage");
        let max = *c.counts.iter().max().expect("cells");
        assert_eq!(max, 4 * 26 * 2);
        assert!(c.fraction_at_least(1) > 0.5);
        // the second visit, shifted by the inter-array gap, covers the first one's gaps: inside the pattern
        // (|l|, |b| < 0.2°) no cell is left unseen; without the shift the gaps of both visits coincide
        let unseen = |c: &Coverage| {
            (0..c.rows)
                .flat_map(|j| (0..c.columns).map(move |i| (i, j)))
                .filter(|&(i, j)| {
                    let (l, b) = c.centre(i, j);
                    l.abs() < 0.2 && b.abs() < 0.2 && c.counts[j * c.columns + i] == 0
                })
                .count()
        };
        assert_eq!(unseen(&c), 0);
        let still = Spec {
            visit_dither_px: 0.0,
            ..Spec::default()
        };
        let c0 = coverage(&plan(&still, &cfg).expect("plan"), &cfg, 0.01).expect("coverage");
        assert!(unseen(&c0) > 20, "{}", unseen(&c0));
    }
}
