//! HST's older "waivered" FITS layout (WFPC2's `_c0f.fits`, converted from GEIS): every chip a plane of one
//! primary data cube (NAXIS3 = the chips), each chip's WCS and group parameters a row of the ASCII table in
//! extension 1, the data-quality cube in the companion `_c1f.fits` beside it. No `BUNIT`: the data are counts
//! (DN), turned into electrons by `ATODGAIN`.

use super::{CalibratedChip, ChipPlanes, HduKeys, Imset, ReadOptions, calibrate, wanted_keys};
use crate::formats::fits_reader::Reader;
use crate::io::IoError;
use std::path::{Path, PathBuf};

/// The group-parameter columns read per chip (the rest of the header comes from the primary).
const NUMBER_COLUMNS: [&str; 8] = [
    "CRVAL1", "CRVAL2", "CRPIX1", "CRPIX2", "CD1_1", "CD1_2", "CD2_1", "CD2_2",
];
const TEXT_COLUMNS: [&str; 2] = ["CTYPE1", "CTYPE2"];

/// The cube's shape: (chips, ny, nx) when the primary HDU is a 3-D image.
fn cube_shape(f: &mut Reader) -> Result<Option<(usize, usize, usize)>, IoError> {
    Ok(match f.image_shape(0)?.as_deref() {
        Some([n, ny, nx]) => Some((*n, *ny, *nx)),
        _ => None,
    })
}

/// The chips of a waivered file: one per plane of its primary cube, when extension 1 is a table with a
/// `CRVAL1` column and a row per plane. Empty otherwise.
pub fn groups(path: &Path) -> Result<Vec<Imset>, IoError> {
    let mut f = Reader::open(path)?;
    let Some((n, _, _)) = cube_shape(&mut f)? else {
        return Ok(Vec::new());
    };
    if !f.has(1) {
        return Ok(Vec::new());
    }
    let rows = match f.column::<f64>(1, "CRVAL1") {
        Ok(v) => v.len(),
        Err(_) => return Ok(Vec::new()),
    };
    if rows != n {
        return Ok(Vec::new());
    }
    Ok((0..n)
        .map(|k| Imset {
            extver: k as i64 + 1,
            sci: 0,
            err: None,
            dq: None,
            var_poisson: None,
            var_rnoise: None,
            group: Some(k),
            extname: String::new(),
        })
        .collect())
}

/// The companion data-quality file of a waivered science file: `…_c0f.fits` → `…_c1f.fits`, when it exists.
pub fn companion_dq(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?.to_str()?;
    let dq = name.replace("_c0f.", "_c1f.").replace("_c0h.", "_c1h.");
    let p = path.with_file_name(dq);
    (p != path && p.exists()).then_some(p)
}

/// Read chip `set` (its `group`) of a waivered file into electrons.
pub fn read_group(path: &Path, set: &Imset, opts: &ReadOptions) -> Result<CalibratedChip, IoError> {
    let k = set.group.unwrap_or(0);
    let mut f = Reader::open(path)?;
    let mut numbers = std::collections::HashMap::new();
    let mut texts = std::collections::HashMap::new();
    for key in wanted_keys() {
        if let Some(v) = f.key_f64(0, &key) {
            numbers.insert(key.clone(), v);
        }
        if let Some(v) = f.key_string(0, &key) {
            texts.insert(key, v);
        }
    }
    let Some((n, ny, nx)) = cube_shape(&mut f)? else {
        return Err(IoError::fits(path, "the primary HDU is not a data cube"));
    };
    let plane = nx * ny;
    // this chip's plane of the cube alone
    let sci = f.section::<f32>(0, k * plane, (k + 1) * plane)?;
    f.image_shape(1)?; // the group table is there
    for c in NUMBER_COLUMNS {
        if let Some(v) = f.column::<f64>(1, c).ok().and_then(|v| v.get(k).copied()) {
            numbers.insert(c.to_string(), v);
        }
    }
    for c in TEXT_COLUMNS {
        if let Some(v) = f
            .column::<String>(1, c)
            .ok()
            .and_then(|v| v.get(k).cloned())
        {
            texts.insert(c.to_string(), v);
        }
    }
    let mut notes = vec![format!(
        "a waivered file: chip {} of {n}, a plane of the primary cube, its WCS from row {} of the group table",
        k + 1,
        k + 1
    )];
    if !texts.contains_key("BUNIT") {
        texts.insert("BUNIT".to_string(), "COUNTS".to_string());
        notes.push("no BUNIT: counts (DN), as a waivered HST file holds".to_string());
    }
    let dq = match companion_dq(path) {
        Some(p) => {
            let mut g = Reader::open(&p)?;
            if cube_shape(&mut g)? != Some((n, ny, nx)) {
                return Err(IoError::fits(
                    &p,
                    format!("not a {n} × {ny} × {nx} cube like {}", path.display()),
                ));
            }
            let v = g.section::<i64>(0, k * plane, (k + 1) * plane)?;
            notes.push(format!("DQ from {}", p.display()));
            Some(v.into_iter().map(|q| (q as u64) & 0xffff).collect())
        }
        None => {
            notes.push("no companion _c1f.fits: no DQ plane".to_string());
            None
        }
    };
    let keys = HduKeys { numbers, texts };
    let mut chip = calibrate(
        &keys,
        ChipPlanes {
            nx,
            ny,
            sci,
            err: None,
            dq,
            var_poisson: None,
            var_rnoise: None,
        },
        opts,
    )
    .map_err(|message| IoError::Format {
        path: path.to_path_buf(),
        message: format!("{}: {message}", set.name()),
    })?;
    notes.append(&mut chip.notes);
    chip.notes = notes;
    // no distortion tables in a waivered file: RA/Dec through the header's WCS as it is
    if let Some(w) = &chip.wcs {
        chip.notes.push(super::units::wcs_note(w));
    }
    Ok(chip)
}
