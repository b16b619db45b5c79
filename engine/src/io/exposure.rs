//! Writing a simulated exposure: `img_NNN.fits` (image + DQ + TRUTH + CONFIG) and `truth_NNN.csv`.

use super::IoError;
use super::csv::{self, Cell};
use super::fits::{self, Card, Column, Hdu, Pixels};
use crate::config::{AceCase, Config};
use crate::simulate::{Exposure, Simulator, TruthRow};
use crate::sky::wcs::{ArrayWcs, KeyValue};
use std::path::{Path, PathBuf};

/// Paths written for one exposure.
#[derive(Debug, Clone)]
pub struct ExposureFiles {
    pub image: PathBuf,
    pub truth_csv: PathBuf,
}

pub use crate::io::products::files::{image_name, truth_name};

/// The time and place cards of an exposure starting `t_start_s` into the ACE series: `TIMESYS` (UTC),
/// `DATE-OBS` and `MJD-OBS` (UTC of `observation.start_utc` + `TSTART`), `MJD-TDB`, `ORBPHASE` (the orbit's
/// argument of latitude then, degrees: the phase of the orbit's aberration and focus breathing); and where the stars
/// were placed: `APPLACE` (1: apparent place, 0: catalogue place), `APPMJD` (the instant of that place,
/// image 0's mid-exposure, MJD UTC), `CATEPOCH` (the catalogue positions' Julian epoch, TDB), the
/// spacecraft's geocentric position `SCGCRSX/Y/Z` (km) and velocity `SCGCRSVX/VY/VZ` (km/s), GCRS, at
/// `APPMJD` — the orbit ephemeris an outside tool needs to repeat the apparent place (astropy's `GCRS`
/// frame with `obsgeoloc`, `obsgeovel`).
pub fn observation_cards(cfg: &crate::config::Config, t_start_s: f64) -> Vec<Card> {
    let (Ok(start), Ok(scene), Ok(orbit)) = (
        crate::sky::exposure_epoch(cfg, t_start_s),
        crate::sky::scene_epoch(cfg),
        crate::sky::orbit(cfg),
    ) else {
        // validation refuses a bad start_utc before anything is written
        return Vec::new();
    };
    let ob = orbit.observer(&scene);
    let mut cards = vec![
        Card::s("TIMESYS", "UTC", "time scale of DATE-OBS, MJD-OBS"),
        Card::s("DATE-OBS", start.utc_iso(), "exposure start (UTC)"),
        Card::f("MJD-OBS", start.utc_mjd(), "[d] exposure start, MJD (UTC)"),
        Card::f("MJD-TDB", start.tdb_mjd(), "[d] exposure start, MJD (TDB)"),
        Card::f(
            "ORBPHASE",
            orbit.argument_of_latitude_deg(&start),
            "[deg] orbit's argument of latitude at start",
        ),
        Card::i(
            "APPLACE",
            i64::from(cfg.observation.apparent_place),
            "1: stars at their apparent place, 0: catalogue",
        ),
        Card::f(
            "APPMJD",
            scene.utc_mjd(),
            "[d] instant of that place, MJD (UTC)",
        ),
        Card::f(
            "CATEPOCH",
            cfg.observation.catalogue_epoch_jyear,
            "[yr] catalogue positions' Julian epoch (TDB)",
        ),
    ];
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        cards.push(Card::f(
            &format!("SCGCRS{axis}"),
            ob.gcrs_position_km[k],
            "[km] spacecraft at APPMJD, GCRS",
        ));
    }
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        cards.push(Card::f(
            &format!("SCGCRSV{axis}"),
            ob.gcrs_velocity_km_s[k],
            "[km/s] its velocity, GCRS",
        ));
    }
    cards
}

/// The provenance headers of an exposure.
pub fn headers(sim: &Simulator, exp: &Exposure) -> Vec<Card> {
    let c = &sim.cfg;
    let mut cards = detector_cards(c);
    cards.extend(identity_cards(sim, exp));
    cards.extend(observation_cards(c, exp.t_start_s));
    cards.extend(timing_cards(sim));
    cards.extend(ace_cards(c, exp));
    cards.extend(model_cards(c, exp));
    if c.scene.kind == crate::config::SceneKind::Grid {
        // the grid's one magnitude and colour (a bulge or catalogue scene has many: see the truth)
        cards.push(Card::f(
            "MAGHW",
            c.scene.mag_hw,
            "scene Hw magnitude (grid)",
        ));
        cards.push(Card::f(
            "JMINUSH",
            c.scene.j_minus_h,
            "scene J-H colour (grid)",
        ));
    }
    cards.extend(provenance_cards(c));
    cards.push(Card::s(
        "COORDS",
        "0-based, integer = pixel centre",
        "TRUTH x,y convention (ds9: +1)",
    ));
    if let Some(counts) = &sim.counts {
        cards.extend(counts_cards(counts));
    }
    // the world coordinate system as the products know it: the design's (config validated: it always exists)
    if let Some(w) = sim.design_wcs() {
        cards.extend(wcs_cards(w));
    }
    cards
}

/// The detector's figures: unit, exposure, gain, linearity, read noise, dark, well, ADC, flat.
fn detector_cards(c: &Config) -> Vec<Card> {
    let d = &c.detector;
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
            "NLCORR",
            d.nonlinearity_correction_per_e(),
            "[1/e-] linearity correction: meas = N - NLCORR N^2",
        ),
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
    ]
}

/// Who and what: plate scale, seed, image, telescope, instrument, array, band.
fn identity_cards(sim: &Simulator, exp: &Exposure) -> Vec<Card> {
    let c = &sim.cfg;
    vec![
        Card::f(
            "PLTSCALE",
            c.instrument.plate_scale_mas(),
            "[mas/pix] plate scale",
        ),
        Card::u("SEED", c.seed, "master random seed"),
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
        Card::s("TELESCOP", "JASMINE", "telescope (simulated)"),
        Card::s("INSTRUME", "JASMINE NIR", "instrument (simulated by jsim)"),
        Card::s(
            "DETECTOR",
            format!("NIR{}", sim.array.index + 1),
            &format!(
                "{n}x{n} array {} of the focal plane",
                sim.array.index + 1,
                n = c.instrument.detector_px
            ),
        ),
        Card::s("FILTER", "Hw", "band: 1.0-1.6 um (the Hw magnitude system)"),
    ]
}

/// The readout: order, channels, timing, row direction, the array's turn.
fn timing_cards(sim: &Simulator) -> Vec<Card> {
    let c = &sim.cfg;
    vec![
        Card::s("READOUT", c.readout.order.name(), "readout order"),
        Card::i("NCHAN", c.readout.channels as i64, "readout channels"),
        Card::f("PIXTIME", c.readout.pixel_time_us, "[us] pixel read time"),
        Card::s(
            "ROWDIR",
            match c.readout.row_direction {
                crate::config::RowDirection::Up => "up",
                crate::config::RowDirection::Down => "down",
            },
            "rows read bottom (Y=0) first: up",
        ),
        Card::i(
            "CHANWID",
            c.readout.channel_width_px as i64,
            "[pix] readout channel width",
        ),
        Card::f(
            "TOVERHD",
            c.readout.t_overhead_s,
            "[s] reset end to first read",
        ),
        Card::f(
            "ROTATION",
            sim.array.rotation_deg,
            "[deg] array turn on the sky",
        ),
    ]
}

/// The attitude control error asked for and met over this exposure.
fn ace_cards(c: &Config, exp: &Exposure) -> Vec<Card> {
    let ace_sigma = match c.ace.case {
        AceCase::None => 0.0,
        _ => c.ace.sigma_mas,
    };
    vec![
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
    ]
}

/// How the image was modelled: stars, zero point, PSF table, integration.
fn model_cards(c: &Config, exp: &Exposure) -> Vec<Card> {
    let modelled = exp
        .truth
        .first()
        .map(|t| t.modelled_fraction)
        .unwrap_or(1.0);
    vec![
        Card::i(
            "NSTARS",
            exp.truth.len() as i64,
            "stars in the truth (this array)",
        ),
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
    ]
}

/// Which configuration and which engine made a file: `CONFHASH`, `ENGINE`.
pub fn provenance_cards(cfg: &Config) -> [Card; 2] {
    [
        Card::s(
            "CONFHASH",
            cfg.hash_hex(),
            "SHA-256 of the config TOML (16 hex)",
        ),
        Card::s(
            "ENGINE",
            format!("jsim {}", crate::VERSION),
            "simulator version",
        ),
    ]
}

/// Where a sky scene's stars fell, as cards (`NCATALOG` … `NOFF`).
pub fn counts_cards(counts: &crate::scene::PlacementCounts) -> impl Iterator<Item = Card> {
    counts.cards().into_iter().map(|(k, v, c)| Card::i(k, v, c))
}

/// The FITS cards of a WCS.
pub fn wcs_cards(w: &ArrayWcs) -> Vec<Card> {
    w.keywords()
        .into_iter()
        .map(|k| {
            let comment = k.comment;
            match k.value {
                KeyValue::F(v) => Card::f(&k.key, v, comment),
                KeyValue::I(v) => Card::i(&k.key, v, comment),
                KeyValue::S(v) => Card::s(&k.key, v, comment),
            }
        })
        .collect()
}

/// The TRUTH table's columns ([`truth_header`]).
pub fn truth_columns(t: &[TruthRow], wcs: Option<&ArrayWcs>) -> Vec<Column> {
    let rows = truth_rows(t, wcs);
    truth_header()
        .iter()
        .enumerate()
        .map(|(j, name)| {
            if j == 0 {
                Column::I64(
                    (*name).into(),
                    rows.iter()
                        .map(|r| match r[j] {
                            Cell::I(v) => v,
                            _ => -1,
                        })
                        .collect(),
                )
            } else {
                Column::F64(
                    (*name).into(),
                    rows.iter()
                        .map(|r| match r[j] {
                            Cell::F(v) => v,
                            _ => f64::NAN,
                        })
                        .collect(),
                )
            }
        })
        .collect()
}

/// The truth's positions in the header's frame (`x_header`, `y_header`: each star's true sky place through the
/// header's design WCS, `Simulator::in_header_frame_px`), written beside the TRUTH table's own columns when the
/// header is not the instrument as built — what a catalogue-referenced countermeasure is scored against.
pub fn header_frame_columns(sim: &Simulator, t: &[TruthRow]) -> [Column; 2] {
    let (x, y): (Vec<f64>, Vec<f64>) = t
        .iter()
        .map(|r| {
            sim.in_header_frame_px(r.x_px, r.y_px)
                .unwrap_or((f64::NAN, f64::NAN))
        })
        .unzip();
    [
        Column::F64(TRUTH_IN_HEADER[0].into(), x),
        Column::F64(TRUTH_IN_HEADER[1].into(), y),
    ]
}

/// The TRUTH table's header-frame columns ([`header_frame_columns`]).
pub const TRUTH_IN_HEADER: [&str; 2] = ["x_header", "y_header"];

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

/// The sky position columns the written truth tables add after [`TRUTH_HEADER`]: each star's RA and Dec
/// (degrees, ICRS) through the image's WCS.
pub const TRUTH_SKY: [&str; 2] = ["ra_deg", "dec_deg"];

/// The columns of the written truth tables: [`TRUTH_HEADER`], then [`TRUTH_SKY`].
pub fn truth_header() -> Vec<&'static str> {
    TRUTH_HEADER
        .iter()
        .chain(TRUTH_SKY.iter())
        .copied()
        .collect()
}

/// The truth catalogue as rows of [`truth_header`] (the sky position NaN without a WCS).
pub fn truth_rows(t: &[TruthRow], wcs: Option<&ArrayWcs>) -> Vec<Vec<Cell>> {
    t.iter()
        .map(|r| {
            let (ra, dec) = wcs
                .and_then(|w| w.pixel_to_sky(r.x_px, r.y_px))
                .unwrap_or((f64::NAN, f64::NAN));
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
                Cell::F(ra),
                Cell::F(dec),
            ]
        })
        .collect()
}

/// A simulated exposure's truth as a table: [`truth_header`]'s columns through the simulator's WCS and, when
/// its header is not the instrument as built ([`Simulator::wcs_deviates`]), [`TRUTH_IN_HEADER`] after them
/// ([`header_frame_columns`]) — what `truth_NNN.csv` and Python's `Exposure.truth` hold, so that `jsim score`
/// can score a catalogue-referenced catalogue in its own frame.
pub fn truth_table(sim: &Simulator, t: &[TruthRow]) -> (Vec<&'static str>, Vec<Vec<Cell>>) {
    let mut header = truth_header();
    let mut rows = truth_rows(t, sim.wcs());
    if sim.wcs_deviates() {
        header.extend(TRUTH_IN_HEADER);
        for (row, r) in rows.iter_mut().zip(t) {
            let (x, y) = sim
                .in_header_frame_px(r.x_px, r.y_px)
                .unwrap_or((f64::NAN, f64::NAN));
            row.extend([Cell::F(x), Cell::F(y)]);
        }
    }
    (header, rows)
}

/// The truth catalogue from its columns ([`TRUTH_HEADER`], in that order).
pub fn truth_from_columns(cols: &[Vec<f64>]) -> Vec<TruthRow> {
    let n = cols.first().map(|c| c.len()).unwrap_or(0);
    (0..n)
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
        .collect()
}

/// Read a truth catalogue (CSV written by [`write_exposure`], or the TRUTH extension of an image).
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
    Ok(truth_from_columns(&cols))
}

/// The image as the FITS file stores it: `uint16` when digitised with ≤ 16 bits (clamped to 0–65535),
/// else `None` (the ADU values are stored as `float32`).
pub fn stored_u16(cfg: &Config, adu: &[f32]) -> Option<Vec<u16>> {
    (cfg.detector.digitise && cfg.detector.adc_bits <= 16)
        .then(|| adu.iter().map(|v| v.clamp(0.0, 65535.0) as u16).collect())
}

/// Write the image file of one exposure (image, DQ, TRUTH, CONFIG) to `path`, with `pixels` and `dq` as the
/// image planes (the exposure's own, or a front end's copy of them).
pub fn write_image_file(
    path: &Path,
    sim: &Simulator,
    exp: &Exposure,
    pixels: Pixels<'_>,
    dq: &[u8],
) -> Result<(), IoError> {
    let n = exp.image.n;
    let config_text = sim.cfg.to_toml();
    fits::write(
        path,
        &[
            Hdu::Image {
                name: "",
                nx: n,
                ny: n,
                pixels,
                cards: headers(sim, exp),
            },
            Hdu::U8Image {
                name: "DQ",
                nx: n,
                ny: n,
                data: dq,
            },
            Hdu::Table {
                name: "TRUTH",
                columns: {
                    let mut c = truth_columns(&exp.truth, sim.wcs());
                    if sim.wcs_deviates() {
                        c.extend(header_frame_columns(sim, &exp.truth));
                    }
                    c
                },
                cards: vec![],
            },
            Hdu::Text {
                name: "CONFIG",
                text: &config_text,
            },
        ],
    )
}

/// Write one exposure into `dir`: `img_NNN.fits` and `truth_NNN.csv`.
pub fn write_exposure(
    dir: &Path,
    sim: &Simulator,
    exp: &Exposure,
) -> Result<ExposureFiles, IoError> {
    let image = dir.join(image_name(exp.index));
    let truth_csv = dir.join(truth_name(exp.index));
    let u16_data = stored_u16(&sim.cfg, &exp.image.adu);
    let pixels = match &u16_data {
        Some(d) => Pixels::U16(d),
        None => Pixels::F32(&exp.image.adu),
    };
    write_image_file(&image, sim, exp, pixels, &exp.image.dq)?;
    let (header, rows) = truth_table(sim, &exp.truth);
    csv::write(&truth_csv, &header, &rows)?;
    Ok(ExposureFiles { image, truth_csv })
}

#[cfg(test)]
mod time_tests {
    use super::*;
    use crate::io::fits::Value;

    /// `DATE-OBS` and `MJD-OBS` are the configured start plus `TSTART`, in UTC, and agree.
    #[test]
    fn time_cards_are_the_start_plus_tstart() {
        let cfg = crate::config::Config::default();
        let cards = observation_cards(&cfg, 86_400.0 + 3_723.25);
        let get = |k: &str| cards.iter().find(|c| c.key == k).map(|c| c.value.clone());
        assert_eq!(get("TIMESYS"), Some(Value::S("UTC".into())));
        assert_eq!(
            get("DATE-OBS"),
            Some(Value::S("2031-03-22T01:02:03.250".into()))
        );
        let Some(Value::F(mjd)) = get("MJD-OBS") else {
            panic!("MJD-OBS")
        };
        assert!((mjd - (62_947.0 + 3_723.25 / 86_400.0)).abs() * 86_400.0 < 1e-4);
        let Some(Value::F(tdb)) = get("MJD-TDB") else {
            panic!("MJD-TDB")
        };
        // TDB − UTC = 69.184 s + (TDB − TT, ≤ 1.7 ms)
        assert!(((tdb - mjd) * 86_400.0 - 69.184).abs() < 2e-3);
        let Some(Value::F(x)) = get("SCGCRSX") else {
            panic!("SCGCRSX")
        };
        assert!(x.abs() <= 6_978.2);
    }
}
