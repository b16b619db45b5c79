//! The crowded-field study: one exposure of the focal plane, analysed array by array with the crowded-field
//! ePSF astrometry ([`crate::analysis::crowded`]) and each countermeasure of a plan, then accuracy against
//! magnitude over the four arrays, scored against the truth ([`crate::scoring::crowded`]).
//!
//! Per array, as the instrument would: the array's own image (flat-fielded with its calibration flat), its
//! own ePSF, its own plate model and its own telemetry correction (the rolling readout runs a different
//! way on the sky on each array). Countermeasures that act on the fitted positions apply: `telemetry`,
//! `plate-*@catalogue` (and the `@oracle` upper limit, only when asked). Those that refit single stars
//! (`yzones`, `exact-epsf`) and a stack reference (a stare's) are not offered for a crowded field and are
//! refused by name.

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::Plan;
use crate::analysis::pipeline::offered_in_crowded_field;
use crate::config::Crowding;
use crate::io::instrument::SurveyModel;
use crate::scoring::crowded as report;
use crate::scoring::image::{ScoredImage, score_image_in_frames};
use crate::scoring::undetected::Undetected;
use crate::session::{Source, SourceError, analysis_image};
use crate::simulate::{FocalPlaneExposure, FocalPlaneSimulator};
use std::time::Instant;

pub use crate::analysis::crowded::CrowdedSummary;
use crate::scoring::focal_plane::registration_error_px;
pub use crate::scoring::focal_plane::{ArrayAnalysis, FocalPlaneAnalysis, VECTOR_CELLS};

/// Refuse the countermeasures a crowded field does not offer, by name.
pub fn check_plan(plan: &Plan) -> Result<(), AnalysisError> {
    for c in &plan.countermeasures {
        if !offered_in_crowded_field(c) {
            return Err(AnalysisError::NotInCrowdedField {
                countermeasure: c.to_string(),
            });
        }
    }
    Ok(())
}

/// Analyse one focal-plane exposure under every countermeasure of `plan`, binning accuracy by true Hw at
/// `edges`: each array's image through the pipeline's crowded analysis (`Source::analyse` with crowding on,
/// as `jsim analyze` runs it on the exposure's file) with the products its simulated instrument delivers
/// (calibration flat, design model PSF, telemetry, and the reference catalogue `survey` gives: the forced
/// stars', the `@catalogue` plate models' at their own floor, and the limit of the undetected stars' "beyond
/// the catalogue" share); the truth only scores (and is the `@oracle` control's reference).
pub fn analyse_focal_plane(
    fps: &FocalPlaneSimulator,
    exp: &FocalPlaneExposure,
    plan: &Plan,
    edges: &[f64],
    survey: &SurveyModel,
) -> Result<Vec<FocalPlaneAnalysis>, SourceError> {
    check_plan(plan)?;
    let cfg = &fps.cfg.analysis;
    let t0 = Instant::now();
    let scale = fps.cfg.instrument.plate_scale_mas();
    let mut per_array: Vec<ScoredImage> = Vec::with_capacity(fps.arrays.len());
    // each array's fit noise (read/quantisation floor, flat error), for the undetected stars' shifts
    let mut noise: Vec<(f64, f64)> = Vec::with_capacity(fps.arrays.len());
    for (sim, e) in fps.arrays.iter().zip(&exp.arrays) {
        let img = analysis_image(sim, &e.image);
        noise.push((img.var_floor_e2, img.flat_sigma));
        // the array's own configuration with the study's analysis, crowded by design
        let mut c = sim.cfg.clone();
        c.analysis = cfg.clone();
        c.analysis.crowding = Crowding::On;
        let analysis = Source {
            sim,
            index: exp.index,
            survey: *survey,
        }
        .analyse(&img, Some(&e.truth), &c, plan, &Default::default())?;
        let in_header = crate::scoring::image::catalogue_truth(sim, &e.truth);
        per_array.push(score_image_in_frames(
            &analysis,
            Some(&e.truth),
            in_header.as_deref(),
            scale,
        ));
    }
    let analyse_s = t0.elapsed().as_secs_f64();
    let mut out = Vec::with_capacity(plan.countermeasures.len());
    for cm in &plan.countermeasures {
        let arrays: Vec<ArrayAnalysis> = fps
            .arrays
            .iter()
            .zip(&exp.arrays)
            .zip(&per_array)
            .map(|((sim, e), ia)| ArrayAnalysis {
                index: sim.array.index,
                stars: ia.of(cm).map(|a| a.stars.clone()).unwrap_or_default(),
                truth: e.truth.clone(),
                n_px: e.image.n,
                summary: ia.crowded.clone().unwrap_or_default(),
                n_unmatched: ia.n_unmatched.unwrap_or(0),
                epsf: ia.global.epsf.clone(),
                registration_error_px: registration_error_px(
                    ia.crowded.as_ref().and_then(|c| c.registration.as_ref()),
                    &e.truth,
                    e.image.n,
                    |x, y| {
                        let (ra, dec) = sim.wcs()?.pixel_to_sky(x, y)?;
                        sim.design_wcs()?.sky_to_pixel(ra, dec)
                    },
                ),
            })
            .collect();
        // each array's undetected truth stars, for the shifts their light gives the isolated stars' fits
        let undetected: Vec<Undetected> = arrays
            .iter()
            .zip(&noise)
            .map(|(a, &(floor, flat_sigma))| {
                Undetected::new(
                    a.epsf.clone(),
                    report::ArrayStars::unmatched(&a.stars, &a.truth, a.n_px),
                    (a.n_px * a.n_px) as f64,
                    floor,
                    flat_sigma,
                    cfg.fit_radius_px,
                    cfg.fit_sky,
                    survey.limit_hw,
                )
            })
            .collect();
        let views: Vec<report::ArrayStars<'_>> = arrays
            .iter()
            .zip(&undetected)
            .map(|(a, u)| report::ArrayStars {
                stars: &a.stars,
                truth: &a.truth,
                n_px: a.n_px,
                undetected: Some(u),
            })
            .collect();
        let bins = report::mag_bins(&views, scale, edges);
        out.push(FocalPlaneAnalysis {
            countermeasure: *cm,
            arrays,
            bins,
            analyse_s,
        });
    }
    Ok(out)
}
