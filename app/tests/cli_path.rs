//! One simulated image, two paths, one answer: the analysis `jsim analyze` runs on the image's FITS file
//! and the explorer worker's image stage give the same reports (`none` and `plate-poly:3`).
//!
//! The `jsim` binary is not built for this crate's tests, so the CLI side calls what `jsim analyze` calls
//! (engine/src/bin/jsim/cmd.rs): the image and its truth read back from the file (the plate scale from its
//! `PLTSCALE` card), the image's own configuration (CONFIG extension, IMAGEIDX) for a session simulator as
//! the source, and the pipeline.
//!
//! The pixels, the truth and the pipeline are identical; the reports are not yet bit-identical because the
//! scalars `jsim analyze` reads from the header (`PLTSCALE`, `RDNOISE`, …) are written with cfitsio's 15
//! significant digits, a few ulps off the simulation's values. So the test that runs checks every figure to
//! 1e-9 relative, and the bit-for-bit check (`--ignored`) waits for the engine to write those cards with 17
//! digits (or for `jsim analyze` to take them from the image's CONFIG).

use app::worker::{FrameResult, Job, Msg, Request, Stages, Worker};
use engine::analysis::countermeasures::{Countermeasure, Plan};
use engine::analysis::{Report, Source, analyse_image};
use engine::config::{Backend, Config};
use engine::io::{exposure, fits};
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
    let img_cfg = image_config(image);
    let index = fits::read_f64_key(image, "IMAGEIDX").expect("IMAGEIDX") as usize;
    let scale = fits::read_f64_key(image, "PLTSCALE").expect("PLTSCALE");
    let (img, assumed) = exposure::read_analysis_image(image, scale).expect("the image");
    assert!(
        assumed.is_empty(),
        "nothing assumed of a simulated image: {assumed:?}"
    );
    let truth = exposure::read_truth(image).expect("the truth");
    let mut c = img_cfg.clone();
    c.fidelity.backend = Backend::Cpu;
    c.fidelity.images = index + 1;
    let session = Session::new();
    let sim = session.simulator(&c).expect("the image's simulator");
    let plan = Plan::new(vec![cm]).expect("a plan");
    let res = analyse_image(
        &img,
        Some(&truth),
        Some(Source { sim: &sim, index }),
        &img_cfg.analysis,
        &plan,
        img_cfg.seed,
    )
    .expect("the analysis");
    res.of(&cm)
        .expect("the countermeasure applies")
        .report
        .clone()
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

/// Every number of two reports equal to `rel` (relative), everything else exactly.
fn assert_close(a: &Report, b: &Report, rel: f64, what: &str) {
    let (ja, jb) = (
        serde_json::to_value(a).expect("json"),
        serde_json::to_value(b).expect("json"),
    );
    let (Some(ma), Some(mb)) = (ja.as_object(), jb.as_object()) else {
        panic!("a report is an object");
    };
    assert_eq!(ma.keys().collect::<Vec<_>>(), mb.keys().collect::<Vec<_>>());
    for (k, va) in ma {
        let vb = &mb[k];
        match (va.as_f64(), vb.as_f64()) {
            (Some(x), Some(y)) if !(va.is_u64() && vb.is_u64()) => assert!(
                (x - y).abs() <= rel * x.abs().max(y.abs()).max(1.0),
                "{what}: {k} = {x} vs {y}"
            ),
            _ => assert_eq!(va, vb, "{what}: {k}"),
        }
    }
}

/// The image, its truth and its file written once; both paths analyse exposure `INDEX` of it.
const INDEX: usize = 1;

fn written_image(name: &str) -> (Config, std::path::PathBuf, std::path::PathBuf) {
    let cfg = small_config();
    let dir = temp_dir(name);
    let sim = Session::new().new_simulator(&cfg).expect("a simulator");
    let exp = sim.exposure(INDEX).expect("the exposure");
    let files = exposure::write_exposure(&dir, &sim, &exp).expect("written");
    assert_eq!(
        image_config(&files.image),
        cfg,
        "the file carries its config"
    );
    (cfg, dir, files.image)
}

#[test]
fn cli_and_worker_give_the_same_reports() {
    let (cfg, dir, image) = written_image("app-cli-path");
    for name in ["none", "plate-poly:3"] {
        let cm: Countermeasure = name.parse().expect("a countermeasure");
        let frame = worker_frame(&cfg, INDEX, cm);
        let cli = cli_report(&image, cm);
        assert!(cli.n_used >= 40, "{name}: {cli:?}");
        assert_eq!(cli.countermeasure, name);
        assert_close(&frame.report, &cli, 1e-9, name);
        if cm == Countermeasure::None {
            assert_close(&frame.report_none, &cli, 1e-9, name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
#[ignore = "engine: header scalars (PLTSCALE, RDNOISE) are written with cfitsio's 15 significant digits, so \
            `jsim analyze` analyses with values a few ulps off the simulation's; run with --ignored once the \
            cards keep 17 digits or jsim analyze takes them from the image's CONFIG"]
fn cli_and_worker_give_identical_reports() {
    let (cfg, dir, image) = written_image("app-cli-path-exact");
    for name in ["none", "plate-poly:3"] {
        let cm: Countermeasure = name.parse().expect("a countermeasure");
        let frame = worker_frame(&cfg, INDEX, cm);
        assert_eq!(frame.report, cli_report(&image, cm), "{name}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
