//! `jsim analyze` on a calibrated multi-extension file of another observatory (HST, JWST: its `SCI` chips,
//! `engine::io::calibrated`). Chips that are exposures of one pointing (a CR-split pair, repeated
//! exposures) have their cosmic rays rejected by comparison before the analysis, and their fitted positions'
//! repeatability set against the bound after it (`engine::analysis::repeat`).

use crate::cmd::{AnalyzeArgs, Part, analyze_parts};
use crate::outputs::Outputs;
use anyhow::{Result, bail};
use engine::analysis::crowding;
use engine::analysis::lacosmic;
use engine::analysis::repeat::{self, Rejection};
use engine::analysis::report::StarResult;
use engine::config::{Config, Crowding};
use engine::io::{analysis_input::AnalysisInput, calibrated, csv, products};
use engine::session::Session;

/// How close (px) two chips' pixel grids must lie on the sky to be exposures of one pointing.
const SAME_POINTING_PX: f64 = 0.1;
/// Matching radius (px) of the repeatability, and the fewest stars a flux bin reports.
const REPEAT_MATCH_PX: f64 = 1.5;
const REPEAT_MIN_STARS: usize = 10;

/// Each chip analysed alone, and the chips together, as a focal plane's arrays; exposures of one pointing
/// compared.
pub fn analyze_calibrated(session: &Session, cfg: &Config, a: &AnalyzeArgs) -> Result<()> {
    let sets = calibrated::imsets(&a.image)?;
    if sets.is_empty() {
        bail!(
            "{}: the primary HDU is not a 2-D image, and the file has neither SCI extensions (a calibrated \
             HST or JWST file) nor ARRAYn ones (a jsim focal plane)",
            a.image.display()
        );
    }
    for (given, what) in [
        (a.flat.is_some(), "--flat"),
        (a.refcat.is_some(), "--refcat"),
        (a.telemetry.is_some(), "--telemetry"),
        (a.truth.is_some(), "--truth"),
    ] {
        if given {
            bail!(
                "{what}: not read with a calibrated file of another observatory (its SCI chips are \
                 flat-fielded by their pipeline; score its catalogue with `jsim score`)"
            );
        }
    }
    let parts: Vec<Part> = sets
        .iter()
        .map(|s| Part {
            label: s.name(),
            dir: s.dir_name(),
            number: s.number(),
        })
        .collect();
    let mut inputs = sets
        .iter()
        .map(|s| AnalysisInput::read_chip(&a.image, s, &a.calibrated, cfg))
        .collect::<Result<Vec<_>, _>>()?;
    let exposures = one_pointing(&inputs);
    // each chip's cosmic-ray mask: by comparison for exposures of one pointing, else L.A.Cosmic
    let before: Vec<Vec<bool>> = inputs.iter().map(|i| i.img.bad.clone()).collect();
    if exposures && let Some(r) = &a.cr_rejection {
        let mut images: Vec<_> = inputs.iter().map(|i| i.img.clone()).collect();
        let counts = repeat::reject_by_comparison(&mut images, r);
        for ((input, img), n) in inputs.iter_mut().zip(images).zip(counts) {
            input.img = img;
            input.assumptions.push(format!(
                "{n} pixel(s) masked as cosmic rays by comparison with the other {} exposure(s) of this pointing \
                 (> {} σ above the clean estimate, neighbours > {} σ)",
                parts.len() - 1,
                r.threshold_sigma,
                r.grow_sigma
            ));
        }
    } else if !exposures && let Some(l) = &a.lacosmic {
        for input in inputs.iter_mut() {
            let hits = lacosmic::detect(&input.img, l);
            let n = hits.iter().filter(|h| **h).count();
            for (b, h) in input.img.bad.iter_mut().zip(&hits) {
                *b |= *h;
            }
            input.assumptions.push(format!(
                "{n} pixel(s) masked as cosmic rays by L.A.Cosmic (σ_lim {}, f_lim {}, {} iterations)",
                l.sigma_clip, l.objlim, l.iterations
            ));
        }
    }
    let cr_masks: Vec<Vec<u16>> = inputs
        .iter()
        .zip(&before)
        .map(|(i, b)| {
            i.img
                .bad
                .iter()
                .zip(b)
                .map(|(now, was)| u16::from(*now && !*was))
                .collect()
        })
        .collect();
    // exposures of one pointing are analysed alike: crowded when any of them is
    let mut cfg = cfg.clone();
    if exposures && cfg.analysis.crowding == Crowding::Auto {
        let crowded = inputs
            .iter()
            .any(|i| crowding::is_crowded(&i.img, &cfg.analysis, Crowding::Auto).0);
        cfg.analysis.crowding = if crowded { Crowding::On } else { Crowding::Off };
        for input in inputs.iter_mut() {
            input.assumptions.push(format!(
                "exposures of one pointing, analysed alike: the {} analysis (from the densest exposure)",
                if crowded { "crowded-field" } else { "isolated-star" }
            ));
        }
    }
    let cfg = &cfg;
    let read = |k: usize| Ok(inputs[k].clone());
    let scale = inputs[0].plate_scale_mas;
    let finish = |fits: &[Vec<StarResult>], outputs: &mut Outputs| -> Result<()> {
        for ((part, mask), input) in parts.iter().zip(&cr_masks).zip(&inputs) {
            let path = a.out.join(&part.dir).join(products::COSMIC_RAYS_NAME);
            outputs.add(&path);
            products::write_cosmic_rays(&path, input.img.nx, input.img.ny, mask)?;
        }
        if !exposures {
            return Ok(());
        }
        let mut rows = Vec::new();
        println!(
            "repeatability of the exposures of one pointing (each pair's differences ÷ √2 against the bound):"
        );
        for i in 0..fits.len() {
            for j in i + 1..fits.len() {
                let (bins, off) =
                    repeat::repeatability(&fits[i], &fits[j], REPEAT_MATCH_PX, REPEAT_MIN_STARS);
                println!(
                    "  {} – {}: common offset ({:+.4}, {:+.4}) px",
                    parts[i].label, parts[j].label, off.0, off.1
                );
                for b in &bins {
                    println!(
                        "    flux {:>9.0}–{:<9.0} e⁻  n {:>5}  repeat/bound x {:.2} y {:.2} (± {:.2})  bound {:.2} mas",
                        b.flux_min_e,
                        b.flux_max_e,
                        b.n,
                        b.ratio_x,
                        b.ratio_y,
                        b.ratio_error,
                        b.crlb_x_px * scale
                    );
                }
                rows.extend(products::repeat_rows(
                    &parts[i].label,
                    &parts[j].label,
                    &bins,
                    off,
                    scale,
                ));
            }
        }
        let path = a.out.join(engine::io::products::files::REPEATABILITY_CSV);
        outputs.add(&path);
        csv::write(&path, &products::REPEAT_HEADER, &rows)?;
        Ok(())
    };
    analyze_parts(session, cfg, a, &parts, "chips", &read, Some(&finish))
}

/// Whether the chips are exposures of one pointing: two or more, each on the first's pixel grid.
fn one_pointing(inputs: &[AnalysisInput]) -> bool {
    let wcs: Vec<Option<&calibrated::ChipWcs>> = inputs
        .iter()
        .map(|i| i.chip.as_ref().and_then(|c| c.wcs.as_ref()))
        .collect();
    inputs.len() >= 2
        && wcs.iter().all(|w| {
            matches!((w, wcs[0]), (Some(w), Some(first)) if calibrated::same_pointing(first, w, SAME_POINTING_PX))
        })
}

/// A cosmic-ray significance option, `--OPTION SIGMA`: 0 (off, `None`) or a finite number ≥ 2.
fn sigma_option(option: &str, sigma: f64) -> Result<Option<f64>> {
    if !(sigma == 0.0 || (sigma >= 2.0 && sigma.is_finite())) {
        bail!("--{option} {sigma}: 0 (off) or a finite number ≥ 2");
    }
    Ok((sigma > 0.0).then_some(sigma))
}

/// The single-exposure knob: `--lacosmic-sigma S` (0: off), L.A.Cosmic's σ_lim.
pub fn lacosmic_knob(sigma: f64) -> Result<Option<lacosmic::LaCosmic>> {
    Ok(
        sigma_option("lacosmic-sigma", sigma)?.map(|sigma_clip| lacosmic::LaCosmic {
            sigma_clip,
            ..lacosmic::LaCosmic::default()
        }),
    )
}

/// The rejection knob: `--cr-reject-sigma T` (0: off).
pub fn rejection(sigma: f64) -> Result<Option<Rejection>> {
    Ok(sigma_option("cr-reject-sigma", sigma)?.map(|t| Rejection {
        threshold_sigma: t,
        grow_sigma: Rejection::default().grow_sigma.min(t),
        ..Rejection::default()
    }))
}
