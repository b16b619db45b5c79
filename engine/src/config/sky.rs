//! Configuration of the sky side: the pointing (`[sky]`), the focal plane (`[focal_plane]`) and the mock
//! Galactic-bulge field (`[scene.bulge]`).

use serde::{Deserialize, Serialize};

/// Where the telescope points: the images' world coordinate system (`engine::sky`). The default is the
/// Galactic centre (Sgr A*, ICRS), JASMINE's survey field, with the detector's +y to the north.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Sky {
    /// Right ascension of the optical axis (ICRS), degrees, 0 ≤ RA < 360.
    pub ra_deg: f64,
    /// Declination of the optical axis (ICRS), degrees, −90 … 90.
    pub dec_deg: f64,
    /// Position angle of the focal plane's +y axis, degrees east of north.
    pub pa_deg: f64,
}

impl Default for Sky {
    fn default() -> Self {
        Self {
            ra_deg: 266.416_8,
            dec_deg: -29.007_8,
            pa_deg: 0.0,
        }
    }
}

/// When the exposures are taken, from where, and whether the stars are seen at their apparent place
/// (`engine::time`, `sky::orbit`, `sky::apparent`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Observation {
    /// UTC of the ACE series' t = 0, ISO 8601 (`YYYY-MM-DDThh:mm:ss[.fff]`): image i starts `TSTART`
    /// seconds later. The default, the March equinox of 2031, is a date in JASMINE's planned mission when
    /// the Galactic centre is 90° from the Sun (the bulge is observed in spring and autumn) — a choice.
    pub start_utc: String,
    /// Julian epoch (TDB) of the scene's sky positions: a catalogue's reference epoch (2016.0 for Gaia
    /// DR3), and the epoch the mock bulge is drawn at.
    pub catalogue_epoch_jyear: f64,
    /// Stars of a sky scene at their apparent place at image 0's mid-exposure: proper motion, parallax
    /// (from the spacecraft), light deflection by the Sun and aberration; the pointing is the apparent
    /// direction of `sky.ra_deg, dec_deg`. Off: the catalogue place, unmoved (the earlier behaviour).
    pub apparent_place: bool,
    /// The spacecraft's circular sun-synchronous orbit: height above the equator, km (JASMINE: 600).
    pub orbit_altitude_km: f64,
    /// Local time of the orbit's ascending node, hours (JASMINE: 6, a dawn-dusk orbit).
    pub orbit_ltan_h: f64,
    /// Argument of latitude at `start_utc`, degrees.
    pub orbit_phase_deg: f64,
}

impl Default for Observation {
    fn default() -> Self {
        Self {
            start_utc: "2031-03-21T00:00:00".into(),
            catalogue_epoch_jyear: 2031.0,
            apparent_place: true,
            orbit_altitude_km: 600.0,
            orbit_ltan_h: 6.0,
            orbit_phase_deg: 0.0,
        }
    }
}

/// How many arrays the focal plane holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// One array with the optical axis at its centre (the paper's experiment; the default).
    Single,
    /// JASMINE's 2 × 2 arrays around the optical axis, `gap_px` apart, each turned by its rotation.
    Quad,
}

/// One SIP coefficient: `value` multiplies u^p v^q (u, v: focal-plane pixels from the optical axis).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SipTerm {
    pub p: usize,
    pub q: usize,
    pub value: f64,
}

/// The focal plane: layout, gaps, the arrays' rotations and the optical distortion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FocalPlaneLayout {
    pub layout: Layout,
    /// Gap between neighbouring arrays' full formats, pixels (300 px = 3 mm of 10-µm pixels, the mission's
    /// design).
    pub gap_px: f64,
    /// Each array's rotation on the sky (0, 90, 180 or 270°; array 0 lower left, 1 lower right, 2 upper
    /// left, 3 upper right): its rows, channels and rolling readout run along a different direction.
    pub rotations_deg: [f64; 4],
    /// Forward SIP distortion (Shupe et al. 2005) in focal-plane pixel axes from the optical axis: the true
    /// position of a star is (u + A(u, v), v + B(u, v)) through the linear WCS. Orders 2 … 9; empty: none.
    /// The default is a third-order radial distortion, `A = k(u³ + u v²)`, `B = k(u² v + v³)`, with
    /// k = 1.1 × 10⁻¹⁰ px⁻²: 3 px (1.4″, 0.1 % of the radius) at the focal plane's corner (r ≈ 3000 px), 0.3 px
    /// at the single array's. The leading term of a rotationally symmetric telescope's distortion at an
    /// amplitude typical of a three-mirror anastigmat; JASMINE's own design figure was not found — a choice,
    /// to be replaced by the optical design's coefficients.
    pub sip_a: Vec<SipTerm>,
    pub sip_b: Vec<SipTerm>,
    /// Each array's displacement from its nominal place as assembled, focal-plane pixels (quad only;
    /// within ±gap_px/2). The default is one fixed draw of σ = 10 px per axis (100 µm: the prior of the
    /// mission's plate model for a detector offset, JASMINE-Mission/jasmine_warpfield) — a choice.
    pub array_offsets_px: [[f64; 2]; 4],
    /// Each array's further turn as assembled, degrees (quad only; within ±1°). The default is one fixed
    /// draw of σ = 0.1° (the same plate model's prior) — a choice.
    pub array_rotation_errors_deg: [f64; 4],
}

/// The default distortion's coefficient k, px⁻² (see [`FocalPlaneLayout::sip_a`]).
pub const DEFAULT_RADIAL_DISTORTION_PER_PX2: f64 = 1.1e-10;

impl Default for FocalPlaneLayout {
    fn default() -> Self {
        Self {
            layout: Layout::Single,
            gap_px: 300.0,
            rotations_deg: [0.0, 90.0, 180.0, 270.0],
            sip_a: vec![
                SipTerm {
                    p: 3,
                    q: 0,
                    value: DEFAULT_RADIAL_DISTORTION_PER_PX2,
                },
                SipTerm {
                    p: 1,
                    q: 2,
                    value: DEFAULT_RADIAL_DISTORTION_PER_PX2,
                },
            ],
            sip_b: vec![
                SipTerm {
                    p: 2,
                    q: 1,
                    value: DEFAULT_RADIAL_DISTORTION_PER_PX2,
                },
                SipTerm {
                    p: 0,
                    q: 3,
                    value: DEFAULT_RADIAL_DISTORTION_PER_PX2,
                },
            ],
            array_offsets_px: [[4.2, -7.9], [-6.3, 2.1], [9.4, 5.6], [-1.8, -10.7]],
            array_rotation_errors_deg: [0.06, -0.11, 0.03, -0.08],
        }
    }
}

/// The built-in mock Galactic-bulge field: stars uniform on the sky over the focal plane, magnitudes from a
/// power-law luminosity function and colours from a reddening distribution, drawn from the seed.
///
/// * Luminosity function dN/dHw ∝ 10^(α·Hw) on [`hw_min`, `hw_max`], α = 0.30: the K-band luminosity
///   function of the Galactic-centre giants (Schödel et al. 2007, A&A 469, 125: α = 0.30 ± 0.01), taken
///   over to Hw unchanged.
/// * Surface density 100 stars per arcmin² with Hw ≤ 17: GALACTICNUCLEUS (Nogueras-Lara et al. 2019,
///   A&A 631, A20) counts 3.3 × 10⁶ stars in 0.3 deg² (≈ 2000 per arcmin² detected in H, to H ≈ 19.5);
///   Hw 17 is H ≈ 15.4 at J − H = 2 (SPEC's Hw − H relation), 10^(0.3 × (15.4 − 19.5)) ≈ 0.06 of them:
///   ≈ 120 per arcmin². An array (236 arcmin² photosensitive) then holds ≈ 2.4 × 10⁴ stars, the focal
///   plane ≈ 10⁵ — inside the 10⁴–10⁵ per array the mission quotes.
/// * J − H: a normal distribution of mean 2.2 and σ 0.35 clipped to [1.5, 3.0] — the intrinsic colours of
///   red giants (≈ 0.7) plus the Galactic-centre reddening E(J − H) ≈ 1–2.3 (Nogueras-Lara et al. 2018,
///   A&A 610, A83).
///
/// * Motion (drawn from its own stream: positions and magnitudes do not change with it): distances normal
///   around 8.2 kpc (the Sun–Galactic-centre distance of the Koshimoto et al. 2021 model) with σ 1.0 kpc,
///   clipped to 5 … 12 kpc (the bar's depth along the line of sight; a choice), parallax = 1/d; proper
///   motions normal in Galactic (µl*, µb) around Sgr A*'s apparent motion (−6.41, −0.22) mas/yr (Reid &
///   Brunthaler 2020, ApJ 892, 39: the reflex of the Sun's motion, which the bulge shares on average) with
///   σ 3.0 and 2.5 mas/yr (the bar's ≈ 150/78/82 km/s dispersions of Koshimoto et al. 2021 projected at
///   8.2 kpc, 1 mas/yr = 38.9 km/s). No disc foreground: a bulge-only field.
///
/// Every field is a knob: an astronomer's own field is a catalogue (`scene.kind = "catalogue"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Bulge {
    /// Stars per square arcminute with `hw_min` ≤ Hw ≤ `density_hw_limit`: the field's density, counted to
    /// a magnitude of its own so that `hw_max` cuts the same field.
    pub density_per_arcmin2: f64,
    /// The magnitude the density is counted to (17: where the default's figure comes from).
    pub density_hw_limit: f64,
    /// The brightest and faintest Hw drawn. The field holds the luminosity function's share of the density
    /// between them: `density_per_arcmin2` × (10^(α·hw_max) − 10^(α·hw_min)) / (10^(α·density_hw_limit) −
    /// 10^(α·hw_min)) per arcmin² ([`Bulge::drawn_per_arcmin2`]). A lower `hw_max` cuts the faint stars off the
    /// same field (at 15, a quarter of the default's stars are left); `density_hw_limit = hw_max` makes the
    /// density the count drawn, whatever the range.
    pub hw_min: f64,
    pub hw_max: f64,
    /// α of dN/dHw ∝ 10^(α·Hw).
    pub lf_slope: f64,
    pub jh_mean: f64,
    pub jh_sigma: f64,
    pub jh_min: f64,
    pub jh_max: f64,
    /// Mean distance, kpc.
    pub distance_kpc: f64,
    /// Its spread (normal, clipped to 5 … 12 kpc), kpc.
    pub distance_sigma_kpc: f64,
    /// Mean proper motion in Galactic longitude, µl* = µl cos b, mas/yr.
    pub pm_l_mean_mas_per_yr: f64,
    /// Mean proper motion in Galactic latitude, mas/yr.
    pub pm_b_mean_mas_per_yr: f64,
    /// Proper-motion dispersion in µl*, mas/yr.
    pub pm_l_sigma_mas_per_yr: f64,
    /// Proper-motion dispersion in µb, mas/yr.
    pub pm_b_sigma_mas_per_yr: f64,
}

impl Bulge {
    /// Stars drawn per arcmin²: the density's share of the luminosity function dN/dHw ∝ 10^(α·Hw) between
    /// `hw_min` and `hw_max`, the density counted between `hw_min` and `density_hw_limit` (∫ 10^(α·m) dm ∝
    /// 10^(α·m); uniform in Hw for α = 0). Exactly the density when `density_hw_limit = hw_max`.
    pub fn drawn_per_arcmin2(&self) -> f64 {
        let f = |m: f64| {
            if self.lf_slope.abs() < 1e-12 {
                m
            } else {
                10f64.powf(self.lf_slope * m)
            }
        };
        let share = (f(self.hw_max) - f(self.hw_min)) / (f(self.density_hw_limit) - f(self.hw_min));
        self.density_per_arcmin2 * share
    }
}

impl Default for Bulge {
    fn default() -> Self {
        Self {
            density_per_arcmin2: 100.0,
            density_hw_limit: 17.0,
            hw_min: 8.0,
            hw_max: 17.0,
            lf_slope: 0.30,
            jh_mean: 2.2,
            jh_sigma: 0.35,
            jh_min: 1.5,
            jh_max: 3.0,
            distance_kpc: 8.2,
            distance_sigma_kpc: 1.0,
            pm_l_mean_mas_per_yr: -6.41,
            pm_b_mean_mas_per_yr: -0.22,
            pm_l_sigma_mas_per_yr: 3.0,
            pm_b_sigma_mas_per_yr: 2.5,
        }
    }
}
