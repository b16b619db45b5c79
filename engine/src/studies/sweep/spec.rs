//! The sweep file: parsing and validation into a [`Sweep`] (grid points, countermeasure plan, the sweep
//! hash), each work unit's seed and configuration, and the output directory the sweep claims.

use super::error::SweepError;
use super::record::{self, FORMAT, Record, RecordParam, RecordTelemetry, read_record, render_line};
use crate::analysis::countermeasures::{DEFAULT_CATALOGUE_ERROR_MAS, Plan, TelemetryQuality};
use crate::config::{Config, ConfigError};
use crate::digest;
use crate::io;
use crate::rng::{self, Stream};
use serde::Deserialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    name: Option<String>,
    seed: u64,
    exposures: i64,
    stare_exposures: Option<i64>,
    countermeasures: Option<Vec<String>>,
    threshold_mas: Option<f64>,
    common_random_numbers: Option<bool>,
    telemetry: Option<TelemetryFile>,
    instrument: Option<crate::config::InstrumentModel>,
    base: Option<toml::Value>,
    set: Option<toml::Table>,
    grid: Option<toml::Table>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct TelemetryFile {
    noise_mas: Option<f64>,
    rate_hz: Option<f64>,
    latency_s: Option<f64>,
    correlated_mas: Option<f64>,
    correlation_time_s: Option<f64>,
    reference_error_mas: Option<f64>,
}

/// One swept field and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Dotted config path (`ace.sigma_mas`).
    pub field: String,
    /// Each value as TOML (what [`Config::with_override`] receives).
    pub toml: Vec<String>,
    /// Each value as written in the CSV columns (strings unquoted).
    pub display: Vec<String>,
}

/// One grid point.
#[derive(Debug, Clone)]
pub struct Point {
    pub index: usize,
    /// Display values, one per [`Param`].
    pub values: Vec<String>,
    /// The point's configuration (`fidelity.images = 1`; the seed is set per unit).
    pub config: Config,
}

/// A parsed, validated sweep.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub name: String,
    pub source: PathBuf,
    pub seed: u64,
    pub exposures: usize,
    /// Consecutive exposures per stare (one work unit, one ACE series; the stack of a stack-referenced
    /// plate model): `exposures` is a multiple of it.
    pub stare_exposures: usize,
    pub countermeasures: Vec<String>,
    pub threshold_mas: f64,
    pub common_random_numbers: bool,
    pub plan: Plan,
    /// The telemetry quality and plate reference error of the plan (recorded in `sweep.json`).
    pub telemetry: TelemetryQuality,
    pub reference_error_mas: f64,
    /// The base configuration after `[set]`.
    pub base: Config,
    /// Swept fields, sorted by name.
    pub params: Vec<Param>,
    pub points: Vec<Point>,
    /// 16 hex digits identifying the sweep (see the module docs for what it covers).
    pub hash: String,
}

impl SweepFile {
    /// Exposures per point, exposures per stare and the threshold, checked.
    fn sizes(&self) -> Result<(usize, usize, f64), String> {
        if self.exposures < 1 {
            return Err(format!(
                "`exposures` = {}: must be ≥ 1 (exposures per grid point)",
                self.exposures
            ));
        }
        let exposures = self.exposures as usize;
        if exposures > 100_000_000 {
            return Err(format!("`exposures` = {exposures}: must be ≤ 1e8"));
        }
        let stare_exposures = self.stare_exposures.unwrap_or(1);
        if !(1..=1000).contains(&stare_exposures)
            || !exposures.is_multiple_of(stare_exposures as usize)
        {
            return Err(format!(
                "`stare_exposures` = {stare_exposures}: must be in 1..=1000 and divide `exposures` = \
                 {exposures}"
            ));
        }
        let threshold_mas = self.threshold_mas.unwrap_or(4.0);
        if !(threshold_mas > 0.0) || !threshold_mas.is_finite() {
            return Err(format!(
                "`threshold_mas` = {threshold_mas}: must be a finite number > 0"
            ));
        }
        Ok((exposures, stare_exposures as usize, threshold_mas))
    }

    /// The countermeasures: one plan, validated where every plan is, with its telemetry quality and the
    /// catalogue's error.
    fn plan(&self, stare_exposures: usize) -> Result<(Plan, TelemetryQuality, f64), String> {
        let names = self
            .countermeasures
            .clone()
            .unwrap_or_else(|| vec!["none".into()]);
        let none = TelemetryFile::default();
        let t = self.telemetry.as_ref().unwrap_or(&none);
        let d = TelemetryQuality::DEFAULT;
        let telemetry = TelemetryQuality {
            noise_mas: t.noise_mas.unwrap_or(d.noise_mas),
            rate_hz: t.rate_hz.unwrap_or(d.rate_hz),
            latency_s: t.latency_s.unwrap_or(d.latency_s),
            correlated_mas: t.correlated_mas.unwrap_or(d.correlated_mas),
            correlation_time_s: t.correlation_time_s.unwrap_or(d.correlation_time_s),
        };
        let reference_error_mas = t.reference_error_mas.unwrap_or(DEFAULT_CATALOGUE_ERROR_MAS);
        let plan = Plan::parse(&names, telemetry, reference_error_mas)
            .map_err(|e| format!("`countermeasures`/`[telemetry]`: {e}"))?;
        if plan.needs_stare() && stare_exposures < 2 {
            return Err(format!(
                "`countermeasures` reference a plate model to the stare's stack: `stare_exposures` = \
                 {stare_exposures} must be ≥ 2 (or name the reference: @catalogue, @oracle)"
            ));
        }
        Ok((plan, telemetry, reference_error_mas))
    }

    /// The base configuration (a file beside the sweep file, a `[base]` table, or the default), with the
    /// instrument (as built by default; "design" zeroes every deviation) and then `[set]` applied.
    fn base_config(&self, base_dir: &Path) -> Result<Config, String> {
        let mut base = match &self.base {
            None => Config::default(),
            Some(toml::Value::String(p)) => {
                let p = Path::new(p);
                let full = if p.is_absolute() {
                    p.to_path_buf()
                } else {
                    base_dir.join(p)
                };
                Config::load(&full).map_err(|e| format!("base config: {e}"))?
            }
            Some(toml::Value::Table(t)) => {
                let text = toml::to_string(t).map_err(|e| format!("[base]: {e}"))?;
                Config::from_toml_str(&text)
                    .map_err(|e| format!("[base]: {}", config_error_text(&e)))?
            }
            Some(_) => {
                return Err("`base` must be a config file path (string) or a [base] table".into());
            }
        };
        if let Some(instrument) = self.instrument {
            base.as_built = base.as_built.for_instrument(instrument);
        }
        if let Some(set) = &self.set {
            let mut leaves = Vec::new();
            flatten("", set, &mut leaves);
            for (field, v) in leaves {
                base = base
                    .with_override(&field, &v.to_string())
                    .map_err(|e| format!("[set] `{field}`: {}", config_error_text(&e)))?;
            }
        }
        Ok(base)
    }
}

/// The grid's parameters, sorted by field: each a non-empty list of distinct values, never the seed or the
/// images per unit (every unit sets those).
fn grid_params(grid: Option<&toml::Table>) -> Result<Vec<Param>, String> {
    let mut leaves = Vec::new();
    flatten("", grid.unwrap_or(&toml::Table::new()), &mut leaves);
    if leaves.is_empty() {
        return Err(
            "the grid is empty: give at least one parameter, e.g. [grid] \"ace.sigma_mas\" = [150, 300]"
                .into(),
        );
    }
    leaves.sort_by(|a, b| a.0.cmp(&b.0));
    let mut params = Vec::new();
    for (field, v) in leaves {
        let toml::Value::Array(values) = v else {
            return Err(format!(
                "grid parameter `{field}` must be a list of values, e.g. `{field} = [a, b]`"
            ));
        };
        if values.is_empty() {
            return Err(format!("grid parameter `{field}` has no values"));
        }
        if field == "seed" || field == "fidelity.images" {
            return Err(format!(
                "grid parameter `{field}` cannot be swept: every unit sets it (the seed from the sweep seed and the unit index, one image per unit); use `exposures` and `seed`"
            ));
        }
        let display: Vec<String> = values.iter().map(display_value).collect();
        for (k, d) in display.iter().enumerate() {
            if display[..k].contains(d) {
                return Err(format!(
                    "grid parameter `{field}` lists the value {d} twice"
                ));
            }
        }
        params.push(Param {
            field,
            toml: values.iter().map(|v| v.to_string()).collect(),
            display,
        });
    }
    Ok(params)
}

/// Every point of the grid (the first parameter slowest), its configuration `base` with the point's values
/// and `stare_exposures` images, validated.
fn grid_points(
    base: &Config,
    params: &[Param],
    stare_exposures: usize,
    source: &Path,
) -> Result<Vec<Point>, SweepError> {
    let n_points: usize = params.iter().map(|p| p.toml.len()).product();
    if n_points > 1_000_000 {
        return Err(SweepError::File {
            path: source.to_path_buf(),
            message: format!("the grid has {n_points} points: at most 1e6"),
        });
    }
    let mut points = Vec::with_capacity(n_points);
    for index in 0..n_points {
        let mut rem = index;
        let mut idx = vec![0; params.len()];
        for (k, p) in params.iter().enumerate().rev() {
            idx[k] = rem % p.toml.len();
            rem /= p.toml.len();
        }
        let mut cfg = base.clone();
        for (k, p) in params.iter().enumerate() {
            cfg = cfg
                .with_override(&p.field, &p.toml[idx[k]])
                .map_err(|e| SweepError::Grid {
                    path: source.to_path_buf(),
                    field: p.field.clone(),
                    message: config_error_text(&e).replace('\n', " ").trim().to_string(),
                })?;
        }
        cfg.fidelity.images = stare_exposures;
        cfg.validate().map_err(|e| SweepError::File {
            path: source.to_path_buf(),
            message: format!("grid point {index} ({}): {e}", describe(params, &idx)),
        })?;
        points.push(Point {
            index,
            values: params
                .iter()
                .zip(&idx)
                .map(|(p, &i)| p.display[i].clone())
                .collect(),
            config: cfg,
        });
    }
    Ok(points)
}

/// Flatten nested TOML tables into dotted paths; `leaf` decides where to stop.
fn flatten(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
    for (k, v) in t {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(sub) => flatten(&path, sub, out),
            other => out.push((path, other.clone())),
        }
    }
}

/// How a grid value appears in the CSV: strings bare, numbers as Rust prints them, others as inline TOML.
fn display_value(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => f.to_string(),
        toml::Value::Boolean(b) => b.to_string(),
        other => other.to_string(),
    }
}

fn config_error_text(e: &ConfigError) -> String {
    match e {
        ConfigError::Parse { message, .. } => message.trim().to_string(),
        other => other.to_string(),
    }
}

impl Sweep {
    /// Read and validate a sweep file.
    pub fn load(path: &Path) -> Result<Sweep, SweepError> {
        let text = std::fs::read_to_string(path).map_err(|e| SweepError::File {
            path: path.to_path_buf(),
            message: format!("cannot read it: {e}"),
        })?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Self::from_toml_str(&text, path, dir)
    }

    /// Parse and validate sweep text; `source` names it in errors, `base_dir` resolves a relative `base` path.
    pub fn from_toml_str(text: &str, source: &Path, base_dir: &Path) -> Result<Sweep, SweepError> {
        let ferr = |message: String| SweepError::File {
            path: source.to_path_buf(),
            message,
        };
        let f: SweepFile =
            toml::from_str(text).map_err(|e| ferr(e.to_string().trim().to_string()))?;
        let (exposures, stare_exposures, threshold_mas) = f.sizes().map_err(ferr)?;
        let (plan, telemetry, reference_error_mas) = f.plan(stare_exposures).map_err(ferr)?;
        let countermeasures = plan.names();
        let base = f.base_config(base_dir).map_err(ferr)?;
        let params = grid_params(f.grid.as_ref()).map_err(ferr)?;
        let points = grid_points(&base, &params, stare_exposures, source)?;
        let common_random_numbers = f.common_random_numbers.unwrap_or(false);
        let mut canon = String::new();
        let _ = writeln!(canon, "{FORMAT}");
        let _ = writeln!(canon, "seed={}", f.seed);
        let _ = writeln!(canon, "common_random_numbers={common_random_numbers}");
        let _ = writeln!(canon, "countermeasures={}", countermeasures.join(";"));
        if stare_exposures > 1 {
            let _ = writeln!(canon, "stare_exposures={stare_exposures}");
        }
        let _ = writeln!(
            canon,
            "telemetry={:?},{:?},{:?},{:?}",
            telemetry.noise_mas, telemetry.rate_hz, telemetry.latency_s, reference_error_mas
        );
        // (added only when used, so the hash of every earlier sweep stays what it was)
        if telemetry.correlated_mas > 0.0 {
            let _ = writeln!(
                canon,
                "telemetry_correlated={:?},{:?}",
                telemetry.correlated_mas, telemetry.correlation_time_s
            );
        }
        for p in &params {
            let _ = writeln!(canon, "grid {}={}", p.field, p.toml.join(" ; "));
        }
        let _ = writeln!(canon, "base:\n{}", base.to_toml());
        let hash = digest::sha256_short_hex(canon.as_bytes());

        Ok(Sweep {
            name: f.name.unwrap_or_else(|| {
                source
                    .file_stem()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_else(|| "sweep".into())
            }),
            source: source.to_path_buf(),
            seed: f.seed,
            exposures,
            stare_exposures,
            plan,
            telemetry,
            reference_error_mas,
            countermeasures,
            threshold_mas,
            common_random_numbers,
            base,
            params,
            points,
            hash,
        })
    }

    /// Number of grid points.
    pub fn n_points(&self) -> usize {
        self.points.len()
    }

    /// Number of work units (points × stares).
    pub fn n_units(&self) -> usize {
        self.points.len() * (self.exposures / self.stare_exposures)
    }

    /// (point, first exposure) of unit `u`: its stare holds exposures `first .. first + stare_exposures`.
    pub fn unit(&self, u: usize) -> (usize, usize) {
        (
            u % self.points.len(),
            (u / self.points.len()) * self.stare_exposures,
        )
    }

    /// The master seed of unit `u`.
    pub fn unit_seed(&self, u: usize) -> u64 {
        let k = if self.common_random_numbers {
            u / self.points.len()
        } else {
            u
        };
        rng::derive_seed(self.seed, &[Stream::Sweep as u64, k as u64])
    }

    /// The configuration of unit `u` (its point's, with the unit's seed and its stare's images).
    pub fn unit_config(&self, u: usize) -> Config {
        let mut c = self.points[u % self.points.len()].config.clone();
        c.seed = self.unit_seed(u);
        c.fidelity.images = self.stare_exposures;
        c
    }

    /// The identity record written to `DIR/sweep.json`.
    pub fn record(&self) -> Record {
        Record {
            format: FORMAT.into(),
            hash: self.hash.clone(),
            name: self.name.clone(),
            seed: self.seed,
            exposures: self.exposures,
            stare_exposures: self.stare_exposures,
            points: self.points.len(),
            countermeasures: self.countermeasures.clone(),
            threshold_mas: self.threshold_mas,
            common_random_numbers: self.common_random_numbers,
            grid: self
                .params
                .iter()
                .map(|p| RecordParam {
                    field: p.field.clone(),
                    values: p.display.clone(),
                })
                .collect(),
            point_values: self.points.iter().map(|p| p.values.clone()).collect(),
            telemetry: RecordTelemetry {
                noise_mas: self.telemetry.noise_mas,
                rate_hz: self.telemetry.rate_hz,
                latency_s: self.telemetry.latency_s,
                correlated_mas: self.telemetry.correlated_mas,
                correlation_time_s: self.telemetry.correlation_time_s,
                reference_error_mas: self.reference_error_mas,
            },
            base_config: self.base.to_toml(),
            engine_version: crate::VERSION.into(),
        }
    }
}

fn describe(params: &[Param], idx: &[usize]) -> String {
    params
        .iter()
        .zip(idx)
        .map(|(p, &i)| format!("{} = {}", p.field, p.display[i]))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Check that `dir` can hold `sweep` (empty, absent, or the same sweep) without writing anything.
pub fn check_dir(sweep: &Sweep, dir: &Path) -> Result<(), SweepError> {
    let rec_path = dir.join(crate::io::products::files::SWEEP_JSON);
    if rec_path.exists() {
        let found = match read_record(dir) {
            Ok(r) => r.hash,
            Err(_) => "unreadable".to_string(),
        };
        if found != sweep.hash {
            return Err(SweepError::OtherSweep {
                dir: dir.to_path_buf(),
                found,
                expected: sweep.hash.clone(),
            });
        }
    } else if dir.join("shards").exists() {
        return Err(SweepError::OtherSweep {
            dir: dir.to_path_buf(),
            found: "unknown (shards/ without sweep.json)".into(),
            expected: sweep.hash.clone(),
        });
    }
    Ok(())
}

/// Create the output directory and write the sweep's record and points (after [`check_dir`]).
pub fn prepare_dir(sweep: &Sweep, dir: &Path) -> Result<(), SweepError> {
    check_dir(sweep, dir)?;
    io::ensure_dir(&dir.join("shards"))?;
    io::ensure_dir(&dir.join("points"))?;
    let rec = sweep.record();
    let rec_path = dir.join(crate::io::products::files::SWEEP_JSON);
    let current = read_record(dir).ok();
    if current.as_ref() != Some(&rec) {
        io::write_atomic(&rec_path, record::to_json(&rec).as_bytes())?;
    }
    let mut header: Vec<String> = vec!["point".into()];
    header.extend(sweep.params.iter().map(|p| p.field.clone()));
    header.push("config_hash".into());
    let mut text = render_line(&header);
    text.push('\n');
    for p in &sweep.points {
        let mut cells = vec![p.index.to_string()];
        cells.extend(p.values.iter().cloned());
        cells.push(p.config.hash_hex());
        text.push_str(&render_line(&cells));
        text.push('\n');
        let path = dir
            .join("points")
            .join(format!("point-{:03}.toml", p.index));
        let body = format!(
            "# grid point {} of sweep {} ({}): {}\n# unit seeds are set per exposure; reproduce unit u with `jsim simulate --config {} --seed <seed column>`\n{}",
            p.index,
            sweep.name,
            sweep.hash,
            describe_values(&sweep.params, &p.values),
            path.display(),
            p.config.to_toml()
        );
        if std::fs::read_to_string(&path).ok().as_deref() != Some(body.as_str()) {
            io::write_atomic(&path, body.as_bytes())?;
        }
    }
    let points_csv = dir.join(crate::io::products::files::POINTS_CSV);
    if std::fs::read_to_string(&points_csv).ok().as_deref() != Some(text.as_str()) {
        io::write_atomic(&points_csv, text.as_bytes())?;
    }
    Ok(())
}

fn describe_values(params: &[Param], values: &[String]) -> String {
    params
        .iter()
        .zip(values)
        .map(|(p, v)| format!("{} = {v}", p.field))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    pub(crate) const QUICK: &str = r#"
seed = 11
exposures = 3
countermeasures = ["none", "plate-poly:3@oracle"]
[base.scene]
grid_n = 5
[grid]
"ace.sigma_mas" = [150, 300]
readout.order = ["rolling", "sample-hold"]
"#;

    pub(crate) fn quick() -> Sweep {
        Sweep::from_toml_str(QUICK, Path::new("t.toml"), Path::new(".")).expect("parses")
    }

    #[test]
    fn grid_is_sorted_product_first_slowest() {
        let s = quick();
        assert_eq!(s.params.len(), 2);
        assert_eq!(s.params[0].field, "ace.sigma_mas");
        assert_eq!(s.params[1].field, "readout.order");
        assert_eq!(s.n_points(), 4);
        assert_eq!(s.points[1].values, vec!["150", "sample-hold"]);
        assert_eq!(s.points[2].values, vec!["300", "rolling"]);
        assert_eq!(s.points[2].config.ace.sigma_mas, 300.0);
        assert_eq!(s.points[1].config.readout.order.name(), "sample-hold");
        assert_eq!(s.points[0].config.scene.grid_n, 5);
        assert_eq!(s.n_units(), 12);
        assert_eq!(s.unit(5), (1, 1));
    }

    /// A sweep's `instrument = "design"` zeroes the default's deviations before `[set]` and the grid, so a file
    /// can sweep one deviation of the design alone; without it the points are the instrument as built.
    #[test]
    fn a_sweeps_instrument_comes_before_its_set_and_grid() {
        let text = format!(
            "instrument = \"design\"\n{}[set]\n\"as_built.gain_error\" = 0.02\n",
            QUICK.replace(
                "[grid]",
                "[grid]\n\"as_built.wavefront_rms_nm\" = [0.0, 50.0]"
            )
        );
        let s = Sweep::from_toml_str(&text, Path::new("t.toml"), Path::new(".")).expect("parses");
        for p in &s.points {
            let a = &p.config.as_built;
            assert_eq!(a.gain_error, 0.02);
            assert_eq!((a.focus_breathing_nm, a.distortion_px), (0.0, 0.0));
        }
        assert_eq!(s.points[0].config.as_built.wavefront_rms_nm, 0.0);
        assert_eq!(
            s.points
                .last()
                .expect("a point")
                .config
                .as_built
                .wavefront_rms_nm,
            50.0
        );
        assert_eq!(quick().base.as_built, crate::config::AsBuilt::default());
        let bad = format!("instrument = \"perfect\"\n{QUICK}");
        let e = Sweep::from_toml_str(&bad, Path::new("t.toml"), Path::new("."))
            .expect_err("an unknown instrument is an error");
        assert!(e.to_string().contains("instrument"), "{e}");
    }

    #[test]
    fn seeds_depend_only_on_sweep_seed_and_unit() {
        let s = quick();
        let mut t = quick();
        t.exposures = 10;
        for u in 0..s.n_units() {
            assert_eq!(s.unit_seed(u), t.unit_seed(u));
            assert_eq!(s.unit_config(u), t.unit_config(u));
        }
        assert_ne!(s.unit_seed(0), s.unit_seed(1));
        // the hash ignores exposures (so a sweep can be extended) but not the seed
        assert_eq!(s.hash, t.hash);
        let other = Sweep::from_toml_str(
            &QUICK.replace("seed = 11", "seed = 12"),
            Path::new("t"),
            Path::new("."),
        )
        .expect("parses");
        assert_ne!(other.hash, s.hash);
    }
}
