//! FITS files as the standard has them, through CFITSIO (bundled by `fitsio-src`): HDUs of images, binary
//! tables and text, and header cards, written ([`create`]); reading them back is [`super::fits_reader`]'s. No schema: what a file of jsim's holds (its
//! extensions, keys, columns and units) is `io`'s; a table column's unit comes from the writer's
//! `unit_of`.

use fitsio::FitsFile;
use fitsio::images::{ImageDescription, ImageType};
use fitsio::tables::{ColumnDataType, ColumnDescription};
use std::path::{Path, PathBuf};

/// A FITS file that could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum FitsError {
    /// The file is not there (or could not be opened as a file).
    #[error("{path}: {reason}")]
    Io {
        path: PathBuf,
        reason: std::io::Error,
    },
    /// CFITSIO's complaint, or a layout that is not the one asked for.
    #[error("FITS file {path}: {message}")]
    Fits { path: PathBuf, message: String },
}

impl FitsError {
    pub fn io(path: &Path, reason: std::io::Error) -> Self {
        FitsError::Io {
            path: path.to_path_buf(),
            reason,
        }
    }
    pub fn fits(path: &Path, e: impl std::fmt::Display) -> Self {
        FitsError::Fits {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

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
) -> Result<(), FitsError> {
    for c in cards {
        let r = match &c.value {
            Value::F(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::I(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::U(v) => hdu.write_key(f, &c.key, (*v, c.comment.as_str())),
            Value::S(v) => hdu.write_key(f, &c.key, (v.clone(), c.comment.as_str())),
        };
        r.map_err(|e| FitsError::fits(path, format!("header {}: {e}", c.key)))?;
    }
    Ok(())
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

pub fn create(
    path: &Path,
    hdus: &[Hdu<'_>],
    unit_of: fn(&str) -> &'static str,
) -> Result<(), FitsError> {
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
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
            drop_primary_extname(&mut f).map_err(|e| FitsError::fits(path, e))?;
            let primary = f.primary_hdu().map_err(fe)?;
            pixels.write(&primary, &mut f).map_err(fe)?;
            write_cards(&mut f, &primary, cards, path)?;
            f
        }
        _ => {
            return Err(FitsError::fits(
                path,
                "the primary HDU must be an image or a header",
            ));
        }
    };
    for h in &hdus[1..] {
        match h {
            Hdu::Header { .. } => {
                return Err(FitsError::fits(
                    path,
                    "a header-only HDU must be the primary",
                ));
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
            } => write_table(&mut f, path, name, columns, cards, unit_of)?,
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
    unit_of: fn(&str) -> &'static str,
) -> Result<(), FitsError> {
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
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
        hdu.write_key(f, &format!("TUNIT{}", i + 1), unit_of(c.name()).to_string())
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
fn write_text(f: &mut FitsFile, path: &Path, name: &str, text: &str) -> Result<(), FitsError> {
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
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

/// A number as a header card keeps it: CFITSIO writes a double with 15 significant digits (`%.15G`), so an
/// in-memory value that must equal what a reader of the file gets is rounded the same way.
pub fn as_header_f64(v: f64) -> f64 {
    format!("{v:.14e}").parse().unwrap_or(v)
}
