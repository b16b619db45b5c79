//! The ACE time series around the shown exposure, with the chosen pixel's exposure window shaded. The
//! window and the readout are those of the configuration the series was generated with.

use super::axes::{X_COLOUR, Y_COLOUR};
use super::widgets::title;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results, chosen_pixel};
use egui::Color32;
use egui_plot::{Line, Plot, PlotPoints, Span};
use engine::config::{AceCase, RowDirection};
use engine::readout::ReadoutTiming;

pub fn ace_ui(ui: &mut egui::Ui, screen: &OnScreen, view: &ViewSettings, results: &Results) {
    let series = results
        .series
        .as_ref()
        .filter(|s| s.image_index == view.image_index);
    title(
        ui,
        &format!("ACE time series of exposure #{}", view.image_index),
        series.is_some_and(|s| s.cfg_hash != screen.cfg_hash),
    );
    let Some(s) = series else {
        ui.centered_and_justified(|ui| {
            ui.weak("generating the series…");
        });
        return;
    };
    let cfg = &s.cfg;
    let pixel = chosen_pixel(view, results.frame.as_ref());
    let window = pixel.map(|(x, y)| ReadoutTiming::new(cfg).window_s(x, y));
    let caption = match (pixel, window) {
        (Some((x, y)), Some((a, b))) => format!(
            "pixel ({x}, {y}) integrates {a:.3}–{b:.3} s ({} readout, rows {})",
            cfg.readout.order.name(),
            match cfg.readout.row_direction {
                RowDirection::Up => "up",
                RowDirection::Down => "down",
            }
        ),
        _ => "click the frame to choose a pixel".into(),
    };
    ui.horizontal_wrapped(|ui| {
        ui.small(caption);
        if s.x.is_empty() {
            return;
        }
        let (sx, sy) = s.achieved_sigma_mas;
        ui.label(
            egui::RichText::new(format!("x: σ {sx:.0} mas"))
                .small()
                .color(X_COLOUR),
        );
        ui.label(
            egui::RichText::new(format!("y: σ {sy:.0} mas"))
                .small()
                .color(Y_COLOUR),
        );
    });
    if cfg.ace.case != AceCase::Realistic || s.x.is_empty() {
        ui.centered_and_justified(|ui| match cfg.ace.case {
            AceCase::Realistic => {
                ui.weak("no series");
            }
            AceCase::Gaussian => {
                ui.weak(format!(
                    "Gaussian ACE: no time series — every pixel sees the same blur of σ = {:.0} mas",
                    cfg.ace.sigma_mas
                ));
            }
            AceCase::None => {
                ui.weak("still telescope: no attitude error");
            }
        });
        return;
    }
    Plot::new("ace_plot")
        .x_axis_label("t from exposure start [s]")
        .y_axis_label("ACE [mas]")
        .show(ui, |pui| {
            if let Some((a, b)) = window {
                pui.span(
                    Span::new("chosen pixel's window", a..=b)
                        .fill(Color32::from_rgba_unmultiplied(255, 255, 120, 28))
                        .border_color(Color32::from_rgb(200, 200, 90)),
                );
            }
            pui.line(
                Line::new("x", PlotPoints::new(s.x.clone()))
                    .color(X_COLOUR)
                    .width(1.0),
            );
            pui.line(
                Line::new("y", PlotPoints::new(s.y.clone()))
                    .color(Y_COLOUR)
                    .width(1.0),
            );
        });
}
