//! What the plots share: their colours, a small legend, decade grid marks and labels for axes that hold
//! log10 values, round numbers, and a colour scale for counts.

use egui::{Color32, Rect, pos2};
use egui_plot::{Corner, GridInput, GridMark, Legend};

pub const X_COLOUR: Color32 = Color32::from_rgb(90, 160, 255);
pub const Y_COLOUR: Color32 = Color32::from_rgb(255, 150, 60);
pub const MEASURED: Color32 = Color32::from_rgb(90, 200, 120);
pub const PREDICTED: Color32 = Color32::from_rgb(255, 150, 60);
pub const BOUND: Color32 = Color32::from_rgb(170, 130, 255);

pub fn small_legend(corner: Corner) -> Legend {
    Legend::default()
        .position(corner)
        .text_style(egui::TextStyle::Small)
        .background_alpha(0.6)
}

/// Grid marks at every decade (labelled) and at 2…9 × each decade, for axes that hold log10 values.
pub fn decade_marks(input: GridInput) -> Vec<GridMark> {
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
pub fn decade_label(mark: GridMark) -> String {
    if (mark.value - mark.value.round()).abs() > 1e-6 {
        return String::new();
    }
    let e = mark.value.round() as i32;
    match e {
        -3..=3 => format!("{}", 10f64.powi(e)),
        _ => format!("1e{e}"),
    }
}

/// Axis label of a log10 value: the number at 1, 2 and 5 × each decade, nothing in between (an axis that
/// spans a decade or two, such as a number of exposures).
pub fn decade_label_125(mark: GridMark) -> String {
    let d = (mark.value + 1e-9).floor();
    let f = mark.value - d;
    if ![1.0f64, 2.0, 5.0]
        .iter()
        .any(|k| (f - k.log10()).abs() < 1e-6)
    {
        return String::new();
    }
    let v = 10f64.powf(mark.value);
    if v >= 1.0 {
        format!("{v:.0}")
    } else {
        let digits = (-d) as usize;
        format!("{v:.digits$}")
    }
}

/// A colour scale for counts: a vertical bar in `rect` from 1 (bottom) to `max`, one band per count (at most
/// 64), labelled at round steps, titled `what`, with the colour of 0 named `zero` below it.
pub fn count_colour_bar(
    ui: &egui::Ui,
    rect: Rect,
    max: u32,
    what: &str,
    zero: &str,
    colour_of: impl Fn(f64) -> Color32,
) {
    let p = ui.painter_at(rect);
    let text = ui.visuals().text_color();
    let font = egui::TextStyle::Small.resolve(ui.style());
    p.text(
        pos2(rect.min.x, rect.min.y + 4.0),
        egui::Align2::LEFT_TOP,
        what,
        font.clone(),
        text,
    );
    let bar = Rect::from_min_max(
        pos2(rect.min.x, rect.min.y + 24.0),
        pos2(rect.min.x + 16.0, rect.max.y - 40.0),
    );
    if max == 0 || bar.height() < 20.0 {
        return;
    }
    // one band per count (up to 64 bands), 1 at the bottom
    let bands = max.min(64);
    let h = bar.height() / bands as f32;
    let y_of = |n: f64| bar.max.y - ((n - 0.5) / f64::from(max)) as f32 * bar.height();
    for k in 0..bands {
        let n = 1.0 + f64::from(k) * f64::from(max - 1) / f64::from(bands.max(2) - 1);
        let y1 = bar.max.y - k as f32 * h;
        p.rect_filled(
            Rect::from_min_max(pos2(bar.min.x, y1 - h), pos2(bar.max.x, y1)),
            0.0,
            colour_of(n),
        );
    }
    let step = nice(f64::from(max) / 5.0).max(1.0) as u32;
    let mut ticks: Vec<u32> = (1..=max).filter(|n| n % step == 0).collect();
    if ticks.first() != Some(&1) {
        ticks.insert(0, 1);
    }
    for n in ticks {
        let y = if max == 1 {
            bar.center().y
        } else {
            y_of(f64::from(n)).clamp(bar.min.y, bar.max.y)
        };
        p.text(
            pos2(bar.max.x + 4.0, y),
            egui::Align2::LEFT_CENTER,
            n.to_string(),
            font.clone(),
            text,
        );
    }
    p.text(
        pos2(rect.min.x, bar.max.y + 6.0),
        egui::Align2::LEFT_TOP,
        zero,
        font,
        ui.visuals().weak_text_color(),
    );
}

/// The 1, 2 or 5 × 10ᵏ nearest `x` (> 0) from below or at it; 1 for anything else (a reference arrow's
/// length, a colour scale's step).
pub fn nice(x: f64) -> f64 {
    if !(x > 0.0) || !x.is_finite() {
        return 1.0;
    }
    let d = 10f64.powf(x.log10().floor());
    let m = x / d;
    d * if m >= 5.0 {
        5.0
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    }
}

/// A vector plot's white reference arrow from `origin` to `tip`, its label `gap` (plot units) to the right of
/// the tip.
pub fn reference_arrow(
    pui: &mut egui_plot::PlotUi<'_>,
    origin: [f64; 2],
    tip: [f64; 2],
    gap: f64,
    label: String,
) {
    use egui_plot::{Arrows, PlotPoint, PlotPoints, Text};
    pui.arrows(
        Arrows::new(
            "reference",
            PlotPoints::new(vec![origin]),
            PlotPoints::new(vec![tip]),
        )
        .color(egui::Color32::WHITE)
        .tip_length(6.0),
    );
    pui.text(
        Text::new("", PlotPoint::new(tip[0] + gap, tip[1]), label)
            .anchor(egui::Align2::LEFT_CENTER),
    );
}

/// What the cursor is over in a plot: the curve's name (empty away from the data) and the point.
pub fn hovered<'a>(pos: &egui_plot::HoverPosition<'a>) -> (&'a str, egui_plot::PlotPoint) {
    match pos {
        egui_plot::HoverPosition::NearDataPoint {
            plot_name,
            position,
            ..
        } => (plot_name, *position),
        egui_plot::HoverPosition::Elsewhere { position } => ("", *position),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_numbers() {
        for (x, want) in [
            (0.37, 0.2),
            (7.0, 5.0),
            (1.0, 1.0),
            (23.0, 20.0),
            (0.0, 1.0),
        ] {
            assert!((nice(x) - want).abs() < 1e-12, "nice({x}) = {}", nice(x));
        }
    }

    #[test]
    fn labels_at_one_two_five() {
        let label = |v: f64| {
            decade_label_125(GridMark {
                value: v,
                step_size: 0.1,
            })
        };
        assert_eq!(label(0.0), "1");
        assert_eq!(label(2f64.log10()), "2");
        assert_eq!(label(1.0 + 5f64.log10()), "50");
        assert_eq!(label(-1.0 + 2f64.log10()), "0.2");
        assert_eq!(label(3f64.log10()), "");
    }
}
