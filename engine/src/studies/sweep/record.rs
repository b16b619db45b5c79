//! What a sweep directory records: `sweep.json` ([`Record`]), the columns of the unit CSVs, their line
//! format (RFC 4180 quoting) and the per-row checks that let a damaged file be salvaged row by row.

use super::error::SweepError;
use crate::digest;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag of `sweep.json`.
pub const FORMAT: &str = "jsim-sweep/1";

/// Leading columns of the unit CSVs (before the grid parameters).
pub const HEAD_COLUMNS: [&str; 3] = ["unit", "point", "exposure"];
/// Result columns (after the grid parameters), deterministic.
pub const RESULT_COLUMNS: [&str; 13] = [
    "countermeasure",
    "status",
    "accuracy_mas",
    "accuracy_x_mas",
    "accuracy_y_mas",
    "bias_x_mas",
    "bias_y_mas",
    "crlb_mas",
    "predicted_mas",
    "n_used",
    "ace_sigma_mas",
    "ace_drift_mas",
    "seed",
];
/// Timing columns: always last (before `check` in shard files), excluded from reproducibility comparisons.
pub const TIMING_COLUMNS: [&str; 4] = ["simulate_s", "analyse_s", "predict_s", "unit_s"];

/// A swept field in `sweep.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordParam {
    pub field: String,
    pub values: Vec<String>,
}

/// Telemetry settings in `sweep.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordTelemetry {
    pub noise_mas: f64,
    pub rate_hz: f64,
    pub latency_s: f64,
    /// The correlated error (absent in sweeps recorded before it existed: none).
    #[serde(default)]
    pub correlated_mas: f64,
    #[serde(default = "default_correlation_time_s")]
    pub correlation_time_s: f64,
    pub reference_error_mas: f64,
}

fn one() -> usize {
    1
}

fn default_correlation_time_s() -> f64 {
    crate::analysis::countermeasures::TelemetryQuality::IDEAL.correlation_time_s
}

/// What `DIR/sweep.json` holds: everything `merge` and `report` need.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub format: String,
    pub hash: String,
    pub name: String,
    pub seed: u64,
    pub exposures: usize,
    /// Exposures per stare, one unit (absent in sweeps recorded before stares: 1).
    #[serde(default = "one")]
    pub stare_exposures: usize,
    pub points: usize,
    pub countermeasures: Vec<String>,
    pub threshold_mas: f64,
    pub common_random_numbers: bool,
    pub grid: Vec<RecordParam>,
    pub point_values: Vec<Vec<String>>,
    pub telemetry: RecordTelemetry,
    pub base_config: String,
    pub engine_version: String,
}

impl Record {
    pub fn n_units(&self) -> usize {
        self.points * (self.exposures / self.stare_exposures.max(1))
    }

    /// Column names of the unit CSVs (`check` last when `with_check`).
    pub fn header(&self, with_check: bool) -> Vec<String> {
        let mut h: Vec<String> = HEAD_COLUMNS.iter().map(|s| s.to_string()).collect();
        h.extend(self.grid.iter().map(|p| p.field.clone()));
        h.extend(RESULT_COLUMNS.iter().map(|s| s.to_string()));
        h.extend(TIMING_COLUMNS.iter().map(|s| s.to_string()));
        if with_check {
            h.push("check".into());
        }
        h
    }

    pub(super) fn col(&self, name: &str) -> usize {
        self.header(false)
            .iter()
            .position(|h| h == name)
            .unwrap_or(usize::MAX)
    }

    /// Index of the first timing column (everything before it is deterministic).
    pub fn first_timing_column(&self) -> usize {
        HEAD_COLUMNS.len() + self.grid.len() + RESULT_COLUMNS.len()
    }
}

/// Read `DIR/sweep.json`.
pub fn read_record(dir: &Path) -> Result<Record, SweepError> {
    let path = dir.join(crate::io::products::files::SWEEP_JSON);
    let text = std::fs::read_to_string(&path).map_err(|e| SweepError::NotASweep {
        dir: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let r: Record = serde_json::from_str(&text).map_err(|e| SweepError::NotASweep {
        dir: dir.to_path_buf(),
        message: format!("{}: {e}", path.display()),
    })?;
    if r.format != FORMAT {
        return Err(SweepError::NotASweep {
            dir: dir.to_path_buf(),
            message: format!("format `{}`, expected `{FORMAT}`", r.format),
        });
    }
    if r.points == 0 || r.point_values.len() != r.points || r.countermeasures.is_empty() {
        return Err(SweepError::NotASweep {
            dir: dir.to_path_buf(),
            message: format!("{} is inconsistent", path.display()),
        });
    }
    Ok(r)
}

pub(super) fn to_json(v: &impl Serialize) -> String {
    let mut s =
        serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
    s.push('\n');
    s
}

/// A float as written in the CSVs: the shortest text that reads back to the same value (`1e-17`, `3.25`,
/// `NaN`, `inf`).
pub(super) fn float_cell(v: f64) -> String {
    format!("{v:?}")
}

fn quote(s: &str) -> String {
    if s.contains(',') || s.contains('"') || s.contains('\n') || s.contains('\r') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// One CSV line from cells (RFC 4180 quoting).
pub fn render_line(cells: &[String]) -> String {
    cells.iter().map(|c| quote(c)).collect::<Vec<_>>().join(",")
}

/// Split one CSV line into cells (RFC 4180 quotes); `None` for a malformed line.
pub fn parse_line(line: &str) -> Option<Vec<String>> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut chars = line.chars().peekable();
    let mut quoted = false;
    let mut at_start = true;
    while let Some(c) = chars.next() {
        if quoted {
            if c == '"' {
                if chars.peek() == Some(&'"') {
                    cur.push('"');
                    chars.next();
                } else {
                    quoted = false;
                    match chars.peek() {
                        None | Some(',') => {}
                        Some(_) => return None,
                    }
                }
            } else {
                cur.push(c);
            }
        } else if c == ',' {
            out.push(std::mem::take(&mut cur));
            at_start = true;
            continue;
        } else if c == '"' && at_start {
            quoted = true;
        } else if c == '"' {
            return None;
        } else {
            cur.push(c);
        }
        at_start = false;
    }
    if quoted {
        return None;
    }
    out.push(cur);
    Some(out)
}

/// The `check` cell of a shard row: a short digest of the sweep hash and the row's text.
pub(super) fn row_check(hash: &str, line: &str) -> String {
    digest::sha256_short_hex(format!("{hash}\n{line}").as_bytes())
}

/// A CSV's text with the timing columns (and `check`) removed: what must be identical between runs.
pub fn without_timing(csv_text: &str) -> String {
    let mut lines = csv_text.lines();
    let Some(header) = lines.next() else {
        return String::new();
    };
    let h = parse_line(header).unwrap_or_default();
    let cut = h
        .iter()
        .position(|c| c == TIMING_COLUMNS[0])
        .unwrap_or(h.len());
    let mut out = render_line(&h[..cut]);
    out.push('\n');
    for l in lines {
        let cells = parse_line(l).unwrap_or_else(|| vec![l.to_string()]);
        out.push_str(&render_line(&cells[..cut.min(cells.len())]));
        out.push('\n');
    }
    out
}

/// The rows (cells, without `check`) of one unit, in countermeasure order.
pub type UnitRows = Vec<Vec<String>>;

pub(super) fn unit_rows_valid(rec: &Record, unit: usize, rows: &UnitRows) -> bool {
    let ncol = rec.header(false).len();
    let k = rec.stare_exposures.max(1);
    let (p, first) = (unit % rec.points, (unit / rec.points) * k);
    let cm_col = HEAD_COLUMNS.len() + rec.grid.len();
    let n_cm = rec.countermeasures.len();
    rows.len() == k * n_cm
        && rows.iter().enumerate().all(|(i, r)| {
            r.len() == ncol
                && r[0] == unit.to_string()
                && r[1] == p.to_string()
                && r[2] == (first + i / n_cm).to_string()
                && r[3..cm_col] == rec.point_values[p][..]
                && r[cm_col] == rec.countermeasures[i % n_cm]
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_lines_round_trip_with_quotes() {
        let cells: Vec<String> = ["a", "b,c", "say \"hi\"", "", "[1, 2]"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let line = render_line(&cells);
        assert_eq!(parse_line(&line), Some(cells));
        assert_eq!(parse_line("a,\"b"), None);
    }

    #[test]
    fn without_timing_drops_trailing_columns() {
        let t = "unit,x,simulate_s,unit_s\n0,1,0.5,0.7\n";
        assert_eq!(without_timing(t), "unit,x\n0,1\n");
    }
}
