//! One array's FITS world coordinate system: a gnomonic (TAN) projection with optional SIP distortion.
//!
//! * **Pixels** are the engine's (0-based, integer = pixel centre); FITS counts from 1, so `CRPIX` = the
//!   engine's position + 1.
//! * **Linear part** (Calabretta & Greisen 2002, eq. 1–3): intermediate world coordinates (ξ east, η north)
//!   = CD · (u, v), u = x_FITS − CRPIX1. With the focal plane's +y at position angle ρ east of north and sky
//!   parity (east to the left when north is up, det CD < 0):
//!   `CD = s · [[−cos ρ, sin ρ], [sin ρ, cos ρ]]`, s = the plate scale in degrees per pixel.
//! * **Projection**: TAN, computed by the CDS `wcs` crate (on `mapproj`) from the same `CTYPE/CRPIX/CRVAL/CD`
//!   keywords this module writes, so the header and the engine cannot disagree.
//! * **SIP** (Shupe et al. 2005): the pixel offsets are distorted before the linear part,
//!   u′ = u + Σ A_p_q u^p v^q (2 ≤ p + q ≤ order), likewise v′ with B. The engine inverts it exactly (fixed-
//!   point iteration to 1e-12 px); the header's inverse (AP, BP, 0 ≤ p + q ≤ order + 1), for other tools, is
//!   fitted by least squares on a grid over the array and its worst residual is reported
//!   ([`ArrayWcs::sip_inverse_error_px`]). The polynomials are evaluated here, not by the crate: `wcs` 0.4.2
//!   returns no pixel for any sky position once `-SIP` is in `CTYPE`, even with zero coefficients.

use super::Pointing;
use crate::numerics::linalg;

/// A header value of a WCS keyword.
#[derive(Debug, Clone, PartialEq)]
pub enum KeyValue {
    F(f64),
    I(i64),
    S(String),
}

/// One WCS keyword of an image header.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyword {
    pub key: String,
    pub value: KeyValue,
    pub comment: &'static str,
}

fn kw(key: impl Into<String>, value: KeyValue, comment: &'static str) -> Keyword {
    Keyword {
        key: key.into(),
        value,
        comment,
    }
}

/// SIP polynomial coefficients: `(p, q, coefficient)` of u^p v^q.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SipPolynomial {
    pub terms: Vec<(usize, usize, f64)>,
}

impl SipPolynomial {
    /// Σ c u^p v^q.
    pub fn eval(&self, u: f64, v: f64) -> f64 {
        self.terms
            .iter()
            .map(|&(p, q, c)| c * u.powi(p as i32) * v.powi(q as i32))
            .sum()
    }

    fn order(&self) -> usize {
        self.terms.iter().map(|&(p, q, _)| p + q).max().unwrap_or(0)
    }
}

/// The forward SIP distortion of an array: `a` for u, `b` for v, terms of order 2 … `order`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sip {
    pub a: SipPolynomial,
    pub b: SipPolynomial,
}

impl Sip {
    /// The largest order present (at least 2, as the SIP convention requires).
    pub fn order(&self) -> usize {
        self.a.order().max(self.b.order()).max(2)
    }

    /// The same distortion in the axes of an array turned by `rotation_deg` (a multiple of 90°): with
    /// focal-plane offsets d = R(r)·u′ of array offsets u′, the array's polynomials are
    /// (A′, B′)(u′) = R(−r)·(A, B)(R(r)·u′) — exact, term by term.
    pub fn rotated(&self, rotation_deg: f64) -> Sip {
        let quarter = ((rotation_deg / 90.0).round() as i64).rem_euclid(4);
        // u, v as (which array axis, sign) under R(r); (A, B) back to array axes by R(−r)
        let ((iu, su), (iv, sv)): ((usize, f64), (usize, f64)) = match quarter {
            0 => ((0, 1.0), (1, 1.0)),
            1 => ((1, -1.0), (0, 1.0)),
            2 => ((0, -1.0), (1, -1.0)),
            _ => ((1, 1.0), (0, -1.0)),
        };
        let substitute = |poly: &SipPolynomial, sign: f64| SipPolynomial {
            terms: poly
                .terms
                .iter()
                .map(|&(p, q, c)| {
                    let mut e = [0usize; 2];
                    e[iu] += p;
                    e[iv] += q;
                    let s = su.powi(p as i32) * sv.powi(q as i32) * sign;
                    (e[0], e[1], c * s)
                })
                .collect(),
        };
        let (a, b) = match quarter {
            0 => (substitute(&self.a, 1.0), substitute(&self.b, 1.0)),
            1 => (substitute(&self.b, 1.0), substitute(&self.a, -1.0)),
            2 => (substitute(&self.a, -1.0), substitute(&self.b, -1.0)),
            _ => (substitute(&self.b, -1.0), substitute(&self.a, 1.0)),
        };
        Sip { a, b }
    }

    fn validate(&self) -> Result<(), String> {
        for (name, poly) in [("A", &self.a), ("B", &self.b)] {
            for &(p, q, c) in &poly.terms {
                if !(2..=9).contains(&(p + q)) {
                    return Err(format!(
                        "SIP {name}_{p}_{q}: p + q must be 2 … 9 (first-order terms belong to CD)"
                    ));
                }
                if !c.is_finite() {
                    return Err(format!("SIP {name}_{p}_{q} = {c}: must be finite"));
                }
            }
        }
        Ok(())
    }
}

/// The WCS of one array.
pub struct ArrayWcs {
    /// Reference pixel, FITS (1-based) convention: the optical axis.
    pub crpix: [f64; 2],
    /// Sky position of the reference pixel (RA, Dec), degrees.
    pub crval_deg: [f64; 2],
    /// The linear transformation, degrees per pixel.
    pub cd_deg: [[f64; 2]; 2],
    /// The array's size, pixels.
    pub naxis: [usize; 2],
    /// The forward distortion and its fitted inverse (AP, BP), if any.
    pub sip: Option<(Sip, Sip)>,
    sip_inverse_error_px: f64,
    tan: wcs::WCS,
    /// A header's lookup-table distortions (HST's `D2IMDIS`, `CPDIS`), when it states any.
    pub lookup: Option<super::lookup_distortion::LookupDistortion>,
}

impl std::fmt::Debug for ArrayWcs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ArrayWcs")
            .field("crpix", &self.crpix)
            .field("crval_deg", &self.crval_deg)
            .field("cd_deg", &self.cd_deg)
            .field("naxis", &self.naxis)
            .field("sip", &self.sip)
            .field("lookup", &self.lookup.is_some())
            .finish()
    }
}

/// sin and cos of an angle in degrees, exact (0, ±1) at multiples of 90° — so a turned array's CD matrix
/// holds exact zeros, not 6e-17.
pub fn sin_cos_deg(deg: f64) -> (f64, f64) {
    let quarter = deg / 90.0;
    if quarter.fract() == 0.0 && quarter.is_finite() {
        match (quarter as i64).rem_euclid(4) {
            0 => (0.0, 1.0),
            1 => (1.0, 0.0),
            2 => (0.0, -1.0),
            _ => (-1.0, 0.0),
        }
    } else {
        deg.to_radians().sin_cos()
    }
}

impl ArrayWcs {
    /// The WCS of an array of `naxis` pixels whose (0-based) pixel `axis_px` is the optical axis, seen at
    /// `pointing` with its +y axis at position angle `pointing.pa_deg + rotation_deg` east of north,
    /// `scale_mas` per pixel, and the forward distortion `sip`.
    pub fn new(
        pointing: &Pointing,
        rotation_deg: f64,
        scale_mas: f64,
        axis_px: [f64; 2],
        naxis: [usize; 2],
        sip: Option<Sip>,
    ) -> Result<Self, String> {
        pointing.validate()?;
        if !(scale_mas > 0.0 && scale_mas.is_finite()) {
            return Err(format!("plate scale {scale_mas} mas/px: must be > 0"));
        }
        if !(axis_px.iter().all(|v| v.is_finite()) && rotation_deg.is_finite()) {
            return Err("the optical axis's pixel position and the rotation must be finite".into());
        }
        if naxis.contains(&0) {
            return Err("an array must have at least one pixel per axis".into());
        }
        let s = scale_mas / 3.6e6;
        let (sin, cos) = sin_cos_deg(pointing.pa_deg + rotation_deg);
        // `+ 0.0` turns a −0 into 0
        let cd_deg = [
            [-s * cos + 0.0, s * sin + 0.0],
            [s * sin + 0.0, s * cos + 0.0],
        ];
        let crpix = [axis_px[0] + 1.0, axis_px[1] + 1.0];
        let crval_deg = [pointing.ra_deg, pointing.dec_deg];
        Self::from_header_with_sip(crpix, crval_deg, cd_deg, naxis, sip)
    }

    /// The TAN projection a FITS header states with its forward SIP distortion (`A_p_q`, `B_p_q`), the
    /// inverse fitted over the array as for a WCS this module writes.
    pub fn from_header_with_sip(
        crpix: [f64; 2],
        crval_deg: [f64; 2],
        cd_deg: [[f64; 2]; 2],
        naxis: [usize; 2],
        sip: Option<Sip>,
    ) -> Result<Self, String> {
        let mut w = Self::from_header(crpix, crval_deg, cd_deg, naxis)?;
        if let Some(forward) = sip {
            forward.validate()?;
            let (inverse, worst) = w.fit_inverse(&forward)?;
            w.sip = Some((forward, inverse));
            w.sip_inverse_error_px = worst;
        }
        Ok(w)
    }

    /// The TAN projection a FITS header states (`CRPIX`, `CRVAL`, `CD`; its SIP terms, if any, left out:
    /// the linear part alone, good to the distortion's few pixels) — to check that a product belongs to
    /// the image's pointing.
    pub fn from_header(
        crpix: [f64; 2],
        crval_deg: [f64; 2],
        cd_deg: [[f64; 2]; 2],
        naxis: [usize; 2],
    ) -> Result<Self, String> {
        let all = crpix
            .iter()
            .chain(&crval_deg)
            .chain(cd_deg.iter().flatten());
        if !all.into_iter().all(|v| v.is_finite()) {
            return Err("CRPIX, CRVAL and CD must be finite".into());
        }
        let det = cd_deg[0][0] * cd_deg[1][1] - cd_deg[0][1] * cd_deg[1][0];
        if det == 0.0 {
            return Err("the CD matrix is singular".into());
        }
        let params = serde_json::json!({
            "CTYPE1": "RA---TAN", "CTYPE2": "DEC--TAN", "NAXIS": 2,
            "NAXIS1": naxis[0], "NAXIS2": naxis[1],
            "CRPIX1": crpix[0], "CRPIX2": crpix[1], "CRVAL1": crval_deg[0], "CRVAL2": crval_deg[1],
            "CD1_1": cd_deg[0][0], "CD1_2": cd_deg[0][1], "CD2_1": cd_deg[1][0], "CD2_2": cd_deg[1][1],
        });
        let params: wcs::WCSParams =
            serde_json::from_value(params).map_err(|e| format!("WCS keywords: {e}"))?;
        let tan = wcs::WCS::new(&params).map_err(|e| format!("TAN projection: {e:?}"))?;
        Ok(Self {
            crpix,
            crval_deg,
            cd_deg,
            naxis,
            sip: None,
            sip_inverse_error_px: 0.0,
            tan,
            lookup: None,
        })
    }

    /// This WCS with a header's lookup-table distortions (none when `lookup` holds no table).
    pub fn with_lookup(mut self, lookup: super::lookup_distortion::LookupDistortion) -> Self {
        self.lookup = (!lookup.is_empty()).then_some(lookup);
        self
    }

    /// The focal-plane offset from the reference pixel (pixels, before the CD matrix) of the engine's pixel
    /// position: the detector correction first, then SIP and the residual table at the corrected pixel
    /// (astropy's `pipeline_pix2foc`).
    fn pixel_to_focal(&self, x_px: f64, y_px: f64) -> (f64, f64) {
        let mut t = [x_px + 1.0, y_px + 1.0];
        if let Some(l) = &self.lookup {
            t = l.detector_to_image(t);
        }
        let (mut u, mut v) = (t[0] - self.crpix[0], t[1] - self.crpix[1]);
        if let Some((f, _)) = &self.sip {
            let (du, dv) = (f.a.eval(u, v), f.b.eval(u, v));
            u += du;
            v += dv;
        }
        if let Some(l) = &self.lookup {
            let r = l.residual(t);
            u += r[0];
            v += r[1];
        }
        (u, v)
    }

    /// The worst error of the fitted inverse distortion over the array, pixels (0 without SIP).
    pub fn sip_inverse_error_px(&self) -> f64 {
        self.sip_inverse_error_px
    }

    /// Fit AP, BP (order + 1, all terms from order 0) to invert `forward` on a 41 × 41 grid over the array;
    /// the worst round-trip error on a finer, offset grid is returned with them.
    fn fit_inverse(&self, forward: &Sip) -> Result<(Sip, f64), String> {
        let order = forward.order() + 1;
        let powers: Vec<(usize, usize)> = (0..=order)
            .flat_map(|p| (0..=order - p).map(move |q| (p, q)))
            .collect();
        // offsets scaled by the array size, so that the normal equations stay well conditioned
        let l = self.naxis[0].max(self.naxis[1]) as f64;
        let grid = |n: usize, shift: f64| -> Vec<(f64, f64)> {
            let mut pts = Vec::with_capacity(n * n);
            for j in 0..n {
                for i in 0..n {
                    let x = 0.5 + (i as f64 + shift) / (n - 1) as f64 * self.naxis[0] as f64;
                    let y = 0.5 + (j as f64 + shift) / (n - 1) as f64 * self.naxis[1] as f64;
                    pts.push((x - self.crpix[0], y - self.crpix[1]));
                }
            }
            pts
        };
        let train = grid(41, 0.0);
        let mut design = Vec::with_capacity(train.len() * powers.len());
        let (mut du, mut dv) = (Vec::new(), Vec::new());
        for &(u, v) in &train {
            let (uu, vv) = (u + forward.a.eval(u, v), v + forward.b.eval(u, v));
            for &(p, q) in &powers {
                design.push((uu / l).powi(p as i32) * (vv / l).powi(q as i32));
            }
            du.push(u - uu);
            dv.push(v - vv);
        }
        let w = vec![1.0; train.len()];
        let fit = |target: &[f64]| -> Result<SipPolynomial, String> {
            let (c, _) = linalg::weighted_lstsq(&design, target, &w, powers.len())
                .ok_or("the SIP distortion cannot be inverted on the array (degenerate fit)")?;
            Ok(SipPolynomial {
                terms: powers
                    .iter()
                    .zip(c)
                    .map(|(&(p, q), c)| (p, q, c / l.powi((p + q) as i32)))
                    .collect(),
            })
        };
        let inverse = Sip {
            a: fit(&du)?,
            b: fit(&dv)?,
        };
        let worst = grid(30, 0.37)
            .iter()
            .map(|&(u, v)| {
                let (uu, vv) = (u + forward.a.eval(u, v), v + forward.b.eval(u, v));
                let (u2, v2) = (uu + inverse.a.eval(uu, vv), vv + inverse.b.eval(uu, vv));
                (u2 - u).hypot(v2 - v)
            })
            .fold(0.0, f64::max);
        Ok((inverse, worst))
    }

    /// The sky position (RA, Dec in degrees) of the engine's pixel position (x, y), or `None` where the
    /// projection has none.
    pub fn pixel_to_sky(&self, x_px: f64, y_px: f64) -> Option<(f64, f64)> {
        let (u, v) = self.pixel_to_focal(x_px, y_px);
        let s = self
            .tan
            .unproj(&wcs::ImgXY::new(self.crpix[0] + u, self.crpix[1] + v))?;
        let ra = s.lon().to_degrees().rem_euclid(360.0);
        Some((ra, s.lat().to_degrees()))
    }

    /// The engine's pixel position (x, y) of a sky position (RA, Dec in degrees), or `None` for a position
    /// the projection cannot show (90° or more from the optical axis). The position may lie off the array.
    pub fn sky_to_pixel(&self, ra_deg: f64, dec_deg: f64) -> Option<(f64, f64)> {
        let p = self
            .tan
            .proj(&wcs::LonLat::new(ra_deg.to_radians(), dec_deg.to_radians()))?;
        let (uu, vv) = (p.x() - self.crpix[0], p.y() - self.crpix[1]);
        let (mut u, mut v) = (uu, vv);
        if let Some((f, inv)) = &self.sip {
            // start from the fitted inverse, then solve u + A(u, v) = U exactly by fixed-point iteration
            // (a contraction while the distortion's gradient is ≪ 1, as in any real optical design)
            u = uu + inv.a.eval(uu, vv);
            v = vv + inv.b.eval(uu, vv);
            for _ in 0..50 {
                let (un, vn) = (uu - f.a.eval(u, v), vv - f.b.eval(u, v));
                let step = (un - u).hypot(vn - v);
                (u, v) = (un, vn);
                if step < 1e-12 {
                    break;
                }
            }
        }
        let (mut x, mut y) = (self.crpix[0] + u - 1.0, self.crpix[1] + v - 1.0);
        if self.lookup.is_some() {
            // the tables have no inverse: solve pixel_to_focal(x, y) = (U, V) by fixed-point iteration from
            // the SIP-only pixel (the tables' offsets are a fraction of a pixel and vary slowly)
            for _ in 0..50 {
                let (fu, fv) = self.pixel_to_focal(x, y);
                let (dx, dy) = (uu - fu, vv - fv);
                x += dx;
                y += dy;
                if dx.hypot(dy) < 1e-12 {
                    break;
                }
            }
        }
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }

    /// The FITS keywords of this WCS (`RA---TAN` or `RA---TAN-SIP` with A/B/AP/BP).
    pub fn keywords(&self) -> Vec<Keyword> {
        let sip = self.sip.is_some();
        let suffix = if sip { "-SIP" } else { "" };
        let mut k = vec![
            kw("WCSAXES", KeyValue::I(2), "number of WCS axes"),
            kw(
                "CTYPE1",
                KeyValue::S(format!("RA---TAN{suffix}")),
                "gnomonic projection",
            ),
            kw(
                "CTYPE2",
                KeyValue::S(format!("DEC--TAN{suffix}")),
                "gnomonic projection",
            ),
            kw("CUNIT1", KeyValue::S("deg".into()), ""),
            kw("CUNIT2", KeyValue::S("deg".into()), ""),
            kw("RADESYS", KeyValue::S("ICRS".into()), ""),
            kw(
                "CRPIX1",
                KeyValue::F(self.crpix[0]),
                "optical axis, FITS pixels (1-based)",
            ),
            kw(
                "CRPIX2",
                KeyValue::F(self.crpix[1]),
                "optical axis, FITS pixels (1-based)",
            ),
            kw(
                "CRVAL1",
                KeyValue::F(self.crval_deg[0]),
                "[deg] RA of the optical axis",
            ),
            kw(
                "CRVAL2",
                KeyValue::F(self.crval_deg[1]),
                "[deg] Dec of the optical axis",
            ),
            kw("CD1_1", KeyValue::F(self.cd_deg[0][0]), "[deg/px]"),
            kw("CD1_2", KeyValue::F(self.cd_deg[0][1]), "[deg/px]"),
            kw("CD2_1", KeyValue::F(self.cd_deg[1][0]), "[deg/px]"),
            kw("CD2_2", KeyValue::F(self.cd_deg[1][1]), "[deg/px]"),
        ];
        if let Some((f, inv)) = &self.sip {
            for (name, poly, order) in [
                ("A", &f.a, f.order()),
                ("B", &f.b, f.order()),
                ("AP", &inv.a, f.order() + 1),
                ("BP", &inv.b, f.order() + 1),
            ] {
                k.push(kw(
                    format!("{name}_ORDER"),
                    KeyValue::I(order as i64),
                    "SIP polynomial order",
                ));
                for &(p, q, c) in &poly.terms {
                    k.push(kw(format!("{name}_{p}_{q}"), KeyValue::F(c), ""));
                }
            }
        }
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_turns_are_exact() {
        for (deg, sc) in [
            (0.0, (0.0, 1.0)),
            (90.0, (1.0, 0.0)),
            (180.0, (0.0, -1.0)),
            (-90.0, (-1.0, 0.0)),
            (450.0, (1.0, 0.0)),
        ] {
            assert_eq!(sin_cos_deg(deg), sc, "{deg}");
        }
        let (s, c) = sin_cos_deg(30.0);
        assert!((s - 0.5).abs() < 1e-15 && (c - 0.75f64.sqrt()).abs() < 1e-15);
    }

    const SCALE_MAS: f64 = 472.1;

    fn centred(pointing: Pointing, sip: Option<Sip>) -> ArrayWcs {
        ArrayWcs::new(&pointing, 0.0, SCALE_MAS, [983.5, 983.5], [1968, 1968], sip).expect("wcs")
    }

    /// Gnomonic projection by hand (Calabretta & Greisen 2002, eq. 5, 12, 54): (ξ, η) in degrees.
    fn gnomonic(ra0: f64, dec0: f64, ra: f64, dec: f64) -> (f64, f64) {
        let (a0, d0, a, d) = (
            ra0.to_radians(),
            dec0.to_radians(),
            ra.to_radians(),
            dec.to_radians(),
        );
        let cos_c = d0.sin() * d.sin() + d0.cos() * d.cos() * (a - a0).cos();
        let xi = d.cos() * (a - a0).sin() / cos_c;
        let eta = (d0.cos() * d.sin() - d0.sin() * d.cos() * (a - a0).cos()) / cos_c;
        (xi.to_degrees(), eta.to_degrees())
    }

    #[test]
    fn the_projection_matches_the_gnomonic_formula_and_sky_parity() {
        let p = Pointing {
            ra_deg: 266.4168,
            dec_deg: -29.0078,
            pa_deg: 30.0,
        };
        let w = centred(p, None);
        let s = SCALE_MAS / 3.6e6;
        let rho = 30f64.to_radians();
        for (dra, ddec) in [
            (0.0, 0.0),
            (0.1, 0.0),
            (0.0, -0.12),
            (-0.09, 0.07),
            (0.13, 0.11),
        ] {
            let (ra, dec) = (p.ra_deg + dra, p.dec_deg + ddec);
            let (xi, eta) = gnomonic(p.ra_deg, p.dec_deg, ra, dec);
            // (ξ, η) = s (u x̂ + v ŷ), ŷ = (sin ρ, cos ρ), x̂ = (−cos ρ, sin ρ)
            let u = (-xi * rho.cos() + eta * rho.sin()) / s;
            let v = (xi * rho.sin() + eta * rho.cos()) / s;
            let (x, y) = w.sky_to_pixel(ra, dec).expect("on the sky");
            assert!(
                (x - (983.5 + u)).abs() < 1e-6 && (y - (983.5 + v)).abs() < 1e-6,
                "({dra}, {ddec}): got ({x}, {y}), expected ({}, {})",
                983.5 + u,
                983.5 + v
            );
            let (ra2, dec2) = w.pixel_to_sky(x, y).expect("a sky position");
            assert!(
                (ra2 - ra).abs() * dec.to_radians().cos() < 1e-10 && (dec2 - dec).abs() < 1e-10
            );
        }
        // sky parity at PA 0: north is +y, east is −x
        let w0 = centred(Pointing { pa_deg: 0.0, ..p }, None);
        let (xn, yn) = w0.sky_to_pixel(p.ra_deg, p.dec_deg + 0.01).expect("north");
        let (xe, ye) = w0.sky_to_pixel(p.ra_deg + 0.01, p.dec_deg).expect("east");
        assert!((xn - 983.5).abs() < 1e-6 && yn > 983.5 + 70.0);
        assert!(xe < 983.5 - 60.0 && (ye - 983.5).abs() < 0.1);
    }

    fn demo_sip() -> Sip {
        // ≈ 2 px of barrel distortion at the corners of a 1968² array
        Sip {
            a: SipPolynomial {
                terms: vec![(3, 0, -2.0e-9), (1, 2, -2.0e-9), (2, 0, 1.0e-7)],
            },
            b: SipPolynomial {
                terms: vec![(0, 3, -2.0e-9), (2, 1, -2.0e-9), (1, 1, -5.0e-8)],
            },
        }
    }

    /// Lookup tables (a detector correction along x, a residual table per axis) on top of SIP: sky → pixel
    /// inverts pixel → sky to 1e-8 px, and the distorted pixel lands where the SIP-only WCS puts it moved
    /// by the tables' offsets.
    #[test]
    fn lookup_tables_round_trip_and_add_their_offsets() {
        use crate::sky::lookup_distortion::{LookupDistortion, LookupTable};
        let p = Pointing::GALACTIC_CENTRE;
        let wave = |n: usize, m: usize, amp: f32| -> Vec<f32> {
            (0..n * m)
                .map(|k| amp * ((k % n) as f32 * 0.7).sin() * ((k / n) as f32 * 0.5).cos())
                .collect()
        };
        let table = |n: usize, m: usize, step: f64, amp: f32| {
            LookupTable::new(
                [n, m],
                [1.0, 1.0],
                [1.0, 1.0],
                [step, step],
                wave(n, m, amp),
            )
            .expect("table")
        };
        let lookup = LookupDistortion {
            det2im: [Some(table(200, 1, 10.0, 0.1)), None],
            cpdis: [
                Some(table(21, 21, 100.0, 0.2)),
                Some(table(21, 21, 100.0, 0.15)),
            ],
        };
        let w = centred(p, Some(demo_sip())).with_lookup(lookup.clone());
        let sip_only = centred(p, Some(demo_sip()));
        let mut largest = 0.0f64;
        for (x, y) in [(0.0, 0.0), (1967.0, 3.0), (500.0, 1500.0), (983.5, 983.5)] {
            let (ra, dec) = w.pixel_to_sky(x, y).expect("sky");
            let (x2, y2) = w.sky_to_pixel(ra, dec).expect("pixel");
            assert!((x2 - x).hypot(y2 - y) < 1e-8, "({x}, {y}) → ({x2}, {y2})");
            // the detector correction moves the pixel, then SIP and the residual table act there
            let t = lookup.detector_to_image([x + 1.0, y + 1.0]);
            let r = lookup.residual(t);
            let (xs, ys) = sip_only.pixel_to_focal(t[0] - 1.0, t[1] - 1.0);
            let (xl, yl) = w.pixel_to_focal(x, y);
            assert!((xl - xs - r[0]).abs() < 1e-12 && (yl - ys - r[1]).abs() < 1e-12);
            largest = largest.max(r[0].abs()).max(r[1].abs());
        }
        assert!(
            largest > 0.05,
            "the tables moved the pixels by {largest} px at most"
        );
        // no table: nothing attached
        let none = centred(p, None).with_lookup(LookupDistortion::default());
        assert!(none.lookup.is_none());
    }

    #[test]
    fn sip_round_trips_and_moves_the_corners_by_the_stated_distortion() {
        let p = Pointing::GALACTIC_CENTRE;
        let w = centred(p, Some(demo_sip()));
        // the header's fitted inverse: order 4 for a cubic distortion of ≈ 2 px, good to a few 0.01 px
        assert!(
            w.sip_inverse_error_px() < 0.05 && w.sip_inverse_error_px() > 0.0,
            "inverse fit error {} px",
            w.sip_inverse_error_px()
        );
        let plain = centred(p, None);
        for (x, y) in [
            (0.0, 0.0),
            (1967.0, 0.0),
            (500.0, 1500.0),
            (983.5, 983.5),
            (1967.0, 1967.0),
        ] {
            let (ra, dec) = w.pixel_to_sky(x, y).expect("sky");
            let (x2, y2) = w.sky_to_pixel(ra, dec).expect("pixel");
            // the engine's own inverse is exact
            assert!((x2 - x).hypot(y2 - y) < 1e-8, "({x}, {y}) → ({x2}, {y2})");
            // the distorted pixel lands where the undistorted WCS puts u + A(u, v)
            let (u, v) = (x - 983.5, y - 983.5);
            let f = &demo_sip();
            let (xd, yd) = plain.sky_to_pixel(ra, dec).expect("pixel");
            assert!((xd - (x + f.a.eval(u, v))).abs() < 1e-6);
            assert!((yd - (y + f.b.eval(u, v))).abs() < 1e-6);
        }
    }

    #[test]
    fn the_keywords_name_the_projection_and_every_sip_term() {
        let w = centred(Pointing::GALACTIC_CENTRE, Some(demo_sip()));
        let k = w.keywords();
        let get = |key: &str| k.iter().find(|k| k.key == key).map(|k| k.value.clone());
        assert_eq!(get("CTYPE1"), Some(KeyValue::S("RA---TAN-SIP".into())));
        assert_eq!(get("CRPIX1"), Some(KeyValue::F(984.5)));
        assert_eq!(get("A_ORDER"), Some(KeyValue::I(3)));
        assert_eq!(get("AP_ORDER"), Some(KeyValue::I(4)));
        assert_eq!(get("A_3_0"), Some(KeyValue::F(-2.0e-9)));
        assert!(get("BP_0_0").is_some());
        let plain = centred(Pointing::GALACTIC_CENTRE, None).keywords();
        assert!(plain.iter().all(|k| !k.key.starts_with("A_")));
    }

    #[test]
    fn bad_input_is_named() {
        let bad = Pointing {
            dec_deg: 91.0,
            ..Pointing::GALACTIC_CENTRE
        };
        let e = ArrayWcs::new(&bad, 0.0, SCALE_MAS, [0.0, 0.0], [8, 8], None).expect_err("dec");
        assert!(e.contains("dec_deg"), "{e}");
        let sip = Sip {
            a: SipPolynomial {
                terms: vec![(1, 0, 1e-3)],
            },
            b: SipPolynomial::default(),
        };
        let e = ArrayWcs::new(
            &Pointing::GALACTIC_CENTRE,
            0.0,
            SCALE_MAS,
            [0.0, 0.0],
            [8, 8],
            Some(sip),
        )
        .expect_err("first order");
        assert!(e.contains("A_1_0"), "{e}");
        let e = ArrayWcs::new(
            &Pointing::GALACTIC_CENTRE,
            0.0,
            -1.0,
            [0.0, 0.0],
            [8, 8],
            None,
        )
        .expect_err("scale");
        assert!(e.contains("plate scale"), "{e}");
        // a position 90° or more from the axis has no pixel
        let w = centred(Pointing::GALACTIC_CENTRE, None);
        assert!(w.sky_to_pixel(86.4168, 29.0078).is_none());
    }
}
