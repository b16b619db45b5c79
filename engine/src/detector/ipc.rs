//! Inter-pixel capacitance: the voltage a pixel's node reads includes a fraction of its neighbours'
//! charge, a convolution of the collected charge with
//!
//! ```text
//!     α′   α    α′
//!     α  1−4α−4α′ α
//!     α′   α    α′
//! ```
//!
//! which keeps the total (charge is not lost, only shared) and correlates neighbouring pixels' shot noise;
//! the read noise, added at the node, is not convolved. α ≈ 1–2 % and α′ ≈ 0.1–0.2 % for HgCdTe (the
//! romanisim kernel, H2RG measurements); JASMINE's InGaAs figure was not found — `detector.ipc_alpha` and
//! `detector.ipc_alpha_diagonal` are knobs, 0 (off) by default. Beyond the array's edge there is no charge.

use rayon::prelude::*;

/// `charge` (row-major `n × n`) convolved with the kernel of `alpha` (edge neighbours) and `alpha_diag`
/// (corner neighbours).
pub fn couple(charge: &[f64], n: usize, alpha: f64, alpha_diag: f64) -> Vec<f64> {
    let centre = 1.0 - 4.0 * alpha - 4.0 * alpha_diag;
    let at = |x: isize, y: isize| -> f64 {
        if x < 0 || y < 0 || x >= n as isize || y >= n as isize {
            0.0
        } else {
            charge[y as usize * n + x as usize]
        }
    };
    let mut out = vec![0.0; n * n];
    out.par_chunks_mut(n).enumerate().for_each(|(y, row)| {
        let y = y as isize;
        for (x, v) in row.iter_mut().enumerate() {
            let x = x as isize;
            let edges = at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1);
            let corners = at(x - 1, y - 1) + at(x + 1, y - 1) + at(x - 1, y + 1) + at(x + 1, y + 1);
            *v = centre * at(x, y) + alpha * edges + alpha_diag * corners;
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_spreads_into_the_kernel_and_the_total_is_kept() {
        let n = 7;
        let mut c = vec![0.0; n * n];
        c[3 * n + 3] = 1000.0;
        let out = couple(&c, n, 0.015, 0.002);
        assert!((out[3 * n + 3] - 1000.0 * (1.0 - 0.06 - 0.008)).abs() < 1e-9);
        for (dx, dy, w) in [(1, 0, 0.015), (0, -1, 0.015), (1, 1, 0.002), (-1, 1, 0.002)] {
            let i = (3 + dy) as usize * n + (3 + dx) as usize;
            assert!((out[i] - 1000.0 * w).abs() < 1e-9);
        }
        assert!((out.iter().sum::<f64>() - 1000.0).abs() < 1e-9);
        // a flat field stays flat inside the array
        let flat = couple(&vec![5.0; n * n], n, 0.015, 0.002);
        assert!((flat[3 * n + 3] - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_shot_noise_of_neighbours_becomes_correlated_by_2_alpha() {
        // white noise of variance 1 through the kernel: the correlation of horizontal neighbours is
        // 2α·c / (c² + 4α² + 4α′²) with c = 1 − 4α − 4α′ (α′ = 0: 2α(1 − 4α)/((1 − 4α)² + 4α²))
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let n = 400;
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let w: Vec<f64> = (0..n * n).map(|_| StandardNormal.sample(&mut r)).collect();
        let a = 0.02;
        let out = couple(&w, n, a, 0.0);
        let (mut s01, mut s00) = (0.0, 0.0);
        for y in 1..n - 1 {
            for x in 1..n - 2 {
                s01 += out[y * n + x] * out[y * n + x + 1];
                s00 += out[y * n + x] * out[y * n + x];
            }
        }
        let c = 1.0 - 4.0 * a;
        let expect = 2.0 * a * c / (c * c + 4.0 * a * a);
        let got = s01 / s00;
        // 1.6e5 pairs: σ ≈ 1/√N = 0.0025
        assert!((got - expect).abs() < 0.01, "{got} vs {expect}");
    }
}
