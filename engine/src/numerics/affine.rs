//! A 2-D affine map `p ↦ (m₀ + m₁ p_x + m₂ p_y, m₃ + m₄ p_x + m₅ p_y)` and its least-squares fit over pairs
//! of points: what registers one set of positions onto another (a catalogue onto an image, an array's
//! detections onto the reference stars of the solution).

/// Fewest pairs for the affine fit (6 parameters); fewer give the mean shift.
pub const MIN_AFFINE_PAIRS: usize = 6;

/// The identity map.
pub const IDENTITY: [f64; 6] = [0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

/// `m` applied to `p`.
pub fn apply(m: &[f64; 6], p: [f64; 2]) -> [f64; 2] {
    [
        m[0] + m[1] * p[0] + m[2] * p[1],
        m[3] + m[4] * p[0] + m[5] * p[1],
    ]
}

/// The least-squares map from `pairs`' first to second points: affine with ≥ [`MIN_AFFINE_PAIRS`] pairs, else the mean shift
/// (the identity for none). The coordinates are centred on their means before the fit.
pub fn fit(pairs: &[([f64; 2], [f64; 2])]) -> [f64; 6] {
    if pairs.is_empty() {
        return IDENTITY;
    }
    let n = pairs.len() as f64;
    let mean = |f: &dyn Fn(&([f64; 2], [f64; 2])) -> f64| pairs.iter().map(f).sum::<f64>() / n;
    let (ox, oy) = (mean(&|p| p.0[0]), mean(&|p| p.0[1]));
    let (rx, ry) = (mean(&|p| p.1[0]), mean(&|p| p.1[1]));
    if pairs.len() >= MIN_AFFINE_PAIRS {
        let mut design = Vec::with_capacity(pairs.len() * 3);
        let (mut yx, mut yy) = (Vec::new(), Vec::new());
        for (o, r) in pairs {
            design.extend_from_slice(&[1.0, (o[0] - ox) / 1e6, (o[1] - oy) / 1e6]);
            yx.push(r[0] - rx);
            yy.push(r[1] - ry);
        }
        let w = vec![1.0; pairs.len()];
        let lstsq = super::linalg::weighted_lstsq;
        if let (Some((a, _)), Some((b, _))) =
            (lstsq(&design, &yx, &w, 3), lstsq(&design, &yy, &w, 3))
        {
            let (a1, a2, b1, b2) = (a[1] / 1e6, a[2] / 1e6, b[1] / 1e6, b[2] / 1e6);
            return [
                rx + a[0] - a1 * ox - a2 * oy,
                a1,
                a2,
                ry + b[0] - b1 * ox - b2 * oy,
                b1,
                b2,
            ];
        }
    }
    [rx - ox, 1.0, 0.0, ry - oy, 0.0, 1.0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_affine_map_is_recovered_and_few_pairs_give_the_mean_shift() {
        let m = [12.5, 1.0 + 2e-4, -1.7e-3, -8.25, 1.7e-3, 1.0 - 3e-4];
        let pts: Vec<[f64; 2]> = (0..30)
            .map(|k| [(k * 67 % 1968) as f64, (k * 151 % 1968) as f64])
            .collect();
        let pairs: Vec<_> = pts.iter().map(|&p| (p, apply(&m, p))).collect();
        let f = fit(&pairs);
        for (a, b) in f.iter().zip(&m) {
            assert!((a - b).abs() < 1e-9, "{f:?} against {m:?}");
        }
        let shift = fit(&[([0.0, 0.0], [1.0, 2.0]), ([4.0, 4.0], [5.0, 6.0])]);
        assert_eq!(shift, [1.0, 1.0, 0.0, 2.0, 0.0, 1.0]);
        assert_eq!(fit(&[]), IDENTITY);
    }
}
