//! Fringe Zernike polynomials Z1…Z37 (the CODE V / Zemax "Fringe" ordering).
//!
//! Convention: unit disk, `ρ = r / R_aperture`, `θ` from +x towards +y; terms are **not** normalised
//! (Fringe convention: each term's radial part is 1 at ρ = 1). Their mean square over the disk is
//! `1/(n+1)` for m = 0 and `1/(2(n+1))` for m ≠ 0 ([`fringe_norm`]); they are mutually orthogonal.
//! A coefficient in waves at the reference wavelength λ_ref means an optical path difference of
//! `c · λ_ref` (µm). Positive Z2 tilts the wavefront so that the image moves towards +x.

/// Number of Fringe terms supported.
pub const N_FRINGE: usize = 37;

/// Azimuthal part of a term.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trig {
    None,
    Cos,
    Sin,
}

/// (n, m, trig) of Fringe term `j` (1-based, 1..=37).
pub fn fringe_nm(j: usize) -> (u32, u32, Trig) {
    use Trig::*;
    const T: [(u32, u32, Trig); N_FRINGE] = [
        (0, 0, None),
        (1, 1, Cos),
        (1, 1, Sin),
        (2, 0, None),
        (2, 2, Cos),
        (2, 2, Sin),
        (3, 1, Cos),
        (3, 1, Sin),
        (4, 0, None),
        (3, 3, Cos),
        (3, 3, Sin),
        (4, 2, Cos),
        (4, 2, Sin),
        (5, 1, Cos),
        (5, 1, Sin),
        (6, 0, None),
        (4, 4, Cos),
        (4, 4, Sin),
        (5, 3, Cos),
        (5, 3, Sin),
        (6, 2, Cos),
        (6, 2, Sin),
        (7, 1, Cos),
        (7, 1, Sin),
        (8, 0, None),
        (5, 5, Cos),
        (5, 5, Sin),
        (6, 4, Cos),
        (6, 4, Sin),
        (7, 3, Cos),
        (7, 3, Sin),
        (8, 2, Cos),
        (8, 2, Sin),
        (9, 1, Cos),
        (9, 1, Sin),
        (10, 0, None),
        (12, 0, None),
    ];
    T[j - 1]
}

fn factorial(n: u32) -> f64 {
    (1..=n).fold(1.0, |a, k| a * k as f64)
}

/// Zernike radial polynomial `R_n^m(ρ)`.
pub fn radial(n: u32, m: u32, rho: f64) -> f64 {
    let mut sum = 0.0;
    for k in 0..=((n - m) / 2) {
        let c = factorial(n - k)
            / (factorial(k) * factorial((n + m) / 2 - k) * factorial((n - m) / 2 - k));
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        sum += sign * c * rho.powi((n - 2 * k) as i32);
    }
    sum
}

/// The low-order Fringe terms (1-based) an as-built telescope departs from its design by: Z4 … Z11 — focus,
/// astigmatism, coma, spherical, trefoil (`instrument` draws them; the analysis' design PSF correction fits them).
pub const LOW_ORDER_TERMS: [usize; 8] = [4, 5, 6, 7, 8, 9, 10, 11];

/// Fringe term `j` (1-based) at polar coordinates on the unit disk.
pub fn fringe(j: usize, rho: f64, theta: f64) -> f64 {
    let (n, m, trig) = fringe_nm(j);
    let r = radial(n, m, rho);
    match trig {
        Trig::None => r,
        Trig::Cos => r * (m as f64 * theta).cos(),
        Trig::Sin => r * (m as f64 * theta).sin(),
    }
}

/// Mean square of Fringe term `j` over the unit disk: `1/(n+1)` (m = 0) or `1/(2(n+1))`.
pub fn fringe_norm(j: usize) -> f64 {
    let (n, m, _) = fringe_nm(j);
    if m == 0 {
        1.0 / (n as f64 + 1.0)
    } else {
        0.5 / (n as f64 + 1.0)
    }
}

/// Wavefront (same unit as the coefficients) of a coefficient list at (ρ, θ).
pub fn wavefront(coeffs: &[f64], rho: f64, theta: f64) -> f64 {
    coeffs
        .iter()
        .enumerate()
        .filter(|(_, c)| **c != 0.0)
        .map(|(k, c)| c * fringe(k + 1, rho, theta))
        .sum()
}

/// RMS of a wavefront over the full unit disk (piston included), from the orthogonality relations.
pub fn rms(coeffs: &[f64]) -> f64 {
    coeffs
        .iter()
        .enumerate()
        .map(|(k, c)| c * c * fringe_norm(k + 1))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gauss–Legendre nodes/weights on [0, 1].
    fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
        crate::numerics::quadrature::gauss_legendre(n)
            .into_iter()
            .map(|(x, w)| (0.5 * (x + 1.0), 0.5 * w))
            .collect()
    }

    #[test]
    fn fringe_terms_are_orthogonal_with_documented_norms() {
        // Exact quadrature: Gauss–Legendre in ρ (degree ≤ 25 integrand with the ρ weight), uniform in θ.
        let gl = gauss_legendre(24);
        let nt = 64;
        let mut gram = vec![vec![0.0; N_FRINGE]; N_FRINGE];
        for &(rho, w) in &gl {
            for t in 0..nt {
                let th = 2.0 * std::f64::consts::PI * t as f64 / nt as f64;
                let z: Vec<f64> = (1..=N_FRINGE).map(|j| fringe(j, rho, th)).collect();
                for a in 0..N_FRINGE {
                    for b in 0..N_FRINGE {
                        // (1/π) ∫∫ Za Zb ρ dρ dθ
                        gram[a][b] +=
                            z[a] * z[b] * rho * w * (2.0 * std::f64::consts::PI / nt as f64)
                                / std::f64::consts::PI;
                    }
                }
            }
        }
        for a in 0..N_FRINGE {
            for b in 0..N_FRINGE {
                let expect = if a == b { fringe_norm(a + 1) } else { 0.0 };
                assert!(
                    (gram[a][b] - expect).abs() < 1e-12,
                    "Z{} · Z{} = {} (expected {expect})",
                    a + 1,
                    b + 1,
                    gram[a][b]
                );
            }
        }
    }

    #[test]
    fn known_closed_forms() {
        let (r, t) = (0.7_f64, 0.3_f64);
        assert!((fringe(4, r, t) - (2.0 * r * r - 1.0)).abs() < 1e-14);
        assert!((fringe(9, r, t) - (6.0 * r.powi(4) - 6.0 * r * r + 1.0)).abs() < 1e-13);
        assert!(
            (fringe(12, r, t) - (4.0 * r.powi(4) - 3.0 * r * r) * (2.0 * t).cos()).abs() < 1e-13
        );
        let z37 = 924.0 * r.powi(12) - 2772.0 * r.powi(10) + 3150.0 * r.powi(8)
            - 1680.0 * r.powi(6)
            + 420.0 * r.powi(4)
            - 42.0 * r * r
            + 1.0;
        assert!((fringe(37, r, t) - z37).abs() < 1e-10);
        for j in 1..=N_FRINGE {
            let (_, _, trig) = fringe_nm(j);
            let th = if trig == Trig::Sin {
                std::f64::consts::FRAC_PI_2 / fringe_nm(j).1.max(1) as f64
            } else {
                0.0
            };
            assert!((fringe(j, 1.0, th) - 1.0).abs() < 1e-10, "Z{j} at the edge");
        }
    }
}
