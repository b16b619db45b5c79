//! 2-D complex FFTs on row-major square/rectangular arrays (rustfft, unnormalised in both directions:
//! `ifft(fft(x)) = nx·ny·x`).

use rustfft::{FftDirection, FftPlanner, num_complex::Complex64};

/// In-place 2-D FFT of a row-major `ny × nx` array.
pub fn fft2(data: &mut [Complex64], nx: usize, ny: usize, direction: FftDirection) {
    assert_eq!(data.len(), nx * ny);
    let mut planner = FftPlanner::<f64>::new();
    let row = planner.plan_fft(nx, direction);
    let mut scratch = vec![Complex64::default(); row.get_inplace_scratch_len()];
    for r in data.chunks_mut(nx) {
        row.process_with_scratch(r, &mut scratch);
    }
    let col = planner.plan_fft(ny, direction);
    let mut scratch = vec![Complex64::default(); col.get_inplace_scratch_len()];
    let mut buf = vec![Complex64::default(); ny];
    for x in 0..nx {
        for y in 0..ny {
            buf[y] = data[y * nx + x];
        }
        col.process_with_scratch(&mut buf, &mut scratch);
        for y in 0..ny {
            data[y * nx + x] = buf[y];
        }
    }
}

/// Smallest n ≥ `min` whose only prime factors are 2, 3 and 5 (fast sizes for rustfft).
pub fn good_size(min: usize) -> usize {
    let mut n = min.max(1);
    loop {
        let mut m = n;
        for p in [2, 3, 5] {
            while m.is_multiple_of(p) {
                m /= p;
            }
        }
        if m == 1 {
            return n;
        }
        n += 1;
    }
}

/// Linear (non-circular) 2-D convolution of a real `n×n` array with a real kernel given by its
/// transfer function `h(fx, fy)` (cycles per sample), by zero-padding to `pad` samples per side.
/// The output has the input's size and centring.
pub fn convolve_transfer(
    input: &[f64],
    n: usize,
    pad: usize,
    h: impl Fn(f64, f64) -> f64,
) -> Vec<f64> {
    let m = good_size(n + 2 * pad);
    let mut buf = vec![Complex64::default(); m * m];
    for y in 0..n {
        for x in 0..n {
            buf[y * m + x] = Complex64::new(input[y * n + x], 0.0);
        }
    }
    fft2(&mut buf, m, m, FftDirection::Forward);
    for ky in 0..m {
        let fy = if ky <= m / 2 {
            ky as f64
        } else {
            ky as f64 - m as f64
        } / m as f64;
        for kx in 0..m {
            let fx = if kx <= m / 2 {
                kx as f64
            } else {
                kx as f64 - m as f64
            } / m as f64;
            buf[ky * m + kx] *= h(fx, fy);
        }
    }
    fft2(&mut buf, m, m, FftDirection::Inverse);
    let norm = 1.0 / (m * m) as f64;
    // A kernel centred on sample 0 keeps the output aligned with the input; the wrap-around region
    // (indices ≥ n) holds the spill beyond the input's edges, which is dropped.
    let mut out = vec![0.0; n * n];
    for y in 0..n {
        for x in 0..n {
            out[y * n + x] = buf[y * m + x].re * norm;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_inverse_round_trip() {
        let (nx, ny) = (12, 10);
        let orig: Vec<Complex64> = (0..nx * ny)
            .map(|i| Complex64::new((i as f64).sin(), (i as f64 * 0.3).cos()))
            .collect();
        let mut d = orig.clone();
        fft2(&mut d, nx, ny, FftDirection::Forward);
        fft2(&mut d, nx, ny, FftDirection::Inverse);
        for (a, b) in d.iter().zip(&orig) {
            assert!((a / (nx * ny) as f64 - b).norm() < 1e-12);
        }
    }

    #[test]
    fn good_sizes() {
        assert_eq!(good_size(7), 8);
        assert_eq!(good_size(241), 243);
        assert_eq!(good_size(1), 1);
    }

    #[test]
    fn gaussian_transfer_conserves_sum_and_blurs() {
        let n = 41;
        let mut a = vec![0.0; n * n];
        a[20 * n + 20] = 1.0;
        let s = 2.0;
        let out = convolve_transfer(&a, n, 12, |fx, fy| {
            (-2.0 * std::f64::consts::PI.powi(2) * s * s * (fx * fx + fy * fy)).exp()
        });
        let sum: f64 = out.iter().sum();
        assert!((sum - 1.0).abs() < 1e-9, "{sum}");
        let var: f64 = (0..n * n)
            .map(|i| out[i] * ((i % n) as f64 - 20.0).powi(2))
            .sum();
        assert!((var - s * s).abs() < 1e-6, "{var}");
    }
}
