//! Small drawing helpers the panels share: a framed cell at a fixed rect, and a cell's title line.

use egui::{Rect, UiBuilder};

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
