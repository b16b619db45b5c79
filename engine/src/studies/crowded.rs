//! The crowded-field study: one exposure of the focal plane, analysed array by array with the crowded-field
//! ePSF astrometry ([`crate::analysis::crowded`]) and each countermeasure of a plan, then accuracy against
//! magnitude over the four arrays ([`crate::analysis::crowded::report`]).
//!
//! Per array, as the instrument would: the array's own image (flat-fielded with its calibration flat), its
//! own ePSF, its own plate model and its own telemetry correction (the rolling readout runs a different
//! way on the sky on each array). Countermeasures that act on the fitted positions apply: `telemetry`,
//! `plate-*@catalogue` (and the `@oracle` upper limit, only when asked); a stack-referenced plate model
//! corrects nothing in a single exposure. Those that refit single stars (`yzones`, `exact-epsf`) are not
//! offered for a crowded field and are refused by name.

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::{self, Context, Countermeasure, Plan};
use crate::analysis::crowded::{self, Crowded, report};
use crate::analysis::image::AnalysisImage;
use crate::analysis::pipeline::{Source, build_options, exact_epsf};
use crate::analysis::report::{StarResult, star_results};
use crate::simulate::{FocalPlaneExposure, FocalPlaneSimulator, TruthRow};
use std::time::Instant;

/// One array's crowded analysis under one countermeasure.
#[derive(Debug, Clone)]
pub struct ArrayAnalysis {
    /// The array's index (0 … 3).
    pub index: usize,
    pub stars: Vec<StarResult>,
    pub truth: Vec<TruthRow>,
    pub n_px: usize,
    /// What the crowded analysis found and how (the fits are in `stars`).
    pub summary: CrowdedSummary,
}

/// Cells per array side of the binned vector maps.
pub const VECTOR_CELLS: usize = 12;

impl ArrayAnalysis {
    /// The array's deviation map in focal-plane axes (its sky layout): per cell of [`VECTOR_CELLS`]² with
    /// at least 3 used stars, the cell's centre and the inverse-variance (bound⁻²) weighted mean fitted −
    /// true of its stars (mas), the array's own median offset removed and the vector turned with the array.
    pub fn binned_vectors(
        &self,
        plane: &crate::sky::focal_plane::FocalPlane,
        scale_mas: f64,
    ) -> Vec<(f64, f64, f64, f64)> {
        use crate::numerics::stats;
        let used: Vec<_> = self.stars.iter().filter(|s| s.is_used()).collect();
        let ox = stats::median(&used.iter().map(|s| s.dx_px).collect::<Vec<_>>());
        let oy = stats::median(&used.iter().map(|s| s.dy_px).collect::<Vec<_>>());
        let cell = self.n_px as f64 / VECTOR_CELLS as f64;
        // (Σ w dx, Σ w dy, Σ w, n) per cell
        let mut acc = vec![(0.0, 0.0, 0.0, 0usize); VECTOR_CELLS * VECTOR_CELLS];
        for s in &used {
            let var = (s.crlb_x_px.powi(2) + s.crlb_y_px.powi(2)) / 2.0;
            if !(var > 0.0 && var.is_finite()) {
                continue;
            }
            let (cx, cy) = (
                ((s.x / cell).max(0.0) as usize).min(VECTOR_CELLS - 1),
                ((s.y / cell).max(0.0) as usize).min(VECTOR_CELLS - 1),
            );
            let e = &mut acc[cy * VECTOR_CELLS + cx];
            e.0 += (s.dx_px - ox) / var;
            e.1 += (s.dy_px - oy) / var;
            e.2 += 1.0 / var;
            e.3 += 1;
        }
        acc.iter()
            .enumerate()
            .filter(|(_, e)| e.3 >= 3)
            .map(|(i, e)| {
                let (x, y) = (
                    ((i % VECTOR_CELLS) as f64 + 0.5) * cell,
                    ((i / VECTOR_CELLS) as f64 + 0.5) * cell,
                );
                let (dx, dy) = (e.0 / e.2, e.1 / e.2);
                let (fx, fy) = plane.to_focal_plane(self.index, x, y);
                // turned with the array: the difference of the mapped end points (the map is affine)
                let (gx, gy) = plane.to_focal_plane(self.index, x + dx, y + dy);
                (fx, fy, (gx - fx) * scale_mas, (gy - fy) * scale_mas)
            })
            .collect()
    }
}

/// The crowded analysis of an array without its fits.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CrowdedSummary {
    pub n_first: usize,
    pub n_residual: usize,
    pub epsf_stars: usize,
    pub epsf_iterations: usize,
    pub fallback: String,
    pub n_groups: usize,
    pub largest_group: usize,
    /// Reported stars matched to no truth star: noise peaks, light from stars off the array's edge, or
    /// duplicates (`None` without a truth).
    pub n_unmatched: Option<usize>,
    /// Wall-clock seconds of the array's crowded analysis (detection, ePSF, grouped fits).
    pub analyse_s: f64,
}

impl CrowdedSummary {
    fn of(c: &Crowded, stars: &[StarResult], analyse_s: f64) -> Self {
        Self {
            n_first: c.n_first,
            n_residual: c.n_residual,
            epsf_stars: c.epsf_stars,
            epsf_iterations: c.epsf_iterations,
            fallback: c.fallback.clone(),
            n_groups: c.n_groups,
            largest_group: c.largest_group,
            n_unmatched: Some(stars.iter().filter(|s| s.truth.is_none()).count()),
            analyse_s,
        }
    }
}

/// The focal plane under one countermeasure.
#[derive(Debug, Clone)]
pub struct FocalPlaneAnalysis {
    pub countermeasure: Countermeasure,
    pub arrays: Vec<ArrayAnalysis>,
    pub bins: Vec<report::MagBin>,
    /// Wall-clock seconds of the whole analysis (all arrays, this countermeasure included).
    pub analyse_s: f64,
}

/// Refuse the countermeasures a crowded field does not offer, by name.
pub fn check_plan(plan: &Plan) -> Result<(), AnalysisError> {
    for c in &plan.countermeasures {
        if matches!(c, Countermeasure::YZones { .. } | Countermeasure::ExactEpsf) {
            return Err(AnalysisError::NotInCrowdedField {
                countermeasure: c.to_string(),
            });
        }
    }
    Ok(())
}

/// Analyse one focal-plane exposure under every countermeasure of `plan`, binning accuracy by true Hw at
/// `edges`. The crowded analysis of each array runs once; the countermeasures correct its positions.
pub fn analyse_focal_plane(
    fps: &FocalPlaneSimulator,
    exp: &FocalPlaneExposure,
    plan: &Plan,
    edges: &[f64],
) -> Result<Vec<FocalPlaneAnalysis>, AnalysisError> {
    check_plan(plan)?;
    let cfg = &fps.cfg.analysis;
    let t0 = Instant::now();
    let mut plain: Vec<(AnalysisImage, Crowded, Vec<StarResult>, f64)> = Vec::new();
    for (sim, e) in fps.arrays.iter().zip(&exp.arrays) {
        let t = Instant::now();
        let img = AnalysisImage::of_exposure(sim, &e.image);
        let model = exact_epsf(&*sim.optical_kernel()?, cfg.epsf_radius_px);
        let c = crowded::analyse(&img, cfg, Some(&model));
        let matches = report::match_catalogue(&c.fits, &e.truth);
        let stars = star_results(&c.fits, &matches, Some(&e.truth));
        plain.push((img, c, stars, t.elapsed().as_secs_f64()));
    }
    let base_s = t0.elapsed().as_secs_f64();
    let scale = fps.cfg.instrument.plate_scale_mas();
    let mut out = Vec::with_capacity(plan.countermeasures.len());
    for cm in &plan.countermeasures {
        let t = Instant::now();
        let mut arrays = Vec::with_capacity(fps.arrays.len());
        for ((sim, e), (img, c, stars, s)) in fps.arrays.iter().zip(&exp.arrays).zip(&plain) {
            let summary = CrowdedSummary::of(c, stars, *s);
            let mut stars = stars.clone();
            let source = Source {
                sim,
                index: exp.index,
            };
            let telemetry = match cm {
                Countermeasure::Telemetry(q) => source.telemetry(q, cfg)?,
                _ => None,
            };
            let build = build_options(cfg);
            let ctx = Context {
                img,
                starts: &[],
                usable: &[],
                build: &build,
                global: &c.epsf,
                truth: Some(&e.truth),
                default_zones: cfg.epsf_zones.max(2),
                telemetry: telemetry.as_ref(),
                seed: fps.cfg.seed ^ sim.array.index as u64,
            };
            countermeasures::apply(cm, &ctx, &mut stars)?;
            arrays.push(ArrayAnalysis {
                index: sim.array.index,
                stars,
                truth: e.truth.clone(),
                n_px: e.image.n,
                summary: summary.clone(),
            });
        }
        let views: Vec<report::ArrayStars<'_>> = arrays
            .iter()
            .map(|a| report::ArrayStars {
                stars: &a.stars,
                truth: &a.truth,
                n_px: a.n_px,
            })
            .collect();
        let bins = report::mag_bins(&views, scale, edges);
        out.push(FocalPlaneAnalysis {
            countermeasure: *cm,
            arrays,
            bins,
            analyse_s: base_s + t.elapsed().as_secs_f64(),
        });
    }
    Ok(out)
}
