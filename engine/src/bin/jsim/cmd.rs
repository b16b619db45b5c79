//! The command implementations (thin: the engine does the work; here we print, write and show progress).

use anyhow::{Context, Result};
use engine::config::Config;
use engine::io::fits::{self, Card, Hdu, Pixels};
use engine::io::{csv, exposure};
use engine::jitter::AceSeries;
use engine::optics::PsfBank;
use engine::optics::spectrum;
use engine::simulate::Simulator;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::time::Instant;

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template(
            "{msg:>12} [{bar:30}] {pos}/{len} {elapsed_precise} (ETA {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

fn parent_dir(path: &Path) -> Result<()> {
    if let Some(p) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        crate::ensure_dir(p)?;
    }
    Ok(())
}

/// `jsim psf`
pub fn psf(cfg: &Config, out: &Path) -> Result<()> {
    parent_dir(out)?;
    let t0 = Instant::now();
    let bank = PsfBank::new(cfg);
    let zone = bank.zone_of(
        cfg.instrument.detector_px as f64 / 2.0,
        cfg.instrument.detector_px as f64 / 2.0,
    );
    let psf = bank.get(cfg.scene.j_minus_h, zone);
    let elapsed = t0.elapsed().as_secs_f64();
    let scale = cfg.instrument.plate_scale_mas();
    let os = psf.oversampling as f64;
    let n = psf.n();
    let grid = spectrum::wavelength_grid(&cfg.band);
    let fwhm = psf.fwhm_px() * scale;
    let cards = vec![
        Card::s("BUNIT", "fraction", "fraction of the total flux per cell"),
        Card::i(
            "OVERSAMP",
            psf.oversampling as i64,
            "cells per detector pixel",
        ),
        Card::f("CDELT1", 1.0 / os, "[pix] cell size"),
        Card::f("CDELT2", 1.0 / os, "[pix] cell size"),
        Card::f(
            "CRPIX1",
            psf.half_cells as f64 + 1.0,
            "optical axis (1-based FITS pixel)",
        ),
        Card::f(
            "CRPIX2",
            psf.half_cells as f64 + 1.0,
            "optical axis (1-based FITS pixel)",
        ),
        Card::f("CELLMAS", scale / os, "[mas] cell size on the sky"),
        Card::f("PLTSCALE", scale, "[mas/pix] detector plate scale"),
        Card::f(
            "LAMMIN",
            grid.first().copied().unwrap_or(0.0),
            "[um] shortest wavelength",
        ),
        Card::f(
            "LAMMAX",
            grid.last().copied().unwrap_or(0.0),
            "[um] longest wavelength",
        ),
        Card::i("NLAMBDA", grid.len() as i64, "wavelengths summed"),
        Card::f(
            "LAMEFF",
            spectrum::effective_wavelength_um(&cfg.band, cfg.scene.j_minus_h),
            "[um] photon-weighted",
        ),
        Card::f("JMINUSH", cfg.scene.j_minus_h, "stellar colour"),
        Card::s(
            "METHOD",
            format!("{:?}", cfg.optics.psf_method),
            "PSF method",
        ),
        Card::i(
            "NPUPIL",
            cfg.optics.pupil_samples as i64,
            "pupil samples across",
        ),
        Card::f("FWHM", fwhm, "[mas] FWHM"),
        Card::f(
            "EE1PX",
            psf.encircled_energy(1.0),
            "encircled energy within 1 pix",
        ),
        Card::f(
            "EE3PX",
            psf.encircled_energy(3.0),
            "encircled energy within 3 pix",
        ),
        Card::f("TABFRAC", psf.sum(), "flux fraction inside this table"),
        Card::s("CONFHASH", cfg.hash_hex(), "config hash"),
        Card::s(
            "ENGINE",
            format!("jsim {}", engine::VERSION),
            "simulator version",
        ),
    ];
    let text = cfg.to_toml();
    fits::write(
        out,
        &[
            Hdu::Image {
                name: "",
                nx: n,
                ny: n,
                pixels: Pixels::F64(&psf.data),
                cards,
            },
            Hdu::Text {
                name: "CONFIG",
                text: &text,
            },
        ],
    )?;
    println!(
        "wrote {} ({n}×{n} cells, {} per pixel, {} wavelengths, FWHM {fwhm:.1} mas, {:.2} % of the flux inside the table) in {elapsed:.2} s",
        out.display(),
        psf.oversampling,
        grid.len(),
        100.0 * psf.sum()
    );
    Ok(())
}

/// `jsim ace`
pub fn ace(cfg: &Config, out: &Path, every: usize) -> Result<()> {
    parent_dir(out)?;
    let t0 = Instant::now();
    let s = AceSeries::generate(cfg, cfg.seed, 0);
    let every = every.max(1);
    let rows: Vec<Vec<csv::Cell>> = (0..s.len())
        .step_by(every)
        .map(|i| {
            vec![
                csv::Cell::F(i as f64 * s.dt_s),
                csv::Cell::F(s.x_mas[i]),
                csv::Cell::F(s.y_mas[i]),
            ]
        })
        .collect();
    csv::write(out, &["t_s", "x_mas", "y_mas"], &rows)?;
    println!(
        "wrote {} ({} samples of {} at {:.3} ms, {} scaling: σ = {:.1}/{:.1} mas) in {:.2} s",
        out.display(),
        rows.len(),
        s.len(),
        s.dt_s * 1e3,
        match s.convention {
            engine::config::SigmaConvention::MedianExposure => "median-exposure",
            engine::config::SigmaConvention::WholeSeries => "whole-series",
        },
        s.achieved_sigma_mas.0,
        s.achieved_sigma_mas.1,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `jsim simulate`
pub fn simulate(cfg: &Config, out: &Path) -> Result<()> {
    crate::ensure_dir(out)?;
    let t0 = Instant::now();
    let sim = Simulator::new(cfg)?;
    if let Some(note) = &sim.gpu_note {
        eprintln!("jsim: {note}");
    }
    sim.jobs()?; // PSFs and kernels now, so the timing below separates set-up from integration
    let setup_s = t0.elapsed().as_secs_f64();
    engine::io::write_atomic(&out.join("config.toml"), cfg.to_toml().as_bytes())?;
    let pb = progress(cfg.fidelity.images as u64, "simulate");
    let mut summary = Vec::new();
    for i in 0..cfg.fidelity.images {
        let exp = sim.exposure(i).with_context(|| format!("image {i}"))?;
        let files = exposure::write_exposure(out, &sim, &exp)?;
        summary.push(serde_json::json!({
            "image": files.image.file_name().map(|n| n.to_string_lossy().to_string()),
            "truth": files.truth_csv.file_name().map(|n| n.to_string_lossy().to_string()),
            "t_start_s": exp.t_start_s,
            "ace_sigma_x_mas": exp.ace.sigma_x_mas,
            "ace_sigma_y_mas": exp.ace.sigma_y_mas,
            "integrate_s": exp.times.integrate_s,
            "detector_s": exp.times.detector_s,
        }));
        pb.inc(1);
    }
    pb.finish_and_clear();
    let run = serde_json::json!({
        "engine": engine::VERSION,
        "config_hash": cfg.hash_hex(),
        "seed": cfg.seed,
        "backend": sim.backend_name(),
        "setup_s": setup_s,
        "total_s": t0.elapsed().as_secs_f64(),
        "images": summary,
    });
    engine::io::write_atomic(
        &out.join("run.json"),
        serde_json::to_string_pretty(&run)?.as_bytes(),
    )?;
    println!(
        "wrote {} images of {} stars to {} ({} ACE, {} readout, Hw {}) on {} in {:.1} s (PSF + kernels {:.1} s)",
        cfg.fidelity.images,
        sim.stars.len(),
        out.display(),
        cfg.ace.case.name(),
        cfg.readout.order.name(),
        cfg.scene.mag_hw,
        sim.backend_name(),
        t0.elapsed().as_secs_f64(),
        setup_s
    );
    Ok(())
}
