//! Persistence's two speed knobs against their exact settings (`jsim bench --parts persistence`): the
//! threshold below which a pixel fills no traps (`detector.persistence.threshold_e`) and the lookback beyond
//! which an exposure leaves nothing (`detector.persistence.lookback_s`). On the second exposure of the third
//! stare of the default sequence's field (Gaussian ACE), each row's time is that of making
//! its persistence from nothing (every earlier exposure's bright light remade: what a shard's first
//! exposure pays; a straight run remakes none when every star fills traps, else one per exposure), and its
//! error the largest and rms
//! difference of the released charge from the exact setting's (1 e⁻ threshold, a day's lookback), e⁻ per
//! pixel, over the pixels where the exact setting releases any.

use super::bench::{BenchError, BenchRow, bench_config};
use super::sequence::persistence::Memory;
use super::sequence::{Spec, plan, run};
use crate::config::{AceCase, Config};
use crate::session::Session;
use std::time::Instant;

/// The exact setting: every pixel with an electron, every earlier exposure of the day.
const EXACT: (f64, f64) = (1.0, 86_400.0);

/// Exposures per stare with `--quick`: the same three stares and target exposure, a sixth of the earlier light
/// to remake (a smoke run; its numbers are not the documented ones).
pub const QUICK_EXPOSURES_PER_STARE: usize = 4;

/// The rows of the persistence bench (`quick`: [`QUICK_EXPOSURES_PER_STARE`] exposures a stare).
pub fn persistence_knobs(
    session: &Session,
    base: &Config,
    quick: bool,
) -> Result<Vec<BenchRow>, BenchError> {
    let mut c = bench_config(base);
    c.ace.case = AceCase::Gaussian;
    c.detector.persistence.enabled = true;
    let mut spec = Spec {
        stares_l: 3,
        stares_b: 1,
        ..Spec::default()
    };
    if quick {
        spec.exposures_per_stare = QUICK_EXPOSURES_PER_STARE;
    }
    let per_stare = spec.exposures_per_stare;
    let plan = plan(&spec, &c).map_err(|m| run::SequenceError::Invalid(m.to_string()))?;
    let dir = std::env::temp_dir().join(format!("jsim-bench-persistence-{}", std::process::id()));
    // the second exposure after the second step: the one before it ≈ 1 s earlier on the same pointing,
    // the earlier stares' exposures from 2 to 15 minutes earlier elsewhere
    let Some(target) = plan.exposures.get(2 * per_stare + 1) else {
        return Ok(Vec::new());
    };
    let default = crate::config::Persistence::default();
    let mut settings: Vec<(String, f64, f64)> = [default.threshold_e, 2000.0]
        .iter()
        .map(|t| {
            (
                format!("threshold_e = {t}, lookback_s = {}", default.lookback_s),
                *t,
                default.lookback_s,
            )
        })
        .collect();
    settings.extend([30.0, 300.0].iter().map(|l| {
        (
            format!("threshold_e = {}, lookback_s = {l}", default.threshold_e),
            default.threshold_e,
            *l,
        )
    }));
    settings.push((
        format!("exact: threshold_e = {}, lookback_s = {}", EXACT.0, EXACT.1),
        EXACT.0,
        EXACT.1,
    ));
    let made_runs = (|| -> Result<Vec<(String, f64, usize, Vec<Vec<f32>>)>, BenchError> {
        let field = run::write_field(&plan, &c, &dir)?;
        let mut runs = Vec::new();
        for (k, (label, threshold_e, lookback_s)) in settings.iter().enumerate() {
            let mut s = c.clone();
            s.detector.persistence.threshold_e = *threshold_e;
            s.detector.persistence.lookback_s = *lookback_s;
            let bright = dir.join(format!("bright{k}.csv"));
            let t0 = Instant::now();
            let mut memory = Memory::from_field(&s, &field, &bright)?;
            let maps = memory.released_e(session, &plan, &s, target)?;
            runs.push((label.clone(), t0.elapsed().as_secs_f64(), memory.made, maps));
        }
        Ok(runs)
    })();
    // the scratch directory goes whether or not the runs succeeded
    let _ = std::fs::remove_dir_all(&dir);
    let runs = made_runs?;
    let Some((_, _, _, exact)) = runs.last() else {
        return Ok(Vec::new());
    };
    let peak = exact.iter().flatten().fold(0.0f32, |a, b| a.max(*b));
    Ok(runs
        .iter()
        .map(|(label, time_s, made, maps)| {
            let (mut max, mut sum2, mut n) = (0.0f64, 0.0, 0usize);
            for (k, x) in exact.iter().enumerate() {
                // an array with nothing released has no map
                let m = maps.get(k);
                for (i, b) in x.iter().enumerate() {
                    if *b > 0.0 {
                        let a = m.and_then(|m| m.get(i)).copied().unwrap_or(0.0);
                        let d = (a - *b) as f64;
                        max = max.max(d.abs());
                        sum2 += d * d;
                        n += 1;
                    }
                }
            }
            BenchRow {
                max_err: max,
                // no pixel released anything in the exact setting: no error to report
                rms_err: if n > 0 {
                    (sum2 / n as f64).sqrt()
                } else {
                    f64::NAN
                },
                ..BenchRow::timing(
                    "persistence",
                    label.clone(),
                    "cpu".into(),
                    0,
                    *time_s,
                    &format!(
                        "{made} earlier exposures remade; errors in e⁻ per pixel (the exact map peaks at {peak:.0} e⁻)"
                    ),
                )
            }
        })
        .collect())
}
