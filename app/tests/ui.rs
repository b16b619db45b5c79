//! UI tests of the explorer, driven through egui_kittest by accessibility label, on a reduced configuration
//! that simulates in seconds in the dev profile. The snapshot renders with wgpu (lavapipe in CI).

use app::ExplorerApp;
use egui::accesskit::Role;
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use engine::analysis::countermeasures::Countermeasure;
use engine::config::{Config, ReadoutOrder};
use std::time::{Duration, Instant};

/// The engine's small test configuration (512², 4 channels) with 6 × 6 stars, a coarser PSF and a 1-minute
/// ACE series, so that every UI test simulates in seconds.
fn small_config() -> Config {
    let mut c = engine::testkit::small_config();
    c.scene.grid_n = 6;
    c.scene.grid_spacing_px = 72.0;
    c.optics.pupil_samples = 64;
    c.optics.psf_radius_px = 8;
    c.band.wavelength_step_um = 0.1;
    c.fidelity.images = 2;
    c.ace.span_s = 60.0;
    c.ace.sample_interval_ms = 0.5;
    if let Err(e) = c.validate() {
        panic!("the UI test config must be valid: {e}");
    }
    c
}

fn plate_poly3() -> Countermeasure {
    "plate-poly:3".parse().expect("a countermeasure")
}

fn small_app() -> ExplorerApp {
    let mut app = ExplorerApp::new(small_config());
    app.set_mags(vec![12.5, 13.5]);
    app
}

fn harness(app: ExplorerApp, render: bool) -> Harness<'static, ExplorerApp> {
    let b = Harness::builder().with_size(egui::vec2(1280.0, 820.0));
    let b = if render { b.wgpu() } else { b };
    b.build_ui_state(|ui, app: &mut ExplorerApp| app.show(ui), app)
}

/// Step frames until the worker has nothing queued or running, then let the UI settle.
fn wait_idle(h: &mut Harness<'_, ExplorerApp>, what: &str) {
    let t0 = Instant::now();
    loop {
        h.step();
        if h.state().is_idle() {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(180),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run();
}

/// The frame on screen was computed with the configuration on screen.
fn assert_current(h: &Harness<'_, ExplorerApp>) {
    let app = h.state();
    let hash = app.settings.cfg.hash_hex();
    let f = app
        .rt
        .results
        .frame
        .as_ref()
        .expect("a frame was simulated");
    assert_eq!(
        f.cfg_hash, hash,
        "the frame belongs to the parameters on screen"
    );
    assert_eq!(f.cfg, app.settings.cfg);
    let p = app.rt.results.prediction.as_ref().expect("a prediction");
    assert_eq!(p.cfg_hash, hash);
    assert!(p.dataset_mas.is_finite() && p.dataset_mas > 0.0, "{p:?}");
    assert!(f.report.n_used >= 20, "stars measured: {:?}", f.report);
    assert!(f.report.accuracy_mas.is_finite() && f.report.accuracy_mas > 0.0);
    let t = app.rt.results.twin.as_ref().expect("the Gaussian twin");
    assert_eq!(t.cfg_hash, hash);
    assert!(
        app.rt.status.note.as_ref().is_none_or(|n| !n.is_error),
        "{:?}",
        app.rt.status.note
    );
}

#[test]
fn controls_rerun_the_engine_with_the_new_parameters() {
    let mut h = harness(small_app(), false);
    wait_idle(&mut h, "the first results");
    assert_current(&h);
    {
        let app = h.state();
        assert_eq!(
            app.rt.results.frame.as_ref().map(|f| f.cfg.readout.order),
            Some(ReadoutOrder::Rolling)
        );
        // the magnitude curve: both magnitudes simulated, with the CRLB and the prediction
        assert_eq!(app.rt.results.curve.len(), 2, "{:?}", app.rt.results.curve);
        for c in &app.rt.results.curve {
            let rows = c.rows.as_ref().expect("Monte Carlo rows");
            assert!(
                rows.iter()
                    .any(|r| r.countermeasure == "none" && r.n_images == 2)
            );
            assert!(rows.iter().all(|r| r.crlb_mas > 0.0));
            assert!(c.predicted_mas.is_some());
        }
    }
    {
        // the PSD panel's estimate is at its true amplitude: in the model's units (the generator's factor
        // removed by the engine, nothing fitted) it lies on the model
        let s = h.state().rt.results.series.clone().expect("the series");
        assert!(s.model_gain.is_some_and(|g| g > 0.0), "{:?}", s.model_gain);
        let psd = engine::jitter::Psd::from_config(&s.cfg.ace);
        let mut ratios: Vec<f64> = s
            .welch_log
            .iter()
            .map(|[lf, lp]| 10f64.powf(*lp) / psd.eval(10f64.powf(*lf)))
            .collect();
        assert!(ratios.len() > 50, "{} bins", ratios.len());
        ratios.sort_by(|a, b| a.total_cmp(b));
        let median = ratios[ratios.len() / 2];
        assert!(
            (median - 1.0).abs() < 0.15,
            "median estimate/model {median}"
        );
    }
    // the panels show the numbers
    h.get_by_label_contains("Measured accuracy:");
    h.get_by_label_contains("measured: accuracy");
    h.get_by_label_contains("1 model unit =");
    h.get_by_label_contains("Predicted accuracy (instant):");
    h.get_by_label_contains("Gaussian twin:");
    let jobs = h.state().rt.jobs_sent;

    // a slider: the magnitude
    h.get_by_role_and_label(Role::Slider, "magnitude Hw")
        .set_value_accesskit(13.0);
    wait_idle(&mut h, "the new magnitude");
    assert_eq!(h.state().settings.cfg.scene.mag_hw, 13.0);
    assert_current(&h);
    assert!(h.state().rt.jobs_sent > jobs);

    // a readout-order change
    h.get_by_label("global reset").click();
    wait_idle(&mut h, "the new readout order");
    assert_eq!(
        h.state().settings.cfg.readout.order,
        ReadoutOrder::GlobalReset
    );
    assert_current(&h);
    assert_eq!(
        h.state()
            .rt
            .results
            .frame
            .as_ref()
            .map(|f| f.cfg.readout.order),
        Some(ReadoutOrder::GlobalReset)
    );
    {
        let app = h.state();
        assert!(
            app.rt.results.curve.iter().all(|c| c.rows.is_some()),
            "the curve follows the readout change"
        );
        assert!(
            app.rt
                .results
                .curve
                .iter()
                .flat_map(|c| c.rows.iter().flatten())
                .all(|r| r.readout == "global-reset")
        );
    }

    // the PSD: add a natural mode, then remove it again
    h.state_mut().settings.view.auto_curve = false;
    h.get_by_label("natural modes (8)").click();
    h.run();
    h.get_by_label("add mode").click();
    wait_idle(&mut h, "the added mode");
    assert_eq!(h.state().settings.cfg.ace.modes.len(), 9);
    assert_current(&h);
    let dels = h.get_all_by_label("del").count();
    assert_eq!(dels, 9);
    h.get_all_by_label("del")
        .last()
        .expect("a del button")
        .click();
    wait_idle(&mut h, "the removed mode");
    assert_eq!(
        h.state().settings.cfg.ace.modes,
        Config::default().ace.modes
    );
    assert_current(&h);
}

/// The instrument control: "as built" images with the typical deviations (the engine's default), "as designed"
/// with none (`--instrument design`); each change reruns the frame with the configuration on screen.
#[test]
fn the_instrument_control_chooses_the_design_or_the_instrument_as_built() {
    let mut h = harness(small_app(), false);
    wait_idle(&mut h, "the first results");
    assert!(h.state().settings.cfg.as_built.has_no_deviation());
    h.get_by_label("as built").click();
    wait_idle(&mut h, "the instrument as built");
    {
        let a = &h.state().settings.cfg.as_built;
        let typical = engine::config::AsBuilt::default();
        assert_eq!(
            (a.wavefront_rms_nm, a.distortion_px, a.gain_error),
            (
                typical.wavefront_rms_nm,
                typical.distortion_px,
                typical.gain_error
            )
        );
    }
    assert_current(&h);
    h.get_by_role_and_label(Role::Slider, "wavefront off the design [nm rms]")
        .set_value_accesskit(50.0);
    wait_idle(&mut h, "a larger wavefront deviation");
    assert_eq!(h.state().settings.cfg.as_built.wavefront_rms_nm, 50.0);
    assert_current(&h);
    h.get_by_label("as designed").click();
    wait_idle(&mut h, "the design");
    assert!(h.state().settings.cfg.as_built.has_no_deviation());
    assert_current(&h);
}

#[test]
fn cancel_stops_the_work_and_drops_its_results() {
    // a curve long enough to be caught running: 4 magnitudes × 12 images
    let mut app = small_app();
    app.settings.cfg.fidelity.images = 12;
    app.settings.cfg.ace.span_s = 200.0;
    app.set_mags(vec![12.0, 12.5, 13.0, 13.5]);
    let mut h = harness(app, false);
    let t0 = Instant::now();
    loop {
        h.step();
        let p = h.state().rt.status.progress.as_ref().map(|p| p.stage);
        if p == Some(app::worker::Stage::Curve) {
            break;
        }
        assert!(
            h.state().rt.status.busy,
            "the curve should still be running"
        );
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "timed out waiting for the curve"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_current(&h);
    let generation = h.state().rt.generation;
    h.get_by_label("Cancel").click_accesskit();
    h.step();
    assert!(h.state().is_idle(), "Cancel leaves the app idle");
    assert!(h.state().rt.generation > generation);
    let simulated = |h: &Harness<'_, ExplorerApp>| {
        h.state()
            .rt
            .results
            .curve
            .iter()
            .filter(|c| c.rows.is_some())
            .count()
    };
    let done = simulated(&h);
    assert!(done < 4, "the curve was cancelled before its end");
    // whatever the abandoned job still sends is dropped
    std::thread::sleep(Duration::from_millis(1500));
    h.run();
    assert_eq!(
        simulated(&h),
        done,
        "no result of the cancelled generation is shown"
    );
    h.get_by_label_contains("cancelled");

    // a change after the cancel runs again, for the new parameters
    h.state_mut().settings.view.auto_curve = false;
    h.get_by_role_and_label(Role::Slider, "ACE σ [mas]")
        .set_value_accesskit(150.0);
    wait_idle(&mut h, "the new σ");
    assert_eq!(h.state().settings.cfg.ace.sigma_mas, 150.0);
    assert_current(&h);
}

#[test]
fn config_files_errors_and_copy_as_cli() {
    let dir = std::env::temp_dir().join(format!("jsim-app-ui-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut app = small_app();
    app.settings.view.auto_curve = false;
    let mut h = harness(app, false);
    h.step();

    // a file that does not exist: the error is shown, nothing crashes
    let missing = dir.join("missing.toml");
    h.state_mut().settings.config_path = missing.display().to_string();
    h.get_by_label("Open config").click();
    h.step();
    h.step();
    h.get_by_label_contains("cannot read config file");

    // a bad value names its field
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[ace]\nsigma_mas = -5.0\n").expect("write");
    h.state_mut().settings.config_path = bad.display().to_string();
    h.get_by_label("Open config").click();
    h.step();
    h.step();
    h.get_by_label_contains("ace.sigma_mas");
    assert_eq!(
        h.state().settings.cfg,
        small_config(),
        "a bad file leaves the parameters alone"
    );

    // copy as CLI saves the configuration and puts the command on the clipboard
    let path = dir.join("explorer.toml");
    h.state_mut().settings.config_path = path.display().to_string();
    h.state_mut().settings.countermeasure = plate_poly3();
    h.step();
    h.get_by_label("Copy as CLI: experiment").click();
    h.step();
    let copied: Vec<String> = h
        .output()
        .platform_output
        .commands
        .iter()
        .filter_map(|c| match c {
            egui::OutputCommand::CopyText(t) => Some(t.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(copied.len(), 1, "{copied:?}");
    let cmd = &copied[0];
    assert!(cmd.starts_with("jsim experiment --config "), "{cmd}");
    assert!(
        cmd.contains("--readouts rolling") && cmd.contains("--aces realistic"),
        "{cmd}"
    );
    assert!(
        cmd.contains("--mags 12.5,13.5") && cmd.contains("--countermeasures none,plate-poly:3"),
        "{cmd}"
    );
    let saved = Config::load(&path).expect("the saved config loads");
    assert_eq!(
        saved,
        h.state().settings.cfg,
        "the file reproduces the parameters on screen"
    );
    assert!(cmd.contains(&path.display().to_string()));

    // and opening it in a fresh app restores the app's choices too
    let mut other = ExplorerApp::new(Config::default());
    other.settings.config_path = path.display().to_string();
    other.open_config();
    assert_eq!(other.settings.cfg, saved);
    assert_eq!(other.settings.countermeasure, plate_poly3());
    drop(h);
    std::fs::remove_dir_all(&dir).ok();
}

/// Choosing the mock bulge in the controls lays out the quad; the frame cell then shows the four arrays,
/// every star on the array the engine's placement put it on, and the cursor line names the array (or the
/// gap) and the RA, Dec under it.
#[test]
fn the_bulge_scene_shows_the_focal_plane_with_sky_positions() {
    let mut cfg = small_config();
    cfg.ace.case = engine::config::AceCase::Gaussian;
    cfg.scene.bulge.density_per_arcmin2 = 20.0;
    let mut h = harness(ExplorerApp::new(cfg), false);
    wait_idle(&mut h, "the single-array frame");
    h.get_by_label("mock bulge").click();
    h.step();
    assert_eq!(
        h.state().settings.cfg.focal_plane.layout,
        engine::config::Layout::Quad,
        "the bulge comes on the quad"
    );
    wait_idle(&mut h, "the focal plane");
    h.get_by_label_contains("Focal plane #0 — 4 arrays");
    let app = h.state();
    let f = app
        .rt
        .results
        .focal_plane
        .as_ref()
        .expect("a focal-plane exposure");
    assert_eq!(f.cfg_hash, app.settings.cfg.hash_hex());
    assert_eq!(f.arrays.len(), 4);
    let mut stars = 0;
    for (k, a) in f.arrays.iter().enumerate() {
        for &(fx, fy) in &a.stars_fp {
            match f.plane.locate(fx, fy) {
                engine::sky::focal_plane::Placement::Photosensitive { array, .. } => {
                    assert_eq!(array, k, "a star of array {k} drawn at ({fx}, {fy})")
                }
                other => panic!("a star of array {k} drawn at ({fx}, {fy}): {other:?}"),
            }
            stars += 1;
        }
        let (cx, cy) = f.plane.centre(k);
        let line = app::panels::focal::describe(f, cx, cy);
        assert!(
            line.starts_with(&format!("array {} pixel", k + 1)) && line.contains("Dec"),
            "{line}"
        );
    }
    assert!(stars > 100, "{stars} stars");
    // the analysis cells show the engine's crowded-field analysis of this exposure: a map per array and
    // the magnitude bins over all four
    h.get_by_label_contains("Deviations per array");
    h.get_by_label_contains("One crowded exposure");
    let c = app
        .rt
        .results
        .crowded
        .as_ref()
        .expect("a crowded-field analysis");
    assert_eq!(c.cfg_hash, app.settings.cfg.hash_hex());
    assert_eq!(c.vectors.len(), 4);
    assert_eq!(c.summaries.len(), 4);
    let found: usize = c.bins.iter().map(|b| b.n_found).sum();
    let truth: usize = c.bins.iter().map(|b| b.n_true).sum();
    assert!(found > 50 && found <= truth, "{found} of {truth} found");
    assert!(app::panels::focal::describe(f, 0.0, 0.0).contains("gap"));
    let far = 3.0 * f.plane.array_px as f64;
    assert!(app::panels::focal::describe(f, far, 0.0).contains("off the focal plane"));
    // a click on a star of array 2 chooses it: its close-up and array 2's own ePSF; the status line shows
    // the predicted and the measured accuracy of the quad
    assert_eq!(c.fits.len(), 4);
    let s = c.fits[1]
        .stars
        .iter()
        .find(|s| s.hw.is_finite())
        .copied()
        .expect("a matched star on array 2");
    let (fx, fy) = c.plane.to_focal_plane(1, s.x_px, s.y_px);
    let star = app::panels::quad::nearest_star(c, fx + 0.3, fy - 0.2, 12.0).expect("the star");
    assert_eq!(star.0, 1, "the click lands on array 2");
    assert!(
        app::panels::quad::nearest_star(c, 0.0, 0.0, 12.0).is_none(),
        "the gap has no star"
    );
    h.state_mut().settings.view.quad_star = Some(star);
    h.step();
    h.step();
    h.get_by_label_contains(&format!("Array 2 star #{} close-up", star.1));
    h.get_by_label_contains("Array 2 ePSF");
    h.get_by_label_contains("true Hw");
    h.get_by_label_contains("Measured accuracy (focal plane, isolated stars Hw");
    let p = h
        .state()
        .rt
        .results
        .prediction
        .as_ref()
        .expect("a prediction in quad mode");
    assert_eq!(p.cfg_hash, h.state().settings.cfg.hash_hex());
    assert!(
        p.image_mas.is_finite() && p.image_mas > 0.0,
        "{}",
        p.image_mas
    );
}

#[test]
fn main_window_snapshot() {
    let mut h = harness(small_app(), true);
    wait_idle(&mut h, "the first results");
    assert_current(&h);
    // wall-clock timings differ from run to run
    let timing = h.get_by_label_contains("timing:").rect();
    h.mask(timing);
    h.snapshot("main_window");
}

/// A tiny sequence directory as `jsim sequence` and `jsim solve` write it (their exact headers): 4 × 3
/// coverage cells, the precision of 2 magnitude bins at N = 1, 2, 4 (a parallax at 2 and 4), and array 1's
/// 9 × 9 calibration map whose
/// residual is ±0.01 px in x and ±0.005 px in y (rms 0.01 / 0.005 px); config.toml empty (the default
/// instrument's plate scale).
fn write_sequence(dir: &std::path::Path) {
    std::fs::create_dir_all(dir.join("solution")).expect("sequence dir");
    let mut coverage = String::from("l_deg,b_deg,exposures\n");
    for j in 0..3 {
        for i in 0..4 {
            let (l, b) = (-0.015 + 0.01 * i as f64, -0.01 + 0.01 * j as f64);
            coverage.push_str(&format!("{l},{b},{}\n", (i + j) % 4 * 3));
        }
    }
    std::fs::write(dir.join("coverage.csv"), coverage).expect("coverage.csv");
    let mut precision = String::from(
        "exposures,hw_lo,hw_hi,sources,observations,position_rms_mas,position_robust_mas,\
         outlier_fraction,position_sigma_mas,single_exposure_mas,sqrt_n_mas,pm_rms_mas_per_yr,\
         pm_sigma_mas_per_yr,parallax_rms_mas,parallax_sigma_mas\n",
    );
    for n in [1, 2, 4] {
        for (lo, single) in [(10, 2.0), (12, 6.0)] {
            let s = single / (n as f64).sqrt();
            // a parallax from N = 2 on (one exposure spans no time)
            let parallax = if n > 1 {
                format!("{},{}", 1.5 * s, 1.4 * s)
            } else {
                "NaN,NaN".into()
            };
            precision.push_str(&format!(
                "{n},{lo},{},40,{n},{},{},0,{},{single},{s},NaN,NaN,{parallax}\n",
                lo + 1,
                1.2 * s,
                1.1 * s,
                0.9 * s
            ));
        }
    }
    std::fs::write(dir.join("solution/precision_vs_n.csv"), precision).expect("precision");
    let mut map = String::from(
        "array,x_px,y_px,u_px,v_px,true_dx_px,true_dy_px,solved_dx_px,solved_dy_px,residual_dx_px,\
         residual_dy_px\n",
    );
    for j in 0..9 {
        for i in 0..9 {
            let (x, y) = ((i as f64 + 0.5) * 64.0, (j as f64 + 0.5) * 64.0);
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            map.push_str(&format!(
                "1,{x},{y},{},{},0.5,-0.3,0.49,-0.29,{},{}\n",
                x - 600.0,
                y - 600.0,
                0.01 * sign,
                -0.005 * sign
            ));
        }
    }
    std::fs::write(dir.join("solution/calibration_map.csv"), map).expect("calibration map");
    std::fs::write(dir.join("config.toml"), "").expect("config.toml");
}

/// The sequence view, opened through its directory field: the coverage map, the precision against N and
/// the distortion residual with its rms in mas; a directory that does not exist shows the named error.
#[test]
fn the_sequence_view_shows_a_solved_sequence() {
    let dir = std::env::temp_dir().join(format!("jsim-app-sequence-{}", std::process::id()));
    write_sequence(&dir);
    let mut app = ExplorerApp::new(small_config());
    app.settings.view.central = app::settings::CentralView::Sequence;
    let mut h = harness(app, false);
    h.run();
    h.get_by_label_contains("open a sequence's directory");
    let field = h.get_by_role_and_label(Role::TextInput, "sequence directory");
    field.focus();
    field.type_text(&dir.display().to_string());
    h.run();
    assert_eq!(h.state().settings.sequence_dir, dir.display().to_string());
    h.get_by_label("Open sequence").click();
    h.run();
    h.get_by_label_contains("Coverage: exposures per sky cell");
    h.get_by_label_contains("at most 9");
    h.get_by_label_contains("Precision against the number of exposures N");
    h.get_by_label_contains("Hw 10–11");
    h.get_by_label_contains("Hw 12–13");
    h.get_by_label_contains("Parallax error against N and against magnitude");
    let scale = Config::default().instrument.plate_scale_mas();
    h.get_by_label_contains(&format!(
        "Distortion residual: solved − true, gauge removed — rms {:.3} / {:.3} mas",
        0.01 * scale,
        0.005 * scale
    ));
    h.get_by_label_contains("array 1:");
    assert!(
        h.state().is_idle(),
        "the sequence view starts no simulation"
    );
    assert_eq!(h.state().rt.jobs_sent, 0);

    // not solved yet: the coverage, and the command that solves it
    std::fs::remove_dir_all(dir.join("solution")).expect("rm solution");
    h.get_by_label("Open sequence").click();
    h.run();
    h.get_by_label_contains("Coverage: exposures per sky cell");
    assert_eq!(
        h.get_all_by_label_contains("not solved yet: jsim solve --sequence")
            .count(),
        3
    );
    drop(h);
    std::fs::remove_dir_all(&dir).ok();

    // from the command line: a directory that does not exist is named in the view
    let missing = std::env::temp_dir().join(format!("jsim-app-no-sequence-{}", std::process::id()));
    let app = ExplorerApp::from_args(
        None,
        ["--sequence".into(), missing.clone().into_os_string()].into_iter(),
    );
    assert_eq!(
        app.settings.view.central,
        app::settings::CentralView::Sequence
    );
    let mut h = harness(app, false);
    h.run();
    h.get_by_label_contains(&format!(
        "Cannot show the sequence: {}: no such directory",
        missing.display()
    ));
    assert_eq!(h.state().rt.jobs_sent, 0);
}

/// The transit view: its first stare shows the light curve, the box found and the noise budget; a change of
/// the intra-pixel amplitude reruns the stare with it.
#[test]
fn the_transit_view_reruns_its_stare_when_a_knob_changes() {
    let mut app = ExplorerApp::new(small_config());
    app.settings.view.central = app::settings::CentralView::Transit;
    app.settings.transit.hours = 1.8;
    app.settings.transit.comparisons = 3;
    app.settings.transit.depth = 0.01;
    let mut h = harness(app, false);
    let wait = |h: &mut Harness<'_, ExplorerApp>| {
        let t0 = Instant::now();
        loop {
            h.step();
            if !h.state().rt.transit.busy && h.state().rt.transit.shown.is_some() {
                break;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(300),
                "timed out waiting for the stare"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        h.run();
    };
    wait(&mut h);
    if let Some(Err(e)) = &h.state().rt.transit.shown {
        panic!("the stare failed: {e}");
    }
    h.get_by_label_contains("Light curve: 514 plates");
    h.get_by_label_contains("box found:");
    h.get_by_label_contains("Noise budget (ppm)");
    h.get_by_label_contains("jitter x intra-pixel");
    let first = h.state().rt.transit.requested.clone();
    h.state_mut().settings.transit.intra_pixel_amplitude = 0.3;
    h.step();
    assert!(h.state().rt.transit.busy, "a new stare runs");
    wait(&mut h);
    let second = h.state().rt.transit.requested.clone();
    assert_ne!(first, second);
    assert_eq!(
        second.map(|(_, c)| c.intra_pixel_amplitude),
        Some(0.3),
        "the stare ran with the new amplitude"
    );
    assert_eq!(
        h.state().rt.jobs_sent,
        0,
        "the exposure's work does not start"
    );
}
