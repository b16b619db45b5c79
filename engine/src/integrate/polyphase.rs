//! The pixel kernel K in polyphase form: its columns regrouped by residue modulo G (nodes per pixel), so that a
//! row of pixels reads each node offset of K contiguously (`convolve`'s blocks of [`LANES`] pixels).

/// Pixels per block along a row (lanes of the accumulators).
pub(super) const LANES: usize = 8;
/// Zeros stored on each side of a residue's row, so that a block's eight look-ups never need clipping.
pub(super) const PAD: usize = LANES;

/// K rearranged by column residue: `data[(ky·G + ρ)·len + PAD + m] = K(ky, G·m + ρ)` (0 beyond the table),
/// `len = ⌈n/G⌉ + 2·PAD`. Built once per kernel (`kernel::PixelKernel::polyphase`); 1.4–1.7 × K's memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Polyphase {
    pub(super) g: usize,
    pub(super) n: usize,
    /// Columns of each residue (`⌈n/G⌉`).
    pub(super) m: usize,
    pub(super) len: usize,
    data: Vec<f64>,
    /// One row's worth of zeros, read for pixel rows beyond the table.
    pub(super) zeros: Vec<f64>,
}

impl Polyphase {
    /// The polyphase form of a kernel table of `n × n` nodes, `g` per pixel, row-major.
    pub fn of_table(g: usize, n: usize, table: &[f64]) -> Self {
        let m = n.div_ceil(g);
        let len = m + 2 * PAD;
        let mut data = vec![0.0; n * g * len];
        for ky in 0..n {
            let row = &table[ky * n..(ky + 1) * n];
            for (kx, &v) in row.iter().enumerate() {
                let (mm, rho) = (kx / g, kx % g);
                data[(ky * g + rho) * len + PAD + mm] = v;
            }
        }
        Self {
            g,
            n,
            m,
            len,
            data,
            zeros: vec![0.0; g * len],
        }
    }

    /// The residues of K's row `ky` (`G · len` values), zeros outside the table.
    #[inline(always)]
    pub(super) fn row(&self, ky: i64) -> &[f64] {
        if ky < 0 || ky >= self.n as i64 {
            return &self.zeros;
        }
        let w = self.g * self.len;
        &self.data[ky as usize * w..(ky as usize + 1) * w]
    }

    /// `K(ky, kx + G·i)` for `i = 0 … count − 1`: what a row of pixels reads of one node offset, contiguous in
    /// this layout (residue ρ = kx mod G of K's row `ky`, from column ⌊kx/G⌋); `None` unless `ky < n` and
    /// `kx + G·(count − 1) < n`.
    pub(super) fn along_row(&self, ky: usize, kx: usize, count: usize) -> Option<&[f64]> {
        if ky >= self.n || count == 0 || kx + self.g * (count - 1) >= self.n {
            return None;
        }
        let s = (kx % self.g) * self.len + PAD + kx / self.g;
        self.row(ky as i64).get(s..s + count)
    }
}
