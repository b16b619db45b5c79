//! A step-stare sequence's products as the explorer shows them, read from its directory: the coverage map
//! (`coverage.csv`, written by `jsim sequence`) and, once `jsim solve --sequence DIR` has run, the precision
//! against the number of exposures (`solution/precision_vs_n.csv`) and the distortion calibration against the
//! instrument's (`solution/calibration_map.csv`), with the plate scale of the sequence's instrument
//! (`design.toml`, the instrument as designed, which the solution uses; else `config.toml`).
//! Reading only: every number here was computed by `jsim`; the explorer draws them.

use super::IoError;
use crate::config::Config;
use std::path::{Path, PathBuf};

/// The files of a sequence's directory read here.
pub const COVERAGE_NAME: &str = crate::io::products::files::COVERAGE_CSV;
pub const PLAN_NAME: &str = crate::io::products::files::PLAN_CSV;
pub const DESIGN_NAME: &str = crate::io::products::files::DESIGN_TOML;
pub const CONFIG_NAME: &str = crate::io::products::files::CONFIG_TOML;
/// `jsim solve --sequence DIR`'s default output directory, and its files read here.
pub const SOLUTION_DIR: &str = "solution";
pub const PRECISION_NAME: &str = crate::io::products::files::PRECISION_VS_N_CSV;
pub const CALIBRATION_MAP_NAME: &str = crate::io::products::files::CALIBRATION_MAP_CSV;

/// A precision point is shown where its bin holds at least this many sources (as `jsim solve`'s figure).
pub const MIN_SOURCES_PER_POINT: usize = 5;

/// What the explorer shows of a sequence's directory.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceView {
    /// The directory read.
    pub dir: PathBuf,
    /// The exposures per sky cell; None where the directory has plan.csv but no coverage.csv.
    pub coverage: Option<CoverageGrid>,
    /// The astrometric solution's products; None where `solution/` does not exist (not solved yet).
    pub solution: Option<SolutionView>,
}

/// The coverage map: exposures per cell of a regular grid in Galactic (l, b).
#[derive(Debug, Clone, PartialEq)]
pub struct CoverageGrid {
    /// Centre of the cell in column 0 (the lowest l) and row 0 (the lowest b), deg.
    pub l_first_deg: f64,
    pub b_first_deg: f64,
    /// The cells' side, deg (the spacing of their centres).
    pub cell_deg: f64,
    pub columns: usize,
    pub rows: usize,
    /// Exposures per cell, row-major (row 0 at the lowest b); a cell absent from the file counts 0.
    pub counts: Vec<u32>,
}

impl CoverageGrid {
    /// The centre (l, b) of the cell in column `i`, row `j`, deg.
    pub fn centre_deg(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.l_first_deg + i as f64 * self.cell_deg,
            self.b_first_deg + j as f64 * self.cell_deg,
        )
    }

    /// The grid's extent, cell edges included: (l_min, l_max, b_min, b_max), deg.
    pub fn extent_deg(&self) -> (f64, f64, f64, f64) {
        let h = self.cell_deg / 2.0;
        (
            self.l_first_deg - h,
            self.l_first_deg + (self.columns as f64 - 0.5) * self.cell_deg,
            self.b_first_deg - h,
            self.b_first_deg + (self.rows as f64 - 0.5) * self.cell_deg,
        )
    }

    /// The most exposures a cell gets.
    pub fn max_count(&self) -> u32 {
        self.counts.iter().copied().max().unwrap_or(0)
    }

    /// The area of the cells seen at least once, deg².
    pub fn covered_deg2(&self) -> f64 {
        self.counts.iter().filter(|c| **c > 0).count() as f64 * self.cell_deg * self.cell_deg
    }

    /// The median exposures of the cells seen at least once (0 where none is).
    pub fn median_covered(&self) -> u32 {
        let mut c: Vec<u32> = self.counts.iter().copied().filter(|c| *c > 0).collect();
        c.sort_unstable();
        c.get(c.len() / 2).copied().unwrap_or(0)
    }
}

/// The solution's products.
#[derive(Debug, Clone, PartialEq)]
pub struct SolutionView {
    /// The precision per magnitude bin and number of exposures, bins without sources left out.
    pub precision: Vec<PrecisionRow>,
    /// The calibration map's cells (9 × 9 per array).
    pub calibration: Vec<CalibrationCell>,
    /// The instrument's plate scale (from design.toml, else config.toml), mas per px; None without either.
    pub plate_scale_mas_per_px: Option<f64>,
}

/// One row of `precision_vs_n.csv`: a magnitude bin's scored sources in the solution of the first N exposures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrecisionRow {
    /// N: the solution is of the sequence's first N exposures.
    pub exposures: usize,
    /// The bin's Hw magnitudes, [lo, hi).
    pub hw_lo: f64,
    pub hw_hi: f64,
    /// Sources scored in the bin (≥ 1 here).
    pub sources: usize,
    /// Median observations per source.
    pub observations: f64,
    /// Position error per axis against the truth: rms, and robust (1.4826 × MAD), mas.
    pub position_rms_mas: f64,
    pub position_robust_mas: f64,
    /// Fraction of the sources off by more than 5σ on either axis.
    pub outlier_fraction: f64,
    /// The solution's own position σ per axis (rms over the sources), mas.
    pub position_sigma_mas: f64,
    /// The single-exposure accuracy in the bin (rms), and its robust scatter (each exposure's common shift
    /// removed) divided by √(observations) — what averaging would give —, mas; None where the file says NaN
    /// (no single-exposure errors in the bin).
    pub single_exposure_mas: Option<f64>,
    pub sqrt_n_mas: Option<f64>,
    /// The parallax error against the truth (rms) and the solution's own σ (rms over the sources), mas;
    /// None where the file says NaN (the position model, or a span too short for a parallax).
    pub parallax_rms_mas: Option<f64>,
    pub parallax_sigma_mas: Option<f64>,
}

/// A magnitude bin's precision against N, N ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct PrecisionCurve {
    pub hw_lo: f64,
    pub hw_hi: f64,
    pub points: Vec<PrecisionRow>,
}

/// One cell of `calibration_map.csv`: the distortion correction at a pixel of an array, px.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationCell {
    /// The array, 1 … 4.
    pub array: u32,
    /// The pixel on the array, px.
    pub x_px: f64,
    pub y_px: f64,
    /// Its place in the focal plane (the design layout, from the optical axis), px.
    pub u_px: f64,
    pub v_px: f64,
    /// The correction the instrument needs there, px (focal-plane axes).
    pub true_dx_px: f64,
    pub true_dy_px: f64,
    /// The solved correction, px.
    pub solved_dx_px: f64,
    pub solved_dy_px: f64,
    /// Solved − true with the attitudes' gauge (shift, turn, scale) removed, px.
    pub residual_dx_px: f64,
    pub residual_dy_px: f64,
}

impl SolutionView {
    /// The precision per magnitude bin against N, bins by Hw, each point with at least
    /// [`MIN_SOURCES_PER_POINT`] sources; bins with no such point left out.
    pub fn precision_curves(&self) -> Vec<PrecisionCurve> {
        let mut curves: Vec<PrecisionCurve> = Vec::new();
        for r in self
            .precision
            .iter()
            .filter(|r| r.sources >= MIN_SOURCES_PER_POINT)
        {
            match curves
                .iter_mut()
                .find(|c| c.hw_lo == r.hw_lo && c.hw_hi == r.hw_hi)
            {
                Some(c) => c.points.push(*r),
                None => curves.push(PrecisionCurve {
                    hw_lo: r.hw_lo,
                    hw_hi: r.hw_hi,
                    points: vec![*r],
                }),
            }
        }
        curves.sort_by(|a, b| a.hw_lo.total_cmp(&b.hw_lo));
        for c in &mut curves {
            c.points.sort_by_key(|p| p.exposures);
        }
        curves
    }

    /// The parallax error per magnitude bin in the solution of the most exposures that solved a parallax:
    /// that N and its bins (Hw ascending) with a parallax error and at least [`MIN_SOURCES_PER_POINT`]
    /// sources; None where no parallax was solved.
    pub fn parallax_by_magnitude(&self) -> Option<(usize, Vec<PrecisionRow>)> {
        let with =
            |r: &&PrecisionRow| r.parallax_rms_mas.is_some() && r.sources >= MIN_SOURCES_PER_POINT;
        let n = self
            .precision
            .iter()
            .filter(with)
            .map(|r| r.exposures)
            .max()?;
        let mut rows: Vec<PrecisionRow> = self
            .precision
            .iter()
            .filter(with)
            .filter(|r| r.exposures == n)
            .copied()
            .collect();
        rows.sort_by(|a, b| a.hw_lo.total_cmp(&b.hw_lo));
        Some((n, rows))
    }

    /// The arrays of the calibration map, ascending.
    pub fn arrays(&self) -> Vec<u32> {
        let mut a: Vec<u32> = self.calibration.iter().map(|c| c.array).collect();
        a.sort_unstable();
        a.dedup();
        a
    }

    /// The residual's rms per axis (x, y) over the cells of `array` (all arrays: None), px — the numbers
    /// `jsim solve` reports.
    pub fn residual_rms_px(&self, array: Option<u32>) -> [f64; 2] {
        let cells: Vec<&CalibrationCell> = self
            .calibration
            .iter()
            .filter(|c| array.is_none_or(|a| c.array == a))
            .collect();
        let n = cells.len().max(1) as f64;
        let rms = |f: &dyn Fn(&CalibrationCell) -> f64| {
            (cells.iter().map(|c| f(c) * f(c)).sum::<f64>() / n).sqrt()
        };
        [rms(&|c| c.residual_dx_px), rms(&|c| c.residual_dy_px)]
    }

    /// [`residual_rms_px`](Self::residual_rms_px) in mas, where the plate scale is known.
    pub fn residual_rms_mas(&self, array: Option<u32>) -> Option<[f64; 2]> {
        let s = self.plate_scale_mas_per_px?;
        let [x, y] = self.residual_rms_px(array);
        Some([x * s, y * s])
    }

    /// The spacing of the calibration grid on an array, px (the smallest step between its cells' x).
    pub fn grid_step_px(&self) -> Option<f64> {
        let mut x: Vec<f64> = self.calibration.iter().map(|c| c.x_px).collect();
        x.sort_by(f64::total_cmp);
        x.windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d > 1e-9)
            .min_by(f64::total_cmp)
    }
}

/// Read what the explorer shows of the sequence in `dir`: its coverage map and, where `dir/solution/`
/// exists, the solution's precision against N and calibration map. A directory with neither coverage.csv
/// nor plan.csv is no sequence's; a malformed or non-finite value is an error naming the file, the row and
/// the column.
pub fn read_sequence_view(dir: &Path) -> Result<SequenceView, IoError> {
    let format = |path: &Path, message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if !dir.is_dir() {
        return Err(format(dir, "no such directory".into()));
    }
    let coverage_path = dir.join(COVERAGE_NAME);
    let coverage = if coverage_path.is_file() {
        Some(read_coverage(&coverage_path)?)
    } else if dir.join(PLAN_NAME).is_file() {
        None
    } else {
        return Err(format(
            dir,
            format!(
                "no {COVERAGE_NAME} or {PLAN_NAME}: not a sequence's directory (written by `jsim sequence \
                 --out DIR`)"
            ),
        ));
    };
    let solution_dir = dir.join(SOLUTION_DIR);
    let solution = if solution_dir.is_dir() {
        let plate_scale_mas_per_px = match [DESIGN_NAME, CONFIG_NAME]
            .iter()
            .map(|n| dir.join(n))
            .find(|p| p.is_file())
        {
            Some(config) => {
                let cfg = Config::load(&config).map_err(|e| format(&config, e.to_string()))?;
                Some(cfg.instrument.plate_scale_mas())
            }
            None => None,
        };
        Some(SolutionView {
            precision: read_precision(&solution_dir.join(PRECISION_NAME))?,
            calibration: read_calibration_map(&solution_dir.join(CALIBRATION_MAP_NAME))?,
            plate_scale_mas_per_px,
        })
    } else {
        None
    };
    Ok(SequenceView {
        dir: dir.to_path_buf(),
        coverage,
        solution,
    })
}

/// A table's columns by name, read once: finite values, or whole numbers ≥ 0, or values that may be NaN.
struct Table {
    path: PathBuf,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn read(path: &Path) -> Result<Self, IoError> {
        let (header, rows) = super::csv::read(path)?;
        Ok(Self {
            path: path.to_path_buf(),
            header,
            rows,
        })
    }

    fn finite(&self, name: &str) -> Result<Vec<f64>, IoError> {
        super::csv::column_f64(&self.path, &self.header, &self.rows, name)
    }

    /// Finite or NaN (None); ±∞ is an error.
    fn finite_or_nan(&self, name: &str) -> Result<Vec<Option<f64>>, IoError> {
        let v = super::csv::column_f64_any(&self.path, &self.header, &self.rows, name)?;
        v.iter()
            .enumerate()
            .map(|(k, x)| match x {
                x if x.is_finite() => Ok(Some(*x)),
                x if x.is_nan() => Ok(None),
                _ => Err(self.bad(k, name, "is not a finite number")),
            })
            .collect()
    }

    fn whole(&self, name: &str) -> Result<Vec<u64>, IoError> {
        let v = self.finite(name)?;
        v.iter()
            .enumerate()
            .map(|(k, x)| {
                if *x >= 0.0 && x.fract() == 0.0 && *x <= u32::MAX as f64 {
                    Ok(*x as u64)
                } else {
                    Err(self.bad(k, name, "is not a whole number ≥ 0"))
                }
            })
            .collect()
    }

    /// The error of row `k` (0-based, after the header: the file's line k + 2, as the CSV reader counts).
    fn bad(&self, k: usize, name: &str, what: &str) -> IoError {
        IoError::Format {
            path: self.path.clone(),
            message: format!("row {}: column `{name}` {what}", k + 2),
        }
    }
}

/// Read `coverage.csv` (l_deg, b_deg, exposures per cell centre) back into its grid.
pub fn read_coverage(path: &Path) -> Result<CoverageGrid, IoError> {
    let t = Table::read(path)?;
    let (l, b, n) = (
        t.finite("l_deg")?,
        t.finite("b_deg")?,
        t.whole("exposures")?,
    );
    let format = |message: String| IoError::Format {
        path: path.to_path_buf(),
        message,
    };
    if l.is_empty() {
        return Err(format("no cells".into()));
    }
    // the distinct centres on each axis, and their spacing: the cell
    let distinct = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * (1.0 + b.abs()));
        s
    };
    let (ls, bs) = (distinct(&l), distinct(&b));
    let step = |s: &[f64]| s.windows(2).map(|w| w[1] - w[0]).min_by(f64::total_cmp);
    let cell_deg = match (step(&ls), step(&bs)) {
        (Some(a), Some(c)) => a.min(c),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => {
            return Err(format(
                "a single cell: the grid's spacing cannot be told".into(),
            ));
        }
    };
    let (l0, b0) = (ls[0], bs[0]);
    let index = |v: f64, v0: f64| (v - v0) / cell_deg;
    let columns = index(ls[ls.len() - 1], l0).round() as usize + 1;
    let rows = index(bs[bs.len() - 1], b0).round() as usize + 1;
    if columns.saturating_mul(rows) > 4_000_000 {
        return Err(format(format!(
            "{columns} × {rows} cells of {cell_deg}°: at most 4e6 (not a regular grid?)"
        )));
    }
    let mut counts = vec![0u32; columns * rows];
    let mut seen = vec![false; columns * rows];
    for k in 0..l.len() {
        let (fi, fj) = (index(l[k], l0), index(b[k], b0));
        if (fi - fi.round()).abs() > 1e-3 || (fj - fj.round()).abs() > 1e-3 {
            return Err(t.bad(
                k,
                "l_deg",
                &format!(
                    "/ `b_deg` ({}, {}) is off the grid of {cell_deg}° cells",
                    l[k], b[k]
                ),
            ));
        }
        let cell = fj.round() as usize * columns + fi.round() as usize;
        if seen[cell] {
            return Err(t.bad(
                k,
                "l_deg",
                &format!("/ `b_deg` ({}, {}) repeats a cell", l[k], b[k]),
            ));
        }
        seen[cell] = true;
        counts[cell] = n[k] as u32;
    }
    Ok(CoverageGrid {
        l_first_deg: l0,
        b_first_deg: b0,
        cell_deg,
        columns,
        rows,
        counts,
    })
}

/// Read `precision_vs_n.csv`; rows of bins without sources (NaN throughout) are left out, the others must
/// be finite (the single-exposure columns may be NaN).
pub fn read_precision(path: &Path) -> Result<Vec<PrecisionRow>, IoError> {
    let t = Table::read(path)?;
    let (exposures, sources) = (t.whole("exposures")?, t.whole("sources")?);
    let (hw_lo, hw_hi) = (t.finite("hw_lo")?, t.finite("hw_hi")?);
    let single = t.finite_or_nan("single_exposure_mas")?;
    let sqrt_n = t.finite_or_nan("sqrt_n_mas")?;
    let parallax = t.finite_or_nan("parallax_rms_mas")?;
    let parallax_sigma = t.finite_or_nan("parallax_sigma_mas")?;
    // finite where the bin has sources
    let scored = |name: &str| -> Result<Vec<f64>, IoError> {
        let v = super::csv::column_f64_any(path, &t.header, &t.rows, name)?;
        for (k, x) in v.iter().enumerate() {
            if sources[k] > 0 && !x.is_finite() {
                return Err(t.bad(k, name, "is not a finite number (the bin has sources)"));
            }
        }
        Ok(v)
    };
    let observations = scored("observations")?;
    let rms = scored("position_rms_mas")?;
    let robust = scored("position_robust_mas")?;
    let outliers = scored("outlier_fraction")?;
    let sigma = scored("position_sigma_mas")?;
    Ok((0..t.rows.len())
        .filter(|k| sources[*k] > 0)
        .map(|k| PrecisionRow {
            exposures: exposures[k] as usize,
            hw_lo: hw_lo[k],
            hw_hi: hw_hi[k],
            sources: sources[k] as usize,
            observations: observations[k],
            position_rms_mas: rms[k],
            position_robust_mas: robust[k],
            outlier_fraction: outliers[k],
            position_sigma_mas: sigma[k],
            single_exposure_mas: single[k],
            sqrt_n_mas: sqrt_n[k],
            parallax_rms_mas: parallax[k],
            parallax_sigma_mas: parallax_sigma[k],
        })
        .collect())
}

/// `calibration_map.csv`'s columns, as `jsim solve` writes them.
pub const CALIBRATION_MAP_COLUMNS: [&str; 11] = [
    "array",
    "x_px",
    "y_px",
    "u_px",
    "v_px",
    "true_dx_px",
    "true_dy_px",
    "solved_dx_px",
    "solved_dy_px",
    "residual_dx_px",
    "residual_dy_px",
];

/// Read `calibration_map.csv`.
pub fn read_calibration_map(path: &Path) -> Result<Vec<CalibrationCell>, IoError> {
    let t = Table::read(path)?;
    let array = t.whole("array")?;
    let cols: Vec<Vec<f64>> = CALIBRATION_MAP_COLUMNS[1..]
        .iter()
        .map(|n| t.finite(n))
        .collect::<Result<_, _>>()?;
    Ok((0..t.rows.len())
        .map(|k| CalibrationCell {
            array: array[k] as u32,
            x_px: cols[0][k],
            y_px: cols[1][k],
            u_px: cols[2][k],
            v_px: cols[3][k],
            true_dx_px: cols[4][k],
            true_dy_px: cols[5][k],
            solved_dx_px: cols[6][k],
            solved_dy_px: cols[7][k],
            residual_dx_px: cols[8][k],
            residual_dy_px: cols[9][k],
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch directory, removed when dropped.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(name: &str) -> Self {
            let d = std::env::temp_dir()
                .join(format!("jsim-sequence-view-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&d);
            std::fs::create_dir_all(d.join(SOLUTION_DIR)).expect("scratch dir");
            Self(d)
        }
        fn write(&self, name: &str, text: &str) {
            std::fs::write(self.0.join(name), text).expect("write");
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    const COVERAGE: &str = "l_deg,b_deg,exposures\n\
        -0.015,-0.01,0\n-0.005,-0.01,3\n0.005,-0.01,3\n\
        -0.015,0,1\n-0.005,0,6\n0.005,0,2\n";

    const PRECISION: &str = "exposures,hw_lo,hw_hi,sources,observations,position_rms_mas,\
        position_robust_mas,outlier_fraction,position_sigma_mas,single_exposure_mas,sqrt_n_mas,\
        pm_rms_mas_per_yr,pm_sigma_mas_per_yr,parallax_rms_mas,parallax_sigma_mas\n\
        1,8,9,0,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN,NaN\n\
        2,10,11,20,2,1.4,1.05,0,1.01,2.12,1.5,NaN,NaN,0.9,0.8\n\
        1,10,11,19,1,1.3,1.1,0,1.25,2.16,2.16,NaN,NaN,NaN,NaN\n\
        1,11,12,3,1,1.8,1.7,0.01,1.5,NaN,NaN,NaN,NaN,NaN,NaN\n";

    fn calibration(residual_dx: f64) -> String {
        let mut s = String::from(
            "array,x_px,y_px,u_px,v_px,true_dx_px,true_dy_px,solved_dx_px,solved_dy_px,residual_dx_px,\
             residual_dy_px\n",
        );
        for (k, r) in [(1, residual_dx), (1, -residual_dx), (2, 0.0), (2, 0.0)]
            .iter()
            .enumerate()
        {
            s.push_str(&format!(
                "{},{},14.2,{},-391.3,-4.3,8.0,-3.1,5.8,{},0.001\n",
                r.0,
                14.2 + 28.4 * (k % 2) as f64,
                -391.3 + 28.4 * k as f64,
                r.1
            ));
        }
        s
    }

    #[test]
    fn a_solved_sequence_reads_back() {
        let d = Scratch::new("solved");
        d.write(COVERAGE_NAME, COVERAGE);
        d.write("solution/precision_vs_n.csv", PRECISION);
        d.write("solution/calibration_map.csv", &calibration(0.004));
        d.write(CONFIG_NAME, "");
        let v = read_sequence_view(&d.0).expect("read");
        let c = v.coverage.as_ref().expect("coverage");
        assert_eq!((c.columns, c.rows), (3, 2));
        assert!((c.cell_deg - 0.01).abs() < 1e-12, "{}", c.cell_deg);
        assert_eq!(c.counts, vec![0, 3, 3, 1, 6, 2]);
        assert_eq!(c.max_count(), 6);
        assert_eq!(c.median_covered(), 3);
        assert!((c.covered_deg2() - 5e-4).abs() < 1e-12);
        let (l, b) = c.centre_deg(2, 1);
        assert!((l - 0.005).abs() < 1e-12 && b.abs() < 1e-12);
        let s = v.solution.as_ref().expect("solved");
        // the bin without sources is left out; NaN single-exposure accuracy is None
        assert_eq!(s.precision.len(), 3);
        assert_eq!(s.precision[0].exposures, 2);
        assert_eq!(s.precision[0].position_robust_mas, 1.05);
        assert_eq!(s.precision[0].sqrt_n_mas, Some(1.5));
        assert_eq!(s.precision[2].single_exposure_mas, None);
        // the parallax: solved at N = 2 only, in the bin with enough sources
        assert_eq!(
            (
                s.precision[0].parallax_rms_mas,
                s.precision[0].parallax_sigma_mas
            ),
            (Some(0.9), Some(0.8))
        );
        assert_eq!(s.precision[1].parallax_rms_mas, None);
        let (n, rows) = s.parallax_by_magnitude().expect("a parallax");
        assert_eq!((n, rows.len(), rows[0].hw_lo), (2, 1, 10.0));
        // the curves: bin 11–12 has 3 sources only, below the figure's 5
        let curves = s.precision_curves();
        assert_eq!(curves.len(), 1);
        assert_eq!((curves[0].hw_lo, curves[0].hw_hi), (10.0, 11.0));
        let ns: Vec<usize> = curves[0].points.iter().map(|p| p.exposures).collect();
        assert_eq!(ns, vec![1, 2], "N ascending");
        assert_eq!(s.calibration.len(), 4);
        assert_eq!(s.arrays(), vec![1, 2]);
        assert_eq!(s.calibration[1].residual_dx_px, -0.004);
        assert_eq!(s.calibration[0].u_px, -391.3);
        let [x, y] = s.residual_rms_px(Some(1));
        assert!((x - 0.004).abs() < 1e-12 && (y - 0.001).abs() < 1e-12);
        let [x, _] = s.residual_rms_px(None);
        assert!((x - 0.004 / 2f64.sqrt()).abs() < 1e-12);
        let scale = Config::default().instrument.plate_scale_mas();
        assert_eq!(s.plate_scale_mas_per_px, Some(scale));
        let mas = s.residual_rms_mas(Some(1)).expect("mas");
        assert!((mas[0] - 0.004 * scale).abs() < 1e-9);
        assert!((s.grid_step_px().expect("step") - 28.4).abs() < 1e-9);
        // the instrument as designed comes first (a broken config.toml is not read)
        d.write(CONFIG_NAME, "[instrument\n");
        assert!(read_sequence_view(&d.0).is_err_and(|e| {
            e.to_string()
                .contains(crate::io::products::files::CONFIG_TOML)
        }));
        d.write(DESIGN_NAME, "");
        let v = read_sequence_view(&d.0).expect("design.toml read");
        assert_eq!(
            v.solution.and_then(|s| s.plate_scale_mas_per_px),
            Some(scale)
        );
    }

    #[test]
    fn not_solved_yet_and_not_a_sequence() {
        let d = Scratch::new("unsolved");
        std::fs::remove_dir_all(d.0.join(SOLUTION_DIR)).expect("rm");
        d.write(COVERAGE_NAME, COVERAGE);
        let v = read_sequence_view(&d.0).expect("coverage only");
        assert!(v.coverage.is_some() && v.solution.is_none());
        // plan.csv without coverage.csv: a sequence, no map
        std::fs::remove_file(d.0.join(COVERAGE_NAME)).expect("rm");
        d.write(PLAN_NAME, "exposure\n0\n");
        let v = read_sequence_view(&d.0).expect("plan only");
        assert!(v.coverage.is_none());
        std::fs::remove_file(d.0.join(PLAN_NAME)).expect("rm");
        let e = read_sequence_view(&d.0)
            .expect_err("no sequence")
            .to_string();
        assert!(
            e.contains(&d.0.display().to_string())
                && e.contains(crate::io::products::files::COVERAGE_CSV),
            "{e}"
        );
        let e = read_sequence_view(&d.0.join("nowhere"))
            .expect_err("missing")
            .to_string();
        assert!(
            e.contains("nowhere") && e.contains("no such directory"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_name_the_file_row_and_column() {
        let d = Scratch::new("bad");
        d.write(COVERAGE_NAME, COVERAGE);
        d.write("solution/precision_vs_n.csv", PRECISION);
        // a solution/ directory without its files names the file missing
        let e = read_sequence_view(&d.0).expect_err("missing").to_string();
        assert!(
            e.contains(crate::io::products::files::CALIBRATION_MAP_CSV),
            "{e}"
        );
        d.write("solution/calibration_map.csv", &calibration(f64::INFINITY));
        let e = read_sequence_view(&d.0).expect_err("inf").to_string();
        assert!(
            e.contains(crate::io::products::files::CALIBRATION_MAP_CSV)
                && e.contains("row 2")
                && e.contains("`residual_dx_px`"),
            "{e}"
        );
        d.write("solution/calibration_map.csv", &calibration(0.001));
        // a scored bin with a NaN error
        d.write(
            "solution/precision_vs_n.csv",
            &PRECISION.replace("2,10,11,20,2,1.4,1.05", "2,10,11,20,2,1.4,NaN"),
        );
        let e = read_sequence_view(&d.0).expect_err("nan").to_string();
        assert!(
            e.contains(crate::io::products::files::PRECISION_VS_N_CSV)
                && e.contains("row 3")
                && e.contains("`position_robust_mas`"),
            "{e}"
        );
        d.write("solution/precision_vs_n.csv", PRECISION);
        assert!(read_sequence_view(&d.0).is_ok());
        // a count that is not a whole number, a cell off the grid
        d.write(COVERAGE_NAME, &COVERAGE.replace("0.005,0,2", "0.005,0,2.5"));
        let e = read_sequence_view(&d.0).expect_err("fraction").to_string();
        assert!(
            e.contains(crate::io::products::files::COVERAGE_CSV)
                && e.contains("row 7")
                && e.contains("`exposures`"),
            "{e}"
        );
        d.write(COVERAGE_NAME, &COVERAGE.replace("0.005,0,2", "0.0072,0,2"));
        let e = read_sequence_view(&d.0).expect_err("off grid").to_string();
        assert!(
            e.contains(crate::io::products::files::COVERAGE_CSV) && e.contains("off the grid"),
            "{e}"
        );
        d.write(COVERAGE_NAME, "l_deg,b_deg\n0,0\n");
        let e = read_sequence_view(&d.0).expect_err("no column").to_string();
        assert!(e.contains("no column `exposures`"), "{e}");
    }
}
