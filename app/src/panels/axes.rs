//! What the plots share: their colours, a small legend, and decade grid marks and labels for axes that
//! hold log10 values.

use egui::Color32;
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
