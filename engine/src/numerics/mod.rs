//! Small numerical building blocks shared by the physics modules: a 2-D affine map and its fit, a k-d tree of neighbours, a vectorisable dot product, a safe dense
//! matrix product, 2-D FFTs, a dense linear solver, Gauss–Legendre quadrature, and robust statistics.

pub mod affine;
pub mod dot;
pub mod fft2;
pub mod gemm;
pub mod linalg;
pub mod neighbours;
pub mod quadrature;
pub mod stats;
