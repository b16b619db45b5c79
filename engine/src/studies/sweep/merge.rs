//! `jsim merge`: every shard file verified and combined into `merged.csv`, sorted by unit index.

use super::error::SweepError;
use super::record::{UnitRows, read_record, render_line, to_json};
use super::shard::{list_shards, read_shard};
use crate::digest;
use crate::io;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Options of [`merge`].
#[derive(Debug, Clone, Default)]
pub struct MergeOptions {
    /// Write `merged.csv` even when units are missing (they are still listed).
    pub allow_missing: bool,
}

/// The outcome of [`merge`].
#[derive(Debug, Clone)]
pub struct MergeSummary {
    pub path: PathBuf,
    pub units: usize,
    pub rows: usize,
    pub files: usize,
    /// Units recorded in more than one shard file (identical apart from timing; one kept).
    pub duplicates: Vec<usize>,
    pub missing: Vec<usize>,
    /// Units beyond `points × exposures` (from a run with more exposures), left out.
    pub extra: usize,
    /// Damaged shard files and what was kept of them.
    pub notes: Vec<String>,
}

/// Unit list as ranges with their (point, exposure): `3 (p1 e1), 5-7, …`.
pub fn describe_units(units: &[usize], points: usize, max: usize) -> String {
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for &u in units {
        match ranges.last_mut() {
            Some(r) if r.1 + 1 == u => r.1 = u,
            _ => ranges.push((u, u)),
        }
    }
    let mut parts: Vec<String> = ranges
        .iter()
        .take(max)
        .map(|&(a, b)| {
            if a == b {
                format!("unit {a} (point {}, exposure {})", a % points, a / points)
            } else {
                format!("units {a}-{b}")
            }
        })
        .collect();
    if ranges.len() > max {
        parts.push(format!("… ({} more ranges)", ranges.len() - max));
    }
    parts.join(", ")
}

/// Combine the shard files of `dir` into `dir/merged.csv` (sorted by unit index, without `check`).
pub fn merge(dir: &Path, opts: &MergeOptions) -> Result<MergeSummary, SweepError> {
    let rec = read_record(dir)?;
    let shards = list_shards(dir)?;
    if shards.is_empty() {
        return Err(SweepError::Invalid(format!(
            "no shard files in {}: run `jsim sweep` first",
            dir.join("shards").display()
        )));
    }
    let cut = rec.first_timing_column();
    let mut all: BTreeMap<usize, (UnitRows, PathBuf)> = BTreeMap::new();
    let mut duplicates = Vec::new();
    let mut notes = Vec::new();
    let mut files = 0;
    for s in shards {
        let sf = read_shard(&rec, dir, s)?;
        files += 1;
        if let Some(n) = sf.note {
            notes.push(n);
        }
        for (u, rows) in sf.units {
            match all.get(&u) {
                Some((prev, from)) => {
                    let same = prev.iter().zip(&rows).all(|(a, b)| a[..cut] == b[..cut]);
                    if !same {
                        return Err(SweepError::Mixed {
                            dir: dir.to_path_buf(),
                            message: format!(
                                "unit {u} differs between {} and {} (not a rerun of the same sweep, or a different engine build/backend)",
                                from.display(),
                                sf.csv.display()
                            ),
                        });
                    }
                    duplicates.push(u);
                }
                None => {
                    all.insert(u, (rows, sf.csv.clone()));
                }
            }
        }
    }
    duplicates.sort_unstable();
    duplicates.dedup();
    let total = rec.n_units();
    let missing: Vec<usize> = (0..total).filter(|u| !all.contains_key(u)).collect();
    let extra = all.range(total..).count();
    if !missing.is_empty() && !opts.allow_missing {
        return Err(SweepError::Missing {
            missing: missing.len(),
            total,
            list: describe_units(&missing, rec.points, 20),
            units: missing,
        });
    }
    let mut text = render_line(&rec.header(false));
    text.push('\n');
    let mut rows = 0;
    let mut units = 0;
    for (_, (rs, _)) in all.range(..total) {
        units += 1;
        for r in rs {
            text.push_str(&render_line(r));
            text.push('\n');
            rows += 1;
        }
    }
    let path = dir.join(crate::io::products::files::MERGED_CSV);
    io::write_atomic(&path, text.as_bytes())?;
    let meta = serde_json::json!({
        "format": "jsim-sweep-merged/1",
        "sweep_hash": rec.hash,
        "units": units,
        "rows": rows,
        "missing_units": missing.len(),
        "duplicate_units": duplicates.len(),
        "sha256": digest::sha256_hex(text.as_bytes()),
    });
    io::write_atomic(
        &dir.join(crate::io::products::files::MERGED_JSON),
        to_json(&meta).as_bytes(),
    )?;
    Ok(MergeSummary {
        path,
        units,
        rows,
        files,
        duplicates,
        missing,
        extra,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_ranges_are_compact() {
        assert_eq!(
            describe_units(&[1, 2, 3, 7], 2, 10),
            "units 1-3, unit 7 (point 1, exposure 3)"
        );
    }
}
