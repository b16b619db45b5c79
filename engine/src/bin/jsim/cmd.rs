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

/// Options of the analysis commands.
pub struct AnalyzeArgs {
    pub image: std::path::PathBuf,
    pub truth: Option<std::path::PathBuf>,
    pub zones: Option<usize>,
    pub countermeasure: String,
    pub telemetry: engine::studies::experiment::TelemetrySpec,
    pub reference_error_mas: f64,
    pub out: std::path::PathBuf,
}

/// The configuration a FITS image was made with (its CONFIG extension), else `fallback`.
fn image_config(path: &Path, fallback: &Config) -> Config {
    fits::read_text(path, "CONFIG")
        .ok()
        .and_then(|t| Config::from_toml_str(&t).ok())
        .unwrap_or_else(|| fallback.clone())
}

/// Write the deviation vector map (CSV + PNG) of star results.
pub fn write_vectors(
    dir: &Path,
    stem: &str,
    stars: &[engine::analysis::astrometry::StarResult],
    scale: f64,
    extent: f64,
    title: &str,
) -> Result<()> {
    use engine::analysis::epsf::fit::flags;
    // show the fit-response prediction where it was computed (experiment), else the mean-jitter one (truth)
    let fit_pred = stars
        .iter()
        .any(|s| s.predicted_fit_dx_px != 0.0 || s.predicted_fit_dy_px != 0.0);
    let owned: Vec<engine::analysis::astrometry::StarResult> = stars
        .iter()
        .map(|s| {
            let mut s = *s;
            if fit_pred {
                s.predicted_dx_px = s.predicted_fit_dx_px;
                s.predicted_dy_px = s.predicted_fit_dy_px;
            }
            s
        })
        .collect();
    let used: Vec<&engine::analysis::astrometry::StarResult> = owned
        .iter()
        .filter(|s| s.truth.is_some() && s.flags & flags::REJECT == 0 && s.dx_px.is_finite())
        .collect();
    let (mx, my) = if used.is_empty() {
        (0.0, 0.0)
    } else {
        (
            used.iter().map(|s| s.dx_px).sum::<f64>() / used.len() as f64,
            used.iter().map(|s| s.dy_px).sum::<f64>() / used.len() as f64,
        )
    };
    let (pmx, pmy) = if used.is_empty() {
        (0.0, 0.0)
    } else {
        (
            used.iter().map(|s| s.predicted_dx_px).sum::<f64>() / used.len() as f64,
            used.iter().map(|s| s.predicted_dy_px).sum::<f64>() / used.len() as f64,
        )
    };
    let rows: Vec<Vec<csv::Cell>> = used
        .iter()
        .map(|s| {
            vec![
                csv::Cell::F(s.x),
                csv::Cell::F(s.y),
                csv::Cell::F((s.dx_px - mx) * scale),
                csv::Cell::F((s.dy_px - my) * scale),
                csv::Cell::F((s.predicted_dx_px - pmx) * scale),
                csv::Cell::F((s.predicted_dy_px - pmy) * scale),
            ]
        })
        .collect();
    csv::write(
        &dir.join(format!("{stem}.csv")),
        &[
            "x",
            "y",
            "dx_mas",
            "dy_mas",
            "predicted_dx_mas",
            "predicted_dy_mas",
        ],
        &rows,
    )?;
    let measured: Vec<(f64, f64, f64, f64)> = used
        .iter()
        .map(|s| (s.x, s.y, (s.dx_px - mx) * scale, (s.dy_px - my) * scale))
        .collect();
    let predicted: Vec<(f64, f64, f64, f64)> = used
        .iter()
        .map(|s| {
            (
                s.x,
                s.y,
                (s.predicted_dx_px - pmx) * scale,
                (s.predicted_dy_px - pmy) * scale,
            )
        })
        .collect();
    let mut sets = vec![("fitted − true (mean removed)".to_string(), measured)];
    if predicted.iter().any(|p| p.2 != 0.0 || p.3 != 0.0) {
        sets.push(("ACE-predicted displacement".to_string(), predicted));
    }
    let rms = (rows
        .iter()
        .map(|r| {
            if let (csv::Cell::F(a), csv::Cell::F(b)) = (&r[2], &r[3]) {
                a * a + b * b
            } else {
                0.0
            }
        })
        .sum::<f64>()
        / rows.len().max(1) as f64)
        .sqrt();
    let reference = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0]
        .into_iter()
        .find(|r| *r >= rms)
        .unwrap_or(100.0);
    engine::io::plot::vector_map(
        &dir.join(format!("{stem}.png")),
        title,
        &sets,
        extent,
        reference,
        60.0,
    )?;
    Ok(())
}

/// `jsim analyze`
pub fn analyze(cfg_fallback: &Config, a: &AnalyzeArgs) -> Result<()> {
    use engine::analysis::astrometry::{self, AnalysisImage, Options};
    use engine::analysis::countermeasures::{Countermeasure, Telemetry};
    crate::ensure_dir(&a.out)?;
    let t0 = Instant::now();
    let read = fits::read_image(&a.image)?;
    let cfg = image_config(&a.image, cfg_fallback);
    let scale =
        fits::read_f64_key(&a.image, "PLTSCALE").unwrap_or(cfg.instrument.plate_scale_mas());
    let truth = match &a.truth {
        Some(p) => Some(exposure::read_truth(p)?),
        None => exposure::read_truth(&a.image).ok(),
    };
    let img = AnalysisImage::from_fits(&read, scale)?;
    let mut opts = Options::new(&cfg_fallback.analysis);
    if let Some(z) = a.zones {
        opts.cfg.epsf_zones = z;
    }
    opts.countermeasure = if a.countermeasure == "telemetry" {
        if cfg.ace.case != engine::config::AceCase::Realistic {
            Countermeasure::None
        } else {
            // the image's own configuration gives back its ACE series, PSF and noise
            let mut c = cfg.clone();
            c.fidelity.backend = engine::config::Backend::Cpu;
            c.fidelity.images = 1;
            let sim = Simulator::new(&c)?;
            let series = sim
                .series()
                .context("the image's configuration has no ACE series")?;
            let t_start = fits::read_f64_key(&a.image, "TSTART").unwrap_or(0.0);
            let tel = Telemetry::from_series(
                series,
                sim.timing,
                t_start,
                scale,
                a.telemetry.noise_mas,
                a.telemetry.rate_hz,
                a.telemetry.latency_s,
                cfg.seed,
                &*sim.optical_kernel()?,
                &sim.fit_noise(),
            )?;
            Countermeasure::Telemetry(std::sync::Arc::new(tel))
        }
    } else {
        Countermeasure::parse(&a.countermeasure, opts.cfg.epsf_zones.max(2))?
            .with_reference_error(a.reference_error_mas, cfg.seed)
    };
    let res = astrometry::analyze(&img, truth.as_deref(), &opts)?;
    // catalogue
    let rows: Vec<Vec<csv::Cell>> = res
        .stars
        .iter()
        .map(|s| {
            vec![
                csv::Cell::F(s.x),
                csv::Cell::F(s.y),
                csv::Cell::F(s.flux_e),
                csv::Cell::F(s.sky_e),
                csv::Cell::F(s.crlb_x_px * scale),
                csv::Cell::F(s.crlb_y_px * scale),
                csv::Cell::I(s.flags as i64),
                csv::Cell::I(s.truth.map(|t| t as i64).unwrap_or(-1)),
                csv::Cell::F(s.dx_px * scale),
                csv::Cell::F(s.dy_px * scale),
            ]
        })
        .collect();
    csv::write(
        &a.out.join("catalogue.csv"),
        &[
            "x",
            "y",
            "flux_e",
            "sky_e",
            "crlb_x_mas",
            "crlb_y_mas",
            "flags",
            "truth_id",
            "dx_mas",
            "dy_mas",
        ],
        &rows,
    )?;
    let e = &res.epsf;
    let n = e.n();
    fits::write(
        &a.out.join("epsf.fits"),
        &[Hdu::Image {
            name: "",
            nx: n,
            ny: n,
            pixels: Pixels::F64(&e.data),
            cards: vec![
                Card::i("OVERSAMP", e.oversampling as i64, "ePSF nodes per pixel"),
                Card::f("CRPIX1", e.half_nodes as f64 + 1.0, "origin (1-based)"),
                Card::f("CRPIX2", e.half_nodes as f64 + 1.0, "origin (1-based)"),
                Card::s("NORM", "sum = oversampling^2", "a star's pixels sum to 1"),
                Card::i(
                    "ITER",
                    res.report.epsf_iterations as i64,
                    "builder iterations",
                ),
            ],
        }],
    )?;
    let summary = serde_json::json!({
        "image": a.image.display().to_string(),
        "plate_scale_mas": scale,
        "countermeasure": res.report.countermeasure,
        "report": res.report,
        "seconds": t0.elapsed().as_secs_f64(),
    });
    engine::io::write_atomic(
        &a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    if truth.is_some() {
        write_vectors(
            &a.out,
            "vectors",
            &res.stars,
            scale,
            read.nx as f64,
            &format!(
                "{} — deviations ({})",
                a.image.display(),
                res.report.countermeasure
            ),
        )?;
    }
    let r = &res.report;
    println!(
        "{}: {} stars detected, {} used; accuracy {:.2} mas (x {:.2}, y {:.2}), median CRLB {:.2} mas (ratio {:.2}), phase bias {:.2}/{:.2} mas [{}] in {:.2} s",
        a.image.display(),
        r.n_detected,
        r.n_used,
        r.accuracy_mas,
        r.accuracy_x_mas,
        r.accuracy_y_mas,
        r.crlb_median_mas,
        r.accuracy_over_crlb,
        r.phase_bias_x_mas,
        r.phase_bias_y_mas,
        r.countermeasure,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Options of `jsim experiment`.
pub struct ExperimentArgs {
    pub aces: Vec<engine::config::AceCase>,
    pub readouts: Vec<engine::config::ReadoutOrder>,
    pub mags: Vec<f64>,
    pub plan: engine::studies::experiment::Plan,
    pub out: std::path::PathBuf,
}

/// `jsim experiment`
pub fn experiment(base: &Config, a: &ExperimentArgs) -> Result<()> {
    use engine::studies::experiment::{self, CSV_HEADER};
    crate::ensure_dir(&a.out)?;
    let t0 = Instant::now();
    let datasets = experiment::grid(base, &a.aces, &a.readouts, &a.mags);
    let total = (datasets.len() * base.fidelity.images) as u64;
    let pb = progress(total, "experiment");
    let bank = std::sync::Arc::new(PsfBank::new(base));
    let gpu = match base.fidelity.backend {
        engine::config::Backend::Cpu => None,
        b => match engine::integrate::gpu::GpuIntegrator::shared(b == engine::config::Backend::Gpu)
        {
            Ok(g) => Some(g),
            Err(e) => {
                pb.suspend(|| eprintln!("jsim: {e}"));
                None
            }
        },
    };
    let mut rows = Vec::new();
    let mut image_rows: Vec<Vec<csv::Cell>> = Vec::new();
    for cfg in &datasets {
        pb.set_message(format!(
            "{} {} {}",
            cfg.ace.case.name(),
            cfg.readout.order.name(),
            cfg.scene.mag_hw
        ));
        let (r, images) =
            experiment::run_dataset(cfg, &a.plan, Some(bank.clone()), gpu.clone(), &mut |_| {
                pb.inc(1)
            })?;
        for im in &images {
            for m in &im.measured {
                image_rows.push(vec![
                    csv::Cell::S(cfg.ace.case.name().into()),
                    csv::Cell::S(cfg.readout.order.name().into()),
                    csv::Cell::S(m.countermeasure.clone()),
                    csv::Cell::F(cfg.scene.mag_hw),
                    csv::Cell::I(im.index as i64),
                    csv::Cell::F(m.report.accuracy_mas),
                    csv::Cell::F(m.report.accuracy_x_mas),
                    csv::Cell::F(m.report.accuracy_y_mas),
                    csv::Cell::F(m.report.crlb_median_mas),
                    csv::Cell::F(m.report.phase_bias_x_mas.max(m.report.phase_bias_y_mas)),
                    csv::Cell::F(m.report.predicted_rms_mas),
                    csv::Cell::F(m.report.predicted_corr_x),
                    csv::Cell::F(m.report.predicted_corr_y),
                    csv::Cell::F(m.report.predicted_slope_x),
                    csv::Cell::F(m.report.predicted_slope_y),
                    csv::Cell::F(m.report.response_corr_x),
                    csv::Cell::F(m.report.response_corr_y),
                    csv::Cell::F(m.report.response_slope_x),
                    csv::Cell::F(m.report.response_slope_y),
                    csv::Cell::I(m.report.n_used as i64),
                    csv::Cell::I(m.report.dof_absorbed as i64),
                    csv::Cell::F(im.ace_sigma_mas),
                    csv::Cell::F(im.ace_drift_mas),
                    csv::Cell::F(im.simulate_s),
                    csv::Cell::F(im.analyse_s),
                ]);
            }
        }
        if let Some(stars) = images.first().and_then(|im| im.stars.as_ref())
            && cfg.scene.mag_hw == a.mags[0]
        {
            let stem = format!(
                "vectors_{}_{}_{}",
                cfg.ace.case.name(),
                cfg.readout.order.name(),
                cfg.scene.mag_hw
            );
            let title = format!(
                "Hw {} {} ACE, {} readout, image 0",
                cfg.scene.mag_hw,
                cfg.ace.case.name(),
                cfg.readout.order.name()
            );
            pb.suspend(|| {
                write_vectors(
                    &a.out,
                    &stem,
                    stars,
                    cfg.instrument.plate_scale_mas(),
                    cfg.instrument.detector_px as f64,
                    &title,
                )
            })?;
        }
        rows.extend(r);
        // keep the CSV current so an interrupted experiment still leaves its finished datasets
        write_experiment_csv(&a.out, &rows)?;
    }
    pb.finish_and_clear();
    csv::write(
        &a.out.join("images.csv"),
        &[
            "ace",
            "readout",
            "countermeasure",
            "mag",
            "image",
            "accuracy_mas",
            "accuracy_x_mas",
            "accuracy_y_mas",
            "crlb_mas",
            "phase_bias_mas",
            "predicted_rms_mas",
            "pred_corr_x",
            "pred_corr_y",
            "pred_slope_x",
            "pred_slope_y",
            "response_corr_x",
            "response_corr_y",
            "response_slope_x",
            "response_slope_y",
            "n_used",
            "dof_absorbed",
            "ace_sigma_mas",
            "ace_drift_mas",
            "simulate_s",
            "analyse_s",
        ],
        &image_rows,
    )?;
    plot_experiment(&a.out, &rows)?;
    println!("{}", render_table(&rows));
    println!(
        "wrote {}/experiment.csv, images.csv, accuracy.png in {:.1} s",
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    let _ = CSV_HEADER;
    Ok(())
}

fn write_experiment_csv(dir: &Path, rows: &[engine::studies::experiment::Row]) -> Result<()> {
    let cells: Vec<Vec<csv::Cell>> = rows
        .iter()
        .map(|r| {
            vec![
                csv::Cell::S(r.ace.clone()),
                csv::Cell::S(r.readout.clone()),
                csv::Cell::S(r.countermeasure.clone()),
                csv::Cell::F(r.mag),
                csv::Cell::F(r.accuracy_mas),
                csv::Cell::F(r.sem_mas),
                csv::Cell::F(r.crlb_mas),
                csv::Cell::F(r.predicted_mas),
                csv::Cell::I(r.n_images as i64),
                csv::Cell::F(r.time_s),
            ]
        })
        .collect();
    csv::write(
        &dir.join("experiment.csv"),
        &engine::studies::experiment::CSV_HEADER,
        &cells,
    )?;
    Ok(())
}

fn render_table(rows: &[engine::studies::experiment::Row]) -> String {
    let mut s = format!(
        "{:<10} {:<13} {:<14} {:>5} {:>10} {:>7} {:>8} {:>10}\n",
        "ace", "readout", "countermeasure", "mag", "acc [mas]", "±sem", "CRLB", "predicted"
    );
    for r in rows {
        s.push_str(&format!(
            "{:<10} {:<13} {:<14} {:>5.1} {:>10.2} {:>7.2} {:>8.2} {:>10.2}\n",
            r.ace,
            r.readout,
            r.countermeasure,
            r.mag,
            r.accuracy_mas,
            r.sem_mas,
            r.crlb_mas,
            r.predicted_mas
        ));
    }
    s
}

fn plot_experiment(dir: &Path, rows: &[engine::studies::experiment::Row]) -> Result<()> {
    use engine::io::plot::{Scale, Series, line_plot};
    // one curve per (readout, countermeasure) of the realistic ACE; the static ACE cases only with the plain
    // analysis (their countermeasures change nothing and would hide the curves that matter); the exact-ePSF
    // control is in the CSV
    let mut keys: Vec<(String, String, String)> = Vec::new();
    for r in rows {
        let shown = r.countermeasure != "exact-epsf"
            && (r.ace == "realistic" || r.countermeasure == "none");
        let k = (r.ace.clone(), r.readout.clone(), r.countermeasure.clone());
        if shown && !keys.contains(&k) {
            keys.push(k);
        }
    }
    let mut series: Vec<Series> = keys
        .iter()
        .map(|(a, ro, c)| {
            let pts: Vec<&engine::studies::experiment::Row> = rows
                .iter()
                .filter(|r| &r.ace == a && &r.readout == ro && &r.countermeasure == c)
                .collect();
            let label = if a == "realistic" {
                format!("{a} ACE, {ro}, {c}")
            } else {
                format!("{a} ACE, {c}")
            };
            Series {
                label,
                x: pts.iter().map(|r| r.mag).collect(),
                y: pts.iter().map(|r| r.accuracy_mas).collect(),
                yerr: Some(pts.iter().map(|r| r.sem_mas).collect()),
            }
        })
        .collect();
    // the bound of the plain analysis, once per ACE case
    for a in ["gaussian", "realistic"] {
        let pts: Vec<&engine::studies::experiment::Row> = rows
            .iter()
            .filter(|r| r.ace == a && r.countermeasure == "none")
            .collect();
        if !pts.is_empty() && (a == "gaussian" || !rows.iter().any(|r| r.ace == "gaussian")) {
            let mut seen = Vec::new();
            let mut x = Vec::new();
            let mut y = Vec::new();
            for p in pts {
                if !seen.contains(&p.mag.to_bits()) {
                    seen.push(p.mag.to_bits());
                    x.push(p.mag);
                    y.push(p.crlb_mas);
                }
            }
            series.push(Series {
                label: format!("Cramér–Rao bound ({a})"),
                x,
                y,
                yerr: None,
            });
        }
    }
    line_plot(
        &dir.join("accuracy.png"),
        "Single-exposure position accuracy (mean over images ± s.e.m.)",
        "Hw magnitude",
        "accuracy per axis [mas]",
        &series,
        &[(4.0, "4 mas requirement".to_string())],
        Scale::Linear,
        Scale::Log,
    )?;
    Ok(())
}

/// `jsim predict`
pub fn predict(
    cfg: &Config,
    names: &[String],
    plan: &engine::studies::experiment::Plan,
) -> Result<()> {
    let t0 = Instant::now();
    let sim = Simulator::new(cfg)?;
    let setup = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let p = engine::analysis::predict::Predictor::new(&sim)?;
    println!(
        "Hw {} {} ACE, {} readout, {} images:",
        cfg.scene.mag_hw,
        cfg.ace.case.name(),
        cfg.readout.order.name(),
        cfg.fidelity.images
    );
    for n in names {
        let v = p.predict(n, plan).unwrap_or(f64::NAN);
        println!("  {n:<14} predicted accuracy {v:7.2} mas");
    }
    println!(
        "prediction {:.0} ms (after {:.2} s building the PSF and the ACE series, shared with a simulation)",
        t1.elapsed().as_secs_f64() * 1e3,
        setup
    );
    Ok(())
}
