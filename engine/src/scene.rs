//! The stars of a simulation: the paper's 20 × 20 grid (SPEC §6) or a CSV catalogue `x,y,hw,j_h` (pixels).
//!
//! Grid: `n × n` stars centred on the detector (centre at `(N − 1)/2`, pixel-centre convention), spacing
//! `grid_spacing_px`, each offset by an independent uniform amount in `±grid_random_px` per axis so the
//! pixel phases are random. The offsets come from the scene stream of the run seed: every image of a
//! dataset shows the same field.

use crate::config::{Config, SceneKind};
use crate::rng::{self, Stream};
use rand::RngExt;
use std::path::Path;

/// A star of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Star {
    pub id: usize,
    pub x_px: f64,
    pub y_px: f64,
    pub mag_hw: f64,
    pub j_minus_h: f64,
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
}

/// Most stars a catalogue may hold (memory and time grow with it: ≈ 1 kB and one stamp per star).
pub const MAX_CATALOGUE_STARS: usize = 10_000_000;
/// Allowed Hw magnitudes of a catalogue star (`inf` is also accepted: a star that delivers no light).
pub const HW_RANGE: (f64, f64) = (-5.0, 35.0);
/// Allowed J − H colours.
pub const JH_RANGE: (f64, f64) = (-1.0, 10.0);

/// The stars of `cfg.scene`.
pub fn build(cfg: &Config) -> Result<Vec<Star>, SceneError> {
    match cfg.scene.kind {
        SceneKind::Grid => Ok(grid(cfg)),
        SceneKind::Catalogue => {
            let path = cfg.scene.catalogue.as_deref().unwrap_or(Path::new(""));
            read_catalogue(
                path,
                cfg.scene.mag_hw,
                cfg.scene.j_minus_h,
                cfg.instrument.detector_px as f64,
            )
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
            });
        }
    }
    stars
}

/// Read `x,y[,hw[,j_h]]` rows (pixels; a header line and `#` comments are skipped). Missing magnitudes
/// and colours take the scene defaults. Every value is range-checked, naming the line and column: x and y
/// within one detector width (`detector_px`) of the array, Hw in [`HW_RANGE`] or `inf` (a star that
/// delivers no light: flux exactly 0), J − H in [`JH_RANGE`]; at most [`MAX_CATALOGUE_STARS`] rows.
pub fn read_catalogue(
    path: &Path,
    default_mag: f64,
    default_jh: f64,
    detector_px: f64,
) -> Result<Vec<Star>, SceneError> {
    let p = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: p.clone(),
        source,
    })?;
    let mut stars = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = l.split(',').map(str::trim).collect();
        if k == 0 && cols.first().is_some_and(|c| c.parse::<f64>().is_err()) {
            continue; // header
        }
        let num = |i: usize,
                   name: &str,
                   default: Option<f64>,
                   (lo, hi): (f64, f64),
                   inf_ok: bool|
         -> Result<f64, SceneError> {
            match cols.get(i) {
                Some(v) if !v.is_empty() => {
                    let x: f64 = v.parse().map_err(|_| SceneError::Parse {
                        path: p.clone(),
                        line: k + 1,
                        message: format!("column {name} = `{v}` is not a number"),
                    })?;
                    if (lo..=hi).contains(&x) || (inf_ok && x == f64::INFINITY) {
                        Ok(x)
                    } else {
                        Err(SceneError::Parse {
                            path: p.clone(),
                            line: k + 1,
                            message: format!(
                                "column {name} = {v}: allowed [{lo}, {hi}]{}",
                                if inf_ok { " or inf (no light)" } else { "" }
                            ),
                        })
                    }
                }
                _ => default.ok_or_else(|| SceneError::Parse {
                    path: p.clone(),
                    line: k + 1,
                    message: format!("missing column {name}"),
                }),
            }
        };
        if stars.len() >= MAX_CATALOGUE_STARS {
            return Err(SceneError::TooMany {
                path: p,
                max: MAX_CATALOGUE_STARS,
            });
        }
        let xy = (-detector_px, 2.0 * detector_px);
        stars.push(Star {
            id: stars.len(),
            x_px: num(0, "x", None, xy, false)?,
            y_px: num(1, "y", None, xy, false)?,
            mag_hw: num(2, "hw", Some(default_mag), HW_RANGE, true)?,
            j_minus_h: num(3, "j_h", Some(default_jh), JH_RANGE, false)?,
        });
    }
    if stars.is_empty() {
        return Err(SceneError::Empty { path: p });
    }
    Ok(stars)
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
        let dir = std::env::temp_dir().join(format!("jsim-cat-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
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
        // Hw = inf is a star without light
        let f = dir.join("dark.csv");
        std::fs::write(&f, "10,10,inf,2\n").expect("write");
        let s = read_catalogue(&f, 13.0, 2.0, 1968.0).expect("inf");
        assert_eq!(crate::photometry::electrons_per_s(s[0].mag_hw, 5800.0), 0.0);
    }
}
