//! A step-stare observation sequence as a file (`[sequence]` in TOML): the survey region, the pattern of
//! stares, the exposures per stare, the visits (epochs) and the per-stare pointing errors.
//!
//! Defaults from the public JASMINE descriptions (JASMINE-Mission/jasmine_toolkit,
//! `utils/constants/jasmine_constant.py` and `operation/pointing_plan*.py`): stares a half field of view
//! apart, 26 exposures per stare (the toolkit's count at 6 fields per orbit), a 115-s manoeuvre for a small
//! step, the bulge observed in spring and autumn, each visit's pattern shifted by the inter-array gap so that
//! one visit's gaps fall on the next one's arrays. The region's size (3 × 2 stares around the Galactic
//! centre), the orientation (focal-plane +y to Galactic north) and the per-stare errors (2″ pointing per
//! axis, 10″ roll, 1σ) are choices: the mission's figures were not found.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// The sequence file's one table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SequenceFile {
    pub sequence: Spec,
}

/// A step-stare sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Spec {
    /// The region's centre, Galactic longitude and latitude, degrees.
    pub centre_l_deg: f64,
    pub centre_b_deg: f64,
    /// Stares along l and along b.
    pub stares_l: usize,
    pub stares_b: usize,
    /// Step between neighbouring stares, in fields of view (the focal plane's side): 0.5 in the paper.
    pub step_fields: f64,
    /// Exposures per stare, back to back at the readout's cadence.
    pub exposures_per_stare: usize,
    /// Time between the last exposure of a stare and the first of the next, s.
    pub manoeuvre_s: f64,
    /// UTC start of each visit (ISO 8601); each visit observes the whole pattern.
    pub visits_utc: Vec<String>,
    /// Visit v's pattern is shifted by v × this in l and in b, focal-plane pixels: the gaps between the
    /// arrays of one visit fall on the arrays of the next (the toolkit's pattern steps by the inter-array
    /// gap; 300 px = 3 mm).
    pub visit_dither_px: f64,
    /// Per-stare pointing error, 1σ per axis, arcsec.
    pub pointing_error_arcsec: f64,
    /// Per-stare roll error, 1σ, arcsec.
    pub roll_error_arcsec: f64,
}

impl Default for Spec {
    fn default() -> Self {
        Self {
            centre_l_deg: 0.0,
            centre_b_deg: 0.0,
            stares_l: 3,
            stares_b: 2,
            step_fields: 0.5,
            exposures_per_stare: 26,
            manoeuvre_s: 115.0,
            visits_utc: vec!["2031-03-21T00:00:00".into(), "2031-09-22T00:00:00".into()],
            visit_dither_px: 300.0,
            pointing_error_arcsec: 2.0,
            roll_error_arcsec: 10.0,
        }
    }
}

/// Most exposures a sequence may plan (memory and time grow with it).
pub const MAX_EXPOSURES: usize = 100_000;

impl Spec {
    /// Read a sequence file (`[sequence]` with any of [`Spec`]'s fields; the rest keep their defaults).
    pub fn load(path: &Path) -> Result<Spec, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("sequence file {}: {e}", path.display()))?;
        let f: SequenceFile = toml::from_str(&text)
            .map_err(|e| format!("sequence file {}: {}", path.display(), e.message()))?;
        f.sequence.validate()?;
        Ok(f.sequence)
    }

    /// How many exposures the sequence takes.
    pub fn exposure_count(&self) -> usize {
        self.stares_l
            .saturating_mul(self.stares_b)
            .saturating_mul(self.exposures_per_stare)
            .saturating_mul(self.visits_utc.len())
    }

    /// Check every field, naming it and its allowed range.
    pub fn validate(&self) -> Result<(), String> {
        let bad = |field: &str, value: String, allowed: &str| {
            Err(format!("sequence.{field} = {value}: {allowed}"))
        };
        if !(-180.0..=360.0).contains(&self.centre_l_deg) {
            return bad(
                "centre_l_deg",
                self.centre_l_deg.to_string(),
                "allowed -180 … 360",
            );
        }
        if !(-90.0..=90.0).contains(&self.centre_b_deg) {
            return bad(
                "centre_b_deg",
                self.centre_b_deg.to_string(),
                "allowed -90 … 90",
            );
        }
        for (field, n) in [("stares_l", self.stares_l), ("stares_b", self.stares_b)] {
            if !(1..=100).contains(&n) {
                return bad(field, n.to_string(), "allowed 1 … 100");
            }
        }
        if !(self.step_fields > 0.0 && self.step_fields <= 10.0) {
            return bad(
                "step_fields",
                self.step_fields.to_string(),
                "allowed (0, 10]",
            );
        }
        if !(1..=10_000).contains(&self.exposures_per_stare) {
            return bad(
                "exposures_per_stare",
                self.exposures_per_stare.to_string(),
                "allowed 1 … 10000",
            );
        }
        if !(0.0..=86_400.0).contains(&self.manoeuvre_s) {
            return bad(
                "manoeuvre_s",
                self.manoeuvre_s.to_string(),
                "allowed 0 … 86400",
            );
        }
        if !(0.0..=100_000.0).contains(&self.visit_dither_px) {
            return bad(
                "visit_dither_px",
                self.visit_dither_px.to_string(),
                "allowed 0 … 100000",
            );
        }
        if self.visits_utc.is_empty() {
            return bad("visits_utc", "[]".into(), "give at least one visit");
        }
        for (k, v) in self.visits_utc.iter().enumerate() {
            crate::time::Epoch::from_utc_iso(v)
                .map_err(|why| format!("sequence.visits_utc[{k}] = {why}"))?;
        }
        for (field, v) in [
            ("pointing_error_arcsec", self.pointing_error_arcsec),
            ("roll_error_arcsec", self.roll_error_arcsec),
        ] {
            if !(0.0..=3600.0).contains(&v) {
                return bad(field, v.to_string(), "allowed 0 … 3600");
            }
        }
        let n = self.exposure_count();
        if n > MAX_EXPOSURES {
            return bad(
                "exposures_per_stare",
                self.exposures_per_stare.to_string(),
                &format!("the sequence would take {n} exposures: at most {MAX_EXPOSURES}"),
            );
        }
        Ok(())
    }
}
