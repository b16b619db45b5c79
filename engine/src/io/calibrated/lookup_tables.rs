//! A chip's lookup-table distortions read from its file, as astropy reads them (`astropy.wcs.WCS`'s
//! `_read_det2im_kw` and `_read_distortion_kw`): `CPDISj = 'Lookup'` with the record-valued `DPj` cards
//! (`DPj = 'EXTVER: e'`, `DPj = 'AXIS.j: a'`) names the `WCSDVARR` extension of `EXTVER` e; `D2IMDISj =
//! 'Lookup'` with `D2IMj` the `D2IMARR` one. A table whose `AXIS.j` is not j is transposed; each table's
//! `CRPIXi`, `CRVALi`, `CDELTi` default to 0, 0, 1.

use crate::io::IoError;
use crate::sky::lookup_distortion::{LookupDistortion, LookupTable};
use fitsio::FitsFile;
use fitsio::hdu::HduInfo;
use std::path::Path;

/// A record-valued card's field (`DP1 = 'AXIS.1: 1'`: keyword `DP1`, field `AXIS.1`) as a number.
fn record_field(cards: &[String], keyword: &str, field: &str) -> Option<f64> {
    cards.iter().find_map(|c| {
        let (key, rest) = c.split_once('=')?;
        if key.trim() != keyword {
            return None;
        }
        let value = rest.split('/').next()?.trim().trim_matches('\'');
        let (f, v) = value.split_once(':')?;
        (f.trim().eq_ignore_ascii_case(field))
            .then(|| v.trim().parse().ok())
            .flatten()
    })
}

/// A plain card's text value (`CPDIS1 = 'Lookup'`), without its quotes.
fn text_value(cards: &[String], keyword: &str) -> Option<String> {
    cards.iter().find_map(|c| {
        let (key, rest) = c.split_once('=')?;
        (key.trim() == keyword).then(|| {
            rest.split('/')
                .next()
                .unwrap_or("")
                .trim()
                .trim_matches('\'')
                .trim()
                .to_string()
        })
    })
}

/// The index of the image extension `name` of version `extver`.
fn find_extension(f: &mut FitsFile, name: &str, extver: i64) -> Option<usize> {
    for i in 1.. {
        let h = f.hdu(i).ok()?;
        let n = h.read_key::<String>(f, "EXTNAME").unwrap_or_default();
        let v = h.read_key::<i64>(f, "EXTVER").unwrap_or(1);
        if n.trim().eq_ignore_ascii_case(name) && v == extver {
            return Some(i);
        }
    }
    None
}

/// One axis's table: the extension `array_name` that `kind{j}` (with its record cards `record{j}`) names.
fn read_table(
    f: &mut FitsFile,
    path: &Path,
    cards: &[String],
    (kind, record, array_name): (&str, &str, &str),
    j: usize,
) -> Result<Option<LookupTable>, IoError> {
    let bad = |m: String| IoError::Format {
        path: path.to_path_buf(),
        message: m,
    };
    let key = format!("{kind}{j}");
    match text_value(cards, &key) {
        Some(v) if v.eq_ignore_ascii_case("lookup") => {}
        Some(v) => {
            return Err(bad(format!(
                "{key} = '{v}': only 'Lookup' distortions are read"
            )));
        }
        None => return Ok(None),
    }
    let rec = format!("{record}{j}");
    let extver = record_field(cards, &rec, "EXTVER").unwrap_or(1.0) as i64;
    let axis = record_field(cards, &rec, &format!("AXIS.{j}")).unwrap_or(j as f64) as usize;
    let i = find_extension(f, array_name, extver).ok_or_else(|| {
        bad(format!(
            "{key} names the table {array_name},{extver}, which the file does not hold"
        ))
    })?;
    let h = f.hdu(i).map_err(|e| IoError::fits(path, e))?;
    let naxis = match &h.info {
        HduInfo::ImageInfo { shape, .. } if shape.len() == 2 => [shape[1], shape[0]],
        HduInfo::ImageInfo { shape, .. } if shape.len() == 1 => [shape[0], 1],
        _ => {
            return Err(bad(format!(
                "{array_name},{extver} is not a 1-D or 2-D image"
            )));
        }
    };
    let mut number = |k: &str, d: f64| h.read_key::<f64>(f, k).unwrap_or(d);
    let crpix = [number("CRPIX1", 0.0), number("CRPIX2", 0.0)];
    let crval = [number("CRVAL1", 0.0), number("CRVAL2", 0.0)];
    let cdelt = [number("CDELT1", 1.0), number("CDELT2", 1.0)];
    let mut data: Vec<f32> = h.read_image(f).map_err(|e| IoError::fits(path, e))?;
    let mut size = naxis;
    if axis != j {
        // astropy's convention: the table's axes swapped
        let (nx, ny) = (naxis[0], naxis[1]);
        data = (0..nx * ny).map(|k| data[(k % ny) * nx + k / ny]).collect();
        size = [ny, nx];
    }
    LookupTable::new(size, crpix, crval, cdelt, data)
        .map(Some)
        .map_err(|m| bad(format!("{array_name},{extver}: {m}")))
}

/// The lookup-table distortions of HDU `sci` (none when its header states none), and a sentence naming
/// the tables read.
pub fn read(
    f: &mut FitsFile,
    path: &Path,
    sci: usize,
) -> Result<Option<(LookupDistortion, String)>, IoError> {
    let cards = super::super::fits::header_cards(f, sci).map_err(|m| IoError::fits(path, m))?;
    let mut l = LookupDistortion::default();
    let mut named = Vec::new();
    for j in 1..=2 {
        l.det2im[j - 1] = read_table(f, path, &cards, ("D2IMDIS", "D2IM", "D2IMARR"), j)?;
        l.cpdis[j - 1] = read_table(f, path, &cards, ("CPDIS", "DP", "WCSDVARR"), j)?;
        if l.det2im[j - 1].is_some() {
            named.push(format!("D2IMDIS{j}"));
        }
        if l.cpdis[j - 1].is_some() {
            named.push(format!("CPDIS{j}"));
        }
    }
    Ok((!l.is_empty()).then(|| {
        let note = format!(
            "RA/Dec with the header's lookup-table distortions ({}), as astropy's all_pix2world applies them",
            named.join(", ")
        );
        (l, note)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn record_valued_cards_are_read_field_by_field() {
        let cards: Vec<String> = [
            "CPDIS1  = 'Lookup  '           / Prior distortion function type",
            "DP1     = 'EXTVER: 1.0'        / Version number of WCSDVARR extension",
            "DP1     = 'NAXES: 2.0'",
            "DP1     = 'AXIS.1: 1.0'",
            "DP2     = 'AXIS.2: 1.0'",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        assert_eq!(text_value(&cards, "CPDIS1").as_deref(), Some("Lookup"));
        assert_eq!(record_field(&cards, "DP1", "EXTVER"), Some(1.0));
        assert_eq!(record_field(&cards, "DP1", "AXIS.1"), Some(1.0));
        assert_eq!(record_field(&cards, "DP2", "AXIS.2"), Some(1.0));
        assert_eq!(record_field(&cards, "DP1", "AXIS.2"), None);
        assert_eq!(text_value(&cards, "CPDIS2"), None);
    }
}
