//! Analytic PSF of a centrally obstructed circular aperture (no spiders, no WFE): the validation target.
//!
//! `I(θ)/I(0) = [2J₁(v)/v − ε²·2J₁(εv)/(εv)]² / (1 − ε²)²`, `v = π D θ / λ`, ε = obstruction ratio, and for
//! unit total flux `I(0) = A/λ²` per steradian with `A = π D² (1 − ε²)/4` (Born & Wolf §8.5; Mahajan 1986).

/// Bessel function J_n(x) by the trapezoid rule on Bessel's integral
/// `J_n(x) = (1/2π) ∫₀^{2π} cos(nτ − x sin τ) dτ`, which converges exponentially for a periodic analytic
/// integrand: with M > |x| + 40 points the result is exact to rounding.
pub fn bessel_jn(n: i32, x: f64) -> f64 {
    let m = (2.0 * x.abs() + 64.0) as usize;
    let s: f64 = (0..m)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / m as f64;
            (n as f64 * t - x * t.sin()).cos()
        })
        .sum();
    s / m as f64
}

/// `2 J₁(v)/v`, → 1 at v = 0.
pub fn jinc(v: f64) -> f64 {
    if v.abs() < 1e-8 {
        1.0 - v * v / 8.0
    } else {
        2.0 * bessel_jn(1, v) / v
    }
}

/// Intensity per steradian for unit total flux at angle `theta_rad`.
pub fn obscured_airy_per_sr(theta_rad: f64, lambda_m: f64, diameter_m: f64, epsilon: f64) -> f64 {
    let v = std::f64::consts::PI * diameter_m * theta_rad / lambda_m;
    let amp = (jinc(v) - epsilon * epsilon * jinc(epsilon * v)) / (1.0 - epsilon * epsilon);
    let area = std::f64::consts::PI * diameter_m * diameter_m * (1.0 - epsilon * epsilon) / 4.0;
    area / (lambda_m * lambda_m) * amp * amp
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bessel_known_values() {
        // Abramowitz & Stegun Table 9.1
        assert!((bessel_jn(1, 1.0) - 0.440_050_585_744_933_5).abs() < 1e-14);
        assert!((bessel_jn(0, 2.0) - 0.223_890_779_141_235_7).abs() < 1e-14);
        assert!((bessel_jn(1, 10.0) - 0.043_472_746_168_861_44).abs() < 1e-14);
        // first zero of J1
        assert!(bessel_jn(1, 3.831_705_970_207_512).abs() < 1e-13);
    }

    #[test]
    fn unobscured_first_dark_ring() {
        // zero at θ = 1.2197 λ/D
        let (l, d) = (1.0e-6, 0.36);
        let theta = 1.219_669_891 * l / d;
        assert!(
            obscured_airy_per_sr(theta, l, d, 0.0) / obscured_airy_per_sr(0.0, l, d, 0.0) < 1e-16
        );
    }
}
