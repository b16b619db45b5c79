//! Speed against error on the Galactic-centre field (`jsim bench --parts bulge`): the knobs a crowded,
//! many-coloured field adds — colour binning of the PSFs and each star's reach — measured like every other
//! knob ([`super::bench::knob_sweep`], against the exact setting), the cost of a whole focal-plane
//! exposure against the number of stars, and the crowded-field analysis' cost and accuracy
//! ([`crowded_analysis`], `--parts crowded`).

use super::bench::{BenchError, BenchRow, bench_config};
use crate::config::{AceCase, Config, Layout, SceneKind};
use crate::session::Session;
use std::time::Instant;

/// A single array of the mock bulge field holding about `stars` stars.
pub fn bulge_array(base: &Config, stars: f64) -> Config {
    let mut c = bench_config(base);
    c.scene.kind = SceneKind::Bulge;
    c.focal_plane.layout = Layout::Single;
    c.scene.bulge.density_per_arcmin2 = 1.0;
    let per_unit = crate::scene::bulge::star_count(&c);
    c.scene.bulge.density_per_arcmin2 = stars / per_unit;
    c
}

/// The bulge knobs: (group, settings with the exact one last, whether to measure positions).
pub fn bulge_knobs(base: &Config) -> Vec<(String, Vec<(String, Config)>, bool)> {
    // colour binning: 60 stars of the bulge's colours, Gaussian ACE; the exact setting is one PSF per star
    let mut colours = bulge_array(base, 60.0);
    colours.ace.case = AceCase::Gaussian;
    // each star's reach: 600 stars of the bulge's luminosity function, realistic ACE, rolling readout; the
    // shared core's phases on the same stars (whole frames compared with every star depositing its whole
    // track)
    let reach = bulge_array(base, 600.0);
    vec![
        (
            "colour step (bulge colours)".into(),
            settings(
                &colours,
                &[0.5, 0.2, 0.1, 0.05, 0.02, 0.0],
                "exact (one PSF per colour)",
                |c, v| {
                    c.fidelity.colour_step_mag = v;
                    format!("{v} mag")
                },
            ),
            true,
        ),
        (
            "deposit phases (bulge, realistic ACE)".into(),
            settings(&reach, &[2, 4, 8, 16, 0], "exact shared core", |c, q| {
                c.fidelity.deposit_phases = q;
                format!("{q} phases")
            }),
            true,
        ),
        (
            "wing threshold (bulge, realistic ACE)".into(),
            settings(
                &reach,
                &[10.0, 3.0, 1.0, 0.3, 0.0],
                "kernel reach (exact)",
                |c, t| {
                    c.fidelity.wing_threshold_e = t;
                    format!("{t} e⁻")
                },
            ),
            true,
        ),
    ]
}

/// One knob's settings on `base`: `set` applies a value and names it; the value 0 (the exact setting) is
/// named `exact`.
fn settings<T: Copy + PartialEq + Default>(
    base: &Config,
    values: &[T],
    exact: &str,
    set: impl Fn(&mut Config, T) -> String,
) -> Vec<(String, Config)> {
    values
        .iter()
        .map(|&v| {
            let mut c = base.clone();
            let label = set(&mut c, v);
            (
                if v == T::default() {
                    exact.into()
                } else {
                    label
                },
                c,
            )
        })
        .collect()
}

/// The settings of the focal-plane rows: the exact one (realistic ACE), the fast knobs one at a time and
/// together, and Gaussian ACE.
pub fn focal_plane_settings() -> Vec<(&'static str, fn(&mut Config))> {
    vec![
        ("realistic ACE, exact", |c| c.ace.case = AceCase::Realistic),
        ("realistic ACE, deposit phases 8", |c| {
            c.ace.case = AceCase::Realistic;
            c.fidelity.deposit_phases = 8;
        }),
        ("realistic ACE, deposit phases 8, wing 1 e⁻", |c| {
            c.ace.case = AceCase::Realistic;
            c.fidelity.deposit_phases = 8;
            c.fidelity.wing_threshold_e = 1.0;
        }),
        ("Gaussian ACE", |c| c.ace.case = AceCase::Gaussian),
    ]
}

/// One exposure of the quad focal plane with about `n` stars of the mock bulge field, for each count and
/// each of [`focal_plane_settings`] (the Gaussian row only at the largest count): PSFs and kernels (once),
/// then the exposure (integration and detector on all four arrays) and its multi-extension FITS, timed
/// apart.
pub fn focal_plane_scaling(
    session: &Session,
    base: &Config,
    counts: &[usize],
) -> Result<Vec<BenchRow>, BenchError> {
    let dir = std::env::temp_dir().join(format!("jsim-bench-fp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|source| BenchError::Io {
        path: dir.clone(),
        source,
    })?;
    let mut rows = Vec::new();
    let largest = counts.iter().copied().max().unwrap_or(0);
    let runs = focal_plane_settings().into_iter().flat_map(|(label, set)| {
        counts
            .iter()
            .filter(move |&&n| !label.starts_with("Gaussian") || n == largest)
            .map(move |&n| (label, set, n))
    });
    for (label, set, n) in runs {
        let mut c = bench_config(base);
        c.scene.kind = SceneKind::Bulge;
        c.focal_plane.layout = Layout::Quad;
        set(&mut c);
        c.scene.bulge.density_per_arcmin2 = 1.0;
        c.scene.bulge.density_per_arcmin2 = n as f64 / crate::scene::bulge::star_count(&c);
        let t0 = Instant::now();
        let fps = session.new_focal_plane(&c)?;
        for a in &fps.arrays {
            a.jobs()?;
        }
        let setup = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let exp = fps.exposure(0)?;
        let t_exp = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        crate::io::focal_plane::write_focal_plane_exposure(&dir, &fps, &exp)?;
        let t_write = t2.elapsed().as_secs_f64();
        let integrate: f64 = exp.arrays.iter().map(|e| e.times.integrate_s).sum();
        rows.push(BenchRow::timing(
            "focal-plane exposure",
            format!("{n} stars, {label}"),
            fps.arrays
                .first()
                .map(|a| a.backend_name())
                .unwrap_or_default(),
            fps.star_count(),
            t_exp + t_write,
            &format!(
                "integration {integrate:.2} s, detector {:.2} s, FITS {t_write:.2} s; PSFs + kernels {setup:.1} s (once per dataset)",
                t_exp - integrate
            ),
        ));
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(rows)
}

/// The crowded-field analysis (`jsim bench --parts crowded`): its time on one Gaussian-ACE focal-plane
/// exposure against the number of stars (≈ `counts` drawn on the focal plane), and its one knob,
/// `analysis.crowded_detect_sigma`, on the largest field — each row's error is the isolated Hw 12–14 stars'
/// accuracy and its ratio to their Cramér–Rao bound (the independent reference: the bound, not a setting),
/// with the completeness at Hw 16–17 in the note.
pub fn crowded_analysis(
    session: &Session,
    base: &Config,
    counts: &[usize],
    sigmas: &[f64],
) -> Result<Vec<BenchRow>, BenchError> {
    use crate::analysis::countermeasures::{Countermeasure, Plan};
    let plan =
        Plan::new(vec![Countermeasure::None]).map_err(crate::analysis::AnalysisError::from)?;
    let largest = counts.iter().copied().max().unwrap_or(0);
    let default_sigma = base.analysis.crowded_detect_sigma;
    let runs = counts.iter().map(|&n| (n, default_sigma)).chain(
        sigmas
            .iter()
            .filter(|&&s| s != default_sigma)
            .map(|&s| (largest, s)),
    );
    let mut rows = Vec::new();
    for (n, sigma) in runs {
        let mut c = bench_config(base);
        c.scene.kind = SceneKind::Bulge;
        c.focal_plane.layout = Layout::Quad;
        c.ace.case = AceCase::Gaussian;
        c.analysis.crowded_detect_sigma = sigma;
        c.scene.bulge.density_per_arcmin2 = 1.0;
        c.scene.bulge.density_per_arcmin2 = n as f64 / crate::scene::bulge::star_count(&c);
        let fps = session.new_focal_plane(&c)?;
        let exp = fps.exposure(0)?;
        let t0 = Instant::now();
        let run = super::crowded::analyse_focal_plane(
            &fps,
            &exp,
            &plan,
            &[12.0, 14.0, 16.0, 17.0],
            &crate::io::instrument::SurveyModel::default(),
        )?;
        let t = t0.elapsed().as_secs_f64();
        let r = &run[0];
        let (bright, faint) = (&r.bins[0], &r.bins[2]);
        let reported: usize = r.arrays.iter().map(|a| a.stars.len()).sum();
        let mut row = BenchRow::timing(
            "crowded analysis",
            format!("{n} stars, crowded_detect_sigma={sigma}"),
            "cpu".into(),
            fps.star_count(),
            t,
            &format!(
                "isolated Hw 12-14: {:.2} x the bound ({} stars); completeness Hw 16-17 {:.1} %; {reported} stars reported",
                bright.isolated.ratio(),
                bright.isolated.n,
                100.0 * faint.completeness
            ),
        );
        row.astro_mas = bright.isolated.accuracy_mas;
        rows.push(row);
    }
    Ok(rows)
}
