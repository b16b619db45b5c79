//! `jsim report`: the fraction of exposures meeting a threshold per grid point and countermeasure, with
//! 95 % Wilson intervals (`report.csv`), their distributions and the fraction against a swept parameter
//! (`report/*.png`), and the same as a text table.

use super::error::SweepError;
use super::record::{float_cell, parse_line, read_record, render_line};
use crate::io::{self, plot};
use crate::numerics::stats;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// z of a two-sided 95 % interval.
pub const Z95: f64 = 1.959_963_984_540_054;
/// Accuracy columns `jsim report` can threshold.
pub const METRICS: [&str; 3] = ["accuracy_mas", "accuracy_x_mas", "accuracy_y_mas"];

/// Options of [`report`].
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// Threshold in mas (default: the sweep's `threshold_mas`).
    pub threshold_mas: Option<f64>,
    /// Which accuracy column is thresholded (one of [`METRICS`]).
    pub metric: String,
    /// Grid field on the x axis of the fraction plot (default: the first numeric one with several values).
    pub x: Option<String>,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            threshold_mas: None,
            metric: "accuracy_mas".into(),
            x: None,
        }
    }
}

/// One (grid point, countermeasure) line of the report.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportRow {
    pub point: usize,
    pub values: Vec<String>,
    pub countermeasure: String,
    /// Exposures.
    pub n: usize,
    /// Exposures meeting the threshold.
    pub k: usize,
    /// Exposures whose analysis failed (counted as not meeting it).
    pub failed: usize,
    pub fraction: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    pub mean_mas: f64,
    pub median_mas: f64,
    pub q90_mas: f64,
    pub crlb_median_mas: f64,
    pub predicted_mean_mas: f64,
    /// Fraction of exposures the instant predictor expects to meet the threshold.
    pub predicted_fraction: f64,
}

/// The outcome of [`report`].
#[derive(Debug, Clone)]
pub struct ReportSummary {
    pub rows: Vec<ReportRow>,
    pub threshold_mas: f64,
    pub metric: String,
    /// Grid fields, in column order.
    pub fields: Vec<String>,
    /// The x axis of the fraction plot (`None`: grid point index).
    pub x_field: Option<String>,
    pub files: Vec<PathBuf>,
}

fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// (point, countermeasure index) → (metric values, crlb, predicted) of every exposure.
type Groups = BTreeMap<(usize, usize), (Vec<f64>, Vec<f64>, Vec<f64>)>;

/// Fractions meeting the threshold per grid point and countermeasure (95 % Wilson intervals), written to
/// `dir/report.csv`, with a histogram + CDF per point and countermeasure and the fraction against the swept
/// parameter in `dir/report/`.
pub fn report(dir: &Path, opts: &ReportOptions) -> Result<ReportSummary, SweepError> {
    let rec = read_record(dir)?;
    if !METRICS.contains(&opts.metric.as_str()) {
        return Err(SweepError::Invalid(format!(
            "--metric {}: expected one of {}",
            opts.metric,
            METRICS.join(", ")
        )));
    }
    let threshold = opts.threshold_mas.unwrap_or(rec.threshold_mas);
    if !(threshold > 0.0) || !threshold.is_finite() {
        return Err(SweepError::Invalid(format!(
            "--threshold-mas {threshold}: must be a finite number > 0"
        )));
    }
    let fields: Vec<String> = rec.grid.iter().map(|p| p.field.clone()).collect();
    let x_index = x_axis(&rec, &fields, opts)?;
    let groups = read_groups(dir, &rec, opts)?;
    let rows = report_rows(&rec, &groups, threshold);
    let csv = report_csv(&fields, &rows, opts, threshold);
    let plots = dir.join("report");
    io::ensure_dir(&plots)?;
    let mut files = plot_distributions(&plots, &rec, &groups, opts, threshold)?;
    files.push(plot_fractions(
        &plots, &rec, &fields, &rows, x_index, opts, threshold,
    )?);
    let report_csv = dir.join(crate::io::products::files::REPORT_CSV);
    io::write_atomic(&report_csv, csv.as_bytes())?;
    files.insert(0, report_csv);
    Ok(ReportSummary {
        rows,
        threshold_mas: threshold,
        metric: opts.metric.clone(),
        fields,
        x_field: x_index.map(|k| rec.grid[k].field.clone()),
        files,
    })
}

/// The grid field on the x axis of the fraction plot: `--x`, which must be a numeric grid field, or the first
/// numeric one with several values; `None`: the grid point's index.
fn x_axis(
    rec: &super::record::Record,
    fields: &[String],
    opts: &ReportOptions,
) -> Result<Option<usize>, SweepError> {
    let numeric = |k: usize| {
        rec.grid[k]
            .values
            .iter()
            .all(|v| v.trim().parse::<f64>().is_ok_and(|x| x.is_finite()))
    };
    Ok(match &opts.x {
        Some(x) => {
            let k = fields.iter().position(|f| f == x).ok_or_else(|| {
                SweepError::Invalid(format!(
                    "--x {x}: not a grid parameter of this sweep ({})",
                    fields.join(", ")
                ))
            })?;
            if !numeric(k) {
                return Err(SweepError::Invalid(format!(
                    "--x {x}: its values ({}) are not numbers",
                    rec.grid[k].values.join(", ")
                )));
            }
            Some(k)
        }
        None => (0..fields.len()).find(|&k| numeric(k) && rec.grid[k].values.len() > 1),
    })
}

/// Every exposure's metric, bound and prediction from `merged.csv`, grouped by point and countermeasure.
fn read_groups(
    dir: &Path,
    rec: &super::record::Record,
    opts: &ReportOptions,
) -> Result<Groups, SweepError> {
    let merged = dir.join(crate::io::products::files::MERGED_CSV);
    let text = std::fs::read_to_string(&merged).map_err(|e| {
        SweepError::Invalid(format!(
            "cannot read {}: {e}; run `jsim merge {}` first",
            merged.display(),
            dir.display()
        ))
    })?;
    let header = rec.header(false);
    let mut lines = text.lines();
    if lines.next().and_then(parse_line).as_deref() != Some(&header[..]) {
        return Err(SweepError::Invalid(format!(
            "{} does not match this sweep's columns: rerun `jsim merge {}`",
            merged.display(),
            dir.display()
        )));
    }
    let c_point = rec.col("point");
    let c_cm = rec.col("countermeasure");
    let c_metric = rec.col(&opts.metric);
    let c_crlb = rec.col("crlb_mas");
    let c_pred = rec.col("predicted_mas");
    // (point, countermeasure index) → (metric values, crlb, predicted)
    let mut groups = Groups::new();
    for (k, l) in lines.enumerate() {
        let cells = parse_line(l)
            .filter(|c| c.len() == header.len())
            .ok_or_else(|| {
                SweepError::Invalid(format!(
                    "{} line {}: malformed; rerun `jsim merge`",
                    merged.display(),
                    k + 2
                ))
            })?;
        let point: usize = cells[c_point].parse().map_err(|_| {
            SweepError::Invalid(format!("{} line {}: bad point", merged.display(), k + 2))
        })?;
        let Some(ci) = rec.countermeasures.iter().position(|c| c == &cells[c_cm]) else {
            continue;
        };
        let num = |c: usize| cells[c].parse::<f64>().unwrap_or(f64::NAN);
        let g = groups.entry((point, ci)).or_default();
        g.0.push(num(c_metric));
        g.1.push(num(c_crlb));
        g.2.push(num(c_pred));
    }
    Ok(groups)
}

/// One row per grid point and countermeasure: the fraction meeting `threshold` with its Wilson interval, the
/// distribution's mean, median and 90th percentile, the bound and the prediction.
fn report_rows(rec: &super::record::Record, groups: &Groups, threshold: f64) -> Vec<ReportRow> {
    let mut rows = Vec::new();
    for p in 0..rec.points {
        for (ci, cm) in rec.countermeasures.iter().enumerate() {
            let (vals, crlb, pred) = groups.get(&(p, ci)).cloned().unwrap_or_default();
            let finite: Vec<f64> = vals.iter().copied().filter(|v| v.is_finite()).collect();
            let n = vals.len();
            let k = finite.iter().filter(|&&v| v <= threshold).count();
            let (lo, hi) = stats::wilson_interval(k, n, Z95);
            let crlb_f: Vec<f64> = crlb.into_iter().filter(|v| v.is_finite()).collect();
            let pred_f: Vec<f64> = pred.into_iter().filter(|v| v.is_finite()).collect();
            let nan_if_empty = |v: &[f64], x: f64| if v.is_empty() { f64::NAN } else { x };
            rows.push(ReportRow {
                point: p,
                values: rec.point_values[p].clone(),
                countermeasure: cm.clone(),
                n,
                k,
                failed: n - finite.len(),
                fraction: if n > 0 { k as f64 / n as f64 } else { f64::NAN },
                ci_low: lo,
                ci_high: hi,
                mean_mas: nan_if_empty(&finite, stats::mean(&finite)),
                median_mas: nan_if_empty(&finite, stats::median(&finite)),
                q90_mas: nan_if_empty(&finite, stats::quantile(&finite, 0.9)),
                crlb_median_mas: nan_if_empty(&crlb_f, stats::median(&crlb_f)),
                predicted_mean_mas: nan_if_empty(&pred_f, stats::mean(&pred_f)),
                predicted_fraction: if pred_f.is_empty() {
                    f64::NAN
                } else {
                    pred_f.iter().filter(|&&v| v <= threshold).count() as f64 / pred_f.len() as f64
                },
            });
        }
    }

    rows
}

/// `report.csv`'s text: the grid's values, the countermeasure, the metric and threshold, then the row's numbers.
fn report_csv(
    fields: &[String],
    rows: &[ReportRow],
    opts: &ReportOptions,
    threshold: f64,
) -> String {
    let mut h: Vec<String> = vec!["point".into()];
    h.extend(fields.iter().cloned());
    for c in [
        "countermeasure",
        "metric",
        "threshold_mas",
        "n",
        "k",
        "n_failed",
        "fraction",
        "ci95_low",
        "ci95_high",
        "mean_mas",
        "median_mas",
        "q90_mas",
        "crlb_median_mas",
        "predicted_mean_mas",
        "predicted_fraction",
    ] {
        h.push(c.into());
    }
    let mut csv = render_line(&h);
    csv.push('\n');
    for r in rows {
        let mut c = vec![r.point.to_string()];
        c.extend(r.values.iter().cloned());
        c.push(r.countermeasure.clone());
        c.push(opts.metric.clone());
        c.push(float_cell(threshold));
        c.push(r.n.to_string());
        c.push(r.k.to_string());
        c.push(r.failed.to_string());
        for v in [
            r.fraction,
            r.ci_low,
            r.ci_high,
            r.mean_mas,
            r.median_mas,
            r.q90_mas,
            r.crlb_median_mas,
            r.predicted_mean_mas,
            r.predicted_fraction,
        ] {
            c.push(float_cell(v));
        }
        csv.push_str(&render_line(&c));
        csv.push('\n');
    }
    csv
}

/// A histogram + CDF of the metric per grid point and countermeasure (`report/dist_p<point>_<countermeasure>.png`).
fn plot_distributions(
    plots: &Path,
    rec: &super::record::Record,
    groups: &Groups,
    opts: &ReportOptions,
    threshold: f64,
) -> Result<Vec<PathBuf>, SweepError> {
    let mut files = Vec::new();
    for p in 0..rec.points {
        for (ci, cm) in rec.countermeasures.iter().enumerate() {
            let vals = groups
                .get(&(p, ci))
                .map(|g| g.0.clone())
                .unwrap_or_default();
            let path = plots.join(format!("dist_p{p:03}_{}.png", slug(cm)));
            let desc = rec
                .grid
                .iter()
                .zip(&rec.point_values[p])
                .map(|(g, v)| format!("{}={v}", g.field))
                .collect::<Vec<_>>()
                .join(", ");
            plot::histogram_cdf(
                &path,
                &format!("point {p}: {desc}; {cm} (n = {})", vals.len()),
                &format!("{} [mas]", opts.metric),
                &vals,
                Some((threshold, format!("{threshold} mas"))),
            )?;
            files.push(path);
        }
    }
    Ok(files)
}

/// The fraction meeting the threshold against the swept parameter (`report/fraction.png`), one series per
/// countermeasure and combination of the other grid fields, side by side where they share an x.
fn plot_fractions(
    plots: &Path,
    rec: &super::record::Record,
    fields: &[String],
    rows: &[ReportRow],
    x_index: Option<usize>,
    opts: &ReportOptions,
    threshold: f64,
) -> Result<PathBuf, SweepError> {
    let mut series_keys: Vec<(Vec<String>, usize)> = Vec::new();
    for r in rows {
        let others: Vec<String> = r
            .values
            .iter()
            .enumerate()
            .filter(|(k, _)| Some(*k) != x_index)
            .map(|(k, v)| format!("{}={v}", fields[k]))
            .collect();
        let ci = rec
            .countermeasures
            .iter()
            .position(|c| c == &r.countermeasure)
            .unwrap_or(0);
        if !series_keys.contains(&(others.clone(), ci)) {
            series_keys.push((others, ci));
        }
    }
    // series sharing an x are offset by ±1 % of the x range so that their bars stay visible
    let xs: Vec<f64> = rows
        .iter()
        .map(|r| match x_index {
            Some(k) => r.values[k].trim().parse().unwrap_or(f64::NAN),
            None => r.point as f64,
        })
        .filter(|v| v.is_finite())
        .collect();
    let span = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - xs.iter().copied().fold(f64::INFINITY, f64::min);
    // one grid point: nothing varies along x, so the series stand side by side one unit apart; grid points
    // without a numeric x (e.g. readout orders) are categories one unit apart, their series side by side
    // within ±0.4 of each
    let one_point = !(span > 0.0);
    let dodge = match (one_point, x_index) {
        (true, _) => 1.0,
        (false, None) => 0.8 / series_keys.len().max(1) as f64,
        (false, Some(_)) => 0.01 * span,
    };
    let categories = {
        let mut seen: Vec<(usize, String)> = Vec::new();
        for r in rows {
            if !seen.iter().any(|(p, _)| *p == r.point) {
                let what: Vec<String> = r
                    .values
                    .iter()
                    .enumerate()
                    .map(|(k, v)| format!("{}={v}", fields[k]))
                    .collect();
                seen.push((r.point, what.join(", ")));
            }
        }
        seen.iter()
            .map(|(p, w)| format!("{p}: {w}"))
            .collect::<Vec<_>>()
            .join("; ")
    };
    let n_series = series_keys.len() as f64;
    let series: Vec<plot::Series> = series_keys
        .iter()
        .enumerate()
        .map(|(si, (others, ci))| {
            let shift = (si as f64 - (n_series - 1.0) / 2.0) * dodge;
            let pts: Vec<&ReportRow> = rows
                .iter()
                .filter(|r| {
                    r.countermeasure == rec.countermeasures[*ci]
                        && &r
                            .values
                            .iter()
                            .enumerate()
                            .filter(|(k, _)| Some(*k) != x_index)
                            .map(|(k, v)| format!("{}={v}", fields[k]))
                            .collect::<Vec<_>>()
                            == others
                })
                .collect();
            let x: Vec<f64> = pts
                .iter()
                .map(|r| match x_index {
                    Some(k) => r.values[k].trim().parse().unwrap_or(f64::NAN),
                    None => r.point as f64,
                } + shift)
                .collect();
            let mut label = rec.countermeasures[*ci].clone();
            if !others.is_empty() {
                label = format!("{label}, {}", others.join(", "));
            }
            plot::Series {
                label,
                x,
                // the measured fraction k/n with its (asymmetric) 95 % Wilson interval
                y: pts.iter().map(|r| r.fraction).collect(),
                yerr: Some(pts.iter().map(|r| r.ci_high - r.fraction).collect()),
                yerr_below: Some(pts.iter().map(|r| r.fraction - r.ci_low).collect()),
            }
        })
        .collect();
    let frac_path = plots.join("fraction.png");
    plot::line_plot(
        &frac_path,
        &format!(
            "Exposures with {} ≤ {threshold} mas: 95 % Wilson intervals",
            opts.metric
        ),
        &match (x_index, one_point) {
            (_, true) => "series side by side (one grid point; see the legend)".to_string(),
            (Some(k), false) => fields[k].clone(),
            (None, false) => format!("grid point ({categories})"),
        },
        "fraction of exposures (measured, 95 % Wilson interval)",
        &series,
        &[],
        plot::Scale::Linear,
        plot::Scale::Linear,
    )?;
    Ok(frac_path)
}

/// The report as a text table (what `jsim report` prints).
pub fn render_report(s: &ReportSummary) -> String {
    let mut out = String::new();
    let mut widths: Vec<usize> = s.fields.iter().map(|f| f.len().max(6)).collect();
    for r in &s.rows {
        for (k, v) in r.values.iter().enumerate() {
            widths[k] = widths[k].max(v.len());
        }
    }
    let cmw = s
        .rows
        .iter()
        .map(|r| r.countermeasure.len())
        .max()
        .unwrap_or(0)
        .max(14);
    let _ = write!(out, "{:>5}", "point");
    for (k, f) in s.fields.iter().enumerate() {
        let _ = write!(out, "  {:<w$}", f, w = widths[k]);
    }
    let _ = writeln!(
        out,
        "  {:<cmw$} {:>7} {:>8}  {:<17} {:>8} {:>8} {:>9}",
        "countermeasure", "n", "fraction", "95 % Wilson", "median", "p90", "predicted"
    );
    for r in &s.rows {
        let _ = write!(out, "{:>5}", r.point);
        for (k, v) in r.values.iter().enumerate() {
            let _ = write!(out, "  {:<w$}", v, w = widths[k]);
        }
        let _ = writeln!(
            out,
            "  {:<cmw$} {:>7} {:>8.3}  [{:.3}, {:.3}]    {:>8.2} {:>8.2} {:>9.3}",
            r.countermeasure,
            format!("{}/{}", r.k, r.n),
            r.fraction,
            r.ci_low,
            r.ci_high,
            r.median_mas,
            r.q90_mas,
            r.predicted_fraction,
        );
    }
    let _ = writeln!(
        out,
        "fraction: exposures with {} ≤ {} mas (analysis failures count as misses); median/p90 in mas; predicted: the fraction the instant predictor expects",
        s.metric, s.threshold_mas
    );
    out
}
