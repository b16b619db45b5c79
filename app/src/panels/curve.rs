//! Accuracy against magnitude: the Monte Carlo mean ± s.e.m. per magnitude (the engine's dataset rows), the
//! median Cramér–Rao bound, the instant prediction and the 4-mas goal.

use super::axes::{BOUND, MEASURED, PREDICTED, small_legend};
use super::widgets::title;
use crate::action::Action;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results};
use egui::Color32;
use egui_plot::{Corner, HLine, Line, LineStyle, MarkerShape, Plot, PlotPoints, Points};
use engine::analysis::countermeasures::Countermeasure;

/// Accuracy against magnitude: Monte Carlo mean ± s.e.m., the median CRLB and the instant prediction.
pub fn curve_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &ViewSettings,
    results: &Results,
    actions: &mut Vec<Action>,
) {
    let cm = screen.countermeasure.to_string();
    let stale = results
        .curve_key
        .as_ref()
        .is_some_and(|k| *k != screen.curve_key);
    let cfg = &screen.cfg;
    ui.horizontal(|ui| {
        title(
            ui,
            &format!(
                "Accuracy vs magnitude ({} images per point, {}, {})",
                cfg.fidelity.images,
                cfg.ace.case.name(),
                cfg.readout.order.name()
            ),
            stale,
        );
        if !view.auto_curve && ui.button("Run curve").clicked() {
            actions.push(Action::RunCurve);
        }
    });
    let curve = &results.curve;
    if curve.is_empty() {
        ui.centered_and_justified(|ui| {
            ui.weak(if view.auto_curve {
                "the curve follows the frame…"
            } else {
                "press Run curve (it simulates images × magnitudes)"
            });
        });
        return;
    }
    let rows_of = |name: &str| -> Vec<(f64, f64, f64, f64)> {
        curve
            .iter()
            .filter_map(|c| {
                c.rows.as_ref().and_then(|rows| {
                    rows.iter()
                        .find(|r| r.countermeasure == name)
                        .map(|r| (c.mag, r.accuracy_mas, r.sem_mas, r.crlb_mas))
                })
            })
            .collect()
    };
    let main = rows_of(&cm);
    let none = Countermeasure::None.to_string();
    let plain = if cm != none {
        rows_of(&none)
    } else {
        Vec::new()
    };
    let predicted: Vec<[f64; 2]> = curve
        .iter()
        .filter_map(|c| c.predicted_mas.map(|p| [c.mag, p]))
        .collect();
    let done = curve.iter().filter(|c| c.rows.is_some()).count();
    ui.small(format!(
        "{done}/{} magnitudes simulated · diamonds: instant predictor · grey: no countermeasure",
        screen.mags.len()
    ));
    Plot::new("curve_plot")
        .legend(small_legend(Corner::LeftTop))
        .x_axis_label("Hw [mag]")
        .y_axis_label("single-image accuracy [mas]")
        .include_y(0.0)
        .include_x(screen.mags.first().copied().unwrap_or(12.0) - 0.25)
        .include_x(screen.mags.last().copied().unwrap_or(14.0) + 0.25)
        .show(ui, |pui| {
            pui.hline(
                HLine::new("4 mas goal", 4.0)
                    .color(Color32::from_gray(140))
                    .style(LineStyle::dashed_loose()),
            );
            if predicted.len() > 1 {
                pui.line(
                    Line::new(
                        format!("predicted [{cm}]"),
                        PlotPoints::new(predicted.clone()),
                    )
                    .color(PREDICTED)
                    .style(LineStyle::dashed_dense())
                    .width(1.5),
                );
            }
            pui.points(
                Points::new(format!("predicted [{cm}]"), PlotPoints::new(predicted))
                    .shape(MarkerShape::Diamond)
                    .radius(3.0)
                    .color(PREDICTED),
            );
            let crlb: Vec<[f64; 2]> = main.iter().map(|r| [r.0, r.3]).collect();
            if !crlb.is_empty() {
                pui.line(
                    Line::new("CRLB (median)", PlotPoints::new(crlb))
                        .color(BOUND)
                        .width(1.5),
                );
            }
            for (rows, name, colour) in [
                (
                    &plain,
                    "measured [none]".to_string(),
                    Color32::from_gray(150),
                ),
                (&main, format!("measured [{cm}] ± s.e.m."), MEASURED),
            ] {
                if rows.is_empty() {
                    continue;
                }
                for r in rows.iter() {
                    pui.line(
                        Line::new(
                            name.clone(),
                            PlotPoints::new(vec![[r.0, r.1 - r.2], [r.0, r.1 + r.2]]),
                        )
                        .color(colour)
                        .width(1.5),
                    );
                }
                pui.points(
                    Points::new(
                        name.clone(),
                        PlotPoints::new(rows.iter().map(|r| [r.0, r.1]).collect()),
                    )
                    .shape(MarkerShape::Circle)
                    .filled(true)
                    .radius(4.0)
                    .color(colour),
                );
            }
        });
}
