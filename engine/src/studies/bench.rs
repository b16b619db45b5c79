//! Speed against error: every approximation has a knob, and this measures what each setting costs in time
//! and in error against the reference (finest) setting. Used by `jsim bench`; tests never assert times.
//!
//! Errors of an integration are measured on the noise-free star electrons: per stamp, the largest
//! |value − reference| relative to the stamp's peak pixel (the worst stamp is reported) and the rms of the
//! same over all stamp pixels; flux error = |Σ − Σ_ref| / Σ_ref. The astrometric cost of a knob is the rms
//! (mean removed, per axis) of the difference between the positions fitted on noise-free images made with
//! the knob and with the reference setting, each with its own ePSF built from the image.

use crate::analysis::pipeline::{Options, analyze};
use crate::analysis::{AnalysisError, AnalysisImage};
use crate::config::{AceCase, Backend, Config, Method};
use crate::integrate::{self, FrameSpec, Integrator, Motion, Stamp};
use crate::io::IoError;
use crate::io::csv::{self, Cell};
use crate::numerics::stats;
use crate::scoring::image::score;
use crate::session::Session;
use crate::simulate::{SimError, Simulator};
use serde::Serialize;
use std::path::Path;
use std::path::PathBuf;
use std::time::Instant;

/// A benchmark failure.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A simulated exposure's analysis (the simulation's products, the pipeline).
    #[error(transparent)]
    Source(#[from] crate::session::SourceError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    File(#[from] IoError),
    #[error(transparent)]
    Sequence(#[from] crate::studies::sequence::run::SequenceError),
    #[error(transparent)]
    Solution(#[from] crate::solution::SolutionError),
    /// A benchmark's own setting out of its range.
    #[error("{0}")]
    Invalid(String),
}

/// One line of the benchmark.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    pub group: String,
    pub setting: String,
    pub backend: String,
    pub stars: usize,
    pub time_s: f64,
    pub max_err: f64,
    pub rms_err: f64,
    pub flux_err: f64,
    /// Position error [mas]: for an integration setting, the rms shift of the fitted positions against those
    /// of the exact frame (Δpos); for an analysis setting (ePSF, crowded field), the accuracy against the truth.
    pub astro_mas: f64,
    pub note: String,
}

impl BenchRow {
    /// A row with a time only (no error columns).
    pub fn timing(
        group: &str,
        setting: String,
        backend: String,
        stars: usize,
        time_s: f64,
        note: &str,
    ) -> Self {
        Self {
            group: group.into(),
            setting,
            backend,
            stars,
            time_s,
            max_err: f64::NAN,
            rms_err: f64::NAN,
            flux_err: f64::NAN,
            astro_mas: f64::NAN,
            note: note.into(),
        }
    }
}

/// The CSV header of `bench.csv`.
pub const CSV_HEADER: [&str; 10] = [
    "group",
    "setting",
    "backend",
    "stars",
    "time_s",
    "max_err",
    "rms_err",
    "flux_err",
    "astro_mas",
    "note",
];

/// Per-stamp error statistics of `a` against the reference `r` (same stamps in the same order).
pub fn compare(a: &[Stamp], r: &[Stamp]) -> (f64, f64, f64) {
    let (mut worst, mut sq, mut n) = (0.0f64, 0.0, 0usize);
    let (mut fa, mut fr) = (0.0, 0.0);
    for (x, y) in a.iter().zip(r) {
        let peak = y.data.iter().cloned().fold(0.0, f64::max).max(1e-300);
        // stamps may differ in size (a knob changes the stamp): compare on the reference's pixels
        for iy in 0..y.ny {
            for ix in 0..y.nx {
                let v = x.at(y.x0 + ix as i64, y.y0 + iy as i64);
                let e = (v - y.data[iy * y.nx + ix]).abs() / peak;
                worst = worst.max(e);
                sq += e * e;
                n += 1;
            }
        }
        fa += x.sum();
        fr += y.sum();
    }
    (
        worst,
        (sq / n.max(1) as f64).sqrt(),
        ((fa - fr) / fr.max(1e-300)).abs(),
    )
}

/// [`compare`] on whole frames, for knobs that change which stars have a stamp at all (a star just off
/// the array whose shorter reach misses it): the stamps of each setting are added into a frame of
/// `detector_px`², and the errors are taken over all pixels against the reference frame's peak; the note
/// gets the largest difference in electrons.
pub fn compare_frames(a: &[Stamp], r: &[Stamp], detector_px: usize) -> (f64, f64, f64, f64) {
    let frame = |s: &[Stamp]| {
        let mut img = vec![0.0; detector_px * detector_px];
        integrate::add_stamps(&mut img, detector_px, s);
        img
    };
    let (fa, fr) = (frame(a), frame(r));
    let peak = fr.iter().cloned().fold(0.0, f64::max).max(1e-300);
    let (mut worst, mut sq) = (0.0f64, 0.0);
    for (x, y) in fa.iter().zip(&fr) {
        worst = worst.max((x - y).abs());
        sq += (x - y) * (x - y);
    }
    let (sa, sr) = (fa.iter().sum::<f64>(), fr.iter().sum::<f64>());
    (
        worst / peak,
        (sq / fr.len().max(1) as f64).sqrt() / peak,
        ((sa - sr) / sr.max(1e-300)).abs(),
        worst,
    )
}

/// Integrate the stars of `sim` (optionally the first `limit`) for exposure 0, timed.
pub fn integrate_stamps(
    sim: &Simulator,
    method: Method,
    integrator: &Integrator,
    limit: Option<usize>,
) -> Result<(Vec<Stamp>, f64), SimError> {
    let mut jobs = sim.jobs()?;
    if let Some(l) = limit {
        jobs.truncate(l);
    }
    let track = sim.track(0);
    let motion = match &track {
        Some(t) => Motion::Track(t),
        None => Motion::Static,
    };
    let map = crate::integrate::kernel::IntraPixelMap::from_config(
        &sim.cfg.detector,
        sim.cfg.fidelity.subpixels,
    )?;
    let frame = FrameSpec {
        timing: &sim.timing,
        detector_px: sim.cfg.instrument.detector_px,
        stamp_radius_px: sim.cfg.fidelity.stamp_radius_px,
        method,
        map: &map,
        deposit_phases: sim.cfg.fidelity.deposit_phases,
    };
    let t0 = Instant::now();
    let stamps = integrator.integrate(&jobs, motion, &frame)?;
    Ok((stamps, t0.elapsed().as_secs_f64()))
}

/// Fitted positions (px) of the stars in the noise-free image of `sim`'s exposure 0.
pub fn noise_free_positions(sim: &Simulator) -> Result<Vec<Option<(f64, f64)>>, BenchError> {
    let jobs = sim.jobs()?;
    let (e, _) = sim.integrate(0, &jobs)?;
    positions_of_image(sim, e)
}

/// Fitted positions (px) of the stars in a noise-free image assembled from stamps.
pub fn positions_of_stamps(
    sim: &Simulator,
    stamps: &[Stamp],
) -> Result<Vec<Option<(f64, f64)>>, BenchError> {
    let n = sim.cfg.instrument.detector_px;
    let mut e = vec![0.0; n * n];
    integrate::add_stamps(&mut e, n, stamps);
    positions_of_image(sim, e)
}

/// Fit the stars of a noise-free electron image (plus the sky) with an ePSF built from it.
fn positions_of_image(
    sim: &Simulator,
    star_e: Vec<f64>,
) -> Result<Vec<Option<(f64, f64)>>, BenchError> {
    let n = sim.cfg.instrument.detector_px;
    let d = &sim.cfg.detector;
    let sky = d.dark_e_per_s * d.exposure_s;
    let img = AnalysisImage {
        nx: n,
        ny: n,
        e: star_e.into_iter().map(|v| v + sky).collect(),
        bad: vec![false; n * n],
        var_floor_e2: d.noise_floor_e2(),
        var_floor_px_e2: None,
        flat_sigma: 0.0,
        plate_scale_mas: sim.cfg.instrument.plate_scale_mas(),
    };
    let jobs = sim.jobs()?;
    let truth = sim.truth(&jobs, sim.track(0).as_ref());
    let a = score(
        &analyze(&img, &Options::new(&sim.cfg.analysis))?,
        Some(&truth),
        img.plate_scale_mas,
    );
    let mut out = vec![None; truth.len()];
    for s in &a.stars {
        if let Some(k) = s.truth {
            out[k] = Some((s.x, s.y));
        }
    }
    Ok(out)
}

/// Per-axis rms (mas, mean removed) of position differences between two fits of the same stars.
pub fn position_rms_mas(a: &[Option<(f64, f64)>], b: &[Option<(f64, f64)>], scale: f64) -> f64 {
    let (mut dx, mut dy) = (Vec::new(), Vec::new());
    for (p, q) in a.iter().zip(b) {
        if let (Some(p), Some(q)) = (p, q) {
            dx.push((p.0 - q.0) * scale);
            dy.push((p.1 - q.1) * scale);
        }
    }
    ((stats::std_dev(&dx).powi(2) + stats::std_dev(&dy).powi(2)) / 2.0).sqrt()
}

/// A configuration for benchmarking: CPU backend, one image, noise-free detector.
pub fn bench_config(base: &Config) -> Config {
    let mut c = base.clone();
    c.fidelity.images = 1;
    c.fidelity.backend = Backend::Cpu;
    c
}

/// A sweep of one knob: `settings` are (label, configuration); the last one is the reference. Each setting
/// runs in a fresh session, so its time includes the PSFs and kernels it needs (a shared session would
/// hand a setting equal to an earlier one its cached PSFs for free).
pub fn knob_sweep(
    group: &str,
    settings: &[(String, Config)],
    astro: bool,
) -> Result<Vec<BenchRow>, BenchError> {
    let mut runs = Vec::new();
    for (label, cfg) in settings {
        let t0 = Instant::now();
        let sim = Session::new().new_simulator(cfg)?;
        let (stamps, t_int) = integrate_stamps(&sim, cfg.fidelity.method, &Integrator::Cpu, None)?;
        let setup = t0.elapsed().as_secs_f64() - t_int;
        let pos = if astro {
            Some(noise_free_positions(&sim)?)
        } else {
            None
        };
        runs.push((label.clone(), stamps, t_int, setup, pos, sim.stars.len()));
    }
    let Some((_, ref_stamps, _, _, ref_pos, _)) = runs
        .last()
        .map(|r| (r.0.clone(), r.1.clone(), r.2, r.3, r.4.clone(), r.5))
    else {
        return Ok(Vec::new());
    };
    let scale = settings[0].1.instrument.plate_scale_mas();
    // a knob that changes each star's reach can leave a star just off the array without a stamp: compare
    // whole frames then
    let reach_knob = settings
        .windows(2)
        .any(|w| w[0].1.fidelity.wing_threshold_e != w[1].1.fidelity.wing_threshold_e);
    let n_px = settings[0].1.instrument.detector_px;
    Ok(runs
        .into_iter()
        .map(|(label, stamps, t_int, setup, pos, n)| {
            let (max_err, rms_err, flux_err, worst_e) = if reach_knob {
                compare_frames(&stamps, &ref_stamps, n_px)
            } else {
                let (a, b, c) = compare(&stamps, &ref_stamps);
                (a, b, c, f64::NAN)
            };
            let astro_mas = match (&pos, &ref_pos) {
                (Some(p), Some(r)) => position_rms_mas(p, r, scale),
                _ => f64::NAN,
            };
            BenchRow {
                group: group.into(),
                setting: label,
                backend: "cpu".into(),
                stars: n,
                time_s: setup + t_int,
                max_err,
                rms_err,
                flux_err,
                astro_mas,
                note: if worst_e.is_nan() {
                    format!("PSF + kernel {setup:.2} s, integration {t_int:.3} s")
                } else {
                    format!(
                        "PSF + kernel {setup:.2} s, integration {t_int:.3} s; largest pixel difference {worst_e:.2} e⁻ (frame errors / frame peak)"
                    )
                },
            }
        })
        .collect())
}

/// Methods × backends on one configuration: errors against the CPU direct method on `ref_stars` stars;
/// times of the full frame (the direct CPU time is measured on the subset and scaled, as noted).
pub fn methods(
    session: &Session,
    cfg: &Config,
    ref_stars: usize,
    gpu: Option<&Integrator>,
) -> Result<Vec<BenchRow>, BenchError> {
    let sim = session.new_simulator(&bench_config(cfg))?;
    let cpu = Integrator::Cpu;
    let n_all = sim.stars.len();
    let sub = ref_stars.min(n_all).max(1);
    let (reference, t_ref) = integrate_stamps(&sim, Method::Direct, &cpu, Some(sub))?;
    let mut rows = vec![BenchRow {
        group: "method".into(),
        setting: "direct (reference)".into(),
        backend: "cpu".into(),
        stars: n_all,
        time_s: t_ref * n_all as f64 / sub as f64,
        max_err: 0.0,
        rms_err: 0.0,
        flux_err: 0.0,
        astro_mas: 0.0,
        note: format!("measured on {sub} stars ({t_ref:.2} s), scaled to {n_all}"),
    }];
    // the fast CPU method equals the direct one to rounding (checked on the subset below), so its full
    // frame is the astrometric reference of the other methods
    let fast_cpu = integrate_stamps(&sim, Method::Fast, &cpu, None)?;
    let scale = sim.cfg.instrument.plate_scale_mas();
    let ref_pos = positions_of_stamps(&sim, &fast_cpu.0)?;
    let mut push =
        |setting: &str, backend: &str, full: (Vec<Stamp>, f64)| -> Result<(), BenchError> {
            let part: Vec<Stamp> = full.0.iter().take(sub).cloned().collect();
            let (max_err, rms_err, flux_err) = compare(&part, &reference);
            let astro_mas = position_rms_mas(&positions_of_stamps(&sim, &full.0)?, &ref_pos, scale);
            rows.push(BenchRow {
                group: "method".into(),
                setting: setting.into(),
                backend: backend.into(),
                stars: n_all,
                time_s: full.1,
                max_err,
                rms_err,
                flux_err,
                astro_mas,
                note: "Δpos against the fast CPU frame".into(),
            });
            Ok(())
        };
    push("fast", "cpu", fast_cpu.clone())?;
    if let Some(g) = gpu {
        let name = g.name();
        // warm-up (pipeline caches, kernel upload), then timed
        let _ = integrate_stamps(&sim, Method::Fast, g, None)?;
        push(
            "fast",
            &name,
            integrate_stamps(&sim, Method::Fast, g, None)?,
        )?;
        push(
            "direct",
            &name,
            integrate_stamps(&sim, Method::Direct, g, None)?,
        )?;
    }
    Ok(rows)
}

/// The integration cost against the number of stars (random positions over the photosensitive area).
pub fn scaling(
    session: &Session,
    cfg: &Config,
    counts: &[usize],
    gpu: Option<&Integrator>,
) -> Result<Vec<BenchRow>, BenchError> {
    use rand::RngExt;
    let dir = std::env::temp_dir().join(format!("jsim-bench-{}", std::process::id()));
    let io = |path: &std::path::Path| {
        let path = path.to_path_buf();
        move |source| BenchError::Io { path, source }
    };
    std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    let mut rows = Vec::new();
    for &n in counts {
        let mut r = crate::rng::stream(cfg.seed, crate::rng::Stream::Test, n as u64);
        let lo = cfg.instrument.border_px() as f64 + 2.0;
        let hi = (cfg.instrument.detector_px - cfg.instrument.border_px()) as f64 - 2.0;
        let mut text = String::from("x,y,hw,j_h\n");
        for _ in 0..n {
            let (x, y) = (
                lo + r.random::<f64>() * (hi - lo),
                lo + r.random::<f64>() * (hi - lo),
            );
            text.push_str(&format!(
                "{x},{y},{},{}\n",
                cfg.scene.mag_hw, cfg.scene.j_minus_h
            ));
        }
        let path = dir.join(format!("stars_{n}.csv"));
        std::fs::write(&path, text).map_err(io(&path))?;
        let mut c = bench_config(cfg);
        c.scene.kind = crate::config::SceneKind::Catalogue;
        c.scene.catalogue = Some(path);
        let sim = session.new_simulator(&c)?;
        let (_, t) = integrate_stamps(&sim, Method::Fast, &Integrator::Cpu, None)?;
        rows.push(BenchRow::timing(
            "stars",
            format!("{n} stars"),
            "cpu".into(),
            n,
            t,
            "fast method",
        ));
        if let Some(g) = gpu {
            let _ = integrate_stamps(&sim, Method::Fast, g, None)?;
            let (_, t) = integrate_stamps(&sim, Method::Fast, g, None)?;
            rows.push(BenchRow::timing(
                "stars",
                format!("{n} stars"),
                g.name(),
                n,
                t,
                "fast method",
            ));
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(rows)
}

/// A field table for the field-WFE knob: a 3 × 3 grid over the array whose coma (Z7, Z8) and
/// astigmatism (Z5) grow linearly across the field by ≈ 40 nm, on top of the default design residual — the
/// size of the field dependence of a wide-field design.
pub fn demo_field_table(detector_px: f64) -> Vec<crate::config::FieldWfe> {
    let mut rows = Vec::new();
    for fy in [0.0, 0.5, 1.0] {
        for fx in [0.0, 0.5, 1.0] {
            let (u, v) = (fx - 0.5, fy - 0.5);
            let mut f = vec![
                0.0,
                0.0,
                0.0,
                0.07,
                0.05 + 0.02 * u,
                -0.03,
                0.03 * u,
                0.03 * v,
            ];
            f.truncate(8);
            rows.push(crate::config::FieldWfe {
                x_px: fx * detector_px,
                y_px: fy * detector_px,
                fringe: f,
            });
        }
    }
    rows
}

/// The knob sweeps of the reference configuration (`quick` uses a 5 × 5 grid for speed).
pub fn knob_settings(base: &Config, quick: bool) -> Vec<(String, Vec<(String, Config)>, bool)> {
    let mut b = bench_config(base);
    if quick {
        b.scene.grid_n = 5;
        b.scene.grid_spacing_px = 300.0;
    }
    let with = |f: &dyn Fn(&mut Config)| {
        let mut c = b.clone();
        f(&mut c);
        c
    };
    let mut g = b.clone();
    g.ace.case = AceCase::Gaussian;
    let gauss = |f: &dyn Fn(&mut Config)| {
        let mut c = g.clone();
        f(&mut c);
        c
    };
    vec![
        (
            "time step (realistic ACE)".into(),
            [64usize, 16, 4, 2, 1]
                .iter()
                .map(|&s| {
                    (
                        format!("{:.2} ms", 0.15 * s as f64),
                        with(&|c| c.fidelity.time_stride = s),
                    )
                })
                .collect(),
            true,
        ),
        (
            "subpixels per axis".into(),
            [2usize, 4, 8, 16]
                .iter()
                .map(|&s| (format!("{s}"), gauss(&|c| c.fidelity.subpixels = s)))
                .collect(),
            true,
        ),
        (
            "PSF cells per pixel".into(),
            [4usize, 8, 16, 32]
                .iter()
                .map(|&o| (format!("{o}"), gauss(&|c| c.optics.psf_oversampling = o)))
                .collect(),
            true,
        ),
        (
            "pupil samples".into(),
            [64usize, 128, 256, 512]
                .iter()
                .map(|&n| (format!("{n}"), gauss(&|c| c.optics.pupil_samples = n)))
                .collect(),
            true,
        ),
        (
            "wavelength step".into(),
            [0.1f64, 0.05, 0.02, 0.01]
                .iter()
                .map(|&s| (format!("{s} µm"), gauss(&|c| c.band.wavelength_step_um = s)))
                .collect(),
            true,
        ),
        (
            "field WFE step (with a field table)".into(),
            [20.0f64, 5.0, 1.0, 0.0]
                .iter()
                .map(|&s| {
                    (
                        if s > 0.0 {
                            format!("{s} nm")
                        } else {
                            "exact (one PSF per star)".into()
                        },
                        gauss(&|c| {
                            c.optics.field_table =
                                demo_field_table(c.instrument.detector_px as f64);
                            c.optics.field_wfe_step_nm = s;
                        }),
                    )
                })
                .collect(),
            true,
        ),
        (
            "field zones (with a field table)".into(),
            // the last setting is the reference: every star the wavefront at its own position
            [984usize, 656, 328, 0]
                .iter()
                .map(|&z| {
                    (
                        match z {
                            0 => "exact (each star its own)".to_string(),
                            z => format!("{z} px"),
                        },
                        gauss(&|c| {
                            c.optics.field_table =
                                demo_field_table(c.instrument.detector_px as f64);
                            c.optics.field_wfe_step_nm = 0.0;
                            c.optics.field_zone_px = z;
                        }),
                    )
                })
                .collect(),
            true,
        ),
        (
            "stamp radius (flux kept)".into(),
            // the last setting is the reference: 0 = the kernel's reach, every modelled photon kept
            [6usize, 8, 12, 0]
                .iter()
                .map(|&r| {
                    (
                        match r {
                            0 => "kernel reach (exact)".to_string(),
                            r => format!("{r} px"),
                        },
                        gauss(&|c| c.fidelity.stamp_radius_px = r),
                    )
                })
                .collect(),
            false,
        ),
    ]
}

/// Accuracy against ePSF iterations on a noisy Gaussian-ACE image (mean over `images`).
pub fn epsf_iterations(
    session: &Session,
    base: &Config,
    images: usize,
) -> Result<Vec<BenchRow>, BenchError> {
    let mut c = bench_config(base);
    c.ace.case = AceCase::Gaussian;
    c.fidelity.images = images.max(1);
    let sim = session.new_simulator(&c)?;
    let imgs: Vec<_> = (0..c.fidelity.images)
        .map(|i| {
            sim.exposure(i)
                .map(|e| (crate::session::analysis_image(&sim, &e.image), e.truth))
        })
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for (label, it, sm) in [
        ("1 (quadratic)", 1usize, crate::config::Smoothing::Quadratic),
        (
            "3 (quadratic, default)",
            3,
            crate::config::Smoothing::Quadratic,
        ),
        (
            "converged (quadratic)",
            0,
            crate::config::Smoothing::Quadratic,
        ),
        (
            "3 (A&K local quadratic)",
            3,
            crate::config::Smoothing::LocalQuadratic,
        ),
        ("3 (no smoothing)", 3, crate::config::Smoothing::None),
    ] {
        let mut o = Options::new(&c.analysis);
        o.cfg.epsf_iterations = it;
        o.cfg.smoothing = sm;
        let t0 = Instant::now();
        let mut acc = Vec::new();
        let mut ratio = Vec::new();
        for (img, truth) in &imgs {
            if let Ok(a) = analyze(img, &o) {
                let a = score(&a, Some(truth), img.plate_scale_mas);
                acc.push(a.report.accuracy_mas);
                ratio.push(a.report.accuracy_over_crlb);
            }
        }
        rows.push(BenchRow {
            group: "ePSF iterations".into(),
            setting: label.into(),
            backend: "cpu".into(),
            stars: sim.stars.len(),
            time_s: t0.elapsed().as_secs_f64() / imgs.len().max(1) as f64,
            max_err: f64::NAN,
            rms_err: f64::NAN,
            flux_err: f64::NAN,
            astro_mas: stats::mean(&acc),
            note: format!(
                "accuracy/CRLB {:.3} (mean of {} images)",
                stats::mean(&ratio),
                acc.len()
            ),
        });
    }
    Ok(rows)
}

/// A relative error for the table: `–` when not measured.
fn fmt(v: f64) -> String {
    if v.is_nan() {
        "–".into()
    } else if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.2e}")
    }
}

/// The rows as a text table (what `jsim bench` prints).
pub fn render_table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<26} {:<24} {:<28} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9}  {}\n",
        "group",
        "setting",
        "backend",
        "stars",
        "time [s]",
        "max err",
        "rms err",
        "flux err",
        "pos [mas]",
        "note"
    );
    for r in rows {
        s.push_str(&format!(
            "{:<26} {:<24} {:<28} {:>6} {:>9.3} {:>9} {:>9} {:>9} {:>9}  {}\n",
            r.group,
            r.setting,
            r.backend.chars().take(28).collect::<String>(),
            r.stars,
            r.time_s,
            fmt(r.max_err),
            fmt(r.rms_err),
            fmt(r.flux_err),
            if r.astro_mas.is_nan() {
                "–".into()
            } else {
                format!("{:.3}", r.astro_mas)
            },
            r.note
        ));
    }
    s.push_str(
        "pos [mas]: an integration setting's rms position shift against the exact frame, the forward \
         model's against its finest node spacing; an analysis setting's (ePSF, crowded) accuracy against \
         the truth\n",
    );
    s
}

/// Write `bench.csv` (columns: [`CSV_HEADER`]).
pub fn write_bench(path: &Path, rows: &[BenchRow]) -> Result<(), IoError> {
    let cells: Vec<Vec<Cell>> = rows
        .iter()
        .map(|r| {
            vec![
                Cell::S(r.group.clone()),
                Cell::S(r.setting.clone()),
                Cell::S(r.backend.clone()),
                Cell::I(r.stars as i64),
                Cell::F(r.time_s),
                Cell::F(r.max_err),
                Cell::F(r.rms_err),
                Cell::F(r.flux_err),
                Cell::F(r.astro_mas),
                Cell::S(r.note.clone()),
            ]
        })
        .collect();
    csv::write(path, &CSV_HEADER, &cells)
}

/// Fewest settings with a measured error (against their exact setting) that make a speed-against-error
/// figure: one point is not a trade-off.
pub const MIN_PLOTTED_SETTINGS: usize = 2;

/// The speed-against-error figure of `jsim bench` (`bench.png`): time against the largest error, one point
/// set per knob group. Returns whether it was drawn: with fewer than [`MIN_PLOTTED_SETTINGS`] settings that
/// have an error (e.g. one method against its exact reference, whose error is 0) there is nothing to draw,
/// and no file is written.
pub fn plot_bench(path: &Path, rows: &[BenchRow]) -> Result<bool, IoError> {
    use crate::io::plot::{Scale, Series, scatter};
    let plotted = |r: &&BenchRow| r.max_err.is_finite() && r.max_err > 0.0;
    if rows.iter().filter(plotted).count() < MIN_PLOTTED_SETTINGS {
        return Ok(false);
    }
    let mut groups: Vec<String> = Vec::new();
    for r in rows.iter().filter(plotted) {
        if !groups.contains(&r.group) {
            groups.push(r.group.clone());
        }
    }
    let sets: Vec<Series> = groups
        .iter()
        .map(|g| {
            let pts: Vec<&BenchRow> = rows
                .iter()
                .filter(|r| &r.group == g && r.max_err > 0.0 && r.max_err.is_finite())
                .collect();
            Series {
                label: g.clone(),
                x: pts.iter().map(|r| r.max_err).collect(),
                y: pts.iter().map(|r| r.time_s).collect(),
                yerr: None,
                yerr_below: None,
            }
        })
        .collect();
    scatter(
        path,
        "Speed against error (each knob against its finest setting)",
        "max |error| / peak pixel",
        "time [s]: PSF + kernel + integration",
        &sets,
        Scale::Log,
        Scale::Log,
        false,
    )?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(setting: &str, max_err: f64) -> BenchRow {
        BenchRow {
            max_err,
            ..BenchRow::timing("method", setting.into(), "cpu".into(), 400, 1.0, "")
        }
    }

    /// One method against its exact reference is one point: no figure is written (not a lone dot); two
    /// settings with an error are a trade-off and are drawn.
    #[test]
    fn the_figure_is_drawn_only_for_a_trade_off() {
        let dir = std::env::temp_dir().join(format!("jsim-bench-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let png = dir.join(crate::io::products::files::BENCH_PNG);
        let one = [row("reference", 0.0), row("fast", 1e-4)];
        assert!(!plot_bench(&png, &one).expect("plot"));
        assert!(!png.exists());
        let two = [
            row("reference", 0.0),
            row("fast", 1e-4),
            row("direct", 1e-9),
        ];
        assert!(plot_bench(&png, &two).expect("plot"));
        assert!(png.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
