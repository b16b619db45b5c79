//! `jsim bench`: speed against error of every knob, the methods × backends, and the cost against the
//! number of stars. Prints a table; writes `bench.csv` and `bench.png` (time vs error).

use crate::ConfigArgs;
use anyhow::Result;
use clap::Args;
use engine::studies::bench::{self, BenchRow};
use std::path::PathBuf;

#[derive(Args, Clone, Debug)]
pub struct BenchArgs {
    #[command(flatten)]
    pub cfg: ConfigArgs,
    /// Parts to run (comma separated): methods, knobs, stars, epsf, forward (the telemetry forward model's
    /// node spacing against time), bulge (the Galactic-centre field's knobs and the focal-plane exposure
    /// against the number of stars), crowded (the crowded-field analysis against the number of stars and its
    /// detection threshold), persistence (its threshold and lookback against the exact setting, on a
    /// two-stare sequence of the default field), solution (the astrometric solution of synthetic sequences of
    /// --solution-sources × --solution-exposures, with the calibration); the last five are not in the default set: minutes.
    #[arg(
        long,
        default_value = "methods,knobs,stars,epsf",
        value_delimiter = ','
    )]
    pub parts: Vec<String>,
    /// Knob sweeps on a 5 × 5 grid instead of the 400-star frame, and persistence's on stares of 4 exposures
    /// instead of 26 (a smoke run: not the documented numbers).
    #[arg(long)]
    pub quick: bool,
    /// Stars on which the direct CPU reference is computed (its time is scaled to the frame).
    #[arg(long, default_value_t = 40)]
    pub ref_stars: usize,
    /// Star counts of the scaling table.
    #[arg(long, default_value = "100,400,4000,40000", value_delimiter = ',')]
    pub stars: Vec<usize>,
    /// Star counts of the focal-plane rows (part bulge).
    #[arg(long, default_value = "1000,10000,100000", value_delimiter = ',')]
    pub bulge_stars: Vec<usize>,
    /// Source counts of the astrometric-solution rows (part solution).
    #[arg(long, default_value = "1000,10000,100000", value_delimiter = ',')]
    pub solution_sources: Vec<usize>,
    /// Exposure counts of the astrometric-solution rows, multiples of 25 (a 5 × 5 pattern per epoch); every
    /// source count is run with each.
    #[arg(long, default_value = "100", value_delimiter = ',')]
    pub solution_exposures: Vec<usize>,
    /// The instrument's calibration in the astrometric-solution rows: full (four arrays' own terms and a
    /// cubic distortion, drawn and solved) or none.
    #[arg(long, value_enum, default_value_t = SolutionCalibration::Full)]
    pub solution_calibration: SolutionCalibration,
    /// How the astrometric-solution rows are solved: cg (conjugate gradients, the default) and/or block (the
    /// block iteration), each row once per method.
    #[arg(long, value_enum, default_value = "cg", value_delimiter = ',')]
    pub solution_methods: Vec<crate::solve_cmd::IterationMethod>,
    /// Detection thresholds of the crowded-analysis rows (part crowded), on the largest field.
    #[arg(long, default_value = "3,5,10", value_delimiter = ',')]
    pub crowded_sigmas: Vec<f64>,
    /// Images for the ePSF-iteration and forward-model rows.
    #[arg(long, default_value_t = 3)]
    pub epsf_images: usize,
    /// Output directory (bench.csv, bench.png).
    #[arg(long, default_value = "out/bench")]
    pub out: PathBuf,
}

/// The calibration the solution's benchmark draws and solves.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolutionCalibration {
    Full,
    None,
}

impl SolutionCalibration {
    /// The engine's calibration model for it.
    pub fn model(self) -> engine::solution::CalibrationModel {
        match self {
            SolutionCalibration::Full => engine::studies::bench_solution::CALIBRATED,
            SolutionCalibration::None => engine::solution::CalibrationModel::NONE,
        }
    }
}

/// The parts `--parts` may name.
pub const PARTS: [&str; 9] = [
    "methods",
    "knobs",
    "stars",
    "epsf",
    "forward",
    "bulge",
    "crowded",
    "persistence",
    "solution",
];

pub fn bench(a: &BenchArgs) -> Result<()> {
    if let Some(p) = a.parts.iter().find(|p| !PARTS.contains(&p.as_str())) {
        anyhow::bail!("--parts {p}: not a part (allowed: {})", PARTS.join(", "));
    }
    let cfg = a.cfg.load()?;
    let mut outputs = crate::outputs::Outputs::in_dir(&a.out)?;
    for name in [
        engine::io::products::files::BENCH_CSV,
        engine::io::products::files::BENCH_PNG,
    ] {
        outputs.path(name);
    }
    let session = engine::session::Session::new();
    // the GPU rows are measured when the configured backend finds one (the CPU rows always)
    let gpu = Some(session.integrator(cfg.fidelity.backend))
        .filter(|i| matches!(i, engine::integrate::Integrator::Gpu(_)));
    for note in session.take_notes() {
        eprintln!("jsim: {note}");
    }
    let mut rows: Vec<BenchRow> = Vec::new();
    let save = |rows: &[BenchRow]| {
        crate::outputs::interrupted()?;
        bench::write_bench(&a.out.join(engine::io::products::files::BENCH_CSV), rows)
            .map_err(anyhow::Error::from)
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
            rows.extend(bench::knob_sweep(&group, &settings, astro)?);
            save(&rows)?;
        }
    }
    if has("epsf") {
        eprintln!("bench: ePSF iterations …");
        rows.extend(bench::epsf_iterations(&session, &cfg, a.epsf_images)?);
        save(&rows)?;
    }
    if has("forward") {
        eprintln!("bench: telemetry forward model …");
        rows.extend(engine::studies::bench_forward::forward_model(
            &session,
            &cfg,
            a.epsf_images,
        )?);
        save(&rows)?;
    }
    if has("bulge") {
        use engine::studies::bench_field;
        for (group, settings, astro) in bench_field::bulge_knobs(&cfg) {
            eprintln!("bench: {group} …");
            rows.extend(bench::knob_sweep(&group, &settings, astro)?);
            save(&rows)?;
        }
        eprintln!("bench: focal-plane exposure against the number of stars …");
        rows.extend(bench_field::focal_plane_scaling(
            &session,
            &cfg,
            &a.bulge_stars,
        )?);
        save(&rows)?;
    }
    if has("crowded") {
        use engine::studies::bench_field;
        if a.crowded_sigmas
            .iter()
            .any(|s| !(*s > 0.0 && s.is_finite()))
        {
            anyhow::bail!("--crowded-sigmas: give positive thresholds, e.g. 3,5,10");
        }
        eprintln!("bench: crowded-field analysis against the number of stars and its threshold …");
        rows.extend(bench_field::crowded_analysis(
            &session,
            &cfg,
            &a.bulge_stars,
            &a.crowded_sigmas,
        )?);
        save(&rows)?;
    }
    if has("persistence") {
        eprintln!("bench: persistence's threshold and lookback …");
        rows.extend(engine::studies::bench_persistence::persistence_knobs(
            &session, &cfg, a.quick,
        )?);
        save(&rows)?;
    }
    if has("solution") {
        eprintln!("bench: the astrometric solution against its size …");
        rows.extend(engine::studies::bench_solution::solution_scaling(
            &a.solution_sources,
            &a.solution_exposures,
            a.solution_calibration.model(),
            &a.solution_methods
                .iter()
                .map(|m| m.method())
                .collect::<Vec<_>>(),
            cfg.seed,
        )?);
        save(&rows)?;
    }
    if has("stars") {
        eprintln!("bench: cost against the number of stars …");
        rows.extend(bench::scaling(&session, &cfg, &a.stars, gpu.as_ref())?);
        save(&rows)?;
    }
    let drawn = bench::plot_bench(&a.out.join(engine::io::products::files::BENCH_PNG), &rows)?;
    outputs.keep();
    println!("{}", bench::render_table(&rows));
    if drawn {
        println!("wrote {}/bench.csv and bench.png", a.out.display());
    } else {
        println!(
            "wrote {}/bench.csv (no bench.png: fewer than {} settings with an error against their exact \
             setting, nothing to trade off)",
            a.out.display(),
            bench::MIN_PLOTTED_SETTINGS
        );
    }
    Ok(())
}
