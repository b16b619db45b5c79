//! Writing an exposure of the quad focal plane: one multi-extension FITS, `fp_NNN.fits`.
//!
//! * primary: header only — the master seed, the image index, the layout and where the scene's stars fell
//!   (NCATALOG, NDUPLIC, NPHOTO, NBORDER, NGAP, NOFF);
//! * `ARRAY1` … `ARRAY4`: each array's image with the full provenance header of a single-array image and
//!   its own WCS (`RA---TAN`, or `RA---TAN-SIP` with A/B/AP/BP), its turn (ROTATION), its streams' seed
//!   (ARRSEED);
//! * `DQ1` … `DQ4`: each array's data-quality flags (`detector::dq`);
//! * `TRUTH`: every star on a photosensitive pixel, the columns of a single image's truth plus `array`
//!   (1 … 4, the extension's number);
//! * `CONFIG`: the TOML the exposure was made with.

use super::IoError;
use super::exposure::{counts_cards, headers, provenance_cards, stored_u16, truth_columns};
use super::fits::{self, Card, Column, Hdu, Pixels};
use crate::simulate::{FocalPlaneExposure, FocalPlaneSimulator};
use std::path::{Path, PathBuf};

pub use crate::io::products::files::focal_plane_name;

/// The primary header of a focal-plane file.
fn primary_cards(fps: &FocalPlaneSimulator, exp: &FocalPlaneExposure) -> Vec<Card> {
    let c = &fps.cfg;
    // the validated configuration always has a pointing; the configured one stands in otherwise
    let axis = crate::sky::pointing(c).unwrap_or_else(|_| crate::sky::Pointing::from(&c.sky));
    let mut cards = vec![
        Card::u("SEED", c.seed, "master random seed"),
        Card::i("IMAGEIDX", exp.index as i64, "image index in the dataset"),
        Card::i(
            "NARRAYS",
            exp.arrays.len() as i64,
            "arrays: extensions ARRAY1..",
        ),
        Card::f("GAPPX", c.focal_plane.gap_px, "[pix] gap between arrays"),
        Card::f(
            "RA_PNT",
            c.sky.ra_deg,
            "[deg] target at the axis, RA (ICRS)",
        ),
        Card::f(
            "DEC_PNT",
            c.sky.dec_deg,
            "[deg] target at the axis, Dec (ICRS)",
        ),
        Card::f(
            "RA_AXIS",
            axis.ra_deg,
            "[deg] optical axis in the images, RA (apparent)",
        ),
        Card::f(
            "DEC_AXIS",
            axis.dec_deg,
            "[deg] optical axis in the images, Dec (apparent)",
        ),
        Card::f(
            "PA_PNT",
            c.sky.pa_deg,
            "[deg] focal plane +y, east of north",
        ),
    ];
    let t_start_s = exp.arrays.first().map(|a| a.t_start_s).unwrap_or(0.0);
    cards.extend(super::exposure::observation_cards(c, t_start_s));
    cards.extend(provenance_cards(c));
    if let Some(counts) = &exp.counts {
        cards.extend(counts_cards(counts));
    }
    cards
}

/// The TRUTH table of a focal-plane exposure: each array's truth, then the `array` column (1-based).
pub fn focal_plane_truth(fps: &FocalPlaneSimulator, exp: &FocalPlaneExposure) -> Vec<Column> {
    let mut merged: Vec<Column> = Vec::new();
    let mut arrays: Vec<i64> = Vec::new();
    // the header-frame columns when any array's header is not the instrument as built (the same as x, y on
    // an array whose header is)
    let in_header = fps.arrays.iter().any(|s| s.wcs_deviates());
    for (sim, e) in fps.arrays.iter().zip(&exp.arrays) {
        let mut cols = truth_columns(&e.truth, sim.wcs());
        if in_header {
            cols.extend(crate::io::exposure::header_frame_columns(sim, &e.truth));
        }
        arrays.extend(std::iter::repeat_n(
            sim.array.index as i64 + 1,
            e.truth.len(),
        ));
        if merged.is_empty() {
            merged = cols;
            continue;
        }
        for (m, c) in merged.iter_mut().zip(cols) {
            match (m, c) {
                (Column::F64(_, a), Column::F64(_, b)) => a.extend(b),
                (Column::I64(_, a), Column::I64(_, b)) => a.extend(b),
                _ => {}
            }
        }
    }
    merged.push(Column::I64("array".into(), arrays));
    merged
}

/// Write focal-plane exposure `exp` into `dir`; returns the file's path.
pub fn write_focal_plane_exposure(
    dir: &Path,
    fps: &FocalPlaneSimulator,
    exp: &FocalPlaneExposure,
) -> Result<PathBuf, IoError> {
    let path = dir.join(focal_plane_name(exp.index));
    write_focal_plane_exposure_to(&path, fps, exp)?;
    Ok(path)
}

/// Write focal-plane exposure `exp` as the file `path` (written whole or not at all).
pub fn write_focal_plane_exposure_to(
    path: &Path,
    fps: &FocalPlaneSimulator,
    exp: &FocalPlaneExposure,
) -> Result<(), IoError> {
    let config_text = fps.cfg.to_toml();
    let stored: Vec<Option<Vec<u16>>> = exp
        .arrays
        .iter()
        .map(|e| stored_u16(&fps.cfg, &e.image.adu))
        .collect();
    let names: Vec<(String, String)> = (1..=exp.arrays.len())
        .map(|k| (format!("ARRAY{k}"), format!("DQ{k}")))
        .collect();
    let mut hdus = vec![Hdu::Header {
        cards: primary_cards(fps, exp),
    }];
    for (((sim, e), u16_data), (name, dq)) in
        fps.arrays.iter().zip(&exp.arrays).zip(&stored).zip(&names)
    {
        let mut cards = headers(sim, e);
        cards.push(Card::i(
            "ARRAYIDX",
            sim.array.index as i64 + 1,
            "array number (1-4)",
        ));
        cards.push(Card::u(
            "ARRSEED",
            sim.array.seed,
            "seed of this array's flat/noise",
        ));
        let n = e.image.n;
        hdus.push(Hdu::Image {
            name,
            nx: n,
            ny: n,
            pixels: match u16_data {
                Some(d) => Pixels::U16(d),
                None => Pixels::F32(&e.image.adu),
            },
            cards,
        });
        hdus.push(Hdu::U8Image {
            name: dq,
            nx: n,
            ny: n,
            data: &e.image.dq,
        });
    }
    hdus.push(Hdu::Table {
        name: "TRUTH",
        columns: focal_plane_truth(fps, exp),
        cards: vec![],
    });
    hdus.push(Hdu::Text {
        name: "CONFIG",
        text: &config_text,
    });
    fits::write(path, &hdus)?;
    Ok(())
}
