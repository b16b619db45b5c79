//! The files of `jsim score`: the measured catalogue and the truth it reads, and `score.csv` / `score.json`
//! it writes ([`crate::scoring`] does the matching and the statistics).
//!
//! * Both may carry an `array` column (the focal-plane arrays, 1 … 4): stars are then matched within
//!   their array only.
//! * **Measured catalogue**: a CSV with columns `x, y` (pixels, 0-based: integer values are pixel centres)
//!   — `catalogue.csv` of `jsim analyze`, or any tool's list. With a `flags` column (jsim's), rows with a
//!   rejection flag (`flags & REJECT`) count as detections (completeness) but not in the accuracy, as the
//!   analysis' own report does. Other columns are ignored.
//! * **Truth**: a CSV with `x, y` and a magnitude column (`mag`, `mag_hw` or `hw`, the first found), or a jsim
//!   image (FITS) whose TRUTH extension gives `x, y, mag_hw`. Both with one convention of pixels. In the
//!   header's frame ([`TruthFrame::Header`]) `x_header, y_header` take the place of `x, y`.

use super::IoError;
use super::csv::{self, Cell};
use crate::analysis::epsf::fit::flags;
use crate::scoring::{Measured, Score, TrueStar};
use std::path::Path;

/// Magnitude columns of a truth CSV, in the order looked for.
pub const MAG_COLUMNS: [&str; 3] = ["mag", "mag_hw", "hw"];

fn format_err(path: &Path, message: String) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        message,
    }
}

/// Read a measured catalogue (see the module's documentation).
pub fn read_measured(path: &Path) -> Result<Vec<Measured>, IoError> {
    let (h, rows) = csv::read(path)?;
    if !(h.iter().any(|c| c == "x") && h.iter().any(|c| c == "y")) {
        return Err(format_err(
            path,
            format!("columns {h:?}: a measured catalogue needs `x, y` (pixels)"),
        ));
    }
    let x = csv::column_f64(path, &h, &rows, "x")?;
    let y = csv::column_f64(path, &h, &rows, "y")?;
    let f = if h.iter().any(|c| c == "flags") {
        Some(csv::column_f64(path, &h, &rows, "flags")?)
    } else {
        None
    };
    let a = array_column(path, &h, &rows)?;
    Ok((0..x.len())
        .map(|k| Measured {
            x_px: x[k],
            y_px: y[k],
            array: a.as_ref().map(|a| a[k]).unwrap_or(0),
            usable: f
                .as_ref()
                .is_none_or(|f| (f[k] as u32) & flags::REJECT == 0),
        })
        .collect())
}

/// Which of a truth's positions a catalogue is scored against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthFrame {
    /// `x, y`: where the stars truly landed on the image.
    Image,
    /// `x_header, y_header`: each star's true sky place through the header's (design) WCS — the frame of a
    /// catalogue referenced to the reference catalogue (`plate-*@catalogue`), which jsim's simulated truth
    /// carries when the header is not the instrument as built.
    Header,
}

impl TruthFrame {
    /// The position columns read in this frame.
    pub fn columns(self) -> [&'static str; 2] {
        match self {
            TruthFrame::Image => ["x", "y"],
            TruthFrame::Header => super::exposure::TRUTH_IN_HEADER,
        }
    }
}

fn is_fits(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("fits") || e.eq_ignore_ascii_case("fit"))
}

/// Whether a truth list (CSV or an image's TRUTH extension) carries the header-frame columns.
pub fn truth_has_header_frame(path: &Path) -> bool {
    let [x, y] = TruthFrame::Header.columns();
    if is_fits(path) {
        super::fits::read_table(path, "TRUTH", &[x, y]).is_ok()
    } else {
        csv::read(path).is_ok_and(|(h, _)| h.iter().any(|c| c == x) && h.iter().any(|c| c == y))
    }
}

/// Read a truth list (see the module's documentation), its positions in `frame` (a truth without the
/// header-frame columns is a named error in [`TruthFrame::Header`]).
pub fn read_truth_list(path: &Path, frame: TruthFrame) -> Result<Vec<TrueStar>, IoError> {
    let [x, y] = frame.columns();
    if frame == TruthFrame::Header && !truth_has_header_frame(path) {
        return Err(format_err(
            path,
            format!(
                "no columns `{x}, {y}`: this truth has no header frame (jsim writes one only when the \
                 image's header is not the instrument as built; score in the image's frame)"
            ),
        ));
    }
    let (cols, arrays) = if is_fits(path) {
        let cols = super::fits::read_table(path, "TRUTH", &[x, y, "mag_hw"])?;
        let arrays = super::fits::read_table(path, "TRUTH", &["array"])
            .ok()
            .map(|a| a[0].iter().map(|v| *v as u32).collect::<Vec<u32>>());
        (cols, arrays)
    } else {
        let (h, rows) = csv::read(path)?;
        let mag = MAG_COLUMNS
            .iter()
            .find(|m| h.iter().any(|c| c == *m))
            .ok_or_else(|| {
                format_err(
                    path,
                    format!(
                        "columns {h:?}: a truth list needs `x, y` and a magnitude ({})",
                        MAG_COLUMNS.join(" or ")
                    ),
                )
            })?;
        let cols = [x, y, mag]
            .iter()
            .map(|c| csv::column_f64(path, &h, &rows, c))
            .collect::<Result<Vec<_>, _>>()?;
        (cols, array_column(path, &h, &rows)?)
    };
    Ok((0..cols[0].len())
        .map(|k| TrueStar {
            x_px: cols[0][k],
            y_px: cols[1][k],
            mag: cols[2][k],
            array: arrays.as_ref().map(|a| a[k]).unwrap_or(0),
        })
        .collect())
}

/// The optional `array` column (a focal-plane file's 1 … 4), checked to be a whole number ≥ 0.
fn array_column(
    path: &Path,
    h: &[String],
    rows: &[Vec<String>],
) -> Result<Option<Vec<u32>>, IoError> {
    if !h.iter().any(|c| c == "array") {
        return Ok(None);
    }
    let a = csv::column_f64(path, h, rows, "array")?;
    if let Some(bad) = a
        .iter()
        .find(|v| !(**v >= 0.0 && v.fract() == 0.0 && **v < 1e6))
    {
        return Err(format_err(
            path,
            format!("column array = {bad}: a whole number ≥ 0 (the array, 1 … 4)"),
        ));
    }
    Ok(Some(a.iter().map(|v| *v as u32).collect()))
}

/// Columns of `score.csv`: one row per magnitude bin, then the row `all`.
pub const SCORE_HEADER: [&str; 12] = [
    "bin",
    "mag_lo",
    "mag_hi",
    "n_true",
    "n_matched",
    "n_scored",
    "completeness",
    "accuracy_x_mas",
    "accuracy_y_mas",
    "accuracy_mas",
    "bias_x_mas",
    "bias_y_mas",
];

/// Rows of `score.csv` (an absent accuracy is an empty cell).
pub fn score_rows(s: &Score) -> Vec<Vec<Cell>> {
    let cell = |v: f64| {
        if v.is_finite() {
            Cell::F(v)
        } else {
            Cell::S(String::new())
        }
    };
    s.bins
        .iter()
        .enumerate()
        .map(|(k, b)| (k.to_string(), b))
        .chain(std::iter::once(("all".to_string(), &s.all)))
        .map(|(name, b)| {
            vec![
                Cell::S(name),
                cell(b.mag_lo),
                cell(b.mag_hi),
                Cell::I(b.n_true as i64),
                Cell::I(b.n_matched as i64),
                Cell::I(b.n_scored as i64),
                cell(b.completeness),
                cell(b.accuracy_x_mas),
                cell(b.accuracy_y_mas),
                cell(b.accuracy_mas),
                cell(b.bias_x_mas),
                cell(b.bias_y_mas),
            ]
        })
        .collect()
}

/// Write `score.csv` and `score.json` (the bins, the totals, the false detections, the offset and the
/// options; the pairs are left out) into `dir`.
pub fn write_score(dir: &Path, s: &Score, measured: &Path, truth: &Path) -> Result<(), IoError> {
    csv::write(
        &dir.join(crate::io::products::files::SCORE_CSV),
        &SCORE_HEADER,
        &score_rows(s),
    )?;
    let json = serde_json::json!({
        "measured": measured.display().to_string(),
        "truth": truth.display().to_string(),
        "n_measured": s.n_measured,
        "false_detections": s.false_detections,
        "offset_x_px": s.offset_x_px,
        "offset_y_px": s.offset_y_px,
        "options": s.options,
        "all": s.all,
        "bins": s.bins,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| {
        format_err(
            &dir.join(crate::io::products::files::SCORE_JSON),
            e.to_string(),
        )
    })?;
    super::write_atomic(
        &dir.join(crate::io::products::files::SCORE_JSON),
        text.as_bytes(),
    )
}
