//! What a stare writes: the light curve (`lightcurve.ecsv`, astropy's table format: the products' side), the
//! truth apart (`truth.ecsv`), the summary (`transit.json`: readout, precision, noise budget, recovery,
//! detection) and the light curve's plot (`lightcurve.png`); on request ([`write_products`]) the instrument's
//! products themselves, for an outside tool: every window of every plate, the calibration flat cut to the
//! windows and the model PSF (`windows.fits`), and the telemetry (`telemetry.ecsv`).

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
        &dir.join(crate::io::products::files::LIGHTCURVE_ECSV),
        &[
            col("time", "d", "mid-plate, from the stare's start", &lc.t_days),
            col(
                "flux",
                "",
                "differential, decorrelated, 1 = median out of transit",
                &lc.flux,
            ),
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
                "jitter sigma in the plate (attitude record)",
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
    let js: Vec<f64> = obs.truth.iter().map(|t| t.jitter_sigma_px).collect();
    ecsv::write(
        &dir.join(crate::io::products::files::TRUTH_ECSV),
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
            col("jitter_sigma", "pix", "ACE sigma over the plate", &js),
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
        &dir.join(crate::io::products::files::TRANSIT_JSON),
        serde_json::to_string_pretty(&json)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    plot_light_curve(
        &dir.join(crate::io::products::files::LIGHTCURVE_PNG),
        obs,
        r,
    )
}

/// Write the stare's products: `windows.fits` — the primary header (seed, plate, sub-exposures, gain, bias,
/// read noise per plate, cadence), per star k an image `STAR_k` of `n × (n · plates)` ADU (plate p in rows
/// `p·n … p·n + n − 1`) with its window's corner `X0`, `Y0` (0-based detector pixels) and Hw, an image
/// `FLAT_k` (the calibration flat over the window), and `PSF_MODEL` (the model PSF the analysis fits: the
/// design PSF blurred by the telemetry's median jitter, `OVERSAMP` nodes per pixel, centred); and
/// `telemetry.ecsv` (each plate's time, mean pointing and jitter σ).
pub fn write_products(dir: &Path, obs: &Observation) -> Result<(), IoError> {
    use crate::io::fits::{self, Card, Hdu, Pixels};
    crate::io::ensure_dir(dir)?;
    let d = &obs.cfg.detector;
    let primary = vec![
        Card::u("SEED", obs.cfg.seed, "master seed"),
        Card::f(
            "PLATE_S",
            obs.readout.plate_s,
            "[s] each plate's integration",
        ),
        Card::i(
            "NSUB",
            obs.readout.sub_exposures as i64,
            "windowed sub-exposures co-added",
        ),
        Card::f("SUBEXP_S", obs.readout.exposure_s, "[s] each sub-exposure"),
        Card::f("CADENCE", obs.readout.cadence_s, "[s] plate start to start"),
        Card::f("GAIN", d.gain_e_per_adu, "[e/ADU]"),
        Card::f(
            "BIAS",
            d.bias_adu * obs.readout.sub_exposures as f64,
            "[ADU] co-added bias",
        ),
        Card::f(
            "RDNOISE",
            obs.readout.read_noise_e,
            "[e] read noise per pixel per plate",
        ),
        Card::i("NPLATES", obs.plates.len() as i64, "plates"),
        Card::i("NSTARS", obs.stars.len() as i64, "star 0 is the target"),
    ];
    let cubes: Vec<Vec<f32>> = (0..obs.windows.len())
        .map(|k| {
            obs.plates
                .iter()
                .flat_map(|p| p.windows_adu[k].iter().copied())
                .collect()
        })
        .collect();
    let names: Vec<(String, String)> = (0..obs.windows.len())
        .map(|k| (format!("STAR_{k}"), format!("FLAT_{k}")))
        .collect();
    let psf_n = 2 * obs.model_psf.half_nodes + 1;
    let mut hdus = vec![Hdu::Header { cards: primary }];
    for (k, w) in obs.windows.iter().enumerate() {
        hdus.push(Hdu::Image {
            name: &names[k].0,
            nx: w.n,
            ny: w.n * obs.plates.len(),
            pixels: Pixels::F32(&cubes[k]),
            cards: vec![
                Card::i("X0", w.x0, "window's first column (0-based)"),
                Card::i("Y0", w.y0, "window's first row (0-based)"),
                Card::f("HW", obs.stars[k].mag_hw, "catalogue magnitude"),
                Card::f(
                    "XCAT",
                    obs.catalogue_px.get(k).map_or(f64::NAN, |c| c.0),
                    "catalogue x via the design WCS (0-based)",
                ),
                Card::f(
                    "YCAT",
                    obs.catalogue_px.get(k).map_or(f64::NAN, |c| c.1),
                    "catalogue y via the design WCS (0-based)",
                ),
            ],
        });
        hdus.push(Hdu::Image {
            name: &names[k].1,
            nx: w.n,
            ny: w.n,
            pixels: Pixels::F32(&obs.calibration_flat[k]),
            cards: vec![],
        });
    }
    hdus.push(Hdu::Image {
        name: "PSF_MODEL",
        nx: psf_n,
        ny: psf_n,
        pixels: Pixels::F64(&obs.model_psf.data),
        cards: vec![Card::i(
            "OVERSAMP",
            obs.model_psf.oversampling as i64,
            "nodes per pixel",
        )],
    });
    fits::write(&dir.join(crate::io::products::files::WINDOWS_FITS), &hdus)?;
    let t: Vec<f64> = obs.plates.iter().map(|p| p.t_mid_days).collect();
    let tx: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_x_mas).collect();
    let ty: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_y_mas).collect();
    let ts: Vec<f64> = obs.plates.iter().map(|p| p.telemetry_sigma_mas).collect();
    ecsv::write(
        &dir.join(crate::io::products::files::TELEMETRY_ECSV),
        &[
            col("time", "d", "mid-plate", &t),
            col("x", "mas", "mean pointing over the plate", &tx),
            col("y", "mas", "mean pointing over the plate", &ty),
            col(
                "sigma",
                "mas",
                "jitter sigma in the plate (attitude record)",
                &ts,
            ),
        ],
        &[("seed", obs.cfg.seed.to_string())],
    )
}

fn col<'a>(name: &'a str, unit: &'a str, d: &'a str, v: &'a [f64]) -> Column<'a> {
    Column {
        name,
        unit,
        description: d,
        values: v,
    }
}

/// The light curve (10-min bins, in hours) with the injected transit and the box found.
fn plot_light_curve(path: &Path, obs: &Observation, r: &StareResult) -> Result<(), IoError> {
    let lc = &r.lc;
    let hours: Vec<f64> = lc.t_days.iter().map(|t| 24.0 * t).collect();
    let (bx, by) = bin(&hours, &lc.flux, 10.0 / 60.0);
    let mut series = vec![Series {
        label: "10-min bins".into(),
        x: bx,
        y: by,
        yerr: None,
        yerr_below: None,
    }];
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
