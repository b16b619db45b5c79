//! From a sequence's instrument products to the solution's input: every detection put on the sequence's
//! tangent plane through its array's **design** WCS at the exposure's **planned** pointing (the pipeline
//! knows no better: the true pointing, the arrays as assembled and any distortion beyond the design are what
//! the solution solves), the detections of all exposures identified as sources against the reference
//! catalogue and each other, and each exposure's epoch, parallax factors and focal-plane map.
//!
//! **Identification.** Each array of each exposure is first aligned to the reference catalogue: the offset
//! between its brightest detections and the reference stars around them voted on a 0.25″ grid (the mode is
//! the pointing error, the aberration the design model leaves, the array's assembly offset: tens of
//! arcseconds, larger than the stars' separations in the bulge), then an affine map fitted to the stars
//! matched within 1″ and again within the match radius. Through that map, a detection whose nearest source
//! (a reference star, or one found in an earlier exposure) lies within the match radius is that source —
//! only the nearest detection of a source per exposure; a detection with no source within the radius starts
//! a new one. The map serves identification only: the observations are the design-model places.
//!
//! **Weights.** An observation's σ is its fit's Cramér–Rao bound and a floor added in quadrature (the
//! jitter, flat and PSF errors the bound leaves out; a knob), the larger of its two axes.

use super::{ExposureGeometry, Observation, Reference};
use crate::config::Config;
use crate::numerics::neighbours::{GrowingNeighbours, Neighbours, nearest_of};
use crate::sky::apparent;
use crate::time::Epoch;
use std::collections::HashMap;

/// One detection of an exposure's catalogue (what `exposures/NNNNN.csv` holds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub exposure: usize,
    /// 0 … 3.
    pub array: usize,
    pub x_px: f64,
    pub y_px: f64,
    pub flux_e: f64,
    /// The fit's Cramér–Rao bound, the larger axis, px.
    pub crlb_px: f64,
    pub flags: u32,
}

/// One entry of a reference catalogue: ICRS degrees at `ref_epoch_jyear`, µα*, µδ (mas/yr), ϖ (mas), and
/// the 1σ errors of those five (mas, mas/yr).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkyReference {
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub pmra_mas_per_yr: f64,
    pub pmdec_mas_per_yr: f64,
    pub parallax_mas: f64,
    pub sigma: [f64; 5],
    pub hw: f64,
    pub ref_epoch_jyear: f64,
}

/// What the pipeline knows of an exposure: its design configuration (the planned pointing, the focal plane
/// as designed, its time and orbit) and its mid-exposure instant.
#[derive(Debug, Clone)]
pub struct DesignExposure {
    pub cfg: Config,
    pub mid: Epoch,
    /// Its stare and visit (the plan's).
    pub stare: usize,
    pub visit: usize,
}

/// The feed's knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedOptions {
    /// A detection is a source's when it lies within this of it (after the alignment), mas.
    pub match_radius_mas: f64,
    /// How far the alignment looks for each array's offset, mas.
    pub search_radius_mas: f64,
    /// Added in quadrature to each detection's Cramér–Rao bound, mas.
    pub sigma_floor_mas: f64,
    /// A source needs this many observations to be solved (a reference star's entry counts as one).
    pub min_observations: usize,
}

impl Default for FeedOptions {
    fn default() -> Self {
        Self {
            match_radius_mas: 200.0,
            search_radius_mas: 30_000.0,
            sigma_floor_mas: 1.0,
            min_observations: 2,
        }
    }
}

/// The solution's input and where each part came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Fed {
    pub obs: Vec<Observation>,
    pub exposures: Vec<ExposureGeometry>,
    pub refs: Vec<Reference>,
    pub n_sources: usize,
    /// Per observation, its detection's index in the input.
    pub detection: Vec<usize>,
    /// Per source, its reference entry's index, if any.
    pub reference: Vec<Option<usize>>,
    /// The tangent point (ICRS degrees) and the reference epoch (Julian year, TDB).
    pub tangent_deg: (f64, f64),
    pub ref_epoch_jyear: f64,
    /// Arrays of exposures left out, too few reference stars to align them: (exposure, array, matched).
    pub unaligned: Vec<(usize, usize, usize)>,
    /// Detections left out: flagged, a closer detection took their source, or on an unaligned array.
    pub left_out: usize,
}

/// The feed cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeedError {
    #[error("feed: {field} = {value}: allowed {allowed}")]
    Option {
        field: &'static str,
        value: f64,
        allowed: &'static str,
    },
    #[error("feed: detection {index}: {what}")]
    Detection { index: usize, what: String },
    #[error("feed: exposure {0}: {1}")]
    Design(usize, String),
    #[error("feed: the reference catalogue is empty or has a non-finite entry (row {0})")]
    Reference(usize),
    #[error("feed: no array of any exposure could be aligned to the reference catalogue")]
    NothingAligned,
}

impl FeedOptions {
    fn validate(&self) -> Result<(), FeedError> {
        let check = |field, v: f64, lo: f64, hi: f64, allowed| {
            if (lo..=hi).contains(&v) && v.is_finite() {
                Ok(())
            } else {
                Err(FeedError::Option {
                    field,
                    value: v,
                    allowed,
                })
            }
        };
        check(
            "match_radius_mas",
            self.match_radius_mas,
            1.0,
            5000.0,
            "1 … 5000 mas",
        )?;
        check(
            "search_radius_mas",
            self.search_radius_mas,
            self.match_radius_mas,
            300_000.0,
            "the match radius … 300000 mas",
        )?;
        check(
            "sigma_floor_mas",
            self.sigma_floor_mas,
            0.0,
            1000.0,
            "0 … 1000 mas",
        )?;
        check(
            "min_observations",
            self.min_observations as f64,
            1.0,
            1000.0,
            "1 … 1000",
        )
    }
}

/// Build the solution's input (see the module's documentation).
pub fn feed(
    detections: &[Detection],
    designs: &[DesignExposure],
    references: &[SkyReference],
    tangent_deg: (f64, f64),
    opt: &FeedOptions,
) -> Result<Fed, FeedError> {
    opt.validate()?;
    if let Some(i) = references.iter().position(|r| {
        ![r.ra_deg, r.dec_deg, r.ref_epoch_jyear]
            .iter()
            .all(|v| v.is_finite())
            || !r.sigma.iter().all(|s| s.is_finite() && *s > 0.0)
    }) {
        return Err(FeedError::Reference(i));
    }
    let ref_epoch = references
        .first()
        .map(|r| r.ref_epoch_jyear)
        .ok_or(FeedError::Reference(0))?;
    let (models, exposures) = design_models(designs, tangent_deg, ref_epoch)?;
    let places = detections_on_plane(detections, &models, tangent_deg)?;
    // the references on the plane, their parameters and a k-d tree of them
    let mut refs = Vec::with_capacity(references.len());
    for r in references {
        let p = plane_params(
            tangent_deg,
            r.ra_deg,
            r.dec_deg,
            [r.pmra_mas_per_yr, r.pmdec_mas_per_yr],
            r.parallax_mas,
        );
        refs.push(p);
    }
    let ref_tree = Neighbours::new(&refs.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>());
    // align each (exposure, array) to the references
    let mut groups: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (i, d) in detections.iter().enumerate() {
        groups.entry((d.exposure, d.array)).or_default().push(i);
    }
    let mut keys: Vec<(usize, usize)> = groups.keys().copied().collect();
    keys.sort_unstable();
    let mut maps: HashMap<(usize, usize), [f64; 6]> = HashMap::new();
    let mut unaligned = Vec::new();
    for key in &keys {
        let members = &groups[key];
        let shift = models[key.0].shift_mas;
        match align(members, detections, &places, &refs, &ref_tree, shift, opt) {
            Ok(m) => {
                maps.insert(*key, m);
            }
            Err(found) => unaligned.push((key.0, key.1, found)),
        }
    }
    if maps.is_empty() {
        return Err(FeedError::NothingAligned);
    }
    let ids = identify(detections, designs.len(), &places, &maps, &refs, opt);
    let (obs, detection, kept_ref, n_sources, left_out) =
        observations(detections, &places, &exposures, ids, opt);
    let solved_refs = kept_ref
        .iter()
        .enumerate()
        .filter_map(|(s, r)| {
            r.map(|r| Reference {
                source: s,
                params: refs[r],
                sigma: references[r].sigma,
            })
        })
        .collect();
    Ok(Fed {
        obs,
        exposures,
        refs: solved_refs,
        n_sources,
        detection,
        reference: kept_ref,
        tangent_deg,
        ref_epoch_jyear: ref_epoch,
        unaligned,
        left_out,
    })
}

/// A sky position (ICRS degrees) on the tangent plane at `tangent_deg`, mas.
fn on_plane(tangent_deg: (f64, f64), ra_deg: f64, dec_deg: f64) -> [f64; 2] {
    let (x, y) = apparent::offset_mas(tangent_deg, (ra_deg, dec_deg));
    [x, y]
}

/// An exposure's design model: its arrays' design WCS and focal plane, and the aberration the design
/// leaves at the tangent point.
struct Design {
    wcs: Vec<crate::sky::wcs::ArrayWcs>,
    fp: crate::sky::focal_plane::FocalPlane,
    shift_mas: [f64; 2],
}

/// Each exposure's design model and its geometry (epoch, parallax factors, the map of its arrays onto
/// the plane).
fn design_models(
    designs: &[DesignExposure],
    tangent_deg: (f64, f64),
    ref_epoch: f64,
) -> Result<(Vec<Design>, Vec<ExposureGeometry>), FeedError> {
    let mut models = Vec::with_capacity(designs.len());
    let mut exposures = Vec::with_capacity(designs.len());
    for (e, d) in designs.iter().enumerate() {
        let err = |m: String| FeedError::Design(e, m);
        let wcs = (0..4)
            .map(|k| crate::sky::array_wcs(&d.cfg, k))
            .collect::<Result<Vec<_>, _>>()
            .map_err(err)?;
        let fp = crate::sky::focal_plane(&d.cfg).nominal();
        let (c, to_plane) = focal_map(&wcs[0], &fp, tangent_deg).map_err(err)?;
        let observer = crate::sky::orbit(&d.cfg).map_err(err)?.observer(&d.mid);
        let place = apparent::Place {
            years: d.mid.julian_year_tdb() - ref_epoch,
            observer,
            apparent: true,
        };
        let (ra_a, dec_a) = apparent::direction(
            tangent_deg.0,
            tangent_deg.1,
            &apparent::Motion::default(),
            &place,
        );
        exposures.push(ExposureGeometry {
            t_yr: d.mid.julian_year_tdb() - ref_epoch,
            parallax_factor: apparent::parallax_factors(
                tangent_deg.0,
                tangent_deg.1,
                observer.position_au,
            ),
            centre_mas: c,
            to_plane,
            stare: d.stare,
            visit: d.visit,
        });
        models.push(Design {
            wcs,
            fp,
            shift_mas: on_plane(tangent_deg, ra_a, dec_a),
        });
    }
    Ok((models, exposures))
}

/// Every detection on the plane through its exposure's design model (mas), with its focal-plane place
/// (px); a detection of no exposure or array, or with a position or bound that is not a number, is named.
fn detections_on_plane(
    detections: &[Detection],
    models: &[Design],
    tangent_deg: (f64, f64),
) -> Result<Vec<([f64; 2], [f64; 2])>, FeedError> {
    let mut places = Vec::with_capacity(detections.len());
    for (index, d) in detections.iter().enumerate() {
        let bad = |what: String| FeedError::Detection { index, what };
        if d.exposure >= models.len() {
            return Err(bad(format!(
                "exposure {} (the plan has {})",
                d.exposure,
                models.len()
            )));
        }
        if d.array >= 4 {
            return Err(bad(format!("array {} (allowed 0 … 3)", d.array)));
        }
        // a flagged detection is left out: only its position must be a number
        let bound_ok = d.flags != 0 || (d.crlb_px.is_finite() && d.crlb_px >= 0.0);
        if !(d.x_px.is_finite() && d.y_px.is_finite() && bound_ok) {
            return Err(bad(format!(
                "x_px {}, y_px {}, crlb {}: a position must be finite, an unflagged detection's bound \
                 finite and ≥ 0",
                d.x_px, d.y_px, d.crlb_px
            )));
        }
        let m = &models[d.exposure];
        let p = m.wcs[d.array]
            .pixel_to_sky(d.x_px, d.y_px)
            .map(|(ra, dec)| on_plane(tangent_deg, ra, dec))
            .ok_or_else(|| bad("its pixel has no sky through the design WCS".into()))?;
        let (fx, fy) = m.fp.to_focal_plane(d.array, d.x_px, d.y_px);
        places.push((p, [fx, fy]));
    }
    Ok(places)
}

/// The identification: each detection's source (the references first, then sources found along the way),
/// and how many detections were left out.
struct Identified {
    source_pos: Vec<[f64; 2]>,
    /// Each source's reference, if it is one.
    reference: Vec<Option<usize>>,
    assigned: Vec<Option<usize>>,
    left_out: usize,
}

/// Identify the detections exposure by exposure: each aligned, unflagged detection's nearest source
/// within the match radius (a source keeps its nearest detection; the farther is left out), and a new
/// source where none is near.
fn identify(
    detections: &[Detection],
    n_exposures: usize,
    places: &[([f64; 2], [f64; 2])],
    maps: &HashMap<(usize, usize), [f64; 6]>,
    refs: &[[f64; 5]],
    opt: &FeedOptions,
) -> Identified {
    // the sources' positions live in the tree alone: the references', then each new source's
    let mut reference: Vec<Option<usize>> = (0..refs.len()).map(Some).collect();
    let mut tree = GrowingNeighbours::new(refs.iter().map(|r| (r[0], r[1])).collect());
    let mut assigned: Vec<Option<usize>> = vec![None; detections.len()];
    let mut left_out = 0usize;
    let mut by_exposure: Vec<Vec<usize>> = vec![Vec::new(); n_exposures];
    for (i, d) in detections.iter().enumerate() {
        by_exposure[d.exposure].push(i);
    }
    for members in &by_exposure {
        // each detection's nearest source within the radius; a source keeps its nearest detection
        let mut claim: HashMap<usize, (usize, f64)> = HashMap::new();
        let mut fresh = Vec::new();
        for &i in members {
            let d = &detections[i];
            let Some(m) = maps.get(&(d.exposure, d.array)) else {
                left_out += 1;
                continue;
            };
            if d.flags != 0 {
                left_out += 1;
                continue;
            }
            let p = apply(m, places[i].0);
            let near = tree.near(p[0], p[1], opt.match_radius_mas);
            let at = |s: usize| tree.position(s);
            match nearest_of(near, at, (p[0], p[1]), opt.match_radius_mas) {
                Some((s, d2)) => {
                    if let Some((_, od2)) = claim.get(&s).copied() {
                        // one of the two is left out: the farther
                        left_out += 1;
                        if d2 < od2 {
                            claim.insert(s, (i, d2));
                        }
                    } else {
                        claim.insert(s, (i, d2));
                    }
                }
                None => fresh.push((i, p)),
            }
        }
        for (s, (i, _)) in claim {
            assigned[i] = Some(s);
        }
        for (i, p) in fresh {
            let s = tree.push((p[0], p[1]));
            reference.push(None);
            assigned[i] = Some(s);
        }
    }
    Identified {
        source_pos: tree
            .into_positions()
            .into_iter()
            .map(|(x, y)| [x, y])
            .collect(),
        reference,
        assigned,
        left_out,
    }
}

/// The observations of the sources seen often enough (renumbered), each with its detection's index, and
/// the kept sources' references: (observations, detection of each, reference of each source, sources,
/// detections left out).
#[allow(clippy::type_complexity)]
fn observations(
    detections: &[Detection],
    places: &[([f64; 2], [f64; 2])],
    exposures: &[ExposureGeometry],
    ids: Identified,
    opt: &FeedOptions,
) -> (
    Vec<Observation>,
    Vec<usize>,
    Vec<Option<usize>>,
    usize,
    usize,
) {
    let Identified {
        source_pos,
        reference,
        assigned,
        mut left_out,
    } = ids;
    let mut count = vec![0usize; source_pos.len()];
    for s in assigned.iter().flatten() {
        count[*s] += 1;
    }
    let mut index = vec![usize::MAX; source_pos.len()];
    let mut kept_ref = Vec::new();
    let mut n_sources = 0;
    for (s, c) in count.iter().enumerate() {
        // a reference star's entry counts as one more observation: seen once, it is still solved
        let seen = *c + usize::from(reference[s].is_some() && *c > 0);
        if seen >= opt.min_observations.max(1) && *c > 0 {
            index[s] = n_sources;
            kept_ref.push(reference[s]);
            n_sources += 1;
        }
    }
    let mut obs = Vec::new();
    let mut detection = Vec::new();
    for (i, a) in assigned.iter().enumerate() {
        let Some(s) = a else { continue };
        if index[*s] == usize::MAX {
            left_out += 1;
            continue;
        }
        let d = &detections[i];
        let g = &exposures[d.exposure];
        let mas_per_px = (g.to_plane[0] * g.to_plane[3] - g.to_plane[1] * g.to_plane[2])
            .abs()
            .sqrt();
        let (p, f) = places[i];
        let sigma_mas = (d.crlb_px * mas_per_px)
            .hypot(opt.sigma_floor_mas)
            .max(1e-3);
        obs.push(Observation::new(
            d.exposure, index[*s], p, sigma_mas, d.array, f,
        ));
        detection.push(i);
    }
    (obs, detection, kept_ref, n_sources, left_out)
}

/// A star's parameters on the plane at `tangent_deg`: its place (ICRS degrees) projected, its proper motion
/// (µα*, µδ, mas/yr) as the projected displacement over a year, its parallax (mas) as it is — the
/// solution's [`Params`](super::Params). Over the half-degree of a sequence the plane's axes turn from the
/// local east and north by ≲ 0.3 %, which the projected motion keeps.
pub fn plane_params(
    tangent_deg: (f64, f64),
    ra_deg: f64,
    dec_deg: f64,
    pm_mas_per_yr: [f64; 2],
    parallax_mas: f64,
) -> super::Params {
    let (x0, y0) = apparent::offset_mas(tangent_deg, (ra_deg, dec_deg));
    let cos_dec = dec_deg.to_radians().cos().max(1e-9);
    let (x1, y1) = apparent::offset_mas(
        tangent_deg,
        (
            ra_deg + pm_mas_per_yr[0] / 3.6e6 / cos_dec,
            dec_deg + pm_mas_per_yr[1] / 3.6e6,
        ),
    );
    [x0, y0, x1 - x0, y1 - y0, parallax_mas]
}

/// Where a design model puts the optical axis on the plane at `tangent_deg` (mas), and its map from
/// focal-plane px to the plane's mas there (row-major 2 × 2), from array 0's design WCS `wcs0` (its TAN
/// projection reaches the axis; the distortion has no gradient there).
pub fn focal_map(
    wcs0: &crate::sky::wcs::ArrayWcs,
    fp: &crate::sky::focal_plane::FocalPlane,
    tangent_deg: (f64, f64),
) -> Result<([f64; 2], [f64; 4]), String> {
    let at = |fx: f64, fy: f64| -> Result<[f64; 2], String> {
        let (x, y) = fp.to_array(0, fx, fy);
        let (ra, dec) = wcs0
            .pixel_to_sky(x, y)
            .ok_or("the design WCS has no sky at its axis")?;
        let (u, v) = apparent::offset_mas(tangent_deg, (ra, dec));
        Ok([u, v])
    };
    let (c, px, py) = (at(0.0, 0.0)?, at(100.0, 0.0)?, at(0.0, 100.0)?);
    Ok((
        c,
        [
            (px[0] - c[0]) / 100.0,
            (py[0] - c[0]) / 100.0,
            (px[1] - c[1]) / 100.0,
            (py[1] - c[1]) / 100.0,
        ],
    ))
}

use crate::numerics::affine::{apply, fit as fit_map};

/// Reference stars an alignment needs: fewer leave the array out.
const MIN_ALIGNMENT_STARS: usize = 3;

/// The map that puts one array's detections onto the reference stars (see the module's documentation), or
/// the number of stars matched when too few are.
fn align(
    members: &[usize],
    detections: &[Detection],
    places: &[([f64; 2], [f64; 2])],
    refs: &[[f64; 5]],
    tree: &Neighbours,
    shift_mas: [f64; 2],
    opt: &FeedOptions,
) -> Result<[f64; 6], usize> {
    // the brightest unflagged detections vote for the offset
    let mut bright: Vec<usize> = members
        .iter()
        .copied()
        .filter(|i| detections[*i].flags == 0)
        .collect();
    bright.sort_by(|a, b| detections[*b].flux_e.total_cmp(&detections[*a].flux_e));
    bright.truncate(300);
    let bin = 250.0;
    let mut votes: HashMap<(i64, i64), u32> = HashMap::new();
    let radius = opt.search_radius_mas;
    for &i in &bright {
        let p = places[i].0;
        let guess = [p[0] - shift_mas[0], p[1] - shift_mas[1]];
        // the square of half-side `radius` around the guess: within its circumscribed circle
        for r in tree.near(guess[0], guess[1], radius * std::f64::consts::SQRT_2) {
            let d = [refs[r][0] - guess[0], refs[r][1] - guess[1]];
            if d[0].abs() <= radius && d[1].abs() <= radius {
                *votes
                    .entry(((d[0] / bin).floor() as i64, (d[1] / bin).floor() as i64))
                    .or_default() += 1;
            }
        }
    }
    let Some((&(bx, by), _)) = votes
        .iter()
        .max_by_key(|(k, v)| (**v, std::cmp::Reverse(**k)))
    else {
        return Err(0);
    };
    let offset = [
        (bx as f64 + 0.5) * bin - shift_mas[0],
        (by as f64 + 0.5) * bin - shift_mas[1],
    ];
    let mut map = [offset[0], 1.0, 0.0, offset[1], 0.0, 1.0];
    for radius in [1000.0f64.max(opt.match_radius_mas), opt.match_radius_mas] {
        let pairs: Vec<([f64; 2], [f64; 2])> = bright
            .iter()
            .filter_map(|&i| {
                let o = places[i].0;
                let p = apply(&map, o);
                let near = tree.near(p[0], p[1], radius);
                nearest_of(near, |r| (refs[r][0], refs[r][1]), (p[0], p[1]), radius)
                    .map(|(r, _)| (o, [refs[r][0], refs[r][1]]))
            })
            .collect();
        if pairs.len() < MIN_ALIGNMENT_STARS {
            return Err(pairs.len());
        }
        map = fit_map(&pairs);
    }
    Ok(map)
}

pub use crate::sky::apparent::plane_to_sky;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plane_round_trips_to_the_sky() {
        let t = (266.4, -29.0);
        for (ra, dec) in [(266.4, -29.0), (266.7, -28.8), (266.1, -29.3)] {
            let (x, y) = apparent::offset_mas(t, (ra, dec));
            let (r2, d2) = plane_to_sky(t, x, y);
            assert!(apparent::separation_mas((ra, dec), (r2, d2)) < 1e-6);
        }
    }
}
