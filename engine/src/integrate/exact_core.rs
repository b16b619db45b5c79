//! The part of an exposure every pixel of a frame shares, deposited once and re-read exactly for a star at
//! any phase of the node grid.
//!
//! A sample at `D = track·G` (nodes) lands, for a star whose offset is `N + φ` nodes (N whole, φ ∈ [0, 1)),
//! at `N + D + φ`: in the cell `N + ⌊D⌋ + c` with `c = [frac D + φ ≥ 1]` and fractions `t = frac D + φ − c`
//! per axis. Its cloud-in-cell weights are bilinear in t, so what a cell's samples give its four nodes is
//! a linear combination of the sums `Σ ω (1, f_u, f_v, f_u f_v)` (f = frac D, ω the window weight) over
//! each of the four carry quadrants. The samples of a cell are stored sorted by f_u with running sums, so
//! the u-carry set is a prefix found by a binary search and the sums over it a look-up; one pass over the
//! cell with the v-carry mask gives the rest. That is a few operations per sample and no scattered writes,
//! where a plain deposit computes and scatters four weights per sample for every star; the histogram is the
//! same (the same terms summed in another order: equal to rounding, ≈ 1e-15 relative).

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
    /// Per sample, cell by cell, sorted by decreasing `f_u`: `f_u`, `f_v`, `ω·(1, f_u, f_v, f_u f_v)`, and
    /// the running sum of the moments within its cell (inclusive).
    fu: Vec<f64>,
    fv: Vec<f64>,
    m: Vec<[f64; 4]>,
    running: Vec<[f64; 4]>,
}

impl ExactCore {
    /// Group the samples of `window` by cell on a grid of `g` nodes per pixel; `None` when the window is
    /// empty.
    pub fn new(track: &Track, window: &WindowWeights, g: usize) -> Option<Self> {
        if track.is_empty() || window.last < window.first {
            return None;
        }
        let gf = g as f64;
        let js = window.first..=window.last;
        let cell_of = |j: usize| {
            let (du, dv) = (track.dx_px[j] * gf, track.dy_px[j] * gf);
            let (a, b) = (du.floor(), dv.floor());
            (a as i64, b as i64, du - a, dv - b)
        };
        let (mut a0, mut a1, mut b0, mut b1) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
        for j in js.clone() {
            let (a, b, _, _) = cell_of(j);
            (a0, a1, b0, b1) = (a0.min(a), a1.max(a), b0.min(b), b1.max(b));
        }
        let (na, nb) = ((a1 - a0 + 1) as usize, (b1 - b0 + 1) as usize);
        // counting sort by cell, then each cell by decreasing f_u
        let mut count = vec![0usize; na * nb + 1];
        let mut sample_cell = Vec::with_capacity(window.last - window.first + 1);
        for j in js.clone() {
            let (a, b, fu, fv) = cell_of(j);
            let c = (b - b0) as usize * na + (a - a0) as usize;
            count[c + 1] += 1;
            sample_cell.push((c, fu, fv, window.weight(j)));
        }
        for c in 0..na * nb {
            count[c + 1] += count[c];
        }
        let mut slot = count.clone();
        let mut sorted = vec![(0.0, 0.0, 0.0); sample_cell.len()];
        for &(c, fu, fv, w) in &sample_cell {
            sorted[slot[c]] = (fu, fv, w);
            slot[c] += 1;
        }
        let mut cells = Vec::new();
        let (mut fus, mut fvs) = (Vec::with_capacity(sorted.len()), Vec::new());
        let (mut m, mut running) = (Vec::with_capacity(sorted.len()), Vec::new());
        for c in 0..na * nb {
            let (s, e) = (count[c], count[c + 1]);
            if s == e {
                continue;
            }
            let cell = &mut sorted[s..e];
            cell.sort_by(|x, y| y.0.total_cmp(&x.0));
            let mut run = [0.0; 4];
            for &(fu, fv, w) in cell.iter() {
                let mk = [w, w * fu, w * fv, w * fu * fv];
                for k in 0..4 {
                    run[k] += mk[k];
                }
                fus.push(fu);
                fvs.push(fv);
                m.push(mk);
                running.push(run);
            }
            cells.push((c % na, c / na, s, e));
        }
        Some(Self {
            g: gf,
            a0,
            b0,
            na,
            nb,
            cells,
            fu: fus,
            fv: fvs,
            m,
            running,
        })
    }

    /// The shared window's histogram of a star at `(ox, oy)` px from a stamp origin, in a box that also
    /// holds every other sample of the track whose displacements lie in `extent` (px: min x, max x, min y,
    /// max y), so the rest of the star's window can be added to it sample by sample.
    pub fn histogram_at(&self, ox_px: f64, oy_px: f64, extent: (f64, f64, f64, f64)) -> NodeTable {
        let (xu, xv) = (ox_px * self.g, oy_px * self.g);
        let (nu_s, nv_s) = (xu.floor(), xv.floor());
        let (px, py) = (xu - nu_s, xv - nv_s);
        let (nu_i, nv_i) = (nu_s as i64, nv_s as i64);
        // the box: this window's cells with their carries and a node of margin, and every sample of the
        // track (the same arithmetic as a sample's own deposit, with a node of margin)
        let node = |o: f64, d: f64| ((o + d) * self.g).floor() as i64;
        let u0 = (nu_i + self.a0 - 1).min(node(ox_px, extent.0) - 1);
        let v0 = (nv_i + self.b0 - 1).min(node(oy_px, extent.2) - 1);
        let u1 = (nu_i + self.a0 + self.na as i64 + 2).max(node(ox_px, extent.1) + 2);
        let v1 = (nv_i + self.b0 + self.nb as i64 + 2).max(node(oy_px, extent.3) + 2);
        let (nu, nv) = ((u1 - u0 + 1) as usize, (v1 - v0 + 1) as usize);
        let mut data = vec![0.0; nu * nv];
        for &(ca, cb, s, e) in &self.cells {
            // samples s..nx carry along u (f_u + φ_u ≥ 1: a prefix, f_u decreasing)
            let nx = s + self.fu[s..e].partition_point(|&f| f + px >= 1.0);
            let total = self.running[e - 1];
            let sx = if nx > s {
                self.running[nx - 1]
            } else {
                [0.0; 4]
            };
            // the v-carry sums over the u-carry prefix and over the rest
            let masked = |r: std::ops::Range<usize>| {
                let mut acc = [0.0; 4];
                for (fv, mk) in self.fv[r.clone()].iter().zip(&self.m[r]) {
                    let c = if fv + py >= 1.0 { 1.0 } else { 0.0 };
                    for k in 0..4 {
                        acc[k] += c * mk[k];
                    }
                }
                acc
            };
            let sxy = masked(s..nx);
            let rest = masked(nx..e);
            let q = |k: usize| {
                let sy = sxy[k] + rest[k];
                [
                    total[k] - sx[k] - sy + sxy[k], // no carry
                    sx[k] - sxy[k],                 // carry along u
                    sy - sxy[k],                    // carry along v
                    sxy[k],                         // both
                ]
            };
            let (q0, q1, q2, q3) = (q(0), q(1), q(2), q(3));
            for (quad, (cu, cv)) in [(0i64, 0i64), (1, 0), (0, 1), (1, 1)]
                .into_iter()
                .enumerate()
            {
                let (m0, m1, m2, m3) = (q0[quad], q1[quad], q2[quad], q3[quad]);
                if m0 == 0.0 {
                    continue;
                }
                // t_u = f_u + α_u, t_v = f_v + α_v for this quadrant's samples
                let (au, av) = (px - cu as f64, py - cv as f64);
                let su = m1 + au * m0;
                let sv = m2 + av * m0;
                let suv = m3 + av * m1 + au * m2 + au * av * m0;
                let iu = (nu_i + self.a0 + ca as i64 + cu - u0) as usize;
                let iv = (nv_i + self.b0 + cb as i64 + cv - v0) as usize;
                let i = iv * nu + iu;
                data[i] += m0 - su - sv + suv;
                data[i + 1] += su - suv;
                data[i + nu] += sv - suv;
                data[i + nu + 1] += suv;
            }
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
