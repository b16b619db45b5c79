//! A transit-monitoring observation as a file (`[transit]` in TOML): the target and its comparison stars,
//! the stare's length and cadence, the windowed co-added readout, the slow pointing drift, the pixel's
//! response, the photometry and the injected transit.
//!
//! Choices (the mission's figures were not found; each is a knob): the plate of 12.5 s (JASMINE-imagesim's
//! planet example: 200 plates of 12.5 s), read as co-added windowed sub-exposures so that bright targets do
//! not saturate; a target of Hw 9.7 (that example's brightest unsaturated star) and J − H = 0.6 (a mid-M
//! dwarf); 20 comparison stars 0–1.5 mag fainter within 400 px; a drift of 20 mas/h plus 30 mas at the orbital
//! period (96.7 min at 600 km); the parabolic intra-pixel response of amplitude 0.12; windows of 31 px with the
//! sky from 11–14 px and the aperture chosen per stare; a 0.3 % transit (the
//! full-success requirement) of 1.5 h (P = 14 d, a/R★ = 71.5: the example's 3-R⊕ planet of a 0.2-R☉ star)
//! with u = (0.1, 0.3).

use serde::{Deserialize, Serialize};
use std::path::Path;

/// The file's one table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitFile {
    pub transit: Spec,
}

/// How the light curve is cleaned of what the pointing does to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Decorrelation {
    /// The differential light curve as measured.
    None,
    /// Regressed on the target's measured centroid (x, y, their squares and product): the pixel-level
    /// decorrelation of Spitzer and K2, reduced to the centroid.
    #[default]
    Centroid,
    /// Regressed on the telemetry's mean pointing of each plate (and its square terms) and its jitter σ.
    Telemetry,
}

/// Which photometry the light curve uses (both are measured and written).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PhotometryKind {
    #[default]
    Aperture,
    Psf,
}

/// A transit-monitoring stare.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Spec {
    /// The target's Hw magnitude and colour.
    pub target_hw: f64,
    pub target_j_minus_h: f64,
    /// Comparison stars, their magnitudes `target_hw + [dmag_min, dmag_max]` and J − H
    /// `target_j_minus_h ± comparison_jh_spread` (uniform), placed uniformly within `field_radius_px` of the
    /// target.
    pub comparisons: usize,
    pub comparison_dmag_min: f64,
    pub comparison_dmag_max: f64,
    pub comparison_jh_spread: f64,
    pub field_radius_px: f64,
    /// The stare's length, hours.
    pub duration_h: f64,
    /// Each plate's integration, s (the cadence adds `readout.t_overhead_s`).
    pub plate_s: f64,
    /// Each windowed sub-exposure, s (the plate is `plate_s / exposure_s` of them co-added); 0 = the longest
    /// `plate_s / n` at which no star's peak pixel fills the well.
    pub exposure_s: f64,
    /// Side of the square window read around each star, px (odd).
    pub window_px: usize,
    /// Linear pointing drift, mas per hour, along `drift_angle_deg` from +x.
    pub drift_mas_per_h: f64,
    pub drift_angle_deg: f64,
    /// Orbital (thermal) drift: amplitude per axis, mas, at `orbital_period_min`.
    pub orbital_drift_mas: f64,
    pub orbital_period_min: f64,
    /// The telemetry's error on each plate's mean pointing, 1σ per axis, mas.
    pub telemetry_error_mas: f64,
    /// The parabolic intra-pixel response's amplitude (`detector.intra_pixel = { kind = "parabolic" }`);
    /// 0 = uniform; negative = keep the configuration's `detector.intra_pixel`.
    pub intra_pixel_amplitude: f64,
    /// Aperture radius, px: 0 = chosen per stare among [`APERTURE_CHOICES_PX`] (those within the annulus)
    /// as the one whose decorrelated light curve scatters least from plate to plate (the habit of the K2 and
    /// TESS pipelines, whose apertures minimise the CDPP). The sky annulus, px.
    pub aperture_px: f64,
    pub annulus_in_px: f64,
    pub annulus_out_px: f64,
    pub photometry: PhotometryKind,
    pub decorrelate: Decorrelation,
    /// The injected transit: depth (Rp/R★)² (0 = none), period, a/R★, impact parameter, mid-transit time from
    /// the stare's start (negative = mid-stare), quadratic limb darkening.
    pub depth: f64,
    pub period_days: f64,
    pub a_over_rs: f64,
    pub impact: f64,
    pub t0_h: f64,
    pub limb_darkening: [f64; 2],
}

impl Default for Spec {
    fn default() -> Self {
        Self {
            target_hw: 9.7,
            target_j_minus_h: 0.6,
            comparisons: 20,
            comparison_dmag_min: 0.0,
            comparison_dmag_max: 1.5,
            comparison_jh_spread: 0.15,
            field_radius_px: 400.0,
            duration_h: 6.5,
            plate_s: 12.5,
            exposure_s: 0.0,
            window_px: 31,
            drift_mas_per_h: 20.0,
            drift_angle_deg: 30.0,
            orbital_drift_mas: 30.0,
            orbital_period_min: 96.7,
            telemetry_error_mas: 10.0,
            intra_pixel_amplitude: 0.12,
            aperture_px: 0.0,
            annulus_in_px: 11.0,
            annulus_out_px: 14.0,
            photometry: PhotometryKind::Aperture,
            decorrelate: Decorrelation::Centroid,
            depth: 0.003,
            period_days: 14.0,
            a_over_rs: 71.5,
            impact: 0.0,
            t0_h: -1.0,
            limb_darkening: [0.1, 0.3],
        }
    }
}

/// The aperture radii an automatic choice tries, px.
pub const APERTURE_CHOICES_PX: [f64; 7] = [3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0];

/// Most plates one stare may take (≈ 2 weeks at 12.6 s; memory and time grow with it).
pub const MAX_PLATES: usize = 100_000;
/// Most memory the stare's windows may take, bytes (plates × stars × window² × 4).
pub const MAX_WINDOW_BYTES: f64 = 4e9;
/// Most comparison stars.
pub const MAX_COMPARISONS: usize = 200;

/// A field's error: `transit.field = value: allowed`.
fn bad(field: &str, value: String, allowed: &str) -> Result<(), String> {
    Err(format!("transit.{field} = {value}: {allowed}"))
}

impl Spec {
    /// Read a transit file (`[transit]` with any of [`Spec`]'s fields; the rest keep their defaults).
    pub fn load(path: &Path) -> Result<Spec, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("transit file {}: {e}", path.display()))?;
        let f: TransitFile = toml::from_str(&text)
            .map_err(|e| format!("transit file {}: {}", path.display(), e.message()))?;
        Ok(f.transit)
    }

    /// Set one field from its TOML text (`depth`, `0.003`; a bare word is a string): the stare with it
    /// changed, or an error naming the field (validation comes once, when the stare runs).
    pub fn set(&self, field: &str, value: &str) -> Result<Spec, String> {
        let field = field.trim().trim_start_matches("transit.");
        let mut table = toml::Value::try_from(self).map_err(|e| e.to_string())?;
        let v: toml::Value = toml::from_str::<toml::Table>(&format!("v = {}", value.trim()))
            .ok()
            .and_then(|t| t.get("v").cloned())
            .unwrap_or_else(|| toml::Value::String(value.trim().to_string()));
        match table.as_table_mut() {
            Some(t) if t.contains_key(field) => {
                t.insert(field.to_string(), v);
            }
            _ => return Err(format!("transit.{field}: the stare has no such field")),
        }
        table.try_into().map_err(|e: toml::de::Error| {
            format!("transit.{field} = {}: {}", value.trim(), e.message())
        })
    }

    /// The aperture radii measured: the spec's, or the automatic choice's candidates.
    pub fn aperture_radii_px(&self) -> Vec<f64> {
        if self.aperture_px > 0.0 {
            vec![self.aperture_px]
        } else {
            APERTURE_CHOICES_PX
                .iter()
                .copied()
                .filter(|r| *r <= self.annulus_in_px)
                .collect()
        }
    }

    /// Plates in the stare at cadence `cadence_s`.
    pub fn plates(&self, cadence_s: f64) -> usize {
        (self.duration_h * 3600.0 / cadence_s).floor().max(0.0) as usize
    }

    /// The injected transit on the light curve's clock (days from the stare's start), or `None` for depth 0.
    pub fn transit(&self) -> Option<crate::scene::transit::Transit> {
        if self.depth <= 0.0 {
            return None;
        }
        let t0_h = if self.t0_h < 0.0 {
            0.5 * self.duration_h
        } else {
            self.t0_h
        };
        let inc = (self.impact / self.a_over_rs)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        Some(crate::scene::transit::Transit {
            t0_days: t0_h / 24.0,
            period_days: self.period_days,
            rp_over_rs: self.depth.sqrt(),
            a_over_rs: self.a_over_rs,
            inclination_deg: inc,
            u1: self.limb_darkening[0],
            u2: self.limb_darkening[1],
        })
    }

    /// Check every field, naming it and its allowed range (the saturation check needs the PSF: the
    /// observation's).
    pub fn validate(&self, cadence_s: f64) -> Result<(), String> {
        self.check_stars()?;
        self.check_plates(cadence_s)?;
        self.check_photometry()?;
        self.check_transit()
    }

    /// The target, its comparisons and the field they are drawn from.
    fn check_stars(&self) -> Result<(), String> {
        let finite = [
            ("target_hw", self.target_hw),
            ("target_j_minus_h", self.target_j_minus_h),
            ("comparison_dmag_min", self.comparison_dmag_min),
            ("comparison_dmag_max", self.comparison_dmag_max),
            ("comparison_jh_spread", self.comparison_jh_spread),
            ("field_radius_px", self.field_radius_px),
            ("duration_h", self.duration_h),
            ("plate_s", self.plate_s),
            ("exposure_s", self.exposure_s),
            ("drift_mas_per_h", self.drift_mas_per_h),
            ("drift_angle_deg", self.drift_angle_deg),
            ("orbital_drift_mas", self.orbital_drift_mas),
            ("orbital_period_min", self.orbital_period_min),
            ("telemetry_error_mas", self.telemetry_error_mas),
            ("intra_pixel_amplitude", self.intra_pixel_amplitude),
            ("aperture_px", self.aperture_px),
            ("annulus_in_px", self.annulus_in_px),
            ("annulus_out_px", self.annulus_out_px),
            ("depth", self.depth),
            ("period_days", self.period_days),
            ("a_over_rs", self.a_over_rs),
            ("impact", self.impact),
            ("t0_h", self.t0_h),
        ];
        if let Some((f, v)) = finite.iter().find(|(_, v)| !v.is_finite()) {
            return bad(f, v.to_string(), "must be a finite number");
        }
        if !(-2.0..=20.0).contains(&self.target_hw) {
            return bad("target_hw", self.target_hw.to_string(), "allowed -2 … 20");
        }
        if !(-1.0..=5.0).contains(&self.target_j_minus_h) {
            return bad(
                "target_j_minus_h",
                self.target_j_minus_h.to_string(),
                "allowed -1 … 5",
            );
        }
        if !(1..=MAX_COMPARISONS).contains(&self.comparisons) {
            return bad(
                "comparisons",
                self.comparisons.to_string(),
                &format!("allowed 1 … {MAX_COMPARISONS} (the differential light curve needs one)"),
            );
        }
        if !(self.comparison_dmag_min >= 0.0
            && self.comparison_dmag_min <= self.comparison_dmag_max
            && self.comparison_dmag_max <= 10.0)
        {
            return bad(
                "comparison_dmag_min, comparison_dmag_max",
                format!("{}, {}", self.comparison_dmag_min, self.comparison_dmag_max),
                "allowed 0 ≤ min ≤ max ≤ 10 (comparisons no brighter than the target)",
            );
        }
        if !(0.0..=1.0).contains(&self.comparison_jh_spread) {
            return bad(
                "comparison_jh_spread",
                self.comparison_jh_spread.to_string(),
                "allowed 0 … 1",
            );
        }
        if !(self.field_radius_px >= self.window_px as f64 && self.field_radius_px <= 900.0) {
            return bad(
                "field_radius_px",
                self.field_radius_px.to_string(),
                "allowed window_px … 900",
            );
        }
        Ok(())
    }

    /// The plates and sub-exposures, the stare's length and its windows (and the memory they take).
    fn check_plates(&self, cadence_s: f64) -> Result<(), String> {
        if !(self.plate_s > 0.0 && self.plate_s <= 600.0) {
            return bad("plate_s", self.plate_s.to_string(), "allowed (0, 600]");
        }
        if self.exposure_s != 0.0 {
            let n = self.plate_s / self.exposure_s;
            if !(self.exposure_s > 0.0 && (n - n.round()).abs() < 1e-6 && n.round() >= 1.0) {
                return bad(
                    "exposure_s",
                    self.exposure_s.to_string(),
                    &format!(
                        "allowed 0 (automatic) or plate_s / n for a whole n ≥ 1 ({} s, {} s, …)",
                        self.plate_s,
                        self.plate_s / 2.0
                    ),
                );
            }
        }
        let plates = self.plates(cadence_s);
        if !(self.duration_h > 0.0) || !(2..=MAX_PLATES).contains(&plates) {
            return bad(
                "duration_h",
                self.duration_h.to_string(),
                &format!(
                    "allowed 2 … {MAX_PLATES} plates of {cadence_s:.2} s: {:.3} … {:.0} h",
                    2.0 * cadence_s / 3600.0,
                    MAX_PLATES as f64 * cadence_s / 3600.0
                ),
            );
        }
        if !(self.window_px % 2 == 1 && (9..=101).contains(&self.window_px)) {
            return bad(
                "window_px",
                self.window_px.to_string(),
                "allowed odd 9 … 101",
            );
        }
        let bytes =
            plates as f64 * (self.comparisons + 1) as f64 * (self.window_px as f64).powi(2) * 4.0;
        if bytes > MAX_WINDOW_BYTES {
            return bad(
                "duration_h",
                self.duration_h.to_string(),
                &format!(
                    "the windows of {plates} plates × {} stars × {}² px would take {:.1} GB (at most {:.0} GB): \
                     shorten the stare, or lower comparisons or window_px",
                    self.comparisons + 1,
                    self.window_px,
                    bytes / 1e9,
                    MAX_WINDOW_BYTES / 1e9
                ),
            );
        }
        Ok(())
    }

    /// The aperture and annulus, the pointing drifts, the telemetry's error and the intra-pixel response.
    fn check_photometry(&self) -> Result<(), String> {
        let half = (self.window_px / 2) as f64;
        if !(self.aperture_px >= 0.0
            && self.aperture_px <= self.annulus_in_px
            && self.annulus_in_px >= APERTURE_CHOICES_PX[0]
            && self.annulus_in_px < self.annulus_out_px
            && self.annulus_out_px <= half)
        {
            return bad(
                "aperture_px, annulus_in_px, annulus_out_px",
                format!(
                    "{}, {}, {}",
                    self.aperture_px, self.annulus_in_px, self.annulus_out_px
                ),
                &format!(
                    "allowed 0 (automatic) or 0 < aperture ≤ annulus_in; {} ≤ annulus_in < annulus_out ≤ \
                     window_px/2 = {half}",
                    APERTURE_CHOICES_PX[0]
                ),
            );
        }
        for (f, v, hi) in [
            ("drift_mas_per_h", self.drift_mas_per_h, 5000.0),
            ("orbital_drift_mas", self.orbital_drift_mas, 5000.0),
            ("telemetry_error_mas", self.telemetry_error_mas, 5000.0),
        ] {
            if !(0.0..=hi).contains(&v) {
                return bad(f, v.to_string(), &format!("allowed 0 … {hi}"));
            }
        }
        if !(self.orbital_period_min > 0.0) {
            return bad(
                "orbital_period_min",
                self.orbital_period_min.to_string(),
                "must be > 0",
            );
        }
        if self.intra_pixel_amplitude >= 0.5 {
            return bad(
                "intra_pixel_amplitude",
                self.intra_pixel_amplitude.to_string(),
                "allowed < 0.5 (negative: the configuration's map; 0: uniform)",
            );
        }
        Ok(())
    }

    /// The injected transit: its depth, and, when there is one, its orbit and its place in the stare.
    fn check_transit(&self) -> Result<(), String> {
        if !(0.0..1.0).contains(&self.depth) {
            return bad("depth", self.depth.to_string(), "allowed 0 (none) … < 1");
        }
        if self.depth > 0.0 {
            if !(self.period_days > 0.0) {
                return bad(
                    "period_days",
                    self.period_days.to_string(),
                    "must be > 0 (a period of zero is no orbit)",
                );
            }
            if !(0.0..1.0 + self.depth.sqrt()).contains(&self.impact) {
                return bad(
                    "impact",
                    self.impact.to_string(),
                    "allowed 0 … < 1 + √depth (the planet must cross its star)",
                );
            }
            if self.t0_h > self.duration_h {
                return bad(
                    "t0_h",
                    self.t0_h.to_string(),
                    &format!(
                        "allowed negative (mid-stare) or 0 … duration_h = {}",
                        self.duration_h
                    ),
                );
            }
            let Some(t) = self.transit() else {
                return Ok(());
            };
            t.validate()?;
            let d_h = t.duration_days() * 24.0;
            if d_h >= self.duration_h {
                return bad(
                    "duration_h",
                    self.duration_h.to_string(),
                    &format!(
                        "must exceed the transit's duration, {d_h:.2} h (a transit longer than the stare \
                         has no baseline: lengthen the stare or raise a_over_rs)"
                    ),
                );
            }
        }
        Ok(())
    }
}
