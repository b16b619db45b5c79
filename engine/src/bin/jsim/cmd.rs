//! The command implementations (thin: the engine session does the work, `engine::io::products` knows the
//! files; here we print, write and show progress).

use crate::outputs::{Outputs, interrupted};
use anyhow::{Context, Result};
use engine::analysis::countermeasures::{Countermeasure, Plan};
use engine::analysis::report::StarResult;
use engine::config::{AceCase, Config, ReadoutOrder};
use engine::io::score::TruthFrame;
use engine::io::{analysis_input, calibrated, csv, products};
use engine::jitter::AceSeries;
use engine::scoring::vectors::VectorMap;
use engine::session::Session;
use engine::studies::experiment;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
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

/// Print the session's notes about the backend (once each).
pub(crate) fn say_notes(session: &Session) {
    for note in session.take_notes() {
        eprintln!("jsim: {note}");
    }
}

/// `jsim psf`
pub fn psf(session: &Session, cfg: &Config, out: &Path) -> Result<()> {
    let t0 = Instant::now();
    let bank = session.bank(cfg);
    let psf = bank.get(cfg.scene.j_minus_h, &bank.centre_key());
    let elapsed = t0.elapsed().as_secs_f64();
    let outputs = Outputs::for_file(out)?;
    products::write_psf(out, cfg, &psf)?;
    outputs.keep();
    let n = psf.n();
    println!(
        "wrote {} ({n}×{n} cells, {} per pixel, {} wavelengths, FWHM {:.1} mas, {:.2} % of the flux inside the table) in {elapsed:.2} s",
        out.display(),
        psf.oversampling,
        cfg.band.wavelength_grid().len(),
        psf.fwhm_px() * cfg.instrument.plate_scale_mas(),
        100.0 * psf.sum()
    );
    Ok(())
}

/// `jsim ace`
pub fn ace(cfg: &Config, out: &Path, every: usize) -> Result<()> {
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
    let outputs = Outputs::for_file(out)?;
    csv::write(out, &["t_s", "x_mas", "y_mas"], &rows)?;
    outputs.keep();
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

/// Options of `jsim analyze`.
pub struct AnalyzeArgs {
    pub image: PathBuf,
    pub truth: Option<PathBuf>,
    pub flat: Option<PathBuf>,
    pub refcat: Option<PathBuf>,
    pub telemetry: Option<PathBuf>,
    pub zones: Option<usize>,
    pub countermeasure: Countermeasure,
    /// How a calibrated (HST, JWST) file's data are read, where its header is silent or wrong.
    pub calibrated: engine::io::calibrated::ReadOptions,
    /// The cosmic-ray rejection by comparison of a calibrated file's exposures of one pointing (`None`: off).
    pub cr_rejection: Option<engine::analysis::repeat::Rejection>,
    /// L.A.Cosmic on a calibrated file's single exposures (`None`: off).
    pub lacosmic: Option<engine::analysis::lacosmic::LaCosmic>,
    pub out: PathBuf,
}

/// `jsim analyze`: the analysis pipeline on one image and the instrument products beside it. `cfg` gives
/// the analysis knobs; the image's own configuration (its CONFIG extension) serves only the `exact-epsf`
/// control (an oracle).
pub fn analyze(session: &Session, cfg: &Config, a: &AnalyzeArgs) -> Result<()> {
    let arrays = analysis_input::focal_plane_arrays(&a.image)?;
    if !arrays.is_empty() {
        let parts: Vec<Part> = arrays
            .iter()
            .enumerate()
            .map(|(k, n)| Part {
                label: n.clone(),
                dir: n.clone(),
                number: k as i64 + 1,
            })
            .collect();
        let read = |k: usize| {
            analysis_input::AnalysisInput::read_array(
                &a.image,
                k,
                a.truth.as_deref(),
                a.flat.as_deref(),
                a.refcat.as_deref(),
                a.telemetry.as_deref(),
                cfg,
            )
        };
        return analyze_parts(session, cfg, a, &parts, "arrays", &read, None);
    }
    if !calibrated::primary_is_image(&a.image)? {
        return crate::calibrated_cmd::analyze_calibrated(session, cfg, a);
    }
    let t0 = Instant::now();
    let input = analysis_input::AnalysisInput::read_products(
        &a.image,
        a.truth.as_deref(),
        a.flat.as_deref(),
        a.refcat.as_deref(),
        a.telemetry.as_deref(),
        cfg,
    )?;
    let assumptions = input.assumptions_for(&a.countermeasure);
    for s in &assumptions {
        eprintln!("jsim: {}: {s}", a.image.display());
    }
    let an = session.analyze_input(cfg, &input, a.zones, a.countermeasure)?;
    let analysis_input::AnalysisInput {
        img,
        truth,
        plate_scale_mas: scale,
        ..
    } = input;
    let an = &an;
    let mut outputs = Outputs::in_dir(&a.out)?;
    for name in [
        engine::io::products::files::CATALOGUE_CSV,
        engine::io::products::files::EPSF_FITS,
        engine::io::products::files::SUMMARY_JSON,
        engine::io::products::files::VECTORS_CSV,
        engine::io::products::files::VECTORS_PNG,
    ] {
        outputs.path(name);
    }
    let title = format!(
        "{} — deviations ({})",
        a.image.display(),
        an.report.countermeasure
    );
    let map = VectorMap::new(&an.stars, scale);
    let summary = products::Summary {
        image: a.image.display().to_string(),
        plate_scale_mas: scale,
        countermeasure: &an.report.countermeasure,
        report: &an.report,
        assumptions,
        calibration: None,
        seconds: t0.elapsed().as_secs_f64(),
    };
    products::write_analysis(
        &a.out,
        an,
        &summary,
        truth
            .is_some()
            .then_some((&map, img.nx as f64, title.as_str())),
        None,
    )?;
    outputs.keep();
    let r = &an.report;
    if !r.accuracy_mas.is_finite() {
        print_report(
            &a.image.display().to_string(),
            r,
            truth.is_some(),
            t0.elapsed().as_secs_f64(),
        );
        return Ok(());
    }
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
    pub aces: Vec<AceCase>,
    pub readouts: Vec<ReadoutOrder>,
    pub mags: Vec<f64>,
    pub plan: Plan,
    pub out: PathBuf,
}

/// `jsim experiment`
pub fn experiment(session: &Session, base: &Config, a: &ExperimentArgs) -> Result<()> {
    let t0 = Instant::now();
    let datasets = experiment::grid(base, &a.aces, &a.readouts, &a.mags);
    // a control that applies to none of the datasets would write an empty table and look like a result
    if a.plan.countermeasures.contains(&Countermeasure::ExactEpsf)
        && datasets.iter().all(|c| c.ace.case == AceCase::Realistic)
    {
        anyhow::bail!(
            "--countermeasures exact-epsf: the exact-ePSF control needs a static ACE (--aces gaussian or \
             none); every dataset here has a realistic ACE"
        );
    }
    let mut outputs = Outputs::in_dir(&a.out)?;
    for name in [
        engine::io::products::files::EXPERIMENT_CSV,
        engine::io::products::files::IMAGES_CSV,
        engine::io::products::files::ACCURACY_PNG,
    ] {
        outputs.path(name);
    }
    let total = (datasets.len() * base.fidelity.images) as u64;
    let pb = progress(total, "experiment");
    let mut rows = Vec::new();
    let mut image_rows: Vec<Vec<csv::Cell>> = Vec::new();
    for cfg in &datasets {
        pb.set_message(format!(
            "{} {} {}",
            cfg.ace.case.name(),
            cfg.readout.order.name(),
            cfg.scene.mag_hw
        ));
        interrupted()?;
        let sim = session.new_simulator(cfg)?;
        pb.suspend(|| say_notes(session));
        let (r, images) = experiment::run_dataset(&sim, &a.plan, &mut |_| {
            pb.inc(1);
            // a Ctrl-C stops between images (the outputs guard removes what was written)
            if interrupted().is_err() {
                std::ops::ControlFlow::Break(())
            } else {
                std::ops::ControlFlow::Continue(())
            }
        })?;
        image_rows.extend(products::image_rows(cfg, &images));
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
            let map = VectorMap::new(stars, cfg.instrument.plate_scale_mas());
            outputs.path(&format!("{stem}.csv"));
            outputs.path(&format!("{stem}.png"));
            pb.suspend(|| {
                products::write_vectors(
                    &a.out,
                    &stem,
                    &map,
                    cfg.instrument.detector_px as f64,
                    &title,
                )
            })?;
        }
        rows.extend(r);
    }
    pb.finish_and_clear();
    products::write_experiment(
        &a.out.join(engine::io::products::files::EXPERIMENT_CSV),
        &rows,
    )?;
    products::write_images(
        &a.out.join(engine::io::products::files::IMAGES_CSV),
        &image_rows,
    )?;
    products::plot_accuracy(
        &a.out.join(engine::io::products::files::ACCURACY_PNG),
        &rows,
    )?;
    outputs.keep();
    println!("{}", experiment::render_table(&rows));
    println!(
        "wrote {}/experiment.csv, images.csv, accuracy.png in {:.1} s",
        a.out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `jsim predict`
pub fn predict(session: &Session, cfg: &Config, plan: &Plan) -> Result<()> {
    let t0 = Instant::now();
    let sim = session.new_simulator(cfg)?;
    let setup = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let p = engine::studies::predict::Predictor::new(&sim, &cfg.analysis)?;
    println!(
        "Hw {} {} ACE, {} readout, {} images:",
        cfg.scene.mag_hw,
        cfg.ace.case.name(),
        cfg.readout.order.name(),
        cfg.fidelity.images
    );
    for c in &plan.countermeasures {
        let v = p.predict(c).with_context(|| format!("predicting {c}"))?;
        println!("  {:<14} predicted accuracy {v:7.2} mas", c.to_string());
    }
    println!(
        "prediction {:.0} ms (after {:.2} s building the PSF and the ACE series, shared with a simulation)",
        t1.elapsed().as_secs_f64() * 1e3,
        setup
    );
    Ok(())
}

/// Options of `jsim score`.
#[derive(clap::Args, Clone, Debug)]
pub struct ScoreArgs {
    /// Measured catalogue: a CSV with x, y in pixels (e.g. `catalogue.csv` of `jsim analyze`; rows flagged
    /// as rejected are left out).
    #[arg(long, value_name = "CSV")]
    pub catalogue: PathBuf,
    /// Truth: a CSV with x, y and mag (or mag_hw, hw), or a jsim image whose TRUTH extension gives them.
    #[arg(long, value_name = "CSV|FITS")]
    pub truth: PathBuf,
    /// Plate scale [mas/px] for the accuracies (default: `plate_scale_mas` of the summary.json beside the
    /// catalogue).
    #[arg(long)]
    pub plate_scale_mas: Option<f64>,
    /// Match radius [px] after the common offset is removed.
    #[arg(long, default_value_t = engine::scoring::DEFAULT_MATCH_RADIUS_PX)]
    pub match_radius_px: f64,
    /// Search radius [px] of the common offset (median displacement to the nearest true star).
    #[arg(long, default_value_t = engine::scoring::DEFAULT_OFFSET_SEARCH_PX)]
    pub offset_search_px: f64,
    /// Width of the magnitude bins.
    #[arg(long, default_value_t = 1.0)]
    pub bin_mag: f64,
    /// The truth's frame: `image` (x, y: where the stars landed), `header` (x_header, y_header: their true
    /// sky places through the header's design WCS, the frame of a catalogue referenced to the reference
    /// catalogue) or `auto` (header when the summary.json beside the catalogue names a `…@catalogue`
    /// countermeasure and the truth has the columns, else image).
    #[arg(long, value_enum, default_value_t = FrameArg::Auto)]
    pub frame: FrameArg,
    /// Output directory (score.csv, score.json).
    #[arg(long, default_value = "out/score")]
    pub out: PathBuf,
}

/// `jsim score --frame`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameArg {
    Auto,
    Image,
    Header,
}

/// The `summary.json` beside a catalogue, if any.
fn summary_beside(catalogue: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(
        catalogue
            .parent()?
            .join(engine::io::products::files::SUMMARY_JSON),
    )
    .ok()?;
    serde_json::from_str(&text).ok()
}

/// The plate scale recorded in the `summary.json` beside a catalogue, if any.
fn summary_plate_scale(catalogue: &Path) -> Option<f64> {
    summary_beside(catalogue)?.get("plate_scale_mas")?.as_f64()
}

/// The frame `jsim score` scores in ([`FrameArg`]), and why.
fn score_frame(a: &ScoreArgs) -> (TruthFrame, &'static str) {
    match a.frame {
        FrameArg::Image => (TruthFrame::Image, "--frame image"),
        FrameArg::Header => (TruthFrame::Header, "--frame header"),
        FrameArg::Auto => {
            let referenced = summary_beside(&a.catalogue)
                .and_then(|v| v.get("countermeasure")?.as_str().map(str::to_string))
                .and_then(|c| c.parse::<Countermeasure>().ok())
                .is_some_and(|c| c.is_catalogue_plate());
            match (
                referenced,
                engine::io::score::truth_has_header_frame(&a.truth),
            ) {
                (true, true) => (
                    TruthFrame::Header,
                    "the catalogue is referenced to the reference catalogue (summary.json) and the \
                     truth carries the header's frame",
                ),
                (true, false) => (
                    TruthFrame::Image,
                    "the catalogue is referenced to the reference catalogue, but the truth has no header \
                     frame: the header is the instrument as built",
                ),
                _ => (TruthFrame::Image, "the catalogue is in the image's frame"),
            }
        }
    }
}

/// `jsim score`
pub fn score(a: &ScoreArgs) -> Result<()> {
    // the inputs first: a missing file is the problem to name, not what its absence implies
    for (what, p) in [("--catalogue", &a.catalogue), ("--truth", &a.truth)] {
        if !p.is_file() {
            anyhow::bail!("{what} {}: no such file", p.display());
        }
    }
    let scale = match a
        .plate_scale_mas
        .or_else(|| summary_plate_scale(&a.catalogue))
    {
        Some(s) => s,
        None => anyhow::bail!(
            "--plate-scale-mas: not given, and no summary.json with plate_scale_mas beside {}",
            a.catalogue.display()
        ),
    };
    let opts = engine::scoring::ScoreOptions {
        match_radius_px: a.match_radius_px,
        offset_search_px: a.offset_search_px,
        bin_mag: a.bin_mag,
        plate_scale_mas: scale,
    };
    opts.validate()
        .map_err(|e| anyhow::anyhow!("--{}", e.replace('_', "-")))?;
    let measured = engine::io::score::read_measured(&a.catalogue)?;
    let (frame, why) = score_frame(a);
    let truth = engine::io::score::read_truth_list(&a.truth, frame)?;
    let s = engine::scoring::score(&measured, &truth, &opts).map_err(anyhow::Error::msg)?;
    let mut outputs = Outputs::in_dir(&a.out)?;
    for name in [
        engine::io::products::files::SCORE_CSV,
        engine::io::products::files::SCORE_JSON,
    ] {
        outputs.path(name);
    }
    engine::io::score::write_score(&a.out, &s, &a.catalogue, &a.truth)?;
    outputs.keep();
    let acc = |v: f64| {
        if v.is_finite() {
            format!("{v:8.2}")
        } else {
            format!("{:>8}", "–")
        }
    };
    println!(
        "{} measured, {} true stars; {} matched, {} false detections; common offset ({:.3}, {:.3}) px",
        s.n_measured,
        s.all.n_true,
        s.all.n_matched,
        s.false_detections,
        s.offset_x_px,
        s.offset_y_px
    );
    let [fx, fy] = frame.columns();
    println!("scored against the truth's {fx}, {fy}: {why}");
    println!("  mag bin      true  matched  scored  complete  accuracy [mas]");
    for b in s.bins.iter().chain(std::iter::once(&s.all)) {
        println!(
            "  {:5.1}–{:<5.1} {:6} {:8} {:7} {:9.3} {}",
            b.mag_lo,
            b.mag_hi,
            b.n_true,
            b.n_matched,
            b.n_scored,
            b.completeness,
            acc(b.accuracy_mas)
        );
    }
    println!("wrote {}/score.csv, score.json", a.out.display());
    Ok(())
}

/// One image of a multi-image file: an array of a focal plane (`ARRAY2`) or a chip of a calibrated file
/// (`SCI,2`, written to `SCI2/`).
pub struct Part {
    pub label: String,
    pub dir: String,
    /// The `array` column of the combined catalogue: the array's number, the chip's EXTVER.
    pub number: i64,
}

/// What a caller of [`analyze_parts`] adds to its outputs once every part is analysed: it gets each part's
/// fits and the outputs' guard (to declare the files it writes).
pub type Finish<'a> = &'a dyn Fn(&[Vec<StarResult>], &mut Outputs) -> Result<()>;

/// An array's scored stars, its truth and its size (px), for the accuracy against magnitude.
type ScoredArray = (
    Vec<engine::scoring::image::ScoredStar>,
    Vec<engine::truth::TruthRow>,
    usize,
);

/// The parts' catalogue rows in one table (`array` first); with `with_sky` the RA/Dec columns, NaN for a
/// part without a WCS.
fn write_combined_catalogue(
    path: &std::path::Path,
    mut rows: Vec<Vec<csv::Cell>>,
    with_sky: bool,
) -> Result<()> {
    let mut header = vec!["array"];
    header.extend(products::CATALOGUE_HEADER);
    if with_sky {
        header.extend(products::SKY_HEADER);
        for r in rows.iter_mut() {
            r.resize(header.len(), csv::Cell::F(f64::NAN));
        }
    }
    csv::write(path, &header, &rows)?;
    Ok(())
}

/// With every array's truth: the accuracy against magnitude as `jsim crowded` reports it (its bins, its
/// classes, the same file, `crowded_bins.csv`); `None` when an array has no truth.
fn accuracy_bins(
    cfg: &Config,
    a: &AnalyzeArgs,
    scored: &[Option<ScoredArray>],
    scale: f64,
    outputs: &mut Outputs,
) -> Result<Option<Vec<engine::scoring::crowded::MagBin>>> {
    let Some(arrays) = scored
        .iter()
        .map(|o| o.as_ref())
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(None);
    };
    let views: Vec<engine::scoring::crowded::ArrayStars<'_>> = arrays
        .iter()
        .map(
            |(stars, truth, n_px)| engine::scoring::crowded::ArrayStars {
                stars,
                truth,
                n_px: *n_px,
                // the undetected stars' shifts are `jsim crowded`'s (they need the arrays' ePSFs)
                undetected: None,
            },
        )
        .collect();
    let b = &cfg.scene.bulge;
    let edges = engine::scoring::crowded::edges(b.hw_min, b.hw_max, 0.5);
    let bins = engine::scoring::crowded::mag_bins(&views, scale, &edges);
    let path = a.out.join(engine::io::products::files::CROWDED_BINS_CSV);
    outputs.add(&path);
    engine::io::crowded::write_table(
        &path,
        &engine::io::crowded::BINS_HEADER,
        &engine::io::crowded::bin_rows("image", &a.countermeasure.to_string(), &bins),
    )?;
    Ok(Some(bins))
}

/// `jsim analyze` on a file of several images: each part (a focal plane's `ARRAY1` … with its own flat
/// `FLAT1` …, or a calibrated file's chips) analysed alone and written to `OUT/<part>/`, and the parts
/// together: `OUT/catalogue.csv` (every part's stars with an `array` column) and `OUT/summary.json` (each
/// part's report and the combined one); then `finish`, if any.
pub fn analyze_parts(
    session: &Session,
    cfg: &Config,
    a: &AnalyzeArgs,
    parts: &[Part],
    noun: &str,
    read: &dyn Fn(usize) -> std::result::Result<analysis_input::AnalysisInput, engine::io::IoError>,
    finish: Option<Finish<'_>>,
) -> Result<()> {
    let t0 = Instant::now();
    let mut outputs = Outputs::in_dir(&a.out)?;
    outputs.path(engine::io::products::files::CATALOGUE_CSV);
    outputs.path(engine::io::products::files::SUMMARY_JSON);
    let mut per_array = Vec::new();
    let mut rows = Vec::new();
    let mut fits: Vec<Vec<StarResult>> = Vec::new();
    let mut all_stars = Vec::new();
    let mut all_crowded = true;
    let mut with_sky_columns = false;
    let mut scale = f64::NAN;
    // each array's stars, truth and size, for the accuracy against magnitude when every array has a truth
    let mut scored: Vec<Option<ScoredArray>> = Vec::new();
    for (k, part) in parts.iter().enumerate() {
        let name = &part.label;
        let t = Instant::now();
        let input = read(k)?;
        let assumptions = input.assumptions_for(&a.countermeasure);
        for s in &assumptions {
            eprintln!("jsim: {}[{name}]: {s}", a.image.display());
        }
        let an = session
            .analyze_input(cfg, &input, a.zones, a.countermeasure)
            .with_context(|| format!("{}[{name}]", a.image.display()))?;
        scale = input.plate_scale_mas;
        let dir = a.out.join(&part.dir);
        for f in [
            engine::io::products::files::CATALOGUE_CSV,
            engine::io::products::files::EPSF_FITS,
            engine::io::products::files::SUMMARY_JSON,
        ] {
            outputs.add(&dir.join(f));
        }
        std::fs::create_dir_all(&dir).with_context(|| dir.display().to_string())?;
        let summary = products::Summary {
            image: format!("{}[{name}]", a.image.display()),
            plate_scale_mas: scale,
            countermeasure: &an.report.countermeasure,
            report: &an.report,
            assumptions: assumptions.clone(),
            calibration: input.chip.as_ref(),
            seconds: t.elapsed().as_secs_f64(),
        };
        // a calibrated chip's stars on the sky through its header's WCS
        let sky = match input.chip.as_ref().and_then(|c| c.wcs.as_ref()) {
            Some(w) => Some(w.projection().map_err(|e| {
                anyhow::anyhow!("{}[{name}]: the header's WCS: {e}", a.image.display())
            })?),
            None => None,
        };
        products::write_analysis(&dir, &an, &summary, None, sky.as_ref())?;
        let (part_header, part_rows) = products::catalogue_table(&an.stars, scale, sky.as_ref());
        with_sky_columns |= part_header.len() > products::CATALOGUE_HEADER.len();
        for mut r in part_rows {
            r.insert(0, csv::Cell::I(part.number));
            rows.push(r);
        }
        print_report(
            &summary.image,
            &an.report,
            input.truth.is_some(),
            t.elapsed().as_secs_f64(),
        );
        // the combined accuracy, like each array's, does not count an array's common offset: its bias goes
        let (bx, by) = (an.report.bias_x_mas / scale, an.report.bias_y_mas / scale);
        all_stars.extend(an.stars.iter().map(|s| engine::scoring::image::ScoredStar {
            dx_px: s.dx_px - if bx.is_finite() { bx } else { 0.0 },
            dy_px: s.dy_px - if by.is_finite() { by } else { 0.0 },
            ..*s
        }));
        all_crowded &= an.report.crowded;
        fits.push(an.stars.iter().map(|s| s.fit).collect());
        scored.push(
            input
                .truth
                .clone()
                .map(|t| (an.stars.clone(), t, input.img.nx)),
        );
        per_array.push(serde_json::json!({
            "array": name,
            "report": an.report,
            "assumptions": assumptions,
            "calibration": input.chip,
        }));
    }
    let combined = engine::scoring::image::summarise(
        &all_stars,
        None,
        scale,
        &engine::analysis::Report {
            n_detected: all_stars.len(),
            countermeasure: a.countermeasure.to_string(),
            crowded: all_crowded,
            ..Default::default()
        },
    );
    write_combined_catalogue(
        &a.out.join(engine::io::products::files::CATALOGUE_CSV),
        rows,
        with_sky_columns,
    )?;
    let bins = accuracy_bins(cfg, a, &scored, scale, &mut outputs)?;
    let json = serde_json::json!({
        "image": a.image.display().to_string(),
        "plate_scale_mas": scale,
        "arrays": per_array,
        "combined": combined,
        "seconds": t0.elapsed().as_secs_f64(),
    });
    engine::io::write_atomic(
        &a.out.join(engine::io::products::files::SUMMARY_JSON),
        serde_json::to_string_pretty(&json)?.as_bytes(),
    )?;
    if let Some(f) = finish {
        f(&fits, &mut outputs)?;
    }
    outputs.keep();
    print_report(
        &format!("{} (all {} {noun})", a.image.display(), parts.len()),
        &combined,
        combined.n_matched > 0,
        t0.elapsed().as_secs_f64(),
    );
    if let Some(bins) = bins {
        crate::crowded_cmd::print_bin_table(&bins);
        println!(
            "wrote {}",
            a.out
                .join(engine::io::products::files::CROWDED_BINS_CSV)
                .display()
        );
    }
    Ok(())
}

/// One line for an analysis report: the accuracy when it was scored, else why not.
fn print_report(what: &str, r: &engine::scoring::image::Report, has_truth: bool, seconds: f64) {
    let mode = if r.crowded {
        "crowded-field"
    } else {
        "isolated-star"
    };
    if r.accuracy_mas.is_finite() {
        println!(
            "{what}: {} stars ({mode}), {} used; accuracy {:.2} mas (x {:.2}, y {:.2}), median CRLB {:.2} mas [{}] in {seconds:.2} s",
            r.n_detected,
            r.n_used,
            r.accuracy_mas,
            r.accuracy_x_mas,
            r.accuracy_y_mas,
            r.crlb_median_mas,
            r.countermeasure,
        );
    } else {
        let why = if has_truth {
            format!(
                "{} star(s) matched to the truth and used, fewer than {}",
                r.n_used,
                engine::scoring::image::MIN_SCORED_STARS
            )
        } else {
            "no truth to score against (score catalogue.csv with `jsim score`)".to_string()
        };
        println!(
            "{what}: {} stars detected and fitted ({mode}); no accuracy: {why} [{}] in {seconds:.2} s",
            r.n_detected, r.countermeasure
        );
    }
}
