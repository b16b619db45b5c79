//! Each pixel's own samples: the few at the ends of its exposure window that its row's shared window does
//! not hold, looked up in K one by one — taken sample by sample across the row.
//!
//! Under the rolling readout a row's pixels start within about one row time of each other, so their own
//! samples are the same few samples with weights that differ from pixel to pixel:
//! `out(X) += Σ_j e_X(j) · K(X − x − dx_j, Y − y − dy_j)` with `e_X(j) = w_X(j) − w_row(j)`
//! ([`super::track::WindowWeights`]). For one sample the look-ups of a row of pixels are G nodes apart in
//! K, which K's residue layout ([`super::convolve::Polyphase`]) stores side by side: the row's bilinear
//! look-ups read four contiguous runs instead of four scattered nodes per pixel. Every pixel adds the same
//! terms in the same order (its samples in time order) with the arithmetic of [`PixelKernel::eval`], so
//! every value keeps its bits; a sample whose node columns are not G apart to the bit (a node coordinate
//! within rounding of a whole node) is looked up pixel by pixel.

use super::kernel::PixelKernel;
use super::track::{Track, WindowWeights, weight_in};

/// One stamp row: each pixel's window, the row's shared window (which each holds), and the pixels' offsets
/// from the star (px: `x − x_star` of each, `y − y_star` of the row).
#[derive(Debug, Clone, Copy)]
pub struct RowWindows<'a> {
    pub owns: &'a [WindowWeights],
    pub row: &'a WindowWeights,
    pub bx_px: &'a [f64],
    pub by_px: f64,
}

/// The memory a row's look-ups work in, kept from row to row of a stamp.
#[derive(Debug, Default)]
pub struct RowScratch {
    /// Each sample's weight beyond the row's, pixel by pixel.
    e: Vec<f64>,
    /// Whether any pixel has a weight for each sample.
    any: Vec<bool>,
    /// One sample's node column, pixel by pixel.
    u: Vec<f64>,
    /// Each pixel's window: first and last sample (as numbers) and their weights.
    ends: Vec<[f64; 4]>,
}

/// `out[ix] += Σ_j e_ix(j) · K(bx_px[ix] − dx_j, by_px − dy_j)` over every sample where some pixel's window
/// `owns[ix]` weighs more than the row's `row` (which each of them holds; [`RowWindows`]).
#[allow(unsafe_code)] // calling the AVX2 build after checking the processor has AVX2: nothing else
pub fn add_own_samples(
    out: &mut [f64],
    r: &RowWindows<'_>,
    track: &Track,
    k: &PixelKernel,
    scratch: &mut RowScratch,
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { own_samples_avx2(out, r, track, k, scratch) };
        return;
    }
    own_samples_body(out, r, track, k, scratch);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn own_samples_avx2(
    out: &mut [f64],
    r: &RowWindows<'_>,
    track: &Track,
    k: &PixelKernel,
    scratch: &mut RowScratch,
) {
    own_samples_body(out, r, track, k, scratch);
}

#[inline(always)]
fn own_samples_body(
    out: &mut [f64],
    r: &RowWindows<'_>,
    track: &Track,
    k: &PixelKernel,
    scratch: &mut RowScratch,
) {
    let RowWindows {
        owns,
        row,
        bx_px,
        by_px,
    } = *r;
    let nx = out.len();
    debug_assert!(owns.len() == nx && bx_px.len() == nx);
    let (Some(first), Some(last)) = (
        owns.iter().map(|w| w.first).min(),
        owns.iter().map(|w| w.last).max(),
    ) else {
        return;
    };
    // the samples where a pixel's weight can differ from the row's: those of the pixels' windows together up to
    // the row's first and from its last (inside the row's window every pixel weighs 1, as the row does) —
    // each pixel's own are among them
    let together = WindowWeights {
        first,
        last,
        w_first: 1.0,
        w_last: 1.0,
    };
    let (head, tail) = together.extra_ranges(row);
    let (head_end, tail_start) = (*head.end(), *tail.start());
    let n_head = (head_end + 1).saturating_sub(first);
    let n_samples = n_head + (last + 1).saturating_sub(tail_start);
    // e[s·nx + ix]: pixel ix's weight beyond the row's for the s-th of those samples, `w_ix(j) − w_row(j)`
    // ([`WindowWeights::weight`]) for every pixel at once: exactly 0 where the sample is not among the
    // pixel's own (before its window starts, the row's has not started either; after it ends, neither has
    // the row's), so the same values as each pixel's own samples (`for_each_extra`) written one by one
    let RowScratch { e, any, u, ends } = scratch;
    ends.clear();
    ends.extend(
        owns.iter()
            .map(|w| [w.first as f64, w.last as f64, w.w_first, w.w_last]),
    );
    e.clear();
    e.resize(n_samples * nx, 0.0);
    any.clear();
    any.resize(n_samples, false);
    for (j, (e_s, any_s)) in head
        .clone()
        .chain(tail.clone())
        .zip(e.chunks_exact_mut(nx).zip(any.iter_mut()))
    {
        let (jf, w_row) = (j as f64, row.weight(j));
        let mut some = false;
        for (ej, &[first, last, w_first, w_last]) in e_s.iter_mut().zip(ends.iter()) {
            *ej = weight_in(jf, first, last, w_first, w_last) - w_row;
            some |= *ej != 0.0;
        }
        *any_s = some;
    }
    let (g, h) = (k.nodes_per_px as f64, k.half_nodes as f64);
    // the table's last node as a bound (the outermost ring is zero: at or beyond it a look-up is zero)
    let last_node = (k.n() - 1) as i32;
    let p = k.polyphase();
    u.clear();
    u.resize(nx, 0.0);
    let samples = head.chain(tail);
    for (j, e) in samples
        .zip(e.chunks_exact(nx))
        .zip(any.iter())
        .filter_map(|(je, a)| a.then_some(je))
    {
        let (dxj, dyj) = (track.dx_px[j], track.dy_px[j]);
        // K's look-up with the arithmetic of `PixelKernel::eval` (node coordinates ≥ 0 inside the table, where
        // truncation is the floor: through i32, one instruction)
        let v = (by_px - dyj) * g + h;
        if !(v >= 0.0) || v as i32 >= last_node {
            continue;
        }
        let fv = (v as i32) as f64;
        let tv = v - fv;
        for (ui, bx) in u.iter_mut().zip(bx_px) {
            *ui = (bx - dxj) * g + h;
        }
        let Some((lo, hi, ku)) = lanes_in_table(u, last_node, k.nodes_per_px) else {
            // a node column within rounding of a whole node (or pixels not a pixel apart): one by one
            for ((o, &ei), bx) in out.iter_mut().zip(e).zip(bx_px) {
                if ei != 0.0 {
                    *o += ei * k.eval(bx - dxj, by_px - dyj);
                }
            }
            continue;
        };
        let (ky, cnt) = (fv as usize, hi - lo);
        // K's four nodes around each pixel's look-up: rows ky, ky + 1, columns ku + G·i and one further
        let (Some(a0), Some(b0), Some(a1), Some(b1)) = (
            p.along_row(ky, ku, cnt),
            p.along_row(ky, ku + 1, cnt),
            p.along_row(ky + 1, ku, cnt),
            p.along_row(ky + 1, ku + 1, cnt),
        ) else {
            // no pixel in the table
            continue;
        };
        let lanes = out[lo..hi].iter_mut().zip(&e[lo..hi]).zip(&u[lo..hi]);
        let nodes = a0.iter().zip(b0).zip(a1.iter().zip(b1));
        for (((o, &ei), &ui), ((&k00, &k01), (&k10, &k11))) in lanes.zip(nodes) {
            let tu = ui - (ui as i32) as f64;
            let val =
                (1.0 - tv) * ((1.0 - tu) * k00 + tu * k01) + tv * ((1.0 - tu) * k10 + tu * k11);
            if ei != 0.0 {
                *o += ei * val;
            }
        }
    }
}

/// The pixels of a row whose node column `u` (one sample's, ≥ 0 and truncated: the floor) lies inside the
/// table (`lo … hi`), and the first one's column, when their columns are G apart to the bit and the pixels
/// before and after lie below and beyond it; `None` otherwise (looked up one by one).
#[inline(always)]
fn lanes_in_table(u: &[f64], last_node: i32, g: usize) -> Option<(usize, usize, usize)> {
    let lo = u.iter().position(|&ui| ui >= 0.0).unwrap_or(u.len());
    let hi = lo
        + u[lo..]
            .iter()
            .take_while(|&&ui| (ui as i32) < last_node)
            .count();
    if lo == hi {
        return Some((lo, hi, 0));
    }
    let ku = u[lo] as i32;
    let mut even = true;
    for (i, &ui) in u[lo..hi].iter().enumerate() {
        even &= ui as i32 == ku + i as i32 * g as i32;
    }
    for &ui in &u[hi..] {
        even &= ui as i32 >= last_node;
    }
    even.then_some((lo, hi, ku as usize))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against each pixel's own samples looked up one by one with [`PixelKernel::eval`] (what the fast method
    /// did before): the same bits — rows inside K's table, rows reaching past it on either side, rows above and
    /// below it, windows that start anywhere within a few samples of each other, and pixels not a whole pixel
    /// apart (looked up pixel by pixel).
    #[test]
    fn a_row_at_once_equals_pixel_by_pixel() {
        let g = 4;
        let k = PixelKernel::tabulated(g, 5, |dx, dy| {
            (-(dx * dx + 0.6 * dy * dy) / 6.0).exp() * (1.0 + 0.2 * dx - 0.1 * dy)
        });
        let n = 400;
        let dt_s = 0.01;
        let dx = (0..n).map(|j| 0.7 * (j as f64 * 0.05).sin()).collect();
        let dy = (0..n).map(|j| 0.5 * (j as f64 * 0.037).cos()).collect();
        let track = Track::new(dt_s, 0.0, dx, dy);
        let mut scratch = RowScratch::default();
        // (first pixel's offset from the star, pixel spacing, row offset, pixels)
        for &(bx0, step, by, nx) in &[
            (-6.3, 1.0, 0.4, 13usize),
            (-20.25, 1.0, -2.1, 30),
            (2.7, 1.0, 5.2, 9),
            (-3.1, 1.0, -5.8, 8),
            (-4.0, 1.0, 9.0, 10),
            (-4.0, 1.0, -9.0, 10),
            (-5.2, 1.013, 0.3, 11),
            (-1.5, 1.0, 0.0, 1),
        ] {
            let bx_px: Vec<f64> = (0..nx).map(|i| bx0 + step * i as f64).collect();
            // windows of 2.5 s starting within 0.04 s (four samples) of each other, at fractions of a sample
            let windows_s: Vec<(f64, f64)> = (0..nx)
                .map(|i| {
                    let a = 1.0033 + 0.0037 * ((i * 7) % 11) as f64;
                    (a, a + 2.5)
                })
                .collect();
            let owns: Vec<WindowWeights> =
                windows_s.iter().map(|w| track.window(w.0, w.1)).collect();
            let (a_max, b_min) = windows_s
                .iter()
                .fold((f64::MIN, f64::MAX), |(a, b), w| (a.max(w.0), b.min(w.1)));
            let row = track.window(a_max, b_min);
            let start: Vec<f64> = (0..nx).map(|i| 0.5 + i as f64).collect();
            let mut plain = start.clone();
            for ((o, w), bx) in plain.iter_mut().zip(&owns).zip(&bx_px) {
                w.for_each_extra(&row, |j, e| {
                    *o += e * k.eval(bx - track.dx_px[j], by - track.dy_px[j]);
                });
            }
            let r = RowWindows {
                owns: &owns,
                row: &row,
                bx_px: &bx_px,
                by_px: by,
            };
            let mut at_once = start.clone();
            add_own_samples(&mut at_once, &r, &track, &k, &mut scratch);
            assert_eq!(at_once, plain, "row at ({bx0}, {by}), step {step}");
            let mut portable = start.clone();
            own_samples_body(&mut portable, &r, &track, &k, &mut scratch);
            assert_eq!(portable, plain, "the portable build at ({bx0}, {by})");
        }
    }

    /// Which pixels a row takes at once: those inside the table when their columns are G apart, none of a row
    /// beyond it, and a row whose columns are not G apart (or that comes back into the table) one by one.
    #[test]
    fn lanes_inside_the_table() {
        let g = 4;
        let cols = |u0: f64, step: f64| (0..10).map(|i| u0 + step * i as f64).collect::<Vec<_>>();
        assert_eq!(lanes_in_table(&cols(-9.5, 4.0), 30, g), Some((3, 10, 2)));
        assert_eq!(lanes_in_table(&cols(1.25, 4.0), 30, g), Some((0, 8, 1)));
        assert_eq!(lanes_in_table(&cols(-50.0, 4.0), 30, g), Some((10, 10, 0)));
        assert_eq!(lanes_in_table(&cols(31.0, 4.0), 30, g), Some((0, 0, 0)));
        assert_eq!(lanes_in_table(&cols(0.5, 4.1), 30, g), None);
        let mut back = cols(20.0, 4.0);
        back[9] = 3.0;
        assert_eq!(lanes_in_table(&back, 30, g), None);
    }
}
