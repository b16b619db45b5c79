//! Instrument products: what the instrument team hands the analysis beside the images, as files an outside
//! tool can read too. Only these — never an image's TRUTH or CONFIG — calibrate `jsim analyze`.
//!
//! * **Calibration flat** (`flat_cal.fits`, beside the images): the detector's inter-pixel flat as the
//!   instrument team measured it — the true flat × (1 + `FLATERR`·N(0, 1)), an independent Gaussian error
//!   per pixel of relative 1σ `FLATERR` (default 0.2 %, `analysis.flat_field`) from its own random stream
//!   of the run seed. One array: the primary HDU. The quad focal plane: an empty primary and one image per
//!   array, `FLAT1` … `FLAT4`, matching `ARRAY1` … `ARRAY4` of the exposures. Header: `FLATERR`, `SEED`,
//!   `CONFHASH`, `ORIGIN`, `CONTENT`. Written only when the configuration's analysis is calibrated
//!   (`analysis.flat_field = { calibrated = … }`, the default).

use super::IoError;
use super::fits::{self, Card, Hdu, Pixels};
use crate::simulate::{FocalPlaneSimulator, Simulator};
use std::path::{Path, PathBuf};

/// File name of the calibration flat beside the images.
pub const FLAT_NAME: &str = "flat_cal.fits";

/// The extension of array `k` (0-based) in a focal-plane flat.
pub fn flat_extension(k: usize) -> String {
    format!("FLAT{}", k + 1)
}

/// A calibration flat read back.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationFlat {
    pub nx: usize,
    pub ny: usize,
    /// Row-major, `data[y * nx + x]`, mean ≈ 1.
    pub data: Vec<f32>,
    /// Relative 1σ error of each pixel (FLATERR).
    pub error: f64,
    /// Where it came from (file and extension), for messages.
    pub source: String,
}

fn flat_cards(sim: &Simulator, error: f64) -> Vec<Card> {
    vec![
        Card::f("FLATERR", error, "relative 1-sigma error per pixel"),
        Card::i("SEED", sim.cfg.seed as i64, "master random seed"),
        Card::s("CONFHASH", sim.cfg.hash_hex(), "configuration hash"),
        Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
        Card::s(
            "CONTENT",
            "calibration flat",
            "true flat x (1 + FLATERR N(0,1)) per pixel",
        ),
        Card::s("BUNIT", "", "dimensionless: divide the image by it"),
    ]
}

/// Write the calibration flat of a single-array simulation into `dir` (none when its analysis is
/// uncalibrated): the path written.
pub fn write_calibration_flat(dir: &Path, sim: &Simulator) -> Result<Option<PathBuf>, IoError> {
    let (Some(flat), crate::config::FlatField::Calibrated { error }) =
        (sim.calibration_flat(), sim.cfg.analysis.flat_field)
    else {
        return Ok(None);
    };
    let n = sim.cfg.instrument.detector_px;
    let path = dir.join(FLAT_NAME);
    fits::write(
        &path,
        &[Hdu::Image {
            name: "",
            nx: n,
            ny: n,
            pixels: Pixels::F32(&flat[..]),
            cards: flat_cards(sim, error),
        }],
    )?;
    Ok(Some(path))
}

/// Write the calibration flats of the quad focal plane into `dir` (`FLAT1` … in one file; none when the
/// analysis is uncalibrated): the path written.
pub fn write_focal_plane_flats(
    dir: &Path,
    fps: &FocalPlaneSimulator,
) -> Result<Option<PathBuf>, IoError> {
    let crate::config::FlatField::Calibrated { error } = fps.cfg.analysis.flat_field else {
        return Ok(None);
    };
    let flats: Vec<_> = fps
        .arrays
        .iter()
        .filter_map(|s| s.calibration_flat())
        .collect();
    let names: Vec<String> = (0..fps.arrays.len()).map(flat_extension).collect();
    let mut hdus = vec![Hdu::Header {
        cards: vec![
            Card::i(
                "NARRAYS",
                fps.arrays.len() as i64,
                "arrays: extensions FLAT1..",
            ),
            Card::f("FLATERR", error, "relative 1-sigma error per pixel"),
            Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
        ],
    }];
    for ((sim, flat), name) in fps.arrays.iter().zip(&flats).zip(&names) {
        let n = sim.cfg.instrument.detector_px;
        hdus.push(Hdu::Image {
            name: name.as_str(),
            nx: n,
            ny: n,
            pixels: Pixels::F32(&flat[..]),
            cards: flat_cards(sim, error),
        });
    }
    let path = dir.join(FLAT_NAME);
    fits::write(&path, &hdus)?;
    Ok(Some(path))
}

/// Read a calibration flat: the primary HDU (`ext` = None) or extension `ext`, with its FLATERR.
pub fn read_calibration_flat(path: &Path, ext: Option<&str>) -> Result<CalibrationFlat, IoError> {
    let (nx, ny, data) = fits::read_plane(path, ext)?;
    let error = fits::read_f64_key_in(path, ext, "FLATERR")?;
    if !(0.0..1.0).contains(&error) {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("header FLATERR = {error}: allowed [0, 1) (relative 1σ error)"),
        });
    }
    if let Some(bad) = data.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("a flat value {bad}: every pixel must be finite and > 0"),
        });
    }
    Ok(CalibrationFlat {
        nx,
        ny,
        data,
        error,
        source: match ext {
            Some(e) => format!("{}[{e}]", path.display()),
            None => path.display().to_string(),
        },
    })
}

/// The calibration flat to use for an image: the one given, else `flat_cal.fits` beside the image if it
/// exists.
pub fn find_flat(image: &Path, given: Option<&Path>) -> Option<PathBuf> {
    match given {
        Some(p) => Some(p.to_path_buf()),
        None => {
            let p = image.parent().unwrap_or(Path::new(".")).join(FLAT_NAME);
            p.exists().then_some(p)
        }
    }
}
