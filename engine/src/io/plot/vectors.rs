//! Deviation vector maps: an arrow per star, magnified, with a reference arrow and equal axes.

use super::{
    Area, Axis, FONT, LEGEND_SIZE, PlotError, TITLE_SIZE, color, configure_mesh, fmt_num, render,
};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::error::Error;
use std::ops::Range;
use std::path::Path;

/// Size of the (square) vector map.
const MAP_SIZE: (u32, u32) = (800, 800);

/// Arrow from the origin to `(dx, dy)` (pixel offsets, y down): shaft polyline and head polygon.
/// A (near) zero-length arrow becomes a small dot.
fn arrow_shape(dx: f64, dy: f64) -> (Vec<(i32, i32)>, Vec<(i32, i32)>) {
    let len = dx.hypot(dy);
    let px = |x: f64, y: f64| (x.round() as i32, y.round() as i32);
    if len.is_nan() || len < 1.0 {
        let dot = (0..8)
            .map(|k| {
                let phi = k as f64 * std::f64::consts::TAU / 8.0;
                px(1.5 * phi.cos(), 1.5 * phi.sin())
            })
            .collect();
        return (vec![(0, 0)], dot);
    }
    let (ux, uy) = (dx / len, dy / len);
    let head = (0.35 * len).clamp(2.0, 9.0);
    let half = 0.45 * head;
    let (bx, by) = (dx - ux * head, dy - uy * head);
    let shaft_end = (dx - ux * head * 0.7, dy - uy * head * 0.7);
    (
        vec![(0, 0), px(shaft_end.0, shaft_end.1)],
        vec![
            px(dx, dy),
            px(bx - uy * half, by + ux * half),
            px(bx + uy * half, by - ux * half),
        ],
    )
}

/// Largest 1, 2 or 5 × 10^k not above `v` (> 0).
fn nice_floor(v: f64) -> f64 {
    let mag = 10f64.powf(v.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&c| c <= v * (1.0 + 1e-12))
        .unwrap_or(mag)
}

/// Smallest 1, 2 or 5 × 10^k not below `v` (> 0).
fn nice_ceil(v: f64) -> f64 {
    let mag = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&c| c >= v * (1.0 - 1e-12))
        .unwrap_or(10.0 * mag)
}

/// Largest `t` in [0, 1] with `base + t·d` inside the pixel rectangle (`base` is inside it).
fn exit_fraction(
    base: (i32, i32),
    (dx, dy): (f64, f64),
    (xr, yr): &(Range<i32>, Range<i32>),
) -> f64 {
    let limit = |b: i32, d: f64, r: &Range<i32>| {
        let b = f64::from(b);
        if d > 0.0 {
            (f64::from(r.end) - b) / d
        } else if d < 0.0 {
            (f64::from(r.start) - b) / d
        } else {
            1.0
        }
    };
    limit(base.0, dx, xr)
        .min(limit(base.1, dy, yr))
        .clamp(0.0, 1.0)
}

/// Deviation vector map (astrometry-paper style): an arrow from each star position `(x, y)` (detector
/// pixels) along `(dx, dy)` (mas), magnified so that `reference_mas` is `reference_len_px` detector pixels
/// long. A labelled reference arrow sits above the top-right corner of the data, the legend of the sets
/// (each `(label, [(x, y, dx_mas, dy_mas)])`, one colour each) above the top-left; equal aspect, both axes
/// from 0 to `extent_px`.
pub fn vector_map(
    path: &Path,
    title: &str,
    sets: &[(String, Vec<(f64, f64, f64, f64)>)],
    extent_px: f64,
    reference_mas: f64,
    reference_len_px: f64,
) -> Result<(), PlotError> {
    vector_map_on_axes(
        path,
        title,
        sets,
        extent_px,
        (reference_mas, reference_len_px),
        ("x [pixel]", "y [pixel]"),
    )
}

/// [`vector_map`] with its axes named (`(x label, y label)`), e.g. the focal plane's axes and where north and
/// east lie; `reference` is `(reference_mas, reference_len_px)`.
pub fn vector_map_on_axes(
    path: &Path,
    title: &str,
    sets: &[(String, Vec<(f64, f64, f64, f64)>)],
    extent_px: f64,
    reference: (f64, f64),
    axes: (&str, &str),
) -> Result<(), PlotError> {
    render(path, MAP_SIZE, |root| {
        draw_vector_map(root, title, sets, extent_px, reference, axes).map(|_| ())
    })
}

fn draw_vector_map(
    root: &Area<'_>,
    title: &str,
    sets: &[(String, Vec<(f64, f64, f64, f64)>)],
    extent_px: f64,
    (reference_mas, reference_len_px): (f64, f64),
    (x_label, y_label): (&str, &str),
) -> Result<(u32, u32), Box<dyn Error>> {
    let finite = |a: &&(f64, f64, f64, f64)| {
        a.0.is_finite() && a.1.is_finite() && a.2.is_finite() && a.3.is_finite()
    };
    let arrows = || sets.iter().flat_map(|s| s.1.iter()).filter(finite);
    let extent = if extent_px.is_finite() && extent_px > 0.0 {
        extent_px
    } else {
        arrows()
            .map(|a| a.0.max(a.1))
            .filter(|v| v.is_finite() && *v > 0.0)
            .fold(1.0, f64::max)
    };
    // Invalid reference values fall back to a round length near the largest arrow drawn over 10 % of
    // the field.
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let reference_mas = if positive(reference_mas) {
        reference_mas
    } else {
        let largest = arrows()
            .map(|a| a.2.hypot(a.3))
            .filter(|&v| positive(v))
            .fold(0.0, f64::max);
        if largest > 0.0 {
            nice_floor(largest)
        } else {
            1.0
        }
    };
    let reference_len_px = if positive(reference_len_px) {
        reference_len_px
    } else {
        0.1 * extent
    };
    // Detector pixels per mas.
    let scale = reference_len_px / reference_mas;

    // Square plotting area: title, then a strip for the legend and the reference arrow, then the plot.
    let area = root.titled(title, (FONT, TITLE_SIZE))?;
    let (w, h) = area.dim_in_pixel();
    let (left, bottom, strip, min_right, min_bottom) = (80u32, 55u32, 56u32, 25u32, 12u32);
    let side = w
        .saturating_sub(left + min_right)
        .min(h.saturating_sub(strip + bottom + min_bottom))
        .max(10);
    let spare_x = w.saturating_sub(left + side);
    let margin_left = spare_x.saturating_sub(min_right) / 2;
    let axis = Axis::linear(0.0, extent);
    let mut chart = ChartBuilder::on(&area)
        .margin_left(margin_left)
        .margin_right(spare_x.saturating_sub(margin_left))
        .margin_top(strip)
        .margin_bottom(h.saturating_sub(strip + bottom + side))
        .x_label_area_size(bottom)
        .y_label_area_size(left)
        .build_cartesian_2d(axis, axis)?;
    configure_mesh(&mut chart, x_label, y_label)?;
    let plot_rect = chart.plotting_area().get_pixel_range();

    for (i, (_, set)) in sets.iter().enumerate() {
        let style = color(i);
        let mut elements = Vec::new();
        for a in set.iter().filter(finite) {
            let (x, y, dx, dy) = *a;
            if !(axis.contains(x) && axis.contains(y)) {
                continue;
            }
            let base = chart.backend_coord(&(x, y));
            let tip = chart.backend_coord(&(x + dx * scale, y + dy * scale));
            let (ox, oy) = (f64::from(tip.0 - base.0), f64::from(tip.1 - base.1));
            // An arrow leaving the plot is cut at the frame and drawn without its head.
            let t = exit_fraction(base, (ox, oy), &plot_rect);
            let (shaft, head) = if t < 1.0 {
                (
                    vec![(0, 0), ((ox * t).round() as i32, (oy * t).round() as i32)],
                    Vec::new(),
                )
            } else {
                arrow_shape(ox, oy)
            };
            elements.push(
                EmptyElement::at((x, y))
                    + PathElement::new(shaft, style.stroke_width(1))
                    + Polygon::new(head, style.filled()),
            );
        }
        chart.draw_series(elements)?;
    }

    // Strip above the plot: legend (left) and reference arrow (right).
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let (ox, oy) = area.get_base_pixel();
    let y_mid = yr.start - oy - (strip as i32) / 2;
    let text = TextStyle::from((FONT, LEGEND_SIZE).into_font()).color(&BLACK);

    let screen_px_per_px = f64::from(xr.end - xr.start) / extent;
    // The reference arrow keeps the requested length unless that is unreadably short or too long for
    // the strip; then a round number of mas is shown instead.
    let screen_per_mas = scale * screen_px_per_px;
    let max_len = 0.4 * f64::from(xr.end - xr.start);
    let wanted = reference_mas * screen_per_mas;
    let ref_mas = if !positive(wanted) {
        1.0
    } else if wanted > max_len {
        nice_floor(max_len / screen_per_mas)
    } else if wanted < 8.0 {
        nice_ceil(8.0 / screen_per_mas)
    } else {
        reference_mas
    };
    let ref_len = (ref_mas * screen_per_mas).clamp(1.0, max_len.max(1.0));
    let x_end = xr.end - ox;
    let x_start = x_end - ref_len.round() as i32;
    let (shaft, head) = arrow_shape(ref_len, 0.0);
    area.draw(
        &(EmptyElement::at((x_start, y_mid))
            + PathElement::new(shaft, BLACK.stroke_width(2))
            + Polygon::new(head, BLACK.filled())),
    )?;
    let ref_label = format!("{} mas", fmt_num(ref_mas));
    area.draw(&Text::new(
        ref_label,
        (x_start - 10, y_mid),
        text.pos(Pos::new(HPos::Right, VPos::Center)),
    ))?;

    draw_legend(&area, sets, &text, (xr.start - ox, x_start, y_mid))?;
    Ok(chart.plotting_area().dim_in_pixel())
}

/// The legend in the strip above the plot: an arrow in each labelled set's colour and its label, in a
/// framed box from `box_left` that stops short of the reference arrow (at `x_reference`), centred on `y_mid`.
fn draw_legend(
    area: &Area<'_>,
    sets: &[(String, Vec<(f64, f64, f64, f64)>)],
    text: &TextStyle<'_>,
    (box_left, x_reference, y_mid): (i32, i32, i32),
) -> Result<(), Box<dyn Error>> {
    let labelled: Vec<(usize, &str)> = sets
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.0.is_empty())
        .map(|(i, s)| (i, s.0.as_str()))
        .collect();
    if !labelled.is_empty() {
        let mut entries = Vec::new();
        let mut x = box_left + 10;
        for &(i, label) in &labelled {
            let (tw, _) = area.estimate_text_size(label, text)?;
            entries.push((i, label, x));
            x += 34 + tw as i32 + 18;
        }
        let box_right = (x - 8).min(x_reference - 90).max(box_left + 40);
        area.draw(&Rectangle::new(
            [(box_left, y_mid - 15), (box_right, y_mid + 15)],
            WHITE.filled(),
        ))?;
        area.draw(&Rectangle::new(
            [(box_left, y_mid - 15), (box_right, y_mid + 15)],
            BLACK.stroke_width(1),
        ))?;
        for (i, label, x) in entries {
            let c = color(i);
            let (shaft, head) = arrow_shape(26.0, 0.0);
            area.draw(
                &(EmptyElement::at((x, y_mid))
                    + PathElement::new(shaft, c.stroke_width(2))
                    + Polygon::new(head, c.filled())),
            )?;
            area.draw(&Text::new(
                label,
                (x + 34, y_mid),
                text.pos(Pos::new(HPos::Left, VPos::Center)),
            ))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::tests::{assert_png, lcg, test_dir};
    use super::super::{DynResult, ensure_font};
    use super::*;

    #[test]
    fn vector_map_two_sets() {
        let dir = test_dir("vector");
        let rx = lcg(60, 3);
        let ry = lcg(60, 4);
        let measured: Vec<(f64, f64, f64, f64)> = rx
            .iter()
            .zip(&ry)
            .map(|(&u, &v)| {
                let (x, y) = (4096.0 * u, 4096.0 * v);
                (
                    x,
                    y,
                    3.0 * (y / 4096.0 - 0.5),
                    -2.0 * (x / 4096.0 - 0.5) + 0.5,
                )
            })
            .collect();
        let predicted: Vec<(f64, f64, f64, f64)> = measured
            .iter()
            .map(|&(x, y, dx, dy)| (x, y, 0.9 * dx, 0.9 * dy))
            .collect();
        let mut with_zero = measured.clone();
        with_zero.push((2048.0, 2048.0, 0.0, 0.0));
        let sets = vec![
            ("measured".to_string(), with_zero),
            ("predicted".to_string(), predicted),
        ];
        let path = dir.join("vectors.png");
        vector_map(&path, "Distortion residuals", &sets, 4096.0, 1.0, 200.0).expect("vector map");
        assert_png(&path, 5000);
    }

    #[test]
    fn nice_numbers() {
        assert_eq!(
            (nice_floor(1.41), nice_floor(0.4), nice_floor(5.0)),
            (1.0, 0.2, 5.0)
        );
        assert_eq!(
            (nice_ceil(1.41), nice_ceil(0.04), nice_ceil(7.0)),
            (2.0, 0.05, 10.0)
        );
    }

    #[test]
    fn vector_map_plot_area_is_square() -> DynResult {
        ensure_font()?;
        let mut buffer = vec![0u8; 800 * 800 * 3];
        let root = BitMapBackend::with_buffer(&mut buffer, MAP_SIZE).into_drawing_area();
        let (w, h) = draw_vector_map(&root, "t", &[], 100.0, (1.0, 5.0), ("x", "y"))?;
        assert_eq!(w, h);
        assert!(w > 500, "plot side {w}");
        Ok(())
    }
}
