//! ECSV tables (astropy's Enhanced CSV, version 1.0): a YAML header naming each column's type and unit and
//! the table's metadata, then space-separated rows. `astropy.table.Table.read(path)` reads them with units.

use super::{IoError, write_atomic};
use std::fmt::Write as _;
use std::path::Path;

/// A float column: its name, unit (`""` for none), description and values.
pub struct Column<'a> {
    pub name: &'a str,
    pub unit: &'a str,
    pub description: &'a str,
    pub values: &'a [f64],
}

/// Render columns of equal length and `meta` (key, value: scalars written as YAML strings or numbers) as ECSV
/// text. NaN is written as `nan`, which astropy reads as a float NaN.
pub fn render(columns: &[Column<'_>], meta: &[(&str, String)]) -> String {
    let mut s = String::from("# %ECSV 1.0\n# ---\n# datatype:\n");
    for c in columns {
        let _ = write!(s, "# - {{name: {}, datatype: float64", c.name);
        if !c.unit.is_empty() {
            let _ = write!(s, ", unit: {}", c.unit);
        }
        if !c.description.is_empty() {
            let _ = write!(s, ", description: '{}'", c.description.replace('\'', "''"));
        }
        s.push_str("}\n");
    }
    if !meta.is_empty() {
        s.push_str("# meta:\n");
        for (k, v) in meta {
            let _ = writeln!(s, "#   {k}: '{}'", v.replace('\'', "''"));
        }
    }
    s.push_str("# schema: astropy-2.0\n");
    let names: Vec<&str> = columns.iter().map(|c| c.name).collect();
    s.push_str(&names.join(" "));
    s.push('\n');
    let rows = columns.iter().map(|c| c.values.len()).min().unwrap_or(0);
    for r in 0..rows {
        let row: Vec<String> = columns
            .iter()
            .map(|c| {
                let v = c.values[r];
                if v.is_finite() {
                    format!("{v}")
                } else {
                    "nan".to_string()
                }
            })
            .collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    s
}

/// Write an ECSV table atomically.
pub fn write(path: &Path, columns: &[Column<'_>], meta: &[(&str, String)]) -> Result<(), IoError> {
    write_atomic(path, render(columns, meta).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_names_every_column_and_rows_follow() {
        let t = [0.0, 0.5];
        let f = [1.0, f64::NAN];
        let s = render(
            &[
                Column {
                    name: "time",
                    unit: "d",
                    description: "mid-plate",
                    values: &t,
                },
                Column {
                    name: "flux",
                    unit: "",
                    description: "",
                    values: &f,
                },
            ],
            &[("seed", "7".into())],
        );
        assert!(s.starts_with("# %ECSV 1.0\n# ---\n"));
        assert!(
            s.contains("# - {name: time, datatype: float64, unit: d, description: 'mid-plate'}\n")
        );
        assert!(s.contains("#   seed: '7'\n"));
        assert!(s.ends_with("time flux\n0 1\n0.5 nan\n"));
    }
}
