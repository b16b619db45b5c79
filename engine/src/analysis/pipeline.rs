//! The per-image analysis pipeline: detect → global ePSF → fits → each countermeasure of a [`Plan`] →
//! report. No truth enters: scoring the fits against one is the next layer's (`scoring::image`). `jsim
//! analyze`, `jsim experiment`, the sweeps and the explorer all run [`analyse_image`]; the pieces
//! ([`analyze_prepared`], [`with_countermeasure`], [`analyze`]) are public for the tests and for studies that
//! need one step alone.

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::TelemetryQuality;
use crate::analysis::countermeasures::telemetry::{ExposureReadout, TelemetryRecord, resample};
use crate::analysis::countermeasures::{self, Context, Countermeasure, Plan, Telemetry, stack};
use crate::analysis::crowded::CrowdedSummary;
use crate::analysis::detection::{detect, starts};
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart};
use crate::analysis::epsf::fit::{StarFit, fit_star, flags};
use crate::analysis::epsf::varying;
use crate::analysis::image::AnalysisImage;
use crate::analysis::report::{Report, StarResult, star_results};
use crate::analysis::response::FitNoise;
use crate::config::{Analysis as AnalysisCfg, EpsfVariation, TelemetryKernel};
use crate::integrate::kernel::PixelKernel;
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
    /// The reference catalogue product's positions (pixels of this image) for `plate-*@catalogue`.
    pub reference: Option<Vec<(f64, f64)>>,
    /// Fit with this ePSF instead of building one (e.g. the exact ePSF from the simulator).
    pub fixed_epsf: Option<Epsf>,
    /// The instrument's model PSF (pixel-integrated, from calibration), used when the image holds fewer
    /// than [`MIN_EPSF_STARS`] stars to build an ePSF from; without one a Gaussian fitted to the stars'
    /// second moments stands in.
    pub model_epsf: Option<Epsf>,
}

/// Fewest stars an ePSF is built from (defined beside the choice of ePSF stars).
pub use super::detection::MIN_EPSF_STARS;

impl Options {
    pub fn new(cfg: &AnalysisCfg) -> Self {
        Self {
            cfg: cfg.clone(),
            countermeasure: Countermeasure::None,
            telemetry: None,
            reference: None,
            fixed_epsf: None,
            model_epsf: None,
        }
    }

    pub fn build_options(&self) -> BuildOptions {
        build_options(&self.cfg)
    }
}

pub use super::epsf::build::build_options;

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
pub fn analyze(img: &AnalysisImage, opts: &Options) -> Result<Analysis, AnalysisError> {
    let (plain, prepared) = analyze_prepared(img, opts)?;
    with_countermeasure(
        img,
        &plain,
        &prepared,
        &opts.countermeasure,
        opts.telemetry.as_deref(),
        opts.reference.as_deref(),
    )
}

/// The analysis without a countermeasure, and what it prepared for [`with_countermeasure`].
pub fn analyze_prepared(
    img: &AnalysisImage,
    opts: &Options,
) -> Result<(Analysis, Prepared), AnalysisError> {
    analyze_prepared_with(img, opts, &|| Ok(opts.model_epsf.clone()))
}

/// [`analyze_prepared`] with the model PSF of the few-star fallback made only when it is needed.
fn analyze_prepared_with(
    img: &AnalysisImage,
    opts: &Options,
    model_epsf: &dyn Fn() -> Result<Option<Epsf>, AnalysisError>,
) -> Result<(Analysis, Prepared), AnalysisError> {
    let det = detect(img, opts.cfg.detect_sigma);
    if det.is_empty() {
        return Err(AnalysisError::NoStars(opts.cfg.detect_sigma));
    }
    let (starts, usable) = starts(img, &det, &opts.cfg);
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
    let mut variation = EpsfVariation::Constant.name().to_string();
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
            match opts.cfg.epsf_variation {
                EpsfVariation::Constant => (built.fits, built.epsf, built.iterations),
                v => {
                    let var = varying::build(&pd, &starts, &usable, &bopt, v, &built);
                    variation = if var.kept_constant.is_empty() {
                        v.name().to_string()
                    } else {
                        var.kept_constant
                    };
                    (var.fits, var.epsf.base, built.iterations + var.iterations)
                }
            }
        }
    };
    flags::mark_poor_fits(&mut fits);
    flags::mark_blends(&mut fits, flags::blend_radius_px(opts.cfg.fit_radius_px));
    let stars = star_results(&fits);
    let mut report = Report {
        n_detected: det.len(),
        epsf_iterations: iterations,
        epsf_stars: n_build,
        epsf_fallback: fallback,
        epsf_variation: variation,
        countermeasure: Countermeasure::None.to_string(),
        ..Default::default()
    };
    report.count(&stars);
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
        epsf_variation: plain.epsf_variation.clone(),
        countermeasure: cm.to_string(),
        ..Default::default()
    }
}

/// Apply a countermeasure to the plain analysis of an image (from [`analyze_prepared`]) and report.
pub fn with_countermeasure(
    img: &AnalysisImage,
    plain: &Analysis,
    prepared: &Prepared,
    cm: &Countermeasure,
    telemetry: Option<&Telemetry>,
    reference: Option<&[(f64, f64)]>,
) -> Result<Analysis, AnalysisError> {
    let mut stars = plain.stars.clone();
    let mut report = countermeasure_report(&plain.report, cm);
    let ctx = Context {
        img,
        starts: &prepared.starts,
        usable: &prepared.usable,
        build: &prepared.build,
        global: &plain.epsf,
        default_zones: prepared.default_zones,
        telemetry,
        reference,
    };
    report.dof_absorbed = countermeasures::apply(cm, &ctx, &mut stars)?;
    if let Some(w) = telemetry.and_then(|t| t.wavefront.as_ref())
        && cm.telemetry_quality().is_some()
    {
        report.static_profile = w.describe();
    }
    if cm.needs_stare() {
        // the image alone is its own stack: nothing corrected until the stare is finished
        report.stare_exposures = Some(1);
    }
    report.count(&stars);
    Ok(Analysis {
        report,
        stars,
        epsf: plain.epsf.clone(),
    })
}

/// Whether a countermeasure acts in a crowded field: on the fitted positions (a plate model referenced to a
/// catalogue or, `@oracle`, to the truth; the telemetry correction), or refitting every star in its group
/// through its own forward-model profile (`telemetry-model`, `telemetry-model+plate-…@catalogue`). Those that
/// refit single stars with another ePSF (`yzones`, `exact-epsf`) and a stack reference (a stare's) do not.
pub fn offered_in_crowded_field(cm: &Countermeasure) -> bool {
    !matches!(
        cm,
        Countermeasure::YZones { .. }
            | Countermeasure::ExactEpsf
            | Countermeasure::Plate {
                reference: countermeasures::Reference::Stack,
                ..
            }
    )
}

/// What is left of a forward-model countermeasure once its refits are done: its plate model (`none` for
/// `telemetry-model`).
fn plate_after_forward(cm: &Countermeasure) -> Countermeasure {
    match *cm {
        Countermeasure::Plate {
            model, reference, ..
        } => Countermeasure::Plate {
            model,
            reference,
            forward: None,
        },
        _ => Countermeasure::None,
    }
}

/// The crowded-field analysis of one image ([`crate::analysis::crowded::analyse`]) under every countermeasure
/// of `plan`, as an [`ImageAnalysis`] of the pipeline: the crowded analysis runs once, each countermeasure
/// corrects its positions. A countermeasure not [`offered_in_crowded_field`] is refused by name. A field
/// without stars gives an analysis without stars (the reason in [`ImageAnalysis::crowded`]).
pub fn analyse_crowded_image(
    img: &AnalysisImage,
    cfg: &AnalysisCfg,
    plan: &Plan,
    supplied: &Supplied<'_>,
) -> Result<ImageAnalysis, AnalysisError> {
    if let Some(cm) = plan
        .countermeasures
        .iter()
        .find(|c| !offered_in_crowded_field(c))
    {
        return Err(AnalysisError::NotInCrowdedField {
            countermeasure: cm.to_string(),
        });
    }
    let t0 = std::time::Instant::now();
    // an empty field is a result (no star, the reason in the summary's fallback), not an error: a study
    // over the focal plane reports its empty arrays; a caller that needs stars checks
    let c = crate::analysis::crowded::analyse(img, cfg, supplied.model_psf, supplied.catalogue);
    let stars = star_results(&c.fits);
    let summary = CrowdedSummary::of(&c, t0.elapsed().as_secs_f64());
    let mut report = Report {
        n_detected: c.fits.len(),
        epsf_iterations: c.epsf_iterations,
        epsf_stars: c.epsf_stars,
        epsf_fallback: c.fallback.clone(),
        epsf_variation: c.variation.clone(),
        countermeasure: Countermeasure::None.to_string(),
        crowded: true,
        ..Default::default()
    };
    report.count(&stars);
    let plain = Analysis {
        report,
        stars,
        epsf: c.field.base.clone(),
    };
    let build = build_options(cfg);
    let mut measured = Vec::with_capacity(plan.countermeasures.len());
    for cm in &plan.countermeasures {
        if *cm == Countermeasure::None {
            measured.push((*cm, plain.clone()));
            continue;
        }
        let telemetry = match cm.telemetry_quality() {
            Some(q) => telemetry_for(&q, supplied, img, &plain, cfg)?,
            None => None,
        };
        let ctx = Context {
            img,
            starts: &[],
            usable: &[],
            build: &build,
            global: &plain.epsf,
            default_zones: cfg.epsf_zones.max(2),
            telemetry: telemetry.as_ref(),
            reference: supplied.reference_for(cm),
        };
        let mut stars = plain.stars.clone();
        let mut report = countermeasure_report(&plain.report, cm);
        report.crowded = true;
        // the forward model refits the groups (each member through its own windows), then its plate model
        let cm_after = match (cm.forward_model(), &telemetry) {
            (Some(_), Some(tel)) => {
                let forward = tel.forward(tel.profile.as_ref().unwrap_or(&plain.epsf), img.nx);
                let fits = crate::analysis::crowded::refit_forward(img, &c, cfg, &forward);
                stars = star_results(&fits);
                plate_after_forward(cm)
            }
            (Some(_), None) => plate_after_forward(cm),
            (None, _) => *cm,
        };
        report.dof_absorbed = countermeasures::apply(&cm_after, &ctx, &mut stars)?;
        report.count(&stars);
        measured.push((
            *cm,
            Analysis {
                report,
                stars,
                epsf: plain.epsf.clone(),
            },
        ));
    }
    Ok(ImageAnalysis {
        global: plain,
        measured,
        crowded: Some(summary),
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
/// positions in the image's pixels (`plate-*@catalogue`), the design model PSF (the fallback below
/// [`MIN_EPSF_STARS`] ePSF stars), the attitude telemetry and the readout timing it is applied with.
#[derive(Debug, Clone, Copy, Default)]
pub struct Supplied<'a> {
    pub reference: Option<&'a [(f64, f64)]>,
    /// The reference catalogue the crowded-field analysis holds its missed stars from
    /// (`analysis.crowded_forced_catalogue`): the product, or the simulated source's survey's.
    pub catalogue: Option<&'a [crate::analysis::crowded::forced::CatalogueStar]>,
    /// Reference catalogues at the catalogue errors (mas) a plan asks for, as a simulated survey draws them
    /// (used where no product is given).
    pub reference_by_error: &'a [(f64, Vec<(f64, f64)>)],
    pub model_psf: Option<&'a Epsf>,
    /// The design model PSF's change per nm rms of each low-order Fringe term (Z4 … Z11), on its grid: what
    /// `analysis.telemetry_kernel = "design-fitted"` corrects the model PSF with.
    pub model_psf_terms: Option<&'a [Epsf]>,
    /// The attitude telemetry product of the exposure: what every telemetry countermeasure of a plan
    /// corrects with (its recorded quality replaces the plan's).
    pub telemetry: Option<&'a TelemetryRecord>,
    /// Telemetry records of the exposure at the qualities a plan asks for, as a simulated instrument records
    /// them (used where no product is given; a quality without a record: nothing to correct).
    pub telemetry_by_quality: &'a [(TelemetryQuality, TelemetryRecord)],
    /// When each pixel integrated and how the array is turned: what the telemetry is applied with.
    pub readout: Option<ExposureReadout>,
    /// The exact ePSF of a static-ACE simulation: the `exact-epsf` control (an oracle; without it that
    /// control does not apply).
    pub exact_epsf: Option<&'a Epsf>,
    /// The true positions (this image's pixels) of a simulated exposure: the `plate-*@oracle` control's
    /// reference (an oracle; without it that control is refused by name).
    pub oracle_reference: Option<&'a [(f64, f64)]>,
}

impl Supplied<'_> {
    /// The reference positions a countermeasure is referenced to: for `plate-*@catalogue` the product, else
    /// the simulated survey's at its catalogue error; for `plate-*@oracle` the true positions.
    pub fn reference_for(&self, cm: &Countermeasure) -> Option<&[(f64, f64)]> {
        let Countermeasure::Plate { reference, .. } = cm else {
            return None;
        };
        match reference {
            countermeasures::Reference::Catalogue { error_mas } => self.reference.or_else(|| {
                self.reference_by_error
                    .iter()
                    .find(|(e, _)| e == error_mas)
                    .map(|(_, r)| r.as_slice())
            }),
            countermeasures::Reference::Oracle => self.oracle_reference,
            countermeasures::Reference::Stack => None,
        }
    }

    /// The telemetry record a countermeasure of quality `q` corrects with: the product, else the record at
    /// that quality.
    fn telemetry_record(&self, q: &TelemetryQuality) -> Option<&TelemetryRecord> {
        self.telemetry.or_else(|| {
            self.telemetry_by_quality
                .iter()
                .find(|(k, _)| k == q)
                .map(|(_, r)| r)
        })
    }
}

/// The telemetry of quality `q` for an image, its fit response built from the PSF `cfg.telemetry_kernel`
/// names — the design model PSF product (the PSF before the jitter), the analysis' own ePSF, or that ePSF
/// deconvolved of each star's own jitter ([`countermeasures::forward_epsf`]) — and the
/// measured fluxes and sky of its stars ([`FitNoise::of_stars`]); `None` without a record (a static ACE, or
/// nothing recorded: nothing to correct).
pub fn telemetry_for(
    q: &TelemetryQuality,
    supplied: &Supplied<'_>,
    img: &AnalysisImage,
    plain: &Analysis,
    cfg: &AnalysisCfg,
) -> Result<Option<Telemetry>, AnalysisError> {
    let Some(rec) = supplied.telemetry_record(q) else {
        return Ok(None);
    };
    let Some(ro) = supplied.readout else {
        return Err(AnalysisError::NoReadoutTiming);
    };
    let epsf = match (cfg.telemetry_kernel, supplied.model_psf) {
        (TelemetryKernel::ModelPsf | TelemetryKernel::DesignFitted, Some(m)) => m,
        _ => &plain.epsf,
    };
    let kernel_of = |e: &Epsf| {
        let half_px = e.half_px().floor() as usize;
        crate::integrate::kernel::PixelKernel::tabulated(8, half_px, |x, y| e.value(x, y))
    };
    let noise = FitNoise::of_stars(&plain.stars, img.var_floor_e2, cfg.fit_radius_px);
    let mut tel = Telemetry::from_record(
        rec,
        0.0,
        ro.timing,
        img.plate_scale_mas,
        ro.rotation_deg,
        &kernel_of(epsf),
        &noise,
    )?;
    tel.profile = Some(epsf.clone());
    tel.model_nodes_per_px = cfg.telemetry_model_nodes_per_px;
    tel.model_track = rec
        .model_record(cfg.telemetry_filter)
        .map(|r| resample(&r, 0.0, &ro.timing, img.plate_scale_mas, ro.rotation_deg));
    if let (TelemetryKernel::DesignFitted, Some(m), Some(terms)) = (
        cfg.telemetry_kernel,
        supplied.model_psf,
        supplied.model_psf_terms,
    ) && let Some(w) =
        countermeasures::wavefront::fit(img, &plain.stars, m, terms, &tel, &build_options(cfg).fit)
    {
        // the design PSF corrected by the stars; the shift correction's response rebuilt from it
        let nominal = tel.track.window(
            ro.timing.t_overhead_s,
            ro.timing.t_overhead_s + ro.timing.exposure_s,
        );
        tel.response = crate::analysis::response::FitResponse::build(
            &kernel_of(&w.profile),
            &tel.track,
            &nominal,
            &noise,
        );
        tel.profile = Some(w.profile.clone());
        tel.wavefront = Some(w);
    }
    if cfg.telemetry_kernel == TelemetryKernel::EpsfDeconvolved {
        // the image's own static profile, through the (filtered) telemetry; the shift correction's
        // response is rebuilt from it
        let profile = countermeasures::forward_epsf::build_deconvolved(
            img,
            &plain.stars,
            &plain.epsf,
            &tel,
            &build_options(cfg),
            cfg.telemetry_deconvolution_iterations,
        );
        let nominal = tel.track.window(
            ro.timing.t_overhead_s,
            ro.timing.t_overhead_s + ro.timing.exposure_s,
        );
        tel.response = crate::analysis::response::FitResponse::build(
            &kernel_of(&profile),
            &tel.track,
            &nominal,
            &noise,
        );
        tel.profile = Some(profile);
    }
    Ok(Some(tel))
}

/// One image analysed under a plan.
#[derive(Debug, Clone)]
pub struct ImageAnalysis {
    /// The global-ePSF analysis (the result of countermeasure `none`).
    pub global: Analysis,
    /// One analysis per countermeasure of the plan that applies to this image, in plan order (`exact-epsf`
    /// applies only to a simulated image with a static ACE).
    pub measured: Vec<(Countermeasure, Analysis)>,
    /// What the crowded-field analysis did (detections per pass, groups, its time), when it ran.
    pub crowded: Option<CrowdedSummary>,
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
/// the global ePSF once, with what the instrument `supplied` beside the image (a countermeasure whose
/// product is missing corrects nothing — a telemetry correction without telemetry — does not apply —
/// `exact-epsf` without an exact ePSF — or is refused by name — `plate-*@catalogue` without a reference).
pub fn analyse_image(
    img: &AnalysisImage,
    cfg: &AnalysisCfg,
    plan: &Plan,
    supplied: &Supplied<'_>,
) -> Result<ImageAnalysis, AnalysisError> {
    let base = Options::new(cfg);
    let model = || -> Result<Option<Epsf>, AnalysisError> { Ok(supplied.model_psf.cloned()) };
    let (plain, prepared) = analyze_prepared_with(img, &base, &model)?;
    let mut measured = Vec::with_capacity(plan.countermeasures.len());
    for cm in &plan.countermeasures {
        let reference = supplied.reference_for(cm);
        let analysis = match cm {
            Countermeasure::None => plain.clone(),
            Countermeasure::ExactEpsf => {
                let Some(exact) = supplied.exact_epsf else {
                    continue;
                };
                let mut o = base.clone();
                o.fixed_epsf = Some(exact.clone());
                analyze(img, &o)?
            }
            Countermeasure::Telemetry(q) | Countermeasure::TelemetryModel(q) => {
                match telemetry_for(q, supplied, img, &plain, cfg)? {
                    // a static ACE (or no telemetry at all) has nothing to correct
                    None => plain.clone(),
                    Some(tel) => {
                        with_countermeasure(img, &plain, &prepared, cm, Some(&tel), reference)?
                    }
                }
            }
            // the forward model, then the plate model on its refits (a static ACE: the plate model alone)
            Countermeasure::Plate {
                forward: Some(q), ..
            } => {
                let tel = telemetry_for(q, supplied, img, &plain, cfg)?;
                with_countermeasure(img, &plain, &prepared, cm, tel.as_ref(), reference)?
            }
            other => with_countermeasure(img, &plain, &prepared, other, None, reference)?,
        };
        measured.push((*cm, analysis));
    }
    Ok(ImageAnalysis {
        global: plain,
        measured,
        crowded: None,
    })
}

/// Finish the analyses of a stare's exposures (`images[k]`): every plate model
/// of the plan referenced to the stack is fitted over all of them ([`stack::stack_plate`], from each image's
/// global fits, or for `telemetry-model+plate-…` from its forward-model refits) and replaces each image's
/// stare-of-one result. A stare of one exposure is left as it is.
pub fn finish_stare(images: &mut [ImageAnalysis], plan: &Plan) -> Result<(), AnalysisError> {
    if images.len() < 2 {
        return Ok(());
    }
    let n = images.len();
    for cm in plan.countermeasures.iter().filter(|c| c.needs_stare()) {
        let Countermeasure::Plate { model, forward, .. } = cm else {
            continue;
        };
        // the fits the plates correct: the global ones, or the forward model's (the stare-of-one result)
        let mut stars: Vec<Vec<StarResult>> = images
            .iter()
            .map(|im| match (forward, im.of(cm)) {
                (Some(_), Some(a)) => a.stars.clone(),
                _ => im.global.stars.clone(),
            })
            .collect();
        let out = stack::stack_plate(&mut stars, *model, &cm.to_string())?;
        for (im, st) in images.iter_mut().zip(stars) {
            let mut report = countermeasure_report(&im.global.report, cm);
            report.dof_absorbed = out.dof_absorbed;
            report.stare_exposures = Some(n);
            report.count(&st);
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
