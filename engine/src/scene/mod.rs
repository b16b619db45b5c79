//! The stars of a simulation, on each array of the focal plane.
//!
//! * **grid**: the paper's 20 × 20 grid (SPEC §6), in pixels of each array: `n × n` stars centred on the
//!   detector (centre at `(N − 1)/2`, pixel-centre convention), spacing `grid_spacing_px`, each offset by an
//!   independent uniform amount in `±grid_random_px` per axis so the pixel phases are random. The offsets
//!   come from the scene stream of the run seed: every image of a dataset shows the same field.
//! * **catalogue**: a CSV or FITS table in pixels of the single array or on the sky ([`catalogue`]).
//! * **bulge**: the mock Galactic-centre field on the sky ([`bulge`]).
//!
//! Stars on the sky are placed on the arrays through each array's WCS ([`placement`]): every star is
//! accounted for — on an array's photosensitive pixels, in its dead border, in a gap between arrays, off
//! the focal plane, or a duplicate row — and the counts travel with the images.

pub mod bulge;
pub mod catalogue;
pub mod placement;
pub mod transit;

use crate::config::{Config, SceneKind};
use crate::rng::{self, Stream};
use rand::RngExt;
use std::path::Path;

pub use placement::PlacementCounts;

/// A star on one array (pixels of that array).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Star {
    /// The star's number in its scene (a catalogue's row among the rows read, from 0).
    pub id: usize,
    pub x_px: f64,
    pub y_px: f64,
    pub mag_hw: f64,
    pub j_minus_h: f64,
    /// Whether the star belongs to this array's truth: always for pixel scenes; for sky scenes when it
    /// falls on the array's photosensitive pixels (a star just off them is simulated for the light its
    /// wings bring, and counted where it fell).
    pub in_truth: bool,
}

/// A star on the sky.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkyStar {
    pub id: usize,
    /// ICRS, degrees.
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub mag_hw: f64,
    pub j_minus_h: f64,
    /// Proper motion and parallax at `observation.catalogue_epoch_jyear` (zero: a star that stays put).
    pub motion: crate::sky::apparent::Motion,
}

/// The stars each array simulates, and where a sky scene's stars fell.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    /// Per array (one for the single layout, four for the quad), in the scene's order.
    pub arrays: Vec<Vec<Star>>,
    /// Where the stars of a sky scene fell (`None` for a scene given in pixels).
    pub counts: Option<PlacementCounts>,
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("star catalogue {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("star catalogue {path}, line {line}: {message}")]
    Parse {
        path: String,
        line: usize,
        message: String,
    },
    #[error("star catalogue {path} holds no stars")]
    Empty { path: String },
    #[error("star catalogue {path} holds more than {max} stars")]
    TooMany { path: String, max: usize },
    #[error("scene: {0}")]
    Invalid(String),
}

/// Most stars a scene may hold (memory and time grow with it: ≈ 1 kB and one stamp per star).
pub const MAX_CATALOGUE_STARS: usize = 10_000_000;
/// Allowed Hw magnitudes of a catalogue star (`inf` is also accepted: a star that delivers no light).
pub const HW_RANGE: (f64, f64) = (-5.0, 35.0);
/// Allowed J − H colours.
pub const JH_RANGE: (f64, f64) = (-1.0, 10.0);

/// The stars of `cfg.scene` on the arrays of `cfg.focal_plane` (`cfg`: the instrument as built, which puts
/// them where they land). A mock bulge is drawn on the sky around `planned`, where the telescope was meant
/// to point: a pointing error moves the arrays over the sky, not the sky.
pub fn build(cfg: &Config, planned: &crate::config::Sky) -> Result<Scene, SceneError> {
    let arrays = crate::sky::array_count(cfg);
    let pixel_scene = |stars: Vec<Star>| Scene {
        arrays: vec![stars; arrays],
        counts: None,
    };
    match cfg.scene.kind {
        SceneKind::Grid => Ok(pixel_scene(grid(cfg))),
        SceneKind::Catalogue => {
            let path = cfg.scene.catalogue.as_deref().unwrap_or(Path::new(""));
            match catalogue::read(
                path,
                cfg.scene.mag_hw,
                cfg.scene.j_minus_h,
                cfg.instrument.detector_px as f64,
            )? {
                catalogue::Catalogue::Pixels(stars) if arrays == 1 => Ok(pixel_scene(stars)),
                catalogue::Catalogue::Pixels(_) => Err(SceneError::Invalid(format!(
                    "{}: a catalogue in pixels (x, y) describes one array; give ra, dec to fill the \
                     quad focal plane, or set focal_plane.layout = \"single\"",
                    path.display()
                ))),
                catalogue::Catalogue::Sky(stars) => {
                    let scene = placement::place(cfg, &stars)?;
                    let none_on =
                        |c: &placement::PlacementCounts| c.photosensitive + c.border + c.gap == 0;
                    if scene.counts.as_ref().is_some_and(none_on) {
                        return Err(placement::outside_field(cfg, path, &stars));
                    }
                    Ok(scene)
                }
            }
        }
        SceneKind::Bulge => {
            let mut at_plan = cfg.clone();
            at_plan.sky = *planned;
            placement::place(cfg, &bulge::draw(&at_plan)?)
        }
    }
}

/// The paper's grid.
pub fn grid(cfg: &Config) -> Vec<Star> {
    let s = &cfg.scene;
    let n = s.grid_n;
    let centre = (cfg.instrument.detector_px as f64 - 1.0) / 2.0;
    let mut r = rng::stream(cfg.seed, Stream::SceneOffsets, 0);
    let mut stars = Vec::with_capacity(n * n);
    for iy in 0..n {
        for ix in 0..n {
            let ox = (r.random::<f64>() * 2.0 - 1.0) * s.grid_random_px;
            let oy = (r.random::<f64>() * 2.0 - 1.0) * s.grid_random_px;
            stars.push(Star {
                id: stars.len(),
                x_px: centre + (ix as f64 - (n as f64 - 1.0) / 2.0) * s.grid_spacing_px + ox,
                y_px: centre + (iy as f64 - (n as f64 - 1.0) / 2.0) * s.grid_spacing_px + oy,
                mag_hw: s.mag_hw,
                j_minus_h: s.j_minus_h,
                in_truth: true,
            });
        }
    }
    stars
}

/// Read a CSV catalogue in pixels (`x,y[,hw[,j_h]]`; see [`catalogue`]).
pub fn read_catalogue(
    path: &Path,
    default_mag: f64,
    default_jh: f64,
    detector_px: f64,
) -> Result<Vec<Star>, SceneError> {
    match catalogue::read(path, default_mag, default_jh, detector_px)? {
        catalogue::Catalogue::Pixels(s) => Ok(s),
        catalogue::Catalogue::Sky(_) => Err(SceneError::Invalid(format!(
            "{}: holds ra, dec; expected x, y",
            path.display()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_grid() {
        let cfg = Config::default();
        let s = grid(&cfg);
        assert_eq!(s.len(), 400);
        let (xmin, xmax) = s.iter().fold((f64::MAX, f64::MIN), |(a, b), st| {
            (a.min(st.x_px), b.max(st.x_px))
        });
        assert!(xmin > 8.0 && xmax < 1960.0, "{xmin} {xmax}");
        // spacing and random phases
        let d = s[1].x_px - s[0].x_px;
        assert!((d - 98.4).abs() <= 1.0);
        let phases: Vec<f64> = s.iter().map(|st| st.x_px - st.x_px.round()).collect();
        assert!(phases.iter().any(|p| *p > 0.3) && phases.iter().any(|p| *p < -0.3));
        assert_eq!(grid(&cfg), s, "same seed, same scene");
    }

    #[test]
    fn catalogue_parsing_and_errors() {
        let dir = crate::testkit::temp_dir("catalogue");
        let good = dir.join("good.csv");
        std::fs::write(
            &good,
            "x,y,hw,j_h\n10.5, 20.25, 12.0, 1.5\n# comment\n30,40\n",
        )
        .expect("write");
        let s = read_catalogue(&good, 13.0, 2.0, 1968.0).expect("parse");
        assert_eq!(s.len(), 2);
        assert_eq!((s[1].mag_hw, s[1].j_minus_h), (13.0, 2.0));
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, "1,2,3\n4,nan,5\n").expect("write");
        let e = read_catalogue(&bad, 13.0, 2.0, 1968.0).expect_err("NaN");
        assert!(e.to_string().contains("line 2"), "{e}");
        let e = read_catalogue(&dir.join("missing.csv"), 13.0, 2.0, 1968.0).expect_err("missing");
        assert!(e.to_string().contains("missing.csv"));
        // every value is range-checked, naming the line, the column and the allowed range
        for (row, needle) in [
            ("1e300,5,12,2", "column x = 1e300"),
            ("5,-4000,12,2", "column y = -4000"),
            ("5,5,99,2", "column hw = 99"),
            ("5,5,-inf,2", "column hw = -inf"),
            ("5,5,12,40", "column j_h = 40"),
        ] {
            let f = dir.join("range.csv");
            std::fs::write(&f, format!("x,y,hw,j_h\n10,10,12,2\n{row}\n")).expect("write");
            let e = read_catalogue(&f, 13.0, 2.0, 1968.0).expect_err(needle);
            let m = e.to_string();
            assert!(
                m.contains(needle) && m.contains("line 3") && m.contains("allowed"),
                "{m}"
            );
        }
        // a sky star's motion: read, range-checked; a pixel catalogue has none
        let f = dir.join("motion.csv");
        std::fs::write(
            &f,
            "ra,dec,pmra,pmdec,parallax\n266.4,-29.0,-2.5,-5.5,0.125\n",
        )
        .expect("write");
        let Ok(catalogue::Catalogue::Sky(sky)) = catalogue::read(&f, 13.0, 2.0, 1968.0) else {
            panic!("a sky catalogue")
        };
        let m = sky[0].motion;
        assert_eq!(
            (m.pmra_mas_per_yr, m.pmdec_mas_per_yr, m.parallax_mas),
            (-2.5, -5.5, 0.125)
        );
        std::fs::write(&f, "ra,dec,pmra\n266.4,-29.0,1e6\n").expect("write");
        let e = catalogue::read(&f, 13.0, 2.0, 1968.0).expect_err("pm range");
        assert!(
            e.to_string().contains("column pmra = 1000000.0: allowed"),
            "{e}"
        );
        std::fs::write(&f, "x,y,parallax\n10,10,1.0\n").expect("write");
        let e = catalogue::read(&f, 13.0, 2.0, 1968.0).expect_err("pixels");
        assert!(e.to_string().contains("give ra, dec"), "{e}");
        // Hw = inf is a star without light
        let f = dir.join("dark.csv");
        std::fs::write(&f, "10,10,inf,2\n").expect("write");
        let s = read_catalogue(&f, 13.0, 2.0, 1968.0).expect("inf");
        assert_eq!(crate::photometry::electrons_per_s(s[0].mag_hw, 5800.0), 0.0);
    }

    /// A sky catalogue wholly outside the field is an error naming the field's bounds and the
    /// catalogue's, not an image of no stars; one with some stars outside is placed as before.
    #[test]
    fn a_catalogue_wholly_outside_the_field_is_refused() {
        let dir = std::env::temp_dir().join(format!("jsim-scene-off-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        let mut cfg = Config::default();
        cfg.scene.kind = SceneKind::Catalogue;
        let off = dir.join("off.csv");
        std::fs::write(&off, "ra,dec,hw\n10,10,12.5\n12,11,13\n").expect("write");
        cfg.scene.catalogue = Some(off);
        let msg = build(&cfg, &cfg.sky)
            .expect_err("wholly outside")
            .to_string();
        for part in [
            "outside the field",
            "RA 10 … 12°",
            "Dec 10 … 11°",
            "266.4",
            "-29.0",
        ] {
            assert!(msg.contains(part), "{part:?} not in: {msg}");
        }
        let some = dir.join("some.csv");
        std::fs::write(&some, "ra,dec,hw\n10,10,12.5\n266.4168,-29.0078,13\n").expect("write");
        cfg.scene.catalogue = Some(some);
        let scene = build(&cfg, &cfg.sky).expect("some outside");
        let counts = scene.counts.expect("counts");
        assert_eq!((counts.off, counts.photosensitive), (1, 1));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
