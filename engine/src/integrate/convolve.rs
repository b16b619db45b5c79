//! The fast method's histogram ⊛ K at every pixel centre of a stamp, blocked for the vector units.
//!
//! `S(X, Y) = Σ_{v,u} H(v, u) · K(X·G − u + h, Y·G − v + h)` (node coordinates relative to the stamp origin,
//! G nodes per pixel, h = K's half width). Pixel centres are G nodes apart, so for one histogram node the
//! K columns a row of pixels reads are G apart too: K stored by residue (`kx = G·m + ρ`, the
//! [`Polyphase`] layout) makes them contiguous. Each histogram node then adds `H · K_ρ[m … m + 8]` to eight
//! pixels of four rows at once — accumulators that stay in registers for the whole histogram, one load per
//! multiply-add, no horizontal sums. It is the same sum as a dot product per pixel (exact: every term is
//! the bilinear K look-up of [`super::kernel`]), in a fixed order that does not depend on the machine: the
//! AVX2 build selected at run time and the portable one give the same bits (no fused multiply-adds).
//!
//! Histogram rows are taken by their residue mod G: rows G apart read the same K rows one pixel row
//! apart, so what one row loads is still in the L1 cache for the next (7 % less time than row by row on the
//! realistic-ACE bulge field). The stamp's last rows are summed in blocks of two and one, its last ≤ 4
//! pixels of a row in a block of four, so no accumulators are spent beyond the stamp (a 34 × 35 stamp in
//! blocks of 8 × 4 spent 15 % of them there). The look-ups in the inner loop are unchecked (their bounds
//! follow from the run's columns, stated where they are read); with both, the convolution takes ≈ 8 % less
//! time on the bulge field, every sum the same bits (each pixel adds the same terms in the same order).
//!
//! A block at the edge of a node's reach multiplies K's zeros: on the realistic-ACE bulge field 7.9 % of the
//! multiply-adds were rows of a block beyond K's table and 14.1 % lanes beyond it (counted over the default
//! exposure). A histogram row's run now leaves out the block's rows beyond the table, and its nodes whose
//! eight look-ups lie half beyond it (≥ 4 lanes) take only the other half's lanes; a product with zero adds
//! nothing to a sum, so every sum keeps its bits. The sums' share of the exposure's profile fell from 43.4
//! to 42.7 % (6–8 % less time against the rest of the integration); the default exposure's MEF is
//! byte-identical.

use super::kernel::PixelKernel;
use super::polyphase::{LANES, PAD, Polyphase};

/// Pixel rows per block.
const ROWS: usize = 4;

/// A histogram on K's node grid, given by its non-zero run of each row: row `v0 + r` holds `values` at
/// columns `u0 + a … u0 + b − 1` (node coordinates relative to the stamp origin).
#[derive(Clone)]
pub struct RowRuns<'a> {
    pub u0: i64,
    pub v0: i64,
    /// (row r, first column a, one-past-last column b, values of columns a … b − 1)
    pub runs: Vec<(usize, usize, usize, &'a [f64])>,
}

/// `out[iy·nx + ix] += Σ H(v, u) K(ix·G − u + h, iy·G − v + h)` for the `nx × ny` pixels of a stamp (the
/// histogram's runs are put in the order they are summed in: by row residue mod G).
#[allow(unsafe_code)] // calling the AVX2 build after checking the processor has AVX2: nothing else
pub fn add_convolution(
    out: &mut [f64],
    nx: usize,
    ny: usize,
    hist: &mut RowRuns<'_>,
    k: &PixelKernel,
) {
    let p = k.polyphase();
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { add_convolution_avx2(out, nx, ny, hist, p, k.half_nodes) };
        return;
    }
    add_convolution_body(out, nx, ny, hist, p, k.half_nodes);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_convolution_avx2(
    out: &mut [f64],
    nx: usize,
    ny: usize,
    hist: &mut RowRuns<'_>,
    p: &Polyphase,
    half: usize,
) {
    add_convolution_body(out, nx, ny, hist, p, half);
}

#[inline(always)]
fn add_convolution_body(
    out: &mut [f64],
    nx: usize,
    ny: usize,
    hist: &mut RowRuns<'_>,
    p: &Polyphase,
    half: usize,
) {
    // histogram rows taken by residue mod G: rows G apart read the same K rows (pixel row i of row
    // v + G reads what pixel row i − 1 of row v does), so the K lines one row loads are still in the
    // nearest cache for the next; a one-row stamp (a row's own histogram) has no rows to share and keeps
    // the histogram's order
    if ny > 1 {
        hist.runs.sort_by_key(|run| (run.0 % p.g, run.0));
    }
    let mut s = Sums {
        out,
        nx,
        hist,
        p,
        half,
        reads: Vec::with_capacity(hist.runs.len()),
    };
    // whole blocks of ROWS rows, then the last rows in blocks of two and one (no accumulators spent on rows
    // beyond the stamp)
    let whole = ny - ny % ROWS;
    for iy0 in (0..whole).step_by(ROWS) {
        s.row_of_blocks::<ROWS>(iy0);
    }
    let mut iy0 = whole;
    if ny - iy0 >= 2 {
        s.row_of_blocks::<2>(iy0);
        iy0 += 2;
    }
    if iy0 < ny {
        s.row_of_blocks::<1>(iy0);
    }
}

/// One stamp's sums: where they go and what they read.
struct Sums<'a, 'h> {
    out: &'a mut [f64],
    nx: usize,
    hist: &'a RowRuns<'h>,
    p: &'a Polyphase,
    half: usize,
    /// What the current row of blocks reads of each histogram row (filled by `row_of_blocks`).
    reads: Vec<RunRows<'a>>,
}

impl<'a> Sums<'a, '_> {
    /// Pixel rows `iy0 … iy0 + R − 1` in blocks of [`LANES`] pixels; the last pixels (≤ 4 of them) in one
    /// block of four. Which K rows each histogram row reads for these pixel rows (and which of them lie in
    /// the table) is the same for every block of the row, so it is found once here.
    #[inline(always)]
    fn row_of_blocks<const R: usize>(&mut self, iy0: usize) {
        let p: &'a Polyphase = self.p;
        let (g, h) = (p.g as i64, self.half as i64);
        let mut reads = std::mem::take(&mut self.reads);
        reads.clear();
        for &(r, a, b, values) in &self.hist.runs {
            let ky0 = iy0 as i64 * g + h - (self.hist.v0 + r as i64);
            // the rows beyond K's table (its row of zeros) are left out: only the rows from the first K row in
            // the table to the last take the run (adding a product with zero changes no sum); none, none do
            let mut rows = [p.zeros.as_slice(); ROWS];
            for (k, row) in rows.iter_mut().take(R).enumerate() {
                *row = p.row(ky0 + k as i64 * g);
            }
            let beyond = |row: &&&[f64]| row.as_ptr() == p.zeros.as_ptr();
            let k0 = rows[..R].iter().take_while(beyond).count();
            if k0 == R {
                continue;
            }
            let k1 = R - rows[..R].iter().rev().take_while(beyond).count();
            reads.push(RunRows {
                a,
                b,
                values,
                rows,
                k0,
                k1,
            });
        }
        let nx = self.nx;
        let whole = nx - nx % LANES;
        for ix0 in (0..whole).step_by(LANES) {
            self.block::<LANES, R>(&reads, ix0, iy0);
        }
        match nx - whole {
            0 => {}
            1..=4 => self.block::<4, R>(&reads, whole, iy0),
            _ => self.block::<LANES, R>(&reads, whole, iy0),
        }
        self.reads = reads;
    }

    /// `Σ H · K` for the L pixels from `ix0` of the R rows from `iy0` (pixels beyond the stamp are summed and
    /// dropped): each histogram node adds `H · K_ρ[q … q + L]` of R K rows to R × L accumulators.
    #[inline(always)]
    fn block<const L: usize, const R: usize>(
        &mut self,
        reads: &[RunRows<'_>],
        ix0: usize,
        iy0: usize,
    ) {
        let p = self.p;
        let (g, h) = (p.g as i64, self.half as i64);
        let m = p.m as i64;
        let mut acc = [[0.0f64; L]; R];
        // K column of pixel ix0 + i for histogram column c: t − c + i·G with t = ix0·G + h − u0
        let t = ix0 as i64 * g + h - self.hist.u0;
        for read in reads {
            let Some((i0, i1, q, rho)) = columns(t, read.a, read.b, m, g, L) else {
                continue;
            };
            let Some(rows) = read.rows.first_chunk::<R>() else {
                continue;
            };
            let values = &read.values[i0..=i1];
            match (R, read.k0, read.k1) {
                (4, 1, 4) => run(&mut acc, rows, values, q, rho, p, 1, 4),
                (4, 2, 4) => run(&mut acc, rows, values, q, rho, p, 2, 4),
                (4, 3, 4) => run(&mut acc, rows, values, q, rho, p, 3, 4),
                (4, 0, 3) => run(&mut acc, rows, values, q, rho, p, 0, 3),
                (4, 0, 2) => run(&mut acc, rows, values, q, rho, p, 0, 2),
                (4, 0, 1) => run(&mut acc, rows, values, q, rho, p, 0, 1),
                _ => run(&mut acc, rows, values, q, rho, p, 0, R),
            }
        }
        let nx = self.nx;
        let w = L.min(nx - ix0);
        for (k, acc_k) in acc.iter().enumerate() {
            let iy = iy0 + k;
            for (o, v) in self.out[iy * nx + ix0..iy * nx + ix0 + w]
                .iter_mut()
                .zip(acc_k)
            {
                *o += v;
            }
        }
    }
}

/// A histogram row's run as a row of blocks reads it: its columns `a … b − 1` and values, the K rows (residue
/// layout) its R ≤ [`ROWS`] pixel rows read, and the first and one-past-last of them in the table.
struct RunRows<'a> {
    a: usize,
    b: usize,
    values: &'a [f64],
    rows: [&'a [f64]; ROWS],
    k0: usize,
    k1: usize,
}

/// One histogram row's nodes (the first at residue position (q, ρ)) into accumulator rows `k0 … k1 − 1`. Nodes
/// whose look-ups lie half beyond K's table (≥ 4 of a block's 8 lanes read its zeros: the block is at the edge
/// of their reach) go only into the other half's lanes. Called with constant rows, so that each case compiles
/// to its own loop.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn run<const L: usize, const R: usize>(
    acc: &mut [[f64; L]; R],
    rows: &[&[f64]; R],
    values: &[f64],
    q: i64,
    rho: i64,
    p: &Polyphase,
    k0: usize,
    k1: usize,
) {
    let (g, m, len) = (p.g as i64, p.m as i64, p.len);
    let mut at = Cursor {
        s: rho as usize * len + (q + PAD as i64) as usize,
        rho,
        g,
        len,
        wrap: (p.g - 1) * len - 1,
    };
    let half = LANES / 2;
    if L == LANES && m >= L as i64 {
        // along the run q falls by one every G nodes: first the nodes with q ≥ m − 4 (lanes ≥ m − q read
        // zeros: the upper half), then the whole blocks, then those with q ≤ −4 (lanes < −q: the lower half)
        let n = values.len() as i64;
        let d0 = q * g + rho;
        let lower_end = (d0 - (m - half as i64) * g + 1).clamp(0, n) as usize;
        let upper_start = (d0 + (half as i64 - 1) * g + 1).clamp(lower_end as i64, n) as usize;
        nodes(acc, rows, &values[..lower_end], &mut at, k0, k1, 0, half);
        nodes(
            acc,
            rows,
            &values[lower_end..upper_start],
            &mut at,
            k0,
            k1,
            0,
            L,
        );
        nodes(acc, rows, &values[upper_start..], &mut at, k0, k1, half, L);
    } else {
        nodes(acc, rows, values, &mut at, k0, k1, 0, L);
    }
}

/// Where a run's next look-up is: `s = ρ·len + PAD + q`; the next node's is one residue down (ρ − 1), or
/// the last residue of the column before (ρ = G − 1, q − 1).
struct Cursor {
    s: usize,
    rho: i64,
    g: i64,
    len: usize,
    wrap: usize,
}

/// `acc[k][i] += H · K_k[s + i]` for each node, rows `k0 … k1 − 1`, lanes `i0 … i1 − 1`.
#[inline(always)]
#[allow(unsafe_code)] // unchecked look-ups, bounds proven below
#[allow(clippy::too_many_arguments)]
fn nodes<const L: usize, const R: usize>(
    acc: &mut [[f64; L]; R],
    rows: &[&[f64]; R],
    values: &[f64],
    at: &mut Cursor,
    k0: usize,
    k1: usize,
    i0: usize,
    i1: usize,
) {
    for &hv in values {
        let s = at.s;
        for k in k0..k1 {
            // SAFETY: `columns` keeps −L < q < m for every node of the run and 0 ≤ ρ < G, so PAD + q ≥ 1 and
            // PAD + q + L ≤ m + 2·PAD = len: s + L ≤ G·len, the length of every row (a K row's residues or
            // the row of zeros); `read_unaligned` takes any alignment.
            debug_assert!(s + L <= rows[k].len());
            let kv: [f64; L] =
                unsafe { std::ptr::read_unaligned(rows[k].as_ptr().add(s).cast::<[f64; L]>()) };
            for i in i0..i1 {
                acc[k][i] += hv * kv[i];
            }
        }
        if at.rho == 0 {
            at.rho = at.g - 1;
            at.s += at.wrap;
        } else {
            at.rho -= 1;
            at.s -= at.len;
        }
    }
}

/// Where a histogram row meets a block of L pixels: its columns `c_lo ..= c_hi` whose K blocks meet the
/// table, and the residue position (q, ρ) of the first (`t − c = G·q + ρ`); `None` when none does.
#[inline(always)]
fn columns(
    t: i64,
    a: usize,
    b: usize,
    m: i64,
    g: i64,
    lanes: usize,
) -> Option<(usize, usize, i64, i64)> {
    // −L < q < m
    let c_lo = (a as i64).max(t - m * g + 1);
    let c_hi = (b as i64 - 1).min(t + (lanes as i64 - 1) * g);
    if c_hi < c_lo {
        return None;
    }
    let d = t - c_lo;
    Some((
        (c_lo - a as i64) as usize,
        (c_hi - a as i64) as usize,
        d.div_euclid(g),
        d.rem_euclid(g),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked convolution against the plain double sum over histogram nodes with K's own node look-up
    /// (no residue layout, no blocks): stamps of sizes that are not multiples of the block, histograms that
    /// reach past K's table on every side, one-row stamps; and the AVX2 build gives the portable one's bits.
    /// Two tables: one narrower than a block of eight columns per residue, and one wider, whose blocks at the
    /// edge of a node's reach take only half their lanes (and rows beyond the table none).
    #[test]
    fn blocked_convolution_equals_the_plain_sum() {
        let g = 4usize;
        for half_px in [3, 9] {
            let k = PixelKernel::tabulated(g, half_px, |dx, dy| {
                (-(dx * dx + 0.7 * dy * dy) / 8.0).exp() * (1.0 + 0.3 * dx) + 0.01 * dy
            });
            assert_eq!(k.polyphase().m >= LANES, half_px == 9);
            plain_sum_cases(&k, g);
        }
    }

    fn plain_sum_cases(k: &PixelKernel, g: usize) {
        let h = k.half_nodes as i64;
        // (stamp nx, ny, histogram origin u0, v0 relative to the stamp, size nu × nv)
        for &(nx, ny, u0, v0, nu, nv) in &[
            (11usize, 9usize, 13i64, 17i64, 9usize, 7usize),
            (1, 1, -3, 2, 5, 4),
            (17, 3, -40, -30, 90, 70),
            (9, 1, 20, 0, 6, 3),
            (30, 13, 60, 30, 11, 12),
            (12, 6, 10, 8, 40, 30),
            (4, 2, 5, 3, 8, 7),
            (40, 30, 70, 50, 30, 26),
        ] {
            let data: Vec<f64> = (0..nu * nv)
                .map(|i| {
                    if i % 7 == 3 {
                        0.0
                    } else {
                        ((i * 37) % 11) as f64 + 0.25
                    }
                })
                .collect();
            let runs = RowRuns {
                u0,
                v0,
                runs: (0..nv)
                    .map(|r| (r, 0, nu, &data[r * nu..(r + 1) * nu]))
                    .collect(),
            };
            let mut plain = vec![0.0; nx * ny];
            for iy in 0..ny {
                for ix in 0..nx {
                    let mut acc = 0.0;
                    for r in 0..nv {
                        for c in 0..nu {
                            let du = ix as i64 * g as i64 - (u0 + c as i64);
                            let dv = iy as i64 * g as i64 - (v0 + r as i64);
                            acc += data[r * nu + c] * k.node(du, dv);
                        }
                    }
                    plain[iy * nx + ix] = acc;
                }
            }
            let mut fast = vec![1.0; nx * ny];
            add_convolution(&mut fast, nx, ny, &mut runs.clone(), k);
            let peak = plain.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (f, p) in fast.iter().zip(&plain) {
                assert!(
                    (f - 1.0 - p).abs() <= 1e-12 * peak.max(1.0),
                    "{nx}×{ny} at ({u0}, {v0}): {f} vs {p} + 1"
                );
            }
            let mut portable = vec![1.0; nx * ny];
            add_convolution_body(
                &mut portable,
                nx,
                ny,
                &mut runs.clone(),
                k.polyphase(),
                h as usize,
            );
            assert_eq!(portable, fast, "{nx}×{ny}: the AVX2 build's bits");
        }
    }
}
