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
//! * **Design model PSF** (`psf_model.fits`): the PSF of the design wavefront at the field centre for the
//!   scene's colour, integrated over the pixel response and sampled as an ePSF table (the `epsf.fits` format:
//!   `OVERSAMP` nodes per pixel, origin at `CRPIX1/2`, a star's pixels sum to 1). The analysis falls back to it
//!   when an image has too few stars to build its own ePSF. One array: the primary HDU; the focal plane:
//!   `PSF1` … `PSF4` (each array's axes).
//! * **Attitude telemetry** (`telemetry_NNN.fits`, one per exposure): the telescope attitude as the
//!   spacecraft records it — sampled at the telemetry rate with its white and correlated errors and latency,
//!   not the true series ([`write_telemetry`]).
//! * **Reference astrometric catalogue** (`refcat.csv`): what a survey gives of the field ([`SurveyModel`]:
//!   magnitude-dependent errors, a limiting magnitude, incompleteness), with each star's position on the sky
//!   and in the pixels of its array through the array's design WCS. The `plate-*@catalogue` countermeasures
//!   of `jsim analyze` fit to it, cross-matched by position.

use super::IoError;
use super::fits::{self, Card, Hdu, Pixels};
use crate::simulate::Simulator;
use std::path::{Path, PathBuf};

/// File name of the calibration flat beside the images.
pub const FLAT_NAME: &str = crate::io::products::files::FLAT_CAL_FITS;

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
        Card::u("SEED", sim.cfg.seed, "master random seed"),
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

/// Whether `arrays` write their products in the single-array form (the primary HDU; `array` = 0 in
/// `refcat.csv`) rather than the focal plane's (an empty primary and one extension per array).
fn single_form(arrays: &[Simulator]) -> bool {
    arrays.len() == 1 && arrays[0].cfg.focal_plane.layout == crate::config::Layout::Single
}

/// Write the calibration flats of a focal plane's arrays into `dir` (none when the analysis is
/// uncalibrated): the path written. One array: the primary HDU; the quad: `FLAT1` … in one file.
pub fn write_calibration_flat(
    dir: &Path,
    arrays: &(impl AsRef<[Simulator]> + ?Sized),
) -> Result<Option<PathBuf>, IoError> {
    let arrays = arrays.as_ref();
    let Some(crate::config::FlatField::Calibrated { error }) =
        arrays.first().map(|a| a.cfg.analysis.flat_field)
    else {
        return Ok(None);
    };
    let flats: Vec<_> = arrays.iter().filter_map(|s| s.calibration_flat()).collect();
    let single = single_form(arrays);
    let names: Vec<String> = if single {
        vec![String::new()]
    } else {
        (0..arrays.len()).map(flat_extension).collect()
    };
    let mut hdus = Vec::with_capacity(arrays.len() + 1);
    if !single {
        hdus.push(Hdu::Header {
            cards: vec![
                Card::i("NARRAYS", arrays.len() as i64, "arrays: extensions FLAT1.."),
                Card::f("FLATERR", error, "relative 1-sigma error per pixel"),
                Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
            ],
        });
    }
    for ((sim, flat), name) in arrays.iter().zip(&flats).zip(&names) {
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

/// File name of the reference astrometric catalogue beside the images.
pub const REFCAT_NAME: &str = crate::io::products::files::REFCAT_CSV;

/// Columns of `refcat.csv`.
pub const REFCAT_HEADER: [&str; 8] = [
    "id",
    "array",
    "ra_deg",
    "dec_deg",
    "x_px",
    "y_px",
    "hw",
    "sigma_mas",
];

/// The survey a reference catalogue comes from: its position error against magnitude, its limiting
/// magnitude and its completeness (the knobs of `jsim simulate --refcat-*`).
///
/// Position error per axis `σ(Hw) = floor_mas · max(1, 10^{0.2 (Hw − knee_hw)})`: a systematic floor for
/// bright stars, photon-limited (∝ flux^{−1/2}) fainter than the knee. Defaults — chosen, not fitted to a
/// survey: a 2-mas floor (the plate model's `DEFAULT_CATALOGUE_ERROR_MAS`, a Gaia-DR3-like star of
/// G ≈ 17–18 propagated to the epoch), the knee at Hw 14, a limit of Hw 16.5 (the JASMINE pilot
/// catalogue's completeness in Hw, from 2MASS + SIRIUS + VVV: JASMINE-Mission/pilot_catalog) and 98 %
/// completeness above it. Its magnitudes carry a Gaussian error of 0.05 mag (chosen: VVV/SIRIUS photometry
/// of a few hundredths at these magnitudes, plus the transformation from their bands to Hw). The catalogue
/// is at the observation epoch (jsim's stars do not move yet): no proper motions, no epoch propagation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurveyModel {
    pub floor_mas: f64,
    pub knee_hw: f64,
    pub limit_hw: f64,
    pub completeness: f64,
    /// Error of its magnitudes, mag (Gaussian): a survey's photometry transformed to Hw from its own bands.
    pub phot_sigma_mag: f64,
}

impl Default for SurveyModel {
    fn default() -> Self {
        Self {
            floor_mas: crate::analysis::countermeasures::DEFAULT_CATALOGUE_ERROR_MAS,
            knee_hw: 14.0,
            limit_hw: 16.5,
            completeness: 0.98,
            phot_sigma_mag: 0.05,
        }
    }
}

impl SurveyModel {
    /// Check every knob, naming it and its allowed range.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.floor_mas > 0.0 && self.floor_mas <= 1e5) {
            return Err(format!(
                "--refcat-floor-mas {}: allowed (0, 100000] mas",
                self.floor_mas
            ));
        }
        for (name, v) in [("knee-hw", self.knee_hw), ("limit-hw", self.limit_hw)] {
            if !(-5.0..=40.0).contains(&v) {
                return Err(format!("--refcat-{name} {v}: allowed [-5, 40]"));
            }
        }
        if !(self.completeness > 0.0 && self.completeness <= 1.0) {
            return Err(format!(
                "--refcat-completeness {}: allowed (0, 1]",
                self.completeness
            ));
        }
        if !(0.0..=5.0).contains(&self.phot_sigma_mag) {
            return Err(format!(
                "--refcat-phot-sigma-mag {}: allowed [0, 5] mag",
                self.phot_sigma_mag
            ));
        }
        Ok(())
    }

    /// Position error per axis of a star of magnitude `hw` [mas].
    pub fn sigma_mas(&self, hw: f64) -> f64 {
        self.floor_mas * 10f64.powf(0.2 * (hw - self.knee_hw)).max(1.0)
    }
}

/// One star of a reference catalogue, in the pixels of its array (through the array's design WCS).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefStar {
    pub id: usize,
    /// 1 … 4 on the focal plane, 0 for a single array.
    pub array: u32,
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub x_px: f64,
    pub y_px: f64,
    pub hw: f64,
    pub sigma_mas: f64,
}

impl RefStar {
    /// The star as the analysis reads it: position in its array's pixels and Hw.
    pub fn catalogue_star(&self) -> crate::analysis::crowded::forced::CatalogueStar {
        crate::analysis::crowded::forced::CatalogueStar {
            x_px: self.x_px,
            y_px: self.y_px,
            hw: self.hw,
        }
    }
}

/// The reference catalogue a survey would give of a simulator's stars (seeded: its own stream of the run
/// seed, per star): those brighter than the limit, each kept with the survey's completeness, at its true
/// position plus a Gaussian error of σ(Hw) per axis.
pub fn reference_catalogue(sim: &Simulator, survey: &SurveyModel, array: u32) -> Vec<RefStar> {
    use crate::rng::{self, Stream};
    use rand::RngExt;
    use rand_distr::{Distribution, StandardNormal};
    let scale = sim.cfg.instrument.plate_scale_mas();
    sim.stars
        .iter()
        .filter(|s| s.in_truth && s.mag_hw.is_finite() && s.mag_hw <= survey.limit_hw)
        .filter_map(|s| {
            let mut r = rng::stream(sim.cfg.seed, Stream::ReferenceCatalogue, s.id as u64);
            let sigma = survey.sigma_mas(s.mag_hw);
            let (zx, zy): (f64, f64) =
                (StandardNormal.sample(&mut r), StandardNormal.sample(&mut r));
            let kept = r.random::<f64>() < survey.completeness;
            // drawn after the others, so that the positions and the kept stars are those of a catalogue
            // without photometric errors
            let zm: f64 = StandardNormal.sample(&mut r);
            kept.then(|| {
                // a sky catalogue: the star's true direction with the survey's error (through the WCS as
                // built, where the star truly lies) …
                let (x, y) = (s.x_px + zx * sigma / scale, s.y_px + zy * sigma / scale);
                let (ra, dec) = sim
                    .wcs()
                    .and_then(|w| w.pixel_to_sky(x, y))
                    .unwrap_or((f64::NAN, f64::NAN));
                // … and its pixel columns through the header's (design) WCS; the same pixels when the two agree
                let (x, y) = if sim.wcs_deviates() {
                    sim.design_wcs()
                        .and_then(|w| w.sky_to_pixel(ra, dec))
                        .unwrap_or((f64::NAN, f64::NAN))
                } else {
                    (x, y)
                };
                RefStar {
                    id: s.id,
                    array,
                    ra_deg: ra,
                    dec_deg: dec,
                    x_px: x,
                    y_px: y,
                    hw: s.mag_hw + zm * survey.phot_sigma_mag,
                    sigma_mas: sigma,
                }
            })
        })
        .collect()
}

fn refcat_rows(stars: &[RefStar]) -> Vec<Vec<super::csv::Cell>> {
    use super::csv::Cell;
    stars
        .iter()
        .map(|s| {
            vec![
                Cell::I(s.id as i64),
                Cell::I(s.array as i64),
                Cell::F(s.ra_deg),
                Cell::F(s.dec_deg),
                Cell::F(s.x_px),
                Cell::F(s.y_px),
                Cell::F(s.hw),
                Cell::F(s.sigma_mas),
            ]
        })
        .collect()
}

/// Write the reference catalogue of a focal plane's arrays (`refcat.csv`) into `dir`: `array` = 0 for the
/// single array, 1 … 4 in the quad.
pub fn write_reference_catalogue(
    dir: &Path,
    arrays: &(impl AsRef<[Simulator]> + ?Sized),
    survey: &SurveyModel,
) -> Result<PathBuf, IoError> {
    let arrays = arrays.as_ref();
    let single = single_form(arrays);
    let stars: Vec<RefStar> = arrays
        .iter()
        .flat_map(|s| {
            let array = if single { 0 } else { s.array.index as u32 + 1 };
            reference_catalogue(s, survey, array)
        })
        .collect();
    let path = dir.join(REFCAT_NAME);
    super::csv::write(&path, &REFCAT_HEADER, &refcat_rows(&stars))?;
    Ok(path)
}

/// Read a reference catalogue (`refcat.csv`: the columns of [`REFCAT_HEADER`]; `array` optional), keeping
/// the stars of `array` (0: every star of a single-array catalogue).
pub fn read_reference_catalogue(path: &Path, array: u32) -> Result<Vec<RefStar>, IoError> {
    let (h, rows) = super::csv::read(path)?;
    let col = |name: &str| super::csv::column_f64(path, &h, &rows, name);
    let (x, y, sigma) = (col("x_px")?, col("y_px")?, col("sigma_mas")?);
    let opt = |name: &str| {
        if h.iter().any(|c| c == name) {
            col(name).map(Some)
        } else {
            Ok(None)
        }
    };
    let (id, arr, ra, dec, hw) = (
        opt("id")?,
        opt("array")?,
        opt("ra_deg"),
        opt("dec_deg"),
        opt("hw")?,
    );
    if let Some(bad) = sigma.iter().find(|s| !(**s > 0.0)) {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("sigma_mas = {bad}: every error must be > 0 mas"),
        });
    }
    // ra/dec may hold NaN (a catalogue without a WCS): read them leniently
    let ra = ra.ok().flatten();
    let dec = dec.ok().flatten();
    Ok((0..x.len())
        .filter(|&k| array == 0 || arr.as_ref().is_none_or(|a| a[k] as u32 == array))
        .map(|k| RefStar {
            id: id.as_ref().map(|v| v[k] as usize).unwrap_or(k),
            array: arr.as_ref().map(|a| a[k] as u32).unwrap_or(0),
            ra_deg: ra.as_ref().map(|v| v[k]).unwrap_or(f64::NAN),
            dec_deg: dec.as_ref().map(|v| v[k]).unwrap_or(f64::NAN),
            x_px: x[k],
            y_px: y[k],
            hw: hw.as_ref().map(|v| v[k]).unwrap_or(f64::NAN),
            sigma_mas: sigma[k],
        })
        .collect())
}

/// The reference catalogue to use for an image: the one given, else `refcat.csv` beside the image.
pub fn find_reference_catalogue(image: &Path, given: Option<&Path>) -> Option<PathBuf> {
    match given {
        Some(p) => Some(p.to_path_buf()),
        None => {
            let p = image.parent().unwrap_or(Path::new(".")).join(REFCAT_NAME);
            p.exists().then_some(p)
        }
    }
}

/// File name of the design model PSF beside the images.
pub const MODEL_PSF_NAME: &str = crate::io::products::files::PSF_MODEL_FITS;

/// The design model PSF of a simulation as an ePSF table (8 nodes per pixel, `analysis.epsf_radius_px`).
pub fn model_psf(
    sim: &Simulator,
) -> Result<crate::analysis::epsf::Epsf, crate::simulate::SimError> {
    Ok(crate::analysis::pipeline::exact_epsf(
        &*sim.design_kernel()?,
        sim.cfg.analysis.epsf_radius_px,
    ))
}

/// The design model PSF's change per nm rms of each low-order term ([`crate::optics::zernike::LOW_ORDER_TERMS`]: Z4 …
/// Z11), on its grid: `(ψ(+h) − ψ(−h)) / 2h` from the design kernels with the term moved by ∓ h =
/// [`crate::simulate::TERM_STEP_NM`]; single precision, as the file holds them.
pub fn model_psf_terms(
    sim: &Simulator,
) -> Result<Vec<crate::analysis::epsf::Epsf>, crate::simulate::SimError> {
    let radius = sim.cfg.analysis.epsf_radius_px;
    let h = crate::simulate::TERM_STEP_NM;
    Ok(sim
        .design_term_kernels()?
        .iter()
        .map(|(minus, plus)| {
            let (m, p) = (
                crate::analysis::pipeline::exact_epsf(minus, radius),
                crate::analysis::pipeline::exact_epsf(plus, radius),
            );
            let mut d = p.clone();
            for (v, (a, b)) in d.data.iter_mut().zip(p.data.iter().zip(&m.data)) {
                *v = ((a - b) / (2.0 * h)) as f32 as f64;
            }
            d
        })
        .collect())
}

/// [`model_psf`] as `psf_model.fits` holds it (single precision): what an analysis in memory is handed, so
/// that it equals the analysis of the written file.
pub fn model_psf_product(
    sim: &Simulator,
) -> Result<crate::analysis::epsf::Epsf, crate::simulate::SimError> {
    let mut e = model_psf(sim)?;
    for v in e.data.iter_mut() {
        *v = *v as f32 as f64;
    }
    Ok(e)
}

fn model_psf_hdu<'a>(
    name: &'a str,
    e: &'a crate::analysis::epsf::Epsf,
    sim: &Simulator,
) -> Hdu<'a> {
    super::products::epsf_hdu(
        name,
        e,
        vec![
            Card::s(
                "CONTENT",
                "design model PSF",
                "design wavefront, field centre",
            ),
            Card::s("CONFHASH", sim.cfg.hash_hex(), "configuration hash"),
            Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
        ],
    )
}

fn model_psf_error(e: crate::simulate::SimError, path: &Path) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        message: format!("the design model PSF: {e}"),
    }
}

/// The extension of the derivative plane of Fringe term `j` (1-based) in `psf_model.fits`.
pub fn model_psf_term_extension(j: usize) -> String {
    format!("DZ{j}")
}

/// The single array's design model PSF (the primary HDU of `psf_model.fits`) into `dir`; with its
/// derivative planes per low-order term (`DZ4` … `DZ11`, [`model_psf_terms`]) when the configuration's analysis
/// corrects it by the stars (`analysis.telemetry_kernel = "design-fitted"`: 16 more PSFs to compute).
fn write_single_model_psf(dir: &Path, sim: &Simulator) -> Result<PathBuf, IoError> {
    let path = dir.join(MODEL_PSF_NAME);
    let e = model_psf(sim).map_err(|e| model_psf_error(e, &path))?;
    let terms = match sim.cfg.analysis.telemetry_kernel {
        crate::config::TelemetryKernel::DesignFitted => {
            model_psf_terms(sim).map_err(|e| model_psf_error(e, &path))?
        }
        _ => Vec::new(),
    };
    let names: Vec<String> = crate::optics::zernike::LOW_ORDER_TERMS
        .iter()
        .map(|&j| model_psf_term_extension(j))
        .collect();
    let mut hdus = vec![model_psf_hdu("", &e, sim)];
    for ((t, name), j) in terms
        .iter()
        .zip(&names)
        .zip(crate::optics::zernike::LOW_ORDER_TERMS)
    {
        hdus.push(super::products::epsf_hdu(
            name.as_str(),
            t,
            vec![
                Card::s(
                    "CONTENT",
                    format!("d(design PSF)/d(Z{j}) per nm rms"),
                    "the PSF's change per nm rms of wavefront",
                ),
                Card::f(
                    "TERMSTEP",
                    crate::simulate::TERM_STEP_NM,
                    "[nm rms] central-difference step",
                ),
            ],
        ));
    }
    fits::write(&path, &hdus)?;
    Ok(path)
}

/// The derivative planes of a model PSF file (`DZ4` … `DZ11`), `None` when it holds none; all of them or an
/// error naming the one missing.
pub fn read_model_psf_terms(
    path: &Path,
) -> Result<Option<Vec<crate::analysis::epsf::Epsf>>, IoError> {
    let names = fits::extension_names(path)?;
    let wanted: Vec<String> = crate::optics::zernike::LOW_ORDER_TERMS
        .iter()
        .map(|&j| model_psf_term_extension(j))
        .collect();
    if !wanted.iter().any(|w| names.contains(w)) {
        return Ok(None);
    }
    let mut out = Vec::with_capacity(wanted.len());
    for w in &wanted {
        if !names.contains(w) {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                message: format!(
                    "the model PSF's derivative planes lack {w} (expected {wanted:?})"
                ),
            });
        }
        let mut e = read_model_psf(path, Some(w))?;
        // a derivative plane is signed: read_model_psf's checks hold, nothing is normalised
        e.data.iter_mut().for_each(|v| *v = *v as f32 as f64);
        out.push(e);
    }
    Ok(Some(out))
}

/// The extension of array `k` (0-based) in a focal-plane model PSF file.
pub fn model_psf_extension(k: usize) -> String {
    format!("PSF{}", k + 1)
}

/// Write the design model PSFs of a focal plane's arrays (`psf_model.fits`) into `dir`. One array: the
/// primary HDU, with the derivative planes when its analysis asks for them ([`write_single_model_psf`]);
/// the quad: `PSF1` … in one file (each array's axes).
pub fn write_model_psf(
    dir: &Path,
    arrays: &(impl AsRef<[Simulator]> + ?Sized),
) -> Result<PathBuf, IoError> {
    let arrays = arrays.as_ref();
    if let (true, Some(sim)) = (single_form(arrays), arrays.first()) {
        return write_single_model_psf(dir, sim);
    }
    let path = dir.join(MODEL_PSF_NAME);
    let psfs = arrays
        .iter()
        .map(model_psf)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| model_psf_error(e, &path))?;
    let names: Vec<String> = (0..arrays.len()).map(model_psf_extension).collect();
    let mut hdus = vec![Hdu::Header {
        cards: vec![
            Card::i("NARRAYS", arrays.len() as i64, "arrays: extensions PSF1.."),
            Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
        ],
    }];
    for ((sim, e), name) in arrays.iter().zip(&psfs).zip(&names) {
        hdus.push(model_psf_hdu(name.as_str(), e, sim));
    }
    fits::write(&path, &hdus)?;
    Ok(path)
}

/// Read a model PSF (an ePSF table: `epsf.fits` or `psf_model.fits`; `ext` as for the flat).
pub fn read_model_psf(
    path: &Path,
    ext: Option<&str>,
) -> Result<crate::analysis::epsf::Epsf, IoError> {
    let (nx, ny, data) = fits::read_plane(path, ext)?;
    let os = fits::read_f64_key_in(path, ext, "OVERSAMP")?;
    let bad = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if nx != ny || nx % 2 == 0 {
        return Err(bad(format!(
            "a model PSF table is square and odd, not {nx}×{ny}"
        )));
    }
    if !((1.0..=64.0).contains(&os) && os.fract() == 0.0) {
        return Err(bad(format!(
            "header OVERSAMP = {os}: a whole number in [1, 64]"
        )));
    }
    if data.iter().any(|v| !v.is_finite()) {
        return Err(bad("a model PSF value is not finite".into()));
    }
    Ok(crate::analysis::epsf::Epsf {
        oversampling: os as usize,
        half_nodes: nx / 2,
        data: data.iter().map(|v| *v as f64).collect(),
    })
}

/// The model PSF to use for an image: the one given, else `psf_model.fits` beside the image.
pub fn find_model_psf(image: &Path, given: Option<&Path>) -> Option<PathBuf> {
    match given {
        Some(p) => Some(p.to_path_buf()),
        None => {
            let p = image
                .parent()
                .unwrap_or(Path::new("."))
                .join(MODEL_PSF_NAME);
            p.exists().then_some(p)
        }
    }
}

pub use crate::io::products::files::telemetry_name;

/// Write the attitude telemetry of exposure `index` as the spacecraft records it under `quality` (one
/// binary table `ATTITUDE`: `T_S` in the ACE series' time, `ATT_X_MAS`, `ATT_Y_MAS` the telescope's attitude
/// with the recording's errors and latency) into `dir`; none for a static ACE (nothing moves). The
/// recording is the one the in-memory analysis makes (same stream of the run seed).
pub fn write_telemetry(
    dir: &Path,
    sim: &Simulator,
    index: usize,
    quality: &crate::analysis::countermeasures::TelemetryQuality,
) -> Result<Option<PathBuf>, IoError> {
    let Some(series) = sim.series() else {
        return Ok(None);
    };
    let path = dir.join(telemetry_name(index));
    let rec = crate::analysis::countermeasures::telemetry::TelemetryRecord::record(
        series,
        sim.timing.span_s(),
        sim.exposure_start_s(index),
        quality,
        sim.cfg.seed,
    )
    .map_err(|e| IoError::Format {
        path: path.clone(),
        message: e.to_string(),
    })?;
    let t: Vec<f64> = (0..rec.x_mas.len())
        .map(|k| rec.t0_s + k as f64 * rec.dt_s)
        .collect();
    fits::write(
        &path,
        &[
            Hdu::Header {
                cards: vec![
                    Card::i(
                        "IMAGEIDX",
                        index as i64,
                        "the exposure this telemetry covers",
                    ),
                    Card::s("ORIGIN", "jsim", "JASMINE image simulator"),
                ],
            },
            Hdu::Table {
                name: "ATTITUDE",
                columns: vec![
                    fits::Column::F64("T_S".into(), t),
                    fits::Column::F64("ATT_X_MAS".into(), rec.x_mas.clone()),
                    fits::Column::F64("ATT_Y_MAS".into(), rec.y_mas.clone()),
                ],
                cards: vec![
                    Card::f(
                        "TSTART",
                        rec.exposure_start_s,
                        "[s] exposure start, series time",
                    ),
                    Card::f("DT_S", rec.dt_s, "[s] sample interval"),
                    Card::f("RATE_HZ", quality.rate_hz, "[Hz] telemetry rate"),
                    Card::f(
                        "NOISEMAS",
                        quality.noise_mas,
                        "[mas] white noise per sample",
                    ),
                    Card::f("LATENCY", quality.latency_s, "[s] latency"),
                    Card::f(
                        "CORRMAS",
                        quality.correlated_mas,
                        "[mas] correlated error rms",
                    ),
                    Card::f(
                        "CORRTAU",
                        quality.correlation_time_s,
                        "[s] its correlation time",
                    ),
                    Card::i(
                        "IMAGEIDX",
                        index as i64,
                        "the exposure this telemetry covers",
                    ),
                    Card::u("SEED", sim.cfg.seed, "master random seed"),
                    Card::s("CONFHASH", sim.cfg.hash_hex(), "configuration hash"),
                    Card::s("CONTENT", "attitude telemetry", "telescope frame, recorded"),
                ],
            },
        ],
    )?;
    Ok(Some(path))
}

/// Read an attitude telemetry product, with the exposure index it covers.
pub fn read_telemetry(
    path: &Path,
) -> Result<
    (
        crate::analysis::countermeasures::telemetry::TelemetryRecord,
        usize,
    ),
    IoError,
> {
    let cols = fits::read_table(path, "ATTITUDE", &["T_S", "ATT_X_MAS", "ATT_Y_MAS"])?;
    let key = |k: &str| fits::read_f64_key_in(path, Some("ATTITUDE"), k);
    let (start, dt, idx) = (key("TSTART")?, key("DT_S")?, key("IMAGEIDX")?);
    let bad = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if cols[0].is_empty() {
        return Err(bad("the ATTITUDE table has no samples".into()));
    }
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(bad(format!("header DT_S = {dt}: must be > 0 [s]")));
    }
    if !(idx >= 0.0 && idx.fract() == 0.0) {
        return Err(bad(format!("header IMAGEIDX = {idx}: a whole number ≥ 0")));
    }
    if cols.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("a telemetry sample is not finite".into()));
    }
    Ok((
        crate::analysis::countermeasures::telemetry::TelemetryRecord {
            t0_s: cols[0][0],
            dt_s: dt,
            x_mas: cols[1].clone(),
            y_mas: cols[2].clone(),
            exposure_start_s: start,
            // optional: an outside tool's product may not state it (the filter then estimates it)
            stated_noise_mas: key("NOISEMAS").ok().filter(|v| v.is_finite() && *v >= 0.0),
        },
        idx as usize,
    ))
}
