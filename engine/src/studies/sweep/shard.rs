//! Shards: which units a process runs (`--shard i/N`), the shard CSV files and their sidecars, reading them
//! back with verification, and salvaging the verified units of a damaged file.

use super::error::{SweepError, io_err};
use super::record::{
    Record, UnitRows, parse_line, render_line, row_check, to_json, unit_rows_valid,
};
use crate::digest;
use crate::io;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Format tag of a shard sidecar.
pub const SHARD_FORMAT: &str = "jsim-sweep-shard/1";

/// What a unit CSV held: verified units, and what was wrong with the rest.
#[derive(Debug, Default)]
pub struct ParsedRows {
    pub units: BTreeMap<usize, UnitRows>,
    /// Lines (after the header) that were dropped: malformed, truncated, failed checks, incomplete units.
    pub dropped_lines: usize,
    pub header_ok: bool,
}

/// Parse a shard CSV, keeping only complete units whose rows all pass their checks.
pub fn parse_shard_text(rec: &Record, text: &str) -> ParsedRows {
    let mut out = ParsedRows::default();
    let header = render_line(&rec.header(true));
    let complete = text.ends_with('\n');
    let mut lines: Vec<&str> = text.split('\n').collect();
    if complete {
        lines.pop(); // the empty piece after the final newline
    }
    let n_lines = lines.len();
    let mut it = lines.into_iter().enumerate();
    match it.next() {
        Some((_, h)) if h == header && (n_lines > 1 || complete) => out.header_ok = true,
        Some(_) => {
            out.dropped_lines = n_lines.saturating_sub(1);
            return out;
        }
        None => return out,
    }
    let ncol = rec.header(true).len();
    let mut pending: BTreeMap<usize, UnitRows> = BTreeMap::new();
    let mut bad_units: BTreeSet<usize> = BTreeSet::new();
    let mut rows_seen: BTreeMap<usize, usize> = BTreeMap::new();
    for (k, line) in it {
        let last_truncated = !complete && k + 1 == n_lines;
        let cells = match parse_line(line) {
            Some(c) if c.len() == ncol && !last_truncated => c,
            _ => {
                out.dropped_lines += 1;
                // a damaged line may belong to a unit: that unit is incomplete anyway
                if let Some(u) = line.split(',').next().and_then(|s| s.parse::<usize>().ok()) {
                    bad_units.insert(u);
                }
                continue;
            }
        };
        let (body, check) = cells.split_at(ncol - 1);
        let line_text = render_line(body);
        let Ok(unit) = body[0].parse::<usize>() else {
            out.dropped_lines += 1;
            continue;
        };
        *rows_seen.entry(unit).or_default() += 1;
        if row_check(&rec.hash, &line_text) != check[0] {
            bad_units.insert(unit);
            continue;
        }
        pending.entry(unit).or_default().push(body.to_vec());
    }
    for (u, rows) in pending {
        if !bad_units.contains(&u) && unit_rows_valid(rec, u, &rows) {
            out.units.insert(u, rows);
        }
    }
    let kept: usize = out.units.values().map(|r| r.len()).sum();
    let seen: usize = rows_seen.values().sum();
    out.dropped_lines += seen - kept.min(seen);
    out
}

/// A shard sidecar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    pub format: String,
    pub sweep_hash: String,
    pub shard: usize,
    pub shards: usize,
    pub rows: usize,
    pub units: usize,
    pub sha256: String,
    pub engine_version: String,
}

/// A shard spec: shard `index` of `count` (0-based). Unit `u` belongs to shard `u mod count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Everything in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parse `i/N`.
    pub fn parse(spec: &str) -> Result<Shard, SweepError> {
        let bad = |message: &str| SweepError::Shard {
            spec: spec.to_string(),
            message: message.to_string(),
        };
        let (i, n) = spec
            .split_once('/')
            .ok_or_else(|| bad("expected i/N, e.g. 0/4 (shard i of N, numbered from 0)"))?;
        let n: usize = n
            .trim()
            .parse()
            .map_err(|_| bad("N must be a whole number ≥ 1"))?;
        let i: usize = i
            .trim()
            .parse()
            .map_err(|_| bad("i must be a whole number ≥ 0"))?;
        Shard::new(i, n).map_err(|e| match e {
            SweepError::Shard { message, .. } => bad(&message),
            other => other,
        })
    }

    pub fn new(index: usize, count: usize) -> Result<Shard, SweepError> {
        let spec = format!("{index}/{count}");
        if count == 0 {
            return Err(SweepError::Shard {
                spec,
                message: "N = 0: the number of shards must be ≥ 1".into(),
            });
        }
        if index >= count {
            return Err(SweepError::Shard {
                spec,
                message: format!(
                    "i = {index} is out of range: shards are numbered 0..{count} (0 ≤ i < N)"
                ),
            });
        }
        Ok(Shard { index, count })
    }

    pub fn contains(&self, unit: usize) -> bool {
        unit % self.count == self.index
    }

    /// `shard-IIII-of-NNNN`.
    pub fn stem(&self) -> String {
        format!("shard-{:04}-of-{:04}", self.index, self.count)
    }

    /// Parse a shard CSV file name back.
    pub fn from_file_name(name: &str) -> Option<Shard> {
        let rest = name.strip_prefix("shard-")?.strip_suffix(".csv")?;
        let (i, n) = rest.split_once("-of-")?;
        if i.is_empty()
            || n.is_empty()
            || !i.bytes().all(|b| b.is_ascii_digit())
            || !n.bytes().all(|b| b.is_ascii_digit())
        {
            return None;
        }
        let s = Shard::new(i.parse().ok()?, n.parse().ok()?).ok()?;
        (s.stem() + ".csv" == name).then_some(s)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Paths of shard `s`'s CSV and sidecar in `dir`.
pub fn shard_paths(dir: &Path, s: Shard) -> (PathBuf, PathBuf) {
    let d = dir.join("shards");
    (
        d.join(format!("{}.csv", s.stem())),
        d.join(format!("{}.json", s.stem())),
    )
}

/// A shard file as read back.
#[derive(Debug)]
pub struct ShardFile {
    pub shard: Shard,
    pub csv: PathBuf,
    pub units: BTreeMap<usize, UnitRows>,
    /// The CSV matched its sidecar and every line verified.
    pub intact: bool,
    /// What was wrong, if anything.
    pub note: Option<String>,
}

/// Read and verify one shard file. A sidecar naming another sweep is an error; anything else damaged is
/// salvaged (verified complete units kept) and described in `note`.
pub fn read_shard(rec: &Record, dir: &Path, shard: Shard) -> Result<ShardFile, SweepError> {
    let (csv, side) = shard_paths(dir, shard);
    let sidecar: Option<Result<Sidecar, String>> = match std::fs::read_to_string(&side) {
        Ok(t) => Some(serde_json::from_str::<Sidecar>(&t).map_err(|e| e.to_string())),
        Err(_) => None,
    };
    if let Some(Ok(s)) = &sidecar
        && s.sweep_hash != rec.hash
    {
        return Err(SweepError::Mixed {
            dir: dir.to_path_buf(),
            message: format!(
                "{} belongs to sweep {} but sweep.json is {}",
                side.display(),
                s.sweep_hash,
                rec.hash
            ),
        });
    }
    let bytes = match std::fs::read(&csv) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(ShardFile {
                shard,
                csv,
                units: BTreeMap::new(),
                intact: sidecar.is_none(),
                note: sidecar.map(|_| "the CSV is missing (its sidecar is there)".to_string()),
            });
        }
        Err(e) => return Err(io_err(&csv, e)),
    };
    let text = String::from_utf8_lossy(&bytes);
    let parsed = parse_shard_text(rec, &text);
    let rows: usize = parsed.units.values().map(|r| r.len()).sum();
    let mut problems = Vec::new();
    match &sidecar {
        None => problems.push("no sidecar (checksum) file".to_string()),
        Some(Err(e)) => problems.push(format!("unreadable sidecar ({e})")),
        Some(Ok(s)) => {
            if s.sha256 != digest::sha256_hex(&bytes) {
                problems.push("SHA-256 differs from its sidecar".into());
            }
            if s.rows != rows {
                problems.push(format!("{rows} verified rows, its sidecar says {}", s.rows));
            }
        }
    }
    if !parsed.header_ok {
        problems.push("header does not match this sweep".into());
    }
    if parsed.dropped_lines > 0 {
        problems.push(format!(
            "{} damaged or incomplete line(s) dropped",
            parsed.dropped_lines
        ));
    }
    let intact = problems.is_empty();
    let note = (!intact).then(|| {
        format!(
            "{}: {}; kept {} verified unit(s)",
            csv.display(),
            problems.join(", "),
            parsed.units.len()
        )
    });
    Ok(ShardFile {
        shard,
        csv,
        units: parsed.units,
        intact,
        note,
    })
}

/// Write a shard's CSV (atomically), then its sidecar.
pub fn write_shard(
    rec: &Record,
    dir: &Path,
    shard: Shard,
    units: &BTreeMap<usize, UnitRows>,
) -> Result<(), SweepError> {
    let (csv, side) = shard_paths(dir, shard);
    let mut text = render_line(&rec.header(true));
    text.push('\n');
    let mut rows = 0;
    for r in units.values().flatten() {
        let line = render_line(r);
        let check = row_check(&rec.hash, &line);
        text.push_str(&line);
        text.push(',');
        text.push_str(&check);
        text.push('\n');
        rows += 1;
    }
    io::write_atomic(&csv, text.as_bytes())?;
    let s = Sidecar {
        format: SHARD_FORMAT.into(),
        sweep_hash: rec.hash.clone(),
        shard: shard.index,
        shards: shard.count,
        rows,
        units: units.len(),
        sha256: digest::sha256_hex(text.as_bytes()),
        engine_version: crate::VERSION.into(),
    };
    io::write_atomic(&side, to_json(&s).as_bytes())?;
    Ok(())
}

/// The shard CSV files present in `dir/shards`.
pub fn list_shards(dir: &Path) -> Result<Vec<Shard>, SweepError> {
    let d = dir.join("shards");
    let mut out = Vec::new();
    let entries = match std::fs::read_dir(&d) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(io_err(&d, e)),
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if let Some(s) = Shard::from_file_name(&name) {
            out.push(s);
        } else if let Some(stem) = name.strip_suffix(".json") {
            // a sidecar whose CSV never arrived still counts (read_shard reports it)
            if let Some(s) = Shard::from_file_name(&format!("{stem}.csv")) {
                out.push(s);
            }
        }
    }
    out.sort_by_key(|s| (s.count, s.index));
    out.dedup();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::studies::sweep::spec::tests::quick;

    #[test]
    fn shard_specs() {
        assert_eq!(
            Shard::parse("1/3").expect("ok"),
            Shard { index: 1, count: 3 }
        );
        for bad in ["3/3", "0/0", "1", "a/2", "-1/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        assert!(
            Shard::parse("0/0")
                .expect_err("N=0")
                .to_string()
                .contains("N = 0")
        );
        assert!(
            Shard::parse("4/3")
                .expect_err("i≥N")
                .to_string()
                .contains("out of range")
        );
        let s = Shard::new(2, 12).expect("ok");
        assert_eq!(Shard::from_file_name(&format!("{}.csv", s.stem())), Some(s));
        assert_eq!(Shard::from_file_name("shard-0001-of-0003.csv.77.tmp"), None);
        assert_eq!(Shard::from_file_name("shard-3-of-3.csv"), None);
    }

    #[test]
    fn shard_text_salvage_keeps_only_verified_units() {
        let s = quick();
        let rec = s.record();
        let ncol = rec.header(false).len();
        let mut units = BTreeMap::new();
        for u in [0usize, 3, 6] {
            let (p, e) = s.unit(u);
            let rows: UnitRows = s
                .countermeasures
                .iter()
                .map(|cm| {
                    let mut r = vec![u.to_string(), p.to_string(), e.to_string()];
                    r.extend(s.points[p].values.iter().cloned());
                    r.push(cm.clone());
                    while r.len() < ncol {
                        r.push("1.5".into());
                    }
                    r
                })
                .collect();
            units.insert(u, rows);
        }
        let dir = std::env::temp_dir().join(format!("jsim-sweep-unit-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        io::ensure_dir(&dir.join("shards")).expect("dir");
        let shard = Shard::new(0, 3).expect("ok");
        write_shard(&rec, &dir, shard, &units).expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert!(back.intact, "{:?}", back.note);
        assert_eq!(back.units, units);
        // flip a digit in unit 3's second row: unit 3 is dropped, the others kept
        let (csv, _) = shard_paths(&dir, shard);
        let text = std::fs::read_to_string(&csv).expect("csv");
        let lines: Vec<&str> = text.lines().collect();
        let damaged = lines[4].replacen("1.5", "1.6", 1);
        let mut t2 = lines.clone();
        t2[4] = &damaged;
        std::fs::write(&csv, t2.join("\n") + "\n").expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert!(!back.intact);
        assert_eq!(back.units.keys().copied().collect::<Vec<_>>(), vec![0, 6]);
        // truncate mid-line: the last unit is incomplete
        std::fs::write(&csv, &text[..text.len() - 10]).expect("write");
        let back = read_shard(&rec, &dir, shard).expect("read");
        assert_eq!(back.units.keys().copied().collect::<Vec<_>>(), vec![0, 3]);
        assert!(back.note.expect("note").contains("SHA-256"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
