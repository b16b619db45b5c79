//! Writing a simulated exposure: `img_NNN.fits` (image + DQ + TRUTH + CONFIG) and `truth_NNN.csv`.

use super::IoError;
use super::csv::{self, Cell};
use super::fits::{self, Card, Column, Hdu, Pixels};
use crate::analysis::AnalysisImage;
use crate::config::{AceCase, Config};
use crate::detector::dq;
use crate::simulate::{Exposure, Simulator, TruthRow};
use std::path::{Path, PathBuf};

/// Paths written for one exposure.
#[derive(Debug, Clone)]
pub struct ExposureFiles {
    pub image: PathBuf,
    pub truth_csv: PathBuf,
}

/// File name of image `index`.
pub fn image_name(index: usize) -> String {
    format!("img_{index:03}.fits")
}

/// File name of the truth catalogue of image `index`.
pub fn truth_name(index: usize) -> String {
    format!("truth_{index:03}.csv")
}

/// The provenance headers of an exposure.
pub fn headers(sim: &Simulator, exp: &Exposure) -> Vec<Card> {
    let c = &sim.cfg;
    let d = &c.detector;
    let ace_sigma = match c.ace.case {
        AceCase::None => 0.0,
        _ => c.ace.sigma_mas,
    };
    let modelled = exp
        .truth
        .first()
        .map(|t| t.modelled_fraction)
        .unwrap_or(1.0);
    vec![
        Card::s(
            "BUNIT",
            if d.digitise { "ADU" } else { "ADU (float)" },
            "pixel unit",
        ),
        Card::f(
            "EXPTIME",
            d.exposure_s,
            "[s] exposure per pixel (CDS interval)",
        ),
        Card::f("GAIN", d.gain_e_per_adu, "[e-/ADU] conversion gain"),
        Card::f(
            "RDNOISE",
            d.image_read_noise_e(),
            "[e-] read noise of this image (all reads)",
        ),
        Card::f(
            "RNREAD",
            d.read_noise_per_read_e,
            "[e-] read noise of one read",
        ),
        Card::s(
            "SAMPLING",
            d.sampling.header(),
            "image = reads after - reads before",
        ),
        Card::f(
            "DARKCUR",
            d.dark_e_per_s,
            "[e-/s/pix] dark current + stray light",
        ),
        Card::f("FULLWELL", d.full_well_e, "[e-] full well"),
        Card::i("ADCBITS", d.adc_bits as i64, "ADC bits"),
        Card::f("BIASADU", d.bias_adu, "[ADU] bias"),
        Card::f(
            "SATURATE",
            2f64.powi(d.adc_bits as i32) - 1.0,
            "[ADU] ADC full scale",
        ),
        Card::f(
            "FLATSIG",
            d.inter_pixel_flat_sigma,
            "inter-pixel flat 1-sigma",
        ),
        Card::f(
            "PLTSCALE",
            c.instrument.plate_scale_mas(),
            "[mas/pix] plate scale",
        ),
        Card::i("SEED", c.seed as i64, "master random seed"),
        Card::i(
            "IMAGEIDX",
            exp.index as i64,
            "image index in the dataset (noise streams)",
        ),
        Card::f(
            "TSTART",
            exp.t_start_s,
            "[s] exposure start in the ACE series",
        ),
        Card::s("READOUT", c.readout.order.name(), "readout order"),
        Card::i("NCHAN", c.readout.channels as i64, "readout channels"),
        Card::f("PIXTIME", c.readout.pixel_time_us, "[us] pixel read time"),
        Card::s("ACECASE", c.ace.case.name(), "attitude control error model"),
        Card::f("ACESIGMA", ace_sigma, "[mas] requested ACE sigma per axis"),
        Card::s(
            "ACECONV",
            format!("{:?}", c.ace.sigma_convention),
            "ACE sigma convention",
        ),
        Card::f(
            "ACESIGX",
            exp.ace.sigma_x_mas,
            "[mas] ACE std over this exposure, x",
        ),
        Card::f(
            "ACESIGY",
            exp.ace.sigma_y_mas,
            "[mas] ACE std over this exposure, y",
        ),
        Card::f(
            "ACEDRIFT",
            exp.ace.drift_mas,
            "[mas] ACE drift over this exposure",
        ),
        Card::f("MAGHW", c.scene.mag_hw, "scene Hw magnitude (grid)"),
        Card::f("JMINUSH", c.scene.j_minus_h, "scene J-H colour (grid)"),
        Card::i("NSTARS", exp.truth.len() as i64, "stars in the scene"),
        Card::f(
            "ZEROPT",
            c.photometry.zero_point_e_per_s,
            "[e-/s] rate at Hw = 0",
        ),
        Card::f("PSFFRAC", modelled, "flux fraction inside the PSF table"),
        Card::i(
            "PSFRAD",
            c.optics.psf_radius_px as i64,
            "[pix] PSF table half-width",
        ),
        Card::i(
            "PSFOVER",
            c.optics.psf_oversampling as i64,
            "PSF cells per pixel",
        ),
        Card::i(
            "SUBPIX",
            c.fidelity.subpixels as i64,
            "subpixels per pixel axis",
        ),
        Card::f(
            "TSTEP",
            c.integration_dt_s() * 1e3,
            "[ms] integration time step",
        ),
        Card::s("METHOD", c.fidelity.method.name(), "integration method"),
        Card::s("BACKEND", exp.backend.clone(), "integration device"),
        Card::s(
            "CONFHASH",
            c.hash_hex(),
            "SHA-256 of the config TOML (16 hex)",
        ),
        Card::s(
            "ENGINE",
            format!("jsim {}", crate::VERSION),
            "simulator version",
        ),
        Card::s(
            "COORDS",
            "0-based, integer = pixel centre",
            "TRUTH x,y convention (ds9: +1)",
        ),
    ]
}

fn truth_columns(t: &[TruthRow]) -> Vec<Column> {
    vec![
        Column::I64("id".into(), t.iter().map(|r| r.id as i64).collect()),
        Column::F64("x".into(), t.iter().map(|r| r.x_px).collect()),
        Column::F64("y".into(), t.iter().map(|r| r.y_px).collect()),
        Column::F64("mag_hw".into(), t.iter().map(|r| r.mag_hw).collect()),
        Column::F64("j_h".into(), t.iter().map(|r| r.j_minus_h).collect()),
        Column::F64("flux_e".into(), t.iter().map(|r| r.flux_e).collect()),
        Column::F64(
            "psf_fraction".into(),
            t.iter().map(|r| r.modelled_fraction).collect(),
        ),
        Column::F64("t_start_s".into(), t.iter().map(|r| r.t_start_s).collect()),
        Column::F64("exptime_s".into(), t.iter().map(|r| r.exptime_s).collect()),
        Column::F64(
            "jitter_dx".into(),
            t.iter().map(|r| r.jitter_dx_px).collect(),
        ),
        Column::F64(
            "jitter_dy".into(),
            t.iter().map(|r| r.jitter_dy_px).collect(),
        ),
    ]
}

/// Columns of the truth CSV.
pub const TRUTH_HEADER: [&str; 11] = [
    "id",
    "x",
    "y",
    "mag_hw",
    "j_h",
    "flux_e",
    "psf_fraction",
    "t_start_s",
    "exptime_s",
    "jitter_dx",
    "jitter_dy",
];

/// Write the truth catalogue as CSV.
pub fn write_truth_csv(path: &Path, t: &[TruthRow]) -> Result<(), IoError> {
    let rows: Vec<Vec<Cell>> = t
        .iter()
        .map(|r| {
            vec![
                Cell::I(r.id as i64),
                Cell::F(r.x_px),
                Cell::F(r.y_px),
                Cell::F(r.mag_hw),
                Cell::F(r.j_minus_h),
                Cell::F(r.flux_e),
                Cell::F(r.modelled_fraction),
                Cell::F(r.t_start_s),
                Cell::F(r.exptime_s),
                Cell::F(r.jitter_dx_px),
                Cell::F(r.jitter_dy_px),
            ]
        })
        .collect();
    csv::write(path, &TRUTH_HEADER, &rows)
}

/// Read a truth catalogue (CSV written by [`write_truth_csv`], or the TRUTH extension of an image).
pub fn read_truth(path: &Path) -> Result<Vec<TruthRow>, IoError> {
    let is_fits = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("fits") || e.eq_ignore_ascii_case("fit"));
    let cols: Vec<Vec<f64>> = if is_fits {
        fits::read_table(path, "TRUTH", &TRUTH_HEADER)?
    } else {
        let (h, rows) = csv::read(path)?;
        TRUTH_HEADER
            .iter()
            .map(|c| csv::column_f64(path, &h, &rows, c))
            .collect::<Result<_, _>>()?
    };
    let n = cols[0].len();
    Ok((0..n)
        .map(|i| TruthRow {
            id: cols[0][i] as usize,
            x_px: cols[1][i],
            y_px: cols[2][i],
            mag_hw: cols[3][i],
            j_minus_h: cols[4][i],
            flux_e: cols[5][i],
            modelled_fraction: cols[6][i],
            t_start_s: cols[7][i],
            exptime_s: cols[8][i],
            jitter_dx_px: cols[9][i],
            jitter_dy_px: cols[10][i],
        })
        .collect())
}

/// Write one exposure into `dir`.
pub fn write_exposure(
    dir: &Path,
    sim: &Simulator,
    exp: &Exposure,
) -> Result<ExposureFiles, IoError> {
    let n = exp.image.n;
    let image = dir.join(image_name(exp.index));
    let truth_csv = dir.join(truth_name(exp.index));
    let cards = headers(sim, exp);
    let u16_data: Vec<u16>;
    let pixels = if sim.cfg.detector.digitise && sim.cfg.detector.adc_bits <= 16 {
        u16_data = exp
            .image
            .adu
            .iter()
            .map(|v| v.clamp(0.0, 65535.0) as u16)
            .collect();
        Pixels::U16(&u16_data)
    } else {
        Pixels::F32(&exp.image.adu)
    };
    let config_text = sim.cfg.to_toml();
    fits::write(
        &image,
        &[
            Hdu::Image {
                name: "",
                nx: n,
                ny: n,
                pixels,
                cards,
            },
            Hdu::U8Image {
                name: "DQ",
                nx: n,
                ny: n,
                data: &exp.image.dq,
            },
            Hdu::Table {
                name: "TRUTH",
                columns: truth_columns(&exp.truth),
                cards: vec![],
            },
            Hdu::Text {
                name: "CONFIG",
                text: &config_text,
            },
        ],
    )?;
    write_truth_csv(&truth_csv, &exp.truth)?;
    Ok(ExposureFiles { image, truth_csv })
}

/// Read an image for analysis: electrons with the bias removed (GAIN, RDNOISE, BIASADU, SATURATE headers),
/// the mask from its DQ extension when present (else from SATURATE and non-finite values). Headers that
/// are missing are assumed (listed in the second value); impossible ones are refused, naming them.
pub fn read_analysis_image(
    path: &Path,
    plate_scale_mas: f64,
) -> Result<(AnalysisImage, Vec<String>), IoError> {
    if !(plate_scale_mas > 0.0 && plate_scale_mas.is_finite()) {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!("plate scale {plate_scale_mas} mas/px (PLTSCALE): must be > 0"),
        });
    }
    let r = fits::read_image(path)?;
    if r.data.len() != r.nx * r.ny {
        return Err(IoError::Format {
            path: path.to_path_buf(),
            message: format!(
                "image is {}×{} but holds {} values",
                r.nx,
                r.ny,
                r.data.len()
            ),
        });
    }
    let g = r.gain_e_per_adu;
    let sat = r.saturation_adu.unwrap_or(f64::INFINITY);
    let bad_bits = dq::BORDER | dq::SATURATED | dq::ADC_HIGH;
    let bad = match &r.dq {
        Some(d) => d.iter().map(|q| q & bad_bits != 0).collect(),
        None => r
            .data
            .iter()
            .map(|v| *v as f64 >= sat || !v.is_finite())
            .collect(),
    };
    let img = AnalysisImage {
        nx: r.nx,
        ny: r.ny,
        e: r.data
            .iter()
            .map(|v| {
                if v.is_finite() {
                    (*v as f64 - r.bias_adu) * g
                } else {
                    0.0
                }
            })
            .collect(),
        bad,
        var_floor_e2: crate::config::noise_floor_e2(r.read_noise_e, g),
        flat_sigma: 0.0,
        plate_scale_mas,
    };
    Ok((img, r.assumed))
}

/// An image file read for analysis, with what it says about itself.
#[derive(Debug, Clone)]
pub struct AnalysisInput {
    pub img: AnalysisImage,
    /// The truth catalogue: the given file, else the image's TRUTH extension (if any).
    pub truth: Option<Vec<TruthRow>>,
    /// The configuration and exposure index the image was simulated with (its CONFIG extension and
    /// IMAGEIDX), when it is a jsim image.
    pub provenance: Option<(Config, usize)>,
    /// The plate scale used: the image's configuration's, else its PLTSCALE header, else `fallback`'s.
    pub plate_scale_mas: f64,
    /// What was assumed because the image did not say.
    pub assumptions: Vec<String>,
}

impl AnalysisInput {
    /// Read `path` (and `truth_path`, if given) as `jsim analyze` does. The image's own configuration,
    /// when it has one, gives the exact plate scale (a header float keeps only 15 digits).
    pub fn read(
        path: &Path,
        truth_path: Option<&Path>,
        fallback: &Config,
    ) -> Result<Self, IoError> {
        let provenance = fits::read_text(path, "CONFIG")
            .ok()
            .and_then(|t| Config::from_toml_str(&t).ok())
            .and_then(|c| {
                let i = fits::read_f64_key(path, "IMAGEIDX").ok()?;
                (i >= 0.0 && i.fract() == 0.0).then_some((c, i as usize))
            });
        let mut assumptions = Vec::new();
        let plate_scale_mas = match (&provenance, fits::read_f64_key(path, "PLTSCALE")) {
            (Some((c, _)), _) => c.instrument.plate_scale_mas(),
            (None, Ok(s)) => s,
            (None, Err(_)) => {
                let s = fallback.instrument.plate_scale_mas();
                assumptions.push(format!(
                    "no PLTSCALE header: {s:.3} mas/px from the configuration assumed"
                ));
                s
            }
        };
        if provenance.is_none() {
            assumptions.push(
                "no CONFIG extension (or IMAGEIDX): not a jsim image, so no simulation context — the \
                 telemetry has no ACE series to correct with, no ACE prediction is attached, exact-epsf \
                 does not apply; the reference seed is the command line's"
                    .to_string(),
            );
        }
        let (mut img, assumed) = read_analysis_image(path, plate_scale_mas)?;
        assumptions.extend(assumed);
        let mode = fallback.analysis.flat_field;
        match &provenance {
            Some((c, _)) => img.flat_field(c, mode),
            None if mode != crate::config::FlatField::Uncalibrated => assumptions.push(
                "analysis.flat_field is calibrated, but a non-jsim image has no calibration flat here: \
                 analysed without flat-fielding"
                    .to_string(),
            ),
            None => {}
        }
        let truth = match truth_path {
            Some(p) => Some(read_truth(p)?),
            None => read_truth(path).ok(),
        };
        Ok(Self {
            img,
            truth,
            provenance,
            plate_scale_mas,
            assumptions,
        })
    }
}
