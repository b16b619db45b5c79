//! Scoring: the one step that reads the truth (layer 7, after the analysis). The analysis measures — positions,
//! fluxes, bounds, flags — from an image and the instrument's products; scoring matches those measurements
//! to a truth list by position and reports what they are worth.
//!
//! * [`catalogue`] — any tool's measured list (x, y) against a truth list (x, y, magnitude): completeness,
//!   accuracy and false detections per magnitude bin (`jsim score`).
//! * [`image`] — one analysis of this engine against its exposure's truth: each star's error, the accuracy
//!   report of SPEC §7, the ACE prediction beside it.
//! * [`crowded`] — the crowded-field match (position and flux), star classes and magnitude bins;
//!   [`focal_plane`] — the four arrays of a focal-plane exposure scored together, their deviation maps.
//! * [`undetected`] — the shift the undetected stars' light gives each fitted position (the crowded
//!   field's floor, explained star by star).
//! * [`vectors`] — the deviation vector map of an image; [`dataset`] — a dataset's scored results.
//!
//! With no truth the accuracy is absent (NaN; `null` in JSON, empty in CSV), never 0.

pub mod catalogue;
pub mod crowded;
pub mod dataset;
pub mod focal_plane;
pub mod image;
pub mod matching;
pub mod solution;
pub mod undetected;
pub mod vectors;

pub use catalogue::*;
