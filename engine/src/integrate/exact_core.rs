//! The part of an exposure every pixel of a frame shares, deposited once and re-read exactly for a star at
//! any phase of the node grid.
//!
//! A sample at `D = track·G` (nodes) lands, for a star whose offset is `N + φ` nodes (N whole, φ ∈ [0, 1)),
//! at `N + D + φ`: in the cell `N + ⌊D⌋ + c` with `c = [frac D + φ ≥ 1]` and fractions `t = frac D + φ − c`
//! per axis. Its cloud-in-cell weights are bilinear in t, so what a cell's samples give its four nodes is
//! a linear combination of the sums `Σ (1, f_u, f_v, f_u f_v)` (f = frac D) over each of the four carry
//! quadrants. The samples are stored cell by cell as their two fractions (16 bytes a sample, read in order),
//! each cell sorted by decreasing f_u so that the u-carries are a prefix (a binary search); one pass sums the
//! moments under the v-carry mask, with no scattered writes (a plain deposit computes and scatters four
//! weights per sample). The window's two end samples (fractional weights) are
//! deposited apart. The histogram is the same as a plain deposit (the same terms summed in another order:
//! equal to rounding, ≈ 1e-15 relative).

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
    /// Occupied cells: (u-cell offset, v-cell offset, first sample, one past the last) and the moments
    /// `Σ (1, f_u, f_v, f_u f_v)` of all its samples.
    cells: Vec<(usize, usize, usize, usize, [f64; 4])>,
    /// The interior samples' fractions, cell by cell.
    fu: Vec<f64>,
    fv: Vec<f64>,
    /// The window's end samples (u-cell, v-cell, f_u, f_v, weight), deposited apart.
    ends: Vec<(i64, i64, f64, f64, f64)>,
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
        // the interior samples by cell, each cell by decreasing f_u (a star's u-carries are then a prefix)
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
            let mut t = [0.0; 4];
            for (u, v) in fu[s..e].iter().zip(&fv[s..e]) {
                t = [t[0] + 1.0, t[1] + u, t[2] + v, t[3] + u * v];
            }
            cells.push((cell.1, cell.0, s, e, t));
            s = e;
        }
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
        })
    }

    /// The shared window's histogram of a star at `(ox, oy)` px from a stamp origin, in a box that also
    /// holds every other sample of the track whose displacements lie in `extent` (px: min x, max x, min y,
    /// max y), so the rest of the star's window can be added to it sample by sample.
    #[allow(unsafe_code)] // calling the AVX2 build after checking the processor has AVX2: nothing else
    pub fn histogram_at(&self, ox_px: f64, oy_px: f64, extent: (f64, f64, f64, f64)) -> NodeTable {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked just above).
            return unsafe { self.histogram_at_avx2(ox_px, oy_px, extent) };
        }
        self.histogram_at_body(ox_px, oy_px, extent)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn histogram_at_avx2(&self, ox_px: f64, oy_px: f64, extent: (f64, f64, f64, f64)) -> NodeTable {
        self.histogram_at_body(ox_px, oy_px, extent)
    }

    #[inline(always)]
    fn histogram_at_body(&self, ox_px: f64, oy_px: f64, extent: (f64, f64, f64, f64)) -> NodeTable {
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
        // what the samples of cell (a, b) carried by (cu, cv) with moments m give the cell's four nodes
        let mut put = |a: i64, b: i64, cu: i64, cv: i64, m: [f64; 4]| {
            if m[0] == 0.0 {
                return;
            }
            // t_u = f_u + α_u, t_v = f_v + α_v for these samples
            let (au, av) = (px - cu as f64, py - cv as f64);
            let su = m[1] + au * m[0];
            let sv = m[2] + av * m[0];
            let suv = m[3] + av * m[1] + au * m[2] + au * av * m[0];
            let i = (nv_i + b + cv - v0) as usize * nu + (nu_i + a + cu - u0) as usize;
            data[i] += m[0] - su - sv + suv;
            data[i + 1] += su - suv;
            data[i + nu] += sv - suv;
            data[i + nu + 1] += suv;
        };
        for &(ca, cb, s, e, total) in &self.cells {
            let (sx, sy, sxy) = carried_sums(&self.fu[s..e], &self.fv[s..e], px, py);
            let (a, b) = (self.a0 + ca as i64, self.b0 + cb as i64);
            put(
                a,
                b,
                0,
                0,
                std::array::from_fn(|k| total[k] - sx[k] - sy[k] + sxy[k]),
            );
            put(a, b, 1, 0, std::array::from_fn(|k| sx[k] - sxy[k]));
            put(a, b, 0, 1, std::array::from_fn(|k| sy[k] - sxy[k]));
            put(a, b, 1, 1, sxy);
        }
        for &(a, b, fu, fv, w) in &self.ends {
            let (cu, cv) = ((fu + px >= 1.0) as i64, (fv + py >= 1.0) as i64);
            put(a, b, cu, cv, [w, w * fu, w * fv, w * fu * fv]);
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

/// The moments `Σ (1, f_u, f_v, f_u f_v)` of the samples that carry along u (`f_u + φ_u ≥ 1`: a prefix, the
/// cell sorted by decreasing f_u), along v (`f_v + φ_v ≥ 1`), and both ways.
#[inline(always)]
fn carried_sums(fu: &[f64], fv: &[f64], px: f64, py: f64) -> ([f64; 4], [f64; 4], [f64; 4]) {
    let nx = fu.partition_point(|&f| f + px >= 1.0);
    let (mut sx, mut sxy, mut rest) = ([0.0; 4], [0.0; 4], [0.0; 4]);
    for (&u, &v) in fu[..nx].iter().zip(&fv[..nx]) {
        let m = [1.0, u, v, u * v];
        let c = if v + py >= 1.0 { 1.0 } else { 0.0 };
        for k in 0..4 {
            sx[k] += m[k];
            sxy[k] += c * m[k];
        }
    }
    for (&u, &v) in fu[nx..].iter().zip(&fv[nx..]) {
        let m = [1.0, u, v, u * v];
        let c = if v + py >= 1.0 { 1.0 } else { 0.0 };
        for k in 0..4 {
            rest[k] += c * m[k];
        }
    }
    let sy = std::array::from_fn(|k| sxy[k] + rest[k]);
    (sx, sy, sxy)
}
