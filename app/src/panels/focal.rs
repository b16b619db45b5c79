//! The quad focal plane: the four arrays side by side as they sit on the sky (each turned into focal-plane
//! axes, north up at position angle 0, east to the left), the gaps between them, the stars, and what lies under
//! the cursor — which array (or gap), its pixel and value, and the RA, Dec of that point through the array's
//! WCS. Every coordinate comes from the engine (`sky::focal_plane::FocalPlane`, `sky::wcs::ArrayWcs`).

use super::widgets::title;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results};
use crate::view::{Colormap, Scale, to_color_image};
use egui::{Color32, TextureHandle, TextureOptions, vec2};
use egui_plot::{MarkerShape, Plot, PlotImage, PlotPoint, PlotPoints, Points, Polygon};
use engine::sky::focal_plane::Placement;

/// The arrays' textures and the key they were made for.
pub type FocalTextures = Option<((u64, crate::view::Stretch, Colormap), Vec<TextureHandle>)>;

const TEXTURE: TextureOptions = TextureOptions {
    magnification: egui::TextureFilter::Nearest,
    minification: egui::TextureFilter::Linear,
    wrap_mode: egui::TextureWrapMode::ClampToEdge,
    mipmap_mode: Some(egui::TextureFilter::Linear),
};

/// What lies under a focal-plane position, in words: array, pixel, value and sky position, or gap / off.
pub fn describe(f: &crate::worker::FocalPlaneResult, fx: f64, fy: f64) -> String {
    match f.plane.locate(fx, fy) {
        Placement::Photosensitive { array, x, y } | Placement::Border { array, x, y } => {
            let n = f.plane.array_px;
            let (ix, iy) = (x.round() as usize, y.round() as usize);
            let adu = f
                .arrays
                .get(array)
                .and_then(|a| a.adu.get(iy.min(n - 1) * n + ix.min(n - 1)))
                .copied()
                .unwrap_or(f32::NAN);
            let sky = f
                .arrays
                .get(array)
                .and_then(|a| a.wcs.as_ref())
                .and_then(|w| w.pixel_to_sky(x, y))
                .map(|(ra, dec)| format!("RA {ra:.5}°, Dec {dec:+.5}°"))
                .unwrap_or_else(|| "RA, Dec —".into());
            let border = if matches!(f.plane.locate(fx, fy), Placement::Border { .. }) {
                " (border: no light)"
            } else {
                ""
            };
            format!(
                "array {} pixel ({ix}, {iy}){border}: {adu:.0} ADU · {sky}",
                array + 1
            )
        }
        Placement::Gap => {
            format!("({fx:.0}, {fy:.0}) px from the axis: in a gap between the arrays")
        }
        Placement::Off => format!("({fx:.0}, {fy:.0}) px from the axis: off the focal plane"),
    }
}

/// The focal-plane view.
pub fn focal_plane_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &mut ViewSettings,
    results: &Results,
    textures: &mut FocalTextures,
) {
    let f = results.focal_plane.as_ref();
    let stale =
        f.is_some_and(|f| f.cfg_hash != screen.cfg_hash || f.image_index != view.image_index);
    let heading = match f {
        Some(f) => format!(
            "Focal plane #{} — 4 arrays of {} px, gaps {:.0} px, {} ACE, {} readout, {} stars",
            f.image_index,
            f.plane.array_px,
            f.plane.gap_px,
            f.cfg.ace.case.name(),
            f.cfg.readout.order.name(),
            f.arrays.iter().map(|a| a.stars_fp.len()).sum::<usize>()
        ),
        None => "Focal plane".into(),
    };
    title(ui, &heading, stale);
    ui.horizontal_wrapped(|ui| {
        ui.label("stretch");
        for s in crate::view::Stretch::ALL {
            ui.radio_value(&mut view.stretch, s, s.name());
        }
        ui.separator();
        ui.checkbox(&mut view.show_stars, "star marks");
    });
    let Some(f) = f else {
        ui.centered_and_justified(|ui| {
            ui.weak("the first focal-plane exposure is on its way (four arrays: longer than one)…");
        });
        return;
    };
    let key = (results.focal_plane_serial, view.stretch, view.colormap);
    if textures.as_ref().map(|t| t.0) != Some(key) {
        let n = f.plane.array_px;
        let scale = Scale::new(view.stretch, f.lo_adu, f.hi_adu, 3.0 * f.noise_adu);
        let tex = f
            .arrays
            .iter()
            .enumerate()
            .map(|(k, a)| {
                let img = to_color_image(&a.adu_fp, n, n, &scale, view.colormap);
                ui.ctx().load_texture(format!("array{k}"), img, TEXTURE)
            })
            .collect();
        *textures = Some((key, tex));
    }
    let Some((_, tex)) = textures.as_ref() else {
        return;
    };
    let n = f.plane.array_px as f64;
    let show_stars = view.show_stars;
    let plot_h = (ui.available_height() - 20.0).max(80.0);
    let resp = Plot::new("focal_plane_plot")
        .data_aspect(1.0)
        .height(plot_h)
        .show_grid(false)
        .allow_boxed_zoom(true)
        .x_axis_label("focal plane x [px] (east to the left)")
        .y_axis_label("focal plane y [px] (north up at PA 0)")
        .show(ui, |pui| {
            for (k, t) in tex.iter().enumerate() {
                let (cx, cy) = f.plane.centre(k);
                pui.image(PlotImage::new(
                    format!("array {}", k + 1),
                    t.id(),
                    PlotPoint::new(cx, cy),
                    vec2(n as f32, n as f32),
                ));
                // the array's outline and its first pixel (where its readout starts)
                let corners = [
                    (0.0, 0.0),
                    (n - 1.0, 0.0),
                    (n - 1.0, n - 1.0),
                    (0.0, n - 1.0),
                ]
                .map(|(x, y)| {
                    let (a, b) = f.plane.to_focal_plane(k, x, y);
                    [a, b]
                });
                pui.polygon(
                    Polygon::new(
                        format!("array {} outline", k + 1),
                        PlotPoints::from(corners.to_vec()),
                    )
                    .fill_color(Color32::TRANSPARENT)
                    .stroke(egui::Stroke::new(1.0, Color32::from_rgb(0, 200, 255))),
                );
                pui.points(
                    Points::new(format!("array {} pixel (0, 0)", k + 1), vec![corners[0]])
                        .shape(MarkerShape::Square)
                        .radius(4.0)
                        .color(Color32::from_rgb(0, 200, 255)),
                );
            }
            // the chosen star (a click picks the nearest fitted star of any array)
            if let Some(c) = results.crowded.as_ref()
                && let Some((k, i)) = view.quad_star
                && let Some(st) = c.fits.get(k).and_then(|a| a.stars.get(i))
            {
                let (x, y) = f.plane.to_focal_plane(k, st.x_px, st.y_px);
                pui.points(
                    Points::new("chosen star", vec![[x, y]])
                        .shape(MarkerShape::Circle)
                        .filled(false)
                        .radius(8.0)
                        .color(Color32::from_rgb(255, 200, 0)),
                );
            }
            if show_stars {
                let pts: PlotPoints = f
                    .arrays
                    .iter()
                    .flat_map(|a| a.stars_fp.iter().map(|&(x, y)| [x, y]))
                    .collect();
                pui.points(
                    Points::new("stars", pts)
                        .shape(MarkerShape::Circle)
                        .filled(false)
                        .radius(3.0)
                        .color(Color32::from_rgb(120, 220, 120)),
                );
            }
            pui.pointer_coordinate()
        });
    if resp.response.clicked()
        && let (Some(p), Some(c)) = (resp.inner, results.crowded.as_ref())
    {
        view.quad_star = super::quad::nearest_star(c, p.x, p.y, 12.0);
    }
    let line = match resp.response.hovered().then_some(resp.inner).flatten() {
        Some(p) => format!("cursor: {}", describe(f, p.x, p.y)),
        None => {
            let c = f.counts.unwrap_or_default();
            format!(
                "hover for array, pixel and RA/Dec, click a star for its close-up · stars: {} on the arrays, {} on borders, {} in gaps, {} off",
                c.photosensitive, c.border, c.gap, c.off
            )
        }
    };
    ui.label(egui::RichText::new(line).monospace().small());
}
