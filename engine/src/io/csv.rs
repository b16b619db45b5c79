//! Plain CSV tables (readable by pandas/astropy): a header line, then rows, written atomically.

use super::{IoError, write_atomic};
use std::fmt::Write as _;
use std::path::Path;

/// A value of a CSV cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    F(f64),
    I(i64),
    S(String),
}

impl std::fmt::Display for Cell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cell::F(v) => write!(f, "{v}"),
            Cell::I(v) => write!(f, "{v}"),
            Cell::S(s) => {
                if s.contains(',') || s.contains('"') {
                    write!(f, "\"{}\"", s.replace('"', "\"\""))
                } else {
                    f.write_str(s)
                }
            }
        }
    }
}

/// Render a table as CSV text.
pub fn render(header: &[&str], rows: &[Vec<Cell>]) -> String {
    let mut s = header.join(",");
    s.push('\n');
    for r in rows {
        let line: Vec<String> = r.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(s, "{}", line.join(","));
    }
    s
}

/// Write a CSV table atomically.
pub fn write(path: &Path, header: &[&str], rows: &[Vec<Cell>]) -> Result<(), IoError> {
    write_atomic(path, render(header, rows).as_bytes())
}

/// Read a CSV with a header into (header, rows of strings) ([`crate::formats::csv`]: quoted cells, `#`
/// comments and blank lines as RFC 4180 and the `csv` crate have them).
pub fn read(path: &Path) -> Result<(Vec<String>, Vec<Vec<String>>), IoError> {
    let records = crate::formats::csv::read(path).map_err(|e| match e {
        crate::formats::csv::CsvError::Io { source, .. } => IoError::io(path, source),
        e => IoError::Format {
            path: path.to_path_buf(),
            message: e.to_string(),
        },
    })?;
    let mut rows = records.into_iter().map(|r| r.cells);
    let header = rows.next().ok_or_else(|| IoError::Format {
        path: path.to_path_buf(),
        message: "empty file".into(),
    })?;
    Ok((header, rows.collect()))
}

/// Column `name` of a table read with [`read`], parsed as f64 where `inf` and `NaN` are values too (a
/// bound a fit could not give).
pub fn column_f64_any(
    path: &Path,
    header: &[String],
    rows: &[Vec<String>],
    name: &str,
) -> Result<Vec<f64>, IoError> {
    let i = header
        .iter()
        .position(|h| h == name)
        .ok_or_else(|| IoError::Format {
            path: path.to_path_buf(),
            message: format!("no column `{name}`"),
        })?;
    rows.iter()
        .enumerate()
        .map(|(k, r)| {
            r.get(i)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .ok_or_else(|| IoError::Format {
                    path: path.to_path_buf(),
                    message: format!("row {}: column `{name}` is not a number", k + 2),
                })
        })
        .collect()
}

/// Column `name` of a table read with [`read`], parsed as f64 (finite values only).
pub fn column_f64(
    path: &Path,
    header: &[String],
    rows: &[Vec<String>],
    name: &str,
) -> Result<Vec<f64>, IoError> {
    let v = column_f64_any(path, header, rows, name)?;
    match v.iter().position(|x| !x.is_finite()) {
        Some(k) => Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("row {}: column `{name}` is not a finite number", k + 2),
        }),
        None => Ok(v),
    }
}
