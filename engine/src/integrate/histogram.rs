//! The fast method's histogram: a star's track deposited cloud-in-cell onto the kernel's node grid over a
//! window, relative to a stamp's origin (`S(X) = r Δt Σ_u H(u) K(X − u)`; [`super::cpu`]).

use super::convolve::RowRuns;
use super::track::Track;

/// One star to integrate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StarSpec {
    pub x_px: f64,
    pub y_px: f64,
    pub rate_e_per_s: f64,
}

/// Largest histogram (nodes) the fast method builds before falling back to the direct method.
pub const MAX_HISTOGRAM_NODES: usize = 1 << 24;

/// The cloud-in-cell histogram of a track over a window, on K's node grid, relative to a stamp origin.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Node coordinates of `data[0]`.
    pub u0: i64,
    pub v0: i64,
    pub nu: usize,
    pub nv: usize,
    pub data: Vec<f64>,
    /// Star position minus origin (px): sample j lands at node coordinates `(o + track_j)·G`.
    pub(super) ox_px: f64,
    pub(super) oy_px: f64,
    pub(super) g: f64,
}

/// (min_x, max_x, min_y, max_y) of the track over sample ranges (infinite bounds when they hold none).
pub(super) fn sample_extent(
    track: &Track,
    ranges: impl IntoIterator<Item = std::ops::RangeInclusive<usize>>,
) -> (f64, f64, f64, f64) {
    let mut e = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for r in ranges {
        for j in r {
            let (dx, dy) = (track.dx_px[j], track.dy_px[j]);
            e = (e.0.min(dx), e.1.max(dx), e.2.min(dy), e.3.max(dy));
        }
    }
    e
}

impl Histogram {
    /// An empty histogram whose box holds the displacements of `extent` (min_x, max_x, min_y, max_y; px) for
    /// a star at `star − origin`, or `None` when the box would exceed [`MAX_HISTOGRAM_NODES`] or the extent
    /// is empty.
    pub(super) fn empty_in(
        star: &StarSpec,
        extent: (f64, f64, f64, f64),
        origin: (i64, i64),
        g: usize,
    ) -> Option<Self> {
        Self::empty_reusing(star, extent, origin, g, Vec::new())
    }

    /// [`Histogram::empty_in`] in `buffer`'s memory (a histogram's data taken back after use).
    pub(super) fn empty_reusing(
        star: &StarSpec,
        extent: (f64, f64, f64, f64),
        origin: (i64, i64),
        g: usize,
        mut buffer: Vec<f64>,
    ) -> Option<Self> {
        let (umin, umax, vmin, vmax) = extent;
        if !(umin <= umax && vmin <= vmax) {
            return None;
        }
        let gf = g as f64;
        let (ox_px, oy_px) = (star.x_px - origin.0 as f64, star.y_px - origin.1 as f64);
        // the same arithmetic as a sample's node coordinate, so every sample lands inside
        let node = |o: f64, d: f64| ((o + d) * gf).floor() as i64;
        let (u0, v0) = (node(ox_px, umin) - 1, node(oy_px, vmin) - 1);
        let nu = (node(ox_px, umax) - u0 + 3) as usize;
        let nv = (node(oy_px, vmax) - v0 + 3) as usize;
        if nu.saturating_mul(nv) > MAX_HISTOGRAM_NODES {
            return None;
        }
        buffer.clear();
        buffer.resize(nu * nv, 0.0);
        Some(Self {
            u0,
            v0,
            nu,
            nv,
            data: buffer,
            ox_px,
            oy_px,
            g: gf,
        })
    }

    /// Deposit sample j of the track with weight `w` (cloud in cell).
    #[inline(always)]
    pub(super) fn add_sample(&mut self, track: &Track, j: usize, w: f64) {
        // node coordinates relative to the box: ≥ 1 (the box starts a node below the lowest sample), so
        // truncation is the floor (through i32: a signed conversion is one instruction, an unsigned one is
        // not)
        let u = (self.ox_px + track.dx_px[j]) * self.g - self.u0 as f64;
        let v = (self.oy_px + track.dy_px[j]) * self.g - self.v0 as f64;
        let (iu, iv) = (u as i32, v as i32);
        let (tu, tv) = (u - iu as f64, v - iv as f64);
        let nu = self.nu;
        let i = iv as usize * nu + iu as usize;
        let (lo, hi) = self.data[i..i + nu + 2].split_at_mut(nu);
        lo[0] += w * (1.0 - tu) * (1.0 - tv);
        lo[1] += w * tu * (1.0 - tv);
        hi[0] += w * (1.0 - tu) * tv;
        hi[1] += w * tu * tv;
    }

    /// Deposit the samples of `run` with weight 1, in order: the same terms in the same order as
    /// [`Histogram::add_sample`] with `w = 1` one by one (a weight of 1 multiplies exactly, so the same bits);
    /// in the AVX2 build the positions and cloud-in-cell weights of four samples at a time are worked out side
    /// by side in the vector units, the additions staying one sample after another.
    #[allow(unsafe_code)] // calling the AVX2 build after checking the processor has AVX2: nothing else
    pub(super) fn add_unit_run(&mut self, track: &Track, run: std::ops::Range<usize>) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked just above).
            unsafe { self.add_unit_run_avx2(track, run) };
            return;
        }
        self.add_unit_run_body(track, run);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)] // stores of vector registers into local arrays: nothing else
    pub(super) fn add_unit_run_avx2(&mut self, track: &Track, run: std::ops::Range<usize>) {
        use std::arch::x86_64::*;
        const B: usize = 4;
        let (dx, dy) = (&track.dx_px[run.clone()], &track.dy_px[run.clone()]);
        let (ox, oy) = (_mm256_set1_pd(self.ox_px), _mm256_set1_pd(self.oy_px));
        let g = _mm256_set1_pd(self.g);
        let (u0, v0) = (
            _mm256_set1_pd(self.u0 as f64),
            _mm256_set1_pd(self.v0 as f64),
        );
        let one = _mm256_set1_pd(1.0);
        let nu = self.nu;
        let nu_i = _mm_set1_epi32(nu as i32);
        let mut xs = dx.chunks_exact(B);
        let mut ys = dy.chunks_exact(B);
        for (x, y) in (&mut xs).zip(&mut ys) {
            // the arithmetic of `add_sample`, lane by lane (truncation is the floor: coordinates ≥ 1)
            let xv = _mm256_set_pd(x[3], x[2], x[1], x[0]);
            let yv = _mm256_set_pd(y[3], y[2], y[1], y[0]);
            let u = _mm256_sub_pd(_mm256_mul_pd(_mm256_add_pd(ox, xv), g), u0);
            let v = _mm256_sub_pd(_mm256_mul_pd(_mm256_add_pd(oy, yv), g), v0);
            let (iu, iv) = (_mm256_cvttpd_epi32(u), _mm256_cvttpd_epi32(v));
            let tu = _mm256_sub_pd(u, _mm256_cvtepi32_pd(iu));
            let tv = _mm256_sub_pd(v, _mm256_cvtepi32_pd(iv));
            let (su, sv) = (_mm256_sub_pd(one, tu), _mm256_sub_pd(one, tv));
            let mut w = [[0.0f64; B]; 4];
            let mut idx = [0i32; B];
            // SAFETY: each store writes one register's bytes into a local array of exactly that size.
            unsafe {
                _mm256_storeu_pd(w[0].as_mut_ptr(), _mm256_mul_pd(su, sv));
                _mm256_storeu_pd(w[1].as_mut_ptr(), _mm256_mul_pd(tu, sv));
                _mm256_storeu_pd(w[2].as_mut_ptr(), _mm256_mul_pd(su, tv));
                _mm256_storeu_pd(w[3].as_mut_ptr(), _mm256_mul_pd(tu, tv));
                _mm_storeu_si128(
                    idx.as_mut_ptr().cast(),
                    _mm_add_epi32(_mm_mullo_epi32(iv, nu_i), iu),
                );
            }
            for (k, &i) in idx.iter().enumerate() {
                // eight bytes at a time: a sixteen-byte addition of two neighbouring nodes would half overlap
                // the last sample's when the track steps one cell along u, and wait for it to reach the cache
                // (the processor cannot forward half a store); `black_box` keeps the compiler from pairing them
                let i = i as usize;
                let (lo, hi) = self.data[i..i + nu + 2].split_at_mut(nu);
                lo[0] += w[0][k];
                hi[0] += w[2][k];
                let i1 = std::hint::black_box(i) + 1;
                self.data[i1] += w[1][k];
                self.data[i1 + nu] += w[3][k];
            }
        }
        let rest = run.end - xs.remainder().len();
        for j in rest..run.end {
            self.add_sample(track, j, 1.0);
        }
    }

    /// The portable build: sample by sample.
    pub(super) fn add_unit_run_body(&mut self, track: &Track, run: std::ops::Range<usize>) {
        for j in run {
            self.add_sample(track, j, 1.0);
        }
    }

    /// Add the samples where window `outer` weighs more than `inner` (a window it contains), with the
    /// difference: the same deposits in the same order as [`WindowWeights::for_each_extra`] into
    /// [`Histogram::add_sample`], each part's interior (weight exactly 1 − 0) through
    /// [`Histogram::add_unit_run`].
    pub(super) fn add_extra(
        &mut self,
        track: &Track,
        outer: &super::track::WindowWeights,
        inner: &super::track::WindowWeights,
    ) {
        let (head, tail) = outer.extra_ranges(inner);
        for part in [head, tail] {
            let (lo, hi) = (*part.start(), *part.end());
            if lo > hi {
                continue;
            }
            let end = |h: &mut Self, j: usize| {
                let e = outer.weight(j) - inner.weight(j);
                if e != 0.0 {
                    h.add_sample(track, j, e);
                }
            };
            end(self, lo);
            if hi > lo {
                // strictly inside the part: inside `outer` and outside `inner`, so 1 − 0
                self.add_unit_run(track, lo + 1..hi);
                end(self, hi);
            }
        }
    }

    /// Deposit positions `q_j = star + track_j − origin` (px) × G with the window's weights.
    pub fn deposit(
        star: &StarSpec,
        track: &Track,
        w: &super::track::WindowWeights,
        origin: (i64, i64),
        g: usize,
    ) -> Option<Self> {
        let mut h = Self::empty_in(star, sample_extent(track, [w.first..=w.last]), origin, g)?;
        h.add_window(track, w);
        Some(h)
    }

    /// Add the samples of window `w`.
    pub(super) fn add_window(&mut self, track: &Track, w: &super::track::WindowWeights) {
        self.add_sample(track, w.first, w.weight(w.first));
        if w.last > w.first {
            for j in w.first + 1..w.last {
                self.add_sample(track, j, 1.0);
            }
            self.add_sample(track, w.last, w.w_last);
        }
    }

    /// The non-zero run of each row (empty rows left out), with its origin moved down by `dv` nodes.
    pub(super) fn runs(&self, dv: i64) -> RowRuns<'_> {
        let runs = (0..self.nv)
            .filter_map(|r| {
                let row = &self.data[r * self.nu..(r + 1) * self.nu];
                let a = row.iter().position(|v| *v != 0.0)?;
                let b = self.nu - row.iter().rev().position(|v| *v != 0.0).unwrap_or(0);
                Some((r, a, b, &row[a..b]))
            })
            .collect();
        RowRuns {
            u0: self.u0,
            v0: self.v0 - dv,
            runs,
        }
    }
}
