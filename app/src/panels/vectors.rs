//! The deviation vector map: the engine's [`VectorMap`](engine::scoring::vectors::VectorMap) of the shown
//! analysis (fitted − true, mean removed, with its per-axis accuracy and reference arrow) and the fit
//! displacement the ACE predicts, drawn at the frame's star grid.

use super::axes::{MEASURED, PREDICTED};
use super::widgets::title;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results};
use egui_plot::{Arrows, Plot, PlotPoints};
use engine::scoring::vectors::Arrow;

/// Origins and tips of arrows drawn `px_per_mas` pixels per mas.
fn arrows(a: &[Arrow], px_per_mas: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    a.iter()
        .map(|a| {
            (
                [a.x_px, a.y_px],
                [
                    a.x_px + a.dx_mas * px_per_mas,
                    a.y_px + a.dy_mas * px_per_mas,
                ],
            )
        })
        .unzip()
}

pub fn vector_ui(ui: &mut egui::Ui, screen: &OnScreen, view: &mut ViewSettings, results: &Results) {
    let Some(f) = &results.frame else {
        title(ui, "Deviation vector map", false);
        ui.weak("…");
        return;
    };
    title(
        ui,
        &format!(
            "Deviations: fitted − true, mean removed [{}]",
            f.countermeasure
        ),
        f.cfg_hash != screen.cfg_hash,
    );
    let map = &f.vectors;
    if map.measured.is_empty() {
        ui.weak("no measured stars");
        return;
    }
    // drawing scale: the rms arrow is 70 % of the frame's star spacing
    let spacing = f.cfg.scene.grid_spacing_px.max(1.0);
    let px_per_mas = 0.7 * spacing / map.rms_length_mas.max(1e-6);
    let (origins, tips) = arrows(&map.measured, px_per_mas);
    let predicted = (view.show_predicted_arrows && !f.predicted.is_empty())
        .then(|| arrows(&f.predicted, px_per_mas));
    let ref_mas = map.reference_mas;
    ui.horizontal_wrapped(|ui| {
        ui.colored_label(
            MEASURED,
            format!("measured: accuracy {:.1} mas per axis", map.accuracy_mas),
        )
        .on_hover_text(format!(
            "√((σx² + σy²)/2) of the arrows; rms arrow length {:.1} mas",
            map.rms_length_mas
        ));
        ui.checkbox(
            &mut view.show_predicted_arrows,
            egui::RichText::new("ACE-predicted fit displacement").color(PREDICTED),
        );
        ui.weak(format!("(white arrow: {ref_mas} mas)"));
    });
    let (xmin, ymin) = origins
        .iter()
        .fold((f64::MAX, f64::MAX), |(a, b), o| (a.min(o[0]), b.min(o[1])));
    let ref_origin = [xmin, ymin - 1.3 * spacing];
    let ref_tip = [xmin + ref_mas * px_per_mas, ref_origin[1]];
    let ref_label = format!("{ref_mas} mas");
    Plot::new("vector_plot")
        .data_aspect(1.0)
        .x_axis_label("X [px]")
        .y_axis_label("Y [px]")
        .show(ui, |pui| {
            if let Some((o, t)) = predicted {
                pui.arrows(
                    Arrows::new("ACE-predicted", PlotPoints::new(o), PlotPoints::new(t))
                        .color(PREDICTED.gamma_multiply(0.8))
                        .tip_length(5.0),
                );
            }
            pui.arrows(
                Arrows::new(
                    format!("measured ({:.1} mas per axis)", map.accuracy_mas),
                    PlotPoints::new(origins),
                    PlotPoints::new(tips),
                )
                .color(MEASURED)
                .tip_length(5.0),
            );
            super::axes::reference_arrow(pui, ref_origin, ref_tip, 0.15 * spacing, ref_label);
        });
}
