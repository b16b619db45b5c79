//! Running a sequence: the field's stars drawn once over the whole region (the mock bulge, written as the
//! sky catalogue `field.csv` every exposure reads), then each exposure simulated on the quad focal plane and
//! analysed as one crowded exposure with the instrument's products (`studies::crowded`), its catalogue
//! written to `exposures/NNNNN.csv` — written whole or not at all, so a run that stops resumes where it
//! stopped — and the scoring's match to the truth beside it (`exposures/NNNNN_truth.csv`: only scoring
//! reads it). [`merge`] gathers the exposures' catalogues into one FITS table, `catalogue.fits`.

use super::plan::{
    Plan, PlannedExposure, exposure_config, galactic_north_pa_deg, galactic_to_icrs,
};
use crate::analysis::countermeasures::Plan as Countermeasures;
use crate::config::{Config, SceneKind};
use crate::io::csv::Cell;
use crate::io::fits::{self, Card, Column, Hdu};
use crate::io::products::files;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use super::{FIELD_NAME, SequenceError};
/// The gathered catalogue of every exposure.
pub const CATALOGUE_NAME: &str = files::CATALOGUE_FITS;

/// The measured columns of an exposure's catalogue (and of `catalogue.fits`).
pub const CATALOGUE_HEADER: [&str; 13] = [
    "exposure",
    "stare",
    "array",
    "x_px",
    "y_px",
    "flux_e",
    "crlb_x_px",
    "crlb_y_px",
    "flags",
    "ra_deg",
    "dec_deg",
    "mjd_tdb",
    "sequence_id",
];

/// The instrument as designed, the sequence's product for its analysis: [`DESIGN_NAME`].
pub const DESIGN_NAME: &str = files::DESIGN_TOML;

/// The configuration as the pipeline knows the instrument: `cfg` with the arrays where they were designed
/// (no assembly offsets or turns). The simulation's `config.toml` holds the instrument as assembled (and
/// the seed of every draw): the truth, read by the Slurm tasks that simulate and by the scoring only.
pub fn design_of(cfg: &Config) -> Config {
    // no as-built deviation either: design.toml holds only design quantities
    crate::instrument::design_of(cfg)
}

/// Write the configuration and the sequence file a sequence is planned with (`config.toml`,
/// `sequence.toml`) into `dir`: what its Slurm tasks read back; and the instrument as designed
/// (`design.toml`, [`design_of`]), which the astrometric solution (`jsim solve`) reads instead of the truth.
pub fn write_setup(plan: &Plan, cfg: &Config, dir: &Path) -> Result<(PathBuf, PathBuf), String> {
    crate::io::ensure_dir(dir).map_err(|e| e.to_string())?;
    let config = dir.join(files::CONFIG_TOML);
    let spec = dir.join(files::SEQUENCE_TOML);
    crate::io::write_atomic(&config, cfg.to_toml().as_bytes()).map_err(|e| e.to_string())?;
    crate::io::write_atomic(&dir.join(DESIGN_NAME), design_of(cfg).to_toml().as_bytes())
        .map_err(|e| e.to_string())?;
    crate::io::write_atomic(&spec, spec_text(plan)?.as_bytes()).map_err(|e| e.to_string())?;
    Ok((config, spec))
}

/// `sequence.toml`'s text.
fn spec_text(plan: &Plan) -> Result<String, String> {
    toml::to_string(&super::spec::SequenceFile {
        sequence: plan.spec.clone(),
    })
    .map_err(|e| e.to_string())
}

/// Refuse a directory that holds another sequence: a rerun keeps the field and the exposures already
/// written, so a `config.toml` or `sequence.toml` other than this run's, or a `sequence.json` written by
/// another jsim version, would mix two sequences. A new directory, one holding only a plan
/// (`--plan-only` writes neither file), or one of this very sequence passes.
pub fn check_resumable(plan: &Plan, cfg: &Config, dir: &Path) -> Result<(), SequenceError> {
    let differs =
        |name: &str, now: &str| std::fs::read_to_string(dir.join(name)).is_ok_and(|was| was != now);
    let spec = spec_text(plan).map_err(SequenceError::Invalid)?;
    let version = std::fs::read_to_string(dir.join(files::SEQUENCE_JSON))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .map(|v| {
            v["jsim_version"]
                .as_str()
                .unwrap_or("that did not record its version")
                .to_string()
        });
    let why = if differs(files::CONFIG_TOML, &cfg.to_toml()) {
        "its config.toml is another configuration's".to_string()
    } else if differs(files::SEQUENCE_TOML, &spec) {
        "its sequence.toml is another sequence's".to_string()
    } else if let Some(v) = version.filter(|v| v != crate::VERSION) {
        format!("it was written by jsim {v}, this is {}", crate::VERSION)
    } else {
        return Ok(());
    };
    Err(SequenceError::Invalid(format!(
        "{}: holds another sequence ({why}); a rerun resumes only the same sequence: choose another --out, \
         or remove the directory to start again",
        dir.display()
    )))
}

/// The sequence's identity, written in every row of its catalogues (`sequence_id`): the first 48 bits of
/// SHA-256 over its products `design.toml`, `sequence.toml` and the reference catalogue — the plan and the
/// field's draw — so that the solution, reading the same products, refuses a catalogue of another sequence.
pub fn sequence_id(dir: &Path) -> Result<u64, SequenceError> {
    let mut bytes = Vec::new();
    for name in [
        DESIGN_NAME,
        files::SEQUENCE_TOML,
        crate::io::sky_reference::REFERENCE_NAME,
    ] {
        let path = dir.join(name);
        let b = std::fs::read(&path).map_err(|e| {
            SequenceError::Invalid(format!(
                "{}: {e} (written by `jsim sequence`)",
                path.display()
            ))
        })?;
        bytes.extend_from_slice(&(b.len() as u64).to_le_bytes());
        bytes.extend(b);
    }
    Ok(crate::digest::sha256_id48(&bytes))
}

/// A sequence's output directory with its identity ([`sequence_id`], hashed once: the reference catalogue
/// it covers is tens of MB).
#[derive(Debug, Clone)]
pub struct SequenceDir {
    pub path: PathBuf,
    pub id: u64,
    /// Keep each exposure's image beside its catalogue ([`image_path`]).
    pub keep_images: bool,
}

impl SequenceDir {
    /// The directory of a sequence whose products (`design.toml`, `sequence.toml`, the reference catalogue)
    /// are written.
    pub fn open(path: &Path) -> Result<Self, SequenceError> {
        Ok(Self {
            path: path.to_path_buf(),
            id: sequence_id(path)?,
            keep_images: false,
        })
    }
}

/// The file of exposure `index`'s catalogue.
pub fn exposure_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(files::sequence_catalogue_name(index))
}

/// The scoring's match of exposure `index`'s catalogue to the truth.
pub fn truth_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(files::sequence_truth_name(index))
}

/// The image of exposure `index` when the sequence keeps its images (`jsim sequence --keep-images`).
pub fn image_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(files::sequence_image_name(index))
}

/// Draw the mock bulge over the whole region of `plan` (every stare's field, its pointing error and the
/// reach of a star's light) and write it as a sky catalogue with each star's motion; `base.scene.bulge`
/// and the master seed decide the stars.
pub fn write_field(plan: &Plan, base: &Config, dir: &Path) -> Result<PathBuf, SequenceError> {
    let (l_lo, l_hi, b_lo, b_hi) = plan.extent_deg();
    let (l, b) = ((l_lo + l_hi) / 2.0, (b_lo + b_hi) / 2.0);
    let scale_deg = base.instrument.plate_scale_mas() / 3.6e6;
    let margin_deg = 3.0 * plan.spec.pointing_error_arcsec / 3600.0
        + crate::scene::placement::margin_px(base) * scale_deg;
    // the field's diagonal turn (its PA at the region's centre is Galactic north): a square covering it
    let half_deg = (l_hi - l_lo).max(b_hi - b_lo) / 2.0 + plan.field_deg / 2.0 * 1.42 + margin_deg;
    let mut c = base.clone();
    let (ra, dec) = galactic_to_icrs(l, b);
    (c.sky.ra_deg, c.sky.dec_deg, c.sky.pa_deg) = (ra, dec, galactic_north_pa_deg(ra, dec));
    let stars = crate::scene::bulge::draw_square(&c, half_deg / scale_deg)?;
    let rows: Vec<Vec<Cell>> = stars
        .iter()
        .map(|s| {
            vec![
                Cell::F(s.ra_deg),
                Cell::F(s.dec_deg),
                Cell::F(s.mag_hw),
                Cell::F(s.j_minus_h),
                Cell::F(s.motion.pmra_mas_per_yr),
                Cell::F(s.motion.pmdec_mas_per_yr),
                Cell::F(s.motion.parallax_mas),
            ]
        })
        .collect();
    crate::io::ensure_dir(dir)?;
    // the survey's catalogue of the same stars: the product that anchors the astrometric solution
    let refs = super::reference::survey(
        &stars,
        &super::reference::SkySurvey::default(),
        base.seed,
        base.observation.catalogue_epoch_jyear,
    );
    crate::io::sky_reference::write(&refs, dir)?;
    let path = dir.join(FIELD_NAME);
    crate::io::csv::write(
        &path,
        &["ra", "dec", "hw", "j_h", "pmra", "pmdec", "parallax"],
        &rows,
    )?;
    Ok(path)
}

/// What one exposure's run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureRun {
    pub index: usize,
    /// Stars reported over the four arrays.
    pub stars: usize,
    pub simulate_s: f64,
    pub analyse_s: f64,
    /// Its catalogue was there already (a resumed run).
    pub skipped: bool,
}

/// Simulate and analyse exposure `e` (unless its catalogue exists), reading the field at `field`, with the
/// countermeasure of `cm` (its first) and the persistence `memory` holds of the exposures before it.
#[allow(clippy::too_many_arguments)]
pub fn run_exposure(
    session: &crate::session::Session,
    plan: &Plan,
    base: &Config,
    field: &Path,
    e: &PlannedExposure,
    cm: &Countermeasures,
    memory: &mut super::persistence::Memory,
    out: &SequenceDir,
) -> Result<ExposureRun, SequenceError> {
    let dir = out.path.as_path();
    let path = exposure_path(dir, e.index);
    if path.exists() {
        return Ok(ExposureRun {
            index: e.index,
            stars: 0,
            simulate_s: 0.0,
            analyse_s: 0.0,
            skipped: true,
        });
    }
    let mut c = exposure_config(base, plan, e);
    c.scene.kind = SceneKind::Catalogue;
    c.scene.catalogue = Some(field.to_path_buf());
    let t = Instant::now();
    let released = memory.released_e(session, plan, base, e)?;
    let fps = session.new_focal_plane(&c)?;
    let exp = fps.exposure_with(0, &released)?;
    memory.remember(e.index, &fps, &exp, base);
    let simulate_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (lo, hi) = (base.scene.bulge.hw_min, base.scene.bulge.hw_max);
    let edges = crate::scoring::crowded::edges(lo, hi, 1.0);
    let analyses = crate::studies::crowded::analyse_focal_plane(
        &fps,
        &exp,
        cm,
        &edges,
        &crate::io::instrument::SurveyModel::default(),
    )?;
    let analyse_s = t.elapsed().as_secs_f64();
    let first = analyses
        .first()
        .ok_or_else(|| SequenceError::Invalid("no countermeasure to run".into()))?;
    let mjd_tdb = super::plan::mid_exposure(&c, e).tdb_mjd();
    let id = out.id as i64;
    let scale = c.instrument.plate_scale_mas();
    // the sky positions a pipeline gives: through the design WCS at the planned pointing (the images'
    // headers carry the simulator's true one)
    let design = super::plan::design_config(base, plan, e);
    let (mut rows, mut truth_rows) = (Vec::new(), Vec::new());
    for a in &first.arrays {
        let wcs = crate::sky::array_wcs(&design, a.index).ok();
        for s in &a.stars {
            let f = &s.fit;
            let (ra, dec) = wcs
                .as_ref()
                .and_then(|w| w.pixel_to_sky(f.x, f.y))
                .unwrap_or((f64::NAN, f64::NAN));
            rows.push(vec![
                Cell::I(e.index as i64),
                Cell::I(e.stare as i64),
                Cell::I(a.index as i64 + 1),
                Cell::F(f.x),
                Cell::F(f.y),
                Cell::F(f.flux_e),
                Cell::F(f.crlb_x_px),
                Cell::F(f.crlb_y_px),
                Cell::I(i64::from(f.flags)),
                Cell::F(ra),
                Cell::F(dec),
                Cell::F(mjd_tdb),
                Cell::I(id),
            ]);
            truth_rows.push(vec![
                Cell::I(e.index as i64),
                Cell::I(a.index as i64 + 1),
                Cell::I(s.truth.map(|t| a.truth[t].id as i64).unwrap_or(-1)),
                Cell::F(s.dx_px * scale),
                Cell::F(s.dy_px * scale),
            ]);
        }
    }
    crate::io::ensure_dir(&dir.join("exposures"))?;
    // what a run killed while writing this exposure left (its files are this shard's alone)
    let own = [&path, &truth_path(dir, e.index), &image_path(dir, e.index)]
        .map(|p| p.file_name().map(|n| n.to_os_string()).unwrap_or_default());
    crate::io::remove_stale_temps(&dir.join("exposures"), |name| {
        own.iter().any(|o| o.as_os_str() == name)
    });
    if out.keep_images {
        // before the catalogue, which marks the exposure done
        crate::io::focal_plane::write_focal_plane_exposure_to(
            &image_path(dir, e.index),
            &fps,
            &exp,
        )?;
    }
    // the truth first: a catalogue on disk always has its scoring beside it
    crate::io::csv::write(
        &truth_path(dir, e.index),
        &["exposure", "array", "truth_id", "dx_mas", "dy_mas"],
        &truth_rows,
    )?;
    crate::io::csv::write(&path, &CATALOGUE_HEADER, &rows)?;
    Ok(ExposureRun {
        index: e.index,
        stars: rows.len(),
        simulate_s,
        analyse_s,
        skipped: false,
    })
}

/// Gather every exposure's catalogue of `plan` into `catalogue.fits` (a binary table `CATALOGUE` with
/// [`CATALOGUE_HEADER`]'s columns; the primary header names the sequence's size). Every exposure must have
/// run: a missing one is named.
pub fn merge(plan: &Plan, dir: &Path) -> Result<PathBuf, SequenceError> {
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); CATALOGUE_HEADER.len()];
    for e in &plan.exposures {
        let path = exposure_path(dir, e.index);
        if !path.exists() {
            return Err(SequenceError::Invalid(format!(
                "exposure {} has not run ({} is missing): run the sequence (or its shards) first",
                e.index,
                path.display()
            )));
        }
        let (h, rows) = crate::io::csv::read(&path)?;
        for (k, name) in CATALOGUE_HEADER.iter().enumerate() {
            // a flagged detection's bounds may be infinite (a failed fit, an edge): kept as they are
            let column = if name.starts_with("crlb_") {
                crate::io::csv::column_f64_any(&path, &h, &rows, name)?
            } else {
                crate::io::csv::column_f64(&path, &h, &rows, name)?
            };
            cols[k].extend(column);
        }
    }
    let integer = ["exposure", "stare", "array", "flags"];
    let columns = CATALOGUE_HEADER
        .iter()
        .zip(cols)
        .map(|(name, v)| {
            if integer.contains(name) {
                Column::I64((*name).into(), v.iter().map(|x| *x as i64).collect())
            } else {
                Column::F64((*name).into(), v)
            }
        })
        .collect();
    let path = dir.join(CATALOGUE_NAME);
    fits::write(
        &path,
        &[
            Hdu::Header {
                cards: vec![
                    Card::i("NEXPOSE", plan.exposures.len() as i64, "exposures"),
                    Card::i("NSTARES", plan.stares.len() as i64, "stares"),
                    Card::s(
                        "CONTENT",
                        "jsim sequence: every exposure's measured stars",
                        "",
                    ),
                ],
            },
            Hdu::Table {
                name: "CATALOGUE",
                columns,
                cards: Vec::new(),
            },
        ],
    )?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flagged detection's bounds are infinite (a failed fit, an edge): the gathered table keeps them,
    /// while a position that is not a number is a named error.
    #[test]
    fn the_gathered_table_keeps_a_flagged_detections_infinite_bounds() {
        let spec = super::super::Spec {
            stares_l: 1,
            stares_b: 1,
            exposures_per_stare: 1,
            visits_utc: vec!["2031-03-21T00:00:00".into()],
            ..Default::default()
        };
        let plan = super::super::plan(&spec, &Config::default()).expect("plan");
        let dir = std::env::temp_dir().join(format!("jsim-merge-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("exposures")).expect("mkdir");
        let header = CATALOGUE_HEADER.join(",");
        let good = "0,0,1,10.5,20.5,1000,0.01,0.01,0,266.4,-28.9,62946.0,12345";
        let flagged = "0,0,1,3.2,20.5,500,inf,inf,788,266.4,-28.9,62946.0,12345";
        std::fs::write(
            exposure_path(&dir, 0),
            format!("{header}\n{good}\n{flagged}\n"),
        )
        .expect("write");
        let path = merge(&plan, &dir).expect("merged");
        let table =
            crate::io::fits::read_table(&path, "CATALOGUE", &CATALOGUE_HEADER).expect("table");
        assert_eq!(table[6][0], 0.01);
        assert!(table[6][1].is_infinite() && table[8][1] == 788.0);
        std::fs::write(
            exposure_path(&dir, 0),
            format!("{header}\n{}\n", good.replace("10.5", "nan")),
        )
        .expect("write");
        let e = merge(&plan, &dir).expect_err("a position that is not a number");
        assert!(e.to_string().contains("x_px"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
