//! A chip's lookup-table distortions read from its file, as astropy reads them (`astropy.wcs.WCS`'s
//! `_read_det2im_kw` and `_read_distortion_kw`): `CPDISj = 'Lookup'` with the record-valued `DPj` cards
//! (`DPj = 'EXTVER: e'`, `DPj = 'AXIS.j: a'`) names the `WCSDVARR` extension of `EXTVER` e; `D2IMDISj =
//! 'Lookup'` with `D2IMj` the `D2IMARR` one. A table whose `AXIS.j` is not j is transposed; each table's
//! `CRPIXi`, `CRVALi`, `CDELTi` default to 0, 0, 1.

use crate::formats::fits_reader::Reader;
use crate::io::IoError;
use crate::sky::lookup_distortion::{LookupDistortion, LookupTable};

/// A card's keyword and value: a quoted string without its quotes (`''` read as `'`, a `/` inside it
/// kept), or otherwise the text before the comment's `/`, trimmed.
fn card_value(card: &str) -> Option<(&str, String)> {
    let (key, rest) = card.split_once('=')?;
    let rest = rest.trim_start();
    let value = match rest.strip_prefix('\'') {
        Some(quoted) => {
            let mut out = String::new();
            let mut chars = quoted.chars().peekable();
            while let Some(c) = chars.next() {
                match (c, chars.peek()) {
                    ('\'', Some('\'')) => {
                        out.push('\'');
                        chars.next();
                    }
                    ('\'', _) => break,
                    _ => out.push(c),
                }
            }
            out.trim().to_string()
        }
        None => rest.split('/').next().unwrap_or("").trim().to_string(),
    };
    Some((key.trim(), value))
}

/// A record-valued card's field (`DP1 = 'AXIS.1: 1'`: keyword `DP1`, field `AXIS.1`) as a number.
fn record_field(cards: &[String], keyword: &str, field: &str) -> Option<f64> {
    cards.iter().find_map(|c| {
        let (key, value) = card_value(c)?;
        let (f, v) = value.split_once(':')?;
        (key == keyword && f.trim().eq_ignore_ascii_case(field))
            .then(|| v.trim().parse().ok())
            .flatten()
    })
}

/// A plain card's text value (`CPDIS1 = 'Lookup'`), without its quotes.
fn text_value(cards: &[String], keyword: &str) -> Option<String> {
    cards.iter().find_map(|c| {
        let (key, value) = card_value(c)?;
        (key == keyword).then_some(value)
    })
}

/// The index of the image extension `name` of version `extver`.
fn find_extension(f: &mut Reader, name: &str, extver: i64) -> Option<usize> {
    f.image_extensions()
        .into_iter()
        .find(|e| e.name.eq_ignore_ascii_case(name) && e.version == extver)
        .map(|e| e.index)
}

/// A distortion kind other than `'Lookup'` (astropy warns and leaves it out; jsim leaves RA/Dec out).
struct Unsupported(String);

/// One axis's table: the extension `array_name` that `kind{j}` (with its record cards `record{j}`) names.
fn read_table(
    f: &mut Reader,
    cards: &[String],
    (kind, record, array_name): (&str, &str, &str),
    j: usize,
) -> Result<Result<Option<LookupTable>, Unsupported>, IoError> {
    let path = f.path().to_path_buf();
    let bad = |m: String| IoError::Format {
        path: path.clone(),
        message: m,
    };
    let key = format!("{kind}{j}");
    match text_value(cards, &key) {
        Some(v) if v.eq_ignore_ascii_case("lookup") => {}
        Some(v) => return Ok(Err(Unsupported(format!("{key} = '{v}'")))),
        None => return Ok(Ok(None)),
    }
    let rec = format!("{record}{j}");
    let extver = record_field(cards, &rec, "EXTVER").unwrap_or(1.0) as i64;
    let axis = record_field(cards, &rec, &format!("AXIS.{j}")).unwrap_or(j as f64) as usize;
    let i = find_extension(f, array_name, extver).ok_or_else(|| {
        bad(format!(
            "{key} names the table {array_name},{extver}, which the file does not hold"
        ))
    })?;
    let naxis = match f.image_shape(i)?.as_deref() {
        Some([ny, nx]) => [*nx, *ny],
        Some([n]) => [*n, 1],
        _ => {
            return Err(bad(format!(
                "{array_name},{extver} is not a 1-D or 2-D image"
            )));
        }
    };
    let mut number = |k: &str, d: f64| f.key_f64(i, k).unwrap_or(d);
    let crpix = [number("CRPIX1", 0.0), number("CRPIX2", 0.0)];
    let crval = [number("CRVAL1", 0.0), number("CRVAL2", 0.0)];
    let cdelt = [number("CDELT1", 1.0), number("CDELT2", 1.0)];
    let mut data = f.image::<f32>(i)?;
    let mut size = naxis;
    if axis != j {
        // astropy's convention: the table's axes swapped
        let (nx, ny) = (naxis[0], naxis[1]);
        data = (0..nx * ny).map(|k| data[(k % ny) * nx + k / ny]).collect();
        size = [ny, nx];
    }
    LookupTable::new(size, crpix, crval, cdelt, data)
        .map(|t| Ok(Some(t)))
        .map_err(|m| bad(format!("{array_name},{extver}: {m}")))
}

/// What a chip's header says of lookup-table distortions.
pub enum Tables {
    /// The tables, and a sentence naming them.
    Read(Box<LookupDistortion>, String),
    /// A distortion jsim does not read: the chip's RA/Dec are left out, for the sentence says why.
    Unsupported(String),
}

/// The lookup-table distortions of HDU `sci` (`None` when its header states none).
pub fn read(f: &mut Reader, sci: usize) -> Result<Option<Tables>, IoError> {
    let cards = f.cards(sci)?;
    let mut l = LookupDistortion::default();
    let mut named = Vec::new();
    let mut unsupported = Vec::new();
    for j in 1..=2 {
        let mut take = |r: Result<Option<LookupTable>, Unsupported>, name: String| match r {
            Ok(t) => {
                if t.is_some() {
                    named.push(name);
                }
                t
            }
            Err(Unsupported(card)) => {
                unsupported.push(card);
                None
            }
        };
        let d2im = read_table(f, &cards, ("D2IMDIS", "D2IM", "D2IMARR"), j)?;
        l.det2im[j - 1] = take(d2im, format!("D2IMDIS{j}"));
        let cpdis = read_table(f, &cards, ("CPDIS", "DP", "WCSDVARR"), j)?;
        l.cpdis[j - 1] = take(cpdis, format!("CPDIS{j}"));
    }
    if !unsupported.is_empty() {
        return Ok(Some(Tables::Unsupported(format!(
            "RA/Dec left out: the header states a distortion jsim does not read ({}; only 'Lookup' tables \
             are read), and without it RA/Dec would be off by that distortion",
            unsupported.join(", ")
        ))));
    }
    Ok((!l.is_empty()).then(|| {
        let note = format!(
            "RA/Dec with the header's lookup-table distortions ({}), as astropy's all_pix2world applies them",
            named.join(", ")
        );
        Tables::Read(Box::new(l), note)
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

    #[test]
    fn a_quoted_value_keeps_its_slashes_and_quotes() {
        let cards = vec![
            "OBJECT  = 'M 13 / north''s edge' / a comment".to_string(),
            "EXPTIME =                 30.0 / seconds".to_string(),
        ];
        assert_eq!(
            text_value(&cards, "OBJECT").as_deref(),
            Some("M 13 / north's edge")
        );
        assert_eq!(text_value(&cards, "EXPTIME").as_deref(), Some("30.0"));
    }
}
