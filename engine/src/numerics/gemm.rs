//! Safe wrapper around `matrixmultiply::dgemm` (row-major, optional transposes): the one place in the
//! crate that uses `unsafe`, with the slice lengths checked before the call.
#![allow(unsafe_code)]

/// A row-major matrix view `rows × cols`, optionally used transposed.
#[derive(Clone, Copy)]
pub struct Mat<'a> {
    pub data: &'a [f64],
    pub rows: usize,
    pub cols: usize,
    pub transposed: bool,
}

impl<'a> Mat<'a> {
    pub fn new(data: &'a [f64], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            transposed: false,
        }
    }
    pub fn t(self) -> Self {
        Self {
            transposed: !self.transposed,
            ..self
        }
    }
    /// (rows, cols) of the matrix as used.
    fn shape(&self) -> (usize, usize) {
        if self.transposed {
            (self.cols, self.rows)
        } else {
            (self.rows, self.cols)
        }
    }
    /// (row stride, column stride) of the matrix as used.
    fn strides(&self) -> (isize, isize) {
        if self.transposed {
            (1, self.cols as isize)
        } else {
            (self.cols as isize, 1)
        }
    }
}

/// `c = alpha · a · b + beta · c`, `c` row-major `a.rows_used × b.cols_used`.
///
/// # Panics
/// If the shapes disagree or a slice is shorter than its shape (a programming error, never user input).
pub fn gemm(alpha: f64, a: Mat<'_>, b: Mat<'_>, beta: f64, c: &mut [f64]) {
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert_eq!(k, k2, "gemm: inner dimensions differ");
    assert!(
        a.data.len() >= a.rows * a.cols && b.data.len() >= b.rows * b.cols,
        "gemm: input too short"
    );
    assert!(c.len() >= m * n, "gemm: output too short");
    if m == 0 || n == 0 {
        return;
    }
    let (rsa, csa) = a.strides();
    let (rsb, csb) = b.strides();
    // SAFETY: every index the kernel touches, i·rs + j·cs for i < rows and j < cols, lies inside the slices
    // whose lengths were checked above; `c` is a unique borrow, so it aliases neither input.
    unsafe {
        matrixmultiply::dgemm(
            m,
            k,
            n,
            alpha,
            a.data.as_ptr(),
            rsa,
            csa,
            b.data.as_ptr(),
            rsb,
            csb,
            beta,
            c.as_mut_ptr(),
            n as isize,
            1,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_naive_product_with_transposes() {
        let a: Vec<f64> = (0..6).map(|x| x as f64 * 0.5 - 1.0).collect(); // 2×3
        let b: Vec<f64> = (0..12).map(|x| (x as f64).sin()).collect(); // 3×4 (or 4×3 transposed)
        let mut c = vec![0.0; 8];
        gemm(1.0, Mat::new(&a, 2, 3), Mat::new(&b, 3, 4), 0.0, &mut c);
        for i in 0..2 {
            for j in 0..4 {
                let s: f64 = (0..3).map(|k| a[i * 3 + k] * b[k * 4 + j]).sum();
                assert!((c[i * 4 + j] - s).abs() < 1e-14);
            }
        }
        let mut d = vec![0.0; 8];
        gemm(1.0, Mat::new(&a, 2, 3), Mat::new(&b, 4, 3).t(), 0.0, &mut d);
        for i in 0..2 {
            for j in 0..4 {
                let s: f64 = (0..3).map(|k| a[i * 3 + k] * b[j * 3 + k]).sum();
                assert!((d[i * 4 + j] - s).abs() < 1e-14);
            }
        }
    }
}
