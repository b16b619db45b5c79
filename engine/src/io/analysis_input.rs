//! Reading an image for analysis, from a file or from memory: the header's facts, electrons with the bias
//! removed, the mask, the instrument products beside it, the image's own configuration (only for the
//! `exact-epsf` control, an oracle) and what was assumed where the image is silent. `jsim analyze` and the Python module read images only through here.

use super::IoError;
use super::exposure::read_truth;
use super::fits::{self, ImageFacts};
use super::instrument::{self, CalibrationFlat};
use crate::analysis::AnalysisImage;
use crate::analysis::countermeasures::telemetry::ExposureReadout;
use crate::analysis::crowded::forced::CatalogueStar;
use crate::config::Config;
use crate::detector::dq;
use crate::truth::TruthRow;
use std::path::Path;

/// An image in ADU as an analysis image: electrons with the bias removed (the header facts), the mask
/// from its DQ plane when given (else from SATURATE and non-finite values).
pub fn analysis_image(
    nx: usize,
    ny: usize,
    data: &[f32],
    dq: Option<&[u8]>,
    facts: &ImageFacts,
    plate_scale_mas: f64,
) -> Result<AnalysisImage, String> {
    if !(plate_scale_mas > 0.0 && plate_scale_mas.is_finite()) {
        return Err(format!(
            "plate scale {plate_scale_mas} mas/px (PLTSCALE): must be > 0"
        ));
    }
    if data.len() != nx * ny {
        return Err(format!(
            "image is {nx}×{ny} but holds {} values",
            data.len()
        ));
    }
    if let Some(d) = dq
        && d.len() != nx * ny
    {
        return Err(format!(
            "the DQ plane holds {} values, the image {nx}×{ny}",
            d.len()
        ));
    }
    let g = facts.gain_e_per_adu;
    let sat = facts.saturation_adu.unwrap_or(f64::INFINITY);
    let bad_bits = dq::UNUSABLE;
    // a non-finite pixel is masked whether or not a DQ plane flags it
    let bad = match dq {
        Some(d) => d
            .iter()
            .zip(data)
            .map(|(q, v)| q & bad_bits != 0 || !v.is_finite())
            .collect(),
        None => data
            .iter()
            .map(|v| *v as f64 >= sat || !v.is_finite())
            .collect(),
    };
    Ok(AnalysisImage {
        nx,
        ny,
        e: data
            .iter()
            .map(|v| {
                if v.is_finite() {
                    crate::detector::linearize(
                        (*v as f64 - facts.bias_adu) * g,
                        facts.nonlinearity_per_e,
                    )
                } else {
                    0.0
                }
            })
            .collect(),
        bad,
        var_floor_e2: crate::config::noise_floor_e2(facts.read_noise_e, g),
        var_floor_px_e2: None,
        flat_sigma: 0.0,
        plate_scale_mas,
    })
}

/// The number of NaN or infinite pixel values (masked by [`analysis_image`], counted in the report).
pub fn non_finite_pixels(data: &[f32]) -> usize {
    data.iter().filter(|v| !v.is_finite()).count()
}

/// Read an image file for analysis ([`analysis_image`] of its primary HDU and DQ extension). Headers that
/// are missing are assumed (listed in the second value); impossible ones are refused, naming them.
pub fn read_analysis_image(
    path: &Path,
    plate_scale_mas: f64,
) -> Result<(AnalysisImage, Vec<String>), IoError> {
    let r = fits::read_image(path)?;
    let img = analysis_image(
        r.nx,
        r.ny,
        &r.data,
        r.dq.as_deref(),
        &r.facts,
        plate_scale_mas,
    )
    .map_err(|message| IoError::Format {
        path: path.to_path_buf(),
        message,
    })?;
    let mut assumed = r.facts.assumed;
    let non_finite = non_finite_pixels(&r.data);
    if non_finite > 0 {
        assumed.push(format!(
            "{non_finite} non-finite (NaN or infinite) pixel(s) masked"
        ));
    }
    Ok((img, assumed))
}

/// An image file read for analysis, with what it says about itself.
#[derive(Debug, Clone)]
pub struct AnalysisInput {
    pub img: AnalysisImage,
    /// The truth catalogue: the given file, else the image's TRUTH extension (if any).
    pub truth: Option<Vec<TruthRow>>,
    /// The same truth in the header's frame (the TRUTH table's `x_header`, `y_header`, written when the
    /// header is not the instrument as built): what a catalogue-referenced countermeasure is scored against.
    pub truth_in_header: Option<Vec<TruthRow>>,
    /// The configuration and exposure index the image was simulated with (its CONFIG extension and
    /// IMAGEIDX), when it is a jsim image.
    pub provenance: Option<(Config, usize)>,
    /// The plate scale used: the PLTSCALE header, else (an image in memory) its configuration's, else
    /// `fallback`'s.
    pub plate_scale_mas: f64,
    /// What was assumed because the image did not say.
    pub assumptions: Vec<String>,
    /// The reference catalogue product's stars (`refcat.csv`): positions in this image's pixels and Hw, when
    /// there is one.
    pub reference: Option<Vec<CatalogueStar>>,
    /// The design model PSF product (`psf_model.fits`), when there is one.
    pub model_psf: Option<crate::analysis::epsf::Epsf>,
    /// Its derivative planes per low-order term (`DZ4` … `DZ11` of `psf_model.fits`), when it holds them.
    pub model_psf_terms: Option<Vec<crate::analysis::epsf::Epsf>>,
    /// The attitude telemetry product of this exposure (`telemetry_NNN.fits`), when there is one.
    pub telemetry: Option<crate::analysis::countermeasures::telemetry::TelemetryRecord>,
    /// The readout timing and array rotation the header states ([`super::readout_header`]): what the
    /// telemetry is applied with.
    pub readout: Option<ExposureReadout>,
    /// What was read of a calibrated chip of another observatory ([`super::calibrated`]), when it is one.
    pub chip: Option<super::calibrated::ChipFacts>,
}

impl AnalysisInput {
    /// Read `path` (and `truth_path`, if given) as `jsim analyze` does, with the calibration flat
    /// `flat_path` (default: `flat_cal.fits` beside the image, if there is one). The image's own
    /// configuration is kept for the `exact-epsf` control alone; never for the calibration.
    pub fn read(
        path: &Path,
        truth_path: Option<&Path>,
        flat_path: Option<&Path>,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        Self::read_products(path, truth_path, flat_path, None, None, fallback)
    }

    /// [`AnalysisInput::read`] with the reference catalogue product `refcat_path` (default: `refcat.csv`
    /// beside the image, if there is one) and the attitude telemetry product `telemetry_path` (default:
    /// `telemetry_NNN.fits` beside the image, NNN its `IMAGEIDX`).
    pub fn read_products(
        path: &Path,
        truth_path: Option<&Path>,
        flat_path: Option<&Path>,
        refcat_path: Option<&Path>,
        telemetry_path: Option<&Path>,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        let products = Products::read(path, None, flat_path, refcat_path)?;
        let provenance = fits::read_text(path, "CONFIG")
            .ok()
            .and_then(|t| Config::from_toml_str(&t).ok())
            .and_then(|c| {
                let i = fits::read_f64_key(path, "IMAGEIDX").ok()?;
                (i >= 0.0 && i.fract() == 0.0).then_some((c, i as usize))
            });
        let r = fits::read_image(path)?;
        let truth = match truth_path {
            Some(p) => Some(read_truth(p)?),
            None => read_truth(path).ok(),
        };
        Self::from_parts(
            ImageParts {
                nx: r.nx,
                ny: r.ny,
                data: &r.data,
                dq: r.dq.as_deref(),
                facts: r.facts,
                plate_scale_header_mas: fits::read_f64_key(path, "PLTSCALE").ok(),
            },
            truth,
            provenance,
            products.flat,
            fallback,
        )
        .map_err(|message| IoError::Format {
            path: path.to_path_buf(),
            message,
        })
        .and_then(|mut input| {
            input.assumptions.extend(products.assumed);
            input.reference = products.reference;
            input.model_psf = products.model_psf;
            input.model_psf_terms = products.model_psf_terms;
            input.telemetry = read_telemetry_for(path, telemetry_path)?;
            input.truth_in_header = truth_in_header(truth_path.unwrap_or(path), None);
            input.with_readout(path, None, fallback)
        })
    }

    /// The analysis input of an image held in memory (what [`AnalysisInput::read`] makes of a file, and
    /// what the Python module makes of an array and its header): `provenance` is the configuration and
    /// exposure index it was simulated with, when known; `flat` the calibration flat product, when there
    /// is one (the image is divided by it and its error counted as noise, unless `analysis.flat_field` is
    /// `uncalibrated`); `fallback` gives the analysis knobs and, where the image says nothing, the plate
    /// scale.
    pub fn from_parts(
        parts: ImageParts<'_>,
        truth: Option<Vec<TruthRow>>,
        provenance: Option<(Config, usize)>,
        flat: Option<CalibrationFlat>,
        fallback: &Config,
    ) -> Result<Self, String> {
        let ImageParts {
            nx,
            ny,
            data,
            dq,
            facts,
            plate_scale_header_mas,
        } = parts;
        let mut assumptions = Vec::new();
        // the header's (15 significant digits); an in-memory image without one: its simulation's
        let plate_scale_mas = match (plate_scale_header_mas, &provenance) {
            (Some(s), _) => s,
            (None, Some((c, _))) => c.instrument.plate_scale_mas(),
            (None, None) => {
                let s = fallback.instrument.plate_scale_mas();
                assumptions.push(format!(
                    "no PLTSCALE header: {s:.3} mas/px from the configuration assumed"
                ));
                s
            }
        };
        if provenance.is_none() {
            assumptions.push(
                "no CONFIG extension (or IMAGEIDX): not a jsim image, so the exact-epsf control (an oracle \
                 from the image's simulation) does not apply"
                    .to_string(),
            );
        }
        let mut img = analysis_image(nx, ny, data, dq, &facts, plate_scale_mas)?;
        assumptions.extend(facts.assumed);
        let non_finite = non_finite_pixels(data);
        if non_finite > 0 {
            assumptions.push(format!(
                "{non_finite} non-finite (NaN or infinite) pixel(s) masked"
            ));
        }
        match (fallback.analysis.flat_field, flat) {
            (crate::config::FlatField::Uncalibrated, _) => {}
            (_, Some(f)) => {
                if (f.nx, f.ny) != (nx, ny) {
                    return Err(format!(
                        "calibration flat {}: {}×{} px, the image {nx}×{ny}: not this detector's flat",
                        f.source, f.nx, f.ny
                    ));
                }
                img.divide_by(&f.data, f.error);
            }
            (_, None) => assumptions.push(format!(
                "no calibration flat ({} beside the image, or --flat): analysed without flat-fielding",
                instrument::FLAT_NAME
            )),
        }
        Ok(Self {
            truth,
            provenance,
            ..Self::bare(img, plate_scale_mas, assumptions)
        })
    }

    /// An image with nothing beside it: no truth, provenance or product yet.
    fn bare(img: AnalysisImage, plate_scale_mas: f64, assumptions: Vec<String>) -> Self {
        Self {
            img,
            truth: None,
            truth_in_header: None,
            provenance: None,
            plate_scale_mas,
            assumptions,
            reference: None,
            model_psf: None,
            model_psf_terms: None,
            telemetry: None,
            readout: None,
            chip: None,
        }
    }
}

/// The instrument products of an image held in memory, each a file (`jsim analyze`'s `--refcat`,
/// `psf_model.fits`, `--telemetry`): what the Python module's array form takes beside its flat.
#[derive(Debug, Clone, Copy, Default)]
pub struct ProductFiles<'a> {
    /// The reference catalogue (`refcat.csv`), its single-array rows.
    pub reference: Option<&'a Path>,
    /// The design model PSF (`psf_model.fits`), with its derivative planes when it holds them.
    pub model_psf: Option<&'a Path>,
    /// The attitude telemetry (`telemetry_NNN.fits`), refused when it covers another exposure than
    /// `image_index` (the header's IMAGEIDX), when that is known.
    pub telemetry: Option<&'a Path>,
    pub image_index: Option<usize>,
}

impl AnalysisInput {
    /// This input with the products of `files` read as `jsim analyze` reads them beside a file (a product not
    /// given stays as it was).
    pub fn with_product_files(mut self, files: ProductFiles<'_>) -> Result<Self, IoError> {
        if let Some(p) = files.reference {
            self.reference = Some(
                instrument::read_reference_catalogue(p, 0)?
                    .iter()
                    .map(instrument::RefStar::catalogue_star)
                    .collect(),
            );
        }
        if let Some(p) = files.model_psf {
            self.model_psf = Some(instrument::read_model_psf(p, None)?);
            self.model_psf_terms = instrument::read_model_psf_terms(p)?;
        }
        if let Some(p) = files.telemetry {
            self.telemetry = Some(read_telemetry_of(p, files.image_index)?);
        }
        Ok(self)
    }

    /// What the analysis under `cm` assumes of this input: [`AnalysisInput::assumptions`], and for the
    /// telemetry correction without a telemetry product, that it has nothing to correct with.
    pub fn assumptions_for(
        &self,
        cm: &crate::analysis::countermeasures::Countermeasure,
    ) -> Vec<String> {
        let mut out = self.assumptions.clone();
        if cm.telemetry_quality().is_some() && self.telemetry.is_none() {
            out.push(format!(
                "no attitude telemetry product ({} beside the image, or --telemetry): the telemetry \
                 correction has nothing to correct with",
                instrument::telemetry_name(0).replace("000", "NNN")
            ));
        }
        out
    }
}

/// An image in ADU as a front end holds it, with what its header says.
#[derive(Debug, Clone)]
pub struct ImageParts<'a> {
    pub nx: usize,
    pub ny: usize,
    /// Pixel values (ADU), row-major: `data[y * nx + x]`.
    pub data: &'a [f32],
    /// The DQ plane, when there is one.
    pub dq: Option<&'a [u8]>,
    pub facts: ImageFacts,
    /// The PLTSCALE header [mas/px], when there is one.
    pub plate_scale_header_mas: Option<f64>,
}

/// The array extensions of a focal-plane file (`ARRAY1` … in order), or none for a single image.
pub fn focal_plane_arrays(path: &Path) -> Result<Vec<String>, IoError> {
    let names = fits::extension_names(path)?;
    Ok((1..)
        .map(|k| format!("ARRAY{k}"))
        .take_while(|n| names.iter().any(|e| e == n))
        .collect())
}

impl AnalysisInput {
    /// Read chip `set` of a calibrated multi-extension file (HST, JWST: [`super::calibrated`]) for
    /// analysis. The image is already flat-fielded by its pipeline and is in electrons once read; the plate
    /// scale is the header's (its WCS), else `fallback`'s.
    pub fn read_chip(
        path: &Path,
        set: &super::calibrated::Imset,
        opts: &super::calibrated::ReadOptions,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        let chip = super::calibrated::read_chip(path, set, opts)?;
        let facts = chip.facts();
        let floor_map = chip.read_noise_map_e2();
        let mut assumptions = chip.notes;
        let plate_scale_mas = chip.plate_scale_mas.unwrap_or_else(|| {
            let s = fallback.instrument.plate_scale_mas();
            assumptions.push(format!(
                "no PLTSCALE header nor WCS matrix: {s:.3} mas/px from the configuration assumed"
            ));
            s
        });
        assumptions.push(if opts.bias_units.is_some() {
            "a raw frame (its bias given): not flat-fielded, as no flat is read with it; no model PSF, so \
             the ePSF is built from the stars alone"
                .to_string()
        } else {
            "a calibrated image: flat-fielded by its own pipeline, not again here; no model PSF, so the \
             ePSF is built from the stars alone"
                .to_string()
        });
        let img = AnalysisImage {
            nx: chip.nx,
            ny: chip.ny,
            e: chip.electrons,
            bad: chip.bad,
            // the data are electrons: no ADC quantisation to add
            var_floor_e2: chip.read_noise_e.powi(2),
            var_floor_px_e2: floor_map,
            flat_sigma: 0.0,
            plate_scale_mas,
        };
        Ok(Self {
            chip: Some(facts),
            ..Self::bare(img, plate_scale_mas, assumptions)
        })
    }

    /// Read array `k` (0-based: extension `ARRAY{k+1}`, its `DQ{k+1}`) of a focal-plane file for analysis,
    /// with the calibration flat's extension `FLAT{k+1}` (from `flat_path`, else `flat_cal.fits` beside
    /// the file) and, when a truth is wanted for the report, the rows of array k+1 of the file's TRUTH
    /// table (or of `truth_path`, a table with an `array` column), the reference catalogue's rows of the
    /// array, the model PSF's `PSF{k+1}` and the exposure's attitude telemetry (`telemetry_path`, else
    /// `telemetry_NNN.fits` beside the file).
    pub fn read_array(
        path: &Path,
        k: usize,
        truth_path: Option<&Path>,
        flat_path: Option<&Path>,
        refcat_path: Option<&Path>,
        telemetry_path: Option<&Path>,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        let ext = format!("ARRAY{}", k + 1);
        let r = fits::read_image_in(path, Some(&ext), &format!("DQ{}", k + 1))?;
        let products = Products::read(path, Some(k), flat_path, refcat_path)?;
        let truth = array_truth(truth_path.unwrap_or(path), k + 1).ok();
        Self::from_parts(
            ImageParts {
                nx: r.nx,
                ny: r.ny,
                data: &r.data,
                dq: r.dq.as_deref(),
                facts: r.facts,
                plate_scale_header_mas: fits::read_f64_key_in(path, Some(&ext), "PLTSCALE").ok(),
            },
            truth,
            None,
            products.flat,
            fallback,
        )
        .map(|mut input| {
            for a in input.assumptions.iter_mut() {
                if a.starts_with("no CONFIG extension") {
                    *a = "a focal-plane array: the exact-epsf control (an oracle from a single array's \
                          simulation) does not apply"
                        .to_string();
                }
            }
            input.truth_in_header = truth_in_header(truth_path.unwrap_or(path), Some(k + 1));
            input
        })
        .map_err(|message| IoError::Format {
            path: path.to_path_buf(),
            message: format!("{ext}: {message}"),
        })
        .map(|mut input| {
            input.assumptions.extend(products.assumed);
            input.reference = products.reference;
            input.model_psf = products.model_psf;
            input
        })
        .and_then(|mut input| {
            // the telescope's attitude, the same record for every array (each applies it turned by its
            // own ROTATION)
            input.telemetry = read_telemetry_for(path, telemetry_path)?;
            input.with_readout(path, Some(&ext), fallback)
        })
    }

    /// The readout timing the header of HDU `ext` of `path` states, and what it assumed.
    fn with_readout(
        mut self,
        path: &Path,
        ext: Option<&str>,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        let (readout, assumed) = super::readout_header::read(
            path,
            ext,
            self.img.ny,
            fits::read_f64_key_in(path, ext, "EXPTIME").unwrap_or(fallback.detector.exposure_s),
            fallback,
        )?;
        self.readout = readout;
        if self.telemetry.is_some() {
            self.assumptions.extend(assumed);
        }
        Ok(self)
    }
}

/// The truth rows of one array (1-based `array` column) of a focal-plane TRUTH table.
/// The TRUTH table's stars (of array `array`, 1-based, of a focal-plane file) in the header's frame: its
/// rows with `x_header`, `y_header` for x, y; `None` when it has no such columns (the header is the
/// instrument as built) or is not a FITS table.
fn truth_in_header(path: &Path, array: Option<usize>) -> Option<Vec<TruthRow>> {
    let mut names: Vec<&str> = crate::io::exposure::TRUTH_HEADER.to_vec();
    names.extend(crate::io::exposure::TRUTH_IN_HEADER);
    if array.is_some() {
        names.push("array");
    }
    let cols = fits::read_table(path, "TRUTH", &names).ok()?;
    let n = crate::io::exposure::TRUTH_HEADER.len();
    let keep: Vec<usize> = (0..cols.first()?.len())
        .filter(|&i| array.is_none_or(|a| cols[names.len() - 1][i] as usize == a))
        .collect();
    let mut sel: Vec<Vec<f64>> = cols[..n]
        .iter()
        .map(|c| keep.iter().map(|&i| c[i]).collect())
        .collect();
    // x and y are the table's first two columns after the id
    sel[1] = keep.iter().map(|&i| cols[n][i]).collect();
    sel[2] = keep.iter().map(|&i| cols[n + 1][i]).collect();
    Some(crate::io::exposure::truth_from_columns(&sel))
}

fn array_truth(path: &Path, array: usize) -> Result<Vec<TruthRow>, IoError> {
    let mut names: Vec<&str> = crate::io::exposure::TRUTH_HEADER.to_vec();
    names.push("array");
    let cols = fits::read_table(path, "TRUTH", &names)?;
    let keep: Vec<usize> = (0..cols[0].len())
        .filter(|&i| cols[names.len() - 1][i] as usize == array)
        .collect();
    let sel: Vec<Vec<f64>> = cols[..names.len() - 1]
        .iter()
        .map(|c| keep.iter().map(|&i| c[i]).collect())
        .collect();
    Ok(crate::io::exposure::truth_from_columns(&sel))
}

/// The instrument products an image's analysis reads beside it (the telemetry apart: it is per exposure),
/// for a single image or array `k` (0-based) of a focal-plane file, with what was assumed where one is
/// missing.
struct Products {
    flat: Option<CalibrationFlat>,
    reference: Option<Vec<CatalogueStar>>,
    model_psf: Option<crate::analysis::epsf::Epsf>,
    model_psf_terms: Option<Vec<crate::analysis::epsf::Epsf>>,
    assumed: Vec<String>,
}

impl Products {
    /// The calibration flat (`flat_path`, else `flat_cal.fits` beside the image; `FLATk` of an array), the
    /// reference catalogue (`refcat_path`, else `refcat.csv`; its rows of the array) and the model PSF
    /// (`psf_model.fits`; `PSFk` of an array).
    fn read(
        image: &Path,
        k: Option<usize>,
        flat_path: Option<&Path>,
        refcat_path: Option<&Path>,
    ) -> Result<Self, IoError> {
        let flat = match instrument::find_flat(image, flat_path) {
            Some(p) => Some(instrument::read_calibration_flat(
                &p,
                k.map(instrument::flat_extension).as_deref(),
            )?),
            None => None,
        };
        let mut assumed = Vec::new();
        let array = k.map_or(0, |k| k as u32 + 1);
        let reference = read_reference(image, refcat_path, array, &mut assumed)?;
        let found = instrument::find_model_psf(image, None);
        let model_psf = match &found {
            Some(p) => Some(instrument::read_model_psf(
                p,
                k.map(instrument::model_psf_extension).as_deref(),
            )?),
            None => None,
        };
        // the derivative planes: a single array's file (the focal plane's have none yet)
        let model_psf_terms = match (&found, k) {
            (Some(p), None) => instrument::read_model_psf_terms(p)?,
            _ => None,
        };
        Ok(Self {
            flat,
            reference,
            model_psf,
            model_psf_terms,
            assumed,
        })
    }
}

/// The reference catalogue product for an image (array `array`, 0 for a single one): its stars' positions in
/// the image's pixels and their Hw, or `None` (said in `assumptions`) when there is none.
fn read_reference(
    image: &Path,
    given: Option<&Path>,
    array: u32,
    assumptions: &mut Vec<String>,
) -> Result<Option<Vec<CatalogueStar>>, IoError> {
    match instrument::find_reference_catalogue(image, given) {
        Some(p) => {
            let stars = instrument::read_reference_catalogue(&p, array)?;
            let ext = (array > 0).then(|| format!("ARRAY{array}"));
            check_pointing(image, ext.as_deref(), &p, &stars)?;
            Ok(Some(
                stars
                    .iter()
                    .map(instrument::RefStar::catalogue_star)
                    .collect(),
            ))
        }
        None => {
            assumptions.push(format!(
                "no reference catalogue ({} beside the image, or --refcat): plate-*@catalogue has no \
                 reference and is refused",
                instrument::REFCAT_NAME
            ));
            Ok(None)
        }
    }
}

/// Largest median distance (px) between a reference catalogue's pixel positions and its sky positions seen
/// through the image's WCS: beyond it the catalogue belongs to another pointing. The WCS is read without its
/// SIP terms (a few pixels of distortion at the corners), so the margin is generous; a catalogue of another
/// field is hundreds of pixels off.
pub const POINTING_TOLERANCE_PX: f64 = 20.0;

/// Refuse a reference catalogue of another pointing: where the image has a TAN WCS (`CRPIX`, `CRVAL`, `CD`
/// of HDU `ext`) and the catalogue sky positions, its stars' RA/Dec must land on their `x_px, y_px` within
/// [`POINTING_TOLERANCE_PX`] (median). Without a WCS or sky positions nothing can be checked.
fn check_pointing(
    image: &Path,
    ext: Option<&str>,
    catalogue: &Path,
    stars: &[instrument::RefStar],
) -> Result<(), IoError> {
    let key = |k: &str| fits::read_f64_key_in(image, ext, k).ok();
    let (Some(c1), Some(c2), Some(v1), Some(v2), Some(n1), Some(n2)) = (
        key("CRPIX1"),
        key("CRPIX2"),
        key("CRVAL1"),
        key("CRVAL2"),
        key("NAXIS1"),
        key("NAXIS2"),
    ) else {
        return Ok(());
    };
    let cd = [
        [key("CD1_1").unwrap_or(0.0), key("CD1_2").unwrap_or(0.0)],
        [key("CD2_1").unwrap_or(0.0), key("CD2_2").unwrap_or(0.0)],
    ];
    let Ok(w) =
        crate::sky::wcs::ArrayWcs::from_header([c1, c2], [v1, v2], cd, [n1 as usize, n2 as usize])
    else {
        return Ok(());
    };
    let d: Vec<f64> = stars
        .iter()
        .filter(|s| s.ra_deg.is_finite() && s.dec_deg.is_finite())
        .filter_map(|s| {
            w.sky_to_pixel(s.ra_deg, s.dec_deg)
                .map(|(x, y)| (x - s.x_px).hypot(y - s.y_px))
        })
        .collect();
    if d.is_empty() {
        return Ok(());
    }
    let median = crate::numerics::stats::median(&d);
    if median > POINTING_TOLERANCE_PX {
        return Err(IoError::Format {
            path: catalogue.to_path_buf(),
            message: format!(
                "reference catalogue of another pointing: its stars' RA/Dec land {median:.0} px (median) \
                 from their x_px, y_px through {}'s WCS (allowed {POINTING_TOLERANCE_PX} px)",
                image.display()
            ),
        });
    }
    Ok(())
}

/// The attitude telemetry product for an image: the one given, else `telemetry_NNN.fits` beside the image
/// (NNN its `IMAGEIDX`); one that covers another exposure is refused by name.
fn read_telemetry_for(
    image: &Path,
    given: Option<&Path>,
) -> Result<Option<crate::analysis::countermeasures::telemetry::TelemetryRecord>, IoError> {
    let index = fits::read_f64_key(image, "IMAGEIDX")
        .ok()
        .filter(|i| *i >= 0.0 && i.fract() == 0.0)
        .map(|i| i as usize);
    let path = match (given, index) {
        (Some(p), _) => p.to_path_buf(),
        (None, Some(i)) => {
            let p = image
                .parent()
                .unwrap_or(Path::new("."))
                .join(instrument::telemetry_name(i));
            if !p.exists() {
                return Ok(None);
            }
            p
        }
        (None, None) => return Ok(None),
    };
    read_telemetry_of(&path, index).map(Some)
}

/// The attitude telemetry product at `path`, refused by name when it covers another exposure than `index`
/// (the image's IMAGEIDX), when that is known.
fn read_telemetry_of(
    path: &Path,
    index: Option<usize>,
) -> Result<crate::analysis::countermeasures::telemetry::TelemetryRecord, IoError> {
    let (rec, covers) = instrument::read_telemetry(path)?;
    if let Some(i) = index
        && i != covers
    {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "telemetry of exposure {covers} (IMAGEIDX), the image is exposure {i}: not this exposure's"
            ),
        });
    }
    Ok(rec)
}
