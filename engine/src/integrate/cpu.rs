//! CPU integration of one star's stamp: the reference, direct and fast methods (same maths, same output).
//!
//! Signal of pixel (X, Y) in electrons, with r = the star's rate (e⁻/s), q_j = star position + track_j and
//! w_j(X, Y) its window weights ([`super::track`]):
//!
//! `S(X, Y) = r · Δt · Σ_j w_j(X, Y) · K(X − q_jx, Y − q_jy)`
//!
//! * **reference**: K replaced by the explicit sum over subpixels of bilinear PSF look-ups (s² per sample);
//! * **direct**: one bilinear look-up of K per (pixel, sample);
//! * **fast**: the window shared by all pixels of the stamp, `[max a, min b)`, is integrated once: the track
//!   is deposited cloud-in-cell onto K's node grid (histogram H) and `Σ_u H(u) K(X − u)` is evaluated at
//!   each pixel centre — exactly equal to the bilinear look-ups because pixel centres are grid nodes and K
//!   is bilinear between nodes. Each pixel then adds only its own samples outside the shared window.
//!   Under the rolling readout the shared window is all but ≈ 0.1 % of the exposure.
//! * **static** (Gaussian ACE or no ACE): `S = r · T · K_blurred(X − x, Y − y)`, one look-up per pixel.

use super::convolve::add_convolution;
use super::exact_core::ExactCore;
use super::histogram::sample_extent;
pub use super::histogram::{Histogram, MAX_HISTOGRAM_NODES, StarSpec};
use super::kernel::{IntraPixelMap, PixelKernel, subpixel_sum};
use super::own_samples::{RowScratch, RowWindows, add_own_samples};
use super::track::Track;
use crate::optics::psf::PsfTable;
use crate::readout::ReadoutTiming;
use rayon::prelude::*;

/// A rectangular patch of the detector: `data[iy * nx + ix]` is pixel (x0 + ix, y0 + iy).
#[derive(Debug, Clone, PartialEq)]
pub struct Stamp {
    pub x0: i64,
    pub y0: i64,
    pub nx: usize,
    pub ny: usize,
    pub data: Vec<f64>,
}

impl Stamp {
    pub fn sum(&self) -> f64 {
        self.data.iter().sum()
    }

    /// The value at detector pixel (x, y): 0 outside the stamp.
    pub fn at(&self, x: i64, y: i64) -> f64 {
        let (sx, sy) = (x - self.x0, y - self.y0);
        if sx >= 0 && sy >= 0 && (sx as usize) < self.nx && (sy as usize) < self.ny {
            self.data[sy as usize * self.nx + sx as usize]
        } else {
            0.0
        }
    }
}

/// Where a star's stamp lies: centred on its mean jittered position, `radius + ⌈excursion⌉` pixels around,
/// clipped to the detector. `None` if it misses the detector entirely.
pub fn stamp_bounds(
    x: f64,
    y: f64,
    track: Option<&Track>,
    radius_px: usize,
    detector_px: usize,
) -> Option<(i64, i64, usize, usize)> {
    let (mx, my, ex) = match track {
        Some(t) => {
            let s = t.summary();
            (s.mean_x, s.mean_y, s.excursion)
        }
        None => (0.0, 0.0, 0.0),
    };
    let r = radius_px as i64 + ex.ceil() as i64;
    let (cx, cy) = ((x + mx).round() as i64, (y + my).round() as i64);
    let d = detector_px as i64;
    let (x0, x1) = ((cx - r).max(0), (cx + r).min(d - 1));
    let (y0, y1) = ((cy - r).max(0), (cy + r).min(d - 1));
    if x1 < x0 || y1 < y0 {
        return None;
    }
    Some((x0, y0, (x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize))
}

/// Static star (no time dependence): `r · T · K(X − x, Y − y)`.
pub fn static_stamp(
    star: &StarSpec,
    kernel: &PixelKernel,
    exposure_s: f64,
    bounds: (i64, i64, usize, usize),
) -> Stamp {
    let (x0, y0, nx, ny) = bounds;
    let mut data = vec![0.0; nx * ny];
    let f = star.rate_e_per_s * exposure_s;
    for iy in 0..ny {
        let dy = (y0 + iy as i64) as f64 - star.y_px;
        for ix in 0..nx {
            let dx = (x0 + ix as i64) as f64 - star.x_px;
            data[iy * nx + ix] = f * kernel.eval(dx, dy);
        }
    }
    Stamp {
        x0,
        y0,
        nx,
        ny,
        data,
    }
}

/// `r · Δt · Σ_j w_j(X, Y) · f(X − x − dx_j, Y − y − dy_j)` for every pixel of the stamp: the sum over each
/// pixel's own window that the reference and direct methods share (they differ only in `f`).
fn window_sum_stamp(
    star: &StarSpec,
    track: &Track,
    timing: &ReadoutTiming,
    bounds: (i64, i64, usize, usize),
    f: impl Fn(f64, f64) -> f64,
) -> Stamp {
    let (x0, y0, nx, ny) = bounds;
    let mut data = vec![0.0; nx * ny];
    for iy in 0..ny {
        let y = y0 + iy as i64;
        for ix in 0..nx {
            let x = x0 + ix as i64;
            let (a, b) = timing.window_s(x as usize, y as usize);
            let w = track.window(a, b);
            let (bx, by) = (x as f64 - star.x_px, y as f64 - star.y_px);
            let mut acc = 0.0;
            for j in w.first..=w.last {
                acc += w.weight(j) * f(bx - track.dx_px[j], by - track.dy_px[j]);
            }
            data[iy * nx + ix] = acc * star.rate_e_per_s * track.dt_s;
        }
    }
    Stamp {
        x0,
        y0,
        nx,
        ny,
        data,
    }
}

/// Reference method: explicit subpixels × samples.
pub fn reference_stamp(
    star: &StarSpec,
    psf: &PsfTable,
    map: &IntraPixelMap,
    track: &Track,
    timing: &ReadoutTiming,
    bounds: (i64, i64, usize, usize),
) -> Stamp {
    window_sum_stamp(star, track, timing, bounds, |dx, dy| {
        subpixel_sum(psf, map, dx, dy)
    })
}

/// Direct method: one pixel-kernel look-up per (pixel, sample).
pub fn direct_stamp(
    star: &StarSpec,
    kernel: &PixelKernel,
    track: &Track,
    timing: &ReadoutTiming,
    bounds: (i64, i64, usize, usize),
) -> Stamp {
    window_sum_stamp(star, track, timing, bounds, |dx, dy| kernel.eval(dx, dy))
}

/// The part of the exposure every pixel of a frame shares, deposited once. By default exactly, grouped by cell
/// ([`ExactCore`]: a star's histogram of it is read at its own phase, equal to its own deposit to rounding).
/// With `fidelity.deposit_phases` = Q > 0 it is deposited at the (Q + 1)² star phases `(a, b)/Q` of a node: a star's histogram of it is the bilinear
/// interpolation of the four phases around its own, shifted by its whole nodes — so each star deposits only
/// the rest of its stamp's shared window (under the rolling readout ≤ one read sweep, ≈ 10 % of the samples)
/// instead of all of it.
///
/// Exact in the mean: a cloud-in-cell deposit's first moment is linear in the star's phase, and so is the
/// interpolation. What it changes is the spread: a sample's weight is piecewise linear in the phase with a
/// kink at each node, so between grid phases the interpolated histogram is a little smoother than the exact
/// one (by at most a 1/(2Q) node in the kink's neighbourhood). `jsim bench --parts bulge` measures the cost
/// against Q = 0 (exact).
#[derive(Debug, Clone)]
pub struct SharedCore {
    /// The window every pixel of the frame shares.
    pub window: super::track::WindowWeights,
    g: usize,
    kind: CoreKind,
}

#[derive(Debug, Clone)]
enum CoreKind {
    /// Exact for a star at any phase ([`ExactCore`]): `fidelity.deposit_phases` = 0, the default.
    Exact(ExactCore),
    /// Deposited at (Q + 1)² phases and interpolated.
    Phases {
        q: usize,
        /// Box of every table, in nodes relative to the star's whole node.
        u0: i64,
        v0: i64,
        nu: usize,
        nv: usize,
        /// `tables[b·(Q + 1) + a]`: the histogram of a star at phase (a/Q, b/Q) of a node.
        tables: Vec<Vec<f64>>,
    },
}

impl SharedCore {
    /// Deposit the frame's shared window `[a_s, b_s)`: exactly, grouped by cell, when `q` = 0, else at the
    /// (Q + 1)² phases; `None` when the window is empty or the box too large.
    pub fn new(track: &Track, a_s: f64, b_s: f64, g: usize, q: usize) -> Option<Self> {
        if track.is_empty() || !(b_s > a_s) {
            return None;
        }
        let window = track.window(a_s, b_s);
        let (xmin, xmax, ymin, ymax) = track.summary().extent;
        let gf = g as f64;
        // every sample of any phase in [0, 1] node, with its cloud-in-cell neighbour and a node of margin: the
        // box each star's histogram takes (either kind), bounded as a star's own deposit is
        let (u0, v0) = (
            (xmin * gf).floor() as i64 - 1,
            (ymin * gf).floor() as i64 - 1,
        );
        let nu = ((xmax * gf).floor() as i64 + 4 - u0) as usize;
        let nv = ((ymax * gf).floor() as i64 + 4 - v0) as usize;
        let tables = if q == 0 { 1 } else { (q + 1) * (q + 1) };
        if nu.saturating_mul(nv).saturating_mul(tables) > MAX_HISTOGRAM_NODES {
            return None;
        }
        if q == 0 {
            return Some(Self {
                window,
                g,
                kind: CoreKind::Exact(ExactCore::new(track, &window, g)?),
            });
        }
        let phases: Vec<(usize, usize)> =
            (0..=q).flat_map(|b| (0..=q).map(move |a| (a, b))).collect();
        let tables = phases
            .par_iter()
            .map(|&(a, b)| {
                let mut h = Histogram {
                    u0,
                    v0,
                    nu,
                    nv,
                    data: vec![0.0; nu * nv],
                    ox_px: a as f64 / (q * g) as f64,
                    oy_px: b as f64 / (q * g) as f64,
                    g: gf,
                };
                h.add_window(track, &window);
                h.data
            })
            .collect();
        Some(Self {
            window,
            g,
            kind: CoreKind::Phases {
                q,
                u0,
                v0,
                nu,
                nv,
                tables,
            },
        })
    }

    /// Nodes per pixel of the grid the tables are deposited on.
    pub fn nodes_per_px(&self) -> usize {
        self.g
    }

    /// A reader for stars taken one after another (see [`CoreReader`]).
    pub fn reader(&self) -> CoreReader<'_> {
        CoreReader {
            core: self,
            cursor: super::exact_core::Cursor::default(),
        }
    }
}

/// A reading of a [`SharedCore`] by one run of stars taken in order: the exact kind's
/// [`super::exact_core::Cursor`] follows their phases (each star read costs the samples whose carry its
/// phase changes, not a pass over all). One reader per run, so the stamps do not depend on how runs are
/// spread over threads.
pub struct CoreReader<'a> {
    pub core: &'a SharedCore,
    cursor: super::exact_core::Cursor,
}

impl CoreReader<'_> {
    /// (samples moved, fresh passes) of the exact kind's cursor so far.
    pub fn cursor_work(&self) -> (usize, usize) {
        (self.cursor.moved, self.cursor.passes)
    }

    /// The shared window's histogram for a star at `(ox, oy)` px from a stamp origin, in a box that holds
    /// every sample of the track: exact, or the four phase tables around its phase interpolated.
    fn histogram_at(&mut self, ox_px: f64, oy_px: f64, track: &Track) -> Histogram {
        let (q, u0, v0, nu, nv, tables) = match &self.core.kind {
            CoreKind::Exact(core) => {
                let t = core.histogram_with(&mut self.cursor, ox_px, oy_px, track.summary().extent);
                return Histogram {
                    u0: t.u0,
                    v0: t.v0,
                    nu: t.nu,
                    nv: t.nv,
                    data: t.data,
                    ox_px,
                    oy_px,
                    g: self.core.g as f64,
                };
            }
            CoreKind::Phases {
                q,
                u0,
                v0,
                nu,
                nv,
                tables,
            } => (*q, *u0, *v0, *nu, *nv, tables),
        };
        let gf = self.core.g as f64;
        let (xu, xv) = (ox_px * gf, oy_px * gf);
        let (nu_s, nv_s) = (xu.floor(), xv.floor());
        let qf = q as f64;
        let (pu, pv) = ((xu - nu_s) * qf, (xv - nv_s) * qf);
        let (ia, ib) = ((pu as usize).min(q - 1), (pv as usize).min(q - 1));
        let (ta, tb) = (pu - ia as f64, pv - ib as f64);
        let row = q + 1;
        let t = |a: usize, b: usize| &tables[b * row + a];
        let (t00, t10, t01, t11) = (t(ia, ib), t(ia + 1, ib), t(ia, ib + 1), t(ia + 1, ib + 1));
        let (w00, w10, w01, w11) = (
            (1.0 - ta) * (1.0 - tb),
            ta * (1.0 - tb),
            (1.0 - ta) * tb,
            ta * tb,
        );
        let data = (0..nu * nv)
            .map(|k| w00 * t00[k] + w10 * t10[k] + w01 * t01[k] + w11 * t11[k])
            .collect();
        Histogram {
            u0: nu_s as i64 + u0,
            v0: nv_s as i64 + v0,
            nu,
            nv,
            data,
            ox_px,
            oy_px,
            g: gf,
        }
    }
}

/// Stamp rows whose shared window is summed as one histogram ⊛ K (the blocked convolution's rows).
const BLOCK_ROWS: usize = 4;

/// A stamp's samples of one window beyond another, deposited in a histogram of their own and summed over
/// some of the stamp's rows (≈ 44 of them a bulge stamp: one per block of rows and one per row, each with
/// a few to a few hundred samples, so their histograms reuse one allocation).
struct ExtraSum<'a> {
    star: &'a StarSpec,
    kernel: &'a PixelKernel,
    track: &'a Track,
    origin: (i64, i64),
    /// The last histogram's data, for the next.
    buffer: Vec<f64>,
}

impl ExtraSum<'_> {
    /// Add `(outer − inner) ⊛ K` to the `rows` stamp rows from `iy0` (`out`: those rows).
    fn add(
        &mut self,
        out: &mut [f64],
        iy0: usize,
        rows: usize,
        outer: &super::track::WindowWeights,
        inner: &super::track::WindowWeights,
    ) {
        // the box holds the samples of a non-zero difference: each part's interior, and its ends unless
        // their weights are equal
        let (head, tail) = outer.extra_ranges(inner);
        let mut held: [Option<std::ops::RangeInclusive<usize>>; 6] = Default::default();
        for (part, slots) in [head, tail].into_iter().zip(held.chunks_exact_mut(3)) {
            let (lo, hi) = (*part.start(), *part.end());
            if lo > hi {
                continue;
            }
            let differs = |j: usize| outer.weight(j) != inner.weight(j);
            if differs(lo) {
                slots[0] = Some(lo..=lo);
            }
            if hi > lo {
                slots[1] = Some(lo + 1..=hi - 1);
                if differs(hi) {
                    slots[2] = Some(hi..=hi);
                }
            }
        }
        let g = self.kernel.nodes_per_px;
        if let Some(mut h) = Histogram::empty_reusing(
            self.star,
            sample_extent(self.track, held.into_iter().flatten()),
            self.origin,
            g,
            std::mem::take(&mut self.buffer),
        ) {
            h.add_extra(self.track, outer, inner);
            let nx = out.len() / rows;
            add_convolution(out, nx, rows, &mut h.runs((iy0 * g) as i64), self.kernel);
            self.buffer = h.data;
        }
    }
}

/// Fast method: shared windows by histogram ⊛ K, plus each pixel's own edge samples.
///
/// Three levels of sharing, all exact: the window all pixels of the stamp share is deposited once (its
/// histogram H); each block of four stamp rows deposits, in a small histogram B of its own, the samples its
/// pixels share beyond that, and each row, in a smaller one E, those its pixels share beyond its block's
/// (under the rolling readout a row's pixels start within one row time, ≈ 4 samples, of each other, where
/// the whole stamp spans ≈ 4 samples per row); a pixel's value is `(H + B + E) ⊛ K` at its centre plus K
/// looked up for its own few samples beyond its row's window. With a [`SharedCore`] the stamp's
/// histogram starts from the frame's shared part read at the star's phase (exactly, or interpolated
/// between deposit phases).
pub fn fast_stamp(
    star: &StarSpec,
    kernel: &PixelKernel,
    track: &Track,
    timing: &ReadoutTiming,
    bounds: (i64, i64, usize, usize),
    core: Option<&mut CoreReader<'_>>,
) -> Stamp {
    let (x0, y0, nx, ny) = bounds;
    let windows: Vec<(f64, f64)> = (0..ny)
        .flat_map(|iy| {
            (0..nx).map(move |ix| ((x0 + ix as i64) as usize, (y0 + iy as i64) as usize))
        })
        .map(|(x, y)| timing.window_s(x, y))
        .collect();
    let shared = |ws: &[(f64, f64)]| {
        ws.iter()
            .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), w| {
                (a.max(w.0), b.min(w.1))
            })
    };
    let (a_max, b_min) = shared(&windows);
    if !(b_min > a_max) {
        return direct_stamp(star, kernel, track, timing, bounds);
    }
    let common = track.window(a_max, b_min);
    let g = kernel.nodes_per_px;
    let origin = (x0, y0);
    let (ox, oy) = (star.x_px - x0 as f64, star.y_px - y0 as f64);
    let base = match core {
        // the frame's shared part read at the star's phase (exactly, or interpolated), then the rest of the
        // stamp's window sample by sample
        Some(c) if c.core.window.first >= common.first && c.core.window.last <= common.last => {
            let mut h = c.histogram_at(ox, oy, track);
            h.add_extra(track, &common, &c.core.window);
            h
        }
        // the box of the whole track holds every window's samples
        _ => match Histogram::empty_in(star, track.summary().extent, origin, g) {
            Some(mut h) => {
                h.add_window(track, &common);
                h
            }
            None => return direct_stamp(star, kernel, track, timing, bounds),
        },
    };
    let mut data = vec![0.0; nx * ny];
    add_convolution(&mut data, nx, ny, &mut base.runs(0), kernel);
    let mut extra = ExtraSum {
        star,
        kernel,
        track,
        origin,
        buffer: Vec::new(),
    };
    let bx_px: Vec<f64> = (0..nx)
        .map(|ix| (x0 + ix as i64) as f64 - star.x_px)
        .collect();
    let mut owns = Vec::with_capacity(nx);
    let mut scratch = RowScratch::default();
    for iy0 in (0..ny).step_by(BLOCK_ROWS) {
        let rows = BLOCK_ROWS.min(ny - iy0);
        // the window these rows share holds the stamp's: its extra samples, summed over the rows at once
        let (ba, bb) = shared(&windows[iy0 * nx..(iy0 + rows) * nx]);
        let block = track.window(ba, bb);
        extra.add(
            &mut data[iy0 * nx..(iy0 + rows) * nx],
            iy0,
            rows,
            &block,
            &common,
        );
        for iy in iy0..iy0 + rows {
            let y = y0 + iy as i64;
            let row_windows = &windows[iy * nx..(iy + 1) * nx];
            let (ra, rb) = shared(row_windows);
            // the row's shared window holds its block's: the row's own extra samples
            let row = track.window(ra, rb);
            let out_row = &mut data[iy * nx..(iy + 1) * nx];
            extra.add(out_row, iy, 1, &row, &block);
            // each pixel's samples outside its row's window
            owns.clear();
            owns.extend(row_windows.iter().map(|w| track.window(w.0, w.1)));
            let by_px = y as f64 - star.y_px;
            let r = RowWindows {
                owns: &owns,
                row: &row,
                bx_px: &bx_px,
                by_px,
            };
            add_own_samples(out_row, &r, track, kernel, &mut scratch);
            for out in out_row.iter_mut() {
                *out = *out * star.rate_e_per_s * track.dt_s;
            }
        }
    }
    Stamp {
        x0,
        y0,
        nx,
        ny,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, ReadoutOrder};

    /// A stamp's value at a detector pixel is its own pixel inside and 0 on every side outside.
    #[test]
    fn a_stamp_is_read_at_detector_pixels_and_zero_outside() {
        let st = Stamp {
            x0: 10,
            y0: -2,
            nx: 3,
            ny: 2,
            data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        };
        assert_eq!(st.at(10, -2), 1.0);
        assert_eq!(st.at(12, -2), 3.0);
        assert_eq!(st.at(11, -1), 5.0);
        for (x, y) in [(9, -2), (13, -2), (10, -3), (10, 0), (-5, 100)] {
            assert_eq!(st.at(x, y), 0.0, "({x}, {y})");
        }
    }

    fn wiggly_track(n: usize, dt: f64, amp_px: f64) -> Track {
        let dx = (0..n)
            .map(|j| amp_px * ((j as f64 * dt * 3.1).sin() + 0.3 * (j as f64 * dt * 130.0).sin()))
            .collect();
        let dy = (0..n)
            .map(|j| {
                amp_px * ((j as f64 * dt * 1.7).cos() * 0.8 + 0.2 * (j as f64 * dt * 95.0).cos())
            })
            .collect();
        Track::new(dt, 0.0, dx, dy)
    }

    fn timing(order: ReadoutOrder, exposure_s: f64) -> ReadoutTiming {
        let mut cfg = Config::default();
        cfg.readout.order = order;
        cfg.detector.exposure_s = exposure_s;
        // shrink the channel so that a small stamp spans a channel boundary and many rows of timing
        cfg.readout.channel_width_px = 20;
        cfg.readout.pixel_time_us = 200.0;
        cfg.readout.channels = 100;
        ReadoutTiming::new(&cfg)
    }

    #[test]
    fn direct_equals_reference_and_fast_equals_direct() {
        let psf = crate::testkit::synthetic_psf(8, 4);
        let map = IntraPixelMap::uniform(4);
        let k = PixelKernel::build(&psf, &map).expect("kernel");
        let track = wiggly_track(3000, 1e-3, 0.4);
        for order in ReadoutOrder::ALL {
            let t = timing(order, 2.5);
            let star = StarSpec {
                x_px: 18.37,
                y_px: 30.81,
                rate_e_per_s: 1000.0,
            };
            let b = stamp_bounds(star.x_px, star.y_px, Some(&track), 4, 200).expect("on detector");
            let r = reference_stamp(&star, &psf, &map, &track, &t, b);
            let d = direct_stamp(&star, &k, &track, &t, b);
            let f = fast_stamp(&star, &k, &track, &t, b, None);
            let (e_dr, e_fd) = (max_error(&d, &r), max_error(&f, &d));
            assert!(e_dr < 1e-12, "{order:?}: direct vs reference {e_dr:e}");
            assert!(e_fd < 1e-12, "{order:?}: fast vs direct {e_fd:e}");
        }
    }

    fn centroid(s: &Stamp) -> (f64, f64) {
        let (mut sx, mut sy, mut t) = (0.0, 0.0, 0.0);
        for iy in 0..s.ny {
            for ix in 0..s.nx {
                let v = s.data[iy * s.nx + ix];
                sx += v * (s.x0 + ix as i64) as f64;
                sy += v * (s.y0 + iy as i64) as f64;
                t += v;
            }
        }
        (sx / t, sy / t)
    }

    /// (Σ H, mean u, mean v) of a histogram, in absolute node coordinates.
    fn moments(h: &Histogram) -> (f64, f64, f64) {
        let (mut w, mut su, mut sv) = (0.0, 0.0, 0.0);
        for r in 0..h.nv {
            for c in 0..h.nu {
                let x = h.data[r * h.nu + c];
                w += x;
                su += x * (h.u0 + c as i64) as f64;
                sv += x * (h.v0 + r as i64) as f64;
            }
        }
        (w, su / w, sv / w)
    }

    /// Largest |a − b| over a stamp, relative to b's peak.
    fn max_error(a: &Stamp, b: &Stamp) -> f64 {
        let peak = b.data.iter().cloned().fold(0.0, f64::max);
        a.data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / peak
    }

    /// The shared core: its interpolated histogram has the exact deposit's weight and mean (both linear in the
    /// phase); against the direct method (independent: no histogram at all) the stamp is exact on the grid of
    /// phases, and between them its error falls as Q⁻².
    #[test]
    fn shared_core_is_exact_on_its_phases_and_keeps_the_centroid() {
        let psf = crate::testkit::synthetic_psf(8, 6);
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(4)).expect("kernel");
        let g = k.nodes_per_px as f64;
        let track = wiggly_track(3000, 1e-3, 0.9);
        let t = timing(ReadoutOrder::Rolling, 2.5);
        let (a, b) = t.shared_window_s(200);
        assert!(b > a);
        // a star at (whole nodes + i/Q, whole nodes + j/Q) of a node
        let star = |q: usize, i: f64, j: f64| StarSpec {
            x_px: 40.0 + i / (q as f64 * g),
            y_px: 61.0 + 5.0 / g + j / (q as f64 * g),
            rate_e_per_s: 1000.0,
        };
        let run = |q: usize, s: &StarSpec| {
            let core = SharedCore::new(&track, a, b, k.nodes_per_px, q).expect("core");
            let bnd = stamp_bounds(s.x_px, s.y_px, Some(&track), 6, 200).expect("on");
            let d = direct_stamp(s, &k, &track, &t, bnd);
            (
                fast_stamp(s, &k, &track, &t, bnd, Some(&mut core.reader())),
                d,
            )
        };
        // on the grid of phases
        let (f, d) = run(4, &star(4, 3.0, 7.0));
        assert!(
            max_error(&f, &d) < 1e-12,
            "on the phase grid: {:e}",
            max_error(&f, &d)
        );
        // half way between grid phases: the worst place
        let mut errs = Vec::new();
        for q in [2, 4, 8, 16] {
            let s = star(q, 0.5, 0.5);
            // the interpolated histogram has the exact deposit's weight and mean, to rounding
            let core = SharedCore::new(&track, a, b, k.nodes_per_px, q).expect("core");
            let interpolated = core.reader().histogram_at(s.x_px, s.y_px, &track);
            let exact = Histogram::deposit(&s, &track, &core.window, (0, 0), k.nodes_per_px)
                .expect("deposit");
            let (mi, me) = (moments(&interpolated), moments(&exact));
            assert!(
                (mi.0 / me.0 - 1.0).abs() < 1e-12,
                "Q {q}: weight {mi:?} vs {me:?}"
            );
            let dm = (mi.1 - me.1).hypot(mi.2 - me.2);
            assert!(dm < 1e-9, "Q {q}: the mean moved {dm:e} nodes");
            // the stamp against the direct method; its centroid also feels the stamp's edge (6 px here)
            let (f, d) = run(q, &s);
            let e = max_error(&f, &d);
            let (cf, cd) = (centroid(&f), centroid(&d));
            let dc = (cf.0 - cd.0).hypot(cf.1 - cd.1);
            println!("Q {q}: max error / peak {e:.2e}, stamp centroid {dc:.2e} px");
            assert!(dc < 1e-5, "Q {q}: the stamp's centroid moved {dc:e} px");
            errs.push(e);
        }
        for w in errs.windows(2) {
            assert!(w[1] < w[0] / 2.5, "error does not fall as Q⁻²: {errs:?}");
        }
        assert!(errs[3] < 1e-4, "{errs:?}");
    }

    /// The exact shared core (`deposit_phases` = 0), read by one cursor through a run of stars: at phases
    /// anywhere in a node — on a node, a rounding away from the next, at random places far apart (fresh
    /// passes), in small steps there and back (moves only, 300 of them) — its histogram equals the plain
    /// deposit node by node, and the stamp equals the direct method (no histogram at all).
    #[test]
    fn runs_of_unit_samples_deposit_the_same_bits_as_one_by_one() {
        // a window's samples beyond an inner one, through `add_extra` (interiors four at a time) and through
        // `for_each_extra` into `add_sample`: the same terms in the same order, so equal bit for bit
        let track = wiggly_track(3000, 1e-3, 0.9);
        let star = StarSpec {
            x_px: 40.3137,
            y_px: 61.871,
            rate_e_per_s: 1.0,
        };
        let cases = [
            ((0.0104, 2.7003), (0.8402, 1.9601)), // head and tail of hundreds of samples
            ((0.5, 0.5107), (0.5021, 0.5052)), // a few samples each side (runs shorter than four)
            ((0.3, 2.0), (0.3, 2.0)),          // nothing beyond
            ((0.30004, 1.3), (0.9, 1.2)),      // fractional ends only
        ];
        let empty =
            || Histogram::empty_in(&star, track.summary().extent, (30, 50), 16).expect("box");
        let same_bits = |h: &Histogram, k: &Histogram| {
            h.data
                .iter()
                .zip(&k.data)
                .all(|(x, y)| x.to_bits() == y.to_bits())
        };
        for ((a, b), (c, d)) in cases {
            let (outer, inner) = (track.window(a, b), track.window(c, d));
            let (mut one, mut runs) = (empty(), empty());
            outer.for_each_extra(&inner, |j, e| one.add_sample(&track, j, e));
            runs.add_extra(&track, &outer, &inner);
            assert!(one.data.iter().any(|v| *v != 0.0) || a == c);
            assert!(
                same_bits(&one, &runs),
                "window ({a}, {b}) beyond ({c}, {d})"
            );
        }
        // the portable build (what a processor without AVX2 runs) against the one in use here
        let (mut portable, mut in_use) = (empty(), empty());
        portable.add_unit_run_body(&track, 7..2990);
        in_use.add_unit_run(&track, 7..2990);
        assert!(portable.data.iter().any(|v| *v != 0.0));
        assert!(
            same_bits(&portable, &in_use),
            "portable and AVX2 run deposits differ"
        );
    }

    #[test]
    fn exact_core_equals_the_plain_deposit_at_any_phase() {
        let psf = crate::testkit::synthetic_psf(8, 6);
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(4)).expect("kernel");
        let g = k.nodes_per_px;
        let track = wiggly_track(3000, 1e-3, 0.9);
        let t = timing(ReadoutOrder::Rolling, 2.5);
        let (a, b) = t.shared_window_s(200);
        let core = SharedCore::new(&track, a, b, g, 0).expect("core");
        let mut reader = core.reader();
        let gf = g as f64;
        let mut phases = vec![
            (0.0, 0.0),
            (1.0 - 1e-13, 0.5),
            (0.37, 1.0 - 1e-13),
            (0.913, 0.071),
            (0.5, 0.5),
        ];
        // small steps out and back, each moving a few samples; then the edge phases again after them
        let steps: Vec<(f64, f64)> = (0..300)
            .map(|i| {
                let s = if i < 150 { i } else { 300 - i } as f64;
                (0.2 + 0.004 * s, 0.9 - 0.005 * s)
            })
            .collect();
        phases.extend(steps);
        phases.extend([(0.0, 0.0), (1.0 - 1e-13, 1.0 - 1e-13), (0.21, 0.13)]);
        for (i, &(fx, fy)) in phases.iter().enumerate() {
            let star = StarSpec {
                x_px: 40.0 + (3.0 + fx) / gf,
                y_px: 61.0 + ((i % 7) as f64 + fy) / gf,
                rate_e_per_s: 1000.0,
            };
            let bnd = stamp_bounds(star.x_px, star.y_px, Some(&track), 6, 200).expect("on");
            let (ox, oy) = (star.x_px - bnd.0 as f64, star.y_px - bnd.1 as f64);
            let exact = reader.histogram_at(ox, oy, &track);
            let plain = Histogram::deposit(&star, &track, &core.window, (bnd.0, bnd.1), g)
                .expect("deposit");
            let at = |h: &Histogram, u: i64, v: i64| {
                let (ru, rv) = (u - h.u0, v - h.v0);
                if ru < 0 || rv < 0 || ru >= h.nu as i64 || rv >= h.nv as i64 {
                    0.0
                } else {
                    h.data[rv as usize * h.nu + ru as usize]
                }
            };
            let mut worst: f64 = 0.0;
            for v in exact.v0.min(plain.v0)..exact.v0.max(plain.v0) + exact.nv.max(plain.nv) as i64
            {
                for u in
                    exact.u0.min(plain.u0)..exact.u0.max(plain.u0) + exact.nu.max(plain.nu) as i64
                {
                    worst = worst.max((at(&exact, u, v) - at(&plain, u, v)).abs());
                }
            }
            let total: f64 = plain.data.iter().sum();
            assert!(
                worst < 1e-13 * total,
                "phase ({fx}, {fy}): node error {worst:e} of {total}"
            );
            if i % 20 == 0 {
                let d = direct_stamp(&star, &k, &track, &t, bnd);
                let f = fast_stamp(&star, &k, &track, &t, bnd, Some(&mut reader));
                assert!(
                    max_error(&f, &d) < 1e-12,
                    "phase ({fx}, {fy}): stamp {:e}",
                    max_error(&f, &d)
                );
            }
        }
        // both ways of reading were taken: fresh passes for the far jumps, moves for the small steps
        let (moved, passes) = reader.cursor_work();
        assert!((4..20).contains(&passes), "{passes} fresh passes");
        assert!(moved > 300, "{moved} samples moved");
    }

    /// A jitter track hundreds of pixels wide: no shared core of either kind is built (each star's histogram
    /// would pass [`MAX_HISTOGRAM_NODES`]), so the fast method falls back as a star's own deposit does.
    #[test]
    fn no_shared_core_beyond_the_histogram_bound() {
        let g = 8;
        let n = 1000;
        let d: Vec<f64> = (0..n).map(|j| 600.0 * j as f64 / n as f64).collect();
        let track = Track::new(1e-3, 0.0, d.clone(), d);
        // 600 px × 8 nodes on each side of a square box: > 2²⁴ nodes
        for q in [0, 4] {
            assert!(SharedCore::new(&track, 0.0, 0.9, g, q).is_none(), "Q = {q}");
        }
        let small = Track::new(1e-3, 0.0, vec![0.0; n], vec![0.0; n]);
        assert!(SharedCore::new(&small, 0.0, 0.9, g, 0).is_some());
    }

    #[test]
    fn still_track_equals_static_and_conserves_flux() {
        let psf = crate::testkit::synthetic_psf(8, 5);
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(8)).expect("kernel");
        let t = timing(ReadoutOrder::Rolling, 2.0);
        let track = Track::still(3.0 + t.span_s(), 1e-3);
        let star = StarSpec {
            x_px: 50.3,
            y_px: 41.7,
            rate_e_per_s: 500.0,
        };
        let b = stamp_bounds(star.x_px, star.y_px, Some(&track), 6, 200).expect("on detector");
        let s = static_stamp(&star, &k, 2.0, b);
        let f = fast_stamp(&star, &k, &track, &t, b, None);
        let err = s
            .data
            .iter()
            .zip(&f.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-9 * 1000.0, "{err}");
        // flux: rate × T × table sum (the 6-px stamp holds the whole 5-px table)
        assert!((s.sum() / (500.0 * 2.0) - psf.sum()).abs() < 1e-9);
    }

    #[test]
    fn stamp_clipped_at_detector_edges() {
        assert_eq!(stamp_bounds(-100.0, 5.0, None, 5, 100), None);
        let (x0, y0, nx, ny) = stamp_bounds(1.2, 98.7, None, 5, 100).expect("partly on");
        assert_eq!((x0, y0), (0, 94));
        assert_eq!((nx, ny), (7, 6));
    }
}
