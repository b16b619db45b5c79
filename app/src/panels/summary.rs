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
                    "the instant predictor (no image simulated){}: without countermeasure {}; \
                     noise floor = CRLB under the exact ePSF; {:.0} ms",
                    p.models
                        .as_ref()
                        .map_or(String::new(), |m| format!(" of {m}")),
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
        if engine::sky::array_count(&screen.cfg) > 1 {
            quad_measured_ui(ui, screen, results);
            return;
        }
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

/// The quad focal plane's measured accuracy: the isolated stars of the magnitude bin holding the explorer's
/// magnitude, over the four arrays (the crowded-field analysis' bins), with their bound.
fn quad_measured_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results) {
    let Some(c) = &results.crowded else {
        ui.weak("Measured accuracy (focal plane): …");
        return;
    };
    let m = screen.cfg.scene.mag_hw;
    let Some(b) = c.bins.iter().find(|b| m >= b.hw_lo && m < b.hw_hi) else {
        ui.weak(format!(
            "Measured accuracy: Hw {m} is outside the field's bins [{}]",
            c.countermeasure
        ));
        return;
    };
    let text = format!(
        "Measured accuracy (focal plane, isolated stars Hw {:.1}–{:.1}): {} [image #{}, {}]",
        b.hw_lo,
        b.hw_hi,
        mas(b.isolated.accuracy_mas),
        c.image_index,
        c.countermeasure
    );
    if c.cfg_hash != screen.cfg_hash {
        ui.weak(text);
    } else {
        ui.strong(text);
    }
    ui.label(format!(
        "CRLB {} · {} isolated of {} found, {} true · completeness {:.3}",
        mas(b.isolated.crlb_mas),
        b.isolated.n,
        b.n_found,
        b.n_true,
        b.completeness
    ));
    ui.separator();
    ui.weak(format!("analysis {:.1} s (4 arrays)", c.analyse_s));
}
