//! Star catalogues: a CSV file or a FITS binary table, with positions in pixels of the single array
//! (`x, y`) or on the sky (`ra, dec`, ICRS degrees).
//!
//! Columns are found by name, case-insensitively: `x, y` or `ra, dec` (also `ra_deg, dec_deg`); `hw`, or
//! 2MASS `j, h` converted with SPEC §5's Hw − H = 1.08(J−H) − 0.15(J−H)² + 0.01(J−H)³; `j_h` (also `jh`,
//! `j-h`), or `j − h` when `j, h` are given; optional `a_hw`, an extinction in Hw magnitudes added to each
//! star's Hw (for catalogues of intrinsic magnitudes). A CSV without a header line is read positionally as
//! `x, y[, hw[, j_h]]` (the original format). Missing magnitudes and colours take `scene.mag_hw` and
//! `scene.j_minus_h`. Sky catalogues may give each star's motion: `pmra` (µα* = µα cos δ, mas/yr, the Gaia
//! convention), `pmdec` (mas/yr) and `parallax` (mas), at `observation.catalogue_epoch_jyear`; missing
//! ones are 0. Every value is range-checked, naming the line (CSV) or row (FITS) and the column.

use super::{HW_RANGE, JH_RANGE, MAX_CATALOGUE_STARS, SceneError, SkyStar, Star};
use crate::photometry;
use crate::sky::apparent::Motion;
use std::path::Path;

/// A catalogue's stars, in the coordinates it gave.
#[derive(Debug, Clone, PartialEq)]
pub enum Catalogue {
    /// Pixels of the single array.
    Pixels(Vec<Star>),
    /// Sky positions.
    Sky(Vec<SkyStar>),
}

/// The column names a catalogue header may hold (any case): positions (`ra, dec` in degrees or `x, y` in
/// pixels), the Hw magnitude, the colour (`j_h`, or `j` and `h` for 2MASS magnitudes), the extinction `a_hw`,
/// identifiers that are read past (`id`, `name`, `source_id`), and a sky star's motion (`pmra`, `pmdec`,
/// `parallax`). Any other column is an error.
pub const KNOWN_COLUMNS: [&str; 23] = [
    "ra",
    "ra_deg",
    "dec",
    "dec_deg",
    "x",
    "x_px",
    "y",
    "y_px",
    "hw",
    "mag_hw",
    "j_h",
    "jh",
    "j-h",
    "j_minus_h",
    "j",
    "h",
    "a_hw",
    "id",
    "name",
    "source_id",
    "pmra",
    "pmdec",
    "parallax",
];

/// Allowed proper motion per axis, mas/yr (Barnard's star: 10 400).
pub const PM_RANGE_MAS_PER_YR: (f64, f64) = (-2.0e4, 2.0e4);
/// Allowed parallax, mas (negative: a catalogue's noisy distant star; Proxima: 768).
pub const PARALLAX_RANGE_MAS: (f64, f64) = (-100.0, 1000.0);

/// One row's values.
#[derive(Debug, Clone, Copy)]
struct Row {
    p0: f64,
    p1: f64,
    hw: f64,
    jh: f64,
    motion: Motion,
}

/// Where each value of a row comes from.
struct Layout {
    pos: [usize; 2],
    sky: bool,
    hw: Option<usize>,
    jh: Option<usize>,
    j_h_2mass: Option<[usize; 2]>,
    a_hw: Option<usize>,
    /// pmra, pmdec, parallax.
    motion: [Option<usize>; 3],
    /// Identifier columns (`id`, `name`, `source_id`): read past, any text.
    identifiers: Vec<usize>,
}

impl Layout {
    fn from_names(names: &[String], path: &str) -> Result<Self, SceneError> {
        let find = |alts: &[&str]| {
            names
                .iter()
                .position(|n| alts.iter().any(|a| n.trim().eq_ignore_ascii_case(a)))
        };
        if let Some(bad) = names.iter().find(|n| {
            !KNOWN_COLUMNS
                .iter()
                .any(|k| n.trim().eq_ignore_ascii_case(k))
        }) {
            return Err(SceneError::Parse {
                path: path.into(),
                line: 1,
                message: format!(
                    "column `{}` is not one jsim reads (a star would silently lose it: e.g. `mag` is not \
                     the Hw magnitude); accepted: {}",
                    bad.trim(),
                    KNOWN_COLUMNS.join(", ")
                ),
            });
        }
        let sky_cols = (find(&["ra", "ra_deg"]), find(&["dec", "dec_deg"]));
        let pixel_cols = (find(&["x", "x_px"]), find(&["y", "y_px"]));
        if sky_cols.0.is_some()
            && sky_cols.1.is_some()
            && pixel_cols.0.is_some()
            && pixel_cols.1.is_some()
        {
            return Err(SceneError::Parse {
                path: path.into(),
                line: 1,
                message: format!(
                    "columns {names:?}: both `ra, dec` and `x, y` given — which places the stars is \
                     ambiguous; keep one pair"
                ),
            });
        }
        // half a pair would leave the other pair to place the stars, or fail later on a missing column
        let col = |i: usize| names[i].trim().to_string();
        for (pair, (a, b), (na, nb)) in [
            ("ra, dec", sky_cols, ("ra", "dec")),
            ("x, y", pixel_cols, ("x", "y")),
        ] {
            let lone = match (a, b) {
                (Some(i), None) => Some((col(i), nb)),
                (None, Some(i)) => Some((col(i), na)),
                _ => None,
            };
            if let Some((found, missing)) = lone {
                return Err(SceneError::Parse {
                    path: path.into(),
                    line: 1,
                    message: format!(
                        "columns {names:?}: `{found}` without `{missing}` — a position is a pair: give \
                         both `ra, dec` (degrees) or both `x, y` (pixels), not half of `{pair}`"
                    ),
                });
            }
        }
        let (pos, sky) = match sky_cols {
            (Some(a), Some(d)) => ([a, d], true),
            _ => match (find(&["x", "x_px"]), find(&["y", "y_px"])) {
                (Some(x), Some(y)) => ([x, y], false),
                _ => {
                    return Err(SceneError::Parse {
                        path: path.into(),
                        line: 1,
                        message: format!(
                            "columns {names:?}: need `ra, dec` (degrees) or `x, y` (pixels)"
                        ),
                    });
                }
            },
        };
        let j_h_2mass = match (find(&["j"]), find(&["h"])) {
            (Some(j), Some(h)) => Some([j, h]),
            _ => None,
        };
        Ok(Self {
            pos,
            sky,
            hw: find(&["hw", "mag_hw"]),
            jh: find(&["j_h", "jh", "j-h", "j_minus_h"]),
            j_h_2mass,
            a_hw: find(&["a_hw"]),
            motion: [find(&["pmra"]), find(&["pmdec"]), find(&["parallax"])],
            identifiers: (0..names.len())
                .filter(|&i| {
                    ["id", "name", "source_id"]
                        .iter()
                        .any(|k| names[i].trim().eq_ignore_ascii_case(k))
                })
                .collect(),
        })
    }

    /// The original header-less layout: `x, y[, hw[, j_h]]`.
    fn positional() -> Self {
        Self {
            pos: [0, 1],
            sky: false,
            hw: Some(2),
            jh: Some(3),
            j_h_2mass: None,
            a_hw: None,
            motion: [None; 3],
            identifiers: Vec::new(),
        }
    }
}

/// What a row's values are checked against.
struct Limits {
    default_mag: f64,
    default_jh: f64,
    detector_px: f64,
}

/// One row → a star (`id` = its index among the stars read).
fn star_of(
    get: &dyn Fn(usize) -> Option<f64>,
    lay: &Layout,
    lim: &Limits,
    at: &dyn Fn(String) -> SceneError,
) -> Result<Row, SceneError> {
    let check = |v: Option<f64>, name: &str, (lo, hi): (f64, f64), inf_ok: bool| match v {
        Some(x) if (lo..=hi).contains(&x) || (inf_ok && x == f64::INFINITY) => Ok(x),
        Some(x) => Err(at(format!(
            "column {name} = {x:?}: allowed [{lo}, {hi}]{}",
            if inf_ok { " or inf (no light)" } else { "" }
        ))),
        None => Err(at(format!("missing column {name}"))),
    };
    let (p0, p1) = if lay.sky {
        let ra = check(get(lay.pos[0]), "ra", (0.0, 360.0), false)?;
        let dec = check(get(lay.pos[1]), "dec", (-90.0, 90.0), false)?;
        (ra % 360.0, dec)
    } else {
        let xy = (-lim.detector_px, 2.0 * lim.detector_px);
        (
            check(get(lay.pos[0]), "x", xy, false)?,
            check(get(lay.pos[1]), "y", xy, false)?,
        )
    };
    let two_mass = match lay.j_h_2mass {
        Some([j, h]) => Some((
            check(get(j), "j", (-5.0, 40.0), false)?,
            check(get(h), "h", (-5.0, 40.0), false)?,
        )),
        None => None,
    };
    let jh = match (lay.jh.and_then(get), two_mass) {
        (Some(v), _) => check(Some(v), "j_h", JH_RANGE, false)?,
        (None, Some((j, h))) => check(Some(j - h), "j - h", JH_RANGE, false)?,
        (None, None) => lim.default_jh,
    };
    let mut hw = match (lay.hw.and_then(get), two_mass) {
        (Some(v), _) => check(Some(v), "hw", HW_RANGE, true)?,
        (None, Some((j, h))) => check(
            Some(photometry::hw_from_2mass(j, h)),
            "hw (from j, h)",
            HW_RANGE,
            false,
        )?,
        (None, None) => lim.default_mag,
    };
    if let Some(a) = lay.a_hw.and_then(get) {
        hw += check(Some(a), "a_hw", (0.0, 30.0), false)?;
    }
    let motion = |k: usize, name: &str, range: (f64, f64)| match lay.motion[k].and_then(get) {
        Some(v) => check(Some(v), name, range, false),
        None => Ok(0.0),
    };
    let pmra = motion(0, "pmra", PM_RANGE_MAS_PER_YR)?;
    let pmdec = motion(1, "pmdec", PM_RANGE_MAS_PER_YR)?;
    let parallax = motion(2, "parallax", PARALLAX_RANGE_MAS)?;
    if !lay.sky && (pmra != 0.0 || pmdec != 0.0 || parallax != 0.0) {
        return Err(at(
            "pmra, pmdec, parallax describe a star on the sky: give ra, dec (a catalogue in pixels \
             places its stars where they are)"
                .into(),
        ));
    }
    Ok(Row {
        p0,
        p1,
        hw,
        jh,
        motion: Motion {
            pmra_mas_per_yr: pmra,
            pmdec_mas_per_yr: pmdec,
            parallax_mas: parallax,
        },
    })
}

fn collect(rows: Vec<Row>, sky: bool, path: &str) -> Result<Catalogue, SceneError> {
    if rows.is_empty() {
        return Err(SceneError::Empty { path: path.into() });
    }
    Ok(if sky {
        Catalogue::Sky(
            rows.into_iter()
                .enumerate()
                .map(|(id, r)| SkyStar {
                    id,
                    ra_deg: r.p0,
                    dec_deg: r.p1,
                    mag_hw: r.hw,
                    j_minus_h: r.jh,
                    motion: r.motion,
                })
                .collect(),
        )
    } else {
        Catalogue::Pixels(
            rows.into_iter()
                .enumerate()
                .map(|(id, r)| Star {
                    id,
                    x_px: r.p0,
                    y_px: r.p1,
                    mag_hw: r.hw,
                    j_minus_h: r.jh,
                    in_truth: true,
                })
                .collect(),
        )
    })
}

/// Read a catalogue: a FITS binary table (`.fits`, `.fit`, `.fits.gz`: its first table extension) or CSV.
/// `detector_px` bounds pixel positions (within one detector width of the array).
pub fn read(
    path: &Path,
    default_mag: f64,
    default_jh: f64,
    detector_px: f64,
) -> Result<Catalogue, SceneError> {
    let lim = Limits {
        default_mag,
        default_jh,
        detector_px,
    };
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".fits") || name.ends_with(".fit") || name.ends_with(".fits.gz") {
        read_fits(path, &lim)
    } else {
        read_csv(path, &lim)
    }
}

fn read_csv(path: &Path, lim: &Limits) -> Result<Catalogue, SceneError> {
    let p = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: p.clone(),
        source,
    })?;
    let mut layout: Option<Layout> = None;
    let mut rows = Vec::new();
    for record in crate::formats::csv::records(path, &text) {
        let record = record.map_err(|e| SceneError::Parse {
            path: p.clone(),
            line: match &e {
                crate::formats::csv::CsvError::Syntax { line, .. } => *line as usize,
                _ => 0,
            },
            message: e.to_string(),
        })?;
        let line = record.line as usize;
        let cols: Vec<&str> = record.cells.iter().map(String::as_str).collect();
        let lay = match &layout {
            Some(lay) => lay,
            None => {
                let header = cols.first().is_some_and(|c| c.parse::<f64>().is_err());
                let lay = if header {
                    let names: Vec<String> = cols.iter().map(|c| c.to_string()).collect();
                    Layout::from_names(&names, &p)?
                } else {
                    Layout::positional()
                };
                layout = Some(lay);
                if header {
                    continue;
                }
                layout
                    .as_ref()
                    .ok_or(SceneError::Empty { path: p.clone() })?
            }
        };
        if rows.len() >= MAX_CATALOGUE_STARS {
            return Err(SceneError::TooMany {
                path: p,
                max: MAX_CATALOGUE_STARS,
            });
        }
        let at = |message: String| SceneError::Parse {
            path: p.clone(),
            line,
            message,
        };
        // a value that is present must be a number; an absent or empty one takes the default
        let mut values = Vec::with_capacity(cols.len());
        for (i, v) in cols.iter().enumerate() {
            values.push(if v.is_empty() || lay.identifiers.contains(&i) {
                None
            } else {
                Some(
                    v.parse::<f64>()
                        .map_err(|_| at(format!("column {} = `{v}` is not a number", i + 1)))?,
                )
            });
        }
        let get = |i: usize| values.get(i).copied().flatten();
        rows.push(star_of(&get, lay, lim, &at)?);
    }
    let sky = layout.as_ref().is_some_and(|l| l.sky);
    collect(rows, sky, &p)
}

fn read_fits(path: &Path, lim: &Limits) -> Result<Catalogue, SceneError> {
    use crate::formats::fits::FitsError;
    use crate::formats::fits_reader as fits;
    let p = path.display().to_string();
    let fe = |e: FitsError| match e {
        FitsError::Io { reason, .. } => SceneError::Io {
            path: p.clone(),
            source: reason,
        },
        FitsError::Fits { message, .. } => SceneError::Parse {
            path: p.clone(),
            line: 0,
            message,
        },
    };
    let mut table = fits::open_table(path, 1).map_err(fe)?;
    let (names, num_rows) = (table.names.clone(), table.num_rows);
    if num_rows > MAX_CATALOGUE_STARS {
        return Err(SceneError::TooMany {
            path: p,
            max: MAX_CATALOGUE_STARS,
        });
    }
    let lay = Layout::from_names(&names, &p)?;
    let wanted: Vec<usize> = [
        Some(lay.pos[0]),
        Some(lay.pos[1]),
        lay.hw,
        lay.jh,
        lay.a_hw,
        lay.j_h_2mass.map(|v| v[0]),
        lay.j_h_2mass.map(|v| v[1]),
    ]
    .into_iter()
    .flatten()
    .collect();
    let wanted_names: Vec<&str> = wanted.iter().map(|&i| names[i].as_str()).collect();
    let mut cols: Vec<Option<Vec<f64>>> = vec![None; names.len()];
    for (i, c) in wanted
        .into_iter()
        .zip(table.read(&wanted_names).map_err(fe)?)
    {
        cols[i] = Some(c);
    }
    let mut rows = Vec::with_capacity(num_rows);
    for r in 0..num_rows {
        let at = |message: String| SceneError::Parse {
            path: p.clone(),
            line: r + 1,
            message: format!("(table row) {message}"),
        };
        // NaN in a FITS table means "no value": the default applies
        let get = |i: usize| {
            cols.get(i)
                .and_then(|c| c.as_ref())
                .map(|c| c[r])
                .filter(|v| !v.is_nan())
        };
        rows.push(star_of(&get, &lay, lim, &at)?);
    }
    collect(rows, lay.sky, &p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One column of a pair (an `x` beside `ra, dec`, a lone `ra`) is refused, naming the columns found
    /// and the pairs expected, instead of placing the stars by the other pair.
    #[test]
    fn a_catalogue_with_half_a_position_pair_is_refused() {
        let dir = std::env::temp_dir().join(format!("jsim-cat-half-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        for (name, header, lone, missing) in [
            ("ra_dec_x", "ra,dec,x,hw", "x", "y"),
            ("ra_dec_y", "ra,dec,y_px,hw", "y_px", "x"),
            ("x_y_ra", "x,y,ra,hw", "ra", "dec"),
            ("ra_only", "ra,hw", "ra", "dec"),
            ("y_only", "y,hw", "y", "x"),
        ] {
            let p = dir.join(format!("{name}.csv"));
            std::fs::write(&p, format!("{header}\n266.4,-29.0,10,12.5\n")).expect("write");
            let msg = read(&p, 12.5, 2.0, 1968.0).expect_err(name).to_string();
            assert!(
                msg.contains(&format!("`{lone}` without `{missing}`"))
                    && msg.contains("ra, dec")
                    && msg.contains("x, y")
                    && msg.contains(header.split(',').next().expect("a column")),
                "{name}: {msg}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A catalogue as spreadsheets and pandas write it: every cell quoted, a name holding a comma, a
    /// comment and a blank line. The stars are read as written (a comma-split reader cut the name in two
    /// and took `"x"` for an unknown column), and a bad value is named at its line.
    #[test]
    fn a_quoted_catalogue_is_read_as_written() {
        let dir = std::env::temp_dir().join(format!("jsim-cat-quoted-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        let p = dir.join("quoted.csv");
        std::fs::write(
            &p,
            "# two stars\n\"name\",\"x\",\"y\",\"hw\"\n\n\"Star, the first\",\"100.5\",\"200.25\",\"12.5\"\n\"B\",300,400,13\n",
        )
        .expect("write");
        let Catalogue::Pixels(stars) = read(&p, 12.5, 2.0, 1968.0).expect("read") else {
            panic!("pixel positions")
        };
        let got: Vec<(f64, f64, f64)> = stars.iter().map(|s| (s.x_px, s.y_px, s.mag_hw)).collect();
        assert_eq!(got, vec![(100.5, 200.25, 12.5), (300.0, 400.0, 13.0)]);
        std::fs::write(&p, "# a comment\nx,y,hw\n\n1,2,12\n3,oops,12\n").expect("write");
        let msg = read(&p, 12.5, 2.0, 1968.0).expect_err("oops").to_string();
        assert!(msg.contains("line 5") && msg.contains("oops"), "{msg}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
