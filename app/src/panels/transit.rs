//! The transit view: a stare of a bright target and its comparison stars (`jsim transit`), rerun as the
//! ACE, the intra-pixel response, the plate, the sub-exposure or the target change — the light curve with
//! the injected transit and the box the search found, and the noise budget beside the measured scatter.
//! Nothing is computed here but the drawing.

use super::axes::{MEASURED, PREDICTED, small_legend};
use super::widgets::{cell, title};
use crate::settings::TransitControls;
use crate::worker::transit::TransitShown;
use egui::{Color32, Rect, pos2, vec2};
use egui_plot::{Corner, Line, MarkerShape, Plot, PlotPoints, Points};

/// The left panel: the stare's knobs.
pub fn controls_ui(ui: &mut egui::Ui, c: &mut TransitControls, busy: bool) {
    ui.heading("Transit stare");
    ui.weak("a bright M dwarf and its comparison stars, read in windows plate after plate");
    let slider = |ui: &mut egui::Ui,
                  v: &mut f64,
                  r: std::ops::RangeInclusive<f64>,
                  text: &str,
                  hover: &str| {
        ui.add(egui::Slider::new(v, r).text(text))
            .on_hover_text(hover);
    };
    slider(
        ui,
        &mut c.target_hw,
        6.0..=13.0,
        "target Hw",
        "the target's magnitude",
    );
    slider(ui, &mut c.hours, 1.7..=12.0, "hours", "the stare's length");
    ui.add(egui::Slider::new(&mut c.comparisons, 1..=40).text("comparison stars"));
    slider(
        ui,
        &mut c.ace_sigma_mas,
        0.0..=1000.0,
        "ACE σ (mas)",
        "the attitude jitter's σ per plate (the configuration's ACE otherwise)",
    );
    slider(
        ui,
        &mut c.intra_pixel_amplitude,
        0.0..=0.45,
        "intra-pixel amplitude",
        "the parabolic response 1 + a(1 − 12(u − ½)²) per axis (0: uniform)",
    );
    slider(
        ui,
        &mut c.plate_s,
        1.0..=60.0,
        "plate (s)",
        "each plate's integration",
    );
    slider(
        ui,
        &mut c.exposure_s,
        0.0..=60.0,
        "sub-exposure (s)",
        "0: the longest plate/n that does not saturate; else plate/n exactly (a saturating one is an error)",
    );
    slider(
        ui,
        &mut c.depth,
        0.0..=0.02,
        "transit depth",
        "(Rp/R★)², 0: none",
    );
    slider(
        ui,
        &mut c.aperture_px,
        0.0..=11.0,
        "aperture (px)",
        "0: chosen per stare",
    );
    if ui.button("Defaults").clicked() {
        *c = TransitControls::default();
    }
    if busy {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label("simulating the stare…");
        });
    }
}

/// The central area: the light curve above, the budget below.
pub fn central_ui(ui: &mut egui::Ui, shown: Option<&Result<TransitShown, String>>, stale: bool) {
    let r = match shown {
        None => {
            ui.label("simulating the first stare…");
            return;
        }
        Some(Err(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("Error: {e}"));
            return;
        }
        Some(Ok(r)) => r,
    };
    let full = ui.available_rect_before_wrap();
    let split = full.top() + 0.62 * full.height();
    let top = Rect::from_min_max(full.min, pos2(full.right(), split));
    let bottom = Rect::from_min_max(pos2(full.left(), split), full.max);
    cell(ui, top, |ui| light_curve(ui, r, stale));
    cell(ui, bottom, |ui| budget(ui, r, stale));
    ui.allocate_rect(full, egui::Sense::hover());
}

fn light_curve(ui: &mut egui::Ui, r: &TransitShown, stale: bool) {
    let found = match &r.recovery {
        Some(rec) => format!(
            "; box found: {:.0} ± {:.0} ppm at {:.2} h (measured {:.1}σ; injected {:.0})",
            1e6 * rec.depth,
            1e6 * rec.depth_sigma,
            24.0 * rec.t0_days,
            rec.snr,
            1e6 * rec.injected_depth
        ),
        None => String::new(),
    };
    title(
        ui,
        &format!(
            "Light curve: {} plates, {} × {:.2} s co-added (longest safe {:.2} s), aperture {} px, {} comparisons{found}",
            r.hours.len(),
            r.sub_exposures,
            r.exposure_s,
            r.longest_safe_s,
            r.aperture_px,
            r.comparisons
        ),
        stale,
    );
    let pts = |x: &[f64], y: &[f64]| -> PlotPoints<'static> {
        x.iter()
            .zip(y)
            .filter(|(_, v)| v.is_finite())
            .map(|(a, b)| [*a, *b])
            .collect()
    };
    Plot::new("transit_lc")
        .legend(small_legend(Corner::LeftBottom))
        .x_axis_label("time (h)")
        .y_axis_label("relative flux")
        .show(ui, |p| {
            p.points(
                Points::new("plates", pts(&r.hours, &r.flux))
                    .radius(1.0)
                    .color(Color32::from_gray(140)),
            );
            p.points(
                Points::new("30-min bins", pts(&r.bin_hours, &r.bin_flux))
                    .radius(3.0)
                    .shape(MarkerShape::Circle)
                    .color(MEASURED),
            );
            if r.injected.iter().any(|v| *v < 1.0) {
                p.line(
                    Line::new("injected", pts(&r.hours, &r.injected))
                        .color(PREDICTED)
                        .allow_band(false),
                );
            }
            if let Some(rec) = &r.recovery {
                let (a, b) = (
                    24.0 * rec.t0_days - 0.5 * rec.duration_h,
                    24.0 * rec.t0_days + 0.5 * rec.duration_h,
                );
                let d = 1.0 - rec.depth;
                let first = r.hours.first().copied().unwrap_or(0.0);
                let last = r.hours.last().copied().unwrap_or(0.0);
                p.line(
                    Line::new(
                        "box found",
                        PlotPoints::from(vec![
                            [first, 1.0],
                            [a, 1.0],
                            [a, d],
                            [b, d],
                            [b, 1.0],
                            [last, 1.0],
                        ]),
                    )
                    .color(Color32::from_rgb(90, 160, 255))
                    .allow_band(false),
                );
            }
        });
}

fn budget(ui: &mut egui::Ui, r: &TransitShown, stale: bool) {
    title(
        ui,
        "Noise budget (ppm): predicted term by term, and measured",
        stale,
    );
    let rows = [
        ("plate", &r.budget.plate, r.precision.plate_ppm),
        ("1 h", &r.budget.hour, r.precision.hour_ppm),
        (
            "6.5 h",
            &r.budget.six_and_half_hours,
            r.precision.six_and_half_hours_ppm,
        ),
    ];
    egui::Grid::new("transit_budget")
        .striped(true)
        .spacing(vec2(18.0, 4.0))
        .show(ui, |ui| {
            ui.strong("");
            for (name, _) in rows[0].1.named() {
                ui.strong(name);
            }
            ui.strong("total");
            ui.strong("measured");
            ui.end_row();
            for (label, terms, measured) in rows {
                ui.label(label);
                for (_, v) in terms.named() {
                    ui.label(format!("{v:.0}"));
                }
                ui.label(format!("{:.0}", terms.total_ppm()));
                ui.label(
                    if measured.is_finite() && (label == "plate" || r.precision.hour_measured) {
                        format!("{measured:.0}")
                    } else {
                        "—".into()
                    },
                );
                ui.end_row();
            }
        });
    ui.add_space(6.0);
    for d in &r.detections {
        ui.label(d.describe());
    }
    ui.weak(format!(
        "{}stare simulated and analysed in {:.1} s",
        match (r.precision.hour_measured, r.precision.six_and_half_measured) {
            (true, true) => "",
            (true, false) => "6.5 h measured: the 1-h scatter / √6.5; ",
            _ => "1 h and 6.5 h measured: the plates' scatter / √N (too few hours out of the transit); ",
        },
        r.seconds
    ));
}
