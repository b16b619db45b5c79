//! Persistence along a sequence (`detector.persistence`): each exposure collects what the traps filled by
//! the earlier exposures of the last `lookback_s` release (`detector::persistence`). An earlier exposure's
//! trap-filling charge is remade from the plan and the field — its bright stars only, at its pointing,
//! with its jitter and flat — so that an exposure's persistence does not depend on which exposures this
//! process ran before it: a sharded or resumed run is the same as a straight one. The maps are kept while
//! they are within the lookback, so a straight run makes each once and its cost per exposure stays flat;
//! when every star of the field is bright enough to fill traps (the default threshold and the mock bulge's
//! Hw ≤ 17), an exposure's own charge is its remake, and a straight run keeps it instead of making it again.

use super::plan::{Plan, PlannedExposure, exposure_config};
use super::{FIELD_NAME, SequenceError};
use crate::config::{Config, SceneKind};
use crate::detector::persistence::{ChargeMap, released_e};
use crate::io::csv::Cell;
use crate::session::Session;
use crate::simulate::{FocalPlaneExposure, FocalPlaneSimulator};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The field's stars bright enough to fill traps, in the output directory.
pub const BRIGHT_FIELD_NAME: &str = crate::io::products::files::FIELD_BRIGHT_CSV;

/// The largest fraction of a star's light one pixel collects (any sub-pixel phase, no jitter): a bound
/// that picks the stars whose brightest pixel can reach the threshold (`tests/persistence.rs` checks it
/// against the PSF).
pub const PEAK_FRACTION_BOUND: f64 = 0.5;

/// The trap-filling charge of the recent exposures of a sequence, per array.
pub struct Memory {
    bright_field: Option<PathBuf>,
    /// Every star of the field can fill traps: an exposure's own charge is what a remake would give, so a
    /// run keeps it ([`Memory::remember`]) instead of remaking it.
    whole_field: bool,
    maps: BTreeMap<usize, Vec<ChargeMap>>,
    /// Exposures whose maps were made (for the cost report).
    pub made: usize,
}

impl Memory {
    /// The memory of a sequence written in `dir` (its field already there). With persistence on, the
    /// field's stars that can fill traps are written to [`BRIGHT_FIELD_NAME`] (unless that is every star).
    pub fn new(base: &Config, dir: &Path) -> Result<Self, SequenceError> {
        Self::from_field(base, &dir.join(FIELD_NAME), &dir.join(BRIGHT_FIELD_NAME))
    }

    /// [`Memory::new`] with the field at `field` and its bright stars at `bright`.
    pub fn from_field(base: &Config, field: &Path, bright: &Path) -> Result<Self, SequenceError> {
        let p = &base.detector.persistence;
        if !p.enabled {
            return Ok(Self {
                bright_field: None,
                whole_field: false,
                maps: BTreeMap::new(),
                made: 0,
            });
        }
        // made afresh on every run: a rerun with another threshold must not read the last run's selection
        let (h, rows) = crate::io::csv::read(field)?;
        let hw = crate::io::csv::column_f64(field, &h, &rows, "hw")?;
        let min_flux_e = p.threshold_e / PEAK_FRACTION_BOUND;
        let zp = base.photometry.zero_point_e_per_s;
        let keep: Vec<&Vec<String>> = rows
            .iter()
            .zip(&hw)
            .filter(|(_, m)| {
                crate::photometry::electrons_per_s(**m, zp) * base.detector.exposure_s >= min_flux_e
            })
            .map(|(r, _)| r)
            .collect();
        // every star: the field itself, in its own order (so a remake is the exposure's own charge)
        let whole_field = keep.len() == rows.len();
        let source = if whole_field {
            field.to_path_buf()
        } else {
            let header: Vec<&str> = h.iter().map(String::as_str).collect();
            let cells: Vec<Vec<Cell>> = keep
                .iter()
                .map(|r| r.iter().map(|v| Cell::S(v.clone())).collect())
                .collect();
            crate::io::csv::write(bright, &header, &cells)?;
            bright.to_path_buf()
        };
        Ok(Self {
            bright_field: (!keep.is_empty()).then_some(source),
            whole_field,
            maps: BTreeMap::new(),
            made: 0,
        })
    }

    /// Keep exposure `index`'s own trap-filling charge (`fps` simulated `exp`) when every star of the field
    /// fills traps — then it is what a remake would give, to the bit; otherwise nothing is done.
    pub fn remember(
        &mut self,
        index: usize,
        fps: &FocalPlaneSimulator,
        exp: &FocalPlaneExposure,
        base: &Config,
    ) {
        if !self.whole_field {
            return;
        }
        let maps = fps
            .arrays
            .iter()
            .zip(&exp.arrays)
            .map(|(a, x)| charge_map(base, &a.collected(&x.star_e)))
            .collect();
        self.maps.insert(index, maps);
    }

    /// The persistence exposure `e` of `plan` collects on each array, e⁻ per pixel (empty when
    /// persistence is off or nothing bright came before within the lookback).
    pub fn released_e(
        &mut self,
        session: &Session,
        plan: &Plan,
        base: &Config,
        e: &PlannedExposure,
    ) -> Result<Vec<Vec<f32>>, SequenceError> {
        let Some(bright) = self.bright_field.clone() else {
            return Ok(Vec::new());
        };
        let p = &base.detector.persistence;
        let t = base.detector.exposure_s;
        // the earlier exposures within the lookback, with the gap from each one's end to e's start
        let earlier: Vec<(usize, f64)> = plan.exposures[..e.index.min(plan.exposures.len())]
            .iter()
            .rev()
            .map(|q| (q.index, e.start.seconds_since(&q.start) - t))
            .take_while(|(_, gap)| *gap <= p.lookback_s)
            .collect();
        self.maps.retain(|k, _| earlier.iter().any(|(q, _)| q == k));
        for (q, _) in &earlier {
            if !self.maps.contains_key(q) {
                let maps = charge_maps(session, plan, base, &plan.exposures[*q], &bright)?;
                self.maps.insert(*q, maps);
                self.made += 1;
            }
        }
        let n = base.instrument.detector_px;
        let arrays = self.maps.values().next().map_or(0, Vec::len);
        Ok((0..arrays)
            .map(|k| {
                let list: Vec<(f64, &ChargeMap)> = earlier
                    .iter()
                    .filter_map(|(q, gap)| self.maps.get(q).map(|m| (*gap, &m[k])))
                    .collect();
                released_e(base, n, &list)
            })
            .collect())
    }
}

/// The trap-filling charge exposure `q` collected on each array from the bright stars of `bright`.
fn charge_maps(
    session: &Session,
    plan: &Plan,
    base: &Config,
    q: &PlannedExposure,
    bright: &Path,
) -> Result<Vec<ChargeMap>, SequenceError> {
    let mut c = exposure_config(base, plan, q);
    c.scene.kind = SceneKind::Catalogue;
    c.scene.catalogue = Some(bright.to_path_buf());
    let fps = session.new_focal_plane(&c)?;
    fps.arrays
        .iter()
        .map(|a| Ok(charge_map(base, &a.collected_star_e(0)?)))
        .collect()
}

/// The pixels of an array's collected star charge that fill traps.
fn charge_map(base: &Config, charge_e: &[f64]) -> ChargeMap {
    ChargeMap::bright(
        charge_e,
        &base.detector.persistence,
        base.detector.full_well_e,
    )
}
