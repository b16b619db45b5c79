//! The engine calls of a job, stage by stage: the instant prediction, the frame with its analysis (the
//! engine's one per-image pipeline, [`analyse_image`]) and its Gaussian-ACE twin. The curve stage is in
//! [`super::curve`]. The engine [`Session`] owns the PSF banks, kernels, integrators and simulators; this
//! state adds only the results the UI may ask for again (the shown exposures and the curve's rows).

use super::out::{Out, StageResult, Stop, failed};
use super::protocol::{
    ArrayFits, CrowdedResult, FittedStar, FocalPlaneArray, FocalPlaneResult, FrameResult, Job, Msg,
    Prediction, Request, Stage, TwinResult,
};
use super::views;
use engine::analysis::countermeasures::{Countermeasure, Plan};
use engine::config::{AceCase, Config};
use engine::scoring::vectors::VectorMap;
use engine::session::{Session, Source, analysis_image, simulation_key};
use engine::simulate::{Exposure, FocalPlaneSimulator, Simulator};
use engine::studies::experiment::Row;
use engine::studies::predict::Predictor;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// What the engine thread keeps between jobs.
#[derive(Default)]
pub struct EngineState {
    pub(super) session: Session,
    /// Exposures on display by (simulation key, index): the frame and its twin, a handful at most.
    exposures: HashMap<(String, usize), Arc<Exposure>>,
    /// Curve results by (config hash, plan) and predictions by (config hash, countermeasure).
    pub(super) curve_rows: HashMap<(String, String), Vec<Row>>,
    pub(super) curve_pred: HashMap<(String, String), (f64, f64)>,
    /// The PSD estimate of the last series shown, by simulation key (it costs an FFT of the whole series).
    psd: Option<(String, views::PsdEstimate)>,
    /// What the session said about the backend (e.g. why the CPU stands in for the GPU).
    notes: Vec<String>,
    /// The focal plane on display, by simulation key (building it draws the scene and the PSFs), and its
    /// exposure on display by index (a change of countermeasure re-analyses it without simulating again).
    focal_plane: Option<(String, Arc<FocalPlaneSimulator>)>,
    focal_plane_exposure: Option<(String, usize, Arc<engine::simulate::FocalPlaneExposure>)>,
}

/// The Gaussian-ACE twin of a configuration.
pub fn twin_config(cfg: &Config) -> Config {
    let mut c = cfg.clone();
    c.ace.case = AceCase::Gaussian;
    c
}

impl EngineState {
    pub fn run(&mut self, job: &Job, out: &Out) -> StageResult<()> {
        let r = &job.request;
        r.cfg.validate().map_err(failed(Stage::Predict))?;
        if r.image_index >= r.cfg.fidelity.images {
            return Err(Stop::Failed(
                Stage::Image,
                format!(
                    "image {} does not exist: the dataset has fidelity.images = {}",
                    r.image_index, r.cfg.fidelity.images
                ),
            ));
        }
        if engine::sky::array_count(&r.cfg) > 1 {
            // the quad focal plane: its exposure for the focal-plane view and its crowded-field analysis
            // (the prediction, the Gaussian twin, the single-array analysis and the curve are those of one
            // array: not run here)
            if job.stages.predict {
                // the instant prediction of an isolated star at the explorer's magnitude on one array of
                // this focal plane (the predictor models a single array's grid)
                out.check()?;
                let mut one = r.clone();
                one.cfg.focal_plane.layout = engine::config::Layout::Single;
                one.cfg.scene.kind = engine::config::SceneKind::Grid;
                self.predict(
                    &one,
                    out,
                    Some((
                        r.cfg.hash_hex(),
                        format!(
                            "an isolated Hw {} star on one array (the paper's grid)",
                            r.cfg.scene.mag_hw
                        ),
                    )),
                )?;
            }
            if job.stages.image {
                out.check()?;
                let (fps, exp) = self.focal_plane(r, out)?;
                out.check()?;
                self.crowded(r, &fps, &exp, out)?;
            }
            return Ok(());
        }
        if job.stages.predict {
            out.check()?;
            self.predict(r, out, None)?;
        }
        if job.stages.image {
            // exposures of other configurations are no longer shown
            let keep = [simulation_key(&r.cfg), simulation_key(&twin_config(&r.cfg))];
            self.exposures.retain(|(k, _), _| keep.contains(k));
            out.check()?;
            self.image(r, out)?;
            out.check()?;
            self.twin(r, out)?;
        }
        if job.stages.curve {
            out.check()?;
            self.curve(r, out)?;
        }
        Ok(())
    }

    /// The session's simulator of `cfg` (its analysis knobs are those it was built with: the pipeline is
    /// given the request's explicitly).
    fn simulator(&mut self, cfg: &Config, stage: Stage) -> StageResult<Arc<Simulator>> {
        let sim = self.session.simulator(cfg).map_err(failed(stage))?;
        self.notes.extend(self.session.take_notes());
        Ok(sim)
    }

    /// Exposure `index` of `sim`, simulated once while it is on display.
    fn exposure(
        &mut self,
        sim: &Simulator,
        index: usize,
        stage: Stage,
    ) -> StageResult<Arc<Exposure>> {
        let key = (simulation_key(&sim.cfg), index);
        if let Some(e) = self.exposures.get(&key) {
            return Ok(e.clone());
        }
        let e = Arc::new(sim.exposure(index).map_err(failed(stage))?);
        self.exposures.insert(key, e.clone());
        Ok(e)
    }

    /// The instant prediction of `r`; `shown_as`: the hash of the displayed configuration it stands for and
    /// what it models, when `r` is a model of it (the quad's single array).
    fn predict(
        &mut self,
        r: &Request,
        out: &Out,
        shown_as: Option<(String, String)>,
    ) -> StageResult<()> {
        let t0 = Instant::now();
        out.progress(
            Stage::Predict,
            0,
            1,
            if !self.session.has_bank(&r.cfg) {
                "computing the PSF and the ACE series"
            } else if !self.session.has_simulator(&r.cfg) {
                "generating the ACE series"
            } else {
                "predicting"
            },
        );
        let sim = self.simulator(&r.cfg, Stage::Predict)?;
        out.check()?;
        let pred = Predictor::new(&sim, &r.cfg.analysis).map_err(failed(Stage::Predict))?;
        let cm = r.countermeasure;
        let image_mas = pred.predict_image(r.image_index, &cm).unwrap_or(f64::NAN);
        // the predictor's figure for the exact-ePSF control is the noise floor of this exposure's blur
        let noise_floor_mas = pred
            .predict_image(r.image_index, &Countermeasure::ExactEpsf)
            .unwrap_or(f64::NAN);
        out.check()?;
        let dataset_mas = pred.predict(&cm).unwrap_or(f64::NAN);
        let dataset_none_mas = pred.predict(&Countermeasure::None).unwrap_or(f64::NAN);
        let (cfg_hash, models) = match shown_as {
            Some((h, m)) => (h, Some(m)),
            None => (r.cfg.hash_hex(), None),
        };
        out.send(Msg::Prediction(Box::new(Prediction {
            generation: out.generation,
            cfg_hash,
            models,
            countermeasure: cm,
            image_index: r.image_index,
            dataset_mas,
            dataset_none_mas,
            image_mas,
            noise_floor_mas,
            elapsed_s: t0.elapsed().as_secs_f64(),
        })));
        Ok(())
    }

    fn image(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let cfg = &r.cfg;
        let index = r.image_index;
        let cached = self.exposures.contains_key(&(simulation_key(cfg), index));
        out.progress(
            Stage::Image,
            0,
            2,
            if cached {
                "analysing the frame"
            } else {
                "simulating the frame"
            },
        );
        let t0 = Instant::now();
        let sim = self.simulator(cfg, Stage::Image)?;
        let exp = self.exposure(&sim, index, Stage::Image)?;
        let simulate_s = t0.elapsed().as_secs_f64();
        out.check()?;
        self.send_series(&sim, cfg, index, out);
        out.progress(Stage::Image, 1, 2, "ePSF analysis");
        let t1 = Instant::now();
        let plan = r.plan().map_err(failed(Stage::Image))?;
        let img = analysis_image(&sim, &exp.image);
        let res = Source::new(&sim, index)
            .analyse_scored(&img, Some(&exp.truth), cfg, &plan, &Default::default())
            .map_err(failed(Stage::Image))?;
        let analyse_s = t1.elapsed().as_secs_f64();
        // a countermeasure that does not apply to this image leaves the plain analysis
        let shown = res.of(&r.countermeasure).unwrap_or(&res.global);
        let (lo, hi, noise) = views::display_limits(&exp.image.adu, &exp.image.dq);
        out.send(Msg::Frame(Box::new(FrameResult {
            generation: out.generation,
            cfg: cfg.clone(),
            cfg_hash: cfg.hash_hex(),
            image_index: index,
            countermeasure: r.countermeasure,
            n: exp.image.n,
            adu: exp.image.adu.clone(),
            dq: exp.image.dq.clone(),
            lo_adu: lo,
            hi_adu: hi,
            noise_adu: noise,
            truth_xy: exp.truth.iter().map(|t| (t.x_px, t.y_px)).collect(),
            report: shown.report.clone(),
            stars: shown.stars.clone(),
            vectors: VectorMap::new(&shown.stars, img.plate_scale_mas),
            predicted: VectorMap::new(&res.global.stars, img.plate_scale_mas).predicted,
            report_none: res.global.report.clone(),
            epsf: res.global.epsf,
            t_start_s: exp.t_start_s,
            backend: exp.backend.clone(),
            backend_note: (!self.notes.is_empty()).then(|| self.notes.join("; ")),
            simulate_s,
            analyse_s,
        })));
        Ok(())
    }

    /// The ACE series view of exposure `index`, with the PSD estimate of `sim`'s series (made once per
    /// simulation key: it costs an FFT of the whole series).
    fn send_series(&mut self, sim: &Simulator, cfg: &Config, index: usize, out: &Out) {
        let key = simulation_key(cfg);
        let psd = match &self.psd {
            Some((k, p)) if *k == key => p.clone(),
            _ => {
                let p = views::psd_estimate(sim);
                self.psd = Some((key, p.clone()));
                p
            }
        };
        out.send(Msg::Series(Box::new(views::series_view(
            sim,
            cfg,
            index,
            psd,
            out.generation,
        ))));
    }

    /// One exposure of the quad focal plane: every array simulated (the jitter common to all, each its own
    /// readout, flat and noise), turned into focal-plane axes for the view, with its WCS and stars.
    fn focal_plane(
        &mut self,
        r: &Request,
        out: &Out,
    ) -> StageResult<(
        Arc<FocalPlaneSimulator>,
        Arc<engine::simulate::FocalPlaneExposure>,
    )> {
        let cfg = &r.cfg;
        out.progress(
            Stage::Image,
            0,
            2,
            "simulating the focal plane (four arrays)",
        );
        let t0 = Instant::now();
        let key = simulation_key(cfg);
        let fps = match &self.focal_plane {
            Some((k, f)) if *k == key => f.clone(),
            _ => {
                let f = Arc::new(
                    self.session
                        .new_focal_plane(cfg)
                        .map_err(failed(Stage::Image))?,
                );
                self.notes.extend(self.session.take_notes());
                self.focal_plane = Some((key.clone(), f.clone()));
                f
            }
        };
        out.check()?;
        let exp = match &self.focal_plane_exposure {
            Some((k, i, e)) if *k == key && *i == r.image_index => e.clone(),
            _ => {
                let e = Arc::new(fps.exposure(r.image_index).map_err(failed(Stage::Image))?);
                self.focal_plane_exposure = Some((key.clone(), r.image_index, e.clone()));
                e
            }
        };
        let simulate_s = t0.elapsed().as_secs_f64();
        out.check()?;
        out.progress(Stage::Image, 1, 2, "laying out the arrays");
        if let Some(sim) = fps.arrays.first() {
            // the jitter is common to the arrays: the first one's series
            self.send_series(sim, cfg, r.image_index, out);
        }
        let plane = engine::sky::focal_plane(cfg);
        let limits: Vec<(f32, f32, f32)> = exp
            .arrays
            .iter()
            .map(|e| views::display_limits(&e.image.adu, &e.image.dq))
            .collect();
        let arrays = exp
            .arrays
            .iter()
            .enumerate()
            .map(|(k, e)| FocalPlaneArray {
                adu_fp: plane.in_focal_plane_axes(k, &e.image.adu),
                adu: e.image.adu.clone(),
                wcs: engine::sky::array_wcs(cfg, k).ok().map(Arc::new),
                stars_fp: e
                    .truth
                    .iter()
                    .map(|t| plane.to_focal_plane(k, t.x_px, t.y_px))
                    .collect(),
            })
            .collect();
        out.send(Msg::FocalPlane(Box::new(FocalPlaneResult {
            generation: out.generation,
            cfg: cfg.clone(),
            cfg_hash: cfg.hash_hex(),
            image_index: r.image_index,
            plane,
            arrays,
            counts: exp.counts,
            lo_adu: limits.iter().map(|l| l.0).fold(f32::INFINITY, f32::min),
            hi_adu: limits.iter().map(|l| l.1).fold(f32::NEG_INFINITY, f32::max),
            noise_adu: limits.iter().map(|l| l.2).sum::<f32>() / limits.len().max(1) as f32,
            backend: exp
                .arrays
                .first()
                .map(|e| e.backend.clone())
                .unwrap_or_default(),
            simulate_s,
        })));
        Ok((fps, exp))
    }

    /// The crowded-field analysis of the focal plane's exposure under the chosen countermeasure (`none`
    /// instead, with a note, for one that refits single stars).
    fn crowded(
        &mut self,
        r: &Request,
        fps: &FocalPlaneSimulator,
        exp: &engine::simulate::FocalPlaneExposure,
        out: &Out,
    ) -> StageResult<()> {
        use engine::studies::crowded;
        out.progress(
            Stage::Image,
            1,
            2,
            "crowded-field analysis of the four arrays",
        );
        let t0 = Instant::now();
        let chosen = Plan::new(vec![r.countermeasure]).map_err(failed(Stage::Image))?;
        let (plan, note) = match crowded::check_plan(&chosen) {
            Ok(()) => (chosen, None),
            Err(e) => (
                Plan::new(vec![Countermeasure::None]).map_err(failed(Stage::Image))?,
                Some(format!("{e}: shown without countermeasure")),
            ),
        };
        let b = &r.cfg.scene.bulge;
        let edges = engine::scoring::crowded::edges(b.hw_min, b.hw_max, 0.5);
        let run = crowded::analyse_focal_plane(fps, exp, &plan, &edges, &Default::default())
            .map_err(failed(Stage::Image))?
            .pop()
            .ok_or_else(|| Stop::Failed(Stage::Image, "no analysis".into()))?;
        let plane = engine::sky::focal_plane(&r.cfg);
        let scale = r.cfg.instrument.plate_scale_mas();
        let fits = run
            .arrays
            .iter()
            .map(|a| ArrayFits {
                epsf: a.epsf.clone(),
                stars: a
                    .stars
                    .iter()
                    .map(|s| {
                        let t = s.truth.and_then(|k| a.truth.get(k));
                        let (dx, dy) = match t {
                            Some(_) => (s.dx_px * scale, s.dy_px * scale),
                            None => (f64::NAN, f64::NAN),
                        };
                        FittedStar {
                            x_px: s.x,
                            y_px: s.y,
                            flux_e: s.flux_e,
                            hw: t.map_or(f64::NAN, |t| t.mag_hw),
                            dx_mas: dx,
                            dy_mas: dy,
                            crlb_mas: (s.crlb_x_px.hypot(s.crlb_y_px) / 2f64.sqrt()) * scale,
                            flags: s.flags,
                        }
                    })
                    .collect(),
            })
            .collect();
        out.send(Msg::Crowded(Box::new(CrowdedResult {
            generation: out.generation,
            cfg_hash: r.cfg.hash_hex(),
            image_index: r.image_index,
            countermeasure: run.countermeasure.to_string(),
            note,
            vectors: run
                .arrays
                .iter()
                .map(|a| a.binned_vectors(&plane, scale))
                .collect(),
            summaries: run.arrays.iter().map(|a| a.summary.clone()).collect(),
            fits,
            bins: run.bins,
            plane,
            analyse_s: t0.elapsed().as_secs_f64(),
        })));
        Ok(())
    }

    fn twin(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let tcfg = twin_config(&r.cfg);
        let index = r.image_index;
        out.progress(Stage::Twin, 0, 1, "simulating the Gaussian-ACE twin");
        let sim = self.simulator(&tcfg, Stage::Twin)?;
        let exp = self.exposure(&sim, index, Stage::Twin)?;
        out.check()?;
        let img = analysis_image(&sim, &exp.image);
        let report = Source::new(&sim, index)
            .analyse_scored(
                &img,
                Some(&exp.truth),
                &tcfg,
                &Plan::default(),
                &Default::default(),
            )
            .ok()
            .map(|a| a.global.report);
        out.send(Msg::Twin(Box::new(TwinResult {
            generation: out.generation,
            cfg_hash: r.cfg.hash_hex(),
            image_index: index,
            n: exp.image.n,
            adu: exp.image.adu.clone(),
            report,
        })));
        Ok(())
    }
}
