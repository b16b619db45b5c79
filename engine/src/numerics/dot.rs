//! Dot products written so the compiler vectorises them: independent partial sums break the floating-point
//! add chain (one sum would wait ≈ 4 cycles per term), and `chunks_exact` drops the bounds checks. The
//! summation order is fixed by the code, so every machine gives the same bits; against a left-to-right
//! loop it differs only by rounding (≈ 1e-16 relative). (A build of the same code for AVX registers,
//! selected at run time, measured no faster on the fast method: the runs are short and the loop, not the
//! arithmetic, sets the pace.)

/// Lanes of the partial sums.
pub const LANES: usize = 4;

/// `acc[k] += Σ_i a[LANES·i + k] · b[LANES·i + k]` over the common length (the tail into `acc[0]`).
#[inline(always)]
fn dot_into(acc: &mut [f64; LANES], a: &[f64], b: &[f64]) {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..LANES {
            acc[k] += x[k] * y[k];
        }
    }
    for (x, y) in ra.iter().zip(rb) {
        acc[0] += x * y;
    }
}

/// `Σ_pairs Σ_i a_i b_i`: many short products summed into one total (one reduction at the end).
#[inline]
pub fn sum_of_dots<'a>(pairs: impl Iterator<Item = (&'a [f64], &'a [f64])>) -> f64 {
    let mut acc = [0.0; LANES];
    for (a, b) in pairs {
        dot_into(&mut acc, a, b);
    }
    (acc[0] + acc[2]) + (acc[1] + acc[3])
}

/// `Σ_i a_i b_i` over the common length.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    sum_of_dots(std::iter::once((a, b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equals_the_plain_sum_for_every_length() {
        // integers below 2^26 multiply and add exactly in f64: any summation order gives the same value
        for n in 0..40 {
            let a: Vec<f64> = (0..n).map(|i| (i * 7 % 13) as f64 - 6.0).collect();
            let b: Vec<f64> = (0..n).map(|i| (i * 5 % 11) as f64 + 1.0).collect();
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert_eq!(dot(&a, &b), plain, "n = {n}");
            // split anywhere and summed: the same total
            let k = n / 3;
            let split = sum_of_dots([(&a[..k], &b[..k]), (&a[k..], &b[k..])].into_iter());
            assert_eq!(split, plain, "n = {n} split at {k}");
        }
        // unequal lengths: the common part
        assert_eq!(dot(&[1.0, 2.0, 3.0], &[4.0, 5.0]), 14.0);
    }
}
