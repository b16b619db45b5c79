//! The pixel-response table: one look-up replaces the sum over a pixel's subpixels, exactly.
//!
//! A pixel is split into s×s subpixels with centres at offsets `δ_k = ((k + ½)/s − ½)` px from its centre and
//! sensitivities `w_k` (the intra-pixel map, mean 1). The signal of a pixel whose centre lies at `Δ` from the
//! (jittered) star is the midpoint-rule integral of the bilinear PSF density ρ over the pixel area:
//!
//! `K(Δ) = Σ_k (w_k / s²) · ρ(Δ + δ_k)`      (fraction of the star's flux, per unit time)
//!
//! ρ is bilinear on the PSF grid (spacing 1/os px), so each term is bilinear between breakpoints
//! `j/os − δ_k`. If every δ_k is a multiple of `1/G` with `G = os·m`, all breakpoints lie on the grid of
//! spacing 1/G, and K tabulated on that grid **is exactly bilinear in between**: one bilinear look-up of K
//! equals the s² look-ups of the reference to rounding. [`refinement`] finds the smallest such m
//! (m = 1 when os is a multiple of 2s; the defaults os = 16, s = 8 give G = 16).
//!
//! The same exactness makes the fast method exact: cloud-in-cell deposits of the jitter track onto the
//! G-grid, convolved with K at the grid nodes, reproduce the bilinear look-ups of K at every pixel centre.

use crate::config::{Detector, IntraPixel};
use crate::optics::psf::PsfTable;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// Errors building the intra-pixel map.
#[derive(Debug, thiserror::Error)]
pub enum KernelError {
    #[error("intra-pixel map {path}: {message}")]
    MapFile { path: String, message: String },
    #[error("intra-pixel map {path}: {source}")]
    MapRead {
        path: String,
        source: std::io::Error,
    },
    #[error(
        "pixel kernel grid too fine: psf_oversampling {os} with {s} subpixels needs {g} nodes per pixel (max 256); pick subpixels dividing the oversampling"
    )]
    TooFine { os: usize, s: usize, g: usize },
}

/// Intra-pixel sensitivity over s×s subpixels, mean 1, row-major `[ky * s + kx]`.
#[derive(Debug, Clone, PartialEq)]
pub struct IntraPixelMap {
    pub subpixels: usize,
    pub weights: Vec<f64>,
}

impl IntraPixelMap {
    pub fn uniform(s: usize) -> Self {
        Self {
            subpixels: s,
            weights: vec![1.0; s * s],
        }
    }

    /// The separable map `w[ky·s + kx] = p_x[kx] · p_y[ky]` (both profiles of s subpixels).
    fn outer(px: &[f64], py: &[f64]) -> Self {
        let s = px.len();
        Self {
            subpixels: s,
            weights: py
                .iter()
                .flat_map(|y| px.iter().map(move |x| x * y))
                .collect(),
        }
    }

    /// Resolve the configured map at `subpixels` per axis (a CSV map sets its own size).
    pub fn from_config(det: &Detector, subpixels: usize) -> Result<Self, KernelError> {
        let map = match &det.intra_pixel {
            IntraPixel::Uniform => Self::uniform(subpixels),
            IntraPixel::Separable {
                profile_x,
                profile_y,
            } => {
                let rs = |p: &[f64]| -> Vec<f64> {
                    (0..subpixels)
                        .map(|k| {
                            p[(((k as f64 + 0.5) / subpixels as f64) * p.len() as f64) as usize]
                        })
                        .collect()
                };
                Self::outer(&rs(profile_x), &rs(profile_y))
            }
            IntraPixel::Parabolic { amplitude } => {
                // each subpixel's mean of 1 + a(1 − 12(u − ½)²) over its width: exact, so the map's mean is 1
                let s = subpixels as f64;
                let cube = |u: f64| (u - 0.5).powi(3);
                let p: Vec<f64> = (0..subpixels)
                    .map(|k| {
                        let (u0, u1) = (k as f64 / s, (k + 1) as f64 / s);
                        1.0 + amplitude * (1.0 - 4.0 * (cube(u1) - cube(u0)) * s)
                    })
                    .collect();
                Self::outer(&p, &p)
            }
            IntraPixel::Csv { path } => Self::from_csv(path)?,
        };
        Ok(map.normalised())
    }

    fn from_csv(path: &Path) -> Result<Self, KernelError> {
        let err = |message: String| KernelError::MapFile {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|source| KernelError::MapRead {
            path: path.display().to_string(),
            source,
        })?;
        let rows: Vec<Vec<f64>> = crate::formats::csv::records(path, &text)
            .map(|r| {
                let r = r.map_err(|e| err(e.to_string()))?;
                r.cells
                    .iter()
                    .map(|v| {
                        v.parse::<f64>()
                            .map_err(|e| err(format!("line {}: `{v}`: {e}", r.line)))
                    })
                    .collect()
            })
            .collect::<Result<_, _>>()?;
        let s = rows.len();
        if s == 0 || rows.iter().any(|r| r.len() != s) {
            return Err(err(format!(
                "needs a square table (found {s} rows of unequal or different length)"
            )));
        }
        let weights: Vec<f64> = rows.into_iter().flatten().collect();
        if weights.iter().any(|w| !w.is_finite() || *w < 0.0) || weights.iter().sum::<f64>() <= 0.0
        {
            return Err(err(
                "values must be finite, ≥ 0, with a positive mean".into()
            ));
        }
        Ok(Self {
            subpixels: s,
            weights,
        })
    }

    fn normalised(mut self) -> Self {
        let mean = self.weights.iter().sum::<f64>() / self.weights.len() as f64;
        if mean > 0.0 {
            self.weights.iter_mut().for_each(|w| *w /= mean);
        }
        self
    }

    /// `(p_x, p_y)` with `w[ky·s + kx] = p_y[ky] · p_x[kx]` when the map is separable (uniform maps and
    /// [`IntraPixel::Separable`] ones are), to 1e-12 of the largest weight; `None` otherwise.
    pub fn separable(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let s = self.subpixels;
        let total: f64 = self.weights.iter().sum();
        if !(total > 0.0) {
            return None;
        }
        let px: Vec<f64> = (0..s)
            .map(|kx| (0..s).map(|ky| self.weights[ky * s + kx]).sum::<f64>())
            .collect();
        let py: Vec<f64> = (0..s)
            .map(|ky| self.weights[ky * s..(ky + 1) * s].iter().sum::<f64>() / total)
            .collect();
        let peak = self.weights.iter().cloned().fold(0.0, f64::max);
        let rank_one = (0..s).all(|ky| {
            (0..s).all(|kx| (py[ky] * px[kx] - self.weights[ky * s + kx]).abs() <= 1e-12 * peak)
        });
        rank_one.then_some((px, py))
    }

    /// Subpixel-centre offset from the pixel centre, px.
    pub fn offset_px(&self, k: usize) -> f64 {
        (k as f64 + 0.5) / self.subpixels as f64 - 0.5
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// Smallest m such that every subpixel offset is a multiple of `1/(os·m)` px.
///
/// Offsets are `(2k + 1 − s)/(2s)`: odd multiples of `1/(2s)` for even s, multiples of `1/s` for odd s.
pub fn refinement(os: usize, s: usize) -> usize {
    let q = if s.is_multiple_of(2) { 2 * s } else { s };
    q / gcd(os, q)
}

/// The pixel-response table K on a grid of `nodes_per_px` nodes per pixel, `(2·half_nodes + 1)²` nodes,
/// centred on Δ = 0. Zero beyond the table.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelKernel {
    pub nodes_per_px: usize,
    pub half_nodes: usize,
    pub data: Vec<f64>,
    /// Fraction of a star's light the kernel delivers to pixels: the sum of the PSF table it was built
    /// from (after any jitter blur, whose flux beyond the table is dropped), weighted by the mean of the
    /// intra-pixel map (1). The truth's `psf_fraction`.
    pub light_fraction: f64,
    /// [`PixelKernel::envelope`], made on first use.
    envelope: std::sync::OnceLock<Vec<f64>>,
    /// [`PixelKernel::polyphase`], made on first use.
    polyphase: std::sync::OnceLock<super::polyphase::Polyphase>,
}

impl PixelKernel {
    /// Build K from a PSF table and an intra-pixel map.
    pub fn build(psf: &PsfTable, map: &IntraPixelMap) -> Result<Self, KernelError> {
        let os = psf.oversampling;
        let s = map.subpixels;
        let m = refinement(os, s);
        let g = os * m;
        if g > 256 {
            return Err(KernelError::TooFine { os, s, g });
        }
        // support: the PSF half-width (+1 cell of bilinear ramp) plus half a pixel; one more node, always
        // zero, closes the table so that look-ups beyond it can return 0
        let half = (psf.half_cells + 1) * m + g / 2 + 1;
        let inv_s2 = 1.0 / (s * s) as f64;
        // Subpixel offsets in PSF cells are integers/m: integer part and the fractional step index.
        let offs: Vec<f64> = (0..s).map(|k| map.offset_px(k) * os as f64).collect();
        let data = match map.separable() {
            Some((px, py)) => separable_kernel(psf, &offs, &px, &py, half, m),
            None => general_kernel(psf, map, &offs, half, m),
        };
        let data: Vec<f64> = data
            .into_iter()
            .map(|v| v * inv_s2 * (os * os) as f64)
            .collect();
        let mean_w = map.weights.iter().sum::<f64>() * inv_s2;
        Ok(Self {
            nodes_per_px: g,
            half_nodes: half,
            data,
            light_fraction: psf.sum() * mean_w,
            envelope: std::sync::OnceLock::new(),
            polyphase: std::sync::OnceLock::new(),
        })
    }

    /// K tabulated from a function of Δ (px) on `nodes_per_px` nodes per pixel out to `half_px`, plus the
    /// closing ring of zeros — e.g. an analysis' own ePSF, which already is a pixel-integrated PSF.
    /// `light_fraction` is the table's pixel sum at phase 0.
    pub fn tabulated(nodes_per_px: usize, half_px: usize, f: impl Fn(f64, f64) -> f64) -> Self {
        let g = nodes_per_px.max(1);
        let half = half_px * g + 1;
        let n = 2 * half + 1;
        let mut data = vec![0.0; n * n];
        for iy in 1..n - 1 {
            for ix in 1..n - 1 {
                let (dx, dy) = (
                    (ix as f64 - half as f64) / g as f64,
                    (iy as f64 - half as f64) / g as f64,
                );
                data[iy * n + ix] = f(dx, dy);
            }
        }
        let mut k = Self {
            nodes_per_px: g,
            half_nodes: half,
            data,
            light_fraction: 0.0,
            envelope: std::sync::OnceLock::new(),
            polyphase: std::sync::OnceLock::new(),
        };
        k.light_fraction = k.pixel_sum(0.0, 0.0);
        k
    }

    pub fn n(&self) -> usize {
        2 * self.half_nodes + 1
    }

    /// K by column residue, for the fast method's blocked convolution ([`super::convolve`]); made on
    /// first use, so kernels only the GPU or the direct method reads never hold it.
    pub fn polyphase(&self) -> &super::polyphase::Polyphase {
        self.polyphase.get_or_init(|| {
            super::polyphase::Polyphase::of_table(self.nodes_per_px, self.n(), &self.data)
        })
    }

    /// Stamp half-size that keeps all of K's light for a star anywhere in its pixel:
    /// `⌈support + ½⌉` (the stamp is centred on the star's rounded position).
    pub fn stamp_radius_px(&self) -> usize {
        (self.support_px() + 0.5).ceil() as usize
    }

    /// Value at node offsets from the centre (0 outside).
    #[inline]
    pub fn node(&self, ix: i64, iy: i64) -> f64 {
        let h = self.half_nodes as i64;
        if ix.abs() > h || iy.abs() > h {
            0.0
        } else {
            self.data[((iy + h) * self.n() as i64 + ix + h) as usize]
        }
    }

    /// Bilinear look-up at Δ = (dx, dy) pixels (pixel centre minus star position).
    #[inline]
    pub fn eval(&self, dx_px: f64, dy_px: f64) -> f64 {
        let g = self.nodes_per_px as f64;
        let h = self.half_nodes as f64;
        let (u, v) = (dx_px * g + h, dy_px * g + h);
        // below the table (or NaN): zero; above 0 truncation is the floor (one instruction, where `floor`
        // is a library call on the baseline x86-64 target)
        if !(u >= 0.0 && v >= 0.0) {
            return 0.0;
        }
        let (fu, fv) = ((u as usize) as f64, (v as usize) as f64);
        let n = self.n();
        // the outermost ring of nodes is zero (the table extends one node past the support), so
        // everything at or beyond it is zero
        if fu >= (n - 1) as f64 || fv >= (n - 1) as f64 {
            return 0.0;
        }
        let (tu, tv) = (u - fu, v - fv);
        let i = fv as usize * n + fu as usize;
        let d = &self.data;
        (1.0 - tv) * ((1.0 - tu) * d[i] + tu * d[i + 1])
            + tv * ((1.0 - tu) * d[i + n] + tu * d[i + n + 1])
    }

    /// Σ over all pixel positions of a star at a given sub-pixel phase: the fraction of the flux the table
    /// delivers to pixels (≈ the PSF table's sum for a uniform map).
    pub fn pixel_sum(&self, phase_x: f64, phase_y: f64) -> f64 {
        let r = (self.half_nodes / self.nodes_per_px) as i64 + 1;
        let mut s = 0.0;
        for py in -r..=r {
            for px in -r..=r {
                s += self.eval(px as f64 - phase_x, py as f64 - phase_y);
            }
        }
        s
    }

    /// The wings' envelope: element r is the largest |K| at a Chebyshev distance of r pixels or more from
    /// the star (r = 0 … ⌈support⌉; 0 beyond). A stamp of half-size R around the star's rounded position
    /// leaves out only pixels ≥ R + ½ px away, none of which receives more than `flux · envelope[R]`.
    pub fn envelope(&self) -> &[f64] {
        self.envelope.get_or_init(|| {
            let g = self.nodes_per_px as i64;
            let h = self.half_nodes as i64;
            let n = self.n();
            let rings = (self.support_px().ceil() as usize) + 2;
            let mut env = vec![0.0f64; rings + 1];
            for iy in -h..=h {
                for ix in -h..=h {
                    let d = ix.abs().max(iy.abs()) as f64 / g as f64;
                    let v = self.data[((iy + h) * n as i64 + ix + h) as usize].abs();
                    let r = (d.floor() as usize).min(rings);
                    env[r] = env[r].max(v);
                }
            }
            for r in (0..rings).rev() {
                env[r] = env[r].max(env[r + 1]);
            }
            env
        })
    }

    /// The smallest stamp half-size R (≥ 1 px, at most [`PixelKernel::stamp_radius_px`]) outside which a
    /// star of `flux_e` electrons puts less than `threshold_e` in any pixel.
    pub fn reach_px(&self, flux_e: f64, threshold_e: f64) -> usize {
        let full = self.stamp_radius_px();
        if threshold_e <= 0.0 {
            return full;
        }
        self.envelope()
            .iter()
            .position(|e| flux_e * e < threshold_e)
            .unwrap_or(full)
            .clamp(1, full)
    }

    /// Largest |Δ| (px) with a non-zero table value.
    pub fn support_px(&self) -> f64 {
        self.half_nodes as f64 / self.nodes_per_px as f64
    }
}

/// `Σ_k w_k ρ(Δ + δ_k)` at every node (in PSF-cell units), straight from the definition: s² bilinear look-ups
/// per node. Any intra-pixel map.
fn general_kernel(
    psf: &PsfTable,
    map: &IntraPixelMap,
    offs: &[f64],
    half: usize,
    m: usize,
) -> Vec<f64> {
    let s = map.subpixels;
    let n = 2 * half + 1;
    let mut data = vec![0.0; n * n];
    data.par_chunks_mut(n).enumerate().for_each(|(iy, row)| {
        let dy_cells = (iy as f64 - half as f64) / m as f64;
        for (ix, out) in row.iter_mut().enumerate() {
            let dx_cells = (ix as f64 - half as f64) / m as f64;
            let mut acc = 0.0;
            for ky in 0..s {
                let v = dy_cells + offs[ky];
                for kx in 0..s {
                    let w = map.weights[ky * s + kx];
                    if w != 0.0 {
                        acc += w * bilinear_cells(psf, dx_cells + offs[kx], v);
                    }
                }
            }
            *out = acc;
        }
    });
    data
}

/// The same sum for a separable map `w = p_y ⊗ p_x`: the bilinear look-up is a product of hat functions, so
/// `K = B_y · P · A_xᵀ` with `A[node][cell] = Σ_k p_k · hat(node + δ_k − cell)` (≤ 2s cells per node):
/// two sparse passes, ≈ 4s multiply-adds per node instead of 4s².
fn separable_kernel(
    psf: &PsfTable,
    offs: &[f64],
    px: &[f64],
    py: &[f64],
    half: usize,
    m: usize,
) -> Vec<f64> {
    let n = 2 * half + 1;
    let hc = psf.half_cells as i64;
    let nc = psf.n();
    // taps[node] = (cell index into the table, weight), cells outside the table dropped (zero there)
    let taps = |p: &[f64]| -> Vec<Vec<(usize, f64)>> {
        (0..n)
            .map(|i| {
                let d_cells = (i as f64 - half as f64) / m as f64;
                let mut t: Vec<(usize, f64)> = Vec::with_capacity(2 * p.len());
                for (k, &w) in p.iter().enumerate() {
                    if w == 0.0 {
                        continue;
                    }
                    let u = d_cells + offs[k];
                    let fu = u.floor();
                    let tu = u - fu;
                    for (c, h) in [(fu as i64, 1.0 - tu), (fu as i64 + 1, tu)] {
                        if c.abs() > hc || h == 0.0 {
                            continue;
                        }
                        let c = (c + hc) as usize;
                        match t.iter_mut().find(|e| e.0 == c) {
                            Some(e) => e.1 += w * h,
                            None => t.push((c, w * h)),
                        }
                    }
                }
                t
            })
            .collect()
    };
    let (ax, by) = (taps(px), taps(py));
    // T[cell row][node x] = Σ_i A_x[node x][i] P[row][i]
    let mut t = vec![0.0; nc * n];
    t.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        let prow = &psf.data[j * nc..(j + 1) * nc];
        for (out, tap) in row.iter_mut().zip(&ax) {
            *out = tap.iter().map(|&(i, w)| w * prow[i]).sum();
        }
    });
    // K[node y][node x] = Σ_j B_y[node y][j] T[j][node x]
    let mut data = vec![0.0; n * n];
    data.par_chunks_mut(n).zip(&by).for_each(|(row, tap)| {
        for &(j, w) in tap {
            for (o, v) in row.iter_mut().zip(&t[j * n..(j + 1) * n]) {
                *o += w * v;
            }
        }
    });
    data
}

/// Bilinear PSF density per cell² at a position in PSF cells.
#[inline]
fn bilinear_cells(psf: &PsfTable, u: f64, v: f64) -> f64 {
    let (fu, fv) = (u.floor(), v.floor());
    let (tu, tv) = (u - fu, v - fv);
    let (iu, iv) = (fu as i64, fv as i64);
    (1.0 - tu) * (1.0 - tv) * psf.at(iu, iv)
        + tu * (1.0 - tv) * psf.at(iu + 1, iv)
        + (1.0 - tu) * tv * psf.at(iu, iv + 1)
        + tu * tv * psf.at(iu + 1, iv + 1)
}

/// The reference sum over subpixels (what K replaces), for tests and the `reference` method.
pub fn subpixel_sum(psf: &PsfTable, map: &IntraPixelMap, dx_px: f64, dy_px: f64) -> f64 {
    let s = map.subpixels;
    let mut acc = 0.0;
    for ky in 0..s {
        for kx in 0..s {
            acc += map.weights[ky * s + kx]
                * psf.density_px2(dx_px + map.offset_px(kx), dy_px + map.offset_px(ky));
        }
    }
    acc / (s * s) as f64
}

/// Pixel kernels by (PSF, Gaussian blur, intra-pixel map), shared by every simulator of a session. Each entry
/// holds the PSF it was built from, so the PSF's address (the key) cannot be reused while it is cached. When
/// a new kernel would pass [`KernelCache::MAX_ENTRIES`], the kernels no caller holds any more are forgotten;
/// those still held stay (the cache then holds no more than its callers do).
#[derive(Default)]
pub struct KernelCache {
    entries: Mutex<HashMap<(usize, u64), Vec<(Arc<PsfTable>, IntraPixelMap, Arc<PixelKernel>)>>>,
}

impl KernelCache {
    pub const MAX_ENTRIES: usize = 128;

    /// The kernel of `psf` blurred by a Gaussian of `blur_px` (0: none) with `map`, built on first use.
    pub fn get(
        &self,
        psf: &Arc<PsfTable>,
        blur_px: f64,
        map: &IntraPixelMap,
    ) -> Result<Arc<PixelKernel>, KernelError> {
        let key = (Arc::as_ptr(psf) as usize, blur_px.to_bits());
        let lock = || self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(v) = lock().get(&key)
            && let Some((_, _, k)) = v.iter().find(|(_, m, _)| m == map)
        {
            return Ok(k.clone());
        }
        let table = if blur_px > 0.0 {
            Arc::new(psf.gaussian_blurred(blur_px))
        } else {
            psf.clone()
        };
        let k = Arc::new(PixelKernel::build(&table, map)?);
        let mut entries = lock();
        if entries.values().map(Vec::len).sum::<usize>() >= Self::MAX_ENTRIES {
            // forget the kernels nobody else holds: one a caller still holds (a dataset's star jobs) stays,
            // so a field of more PSFs than the cache's size never builds a kernel twice, and the memory
            // held is what the callers hold
            for v in entries.values_mut() {
                v.retain(|(_, _, k)| Arc::strong_count(k) > 1);
            }
            entries.retain(|_, v| !v.is_empty());
        }
        entries
            .entry(key)
            .or_default()
            .push((psf.clone(), map.clone(), k.clone()));
        Ok(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parabolic map: mean 1 at any subpixel count (each subpixel the exact mean of the profile over its
    /// width), 1 + a at the centre and 1 − 2a at the edges per axis when fine, uniform at 2 subpixels (each
    /// half's mean of a symmetric profile about its mean is the mean), separable; and an amplitude that would
    /// make the edges dark or negative is refused.
    #[test]
    fn the_parabolic_intra_pixel_map_has_its_stated_shape() {
        let mut det = crate::config::Config::default().detector;
        det.intra_pixel = IntraPixel::Parabolic { amplitude: 0.12 };
        let fine = IntraPixelMap::from_config(&det, 200).expect("map");
        let mean = fine.weights.iter().sum::<f64>() / fine.weights.len() as f64;
        assert!((mean - 1.0).abs() < 1e-12, "{mean}");
        // separable (its factors come back up to a common scale: normalised to mean 1 here)
        let (px, _) = fine.separable().expect("separable");
        let m = px.iter().sum::<f64>() / px.len() as f64;
        let (lo, hi) = px.iter().fold((f64::MAX, f64::MIN), |(a, b), v| {
            (a.min(v / m), b.max(v / m))
        });
        assert!(
            (hi - 1.12).abs() < 1e-4 && (lo - 0.76).abs() < 4e-3,
            "{lo} … {hi}"
        );
        let two = IntraPixelMap::from_config(&det, 2).expect("map");
        assert!(two.weights.iter().all(|w| (w - 1.0).abs() < 1e-12));
        let mut cfg = crate::config::Config::default();
        cfg.detector.intra_pixel = IntraPixel::Parabolic { amplitude: 0.5 };
        let e = cfg.validate().expect_err("dark edges");
        assert!(
            e.to_string().contains("detector.intra_pixel.amplitude"),
            "{e}"
        );
    }

    #[test]
    fn refinement_makes_offsets_grid_multiples() {
        for os in [4, 8, 13, 16] {
            for s in [1, 2, 3, 4, 5, 8] {
                let m = refinement(os, s);
                let g = (os * m) as f64;
                for k in 0..s {
                    let off = ((k as f64 + 0.5) / s as f64 - 0.5) * g;
                    assert!(
                        (off - off.round()).abs() < 1e-9,
                        "os {os} s {s}: offset {off}"
                    );
                }
            }
        }
        assert_eq!(refinement(16, 8), 1);
        assert_eq!(refinement(13, 8), 16);
    }

    #[test]
    fn kernel_lookup_equals_subpixel_sum_exactly() {
        for (os, s) in [(8, 4), (6, 3), (8, 8)] {
            let psf = crate::testkit::synthetic_psf(os, 4);
            let mut map = IntraPixelMap::uniform(s);
            // a non-uniform map
            for (i, w) in map.weights.iter_mut().enumerate() {
                *w = 0.6 + 0.8 * ((i * 7) % 5) as f64 / 4.0;
            }
            let map = map.normalised();
            let k = PixelKernel::build(&psf, &map).expect("kernel");
            let mut worst: f64 = 0.0;
            for t in 0..200 {
                let dx = -3.0 + 6.0 * ((t as f64 * 0.618_034) % 1.0);
                let dy = -3.0 + 6.0 * ((t as f64 * 0.414_214) % 1.0);
                let a = k.eval(dx, dy);
                let b = subpixel_sum(&psf, &map, dx, dy);
                worst = worst.max((a - b).abs());
            }
            let peak = k.data.iter().cloned().fold(0.0, f64::max);
            assert!(
                worst / peak < 1e-13,
                "os {os} s {s}: |K − Σ subpixels| / peak = {:e}",
                worst / peak
            );
        }
    }

    /// Separable maps take the two-pass build: it must equal the definition (the subpixel sum) as the
    /// general build does, and the general build itself to rounding.
    #[test]
    fn separable_build_equals_subpixel_sum_and_general_build() {
        let mut det = Detector::default();
        det.intra_pixel = IntraPixel::Separable {
            profile_x: vec![0.55, 1.0, 1.35, 0.9],
            profile_y: vec![1.2, 0.7, 1.1],
        };
        for (os, s) in [(8, 4), (6, 3), (13, 8), (16, 8)] {
            let psf = crate::testkit::synthetic_psf(os, 4);
            for map in [
                IntraPixelMap::uniform(s),
                IntraPixelMap::from_config(&det, s).expect("map"),
            ] {
                assert!(
                    map.separable().is_some(),
                    "os {os} s {s}: map not seen as separable"
                );
                let k = PixelKernel::build(&psf, &map).expect("kernel");
                let peak = k.data.iter().cloned().fold(0.0, f64::max);
                let mut worst: f64 = 0.0;
                for t in 0..200 {
                    let dx = -5.0 + 10.0 * ((t as f64 * 0.618_034) % 1.0);
                    let dy = -5.0 + 10.0 * ((t as f64 * 0.414_214) % 1.0);
                    worst = worst.max((k.eval(dx, dy) - subpixel_sum(&psf, &map, dx, dy)).abs());
                }
                assert!(worst / peak < 1e-13, "os {os} s {s}: {:e}", worst / peak);
                let m = refinement(os, s);
                let offs: Vec<f64> = (0..s).map(|j| map.offset_px(j) * os as f64).collect();
                let general = general_kernel(&psf, &map, &offs, k.half_nodes, m);
                let scale = (os * os) as f64 / (s * s) as f64;
                let diff = general
                    .iter()
                    .zip(&k.data)
                    .map(|(g, v)| (g * scale - v).abs())
                    .fold(0.0, f64::max);
                assert!(
                    diff / peak < 1e-13,
                    "os {os} s {s}: general vs separable {:e}",
                    diff / peak
                );
            }
        }
        // a map that is not rank one takes the general build
        let mut map = IntraPixelMap::uniform(3);
        map.weights[4] = 2.0;
        assert!(map.separable().is_none());
    }

    #[test]
    fn kernel_conserves_flux_for_uniform_map() {
        // subpixels = PSF cells: the subpixel lattice samples the bilinear PSF at every cell, exactly
        let psf = crate::testkit::synthetic_psf(4, 5);
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(4)).expect("kernel");
        for (px, py) in [(0.0, 0.0), (0.3, -0.2), (0.49, 0.5)] {
            let s = k.pixel_sum(px, py);
            assert!((s - psf.sum()).abs() < 1e-12, "phase ({px},{py}): {s}");
        }
        // coarser subpixels: the midpoint rule's error is small but not zero
        let psf = crate::testkit::synthetic_psf(8, 5);
        let k = PixelKernel::build(&psf, &IntraPixelMap::uniform(4)).expect("kernel");
        let s = k.pixel_sum(0.3, -0.2);
        assert!((s - psf.sum()).abs() < 1e-4, "{s}");
    }

    #[test]
    fn separable_map_is_normalised() {
        let mut det = Detector::default();
        det.intra_pixel = IntraPixel::Separable {
            profile_x: vec![0.55, 1.0, 1.35],
            profile_y: vec![1.0, 2.0],
        };
        let m = IntraPixelMap::from_config(&det, 6).expect("map");
        assert!((m.weights.iter().sum::<f64>() / 36.0 - 1.0).abs() < 1e-12);
        assert!(m.weights[0] < m.weights[5]);
    }
}
