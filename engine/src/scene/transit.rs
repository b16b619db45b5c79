//! A star's brightness through a planet's transit: the limb-darkened occultation of Mandel & Agol (2002, ApJ
//! 580, L171) with the quadratic law, on a circular orbit.
//!
//! The star's intensity at radius r (in stellar radii; μ = √(1 − r²)) is
//! `I(r) = 1 − u₁(1 − μ) − u₂(1 − μ)²`; its flux `F₀ = ∫₀¹ I 2πr dr = π (1 − u₁/3 − u₂/6)`. A planet of radius
//! p at projected distance z hides, of the ring at radius r, the arc 2φ(r) with
//! `cos φ = (r² + z² − p²) / (2 r z)` (φ = π where the ring lies inside the planet, 0 where outside), so the
//! fraction of the flux hidden is
//!
//! ```text
//!     δ(p, z) = (1 / F₀) ∫₀¹ I(r) 2 r φ(r) dr.
//! ```
//!
//! Mandel & Agol write this integral in closed form with elliptic integrals; here it is evaluated by
//! Gauss–Legendre quadrature on each interval between its kinks (|z − p|, p − z, z + p, 1) after the
//! substitution `r = a + (b − a)(1 − cos θ)/2`, which removes the square-root behaviour of φ and of μ at the
//! ends — the way batman (Kreidberg 2015) evaluates laws without a closed form. 48 nodes per interval give
//! δ to better than 10⁻¹⁰ (tests: the uniform source's closed form; the small-planet limit; batman's
//! closed-form quadratic law in the Python tests).
//!
//! The orbit: `z(t) = (a/R★) √(sin² ω + cos² i cos² ω)`, `ω = 2π (t − t₀)/P`, the planet in front when
//! `cos ω > 0`.

/// A transiting planet on a circular orbit, with its star's limb darkening.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transit {
    /// Mid-transit time, days (on the light curve's clock).
    pub t0_days: f64,
    pub period_days: f64,
    /// Planet radius over star radius (p).
    pub rp_over_rs: f64,
    /// Orbital semi-major axis over star radius.
    pub a_over_rs: f64,
    /// Orbital inclination, degrees (90: central transit).
    pub inclination_deg: f64,
    /// Quadratic limb-darkening coefficients.
    pub u1: f64,
    pub u2: f64,
}

impl Transit {
    /// Every field in its allowed range, or the named field and that range.
    pub fn validate(&self) -> Result<(), String> {
        let finite = [
            ("transit.t0_days", self.t0_days),
            ("transit.period_days", self.period_days),
            ("transit.rp_over_rs", self.rp_over_rs),
            ("transit.a_over_rs", self.a_over_rs),
            ("transit.inclination_deg", self.inclination_deg),
            ("transit.u1", self.u1),
            ("transit.u2", self.u2),
        ];
        if let Some((name, v)) = finite.iter().find(|(_, v)| !v.is_finite()) {
            return Err(format!("{name} = {v}: must be a finite number"));
        }
        if self.period_days <= 0.0 {
            return Err(format!(
                "transit.period_days = {}: must be > 0 (a period of zero is no orbit)",
                self.period_days
            ));
        }
        if !(self.rp_over_rs > 0.0 && self.rp_over_rs <= 1.0) {
            return Err(format!(
                "transit.rp_over_rs = {}: allowed (0, 1]",
                self.rp_over_rs
            ));
        }
        if self.a_over_rs <= 1.0 + self.rp_over_rs {
            return Err(format!(
                "transit.a_over_rs = {}: must exceed 1 + rp_over_rs = {} (the planet outside its star)",
                self.a_over_rs,
                1.0 + self.rp_over_rs
            ));
        }
        if !(0.0..=90.0).contains(&self.inclination_deg) {
            return Err(format!(
                "transit.inclination_deg = {}: allowed 0 … 90",
                self.inclination_deg
            ));
        }
        // the law must stay positive and fall from the centre: u₁ + u₂ ≤ 1, u₁ ≥ 0, u₁ + 2u₂ ≥ 0 (Kipping 2013)
        if !(self.u1 >= 0.0 && self.u1 + self.u2 <= 1.0 && self.u1 + 2.0 * self.u2 >= 0.0) {
            return Err(format!(
                "transit.u1 = {}, transit.u2 = {}: allowed u1 ≥ 0, u1 + u2 ≤ 1, u1 + 2·u2 ≥ 0 (a positive \
                 intensity falling towards the limb)",
                self.u1, self.u2
            ));
        }
        Ok(())
    }

    /// The impact parameter b = (a/R★) cos i.
    pub fn impact(&self) -> f64 {
        self.a_over_rs * self.inclination_deg.to_radians().cos()
    }

    /// The total duration (first to fourth contact), days: `P/π · asin(√((1 + p)² − b²) / (a sin i))`; 0
    /// when the planet misses the star.
    pub fn duration_days(&self) -> f64 {
        let b = self.impact();
        let reach = (1.0 + self.rp_over_rs).powi(2) - b * b;
        if reach <= 0.0 {
            return 0.0;
        }
        let s =
            (reach.sqrt() / (self.a_over_rs * self.inclination_deg.to_radians().sin())).min(1.0);
        self.period_days / std::f64::consts::PI * s.asin()
    }

    /// The projected star–planet distance at `t_days`, in stellar radii; `None` when the planet is behind.
    pub fn separation(&self, t_days: f64) -> Option<f64> {
        let w = std::f64::consts::TAU * (t_days - self.t0_days) / self.period_days;
        let (s, c) = w.sin_cos();
        (c > 0.0).then(|| {
            let ci = self.inclination_deg.to_radians().cos();
            self.a_over_rs * (s * s + ci * ci * c * c).sqrt()
        })
    }

    /// The star's relative flux at `t_days` (1 out of transit).
    pub fn flux(&self, t_days: f64) -> f64 {
        match self.separation(t_days) {
            Some(z) => 1.0 - occulted_fraction(self.rp_over_rs, z, self.u1, self.u2),
            None => 1.0,
        }
    }

    /// The flux averaged over an exposure from `t_days` to `t_days + exposure_days`, sampled at `samples`
    /// instants (the middles of equal parts; batman's `supersample_factor`).
    pub fn mean_flux(&self, t_days: f64, exposure_days: f64, samples: usize) -> f64 {
        let n = samples.max(1);
        (0..n)
            .map(|k| self.flux(t_days + exposure_days * (k as f64 + 0.5) / n as f64))
            .sum::<f64>()
            / n as f64
    }
}

/// Nodes per interval of the occultation integral.
const NODES: usize = 48;

thread_local! {
    static GL: Vec<(f64, f64)> = crate::numerics::quadrature::gauss_legendre(NODES);
}

/// ∫ₐᵇ f(r) dr with r = a + (b − a)(1 − cos θ)/2, θ ∈ [0, π], by Gauss–Legendre in θ.
fn integrate(a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    GL.with(|gl| {
        let h = std::f64::consts::FRAC_PI_2;
        gl.iter()
            .map(|&(x, w)| {
                let th = h * (x + 1.0);
                let r = a + (b - a) * (1.0 - th.cos()) / 2.0;
                w * f(r) * (b - a) / 2.0 * th.sin()
            })
            .sum::<f64>()
            * h
    })
}

/// The fraction of a quadratically limb-darkened star's flux hidden by a planet of radius `p` (stellar
/// radii) at projected distance `z`: δ of the module's equation.
pub fn occulted_fraction(p: f64, z: f64, u1: f64, u2: f64) -> f64 {
    if !(p > 0.0) || z >= 1.0 + p {
        return 0.0;
    }
    let intensity = |r: f64| {
        let m = 1.0 - (1.0 - (r * r).min(1.0)).sqrt();
        1.0 - u1 * m - u2 * m * m
    };
    let f0 = std::f64::consts::PI * (1.0 - u1 / 3.0 - u2 / 6.0);
    let pi = std::f64::consts::PI;
    // rings wholly inside the planet (z < p): φ = π
    let inner = (p - z).clamp(0.0, 1.0);
    let mut hidden = integrate(0.0, inner, |r| intensity(r) * 2.0 * r * pi);
    // rings the planet's edge crosses
    let (lo, hi) = ((z - p).abs().max(inner), (z + p).min(1.0));
    hidden += integrate(lo, hi, |r| {
        let c = ((r * r + z * z - p * p) / (2.0 * r * z)).clamp(-1.0, 1.0);
        intensity(r) * 2.0 * r * c.acos()
    });
    (hidden / f0).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mandel & Agol's λᵉ: the uniform source's hidden fraction in closed form (their eq. 1).
    fn uniform(p: f64, z: f64) -> f64 {
        if z >= 1.0 + p {
            0.0
        } else if z <= p - 1.0 {
            1.0
        } else if z <= 1.0 - p {
            p * p
        } else {
            let k0 = ((p * p + z * z - 1.0) / (2.0 * p * z)).acos();
            let k1 = ((1.0 - p * p + z * z) / (2.0 * z)).acos();
            (p * p * k0 + k1 - ((4.0 * z * z - (1.0 + z * z - p * p).powi(2)) / 4.0).sqrt())
                / std::f64::consts::PI
        }
    }

    #[test]
    fn a_uniform_star_matches_the_closed_form_everywhere() {
        for &p in &[0.01, 0.1, 0.3, 0.7, 1.0] {
            for k in 0..=400 {
                let z = k as f64 / 400.0 * (1.0 + p) * 1.02;
                let (a, b) = (occulted_fraction(p, z, 0.0, 0.0), uniform(p, z));
                assert!((a - b).abs() < 1e-10, "p {p} z {z}: {a} vs {b}");
            }
        }
    }

    /// A small planet hides its area times the local intensity over the mean: δ → p² I(z) / (1 − u₁/3 − u₂/6)
    /// (Mandel & Agol's small-planet approximation), to O(p⁴).
    #[test]
    fn a_small_planet_hides_its_area_times_the_local_intensity() {
        let (u1, u2, p): (f64, f64, f64) = (0.4, 0.25, 1e-3);
        for z in [0.0f64, 0.3, 0.6, 0.9, 0.99] {
            let mu: f64 = (1.0 - z * z).sqrt();
            let i = 1.0 - u1 * (1.0 - mu) - u2 * (1.0 - mu).powi(2);
            let expect = p * p * i / (1.0 - u1 / 3.0 - u2 / 6.0);
            let got = occulted_fraction(p, z, u1, u2);
            assert!(
                (got / expect - 1.0).abs() < 1e-4,
                "z {z}: {got} vs {expect}"
            );
        }
    }

    /// A planet larger than the star at its centre hides all of it, whatever the law.
    #[test]
    fn a_planet_covering_the_star_hides_all_of_it() {
        assert!((occulted_fraction(1.0, 0.0, 0.3, 0.2) - 1.0).abs() < 1e-12);
        assert_eq!(occulted_fraction(0.1, 1.2, 0.3, 0.2), 0.0);
    }

    #[test]
    fn a_central_transit_lasts_and_dips_as_its_geometry_says() {
        let t = Transit {
            t0_days: 1.0,
            period_days: 3.0,
            rp_over_rs: 0.1,
            a_over_rs: 10.0,
            inclination_deg: 90.0,
            u1: 0.0,
            u2: 0.0,
        };
        // T14 = P/π asin((1 + p)/a) for b = 0
        let t14 = 3.0 / std::f64::consts::PI * (1.1f64 / 10.0).asin();
        assert!((t.duration_days() - t14).abs() < 1e-12);
        assert!((1.0 - t.flux(1.0) - 0.01).abs() < 1e-12);
        assert_eq!(t.flux(1.0 + 0.5 * t14 * 1.001), 1.0);
        assert!(t.flux(1.0 + 0.5 * t14 * 0.999) < 1.0);
        // half a period later the planet is behind the star
        assert_eq!(t.flux(2.5), 1.0);
    }

    #[test]
    fn bad_transits_are_named() {
        let ok = Transit {
            t0_days: 0.0,
            period_days: 14.0,
            rp_over_rs: 0.05,
            a_over_rs: 40.0,
            inclination_deg: 89.9,
            u1: 0.1,
            u2: 0.3,
        };
        assert!(ok.validate().is_ok());
        let e = Transit {
            period_days: 0.0,
            ..ok
        }
        .validate()
        .expect_err("zero period");
        assert!(e.contains("transit.period_days"), "{e}");
        let e = Transit { u1: 1.2, ..ok }.validate().expect_err("law");
        assert!(e.contains("transit.u1"), "{e}");
        let e = Transit {
            a_over_rs: 1.0,
            ..ok
        }
        .validate()
        .expect_err("inside");
        assert!(e.contains("a_over_rs"), "{e}");
    }
}
