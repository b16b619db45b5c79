//! The curve stage: accuracy against magnitude. First the instant predictor at every magnitude (the curve's
//! first shape), then the Monte Carlo datasets as `jsim experiment` runs them (the engine's
//! [`experiment::analyse_exposure`] per image and [`experiment::summarise`]), cancellable between images.

use super::out::{Out, StageResult, failed};
use super::protocol::{CurvePoint, Msg, Request, Stage};
use super::stages::EngineState;
use engine::analysis::countermeasures::Countermeasure;
use engine::config::Config;
use engine::simulate::{SimError, Simulator};
use engine::studies::experiment::{self, ImageResult};
use engine::studies::predict::Predictor;
use std::sync::Arc;
use std::time::Instant;

impl EngineState {
    /// A simulator of exactly `cfg`, analysis knobs included (the dataset's analysis reads them from it):
    /// the session's when it has that one, else a new one on the session's PSFs and kernels (kept out of
    /// the session's few slots, which hold the frame on display and its twin).
    fn dataset_simulator(&self, cfg: &Config) -> Result<Arc<Simulator>, SimError> {
        if self.session.has_simulator(cfg) {
            let sim = self.session.simulator(cfg)?;
            if sim.cfg == *cfg {
                return Ok(sim);
            }
        }
        Ok(Arc::new(self.session.new_simulator(cfg)?))
    }

    pub(super) fn curve(&mut self, r: &Request, out: &Out) -> StageResult<()> {
        let plan = r.plan().map_err(failed(Stage::Curve))?;
        let cm = r.countermeasure;
        let cm_name = cm.to_string();
        let plan_key = plan
            .countermeasures
            .iter()
            .map(|c| c.to_string())
            .collect::<Vec<_>>()
            .join(",");
        let cfgs: Vec<Config> = r
            .mags
            .iter()
            .map(|&m| {
                let mut c = r.cfg.clone();
                c.scene.mag_hw = m;
                c
            })
            .collect();
        // 1. the predictor at every magnitude (cheap): the curve's first shape
        for c in &cfgs {
            out.check()?;
            let key = (c.hash_hex(), cm_name.clone());
            let (p, p_none) = match self.curve_pred.get(&key) {
                Some(v) => *v,
                None => {
                    out.progress(
                        Stage::Curve,
                        0,
                        cfgs.len(),
                        format!("predicting Hw = {}", c.scene.mag_hw),
                    );
                    let sim = self.dataset_simulator(c).map_err(failed(Stage::Curve))?;
                    let pred = Predictor::new(&sim, &c.analysis).map_err(failed(Stage::Curve))?;
                    let v = (
                        pred.predict(&cm).unwrap_or(f64::NAN),
                        pred.predict(&Countermeasure::None).unwrap_or(f64::NAN),
                    );
                    self.curve_pred.insert(key, v);
                    v
                }
            };
            out.send(Msg::Curve(Box::new(CurvePoint {
                generation: out.generation,
                mag: c.scene.mag_hw,
                predicted_mas: Some(p).filter(|v| v.is_finite()),
                predicted_none_mas: Some(p_none).filter(|v| v.is_finite()),
                rows: self
                    .curve_rows
                    .get(&(c.hash_hex(), plan_key.clone()))
                    .cloned(),
            })));
        }
        // 2. the Monte Carlo datasets, image by image (cancellable between images)
        let images = r.cfg.fidelity.images;
        let total = images * cfgs.len();
        for (k, c) in cfgs.iter().enumerate() {
            let key = (c.hash_hex(), plan_key.clone());
            if self.curve_rows.contains_key(&key) {
                continue;
            }
            out.check()?;
            let t0 = Instant::now();
            let sim = self.dataset_simulator(c).map_err(failed(Stage::Curve))?;
            // the dataset is one stare: its stack references the stack-referenced plate models
            let mut stare = Vec::with_capacity(images);
            for i in 0..images {
                out.check()?;
                out.progress(
                    Stage::Curve,
                    k * images + i,
                    total,
                    format!("Hw = {}: image {}/{}", c.scene.mag_hw, i + 1, images),
                );
                stare.push(
                    experiment::analyse_in_stare(&sim, i, &plan).map_err(failed(Stage::Curve))?,
                );
            }
            let results: Vec<ImageResult> =
                experiment::finish_stare(&sim, &plan, stare).map_err(failed(Stage::Curve))?;
            // the predictions of step 1, for the plan's countermeasures
            let p = self
                .curve_pred
                .get(&(c.hash_hex(), cm_name.clone()))
                .copied();
            let predicted = |name: &str| match p {
                Some((v, _)) if name == cm_name => v,
                Some((_, v)) if name == Countermeasure::None.to_string() => v,
                _ => f64::NAN,
            };
            let rows = experiment::summarise(c, &results, &predicted, t0.elapsed().as_secs_f64());
            self.curve_rows.insert(key, rows.clone());
            out.send(Msg::Curve(Box::new(CurvePoint {
                generation: out.generation,
                mag: c.scene.mag_hw,
                predicted_mas: p.map(|v| v.0).filter(|v| v.is_finite()),
                predicted_none_mas: p.map(|v| v.1).filter(|v| v.is_finite()),
                rows: Some(rows),
            })));
        }
        out.progress(Stage::Curve, total, total, "done");
        Ok(())
    }
}
