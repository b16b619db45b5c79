//! The transit view's engine work: a stare (`engine::studies::transit`) on its own thread, started when the
//! transit controls change; a result of an older request is dropped.

use crate::settings::TransitControls;
use engine::config::Config;
use engine::studies::transit::budget::Budget;
use engine::studies::transit::outputs::bin;
use engine::studies::transit::run::{self, Detection, Precision, Recovery};
use std::sync::mpsc::{Receiver, channel};

/// What the transit view draws (all of it the engine's numbers).
#[derive(Debug, Clone)]
pub struct TransitShown {
    pub hours: Vec<f64>,
    pub flux: Vec<f64>,
    /// 30-min bins of the light curve.
    pub bin_hours: Vec<f64>,
    pub bin_flux: Vec<f64>,
    /// The injected transit (truth: shown as the model).
    pub injected: Vec<f64>,
    pub recovery: Option<Recovery>,
    pub budget: Budget,
    pub precision: Precision,
    pub detections: Vec<Detection>,
    pub aperture_px: f64,
    pub sub_exposures: usize,
    pub exposure_s: f64,
    pub longest_safe_s: f64,
    pub comparisons: usize,
    pub seconds: f64,
}

/// Runs stares one at a time: a change while one runs waits for it, then the newest settings run.
#[derive(Default)]
pub struct TransitRunner {
    generation: u64,
    rx: Option<Receiver<(u64, Result<TransitShown, String>)>>,
    /// The request of the running or last finished stare.
    pub requested: Option<(Config, TransitControls)>,
    pub shown: Option<Result<TransitShown, String>>,
    pub busy: bool,
}

impl TransitRunner {
    /// Whether what is shown is for other settings than these.
    pub fn stale(&self, cfg: &Config, controls: &TransitControls) -> bool {
        self.requested.as_ref() != Some(&(cfg.clone(), controls.clone())) || self.busy
    }
}

impl TransitRunner {
    /// Take a finished result; start a stare for these settings unless one runs or the last was for them.
    pub fn update(&mut self, cfg: &Config, controls: &TransitControls, ctx: &egui::Context) {
        if let Some(rx) = &self.rx {
            while let Ok((g, r)) = rx.try_recv() {
                if g == self.generation {
                    self.shown = Some(r);
                    self.busy = false;
                }
            }
        }
        let want = (cfg.clone(), controls.clone());
        // one stare at a time: a change made while one runs starts when it ends
        if self.busy || self.requested.as_ref() == Some(&want) {
            return;
        }
        self.generation += 1;
        self.requested = Some(want);
        self.busy = true;
        let (tx, rx) = channel();
        self.rx = Some(rx);
        let (g, cfg, spec, ctx) = (
            self.generation,
            controls.config(cfg),
            controls.spec(),
            ctx.clone(),
        );
        let spawned = std::thread::Builder::new()
            .name("jsim-transit".into())
            .spawn(move || {
                let t = std::time::Instant::now();
                let r = run::run(&cfg, &spec)
                    .map(|(obs, r)| {
                        let hours: Vec<f64> = r.lc.t_days.iter().map(|t| 24.0 * t).collect();
                        let (bin_hours, bin_flux) = bin(&hours, &r.lc.flux, 0.5);
                        TransitShown {
                            bin_hours,
                            bin_flux,
                            flux: r.lc.flux.clone(),
                            injected: obs.truth.iter().map(|t| t.transit_flux).collect(),
                            hours,
                            recovery: r.recovery,
                            budget: r.budget,
                            precision: r.precision,
                            detections: r.detections.clone(),
                            aperture_px: r.lc.aperture_px,
                            sub_exposures: r.readout.sub_exposures,
                            exposure_s: r.readout.exposure_s,
                            longest_safe_s: r.readout.longest_safe_s,
                            comparisons: obs.stars.len() - 1,
                            seconds: t.elapsed().as_secs_f64(),
                        }
                    })
                    .map_err(|e| e.to_string());
                let _ = tx.send((g, r));
                ctx.request_repaint();
            });
        if let Err(e) = spawned {
            self.shown = Some(Err(format!("cannot start the transit thread: {e}")));
            self.busy = false;
        }
    }
}
