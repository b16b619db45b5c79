//! The ACE PSD (log–log): the engine's model of the configuration on screen, and the Welch estimate of the
//! generated series in the model's units at its true amplitude (the engine removes the generator's own
//! factor; nothing is fitted here, so an amplitude mismatch shows).

use super::axes::{X_COLOUR, Y_COLOUR, decade_label, decade_marks, small_legend};
use super::widgets::title;
use crate::state::{OnScreen, Results};
use egui::Color32;
use egui_plot::{AxisHints, Corner, Line, LineStyle, Plot, PlotPoints, VLine};
use engine::jitter::Psd;

/// Frequencies at which the model is drawn: a log grid over the series' band, plus points across each
/// mode's peak so narrow Lorentzians are drawn.
fn model_grid(a: &engine::config::Ace) -> Vec<f64> {
    let dt = a.sample_interval_ms * 1e-3;
    let (f0, f1) = (1.0 / a.span_s.max(1e-3), 0.5 / dt.max(1e-9));
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
    fs
}

pub fn psd_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results) {
    let a = &screen.cfg.ace;
    let series = results.series.as_ref();
    title(
        ui,
        "ACE power spectral density (per axis, log–log)",
        series.is_some_and(|s| s.cfg_hash != screen.cfg_hash),
    );
    let psd = Psd::from_config(a);
    let fs = model_grid(a);
    let log_points = |part: &dyn Fn(f64) -> f64| -> PlotPoints {
        fs.iter()
            .filter_map(|&f| {
                let p = part(f);
                (p > 0.0).then(|| [f.log10(), p.log10()])
            })
            .collect()
    };
    let model = log_points(&|f| psd.eval(f));
    let continuum = log_points(&|f| psd.continuum(f));
    let gain = series.and_then(|s| s.model_gain);
    if let Some(g) = gain {
        ui.small(format!("1 model unit = {g:.3e} mas²/Hz of the series"))
            .on_hover_text(
                "the generator's own factor (its σ scaling of the unnormalised series), recovered by \
                 the engine: the estimate is not fitted to the model, so an amplitude mismatch shows",
            );
    }
    let t_exp = screen.cfg.detector.exposure_s;
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
        .label_formatter(move |pos| {
            let (name, p) = super::axes::hovered(pos);
            let (f, v) = (10f64.powf(p.x), 10f64.powf(p.y));
            let mut text = format!("{name}\nf = {f:.3} Hz\nPSD = {v:.3e} model units/Hz");
            if let Some(g) = gain {
                text.push_str(&format!("\n    = {:.3e} mas²/Hz of the series", v * g));
            }
            Some(text)
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
            if let Some(s) = series.filter(|s| !s.welch_log.is_empty()) {
                pui.line(
                    Line::new(
                        "Welch PSD of the generated x series (true amplitude)",
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
