//! Image panels: the full simulated frame (pan, zoom, stretch, pixel under the cursor, channel boundaries),
//! the close-up of the chosen star beside its Gaussian-ACE twin, and the ePSF.

use super::widgets::title;
use crate::settings::ViewSettings;
use crate::state::{OnScreen, Results, chosen_pixel};
use crate::view::{Colormap, Scale, Stretch, diverging, stamp, to_color_image};
use crate::worker::FrameResult;
use egui::{Color32, TextureHandle, TextureOptions, vec2};
use egui_plot::{MarkerShape, Plot, PlotImage, PlotPoint, PlotPoints, Points, VLine};
use engine::readout::ReadoutTiming;

/// Textures of the image panels, with the keys they were made for.
#[derive(Default)]
pub struct Textures {
    frame: Option<((u64, Stretch, Colormap), TextureHandle)>,
    close: Option<(CloseKey, [TextureHandle; 3])>,
    epsf: Option<(u64, TextureHandle)>,
    /// The quad focal plane's arrays ([`super::focal`]).
    pub focal: super::focal::FocalTextures,
    /// The quad's chosen star and its array's ePSF ([`super::quad`]).
    pub quad_close: Option<(super::quad::CloseKey, TextureHandle)>,
    pub quad_epsf: Option<(u64, TextureHandle)>,
}

type CloseKey = (u64, u64, usize, usize, Stretch);

/// Minified frames average their pixels (so a star stays visible when zoomed out); magnified ones show
/// the pixels.
const FRAME_TEXTURE: TextureOptions = TextureOptions {
    magnification: egui::TextureFilter::Nearest,
    minification: egui::TextureFilter::Linear,
    wrap_mode: egui::TextureWrapMode::ClampToEdge,
    mipmap_mode: Some(egui::TextureFilter::Linear),
};

pub(super) fn set_texture(
    ctx: &egui::Context,
    slot: Option<TextureHandle>,
    name: &str,
    img: egui::ColorImage,
    opts: TextureOptions,
) -> TextureHandle {
    match slot {
        Some(mut t) => {
            t.set(img, opts);
            t
        }
        None => ctx.load_texture(name, img, opts),
    }
}

/// The full frame. Its channels, exposure windows and scale are those of the configuration it was
/// simulated with.
pub fn frame_ui(
    ui: &mut egui::Ui,
    screen: &OnScreen,
    view: &mut ViewSettings,
    results: &Results,
    textures: &mut Textures,
) {
    let stale = results
        .frame
        .as_ref()
        .is_some_and(|f| f.cfg_hash != screen.cfg_hash || f.image_index != view.image_index);
    let heading = match &results.frame {
        Some(f) => format!(
            "Simulated frame #{} — Hw {:.1}, {} ACE, {} readout ({}×{} px)",
            f.image_index,
            f.cfg.scene.mag_hw,
            f.cfg.ace.case.name(),
            f.cfg.readout.order.name(),
            f.n,
            f.n
        ),
        None => "Simulated frame".into(),
    };
    title(ui, &heading, stale);
    view_controls(ui, view);
    let Some(f) = &results.frame else {
        ui.centered_and_justified(|ui| {
            ui.weak("the first frame is on its way…");
        });
        return;
    };
    let key = (results.frame_serial, view.stretch, view.colormap);
    if textures.frame.as_ref().map(|t| t.0) != Some(key) {
        let scale = Scale::new(view.stretch, f.lo_adu, f.hi_adu, 3.0 * f.noise_adu);
        let img = to_color_image(&f.adu, f.n, f.n, &scale, view.colormap);
        let old = textures.frame.take().map(|t| t.1);
        let tex = set_texture(ui.ctx(), old, "frame", img, FRAME_TEXTURE);
        textures.frame = Some((key, tex));
    }
    let Some((_, tex)) = &textures.frame else {
        return;
    };
    let n = f.n as f64;
    let centre = (n - 1.0) / 2.0;
    let chosen = chosen_pixel(view, Some(f));
    let star = f.truth_xy.get(view.star).copied();
    let w = f.cfg.readout.channel_width_px.max(1);
    let channels = f.cfg.readout.channels;
    let (show_channels, show_stars) = (view.show_channels, view.show_stars);
    let plot_h = (ui.available_height() - 20.0).max(80.0);
    let resp = Plot::new("frame_plot")
        .data_aspect(1.0)
        .height(plot_h)
        .show_grid(false)
        .allow_boxed_zoom(true)
        .x_axis_label("X [px]")
        .y_axis_label("Y [px]")
        .show(ui, |pui| {
            pui.image(PlotImage::new(
                "frame",
                tex.id(),
                PlotPoint::new(centre, centre),
                vec2(n as f32, n as f32),
            ));
            if show_channels {
                for k in 1..channels {
                    let x = (k * w) as f64 - 0.5;
                    if x < n {
                        pui.vline(
                            VLine::new("channel boundary", x)
                                .color(Color32::from_rgba_unmultiplied(0, 200, 255, 110))
                                .width(1.0),
                        );
                    }
                }
            }
            if show_stars {
                let pts: PlotPoints = f.truth_xy.iter().map(|&(x, y)| [x, y]).collect();
                pui.points(
                    Points::new("stars", pts)
                        .shape(MarkerShape::Circle)
                        .filled(false)
                        .radius(5.0)
                        .color(Color32::from_rgb(120, 220, 120)),
                );
            }
            if let Some((x, y)) = star {
                pui.points(
                    Points::new("chosen star", vec![[x, y]])
                        .shape(MarkerShape::Circle)
                        .filled(false)
                        .radius(9.0)
                        .color(Color32::YELLOW),
                );
            }
            if let Some((x, y)) = chosen {
                pui.points(
                    Points::new("chosen pixel", vec![[x as f64, y as f64]])
                        .shape(MarkerShape::Square)
                        .filled(false)
                        .radius(3.0)
                        .color(Color32::from_rgb(255, 80, 80)),
                );
            }
            pui.pointer_coordinate()
        });
    let pixel_at = |p: PlotPoint| -> Option<(usize, usize)> {
        let (x, y) = (p.x.round(), p.y.round());
        (x >= 0.0 && y >= 0.0 && x < n && y < n).then_some((x as usize, y as usize))
    };
    let hovered = resp
        .response
        .hovered()
        .then_some(resp.inner)
        .flatten()
        .and_then(pixel_at);
    if resp.response.clicked()
        && let Some((px, py)) = resp.inner.and_then(pixel_at)
    {
        view.pixel = Some((px, py));
        let nearest = f
            .truth_xy
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| (k, (x - px as f64).hypot(y - py as f64)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, d)) = nearest
            && d < 15.0
        {
            view.star = k;
        }
    }
    let line = pixel_line(f, hovered, chosen);
    ui.label(egui::RichText::new(line).monospace().small());
}

/// The frame's view controls: the stretch, false colour, the channel boundaries and the star marks.
fn view_controls(ui: &mut egui::Ui, view: &mut ViewSettings) {
    ui.horizontal_wrapped(|ui| {
        ui.label("stretch");
        for s in Stretch::ALL {
            ui.radio_value(&mut view.stretch, s, s.name());
        }
        ui.separator();
        let mut false_colour = view.colormap == Colormap::Inferno;
        if ui.checkbox(&mut false_colour, "false colour").changed() {
            view.colormap = if false_colour {
                Colormap::Inferno
            } else {
                Colormap::Gray
            };
        }
        ui.checkbox(&mut view.show_channels, "channels");
        ui.checkbox(&mut view.show_stars, "star marks");
    });
}

/// The line under the frame: the hovered (else the chosen) pixel's value, DQ and exposure window.
fn pixel_line(
    f: &FrameResult,
    hovered: Option<(usize, usize)>,
    chosen: Option<(usize, usize)>,
) -> String {
    let timing = ReadoutTiming::new(&f.cfg);
    match hovered.or(chosen) {
        Some((x, y)) => {
            let i = y * f.n + x;
            let (a, b) = timing.window_s(x, y);
            format!(
                "{} pixel ({x}, {y}): {:.0} ADU, DQ {} · exposure window {a:.3}–{b:.3} s",
                if hovered.is_some() {
                    "cursor"
                } else {
                    "chosen"
                },
                f.adu.get(i).copied().unwrap_or(f32::NAN),
                f.dq.get(i).copied().unwrap_or(0),
            )
        }
        None => "hover for pixel values; click to choose a star and pixel".into(),
    }
}

/// The chosen star beside its Gaussian-ACE twin, and their difference.
pub fn closeup_ui(
    ui: &mut egui::Ui,
    view: &mut ViewSettings,
    results: &Results,
    textures: &mut Textures,
) {
    title(
        ui,
        &format!(
            "Star #{} close-up: this ACE vs its Gaussian-ACE twin",
            view.star
        ),
        false,
    );
    let (Some(f), Some(t)) = (&results.frame, &results.twin) else {
        ui.weak("waiting for the frame and its twin…");
        return;
    };
    if t.image_index != f.image_index || t.n != f.n {
        ui.weak("waiting for the twin of this frame…");
        return;
    }
    let Some(&(sx, sy)) = f.truth_xy.get(view.star) else {
        ui.weak("choose a star by clicking the frame");
        return;
    };
    let r = view.closeup_radius_px as i64;
    let (cx, cy) = (sx.round() as i64, sy.round() as i64);
    let key: CloseKey = (
        results.frame_serial,
        results.twin_serial,
        view.star,
        view.closeup_radius_px,
        view.stretch,
    );
    if textures.close.as_ref().map(|c| c.0) != Some(key) {
        let a = stamp(&f.adu, f.n, cx, cy, r);
        let b = stamp(&t.adu, t.n, cx, cy, r);
        let hi = a.iter().chain(&b).copied().fold(f.lo_adu + 1.0, f32::max);
        let scale = Scale::new(view.stretch, f.lo_adu, hi, 3.0 * f.noise_adu);
        let side = (2 * r + 1) as usize;
        let ia = to_color_image(&a, side, side, &scale, Colormap::Inferno);
        let ib = to_color_image(&b, side, side, &scale, Colormap::Inferno);
        let d: Vec<f32> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
        let dmax = d.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
        let mut px = Vec::with_capacity(side * side);
        for row in (0..side).rev() {
            px.extend(
                d[row * side..(row + 1) * side]
                    .iter()
                    .map(|v| diverging(v / dmax)),
            );
        }
        let id = egui::ColorImage::new([side, side], px);
        let old = textures.close.take().map(|c| c.1);
        let [oa, ob, od] = match old {
            Some([x, y, z]) => [Some(x), Some(y), Some(z)],
            None => [None, None, None],
        };
        let ctx = ui.ctx().clone();
        textures.close = Some((
            key,
            [
                set_texture(&ctx, oa, "close_a", ia, TextureOptions::NEAREST),
                set_texture(&ctx, ob, "close_b", ib, TextureOptions::NEAREST),
                set_texture(&ctx, od, "close_d", id, TextureOptions::NEAREST),
            ],
        ));
    }
    let Some((_, texs)) = &textures.close else {
        return;
    };
    let scale_mas = f.cfg.instrument.plate_scale_mas();
    let fit = f
        .stars
        .iter()
        .find(|s| s.truth == Some(view.star))
        .map(|s| (s.dx_px * scale_mas, s.dy_px * scale_mas));
    // the accuracy ignores what all stars share: show the deviation relative to the mean too
    let (mx, my) = (f.report.bias_x_mas, f.report.bias_y_mas);
    let avail = ui.available_size();
    let side = ((avail.x - 16.0) / 3.0).min(avail.y - 64.0).max(40.0);
    let captions = [
        format!("{} ACE", f.cfg.ace.case.name()),
        "Gaussian twin".to_string(),
        "difference (red +, blue −)".to_string(),
    ];
    ui.horizontal(|ui| {
        for (tex, cap) in texs.iter().zip(captions) {
            ui.vertical(|ui| {
                ui.add(egui::Image::new((tex.id(), vec2(side, side))));
                ui.small(cap);
            });
        }
    });
    let mut info = format!("true position ({sx:.2}, {sy:.2}) px");
    if let Some((dx, dy)) = fit {
        info.push_str(&format!(
            " · fitted − true ({dx:+.1}, {dy:+.1}) mas; minus the mean of all stars ({:+.1}, {:+.1}) mas",
            dx - mx,
            dy - my
        ));
    }
    ui.horizontal_wrapped(|ui| {
        ui.small(info);
        let l = ui.small("half-size [px]");
        ui.add(egui::DragValue::new(&mut view.closeup_radius_px).range(3..=40))
            .labelled_by(l.id);
    });
}

/// The ePSF the analysis built.
pub fn epsf_ui(ui: &mut egui::Ui, screen: &OnScreen, results: &Results, textures: &mut Textures) {
    let Some(f) = &results.frame else {
        title(ui, "ePSF", false);
        ui.weak("…");
        return;
    };
    let e = &f.epsf;
    title(
        ui,
        &format!(
            "ePSF ({}× oversampled, {} iterations)",
            e.oversampling, f.report_none.epsf_iterations
        ),
        f.cfg_hash != screen.cfg_hash,
    );
    draw_epsf(ui, e, results.frame_serial, &mut textures.epsf, "epsf");
}

/// An ePSF table on a log stretch, its texture remade only when `key` changes.
pub(super) fn draw_epsf(
    ui: &mut egui::Ui,
    e: &engine::analysis::epsf::Epsf,
    key: u64,
    slot: &mut Option<(u64, TextureHandle)>,
    name: &str,
) {
    let n = e.n();
    if n == 0 || e.data.len() != n * n {
        ui.weak("empty ePSF");
        return;
    }
    if slot.as_ref().map(|t| t.0) != Some(key) {
        let data: Vec<f32> = e.data.iter().map(|v| *v as f32).collect();
        let hi = data.iter().copied().fold(1e-12f32, f32::max);
        let scale = Scale::new(Stretch::Log, 0.0, hi, hi * 1e-3);
        let img = to_color_image(&data, n, n, &scale, Colormap::Inferno);
        let old = slot.take().map(|t| t.1);
        let tex = set_texture(ui.ctx(), old, name, img, TextureOptions::LINEAR);
        *slot = Some((key, tex));
    }
    let Some((_, tex)) = slot.as_ref() else {
        return;
    };
    let size = n as f32 / e.oversampling.max(1) as f32;
    Plot::new(format!("{name}_plot"))
        .data_aspect(1.0)
        .show_grid(false)
        .x_axis_label("Δx [px]")
        .y_axis_label("Δy [px]")
        .show(ui, |pui| {
            pui.image(PlotImage::new(
                "ePSF",
                tex.id(),
                PlotPoint::new(0.0, 0.0),
                vec2(size, size),
            ));
        });
}
