//! Sky stars onto the arrays: each star through each array's WCS (`sky::array_wcs`, distortion included),
//! and an account of where every star fell.
//!
//! A star is simulated on every array whose pixels its light reaches (its position within
//! [`margin_px`] of the array's full format), and belongs to that array's truth when it lies on the
//! photosensitive pixels. Every catalogue row is counted exactly once: duplicate (an exact repeat of an
//! earlier row: dropped, so its light is not doubled), photosensitive, border (on an array's dead border),
//! gap (between the arrays of the quad) or off (outside the focal plane, or 90° or more from the axis).
//!
//! With `observation.apparent_place` each star is first carried to its apparent place at image 0's
//! mid-exposure (`sky::apparent`: proper motion, parallax, light deflection, aberration), and the arrays'
//! WCS points at the apparent axis (`sky::pointing`).

use super::{Scene, SceneError, SkyStar, Star};
use crate::config::{AceCase, Config, Layout};
use crate::sky::focal_plane::Placement;
use rayon::prelude::*;
use std::collections::HashSet;

/// Where a sky scene's stars fell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlacementCounts {
    /// Rows of the catalogue (or stars drawn).
    pub catalogue: usize,
    /// Exact repeats of an earlier row, dropped.
    pub duplicates: usize,
    /// On an array's photosensitive pixels (in the truth).
    pub photosensitive: usize,
    /// On an array's dead border.
    pub border: usize,
    /// Between the arrays.
    pub gap: usize,
    /// Outside the focal plane.
    pub off: usize,
}

impl PlacementCounts {
    /// The FITS header cards' keys, values and comments.
    pub fn cards(&self) -> [(&'static str, i64, &'static str); 6] {
        [
            (
                "NCATALOG",
                self.catalogue as i64,
                "catalogue rows (or stars drawn)",
            ),
            (
                "NDUPLIC",
                self.duplicates as i64,
                "exact duplicate rows, dropped",
            ),
            (
                "NPHOTO",
                self.photosensitive as i64,
                "stars on photosensitive pixels",
            ),
            (
                "NBORDER",
                self.border as i64,
                "stars on an array's dead border",
            ),
            ("NGAP", self.gap as i64, "stars in the gaps between arrays"),
            ("NOFF", self.off as i64, "stars off the focal plane"),
        ]
    }
}

/// How far outside an array a star's light still reaches it, pixels: the PSF table and halo, the kernel's
/// pixel of support, and 3σ of the ACE.
pub fn margin_px(cfg: &Config) -> f64 {
    let jitter = match cfg.ace.case {
        AceCase::None => 0.0,
        _ => 3.0 * cfg.ace.sigma_mas / cfg.instrument.plate_scale_mas(),
    };
    (cfg.optics.psf_radius_px + cfg.fidelity.halo_radius_px) as f64 + 2.0 + jitter
}

/// Place sky stars on the arrays of `cfg`.
pub fn place(cfg: &Config, stars: &[SkyStar]) -> Result<Scene, SceneError> {
    let arrays = crate::sky::array_count(cfg);
    let wcs = (0..arrays)
        .map(|k| crate::sky::array_wcs(cfg, k))
        .collect::<Result<Vec<_>, _>>()
        .map_err(SceneError::Invalid)?;
    let plane = crate::sky::focal_plane(cfg);
    let pointing = crate::sky::pointing(cfg).map_err(SceneError::Invalid)?;
    let projection = crate::sky::projection_at(cfg, &pointing).map_err(SceneError::Invalid)?;
    let place = crate::sky::scene_place(cfg).map_err(SceneError::Invalid)?;
    let n = cfg.instrument.detector_px as f64;
    let border = (cfg.instrument.detector_px - cfg.instrument.photosensitive_px) as f64 / 2.0;
    let margin = margin_px(cfg);
    let mut counts = PlacementCounts {
        catalogue: stars.len(),
        ..Default::default()
    };
    // duplicates: the first of equal rows is kept
    let mut seen = HashSet::with_capacity(stars.len());
    let keep: Vec<bool> = stars
        .iter()
        .map(|s| {
            seen.insert([
                s.ra_deg.to_bits(),
                s.dec_deg.to_bits(),
                s.mag_hw.to_bits(),
                s.j_minus_h.to_bits(),
            ])
        })
        .collect();
    counts.duplicates = keep.iter().filter(|k| !**k).count();
    // where each star appears, and its pixel position on each array (None: the projection has none)
    let seen: Vec<(f64, f64)> = stars
        .par_iter()
        .map(|s| match &place {
            Some(p) => crate::sky::apparent::direction(s.ra_deg, s.dec_deg, &s.motion, p),
            None => (s.ra_deg, s.dec_deg),
        })
        .collect();
    let pixels: Vec<Vec<Option<(f64, f64)>>> = seen
        .par_iter()
        .map(|&(ra, dec)| wcs.iter().map(|w| w.sky_to_pixel(ra, dec)).collect())
        .collect();
    let inside = |v: f64, lo: f64| v >= lo - 0.5 && v < n - lo - 0.5;
    let mut out: Vec<Vec<Star>> = vec![Vec::new(); arrays];
    for (((s, px), keep), &(ra, dec)) in stars.iter().zip(&pixels).zip(&keep).zip(&seen) {
        if !keep {
            continue;
        }
        let mut fell = None;
        for (k, p) in px.iter().enumerate() {
            let Some((x, y)) = *p else { continue };
            let photo = inside(x, border) && inside(y, border);
            if photo {
                fell = Some(Placement::Photosensitive { array: k, x, y });
            } else if inside(x, 0.0) && inside(y, 0.0) && fell.is_none() {
                fell = Some(Placement::Border { array: k, x, y });
            }
            if x > -margin && x < n - 1.0 + margin && y > -margin && y < n - 1.0 + margin {
                out[k].push(Star {
                    id: s.id,
                    x_px: x,
                    y_px: y,
                    mag_hw: s.mag_hw,
                    j_minus_h: s.j_minus_h,
                    in_truth: photo,
                });
            }
        }
        match fell {
            Some(Placement::Photosensitive { .. }) => counts.photosensitive += 1,
            Some(_) => counts.border += 1,
            None => {
                // between the arrays when inside the quad's outer edge (the undistorted layout decides:
                // a star the distortion moves off an edge counts as in the gap), else off the plane
                let in_gap = cfg.focal_plane.layout == Layout::Quad
                    && projection
                        .sky_to_pixel(ra, dec)
                        .is_some_and(|(fx, fy)| !matches!(plane.locate(fx, fy), Placement::Off));
                if in_gap {
                    counts.gap += 1;
                } else {
                    counts.off += 1;
                }
            }
        }
    }
    Ok(Scene {
        arrays: out,
        counts: Some(counts),
    })
}

/// The error of a sky catalogue none of whose stars reaches the focal plane: the field's bounds (its
/// pointing, the radius to its farthest corner, the arrays' corners' RA/Dec range) and the catalogue's.
pub fn outside_field(cfg: &Config, path: &std::path::Path, stars: &[SkyStar]) -> SceneError {
    let n = cfg.instrument.detector_px as f64;
    let (ra0, dec0) = (cfg.sky.ra_deg, cfg.sky.dec_deg);
    let edges = [
        (-0.5, -0.5),
        (n - 0.5, -0.5),
        (-0.5, n - 0.5),
        (n - 0.5, n - 0.5),
    ];
    let corners: Vec<(f64, f64)> = (0..crate::sky::array_count(cfg))
        .filter_map(|k| crate::sky::array_wcs(cfg, k).ok())
        .flat_map(|w| {
            edges
                .iter()
                .filter_map(|&(x, y)| w.pixel_to_sky(x, y))
                .collect::<Vec<_>>()
        })
        .collect();
    let separation = |ra: f64, dec: f64| {
        let (d1, d2, dra) = (dec0.to_radians(), dec.to_radians(), (ra - ra0).to_radians());
        let c = d1.sin() * d2.sin() + d1.cos() * d2.cos() * dra.cos();
        c.clamp(-1.0, 1.0).acos().to_degrees()
    };
    let radius = corners
        .iter()
        .map(|&(ra, dec)| separation(ra, dec))
        .fold(0.0, f64::max);
    let range = |v: Vec<f64>| {
        v.into_iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(x), b.max(x))
            })
    };
    let (fra, fdec) = (
        range(corners.iter().map(|c| c.0).collect()),
        range(corners.iter().map(|c| c.1).collect()),
    );
    let (cra, cdec) = (
        range(stars.iter().map(|s| s.ra_deg).collect()),
        range(stars.iter().map(|s| s.dec_deg).collect()),
    );
    SceneError::Invalid(format!(
        "{}: every one of its {} stars is outside the field — the catalogue spans RA {} … {}°, Dec {} … {}°; \
         the field is pointed at RA {ra0:.4}°, Dec {dec0:.4}° (sky.ra_deg, sky.dec_deg) with a radius of \
         {radius:.3}° to its farthest corner (RA {:.4} … {:.4}°, Dec {:.4} … {:.4}°)",
        path.display(),
        stars.len(),
        cra.0,
        cra.1,
        cdec.0,
        cdec.1,
        fra.0,
        fra.1,
        fdec.0,
        fdec.1,
    ))
}
