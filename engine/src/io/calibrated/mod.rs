//! Calibrated images of other observatories: the multi-extension files of HST and JWST (and any file laid out
//! the same way), read into electrons with a mask, a read noise and a plate scale, each choice written down.
//!
//! The layout (the "imset" convention of HST's `_flt` / `_flc` and JWST's `_cal` / `_rate` products): an
//! empty primary header, then per detector chip a `SCI` image with its `ERR` and `DQ` planes (JWST also
//! `VAR_POISSON`, `VAR_RNOISE`), the chips told apart by `EXTVER`. Keywords are looked up in the `SCI`
//! header first, then the primary's (the `INHERIT = T` convention).
//!
//! What is read, in order of precedence (each used value is stated in the report):
//! - **Electrons per data unit** `k`: `--electrons-per-unit`; else the `VAR_POISSON` plane, whose ratio to the
//!   data is `1/k` for every pixel with signal (variance of a Poisson count in data units = data/k); else from
//!   `BUNIT`: ELECTRONS → 1; COUNTS / DN → the gain; a rate (…/S) → times the exposure; MJy/sr → gain ×
//!   exposure / `PHOTMJSR`. The gain is `GAIN`, `ATODGAIN`, the mean of `ATODGN{A–D}` over the amplifiers in
//!   `CCDAMP`, or the nominal `CCDGAIN`, in that order.
//! - **Read noise** (e⁻): `--read-noise-e`; else `RDNOISE` or `READNSE` (STIS); else the rms of `READNSE{A–D}` over the
//!   amplifiers in `CCDAMP`; else √median(`VAR_RNOISE`)·k; else from the `ERR` plane of the sky pixels:
//!   σ_RN² = median((k·ERR)² − k·data).
//! - **Data quality**: a pixel is masked when its DQ value has a bit outside the ignored ones. The default
//!   follows each pipeline: HST masks every flagged pixel (AstroDrizzle's `final_bits = 0`); JWST only
//!   `DO_NOT_USE` (1) and `NON_SCIENCE` (512), as the JWST pipeline's resampling does
//!   (`good_bits = "~DO_NOT_USE+NON_SCIENCE"`). `--dq-ignore` replaces the default. Non-finite values are
//!   masked too. Saturated pixels (HST bits 256 and 2048, JWST bit 2) are counted apart.
//! - **Plate scale**: `PLTSCALE`; else √|det CD| (or of `CDELT`·`PC`) of the chip's WCS.
//!
//! HST's older waivered layout (WFPC2's `_c0f.fits`: the chips as planes of one cube) is read by [`waivered`].
//! A file without `SCI` extensions has each image extension as a chip (a tile-compressed `.fz` frame, a
//! ground-based mosaic's amplifiers); a raw frame's bias (`--bias-units`) comes off first, and its pixels at
//! the saturation level (`--saturate-units`, else `SATURATE`) are masked. The header's lookup-table
//! distortions are read by [`lookup_tables`].

mod amplifiers;
mod header_wcs;
mod lookup_tables;
mod units;
pub mod waivered;

use header_wcs::MAX_SIP_ORDER;
pub use header_wcs::{ChipWcs, chip_wcs, plate_scale_mas, same_pointing};
pub use units::{DataUnit, Observatory, calibrate, parse_dq_bits, read_noise_from_err};

use super::IoError;
use crate::formats::fits_reader::Reader;
use std::path::Path;

/// One chip of a calibrated file: the HDU indices (0 = primary) of its planes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Imset {
    /// The chips' `EXTVER` (1 when absent).
    pub extver: i64,
    pub sci: usize,
    pub err: Option<usize>,
    pub dq: Option<usize>,
    pub var_poisson: Option<usize>,
    pub var_rnoise: Option<usize>,
    /// The plane of the primary cube, for a waivered file ([`waivered`]); `None` for an imset.
    pub group: Option<usize>,
    /// The chip's `EXTNAME`: `SCI` for an imset; a file without `SCI` extensions has each image extension
    /// as a chip, named as it is (empty when unnamed, as in a tile-compressed `.fz` file's image).
    pub extname: String,
}

impl Imset {
    /// `SCI,1`: how astronomers name the chip (FITS `EXTNAME,EXTVER`); `GROUP1` for a waivered file's.
    pub fn name(&self) -> String {
        match self.group {
            Some(_) => self.dir_name(),
            None if self.extname.is_empty() => self.dir_name(),
            None => format!("{},{}", self.extname, self.extver),
        }
    }
    /// The chip's number (the combined catalogue's `array` column, Python's `chip=`): its `EXTVER` (the
    /// group's for a waivered file); for a file of image extensions, which may share one `EXTVER`, the
    /// HDU's index (0: the primary).
    pub fn number(&self) -> i64 {
        if self.group.is_none() && self.extname != "SCI" {
            self.sci as i64
        } else {
            self.extver
        }
    }
    /// `SCI1` (`GROUP1`; `HDU1` for an unnamed extension): the chip's name as a directory name.
    pub fn dir_name(&self) -> String {
        match self.group {
            Some(_) => format!("GROUP{}", self.extver),
            None if self.extname.is_empty() => format!("HDU{}", self.sci),
            None => {
                let name: String = self
                    .extname
                    .chars()
                    .filter(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                format!("{name}{}", self.extver)
            }
        }
    }
}

/// What the command line may say in place of, or beyond, the header.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReadOptions {
    /// Electrons per data unit (overrides BUNIT, the gain and VAR_POISSON).
    pub electrons_per_unit: Option<f64>,
    /// Read noise of a pixel, e⁻ (overrides the header and the noise planes).
    pub read_noise_e: Option<f64>,
    /// DQ bits that do not mask a pixel (replaces the pipeline's default).
    pub dq_ignore: Option<u64>,
    /// A raw frame's bias, data units, subtracted before anything else (a calibrated file has none left).
    pub bias_units: Option<f64>,
    /// The level, data units (before the bias is taken off), at and above which a pixel is saturated and
    /// masked (overrides the header's `SATURATE`).
    pub saturate_units: Option<f64>,
}

/// A [`ReadOptions`] value out of its range: the field (as the struct names it), the value and the rule.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadOptionError {
    pub field: &'static str,
    pub value: f64,
    pub rule: &'static str,
}

impl ReadOptions {
    /// Each value given within its range: the gain and the saturation level finite and > 0, the read noise
    /// finite and ≥ 0 e⁻, the bias finite. The CLI and Python name the field in their own spelling.
    pub fn validate(&self) -> Result<(), ReadOptionError> {
        let checks: [(&'static str, Option<f64>, fn(f64) -> bool, &'static str); 4] = [
            (
                "electrons_per_unit",
                self.electrons_per_unit,
                |v| v > 0.0,
                "must be a finite number > 0",
            ),
            (
                "read_noise_e",
                self.read_noise_e,
                |v| v >= 0.0,
                "must be a finite number ≥ 0 [e-]",
            ),
            (
                "bias_units",
                self.bias_units,
                |_| true,
                "must be a finite number",
            ),
            (
                "saturate_units",
                self.saturate_units,
                |v| v > 0.0,
                "must be a finite number > 0",
            ),
        ];
        for (field, value, ok, rule) in checks {
            if let Some(v) = value
                && !(v.is_finite() && ok(v))
            {
                return Err(ReadOptionError {
                    field,
                    value: v,
                    rule,
                });
            }
        }
        Ok(())
    }
}

/// A header's values as the reader looks them up (the chip's header, then the primary).
pub trait Keys {
    fn number(&self, key: &str) -> Option<f64>;
    fn text(&self, key: &str) -> Option<String>;
}

/// What was read of a chip, for the report (`summary.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChipFacts {
    pub electrons_per_unit: f64,
    pub read_noise_e: f64,
    pub n_flagged: usize,
    pub n_saturated: usize,
    pub n_non_finite: usize,
    /// The header's WCS (TAN, SIP): the catalogue's RA/Dec come through it.
    #[serde(skip)]
    pub wcs: Option<ChipWcs>,
}

/// A chip read into electrons, with what was used and how.
#[derive(Debug, Clone)]
pub struct CalibratedChip {
    pub nx: usize,
    pub ny: usize,
    pub electrons: Vec<f64>,
    pub bad: Vec<bool>,
    /// The read noise, e⁻: where amplifiers of different read noise read the chip, their rms over its
    /// pixels.
    pub read_noise_e: f64,
    /// Where amplifiers of different read noise read the chip: (first column, e⁻) of each, in column
    /// order; empty where one value holds for every pixel.
    pub read_noise_columns_e: Vec<(usize, f64)>,
    /// From `PLTSCALE` or the WCS; `None` when the header has neither.
    pub plate_scale_mas: Option<f64>,
    pub electrons_per_unit: f64,
    /// Pixels masked by their DQ value, of which saturated, and non-finite values.
    pub n_flagged: usize,
    pub n_saturated: usize,
    pub n_non_finite: usize,
    pub wcs: Option<ChipWcs>,
    /// Each value used and where it came from, one sentence each.
    pub notes: Vec<String>,
}

impl CalibratedChip {
    /// Each pixel's read noise squared, e⁻², where amplifiers of different read noise read the chip.
    pub fn read_noise_map_e2(&self) -> Option<Vec<f64>> {
        if self.read_noise_columns_e.len() < 2 {
            return None;
        }
        let mut row = vec![0.0; self.nx];
        for (x0, x1, r) in amplifiers::spans(&self.read_noise_columns_e, self.nx) {
            for v in &mut row[x0..x1] {
                *v = r * r;
            }
        }
        Some((0..self.ny).flat_map(|_| row.iter().copied()).collect())
    }

    /// What was read, without the pixels.
    pub fn facts(&self) -> ChipFacts {
        ChipFacts {
            electrons_per_unit: self.electrons_per_unit,
            read_noise_e: self.read_noise_e,
            n_flagged: self.n_flagged,
            n_saturated: self.n_saturated,
            n_non_finite: self.n_non_finite,
            wcs: self.wcs.clone(),
        }
    }
}

/// The planes of one chip as read, before the header's facts are applied.
#[derive(Debug, Clone, Default)]
pub struct ChipPlanes {
    pub nx: usize,
    pub ny: usize,
    pub sci: Vec<f32>,
    pub err: Option<Vec<f32>>,
    pub dq: Option<Vec<u64>>,
    pub var_poisson: Option<Vec<f32>>,
    pub var_rnoise: Option<Vec<f32>>,
}

/// The HDU's header values: its own cards, then the primary's.
pub(super) struct HduKeys {
    numbers: std::collections::HashMap<String, f64>,
    texts: std::collections::HashMap<String, String>,
}

impl Keys for HduKeys {
    fn number(&self, key: &str) -> Option<f64> {
        self.numbers.get(key).copied()
    }
    fn text(&self, key: &str) -> Option<String> {
        self.texts.get(key).cloned()
    }
}

/// The keys the reader looks up.
pub(super) fn wanted_keys() -> Vec<String> {
    let mut k: Vec<String> = [
        "BUNIT", "TELESCOP", "INSTRUME", "GAIN", "ATODGAIN", "CCDGAIN", "CCDAMP", "RDNOISE",
        "READNSE", "EXPTIME", "XPOSURE", "EFFEXPTM", "PHOTMJSR", "PIXAR_SR", "PLTSCALE", "CD1_1",
        "CD1_2", "CD2_1", "CD2_2", "CDELT1", "CDELT2", "PC1_1", "PC1_2", "PC2_1", "PC2_2",
        "CTYPE1", "CTYPE2", "CRPIX1", "CRPIX2", "CRVAL1", "CRVAL2", "A_ORDER", "B_ORDER",
        "SATURATE",
        // which lookup-table distortions the header states (lookup_tables reads their record cards)
        "CPDIS1", "CPDIS2", "D2IMDIS1", "D2IMDIS2",
        // which amplifiers read which columns (amplifiers)
        "DETECTOR", "CCDCHIP", "LTV1",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for name in ["A", "B"] {
        for p in 0..=MAX_SIP_ORDER {
            for q in 0..=MAX_SIP_ORDER - p {
                if p + q >= 2 {
                    k.push(format!("{name}_{p}_{q}"));
                }
            }
        }
    }
    for a in ['A', 'B', 'C', 'D'] {
        k.push(format!("ATODGN{a}"));
        k.push(format!("READNSE{a}"));
    }
    k
}

/// The chips of a calibrated file: its `SCI` extensions grouped with their planes by `EXTVER`, in order, or a
/// waivered file's cube planes ([`waivered::groups`]). Empty when the file has neither.
pub fn imsets(path: &Path) -> Result<Vec<Imset>, IoError> {
    let sets = sci_imsets(path)?;
    if sets.is_empty() {
        return waivered::groups(path);
    }
    Ok(sets)
}

/// The `SCI` extensions of a file with their planes.
fn sci_imsets(path: &Path) -> Result<Vec<Imset>, IoError> {
    // a chip and its planes are 2-D; 1-D images (distortion tables) are never one
    let found: Vec<(String, i64, usize)> = Reader::open(path)?
        .image_extensions()
        .into_iter()
        .filter(|e| e.axes == 2)
        .map(|e| (e.name, e.version, e.index))
        .collect();
    let at = |n: &str, v: i64| {
        found
            .iter()
            .find(|(m, w, _)| m == n && *w == v)
            .map(|x| x.2)
    };
    if !found.iter().any(|(n, _, _)| n == "SCI") {
        // no imset: each image extension that is not a known companion plane is a chip of its own (a
        // tile-compressed `.fz` image, a ground-based mosaic's amplifiers), with no ERR or DQ
        return Ok(found
            .iter()
            .filter(|(n, _, _)| !COMPANION_PLANES.contains(&n.as_str()))
            .map(|(n, v, i)| Imset {
                extver: *v,
                sci: *i,
                err: None,
                dq: None,
                var_poisson: None,
                var_rnoise: None,
                group: None,
                extname: n.clone(),
            })
            .collect());
    }
    Ok(found
        .iter()
        .filter(|(n, _, _)| n == "SCI")
        .map(|(_, v, i)| Imset {
            extver: *v,
            sci: *i,
            err: at("ERR", *v),
            dq: at("DQ", *v),
            var_poisson: at("VAR_POISSON", *v),
            var_rnoise: at("VAR_RNOISE", *v),
            group: None,
            extname: "SCI".into(),
        })
        .collect())
}

/// Extensions that are planes of a chip, never a chip: the imsets', common weight, mask and context maps,
/// and distortion tables.
const COMPANION_PLANES: [&str; 12] = [
    "ERR",
    "DQ",
    "VAR_POISSON",
    "VAR_RNOISE",
    "VAR_FLAT",
    "WHT",
    "CTX",
    "CON",
    "MASK",
    "BPM",
    // HST's lookup-table distortions (lookup_tables)
    "D2IMARR",
    "WCSDVARR",
];

/// Whether the primary HDU holds a 2-D image (jsim's single-array files and any plain image).
pub fn primary_is_image(path: &Path) -> Result<bool, IoError> {
    Ok(Reader::open(path)?.plane_shape(0)?.is_some())
}

/// Read chip `set` of `path` into electrons ([`calibrate`]).
pub fn read_chip(path: &Path, set: &Imset, opts: &ReadOptions) -> Result<CalibratedChip, IoError> {
    if set.group.is_some() {
        return waivered::read_group(path, set, opts);
    }
    let mut f = Reader::open(path)?;
    let wanted = wanted_keys();
    let mut numbers = std::collections::HashMap::new();
    let mut texts = std::collections::HashMap::new();
    // the primary first, so that the chip's own cards replace its
    for i in [0, set.sci] {
        f.image_shape(i)?; // the HDU is there
        for k in &wanted {
            if let Some(v) = f.key_f64(i, k) {
                numbers.insert(k.clone(), v);
            }
            if let Some(v) = f.key_string(i, k) {
                texts.insert(k.clone(), v);
            }
        }
    }
    let keys = HduKeys { numbers, texts };
    let (nx, ny) = f
        .plane_shape(set.sci)?
        .ok_or_else(|| IoError::fits(path, format!("{} is not a 2-D image", set.name())))?;
    let sci = f.image::<f32>(set.sci)?;
    // a companion plane must have SCI's shape
    let same_shape = |f: &mut Reader, i: usize, what: &str| -> Result<(), IoError> {
        if f.plane_shape(i)? != Some((nx, ny)) {
            return Err(IoError::fits(
                path,
                format!("{what},{} is not {nx}×{ny} like SCI", set.extver),
            ));
        }
        Ok(())
    };
    let mut plane_f32 = |i: Option<usize>, what: &str| -> Result<Option<Vec<f32>>, IoError> {
        let Some(i) = i else { return Ok(None) };
        same_shape(&mut f, i, what)?;
        Ok(Some(f.image::<f32>(i)?))
    };
    let err = plane_f32(set.err, "ERR")?;
    let var_poisson = plane_f32(set.var_poisson, "VAR_POISSON")?;
    let var_rnoise = plane_f32(set.var_rnoise, "VAR_RNOISE")?;
    let dq = match set.dq {
        Some(i) => {
            same_shape(&mut f, i, "DQ")?;
            // a 16-bit DQ read as a signed integer keeps its bits in the low 16
            let v = f.image::<i64>(i)?;
            Some(v.into_iter().map(|q| (q as u64) & 0xffff_ffff).collect())
        }
        None => None,
    };
    let mut chip = calibrate(
        &keys,
        ChipPlanes {
            nx,
            ny,
            sci,
            err,
            dq,
            var_poisson,
            var_rnoise,
        },
        opts,
    )
    .map_err(|message| IoError::Format {
        path: path.to_path_buf(),
        message: format!("{}: {message}", set.name()),
    })?;
    // the card-by-card read only where the header states a lookup-table distortion
    let states_tables = ["CPDIS1", "CPDIS2", "D2IMDIS1", "D2IMDIS2"]
        .iter()
        .any(|k| keys.text(k).is_some());
    let tables = if states_tables && chip.wcs.is_some() {
        lookup_tables::read(&mut f, set.sci)?
    } else {
        None
    };
    // RA/Dec through the header's WCS, said once what the tables make of it is known: a distortion jsim cannot
    // apply leaves the chip without RA/Dec
    let (lookup, tables_note) = match tables {
        Some(lookup_tables::Tables::Read(lookup, note)) => (Some(*lookup), Some(note)),
        Some(lookup_tables::Tables::Unsupported(note)) => {
            chip.wcs = None;
            (None, Some(note))
        }
        None => (None, None),
    };
    if let Some(w) = chip.wcs.as_mut() {
        w.lookup = lookup;
        chip.notes.push(units::wcs_note(w));
    }
    chip.notes.extend(tables_note);
    Ok(chip)
}
