//! Plot panels: the ACE PSD (log–log), the ACE time series with the chosen pixel's exposure window, the
//! deviation vector map, and the accuracy-vs-magnitude curve.

use crate::app::{Action, ExplorerApp, curve_key};
use crate::panels::image::chosen_pixel;
use egui::Color32;
use egui_plot::{
    Arrows, AxisHints, Corner, GridInput, GridMark, HLine, HoverPosition, Legend, Line, LineStyle,
    MarkerShape, Plot, PlotPoint, PlotPoints, Points, Span, Text, VLine,
};
use engine::analysis::epsf::fit::flags;
use engine::jitter::Psd;
use engine::readout::ReadoutTiming;

const X_COLOUR: Color32 = Color32::from_rgb(90, 160, 255);
const Y_COLOUR: Color32 = Color32::from_rgb(255, 150, 60);
const MEASURED: Color32 = Color32::from_rgb(90, 200, 120);
const PREDICTED: Color32 = Color32::from_rgb(255, 150, 60);
const BOUND: Color32 = Color32::from_rgb(170, 130, 255);

fn small_legend(corner: Corner) -> Legend {
    Legend::default()
        .position(corner)
        .text_style(egui::TextStyle::Small)
        .background_alpha(0.6)
}

/// Grid marks at every decade (labelled) and at 2…9 × each decade, for axes that hold log10 values.
fn decade_marks(input: GridInput) -> Vec<GridMark> {
    let (a, b) = input.bounds;
    let mut v = Vec::new();
    if !(b > a) || (b - a) > 60.0 {
        return v;
    }
    let (lo, hi) = (a.floor() as i64, b.ceil() as i64);
    for d in lo..=hi {
        v.push(GridMark {
            value: d as f64,
            step_size: 1.0,
        });
        if b - a < 8.0 {
            for k in 2..10 {
                v.push(GridMark {
                    value: d as f64 + (k as f64).log10(),
                    step_size: 0.1,
                });
            }
        }
    }
    v.retain(|m| m.value >= a && m.value <= b);
    v
}

/// Axis label of a log10 value: the number at decades, nothing in between.
fn decade_label(mark: GridMark) -> String {
    if (mark.value - mark.value.round()).abs() > 1e-6 {
        return String::new();
    }
    let e = mark.value.round() as i32;
    match e {
        -3..=3 => format!("{}", 10f64.powi(e)),
        _ => format!("1e{e}"),
    }
}

/// The ACE PSD model (engine) with the Welch estimate of the generated series.
pub fn psd_ui(ui: &mut egui::Ui, app: &mut ExplorerApp) {
    let a = &app.cfg.ace;
    let stale_series = app
        .rt
        .series
        .as_ref()
        .is_some_and(|s| s.cfg_hash != app.cfg.hash_hex());
    super::title(
        ui,
        "ACE power spectral density (per axis, log–log)",
        stale_series,
    );
    let psd = Psd::from_config(a);
    let dt = a.sample_interval_ms * 1e-3;
    let (f0, f1) = (1.0 / a.span_s.max(1e-3), 0.5 / dt.max(1e-9));
    // log grid, plus points across each mode's peak so narrow Lorentzians are drawn
    let mut fs: Vec<f64> = (0..=600)
        .map(|k| (f0.ln() + (f1.ln() - f0.ln()) * k as f64 / 600.0).exp())
        .collect();
    for m in &a.modes {
        for k in -12..=12 {
            let f = m.freq_hz + m.width_hz * (k as f64) * (k as f64).abs() / 12.0;
            if f > f0 && f < f1 {
                fs.push(f);
            }
        }
    }
    fs.sort_by(|x, y| x.total_cmp(y));
    let model: PlotPoints = fs
        .iter()
        .filter_map(|&f| {
            let p = psd.eval(f);
            (p > 0.0).then(|| [f.log10(), p.log10()])
        })
        .collect();
    let continuum: PlotPoints = fs
        .iter()
        .filter_map(|&f| {
            let p = psd.continuum(f);
            (p > 0.0).then(|| [f.log10(), p.log10()])
        })
        .collect();
    let t_exp = app.cfg.detector.exposure_s;
    Plot::new("psd_plot")
        .legend(small_legend(Corner::RightTop))
        .custom_x_axes(vec![
            AxisHints::new_x()
                .label("f [Hz]")
                .formatter(|m, _| decade_label(m))
                .label_spacing(28.0..=40.0),
        ])
        .y_axis_label("PSD [model units / Hz]")
        .x_grid_spacer(decade_marks)
        .y_grid_spacer(decade_marks)
        .y_axis_formatter(|m, _| decade_label(m))
        .label_formatter(|pos| {
            let (name, p) = match pos {
                HoverPosition::NearDataPoint {
                    plot_name,
                    position,
                    ..
                } => (*plot_name, *position),
                HoverPosition::Elsewhere { position } => ("", *position),
            };
            Some(format!(
                "{name}\nf = {:.3} Hz\nPSD = {:.3e}",
                10f64.powf(p.x),
                10f64.powf(p.y)
            ))
        })
        .show(ui, |pui| {
            pui.line(
                Line::new("continuum", continuum)
                    .color(X_COLOUR)
                    .style(LineStyle::dashed_dense())
                    .width(1.0),
            );
            pui.line(
                Line::new("model PSD (continuum + modes)", model)
                    .color(X_COLOUR)
                    .width(1.5),
            );
            if let Some(s) = &app.rt.series {
                pui.line(
                    Line::new(
                        "Welch PSD of the generated series",
                        PlotPoints::new(s.welch_log.clone()),
                    )
                    .color(Color32::from_rgb(235, 235, 235))
                    .width(1.0),
                );
            }
            if a.boundary_freq_hz > 0.0 {
                pui.vline(
                    VLine::new("boundary f_b", a.boundary_freq_hz.log10())
                        .color(Color32::from_gray(120))
                        .style(LineStyle::dashed_loose()),
                );
            }
            if t_exp > 0.0 {
                pui.vline(
                    VLine::new("1 / exposure", (1.0 / t_exp).log10())
                        .color(Y_COLOUR)
                        .style(LineStyle::dashed_loose()),
                );
            }
        });
}

/// The ACE series around the shown exposure, with the chosen pixel's window shaded.
pub fn ace_ui(ui: &mut egui::Ui, app: &mut ExplorerApp) {
    let timing = ReadoutTiming::new(&app.cfg);
    let pixel = chosen_pixel(app);
    let window = pixel.map(|(x, y)| timing.window_s(x, y));
    let series = app
        .rt
        .series
        .as_ref()
        .filter(|s| s.image_index == app.view.image_index);
    let stale = series.is_some_and(|s| s.cfg_hash != app.cfg.hash_hex());
    super::title(
        ui,
        &format!("ACE time series of exposure #{}", app.view.image_index),
        stale,
    );
    let caption = match (pixel, window) {
        (Some((x, y)), Some((a, b))) => format!(
            "pixel ({x}, {y}) integrates {a:.3}–{b:.3} s ({} readout, rows {})",
            app.cfg.readout.order.name(),
            match app.cfg.readout.row_direction {
                engine::config::RowDirection::Up => "up",
                engine::config::RowDirection::Down => "down",
            }
        ),
        _ => "click the frame to choose a pixel".into(),
    };
    ui.horizontal_wrapped(|ui| {
        ui.small(caption);
        if let Some(s) = series {
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
        }
    });
    let Some(s) = series.filter(|_| app.cfg.ace.case == engine::config::AceCase::Realistic) else {
        ui.centered_and_justified(|ui| match app.cfg.ace.case {
            engine::config::AceCase::Realistic => {
                ui.weak("generating the series…");
            }
            engine::config::AceCase::Gaussian => {
                ui.weak(format!(
                    "Gaussian ACE: no time series — every pixel sees the same blur of σ = {:.0} mas",
                    app.cfg.ace.sigma_mas
                ));
            }
            engine::config::AceCase::None => {
                ui.weak("still telescope: no attitude error");
            }
        });
        return;
    };
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

fn nice_length(v: f64) -> f64 {
    if !(v > 0.0) || !v.is_finite() {
        return 1.0;
    }
    let e = v.log10().floor();
    let b = 10f64.powf(e);
    let m = v / b;
    let k = if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    };
    k * b
}

/// Measured deviation of every star (fitted − true, common offset removed), with a reference arrow.
pub fn vector_ui(ui: &mut egui::Ui, app: &mut ExplorerApp) {
    let Some(f) = &app.rt.frame else {
        super::title(ui, "Deviation vector map", false);
        ui.weak("…");
        return;
    };
    super::title(
        ui,
        &format!(
            "Deviations: fitted − true, mean removed [{}]",
            f.countermeasure
        ),
        f.cfg_hash != app.cfg.hash_hex(),
    );
    let scale_mas = app.cfg.instrument.plate_scale_mas();
    let used: Vec<_> = f
        .stars
        .iter()
        .filter(|s| {
            s.truth.is_some()
                && s.flags & flags::REJECT == 0
                && s.dx_px.is_finite()
                && s.dy_px.is_finite()
        })
        .collect();
    if used.is_empty() {
        ui.weak("no measured stars");
        return;
    }
    let k = used.len() as f64;
    let (mx, my) = (
        used.iter().map(|s| s.dx_px).sum::<f64>() / k,
        used.iter().map(|s| s.dy_px).sum::<f64>() / k,
    );
    let rms_mas = (used
        .iter()
        .map(|s| (s.dx_px - mx).powi(2) + (s.dy_px - my).powi(2))
        .sum::<f64>()
        / k)
        .sqrt()
        * scale_mas;
    // arrows: the rms deviation drawn as 70 % of the star spacing
    let spacing = app.cfg.scene.grid_spacing_px.max(1.0);
    let px_per_mas = 0.7 * spacing / rms_mas.max(1e-6);
    let origins: Vec<[f64; 2]> = used
        .iter()
        .map(|s| [s.x - s.dx_px, s.y - s.dy_px])
        .collect();
    let tips: Vec<[f64; 2]> = used
        .iter()
        .zip(&origins)
        .map(|(s, o)| {
            [
                o[0] + (s.dx_px - mx) * scale_mas * px_per_mas,
                o[1] + (s.dy_px - my) * scale_mas * px_per_mas,
            ]
        })
        .collect();
    let predicted = if app.view.show_predicted_arrows {
        let p: Vec<_> = f
            .stars_none
            .iter()
            .filter(|s| s.truth.is_some() && s.flags & flags::REJECT == 0 && s.dx_px.is_finite())
            .collect();
        let n = p.len().max(1) as f64;
        let (pmx, pmy) = (
            p.iter().map(|s| s.predicted_fit_dx_px).sum::<f64>() / n,
            p.iter().map(|s| s.predicted_fit_dy_px).sum::<f64>() / n,
        );
        let any = p
            .iter()
            .any(|s| s.predicted_fit_dx_px != 0.0 || s.predicted_fit_dy_px != 0.0);
        any.then(|| {
            let o: Vec<[f64; 2]> = p.iter().map(|s| [s.x - s.dx_px, s.y - s.dy_px]).collect();
            let t: Vec<[f64; 2]> = p
                .iter()
                .zip(&o)
                .map(|(s, o)| {
                    [
                        o[0] + (s.predicted_fit_dx_px - pmx) * scale_mas * px_per_mas,
                        o[1] + (s.predicted_fit_dy_px - pmy) * scale_mas * px_per_mas,
                    ]
                })
                .collect();
            (o, t)
        })
    } else {
        None
    };
    let ref_mas = nice_length(rms_mas);
    ui.horizontal_wrapped(|ui| {
        ui.colored_label(MEASURED, format!("measured: rms {rms_mas:.1} mas"));
        ui.checkbox(
            &mut app.view.show_predicted_arrows,
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
                    format!("measured (rms {rms_mas:.1} mas)"),
                    PlotPoints::new(origins),
                    PlotPoints::new(tips),
                )
                .color(MEASURED)
                .tip_length(5.0),
            );
            pui.arrows(
                Arrows::new(
                    "reference",
                    PlotPoints::new(vec![ref_origin]),
                    PlotPoints::new(vec![ref_tip]),
                )
                .color(Color32::WHITE)
                .tip_length(6.0),
            );
            pui.text(
                Text::new(
                    "",
                    PlotPoint::new(ref_tip[0] + 0.15 * spacing, ref_tip[1]),
                    ref_label,
                )
                .anchor(egui::Align2::LEFT_CENTER),
            );
        });
}

/// Accuracy against magnitude: Monte Carlo mean ± s.e.m., the median CRLB and the instant prediction.
pub fn curve_ui(ui: &mut egui::Ui, app: &mut ExplorerApp, actions: &mut Vec<Action>) {
    let cm = app.countermeasure.clone();
    let stale = app
        .rt
        .curve_key
        .as_ref()
        .is_some_and(|k| *k != curve_key(&app.request()));
    ui.horizontal(|ui| {
        super::title(
            ui,
            &format!(
                "Accuracy vs magnitude ({} images per point, {}, {})",
                app.cfg.fidelity.images,
                app.cfg.ace.case.name(),
                app.cfg.readout.order.name()
            ),
            stale,
        );
        if !app.view.auto_curve && ui.button("Run curve").clicked() {
            actions.push(Action::RunCurve);
        }
    });
    let curve = &app.rt.curve;
    if curve.is_empty() {
        ui.centered_and_justified(|ui| {
            ui.weak(if app.view.auto_curve {
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
    let plain = if cm != "none" {
        rows_of("none")
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
        app.mags.len()
    ));
    Plot::new("curve_plot")
        .legend(small_legend(Corner::LeftTop))
        .x_axis_label("Hw [mag]")
        .y_axis_label("single-image accuracy [mas]")
        .include_y(0.0)
        .include_x(app.mags.first().copied().unwrap_or(12.0) - 0.25)
        .include_x(app.mags.last().copied().unwrap_or(14.0) + 0.25)
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
