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
use crate::simulate::{FocalPlaneExposure, FocalPlaneSimulator};
use std::time::Instant;

pub use crate::analysis::crowded::focal_plane::{
    ArrayAnalysis, CrowdedSummary, FocalPlaneAnalysis, VECTOR_CELLS,
};

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
                reference: None,
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
