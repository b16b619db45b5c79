//! The part of an exposure every pixel of a frame shares, deposited once and re-read exactly for a star at
//! any phase of the node grid.
//!
//! A sample at `D = track·G` (nodes) lands, for a star whose offset is `N + φ` nodes (N whole, φ ∈ [0, 1)),
//! at `N + D + φ`: in the cell `N + ⌊D⌋ + c` with `c = [frac D + φ ≥ 1]` and fractions `t = frac D + φ − c`
//! per axis. Its cloud-in-cell weights are bilinear in t, so what a cell's samples give its four nodes is
//! a linear combination of the sums `Σ (1, f_u, f_v, f_u f_v)` (f = frac D) over each of the four carry
//! quadrants. Those sums are kept in a [`Cursor`] that follows the stars a thread reads: stars taken in
//! order of phase, the next star moves only the samples whose fraction lies between its phase and the
//! last one's from one quadrant to another (the samples sorted by each fraction make the carried ones a
//! prefix, so the movers are the difference of two prefixes); a star far from the last is summed afresh,
//! cell by cell. The window's two end samples (fractional weights) are deposited apart. The histogram is
//! the same as a plain deposit (the same terms summed in another order: equal to rounding, ≈ 1e-15
//! relative).

use super::track::{Track, WindowWeights};

/// A star's histogram of the shared window: `data[r·nu + c]` at nodes `(u0 + c, v0 + r)` from the stamp origin.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeTable {
    pub u0: i64,
    pub v0: i64,
    pub nu: usize,
    pub nv: usize,
    pub data: Vec<f64>,
}

/// A frame's shared window, its samples grouped by cell (at star phase 0).
#[derive(Debug, Clone)]
pub struct ExactCore {
    g: f64,
    /// Cell box: cells `a0 … a0 + na − 1` along u, `b0 … b0 + nb − 1` along v.
    a0: i64,
    b0: i64,
    na: usize,
    nb: usize,
    /// Occupied cells: (u-cell offset, v-cell offset, first sample, one past the last).
    cells: Vec<(usize, usize, usize, usize)>,
    /// The interior samples' fractions, cell by cell.
    fu: Vec<f64>,
    fv: Vec<f64>,
    /// The window's end samples (u-cell, v-cell, f_u, f_v, weight), deposited apart.
    ends: Vec<(i64, i64, f64, f64, f64)>,
    /// The interior samples as (cell index, moments `(1, f_u, f_v, f_u f_v)`), by decreasing f_u and by
    /// decreasing f_v: a star's u-carried samples are a prefix of the one, its v-carried samples of the
    /// other. The moments are what a move adds and subtracts (four lanes at once).
    by_u: Vec<(u32, [f64; 4])>,
    by_v: Vec<(u32, [f64; 4])>,
}

/// A running read of an [`ExactCore`] for stars taken one after another: the moments of each cell's four
/// carry quadrants at the last star's phase. The next star's phase changes the quadrant of only the samples
/// whose fraction lies between the two phases (found as the difference of two prefixes of `by_u`, `by_v`),
/// so stars taken in order of phase cost a few of those moves each instead of a pass over every sample.
/// The sums are those of a fresh pass to rounding (each move adds and subtracts the same moments; a
/// quadrant whose count returns to 0 is reset to exact zeros), and a star far from the last is read by
/// a fresh pass.
#[derive(Debug, Clone, Default)]
pub struct Cursor {
    /// The phase the sums hold (none before the first read).
    phase: Option<(f64, f64)>,
    /// `by_u[..iu]` are u-carried, `by_v[..iv]` v-carried.
    iu: usize,
    iv: usize,
    /// Per cell, the moments `Σ (1, f_u, f_v, f_u f_v)` of quadrants `(c_u, c_v)` = (0, 0), (1, 0), (0, 1),
    /// (1, 1): `quad[cell][moment][quadrant]`, so that the four quadrants of a moment sit side by side in the
    /// vector units when the cell is read.
    quad: Vec<[[f64; 4]; 4]>,
    /// Samples moved and fresh passes so far (what a test reads to see that both ways of reading ran).
    pub moved: usize,
    pub passes: usize,
}

impl ExactCore {
    /// Group the samples of `window` by cell on a grid of `g` nodes per pixel; `None` when the window is
    /// empty.
    pub fn new(track: &Track, window: &WindowWeights, g: usize) -> Option<Self> {
        if track.is_empty() || window.last < window.first {
            return None;
        }
        let gf = g as f64;
        let cell_of = |j: usize| {
            let (du, dv) = (track.dx_px[j] * gf, track.dy_px[j] * gf);
            let (a, b) = (du.floor(), dv.floor());
            (a as i64, b as i64, du - a, dv - b)
        };
        let (mut a0, mut a1, mut b0, mut b1) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
        for j in window.first..=window.last {
            let (a, b, _, _) = cell_of(j);
            (a0, a1, b0, b1) = (a0.min(a), a1.max(a), b0.min(b), b1.max(b));
        }
        let (na, nb) = ((a1 - a0 + 1) as usize, (b1 - b0 + 1) as usize);
        let ends: Vec<(i64, i64, f64, f64, f64)> = [window.first, window.last]
            .into_iter()
            .take(if window.last > window.first { 2 } else { 1 })
            .map(|j| {
                let (a, b, fu, fv) = cell_of(j);
                (a, b, fu, fv, window.weight(j))
            })
            .collect();
        // the interior samples by cell; within a cell by decreasing f_u — no longer needed by the cursor (it
        // finds the carried samples in `by_u`, `by_v`), kept because it fixes the order a fresh pass sums them
        // in, and so the rounding of every image made since
        let mut samples: Vec<(usize, usize, f64, f64)> = (window.first + 1..window.last)
            .map(|j| {
                let (a, b, fu, fv) = cell_of(j);
                ((b - b0) as usize, (a - a0) as usize, fu, fv)
            })
            .collect();
        samples.sort_by(|x, y| (x.0, x.1).cmp(&(y.0, y.1)).then(y.2.total_cmp(&x.2)));
        let fu: Vec<f64> = samples.iter().map(|x| x.2).collect();
        let fv: Vec<f64> = samples.iter().map(|x| x.3).collect();
        let mut cells = Vec::new();
        let mut s = 0;
        while s < samples.len() {
            let cell = (samples[s].0, samples[s].1);
            let e = s + samples[s..]
                .iter()
                .position(|x| (x.0, x.1) != cell)
                .unwrap_or(samples.len() - s);
            cells.push((cell.1, cell.0, s, e));
            s = e;
        }
        let mut by_u: Vec<(u32, [f64; 4])> = Vec::with_capacity(fu.len());
        for (c, &(_, _, s, e)) in cells.iter().enumerate() {
            by_u.extend((s..e).map(|j| (c as u32, [1.0, fu[j], fv[j], fu[j] * fv[j]])));
        }
        let mut by_v = by_u.clone();
        by_u.sort_by(|x, y| y.1[1].total_cmp(&x.1[1]));
        by_v.sort_by(|x, y| y.1[2].total_cmp(&x.1[2]));
        Some(Self {
            g: gf,
            a0,
            b0,
            na,
            nb,
            cells,
            fu,
            fv,
            ends,
            by_u,
            by_v,
        })
    }

    /// A cursor for reading stars one after another ([`ExactCore::histogram_with`]).
    pub fn cursor(&self) -> Cursor {
        Cursor::default()
    }

    /// Bring the cursor's quadrant sums to phase `(px, py)`: move the samples whose carry changes, or,
    /// when they are more than a third of all, sum every cell afresh.
    fn follow(&self, c: &mut Cursor, px: f64, py: f64) {
        let iu = self.by_u.partition_point(|x| x.1[1] + px >= 1.0);
        let iv = self.by_v.partition_point(|x| x.1[2] + py >= 1.0);
        let Some((_, py0)) = c.phase else {
            return self.fresh(c, px, py, iu, iv);
        };
        if iu.abs_diff(c.iu) + iv.abs_diff(c.iv) > self.by_u.len() / 3 {
            return self.fresh(c, px, py, iu, iv);
        }
        // u first (at the old v-phase), then v (at the new u-phase)
        let mut moved = 0;
        let (lo, hi, to) = (c.iu.min(iu), c.iu.max(iu), iu > c.iu);
        for (cell, m) in &self.by_u[lo..hi] {
            let cv = (m[2] + py0 >= 1.0) as usize;
            move_sample(&mut c.quad[*cell as usize], m, 2 * cv, 2 * cv + 1, to);
        }
        moved += hi - lo;
        let (lo, hi, to) = (c.iv.min(iv), c.iv.max(iv), iv > c.iv);
        for (cell, m) in &self.by_v[lo..hi] {
            let cu = (m[1] + px >= 1.0) as usize;
            move_sample(&mut c.quad[*cell as usize], m, cu, cu + 2, to);
        }
        moved += hi - lo;
        c.moved += moved;
        (c.iu, c.iv, c.phase) = (iu, iv, Some((px, py)));
    }

    /// The quadrant sums at phase `(px, py)`, every sample summed.
    fn fresh(&self, c: &mut Cursor, px: f64, py: f64, iu: usize, iv: usize) {
        c.quad.clear();
        c.quad.resize(self.cells.len(), [[0.0; 4]; 4]);
        for (q, &(_, _, s, e)) in c.quad.iter_mut().zip(&self.cells) {
            for (&u, &v) in self.fu[s..e].iter().zip(&self.fv[s..e]) {
                let k = (u + px >= 1.0) as usize + 2 * (v + py >= 1.0) as usize;
                let m = [1.0, u, v, u * v];
                for (t, mi) in q.iter_mut().zip(m) {
                    t[k] += mi;
                }
            }
        }
        c.passes += 1;
        (c.iu, c.iv, c.phase) = (iu, iv, Some((px, py)));
    }

    /// The shared window's histogram of a star at `(ox, oy)` px from a stamp origin, in a box that also
    /// holds every other sample of the track whose displacements lie in `extent` (px: min x, max x, min y,
    /// max y), so the rest of the star's window can be added to it sample by sample. `cursor` holds the
    /// last star's quadrant sums and follows this star's phase.
    pub fn histogram_with(
        &self,
        cursor: &mut Cursor,
        ox_px: f64,
        oy_px: f64,
        extent: (f64, f64, f64, f64),
    ) -> NodeTable {
        let (xu, xv) = (ox_px * self.g, oy_px * self.g);
        let (nu_s, nv_s) = (xu.floor(), xv.floor());
        let (px, py) = (xu - nu_s, xv - nv_s);
        let (nu_i, nv_i) = (nu_s as i64, nv_s as i64);
        self.follow(cursor, px, py);
        // the box: this window's cells with their carries and a node of margin, and every sample of the
        // track (the same arithmetic as a sample's own deposit, with a node of margin)
        let node = |o: f64, d: f64| ((o + d) * self.g).floor() as i64;
        let u0 = (nu_i + self.a0 - 1).min(node(ox_px, extent.0) - 1);
        let v0 = (nv_i + self.b0 - 1).min(node(oy_px, extent.2) - 1);
        let u1 = (nu_i + self.a0 + self.na as i64 + 2).max(node(ox_px, extent.1) + 2);
        let v1 = (nv_i + self.b0 + self.nb as i64 + 2).max(node(oy_px, extent.3) + 2);
        let (nu, nv) = ((u1 - u0 + 1) as usize, (v1 - v0 + 1) as usize);
        let mut data = vec![0.0; nu * nv];
        // what the samples of a cell carried by (cu, cv) with moments m give the cell's four nodes: (1 − t_u)(1 − t_v),
        // t_u (1 − t_v), (1 − t_u) t_v, t_u t_v summed, with t_u = f_u + α_u, t_v = f_v + α_v
        let weights = |cu: usize, cv: usize, m: &[f64; 4]| {
            let (au, av) = (px - cu as f64, py - cv as f64);
            let su = m[1] + au * m[0];
            let sv = m[2] + av * m[0];
            let suv = m[3] + av * m[1] + au * m[2] + au * av * m[0];
            [m[0] - su - sv + suv, su - suv, sv - suv, suv]
        };
        let at = |a: i64, b: i64| (nv_i + b - v0) as usize * nu + (nu_i + a - u0) as usize;
        let read = CellRead {
            cells: &self.cells,
            quad: &cursor.quad,
            px,
            py,
            nu,
            base: at(self.a0, self.b0),
        };
        add_cells(&mut data, &read);
        for &(a, b, fu, fv, wt) in &self.ends {
            if wt == 0.0 {
                continue;
            }
            let (cu, cv) = ((fu + px >= 1.0) as usize, (fv + py >= 1.0) as usize);
            let w = weights(cu, cv, &[wt, wt * fu, wt * fv, wt * fu * fv]);
            let i = at(a + cu as i64, b + cv as i64);
            data[i] += w[0];
            data[i + 1] += w[1];
            data[i + nu] += w[2];
            data[i + nu + 1] += w[3];
        }
        NodeTable {
            u0,
            v0,
            nu,
            nv,
            data,
        }
    }
}

/// Move one sample's moments `m` from quadrant `from` to `to_k` (`forward`), or back.
#[inline(always)]
fn move_sample(q: &mut [[f64; 4]; 4], m: &[f64; 4], from: usize, to_k: usize, forward: bool) {
    let (src, dst) = if forward { (from, to_k) } else { (to_k, from) };
    for (qm, mk) in q.iter_mut().zip(m) {
        qm[src] -= mk;
        qm[dst] += mk;
    }
    if q[0][src] == 0.0 {
        // the count is exact: an emptied quadrant holds exact zeros, not the rounding of its moves
        for qm in q.iter_mut() {
            qm[src] = 0.0;
        }
    }
}

/// What the samples of a cell give its 3 × 3 nodes (`nodes`, row by row, added to): quadrant `(c_u, c_v)`
/// with moments `m` carried by `α = phase − c` gives its four nodes `(1 − t_u)(1 − t_v)`, `t_u (1 − t_v)`,
/// `(1 − t_u) t_v`, `t_u t_v` summed over its samples, `t = f + α` — written in the moments. The four
/// quadrants are worked out side by side; each node then takes its quadrants' terms in the order of the
/// quadrants. An empty quadrant's moments are exact zeros, so its terms are +0 and change no node.
#[inline(always)]
fn add_cell(nodes: &mut [[f64; 3]; 3], q: &[[f64; 4]; 4], px: f64, py: f64) {
    let [m0, m1, m2, m3] = *q;
    let au = [px, px - 1.0, px, px - 1.0];
    let av = [py, py, py - 1.0, py - 1.0];
    let mut w = [[0.0; 4]; 4];
    for k in 0..4 {
        let su = m1[k] + au[k] * m0[k];
        let sv = m2[k] + av[k] * m0[k];
        let suv = m3[k] + av[k] * m1[k] + au[k] * m2[k] + au[k] * av[k] * m0[k];
        w[0][k] = m0[k] - su - sv + suv;
        w[1][k] = su - suv;
        w[2][k] = sv - suv;
        w[3][k] = suv;
    }
    // quadrant k = c_u + 2 c_v adds w[0][k] … w[3][k] to nodes (c_v, c_u), (c_v, c_u + 1), (c_v + 1, c_u),
    // (c_v + 1, c_u + 1); here node by node, quadrants in increasing k
    nodes[0][0] += w[0][0];
    nodes[0][1] = nodes[0][1] + w[1][0] + w[0][1];
    nodes[0][2] += w[1][1];
    nodes[1][0] = nodes[1][0] + w[2][0] + w[0][2];
    nodes[1][1] = nodes[1][1] + w[3][0] + w[2][1] + w[1][2] + w[0][3];
    nodes[1][2] = nodes[1][2] + w[3][1] + w[1][3];
    nodes[2][0] += w[2][2];
    nodes[2][1] = nodes[2][1] + w[3][2] + w[2][3];
    nodes[2][2] += w[3][3];
}

/// A star's read of the occupied cells: their quadrants' moments at its phase `(px, py)`, into a table of row
/// length `nu` where cell (0, 0)'s first node is at `base` (cell `(a, b)`'s at `base + b·nu + a`).
struct CellRead<'a> {
    cells: &'a [(usize, usize, usize, usize)],
    quad: &'a [[[f64; 4]; 4]],
    px: f64,
    py: f64,
    nu: usize,
    base: usize,
}

/// Every occupied cell's quadrants into `data`.
#[inline(always)]
fn add_cells_body(data: &mut [f64], r: &CellRead<'_>) {
    let nu = r.nu;
    for (&(ca, cb, _, _), q) in r.cells.iter().zip(r.quad) {
        // the cell's 3 × 3 nodes (its four quadrants reach one node further each way) summed in registers
        let i = r.base + cb * nu + ca;
        let mut nodes = [[0.0; 3]; 3];
        for (k, row) in nodes.iter_mut().enumerate() {
            row.copy_from_slice(&data[i + k * nu..i + k * nu + 3]);
        }
        add_cell(&mut nodes, q, r.px, r.py);
        for (k, row) in nodes.iter().enumerate() {
            data[i + k * nu..i + k * nu + 3].copy_from_slice(row);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_cells_avx2(data: &mut [f64], r: &CellRead<'_>) {
    add_cells_body(data, r);
}

/// [`add_cells_body`], in its AVX2 build where the processor has it (the same bits: no fused multiply-adds).
#[allow(unsafe_code)] // calling the AVX2 build after checking the processor has AVX2: nothing else
fn add_cells(data: &mut [f64], r: &CellRead<'_>) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { add_cells_avx2(data, r) };
        return;
    }
    add_cells_body(data, r);
}
