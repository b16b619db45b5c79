//! The summary line: the instant prediction, the measured accuracy of the shown image and its bound, the
//! Gaussian twin, and where the numbers come from.

use crate::state::{OnScreen, Results};

fn mas(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2} mas")
    } else {
        "–".into()
    }
}

pub fn summary_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results) {
    let hash = &screen.cfg_hash;
    ui.horizontal_wrapped(|ui| {
        match &results.prediction {
            Some(p) => {
                let stale = p.cfg_hash != *hash || p.countermeasure != screen.countermeasure;
                let text = format!(
                    "Predicted accuracy (instant): {} [image #{}, {}]",
                    mas(p.image_mas),
                    p.image_index,
                    p.countermeasure
                );
                let r = if stale {
                    ui.weak(text)
                } else {
                    ui.strong(text)
                };
                r.on_hover_text(format!(
                    "the instant predictor (no image simulated): without countermeasure {}; \
                     noise floor = CRLB under the exact ePSF; {:.0} ms",
                    mas(p.dataset_none_mas),
                    p.elapsed_s * 1e3
                ));
                ui.label(format!(
                    "dataset mean {} · noise floor {}",
                    mas(p.dataset_mas),
                    mas(p.noise_floor_mas)
                ));
            }
            None => {
                ui.weak("Predicted accuracy (instant): …");
            }
        }
        ui.separator();
        match &results.frame {
            Some(f) => {
                let r = &f.report;
                let text = format!(
                    "Measured accuracy: {} (x {}, y {}) [image #{}, {}]",
                    mas(r.accuracy_mas),
                    mas(r.accuracy_x_mas),
                    mas(r.accuracy_y_mas),
                    f.image_index,
                    f.countermeasure
                );
                if f.cfg_hash != *hash {
                    ui.weak(text);
                } else {
                    ui.strong(text);
                }
                ui.label(format!(
                    "CRLB {} · ratio {:.2} · {}/{} stars",
                    mas(r.crlb_median_mas),
                    r.accuracy_over_crlb,
                    r.n_used,
                    f.truth_xy.len()
                ));
                ui.separator();
                let twin = results
                    .twin
                    .as_ref()
                    .filter(|t| t.image_index == f.image_index)
                    .and_then(|t| t.report.as_ref())
                    .map(|r| mas(r.accuracy_mas))
                    .unwrap_or_else(|| "…".into());
                ui.label(format!("Gaussian twin: {twin}"));
                ui.separator();
                ui.weak(format!(
                    "{} · {} readout · config {}",
                    f.backend,
                    f.cfg.readout.order.name(),
                    f.cfg_hash
                ))
                .on_hover_text(f.backend_note.clone().unwrap_or_else(|| {
                    "integration backend, readout and config hash of this frame".into()
                }));
                ui.weak(format!(
                    "timing: sim {:.1} s · analysis {:.1} s",
                    f.simulate_s, f.analyse_s
                ));
            }
            None => {
                ui.weak("Measured accuracy: …");
            }
        }
    });
}
