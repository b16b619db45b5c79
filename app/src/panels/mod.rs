//! The panels: free functions that draw one part of the window from the state they are given (the
//! settings they edit, the results they show) and return [`Action`]s for the app to perform. None of them
//! sees the app itself.
//!
//! * [`toolbar`], [`controls`], [`summary`] — the edges of the window;
//! * [`image`] — the frame, the close-up beside the Gaussian twin, the ePSF; [`focal`] — the quad focal
//!   plane in its sky layout, shown instead of the frame when the layout is quad; [`quad`] — its chosen
//!   star's close-up and that array's ePSF;
//! * [`psd`], [`series`], [`vectors`], [`curve`] — the four plots; [`crowded`] — the quad's vector maps
//!   and magnitude curve from its crowded-field analysis; [`axes`] — what the plots share;
//! * [`sequence`] — the sequence view: a sequence directory's coverage map, precision against the number of
//!   exposures and distortion residual map (its own left panel and central area);
//! * [`transit`] — the transit view: a stare's light curve and noise budget (its own left panel and central
//!   area, rerun as its controls change);
//! * [`widgets`] — the framed cells and their titles.

pub mod axes;
pub mod controls;
pub mod crowded;
pub mod curve;
pub mod focal;
pub mod image;
pub mod psd;
pub mod quad;
pub mod sequence;
pub mod series;
pub mod summary;
pub mod toolbar;
pub mod transit;
pub mod vectors;
pub mod widgets;

use crate::action::Action;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results};
use egui::{Rect, pos2, vec2};
use widgets::cell;

/// The central area: the frame with its close-ups and ePSF on the left, four plots on the right.
pub fn central_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &mut ViewSettings,
    results: &Results,
    textures: &mut image::Textures,
    actions: &mut Vec<Action>,
) {
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

    cell(ui, at(0, 0), |ui| psd::psd_ui(ui, screen, results));
    cell(ui, at(1, 0), |ui| series::ace_ui(ui, screen, view, results));
    if engine::sky::array_count(&screen.cfg) > 1 {
        // the quad: the focal plane and the common jitter; the analysis panels are a single array's
        cell(ui, frame_rect, |ui| {
            focal::focal_plane_ui(ui, screen, view, results, &mut textures.focal)
        });
        cell(ui, close_rect, |ui| {
            quad::quad_closeup_ui(ui, screen, view, results, textures)
        });
        cell(ui, epsf_rect, |ui| {
            quad::quad_epsf_ui(ui, screen, view, results, textures)
        });
        cell(ui, at(0, 1), |ui| crowded::vectors_ui(ui, screen, results));
        cell(ui, at(1, 1), |ui| crowded::curve_ui(ui, screen, results));
    } else {
        cell(ui, frame_rect, |ui| {
            image::frame_ui(ui, screen, view, results, textures)
        });
        cell(ui, close_rect, |ui| {
            image::closeup_ui(ui, view, results, textures)
        });
        cell(ui, epsf_rect, |ui| {
            image::epsf_ui(ui, screen, results, textures)
        });
        cell(ui, at(0, 1), |ui| {
            vectors::vector_ui(ui, screen, view, results)
        });
        cell(ui, at(1, 1), |ui| {
            curve::curve_ui(ui, screen, view, results, actions)
        });
    }
    ui.advance_cursor_after_rect(r);
}
