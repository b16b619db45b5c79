//! The per-image analysis pipeline: detect → global ePSF → fits → each countermeasure of a [`Plan`] → the
//! ACE prediction → report. `jsim analyze`, `jsim experiment`, the sweeps and the explorer all run
//! [`analyse_image`]; the pieces ([`analyze_prepared`], [`with_countermeasure`], [`analyze`]) are public for
//! the tests and for studies that need one step alone.

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::{self, Context, Countermeasure, Plan, Telemetry, stack};
use crate::analysis::detection::{detect, match_truth, starts};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart};
use crate::analysis::epsf::fit::{FitOptions, StarFit, fit_star, flags};
use crate::analysis::image::AnalysisImage;
use crate::analysis::report::{Report, StarResult, attach_fit_prediction, star_results, summarise};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::config::{AceCase, Analysis as AnalysisCfg};
use crate::integrate::kernel::PixelKernel;
use crate::simulate::{Simulator, TruthRow};
use rayon::prelude::*;
use std::sync::Arc;

/// Everything the analysis of one image produced.
#[derive(Debug, Clone)]
pub struct Analysis {
    pub report: Report,
    pub stars: Vec<StarResult>,
    pub epsf: Epsf,
}

/// Options of one analysis: the configured knobs, a countermeasure with what it needs, and an optional
/// fixed ePSF (the control).
#[derive(Debug, Clone)]
pub struct Options {
    pub cfg: AnalysisCfg,
    pub countermeasure: Countermeasure,
    /// The exposure's telemetry, for [`Countermeasure::Telemetry`] (none: nothing to correct).
    pub telemetry: Option<Arc<Telemetry>>,
    /// Seed of the reference catalogue's error draws (the simulation's seed).
    pub seed: u64,
    /// The reference catalogue product's positions (pixels of this image) for `plate-*@catalogue`; without
    /// one the reference is drawn from the truth with the plan's error (a simulation's).
    pub reference: Option<Vec<(f64, f64)>>,
    /// Fit with this ePSF instead of building one (e.g. the exact ePSF from the simulator).
    pub fixed_epsf: Option<Epsf>,
    /// The instrument's model PSF (pixel-integrated, from calibration), used when the image holds fewer
    /// than [`MIN_EPSF_STARS`] stars to build an ePSF from; without one a Gaussian fitted to the stars'
    /// second moments stands in.
    pub model_epsf: Option<Epsf>,
}

/// Fewest isolated, unsaturated stars an ePSF is built from. Each star samples one sub-pixel phase per
/// pixel of the 4× oversampled table; the builder's smoothing (zeros at whole cycles per pixel) fills the
/// rest well from 9 stars (`engine/tests/cli.rs` analyses a 3 × 3 grid to a few mas), not from 4.
pub const MIN_EPSF_STARS: usize = 5;

impl Options {
    pub fn new(cfg: &AnalysisCfg) -> Self {
        Self {
            cfg: cfg.clone(),
            countermeasure: Countermeasure::None,
            telemetry: None,
            seed: 0,
            reference: None,
            fixed_epsf: None,
            model_epsf: None,
        }
    }

    pub fn build_options(&self) -> BuildOptions {
        build_options(&self.cfg)
    }
}

/// The ePSF builder's options from the analysis configuration.
pub fn build_options(cfg: &AnalysisCfg) -> BuildOptions {
    BuildOptions {
        oversampling: cfg.epsf_oversampling,
        half_px: cfg.epsf_radius_px,
        iterations: cfg.epsf_iterations,
        smoothing: cfg.smoothing,
        clip_sigma: cfg.clip_sigma,
        fit: FitOptions {
            radius_px: cfg.fit_radius_px,
            max_iter: cfg.fit_max_iter,
            fit_sky: cfg.fit_sky,
        },
        recentre: true,
    }
}

/// What the global analysis of an image prepared: enough to apply further countermeasures to its fits
/// without detecting the stars and building the ePSF again.
#[derive(Debug, Clone)]
pub struct Prepared {
    pub starts: Vec<StarStart>,
    pub usable: Vec<bool>,
    pub build: BuildOptions,
    /// Zones of `yzones` without `:K`.
    pub default_zones: usize,
}

/// Analyse one image: detect, build (or take) the ePSF, fit, apply the countermeasure, report.
pub fn analyze(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    opts: &Options,
) -> Result<Analysis, AnalysisError> {
    let (plain, prepared) = analyze_prepared(img, truth, opts)?;
    with_countermeasure(
        img,
        truth,
        &plain,
        &prepared,
        &opts.countermeasure,
        opts.telemetry.as_deref(),
        opts.reference.as_deref(),
        opts.seed,
    )
}

/// The analysis without a countermeasure, and what it prepared for [`with_countermeasure`].
pub fn analyze_prepared(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    opts: &Options,
) -> Result<(Analysis, Prepared), AnalysisError> {
    analyze_prepared_with(img, truth, opts, &|| Ok(opts.model_epsf.clone()))
}

/// [`analyze_prepared`] with the model PSF of the few-star fallback made only when it is needed.
fn analyze_prepared_with(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    opts: &Options,
    model_epsf: &dyn Fn() -> Result<Option<Epsf>, AnalysisError>,
) -> Result<(Analysis, Prepared), AnalysisError> {
    let det = detect(img, opts.cfg.detect_sigma);
    if det.is_empty() {
        return Err(AnalysisError::NoStars(opts.cfg.detect_sigma));
    }
    let (starts, usable) = starts(img, &det, &opts.cfg);
    let initial: Vec<(f64, f64)> = starts.iter().map(|s| (s.x, s.y)).collect();
    let matches = match truth {
        Some(t) => match_truth(&initial, t),
        None => vec![None; initial.len()],
    };
    let bopt = opts.build_options();
    let pd = img.pixels();
    let n_build = usable.iter().filter(|u| **u).count();
    let fit_all = |e: &Epsf| -> Vec<StarFit> {
        starts
            .par_iter()
            .map(|s| fit_star(&pd, e, s.x, s.y, s.flux, s.sky, &bopt.fit))
            .collect()
    };
    let mut fallback = String::new();
    let (mut fits, epsf, iterations) = match &opts.fixed_epsf {
        Some(e) => (fit_all(e), e.clone(), 0),
        None if n_build < MIN_EPSF_STARS => {
            let (e, what) = match model_epsf()? {
                Some(m) => (m, "the instrument's model PSF"),
                None => (
                    build::gaussian_seed(&pd, &starts, bopt.oversampling, bopt.half_px),
                    "a Gaussian of the stars' mean second moment",
                ),
            };
            fallback = format!(
                "{n_build} isolated unsaturated star(s), fewer than {MIN_EPSF_STARS}: no ePSF built; \
                 fitted with {what}"
            );
            (fit_all(&e), e, 0)
        }
        None => {
            let built = build::build(&pd, &starts, &usable, &bopt, None, None);
            (built.fits, built.epsf, built.iterations)
        }
    };
    flags::mark_poor_fits(&mut fits);
    flags::mark_blends(&mut fits, flags::blend_radius_px(opts.cfg.fit_radius_px));
    let stars = star_results(&fits, &matches, truth);
    let mut report = Report {
        n_detected: det.len(),
        epsf_iterations: iterations,
        epsf_stars: n_build,
        epsf_fallback: fallback,
        countermeasure: Countermeasure::None.to_string(),
        ..Default::default()
    };
    summarise(&stars, truth, img.plate_scale_mas, &mut report);
    Ok((
        Analysis {
            report,
            stars,
            epsf,
        },
        Prepared {
            starts,
            usable,
            build: bopt,
            default_zones: opts.cfg.epsf_zones.max(2),
        },
    ))
}

/// The report of a countermeasure applied to a plain analysis, before its statistics: what the plain
/// analysis found (detections, the ePSF and how it was made) and the countermeasure's name.
fn countermeasure_report(plain: &Report, cm: &Countermeasure) -> Report {
    Report {
        n_detected: plain.n_detected,
        epsf_iterations: plain.epsf_iterations,
        epsf_stars: plain.epsf_stars,
        epsf_fallback: plain.epsf_fallback.clone(),
        countermeasure: cm.to_string(),
        ..Default::default()
    }
}

/// Apply a countermeasure to the plain analysis of an image (from [`analyze_prepared`]) and report.
pub fn with_countermeasure(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    plain: &Analysis,
    prepared: &Prepared,
    cm: &Countermeasure,
    telemetry: Option<&Telemetry>,
    reference: Option<&[(f64, f64)]>,
    seed: u64,
) -> Result<Analysis, AnalysisError> {
    let mut stars = plain.stars.clone();
    let mut report = countermeasure_report(&plain.report, cm);
    let ctx = Context {
        img,
        starts: &prepared.starts,
        usable: &prepared.usable,
        build: &prepared.build,
        global: &plain.epsf,
        truth,
        default_zones: prepared.default_zones,
        telemetry,
        reference,
        seed,
    };
    report.dof_absorbed = countermeasures::apply(cm, &ctx, &mut stars)?;
    if cm.needs_stare() {
        // the image alone is its own stack: nothing corrected until the stare is finished
        report.stare_exposures = 1;
    }
    summarise(&stars, truth, img.plate_scale_mas, &mut report);
    Ok(Analysis {
        report,
        stars,
        epsf: plain.epsf.clone(),
    })
}

/// The crowded-field analysis of one image ([`crate::analysis::crowded::analyse`]) as an [`Analysis`] of the
/// pipeline: its stars, its ePSF and a report (the accuracy only with a truth given), corrected by `cm` when
/// it is one that acts on the fitted positions alone — a plate model referenced to the reference catalogue
/// product (`reference`) or, `@oracle`, to the truth. The others are refused by name: those that refit
/// single stars (`yzones`, `exact-epsf`), the telemetry correction (it needs the simulation context of a
/// single-array jsim image: `jsim crowded` applies it) and a stack reference (a stare's).
pub fn analyze_crowded(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    cfg: &AnalysisCfg,
    model_epsf: Option<&Epsf>,
    cm: &Countermeasure,
    reference: Option<&[(f64, f64)]>,
    seed: u64,
) -> Result<Analysis, AnalysisError> {
    let applies = match cm {
        Countermeasure::None => true,
        Countermeasure::Plate {
            reference: countermeasures::Reference::Catalogue { .. },
            ..
        } => reference.is_some() || truth.is_some(),
        Countermeasure::Plate {
            reference: countermeasures::Reference::Oracle,
            ..
        } => truth.is_some(),
        _ => false,
    };
    if !applies {
        return Err(AnalysisError::NotInCrowdedField {
            countermeasure: cm.to_string(),
        });
    }
    let c = crate::analysis::crowded::analyse(img, cfg, model_epsf);
    if c.fits.is_empty() {
        return Err(AnalysisError::NoStars(cfg.crowded_detect_sigma));
    }
    let pos: Vec<(f64, f64)> = c.fits.iter().map(|f| (f.x, f.y)).collect();
    let matches = match truth {
        Some(t) => match_truth(&pos, t),
        None => vec![None; pos.len()],
    };
    let mut stars = star_results(&c.fits, &matches, truth);
    let mut report = Report {
        n_detected: c.fits.len(),
        epsf_iterations: c.epsf_iterations,
        epsf_stars: c.epsf_stars,
        epsf_fallback: c.fallback,
        countermeasure: cm.to_string(),
        crowded: true,
        ..Default::default()
    };
    if *cm != Countermeasure::None {
        let build = build_options(cfg);
        let ctx = Context {
            img,
            starts: &[],
            usable: &[],
            build: &build,
            global: &c.epsf,
            truth,
            default_zones: cfg.epsf_zones.max(2),
            telemetry: None,
            reference,
            seed,
        };
        report.dof_absorbed = countermeasures::apply(cm, &ctx, &mut stars)?;
    }
    summarise(&stars, truth, img.plate_scale_mas, &mut report);
    Ok(Analysis {
        report,
        stars,
        epsf: c.epsf,
    })
}

/// The exact ePSF of a static simulation: its pixel kernel (PSF ⊛ Gaussian ACE ⊛ pixel) sampled at 8 nodes
/// per pixel. Only meaningful when every star shares one kernel and the ACE is static.
pub fn exact_epsf(kernel: &PixelKernel, half_px: usize) -> Epsf {
    let mut e = Epsf::from_fn(8, half_px, |x, y| kernel.eval(x, y));
    e.normalise();
    e
}

/// What the instrument supplied beside an image (its products), for the analysis: the reference catalogue's
/// positions in the image's pixels (`plate-*@catalogue`) and the design model PSF (the fallback below
/// [`MIN_EPSF_STARS`] ePSF stars).
#[derive(Debug, Clone, Copy, Default)]
pub struct Supplied<'a> {
    pub reference: Option<&'a [(f64, f64)]>,
    pub model_psf: Option<&'a Epsf>,
    /// The attitude telemetry product: what the telemetry correction corrects with (its recorded quality
    /// replaces the plan's); without it the telemetry is recorded from the simulation's series.
    pub telemetry: Option<&'a countermeasures::telemetry::TelemetryRecord>,
}

/// The simulated exposure an image came from: what only a simulation knows (the ACE series behind the
/// telemetry and the ACE prediction, the exact ePSF of the control).
#[derive(Clone, Copy)]
pub struct Source<'a> {
    pub sim: &'a Simulator,
    /// The exposure's index in the simulator's dataset.
    pub index: usize,
}

impl Source<'_> {
    /// Noise parameters of a typical star's fit in this simulation, with the analysis' fit radius.
    fn fit_noise(&self, cfg: &AnalysisCfg) -> FitNoise {
        FitNoise::of_simulation(self.sim, cfg.fit_radius_px)
    }

    /// The exposure's telemetry of the given quality, `None` for a static ACE (nothing to correct).
    pub fn telemetry(
        &self,
        quality: &countermeasures::TelemetryQuality,
        cfg: &AnalysisCfg,
    ) -> Result<Option<Telemetry>, AnalysisError> {
        let Some(series) = self.sim.series() else {
            return Ok(None);
        };
        let sim = self.sim;
        Ok(Some(Telemetry::from_series(
            series,
            sim.timing,
            sim.exposure_start_s(self.index),
            sim.cfg.instrument.plate_scale_mas(),
            sim.array.rotation_deg,
            quality,
            sim.cfg.seed,
            &*sim.optical_kernel()?,
            &self.fit_noise(cfg),
        )?))
    }

    /// The exposure's telemetry from a recorded product (the response still from this simulation's optics
    /// and noise); `None` for a static ACE.
    pub fn telemetry_from_record(
        &self,
        rec: &countermeasures::telemetry::TelemetryRecord,
        cfg: &AnalysisCfg,
    ) -> Result<Option<Telemetry>, AnalysisError> {
        if self.sim.series().is_none() {
            return Ok(None);
        }
        let sim = self.sim;
        Ok(Some(Telemetry::from_record(
            rec,
            0.0,
            sim.timing,
            sim.cfg.instrument.plate_scale_mas(),
            sim.array.rotation_deg,
            &*sim.optical_kernel()?,
            &self.fit_noise(cfg),
        )?))
    }

    /// Attach to an analysis the fit displacement the true ACE predicts for every star (realistic ACE only;
    /// the mechanism, shown beside the measured errors) and refresh its report.
    pub fn attach_ace_prediction(
        &self,
        truth: &[TruthRow],
        analysis: &mut Analysis,
        cfg: &AnalysisCfg,
        plate_scale_mas: f64,
    ) -> Result<(), AnalysisError> {
        let sim = self.sim;
        if let Some(track) = sim.track(self.index) {
            let resp = FitResponse::build(
                &*sim.optical_kernel()?,
                &track,
                &sim.nominal_window(&track),
                &self.fit_noise(cfg),
            );
            let pos: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
            let pred = resp.displacements(&track, &sim.timing, &pos);
            attach_fit_prediction(&mut analysis.stars, &pred);
            summarise(
                &analysis.stars,
                Some(truth),
                plate_scale_mas,
                &mut analysis.report,
            );
        }
        Ok(())
    }
}

/// One image analysed under a plan.
#[derive(Debug, Clone)]
pub struct ImageAnalysis {
    /// The global-ePSF analysis, with the ACE prediction attached when the image is a simulated one with a
    /// realistic ACE (the result of countermeasure `none`).
    pub global: Analysis,
    /// One analysis per countermeasure of the plan that applies to this image, in plan order (`exact-epsf`
    /// applies only to a simulated image with a static ACE).
    pub measured: Vec<(Countermeasure, Analysis)>,
}

impl ImageAnalysis {
    /// The analysis of one countermeasure, if it applied.
    pub fn of(&self, cm: &Countermeasure) -> Option<&Analysis> {
        self.measured.iter().find(|(c, _)| c == cm).map(|(_, a)| a)
    }

    /// The analysis of one countermeasure, if it applied, taken out.
    pub fn into_of(self, cm: &Countermeasure) -> Option<Analysis> {
        self.measured
            .into_iter()
            .find(|(c, _)| c == cm)
            .map(|(_, a)| a)
    }
}

/// The pipeline: analyse one image under every countermeasure of `plan`, detecting the stars and building
/// the global ePSF once. `source` is the simulation the image came from, when known (without it the
/// telemetry has no ACE series to correct with and the exact-ePSF control does not apply); `seed` draws the
/// reference catalogue's errors.
pub fn analyse_image(
    img: &AnalysisImage,
    truth: Option<&[TruthRow]>,
    source: Option<Source<'_>>,
    cfg: &AnalysisCfg,
    plan: &Plan,
    seed: u64,
    supplied: &Supplied<'_>,
) -> Result<ImageAnalysis, AnalysisError> {
    let reference = supplied.reference;
    let base = Options::new(cfg);
    let model = || -> Result<Option<Epsf>, AnalysisError> {
        if let Some(m) = supplied.model_psf {
            return Ok(Some(m.clone()));
        }
        // without the model PSF product: the simulation's own (its true optics), when there is one
        match source {
            Some(src) => Ok(Some(exact_epsf(
                &*src.sim.optical_kernel()?,
                cfg.epsf_radius_px,
            ))),
            None => Ok(None),
        }
    };
    let (plain, prepared) = analyze_prepared_with(img, truth, &base, &model)?;
    let mut global = plain.clone();
    if let (Some(src), Some(t)) = (source, truth) {
        src.attach_ace_prediction(t, &mut global, cfg, img.plate_scale_mas)?;
    }
    let mut measured = Vec::with_capacity(plan.countermeasures.len());
    for cm in &plan.countermeasures {
        let analysis = match cm {
            Countermeasure::None => global.clone(),
            Countermeasure::ExactEpsf => {
                let Some(src) = source.filter(|s| s.sim.cfg.ace.case != AceCase::Realistic) else {
                    continue;
                };
                let jobs = src.sim.jobs()?;
                let Some(j) = jobs.first() else { continue };
                let mut o = base.clone();
                o.fixed_epsf = Some(exact_epsf(&j.kernel, cfg.epsf_radius_px));
                analyze(img, truth, &o)?
            }
            Countermeasure::Telemetry(q) => {
                let tel = match (supplied.telemetry, source) {
                    (Some(rec), Some(s)) => s.telemetry_from_record(rec, cfg)?,
                    _ => source.map(|s| s.telemetry(q, cfg)).transpose()?.flatten(),
                };
                match tel {
                    // a static ACE (or an image without its simulation) has nothing to correct
                    None => global.clone(),
                    Some(tel) => with_countermeasure(
                        img,
                        truth,
                        &plain,
                        &prepared,
                        cm,
                        Some(&tel),
                        reference,
                        seed,
                    )?,
                }
            }
            other => {
                with_countermeasure(img, truth, &plain, &prepared, other, None, reference, seed)?
            }
        };
        measured.push((*cm, analysis));
    }
    Ok(ImageAnalysis { global, measured })
}

/// Finish the analyses of a stare's exposures (`images[k]`, with `truths[k]` when known): every plate model
/// of the plan referenced to the stack is fitted over all of them ([`stack::stack_plate`], from each image's
/// global fits) and replaces each image's stare-of-one result. A stare of one exposure is left as it is.
pub fn finish_stare(
    images: &mut [ImageAnalysis],
    truths: &[Option<&[TruthRow]>],
    plan: &Plan,
    plate_scale_mas: f64,
) -> Result<(), AnalysisError> {
    if images.len() < 2 {
        return Ok(());
    }
    let n = images.len();
    for cm in plan.countermeasures.iter().filter(|c| c.needs_stare()) {
        let Countermeasure::Plate { model, .. } = cm else {
            continue;
        };
        let mut stars: Vec<Vec<StarResult>> =
            images.iter().map(|im| im.global.stars.clone()).collect();
        let out = stack::stack_plate(&mut stars, *model, &cm.to_string())?;
        for (k, (im, st)) in images.iter_mut().zip(stars).enumerate() {
            let mut report = countermeasure_report(&im.global.report, cm);
            report.dof_absorbed = out.dof_absorbed;
            report.stare_exposures = n;
            summarise(
                &st,
                truths.get(k).copied().flatten(),
                plate_scale_mas,
                &mut report,
            );
            let analysis = Analysis {
                report,
                stars: st,
                epsf: im.global.epsf.clone(),
            };
            match im.measured.iter_mut().find(|(c, _)| c == cm) {
                Some(slot) => slot.1 = analysis,
                None => im.measured.push((*cm, analysis)),
            }
        }
    }
    Ok(())
}
