//! The instrument as built (`[as_built]`): how the telescope that takes the images departs from the design the
//! rest of the configuration describes, and what the products beside the images are made from.
//!
//! The configuration's `instrument`, `optics`, `detector` and `focal_plane` sections are the **design**: what
//! the documents say. The **as-built** instrument is drawn from it by the seeded deviations below
//! (the `instrument` module's `realise`); the images come from it, while every product an analysis reads (the model
//! PSF, the header's WCS and gain, the reference catalogue's pixel columns, `design.toml`) comes from the
//! design — unless `knowledge = "as-built"`, the `oracle` control that hands the analysis the as-built
//! instrument so that a table can show what honest knowledge costs.
//!
//! The default is the typical instrument as built ([`AsBuilt::default`]; the figures and their reasons are in
//! the default configuration's `[as_built]` block and docs/instrument-products.md). [`AsBuilt::design`] has every
//! deviation 0 — the design itself, images and products bit for bit the design's — and is the control that
//! `--instrument design` selects on the command line.

use super::{ConfigError, invalid};
use serde::{Deserialize, Serialize};

/// What the products beside the images are made from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Knowledge {
    /// The design (and calibrations with their errors): what a mission has. The default.
    #[default]
    Design,
    /// `oracle`: the as-built instrument itself — the model PSF is the as-built PSF, the header's WCS the
    /// as-built distortion, the header's gain and read noise the true ones. Never a default.
    AsBuilt,
}

impl Knowledge {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Knowledge::Design => "design",
            Knowledge::AsBuilt => "as-built (oracle)",
        }
    }
}

/// Which of the two instruments takes the images (`--instrument` on the command line, `instrument` in a sweep
/// file; the command line's `as-built|design` are the same kebab-case names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum InstrumentModel {
    /// The configuration's `[as_built]` deviations (by default the typical ones).
    #[default]
    AsBuilt,
    /// Every deviation 0: the telescope exactly as designed, the control.
    Design,
}

/// How the instrument as built departs from its design ([`AsBuilt::design`]: all 0, the design itself).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AsBuilt {
    /// The instrument's own seed: the deviations are drawn from it, not from the run's seed, so every
    /// exposure of a sequence (each with its own run seed) shares one instrument.
    #[serde(with = "super::seed")]
    pub seed: u64,
    /// Static low-order wavefront deviation over Fringe Z4–Z11 at the field's centre, nm rms of the
    /// wavefront (the terms drawn N(0, 1) in rms-normalised units, then scaled to exactly this rms).
    pub wavefront_rms_nm: f64,
    /// The deviation's change across the field, linear in x and y: nm rms of the added wavefront at the
    /// array's corner (a second Z4–Z11 draw per axis).
    pub wavefront_field_rms_nm: f64,
    /// Focus (Z4) breathing over the orbit: amplitude, nm rms of the wavefront, of
    /// `A sin(2π t / P + φ)` (φ drawn from the seed, t the dataset's first mid-exposure in TT seconds).
    pub focus_breathing_nm: f64,
    /// Period of the breathing, s (the orbit: 96.7 min = 5802 s at 600 km).
    pub breathing_period_s: f64,
    /// Low-order (quadratic) distortion beyond the design: the rms length, px, of the added displacement at
    /// the array's corner.
    pub distortion_px: f64,
    /// Relative 1σ of the as-built conversion gain about the design's `detector.gain_e_per_adu`.
    pub gain_error: f64,
    /// Relative 1σ of the as-built read noise about the design's `detector.read_noise_per_read_e`.
    pub read_noise_error: f64,
    /// Where the optical axis truly points, less where `[sky]` plans it: (east, north) on the tangent plane
    /// at the planned axis, arcsec. One pointing per dataset (a stare holds it; a sequence draws one per
    /// stare, `sequence.pointing_error_arcsec`). The header's WCS stays at the planned pointing.
    pub pointing_offset_arcsec: [f64; 2],
    /// The focal plane's true turn less the planned `sky.pa_deg`, arcsec (east of north).
    pub roll_offset_arcsec: f64,
    /// What the products are made from: the design (default) or, as an `oracle` control, the as-built
    /// instrument.
    pub knowledge: Knowledge,
}

/// The typical instrument as built: the default (each figure's reason in the default configuration's
/// `[as_built]` block; no as-built JASMINE figure is public, so each is a stated choice and a knob).
impl Default for AsBuilt {
    fn default() -> Self {
        Self {
            wavefront_rms_nm: 30.0,
            wavefront_field_rms_nm: 10.0,
            focus_breathing_nm: 10.0,
            distortion_px: 0.03,
            gain_error: 0.01,
            read_noise_error: 0.05,
            pointing_offset_arcsec: [1.4, -0.9],
            roll_offset_arcsec: 7.0,
            ..Self::design()
        }
    }
}

/// Largest wavefront deviation accepted, nm rms (a quarter wave at 1.4 µm is 350 nm: far beyond a working
/// telescope).
pub const MAX_WAVEFRONT_DEVIATION_NM: f64 = 500.0;
/// Largest distortion beyond the design accepted, px.
pub const MAX_DISTORTION_DEVIATION_PX: f64 = 10.0;
/// Largest relative gain or read-noise error accepted.
pub const MAX_RELATIVE_ERROR: f64 = 0.5;
/// Largest pointing or roll offset accepted, arcsec (1°: a pointing that missed its field; the analysis
/// finds a catalogue's offset within `analysis::registration`'s search, ≈ 20 px ≈ 9″).
pub const MAX_POINTING_OFFSET_ARCSEC: f64 = 3600.0;

impl AsBuilt {
    /// The design itself: every deviation 0, the design's knowledge (the control; `--instrument design`).
    pub fn design() -> Self {
        Self {
            seed: 1,
            wavefront_rms_nm: 0.0,
            wavefront_field_rms_nm: 0.0,
            focus_breathing_nm: 0.0,
            breathing_period_s: 5802.0,
            distortion_px: 0.0,
            gain_error: 0.0,
            read_noise_error: 0.0,
            pointing_offset_arcsec: [0.0; 2],
            roll_offset_arcsec: 0.0,
            knowledge: Knowledge::Design,
        }
    }

    /// This instrument (its seed, knowledge and breathing period) with the deviations of `deviations`.
    pub fn with_deviations_of(&self, deviations: AsBuilt) -> AsBuilt {
        AsBuilt {
            seed: self.seed,
            knowledge: self.knowledge,
            breathing_period_s: self.breathing_period_s,
            ..deviations
        }
    }

    /// These deviations for `instrument`: themselves for the as-built one, none (seed, knowledge and period
    /// kept) for the design.
    pub fn for_instrument(&self, instrument: InstrumentModel) -> AsBuilt {
        match instrument {
            InstrumentModel::AsBuilt => self.clone(),
            InstrumentModel::Design => self.realised(),
        }
    }

    /// Whether the as-built instrument is the design (every deviation 0) and the products are the design's.
    pub fn is_design(&self) -> bool {
        self.has_no_deviation() && self.knowledge == Knowledge::Design
    }

    /// Whether no deviation is switched on.
    pub fn has_no_deviation(&self) -> bool {
        self.wavefront_rms_nm == 0.0
            && self.wavefront_field_rms_nm == 0.0
            && self.focus_breathing_nm == 0.0
            && self.distortion_px == 0.0
            && self.gain_error == 0.0
            && self.read_noise_error == 0.0
            && self.pointing_offset_arcsec == [0.0; 2]
            && self.roll_offset_arcsec == 0.0
    }

    /// The same knobs with every deviation off (what a realised, as-built configuration carries: its
    /// deviations are already in its optics, distortion and detector).
    pub fn realised(&self) -> AsBuilt {
        self.with_deviations_of(AsBuilt::design())
    }

    /// One line for a run's output: the deviations switched on and what the products come from (`None` for
    /// the design itself).
    pub fn describe(&self) -> Option<String> {
        if self.is_design() {
            return None;
        }
        let parts: Vec<String> = [
            (self.wavefront_rms_nm, "nm rms wavefront (Z4–Z11)"),
            (self.wavefront_field_rms_nm, "nm rms across the array"),
            (self.focus_breathing_nm, "nm focus breathing"),
            (self.distortion_px, "px distortion beyond the design"),
            (100.0 * self.gain_error, "% gain error"),
            (100.0 * self.read_noise_error, "% read-noise error"),
            (
                self.pointing_offset_arcsec[0].hypot(self.pointing_offset_arcsec[1]),
                "arcsec pointing offset",
            ),
            (self.roll_offset_arcsec.abs(), "arcsec roll offset"),
        ]
        .iter()
        .filter(|(v, _)| *v > 0.0)
        // four decimals: a pointing offset's length is a root
        .map(|(v, what)| format!("{} {what}", (v * 1e4).round() / 1e4))
        .collect();
        let products = match self.knowledge {
            Knowledge::Design => "products from the design",
            Knowledge::AsBuilt => "ORACLE: products from the as-built instrument",
        };
        Some(format!(
            "the instrument as built (seed {}): {}; {products}",
            self.seed,
            if parts.is_empty() {
                "the design".to_string()
            } else {
                parts.join(", ")
            }
        ))
    }

    /// Check every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let p = MAX_POINTING_OFFSET_ARCSEC;
        let ranges: [(&str, f64, f64, f64); 10] = [
            (
                "as_built.wavefront_rms_nm",
                self.wavefront_rms_nm,
                0.0,
                MAX_WAVEFRONT_DEVIATION_NM,
            ),
            (
                "as_built.wavefront_field_rms_nm",
                self.wavefront_field_rms_nm,
                0.0,
                MAX_WAVEFRONT_DEVIATION_NM,
            ),
            (
                "as_built.focus_breathing_nm",
                self.focus_breathing_nm,
                0.0,
                MAX_WAVEFRONT_DEVIATION_NM,
            ),
            (
                "as_built.breathing_period_s",
                self.breathing_period_s,
                1.0,
                1.0e7,
            ),
            (
                "as_built.distortion_px",
                self.distortion_px,
                0.0,
                MAX_DISTORTION_DEVIATION_PX,
            ),
            (
                "as_built.gain_error",
                self.gain_error,
                0.0,
                MAX_RELATIVE_ERROR,
            ),
            (
                "as_built.read_noise_error",
                self.read_noise_error,
                0.0,
                MAX_RELATIVE_ERROR,
            ),
            (
                "as_built.pointing_offset_arcsec[0]",
                self.pointing_offset_arcsec[0],
                -p,
                p,
            ),
            (
                "as_built.pointing_offset_arcsec[1]",
                self.pointing_offset_arcsec[1],
                -p,
                p,
            ),
            (
                "as_built.roll_offset_arcsec",
                self.roll_offset_arcsec,
                -p,
                p,
            ),
        ];
        for (field, v, lo, hi) in ranges {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(invalid(field, v, &format!("must be in [{lo}, {hi}]")));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_deviates_and_the_design_does_not() {
        assert!(AsBuilt::design().is_design());
        assert!(AsBuilt::design().validate().is_ok());
        let typical = AsBuilt::default();
        assert!(!typical.has_no_deviation());
        assert_eq!(typical.knowledge, Knowledge::Design);
        assert!(typical.validate().is_ok());
        assert_eq!(typical.realised(), AsBuilt::design());
    }

    #[test]
    fn out_of_range_deviations_name_their_field() {
        let cases: [(&str, fn(&mut AsBuilt)); 5] = [
            ("as_built.wavefront_rms_nm", |a| a.wavefront_rms_nm = -1.0),
            ("as_built.distortion_px", |a| a.distortion_px = f64::NAN),
            ("as_built.gain_error", |a| a.gain_error = 0.9),
            ("as_built.pointing_offset_arcsec[1]", |a| {
                a.pointing_offset_arcsec[1] = -4000.0
            }),
            ("as_built.breathing_period_s", |a| {
                a.breathing_period_s = 0.0
            }),
        ];
        for (field, set) in cases {
            let mut a = AsBuilt::default();
            set(&mut a);
            let e = a.validate().expect_err(field).to_string();
            assert!(e.contains(field), "{e}");
        }
    }

    #[test]
    fn a_run_names_the_deviations_and_the_oracle() {
        assert_eq!(AsBuilt::design().describe(), None);
        let a = AsBuilt {
            wavefront_rms_nm: 30.0,
            gain_error: 0.01,
            ..AsBuilt::design()
        };
        let line = a.describe().expect("a line");
        assert!(
            line.contains("30 nm rms wavefront") && line.contains("1 % gain"),
            "{line}"
        );
        assert!(line.contains("products from the design"), "{line}");
        let oracle = AsBuilt {
            knowledge: Knowledge::AsBuilt,
            ..AsBuilt::design()
        };
        assert!(oracle.describe().expect("a line").contains("ORACLE"));
    }

    #[test]
    fn a_realised_instrument_keeps_its_seed_and_knowledge_and_deviates_no_further() {
        let a = AsBuilt {
            seed: 7,
            wavefront_rms_nm: 30.0,
            distortion_px: 0.03,
            knowledge: Knowledge::AsBuilt,
            ..AsBuilt::default()
        };
        let r = a.realised();
        assert!(r.has_no_deviation());
        assert_eq!((r.seed, r.knowledge), (7, Knowledge::AsBuilt));
    }
}
