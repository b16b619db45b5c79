//! The astrometric solution of a sequence that has run (`jsim solve`): its products read back — the
//! configuration and sequence file it was planned with (for the planned pointings and the design focal
//! plane), the exposures' catalogues, the reference catalogue — fed to `solution` and solved; the
//! sources, attitudes and calibration written; then, apart, the scoring: the solved sources against the
//! field's stars, the calibration against the instrument's, the precision against the number of exposures
//! beside √N from the single-exposure accuracy.

use super::plan::{Plan, design_config, exposure_config, mid_exposure};
use super::run::SequenceError;
use crate::config::Config;
use crate::io::csv::Cell;
use crate::scoring::solution::{BinScore, TrueSource};
use crate::solution::feed::{self, DesignExposure, Detection, Fed, FeedOptions, SkyReference};
use crate::solution::{CalibrationModel, Method, Options, Solution, SourceModel};
use std::path::Path;

/// What to solve.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SolveSpec {
    /// Solve positions only, or all five parameters; None: five where the exposures span ≥ 0.1 yr.
    pub model: Option<SourceModel>,
    /// The global distortion's order (0 or 2 … 5); None: 3 where the exposures point at ≥ 2 places, else 0.
    pub distortion_order: Option<usize>,
    /// How the solution iterates (conjugate gradients by default; the block iteration as a reference).
    pub method: Method,
    /// The error beyond each detection's σ that the sources' σ carry (none by default).
    pub excess: crate::solution::ExcessNoise,
    pub feed: FeedOptions,
}

/// A sequence's products, read back.
#[derive(Debug, Clone)]
pub struct Products {
    pub cfg: Config,
    pub plan: Plan,
    /// Exposures 0 … n − 1 have run (their catalogues are there).
    pub exposures_run: usize,
    pub designs: Vec<DesignExposure>,
    pub detections: Vec<Detection>,
    pub references: Vec<SkyReference>,
    /// The sequence's centre: the tangent point (ICRS degrees).
    pub tangent_deg: (f64, f64),
}

fn invalid(m: impl std::fmt::Display) -> SequenceError {
    SequenceError::Invalid(m.to_string())
}

/// Read a sequence directory's products: the exposures that have run, from the first on.
pub fn read_products(dir: &Path) -> Result<Products, SequenceError> {
    read_products_every(dir, 1)
}

/// [`read_products`] thinned: of the exposures that have run, every `every`-th of each stare (its 1st,
/// (every + 1)-th, …), renumbered 0 … in their order — every stare and season kept, fewer exposures in
/// each: the precision against the exposures per star over the sequence's whole time span. `every` is
/// 1 … the exposures per stare (a named error otherwise).
pub fn read_products_every(dir: &Path, every: usize) -> Result<Products, SequenceError> {
    // the instrument as designed and the plan: never config.toml (the instrument as assembled, the seeds)
    let cfg_path = dir.join(super::run::DESIGN_NAME);
    let spec_path = dir.join(crate::io::products::files::SEQUENCE_TOML);
    if !cfg_path.exists() || !spec_path.exists() {
        return Err(invalid(format!(
            "{} holds no sequence (design.toml and sequence.toml are written by `jsim sequence`)",
            dir.display()
        )));
    }
    let cfg = Config::load(&cfg_path).map_err(invalid)?;
    let mut spec = super::Spec::load(&spec_path).map_err(invalid)?;
    // the plan as planned: what the pointings and rolls were meant to be, no draw of their errors
    spec.pointing_error_arcsec = 0.0;
    spec.roll_error_arcsec = 0.0;
    let mut plan = super::plan(&spec, &cfg).map_err(invalid)?;
    let exposures_run = plan
        .exposures
        .iter()
        .take_while(|e| super::run::exposure_path(dir, e.index).exists())
        .count();
    if exposures_run == 0 {
        return Err(invalid(format!(
            "{}: no exposure has run yet (exposures/00000.csv is missing)",
            dir.display()
        )));
    }
    if every == 0 || every > spec.exposures_per_stare {
        return Err(invalid(format!(
            "every {every}: allowed 1 … {} (the exposures per stare)",
            spec.exposures_per_stare
        )));
    }
    // the kept exposures, in order; each keeps its index (its files), its place in the list is its number
    plan.exposures.truncate(exposures_run);
    let mut first_of_stare = std::collections::HashMap::new();
    for e in &plan.exposures {
        first_of_stare.entry(e.stare).or_insert(e.index);
    }
    plan.exposures.retain(|e| {
        first_of_stare
            .get(&e.stare)
            .is_none_or(|first| (e.index - first) % every == 0)
    });
    let exposures_run = plan.exposures.len();
    let designs: Vec<DesignExposure> = plan.exposures[..exposures_run]
        .iter()
        .map(|e| {
            let c = design_config(&cfg, &plan, e);
            let mid = mid_exposure(&c, e);
            DesignExposure {
                cfg: c,
                mid,
                stare: e.stare,
                visit: plan.stares[e.stare].visit,
            }
        })
        .collect();
    let id = super::run::sequence_id(dir)?;
    let mut detections = Vec::new();
    // each detection's exposure is its place in the kept list (its catalogue's column, checked to be the
    // exposure's own index, numbers its file)
    for (number, (e, d)) in plan.exposures[..exposures_run]
        .iter()
        .zip(&designs)
        .enumerate()
    {
        let path = super::run::exposure_path(dir, e.index);
        let (h, rows) = crate::io::csv::read(&path)?;
        let col = |n: &str| crate::io::csv::column_f64(&path, &h, &rows, n);
        let (ex, ar, x, y, f) = (
            col("exposure")?,
            col("array")?,
            col("x_px")?,
            col("y_px")?,
            col("flux_e")?,
        );
        let seen = Seen {
            exposure: &ex,
            mjd: &col("mjd_tdb")?,
            sequence_id: &col("sequence_id")?,
        };
        same_sequence(&path, e.index, d.mid.tdb_mjd(), id, &seen)?;
        let any = |n: &str| crate::io::csv::column_f64_any(&path, &h, &rows, n);
        let (cx, cy, fl) = (any("crlb_x_px")?, any("crlb_y_px")?, col("flags")?);
        for i in 0..rows.len() {
            detections.push(Detection {
                exposure: number,
                array: (ar[i] as usize).saturating_sub(1),
                x_px: x[i],
                y_px: y[i],
                flux_e: f[i],
                crlb_px: cx[i].max(cy[i]),
                flags: fl[i] as u32,
            });
        }
    }
    let references =
        crate::io::sky_reference::read(&dir.join(crate::io::sky_reference::REFERENCE_NAME))?;
    let tangent_deg = super::plan::galactic_to_icrs(spec.centre_l_deg, spec.centre_b_deg);
    Ok(Products {
        cfg,
        plan,
        exposures_run,
        designs,
        detections,
        references,
        tangent_deg,
    })
}

/// How far a catalogue's time may stand from its planned exposure's, days (0.09 s: the plan's exposures are
/// 12.5 s apart at least, a visit's months).
const SAME_EXPOSURE_DAYS: f64 = 1e-6;

/// What a catalogue says of where its rows come from.
struct Seen<'a> {
    exposure: &'a [f64],
    mjd: &'a [f64],
    sequence_id: &'a [f64],
}

/// A catalogue belongs to this sequence's exposure `index`: every row carries this sequence's identity
/// ([`super::run::sequence_id`], from the products the solution reads) and names that exposure at its
/// planned mid-exposure time. A catalogue of another sequence is refused by name.
fn same_sequence(
    path: &Path,
    index: usize,
    planned_mjd: f64,
    id: u64,
    seen: &Seen,
) -> Result<(), SequenceError> {
    let row = |i: usize| format!("{}: row {}", path.display(), i + 2);
    if let Some(i) = seen.sequence_id.iter().position(|v| *v != id as f64) {
        return Err(invalid(format!(
            "{} carries sequence_id {}, where this sequence (its design.toml, sequence.toml and reference \
             catalogue) is {id}: a catalogue of another sequence is not read into this one",
            row(i),
            seen.sequence_id[i]
        )));
    }
    let bad = (0..seen.exposure.len()).find(|&i| {
        seen.exposure[i] != index as f64 || (seen.mjd[i] - planned_mjd).abs() > SAME_EXPOSURE_DAYS
    });
    match bad {
        Some(i) => Err(invalid(format!(
            "{} is exposure {} at MJD {:.6} (TDB), where this sequence's exposure {index} is at MJD \
             {planned_mjd:.6}: a catalogue of another exposure is not read as this one",
            row(i),
            seen.exposure[i],
            seen.mjd[i],
        ))),
        None => Ok(()),
    }
}

/// The options a solution of the first `n` exposures gets from `spec`.
fn options(p: &Products, n: usize, spec: &SolveSpec) -> Options {
    let ex = &p.plan.exposures[..n];
    let years: Vec<f64> = p.designs[..n]
        .iter()
        .map(|d| d.mid.julian_year_tdb())
        .collect();
    let span = years.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - years.iter().cloned().fold(f64::INFINITY, f64::min);
    let model = spec.model.unwrap_or(if span >= 0.1 {
        SourceModel::Full
    } else {
        SourceModel::Position
    });
    let pointings = {
        let mut s: Vec<usize> = ex.iter().map(|e| e.stare).collect();
        s.dedup();
        s.len()
    };
    let distortion_order = spec
        .distortion_order
        .unwrap_or(if pointings >= 2 { 3 } else { 0 });
    // (each array's own terms are quadratic: the global distortion starts at order 3)
    Options {
        model,
        method: spec.method,
        excess: spec.excess,
        calibration: CalibrationModel {
            arrays: 4,
            array_order: 2,
            distortion_order,
        },
        max_iterations: 2000,
        // the focal plane's corner radius: its terms of order 1
        focal_norm_px: (p.cfg.instrument.detector_px as f64 + p.cfg.focal_plane.gap_px / 2.0)
            * std::f64::consts::SQRT_2,
        ..Options::default()
    }
}

/// Feed and solve the first `n` exposures (on this thread's ranks), resumed from and checkpointed to
/// `checkpoint` if given.
pub fn solve_first(
    p: &Products,
    n: usize,
    spec: &SolveSpec,
    checkpoint: Option<&Path>,
) -> Result<(Fed, Options, Solution), SequenceError> {
    if n == 0 || n > p.exposures_run {
        return Err(invalid(format!(
            "exposures {n}: allowed 1 … {} (the exposures that have run)",
            p.exposures_run
        )));
    }
    let dets: Vec<Detection> = p
        .detections
        .iter()
        .filter(|d| d.exposure < n)
        .copied()
        .collect();
    let fed = feed::feed(
        &dets,
        &p.designs[..n],
        &p.references,
        p.tangent_deg,
        &spec.feed,
    )
    .map_err(invalid)?;
    let opt = options(p, n, spec);
    let sol = solve_checkpointed(
        &fed.obs,
        &fed.exposures,
        &fed.refs,
        fed.n_sources,
        &opt,
        checkpoint,
    )
    .map_err(invalid)?;
    Ok((fed, opt, sol))
}

/// The solution on this thread's ranks ([`crate::solution::ranks::world`]), resumed from and
/// checkpointed to the file `checkpoint` if given: what `jsim solve` and `jsim solve-synthetic` run.
pub fn solve_checkpointed(
    obs: &[crate::solution::Observation],
    exposures: &[crate::solution::ExposureGeometry],
    refs: &[crate::solution::Reference],
    n_sources: usize,
    opt: &Options,
    checkpoint: Option<&Path>,
) -> Result<Solution, crate::solution::SolutionError> {
    let store = checkpoint.map(crate::io::checkpoint::FileStore::new);
    crate::solution::solve_with(
        obs,
        exposures,
        refs,
        n_sources,
        opt,
        &*crate::solution::ranks::world(),
        store.as_ref().map(|store| crate::solution::Checkpointing {
            store,
            interrupt_after: None,
        }),
    )
}

/// A solved source's columns in a sources table (after its index, and its sky position where given).
pub const SOURCE_COLUMNS: [&str; 12] = [
    "xi_mas",
    "eta_mas",
    "pm_xi",
    "pm_eta",
    "parallax",
    "xi_error",
    "eta_error",
    "pm_xi_error",
    "pm_eta_error",
    "parallax_error",
    "observations",
    "chi2",
];

/// A solved source's cells under [`SOURCE_COLUMNS`].
pub fn source_cells(v: &crate::solution::SolvedSource) -> Vec<Cell> {
    let mut row: Vec<Cell> = v
        .params
        .iter()
        .chain(&v.sigma)
        .map(|x| Cell::F(*x))
        .collect();
    row.extend([Cell::I(v.observations as i64), Cell::F(v.chi2)]);
    row
}

/// Write the solution into `out`: `sources.csv`, `attitudes.csv`, `calibration.csv`.
pub fn write_solution(
    out: &Path,
    p: &Products,
    fed: &Fed,
    sol: &Solution,
) -> Result<(), SequenceError> {
    crate::io::ensure_dir(out)?;
    let rows: Vec<Vec<Cell>> = sol
        .sources
        .iter()
        .enumerate()
        .map(|(s, v)| {
            let (ra, dec) = feed::plane_to_sky(p.tangent_deg, v.params[0], v.params[1]);
            let mut row = vec![Cell::I(s as i64), Cell::F(ra), Cell::F(dec)];
            row.extend(source_cells(v));
            row.push(Cell::I(i64::from(fed.reference[s].is_some())));
            row
        })
        .collect();
    let header: Vec<&str> = ["source", "ra", "dec"]
        .into_iter()
        .chain(SOURCE_COLUMNS)
        .chain(["in_reference"])
        .collect();
    crate::io::csv::write(
        &out.join(crate::io::products::files::SOURCES_CSV),
        &header,
        &rows,
    )?;
    let rows: Vec<Vec<Cell>> = sol
        .attitudes
        .iter()
        .zip(&fed.exposures)
        .enumerate()
        .map(|(e, (a, g))| {
            vec![
                Cell::I(p.plan.exposures.get(e).map_or(e, |x| x.index) as i64),
                Cell::F(g.t_yr + fed.ref_epoch_jyear),
                Cell::F(a.offset_mas[0]),
                Cell::F(a.offset_mas[1]),
                Cell::F(a.roll_rad().to_degrees() * 3600.0),
                Cell::F(a.scale_error() * 1e6),
            ]
        })
        .collect();
    crate::io::csv::write(
        &out.join(crate::io::products::files::ATTITUDES_CSV),
        &[
            "exposure",
            "epoch_jyear",
            "offset_xi_mas",
            "offset_eta_mas",
            "roll_arcsec",
            "scale_ppm",
        ],
        &rows,
    )?;
    let c = &sol.calibration;
    let term = |axis: &str, (pp, qq): (i32, i32)| format!("d{axis}_u{pp}v{qq}");
    let mut rows: Vec<Vec<Cell>> = Vec::new();
    for (k, a) in c.arrays.iter().enumerate() {
        for (m, t) in c.model.array_terms().into_iter().enumerate() {
            for (axis, name) in ["x", "y"].iter().enumerate() {
                rows.push(vec![
                    Cell::S(format!("array{}", k + 1)),
                    Cell::S(term(name, t)),
                    Cell::F(a[axis][m]),
                ]);
            }
        }
    }
    for (m, t) in c.model.monomials().into_iter().enumerate() {
        for (axis, name) in ["x", "y"].iter().enumerate() {
            rows.push(vec![
                Cell::S("distortion".into()),
                Cell::S(term(name, t)),
                Cell::F(c.distortion[axis][m]),
            ]);
        }
    }
    crate::io::csv::write(
        &out.join(crate::io::products::files::CALIBRATION_CSV),
        &["part", "term", "px"],
        &rows,
    )?;
    Ok(())
}

/// The scoring's view of a sequence: each detection's true star, the field's stars on the plane.
pub struct Truth {
    /// The instrument as assembled (`config.toml`).
    pub cfg: Config,
    /// Per detection of [`Products::detections`]: its star's row in `field.csv`, if matched.
    pub star_of_detection: Vec<Option<usize>>,
    /// Per detection: its position error in the exposure's own analysis (mas, x and y), if matched.
    pub single_error_mas: Vec<Option<[f64; 2]>>,
    pub stars: Vec<TrueSource>,
}

/// Read the truth of a sequence (the scoring step only).
pub fn read_truth(dir: &Path, p: &Products) -> Result<Truth, SequenceError> {
    let cfg = Config::load(&dir.join(crate::io::products::files::CONFIG_TOML)).map_err(invalid)?;
    let field = dir.join(super::run::FIELD_NAME);
    let (h, rows) = crate::io::csv::read(&field)?;
    let col = |n: &str| crate::io::csv::column_f64(&field, &h, &rows, n);
    let (ra, dec, hw, pmra, pmdec, plx) = (
        col("ra")?,
        col("dec")?,
        col("hw")?,
        col("pmra")?,
        col("pmdec")?,
        col("parallax")?,
    );
    let stars = (0..rows.len())
        .map(|i| TrueSource {
            params: feed::plane_params(p.tangent_deg, ra[i], dec[i], [pmra[i], pmdec[i]], plx[i]),
            hw: hw[i],
        })
        .collect();
    let (mut star_of_detection, mut single_error_mas) = (Vec::new(), Vec::new());
    for e in &p.plan.exposures[..p.exposures_run] {
        let path = super::run::truth_path(dir, e.index);
        let (h, rows) = crate::io::csv::read(&path)?;
        let col = |n: &str| crate::io::csv::column_f64(&path, &h, &rows, n);
        let any = |n: &str| crate::io::csv::column_f64_any(&path, &h, &rows, n);
        let (id, dx, dy) = (col("truth_id")?, any("dx_mas")?, any("dy_mas")?);
        for i in 0..rows.len() {
            let m = (id[i] >= 0.0).then_some(id[i] as usize);
            star_of_detection.push(m);
            single_error_mas.push(
                m.filter(|_| dx[i].is_finite() && dy[i].is_finite())
                    .map(|_| [dx[i], dy[i]]),
            );
        }
    }
    if star_of_detection.len() != p.detections.len() {
        return Err(invalid(
            "the exposures' truth files do not match their catalogues row by row",
        ));
    }
    Ok(Truth {
        cfg,
        star_of_detection,
        single_error_mas,
        stars,
    })
}

/// Each solved source's true star: the one most of its observations' detections were matched to.
pub fn true_sources(fed: &Fed, truth: &Truth) -> Vec<Option<TrueSource>> {
    let mut votes: Vec<std::collections::HashMap<usize, usize>> =
        vec![Default::default(); fed.n_sources];
    for (o, &d) in fed.obs.iter().zip(&fed.detection) {
        if let Some(s) = truth.star_of_detection[d] {
            *votes[o.source()].entry(s).or_default() += 1;
        }
    }
    votes
        .into_iter()
        .map(|v| {
            v.into_iter()
                .max_by_key(|(s, n)| (*n, std::cmp::Reverse(*s)))
                .and_then(|(s, _)| truth.stars.get(s).copied())
        })
        .collect()
}

/// For a positions-only solution: each source's solved and true place at the mean epoch of its
/// observations (its position is that epoch's, carried to the reference epoch by motions taken as they are —
/// the reference's, or none — so the place at the epoch is what its σ describes).
pub fn at_mean_epoch(
    fed: &Fed,
    sol: &Solution,
    truths: &[Option<TrueSource>],
) -> (Vec<crate::solution::SolvedSource>, Vec<Option<TrueSource>>) {
    let n = sol.sources.len();
    let (mut t, mut px, mut py, mut k) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0usize; n]);
    for o in &fed.obs {
        let g = &fed.exposures[o.exposure()];
        t[o.source()] += g.t_yr;
        px[o.source()] += g.parallax_factor[0];
        py[o.source()] += g.parallax_factor[1];
        k[o.source()] += 1;
    }
    let place = |p: &crate::solution::Params, s: usize| -> crate::solution::Params {
        let m = k[s].max(1) as f64;
        let mut q = *p;
        q[0] = p[0] + p[2] * t[s] / m + p[4] * px[s] / m;
        q[1] = p[1] + p[3] * t[s] / m + p[4] * py[s] / m;
        q
    };
    let solved = sol
        .sources
        .iter()
        .enumerate()
        .map(|(s, v)| crate::solution::SolvedSource {
            params: place(&v.params, s),
            ..*v
        })
        .collect();
    let truth = truths
        .iter()
        .enumerate()
        .map(|(s, t)| {
            t.map(|t| TrueSource {
                params: place(&t.params, s),
                hw: t.hw,
            })
        })
        .collect();
    (solved, truth)
}

/// The single-exposure accuracy per magnitude bin over the first `n` exposures (unflagged detections matched
/// to a star, in each exposure's own analysis), per axis: the rms, and the robust scatter (1.4826 × the median
/// absolute deviation) after each exposure's and array's median shift is removed — what an exposure's
/// attitude takes up (a realistic ACE moves a whole exposure by its mean pointing: hundreds of mas common to
/// every star, which the rms keeps).
pub fn single_exposure_errors(
    p: &Products,
    truth: &Truth,
    n: usize,
    edges: &[f64],
) -> Vec<SingleExposure> {
    use crate::numerics::stats::{mad_sigma, median};
    let bins = edges.len().saturating_sub(1);
    // each (exposure, array)'s detections: (bin, dx, dy)
    let mut groups: std::collections::BTreeMap<(usize, usize), Vec<(usize, [f64; 2])>> =
        std::collections::BTreeMap::new();
    for (i, d) in p.detections.iter().enumerate() {
        if d.exposure >= n || d.flags != 0 {
            continue;
        }
        if let (Some(s), Some(e)) = (truth.star_of_detection[i], truth.single_error_mas[i]) {
            let hw = truth.stars[s].hw;
            if let Some(b) = edges.windows(2).position(|w| hw >= w[0] && hw < w[1]) {
                groups
                    .entry((d.exposure, d.array))
                    .or_default()
                    .push((b, e));
            }
        }
    }
    let (mut sum, mut k) = (vec![0.0; bins], vec![0usize; bins]);
    let mut shifted: Vec<Vec<f64>> = vec![Vec::new(); bins];
    for g in groups.values() {
        let shift = [0, 1].map(|a| median(&g.iter().map(|(_, e)| e[a]).collect::<Vec<_>>()));
        for (b, e) in g {
            sum[*b] += e[0] * e[0] + e[1] * e[1];
            k[*b] += 2;
            shifted[*b].extend([e[0] - shift[0], e[1] - shift[1]]);
        }
    }
    (0..bins)
        .map(|b| SingleExposure {
            rms_mas: if k[b] > 0 {
                (sum[b] / k[b] as f64).sqrt()
            } else {
                f64::NAN
            },
            robust_mas: if shifted[b].is_empty() {
                f64::NAN
            } else {
                mad_sigma(&shifted[b])
            },
        })
        .collect()
}

/// One magnitude bin's single-exposure accuracy ([`single_exposure_errors`]), mas per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SingleExposure {
    pub rms_mas: f64,
    pub robust_mas: f64,
}

/// The solved calibration against the instrument's, on a 9 × 9 grid over each array ([`needed_corrections`]):
/// the correction the instrument needs and the solved one, and their difference with the attitudes' gauge
/// removed. Rows: array, x_px, y_px, focal u, v (px), true Δ, solved Δ, residual (px).
pub fn calibration_map(
    p: &Products,
    truth: &Truth,
    sol: &Solution,
) -> Result<Vec<[f64; 11]>, SequenceError> {
    let e = &p.plan.exposures[0];
    let design = design_config(&p.cfg, &p.plan, e);
    let flown = exposure_config(&truth.cfg, &p.plan, e);
    let needed = needed_corrections(&design, &flown, p.tangent_deg)?;
    let mut points = Vec::with_capacity(needed.len());
    let mut diff = Vec::with_capacity(needed.len());
    let rows: Vec<[f64; 11]> = needed
        .iter()
        .map(|n| {
            let solved = sol.calibration.correction_px(n.array, n.focal_px);
            // the gauge (a shift, turn and scale the attitudes can take from the arrays) acts on where the
            // sky's light would land as designed, not on the measured place: its lever arm
            points.push([
                n.focal_px[0] - n.needed_px[0],
                n.focal_px[1] - n.needed_px[1],
            ]);
            diff.push([solved[0] - n.needed_px[0], solved[1] - n.needed_px[1]]);
            [
                n.array as f64 + 1.0,
                n.pixel[0],
                n.pixel[1],
                n.focal_px[0],
                n.focal_px[1],
                n.needed_px[0],
                n.needed_px[1],
                solved[0],
                solved[1],
                0.0,
                0.0,
            ]
        })
        .collect();
    let res = crate::scoring::solution::calibration_residuals(&points, &diff);
    Ok(rows
        .into_iter()
        .zip(res)
        .map(|(mut r, d)| {
            (r[9], r[10]) = (d[0], d[1]);
            r
        })
        .collect())
}

/// What the instrument needs at one pixel of one array.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeededCorrection {
    /// 0-based array.
    pub array: usize,
    /// The pixel (x, y) of the array.
    pub pixel: [f64; 2],
    /// Its design focal-plane place, px from the optical axis.
    pub focal_px: [f64; 2],
    /// The correction, focal-plane px.
    pub needed_px: [f64; 2],
}

/// The correction the instrument flown as `flown` needs against its design `design`, on a 9 × 9 grid over
/// each array: the design place of a pixel minus the place of the sky it truly sees, on the plane at
/// `tangent_deg`, turned back into focal-plane px by the design map at the axis (the solution's own
/// convention). `flown` is realised first ([`crate::instrument::realise`]: its arrays as assembled *and* its
/// distortion beyond the design), both at the design's (planned) pointing, so only the instrument differs.
pub fn needed_corrections(
    design: &Config,
    flown: &Config,
    tangent_deg: (f64, f64),
) -> Result<Vec<NeededCorrection>, SequenceError> {
    let mut flown = crate::instrument::realise(flown).map_err(invalid)?;
    flown.sky = design.sky;
    let nominal = crate::sky::focal_plane(design).nominal();
    let wcs = |c: &Config| -> Result<Vec<_>, SequenceError> {
        (0..4)
            .map(|k| crate::sky::array_wcs(c, k))
            .collect::<Result<_, _>>()
            .map_err(invalid)
    };
    let (wd, wt) = (wcs(design)?, wcs(&flown)?);
    let (_, m) = feed::focal_map(&wd[0], &nominal, tangent_deg).map_err(invalid)?;
    let inv = crate::solution::calibration::inverse2(&m)
        .ok_or_else(|| invalid("the design focal-plane map is singular"))?;
    let plane = |s: (f64, f64)| crate::sky::apparent::offset_mas(tangent_deg, s);
    let n = design.instrument.detector_px as f64;
    let mut out = Vec::new();
    for (k, (wd, wt)) in wd.iter().zip(&wt).enumerate() {
        for j in 0..9 {
            for i in 0..9 {
                let (x, y) = ((i as f64 + 0.5) / 9.0 * n, (j as f64 + 0.5) / 9.0 * n);
                let (Some(sky_true), Some(sky_design)) =
                    (wt.pixel_to_sky(x, y), wd.pixel_to_sky(x, y))
                else {
                    continue;
                };
                let (a, b) = (plane(sky_design), plane(sky_true));
                let d = [a.0 - b.0, a.1 - b.1];
                let f = nominal.to_focal_plane(k, x, y);
                out.push(NeededCorrection {
                    array: k,
                    pixel: [x, y],
                    focal_px: [f.0, f.1],
                    needed_px: [inv[0] * d[0] + inv[1] * d[1], inv[2] * d[0] + inv[3] * d[1]],
                });
            }
        }
    }
    Ok(out)
}

/// One row of the precision-against-N table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrecisionRow {
    pub exposures: usize,
    pub bin: BinScore,
    /// The single-exposure accuracy in the bin over the first N exposures ([`single_exposure_errors`]).
    pub single: SingleExposure,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Layout, SipTerm};

    fn poly(t: &[SipTerm], u: f64, v: f64) -> f64 {
        t.iter()
            .map(|t| t.value * u.powi(t.p as i32) * v.powi(t.q as i32))
            .sum()
    }

    /// The correction the scoring holds the solved calibration against includes the distortion beyond the
    /// design (it once took the flown configuration unrealised: the arrays' assembly only, and a zero map for
    /// an instrument whose only deviation is its distortion). Independent check: its length at every grid
    /// point is the length of the added SIP displacement evaluated at the pixel's focal-plane place (a turn
    /// of the arrays does not change a length).
    #[test]
    fn the_needed_correction_holds_the_distortion_beyond_the_design() {
        let mut flown = Config::default();
        flown.focal_plane.layout = Layout::Quad;
        flown.as_built.distortion_px = 0.03;
        // the arrays where designed: the distortion is the only deviation
        flown.focal_plane.array_offsets_px = [[0.0; 2]; 4];
        flown.focal_plane.array_rotation_errors_deg = [0.0; 4];
        let design = crate::instrument::design_of(&flown);
        let tangent = (design.sky.ra_deg, design.sky.dec_deg);
        let built = crate::instrument::realise(&flown).expect("realise");
        let needed = needed_corrections(&design, &flown, tangent).expect("needed");
        assert_eq!(needed.len(), 4 * 81);
        let (mut worst, mut largest) = (0.0f64, 0.0f64);
        for n in &needed {
            let [u, v] = n.focal_px;
            let d = |b: &[SipTerm], a: &[SipTerm]| poly(b, u, v) - poly(a, u, v);
            let dx = d(&built.focal_plane.sip_a, &design.focal_plane.sip_a);
            let dy = d(&built.focal_plane.sip_b, &design.focal_plane.sip_b);
            let expected = dx.hypot(dy);
            let got = n.needed_px[0].hypot(n.needed_px[1]);
            worst = worst.max((got - expected).abs());
            largest = largest.max(expected);
        }
        assert!(largest > 0.02, "the drawn distortion reaches {largest} px");
        assert!(worst < 1e-3 * largest, "off by {worst} px of {largest}");
        // without the deviation nothing is needed
        let none = needed_corrections(&design, &design, tangent).expect("needed");
        let most = none
            .iter()
            .map(|n| n.needed_px[0].hypot(n.needed_px[1]))
            .fold(0.0, f64::max);
        assert!(most < 1e-9, "{most}");
    }
}
