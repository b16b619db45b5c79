//! A simulated exposure as the analysis meets it: what the simulated instrument delivers beside the image
//! (the design model PSF, the attitude telemetry it records, its readout timing — [`Source::products`]),
//! and what only a simulation knows, each labelled as such: the exact ePSF of a static simulation (the
//! `exact-epsf` control, an oracle) and the fit displacement the true ACE predicts for every star (the
//! mechanism, shown beside the measured errors), and the true positions (the `plate-*@oracle` control's
//! reference). The analysis itself ([`analyse_image`]) never sees the simulator; [`Source::score`] scores
//! its result against the exposure's truth.

use crate::analysis::countermeasures::telemetry::{ExposureReadout, TelemetryRecord};
use crate::analysis::countermeasures::{Countermeasure, Plan, Reference, TelemetryQuality};
use crate::analysis::crowded::forced::{CatalogueStar, positions_px};
use crate::analysis::epsf::Epsf;
use crate::analysis::image::AnalysisImage;
use crate::analysis::pipeline::{
    ImageAnalysis, Supplied, analyse_crowded_image, analyse_image, exact_epsf,
};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::analysis::{AnalysisError, countermeasures::CountermeasureError};
use crate::config::{AceCase, Analysis as AnalysisCfg, Crowding, FlatField};
use crate::detector::DetectorImage;
use crate::io::instrument::{self, SurveyModel};
use crate::numerics::stats;
use crate::photometry;
use crate::scoring::image::{Scored, ScoredImage, attach_fit_prediction, score_image};
use crate::simulate::{SimError, Simulator};
use crate::truth::TruthRow;

/// The true positions a `plate-*@oracle` control of `plan` is referenced to (`None` when the plan asks for
/// none, or without a truth).
pub fn oracle_reference(plan: &Plan, truth: Option<&[TruthRow]>) -> Option<Vec<(f64, f64)>> {
    truth
        .filter(|_| plan.asks_oracle_plate())
        .map(|t| t.iter().map(|r| (r.x_px, r.y_px)).collect())
}

/// A failure of a simulation's analysis: of the simulation (its kernels, its stars) or of the analysis.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(transparent)]
    Simulation(#[from] SimError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The configuration an analysis was asked for is not the one the image was simulated with.
    #[error(
        "the configuration given differs from the simulator's beyond the analysis knobs (config {given} against \
         {simulated}): an image is analysed with the configuration it was simulated with"
    )]
    ConfigMismatch { given: String, simulated: String },
}

impl From<CountermeasureError> for SourceError {
    fn from(e: CountermeasureError) -> Self {
        SourceError::Analysis(e.into())
    }
}

/// An exposure of a simulation, flat-fielded as its `analysis.flat_field` says with the simulator's (cached)
/// calibration flat product (the true flat with its stated error).
pub fn analysis_image(sim: &Simulator, img: &DetectorImage) -> AnalysisImage {
    let mut a = AnalysisImage::from_detector_unflattened(&sim.cfg, img);
    if let (Some(flat), FlatField::Calibrated { error }) =
        (sim.calibration_flat(), sim.cfg.analysis.flat_field)
    {
        a.divide_by(&flat, error);
    }
    a
}

/// Noise parameters of a typical star's fit in a simulation (median flux, sky, read/quantisation floor)
/// with the analysis' fit radius (px): the predictor's model of a dataset.
pub fn simulation_fit_noise(sim: &Simulator, radius_px: f64) -> FitNoise {
    let cfg = &sim.cfg;
    let d = &cfg.detector;
    let rates: Vec<f64> = sim
        .stars
        .iter()
        .map(|s| photometry::electrons_per_s(s.mag_hw, cfg.photometry.zero_point_e_per_s))
        .collect();
    FitNoise {
        flux_e: if rates.is_empty() {
            0.0
        } else {
            stats::median(&rates)
        } * d.exposure_s,
        sky_e: d.dark_e_per_s * d.exposure_s,
        floor_e2: d.noise_floor_e2(),
        radius_px,
    }
}

/// The simulated exposure an image came from.
#[derive(Clone, Copy)]
pub struct Source<'a> {
    pub sim: &'a Simulator,
    /// The exposure's index in the simulator's dataset.
    pub index: usize,
    /// The survey the reference catalogue product comes from: the forced stars' catalogue, and the plate
    /// models' `@catalogue` reference at its own error floor.
    pub survey: SurveyModel,
}

impl<'a> Source<'a> {
    /// Exposure `index` of `sim`, its reference catalogue from the default survey.
    pub fn new(sim: &'a Simulator, index: usize) -> Self {
        Self {
            sim,
            index,
            survey: SurveyModel::default(),
        }
    }
}

/// What a simulated instrument delivers beside one exposure (owned; lend it with [`SourceProducts::supplied`]).
pub struct SourceProducts {
    /// The design model PSF (design wavefront, pixel-integrated, no jitter).
    pub model_psf: Epsf,
    /// Its derivative planes per low-order term, when the analysis corrects it by the stars
    /// (`analysis.telemetry_kernel = "design-fitted"`); else empty.
    pub model_psf_terms: Vec<Epsf>,
    /// The reference catalogue a survey gives of the field ([`instrument::reference_catalogue`]: the source's
    /// survey with its floor at each catalogue error of the plan's `plate-*@catalogue`), in pixels.
    pub references: Vec<(f64, Vec<(f64, f64)>)>,
    /// The reference catalogue of the source's survey, in pixels, when the analysis is crowded and
    /// holds the catalogue's missed stars (`analysis.crowded_forced_catalogue`); else empty.
    pub catalogue: Vec<CatalogueStar>,
    /// The attitude recorded at each telemetry quality of the plan (none for a static ACE).
    pub telemetry: Vec<(TelemetryQuality, TelemetryRecord)>,
    pub readout: ExposureReadout,
    /// The exact ePSF of a static-ACE simulation, when the plan asks for the `exact-epsf` control.
    pub exact_epsf: Option<Epsf>,
}

impl SourceProducts {
    /// The products as the pipeline takes them; `reference`, `catalogue`: the reference catalogue product's
    /// positions and stars, if any.
    pub fn supplied<'a>(
        &'a self,
        reference: Option<&'a [(f64, f64)]>,
        catalogue: Option<&'a [CatalogueStar]>,
    ) -> Supplied<'a> {
        Supplied {
            reference,
            catalogue: catalogue
                .or((!self.catalogue.is_empty()).then_some(self.catalogue.as_slice())),
            reference_by_error: &self.references,
            model_psf: Some(&self.model_psf),
            model_psf_terms: (!self.model_psf_terms.is_empty())
                .then_some(self.model_psf_terms.as_slice()),
            telemetry: None,
            telemetry_by_quality: &self.telemetry,
            readout: Some(self.readout),
            exact_epsf: self.exact_epsf.as_ref(),
            oracle_reference: None,
        }
    }
}

impl Source<'_> {
    /// The exposure's readout timing and array rotation.
    pub fn readout(&self) -> ExposureReadout {
        ExposureReadout {
            timing: self.sim.timing,
            rotation_deg: self.sim.array.rotation_deg,
        }
    }

    /// The attitude telemetry the spacecraft records over this exposure at quality `q` (the instrument
    /// product `telemetry_NNN.fits`); `None` for a static ACE.
    pub fn telemetry_record(
        &self,
        q: &TelemetryQuality,
    ) -> Result<Option<TelemetryRecord>, CountermeasureError> {
        let Some(series) = self.sim.series() else {
            return Ok(None);
        };
        TelemetryRecord::record(
            series,
            self.sim.timing.span_s(),
            self.sim.exposure_start_s(self.index),
            q,
            self.sim.cfg.seed,
        )
        .map(Some)
    }

    /// The exact ePSF of a static-ACE simulation (the `exact-epsf` control, an oracle); `None` for a realistic
    /// ACE, whose stars each see their own jitter.
    pub fn exact_epsf(&self, cfg: &AnalysisCfg) -> Result<Option<Epsf>, SimError> {
        if self.sim.cfg.ace.case == AceCase::Realistic {
            return Ok(None);
        }
        Ok(self
            .sim
            .jobs()?
            .first()
            .map(|j| exact_epsf(&j.kernel, cfg.epsf_radius_px)))
    }

    /// The positions (pixels) of the reference catalogue a survey of this model gives of the field.
    fn catalogue_px(&self, survey: &SurveyModel) -> Vec<(f64, f64)> {
        positions_px(&self.catalogue_stars(survey))
    }

    /// The reference catalogue a survey of this model gives of the field: positions (pixels) and Hw.
    fn catalogue_stars(&self, survey: &SurveyModel) -> Vec<CatalogueStar> {
        instrument::reference_catalogue(self.sim, survey, 0)
            .iter()
            .map(instrument::RefStar::catalogue_star)
            .collect()
    }

    /// What the simulated instrument delivers beside this exposure for the countermeasures of `plan`.
    pub fn products(&self, plan: &Plan, cfg: &AnalysisCfg) -> Result<SourceProducts, SourceError> {
        let mut telemetry: Vec<(TelemetryQuality, TelemetryRecord)> = Vec::new();
        let mut references: Vec<(f64, Vec<(f64, f64)>)> = Vec::new();
        for cm in &plan.countermeasures {
            if let Countermeasure::Plate {
                reference: Reference::Catalogue { error_mas },
                ..
            } = cm
                && !references.iter().any(|(e, _)| e == error_mas)
            {
                let survey = SurveyModel {
                    floor_mas: *error_mas,
                    ..self.survey
                };
                references.push((*error_mas, self.catalogue_px(&survey)));
            }
            if let Some(q) = cm.telemetry_quality()
                && !telemetry.iter().any(|(k, _)| *k == q)
                && let Some(r) = self.telemetry_record(&q)?
            {
                telemetry.push((q, r));
            }
        }
        let exact_epsf = match plan.countermeasures.contains(&Countermeasure::ExactEpsf) {
            true => self.exact_epsf(cfg)?,
            false => None,
        };
        let catalogue = if cfg.crowding != Crowding::Off && cfg.crowded_forced_catalogue {
            self.catalogue_stars(&self.survey)
        } else {
            Vec::new()
        };
        let model_psf_terms = match cfg.telemetry_kernel {
            crate::config::TelemetryKernel::DesignFitted => instrument::model_psf_terms(self.sim)?,
            _ => Vec::new(),
        };
        Ok(SourceProducts {
            model_psf: instrument::model_psf_product(self.sim)?,
            model_psf_terms,
            references,
            catalogue,
            telemetry,
            readout: self.readout(),
            exact_epsf,
        })
    }

    /// The pipeline on this exposure's image — isolated or crowded as `cfg.crowding` says — with the products
    /// the simulated instrument delivers (those in `supplied` first: a product read from a file replaces the
    /// simulated one). `truth` is read for one thing only: the true positions a `plate-*@oracle` control of
    /// the plan is referenced to (without it that control is refused by name). `config` gives the analysis
    /// knobs; the rest of it must be the simulator's (a [`SourceError::ConfigMismatch`] otherwise), so no
    /// caller analyses with one configuration an image simulated with another.
    pub fn analyse(
        &self,
        img: &AnalysisImage,
        truth: Option<&[TruthRow]>,
        config: &crate::config::Config,
        plan: &Plan,
        supplied: &Supplied<'_>,
    ) -> Result<ImageAnalysis, SourceError> {
        let (given, simulated) = (
            super::simulation_key(config),
            super::simulation_key(&self.sim.cfg),
        );
        if given != simulated {
            return Err(SourceError::ConfigMismatch { given, simulated });
        }
        let cfg = &config.analysis;
        let products = self.products(plan, cfg)?;
        let mut s = products.supplied(supplied.reference, supplied.catalogue);
        s.model_psf = supplied.model_psf.or(s.model_psf);
        s.model_psf_terms = supplied.model_psf_terms.or(s.model_psf_terms);
        s.telemetry = supplied.telemetry;
        s.readout = supplied.readout.or(s.readout);
        let oracle = oracle_reference(plan, truth);
        s.oracle_reference = oracle.as_deref();
        Ok(
            if crate::analysis::crowding::is_crowded(img, cfg, cfg.crowding).0 {
                analyse_crowded_image(img, cfg, plan, &s)?
            } else {
                analyse_image(img, cfg, plan, &s)?
            },
        )
    }

    /// Score an analysis of this exposure against its truth, with the fit displacement the true ACE predicts
    /// attached to the plain analysis (and to countermeasure `none`, the same analysis).
    pub fn score(
        &self,
        analysis: &ImageAnalysis,
        truth: &[TruthRow],
        cfg: &AnalysisCfg,
        plate_scale_mas: f64,
    ) -> Result<ScoredImage, SourceError> {
        let in_header = crate::scoring::image::catalogue_truth(self.sim, truth);
        let mut res = crate::scoring::image::score_image_in_frames(
            analysis,
            Some(truth),
            in_header.as_deref(),
            plate_scale_mas,
        );
        self.attach_ace_prediction(truth, &mut res.global, cfg, plate_scale_mas)?;
        for (cm, a) in &mut res.measured {
            if *cm == Countermeasure::None {
                *a = res.global.clone();
            }
        }
        Ok(res)
    }

    /// [`Source::analyse`], then [`Source::score`] against `truth` (unscored — every accuracy absent —
    /// without one).
    pub fn analyse_scored(
        &self,
        img: &AnalysisImage,
        truth: Option<&[TruthRow]>,
        config: &crate::config::Config,
        plan: &Plan,
        supplied: &Supplied<'_>,
    ) -> Result<ScoredImage, SourceError> {
        let a = self.analyse(img, truth, config, plan, supplied)?;
        match truth {
            Some(t) => self.score(&a, t, &config.analysis, img.plate_scale_mas),
            None => Ok(score_image(&a, None, img.plate_scale_mas)),
        }
    }

    /// Attach to a scored analysis the fit displacement the true ACE predicts for every star (realistic ACE
    /// only; the mechanism, shown beside the measured errors) and refresh its report.
    pub fn attach_ace_prediction(
        &self,
        truth: &[TruthRow],
        analysis: &mut Scored,
        cfg: &AnalysisCfg,
        plate_scale_mas: f64,
    ) -> Result<(), SimError> {
        let sim = self.sim;
        if let Some(track) = sim.track(self.index) {
            let resp = FitResponse::build(
                &*sim.optical_kernel()?,
                &track,
                &sim.nominal_window(&track),
                &simulation_fit_noise(sim, cfg.fit_radius_px),
            );
            let pos: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
            let pred = resp.displacements(&track, &sim.timing, &pos);
            attach_fit_prediction(analysis, &pred, truth, plate_scale_mas);
        }
        Ok(())
    }
}
