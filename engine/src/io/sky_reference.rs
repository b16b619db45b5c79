//! A sky reference catalogue with motions (`reference.csv`: a sequence's, or a survey's own file with the
//! same columns): positions at `ref_epoch`, proper motions, parallaxes, each with its 1σ error — what anchors
//! an astrometric solution's frame (`solution::feed`).

use super::IoError;
use super::csv::Cell;
pub use crate::solution::feed::SkyReference;
use std::path::{Path, PathBuf};

/// The file name in a sequence's directory.
pub const REFERENCE_NAME: &str = crate::io::products::files::REFERENCE_CSV;

/// Its columns (ICRS degrees; mas/yr; mas; errors in mas and mas/yr; the epoch a Julian year, TDB).
pub const REFERENCE_HEADER: [&str; 12] = [
    "ra",
    "dec",
    "pmra",
    "pmdec",
    "parallax",
    "ra_error_mas",
    "dec_error_mas",
    "pmra_error",
    "pmdec_error",
    "parallax_error",
    "hw",
    "ref_epoch",
];

/// Write `reference.csv` into `dir`.
pub fn write(refs: &[SkyReference], dir: &Path) -> Result<PathBuf, IoError> {
    let rows: Vec<Vec<Cell>> = refs
        .iter()
        .map(|r| {
            let mut row = vec![
                Cell::F(r.ra_deg),
                Cell::F(r.dec_deg),
                Cell::F(r.pmra_mas_per_yr),
                Cell::F(r.pmdec_mas_per_yr),
                Cell::F(r.parallax_mas),
            ];
            row.extend(r.sigma.iter().map(|v| Cell::F(*v)));
            row.extend([Cell::F(r.hw), Cell::F(r.ref_epoch_jyear)]);
            row
        })
        .collect();
    let path = dir.join(REFERENCE_NAME);
    super::csv::write(&path, &REFERENCE_HEADER, &rows)?;
    Ok(path)
}

/// Read a reference catalogue with [`REFERENCE_HEADER`]'s columns (a survey's own file, or jsim's).
pub fn read(path: &Path) -> Result<Vec<SkyReference>, IoError> {
    let (h, rows) = super::csv::read(path)?;
    let col = |name: &str| super::csv::column_f64(path, &h, &rows, name);
    let cols: Vec<Vec<f64>> = REFERENCE_HEADER
        .iter()
        .map(|n| col(n))
        .collect::<Result<_, _>>()?;
    Ok((0..rows.len())
        .map(|i| SkyReference {
            ra_deg: cols[0][i],
            dec_deg: cols[1][i],
            pmra_mas_per_yr: cols[2][i],
            pmdec_mas_per_yr: cols[3][i],
            parallax_mas: cols[4][i],
            sigma: [cols[5][i], cols[6][i], cols[7][i], cols[8][i], cols[9][i]],
            hw: cols[10][i],
            ref_epoch_jyear: cols[11][i],
        })
        .collect())
}
