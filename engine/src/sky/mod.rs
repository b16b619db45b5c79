//! The sky: where the telescope points and how sky positions land on an array's pixels.
//!
//! A [`Pointing`] (RA, Dec of the optical axis and the position angle of the focal plane's +y axis, east of
//! north) and an array's place in the focal plane give that array's FITS world coordinate system
//! ([`wcs::ArrayWcs`]): a gnomonic (TAN) projection — computed by the CDS `wcs`/`mapproj` crates from the very
//! header cards the image files carry — with optional SIP distortion polynomials (Shupe et al. 2005) on the
//! pixel side. Angles are degrees in the configuration and the headers, radians inside.
//!
//! When ([`crate::time`]) and from where ([`orbit`]) the exposures are taken set where the stars appear
//! ([`apparent`]): a sky scene's stars and the pointing are carried to their apparent place at image 0's
//! mid-exposure ([`scene_place`]), so the images' WCS maps pixels to the directions the spacecraft sees.

pub mod apparent;
pub mod focal_plane;
pub mod lookup_distortion;
pub mod orbit;
pub mod wcs;

use crate::config::{Config, Layout};
use focal_plane::FocalPlane;
use wcs::{ArrayWcs, Sip, SipPolynomial};

/// How many arrays the configured focal plane holds (1 or 4).
pub fn array_count(cfg: &Config) -> usize {
    match cfg.focal_plane.layout {
        Layout::Single => 1,
        Layout::Quad => 4,
    }
}

/// The 2 × 2 focal plane of `cfg` (its arrays of `instrument.detector_px`, the configured gap and turns).
pub fn focal_plane(cfg: &Config) -> FocalPlane {
    FocalPlane {
        array_px: cfg.instrument.detector_px,
        photosensitive_px: cfg.instrument.photosensitive_px,
        gap_px: cfg.focal_plane.gap_px,
        rotations_deg: cfg.focal_plane.rotations_deg,
        offsets_px: cfg.focal_plane.array_offsets_px,
        rotation_errors_deg: cfg.focal_plane.array_rotation_errors_deg,
    }
}

/// The rotation of array k on the sky (0 for the single array).
pub fn array_rotation_deg(cfg: &Config, k: usize) -> f64 {
    match cfg.focal_plane.layout {
        Layout::Single => 0.0,
        Layout::Quad => cfg.focal_plane.rotations_deg[k.min(3)],
    }
}

/// The configured forward distortion in focal-plane axes, if any.
pub fn distortion(cfg: &Config) -> Option<Sip> {
    let fp = &cfg.focal_plane;
    if fp.sip_a.is_empty() && fp.sip_b.is_empty() {
        return None;
    }
    let poly = |t: &[crate::config::SipTerm]| SipPolynomial {
        terms: t.iter().map(|t| (t.p, t.q, t.value)).collect(),
    };
    Some(Sip {
        a: poly(&fp.sip_a),
        b: poly(&fp.sip_b),
    })
}

/// UTC of the ACE series' t = 0 (`observation.start_utc`).
pub fn start_epoch(cfg: &Config) -> Result<crate::time::Epoch, String> {
    crate::time::Epoch::from_utc_iso(&cfg.observation.start_utc)
        .map_err(|why| format!("observation.start_utc = {why}"))
}

/// The instant an image starts: the series' t = 0 plus its `TSTART` (`t_start_s`).
pub fn exposure_epoch(cfg: &Config, t_start_s: f64) -> Result<crate::time::Epoch, String> {
    Ok(start_epoch(cfg)?.plus_s(t_start_s))
}

/// The spacecraft's orbit of `cfg` (its phase counted from the series' t = 0).
pub fn orbit(cfg: &Config) -> Result<orbit::Orbit, String> {
    let o = &cfg.observation;
    Ok(orbit::Orbit {
        altitude_km: o.orbit_altitude_km,
        ltan_h: o.orbit_ltan_h,
        phase_deg: o.orbit_phase_deg,
        phase_epoch: start_epoch(cfg)?,
    })
}

/// The instant of a sky scene's apparent place: image 0's mid-exposure (its start plus half the exposure
/// time). The images of one dataset share the scene: over a few minutes the differential aberration
/// changes by < 0.01 px.
pub fn scene_epoch(cfg: &Config) -> Result<crate::time::Epoch, String> {
    exposure_epoch(
        cfg,
        cfg.ace.first_exposure_start_s + cfg.detector.exposure_s / 2.0,
    )
}

/// Where a sky scene's catalogue place is carried to ([`apparent::direction`]), or `None` with
/// `observation.apparent_place` off (the catalogue place as it is).
pub fn scene_place(cfg: &Config) -> Result<Option<apparent::Place>, String> {
    if !cfg.observation.apparent_place {
        return Ok(None);
    }
    let t = scene_epoch(cfg)?;
    Ok(Some(apparent::Place {
        years: t.julian_year_tdb() - cfg.observation.catalogue_epoch_jyear,
        observer: orbit(cfg)?.observer(&t),
        apparent: true,
    }))
}

/// Where the optical axis points in the images: the apparent direction of the configured axis (no motion
/// of its own) with `observation.apparent_place`, else the configured axis.
pub fn pointing(cfg: &Config) -> Result<Pointing, String> {
    let configured = Pointing::from(&cfg.sky);
    Ok(match scene_place(cfg)? {
        Some(place) => {
            let (ra_deg, dec_deg) = apparent::direction(
                configured.ra_deg,
                configured.dec_deg,
                &apparent::Motion::default(),
                &place,
            );
            Pointing {
                ra_deg,
                dec_deg,
                pa_deg: configured.pa_deg,
            }
        }
        None => configured,
    })
}

/// The WCS of array k of `cfg`: the single array with the optical axis at its centre, or array k of the
/// 2 × 2 focal plane; the configured distortion turned into the array's axes; the axis at
/// [`pointing`].
pub fn array_wcs(cfg: &Config, k: usize) -> Result<ArrayWcs, String> {
    let pointing = pointing(cfg)?;
    let scale = cfg.instrument.plate_scale_mas();
    let sip = distortion(cfg).map(|s| s.rotated(array_rotation_deg(cfg, k)));
    match cfg.focal_plane.layout {
        Layout::Single => {
            let n = cfg.instrument.detector_px;
            let centre = (n as f64 - 1.0) / 2.0;
            ArrayWcs::new(&pointing, 0.0, scale, [centre, centre], [n, n], sip)
        }
        Layout::Quad => focal_plane(cfg).array_wcs(k, &pointing, scale, sip),
    }
}

/// The WCS of the single array of `cfg` (array 0): the optical axis at the array's centre.
pub fn single_array_wcs(cfg: &Config) -> Result<ArrayWcs, String> {
    array_wcs(cfg, 0)
}

/// The undistorted gnomonic projection with focal-plane pixels (from the optical axis) as its pixels, at
/// the configured (catalogue) pointing: where a mock field is drawn.
pub fn focal_plane_projection(cfg: &Config) -> Result<ArrayWcs, String> {
    projection_at(cfg, &Pointing::from(&cfg.sky))
}

/// The undistorted gnomonic projection with focal-plane pixels at `pointing`.
pub fn projection_at(cfg: &Config, pointing: &Pointing) -> Result<ArrayWcs, String> {
    ArrayWcs::new(
        pointing,
        0.0,
        cfg.instrument.plate_scale_mas(),
        [0.0, 0.0],
        [1, 1],
        None,
    )
}

/// Where the optical axis points and how the focal plane is turned on the sky.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pointing {
    /// Right ascension of the optical axis (ICRS), degrees.
    pub ra_deg: f64,
    /// Declination of the optical axis (ICRS), degrees.
    pub dec_deg: f64,
    /// Position angle of the focal plane's +y axis, degrees east of north.
    pub pa_deg: f64,
}

impl From<&crate::config::Sky> for Pointing {
    fn from(s: &crate::config::Sky) -> Self {
        Self {
            ra_deg: s.ra_deg,
            dec_deg: s.dec_deg,
            pa_deg: s.pa_deg,
        }
    }
}

impl Pointing {
    /// The Galactic centre (Sgr A*, ICRS: 266.4168°, −29.0078°) with the focal plane's +y to the north (the
    /// configuration's default, `config::Sky`).
    pub const GALACTIC_CENTRE: Pointing = Pointing {
        ra_deg: 266.416_8,
        dec_deg: -29.007_8,
        pa_deg: 0.0,
    };

    /// Check the ranges, naming the field: RA in [0, 360), Dec in [−90, 90], PA finite.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.ra_deg >= 0.0 && self.ra_deg < 360.0) {
            return Err(format!("ra_deg = {}: must be in [0, 360)", self.ra_deg));
        }
        if !(self.dec_deg >= -90.0 && self.dec_deg <= 90.0) {
            return Err(format!("dec_deg = {}: must be in [-90, 90]", self.dec_deg));
        }
        if !self.pa_deg.is_finite() {
            return Err(format!("pa_deg = {}: must be finite", self.pa_deg));
        }
        Ok(())
    }
}
