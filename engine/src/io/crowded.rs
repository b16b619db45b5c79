//! The products of the crowded-field study (`jsim crowded`):
//!
//! * `crowded_bins.csv` — per ACE case, countermeasure and bin of true Hw: truth stars, found,
//!   completeness, fractions flagged blended and saturated, and per class (isolated, crowded, merged) the
//!   number of stars, accuracy and median Cramér–Rao bound (mas);
//! * `crowded_arrays.csv` — per case and array: detections (first pass, residual, matched to no truth
//!   star), ePSF stars and
//!   iterations, the fallback if any, groups and the largest, analysis time, and the reference catalogue's
//!   registration when its stars were forced (pairs, residual rms, the map's predicted and true error, px);
//! * `stars_<case>.csv` — every reported star of the case without countermeasure: array, position, flux,
//!   bound, flags (bits of `analysis::epsf::fit::flags`), class, and where matched the truth's id, Hw and
//!   fitted − true (mas);
//! * `accuracy_vs_mag.png` — isolated-star accuracy against Hw per case and countermeasure, with the bound
//!   and the 4-mas line;
//! * `vectors_<case>_<countermeasure>.png` — the four arrays in their sky layout (focal-plane axes), an
//!   arrow per cell ([`ArrayAnalysis::binned_vectors`]).

use super::IoError;
use super::csv::{self, Cell};
use super::plot::{self, Scale, Series};
use crate::scoring::crowded::{ClassStats, MagBin};
use crate::scoring::focal_plane::{ArrayAnalysis, FocalPlaneAnalysis, VECTOR_CELLS};
use crate::sky::focal_plane::FocalPlane;
use std::path::Path;

/// Columns of `crowded_bins.csv`.
pub const BINS_HEADER: [&str; 22] = [
    "case",
    "countermeasure",
    "hw_lo",
    "hw_hi",
    "n_true",
    "n_found",
    "completeness",
    "frac_blended",
    "frac_saturated",
    "isolated_n",
    "isolated_mas",
    "isolated_crlb_mas",
    "isolated_over_crlb",
    "crowded_n",
    "crowded_mas",
    "crowded_crlb_mas",
    "merged_n",
    "merged_mas",
    "merged_crlb_mas",
    "isolated_undetected_mas",
    "isolated_undetected_faint_mas",
    "isolated_predicted_mas",
];

fn class_cells(c: &ClassStats, ratio: bool) -> Vec<Cell> {
    let mut v = vec![
        Cell::I(c.n as i64),
        Cell::F(c.accuracy_mas),
        Cell::F(c.crlb_mas),
    ];
    if ratio {
        v.push(Cell::F(c.ratio()));
    }
    v
}

/// The rows of one case and countermeasure.
pub fn bin_rows(case: &str, countermeasure: &str, bins: &[MagBin]) -> Vec<Vec<Cell>> {
    bins.iter()
        .map(|b| {
            let mut r = vec![
                Cell::S(case.into()),
                Cell::S(countermeasure.into()),
                Cell::F(b.hw_lo),
                Cell::F(b.hw_hi),
                Cell::I(b.n_true as i64),
                Cell::I(b.n_found as i64),
                Cell::F(b.completeness),
                Cell::F(b.frac_blended),
                Cell::F(b.frac_saturated),
            ];
            r.extend(class_cells(&b.isolated, true));
            r.extend(class_cells(&b.crowded, false));
            r.extend(class_cells(&b.merged, false));
            r.extend([
                Cell::F(b.isolated_undetected_mas),
                Cell::F(b.isolated_undetected_faint_mas),
                Cell::F(b.isolated_predicted_mas()),
            ]);
            r
        })
        .collect()
}

/// Columns of `crowded_arrays.csv`.
pub const ARRAYS_HEADER: [&str; 15] = [
    "case",
    "array",
    "n_first",
    "n_residual",
    "n_unmatched",
    "epsf_stars",
    "epsf_iterations",
    "n_groups",
    "largest_group",
    "analyse_s",
    "fallback",
    "registration_pairs",
    "registration_rms_px",
    "registration_predicted_px",
    "registration_error_px",
];

/// The rows of one case's arrays.
pub fn array_rows(case: &str, arrays: &[ArrayAnalysis]) -> Vec<Vec<Cell>> {
    arrays
        .iter()
        .map(|a| {
            let s = &a.summary;
            vec![
                Cell::S(case.into()),
                Cell::I(a.index as i64 + 1),
                Cell::I(s.n_first as i64),
                Cell::I(s.n_residual as i64),
                Cell::I(a.n_unmatched as i64),
                Cell::I(s.epsf_stars as i64),
                Cell::I(s.epsf_iterations as i64),
                Cell::I(s.n_groups as i64),
                Cell::I(s.largest_group as i64),
                Cell::F(s.analyse_s),
                Cell::S(s.fallback.clone()),
                Cell::I(s.registration.map_or(0, |r| r.pairs) as i64),
                Cell::F(s.registration.map_or(f64::NAN, |r| r.rms_px)),
                Cell::F(s.registration.map_or(f64::NAN, |r| r.predicted_error_px())),
                Cell::F(a.registration_error_px),
            ]
        })
        .collect()
}

/// Columns of `stars_<case>.csv`.
pub const STARS_HEADER: [&str; 12] = [
    "array",
    "x_px",
    "y_px",
    "flux_e",
    "crlb_x_px",
    "crlb_y_px",
    "flags",
    "class",
    "truth_id",
    "hw",
    "dx_mas",
    "dy_mas",
];

/// One row per reported star of every array.
pub fn star_rows(arrays: &[ArrayAnalysis], scale_mas: f64) -> Vec<Vec<Cell>> {
    use crate::scoring::crowded as report;
    let mut rows = Vec::new();
    for a in arrays {
        let merged = report::merged(&a.stars, &a.truth);
        for (s, m) in a.stars.iter().zip(merged) {
            let t = s.truth.map(|k| &a.truth[k]);
            let class = serde_json::to_value(report::class(s, m))
                .ok()
                .and_then(|v| v.as_str().map(String::from))
                .unwrap_or_default();
            rows.push(vec![
                Cell::I(a.index as i64 + 1),
                Cell::F(s.x),
                Cell::F(s.y),
                Cell::F(s.flux_e),
                Cell::F(s.crlb_x_px),
                Cell::F(s.crlb_y_px),
                Cell::I(s.flags as i64),
                Cell::S(class),
                Cell::I(t.map(|t| t.id as i64).unwrap_or(-1)),
                Cell::F(t.map(|t| t.mag_hw).unwrap_or(f64::NAN)),
                Cell::F(s.dx_px * scale_mas),
                Cell::F(s.dy_px * scale_mas),
            ]);
        }
    }
    rows
}

/// Write a table.
pub fn write_table(path: &Path, header: &[&str], rows: &[Vec<Cell>]) -> Result<(), IoError> {
    csv::write(path, header, rows)
}

/// Isolated-star accuracy against Hw, each `(label, bins)` a curve; the first one's bound dashed-in as a
/// curve of its own; the 4-mas line.
pub fn plot_accuracy(path: &Path, runs: &[(String, &[MagBin])]) -> Result<(), IoError> {
    let centre = |b: &MagBin| 0.5 * (b.hw_lo + b.hw_hi);
    let mut series: Vec<Series> = runs
        .iter()
        .map(|(label, bins)| Series {
            label: format!("{label}: isolated"),
            x: bins.iter().map(centre).collect(),
            y: bins.iter().map(|b| b.isolated.accuracy_mas).collect(),
            yerr: None,
            yerr_below: None,
        })
        .collect();
    if let Some((label, bins)) = runs.first() {
        series.push(Series {
            label: format!("Cramér–Rao bound ({label})"),
            x: bins.iter().map(centre).collect(),
            y: bins.iter().map(|b| b.isolated.crlb_mas).collect(),
            yerr: None,
            yerr_below: None,
        });
    }
    plot::line_plot(
        path,
        "One crowded exposure: accuracy of isolated stars against magnitude",
        "Hw [mag]",
        "position accuracy per axis [mas]",
        &series,
        &[(4.0, "4 mas".into())],
        Scale::Linear,
        Scale::Log,
    )?;
    Ok(())
}

/// The vector map of the four arrays in their sky layout.
pub fn plot_vectors(
    path: &Path,
    title: &str,
    plane: &FocalPlane,
    run: &FocalPlaneAnalysis,
    scale_mas: f64,
) -> Result<(), IoError> {
    let n = plane.array_px as f64;
    // the plot's axes start at 0: shift the focal plane's lower-left corner there
    let origin = n + plane.gap_px / 2.0;
    let sets: Vec<(String, Vec<(f64, f64, f64, f64)>)> = run
        .arrays
        .iter()
        .map(|a| {
            let v = a
                .binned_vectors(plane, scale_mas)
                .into_iter()
                .map(|(x, y, dx, dy)| (x + origin, y + origin, dx, dy))
                .collect();
            (format!("array {}", a.index + 1), v)
        })
        .collect();
    plot::vector_map_on_axes(
        path,
        title,
        &sets,
        2.0 * origin,
        (f64::NAN, 0.75 * n / VECTOR_CELLS as f64),
        (
            "focal-plane x [px], from the corner (east to the left at PA 0)",
            "focal-plane y [px] (north up at PA 0)",
        ),
    )?;
    Ok(())
}
