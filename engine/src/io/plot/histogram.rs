//! Histograms with the empirical CDF on a secondary axis and an optional threshold line.

use super::{
    Area, Axis, DESC_SIZE, DynResult, FONT, PALETTE, PLOT_SIZE, PlotError, REF_COLORS, Scale,
    TICK_SIZE, TITLE_SIZE, configure_mesh, dashed_glyph, draw_legend, fmt_num, legend_corner,
    render, tick_label,
};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// Histogram (about sqrt(n) bins, at most 40) with the empirical CDF on a secondary right-hand axis (0..1)
/// and a vertical dashed line at `threshold` (value, label) if given; its legend entry states the fraction
/// of values at or below it. Non-finite values are skipped; an empty list gives an empty titled plot.
pub fn histogram_cdf(
    path: &Path,
    title: &str,
    x_label: &str,
    values: &[f64],
    threshold: Option<(f64, String)>,
) -> Result<(), PlotError> {
    render(path, PLOT_SIZE, |root| {
        draw_histogram(root, title, x_label, values, threshold.as_ref())
    })
}

fn draw_histogram(
    root: &Area<'_>,
    title: &str,
    x_label: &str,
    values: &[f64],
    threshold: Option<&(f64, String)>,
) -> DynResult {
    let mut vals: Vec<f64> = values
        .iter()
        .copied()
        .filter(|&v| Axis::usable(v, Scale::Linear))
        .collect();
    vals.sort_by(f64::total_cmp);
    let n = vals.len();
    let threshold = threshold.filter(|t| Axis::usable(t.0, Scale::Linear));

    let (lo, hi, width, counts) = bins(&vals);
    let max_count = counts.iter().copied().max().unwrap_or(0);

    let x_axis = Axis::fit(
        [lo, hi].into_iter().chain(threshold.map(|t| t.0)),
        Scale::Linear,
    );
    let y_axis = Axis {
        lo: 0.0,
        hi: (max_count as f64 * 1.1).max(1.0),
        log: false,
        integer: true,
    };
    let cdf_axis = Axis::linear(0.0, 1.05);

    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, TITLE_SIZE))
        .margin(15)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .right_y_label_area_size(75)
        .build_cartesian_2d(x_axis, y_axis)?
        .set_secondary_coord(x_axis, cdf_axis);
    configure_mesh(&mut chart, x_label, "count")?;
    chart
        .configure_secondary_axes()
        .y_desc("cumulative fraction")
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .y_label_formatter(&|v| tick_label(&cdf_axis, *v))
        .y_labels(8)
        .draw()?;

    let mut occupied = Vec::new();
    if n == 0 {
        let center = ((x_axis.lo + x_axis.hi) / 2.0, y_axis.hi / 2.0);
        let style = TextStyle::from((FONT, 22).into_font()).color(&RGBColor(120, 120, 120));
        chart.plotting_area().draw(&Text::new(
            "no data",
            center,
            style.pos(Pos::new(HPos::Center, VPos::Center)),
        ))?;
    } else {
        let bar_color = PALETTE[0];
        let bars: Vec<(f64, f64, usize)> = counts
            .iter()
            .enumerate()
            .map(|(k, &c)| (lo + k as f64 * width, lo + (k + 1) as f64 * width, c))
            .collect();
        for &(a, b, c) in &bars {
            occupied.extend((0..=4).map(|j| {
                (
                    x_axis.frac((a + b) / 2.0),
                    y_axis.frac(c as f64 * f64::from(j) / 4.0),
                )
            }));
        }
        let fill = bar_color.mix(0.45).filled();
        chart
            .draw_series(
                bars.iter()
                    .filter(|b| b.2 > 0)
                    .map(|&(a, b, c)| Rectangle::new([(a, 0.0), (b, c as f64)], fill)),
            )?
            .label(format!("histogram (N = {n})"))
            .legend(move |(x, y)| Rectangle::new([(x + 2, y - 6), (x + 26, y + 6)], fill));
        chart.draw_series(bars.iter().filter(|b| b.2 > 0).map(|&(a, b, c)| {
            Rectangle::new([(a, 0.0), (b, c as f64)], bar_color.stroke_width(1))
        }))?;

        let steps = cdf_steps(&vals, &x_axis);
        occupied.extend(
            steps
                .iter()
                .step_by((steps.len() / 50).max(1))
                .map(|&(x, f)| (x_axis.frac(x), y_axis.frac(f * y_axis.hi / 1.05))),
        );
        let cdf_style = PALETTE[3].stroke_width(2);
        chart
            .draw_secondary_series(LineSeries::new(steps, cdf_style))?
            .label("empirical CDF")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 28, y)], cdf_style));
    }

    if let Some((t, label)) = threshold {
        let style = REF_COLORS[0].stroke_width(2);
        occupied.extend([0.1, 0.3, 0.5, 0.7, 0.9].map(|fy| (x_axis.frac(*t), fy)));
        let name = if label.is_empty() {
            format!("threshold {}", fmt_num(*t))
        } else {
            label.clone()
        };
        let text = if n > 0 {
            let below = vals.iter().filter(|&&v| v <= *t).count();
            format!("{name} ({:.1} % below)", 100.0 * below as f64 / n as f64)
        } else {
            name
        };
        chart
            .draw_series(DashedLineSeries::new(
                vec![(*t, 0.0), (*t, y_axis.hi)],
                10,
                6,
                style,
            ))?
            .label(text)
            .legend(move |p| dashed_glyph!(p, style));
    }

    if n > 0 || threshold.is_some() {
        // the histogram, its CDF, the threshold
        let entries = 2 * usize::from(n > 0) + usize::from(threshold.is_some());
        draw_legend(&mut chart, legend_corner(&occupied, entries))?;
    }
    Ok(())
}

/// Bins of the sorted values, √n of them (1–40), over [lo, hi] (widened to one bin about them when all are
/// equal): (lo, hi, bin width, counts).
fn bins(sorted: &[f64]) -> (f64, f64, f64, Vec<usize>) {
    let n = sorted.len();
    let mut nbins = ((n as f64).sqrt().ceil() as usize).clamp(1, 40);
    let (mut lo, mut hi) = match (sorted.first(), sorted.last()) {
        (Some(&a), Some(&b)) => (a, b),
        _ => (0.0, 1.0),
    };
    if hi - lo <= 1e-12 * lo.abs().max(hi.abs()) {
        // All values equal: one bin centred on them.
        let half = if lo == 0.0 { 0.5 } else { 0.05 * lo.abs() };
        (lo, hi, nbins) = (lo - half, hi + half, 1);
    }
    let width = (hi - lo) / nbins as f64;
    let mut counts = vec![0usize; nbins];
    for &v in sorted {
        let k = (((v - lo) / width).floor().max(0.0) as usize).min(nbins - 1);
        counts[k] += 1;
    }
    (lo, hi, width, counts)
}

/// The empirical CDF of the sorted values as a step function over the whole x axis.
fn cdf_steps(sorted: &[f64], x_axis: &Axis) -> Vec<(f64, f64)> {
    let n = sorted.len();
    let mut steps = vec![(x_axis.lo, 0.0)];
    for (i, &v) in sorted.iter().enumerate() {
        steps.push((v, i as f64 / n as f64));
        steps.push((v, (i + 1) as f64 / n as f64));
    }
    steps.push((x_axis.hi, 1.0));
    steps
}

#[cfg(test)]
mod tests {
    use super::super::tests::{assert_png, lcg, test_dir};
    use super::*;

    #[test]
    fn histogram_with_threshold() {
        let dir = test_dir("hist");
        let values: Vec<f64> = lcg(500, 5)
            .iter()
            .zip(lcg(500, 6))
            .map(|(a, b)| 3.0 * (a + b))
            .collect();
        let path = dir.join("hist.png");
        histogram_cdf(
            &path,
            "Per-star error",
            "error [mas]",
            &values,
            Some((4.0, "4 mas requirement".into())),
        )
        .expect("histogram");
        assert_png(&path, 5000);
    }
}
