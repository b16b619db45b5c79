//! Reading any FITS file HDU by HDU, as the standard lays it out (issue #53: no module above `formats` holds
//! a CFITSIO handle): its image extensions with their `EXTNAME`/`EXTVER`, header keys, images whole or a
//! contiguous section of them (a cube's plane), table columns and raw header cards. No schema: what the
//! extensions of a calibrated HST or JWST file mean is `io::calibrated`'s.

use super::fits::{FitsError, header_cards, open};
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::fits::{Card, Column, Hdu, Pixels, create};

    #[test]
    fn a_file_written_by_the_format_is_read_back_hdu_by_hdu() {
        let dir = std::env::temp_dir().join(format!("jsim-fits-reader-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
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
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
