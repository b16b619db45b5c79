//! The schemas of the output files (one place each): the analysis catalogue, ePSF and summary of
//! `jsim analyze`, the deviation vector map, the experiment's `experiment.csv` and `images.csv`, and the PSF
//! FITS of `jsim psf`. The CLI and the Python module write through these; docs/file-formats.md documents them.

pub mod files;

use super::IoError;
use super::csv::{self, Cell};
use super::fits::{self, Card, Hdu, Pixels};
use super::plot;
use crate::analysis::epsf::Epsf;
use crate::config::Config;
use crate::optics::psf::PsfTable;
use crate::scoring::dataset::{ImageResult, Row};
use crate::scoring::image::{Report, Scored, ScoredStar};
use crate::scoring::vectors::VectorMap;
use serde::Serialize;
use std::path::Path;

/// Columns of `catalogue.csv`.
pub const CATALOGUE_HEADER: [&str; 10] = [
    "x",
    "y",
    "flux_e",
    "sky_e",
    "crlb_x_mas",
    "crlb_y_mas",
    "flags",
    "truth_id",
    "dx_mas",
    "dy_mas",
];

/// Rows of `catalogue.csv`: one per detected star (`plate_scale_mas` per pixel; truth_id −1 when unmatched).
pub fn catalogue_rows(stars: &[ScoredStar], plate_scale_mas: f64) -> Vec<Vec<Cell>> {
    stars
        .iter()
        .map(|s| {
            vec![
                Cell::F(s.x),
                Cell::F(s.y),
                Cell::F(s.flux_e),
                Cell::F(s.sky_e),
                Cell::F(s.crlb_x_px * plate_scale_mas),
                Cell::F(s.crlb_y_px * plate_scale_mas),
                Cell::I(s.flags as i64),
                Cell::I(s.truth.map(|t| t as i64).unwrap_or(-1)),
                Cell::F(s.dx_px * plate_scale_mas),
                Cell::F(s.dy_px * plate_scale_mas),
            ]
        })
        .collect()
}

/// The cosmic-ray mask `jsim analyze` writes per chip of a calibrated file (`SCIk/cosmic_rays.fits`).
pub const COSMIC_RAYS_NAME: &str = "cosmic_rays.fits";

/// Write a chip's cosmic-ray mask: a 16-bit image, 1 where the analysis masked a cosmic ray (by comparison
/// with another exposure of the pointing, or by L.A.Cosmic), else 0.
pub fn write_cosmic_rays(path: &Path, nx: usize, ny: usize, mask: &[u16]) -> Result<(), IoError> {
    fits::write(
        path,
        &[Hdu::Image {
            name: "",
            nx,
            ny,
            pixels: Pixels::U16(mask),
            cards: vec![Card::s(
                "CONTENT",
                "cosmic rays masked by jsim",
                "1: a cosmic ray (comparison or L.A.Cosmic)",
            )],
        }],
    )
}

/// Columns of `repeatability.csv` (`jsim analyze` on exposures of one pointing): per pair of exposures and
/// flux bin, the repeatability of the fitted positions against their bounds (`analysis::repeat`).
pub const REPEAT_HEADER: [&str; 14] = [
    "exposure_a",
    "exposure_b",
    "flux_min_e",
    "flux_max_e",
    "n",
    "repeat_x_mas",
    "repeat_y_mas",
    "crlb_x_mas",
    "crlb_y_mas",
    "ratio_x",
    "ratio_y",
    "ratio_error",
    "offset_x_px",
    "offset_y_px",
];

/// The rows of `repeatability.csv` for the pair (`a`, `b`) (their labels), its bins and common offset.
pub fn repeat_rows(
    a: &str,
    b: &str,
    bins: &[crate::analysis::repeat::RepeatBin],
    offset_px: (f64, f64),
    plate_scale_mas: f64,
) -> Vec<Vec<Cell>> {
    bins.iter()
        .map(|r| {
            vec![
                Cell::S(a.to_string()),
                Cell::S(b.to_string()),
                Cell::F(r.flux_min_e),
                Cell::F(r.flux_max_e),
                Cell::I(r.n as i64),
                Cell::F(r.repeat_x_px * plate_scale_mas),
                Cell::F(r.repeat_y_px * plate_scale_mas),
                Cell::F(r.crlb_x_px * plate_scale_mas),
                Cell::F(r.crlb_y_px * plate_scale_mas),
                Cell::F(r.ratio_x),
                Cell::F(r.ratio_y),
                Cell::F(r.ratio_error),
                Cell::F(offset_px.0),
                Cell::F(offset_px.1),
            ]
        })
        .collect()
}

/// The columns `catalogue.csv` gains when the image's header has a celestial WCS that the analysis reads
/// (a calibrated chip of another observatory): each star's RA and Dec, degrees (ICRS, as the header's).
pub const SKY_HEADER: [&str; 2] = ["ra_deg", "dec_deg"];

/// `rows` (of [`catalogue_rows`]) with each star's RA, Dec through `wcs` appended (NaN where the
/// projection has none).
fn with_sky(
    mut rows: Vec<Vec<Cell>>,
    stars: &[ScoredStar],
    wcs: &crate::sky::wcs::ArrayWcs,
) -> Vec<Vec<Cell>> {
    for (r, s) in rows.iter_mut().zip(stars) {
        let (ra, dec) = wcs.pixel_to_sky(s.x, s.y).unwrap_or((f64::NAN, f64::NAN));
        r.extend([Cell::F(ra), Cell::F(dec)]);
    }
    rows
}

/// The columns and rows of `catalogue.csv`: [`CATALOGUE_HEADER`], and [`SKY_HEADER`] with each star's RA/Dec
/// when `sky` is given.
pub fn catalogue_table(
    stars: &[ScoredStar],
    plate_scale_mas: f64,
    sky: Option<&crate::sky::wcs::ArrayWcs>,
) -> (Vec<&'static str>, Vec<Vec<Cell>>) {
    let rows = catalogue_rows(stars, plate_scale_mas);
    let mut header = CATALOGUE_HEADER.to_vec();
    match sky {
        Some(w) => {
            header.extend(SKY_HEADER);
            (header, with_sky(rows, stars, w))
        }
        None => (header, rows),
    }
}

/// Write `catalogue.csv` (with RA/Dec through `sky`, when given).
pub fn write_catalogue(
    path: &Path,
    stars: &[ScoredStar],
    plate_scale_mas: f64,
    sky: Option<&crate::sky::wcs::ArrayWcs>,
) -> Result<(), IoError> {
    let (header, rows) = catalogue_table(stars, plate_scale_mas, sky);
    csv::write(path, &header, &rows)
}

/// An ePSF table as an image HDU (`epsf.fits`, the model PSF product): its nodes, nodes per pixel, origin
/// and normalisation, then `extra` cards.
pub fn epsf_hdu<'a>(name: &'a str, e: &'a Epsf, extra: Vec<Card>) -> Hdu<'a> {
    let n = e.n();
    let mut cards = vec![
        Card::i("OVERSAMP", e.oversampling as i64, "ePSF nodes per pixel"),
        Card::f("CRPIX1", e.half_nodes as f64 + 1.0, "origin (1-based)"),
        Card::f("CRPIX2", e.half_nodes as f64 + 1.0, "origin (1-based)"),
        Card::s("NORM", "sum = oversampling^2", "a star's pixels sum to 1"),
    ];
    cards.extend(extra);
    Hdu::Image {
        name,
        nx: n,
        ny: n,
        pixels: Pixels::F64(&e.data),
        cards,
    }
}

/// Write the ePSF table (`epsf.fits`): nodes per pixel, origin, normalisation and builder iterations.
pub fn write_epsf(path: &Path, e: &Epsf, iterations: usize) -> Result<(), IoError> {
    fits::write(
        path,
        &[epsf_hdu(
            "",
            e,
            vec![Card::i("ITER", iterations as i64, "builder iterations")],
        )],
    )
}

/// `summary.json` of `jsim analyze`.
#[derive(Debug, Clone, Serialize)]
pub struct Summary<'a> {
    pub image: String,
    pub plate_scale_mas: f64,
    pub countermeasure: &'a str,
    pub report: &'a Report,
    /// What the analysis assumed where the image did not say (empty when it said everything).
    pub assumptions: Vec<String>,
    /// What was read of a calibrated chip of another observatory (its unit, read noise, masked pixels).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<&'a super::calibrated::ChipFacts>,
    pub seconds: f64,
}

/// Write `summary.json`.
pub fn write_summary(path: &Path, s: &Summary<'_>) -> Result<(), IoError> {
    let text = serde_json::to_string_pretty(s).map_err(|e| IoError::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    super::write_atomic(path, text.as_bytes())
}

/// Everything `jsim analyze` writes for one analysis: `catalogue.csv`, `epsf.fits`, `summary.json`, and
/// the vector map when the truth was known.
pub fn write_analysis(
    dir: &Path,
    analysis: &Scored,
    summary: &Summary<'_>,
    vectors: Option<(&VectorMap, f64, &str)>,
    sky: Option<&crate::sky::wcs::ArrayWcs>,
) -> Result<(), IoError> {
    write_catalogue(
        &dir.join(crate::io::products::files::CATALOGUE_CSV),
        &analysis.stars,
        summary.plate_scale_mas,
        sky,
    )?;
    write_epsf(
        &dir.join(crate::io::products::files::EPSF_FITS),
        &analysis.epsf,
        analysis.report.epsf_iterations,
    )?;
    write_summary(&dir.join(crate::io::products::files::SUMMARY_JSON), summary)?;
    if let Some((map, extent_px, title)) = vectors {
        write_vectors(dir, "vectors", map, extent_px, title)?;
    }
    Ok(())
}

/// Columns of a vector map's CSV.
pub const VECTORS_HEADER: [&str; 6] = [
    "x",
    "y",
    "dx_mas",
    "dy_mas",
    "predicted_dx_mas",
    "predicted_dy_mas",
];

/// Write a deviation vector map as `DIR/STEM.csv` and `DIR/STEM.png` (`extent_px`: the detector size).
pub fn write_vectors(
    dir: &Path,
    stem: &str,
    map: &VectorMap,
    extent_px: f64,
    title: &str,
) -> Result<(), IoError> {
    let rows: Vec<Vec<Cell>> = map
        .measured
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let p = map.predicted.get(k);
            vec![
                Cell::F(a.x_px),
                Cell::F(a.y_px),
                Cell::F(a.dx_mas),
                Cell::F(a.dy_mas),
                Cell::F(p.map(|p| p.dx_mas).unwrap_or(0.0)),
                Cell::F(p.map(|p| p.dy_mas).unwrap_or(0.0)),
            ]
        })
        .collect();
    csv::write(&dir.join(format!("{stem}.csv")), &VECTORS_HEADER, &rows)?;
    let set = |v: &[crate::scoring::vectors::Arrow]| -> Vec<(f64, f64, f64, f64)> {
        v.iter()
            .map(|a| (a.x_px, a.y_px, a.dx_mas, a.dy_mas))
            .collect()
    };
    let mut sets = vec![(
        "fitted − true (mean removed)".to_string(),
        set(&map.measured),
    )];
    if !map.predicted.is_empty() {
        sets.push((
            "ACE-predicted displacement".to_string(),
            set(&map.predicted),
        ));
    }
    plot::vector_map(
        &dir.join(format!("{stem}.png")),
        title,
        &sets,
        extent_px,
        map.reference_mas,
        60.0,
    )?;
    Ok(())
}

/// Columns of `experiment.csv`: one row per dataset and countermeasure.
pub const EXPERIMENT_HEADER: [&str; 10] = [
    "ace",
    "readout",
    "countermeasure",
    "mag",
    "accuracy_mas",
    "sem_mas",
    "crlb_mas",
    "predicted_mas",
    "n_images",
    "time_s",
];

/// Write `experiment.csv`.
pub fn write_experiment(path: &Path, rows: &[Row]) -> Result<(), IoError> {
    csv::write(path, &EXPERIMENT_HEADER, &experiment_rows(rows))
}

/// The rows of `experiment.csv` ([`EXPERIMENT_HEADER`]).
pub fn experiment_rows(rows: &[Row]) -> Vec<Vec<Cell>> {
    rows.iter()
        .map(|r| {
            vec![
                Cell::S(r.ace.clone()),
                Cell::S(r.readout.clone()),
                Cell::S(r.countermeasure.clone()),
                Cell::F(r.mag),
                Cell::F(r.accuracy_mas),
                Cell::F(r.sem_mas),
                Cell::F(r.crlb_mas),
                Cell::F(r.predicted_mas),
                Cell::I(r.n_images as i64),
                Cell::F(r.time_s),
            ]
        })
        .collect()
}

/// Columns of `images.csv`: one row per image and countermeasure.
pub const IMAGES_HEADER: [&str; 26] = [
    "ace",
    "readout",
    "countermeasure",
    "mag",
    "image",
    "accuracy_mas",
    "accuracy_x_mas",
    "accuracy_y_mas",
    "crlb_mas",
    "phase_bias_mas",
    "predicted_rms_mas",
    "pred_corr_x",
    "pred_corr_y",
    "pred_slope_x",
    "pred_slope_y",
    "response_corr_x",
    "response_corr_y",
    "response_slope_x",
    "response_slope_y",
    "n_used",
    "dof_absorbed",
    "stare_exposures",
    "ace_sigma_mas",
    "ace_drift_mas",
    "simulate_s",
    "analyse_s",
];

/// Rows of `images.csv` for the images of one dataset of `cfg`.
pub fn image_rows(cfg: &Config, images: &[ImageResult]) -> Vec<Vec<Cell>> {
    let mut out = Vec::new();
    for im in images {
        for m in &im.measured {
            let r = &m.report;
            out.push(vec![
                Cell::S(cfg.ace.case.name().into()),
                Cell::S(cfg.readout.order.name().into()),
                Cell::S(m.countermeasure.clone()),
                Cell::F(cfg.scene.mag_hw),
                Cell::I(im.index as i64),
                Cell::F(r.accuracy_mas),
                Cell::F(r.accuracy_x_mas),
                Cell::F(r.accuracy_y_mas),
                Cell::F(r.crlb_median_mas),
                Cell::F(r.phase_bias_x_mas.max(r.phase_bias_y_mas)),
                Cell::F(r.predicted_rms_mas),
                Cell::F(r.predicted_corr_x),
                Cell::F(r.predicted_corr_y),
                Cell::F(r.predicted_slope_x),
                Cell::F(r.predicted_slope_y),
                Cell::F(r.response_corr_x),
                Cell::F(r.response_corr_y),
                Cell::F(r.response_slope_x),
                Cell::F(r.response_slope_y),
                Cell::I(r.n_used as i64),
                Cell::I(r.dof_absorbed as i64),
                r.stare_exposures
                    .map_or(Cell::S(String::new()), |n| Cell::I(n as i64)),
                Cell::F(im.ace_sigma_mas),
                Cell::F(im.ace_drift_mas),
                Cell::F(im.simulate_s),
                Cell::F(im.analyse_s),
            ]);
        }
    }
    out
}

/// Write `images.csv`.
pub fn write_images(path: &Path, rows: &[Vec<Cell>]) -> Result<(), IoError> {
    csv::write(path, &IMAGES_HEADER, rows)
}

/// The header cards of a PSF table written by `jsim psf`: sampling, wavelengths, FWHM and encircled
/// energies, provenance.
pub fn psf_cards(cfg: &Config, psf: &PsfTable) -> Vec<Card> {
    let scale = cfg.instrument.plate_scale_mas();
    let os = psf.oversampling as f64;
    let grid = cfg.band.wavelength_grid();
    vec![
        Card::s("BUNIT", "fraction", "fraction of the total flux per cell"),
        Card::i(
            "OVERSAMP",
            psf.oversampling as i64,
            "cells per detector pixel",
        ),
        Card::f("CDELT1", 1.0 / os, "[pix] cell size"),
        Card::f("CDELT2", 1.0 / os, "[pix] cell size"),
        Card::f(
            "CRPIX1",
            psf.half_cells as f64 + 1.0,
            "optical axis (1-based FITS pixel)",
        ),
        Card::f(
            "CRPIX2",
            psf.half_cells as f64 + 1.0,
            "optical axis (1-based FITS pixel)",
        ),
        Card::f("CELLMAS", scale / os, "[mas] cell size on the sky"),
        Card::f("PLTSCALE", scale, "[mas/pix] detector plate scale"),
        Card::f(
            "LAMMIN",
            grid.first().copied().unwrap_or(0.0),
            "[um] shortest wavelength",
        ),
        Card::f(
            "LAMMAX",
            grid.last().copied().unwrap_or(0.0),
            "[um] longest wavelength",
        ),
        Card::i("NLAMBDA", grid.len() as i64, "wavelengths summed"),
        Card::f(
            "LAMEFF",
            crate::optics::spectrum::effective_wavelength_um(&cfg.band, cfg.scene.j_minus_h),
            "[um] photon-weighted",
        ),
        Card::f("JMINUSH", cfg.scene.j_minus_h, "stellar colour"),
        Card::s(
            "METHOD",
            format!("{:?}", cfg.optics.psf_method),
            "PSF method",
        ),
        Card::i(
            "NPUPIL",
            cfg.optics.pupil_samples as i64,
            "pupil samples across",
        ),
        Card::f("FWHM", psf.fwhm_px() * scale, "[mas] FWHM"),
        Card::f(
            "EE1PX",
            psf.encircled_energy(1.0),
            "encircled energy within 1 pix",
        ),
        Card::f(
            "EE3PX",
            psf.encircled_energy(3.0),
            "encircled energy within 3 pix",
        ),
        Card::f("TABFRAC", psf.sum(), "flux fraction inside this table"),
        Card::s("CONFHASH", cfg.hash_hex(), "config hash"),
        Card::s(
            "ENGINE",
            format!("jsim {}", crate::VERSION),
            "simulator version",
        ),
    ]
}

/// Write the PSF table with its cards and the configuration (`jsim psf`).
pub fn write_psf(path: &Path, cfg: &Config, psf: &PsfTable) -> Result<(), IoError> {
    let n = psf.n();
    let text = cfg.to_toml();
    fits::write(
        path,
        &[
            Hdu::Image {
                name: "",
                nx: n,
                ny: n,
                pixels: Pixels::F64(&psf.data),
                cards: psf_cards(cfg, psf),
            },
            Hdu::Text {
                name: "CONFIG",
                text: &text,
            },
        ],
    )
}

/// The accuracy-against-magnitude figure of an experiment (`accuracy.png`): the mean accuracy ± s.e.m. per
/// curve, the Cramér–Rao bound and the 4-mas requirement.
pub fn plot_accuracy(path: &Path, rows: &[Row]) -> Result<(), IoError> {
    use super::plot::{Scale, Series, line_plot};
    // one curve per (readout, countermeasure) of the realistic ACE; the static ACE cases only with the plain
    // analysis (their countermeasures change nothing and would hide the curves that matter); the exact-ePSF
    // control is in the CSV
    let mut keys: Vec<(String, String, String)> = Vec::new();
    for r in rows {
        let shown = r.countermeasure != "exact-epsf"
            && (r.ace == "realistic" || r.countermeasure == "none");
        let k = (r.ace.clone(), r.readout.clone(), r.countermeasure.clone());
        if shown && !keys.contains(&k) {
            keys.push(k);
        }
    }
    let mut series: Vec<Series> = keys
        .iter()
        .map(|(a, ro, c)| {
            let pts: Vec<&Row> = rows
                .iter()
                .filter(|r| &r.ace == a && &r.readout == ro && &r.countermeasure == c)
                .collect();
            let label = if a == "realistic" {
                format!("{a} ACE, {ro}, {c}")
            } else {
                format!("{a} ACE, {c}")
            };
            Series {
                label,
                x: pts.iter().map(|r| r.mag).collect(),
                y: pts.iter().map(|r| r.accuracy_mas).collect(),
                yerr: Some(pts.iter().map(|r| r.sem_mas).collect()),
                yerr_below: None,
            }
        })
        .collect();
    // the bound of the plain analysis, once per ACE case
    for a in ["gaussian", "realistic"] {
        let pts: Vec<&Row> = rows
            .iter()
            .filter(|r| r.ace == a && r.countermeasure == "none")
            .collect();
        if !pts.is_empty() && (a == "gaussian" || !rows.iter().any(|r| r.ace == "gaussian")) {
            let mut seen = Vec::new();
            let mut x = Vec::new();
            let mut y = Vec::new();
            for p in pts {
                if !seen.contains(&p.mag.to_bits()) {
                    seen.push(p.mag.to_bits());
                    x.push(p.mag);
                    y.push(p.crlb_mas);
                }
            }
            series.push(Series {
                label: format!("Cramér–Rao bound ({a})"),
                x,
                y,
                yerr: None,
                yerr_below: None,
            });
        }
    }
    line_plot(
        path,
        "Single-exposure position accuracy (mean over images ± s.e.m.)",
        "Hw magnitude",
        "accuracy per axis [mas]",
        &series,
        &[(4.0, "4 mas requirement".to_string())],
        Scale::Linear,
        Scale::Log,
    )?;
    Ok(())
}
