//! `jsim crowded`: accuracy against magnitude from one crowded exposure of the focal plane (the mock
//! Galactic-centre field by default), per ACE case and countermeasure, with completeness and the blended
//! and saturated fractions; vector maps of the four arrays. Products: [`engine::io::crowded`].

use crate::options::CrowdedConfigArgs;
use crate::{SurveyArgs, TelemetryArgs};
use anyhow::{Result, bail};
use clap::Args;
use engine::config::{AceCase, SceneKind};
use engine::io::crowded as out;
use engine::studies::crowded::{self, FocalPlaneAnalysis};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Clone, Debug)]
pub struct CrowdedArgs {
    #[command(flatten)]
    pub cfg: CrowdedConfigArgs,
    /// ACE cases (comma separated), each one exposure.
    #[arg(long, default_value = "gaussian,realistic", value_delimiter = ',')]
    pub aces: Vec<String>,
    /// Countermeasures (comma separated): none, telemetry, plate-affine@catalogue, plate-poly:N@catalogue
    /// (@oracle: the truth as reference, an upper limit).
    #[arg(long, default_value = "none,telemetry", value_delimiter = ',')]
    pub countermeasures: Vec<String>,
    #[command(flatten)]
    pub tel: TelemetryArgs,
    /// The survey the reference catalogue product comes from (the forced stars' catalogue with
    /// `analysis.crowded_forced_catalogue`, the `@catalogue` plate models' reference, and the one written
    /// with --save-images).
    #[command(flatten)]
    pub survey: SurveyArgs,
    /// Width of the magnitude bins (0.1 … 2).
    #[arg(long, default_value_t = 0.5)]
    pub bin_mag: f64,
    /// Also write each case's exposure (fp_000.fits under OUT/CASE/), e.g. for the photutils reference.
    #[arg(long)]
    pub save_images: bool,
    /// Output directory (crowded_bins.csv, crowded_arrays.csv, stars_CASE.csv, accuracy_vs_mag.png, the
    /// vector maps, and each case's exposure and products under CASE/ with --save-images).
    #[arg(long, default_value = "out/crowded")]
    pub out: PathBuf,
}

pub fn crowded(a: &CrowdedArgs) -> Result<()> {
    let cfg = a.cfg.load()?;
    if cfg.scene.kind == SceneKind::Grid {
        eprintln!("jsim crowded: note: the scene is the paper's grid, not a crowded field");
    }
    if !(0.1..=2.0).contains(&a.bin_mag) {
        bail!("--bin-mag {}: allowed 0.1 … 2", a.bin_mag);
    }
    let aces = a
        .aces
        .iter()
        .map(|s| AceCase::parse(s.trim()))
        .collect::<Result<Vec<_>, _>>()?;
    if aces.is_empty() {
        bail!("--aces: give at least one ACE case");
    }
    let plan = a.tel.plan(&a.countermeasures)?;
    let survey = a.survey.model()?;
    // one catalogue: the plate models' reference, the held stars' and the saved refcat.csv
    if survey.floor_mas != a.tel.reference_error_mas {
        bail!(
            "--refcat-floor-mas {} and --reference-error-mas {}: jsim crowded has one reference catalogue, give both the same floor",
            survey.floor_mas,
            a.tel.reference_error_mas
        );
    }
    crowded::check_plan(&plan)?;
    let telemetry_quality = plan
        .countermeasures
        .iter()
        .find_map(|c| c.telemetry_quality())
        .unwrap_or(engine::analysis::countermeasures::TelemetryQuality::DEFAULT);
    let mut outputs = crate::outputs::Outputs::in_dir(&a.out)?;
    for name in [
        engine::io::products::files::CROWDED_BINS_CSV,
        engine::io::products::files::CROWDED_ARRAYS_CSV,
        engine::io::products::files::ACCURACY_VS_MAG_PNG,
    ] {
        outputs.path(name);
    }
    let session = engine::session::Session::new();
    let (lo, hi) = match cfg.scene.kind {
        SceneKind::Bulge => (cfg.scene.bulge.hw_min, cfg.scene.bulge.hw_max),
        _ => (8.0, 17.0),
    };
    let edges = engine::scoring::crowded::edges(lo, hi, a.bin_mag);
    let mut bin_rows = Vec::new();
    let mut array_rows = Vec::new();
    let mut runs: Vec<(String, FocalPlaneAnalysis)> = Vec::new();
    let plane = engine::sky::focal_plane(&cfg);
    let scale = cfg.instrument.plate_scale_mas();
    for ace in aces {
        crate::outputs::interrupted()?;
        let mut c = cfg.clone();
        c.ace.case = ace;
        let case = format!("{}, {}", ace.name(), c.readout.order.name());
        let t = Instant::now();
        let fps = session.new_focal_plane(&c)?;
        let exp = fps.exposure(0)?;
        let sim_s = t.elapsed().as_secs_f64();
        if a.save_images {
            let dir = a.out.join(ace.name());
            engine::io::ensure_dir(&dir)?;
            outputs.add(&dir.join(engine::io::focal_plane::focal_plane_name(0)));
            engine::io::focal_plane::write_focal_plane_exposure(&dir, &fps, &exp)?;
            // the instrument's calibration flat beside it, so that `jsim analyze` can read the exposure
            outputs.add(&dir.join(engine::io::instrument::FLAT_NAME));
            engine::io::instrument::write_calibration_flat(&dir, &fps)?;
            outputs.add(&dir.join(engine::io::instrument::REFCAT_NAME));
            engine::io::instrument::write_reference_catalogue(&dir, &fps, &survey)?;
            outputs.add(&dir.join(engine::io::instrument::MODEL_PSF_NAME));
            engine::io::instrument::write_model_psf(&dir, &fps)?;
            // the telescope's attitude as recorded at the plan's telemetry quality (one record for
            // all arrays; none for a static ACE)
            outputs.add(&dir.join(engine::io::instrument::telemetry_name(0)));
            engine::io::instrument::write_telemetry(&dir, &fps.arrays[0], 0, &telemetry_quality)?;
        }
        crate::outputs::interrupted()?;
        let analyses = crowded::analyse_focal_plane(&fps, &exp, &plan, &edges, &survey)?;
        let stars: usize = fps.arrays.iter().map(|s| s.stars.len()).sum();
        eprintln!(
            "{case}: {stars} stars simulated in {sim_s:.1} s; analysed (4 arrays, {} countermeasure(s)) in {:.1} s",
            plan.countermeasures.len(),
            analyses.last().map(|r| r.analyse_s).unwrap_or(0.0)
        );
        if let Some(first) = analyses.first() {
            array_rows.extend(out::array_rows(&case, &first.arrays));
            let name = format!("stars_{}.csv", ace.name());
            outputs.add(&a.out.join(&name));
            out::write_table(
                &a.out.join(&name),
                &out::STARS_HEADER,
                &out::star_rows(&first.arrays, scale),
            )?;
        }
        for r in analyses {
            let cm = r.countermeasure.to_string();
            bin_rows.extend(out::bin_rows(&case, &cm, &r.bins));
            print_bins(&case, &cm, &r);
            let name = format!("vectors_{}_{}.png", ace.name(), cm.replace([':', '@'], "-"));
            outputs.add(&a.out.join(&name));
            out::plot_vectors(
                &a.out.join(&name),
                &format!("{case}, {cm}: fitted − true per cell"),
                &plane,
                &r,
                scale,
            )?;
            runs.push((format!("{case}, {cm}"), r));
        }
    }
    out::write_table(
        &a.out.join(engine::io::products::files::CROWDED_BINS_CSV),
        &out::BINS_HEADER,
        &bin_rows,
    )?;
    out::write_table(
        &a.out.join(engine::io::products::files::CROWDED_ARRAYS_CSV),
        &out::ARRAYS_HEADER,
        &array_rows,
    )?;
    let curves: Vec<(String, &[engine::scoring::crowded::MagBin])> = runs
        .iter()
        .map(|(l, r)| (l.clone(), r.bins.as_slice()))
        .collect();
    out::plot_accuracy(
        &a.out.join(engine::io::products::files::ACCURACY_VS_MAG_PNG),
        &curves,
    )?;
    outputs.keep();
    eprintln!("wrote {}", a.out.display());
    Ok(())
}

fn print_bins(case: &str, cm: &str, r: &FocalPlaneAnalysis) {
    println!("{case}, {cm}");
    print_bin_table(&r.bins);
    for a in &r.arrays {
        let s = &a.summary;
        println!(
            "  array {}: {} found + {} from the residual ({} matched to no truth star), ePSF from {} stars{}, {} groups (largest {}), {:.1} s",
            a.index + 1,
            s.n_first,
            s.n_residual,
            a.n_unmatched,
            s.epsf_stars,
            if s.fallback.is_empty() {
                String::new()
            } else {
                format!(" [{}]", s.fallback)
            },
            s.n_groups,
            s.largest_group,
            s.analyse_s
        );
        if let Some(r) = s.registration.filter(|r| r.pairs > 0) {
            println!(
                "    catalogue registered onto the fits ({} parameters per axis, {} pairs): residual {:.4} px rms; \
                 the map's error {:.4} px against the truth, {:.4} px predicted",
                r.parameters,
                r.pairs,
                r.rms_px,
                a.registration_error_px,
                r.predicted_error_px()
            );
        }
    }
}

/// The accuracy against magnitude of a focal-plane exposure, one line per bin of true Hw (`jsim crowded`, and
/// `jsim analyze` on a focal-plane file with its truth).
pub fn print_bin_table(bins: &[engine::scoring::crowded::MagBin]) {
    println!(
        "  Hw bin      true  found  compl.  blend  sat.  | isolated: n  mas   CRLB  ratio undet. faint pred. | crowded: n  mas   | merged: n  mas"
    );
    for b in bins {
        println!(
            "  {:5.2}-{:5.2} {:6} {:6} {:6.3} {:6.3} {:5.3} | {:6} {:6.2} {:6.2} {:5.2} {:6.2} {:5.2} {:5.2} | {:6} {:6.2} | {:5} {:6.2}",
            b.hw_lo,
            b.hw_hi,
            b.n_true,
            b.n_found,
            b.completeness,
            b.frac_blended,
            b.frac_saturated,
            b.isolated.n,
            b.isolated.accuracy_mas,
            b.isolated.crlb_mas,
            b.isolated.ratio(),
            b.isolated_undetected_mas,
            b.isolated_undetected_faint_mas,
            b.isolated_predicted_mas(),
            b.crowded.n,
            b.crowded.accuracy_mas,
            b.merged.n,
            b.merged.accuracy_mas
        );
    }
}
