//! CSV records as RFC 4180 has them (the `csv` crate): quoted cells may hold commas, quotes (doubled) and
//! line breaks. Lines starting with `#` (after white space) are comments and blank lines are skipped; cells are trimmed of
//! surrounding white space; rows may differ in length (the reader of a schema names a short row).

use std::path::{Path, PathBuf};

/// A CSV file that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}, line {line}: {message}")]
    Syntax {
        path: PathBuf,
        line: u64,
        message: String,
    },
}

/// One record: its cells and the line it starts on (1-based).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub line: u64,
    pub cells: Vec<String>,
}

/// The records of the CSV text `text` one by one (`path` names it in errors), the header (if any) included.
pub fn records<'a>(
    path: &'a Path,
    text: &'a str,
) -> impl Iterator<Item = Result<Record, CsvError>> + 'a {
    // comment lines emptied, and the line of a record counted from its first non-blank byte: the crate's own
    // line numbers leave out comment and blank lines, and its offset is where the blank lines before it begin
    let uncommented: String = text
        .lines()
        .map(|l| {
            if l.trim_start().starts_with('#') {
                ""
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    // one copy of the text, shared by the reader and the line counter
    let bytes: std::sync::Arc<[u8]> = uncommented.into_bytes().into();
    let text_bytes = bytes.clone();
    let newlines: Vec<usize> = (0..bytes.len()).filter(|&i| bytes[i] == b'\n').collect();
    let line_of = move |p: Option<&::csv::Position>| {
        p.map(|p| {
            let start = (p.byte() as usize).min(bytes.len());
            let first = bytes[start..]
                .iter()
                .position(|b| !b.is_ascii_whitespace())
                .map_or(bytes.len(), |k| start + k);
            newlines.partition_point(|&n| n < first) as u64 + 1
        })
        .unwrap_or(0)
    };
    ::csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(::csv::Trim::All)
        .from_reader(std::io::Cursor::new(text_bytes))
        .into_records()
        .filter_map(move |r| match r {
            Err(e) => Some(Err(CsvError::Syntax {
                path: path.to_path_buf(),
                line: line_of(e.position()),
                message: e.to_string(),
            })),
            // a line of white space alone is a record of one empty cell: skipped, as a blank line
            Ok(r) if r.len() == 1 && r[0].is_empty() => None,
            Ok(r) => Some(Ok(Record {
                line: line_of(r.position()),
                cells: r.iter().map(str::to_string).collect(),
            })),
        })
}

/// Every record of the CSV text `text` ([`records`]).
pub fn parse(path: &Path, text: &str) -> Result<Vec<Record>, CsvError> {
    records(path, text).collect()
}

/// Every record of the CSV file at `path`.
pub fn read(path: &Path) -> Result<Vec<Record>, CsvError> {
    let text = std::fs::read_to_string(path).map_err(|source| CsvError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(path, &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quoted cells keep their commas and doubled quotes; comments, blank lines and surrounding spaces go;
    /// each record keeps the line it starts on.
    #[test]
    fn quoted_cells_comments_and_blank_lines() {
        let text =
            "# a comment\nname, x ,y\n\n\"Star, the first\",1.5,2\n  \n\"say \"\"hi\"\"\",3,4\n";
        let r = parse(Path::new("t.csv"), text).expect("parse");
        let cells: Vec<Vec<&str>> = r
            .iter()
            .map(|r| r.cells.iter().map(String::as_str).collect())
            .collect();
        assert_eq!(
            cells,
            vec![
                vec!["name", "x", "y"],
                vec!["Star, the first", "1.5", "2"],
                vec!["say \"hi\"", "3", "4"],
            ]
        );
        assert_eq!(r.iter().map(|r| r.line).collect::<Vec<_>>(), vec![2, 4, 6]);
    }

    /// A missing file is an error naming it.
    #[test]
    fn a_missing_file_is_named() {
        let e = read(Path::new("/nonexistent/stars.csv")).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/stars.csv"), "{e}");
    }
}
