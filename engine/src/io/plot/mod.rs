//! PNG figures: accuracy curves, trade-off scatter plots, deviation vector maps, histograms with the
//! empirical CDF and greyscale image previews.
//!
//! Everything is drawn with `plotters` on a bitmap using the embedded DejaVu Sans font (registered once as
//! "sans-serif"). Every figure is drawn to a temporary `.png` sibling and renamed into place
//! ([`super::write_atomic_with`]), so an interrupted run never leaves a half-written PNG. Odd input
//! (NaN/inf, empty series, constant values) never panics: such points are skipped and degenerate axis
//! ranges are widened.
//!
//! Shared here: the font, the atomic PNG output, colours, the axis (linear or log, with its ticks),
//! markers, legends and the mesh. One file per kind of figure: `line` ([`line_plot`], [`scatter`]),
//! `vectors` ([`vector_map`]), `histogram` ([`histogram_cdf`]), `image` ([`image_png`]) and `map`
//! ([`count_map`]).

mod histogram;
mod image;
mod line;
mod map;
mod vectors;

pub use histogram::histogram_cdf;
pub use image::image_png;
pub use line::{line_plot, line_plot_with_guides, scatter};
pub use map::{CountGrid, count_map};
pub use vectors::{vector_map, vector_map_on_axes};

use super::IoError;
use std::error::Error;
use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("cannot draw {path}: {message}")]
    Draw { path: String, message: String },
}

impl From<IoError> for PlotError {
    /// A failure of the atomic write around a figure (the rename into place), as a [`PlotError`].
    fn from(e: IoError) -> Self {
        match e {
            IoError::Plot(p) => p,
            IoError::Io { path, reason } => draw_error(&path, reason),
            IoError::Fits { path, message } | IoError::Format { path, message } => {
                draw_error(&path, message)
            }
        }
    }
}

/// One curve: points joined by lines with markers; optional symmetric y error bars.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// Error-bar lengths: both ways, or above the point when `yerr_below` is given.
    pub yerr: Option<Vec<f64>>,
    /// Error-bar lengths below the point, for asymmetric bars (a confidence interval about a measured value).
    pub yerr_below: Option<Vec<f64>>,
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
static FONT_BYTES: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

/// Size of the line/scatter/histogram figures.
const PLOT_SIZE: (u32, u32) = (900, 600);

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

/// Write the figure at `path` through `write` ([`super::write_atomic_with`]: a temporary `.png` sibling,
/// renamed into place, removed on failure), creating the directory first.
fn write_png(path: &Path, write: impl FnOnce(&Path) -> DynResult) -> Result<(), PlotError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| draw_error(path, e))?;
    }
    super::write_atomic_with(path, |tmp| write(tmp).map_err(|e| draw_error(path, e)))
}

/// Draw a figure of `size` pixels on a white background and write it atomically to `path`.
fn render(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> DynResult,
) -> Result<(), PlotError> {
    ensure_font().map_err(|e| draw_error(path, e))?;
    write_png(path, |tmp| {
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

/// The marker (0–4) of series `i`: it advances once more per pass through the palette, so series i and i + 10
/// (the same colour) differ in shape — 50 series have distinct colour-and-shape pairs.
fn marker_index(i: usize) -> usize {
    (i + i / PALETTE.len()) % 5
}

/// Marker outline (pixel offsets) for series `i`: circle, square, triangle, diamond, inverted triangle.
fn marker_shape(i: usize, r: f64) -> Vec<(i32, i32)> {
    let polygon = |pts: &[(f64, f64)]| {
        pts.iter()
            .map(|&(x, y)| ((x * r).round() as i32, (y * r).round() as i32))
            .collect()
    };
    match marker_index(i) {
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

/// Where the legend box of `entries` lines overlaps the fewest of the given points (fractions of the plot, y
/// up): the box's size estimated from its lines (≈ 5.5 % of the plot's height each, a third of its width).
fn legend_corner(points: &[(f64, f64)], entries: usize) -> SeriesLabelPosition {
    let h = (0.05 + 0.055 * entries as f64).clamp(0.2, 0.9);
    let w = 0.35;
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
                let in_x = if right { fx > 1.0 - w } else { fx < w };
                let in_y = if upper { fy > 1.0 - h } else { fy < h };
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
use dashed_glyph;

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

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn fifty_series_have_distinct_colour_and_marker_pairs() {
        let pairs: std::collections::HashSet<(usize, usize)> = (0..50)
            .map(|i| (i % PALETTE.len(), marker_index(i)))
            .collect();
        assert_eq!(pairs.len(), 50);
    }

    pub(super) const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

    /// Removes a test directory when dropped, unless `JSIM_KEEP_PLOTS` is set (to look at the figures).
    pub(super) struct TestDir(PathBuf);

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
    pub(super) fn test_dir(name: &str) -> TestDir {
        let dir = std::env::temp_dir().join(format!("jsim-plot-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test dir");
        TestDir(dir)
    }

    pub(super) fn assert_png(path: &Path, min_bytes: usize) {
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
        let name = path
            .file_name()
            .expect("file name")
            .to_string_lossy()
            .to_string();
        let dir = path.parent().expect("directory");
        let leftovers: Vec<String> = std::fs::read_dir(dir)
            .expect("list directory")
            .map(|e| e.expect("entry").file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with(&name) && n.contains(".tmp"))
            .collect();
        assert!(
            leftovers.is_empty(),
            "temporary file left behind: {leftovers:?}"
        );
    }

    pub(super) fn series(label: &str, x: &[f64], y: &[f64], yerr: Option<&[f64]>) -> Series {
        Series {
            label: label.into(),
            x: x.to_vec(),
            y: y.to_vec(),
            yerr: yerr.map(<[f64]>::to_vec),
            yerr_below: None,
        }
    }

    /// A deterministic pseudo-random sequence in [0, 1).
    pub(super) fn lcg(n: usize, seed: u64) -> Vec<f64> {
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
    fn odd_inputs_to_line_plots_and_scatters_do_not_fail() {
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

        for name in ["a", "b", "c", "d", "e", "f", "g"] {
            assert_png(&dir.join(format!("{name}.png")), 1000);
        }
    }

    #[test]
    fn odd_inputs_to_histograms_and_vector_maps_do_not_fail() {
        let dir = test_dir("odd-hist");
        let nan = f64::NAN;
        let inf = f64::INFINITY;
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
        for name in ["h", "i", "j", "k", "l", "m", "n"] {
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
