//! The sky: where the telescope points and how sky positions land on an array's pixels.
//!
//! A [`Pointing`] (RA, Dec of the optical axis and the position angle of the focal plane's +y axis, east of
//! north) and an array's place in the focal plane give that array's FITS world coordinate system
//! ([`wcs::ArrayWcs`]): a gnomonic (TAN) projection — computed by the CDS `wcs`/`mapproj` crates from the very
//! header cards the image files carry — with optional SIP distortion polynomials (Shupe et al. 2005) on the
//! pixel side. Angles are degrees in the configuration and the headers, radians inside.

pub mod focal_plane;
pub mod wcs;

use crate::config::Config;

/// The WCS of the single array of `cfg` (today's scene): the optical axis at the array's centre, the
/// pointing of `cfg.sky`, no distortion.
pub fn single_array_wcs(cfg: &Config) -> Result<wcs::ArrayWcs, String> {
    let n = cfg.instrument.detector_px;
    let centre = (n as f64 - 1.0) / 2.0;
    wcs::ArrayWcs::new(
        &Pointing::from(&cfg.sky),
        0.0,
        cfg.instrument.plate_scale_mas(),
        [centre, centre],
        [n, n],
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
