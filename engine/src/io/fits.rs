//! FITS output and input (cfitsio, bundled through `fitsio-src`).
//!
//! A simulated exposure is one file:
//! * primary HDU: the image in ADU — `uint16` (BITPIX 16, BZERO 32768) when digitised with ≤ 16 bits,
//!   `float32` otherwise — with the provenance headers (EXPTIME, GAIN, RDNOISE, BUNIT, SEED, READOUT,
//!   ACECASE, ACESIGMA, CONFHASH, ENGINE, …);
//! * `DQ`: data-quality bits (uint8, see [`crate::detector::dq`]);
//! * `TRUTH`: the input catalogue (binary table: id, x, y, flux_e, …; 0-based pixel coordinates);
//! * `CONFIG`: the full configuration as TOML text, one line per row.
//!
//! FITS dimensions are `[ny, nx]` (NAXIS2, NAXIS1) and the data row-major, so astropy's `data[y, x]`
//! is our pixel (x, y); ds9 shows it at (x + 1, y + 1).

//!
//! The format itself (HDUs, cards, CFITSIO) is [`crate::formats::fits`]; this module adds what jsim's files
//! mean: the units of its columns' names, the image's header facts, atomic writes.

pub use crate::formats::fits::{Card, Column, FitsError, Hdu, Pixels, Value, as_header_f64};
pub use crate::formats::fits_reader::{
    extension_names, read_f64_key, read_f64_key_in, read_plane, read_string_key,
    read_string_key_in, read_table, read_text,
};

use super::{IoError, temp_path};
use crate::formats::fits_reader::Reader;
use std::path::Path;

impl From<FitsError> for IoError {
    fn from(e: FitsError) -> Self {
        match e {
            FitsError::Io { path, reason } => IoError::Io { path, reason },
            FitsError::Fits { path, message } => IoError::Fits { path, message },
        }
    }
}

/// Write a multi-HDU FITS file atomically. The first HDU must be an image (the primary).
pub fn write(path: &Path, hdus: &[Hdu<'_>]) -> Result<(), IoError> {
    let tmp = temp_path(path);
    let _ = std::fs::remove_file(&tmp);
    let result = crate::formats::fits::create(&tmp, hdus, column_unit).map_err(IoError::from);
    match result {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            IoError::io(path, e)
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// The FITS unit of a table column, from the unit its name ends with (the engine's `_px`, `_mas`, `_s`, …
/// convention, any case); "" (dimensionless) for counts, flags, indices and fractions. Electrons are written
/// `ct` (the FITS standard has no electron; astropy reads `electron` with a warning).
pub fn column_unit(name: &str) -> &'static str {
    let n = name.to_ascii_lowercase();
    const SUFFIXES: [(&str, &str); 9] = [
        ("_e_per_s", "ct/s"),
        ("_px", "pix"),
        ("_mas", "mas"),
        ("_deg", "deg"),
        ("_um", "um"),
        ("_adu", "adu"),
        ("_hz", "Hz"),
        ("_e", "ct"),
        ("_s", "s"),
    ];
    if let Some((_, u)) = SUFFIXES.iter().find(|(s, _)| n.ends_with(s)) {
        return u;
    }
    match n.as_str() {
        "hw" | "mag_hw" | "j_minus_h" | "mag" | "j_h" => "mag",
        // the truth's positions and jitter, in pixels by the table's documentation
        "x" | "y" | "jitter_dx" | "jitter_dy" => "pix",
        _ => "",
    }
}

/// What an image's header says about its pixel values (the keys the analysis needs), with what was
/// assumed where it is silent. One reading of the header for every front end: the FITS reader
/// ([`read_image`]) and the Python module (a dict of cards) look the keys up their own way.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageFacts {
    pub gain_e_per_adu: f64,
    /// The image's read noise (all reads): from `RNREAD` and `SAMPLING` when both are given (exact), else
    /// `RDNOISE`.
    pub read_noise_e: f64,
    pub bias_adu: f64,
    pub exposure_s: f64,
    pub saturation_adu: Option<f64>,
    /// The linearity correction's coefficient β̂ (`NLCORR`, e⁻⁻¹: measured = true − β̂·true²); 0, the
    /// default when the header is silent, is a linear detector.
    pub nonlinearity_per_e: f64,
    /// What was assumed because the header did not say (one sentence each; empty for a jsim image).
    pub assumed: Vec<String>,
}

impl ImageFacts {
    /// Read the facts through `number(KEY)` and `text(KEY)` lookups; an impossible value is an error naming
    /// its key and the allowed range.
    pub fn from_keys(
        mut number: impl FnMut(&str) -> Option<f64>,
        mut text: impl FnMut(&str) -> Option<String>,
    ) -> Result<Self, String> {
        // a card that is present but not a number is an error naming it, never a default
        let mut values = std::collections::HashMap::new();
        for k in NUMERIC_KEYS {
            match (number(k), text(k)) {
                (Some(v), _) => {
                    values.insert(k, v);
                }
                (None, Some(raw)) => {
                    return Err(format!(
                        "header {k} = '{}': not a number (expected {})",
                        raw.trim(),
                        numeric_key_meaning(k)
                    ));
                }
                (None, None) => {}
            }
        }
        let sampling = match text("SAMPLING") {
            Some(s) => Some(crate::config::Sampling::from_header(&s).ok_or_else(|| {
                format!(
                    "header SAMPLING = '{}': not a sampling mode (expected CDS or FOWLER-<pairs>)",
                    s.trim()
                )
            })?),
            None => None,
        };
        let per_read = values.get("RNREAD").copied();
        let mut assumed = Vec::new();
        let mut key = |name: &str, default: f64| -> f64 {
            values.get(name).copied().unwrap_or_else(|| {
                assumed.push(format!(
                    "no {name} header: {} {default} assumed",
                    numeric_key_meaning(name)
                ));
                default
            })
        };
        let gain = key("GAIN", 1.0);
        let rn = match (per_read, sampling) {
            (Some(per_read), Some(s)) => s.image_read_noise_e(per_read),
            _ => key("RDNOISE", 0.0),
        };
        let bias = key("BIASADU", 0.0);
        let exposure_s = key("EXPTIME", 1.0);
        let saturation_adu = values.get("SATURATE").copied();
        let nonlinearity_per_e = values.get("NLCORR").copied().unwrap_or(0.0);
        let bad = |k: &str, v: f64, allowed: &str| Err(format!("header {k} = {v}: {allowed}"));
        if !(gain > 0.0 && gain.is_finite()) {
            return bad("GAIN", gain, "must be a finite number > 0 [e-/ADU]");
        }
        if !(rn >= 0.0 && rn.is_finite()) {
            return bad("RDNOISE", rn, "must be a finite number ≥ 0 [e-]");
        }
        if !bias.is_finite() {
            return bad("BIASADU", bias, "must be finite [ADU]");
        }
        if !(exposure_s > 0.0 && exposure_s.is_finite()) {
            return bad("EXPTIME", exposure_s, "must be a finite number > 0 [s]");
        }
        if let Some(s) = saturation_adu
            && !(s > 0.0)
        {
            return bad("SATURATE", s, "must be > 0 [ADU]");
        }
        if !(0.0..=1e-3).contains(&nonlinearity_per_e) {
            return bad("NLCORR", nonlinearity_per_e, "must be in [0, 1e-3] [1/e-]");
        }
        Ok(Self {
            gain_e_per_adu: gain,
            read_noise_e: rn,
            bias_adu: bias,
            exposure_s,
            saturation_adu,
            nonlinearity_per_e,
            assumed,
        })
    }
}

/// The numeric header cards the analysis reads ([`ImageFacts::from_keys`]).
pub const NUMERIC_KEYS: [&str; 7] = [
    "RNREAD", "GAIN", "RDNOISE", "BIASADU", "EXPTIME", "SATURATE", "NLCORR",
];

/// What a numeric card of [`NUMERIC_KEYS`] holds, for messages.
fn numeric_key_meaning(key: &str) -> &'static str {
    match key {
        "RNREAD" => "read noise of one read [e-]",
        "GAIN" => "gain [e-/ADU]",
        "RDNOISE" => "read noise [e-]",
        "BIASADU" => "bias [ADU]",
        "NLCORR" => "linearity correction coefficient [1/e-]",
        "EXPTIME" => "exposure [s]",
        "SATURATE" => "saturation level [ADU]",
        _ => "a number",
    }
}

/// An image read back, with what its header says.
#[derive(Debug, Clone)]
pub struct ImageRead {
    pub nx: usize,
    pub ny: usize,
    /// Pixel values as stored (ADU), as f32.
    pub data: Vec<f32>,
    pub dq: Option<Vec<u8>>,
    pub facts: ImageFacts,
}

/// Read the primary image (and DQ extension, if any) of a file.
pub fn read_image(path: &Path) -> Result<ImageRead, IoError> {
    read_image_in(path, None, "DQ")
}

/// Read an image HDU (`image_ext`: an EXTNAME, or `None` for the primary) and its DQ extension `dq_ext`
/// (if the file has one of the image's size) with what the image's header says.
pub fn read_image_in(
    path: &Path,
    image_ext: Option<&str>,
    dq_ext: &str,
) -> Result<ImageRead, IoError> {
    let mut f = Reader::open(path)?;
    let index = match image_ext {
        Some(name) => f.index_of(name)?,
        None => 0,
    };
    let Some((nx, ny)) = f.plane_shape(index)? else {
        return Err(IoError::fits(
            path,
            match image_ext {
                Some(name) => format!("extension {name} is not a 2-D image"),
                None => "the primary HDU is not a 2-D image (a focal-plane file? its arrays are \
                         analysed one by one by EXTNAME)"
                    .to_string(),
            },
        ));
    };
    let data = f.image::<f32>(index)?;
    let numbers: std::collections::HashMap<&str, f64> = NUMERIC_KEYS
        .into_iter()
        .filter_map(|k| f.key_f64(index, k).map(|v| (k, v)))
        .collect();
    // the text of every card the analysis reads: SAMPLING, and a numeric card that did not read as a number
    let texts: std::collections::HashMap<&str, String> = NUMERIC_KEYS
        .into_iter()
        .filter(|k| !numbers.contains_key(k))
        .chain(["SAMPLING"])
        .filter_map(|k| f.key_string(index, k).map(|v| (k, v)))
        .collect();
    let facts = ImageFacts::from_keys(|k| numbers.get(k).copied(), |k| texts.get(k).cloned())
        .map_err(|message| IoError::Format {
            path: path.to_path_buf(),
            message,
        })?;
    let dq = match f.index_of(dq_ext) {
        Ok(i) => f.image::<u8>(i).ok().filter(|d| d.len() == nx * ny),
        Err(_) => None,
    };
    Ok(ImageRead {
        nx,
        ny,
        data,
        dq,
        facts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_primary_image_has_no_extname_and_every_table_column_a_unit() {
        let dir = crate::testkit::temp_dir("fits-meta");
        let path = dir.join("m.fits");
        let data = vec![0.0f32; 4];
        write(
            &path,
            &[
                Hdu::Image {
                    name: "",
                    nx: 2,
                    ny: 2,
                    pixels: Pixels::F32(&data),
                    cards: vec![Card::f("EXPTIME", 12.5, "")],
                },
                Hdu::Table {
                    name: "T",
                    columns: vec![
                        Column::F64("x_px".into(), vec![1.0]),
                        Column::F64("T_S".into(), vec![1.0]),
                        Column::F64("mag_hw".into(), vec![1.0]),
                        Column::I64("id".into(), vec![1]),
                    ],
                    cards: vec![],
                },
            ],
        )
        .expect("write");
        assert!(
            read_string_key(&path, "EXTNAME").is_err(),
            "no EXTNAME on the primary"
        );
        for (i, unit) in ["pix", "s", "mag", ""].iter().enumerate() {
            let u =
                read_string_key_in(&path, Some("T"), &format!("TUNIT{}", i + 1)).expect("TUNIT");
            assert_eq!(u.trim(), *unit);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_header_double_reads_back_as_as_header_f64_says() {
        let dir = crate::testkit::temp_dir("fits-f64");
        let path = dir.join("k.fits");
        let values = [471.269_843_752_123_4, 1.0 / 3.0, 2.0f64.sqrt() * 1e-7, 12.5];
        let cards: Vec<Card> = values
            .iter()
            .enumerate()
            .map(|(i, v)| Card::f(&format!("V{i}"), *v, ""))
            .collect();
        write(&path, &[Hdu::Header { cards }]).expect("write");
        for (i, v) in values.iter().enumerate() {
            let back = read_f64_key(&path, &format!("V{i}")).expect("read");
            assert_eq!(back, as_header_f64(*v), "{v}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn round_trip_image_table_and_text() {
        let dir = crate::testkit::temp_dir("fits");
        let path = dir.join("t.fits");
        let (nx, ny) = (5usize, 3usize);
        let img: Vec<u16> = (0..15).map(|v| v * 1000).collect();
        let dq: Vec<u8> = (0..15).map(|v| (v % 3) as u8).collect();
        write(
            &path,
            &[
                Hdu::Image {
                    name: "",
                    nx,
                    ny,
                    pixels: Pixels::U16(&img),
                    cards: vec![
                        Card::f("GAIN", 3.0, "e/ADU"),
                        Card::s("READOUT", "rolling", "order"),
                    ],
                },
                Hdu::U8Image {
                    name: "DQ",
                    nx,
                    ny,
                    data: &dq,
                },
                Hdu::Table {
                    name: "TRUTH",
                    columns: vec![
                        Column::F64("x".into(), vec![1.5, 2.5]),
                        Column::I64("id".into(), vec![7, 8]),
                    ],
                    cards: vec![],
                },
                Hdu::Text {
                    name: "CONFIG",
                    text: "a = 1\n\n[b]\nc = \"x\"",
                },
            ],
        )
        .expect("write");
        let r = read_image(&path).expect("read");
        assert_eq!((r.nx, r.ny), (5, 3));
        assert_eq!(r.data[7], 7000.0);
        assert_eq!(r.data[14], 14000.0); // above 32767: BZERO handled
        assert_eq!(r.facts.gain_e_per_adu, 3.0);
        assert_eq!(r.dq.as_deref(), Some(&dq[..]));
        let t = read_table(&path, "TRUTH", &["x", "id"]).expect("table");
        assert_eq!(t[0], vec![1.5, 2.5]);
        assert_eq!(t[1], vec![7.0, 8.0]);
        assert_eq!(read_string_key(&path, "READOUT").expect("key"), "rolling");
        assert!(
            read_text(&path, "CONFIG")
                .expect("text")
                .contains("c = \"x\"")
        );
        // no temporary file left behind
        let left: Vec<_> = std::fs::read_dir(&dir)
            .expect("dir")
            .filter_map(|e| e.ok())
            .collect();
        assert_eq!(left.len(), 1);
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = read_image(Path::new("/nonexistent/img.fits")).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/img.fits"));
    }
}
