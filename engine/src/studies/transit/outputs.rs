//! What a stare writes: the light curve (`lightcurve.ecsv`, astropy's table format: the products' side), the
//! truth apart (`truth.ecsv`), the summary (`transit.json`: readout, precision, noise budget, recovery,
//! detection) and the light curve's plot (`lightcurve.png`).

use super::budget::Terms;
use super::observe::Observation;
use super::run::StareResult;
use crate::io::ecsv::{self, Column};
use crate::io::plot::{self, Scale, Series};
use crate::io::{IoError, write_atomic};
use std::path::Path;

/// Write a stare's outputs into `dir` (created).
pub fn write(dir: &Path, obs: &Observation, r: &StareResult) -> Result<(), IoError> {
    crate::io::ensure_dir(dir)?;
    let lc = &r.lc;
    let in_box: Vec<f64> = lc.in_box.iter().map(|b| f64::from(u8::from(*b))).collect();
    let meta = [
        ("seed", obs.cfg.seed.to_string()),
        ("target_hw", obs.spec.target_hw.to_string()),
        ("plate_s", obs.readout.plate_s.to_string()),
        ("sub_exposures", obs.readout.sub_exposures.to_string()),
        ("cadence_s", obs.readout.cadence_s.to_string()),
        ("comparisons", (obs.stars.len() - 1).to_string()),
        ("aperture_px", lc.aperture_px.to_string()),
        (
            "photometry",
            format!("{:?}", obs.spec.photometry).to_lowercase(),
        ),
        (
            "decorrelate",
            format!("{:?}", obs.spec.decorrelate).to_lowercase(),
        ),
    ];
    ecsv::write(
        &dir.join("lightcurve.ecsv"),
        &[
            col("time", "d", "mid-plate, from the stare's start", &lc.t_days),
            col("flux", "", "differential, decorrelated, median 1", &lc.flux),
            col(
                "flux_raw",
                "",
                "differential, before decorrelation",
                &lc.flux_raw,
            ),
            col(
                "flux_aperture",
                "",
                "differential aperture photometry",
                &lc.aperture_rel,
            ),
            col("flux_psf", "", "differential PSF photometry", &lc.psf_rel),
            col("x", "pix", "target's fitted column (0-based)", &lc.x_px),
            col("y", "pix", "target's fitted row (0-based)", &lc.y_px),
            col(
                "sky",
                "electron",
                "sky per pixel (annulus median)",
                &lc.sky_e,
            ),
            col(
                "telemetry_x",
                "mas",
                "mean pointing of the plate",
                &lc.telemetry_x_mas,
            ),
            col(
                "telemetry_y",
                "mas",
                "mean pointing of the plate",
                &lc.telemetry_y_mas,
            ),
            col(
                "telemetry_sigma",
                "mas",
                "jitter sigma in the plate",
                &lc.telemetry_sigma_mas,
            ),
            col(
                "in_box",
                "",
                "1 inside the transit box found (widened by a quarter of its duration each side)",
                &in_box,
            ),
        ],
        &meta,
    )?;
    let tf: Vec<f64> = obs.truth.iter().map(|t| t.transit_flux).collect();
    let clean =
        crate::analysis::stare_photometry::differential(&obs.clean_aperture_e[lc.aperture_index]);
    let dx: Vec<f64> = obs.truth.iter().map(|t| t.drift_px.0).collect();
    let dy: Vec<f64> = obs.truth.iter().map(|t| t.drift_px.1).collect();
    let jx: Vec<f64> = obs.truth.iter().map(|t| t.jitter_mean_px.0).collect();
    let jy: Vec<f64> = obs.truth.iter().map(|t| t.jitter_mean_px.1).collect();
    ecsv::write(
        &dir.join("truth.ecsv"),
        &[
            col("time", "d", "mid-plate", &lc.t_days),
            col("transit_flux", "", "injected, plate mean", &tf),
            col(
                "clean_flux",
                "",
                "noise-free differential aperture flux",
                &clean,
            ),
            col("drift_x", "pix", "", &dx),
            col("drift_y", "pix", "", &dy),
            col("jitter_mean_x", "pix", "ACE mean over the plate", &jx),
            col("jitter_mean_y", "pix", "ACE mean over the plate", &jy),
        ],
        &[("seed", obs.cfg.seed.to_string())],
    )?;
    let json = serde_json::json!({
        "seed": obs.cfg.seed,
        "spec": obs.spec,
        "readout": {
            "plate_s": r.readout.plate_s,
            "sub_exposures": r.readout.sub_exposures,
            "exposure_s": r.readout.exposure_s,
            "longest_safe_exposure_s": r.readout.longest_safe_s,
            "cadence_s": r.readout.cadence_s,
            "read_noise_e": r.readout.read_noise_e,
        },
        "plates": lc.t_days.len(),
        "aperture_px": lc.aperture_px,
        "precision": r.precision,
        "precision_psf": r.precision_psf,
        "budget": r.budget,
        "budget_total_ppm": {
            "plate": r.budget.plate.total_ppm(),
            "hour": r.budget.hour.total_ppm(),
            "six_and_half_hours": r.budget.six_and_half_hours.total_ppm(),
        },
        "recovery": r.recovery,
        "detections": r.detections,
        "simulate_s": r.simulate_s,
        "analyse_s": r.analyse_s,
        "backend": r.backend,
    });
    write_atomic(
        &dir.join("transit.json"),
        serde_json::to_string_pretty(&json)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    plot_light_curve(&dir.join("lightcurve.png"), obs, r)
}

fn col<'a>(name: &'a str, unit: &'a str, d: &'a str, v: &'a [f64]) -> Column<'a> {
    Column {
        name,
        unit,
        description: d,
        values: v,
    }
}

/// The light curve (plates and 30-min bins, in hours) with the injected transit and the box found.
fn plot_light_curve(path: &Path, obs: &Observation, r: &StareResult) -> Result<(), IoError> {
    let lc = &r.lc;
    let hours: Vec<f64> = lc.t_days.iter().map(|t| 24.0 * t).collect();
    let (bx, by) = bin(&hours, &lc.flux, 0.5);
    let mut series = vec![
        Series {
            label: "plates".into(),
            x: hours.clone(),
            y: lc.flux.clone(),
            yerr: None,
            yerr_below: None,
        },
        Series {
            label: "30-min bins".into(),
            x: bx,
            y: by,
            yerr: None,
            yerr_below: None,
        },
    ];
    if obs.spec.depth > 0.0 {
        series.push(Series {
            label: "injected".into(),
            x: hours.clone(),
            y: obs.truth.iter().map(|t| t.transit_flux).collect(),
            yerr: None,
            yerr_below: None,
        });
    }
    if let Some(rec) = &r.recovery {
        series.push(Series {
            label: format!(
                "box found: {:.0} ± {:.0} ppm",
                1e6 * rec.depth,
                1e6 * rec.depth_sigma
            ),
            x: hours.clone(),
            y: hours
                .iter()
                .map(|h| {
                    if (h / 24.0 - rec.t0_days).abs() <= rec.duration_h / 48.0 {
                        1.0 - rec.depth
                    } else {
                        1.0
                    }
                })
                .collect(),
            yerr: None,
            yerr_below: None,
        });
    }
    plot::line_plot(
        path,
        &format!(
            "Hw {:.1}: {} plates of {} s, {} comparison stars",
            obs.spec.target_hw,
            hours.len(),
            obs.readout.plate_s,
            obs.stars.len() - 1
        ),
        "time (h)",
        "relative flux",
        &series,
        &[],
        Scale::Linear,
        Scale::Linear,
    )?;
    Ok(())
}

/// Means of consecutive `width` bins of (x, y) (finite y only).
pub fn bin(x: &[f64], y: &[f64], width: f64) -> (Vec<f64>, Vec<f64>) {
    let mut out: Vec<(f64, f64, usize)> = Vec::new();
    let x0 = x.first().copied().unwrap_or(0.0);
    for (a, b) in x.iter().zip(y) {
        if !b.is_finite() {
            continue;
        }
        let k = ((a - x0) / width).floor() as usize;
        while out.len() <= k {
            out.push((0.0, 0.0, 0));
        }
        out[k].0 += a;
        out[k].1 += b;
        out[k].2 += 1;
    }
    out.iter()
        .filter(|o| o.2 > 0)
        .map(|o| (o.0 / o.2 as f64, o.1 / o.2 as f64))
        .unzip()
}

/// The budget as text lines: each term at a plate, 1 h and 6.5 h, and the total.
pub fn budget_lines(r: &StareResult) -> Vec<String> {
    let b = &r.budget;
    let mut out = vec![format!(
        "{:<22} {:>10} {:>10} {:>10}",
        "term (ppm)", "plate", "1 h", "6.5 h"
    )];
    let rows = |t: &Terms| t.named();
    for i in 0..5 {
        let (name, p) = rows(&b.plate)[i];
        out.push(format!(
            "{:<22} {:>10.0} {:>10.1} {:>10.1}",
            name,
            p,
            rows(&b.hour)[i].1,
            rows(&b.six_and_half_hours)[i].1
        ));
    }
    out.push(format!(
        "{:<22} {:>10.0} {:>10.1} {:>10.1}",
        "predicted total",
        b.plate.total_ppm(),
        b.hour.total_ppm(),
        b.six_and_half_hours.total_ppm()
    ));
    out.push(format!(
        "{:<22} {:>10.0} {:>10.1} {:>10.1}{}",
        "measured",
        r.precision.plate_ppm,
        r.precision.hour_ppm,
        r.precision.six_and_half_hours_ppm,
        match (r.precision.hour_measured, r.precision.six_and_half_measured) {
            (true, true) => "",
            (true, false) => "  (6.5 h: the 1-h scatter / √6.5)",
            _ => "  (1 h, 6.5 h: the plates' scatter / √N)",
        }
    ));
    out
}
