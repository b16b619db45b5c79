//! From a chip's planes and header to electrons, a read noise and a mask: the units, the gain, the read noise and
//! the DQ bits, in the order of precedence the module's documentation gives.

use super::amplifiers::{self, per_amplifier};
use super::header_wcs::{chip_wcs, plate_scale_mas};
use super::{CalibratedChip, ChipPlanes, Keys, ReadOptions};

/// The report's sentence on a chip's RA/Dec.
pub(super) fn wcs_note(w: &super::ChipWcs) -> String {
    format!(
        "RA/Dec through the header's WCS (TAN{})",
        if w.sip.is_some() {
            " with SIP distortion"
        } else {
            ""
        }
    )
}

/// The observatory (and, where its DQ bits differ, the instrument) whose conventions a file follows
/// (`TELESCOP`, `INSTRUME`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Observatory {
    Hst,
    /// HST's WFPC2, whose DQ flags A-to-D saturation with bit 8.
    HstWfpc2,
    Jwst,
    Other,
}

impl Observatory {
    pub fn from_header(telescop: Option<&str>, instrume: Option<&str>) -> Self {
        let up = |t: Option<&str>| t.map(|s| s.trim().to_ascii_uppercase());
        match (up(telescop).as_deref(), up(instrume).as_deref()) {
            (_, Some("WFPC2")) => Self::HstWfpc2,
            (Some("HST"), _) => Self::Hst,
            (Some("JWST"), _) => Self::Jwst,
            _ => Self::Other,
        }
    }
    /// The DQ bits a pipeline of this observatory does not mask by default.
    pub fn default_dq_ignore(self) -> u64 {
        match self {
            // everything but DO_NOT_USE (bit 0) and NON_SCIENCE (bit 9)
            Self::Jwst => !(1 | 512),
            Self::Hst | Self::HstWfpc2 | Self::Other => 0,
        }
    }
    /// The DQ bits that flag a saturated pixel.
    pub fn saturated_bits(self) -> u64 {
        match self {
            // full-well (256) and A-to-D (2048) saturation of ACS and WFC3
            Self::Hst => 256 | 2048,
            Self::HstWfpc2 => 8,
            Self::Jwst => 2,
            Self::Other => 0,
        }
    }
}

/// The unit of the data (`BUNIT`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataUnit {
    Electrons,
    Counts,
    ElectronsPerS,
    CountsPerS,
    MjyPerSr,
    /// MJy per pixel: MJy/sr times the pixel's solid angle `PIXAR_SR`.
    Mjy,
}

impl DataUnit {
    /// `BUNIT`'s value, read without regard to case, spaces or a plural.
    pub fn parse(bunit: &str) -> Option<Self> {
        let s: String = bunit
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_uppercase();
        let (num, rate) = match s.split_once('/') {
            Some((n, "S" | "SEC" | "SECOND" | "SECONDS")) => (n.to_string(), true),
            Some((n, d)) if n == "MJY" && d == "SR" => return Some(Self::MjyPerSr),
            Some(_) => return None,
            None if s == "MJY" => return Some(Self::Mjy),
            None => (s, false),
        };
        let electrons = matches!(num.as_str(), "ELECTRONS" | "ELECTRON" | "E-" | "E");
        let counts = matches!(num.as_str(), "COUNTS" | "COUNT" | "DN" | "ADU" | "CTS");
        match (electrons, counts, rate) {
            (true, _, false) => Some(Self::Electrons),
            (true, _, true) => Some(Self::ElectronsPerS),
            (_, true, false) => Some(Self::Counts),
            (_, true, true) => Some(Self::CountsPerS),
            _ => None,
        }
    }
}

/// The gain (e⁻ per count) and the key it came from.
fn gain(keys: &dyn Keys) -> Option<(f64, String)> {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    for k in ["GAIN", "ATODGAIN"] {
        if let Some(v) = keys.number(k).filter(|v| positive(*v)) {
            return Some((v, k.to_string()));
        }
    }
    let (amps, per_amp) = per_amplifier(keys, "ATODGN");
    if !per_amp.is_empty() {
        let mean = per_amp.iter().map(|p| p.1).sum::<f64>() / per_amp.len() as f64;
        let names: Vec<String> = per_amp.iter().map(|p| format!("ATODGN{}", p.0)).collect();
        return Some((
            mean,
            format!(
                "{} (amplifiers {} of CCDAMP)",
                names.join(", "),
                amps.iter().collect::<String>()
            ),
        ));
    }
    keys.number("CCDGAIN")
        .filter(|v| positive(*v))
        .map(|v| (v, "CCDGAIN (the nominal setting)".to_string()))
}

/// The exposure, s, and its key.
fn exposure(keys: &dyn Keys) -> Option<(f64, &'static str)> {
    ["EXPTIME", "XPOSURE", "EFFEXPTM"]
        .into_iter()
        .find_map(|k| {
            keys.number(k)
                .filter(|v| *v > 0.0 && v.is_finite())
                .map(|v| (v, k))
        })
}

/// The median of the finite values of `v` (NaN when none).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    crate::numerics::stats::median(&v)
}

/// Electrons per data unit and how it was found.
fn electrons_per_unit(
    keys: &dyn Keys,
    planes: &ChipPlanes,
    good: &[bool],
    opts: &ReadOptions,
) -> Result<(f64, String), String> {
    if let Some(k) = opts.electrons_per_unit {
        return Ok((k, format!("{k} e⁻ per data unit (--electrons-per-unit)")));
    }
    let bunit = keys.text("BUNIT");
    if let Some(vp) = &planes.var_poisson {
        // Var = data/k for a Poisson count in data units: k from the pixels with signal
        let ratios: Vec<f64> = planes
            .sci
            .iter()
            .zip(vp)
            .zip(good)
            .filter(|((d, v), g)| **g && **d > 0.0 && **v > 0.0)
            .map(|((d, v), _)| *d as f64 / *v as f64)
            .collect();
        let k = median(ratios);
        if k > 0.0 && k.is_finite() {
            return Ok((
                k,
                format!(
                    "{k:.6} e⁻ per data unit ({}) from VAR_POISSON (median of data / VAR_POISSON)",
                    bunit.as_deref().map(str::trim).unwrap_or("BUNIT not given")
                ),
            ));
        }
    }
    let Some(raw) = bunit else {
        return Err(
            "no BUNIT header (nor VAR_POISSON plane): the data's unit is unknown; give --electrons-per-unit"
                .to_string(),
        );
    };
    let unit = DataUnit::parse(&raw).ok_or_else(|| {
        format!(
            "header BUNIT = '{}': not a unit jsim reads (ELECTRONS, COUNTS, DN, their rates …/S, MJy/sr or MJy); \
             give --electrons-per-unit",
            raw.trim()
        )
    })?;
    let need_gain = || {
        gain(keys).ok_or_else(|| {
            format!(
                "BUNIT = '{}' needs the gain: no GAIN, ATODGAIN, ATODGN[A-D] or CCDGAIN header; give \
                 --electrons-per-unit",
                raw.trim()
            )
        })
    };
    let need_exposure = || {
        exposure(keys).ok_or_else(|| {
            format!(
                "BUNIT = '{}' is a rate: no EXPTIME, XPOSURE or EFFEXPTM header > 0; give --electrons-per-unit",
                raw.trim()
            )
        })
    };
    let b = raw.trim();
    Ok(match unit {
        DataUnit::Electrons => (1.0, format!("BUNIT {b}: 1 e⁻ per data unit")),
        DataUnit::Counts => {
            let (g, from) = need_gain()?;
            (g, format!("BUNIT {b}: gain {g} e⁻/count from {from}"))
        }
        DataUnit::ElectronsPerS => {
            let (t, from) = need_exposure()?;
            (t, format!("BUNIT {b}: × {t} s ({from})"))
        }
        DataUnit::CountsPerS => {
            let (g, gfrom) = need_gain()?;
            let (t, tfrom) = need_exposure()?;
            (
                g * t,
                format!("BUNIT {b}: gain {g} e⁻/count from {gfrom} × {t} s ({tfrom})"),
            )
        }
        DataUnit::MjyPerSr | DataUnit::Mjy => {
            // a positive header number the unit needs, or an error naming it
            let need = |key: &str, what: &str| {
                keys.number(key)
                    .filter(|v| *v > 0.0 && v.is_finite())
                    .ok_or_else(|| {
                        format!("BUNIT = '{b}' needs {key} ({what}) > 0; give --electrons-per-unit")
                    })
            };
            let p = need("PHOTMJSR", "MJy/sr per count/s")?;
            let (g, gfrom) = need_gain()?;
            let (t, tfrom) = need_exposure()?;
            if unit == DataUnit::Mjy {
                // MJy in a pixel = MJy/sr × PIXAR_SR: divide it out first
                let a = need("PIXAR_SR", "the pixel's solid angle, sr")?;
                (
                    g * t / (p * a),
                    format!(
                        "BUNIT {b}: gain {g} ({gfrom}) × {t} s ({tfrom}) / PHOTMJSR {p} / PIXAR_SR {a:e}"
                    ),
                )
            } else {
                (
                    g * t / p,
                    format!("BUNIT {b}: gain {g} ({gfrom}) × {t} s ({tfrom}) / PHOTMJSR {p}"),
                )
            }
        }
    })
}

/// Where a chip's read noise came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReadNoiseSource {
    /// `--read-noise-e` (Python's `read_noise_e=`).
    Option,
    /// `RDNOISE` or `READNSE`.
    Header,
    /// `READNSE[A-D]` of the amplifiers `CCDAMP` names.
    Amplifiers,
    /// The `VAR_RNOISE` plane.
    VarRnoise,
    /// The `ERR` plane over the sky.
    ErrPlane,
}

/// The read noise, e⁻ (an rms over the pixels where amplifiers differ), where it came from, the report's
/// sentence, and each amplifier's (first column, e⁻) where several of different read noise read the chip.
type ReadNoise = (f64, ReadNoiseSource, String, Vec<(usize, f64)>);

/// The chip's read noise ([`ReadNoise`]).
fn read_noise_e(
    keys: &dyn Keys,
    planes: &ChipPlanes,
    good: &[bool],
    k: f64,
    opts: &ReadOptions,
) -> Result<ReadNoise, String> {
    if let Some(r) = opts.read_noise_e {
        return Ok((
            r,
            ReadNoiseSource::Option,
            format!("read noise {r} e⁻ (--read-noise-e)"),
            Vec::new(),
        ));
    }
    for key in ["RDNOISE", "READNSE"] {
        if let Some(r) = keys.number(key).filter(|v| *v >= 0.0 && v.is_finite()) {
            return Ok((
                r,
                ReadNoiseSource::Header,
                format!("read noise {r} e⁻ from {key}"),
                Vec::new(),
            ));
        }
    }
    let (amps, per_amp) = per_amplifier(keys, "READNSE");
    if let Some(cols) = amplifiers::columns(keys, planes.nx, &per_amp) {
        // each amplifier's own value on the columns it read; the rms over the chip's pixels reported
        let mut var = 0.0;
        let mut named = Vec::new();
        let firsts: Vec<(usize, (char, f64))> =
            cols.iter().map(|&(x0, a, r)| (x0, (a, r))).collect();
        for (x0, x1, (a, r)) in amplifiers::spans(&firsts, planes.nx) {
            var += r * r * (x1 - x0) as f64 / planes.nx as f64;
            named.push(format!(
                "READNSE{a} = {r} on columns {x0}–{}",
                x1.max(1) - 1
            ));
        }
        let rms = var.sqrt();
        let note = if cols.len() == 1 {
            format!(
                "read noise {} e⁻ from READNSE{} (the amplifier that read the chip)",
                cols[0].2, cols[0].1
            )
        } else {
            format!(
                "read noise per amplifier: {} (amplifiers {} of CCDAMP; rms {rms:.3} e⁻)",
                named.join(", "),
                amps.iter().collect::<String>()
            )
        };
        let per_column = if cols.len() > 1 {
            cols.iter().map(|c| (c.0, c.2)).collect()
        } else {
            Vec::new()
        };
        return Ok((rms, ReadNoiseSource::Amplifiers, note, per_column));
    }
    if !per_amp.is_empty() {
        let rms = (per_amp.iter().map(|p| p.1 * p.1).sum::<f64>() / per_amp.len() as f64).sqrt();
        let names: Vec<String> = per_amp
            .iter()
            .map(|p| format!("READNSE{} = {}", p.0, p.1))
            .collect();
        return Ok((
            rms,
            ReadNoiseSource::Amplifiers,
            format!(
                "read noise {rms:.3} e⁻: rms of {} (amplifiers {} of CCDAMP, whose columns this instrument \
                 does not state)",
                names.join(", "),
                amps.iter().collect::<String>()
            ),
            Vec::new(),
        ));
    }
    if let Some(vr) = &planes.var_rnoise {
        let m = median(
            vr.iter()
                .zip(good)
                .filter(|(_, g)| **g)
                .map(|(v, _)| *v as f64)
                .collect(),
        );
        if m >= 0.0 {
            let r = m.sqrt() * k;
            return Ok((
                r,
                ReadNoiseSource::VarRnoise,
                format!("read noise {r:.3} e⁻ from VAR_RNOISE (√median × e⁻ per unit)"),
                Vec::new(),
            ));
        }
    }
    if let Some(e) = &planes.err
        && let Some(r) = read_noise_from_err(&planes.sci, e, good, k)
    {
        return Ok((
            r,
            ReadNoiseSource::ErrPlane,
            format!(
                "read noise {r:.3} e⁻ from the ERR plane: √median((k·ERR)² − k·data) over the sky pixels"
            ),
            Vec::new(),
        ));
    }
    Err("no read noise: no RDNOISE, READNSE, READNSE[A-D] (with CCDAMP), VAR_RNOISE or ERR plane; give --read-noise-e"
        .to_string())
}

/// The read noise (e⁻) an ERR plane implies over the sky: the pixels at or below the image's median, where
/// ERR² (data units²) = σ_RN²/k² + data/k, so σ_RN² = median((k·ERR)² − k·data). `None` with too few pixels.
pub fn read_noise_from_err(sci: &[f32], err: &[f32], good: &[bool], k: f64) -> Option<f64> {
    let level = median(
        sci.iter()
            .zip(good)
            .filter(|(_, g)| **g)
            .map(|(v, _)| *v as f64)
            .collect(),
    );
    let v: Vec<f64> = sci
        .iter()
        .zip(err)
        .zip(good)
        .filter(|((d, e), g)| **g && (**d as f64) <= level && e.is_finite() && **e > 0.0)
        .map(|((d, e), _)| (k * *e as f64).powi(2) - k * (*d as f64).max(0.0))
        .collect();
    if v.len() < 100 {
        return None;
    }
    Some(median(v).max(0.0).sqrt())
}

/// A raw frame's saturation level (data units, before the bias is taken off) and where it came from:
/// `--saturate-units`, else the header's `SATURATE` (the ground-based convention).
fn saturation_level(keys: &dyn Keys, opts: &ReadOptions) -> Option<(f64, &'static str)> {
    match opts.saturate_units {
        Some(v) => Some((v, "--saturate-units")),
        None => keys
            .number("SATURATE")
            .filter(|v| *v > 0.0 && v.is_finite())
            .map(|v| (v, "SATURATE")),
    }
}

/// The pixels masked and why, each counted once.
struct Mask {
    bad: Vec<bool>,
    /// Flagged by a DQ bit outside the ignored ones, of which with a saturation bit.
    n_flagged: usize,
    n_saturated: usize,
    n_non_finite: usize,
    /// At or above the saturation level and not flagged otherwise.
    n_at_level: usize,
}

/// Mask the non-finite pixels, those whose DQ has a bit outside `ignore`, and those at or above `level`.
fn mask_pixels(planes: &ChipPlanes, ignore: u64, saturated_bits: u64, level: Option<f64>) -> Mask {
    let n = planes.nx * planes.ny;
    let mut m = Mask {
        bad: vec![false; n],
        n_flagged: 0,
        n_saturated: 0,
        n_non_finite: 0,
        n_at_level: 0,
    };
    for i in 0..n {
        if !planes.sci[i].is_finite() {
            m.bad[i] = true;
            m.n_non_finite += 1;
        }
        if let Some(dq) = &planes.dq
            && dq[i] & !ignore != 0
        {
            m.bad[i] = true;
            m.n_flagged += 1;
            if dq[i] & saturated_bits != 0 {
                m.n_saturated += 1;
            }
        }
        // counted once: a pixel masked already is not counted again
        if let Some(level) = level
            && planes.sci[i] as f64 >= level
            && !m.bad[i]
        {
            m.bad[i] = true;
            m.n_at_level += 1;
        }
    }
    m
}

/// A chip's planes turned into electrons, a mask, a read noise and a plate scale, with every choice stated.
pub fn calibrate(
    keys: &dyn Keys,
    planes: ChipPlanes,
    opts: &ReadOptions,
) -> Result<CalibratedChip, String> {
    let n = planes.nx * planes.ny;
    let obs = Observatory::from_header(
        keys.text("TELESCOP").as_deref(),
        keys.text("INSTRUME").as_deref(),
    );
    let saturated_bits = obs.saturated_bits();
    let ignore = opts.dq_ignore.unwrap_or(obs.default_dq_ignore());
    let mut notes = Vec::new();
    let saturate = saturation_level(keys, opts);
    let Mask {
        bad,
        n_flagged,
        mut n_saturated,
        n_non_finite,
        n_at_level,
    } = mask_pixels(&planes, ignore, saturated_bits, saturate.map(|s| s.0));
    let good: Vec<bool> = bad.iter().map(|b| !b).collect();
    if n > 0 && good.iter().all(|g| !g) {
        return Err(format!(
            "every pixel is masked ({n_flagged} by DQ, {n_non_finite} not finite; DQ bits not masking a pixel: {}): \
             nothing to analyse (--dq-ignore BITS keeps pixels whose flags are harmless)",
            describe_bits(ignore, opts.dq_ignore.is_some())
        ));
    }
    if let Some(e) = &planes.err
        && let Some(i) = (0..n).find(|&i| good[i] && !(e[i].is_finite() && e[i] > 0.0))
    {
        let count = (0..n)
            .filter(|&i| good[i] && !(e[i].is_finite() && e[i] > 0.0))
            .count();
        return Err(format!(
            "ERR: {count} unmasked pixel(s) with an error that is zero, negative or not a number (the first at x {}, \
             y {}): a calibrated ERR plane is > 0 wherever the DQ plane lets a pixel through",
            i % planes.nx,
            i / planes.nx
        ));
    }
    let mut planes = planes;
    if let Some(bias) = opts.bias_units {
        for v in planes.sci.iter_mut() {
            *v -= bias as f32;
        }
        notes.push(format!("bias {bias} data units subtracted (--bias-units)"));
    }
    let (k, k_note) = electrons_per_unit(keys, &planes, &good, opts)?;
    if !(k > 0.0 && k.is_finite()) {
        return Err(format!("{k} e⁻ per data unit: must be a finite number > 0"));
    }
    notes.push(k_note);
    let (rn, rn_source, rn_note, rn_columns) = read_noise_e(keys, &planes, &good, k, opts)?;
    if !(rn >= 0.0 && rn.is_finite()) {
        return Err(format!("read noise {rn} e⁻: must be a finite number ≥ 0"));
    }
    notes.push(rn_note);
    // the ERR plane as a check on a read noise taken from elsewhere
    if let Some(e) = &planes.err
        && rn_source != ReadNoiseSource::ErrPlane
        && let Some(r) = read_noise_from_err(&planes.sci, e, &good, k)
    {
        notes.push(format!(
            "(the ERR plane implies {r:.3} e⁻ of read noise over the sky)"
        ));
    }
    let dq_note = match &planes.dq {
        Some(_) => format!(
            "DQ: {n_flagged} flagged pixel(s) masked ({n_saturated} saturated); bits not masking a pixel: {}",
            describe_bits(ignore, opts.dq_ignore.is_some())
        ),
        None => "no DQ plane: only non-finite pixels masked".to_string(),
    };
    notes.push(dq_note);
    if n_non_finite > 0 {
        notes.push(format!(
            "{n_non_finite} non-finite (NaN or infinite) pixel(s) masked"
        ));
    }
    if let Some((level, from)) = saturate {
        n_saturated += n_at_level;
        notes.push(format!(
            "{n_at_level} pixel(s) at or above the saturation level {level} data units ({from}) masked \
             as saturated"
        ));
    }
    let plate = plate_scale_mas(keys);
    if let Some((s, from)) = plate {
        notes.push(format!("plate scale {s:.4} mas/px from {from}"));
    }
    // the sentence on RA/Dec is the reader's (`read_chip`), once it knows the distortion tables jsim applies
    let wcs = match chip_wcs(keys, [planes.nx, planes.ny]) {
        Ok(w) => Some(w),
        Err(why) => {
            notes.push(why);
            None
        }
    };
    Ok(CalibratedChip {
        nx: planes.nx,
        ny: planes.ny,
        electrons: planes
            .sci
            .iter()
            .map(|v| if v.is_finite() { *v as f64 * k } else { 0.0 })
            .collect(),
        bad,
        read_noise_e: rn,
        read_noise_columns_e: rn_columns,
        plate_scale_mas: plate.map(|p| p.0),
        electrons_per_unit: k,
        n_flagged,
        n_saturated,
        n_non_finite,
        wcs,
        notes,
    })
}

/// The ignored DQ bits, for the report.
fn describe_bits(ignore: u64, given: bool) -> String {
    let source = if given {
        "--dq-ignore"
    } else {
        "the pipeline's default"
    };
    if ignore == 0 {
        return format!("none ({source})");
    }
    if ignore.count_ones() > 32 {
        let masking: Vec<String> = (0..64)
            .filter(|b| ignore & (1 << b) == 0)
            .map(|b| (1u64 << b).to_string())
            .collect();
        return format!("all but {} ({source})", masking.join(", "));
    }
    let bits: Vec<String> = (0..64)
        .filter(|b| ignore & (1 << b) != 0)
        .map(|b| (1u64 << b).to_string())
        .collect();
    format!("{} ({source})", bits.join(", "))
}

/// Parse `--dq-ignore`: bit values (powers of two) or their sums, separated by commas or `+`; `~N` for every
/// bit but those of N.
pub fn parse_dq_bits(s: &str) -> Result<u64, String> {
    let t = s.trim();
    if let Some(rest) = t.strip_prefix('~') {
        return parse_dq_bits(rest).map(|b| !b);
    }
    let mut bits = 0u64;
    for part in t.split([',', '+']).map(str::trim).filter(|p| !p.is_empty()) {
        bits |= part.parse::<u64>().map_err(|_| {
            format!("--dq-ignore '{s}': '{part}' is not a bit value (allowed: integers ≥ 0, e.g. 4096,8192 or ~1)")
        })?;
    }
    Ok(bits)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    struct MapKeys(HashMap<&'static str, &'static str>);
    impl Keys for MapKeys {
        fn number(&self, key: &str) -> Option<f64> {
            self.0.get(key).and_then(|v| v.parse().ok())
        }
        fn text(&self, key: &str) -> Option<String> {
            self.0.get(key).map(|s| s.to_string())
        }
    }

    #[test]
    fn units_are_read_in_the_forms_the_pipelines_write() {
        use DataUnit::*;
        for (s, u) in [
            ("ELECTRONS", Some(Electrons)),
            ("electrons/s", Some(ElectronsPerS)),
            ("COUNTS/S", Some(CountsPerS)),
            ("DN/s", Some(CountsPerS)),
            ("counts", Some(Counts)),
            ("MJy/sr", Some(MjyPerSr)),
            ("MJy", Some(Mjy)),
            ("Jy", None),
            ("ELECTRONS/HOUR", None),
        ] {
            assert_eq!(DataUnit::parse(s), u, "{s}");
        }
    }

    #[test]
    fn dq_bits_parse_as_lists_sums_and_complements() {
        assert_eq!(parse_dq_bits("4096,8192"), Ok(12288));
        assert_eq!(parse_dq_bits("4+64"), Ok(68));
        assert_eq!(parse_dq_bits("~1"), Ok(!1));
        assert!(
            parse_dq_bits("cosmic")
                .expect_err("an error")
                .contains("--dq-ignore")
        );
    }

    /// A synthetic chip in counts per second with a known gain, exposure and read noise: the electrons, the
    /// read noise from READNSE and from the ERR plane (independent of the header), and the masks.
    #[test]
    fn a_rate_image_in_counts_becomes_electrons_with_its_read_noise_and_mask() {
        let (nx, ny) = (64, 64);
        let (g, t, rn) = (2.0, 100.0, 5.0);
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = crate::rng::stream(3, crate::rng::Stream::Test, 0);
        let mut z = move || -> f64 { StandardNormal.sample(&mut rng) };
        let sky_e = 40.0;
        let mut sci = Vec::new();
        let mut err_plane = Vec::new();
        let mut dq = vec![0u64; nx * ny];
        for i in 0..nx * ny {
            let e = sky_e + rn * z() + sky_e.sqrt() * z();
            sci.push((e / g / t) as f32);
            // what a pipeline writes: √(RN² + signal) in the data's unit
            err_plane.push(((rn * rn + e.max(0.0)).sqrt() / g / t) as f32);
            if i % 97 == 0 {
                dq[i] = 256;
            }
        }
        dq[5] = 4096;
        let keys = MapKeys(HashMap::from([
            ("TELESCOP", "HST"),
            ("BUNIT", "COUNTS/S"),
            ("ATODGAIN", "2.0"),
            ("EXPTIME", "100.0"),
            ("CCDAMP", "C"),
            ("READNSEA", "0.0"),
            ("READNSEC", "5.0"),
            ("CD1_1", "-7.0e-6"),
            ("CD2_2", "7.0e-6"),
        ]));
        let planes = ChipPlanes {
            nx,
            ny,
            sci: sci.clone(),
            err: Some(err_plane.clone()),
            dq: Some(dq.clone()),
            ..Default::default()
        };
        let c = calibrate(&keys, planes.clone(), &ReadOptions::default()).expect("ok");
        assert!((c.electrons_per_unit - g * t).abs() < 1e-12);
        assert!((c.electrons[1] - sci[1] as f64 * g * t).abs() < 1e-9);
        assert_eq!(c.read_noise_e, 5.0);
        assert_eq!(
            c.n_flagged,
            (0..nx * ny).filter(|i| i % 97 == 0).count() + 1
        );
        assert_eq!(c.n_saturated, c.n_flagged - 1);
        assert!(c.bad[0] && c.bad[5] && !c.bad[1]);
        assert!((c.plate_scale_mas.expect("ok") - 7.0e-6 * 3.6e6).abs() < 1e-9);
        // the ERR plane alone: within 3 % of the true read noise (its median over ~2000 sky pixels)
        let no_rn = MapKeys(HashMap::from([
            ("BUNIT", "COUNTS/S"),
            ("GAIN", "2.0"),
            ("EXPTIME", "100"),
        ]));
        let c2 = calibrate(&no_rn, planes.clone(), &ReadOptions::default()).expect("ok");
        assert!(
            (c2.read_noise_e - rn).abs() < 0.03 * rn,
            "{}",
            c2.read_noise_e
        );
        // ignoring the CR bit unmasks that pixel alone
        let opts = ReadOptions {
            dq_ignore: Some(4096),
            ..Default::default()
        };
        let c3 = calibrate(&keys, planes.clone(), &opts).expect("ok");
        assert!(!c3.bad[5] && c3.bad[0]);
        // a unit the header does not give is a named error, with the override named
        let bare = MapKeys(HashMap::new());
        let e = calibrate(&bare, planes, &ReadOptions::default()).expect_err("an error");
        assert!(
            e.contains("BUNIT") && e.contains("--electrons-per-unit"),
            "{e}"
        );
    }

    /// JWST's MJy/sr with VAR_POISSON and VAR_RNOISE: the electrons per unit and the read noise come back
    /// from the variance planes, and only DO_NOT_USE masks by default.
    #[test]
    fn a_jwst_image_in_mjy_per_sr_is_converted_through_its_variance_planes() {
        let (nx, ny) = (40, 40);
        let k = 1234.5; // e⁻ per MJy/sr
        let rn = 12.0;
        let mut sci = Vec::new();
        let mut vp = Vec::new();
        let mut vr = Vec::new();
        for i in 0..nx * ny {
            let e = 500.0 + i as f64;
            sci.push((e / k) as f32);
            vp.push((e / (k * k)) as f32);
            vr.push((rn * rn / (k * k)) as f32);
        }
        let mut dq = vec![0u64; nx * ny];
        dq[0] = 1;
        dq[1] = 4; // JUMP_DET: kept
        let keys = MapKeys(HashMap::from([("TELESCOP", "JWST"), ("BUNIT", "MJy/sr")]));
        let c = calibrate(
            &keys,
            ChipPlanes {
                nx,
                ny,
                sci,
                dq: Some(dq),
                var_poisson: Some(vp),
                var_rnoise: Some(vr),
                ..Default::default()
            },
            &ReadOptions::default(),
        )
        .expect("ok");
        assert!(
            (c.electrons_per_unit / k - 1.0).abs() < 1e-5,
            "{}",
            c.electrons_per_unit
        );
        assert!(
            (c.read_noise_e / rn - 1.0).abs() < 1e-5,
            "{}",
            c.read_noise_e
        );
        assert!(c.bad[0] && !c.bad[1]);
        assert_eq!(c.n_flagged, 1);
    }

    /// A surface brightness in MJy/sr and the same image in MJy per pixel (× PIXAR_SR): through PHOTMJSR,
    /// the gain and the exposure both give the electrons a count rate of 1 DN/s worked by hand holds; without
    /// PIXAR_SR the per-pixel unit is a named error.
    #[test]
    fn mjy_per_pixel_is_mjy_per_sr_times_the_pixel_solid_angle() {
        let (g, t, photmjsr, pixar) = (1.6, 300.0, 0.25, 2.3e-13);
        let rate_dn_s = 1.0;
        let per_sr = rate_dn_s * photmjsr; // MJy/sr of 1 DN/s
        for (bunit, value) in [("MJy/sr", per_sr), ("MJy", per_sr * pixar)] {
            let keys = MapKeys(HashMap::from([
                ("BUNIT", bunit),
                ("GAIN", "1.6"),
                ("EXPTIME", "300.0"),
                ("PHOTMJSR", "0.25"),
                ("PIXAR_SR", "2.3e-13"),
                ("RDNOISE", "5.0"),
            ]));
            let c = calibrate(
                &keys,
                ChipPlanes {
                    nx: 2,
                    ny: 2,
                    sci: vec![value as f32; 4],
                    ..Default::default()
                },
                &ReadOptions::default(),
            )
            .expect("ok");
            let want_e = rate_dn_s * t * g;
            assert!(
                (c.electrons[0] / want_e - 1.0).abs() < 1e-6,
                "{bunit}: {} e⁻ against {want_e}",
                c.electrons[0]
            );
        }
        let no_area = MapKeys(HashMap::from([
            ("BUNIT", "MJy"),
            ("GAIN", "1.6"),
            ("EXPTIME", "300.0"),
            ("PHOTMJSR", "0.25"),
        ]));
        let e = calibrate(
            &no_area,
            ChipPlanes {
                nx: 2,
                ny: 2,
                sci: vec![1.0; 4],
                ..Default::default()
            },
            &ReadOptions::default(),
        )
        .expect_err("no PIXAR_SR");
        assert!(e.contains("needs PIXAR_SR"), "{e}");
    }

    /// A raw frame: its bias (given) comes off before the gain, its pixels at the saturation level (given, or
    /// the header's SATURATE) are masked and counted once, a DQ-flagged one not again.
    #[test]
    fn a_raw_frames_bias_comes_off_and_its_saturated_pixels_are_masked() {
        let (nx, ny) = (4, 4);
        let mut sci = vec![2148.0f32; nx * ny];
        sci[3] = 13583.0;
        sci[7] = 13600.0;
        sci[9] = 13583.0;
        let mut dq = vec![0u64; nx * ny];
        dq[9] = 2;
        let keys = MapKeys(HashMap::from([("SATURATE", "13583")]));
        let planes = ChipPlanes {
            nx,
            ny,
            sci,
            dq: Some(dq),
            ..Default::default()
        };
        let opts = ReadOptions {
            electrons_per_unit: Some(0.5),
            read_noise_e: Some(5.0),
            bias_units: Some(2048.0),
            ..Default::default()
        };
        let c = calibrate(&keys, planes.clone(), &opts).expect("ok");
        assert_eq!(c.electrons[0], 50.0, "(2148 − 2048) × 0.5");
        assert!(c.bad[3] && c.bad[7] && c.bad[9] && !c.bad[0]);
        // pixel 9 is DQ-flagged: masked once, counted as flagged, not again at the level
        assert_eq!((c.n_flagged, c.n_saturated), (1, 2));
        assert!(
            c.notes.iter().any(|n| n.contains("bias 2048")),
            "{:?}",
            c.notes
        );
        assert!(
            c.notes.iter().any(|n| n.contains(
                "2 pixel(s) at or above the saturation level 13583 data units (SATURATE)"
            )),
            "{:?}",
            c.notes
        );
        // the option replaces the header's level
        let c = calibrate(
            &keys,
            planes,
            &ReadOptions {
                saturate_units: Some(13590.0),
                ..opts
            },
        )
        .expect("ok");
        assert!(!c.bad[3] && c.bad[7]);
    }
}
