//! HST's older "waivered" FITS layout (WFPC2's `_c0f.fits`, converted from GEIS): every chip a plane of one
//! primary data cube (NAXIS3 = the chips), each chip's WCS and group parameters a row of the ASCII table in
//! extension 1, the data-quality cube in the companion `_c1f.fits` beside it. No `BUNIT`: the data are counts
//! (DN), turned into electrons by `ATODGAIN`.

use super::{CalibratedChip, ChipPlanes, HduKeys, Imset, ReadOptions, calibrate, wanted_keys};
use crate::io::IoError;
use fitsio::hdu::HduInfo;
use std::path::{Path, PathBuf};

/// The group-parameter columns read per chip (the rest of the header comes from the primary).
const NUMBER_COLUMNS: [&str; 8] = [
    "CRVAL1", "CRVAL2", "CRPIX1", "CRPIX2", "CD1_1", "CD1_2", "CD2_1", "CD2_2",
];
const TEXT_COLUMNS: [&str; 2] = ["CTYPE1", "CTYPE2"];

/// The cube's shape: (chips, ny, nx) when the primary HDU is a 3-D image.
fn cube_shape(info: &HduInfo) -> Option<(usize, usize, usize)> {
    match info {
        HduInfo::ImageInfo { shape, .. } if shape.len() == 3 => {
            Some((shape[0], shape[1], shape[2]))
        }
        _ => None,
    }
}

/// The chips of a waivered file: one per plane of its primary cube, when extension 1 is a table with a
/// `CRVAL1` column and a row per plane. Empty otherwise.
pub fn groups(path: &Path) -> Result<Vec<Imset>, IoError> {
    let mut f = crate::io::fits::open(path)?;
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let primary = f.primary_hdu().map_err(fe)?;
    let Some((n, _, _)) = cube_shape(&primary.info) else {
        return Ok(Vec::new());
    };
    let Ok(table) = f.hdu(1) else {
        return Ok(Vec::new());
    };
    let rows = match table.read_col::<f64>(&mut f, "CRVAL1") {
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
    let mut f = crate::io::fits::open(path)?;
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut numbers = std::collections::HashMap::new();
    let mut texts = std::collections::HashMap::new();
    let primary = f.primary_hdu().map_err(fe)?;
    for key in wanted_keys() {
        if let Ok(v) = primary.read_key::<f64>(&mut f, &key) {
            numbers.insert(key.clone(), v);
        }
        if let Ok(v) = primary.read_key::<String>(&mut f, &key) {
            texts.insert(key, v);
        }
    }
    let Some((n, ny, nx)) = cube_shape(&primary.info) else {
        return Err(IoError::fits(path, "the primary HDU is not a data cube"));
    };
    let plane = nx * ny;
    // this chip's plane of the cube alone
    let sci: Vec<f32> = primary
        .read_section(&mut f, k * plane, (k + 1) * plane)
        .map_err(fe)?;
    let table = f.hdu(1).map_err(fe)?;
    for c in NUMBER_COLUMNS {
        if let Some(v) = table
            .read_col::<f64>(&mut f, c)
            .ok()
            .and_then(|v| v.get(k).copied())
        {
            numbers.insert(c.to_string(), v);
        }
    }
    for c in TEXT_COLUMNS {
        if let Some(v) = table
            .read_col::<String>(&mut f, c)
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
            let mut g = crate::io::fits::open(&p)?;
            let h = g.primary_hdu().map_err(|e| IoError::fits(&p, e))?;
            if cube_shape(&h.info) != Some((n, ny, nx)) {
                return Err(IoError::fits(
                    &p,
                    format!("not a {n} × {ny} × {nx} cube like {}", path.display()),
                ));
            }
            let v: Vec<i64> = h
                .read_section(&mut g, k * plane, (k + 1) * plane)
                .map_err(|e| IoError::fits(&p, e))?;
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
