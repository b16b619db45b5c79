//! Dense linear algebra for small systems (fits with ≤ a few dozen parameters).

/// Solve `A x = b` (A row-major `n×n`) by Gaussian elimination with partial pivoting.
/// Returns `None` when A is singular to working precision (relative pivot < 1e-13).
pub fn solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    let scale = m.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if !(scale > 0.0) || !scale.is_finite() {
        return None;
    }
    for col in 0..n {
        let piv =
            (col..n).max_by(|&i, &j| m[i * n + col].abs().total_cmp(&m[j * n + col].abs()))?;
        if m[piv * n + col].abs() < 1e-13 * scale {
            return None;
        }
        if piv != col {
            for k in 0..n {
                m.swap(piv * n + k, col * n + k);
            }
            x.swap(piv, col);
        }
        for row in col + 1..n {
            let f = m[row * n + col] / m[col * n + col];
            if f != 0.0 {
                for k in col..n {
                    m[row * n + k] -= f * m[col * n + k];
                }
                x[row] -= f * x[col];
            }
        }
    }
    for col in (0..n).rev() {
        let mut s = x[col];
        for k in col + 1..n {
            s -= m[col * n + k] * x[k];
        }
        x[col] = s / m[col * n + col];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Inverse of a row-major `n×n` matrix (column by column with [`solve`]).
pub fn inverse(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut inv = vec![0.0; n * n];
    for c in 0..n {
        let mut e = vec![0.0; n];
        e[c] = 1.0;
        let col = solve(a, &e, n)?;
        for r in 0..n {
            inv[r * n + c] = col[r];
        }
    }
    Some(inv)
}

/// Weighted linear least squares: minimise Σ wᵢ (yᵢ − Σⱼ Xᵢⱼ βⱼ)². `design` is row-major `n_obs × n_par`.
/// Returns the coefficients and their covariance `(XᵀWX)⁻¹`, or `None` if the system is degenerate.
pub fn weighted_lstsq(
    design: &[f64],
    y: &[f64],
    w: &[f64],
    n_par: usize,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n_obs = y.len();
    if n_obs < n_par {
        return None;
    }
    let mut ata = vec![0.0; n_par * n_par];
    let mut atb = vec![0.0; n_par];
    for i in 0..n_obs {
        let row = &design[i * n_par..(i + 1) * n_par];
        for a in 0..n_par {
            atb[a] += w[i] * row[a] * y[i];
            for b in 0..n_par {
                ata[a * n_par + b] += w[i] * row[a] * row[b];
            }
        }
    }
    let beta = solve(&ata, &atb, n_par)?;
    let cov = inverse(&ata, n_par)?;
    Some((beta, cov))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_and_inverts() {
        let a = [4.0, 1.0, 2.0, 1.0, 3.0, 0.5, 2.0, 0.5, 5.0];
        let x = solve(&a, &[1.0, 2.0, 3.0], 3).expect("regular");
        for r in 0..3 {
            let s: f64 = (0..3).map(|c| a[r * 3 + c] * x[c]).sum();
            assert!((s - [1.0, 2.0, 3.0][r]).abs() < 1e-12);
        }
        let inv = inverse(&a, 3).expect("regular");
        for r in 0..3 {
            for c in 0..3 {
                let s: f64 = (0..3).map(|k| a[r * 3 + k] * inv[k * 3 + c]).sum();
                assert!((s - if r == c { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn singular_is_none() {
        assert!(solve(&[1.0, 2.0, 2.0, 4.0], &[1.0, 1.0], 2).is_none());
        assert!(solve(&[f64::NAN, 0.0, 0.0, 1.0], &[1.0, 1.0], 2).is_none());
        assert!(weighted_lstsq(&[1.0, 1.0], &[1.0], &[1.0], 2).is_none());
    }
}
