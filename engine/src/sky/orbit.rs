//! Where the spacecraft is and how fast it moves: the Earth's barycentric position and velocity from
//! SOFA's `epv00` (VSOP2000-based, ≈ 5 km; the same series astropy's "builtin" ephemeris uses) plus the
//! spacecraft on a circular sun-synchronous orbit.
//!
//! The orbit (a model, every number a knob in `[observation]`): JASMINE's 600 km sun-synchronous orbit with
//! the ascending node at local time 6 h (JASMINE-Mission/jasmine_toolkit). Radius a = R⊕ + h; period
//! P = 2π √(a³/μ); inclination from the node's precession matching the Sun's mean motion,
//! cos i = −(2/3) Ω̇ a^{7/2} / (J₂ R⊕² √μ) (Vallado 2013, eq. 9-43), ≈ 97.8° at 600 km; the node's right
//! ascension is the Sun's plus (LTAN − 12 h)·15°; the argument of latitude advances uniformly from
//! `orbit_phase_deg` at the observation's start. Axes: the GCRS, parallel to the ICRS (precession of the
//! orbit's frame is ignored: it moves the model orbit, not the physics it feeds).
//!
//! Only the observer's position (parallax: 600 km is 4·10⁻⁵ au) and velocity (aberration: 7.6 km/s is
//! 5″ on top of the Earth's 20″) enter the astrometry ([`super::apparent`]).

use crate::time::Epoch;
use sofars::consts::{AULT, DAU, DAYSEC};
use sofars::eph::epv00;

/// Equatorial radius of the Earth, km (WGS 84).
pub const EARTH_RADIUS_KM: f64 = 6_378.137;
/// Geocentric gravitational constant μ, km³/s² (EGM 96).
pub const GM_EARTH_KM3_PER_S2: f64 = 398_600.441_8;
/// The Earth's second zonal harmonic J₂ (EGM 96).
pub const J2_EARTH: f64 = 1.082_63e-3;
/// The Sun's mean motion in right ascension: one turn per tropical year, rad/s.
pub const SUN_MEAN_MOTION_RAD_PER_S: f64 = 2.0 * std::f64::consts::PI / (365.242_2 * 86_400.0);

/// A circular sun-synchronous orbit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// Height above the equatorial radius, km.
    pub altitude_km: f64,
    /// Local time of the ascending node, hours.
    pub ltan_h: f64,
    /// Argument of latitude at `phase_epoch`, degrees.
    pub phase_deg: f64,
    /// When the argument of latitude is `phase_deg`.
    pub phase_epoch: Epoch,
}

/// The observer at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observer {
    /// Barycentric position (BCRS, ICRS axes), au.
    pub position_au: [f64; 3],
    /// Barycentric velocity, au/day.
    pub velocity_au_per_day: [f64; 3],
    /// Heliocentric position, au.
    pub heliocentric_au: [f64; 3],
    /// The spacecraft's geocentric position (GCRS), km.
    pub gcrs_position_km: [f64; 3],
    /// The spacecraft's geocentric velocity (GCRS), km/s.
    pub gcrs_velocity_km_s: [f64; 3],
}

impl Orbit {
    /// Orbit radius a, km.
    pub fn radius_km(&self) -> f64 {
        EARTH_RADIUS_KM + self.altitude_km
    }

    /// Period P = 2π √(a³/μ), s.
    pub fn period_s(&self) -> f64 {
        2.0 * std::f64::consts::PI * (self.radius_km().powi(3) / GM_EARTH_KM3_PER_S2).sqrt()
    }

    /// The sun-synchronous inclination, radians: cos i = −(2/3) Ω̇ a^{7/2} / (J₂ R⊕² √μ).
    pub fn inclination_rad(&self) -> f64 {
        let a = self.radius_km();
        let c = -2.0 / 3.0 * SUN_MEAN_MOTION_RAD_PER_S * a.powf(3.5)
            / (J2_EARTH * EARTH_RADIUS_KM * EARTH_RADIUS_KM * GM_EARTH_KM3_PER_S2.sqrt());
        c.clamp(-1.0, 1.0).acos()
    }

    /// The argument of latitude at `t`, degrees in [0, 360): `phase_deg` + 360° (t − phase_epoch)/P (the
    /// angle [`Orbit::geocentric`] places the spacecraft at, from the ascending node).
    pub fn argument_of_latitude_deg(&self, t: &Epoch) -> f64 {
        (self.phase_deg + 360.0 * t.seconds_since(&self.phase_epoch) / self.period_s())
            .rem_euclid(360.0)
    }

    /// The spacecraft's geocentric position (km) and velocity (km/s) at `t`, the Sun's geocentric
    /// direction `sun` (unit vector) giving the node.
    pub fn geocentric(&self, t: &Epoch, sun: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let sun_ra = sun[1].atan2(sun[0]);
        let node = sun_ra + (self.ltan_h - 12.0) * std::f64::consts::PI / 12.0;
        let i = self.inclination_rad();
        let u = self.phase_deg.to_radians()
            + 2.0 * std::f64::consts::PI * t.seconds_since(&self.phase_epoch) / self.period_s();
        let (sn, cn) = node.sin_cos();
        let (si, ci) = i.sin_cos();
        let (su, cu) = u.sin_cos();
        let n_hat = [cn, sn, 0.0];
        let m_hat = [-ci * sn, ci * cn, si];
        let a = self.radius_km();
        let v = (GM_EARTH_KM3_PER_S2 / a).sqrt();
        let pos = std::array::from_fn(|k| a * (cu * n_hat[k] + su * m_hat[k]));
        let vel = std::array::from_fn(|k| v * (-su * n_hat[k] + cu * m_hat[k]));
        (pos, vel)
    }

    /// The observer (the spacecraft) at `t`: the Earth's barycentric and heliocentric position and
    /// velocity (`epv00`, TDB) plus the spacecraft's geocentric ones.
    pub fn observer(&self, t: &Epoch) -> Observer {
        let (d1, d2) = t.tdb_jd();
        // epv00 warns (None) only outside 1900–2100, which Epoch refuses; fall back to its values anyway
        let ([ph, _vh], [pb, vb]) = epv00(d1, d2).unwrap_or(([[0.0; 3]; 2], [[0.0; 3]; 2]));
        let norm = (ph[0] * ph[0] + ph[1] * ph[1] + ph[2] * ph[2])
            .sqrt()
            .max(1e-12);
        let sun = [-ph[0] / norm, -ph[1] / norm, -ph[2] / norm];
        let (gp, gv) = self.geocentric(t, sun);
        let km_per_au = DAU / 1e3;
        Observer {
            position_au: std::array::from_fn(|k| pb[k] + gp[k] / km_per_au),
            velocity_au_per_day: std::array::from_fn(|k| vb[k] + gv[k] * DAYSEC / km_per_au),
            heliocentric_au: std::array::from_fn(|k| ph[k] + gp[k] / km_per_au),
            gcrs_position_km: gp,
            gcrs_velocity_km_s: gv,
        }
    }
}

impl Observer {
    /// Barycentric velocity in units of c.
    pub fn velocity_c(&self) -> [f64; 3] {
        self.velocity_au_per_day.map(|v| v * AULT / DAYSEC)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn orbit() -> Orbit {
        Orbit {
            altitude_km: 600.0,
            ltan_h: 6.0,
            phase_deg: 0.0,
            phase_epoch: Epoch::from_utc_iso("2031-03-21T00:00:00").expect("date"),
        }
    }

    #[test]
    fn sun_synchronous_orbit_of_600_km() {
        let o = orbit();
        // the textbook values for a 600-km sun-synchronous orbit: i ≈ 97.79°, P ≈ 96.7 min, v ≈ 7.56 km/s
        assert!((o.inclination_rad().to_degrees() - 97.79).abs() < 0.02);
        assert!(
            (o.period_s() / 60.0 - 96.69).abs() < 0.05,
            "{}",
            o.period_s()
        );
        let t = o.phase_epoch.plus_s(1234.0);
        let ob = o.observer(&t);
        let r = ob
            .gcrs_position_km
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        let v = ob
            .gcrs_velocity_km_s
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        assert!(
            (r - 6_978.137).abs() < 1e-6 && (v - 7.558).abs() < 0.002,
            "{r} {v}"
        );
        let dot: f64 = (0..3)
            .map(|k| ob.gcrs_position_km[k] * ob.gcrs_velocity_km_s[k])
            .sum();
        assert!(dot.abs() < 1e-6 * r * v, "circular: r ⟂ v");
        // LTAN 6 h: the orbit's normal points within 9° of the Sun at the equinox (a dawn-dusk orbit; i ≠ 90° tilts it)
        let p = ob.gcrs_position_km;
        let w = ob.gcrs_velocity_km_s;
        let n = [
            p[1] * w[2] - p[2] * w[1],
            p[2] * w[0] - p[0] * w[2],
            p[0] * w[1] - p[1] * w[0],
        ];
        let nn = n.iter().map(|v| v * v).sum::<f64>().sqrt();
        let h = ob.heliocentric_au;
        let hn = h.iter().map(|v| v * v).sum::<f64>().sqrt();
        let cos_sun = -(0..3).map(|k| n[k] * h[k]).sum::<f64>() / (nn * hn);
        assert!(cos_sun.abs() > (9f64).to_radians().cos(), "{cos_sun}");
        // one period later the spacecraft is back (the node moved with the Sun: ≈ 0.07°)
        let later = o.observer(&t.plus_s(o.period_s()));
        let d = (0..3)
            .map(|k| (later.gcrs_position_km[k] - p[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(d < 0.002 * r, "{d}");
    }

    #[test]
    fn earth_is_one_au_from_the_sun_moving_30_km_s() {
        let ob = orbit().observer(&Epoch::from_utc_iso("2031-07-04T00:00:00").expect("date"));
        let r: f64 = ob.heliocentric_au.iter().map(|v| v * v).sum::<f64>().sqrt();
        // aphelion early July: 1.0167 au
        assert!((r - 1.0167).abs() < 2e-4, "{r}");
        let v: f64 = ob.velocity_c().iter().map(|v| v * v).sum::<f64>().sqrt();
        // 29.3 km/s at aphelion ± 7.6 km/s of the orbit, in units of c
        assert!(v * 299_792.458 > 21.0 && v * 299_792.458 < 37.5, "{v}");
    }
}
