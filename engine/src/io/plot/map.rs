//! A map of counts on a regular grid (a sequence's coverage: exposures per sky cell), with a colour key.

use super::{DESC_SIZE, DynResult, FONT, PlotError, TICK_SIZE, TITLE_SIZE, render};
use plotters::prelude::*;
use std::path::Path;

/// The colour of a fraction t ∈ [0, 1] of the largest count: white for zero, then a sequential scale from
/// pale yellow through orange to dark red-brown (readable in print and for red-green colour blindness).
fn heat(t: f64) -> RGBColor {
    const STOPS: [(f64, (u8, u8, u8)); 5] = [
        (0.0, (255, 247, 188)),
        (0.25, (254, 196, 79)),
        (0.5, (236, 112, 20)),
        (0.75, (204, 76, 2)),
        (1.0, (102, 37, 6)),
    ];
    let t = t.clamp(0.0, 1.0);
    let k = STOPS.iter().rposition(|(s, _)| *s <= t).unwrap_or(0).min(3);
    let ((a, ca), (b, cb)) = (STOPS[k], STOPS[k + 1]);
    let f = (t - a) / (b - a);
    let mix = |x: u8, y: u8| (x as f64 + f * (y as f64 - x as f64)).round() as u8;
    RGBColor(mix(ca.0, cb.0), mix(ca.1, cb.1), mix(ca.2, cb.2))
}

/// The grid of counts: `columns × rows` cells, row-major with row 0 at the bottom, cell (i, j) spanning
/// x ∈ [x0 + i·cell, x0 + (i+1)·cell] (and y likewise). `x_reversed` draws x growing to the left (Galactic
/// longitude on the sky).
#[derive(Debug, Clone, Copy)]
pub struct CountGrid<'a> {
    pub counts: &'a [u32],
    pub columns: usize,
    pub rows: usize,
    pub x0: f64,
    pub y0: f64,
    pub cell: f64,
    pub x_reversed: bool,
}

/// Draw `grid` as a map (zero cells white) with a colour key of the counts.
pub fn count_map(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    grid: CountGrid<'_>,
) -> Result<(), PlotError> {
    if grid.columns.checked_mul(grid.rows) != Some(grid.counts.len()) || grid.counts.is_empty() {
        return Err(super::draw_error(
            path,
            format!(
                "{} counts for a {} × {} grid",
                grid.counts.len(),
                grid.columns,
                grid.rows
            ),
        ));
    }
    let aspect = grid.rows as f64 / grid.columns as f64;
    let width = 900u32;
    let height = ((width as f64 - 220.0) * aspect + 140.0).clamp(300.0, 1200.0) as u32;
    render(path, (width, height), |root| {
        draw(root, title, x_label, y_label, grid)
    })
}

fn draw(
    root: &super::Area<'_>,
    title: &str,
    x_label: &str,
    y_label: &str,
    g: CountGrid<'_>,
) -> DynResult {
    let max = g.counts.iter().copied().max().unwrap_or(0).max(1);
    let (main, key) = root.split_horizontally(root.dim_in_pixel().0 - 120);
    let (x_lo, x_hi) = (g.x0, g.x0 + g.columns as f64 * g.cell);
    let (y_lo, y_hi) = (g.y0, g.y0 + g.rows as f64 * g.cell);
    let mut chart = ChartBuilder::on(&main)
        .caption(title, (FONT, TITLE_SIZE))
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(
            if g.x_reversed {
                -x_hi..-x_lo
            } else {
                x_lo..x_hi
            },
            y_lo..y_hi,
        )?;
    let reversed = g.x_reversed;
    let fmt_x = move |v: &f64| format!("{:.2}", if reversed { -*v } else { *v });
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&fmt_x)
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    let sx = |x: f64| if reversed { -x } else { x };
    chart.draw_series(
        g.counts
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(|(k, c)| {
                let (i, j) = ((k % g.columns) as f64, (k / g.columns) as f64);
                let (a, b) = (sx(g.x0 + i * g.cell), sx(g.x0 + (i + 1.0) * g.cell));
                Rectangle::new(
                    [(a, g.y0 + j * g.cell), (b, g.y0 + (j + 1.0) * g.cell)],
                    heat(*c as f64 / max as f64).filled(),
                )
            }),
    )?;
    // the key: the colour scale from 1 to the largest count
    let mut k = ChartBuilder::on(&key)
        .margin_top(60)
        .margin_bottom(62)
        .margin_right(50)
        .y_label_area_size(0)
        .right_y_label_area_size(45)
        .build_cartesian_2d(0.0..1.0, 0.0..max as f64)?;
    k.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .label_style((FONT, TICK_SIZE))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    let steps = 100;
    k.draw_series((0..steps).map(|s| {
        let (a, b) = (s as f64 / steps as f64, (s + 1) as f64 / steps as f64);
        Rectangle::new(
            [(0.0, a * max as f64), (1.0, b * max as f64)],
            heat((a + b) / 2.0).filled(),
        )
    }))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_map_is_drawn_and_a_wrong_grid_is_an_error() {
        let dir = std::env::temp_dir().join(format!("jsim-map-{}", std::process::id()));
        let path = dir.join("map.png");
        let counts: Vec<u32> = (0..12).collect();
        let grid = CountGrid {
            counts: &counts,
            columns: 4,
            rows: 3,
            x0: -1.0,
            y0: -0.5,
            cell: 0.5,
            x_reversed: true,
        };
        count_map(&path, "coverage", "l [deg]", "b [deg]", grid).expect("drawn");
        assert!(std::fs::metadata(&path).expect("png").len() > 1000);
        let bad = CountGrid { columns: 5, ..grid };
        assert!(count_map(&path, "t", "x", "y", bad).is_err());
        assert_eq!(heat(0.0), RGBColor(255, 247, 188));
        assert_eq!(heat(1.0), RGBColor(102, 37, 6));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
