//! The sequence view: a step-stare sequence's products as the engine reads them from its directory
//! ([`engine::io::sequence_view`]) — the coverage map (exposures per (l, b) cell), the solved position error
//! against the number of exposures per magnitude bin beside the solution's σ and the single-exposure error
//! over √(observations), the parallax error against N and against magnitude beside its σ, and the solved
//! distortion's residual against the instrument's per array. Nothing is
//! computed here but the drawing.

use super::axes::{count_colour_bar, decade_label_125, decade_marks, nice};
use super::crowded::ARRAY_COLOURS;
use super::widgets::{cell, title};
use crate::action::Action;
use crate::view::{Colormap, colour};
use egui::{Color32, Rect, UiBuilder, pos2, vec2};
use egui_plot::{
    Arrows, Heatmap, Line, LineStyle, MarkerShape, Plot, PlotPoint, PlotPoints, Points,
};
use engine::io::sequence_view::{
    CoverageGrid, PrecisionCurve, PrecisionRow, SequenceView, SolutionView,
};

/// What Open sequence read: the sequence, or why it could not be read; None before the first.
pub type Loaded = Option<Result<SequenceView, String>>;

/// The left panel: the directory, Open sequence, and what was read from it.
pub fn controls_ui(
    ui: &mut egui::Ui,
    dir: &mut String,
    loaded: &Loaded,
    actions: &mut Vec<Action>,
) {
    ui.heading("Step-stare sequence");
    ui.weak(
        "a directory written by `jsim sequence --out DIR`, solved by `jsim solve --sequence DIR`",
    );
    let l = ui.label("sequence directory");
    let edit = ui
        .add(egui::TextEdit::singleline(dir).desired_width(f32::INFINITY))
        .labelled_by(l.id);
    let enter = edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
    if ui
        .button("Open sequence")
        .on_hover_text("read the directory's coverage.csv and solution/")
        .clicked()
        || enter
    {
        actions.push(Action::OpenSequence);
    }
    ui.separator();
    let Some(Ok(v)) = loaded else { return };
    ui.label(format!("read {}", v.dir.display()));
    match &v.coverage {
        Some(c) => ui.small(format!(
            "coverage.csv: {} × {} cells of {:.1} arcsec",
            c.columns,
            c.rows,
            c.cell_deg * 3600.0
        )),
        None => ui.small("no coverage.csv (plan.csv only)"),
    };
    match &v.solution {
        Some(s) => {
            ui.small(format!(
                "solution/precision_vs_n.csv: {} rows with sources",
                s.precision.len()
            ));
            ui.small(format!(
                "solution/calibration_map.csv: {} cells over {} arrays",
                s.calibration.len(),
                s.arrays().len()
            ));
            ui.small(match s.plate_scale_mas_per_px {
                Some(p) => format!("plate scale {p:.2} mas/px"),
                None => "no design.toml or config.toml: the residual in px".into(),
            });
        }
        None => {
            ui.small("no solution/ yet");
        }
    };
}

/// The central area: the coverage map and the distortion residual above, the precision against N below.
pub fn central_ui(ui: &mut egui::Ui, loaded: &Loaded) {
    let r = ui.available_rect_before_wrap();
    match loaded {
        None => {
            ui.centered_and_justified(|ui| {
                ui.weak("open a sequence's directory (on the left, or jsim-app --sequence DIR)");
            });
        }
        Some(Err(e)) => {
            ui.colored_label(
                ui.visuals().error_fg_color,
                format!("Cannot show the sequence: {e}"),
            );
        }
        Some(Ok(v)) => {
            let gap = 4.0;
            let top_h = (r.height() * 0.5).max(240.0);
            let half = (r.width() - gap) / 2.0;
            let top_left = Rect::from_min_size(r.min, vec2(half, top_h));
            let top_right =
                Rect::from_min_size(pos2(r.min.x + half + gap, r.min.y), vec2(half, top_h));
            let bottom = Rect::from_min_max(pos2(r.min.x, r.min.y + top_h + gap), r.max);
            let left_w = (bottom.width() - gap) * 0.55;
            let bottom_left = Rect::from_min_size(bottom.min, vec2(left_w, bottom.height()));
            let bottom_right =
                Rect::from_min_max(pos2(bottom.min.x + left_w + gap, bottom.min.y), bottom.max);
            let unsolved = format!(
                "not solved yet: jsim solve --sequence {}",
                engine::io::shell_quote(&v.dir)
            );
            cell(ui, top_left, |ui| coverage_ui(ui, v));
            cell(ui, top_right, |ui| match &v.solution {
                Some(s) => calibration_ui(ui, s),
                None => waiting(ui, "Distortion residual", &unsolved),
            });
            cell(ui, bottom_left, |ui| match &v.solution {
                Some(s) => precision_ui(ui, s),
                None => waiting(ui, "Precision against the number of exposures", &unsolved),
            });
            cell(ui, bottom_right, |ui| match &v.solution {
                Some(s) => parallax_ui(ui, s),
                None => waiting(ui, "Parallax", &unsolved),
            });
        }
    }
    ui.advance_cursor_after_rect(r);
}

fn waiting(ui: &mut egui::Ui, what: &str, why: &str) {
    title(ui, what, false);
    ui.centered_and_justified(|ui| {
        ui.weak(why);
    });
}

/// A cell's colour on the coverage map: none where no exposure sees it, else along the colour map.
fn count_colour(n: f64, max: f64) -> Color32 {
    if n < 0.5 {
        Color32::TRANSPARENT
    } else {
        colour(Colormap::Inferno, (0.2 + 0.8 * n / max.max(1.0)) as f32)
    }
}

/// The coverage map: exposures per (l, b) cell, l growing to the left as on the sky, with its colour scale.
fn coverage_ui(ui: &mut egui::Ui, v: &SequenceView) {
    let Some(c) = &v.coverage else {
        title(ui, "Coverage", false);
        ui.weak("no coverage.csv in the directory (jsim sequence writes it)");
        return;
    };
    title(ui, "Coverage: exposures per sky cell", false);
    let max = c.max_count();
    ui.small(format!(
        "{:.4} deg² seen · median {} exposures per seen cell, at most {max} · cells of {:.1} arcsec",
        c.covered_deg2(),
        c.median_covered(),
        c.cell_deg * 3600.0
    ));
    let r = ui.available_rect_before_wrap();
    let bar_w = 70.0;
    let plot_rect = Rect::from_min_max(r.min, pos2(r.max.x - bar_w, r.max.y));
    let bar_rect = Rect::from_min_max(pos2(r.max.x - bar_w + 10.0, r.min.y), r.max);
    let (l0, _, b0, _) = c.extent_deg();
    let values: Vec<f64> = c.counts.iter().map(|n| f64::from(*n)).collect();
    let maxf = f64::from(max);
    let heat = Heatmap::new(values, c.columns)
        .at(PlotPoint::new(l0, b0))
        .tile_size(c.cell_deg as f32, c.cell_deg as f32)
        .show_labels(false)
        .custom_mapping(Box::new(move |n| count_colour(n, maxf)));
    let grid = c.clone();
    ui.scope_builder(UiBuilder::new().max_rect(plot_rect), |ui| {
        Plot::new(("sequence_coverage", &v.dir))
            .data_aspect(1.0)
            .invert_x(true)
            .x_axis_label("Galactic longitude l [deg]")
            .y_axis_label("Galactic latitude b [deg]")
            .label_formatter(move |pos| {
                let (_, p) = super::axes::hovered(pos);
                Some(describe_cell(&grid, p.x, p.y))
            })
            .show(ui, |pui| pui.heatmap(heat));
    });
    count_colour_bar(ui, bar_rect, max, "exposures", "0: blank", |n| {
        count_colour(n, maxf)
    });
}

/// What lies under the cursor on the coverage map.
fn describe_cell(c: &CoverageGrid, l: f64, b: f64) -> String {
    let i = ((l - c.l_first_deg) / c.cell_deg).round();
    let j = ((b - c.b_first_deg) / c.cell_deg).round();
    let n = (i >= 0.0 && j >= 0.0 && (i as usize) < c.columns && (j as usize) < c.rows)
        .then(|| c.counts[j as usize * c.columns + i as usize]);
    match n {
        Some(n) => format!("l {l:.4}°, b {b:.4}°: {n} exposures"),
        None => format!("l {l:.4}°, b {b:.4}°: off the map"),
    }
}

/// A magnitude bin's colour: hues from blue (the brightest bin) through green and yellow to red (the
/// faintest), apart enough to tell neighbouring bins.
fn bin_colour(k: usize, n: usize) -> Color32 {
    let t = if n > 1 {
        k as f32 / (n - 1) as f32
    } else {
        0.5
    };
    egui::ecolor::Hsva::new(0.62 * (1.0 - t), 0.7, 1.0, 1.0).into()
}

/// The solved position error against N (log–log) per magnitude bin, beside the solution's σ (dotted) and
/// the single-exposure error over √(observations) (dashed), same colour per bin; the key above the plot.
fn precision_ui(ui: &mut egui::Ui, s: &SolutionView) {
    title(
        ui,
        "Precision against the number of exposures N: solved position error per axis (robust)",
        false,
    );
    let curves = s.precision_curves();
    if curves.is_empty() {
        ui.weak(format!(
            "no magnitude bin with {} sources or more",
            engine::io::sequence_view::MIN_SOURCES_PER_POINT
        ));
        return;
    }
    let one_n = curves.iter().any(|c| c.points.len() == 1);
    ui.horizontal_wrapped(|ui| {
        ui.small(if one_n {
            "dots: solved (robust) · diamonds: single exposure / √obs · squares: solution σ ·"
        } else {
            "solid with dots: solved (robust) · dashed: single exposure / √obs · dotted: solution σ ·"
        });
        for (k, c) in curves.iter().enumerate() {
            ui.colored_label(
                bin_colour(k, curves.len()),
                egui::RichText::new(format!("— Hw {:.0}–{:.0}", c.hw_lo, c.hw_hi)).small(),
            );
        }
    });
    let log = |x: f64| (x > 0.0 && x.is_finite()).then(|| x.log10());
    Plot::new("sequence_precision")
        .x_axis_label("exposures N")
        .y_axis_label("position error per axis [mas]")
        .x_grid_spacer(decade_marks)
        .y_grid_spacer(decade_marks)
        .x_axis_formatter(|m, _| decade_label_125(m))
        .y_axis_formatter(|m, _| decade_label_125(m))
        .label_formatter(|pos| {
            let (name, p) = super::axes::hovered(pos);
            Some(format!(
                "{name}\nN = {:.1}\n{:.3} mas",
                10f64.powf(p.x),
                10f64.powf(p.y)
            ))
        })
        .show(ui, |pui| {
            for (k, c) in curves.iter().enumerate() {
                let colour = bin_colour(k, curves.len());
                let bin = format!("Hw {:.0}–{:.0}", c.hw_lo, c.hw_hi);
                let pts =
                    |f: &dyn Fn(&PrecisionRow) -> Option<f64>| against_log_n(c, &|p| log(f(p)?));
                let solved = pts(&|p| Some(p.position_robust_mas));
                // a bin solved at one N only: its σ and √obs points as hollow markers
                for (name, v, style, shape) in [
                    (
                        "single / √obs",
                        pts(&|p| p.sqrt_n_mas),
                        LineStyle::dashed_dense(),
                        MarkerShape::Diamond,
                    ),
                    (
                        "solution σ",
                        pts(&|p| Some(p.position_sigma_mas)),
                        LineStyle::dotted_dense(),
                        MarkerShape::Square,
                    ),
                ] {
                    let name = format!("{bin}: {name}");
                    if v.len() > 1 {
                        pui.line(Line::new(name, v).color(colour).style(style).width(1.2));
                    } else {
                        pui.points(Points::new(name, v).shape(shape).radius(3.5).color(colour));
                    }
                }
                pui.line(
                    Line::new(format!("{bin}: solved"), PlotPoints::new(solved.clone()))
                        .color(colour)
                        .width(2.0),
                );
                pui.points(
                    Points::new(format!("{bin}: solved"), PlotPoints::new(solved))
                        .shape(MarkerShape::Circle)
                        .filled(true)
                        .radius(3.0)
                        .color(colour),
                );
            }
        });
}

/// A curve's points `[log₁₀ N, y]`, the points without a y (or N) left out.
fn against_log_n(c: &PrecisionCurve, y: &dyn Fn(&PrecisionRow) -> Option<f64>) -> Vec<[f64; 2]> {
    c.points
        .iter()
        .filter_map(|p| {
            Some([
                (p.exposures > 0).then(|| (p.exposures as f64).log10())?,
                y(p)?,
            ])
        })
        .collect()
}

/// The parallax error against the truth (solid, dots) and the solution's σ (dotted) per magnitude bin
/// against N (log–log), and against magnitude in the solution of the most exposures (log).
fn parallax_ui(ui: &mut egui::Ui, s: &SolutionView) {
    title(ui, "Parallax error against N and against magnitude", false);
    let Some((n_max, by_mag)) = s.parallax_by_magnitude() else {
        ui.weak(
            "no parallax solved: the position model, or a span too short (jsim solve --model full)",
        );
        return;
    };
    // the bins' colours as in the precision plot beside
    let curves = s.precision_curves();
    ui.small("solid with dots: against the truth (rms) · dotted: solution σ · colours as beside");
    let h = (ui.available_height() - 8.0) / 2.0;
    Plot::new("sequence_parallax_n")
        .height(h)
        .x_axis_label("exposures N")
        .y_axis_label("parallax error [mas]")
        .x_grid_spacer(decade_marks)
        .x_axis_formatter(|m, _| decade_label_125(m))
        .include_y(0.0)
        .label_formatter(|pos| {
            let (name, p) = super::axes::hovered(pos);
            Some(format!(
                "{name}\nN = {:.1}\n{:.3} mas",
                10f64.powf(p.x),
                p.y
            ))
        })
        .show(ui, |pui| {
            for (k, c) in curves.iter().enumerate() {
                let colour = bin_colour(k, curves.len());
                let bin = format!("Hw {:.0}–{:.0}", c.hw_lo, c.hw_hi);
                let pts = |f: &dyn Fn(&PrecisionRow) -> Option<f64>| against_log_n(c, f);
                let error = pts(&|p| p.parallax_rms_mas);
                if error.is_empty() {
                    continue;
                }
                pui.line(
                    Line::new(format!("{bin}: σ"), pts(&|p| p.parallax_sigma_mas))
                        .color(colour)
                        .style(LineStyle::dotted_dense()),
                );
                pui.line(
                    Line::new(format!("{bin}: error"), error.clone())
                        .color(colour)
                        .width(2.0),
                );
                pui.points(
                    Points::new(format!("{bin}: error"), error)
                        .filled(true)
                        .radius(3.0)
                        .color(colour),
                );
            }
        });
    let mags = |f: &dyn Fn(&PrecisionRow) -> Option<f64>| {
        by_mag
            .iter()
            .filter_map(|p| Some([(p.hw_lo + p.hw_hi) / 2.0, f(p)?]))
            .collect::<Vec<[f64; 2]>>()
    };
    let error = mags(&|p| p.parallax_rms_mas);
    let colour = ui.visuals().text_color();
    Plot::new("sequence_parallax_mag")
        .height(h)
        .x_axis_label(format!("Hw (bin centre), in the solution of N = {n_max}"))
        .y_axis_label("parallax error [mas]")
        .include_y(0.0)
        .label_formatter(|pos| {
            let (name, p) = super::axes::hovered(pos);
            Some(format!("{name}\nHw {:.2}\n{:.3} mas", p.x, p.y))
        })
        .show(ui, |pui| {
            pui.line(
                Line::new("solution σ", mags(&|p| p.parallax_sigma_mas))
                    .color(colour)
                    .style(LineStyle::dotted_dense()),
            );
            pui.line(Line::new("error", error.clone()).color(colour).width(2.0));
            pui.points(
                Points::new("error", error)
                    .filled(true)
                    .radius(3.0)
                    .color(colour),
            );
        });
}

/// The solved distortion's residual (solved − true, the attitudes' gauge removed) per array in the focal
/// plane, as arrows, with the rms in the title and a reference arrow.
fn calibration_ui(ui: &mut egui::Ui, s: &SolutionView) {
    let scale = s.plate_scale_mas_per_px;
    let unit = if scale.is_some() { "mas" } else { "px" };
    let rms = |a: Option<u32>| -> [f64; 2] {
        s.residual_rms_mas(a)
            .unwrap_or_else(|| s.residual_rms_px(a))
    };
    let [rx, ry] = rms(None);
    title(
        ui,
        &format!(
            "Distortion residual: solved − true, gauge removed — rms {rx:.3} / {ry:.3} {unit} (x / y)"
        ),
        false,
    );
    let arrays = s.arrays();
    if arrays.is_empty() {
        ui.weak("the calibration map has no cells");
        return;
    }
    // drawing scale: the rms arrow is 70 % of the grid's step (none without a residual); the reference a
    // round number near it
    let step = s.grid_step_px().unwrap_or(1.0);
    let [px, py] = s.residual_rms_px(None);
    let rms_px = (px * px + py * py).sqrt();
    let per_px = if rms_px > 0.0 {
        0.7 * step / rms_px
    } else {
        0.0
    };
    let to_unit = scale.unwrap_or(1.0);
    let ref_unit = nice(rms_px * to_unit);
    let ref_px = ref_unit / to_unit;
    ui.horizontal_wrapped(|ui| {
        for &a in &arrays {
            let [x, y] = rms(Some(a));
            ui.colored_label(
                ARRAY_COLOURS[(a as usize + 3) % 4],
                egui::RichText::new(format!("array {a}: {x:.3} / {y:.3} {unit}")).small(),
            );
        }
        if per_px > 0.0 {
            ui.small(format!("· white arrow: {ref_unit} {unit}"));
        }
    });
    let (u_min, v_min) = s
        .calibration
        .iter()
        .fold((f64::MAX, f64::MAX), |(u, v), c| {
            (u.min(c.u_px), v.min(c.v_px))
        });
    let ref_origin = [u_min, v_min - 1.2 * step];
    let ref_tip = [u_min + ref_px * per_px, ref_origin[1]];
    Plot::new("sequence_calibration")
        .data_aspect(1.0)
        .x_axis_label("focal plane u [px]")
        .y_axis_label("focal plane v [px]")
        .show(ui, |pui| {
            for &a in &arrays {
                let (o, t): (Vec<[f64; 2]>, Vec<[f64; 2]>) = s
                    .calibration
                    .iter()
                    .filter(|c| c.array == a)
                    .map(|c| {
                        (
                            [c.u_px, c.v_px],
                            [
                                c.u_px + c.residual_dx_px * per_px,
                                c.v_px + c.residual_dy_px * per_px,
                            ],
                        )
                    })
                    .unzip();
                pui.arrows(
                    Arrows::new(format!("array {a}"), PlotPoints::new(o), PlotPoints::new(t))
                        .color(ARRAY_COLOURS[(a as usize + 3) % 4])
                        .tip_length(5.0),
                );
            }
            if per_px == 0.0 {
                return;
            }
            super::axes::reference_arrow(
                pui,
                ref_origin,
                ref_tip,
                0.3 * step,
                format!("{ref_unit} {unit}"),
            );
        });
}
