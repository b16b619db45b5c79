//! `jsim simulate`: one simulator for every layout. A single array is a focal plane of one array; only the
//! file an exposure is written to depends on the layout — `img_NNN.fits` with `truth_NNN.csv` for the
//! single array, one multi-extension `fp_NNN.fits` for the quad — and the instrument products (flat, model
//! PSF, reference catalogue, telemetry) come from the same writers for both.

use crate::cmd::progress;
use crate::outputs::{Outputs, interrupted};
use anyhow::{Context, Result};
use engine::config::{Config, Layout};
use engine::io::{exposure, focal_plane, instrument};
use engine::session::Session;
use engine::simulate::{FocalPlaneExposure, FocalPlaneSimulator};
use std::path::Path;
use std::time::Instant;

/// `jsim simulate`
pub fn simulate(
    session: &Session,
    cfg: &Config,
    out: &Path,
    survey: &instrument::SurveyModel,
) -> Result<()> {
    let t0 = Instant::now();
    let fps = session.new_focal_plane(cfg)?;
    crate::cmd::say_notes(session);
    for a in &fps.arrays {
        a.jobs()?; // PSFs and kernels now, so the timing below separates set-up from integration
    }
    let setup_s = t0.elapsed().as_secs_f64();
    let mut outputs = Outputs::in_dir(out)?;
    engine::io::write_atomic(
        &outputs.path(engine::io::products::files::CONFIG_TOML),
        cfg.to_toml().as_bytes(),
    )?;
    outputs.path(instrument::FLAT_NAME);
    instrument::write_calibration_flat(out, &fps)?;
    outputs.path(instrument::REFCAT_NAME);
    instrument::write_reference_catalogue(out, &fps, survey)?;
    outputs.path(instrument::MODEL_PSF_NAME);
    instrument::write_model_psf(out, &fps)?;
    let pb = progress(cfg.fidelity.images as u64, "simulate");
    let mut summary = Vec::new();
    for i in 0..cfg.fidelity.images {
        interrupted()?;
        let t = Instant::now();
        let exp = fps.exposure(i).with_context(|| format!("image {i}"))?;
        let sim_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut record = write_exposure(out, &fps, &exp, &mut outputs)?;
        // the telescope's attitude as the spacecraft records it (the default quality; one record for all
        // arrays, each applies it turned by its ROTATION)
        if let Some(first) = fps.arrays.first() {
            outputs.add(&out.join(instrument::telemetry_name(i)));
            instrument::write_telemetry(
                out,
                first,
                i,
                &engine::analysis::countermeasures::TelemetryQuality::DEFAULT,
            )?;
        }
        if cfg.focal_plane.layout == Layout::Quad {
            record["simulate_s"] = sim_s.into();
            record["write_s"] = t.elapsed().as_secs_f64().into();
        }
        summary.push(record);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let backend = fps
        .arrays
        .first()
        .map(|a| a.backend_name())
        .unwrap_or_default();
    let mut run = serde_json::json!({
        "engine": engine::VERSION,
        "config_hash": cfg.hash_hex(),
        "seed": cfg.seed,
        "backend": backend,
    });
    if cfg.focal_plane.layout == Layout::Quad {
        let counts = fps.counts.map(|c| {
            serde_json::json!({
                "catalogue": c.catalogue, "duplicates": c.duplicates, "photosensitive": c.photosensitive,
                "border": c.border, "gap": c.gap, "off": c.off,
            })
        });
        run["arrays"] = fps.arrays.len().into();
        run["stars_simulated"] = fps.star_count().into();
        run["placement"] = counts.into();
    }
    run["setup_s"] = setup_s.into();
    run["total_s"] = t0.elapsed().as_secs_f64().into();
    run["images"] = summary.into();
    engine::io::write_atomic(
        &outputs.path(engine::io::products::files::RUN_JSON),
        serde_json::to_string_pretty(&run)?.as_bytes(),
    )?;
    outputs.keep();
    println!("{}", said(cfg, &fps, out, &backend, t0, setup_s));
    if let Some(line) = cfg.as_built.describe() {
        println!("{line}");
    }
    Ok(())
}

/// Write exposure `exp` in the layout's file form, declaring its files to `outputs`: its record for
/// `run.json`.
fn write_exposure(
    out: &Path,
    fps: &FocalPlaneSimulator,
    exp: &FocalPlaneExposure,
    outputs: &mut Outputs,
) -> Result<serde_json::Value> {
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().to_string());
    match (
        fps.cfg.focal_plane.layout,
        fps.arrays.first(),
        exp.arrays.first(),
    ) {
        (Layout::Single, Some(sim), Some(e)) => {
            outputs.add(&out.join(exposure::image_name(exp.index)));
            outputs.add(&out.join(exposure::truth_name(exp.index)));
            let files = exposure::write_exposure(out, sim, e)?;
            Ok(serde_json::json!({
                "image": name(&files.image),
                "truth": name(&files.truth_csv),
                "t_start_s": e.t_start_s,
                "ace_sigma_x_mas": e.ace.sigma_x_mas,
                "ace_sigma_y_mas": e.ace.sigma_y_mas,
                "integrate_s": e.times.integrate_s,
                "detector_s": e.times.detector_s,
            }))
        }
        _ => {
            outputs.add(&out.join(focal_plane::focal_plane_name(exp.index)));
            let file = focal_plane::write_focal_plane_exposure(out, fps, exp)?;
            Ok(serde_json::json!({
                "image": name(&file),
                "t_start_s": exp.arrays.first().map(|e| e.t_start_s),
                "stars_in_truth": exp.arrays.iter().map(|e| e.truth.len()).sum::<usize>(),
            }))
        }
    }
}

/// The closing line: what was written where, and in how long.
fn said(
    cfg: &Config,
    fps: &FocalPlaneSimulator,
    out: &Path,
    backend: &str,
    t0: Instant,
    setup_s: f64,
) -> String {
    let total_s = t0.elapsed().as_secs_f64();
    if cfg.focal_plane.layout == Layout::Single {
        return format!(
            "wrote {} images of {} stars to {} ({} ACE, {} readout, Hw {}) on {backend} in {total_s:.1} s (PSF + kernels {setup_s:.1} s)",
            cfg.fidelity.images,
            fps.star_count(),
            out.display(),
            cfg.ace.case.name(),
            cfg.readout.order.name(),
            cfg.scene.mag_hw,
        );
    }
    let placed = match fps.counts {
        Some(c) => format!(
            "; of {} stars {} on photosensitive pixels, {} on borders, {} in gaps, {} off the focal plane, {} duplicates",
            c.catalogue, c.photosensitive, c.border, c.gap, c.off, c.duplicates
        ),
        None => String::new(),
    };
    format!(
        "wrote {} focal-plane exposures of {} arrays to {} ({} ACE, {} readout) on {backend} in {total_s:.1} s (PSF + kernels {setup_s:.1} s){placed}",
        cfg.fidelity.images,
        fps.arrays.len(),
        out.display(),
        cfg.ace.case.name(),
        cfg.readout.order.name(),
    )
}
