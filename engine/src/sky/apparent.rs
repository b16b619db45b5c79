//! Where a star appears at an instant: its catalogue place (ICRS, at the catalogue's epoch) carried to the
//! spacecraft's proper direction, the direction a camera on the moving spacecraft records.
//!
//! The steps of SOFA's `atciq` without its final rotation to the equator of date (the images' WCS keeps
//! ICRS axes, as the GCRS does):
//! 1. proper motion and parallax, `pmpx`: the coordinate direction from the observer's barycentric position
//!    after Δt = epoch − catalogue epoch (TDB Julian years; no radial velocity);
//! 2. light deflection by the Sun, `ldsun` (≈ 4 mas at 90° from the Sun);
//! 3. aberration by the observer's barycentric velocity, `ab` (20.5″ sin θ from the Earth, ≤ 5.2″ from the orbit).
//!
//! The pointing is the apparent direction of the configured axis (the attitude control holds the target
//! where the star trackers see it), so a field shows the *differential* effects: a scale change of up to
//! 10⁻⁴ (0.25 px at an array's far corner) from the aberration, µas-level from the deflection.

use super::orbit::Observer;
use sofars::astro::{ab, ldsun, pmpx};
use sofars::vm::{anp, c2s};

/// Milliarcseconds per radian.
const MAS_PER_RAD: f64 = 180.0 / std::f64::consts::PI * 3.6e6;

/// A star's motion on the sky: proper motion (µα* = µα cos δ, µδ) and parallax.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motion {
    /// µα* = dα/dt · cos δ, mas/yr (the Gaia convention).
    pub pmra_mas_per_yr: f64,
    /// µδ, mas/yr.
    pub pmdec_mas_per_yr: f64,
    /// ϖ, mas.
    pub parallax_mas: f64,
}

/// The catalogue place carried to an instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Place {
    /// Years from the catalogue's epoch to the instant (TDB Julian years).
    pub years: f64,
    /// Where the observer is and how it moves.
    pub observer: Observer,
    /// Light deflection by the Sun and aberration: on for the proper direction, off for the astrometric
    /// (coordinate) direction `pmpx` gives.
    pub apparent: bool,
}

/// The coordinate direction (step 1 alone: proper motion and parallax), unit vector.
pub fn astrometric_vector(ra_deg: f64, dec_deg: f64, m: &Motion, p: &Place) -> [f64; 3] {
    let dec = dec_deg.to_radians();
    let cos_dec = dec.cos().max(1e-12);
    pmpx(
        ra_deg.to_radians(),
        dec,
        m.pmra_mas_per_yr / MAS_PER_RAD / cos_dec,
        m.pmdec_mas_per_yr / MAS_PER_RAD,
        m.parallax_mas / 1e3,
        0.0,
        p.years,
        p.observer.position_au,
    )
}

/// The direction `p` says: the astrometric one, then deflected and aberrated when `p.apparent`.
pub fn direction(ra_deg: f64, dec_deg: f64, m: &Motion, p: &Place) -> (f64, f64) {
    let mut v = astrometric_vector(ra_deg, dec_deg, m, p);
    if p.apparent {
        let h = p.observer.heliocentric_au;
        let em = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let eh = h.map(|c| c / em);
        v = ldsun(v, eh, em);
        let vel = p.observer.velocity_c();
        let bm1 = (1.0 - vel.iter().map(|c| c * c).sum::<f64>()).sqrt();
        v = ab(&v, &vel, em, bm1);
    }
    let (ra, dec) = c2s(&v);
    (anp(ra).to_degrees(), dec.to_degrees())
}

/// Angular separation of two directions, mas (haversine: exact for small angles).
pub fn separation_mas(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (ra1, de1) = (a.0.to_radians(), a.1.to_radians());
    let (ra2, de2) = (b.0.to_radians(), b.1.to_radians());
    let h = ((de2 - de1) / 2.0).sin().powi(2)
        + de1.cos() * de2.cos() * ((ra2 - ra1) / 2.0).sin().powi(2);
    2.0 * h.sqrt().asin() * MAS_PER_RAD
}

/// The offset of `b` from `a` on the sky, (Δα*, Δδ) in mas, on the tangent plane at `a` (gnomonic).
pub fn offset_mas(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let (ra0, de0) = (a.0.to_radians(), a.1.to_radians());
    let (ra, de) = (b.0.to_radians(), b.1.to_radians());
    let cos_c = de0.sin() * de.sin() + de0.cos() * de.cos() * (ra - ra0).cos();
    let xi = de.cos() * (ra - ra0).sin() / cos_c;
    let eta = (de0.cos() * de.sin() - de0.sin() * de.cos() * (ra - ra0).cos()) / cos_c;
    (xi * MAS_PER_RAD, eta * MAS_PER_RAD)
}

/// The inverse of [`offset_mas`] (the gnomonic projection at `tangent_deg`): the ICRS place (degrees) of plane point
/// (ξ, η) mas.
pub fn plane_to_sky(tangent_deg: (f64, f64), xi_mas: f64, eta_mas: f64) -> (f64, f64) {
    let rad = std::f64::consts::PI / 180.0 / 3.6e6;
    let (x, y) = (xi_mas * rad, eta_mas * rad);
    let (ra0, de0) = (tangent_deg.0.to_radians(), tangent_deg.1.to_radians());
    let den = de0.cos() - y * de0.sin();
    let ra = ra0 + x.atan2(den);
    let dec = ((de0.sin() + y * de0.cos()) * (ra - ra0).cos()).atan2(den);
    (ra.to_degrees().rem_euclid(360.0), dec.to_degrees())
}

/// The parallax factors of a star at (α, δ) seen from `observer_au` (barycentric, ICRS axes, au): the
/// displacement (Δα*, Δδ) on the tangent plane per mas of parallax, to first order —
/// `Δα* = X sin α − Y cos α`, `Δδ = X cos α sin δ + Y sin α sin δ − Z cos δ` (the star is seen away from the
/// observer's position). What an astrometric solution multiplies ϖ by (`solution`).
pub fn parallax_factors(ra_deg: f64, dec_deg: f64, observer_au: [f64; 3]) -> [f64; 2] {
    let (sa, ca) = ra_deg.to_radians().sin_cos();
    let (sd, cd) = dec_deg.to_radians().sin_cos();
    let [x, y, z] = observer_au;
    [x * sa - y * ca, x * ca * sd + y * sa * sd - z * cd]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sky::orbit::Orbit;
    use crate::time::Epoch;

    fn place(date: &str, apparent: bool) -> Place {
        let t = Epoch::from_utc_iso(date).expect("date");
        let orbit = Orbit {
            altitude_km: 600.0,
            ltan_h: 6.0,
            phase_deg: 0.0,
            phase_epoch: t,
        };
        Place {
            years: t.julian_year_tdb() - 2031.0,
            observer: orbit.observer(&t),
            apparent,
        }
    }

    #[test]
    fn aberration_has_its_size() {
        // the Galactic centre near the March equinox: the Earth moves towards (RA 270°, Dec −23°), 6° from
        // the target, so the aberration is 20.5″ · sin θ ≈ 2″ plus the orbit's ≤ 5.2″
        let gc = (266.4168, -29.0078);
        let none = Motion::default();
        let astro = direction(gc.0, gc.1, &none, &place("2031-03-21T00:00:00", false));
        assert!(
            separation_mas(astro, gc) < 1e-6,
            "no motion: the catalogue place"
        );
        let app = direction(gc.0, gc.1, &none, &place("2031-03-21T00:00:00", true));
        let s = separation_mas(astro, app) / 1e3;
        assert!(s > 0.0 && s < 2.2 + 5.3, "{s} arcsec");
        // at the solstices it moves across the line of sight (θ ≈ 96°): 20.4″ ± 5.2″, opposite in June
        // and December
        let june = direction(gc.0, gc.1, &none, &place("2031-06-21T00:00:00", true));
        let december = direction(gc.0, gc.1, &none, &place("2031-12-21T00:00:00", true));
        for d in [june, december] {
            let s = separation_mas(gc, d) / 1e3;
            assert!(s > 20.3 - 5.3 && s < 20.6 + 5.3, "{s} arcsec");
        }
        let (a, b) = (offset_mas(gc, june), offset_mas(gc, december));
        let cos = (a.0 * b.0 + a.1 * b.1) / (a.0.hypot(a.1) * b.0.hypot(b.1));
        assert!(cos < -0.8, "{a:?} {b:?}");
        // a star next to the axis moves with it: the differential aberration over 0.3° is ≤ 1e-4 of it
        let near = (gc.0 + 0.3 / gc.1.to_radians().cos(), gc.1);
        let near_app = direction(near.0, near.1, &none, &place("2031-03-21T00:00:00", true));
        let d = separation_mas(near, near_app) - separation_mas(gc, app);
        assert!(d.abs() < 1e-4 * 0.3 * 3.6e6 + 0.1, "{d} mas");
    }

    #[test]
    fn proper_motion_moves_the_star_by_mu_t() {
        // 10 years of (3, −4) mas/yr at no parallax: (30, −40) mas on the tangent plane, to 1 µas
        let m = Motion {
            pmra_mas_per_yr: 3.0,
            pmdec_mas_per_yr: -4.0,
            parallax_mas: 0.0,
        };
        let mut p = place("2031-03-21T00:00:00", false);
        p.years = 10.0;
        let c = (266.4168, -29.0078);
        let (dx, dy) = offset_mas(c, direction(c.0, c.1, &m, &p));
        assert!(
            (dx - 30.0).abs() < 1e-3 && (dy + 40.0).abs() < 1e-3,
            "{dx} {dy}"
        );
    }

    #[test]
    fn proper_motion_and_parallax_are_recovered_over_two_seasons() {
        // a bulge-like star observed at 40 instants over the spring and autumn seasons of two years;
        // its astrometric positions fitted with the textbook five-parameter model (offsets on the tangent
        // plane, parallax factors from the observer's barycentric position: Green 1985, §11) give back
        // the proper motion and parallax to 1 µas
        let (ra, dec): (f64, f64) = (266.4168, -29.0078);
        let m = Motion {
            pmra_mas_per_yr: -2.7,
            pmdec_mas_per_yr: -5.6,
            parallax_mas: 0.125,
        };
        let start = Epoch::from_utc_iso("2031-02-15T00:00:00").expect("date");
        let orbit = Orbit {
            altitude_km: 600.0,
            ltan_h: 6.0,
            phase_deg: 0.0,
            phase_epoch: start,
        };
        let epoch0 = 2031.0;
        let (sa, ca) = ra.to_radians().sin_cos();
        let (sd, cd) = dec.to_radians().sin_cos();
        let (mut design, mut y) = (Vec::new(), Vec::new());
        for year in 0..2 {
            for days in [0.0, 210.0] {
                for k in 0..10 {
                    let t = start.plus_s((year as f64 * 365.25 + days + 6.0 * k as f64) * 86_400.0);
                    let years = t.julian_year_tdb() - epoch0;
                    let ob = orbit.observer(&t);
                    let p = Place {
                        years,
                        observer: ob,
                        apparent: false,
                    };
                    let (dx, dy) = offset_mas((ra, dec), direction(ra, dec, &m, &p));
                    let [x, yy, z] = ob.position_au;
                    let f_ra = x * sa - yy * ca;
                    let f_dec = x * ca * sd + yy * sa * sd - z * cd;
                    design.extend([1.0, 0.0, years, 0.0, f_ra]);
                    y.push(dx);
                    design.extend([0.0, 1.0, 0.0, years, f_dec]);
                    y.push(dy);
                }
            }
        }
        let w = vec![1.0; y.len()];
        let (beta, _) = crate::numerics::linalg::weighted_lstsq(&design, &y, &w, 5).expect("fit");
        let err_uas = [
            (beta[2] - m.pmra_mas_per_yr) * 1e3,
            (beta[3] - m.pmdec_mas_per_yr) * 1e3,
            (beta[4] - m.parallax_mas) * 1e3,
        ];
        assert!(
            err_uas.iter().all(|e| e.abs() < 1.0),
            "{err_uas:?} µas(/yr)"
        );
        assert!(beta[0].abs() < 1e-3 && beta[1].abs() < 1e-3, "{beta:?}");
    }

    #[test]
    fn parallax_factors_are_what_pmpx_displaces() {
        // SOFA's pmpx with ϖ = 1 mas against ϖ = 0, on the tangent plane: the factors to 1 µas, at four
        // dates around the year (the first-order formula's error is ≈ ϖ² ≪ 1 µas)
        let c = (266.4168, -29.0078);
        for date in [
            "2031-03-21T00:00:00",
            "2031-06-21T06:00:00",
            "2031-09-22T12:00:00",
            "2031-12-21T18:00:00",
        ] {
            let p = place(date, false);
            let none = direction(c.0, c.1, &Motion::default(), &p);
            let with = direction(
                c.0,
                c.1,
                &Motion {
                    parallax_mas: 1.0,
                    ..Motion::default()
                },
                &p,
            );
            let (dx, dy) = offset_mas(none, with);
            let f = parallax_factors(c.0, c.1, p.observer.position_au);
            assert!(
                (dx - f[0]).abs() < 1e-3 && (dy - f[1]).abs() < 1e-3,
                "{date}: ({dx}, {dy}) vs {f:?}"
            );
            assert!(f[0].hypot(f[1]) > 0.05 && f[0].hypot(f[1]) < 1.02, "{f:?}");
        }
    }
}
