//! The quad focal plane's chosen star: its close-up in its array's pixels with what the crowded-field
//! analysis measured of it, and that array's own ePSF. A click on the focal plane ([`super::focal`]) chooses
//! the star; every number comes from the engine's analysis ([`crate::worker::CrowdedResult`]).

use super::image::{Textures, draw_epsf, set_texture};
use super::widgets::title;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results};
use crate::view::{Colormap, Scale, Stretch, stamp, to_color_image};
use crate::worker::{CrowdedResult, FittedStar};
use egui::{TextureOptions, vec2};

/// What the close-up's texture was made from: the focal plane's serial, the star, the half-size, the stretch.
pub type CloseKey = (u64, (usize, usize), usize, Stretch);

/// The fitted star nearest to the focal-plane position (fx, fy), within `max_px`: (array, index).
pub fn nearest_star(c: &CrowdedResult, fx: f64, fy: f64, max_px: f64) -> Option<(usize, usize)> {
    let mut best: Option<((usize, usize), f64)> = None;
    for (k, a) in c.fits.iter().enumerate() {
        for (i, s) in a.stars.iter().enumerate() {
            let (x, y) = c.plane.to_focal_plane(k, s.x_px, s.y_px);
            let d = (x - fx).hypot(y - fy);
            if d <= max_px && best.is_none_or(|(_, b)| d < b) {
                best = Some(((k, i), d));
            }
        }
    }
    best.map(|(s, _)| s)
}

/// The chosen star of the quad, if it is in the shown analysis.
fn chosen<'a>(
    c: &'a CrowdedResult,
    view: &ViewSettings,
) -> Option<((usize, usize), &'a FittedStar)> {
    let (k, i) = view.quad_star?;
    c.fits.get(k)?.stars.get(i).map(|s| ((k, i), s))
}

/// The chosen star's close-up (its array's pixels, as read out) and what the analysis measured of it.
pub fn quad_closeup_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &mut ViewSettings,
    results: &Results,
    textures: &mut Textures,
) {
    let (Some(c), Some(f)) = (&results.crowded, &results.focal_plane) else {
        title(ui, "Star close-up", false);
        ui.weak("waiting for the focal plane's analysis…");
        return;
    };
    let Some(((k, i), s)) = chosen(c, view) else {
        title(ui, "Star close-up", false);
        ui.weak(
            "click a star on the focal plane (any array) for its close-up and that array's ePSF",
        );
        return;
    };
    title(
        ui,
        &format!("Array {} star #{i} close-up ({})", k + 1, c.countermeasure),
        c.cfg_hash != screen.cfg_hash,
    );
    let Some(a) = f.arrays.get(k) else {
        return;
    };
    let n = f.plane.array_px;
    let r = view.closeup_radius_px as i64;
    let key: CloseKey = (
        results.focal_plane_serial,
        (k, i),
        view.closeup_radius_px,
        view.stretch,
    );
    if textures.quad_close.as_ref().map(|t| t.0) != Some(key) {
        let px = stamp(&a.adu, n, s.x_px.round() as i64, s.y_px.round() as i64, r);
        let hi = px.iter().copied().fold(f.lo_adu + 1.0, f32::max);
        let scale = Scale::new(view.stretch, f.lo_adu, hi, 3.0 * f.noise_adu);
        let side = (2 * r + 1) as usize;
        let img = to_color_image(&px, side, side, &scale, Colormap::Inferno);
        let old = textures.quad_close.take().map(|t| t.1);
        let tex = set_texture(ui.ctx(), old, "quad_close", img, TextureOptions::NEAREST);
        textures.quad_close = Some((key, tex));
    }
    let Some((_, tex)) = &textures.quad_close else {
        return;
    };
    let avail = ui.available_size();
    let side = (avail.y - 64.0).min(avail.x * 0.6).max(40.0);
    ui.horizontal(|ui| {
        ui.add(egui::Image::new((tex.id(), vec2(side, side))));
        ui.vertical(|ui| {
            ui.small(format!("array pixel ({:.2}, {:.2})", s.x_px, s.y_px));
            ui.small(format!("flux {:.0} e-", s.flux_e));
            if s.hw.is_finite() {
                ui.small(format!("true Hw {:.2}", s.hw));
                ui.small(format!(
                    "fitted − true ({:+.1}, {:+.1}) mas",
                    s.dx_mas, s.dy_mas
                ));
            } else {
                ui.small("matched to no true star");
            }
            ui.small(format!("Cramér–Rao bound {:.1} mas", s.crlb_mas));
            ui.small(format!("flags {:#x}", s.flags));
        });
    });
    ui.horizontal_wrapped(|ui| {
        let l = ui.small("half-size [px]");
        ui.add(egui::DragValue::new(&mut view.closeup_radius_px).range(3..=40))
            .labelled_by(l.id);
    });
}

/// The chosen star's array's own ePSF (array 1's before a star is chosen).
pub fn quad_epsf_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &ViewSettings,
    results: &Results,
    textures: &mut Textures,
) {
    let Some(c) = &results.crowded else {
        title(ui, "ePSF", false);
        ui.weak("…");
        return;
    };
    let k = view.quad_star.map_or(0, |(k, _)| k);
    let Some(a) = c.fits.get(k) else {
        title(ui, "ePSF", false);
        ui.weak("no array analysed");
        return;
    };
    let summary = c.summaries.get(k);
    title(
        ui,
        &format!(
            "Array {} ePSF ({}× oversampled, from {} stars{})",
            k + 1,
            a.epsf.oversampling,
            summary.map_or(0, |s| s.epsf_stars),
            summary
                .filter(|s| !s.fallback.is_empty())
                .map_or(String::new(), |s| format!("; {}", s.fallback))
        ),
        c.cfg_hash != screen.cfg_hash,
    );
    draw_epsf(
        ui,
        &a.epsf,
        results.crowded_serial * 8 + k as u64,
        &mut textures.quad_epsf,
        "quad_epsf",
    );
}
