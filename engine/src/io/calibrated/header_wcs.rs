//! The chip's celestial WCS and plate scale as its header states them.

use super::Keys;

/// A chip's celestial WCS as its header states it: TAN, with SIP distortion when `CTYPE` ends in `-SIP`,
/// and HST's lookup-table distortions (`D2IMDIS`, `CPDIS`) when the file holds them ([`super::lookup_tables`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ChipWcs {
    pub crpix: [f64; 2],
    pub crval_deg: [f64; 2],
    pub cd_deg: [[f64; 2]; 2],
    pub naxis: [usize; 2],
    pub sip: Option<crate::sky::wcs::Sip>,
    pub lookup: Option<crate::sky::lookup_distortion::LookupDistortion>,
}

impl ChipWcs {
    /// The projection, ready to turn pixels into RA/Dec.
    pub fn projection(&self) -> Result<crate::sky::wcs::ArrayWcs, String> {
        let w = crate::sky::wcs::ArrayWcs::from_header_with_sip(
            self.crpix,
            self.crval_deg,
            self.cd_deg,
            self.naxis,
            self.sip.clone(),
        )?;
        Ok(match &self.lookup {
            Some(l) => w.with_lookup(l.clone()),
            None => w,
        })
    }
}

/// The highest SIP order read (the convention's and the engine's limit).
pub(super) const MAX_SIP_ORDER: usize = 9;

/// The chip's WCS from its header, or why there is none (a sentence for the report).
pub fn chip_wcs(keys: &dyn Keys, naxis: [usize; 2]) -> Result<ChipWcs, String> {
    let ctype = |k: &str| keys.text(k).map(|s| s.trim().to_ascii_uppercase());
    let (Some(c1), Some(c2)) = (ctype("CTYPE1"), ctype("CTYPE2")) else {
        return Err("no CTYPE1/CTYPE2: the catalogue has no RA/Dec".into());
    };
    if !(c1.starts_with("RA---TAN") && c2.starts_with("DEC--TAN")) {
        return Err(format!(
            "CTYPE {c1}, {c2}: only the TAN projection (with or without SIP) is read; the catalogue has no RA/Dec"
        ));
    }
    let n = |k: &str| keys.number(k);
    let (Some(p1), Some(p2), Some(v1), Some(v2)) =
        (n("CRPIX1"), n("CRPIX2"), n("CRVAL1"), n("CRVAL2"))
    else {
        return Err("CRPIX or CRVAL missing: the catalogue has no RA/Dec".into());
    };
    let cd_deg = match (n("CD1_1"), n("CD2_2")) {
        (Some(a), Some(d)) => [
            [a, n("CD1_2").unwrap_or(0.0)],
            [n("CD2_1").unwrap_or(0.0), d],
        ],
        _ => match (n("CDELT1"), n("CDELT2")) {
            (Some(c1), Some(c2)) => {
                let pc = |k: &str, d: f64| n(k).unwrap_or(d);
                [
                    [c1 * pc("PC1_1", 1.0), c1 * pc("PC1_2", 0.0)],
                    [c2 * pc("PC2_1", 0.0), c2 * pc("PC2_2", 1.0)],
                ]
            }
            _ => return Err("no CD matrix nor CDELT: the catalogue has no RA/Dec".into()),
        },
    };
    let sip = if c1.ends_with("-SIP") {
        let poly = |name: &str| {
            let order = keys
                .number(&format!("{name}_ORDER"))
                .map_or(0, |o| o.max(0.0) as usize)
                .min(MAX_SIP_ORDER);
            crate::sky::wcs::SipPolynomial {
                terms: (0..=order)
                    .flat_map(|p| (0..=order - p).map(move |q| (p, q)))
                    .filter(|(p, q)| p + q >= 2)
                    .filter_map(|(p, q)| keys.number(&format!("{name}_{p}_{q}")).map(|c| (p, q, c)))
                    .collect(),
            }
        };
        Some(crate::sky::wcs::Sip {
            a: poly("A"),
            b: poly("B"),
        })
    } else {
        None
    };
    Ok(ChipWcs {
        crpix: [p1, p2],
        crval_deg: [v1, v2],
        cd_deg,
        naxis,
        sip,
        lookup: None,
    })
}

/// The plate scale, mas/px, the header states: `PLTSCALE`, else √|det| of the WCS's CD matrix (or of
/// `CDELTi`·`PCi_j`), in degrees per pixel.
pub fn plate_scale_mas(keys: &dyn Keys) -> Option<(f64, &'static str)> {
    if let Some(s) = keys.number("PLTSCALE").filter(|v| *v > 0.0) {
        return Some((s, "PLTSCALE"));
    }
    let n = |k: &str| keys.number(k);
    let det = match (n("CD1_1"), n("CD1_2"), n("CD2_1"), n("CD2_2")) {
        (Some(a), b, c, Some(d)) => Some((
            a * d - b.unwrap_or(0.0) * c.unwrap_or(0.0),
            "the WCS's CD matrix",
        )),
        _ => match (n("CDELT1"), n("CDELT2")) {
            (Some(c1), Some(c2)) => {
                let pc = |k: &str, d: f64| n(k).unwrap_or(d);
                let det_pc =
                    pc("PC1_1", 1.0) * pc("PC2_2", 1.0) - pc("PC1_2", 0.0) * pc("PC2_1", 0.0);
                Some((c1 * c2 * det_pc, "the WCS's CDELT and PC"))
            }
            _ => None,
        },
    };
    det.map(|(d, from)| (d.abs().sqrt() * 3.6e6, from))
        .filter(|(s, _)| *s > 0.0 && s.is_finite())
}

/// Whether two chips are exposures of one pointing on one pixel grid: the same size, and each of the first's
/// corners and centre lands within `tolerance_px` of itself through the second's WCS. Chips without a WCS
/// are not.
pub fn same_pointing(a: &ChipWcs, b: &ChipWcs, tolerance_px: f64) -> bool {
    if a.naxis != b.naxis {
        return false;
    }
    let (Ok(wa), Ok(wb)) = (a.projection(), b.projection()) else {
        return false;
    };
    let (nx, ny) = ((a.naxis[0] - 1) as f64, (a.naxis[1] - 1) as f64);
    [
        (0.0, 0.0),
        (nx, 0.0),
        (0.0, ny),
        (nx, ny),
        (nx / 2.0, ny / 2.0),
    ]
    .iter()
    .all(|&(x, y)| {
        wa.pixel_to_sky(x, y)
            .and_then(|(ra, dec)| wb.sky_to_pixel(ra, dec))
            .is_some_and(|(u, v)| (u - x).hypot(v - y) <= tolerance_px)
    })
}
