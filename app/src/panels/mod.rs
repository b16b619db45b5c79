//! The panels: free functions that draw one part of the window from the app's state.

pub mod controls;
pub mod image;
pub mod plots;
pub mod summary;
pub mod toolbar;

use crate::app::{Action, ExplorerApp};
use egui::{Rect, UiBuilder, pos2, vec2};

/// A framed cell at a fixed rect: `add` draws inside it, clipped to it (a cell never pushes its neighbours).
pub fn cell(ui: &mut egui::Ui, rect: Rect, add: impl FnOnce(&mut egui::Ui)) {
    let stroke = ui.visuals().widgets.noninteractive.bg_stroke;
    ui.painter()
        .rect_stroke(rect, 4.0, stroke, egui::StrokeKind::Inside);
    let inner = rect.shrink(5.0);
    let mut child = ui.new_child(
        UiBuilder::new()
            .max_rect(inner)
            .layout(egui::Layout::top_down(egui::Align::Min)),
    );
    child.shrink_clip_rect(inner);
    add(&mut child);
}

/// Title line of a cell (truncated to the cell), with a tag when the content belongs to other parameters.
pub fn title(ui: &mut egui::Ui, text: &str, stale: bool) {
    ui.horizontal(|ui| {
        if stale {
            ui.colored_label(ui.visuals().warn_fg_color, "(stale)")
                .on_hover_text("computed with the previous parameters; new results are on the way (or were cancelled)");
        }
        ui.add(egui::Label::new(egui::RichText::new(text).strong()).truncate());
    });
}

/// The central area: the frame with its close-ups and ePSF on the left, four plots on the right.
pub fn central_ui(ui: &mut egui::Ui, app: &mut ExplorerApp, actions: &mut Vec<Action>) {
    let r = ui.available_rect_before_wrap();
    let gap = 4.0;
    let left_w = (r.width() * 0.45).clamp(280.0, 1000.0);
    let left = Rect::from_min_size(r.min, vec2(left_w, r.height()));
    let right = Rect::from_min_max(pos2(r.min.x + left_w + gap, r.min.y), r.max);
    let frame_h = (left.height() * 0.64).max(200.0);
    let frame_rect = Rect::from_min_size(left.min, vec2(left.width(), frame_h));
    let lower = Rect::from_min_max(pos2(left.min.x, left.min.y + frame_h + gap), left.max);
    let close_w = lower.width() * 0.62;
    let close_rect = Rect::from_min_size(lower.min, vec2(close_w, lower.height()));
    let epsf_rect = Rect::from_min_max(pos2(lower.min.x + close_w + gap, lower.min.y), lower.max);

    let (cw, ch) = ((right.width() - gap) / 2.0, (right.height() - gap) / 2.0);
    let at = |i: usize, j: usize| {
        Rect::from_min_size(
            pos2(
                right.min.x + i as f32 * (cw + gap),
                right.min.y + j as f32 * (ch + gap),
            ),
            vec2(cw, ch),
        )
    };

    cell(ui, frame_rect, |ui| image::frame_ui(ui, app));
    cell(ui, close_rect, |ui| image::closeup_ui(ui, app));
    cell(ui, epsf_rect, |ui| image::epsf_ui(ui, app));
    cell(ui, at(0, 0), |ui| plots::psd_ui(ui, app));
    cell(ui, at(1, 0), |ui| plots::ace_ui(ui, app));
    cell(ui, at(0, 1), |ui| plots::vector_ui(ui, app));
    cell(ui, at(1, 1), |ui| plots::curve_ui(ui, app, actions));
    ui.advance_cursor_after_rect(r);
}
