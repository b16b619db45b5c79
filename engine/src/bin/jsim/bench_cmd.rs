//! `jsim bench`: speed against error of every knob, the methods × backends, and the cost against the
//! number of stars. Prints a table; writes `bench.csv` and `bench.png` (time vs error).

use crate::ConfigArgs;
use anyhow::Result;
use clap::Args;
use engine::io::csv::{self, Cell};
use engine::io::plot::{Scale, Series, scatter};
use engine::studies::bench::{self, BenchRow, CSV_HEADER};
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
pub struct BenchArgs {
    #[command(flatten)]
    pub cfg: ConfigArgs,
    /// Parts to run (comma separated): methods, knobs, stars, epsf.
    #[arg(
        long,
        default_value = "methods,knobs,stars,epsf",
        value_delimiter = ','
    )]
    pub parts: Vec<String>,
    /// Knob sweeps on a 5 × 5 grid instead of the 400-star frame.
    #[arg(long)]
    pub quick: bool,
    /// Stars on which the direct CPU reference is computed (its time is scaled to the frame).
    #[arg(long, default_value_t = 40)]
    pub ref_stars: usize,
    /// Star counts of the scaling table.
    #[arg(long, default_value = "100,400,4000,40000", value_delimiter = ',')]
    pub stars: Vec<usize>,
    /// Images for the ePSF-iteration rows.
    #[arg(long, default_value_t = 3)]
    pub epsf_images: usize,
    #[arg(long, default_value = "out/bench")]
    pub out: PathBuf,
}

fn fmt(v: f64) -> String {
    if v.is_nan() {
        "–".into()
    } else if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.2e}")
    }
}

fn table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<26} {:<24} {:<28} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9}  {}\n",
        "group",
        "setting",
        "backend",
        "stars",
        "time [s]",
        "max err",
        "rms err",
        "flux err",
        "Δpos mas",
        "note"
    );
    for r in rows {
        s.push_str(&format!(
            "{:<26} {:<24} {:<28} {:>6} {:>9.3} {:>9} {:>9} {:>9} {:>9}  {}\n",
            r.group,
            r.setting,
            r.backend.chars().take(28).collect::<String>(),
            r.stars,
            r.time_s,
            fmt(r.max_err),
            fmt(r.rms_err),
            fmt(r.flux_err),
            if r.astro_mas.is_nan() {
                "–".into()
            } else {
                format!("{:.3}", r.astro_mas)
            },
            r.note
        ));
    }
    s
}

pub fn bench(a: &BenchArgs) -> Result<()> {
    let cfg = a.cfg.load()?;
    crate::ensure_dir(&a.out)?;
    let session = engine::session::Session::new();
    // the GPU rows are measured when the configured backend finds one (the CPU rows always)
    let gpu = Some(session.integrator(cfg.fidelity.backend))
        .filter(|i| matches!(i, engine::integrate::Integrator::Gpu(_)));
    for note in session.take_notes() {
        eprintln!("jsim: {note}");
    }
    let mut rows: Vec<BenchRow> = Vec::new();
    let save = |rows: &[BenchRow]| -> Result<()> {
        let cells: Vec<Vec<Cell>> = rows
            .iter()
            .map(|r| {
                vec![
                    Cell::S(r.group.clone()),
                    Cell::S(r.setting.clone()),
                    Cell::S(r.backend.clone()),
                    Cell::I(r.stars as i64),
                    Cell::F(r.time_s),
                    Cell::F(r.max_err),
                    Cell::F(r.rms_err),
                    Cell::F(r.flux_err),
                    Cell::F(r.astro_mas),
                    Cell::S(r.note.clone()),
                ]
            })
            .collect();
        csv::write(&a.out.join("bench.csv"), &CSV_HEADER, &cells)?;
        Ok(())
    };
    let has = |p: &str| a.parts.iter().any(|x| x == p);
    if has("methods") {
        eprintln!("bench: methods × backends …");
        rows.extend(bench::methods(&session, &cfg, a.ref_stars, gpu.as_ref())?);
        save(&rows)?;
    }
    if has("knobs") {
        for (group, settings, astro) in bench::knob_settings(&cfg, a.quick) {
            eprintln!("bench: {group} …");
            rows.extend(bench::knob_sweep(&session, &group, &settings, astro)?);
            save(&rows)?;
        }
    }
    if has("epsf") {
        eprintln!("bench: ePSF iterations …");
        rows.extend(bench::epsf_iterations(&session, &cfg, a.epsf_images)?);
        save(&rows)?;
    }
    if has("stars") {
        eprintln!("bench: cost against the number of stars …");
        rows.extend(bench::scaling(&session, &cfg, &a.stars, gpu.as_ref())?);
        save(&rows)?;
    }
    // time against error, one point set per knob group
    let mut groups: Vec<String> = Vec::new();
    for r in &rows {
        if r.max_err.is_finite() && r.max_err > 0.0 && !groups.contains(&r.group) {
            groups.push(r.group.clone());
        }
    }
    let sets: Vec<Series> = groups
        .iter()
        .map(|g| {
            let pts: Vec<&BenchRow> = rows
                .iter()
                .filter(|r| &r.group == g && r.max_err > 0.0 && r.max_err.is_finite())
                .collect();
            Series {
                label: g.clone(),
                x: pts.iter().map(|r| r.max_err).collect(),
                y: pts.iter().map(|r| r.time_s).collect(),
                yerr: None,
            }
        })
        .collect();
    scatter(
        &a.out.join("bench.png"),
        "Speed against error (each knob against its finest setting)",
        "max |error| / peak pixel",
        "time [s]: PSF + kernel + integration",
        &sets,
        Scale::Log,
        Scale::Log,
        false,
    )?;
    println!("{}", table(&rows));
    println!("wrote {}/bench.csv and bench.png", a.out.display());
    Ok(())
}
