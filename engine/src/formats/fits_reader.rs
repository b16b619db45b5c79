//! Reading FITS files (issue #53: no module above `formats` holds a CFITSIO handle): [`Reader`], any file HDU
//! by HDU — its image extensions with their `EXTNAME`/`EXTVER`, header keys, images whole or a contiguous
//! section of them (a cube's plane), table columns and raw header cards — and the one-call readers of an
//! image plane, a key, a table's columns or a text extension. No schema: what the extensions of a calibrated
//! HST or JWST file mean is `io::calibrated`'s, what jsim's own hold is `io`'s. Writing is [`super::fits`].

use super::fits::FitsError;
use fitsio::FitsFile;
use fitsio::hdu::{FitsHdu, HduInfo};
use fitsio::images::ReadImage;
use fitsio::tables::ReadsCol;
use std::path::{Path, PathBuf};

/// An image extension of a file: where it is and what the standard's keys call it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageExtension {
    /// `EXTNAME` trimmed, in capitals (empty when absent).
    pub name: String,
    /// `EXTVER` (1 when absent, as the standard defaults it).
    pub version: i64,
    /// Its HDU index (0: the primary).
    pub index: usize,
    /// Its number of axes (`NAXIS`).
    pub axes: usize,
}

/// An open FITS file, read HDU by HDU (index 0: the primary). Every error names the file.
pub struct Reader {
    file: FitsFile,
    path: PathBuf,
}

impl Reader {
    /// Open `path` for reading; a missing file says so once.
    pub fn open(path: &Path) -> Result<Self, FitsError> {
        Ok(Reader {
            file: open(path)?,
            path: path.to_path_buf(),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn error(&self, e: impl std::fmt::Display) -> FitsError {
        FitsError::fits(&self.path, e)
    }

    fn hdu(&mut self, index: usize) -> Result<FitsHdu, FitsError> {
        let path = &self.path;
        self.file.hdu(index).map_err(|e| FitsError::fits(path, e))
    }

    /// The index of the HDU whose `EXTNAME` is `name` (the first, when several share it).
    pub fn index_of(&mut self, name: &str) -> Result<usize, FitsError> {
        let path = &self.path;
        self.file
            .hdu(name)
            .map(|h| h.number)
            .map_err(|e| FitsError::fits(path, format!("extension {name}: {e}")))
    }

    /// Whether HDU `index` exists.
    pub fn has(&mut self, index: usize) -> bool {
        self.file.hdu(index).is_ok()
    }

    /// HDU `index`'s image shape, slowest axis first (`[NAXIS2, NAXIS1]` for a 2-D image), or `None` when
    /// it is a table.
    pub fn image_shape(&mut self, index: usize) -> Result<Option<Vec<usize>>, FitsError> {
        Ok(match self.hdu(index)?.info {
            HduInfo::ImageInfo { shape, .. } => Some(shape),
            _ => None,
        })
    }

    /// HDU `index`'s shape as (nx, ny) when it is a 2-D image, else `None`.
    pub fn plane_shape(&mut self, index: usize) -> Result<Option<(usize, usize)>, FitsError> {
        Ok(match self.image_shape(index)?.as_deref() {
            Some([ny, nx]) => Some((*nx, *ny)),
            _ => None,
        })
    }

    /// Every image extension after the primary, in order.
    pub fn image_extensions(&mut self) -> Vec<ImageExtension> {
        let mut found = Vec::new();
        for index in 1.. {
            let Ok(h) = self.file.hdu(index) else { break };
            let HduInfo::ImageInfo { shape, .. } = &h.info else {
                continue;
            };
            let axes = shape.len();
            let name = h
                .read_key::<String>(&mut self.file, "EXTNAME")
                .unwrap_or_default()
                .trim()
                .to_ascii_uppercase();
            let version = h.read_key::<i64>(&mut self.file, "EXTVER").unwrap_or(1);
            found.push(ImageExtension {
                name,
                version,
                index,
                axes,
            });
        }
        found
    }

    /// Key `key` of HDU `index` as a number, `None` when absent or not a number.
    pub fn key_f64(&mut self, index: usize, key: &str) -> Option<f64> {
        let h = self.file.hdu(index).ok()?;
        h.read_key::<f64>(&mut self.file, key).ok()
    }

    /// Key `key` of HDU `index` as text, `None` when absent.
    pub fn key_string(&mut self, index: usize, key: &str) -> Option<String> {
        let h = self.file.hdu(index).ok()?;
        h.read_key::<String>(&mut self.file, key).ok()
    }

    /// HDU `index`'s whole image, as `Vec<f32>`, `Vec<i64>`, `Vec<u8>`, … (CFITSIO converts the stored type and
    /// applies BSCALE/BZERO).
    pub fn image<T>(&mut self, index: usize) -> Result<Vec<T>, FitsError>
    where
        Vec<T>: ReadImage,
    {
        let h = self.hdu(index)?;
        h.read_image(&mut self.file).map_err(|e| self.error(e))
    }

    /// Pixels `start … end − 1` of HDU `index`'s image in storage order (a cube's plane k of n × m pixels
    /// is `k n m … (k + 1) n m`).
    pub fn section<T>(
        &mut self,
        index: usize,
        start: usize,
        end: usize,
    ) -> Result<Vec<T>, FitsError>
    where
        Vec<T>: ReadImage,
    {
        let h = self.hdu(index)?;
        h.read_section(&mut self.file, start, end)
            .map_err(|e| self.error(e))
    }

    /// Column `name` of the table in HDU `index`, as `f64`, `String`, ….
    pub fn column<T: ReadsCol>(&mut self, index: usize, name: &str) -> Result<Vec<T>, FitsError> {
        let h = self.hdu(index)?;
        h.read_col(&mut self.file, name).map_err(|e| self.error(e))
    }

    /// Every card of HDU `index` as its text ([`header_cards`]: record-valued keywords kept apart).
    pub fn cards(&mut self, index: usize) -> Result<Vec<String>, FitsError> {
        header_cards(&mut self.file, index).map_err(|e| FitsError::fits(&self.path, e))
    }
}

/// Every card of HDU `index` (0: the primary) as its text. Record-valued keywords (`DP1 = 'EXTVER: 1'`,
/// `DP1 = 'AXIS.1: 1'`) repeat one keyword, which the safe reader, keyword by keyword, cannot tell apart.
#[allow(unsafe_code)] // two CFITSIO calls (ffghsp, ffgrec) the safe wrapper does not offer; `f` is a live, open file
fn header_cards(f: &mut FitsFile, index: usize) -> Result<Vec<String>, String> {
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

/// Open a file for reading, a missing one an error that says so once.
fn open(path: &Path) -> Result<FitsFile, FitsError> {
    if !path.exists() {
        return Err(FitsError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    FitsFile::open(path).map_err(|e| FitsError::fits(path, e))
}

/// An HDU of an open file: extension `ext` by EXTNAME, or the primary for `None`.
fn select(
    f: &mut FitsFile,
    path: &Path,
    ext: Option<&str>,
) -> Result<fitsio::hdu::FitsHdu, FitsError> {
    match ext {
        None => f.primary_hdu().map_err(|e| FitsError::fits(path, e)),
        Some(name) => f
            .hdu(name)
            .map_err(|e| FitsError::fits(path, format!("extension {name}: {e}"))),
    }
}

/// The extension names of a file (its HDUs after the primary; unnamed ones as empty strings).
pub fn extension_names(path: &Path) -> Result<Vec<String>, FitsError> {
    let mut f = open(path)?;
    let mut names = Vec::new();
    for i in 1.. {
        let Ok(h) = f.hdu(i) else { break };
        names.push(h.read_key::<String>(&mut f, "EXTNAME").unwrap_or_default());
    }
    Ok(names)
}

/// Read a 2-D image HDU (`ext`: an EXTNAME, or `None` for the primary) as f32, with its shape.
pub fn read_plane(path: &Path, ext: Option<&str>) -> Result<(usize, usize, Vec<f32>), FitsError> {
    let mut f = open(path)?;
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
    let hdu = select(&mut f, path, ext)?;
    let what = ext.unwrap_or("the primary HDU");
    let (nx, ny) = match &hdu.info {
        fitsio::hdu::HduInfo::ImageInfo { shape, .. } if shape.len() == 2 => (shape[1], shape[0]),
        _ => return Err(FitsError::fits(path, format!("{what} is not a 2-D image"))),
    };
    let data: Vec<f32> = hdu.read_image(&mut f).map_err(fe)?;
    Ok((nx, ny, data))
}

/// Read a numeric header of an HDU (`ext`: an EXTNAME, or `None` for the primary).
pub fn read_f64_key_in(path: &Path, ext: Option<&str>, key: &str) -> Result<f64, FitsError> {
    let mut f = open(path)?;
    let hdu = select(&mut f, path, ext)?;
    hdu.read_key::<f64>(&mut f, key)
        .map_err(|e| FitsError::fits(path, format!("header {key}: {e}")))
}

/// Read a string header of an HDU (`ext`: an EXTNAME, or `None` for the primary).
pub fn read_string_key_in(path: &Path, ext: Option<&str>, key: &str) -> Result<String, FitsError> {
    let mut f = open(path)?;
    let hdu = select(&mut f, path, ext)?;
    hdu.read_key::<String>(&mut f, key)
        .map_err(|e| FitsError::fits(path, format!("header {key}: {e}")))
}

/// Read numeric columns of a binary-table extension.
pub fn read_table(path: &Path, ext: &str, columns: &[&str]) -> Result<Vec<Vec<f64>>, FitsError> {
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f
        .hdu(ext)
        .map_err(|e| FitsError::fits(path, format!("extension {ext}: {e}")))?;
    read_columns(&mut f, &hdu, path, columns)
}

/// Numeric columns of a table HDU of an open file.
fn read_columns(
    f: &mut FitsFile,
    hdu: &fitsio::hdu::FitsHdu,
    path: &Path,
    columns: &[&str],
) -> Result<Vec<Vec<f64>>, FitsError> {
    columns
        .iter()
        .map(|c| {
            hdu.read_col::<f64>(f, c)
                .map_err(|e| FitsError::fits(path, format!("column {c}: {e}")))
        })
        .collect()
}

/// A binary table open for reading (the file opened once): its columns' names and its row count, its
/// numeric columns read on demand.
pub struct OpenTable {
    f: FitsFile,
    hdu: fitsio::hdu::FitsHdu,
    path: std::path::PathBuf,
    pub names: Vec<String>,
    pub num_rows: usize,
}

/// Open the binary table in HDU `index` (0: the primary, 1: the first extension).
pub fn open_table(path: &Path, index: usize) -> Result<OpenTable, FitsError> {
    let mut f = open(path)?;
    let hdu = f
        .hdu(index)
        .map_err(|e| FitsError::fits(path, format!("no table extension: {e}")))?;
    let (names, num_rows) = match &hdu.info {
        fitsio::hdu::HduInfo::TableInfo {
            column_descriptions,
            num_rows,
        } => (
            column_descriptions.iter().map(|c| c.name.clone()).collect(),
            *num_rows,
        ),
        _ => return Err(FitsError::fits(path, format!("HDU {index} is not a table"))),
    };
    Ok(OpenTable {
        f,
        hdu,
        path: path.to_path_buf(),
        names,
        num_rows,
    })
}

impl OpenTable {
    /// Its numeric columns named `columns`, in that order.
    pub fn read(&mut self, columns: &[&str]) -> Result<Vec<Vec<f64>>, FitsError> {
        read_columns(&mut self.f, &self.hdu, &self.path, columns)
    }
}

/// Read a string header of the primary HDU.
pub fn read_string_key(path: &Path, key: &str) -> Result<String, FitsError> {
    read_string_key_in(path, None, key)
}

/// Read a numeric header of the primary HDU.
pub fn read_f64_key(path: &Path, key: &str) -> Result<f64, FitsError> {
    read_f64_key_in(path, None, key)
}

/// Read the CONFIG text extension (the TOML the file was made with).
pub fn read_text(path: &Path, ext: &str) -> Result<String, FitsError> {
    let fe = |e: fitsio::errors::Error| FitsError::fits(path, e);
    let mut f = FitsFile::open(path).map_err(fe)?;
    let hdu = f
        .hdu(ext)
        .map_err(|e| FitsError::fits(path, format!("extension {ext}: {e}")))?;
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
    use crate::formats::fits::{Card, Column, Hdu, Pixels, create};

    #[test]
    fn a_file_written_by_the_format_is_read_back_hdu_by_hdu() {
        let dir = crate::testkit::temp_dir("fits-reader");
        let path = dir.join("t.fits");
        let sci: Vec<f32> = (0..12).map(|k| k as f32 * 0.5).collect();
        let cube: Vec<f32> = (0..24).map(|k| k as f32).collect();
        create(
            &path,
            &[
                Hdu::Image {
                    name: "",
                    nx: 4,
                    ny: 6,
                    pixels: Pixels::F32(&cube[..]),
                    cards: vec![
                        Card::f("GAIN", 2.5, "e/ADU"),
                        Card::s("BUNIT", "COUNTS", ""),
                    ],
                },
                Hdu::Image {
                    name: "SCI",
                    nx: 4,
                    ny: 3,
                    pixels: Pixels::F32(&sci[..]),
                    cards: vec![Card::i("EXTVER", 2, "")],
                },
                Hdu::Table {
                    name: "ROWS",
                    columns: vec![Column::F64("CRVAL1".into(), vec![1.5, 2.5])],
                    cards: vec![],
                },
            ],
            |_| "",
        )
        .expect("write");
        let mut r = Reader::open(&path).expect("open");
        assert_eq!(
            r.image_extensions(),
            vec![ImageExtension {
                name: "SCI".into(),
                version: 2,
                index: 1,
                axes: 2
            }]
        );
        assert_eq!(r.plane_shape(1).expect("shape"), Some((4, 3)));
        assert_eq!(r.image_shape(2).expect("shape"), None);
        assert_eq!(r.key_f64(0, "GAIN"), Some(2.5));
        assert_eq!(r.key_string(0, "BUNIT").as_deref(), Some("COUNTS"));
        assert_eq!(r.key_f64(0, "NOPE"), None);
        assert_eq!(r.image::<f32>(1).expect("image"), sci);
        assert_eq!(
            r.section::<f32>(0, 12, 24).expect("section"),
            cube[12..].to_vec()
        );
        assert_eq!(r.column::<f64>(2, "CRVAL1").expect("col"), vec![1.5, 2.5]);
        assert!(r.has(2) && !r.has(3));
        assert_eq!(r.index_of("ROWS").expect("by name"), 2);
        let absent = r.index_of("NOPE").expect_err("no such extension");
        assert!(absent.to_string().contains("extension NOPE"), "{absent}");
        assert!(
            r.cards(1)
                .expect("cards")
                .iter()
                .any(|c| c.starts_with("EXTNAME = 'SCI"))
        );
        let missing = r.column::<f64>(2, "NOPE").expect_err("no such column");
        assert!(missing.to_string().contains("t.fits"), "{missing}");
    }
}
