//! The quad's analysis cells: the crowded-field analysis of the focal plane's exposure
//! ([`CrowdedResult`](crate::worker::CrowdedResult), all numbers from the engine) — each array's deviation
//! map in the focal plane's sky layout (bound-weighted mean per cell), and accuracy against magnitude over the four arrays with the bound,
//! completeness and the 4-mas line.

use super::axes::{BOUND, MEASURED, decade_label, decade_marks, small_legend};
use super::widgets::title;
use crate::state::{OnScreen, Results};
use egui::Color32;
use egui_plot::{Arrows, Corner, HLine, Line, LineStyle, Plot, PlotPoints, uniform_grid_spacer};

/// One colour per array.
pub const ARRAY_COLOURS: [Color32; 4] = [
    Color32::from_rgb(90, 200, 120),
    Color32::from_rgb(90, 160, 255),
    Color32::from_rgb(255, 150, 60),
    Color32::from_rgb(230, 100, 200),
];

fn waiting(ui: &mut egui::Ui, what: &str, results: &Results) {
    title(ui, what, false);
    ui.weak(if results.focal_plane.is_some() {
        "analysing the crowded field (four arrays)…"
    } else {
        "…"
    });
}

/// Each array's deviation map (mean fitted − true per cell, the array's offset removed) where the array sits.
pub fn vectors_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results) {
    let Some(c) = &results.crowded else {
        waiting(ui, "Deviation vector maps", results);
        return;
    };
    title(
        ui,
        &format!(
            "Deviations per array: weighted mean fitted − true per cell [{}]",
            c.countermeasure
        ),
        c.cfg_hash != screen.cfg_hash,
    );
    let rms = {
        let v: Vec<f64> = c
            .vectors
            .iter()
            .flatten()
            .map(|a| a.2 * a.2 + a.3 * a.3)
            .collect();
        (v.iter().sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    ui.small(format!(
        "rms cell arrow {rms:.1} mas · each array's own offset removed{}",
        c.note
            .as_deref()
            .map(|n| format!(" · {n}"))
            .unwrap_or_default()
    ));
    let plane = &c.plane;
    let cell = plane.array_px as f64 / engine::studies::crowded::VECTOR_CELLS as f64;
    let px_per_mas = 0.7 * cell / rms.max(1e-6);
    Plot::new("crowded_vectors")
        .data_aspect(1.0)
        .legend(small_legend(Corner::LeftTop))
        .x_axis_label("focal plane x [px]")
        .y_axis_label("focal plane y [px]")
        .show(ui, |pui| {
            let h = (plane.array_px as f64 - 1.0) / 2.0;
            for (k, v) in c.vectors.iter().enumerate() {
                let colour = ARRAY_COLOURS[k % 4];
                let (cx, cy) = plane.centre(k);
                let outline = vec![
                    [cx - h, cy - h],
                    [cx + h, cy - h],
                    [cx + h, cy + h],
                    [cx - h, cy + h],
                    [cx - h, cy - h],
                ];
                let name = format!("array {}", k + 1);
                pui.line(
                    Line::new(name.clone(), PlotPoints::new(outline))
                        .color(colour.gamma_multiply(0.5))
                        .width(1.0),
                );
                let (o, t): (Vec<[f64; 2]>, Vec<[f64; 2]>) = v
                    .iter()
                    .map(|a| ([a.0, a.1], [a.0 + a.2 * px_per_mas, a.1 + a.3 * px_per_mas]))
                    .unzip();
                pui.arrows(
                    Arrows::new(name, PlotPoints::new(o), PlotPoints::new(t))
                        .color(colour)
                        .tip_length(6.0),
                );
            }
        });
}

/// Accuracy of isolated and crowded stars against Hw over the arrays, the median bound, completeness and
/// the 4-mas line (log accuracy axis; completeness in a strip below).
pub fn curve_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results) {
    let Some(c) = &results.crowded else {
        waiting(ui, "Accuracy vs magnitude", results);
        return;
    };
    title(
        ui,
        &format!(
            "One crowded exposure: accuracy vs magnitude, four arrays [{}]",
            c.countermeasure
        ),
        c.cfg_hash != screen.cfg_hash,
    );
    let found: usize = c.summaries.iter().map(|s| s.n_first + s.n_residual).sum();
    let fallback = c.summaries.iter().any(|s| !s.fallback.is_empty());
    ui.small(format!(
        "{found} stars measured in {:.1} s{}",
        c.analyse_s,
        if fallback {
            " · an array has no ePSF of its own (see the report)"
        } else {
            ""
        }
    ));
    let centre = |b: &engine::scoring::crowded::MagBin| 0.5 * (b.hw_lo + b.hw_hi);
    let log_line = |f: &dyn Fn(&engine::scoring::crowded::MagBin) -> f64| -> Vec<[f64; 2]> {
        c.bins
            .iter()
            .filter_map(|b| {
                let v = f(b);
                (v.is_finite() && v > 0.0).then(|| [centre(b), v.log10()])
            })
            .collect()
    };
    // both plots span the bins (x aligned)
    let x_lo = c.bins.first().map(|b| b.hw_lo).unwrap_or(8.0);
    let x_hi = c.bins.last().map(|b| b.hw_hi).unwrap_or(17.0);
    let h = ui.available_height();
    let strip = (h * 0.28).clamp(40.0, 120.0);
    Plot::new("crowded_curve")
        .height(h - strip - 4.0)
        .legend(small_legend(Corner::LeftTop))
        .x_axis_label("Hw [mag]")
        .y_axis_label("accuracy per axis [mas]")
        .y_grid_spacer(decade_marks)
        .x_grid_spacer(uniform_grid_spacer(|_| [1.0, 2.0, 4.0]))
        .y_axis_formatter(|m, _| decade_label(m))
        .include_x(x_lo)
        .include_x(x_hi)
        .show(ui, |pui| {
            pui.hline(
                HLine::new("4 mas goal", 4f64.log10())
                    .color(Color32::from_gray(140))
                    .style(LineStyle::dashed_loose()),
            );
            pui.line(
                Line::new(
                    "CRLB (isolated, median)",
                    PlotPoints::new(log_line(&|b| b.isolated.crlb_mas)),
                )
                .color(BOUND)
                .width(1.5),
            );
            pui.line(
                Line::new(
                    "isolated stars",
                    PlotPoints::new(log_line(&|b| b.isolated.accuracy_mas)),
                )
                .color(MEASURED)
                .width(2.0),
            );
            pui.line(
                Line::new(
                    "crowded stars",
                    PlotPoints::new(log_line(&|b| b.crowded.accuracy_mas)),
                )
                .color(Color32::from_gray(160))
                .style(LineStyle::dashed_dense())
                .width(1.5),
            );
        });
    let lin = |f: &dyn Fn(&engine::scoring::crowded::MagBin) -> f64| -> Vec<[f64; 2]> {
        c.bins
            .iter()
            .filter_map(|b| {
                let v = f(b);
                v.is_finite().then(|| [centre(b), 100.0 * v])
            })
            .collect()
    };
    Plot::new("crowded_completeness")
        .height(strip)
        .legend(small_legend(Corner::LeftBottom))
        .y_axis_label("%")
        .x_grid_spacer(uniform_grid_spacer(|_| [1.0, 2.0, 4.0]))
        .include_y(0.0)
        .include_y(100.0)
        .include_x(x_lo)
        .include_x(x_hi)
        .show(ui, |pui| {
            pui.line(
                Line::new("completeness", PlotPoints::new(lin(&|b| b.completeness)))
                    .color(MEASURED)
                    .width(1.5),
            );
            pui.line(
                Line::new("blended", PlotPoints::new(lin(&|b| b.frac_blended)))
                    .color(Color32::from_gray(160))
                    .width(1.0),
            );
        });
}
