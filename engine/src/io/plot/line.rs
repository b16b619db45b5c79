//! Line plots (error bars, horizontal reference lines) and scatter plots (optional y = x diagonal).

use super::{
    Area, Axis, DynResult, FONT, PLOT_SIZE, PlotError, REF_COLORS, Scale, Series, TITLE_SIZE,
    color, configure_mesh, dashed_glyph, draw_legend, legend_corner, marker_shape, render,
};
use plotters::prelude::*;
use std::path::Path;

/// An error bar: its lengths below and above the point.
type Bar = (f64, f64);

/// The (x, y, bar) triples of a series, truncated to the shorter of x and y: the bar is `yerr` both ways, or
/// `yerr_below` below and `yerr` above when the series has asymmetric bars.
fn triples(s: &Series) -> impl Iterator<Item = (f64, f64, Option<Bar>)> + '_ {
    s.x.iter().zip(&s.y).enumerate().map(|(i, (&x, &y))| {
        let above = s.yerr.as_ref().and_then(|e| e.get(i).copied());
        let below = match &s.yerr_below {
            Some(b) => b.get(i).copied(),
            None => above,
        };
        (x, y, above.zip(below).map(|(a, b)| (b, a)))
    })
}

/// Usable error-bar lengths (below, above): finite, not negative, not both zero.
fn usable_err(e: Option<Bar>) -> Option<Bar> {
    e.map(|(b, a)| (b.abs(), a.abs()))
        .filter(|(b, a)| b.is_finite() && a.is_finite() && (*b > 0.0 || *a > 0.0))
}

/// What distinguishes `line_plot` from `scatter`.
struct XyOptions<'a> {
    lines: bool,
    hlines: &'a [(f64, String)],
    diagonal: bool,
    /// Dashed companions: guide i is drawn in series i's colour, thin, without markers or a legend entry.
    guides: &'a [Series],
}

/// Shared body of `line_plot` and `scatter`.
#[allow(clippy::too_many_arguments)]
fn draw_xy(
    root: &Area<'_>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    x_scale: Scale,
    y_scale: Scale,
    opts: &XyOptions<'_>,
) -> DynResult {
    let ok = |x: f64, y: f64| Axis::usable(x, x_scale) && Axis::usable(y, y_scale);
    let (x_axis, y_axis) = fit_axes(series, (x_scale, y_scale), opts, &ok);

    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, TITLE_SIZE))
        .margin(15)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(x_axis, y_axis)?;
    configure_mesh(&mut chart, x_label, y_label)?;

    let mut occupied = Vec::new();
    let mut labels = 0usize;
    for (i, s) in series.iter().enumerate() {
        let c = color(i);
        let pts: Vec<(f64, f64, Option<Bar>)> = triples(s).collect();
        let valid: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| ok(p.0, p.1))
            .map(|p| (p.0, p.1))
            .collect();
        occupied.extend(valid.iter().map(|&(x, y)| (x_axis.frac(x), y_axis.frac(y))));

        let bar_style = c.stroke_width(1);
        let (bars, caps) = error_bars(&pts, &ok, &y_axis, y_scale);
        chart.draw_series(bars.into_iter().map(|b| PathElement::new(b, bar_style)))?;
        chart
            .draw_series(caps.into_iter().map(|p| {
                EmptyElement::at(p) + PathElement::new(vec![(-4, 0), (4, 0)], bar_style)
            }))?;

        let line_style = c.stroke_width(2);
        let segments = if opts.lines {
            line_segments(&pts, &ok)
        } else {
            Vec::new()
        };
        chart.draw_series(
            segments
                .into_iter()
                .map(|seg| PathElement::new(seg, line_style)),
        )?;

        let shape = marker_shape(i, 4.5);
        let anno = chart.draw_series(
            valid
                .iter()
                .map(|&p| EmptyElement::at(p) + Polygon::new(shape.clone(), c.filled())),
        )?;
        if !s.label.is_empty() {
            labels += 1;
            let lines = opts.lines;
            let glyph = marker_shape(i, 4.5);
            anno.label(s.label.as_str()).legend(move |(x, y)| {
                let line = if lines {
                    vec![(0, 0), (28, 0)]
                } else {
                    vec![(14, 0), (14, 0)]
                };
                EmptyElement::at((x, y))
                    + PathElement::new(line, line_style)
                    + Polygon::new(
                        glyph
                            .iter()
                            .map(|&(dx, dy)| (dx + 14, dy))
                            .collect::<Vec<_>>(),
                        c.filled(),
                    )
            });
        }
    }

    // Each series' dashed guide, in its colour.
    for (i, g) in opts.guides.iter().enumerate() {
        let style = color(i).stroke_width(1);
        let line: Vec<(f64, f64)> =
            g.x.iter()
                .zip(&g.y)
                .map(|(x, y)| (*x, *y))
                .filter(|&(x, y)| ok(x, y) && x_axis.contains(x) && y_axis.contains(y))
                .collect();
        occupied.extend(line.iter().map(|&(x, y)| (x_axis.frac(x), y_axis.frac(y))));
        chart.draw_series(DashedLineSeries::new(line, 6, 4, style))?;
    }

    // Horizontal dashed reference lines.
    let usable_hlines = opts.hlines.iter().filter(|h| Axis::usable(h.0, y_scale));
    for (k, (v, label)) in usable_hlines.enumerate() {
        let style = REF_COLORS[k % REF_COLORS.len()].stroke_width(2);
        let anno = chart.draw_series(DashedLineSeries::new(
            vec![(x_axis.lo, *v), (x_axis.hi, *v)],
            10,
            6,
            style,
        ))?;
        occupied.extend([0.1, 0.3, 0.5, 0.7, 0.9].map(|fx| (fx, y_axis.frac(*v))));
        if !label.is_empty() {
            labels += 1;
            anno.label(label.as_str())
                .legend(move |p| dashed_glyph!(p, style));
        }
    }

    // y = x over the part of the plot where both axes overlap.
    if opts.diagonal
        && let Some(line) = diagonal(&x_axis, &y_axis)
    {
        occupied.extend(
            line.iter()
                .step_by(10)
                .map(|&(x, y)| (x_axis.frac(x), y_axis.frac(y))),
        );
        let style = REF_COLORS[1].stroke_width(1);
        chart
            .draw_series(DashedLineSeries::new(line, 8, 5, style))?
            .label("y = x")
            .legend(move |p| dashed_glyph!(p, style));
        labels += 1;
    }

    if labels > 0 {
        draw_legend(&mut chart, legend_corner(&occupied, labels))?;
    }
    Ok(())
}

/// The axes that show every usable point with its error bar, the reference lines and the guides (within
/// the x axis).
fn fit_axes(
    series: &[Series],
    (x_scale, y_scale): (Scale, Scale),
    opts: &XyOptions<'_>,
    ok: &dyn Fn(f64, f64) -> bool,
) -> (Axis, Axis) {
    let x_axis = Axis::fit(
        series
            .iter()
            .flat_map(triples)
            .filter(|&(x, y, _)| ok(x, y))
            .map(|p| p.0),
        x_scale,
    );
    let y_values = series
        .iter()
        .flat_map(triples)
        .filter(|&(x, y, _)| ok(x, y))
        .flat_map(|(_, y, e)| {
            let (below, above) = usable_err(e).unwrap_or((0.0, 0.0));
            [y, y - below, y + above]
        });
    let hline_values = opts.hlines.iter().map(|h| h.0);
    let guide_values = opts
        .guides
        .iter()
        .flat_map(|g| g.x.iter().zip(&g.y))
        .filter(|&(x, y)| ok(*x, *y) && x_axis.contains(*x))
        .map(|(_, y)| *y);
    let y_axis = Axis::fit(y_values.chain(hline_values).chain(guide_values), y_scale);
    (x_axis, y_axis)
}

/// Error bars of the usable points: each bar's ends (a lower end that a log axis cannot show runs to the
/// axis) and the caps the axis can show (none at such an end).
fn error_bars(
    pts: &[(f64, f64, Option<Bar>)],
    ok: &dyn Fn(f64, f64) -> bool,
    y_axis: &Axis,
    y_scale: Scale,
) -> (Vec<Vec<(f64, f64)>>, Vec<(f64, f64)>) {
    let mut bars = Vec::new();
    let mut caps = Vec::new();
    for &(x, y, e) in pts.iter().filter(|p| ok(p.0, p.1)) {
        let Some((below, above)) = usable_err(e) else {
            continue;
        };
        let (lo, hi) = (y - below, y + above);
        for end in [lo, hi] {
            if Axis::usable(end, y_scale) && y_axis.contains(end) {
                caps.push((x, end));
            }
        }
        let lo = if Axis::usable(lo, y_scale) {
            lo
        } else {
            y_axis.lo
        };
        bars.push(vec![(x, y_axis.clamp(lo)), (x, y_axis.clamp(hi))]);
    }
    (bars, caps)
}

/// A series' line, broken at its unusable points.
fn line_segments(
    pts: &[(f64, f64, Option<Bar>)],
    ok: &dyn Fn(f64, f64) -> bool,
) -> Vec<Vec<(f64, f64)>> {
    let mut segments = Vec::new();
    let mut current = Vec::new();
    for p in pts {
        if ok(p.0, p.1) {
            current.push((p.0, p.1));
        } else if !current.is_empty() {
            segments.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        segments.push(current);
    }
    segments
}

/// y = x over the range both axes show, as 201 points even in the x axis' scale; `None` where they do not
/// overlap.
fn diagonal(x_axis: &Axis, y_axis: &Axis) -> Option<Vec<(f64, f64)>> {
    let (lo, hi) = (x_axis.lo.max(y_axis.lo), x_axis.hi.min(y_axis.hi));
    if !(lo < hi) {
        return None;
    }
    let (ta, tb) = (x_axis.t(lo), x_axis.t(hi));
    Some(
        (0..=200)
            .map(|k| {
                x_axis
                    .inv_t(ta + (tb - ta) * k as f64 / 200.0)
                    .clamp(lo, hi)
            })
            .map(|v| (v, v))
            .collect(),
    )
}

/// Line plot with error bars and a legend; `hlines` are horizontal dashed reference lines (value, label),
/// e.g. the 4-mas requirement. Axis ranges fit all data (and error bars and hlines) with a 5 % margin; for
/// Log scales non-positive values are ignored.
#[allow(clippy::too_many_arguments)]
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    hlines: &[(f64, String)],
    x_scale: Scale,
    y_scale: Scale,
) -> Result<(), PlotError> {
    line_plot_with_guides(
        path,
        title,
        x_label,
        y_label,
        series,
        &[],
        hlines,
        x_scale,
        y_scale,
    )
}

/// [`line_plot`] with a dashed guide beside each series (guide i in series i's colour, no legend entry):
/// e.g. what √N averaging would give beside each measured curve.
#[allow(clippy::too_many_arguments)]
pub fn line_plot_with_guides(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    guides: &[Series],
    hlines: &[(f64, String)],
    x_scale: Scale,
    y_scale: Scale,
) -> Result<(), PlotError> {
    let opts = XyOptions {
        lines: true,
        hlines,
        diagonal: false,
        guides,
    };
    render(path, PLOT_SIZE, |root| {
        draw_xy(
            root, title, x_label, y_label, series, x_scale, y_scale, &opts,
        )
    })
}

/// Scatter plot (markers only, no lines; error bars where `yerr` is given) of several labelled point sets
/// with a legend and optional log axes. `diagonal` draws the y = x line.
#[allow(clippy::too_many_arguments)]
pub fn scatter(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    sets: &[Series],
    x_scale: Scale,
    y_scale: Scale,
    diagonal: bool,
) -> Result<(), PlotError> {
    let opts = XyOptions {
        lines: false,
        hlines: &[],
        guides: &[],
        diagonal,
    };
    render(path, PLOT_SIZE, |root| {
        draw_xy(root, title, x_label, y_label, sets, x_scale, y_scale, &opts)
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::{assert_png, lcg, series, test_dir};
    use super::*;

    #[test]
    fn line_plot_with_error_bars_and_hline() {
        let dir = test_dir("line");
        let mags = [8.0, 9.0, 10.0, 11.0, 12.0, 12.5];
        let err = [0.8, 1.1, 1.9, 3.2, 5.6, 7.9];
        let sig = [0.1, 0.15, 0.2, 0.4, 0.7, 1.0];
        let s = [
            series("fast integrator", &mags, &err, Some(&sig)),
            series(
                "reference",
                &mags,
                &err.map(|e| e * 0.8),
                Some(&sig.map(|s| s * 0.5)),
            ),
            series("CRLB", &mags, &err.map(|e| e * 0.6), None),
        ];
        let path = dir.join("accuracy.png");
        line_plot(
            &path,
            "Astrometric accuracy vs magnitude",
            "Hw [mag]",
            "error [mas]",
            &s,
            &[(4.0, "4 mas requirement".into())],
            Scale::Linear,
            Scale::Linear,
        )
        .expect("line plot");
        assert_png(&path, 5000);

        let path = dir.join("accuracy_log.png");
        line_plot(
            &path,
            "log-log",
            "exposure [s]",
            "error [mas]",
            &s,
            &[(4.0, "4 mas".into()), (-1.0, "ignored".into())],
            Scale::Log,
            Scale::Log,
        )
        .expect("log line plot");
        assert_png(&path, 5000);
    }

    #[test]
    fn scatter_with_diagonal() {
        let dir = test_dir("scatter");
        let r = lcg(80, 1);
        let predicted: Vec<f64> = r.iter().map(|v| 0.5 + 10.0 * v).collect();
        let measured: Vec<f64> = predicted
            .iter()
            .zip(lcg(80, 2))
            .map(|(p, n)| p * (0.8 + 0.4 * n))
            .collect();
        let sets = [
            series("x component", &predicted, &measured, None),
            series("y component", &measured, &predicted, Some(&[0.3; 80])),
        ];
        let path = dir.join("pred_vs_meas.png");
        scatter(
            &path,
            "Predicted vs measured",
            "predicted [mas]",
            "measured [mas]",
            &sets,
            Scale::Linear,
            Scale::Linear,
            true,
        )
        .expect("scatter");
        assert_png(&path, 5000);

        let times = [0.5, 2.0, 8.0, 30.0, 120.0];
        let errs = [3.0, 1.2, 0.6, 0.31, 0.3];
        let path = dir.join("tradeoff.png");
        let sets = [
            series("CPU", &times, &errs, None),
            series("GPU", &times.map(|t| t / 20.0), &errs, None),
        ];
        scatter(
            &path,
            "Wall time vs error",
            "wall time [s]",
            "error [mas]",
            &sets,
            Scale::Log,
            Scale::Log,
            false,
        )
        .expect("log scatter");
        assert_png(&path, 5000);
    }
}
