//! The readout timing and array rotation an image's header states — what the telemetry correction applies
//! a telemetry record with: `READOUT` (rolling, global-reset, sample-hold), `ROWDIR` (up, down), `NCHAN`,
//! `CHANWID` [px], `PIXTIME` [µs], `TOVERHD` [s], `EXPTIME` [s] and `ROTATION` [deg]. A card the header
//! lacks is taken from the configuration and said; a card that is there but malformed, or a timing that is
//! impossible, is an error naming it.

use super::IoError;
use super::fits;
use crate::analysis::countermeasures::telemetry::ExposureReadout;
use crate::config::{Config, ReadoutOrder, RowDirection};
use crate::readout::ReadoutTiming;
use std::path::Path;

/// The cards of the readout timing, in the order they are looked up.
pub const READOUT_KEYS: [&str; 7] = [
    "READOUT", "ROWDIR", "NCHAN", "CHANWID", "PIXTIME", "TOVERHD", "ROTATION",
];

/// The readout of an image of `ny` rows and exposure `exposure_s` (from its facts) through a header lookup
/// `card(KEY)` (the card's text, `None` when absent). Returns the readout — `None` when the header states
/// no readout card and the configuration's timing does not fit this image (then the telemetry correction
/// has no timing) — and what was assumed.
pub fn from_cards(
    mut card: impl FnMut(&str) -> Option<String>,
    ny: usize,
    exposure_s: f64,
    fallback: &Config,
) -> Result<(Option<ExposureReadout>, Vec<String>), String> {
    let mut cfg = fallback.clone();
    let mut missing = Vec::new();
    let mut values = std::collections::HashMap::new();
    for key in READOUT_KEYS {
        match card(key) {
            Some(v) => {
                values.insert(key, v.trim().trim_matches('\'').trim().to_string());
            }
            None => missing.push(key),
        }
    }
    let number = |key: &str| -> Result<Option<f64>, String> {
        values
            .get(key)
            .map(|v| {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| format!("header {key} = '{v}': not a number"))
            })
            .transpose()
    };
    let count = |key: &str| -> Result<Option<usize>, String> {
        match number(key)? {
            Some(x) if x >= 1.0 && x.fract() == 0.0 && x <= 65_536.0 => Ok(Some(x as usize)),
            Some(x) => Err(format!(
                "header {key} = {x}: allowed a whole number in 1..=65536"
            )),
            None => Ok(None),
        }
    };
    if let Some(v) = values.get("READOUT") {
        cfg.readout.order = ReadoutOrder::parse(v).map_err(|_| {
            format!("header READOUT = '{v}': allowed rolling, global-reset, sample-hold")
        })?;
    }
    if let Some(v) = values.get("ROWDIR") {
        cfg.readout.row_direction = match v.as_str() {
            "up" => RowDirection::Up,
            "down" => RowDirection::Down,
            _ => return Err(format!("header ROWDIR = '{v}': allowed up, down")),
        };
    }
    if let Some(n) = count("NCHAN")? {
        cfg.readout.channels = n;
    }
    if let Some(w) = count("CHANWID")? {
        cfg.readout.channel_width_px = w;
    }
    if let Some(t) = number("PIXTIME")? {
        cfg.readout.pixel_time_us = t;
    }
    if let Some(t) = number("TOVERHD")? {
        cfg.readout.t_overhead_s = t;
    }
    let rotation_deg = number("ROTATION")?.unwrap_or(0.0);
    cfg.instrument.detector_px = ny;
    cfg.instrument.photosensitive_px = cfg.instrument.photosensitive_px.min(ny);
    cfg.detector.exposure_s = exposure_s;
    let stated = missing.len() < READOUT_KEYS.len();
    let mut assumed = Vec::new();
    if let Err(e) = cfg.validate() {
        if stated {
            return Err(format!(
                "the readout cards ({}) give {e}",
                READOUT_KEYS.join(", ")
            ));
        }
        assumed.push(format!(
            "no readout cards ({}) and the configuration's readout does not fit this image ({e}): no \
             readout timing, so no telemetry correction",
            READOUT_KEYS.join(", ")
        ));
        return Ok((None, assumed));
    }
    if !missing.is_empty() {
        assumed.push(format!(
            "no {} header card(s): the configuration's readout timing and a 0° array rotation assumed \
             (used by the telemetry correction only)",
            missing.join(", ")
        ));
    }
    Ok((
        Some(ExposureReadout {
            timing: ReadoutTiming::new(&cfg),
            rotation_deg,
        }),
        assumed,
    ))
}

/// [`from_cards`] on the header of HDU `ext` (`None`: the primary) of a file.
pub fn read(
    path: &Path,
    ext: Option<&str>,
    ny: usize,
    exposure_s: f64,
    fallback: &Config,
) -> Result<(Option<ExposureReadout>, Vec<String>), IoError> {
    from_cards(
        |key| fits::read_string_key_in(path, ext, key).ok(),
        ny,
        exposure_s,
        fallback,
    )
    .map_err(|message| IoError::Format {
        path: path.to_path_buf(),
        message,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cards(pairs: &[(&str, &str)]) -> impl FnMut(&str) -> Option<String> {
        let m: std::collections::HashMap<String, String> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k| m.get(k).cloned()
    }

    #[test]
    fn a_header_gives_the_configurations_timing_and_bad_cards_are_named() {
        let cfg = Config::default();
        let n = cfg.instrument.detector_px;
        let full = [
            ("READOUT", "global-reset"),
            ("ROWDIR", "down"),
            ("NCHAN", "16"),
            ("CHANWID", "123"),
            ("PIXTIME", "10.0"),
            ("TOVERHD", "0.2"),
            ("ROTATION", "90.0"),
        ];
        let (r, assumed) = from_cards(cards(&full), n, 12.5, &cfg).expect("readout");
        let r = r.expect("a timing");
        assert!(assumed.is_empty(), "{assumed:?}");
        let mut c = cfg.clone();
        c.readout.order = ReadoutOrder::GlobalReset;
        c.readout.row_direction = RowDirection::Down;
        c.readout.pixel_time_us = 10.0;
        c.readout.t_overhead_s = 0.2;
        c.detector.exposure_s = 12.5;
        assert_eq!(r.timing, ReadoutTiming::new(&c));
        assert_eq!(r.rotation_deg, 90.0);
        // nothing stated: the configuration's, said
        let (r, assumed) = from_cards(cards(&[]), n, cfg.detector.exposure_s, &cfg).expect("ok");
        assert_eq!(r.map(|r| r.timing), Some(ReadoutTiming::new(&cfg)));
        assert_eq!(assumed.len(), 1, "{assumed:?}");
        // an image the configuration's channels do not cover, with no cards: no timing, said
        let (r, assumed) = from_cards(cards(&[]), 4096, 10.0, &cfg).expect("ok");
        assert!(r.is_none());
        assert!(
            assumed[0].contains("no telemetry correction"),
            "{assumed:?}"
        );
        // malformed and impossible cards are errors naming the card
        for (bad, key) in [
            (("PIXTIME", "abc"), "PIXTIME"),
            (("READOUT", "sideways"), "READOUT"),
            (("NCHAN", "2.5"), "NCHAN"),
            (("ROWDIR", "left"), "ROWDIR"),
        ] {
            let e = from_cards(cards(&[bad]), n, 10.0, &cfg).expect_err(key);
            assert!(e.contains(key), "{e}");
        }
        let e = from_cards(cards(&[("CHANWID", "10")]), n, 10.0, &cfg).expect_err("too narrow");
        assert!(e.contains("readout.channel_width_px"), "{e}");
    }
}
