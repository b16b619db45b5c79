//! Gauss–Legendre quadrature: n nodes and weights on [−1, 1] that integrate polynomials of degree ≤ 2n − 1
//! exactly (Newton's iteration on Pₙ from the Chebyshev-like guesses cos(π(i − ¼)/(n + ½))).

/// The n nodes and weights on [−1, 1], nodes descending.
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    // Pₙ(x) and Pₙ₋₁(x) by the three-term recurrence
    let legendre = |x: f64| {
        let (mut p0, mut p1) = (1.0, x);
        for k in 2..=n {
            let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
            p0 = p1;
            p1 = p2;
        }
        (p1, p0)
    };
    (1..=n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 - 0.25) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                let (p, q) = legendre(x);
                let dx = p / (n as f64 * (x * p - q) / (x * x - 1.0));
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            let (p, q) = legendre(x);
            let dp = n as f64 * (x * p - q) / (x * x - 1.0);
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫₋₁¹ xᵏ dx = 2/(k + 1) for even k, 0 for odd: exact to degree 2n − 1, not at 2n.
    #[test]
    fn integrates_polynomials_to_degree_2n_minus_1() {
        for n in [1usize, 4, 24, 48] {
            let gl = gauss_legendre(n);
            assert_eq!(gl.len(), n);
            for k in 0..2 * n {
                let got: f64 = gl.iter().map(|(x, w)| w * x.powi(k as i32)).sum();
                let exact = if k % 2 == 0 {
                    2.0 / (k + 1) as f64
                } else {
                    0.0
                };
                assert!((got - exact).abs() < 1e-13, "n {n} k {k}: {got} vs {exact}");
            }
        }
        // and not beyond: x^(2n) with few nodes
        for n in [1usize, 2, 4] {
            let k = 2 * n;
            let got: f64 = gauss_legendre(n)
                .iter()
                .map(|(x, w)| w * x.powi(k as i32))
                .sum();
            assert!(
                (got - 2.0 / (k + 1) as f64).abs() > 1e-6,
                "n {n}: degree 2n is not exact"
            );
        }
    }
}
