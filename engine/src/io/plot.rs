//! PNG figures: accuracy curves, trade-off scatter plots, deviation vector maps, histograms with the
//! empirical CDF and greyscale image previews.
//!
//! Everything is drawn with `plotters` on a bitmap using the embedded DejaVu Sans font (registered once as
//! "sans-serif"). Every figure is drawn to `<path>.tmp.png` and renamed into place, so an interrupted run
//! never leaves a half-written PNG. Odd input (NaN/inf, empty series, constant values) never panics: such
//! points are skipped and degenerate axis ranges are widened.

use std::error::Error;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, register_font};

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("cannot draw {path}: {message}")]
    Draw { path: String, message: String },
}

/// One curve: points joined by lines with markers; optional symmetric y error bars.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub yerr: Option<Vec<f64>>,
}

/// Axis scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Linear,
    Log,
}

// ---------------------------------------------------------------------------------------------------------
// Shared infrastructure: font, atomic output, style constants.
// ---------------------------------------------------------------------------------------------------------

/// Font family used for every text element.
const FONT: &str = "sans-serif";
/// DejaVu Sans, embedded so that figures render identically everywhere.
static FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Size of the line/scatter/histogram figures.
const PLOT_SIZE: (u32, u32) = (900, 600);
/// Size of the (square) vector map.
const MAP_SIZE: (u32, u32) = (800, 800);
/// Largest image `image_png` writes (pixels), keeping the bitmap allocation sane.
const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// Fixed colour cycle for series (Tableau 10).
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];
/// Colours of horizontal/vertical reference lines.
const REF_COLORS: [RGBColor; 3] = [
    RGBColor(0, 0, 0),
    RGBColor(90, 90, 90),
    RGBColor(150, 60, 20),
];
const GRID: RGBColor = RGBColor(225, 225, 225);

const TITLE_SIZE: u32 = 24;
const DESC_SIZE: u32 = 18;
const TICK_SIZE: u32 = 15;
const LEGEND_SIZE: u32 = 15;

type DynResult = Result<(), Box<dyn Error>>;
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

fn draw_error(path: &Path, message: impl ToString) -> PlotError {
    PlotError::Draw {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// Register the embedded font once; later calls return the cached outcome.
fn ensure_font() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "the embedded font cannot be parsed".to_string())
        })
        .clone()
}

/// `<path>.tmp.png`: the bitmap encoder is chosen from the extension, so it must stay `.png`.
fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp.png");
    PathBuf::from(name)
}

/// Run `write` on the temporary sibling of `path`, then rename it into place (removing it on failure).
fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> DynResult) -> Result<(), PlotError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| draw_error(path, e))?;
    }
    let tmp = tmp_path(path);
    let outcome = write(&tmp)
        .map_err(|e| draw_error(path, e))
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| draw_error(path, e)));
    if outcome.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    outcome
}

/// Draw a figure of `size` pixels on a white background and write it atomically to `path`.
fn render(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> DynResult,
) -> Result<(), PlotError> {
    ensure_font().map_err(|e| draw_error(path, e))?;
    write_atomic(path, |tmp| {
        let root = BitMapBackend::new(tmp, size).into_drawing_area();
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
        Ok(())
    })
}

fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

// ---------------------------------------------------------------------------------------------------------
// Axis: one coordinate type for both linear and logarithmic scales, with its own tick placement.
// ---------------------------------------------------------------------------------------------------------

/// A 1-D axis from `lo` to `hi` (both > 0 when `log`). `integer` forces tick steps ≥ 1 (counts).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    integer: bool,
}

impl Axis {
    fn linear(lo: f64, hi: f64) -> Self {
        Axis {
            lo,
            hi,
            log: false,
            integer: false,
        }
    }

    /// Whether `v` can be placed on an axis of this scale (finite, not absurdly large, > 0 for log).
    fn usable(v: f64, scale: Scale) -> bool {
        v.is_finite() && v.abs() < 1e300 && (scale == Scale::Linear || v > 1e-300)
    }

    /// Fit the usable `values` with a 5 % margin; an empty or constant set gets a small nonzero range.
    fn fit(values: impl IntoIterator<Item = f64>, scale: Scale) -> Self {
        let log = scale == Scale::Log;
        let (mut lo, mut hi) = values
            .into_iter()
            .filter(|&v| Self::usable(v, scale))
            .map(|v| if log { v.log10() } else { v })
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
                (lo.min(t), hi.max(t))
            });
        if lo > hi {
            (lo, hi) = (0.0, 1.0);
        }
        if hi - lo <= 1e-12 * lo.abs().max(hi.abs()) {
            let half = if log {
                0.5
            } else if lo == 0.0 {
                1.0
            } else {
                0.1 * lo.abs()
            };
            (lo, hi) = (lo - half, hi + half);
        }
        let pad = 0.05 * (hi - lo);
        let (lo, hi) = (lo - pad, hi + pad);
        if log {
            Axis {
                lo: 10f64.powf(lo),
                hi: 10f64.powf(hi),
                log,
                integer: false,
            }
        } else {
            Axis::linear(lo, hi)
        }
    }

    /// Position along the axis in drawing space (log10 for log axes).
    fn t(&self, v: f64) -> f64 {
        if !self.log {
            v
        } else if v > 0.0 {
            v.log10()
        } else {
            f64::NEG_INFINITY
        }
    }

    /// Inverse of [`Axis::t`].
    fn inv_t(&self, t: f64) -> f64 {
        if self.log { 10f64.powf(t) } else { t }
    }

    /// Fraction of the axis length at which `v` lies (0 at `lo`, 1 at `hi`; NaN maps to 0).
    fn frac(&self, v: f64) -> f64 {
        let (a, b) = (self.t(self.lo), self.t(self.hi));
        let f = (self.t(v) - a) / (b - a);
        if f.is_nan() { 0.0 } else { f }
    }

    fn contains(&self, v: f64) -> bool {
        v >= self.lo && v <= self.hi
    }

    fn clamp(&self, v: f64) -> f64 {
        v.clamp(self.lo, self.hi)
    }
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        // Keep far-off (or -inf on a log axis) values at a bounded pixel position.
        let f = self.frac(*value).clamp(-10.0, 11.0);
        let px = f64::from(limit.0) + f * f64::from(limit.1 - limit.0);
        px.round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        let n = hint.max_num_points();
        if n == 0 {
            Vec::new()
        } else if self.log {
            log_ticks(self.lo, self.hi, n)
        } else {
            linear_ticks(self.lo, self.hi, n, self.integer)
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// At most `n` ticks at multiples of 1, 2 or 5 × 10^k inside `[lo, hi]`.
fn linear_ticks(lo: f64, hi: f64, n: usize, integer: bool) -> Vec<f64> {
    let span = hi - lo;
    if !(span > 0.0 && span.is_finite()) {
        return if lo.is_finite() { vec![lo] } else { Vec::new() };
    }
    let raw = span / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let mut step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * mag);
    if integer {
        step = step.max(1.0).round();
    }
    let (k0, k1) = ((lo / step).ceil(), (hi / step).floor());
    let mut ticks = Vec::new();
    for i in 0..=n {
        let k = k0 + i as f64;
        if k > k1 {
            break;
        }
        let v = k * step;
        ticks.push(if v.abs() < 1e-9 * step { 0.0 } else { v });
    }
    ticks
}

/// Decades when the range spans at least three of them, else 1-2-5 × 10^k, else plain linear ticks for
/// less than a decade (or 1…9 × 10^k).
fn log_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (
        lo.log10().clamp(-400.0, 400.0),
        hi.log10().clamp(-400.0, 400.0),
    );
    if a.is_nan() || b.is_nan() || a >= b {
        return linear_ticks(lo, hi, n, false);
    }
    let (d0, d1) = (a.ceil() as i32, b.floor() as i32);
    let decades = (d1 - d0 + 1).max(0) as usize;
    let decade_ticks = || {
        (d0..=d1)
            .step_by(decades.div_ceil(n).max(1))
            .map(|d| 10f64.powi(d))
            .collect()
    };
    if decades >= 3 {
        return decade_ticks();
    }
    let multiples = |mults: &'static [f64]| -> Vec<f64> {
        (a.floor() as i32..=b.ceil() as i32)
            .flat_map(|d| mults.iter().map(move |m| m * 10f64.powi(d)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    let ticks = multiples(&[1.0, 2.0, 5.0]);
    if (3..=n).contains(&ticks.len()) {
        return ticks;
    }
    if b - a < 1.0 {
        return linear_ticks(lo, hi, n.min(6), false);
    }
    let ticks = multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    if (2..=n).contains(&ticks.len()) {
        return ticks;
    }
    if decades >= 2 {
        return decade_ticks();
    }
    linear_ticks(lo, hi, n, false)
}

/// Tick label on `axis`: decimals matched to the tick spacing on linear axes (so that one axis never
/// mixes plain and scientific notation), [`fmt_num`] otherwise.
fn tick_label(axis: &Axis, v: f64) -> String {
    let big = axis.lo.abs().max(axis.hi.abs());
    if axis.log || !(1e-3..1e6).contains(&big) || v == 0.0 {
        return fmt_num(v);
    }
    // The finest spacing the mesh may use; trailing zeros are trimmed afterwards.
    let fine = (axis.hi - axis.lo) / 40.0;
    let decimals = (-fine.log10().floor()).clamp(0.0, 12.0) as usize;
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    if s == "-0" { "0".into() } else { s.to_string() }
}

/// Compact tick/label number: plain decimals for moderate magnitudes, scientific notation otherwise.
fn fmt_num(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-3..1e6).contains(&a) {
        let s = format!("{v:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{v:.3e}");
        match s.split_once('e') {
            Some((mantissa, exp)) => {
                format!(
                    "{}e{exp}",
                    mantissa.trim_end_matches('0').trim_end_matches('.')
                )
            }
            None => s,
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Markers, legends and shared chart pieces.
// ---------------------------------------------------------------------------------------------------------

/// Marker outline (pixel offsets) for series `i`: circle, square, triangle, diamond, inverted triangle.
fn marker_shape(i: usize, r: f64) -> Vec<(i32, i32)> {
    let polygon = |pts: &[(f64, f64)]| {
        pts.iter()
            .map(|&(x, y)| ((x * r).round() as i32, (y * r).round() as i32))
            .collect()
    };
    match i % 5 {
        0 => (0..16)
            .map(|k| {
                let phi = k as f64 * std::f64::consts::TAU / 16.0;
                (
                    (r * phi.cos()).round() as i32,
                    (r * phi.sin()).round() as i32,
                )
            })
            .collect(),
        1 => polygon(&[(-0.85, -0.85), (0.85, -0.85), (0.85, 0.85), (-0.85, 0.85)]),
        2 => polygon(&[(0.0, -1.15), (1.0, 0.6), (-1.0, 0.6)]),
        3 => polygon(&[(0.0, -1.2), (1.2, 0.0), (0.0, 1.2), (-1.2, 0.0)]),
        _ => polygon(&[(0.0, 1.15), (1.0, -0.6), (-1.0, -0.6)]),
    }
}

/// Where the legend box overlaps the fewest of the given points (fractions of the plot, y up).
fn legend_corner(points: &[(f64, f64)]) -> SeriesLabelPosition {
    let corners = [
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let mut best = (SeriesLabelPosition::UpperRight, usize::MAX);
    for (pos, right, upper) in corners {
        let count = points
            .iter()
            .filter(|&&(fx, fy)| {
                let in_x = if right { fx > 0.55 } else { fx < 0.45 };
                let in_y = if upper { fy > 0.6 } else { fy < 0.4 };
                in_x && in_y
            })
            .count();
        if count < best.1 {
            best = (pos, count);
        }
    }
    best.0
}

fn draw_legend<'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
    position: SeriesLabelPosition,
) -> DynResult {
    chart
        .configure_series_labels()
        .position(position)
        .margin(12)
        .legend_area_size(34)
        .label_font((FONT, LEGEND_SIZE))
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Dashed legend glyph (pixel offsets from the glyph's left-middle point `$p`).
macro_rules! dashed_glyph {
    ($p:expr, $style:expr) => {
        EmptyElement::at($p)
            + PathElement::new(vec![(0, 0), (8, 0)], $style)
            + PathElement::new(vec![(12, 0), (20, 0)], $style)
            + PathElement::new(vec![(24, 0), (28, 0)], $style)
    };
}

fn configure_mesh(
    chart: &mut ChartContext<'_, BitMapBackend<'_>, Cartesian2d<Axis, Axis>>,
    x_label: &str,
    y_label: &str,
) -> DynResult {
    let spec = chart.as_coord_spec();
    let (x_axis, y_axis) = (*spec.x_spec(), *spec.y_spec());
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .axis_desc_style((FONT, DESC_SIZE))
        .label_style((FONT, TICK_SIZE))
        .x_label_formatter(&|v| tick_label(&x_axis, *v))
        .y_label_formatter(&|v| tick_label(&y_axis, *v))
        .bold_line_style(GRID)
        .light_line_style(TRANSPARENT)
        .x_labels(10)
        .y_labels(10)
        .draw()?;
    Ok(())
}

/// The (x, y, yerr) triples of a series, truncated to the shorter of x and y.
fn triples(s: &Series) -> impl Iterator<Item = (f64, f64, Option<f64>)> + '_ {
    s.x.iter()
        .zip(&s.y)
        .enumerate()
        .map(|(i, (&x, &y))| (x, y, s.yerr.as_ref().and_then(|e| e.get(i).copied())))
}

/// Usable error-bar half length.
fn usable_err(e: Option<f64>) -> Option<f64> {
    e.map(f64::abs).filter(|e| e.is_finite() && *e > 0.0)
}

/// What distinguishes `line_plot` from `scatter`.
struct XyOptions<'a> {
    lines: bool,
    hlines: &'a [(f64, String)],
    diagonal: bool,
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
            let e = usable_err(e).unwrap_or(0.0);
            [y, y - e, y + e]
        });
    let hline_values = opts.hlines.iter().map(|h| h.0);
    let y_axis = Axis::fit(y_values.chain(hline_values), y_scale);

    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, TITLE_SIZE))
        .margin(15)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(x_axis, y_axis)?;
    configure_mesh(&mut chart, x_label, y_label)?;

    let mut occupied = Vec::new();
    let mut any_label = false;
    for (i, s) in series.iter().enumerate() {
        let c = color(i);
        let pts: Vec<(f64, f64, Option<f64>)> = triples(s).collect();
        let valid: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| ok(p.0, p.1))
            .map(|p| (p.0, p.1))
            .collect();
        occupied.extend(valid.iter().map(|&(x, y)| (x_axis.frac(x), y_axis.frac(y))));

        // Error bars; a lower end that a log axis cannot show runs to the axis, without a cap.
        let bar_style = c.stroke_width(1);
        let mut bars = Vec::new();
        let mut caps = Vec::new();
        for &(x, y, e) in pts.iter().filter(|p| ok(p.0, p.1)) {
            let Some(e) = usable_err(e) else { continue };
            let (lo, hi) = (y - e, y + e);
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
        chart.draw_series(bars.into_iter().map(|b| PathElement::new(b, bar_style)))?;
        chart
            .draw_series(caps.into_iter().map(|p| {
                EmptyElement::at(p) + PathElement::new(vec![(-4, 0), (4, 0)], bar_style)
            }))?;

        // Lines, broken at unusable points.
        let line_style = c.stroke_width(2);
        let mut segments: Vec<Vec<(f64, f64)>> = Vec::new();
        if opts.lines {
            let mut current = Vec::new();
            for p in &pts {
                if ok(p.0, p.1) {
                    current.push((p.0, p.1));
                } else if !current.is_empty() {
                    segments.push(std::mem::take(&mut current));
                }
            }
            if !current.is_empty() {
                segments.push(current);
            }
        }
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
            any_label = true;
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
            any_label = true;
            anno.label(label.as_str())
                .legend(move |p| dashed_glyph!(p, style));
        }
    }

    // y = x over the part of the plot where both axes overlap.
    if opts.diagonal {
        let (lo, hi) = (x_axis.lo.max(y_axis.lo), x_axis.hi.min(y_axis.hi));
        if lo < hi {
            let (ta, tb) = (x_axis.t(lo), x_axis.t(hi));
            let line: Vec<(f64, f64)> = (0..=200)
                .map(|k| {
                    x_axis
                        .inv_t(ta + (tb - ta) * k as f64 / 200.0)
                        .clamp(lo, hi)
                })
                .map(|v| (v, v))
                .collect();
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
            any_label = true;
        }
    }

    if any_label {
        draw_legend(&mut chart, legend_corner(&occupied))?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------------------
// Public figures.
// ---------------------------------------------------------------------------------------------------------

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
    let opts = XyOptions {
        lines: true,
        hlines,
        diagonal: false,
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
        diagonal,
    };
    render(path, PLOT_SIZE, |root| {
        draw_xy(root, title, x_label, y_label, sets, x_scale, y_scale, &opts)
    })
}

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
    render(path, MAP_SIZE, |root| {
        draw_vector_map(
            root,
            title,
            sets,
            extent_px,
            reference_mas,
            reference_len_px,
        )
        .map(|_| ())
    })
}

fn draw_vector_map(
    root: &Area<'_>,
    title: &str,
    sets: &[(String, Vec<(f64, f64, f64, f64)>)],
    extent_px: f64,
    reference_mas: f64,
    reference_len_px: f64,
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
    configure_mesh(&mut chart, "x [pixel]", "y [pixel]")?;
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

    let labelled: Vec<(usize, &str)> = sets
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.0.is_empty())
        .map(|(i, s)| (i, s.0.as_str()))
        .collect();
    if !labelled.is_empty() {
        let mut entries = Vec::new();
        let mut x = xr.start - ox + 10;
        for &(i, label) in &labelled {
            let (tw, _) = area.estimate_text_size(label, &text)?;
            entries.push((i, label, x));
            x += 34 + tw as i32 + 18;
        }
        let box_left = xr.start - ox;
        let box_right = (x - 8).min(x_start - 90).max(box_left + 40);
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
    Ok(chart.plotting_area().dim_in_pixel())
}

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

    // Bins over [lo, hi] (widened when all values are equal).
    let mut nbins = ((n as f64).sqrt().ceil() as usize).clamp(1, 40);
    let (mut lo, mut hi) = match (vals.first(), vals.last()) {
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
    for &v in &vals {
        let k = (((v - lo) / width).floor().max(0.0) as usize).min(nbins - 1);
        counts[k] += 1;
    }
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

        // Empirical CDF as a step function over the whole x axis.
        let mut steps = vec![(x_axis.lo, 0.0)];
        for (i, &v) in vals.iter().enumerate() {
            steps.push((v, i as f64 / n as f64));
            steps.push((v, (i + 1) as f64 / n as f64));
        }
        steps.push((x_axis.hi, 1.0));
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
        draw_legend(&mut chart, legend_corner(&occupied))?;
    }
    Ok(())
}

/// Greyscale PNG of a row-major `nx × ny` array (row 0 at the bottom, astronomical convention), stretched
/// linearly from `low` (black) to `high` (white) with clipping, each pixel repeated `zoom × zoom` times
/// (nearest neighbour). NaN is drawn black. Empty images, `zoom == 0` and a data length other than
/// `nx * ny` are errors.
pub fn image_png(
    path: &Path,
    data: &[f32],
    nx: usize,
    ny: usize,
    low: f32,
    high: f32,
    zoom: usize,
) -> Result<(), PlotError> {
    if nx == 0 || ny == 0 || zoom == 0 {
        return Err(draw_error(
            path,
            format!("empty image ({nx} × {ny}, zoom {zoom})"),
        ));
    }
    if nx.checked_mul(ny) != Some(data.len()) {
        return Err(draw_error(
            path,
            format!("{} values for a {nx} × {ny} image", data.len()),
        ));
    }
    let size = nx
        .checked_mul(zoom)
        .zip(ny.checked_mul(zoom))
        .and_then(|(w, h)| Some((u32::try_from(w).ok()?, u32::try_from(h).ok()?)));
    let (w, h) = match size {
        Some((w, h)) if u64::from(w) * u64::from(h) <= MAX_IMAGE_PIXELS => (w, h),
        _ => {
            return Err(draw_error(
                path,
                format!("image too large ({nx} × {ny} at zoom {zoom})"),
            ));
        }
    };

    let span = high - low;
    let grey = |v: f32| -> u8 {
        if v.is_nan() {
            0
        } else if span > 0.0 && span.is_finite() {
            (((v - low) / span).clamp(0.0, 1.0) * 255.0).round() as u8
        } else if v >= low {
            255
        } else {
            0
        }
    };

    write_atomic(path, |tmp| {
        let mut backend = BitMapBackend::new(tmp, (w, h));
        let mut row = vec![0u8; 3 * w as usize];
        for r in 0..ny {
            // Output rows run top-down; data row 0 is the bottom of the picture.
            let src = &data[(ny - 1 - r) * nx..(ny - r) * nx];
            for (i, &v) in src.iter().enumerate() {
                let g = grey(v);
                row[3 * i * zoom..3 * (i + 1) * zoom].fill(g);
            }
            for z in 0..zoom {
                let y = i32::try_from(r * zoom + z)?;
                backend.blit_bitmap((0, y), (w, 1), &row)?;
            }
        }
        backend.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

    /// Removes a test directory when dropped, unless `JSIM_KEEP_PLOTS` is set (to look at the figures).
    struct TestDir(PathBuf);

    impl Drop for TestDir {
        fn drop(&mut self) {
            if std::env::var_os("JSIM_KEEP_PLOTS").is_none() {
                let _ = std::fs::remove_dir_all(&self.0);
            }
        }
    }

    impl std::ops::Deref for TestDir {
        type Target = Path;
        fn deref(&self) -> &Path {
            &self.0
        }
    }

    /// A fresh directory for one test.
    fn test_dir(name: &str) -> TestDir {
        let dir = std::env::temp_dir().join(format!("jsim-plot-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test dir");
        TestDir(dir)
    }

    fn assert_png(path: &Path, min_bytes: usize) {
        let bytes = std::fs::read(path).expect("read png");
        assert!(
            bytes.starts_with(&PNG_SIGNATURE),
            "{} is not a PNG",
            path.display()
        );
        assert!(
            bytes.len() > min_bytes,
            "{} has only {} bytes",
            path.display(),
            bytes.len()
        );
        assert!(!tmp_path(path).exists(), "temporary file left behind");
    }

    fn series(label: &str, x: &[f64], y: &[f64], yerr: Option<&[f64]>) -> Series {
        Series {
            label: label.into(),
            x: x.to_vec(),
            y: y.to_vec(),
            yerr: yerr.map(<[f64]>::to_vec),
        }
    }

    /// A deterministic pseudo-random sequence in [0, 1).
    fn lcg(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

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
    fn vector_map_plot_area_is_square() -> DynResult {
        ensure_font()?;
        let mut buffer = vec![0u8; 800 * 800 * 3];
        let root = BitMapBackend::with_buffer(&mut buffer, MAP_SIZE).into_drawing_area();
        let (w, h) = draw_vector_map(&root, "t", &[], 100.0, 1.0, 5.0)?;
        assert_eq!(w, h);
        assert!(w > 500, "plot side {w}");
        Ok(())
    }

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

    #[test]
    fn image_png_writes_and_rejects_empty() {
        let dir = test_dir("image");
        let (nx, ny) = (64, 48);
        let data: Vec<f32> = (0..nx * ny)
            .map(|i| {
                let (x, y) = ((i % nx) as f32 - 20.0, (i / nx) as f32 - 10.0);
                1000.0 * (-(x * x + y * y) / 30.0).exp() + (i % 7) as f32
            })
            .collect();
        let path = dir.join("stamp.png");
        image_png(&path, &data, nx, ny, 0.0, 300.0, 4).expect("image");
        assert_png(&path, 1000);

        assert!(image_png(&dir.join("empty.png"), &[], 0, 0, 0.0, 1.0, 1).is_err());
        assert!(image_png(&dir.join("zoom0.png"), &data, nx, ny, 0.0, 1.0, 0).is_err());
        assert!(image_png(&dir.join("short.png"), &data[1..], nx, ny, 0.0, 1.0, 1).is_err());
        assert!(
            image_png(
                &dir.join("huge.png"),
                &data,
                nx,
                ny,
                0.0,
                1.0,
                usize::MAX / 2
            )
            .is_err()
        );
        assert!(!dir.join("empty.png").exists());
        // Degenerate stretch and NaN pixels still produce a picture.
        let odd = vec![f32::NAN, 1.0, f32::INFINITY, -1.0];
        image_png(&dir.join("odd.png"), &odd, 2, 2, 1.0, 1.0, 1).expect("odd image");
        assert_png(&dir.join("odd.png"), 10);
    }

    #[test]
    fn odd_inputs_do_not_fail() {
        let dir = test_dir("odd");
        let nan = f64::NAN;
        let inf = f64::INFINITY;
        let s = [
            series("empty", &[], &[], None),
            series(
                "nan",
                &[nan, 1.0, 2.0, inf, 4.0],
                &[1.0, nan, 2.0, 3.0, -inf],
                Some(&[nan, 1.0]),
            ),
            series("mismatched", &[1.0, 2.0, 3.0], &[5.0], Some(&[])),
        ];
        line_plot(
            &dir.join("a.png"),
            "odd",
            "x",
            "y",
            &s,
            &[(nan, "nan".into())],
            Scale::Linear,
            Scale::Linear,
        )
        .expect("a");
        line_plot(
            &dir.join("b.png"),
            "odd log",
            "x",
            "y",
            &s,
            &[],
            Scale::Log,
            Scale::Log,
        )
        .expect("b");
        line_plot(
            &dir.join("c.png"),
            "nothing",
            "x",
            "y",
            &[],
            &[],
            Scale::Log,
            Scale::Linear,
        )
        .expect("c");
        let constant = [series(
            "flat",
            &[2.0, 2.0, 2.0],
            &[0.0, 0.0, 0.0],
            Some(&[0.0, 0.0, 0.0]),
        )];
        line_plot(
            &dir.join("d.png"),
            "constant",
            "x",
            "y",
            &constant,
            &[],
            Scale::Linear,
            Scale::Linear,
        )
        .expect("d");
        scatter(
            &dir.join("e.png"),
            "constant log",
            "x",
            "y",
            &constant,
            Scale::Log,
            Scale::Log,
            true,
        )
        .expect("e");
        scatter(
            &dir.join("f.png"),
            "nan",
            "x",
            "y",
            &s,
            Scale::Linear,
            Scale::Log,
            true,
        )
        .expect("f");
        let tiny = [series("tiny", &[1.0, 1.0 + 1e-14], &[1e-320, 1e300], None)];
        scatter(
            &dir.join("g.png"),
            "extremes",
            "x",
            "y",
            &tiny,
            Scale::Linear,
            Scale::Log,
            true,
        )
        .expect("g");

        histogram_cdf(&dir.join("h.png"), "empty", "x", &[], None).expect("h");
        histogram_cdf(
            &dir.join("i.png"),
            "empty with threshold",
            "x",
            &[nan, inf],
            Some((4.0, "4 mas".into())),
        )
        .expect("i");
        histogram_cdf(
            &dir.join("j.png"),
            "constant",
            "x",
            &[3.0; 10],
            Some((nan, String::new())),
        )
        .expect("j");
        histogram_cdf(
            &dir.join("k.png"),
            "single",
            "x",
            &[0.0],
            Some((0.0, String::new())),
        )
        .expect("k");

        let arrows = vec![
            (10.0, 10.0, 0.0, 0.0),
            (nan, 1.0, 1.0, 1.0),
            (50.0, 50.0, inf, 0.0),
            (-5.0, 3.0, 1.0, 1.0),
        ];
        vector_map(
            &dir.join("l.png"),
            "odd arrows",
            &[("a".into(), arrows.clone()), (String::new(), vec![])],
            100.0,
            0.0,
            nan,
        )
        .expect("l");
        vector_map(
            &dir.join("m.png"),
            "no extent",
            &[("a".into(), arrows)],
            nan,
            10.0,
            100.0,
        )
        .expect("m");
        vector_map(&dir.join("n.png"), "nothing", &[], 0.0, 10.0, 100.0).expect("n");
        for name in [
            "a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l", "m", "n",
        ] {
            assert_png(&dir.join(format!("{name}.png")), 1000);
        }
    }

    #[test]
    fn unwritable_path_is_an_error() {
        let dir = test_dir("unwritable");
        let blocker = dir.join("file");
        std::fs::write(&blocker, b"x").expect("write blocker");
        let path = blocker.join("sub").join("plot.png");
        let result = histogram_cdf(&path, "t", "x", &[1.0, 2.0], None);
        assert!(matches!(result, Err(PlotError::Draw { .. })));
    }

    #[test]
    fn ticks_are_sane() {
        let ticks = linear_ticks(0.0, 1.0, 5, false);
        assert_eq!(ticks.len(), 6);
        assert!(
            ticks
                .iter()
                .enumerate()
                .all(|(i, t)| (t - 0.2 * i as f64).abs() < 1e-12)
        );
        assert_eq!(linear_ticks(0.0, 3.0, 10, true), vec![0.0, 1.0, 2.0, 3.0]);
        assert_eq!(log_ticks(0.5, 2000.0, 10), vec![1.0, 10.0, 100.0, 1000.0]);
        assert_eq!(log_ticks(1.5, 8.0, 10), vec![2.0, 4.0, 6.0, 8.0]);
        assert_eq!(log_ticks(0.45, 10.5, 10), vec![0.5, 1.0, 2.0, 5.0, 10.0]);
        assert!(log_ticks(2.1, 2.9, 10).len() >= 2);
        assert_eq!(fmt_num(0.30000000000000004), "0.3");
        assert_eq!(
            (nice_floor(1.41), nice_floor(0.4), nice_floor(5.0)),
            (1.0, 0.2, 5.0)
        );
        assert_eq!(
            (nice_ceil(1.41), nice_ceil(0.04), nice_ceil(7.0)),
            (2.0, 0.05, 10.0)
        );
        assert_eq!(fmt_num(1e-5), "1e-5");
        assert_eq!(fmt_num(2500.0), "2500");
        let small = Axis::linear(-0.0001, 0.0013);
        let labels: Vec<String> = linear_ticks(small.lo, small.hi, 10, false)
            .into_iter()
            .map(|v| tick_label(&small, v))
            .collect();
        assert_eq!(
            labels,
            [
                "0", "0.0002", "0.0004", "0.0006", "0.0008", "0.001", "0.0012"
            ]
        );
        let a = Axis::fit([5.0, 5.0], Scale::Linear);
        assert!(a.hi > a.lo);
        let l = Axis::fit([-1.0, 0.0, 10.0, 1000.0], Scale::Log);
        assert!(l.lo > 0.0 && l.lo < 10.0 && l.hi > 1000.0);
    }
}
