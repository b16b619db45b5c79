//! One simulated image, two paths, one answer: the analysis `jsim analyze` runs on the image's FITS file
//! and the explorer worker's image stage give the same reports (`none` and `plate-poly:3`).
//!
//! The `jsim` binary is not built for this crate's tests, so the CLI side calls what `jsim analyze` calls
//! (engine/src/bin/jsim/cmd.rs): `engine::io::analysis_input::AnalysisInput::read` (the image, its truth and
//! the products beside it) and `Session::analyze_input` (the pipeline on those alone). The reports must be
//! the same — counts equal, numbers to 1e-9 relative (the PLTSCALE card keeps 15 digits) — but for the true
//! ACE's prediction the explorer attaches: the read noise comes back exactly from the per-read noise and the
//! sampling (RNREAD, SAMPLING).

use app::worker::{FrameResult, Job, Msg, Request, Stages, Worker};
use engine::analysis::countermeasures::Countermeasure;
use engine::config::Config;
use engine::io::{analysis_input, exposure, fits};
use engine::scoring::image::Report;
use engine::session::Session;
use engine::testkit::{small_config, temp_dir};
use std::path::Path;
use std::time::{Duration, Instant};

/// The configuration an image file was simulated with (its CONFIG extension).
fn image_config(image: &Path) -> Config {
    let text = fits::read_text(image, "CONFIG").expect("the CONFIG extension");
    Config::from_toml_str(&text).expect("the image's configuration")
}

/// `jsim analyze --image IMAGE --countermeasure CM` with the image's own configuration, up to its report.
fn cli_report(image: &Path, cm: Countermeasure) -> Report {
    let input = analysis_input::AnalysisInput::read(image, None, None, &Config::default())
        .expect("the image");
    assert!(
        input.assumptions.is_empty(),
        "nothing assumed of a simulated image: {:?}",
        input.assumptions
    );
    let (img_cfg, _) = input.provenance.clone().expect("a jsim image");
    Session::new()
        .analyze_input(&img_cfg, &input, None, cm)
        .expect("the analysis")
        .report
}

/// The frame the explorer's worker sends for `cfg`, exposure `index`, under `cm`.
fn worker_frame(cfg: &Config, index: usize, cm: Countermeasure) -> FrameResult {
    let worker = Worker::spawn(egui::Context::default()).expect("the engine thread");
    let job = Job {
        generation: 1,
        request: Request {
            cfg: cfg.clone(),
            countermeasure: cm,
            image_index: index,
            mags: vec![cfg.scene.mag_hw],
        },
        stages: Stages {
            image: true,
            ..Default::default()
        },
    };
    worker
        .try_submit(Box::new(job))
        .expect("the queue is empty");
    let t0 = Instant::now();
    let mut frame = None;
    loop {
        for m in worker.poll() {
            match m {
                Msg::Frame(f) => frame = Some(*f),
                Msg::Done { .. } => return frame.expect("a frame before Done"),
                Msg::Error { message, .. } => panic!("the worker failed: {message}"),
                Msg::Cancelled { .. } => panic!("the job was cancelled"),
                _ => {}
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "timed out");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The image, its truth and its file written once; both paths analyse exposure `INDEX` of it.
const INDEX: usize = 1;

fn written_image(name: &str) -> (Config, engine::testkit::Scratch, std::path::PathBuf) {
    let cfg = small_config();
    let dir = temp_dir(name);
    let sim = Session::new().new_simulator(&cfg).expect("a simulator");
    let exp = sim.exposure(INDEX).expect("the exposure");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("written");
    // the calibration flat product beside it, as `jsim simulate` writes it
    engine::io::instrument::write_calibration_flat(&dir, &sim).expect("the flat");
    engine::io::instrument::write_reference_catalogue(
        &dir,
        &sim,
        &engine::io::instrument::SurveyModel::default(),
    )
    .expect("the reference catalogue");
    engine::io::instrument::write_model_psf(&dir, &sim).expect("the model PSF");
    assert_eq!(
        image_config(&files.image),
        cfg,
        "the file carries its config"
    );
    (cfg, dir, files.image)
}

/// A report without the fit displacement the true ACE predicts: the explorer shows that mechanism from the
/// simulation it holds; `jsim analyze` reads no simulation (CONFIG) and attaches none.
fn without_ace_prediction(r: &Report) -> Report {
    Report {
        response_corr_x: 0.0,
        response_corr_y: 0.0,
        response_slope_x: 0.0,
        response_slope_y: 0.0,
        response_rms_mas: 0.0,
        ..r.clone()
    }
}

/// The same report: every count equal, every number to 1e-9 relative (the file's PLTSCALE card keeps 15
/// significant digits of the plate scale the worker holds exactly).
fn assert_same(a: &Report, b: &Report, what: &str) {
    let (ja, jb) = (
        serde_json::to_value(a).expect("json"),
        serde_json::to_value(b).expect("json"),
    );
    let (Some(ma), Some(mb)) = (ja.as_object(), jb.as_object()) else {
        panic!("reports are objects");
    };
    for (k, va) in ma {
        let vb = &mb[k];
        match (va.as_f64(), vb.as_f64()) {
            (Some(x), Some(y)) => assert!(
                x == y || (x - y).abs() <= 1e-9 * x.abs().max(y.abs()),
                "{what}: {k} = {x} against {y}"
            ),
            _ => assert_eq!(va, vb, "{what}: {k}"),
        }
    }
}

#[test]
fn cli_and_worker_give_identical_reports() {
    let (cfg, dir, image) = written_image("app-cli-path");
    for name in ["none", "plate-poly:3"] {
        let cm: Countermeasure = name.parse().expect("a countermeasure");
        let frame = worker_frame(&cfg, INDEX, cm);
        let cli = cli_report(&image, cm);
        assert!(cli.n_used >= 40, "{name}: {cli:?}");
        assert_eq!(cli.countermeasure, name);
        assert_same(&without_ace_prediction(&frame.report), &cli, name);
        if cm == Countermeasure::None {
            assert_same(&without_ace_prediction(&frame.report_none), &cli, name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
