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

use super::{IoError, temp_path};
use fitsio::FitsFile;
use fitsio::images::{ImageDescription, ImageType};
use fitsio::tables::{ColumnDataType, ColumnDescription};
use std::path::Path;

/// A header card value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    F(f64),
    I(i64),
    /// An unsigned integer (a seed: all 64 bits, which a signed card would wrap); FITS integers have no
    /// fixed width.
    U(u64),
    S(String),
}

/// A header card: key (≤ 8 characters), value, comment.
#[derive(Debug, Clone, PartialEq)]
pub struct Card {
    pub key: String,
    pub value: Value,
    pub comment: String,
}

impl Card {
    pub fn f(key: &str, v: f64, comment: &str) -> Self {
        Self {
            key: key.into(),
            value: Value::F(v),
            comment: comment.into(),
        }
    }
    pub fn i(key: &str, v: i64, comment: &str) -> Self {
        Self {
            key: key.into(),
            value: Value::I(v),
            comment: comment.into(),
        }
    }
    /// An unsigned card (a seed).
    pub fn u(key: &str, v: u64, comment: &str) -> Self {
        Self {
            key: key.into(),
            value: Value::U(v),
            comment: comment.into(),
        }
    }
    pub fn s(key: &str, v: impl Into<String>, comment: &str) -> Self {
        Self {
            key: key.into(),
            value: Value::S(v.into()),
            comment: comment.into(),
        }
    }
}

/// A numeric column of a binary table.
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    F64(String, Vec<f64>),
    I64(String, Vec<i64>),
}

impl Column {
    fn name(&self) -> &str {
        match self {
            Column::F64(n, _) | Column::I64(n, _) => n,
        }
    }
    fn len(&self) -> usize {
        match self {
            Column::F64(_, v) => v.len(),
            Column::I64(_, v) => v.len(),
        }
    }
}

/// Image pixel storage.
#[derive(Debug, Clone, PartialEq)]
pub enum Pixels<'a> {
    U16(&'a [u16]),
    F32(&'a [f32]),
    F64(&'a [f64]),
}

/// One HDU to write.
#[derive(Debug, Clone)]
pub enum Hdu<'a> {
    /// A header without data: only as the primary HDU (a multi-extension file's).
    Header {
        cards: Vec<Card>,
    },
    Image {
        name: &'a str,
        nx: usize,
        ny: usize,
        pixels: Pixels<'a>,
        cards: Vec<Card>,
    },
    U8Image {
        name: &'a str,
        nx: usize,
        ny: usize,
        data: &'a [u8],
    },
    Table {
        name: &'a str,
        columns: Vec<Column>,
        cards: Vec<Card>,
    },
    Text {
        name: &'a str,
        text: &'a str,
    },
}

fn write_cards(
    f: &mut FitsFile,
    hdu: &fitsio::hdu::FitsHdu,
    cards: &[Card],
    path: &Path,
) -> Result<(), IoError> {
    for c in cards {
        let r = match &c.value {
            Value::F(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::I(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::U(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::S(v) => hdu.write_key(f, &c.key, (v.clone(), c.comment.as_str())),
        };
        r.map_err(|e| IoError::fits(path, format!("header {}: {e}", c.key)))?;
    }
    Ok(())
}

/// Write a multi-HDU FITS file atomically. The first HDU must be an image (the primary).
pub fn write(path: &Path, hdus: &[Hdu<'_>]) -> Result<(), IoError> {
    let tmp = temp_path(path);
    let _ = std::fs::remove_file(&tmp);
    let result = write_inner(&tmp, hdus);
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

/// Remove the `EXTNAME = '_PRIMARY'` card the `fitsio` crate gives a primary image it creates (the FITS
/// standard reserves no such name, and a primary HDU needs none).
#[allow(unsafe_code)] // one CFITSIO call (ffdkey) the safe wrapper does not offer; `f` is a live, open file
fn drop_primary_extname(f: &mut FitsFile) -> Result<(), String> {
    let key = std::ffi::CString::new("EXTNAME").map_err(|e| e.to_string())?;
    let mut status = 0;
    // SAFETY: `as_raw` is the open file's CFITSIO handle, valid for the call; `key` is NUL-terminated
    unsafe {
        fitsio::sys::ffmahd(f.as_raw(), 1, std::ptr::null_mut(), &mut status);
        fitsio::sys::ffdkey(f.as_raw(), key.as_ptr(), &mut status);
    }
    match status {
        0 | 202 => Ok(()), // 202: KEY_NO_EXIST, nothing to remove
        s => Err(format!(
            "removing EXTNAME from the primary HDU: CFITSIO status {s}"
        )),
    }
}

/// Every card of HDU `index` (0: the primary) as its text. Record-valued keywords (`DP1 = 'EXTVER: 1'`,
/// `DP1 = 'AXIS.1: 1'`) repeat one keyword, which the safe reader, keyword by keyword, cannot tell apart.
#[allow(unsafe_code)] // two CFITSIO calls (ffghsp, ffgrec) the safe wrapper does not offer; `f` is a live, open file
pub fn header_cards(f: &mut FitsFile, index: usize) -> Result<Vec<String>, String> {
    let hdu = std::os::raw::c_int::try_from(index + 1).map_err(|e| e.to_string())?;
    let (mut status, mut n, mut more) = (0, 0, 0);
    // SAFETY: `as_raw` is the open file's CFITSIO handle, valid for the calls
    unsafe {
        fitsio::sys::ffmahd(f.as_raw(), hdu, std::ptr::null_mut(), &mut status);
        fitsio::sys::ffghsp(f.as_raw(), &mut n, &mut more, &mut status);
    }
    if status != 0 {
        return Err(format!(
            "reading HDU {index}'s header: CFITSIO status {status}"
        ));
    }
    let mut cards = Vec::new();
    for k in 1..=n {
        // a card is 80 characters; CFITSIO writes it NUL-terminated
        let mut buf = [0 as std::os::raw::c_char; 81];
        // SAFETY: `buf` holds the 81 bytes ffgrec may write; the handle is as above
        unsafe {
            fitsio::sys::ffgrec(f.as_raw(), k, buf.as_mut_ptr(), &mut status);
        }
        if status != 0 {
            return Err(format!(
                "reading card {k} of HDU {index}: CFITSIO status {status}"
            ));
        }
        // SAFETY: ffgrec NUL-terminated `buf` within its 81 bytes
        let text = unsafe { std::ffi::CStr::from_ptr(buf.as_ptr()) };
        cards.push(text.to_string_lossy().into_owned());
    }
    Ok(cards)
}

fn write_inner(path: &Path, hdus: &[Hdu<'_>]) -> Result<(), IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut f = match hdus.first() {
        Some(Hdu::Header { cards }) => {
            let mut f = FitsFile::create(path).open().map_err(fe)?;
            let primary = f.primary_hdu().map_err(fe)?;
            write_cards(&mut f, &primary, cards, path)?;
            f
        }
        Some(Hdu::Image {
            nx,
            ny,
            pixels,
            cards,
            ..
        }) => {
            let dims = [*ny, *nx];
            let desc = ImageDescription {
                data_type: pixels.image_type(),
                dimensions: &dims,
            };
            let mut f = FitsFile::create(path)
                .with_custom_primary(&desc)
                .open()
                .map_err(fe)?;
            drop_primary_extname(&mut f).map_err(|e| IoError::fits(path, e))?;
            let primary = f.primary_hdu().map_err(fe)?;
            pixels.write(&primary, &mut f).map_err(fe)?;
            write_cards(&mut f, &primary, cards, path)?;
            f
        }
        _ => {
            return Err(IoError::fits(
                path,
                "the primary HDU must be an image or a header",
            ));
        }
    };
    for h in &hdus[1..] {
        match h {
            Hdu::Header { .. } => {
                return Err(IoError::fits(path, "a header-only HDU must be the primary"));
            }
            Hdu::Image {
                name,
                nx,
                ny,
                pixels,
                cards,
            } => {
                let dims = [*ny, *nx];
                let hdu = f
                    .create_image(
                        *name,
                        &ImageDescription {
                            data_type: pixels.image_type(),
                            dimensions: &dims,
                        },
                    )
                    .map_err(fe)?;
                pixels.write(&hdu, &mut f).map_err(fe)?;
                write_cards(&mut f, &hdu, cards, path)?;
            }
            Hdu::U8Image { name, nx, ny, data } => {
                let dims = [*ny, *nx];
                let hdu = f
                    .create_image(
                        *name,
                        &ImageDescription {
                            data_type: ImageType::UnsignedByte,
                            dimensions: &dims,
                        },
                    )
                    .map_err(fe)?;
                hdu.write_image(&mut f, data).map_err(fe)?;
            }
            Hdu::Table {
                name,
                columns,
                cards,
            } => write_table(&mut f, path, name, columns, cards)?,
            Hdu::Text { name, text } => write_text(&mut f, path, name, text)?,
        }
    }
    Ok(())
}

impl Pixels<'_> {
    /// The FITS image type of the pixels.
    fn image_type(&self) -> ImageType {
        match self {
            Pixels::U16(_) => ImageType::UnsignedShort,
            Pixels::F32(_) => ImageType::Float,
            Pixels::F64(_) => ImageType::Double,
        }
    }

    /// Write the pixels into image HDU `hdu`.
    fn write(
        &self,
        hdu: &fitsio::hdu::FitsHdu,
        f: &mut FitsFile,
    ) -> Result<(), fitsio::errors::Error> {
        match self {
            Pixels::U16(d) => hdu.write_image(f, d),
            Pixels::F32(d) => hdu.write_image(f, d),
            Pixels::F64(d) => hdu.write_image(f, d),
        }
    }
}

/// A binary table HDU `name`: each column with its unit (`TUNITn`), then the cards.
fn write_table(
    f: &mut FitsFile,
    path: &Path,
    name: &str,
    columns: &[Column],
    cards: &[Card],
) -> Result<(), IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let descs = columns
        .iter()
        .map(|c| {
            let t = match c {
                Column::F64(..) => ColumnDataType::Double,
                Column::I64(..) => ColumnDataType::Long,
            };
            ColumnDescription::new(c.name()).with_type(t).create()
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(fe)?;
    let hdu = f.create_table(name, &descs).map_err(fe)?;
    for (i, c) in columns.iter().enumerate() {
        hdu.write_key(
            f,
            &format!("TUNIT{}", i + 1),
            column_unit(c.name()).to_string(),
        )
        .map_err(fe)?;
    }
    for c in columns {
        if c.len() == 0 {
            continue;
        }
        match c {
            Column::F64(n, v) => hdu.write_col(f, n.as_str(), v),
            Column::I64(n, v) => hdu.write_col(f, n.as_str(), v),
        }
        .map_err(fe)?;
    }
    write_cards(f, &hdu, cards, path)
}

/// A text HDU `name`: a table of one string column `LINE`, a line per row (an empty line a space).
fn write_text(f: &mut FitsFile, path: &Path, name: &str, text: &str) -> Result<(), IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let lines: Vec<String> = text
        .lines()
        .map(|l| {
            if l.is_empty() {
                " ".to_string()
            } else {
                l.to_string()
            }
        })
        .collect();
    let width = lines.iter().map(|l| l.len()).max().unwrap_or(1).max(1);
    let desc = ColumnDescription::new("LINE")
        .with_type(ColumnDataType::String)
        .that_repeats(width)
        .create()
        .map_err(fe)?;
    let hdu = f.create_table(name, &[desc]).map_err(fe)?;
    // text has no unit, said as every column's is (TUNITn on every column)
    hdu.write_key(f, "TUNIT1", String::new()).map_err(fe)?;
    if !lines.is_empty() {
        hdu.write_col(f, "LINE", &lines).map_err(fe)?;
    }
    Ok(())
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

/// Open a file for reading, a missing one an error that says so once.
pub(crate) fn open(path: &Path) -> Result<FitsFile, IoError> {
    if !path.exists() {
        return Err(IoError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    FitsFile::open(path).map_err(|e| IoError::fits(path, e))
}

/// An HDU of an open file: extension `ext` by EXTNAME, or the primary for `None`.
fn select(
    f: &mut FitsFile,
    path: &Path,
    ext: Option<&str>,
) -> Result<fitsio::hdu::FitsHdu, IoError> {
    match ext {
        None => f.primary_hdu().map_err(|e| IoError::fits(path, e)),
        Some(name) => f
            .hdu(name)
            .map_err(|e| IoError::fits(path, format!("extension {name}: {e}"))),
    }
}

/// The extension names of a file (its HDUs after the primary; unnamed ones as empty strings).
pub fn extension_names(path: &Path) -> Result<Vec<String>, IoError> {
    let mut f = open(path)?;
    let mut names = Vec::new();
    for i in 1.. {
        let Ok(h) = f.hdu(i) else { break };
        names.push(h.read_key::<String>(&mut f, "EXTNAME").unwrap_or_default());
    }
    Ok(names)
}

/// Read a 2-D image HDU (`ext`: an EXTNAME, or `None` for the primary) as f32, with its shape.
pub fn read_plane(path: &Path, ext: Option<&str>) -> Result<(usize, usize, Vec<f32>), IoError> {
    let mut f = open(path)?;
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let hdu = select(&mut f, path, ext)?;
    let what = ext.unwrap_or("the primary HDU");
    let (nx, ny) = match &hdu.info {
        fitsio::hdu::HduInfo::ImageInfo { shape, .. } if shape.len() == 2 => (shape[1], shape[0]),
        _ => return Err(IoError::fits(path, format!("{what} is not a 2-D image"))),
    };
    let data: Vec<f32> = hdu.read_image(&mut f).map_err(fe)?;
    Ok((nx, ny, data))
}

/// Read a numeric header of an HDU (`ext`: an EXTNAME, or `None` for the primary).
pub fn read_f64_key_in(path: &Path, ext: Option<&str>, key: &str) -> Result<f64, IoError> {
    let mut f = open(path)?;
    let hdu = select(&mut f, path, ext)?;
    hdu.read_key::<f64>(&mut f, key)
        .map_err(|e| IoError::fits(path, format!("header {key}: {e}")))
}

/// Read a string header of an HDU (`ext`: an EXTNAME, or `None` for the primary).
pub fn read_string_key_in(path: &Path, ext: Option<&str>, key: &str) -> Result<String, IoError> {
    let mut f = open(path)?;
    let hdu = select(&mut f, path, ext)?;
    hdu.read_key::<String>(&mut f, key)
        .map_err(|e| IoError::fits(path, format!("header {key}: {e}")))
}

/// Read an image HDU (`image_ext`: an EXTNAME, or `None` for the primary) and its DQ extension `dq_ext`
/// (if the file has one of the image's size) with what the image's header says.
pub fn read_image_in(
    path: &Path,
    image_ext: Option<&str>,
    dq_ext: &str,
) -> Result<ImageRead, IoError> {
    let mut f = open(path)?;
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let hdu = select(&mut f, path, image_ext)?;
    let (nx, ny) = match &hdu.info {
        fitsio::hdu::HduInfo::ImageInfo { shape, .. } if shape.len() == 2 => (shape[1], shape[0]),
        _ => {
            return Err(IoError::fits(
                path,
                match image_ext {
                    Some(name) => format!("extension {name} is not a 2-D image"),
                    None => {
                        "the primary HDU is not a 2-D image (a focal-plane file? its arrays are \
                             analysed one by one by EXTNAME)"
                            .to_string()
                    }
                },
            ));
        }
    };
    let data: Vec<f32> = hdu.read_image(&mut f).map_err(fe)?;
    let numbers: std::collections::HashMap<&str, f64> = NUMERIC_KEYS
        .into_iter()
        .filter_map(|k| hdu.read_key::<f64>(&mut f, k).ok().map(|v| (k, v)))
        .collect();
    // the text of every card the analysis reads: SAMPLING, and a numeric card that did not read as a number
    let texts: std::collections::HashMap<&str, String> = NUMERIC_KEYS
        .into_iter()
        .filter(|k| !numbers.contains_key(k))
        .chain(["SAMPLING"])
        .filter_map(|k| hdu.read_key::<String>(&mut f, k).ok().map(|v| (k, v)))
        .collect();
    let facts = ImageFacts::from_keys(|k| numbers.get(k).copied(), |k| texts.get(k).cloned())
        .map_err(|message| IoError::Format {
            path: path.to_path_buf(),
            message,
        })?;
    let dq = match f.hdu(dq_ext) {
        Ok(h) => h
            .read_image::<Vec<u8>>(&mut f)
            .ok()
            .filter(|d| d.len() == nx * ny),
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

/// Read numeric columns of a binary-table extension.
pub fn read_table(path: &Path, ext: &str, columns: &[&str]) -> Result<Vec<Vec<f64>>, IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f
        .hdu(ext)
        .map_err(|e| IoError::fits(path, format!("extension {ext}: {e}")))?;
    columns
        .iter()
        .map(|c| {
            hdu.read_col::<f64>(&mut f, c)
                .map_err(|e| IoError::fits(path, format!("column {c}: {e}")))
        })
        .collect()
}

/// A number as a header card keeps it: CFITSIO writes a double with 15 significant digits (`%.15G`), so an
/// in-memory value that must equal what a reader of the file gets is rounded the same way.
pub fn as_header_f64(v: f64) -> f64 {
    format!("{v:.14e}").parse().unwrap_or(v)
}

/// Read a string header of the primary HDU.
pub fn read_string_key(path: &Path, key: &str) -> Result<String, IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f.primary_hdu().map_err(fe)?;
    hdu.read_key::<String>(&mut f, key)
        .map_err(|e| IoError::fits(path, format!("header {key}: {e}")))
}

/// Read a numeric header of the primary HDU.
pub fn read_f64_key(path: &Path, key: &str) -> Result<f64, IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f.primary_hdu().map_err(fe)?;
    hdu.read_key::<f64>(&mut f, key)
        .map_err(|e| IoError::fits(path, format!("header {key}: {e}")))
}

/// Read the CONFIG text extension (the TOML the file was made with).
pub fn read_text(path: &Path, ext: &str) -> Result<String, IoError> {
    let fe = |e: fitsio::errors::Error| IoError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f
        .hdu(ext)
        .map_err(|e| IoError::fits(path, format!("extension {ext}: {e}")))?;
    let lines: Vec<String> = hdu.read_col(&mut f, "LINE").map_err(fe)?;
    Ok(lines
        .iter()
        .map(|l| l.trim_end())
        .collect::<Vec<_>>()
        .join("\n"))
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
