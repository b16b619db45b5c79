//! The predictor's shape term: what the linear fit response ([`crate::analysis::response`]) misses of a star's
//! fit displacement when the jitter of its window differs from the image's mean jitter (under the rolling
//! readout a large drift makes the star images change shape along Y, not only shift), and what the ePSF
//! builder makes of stars whose shapes differ.
//!
//! Each sampled star (the scene's, at most [`MAX_SAMPLE`] of them) is imaged noise-free, on its own stamp, as
//! the static profile ψ (the PSF integrated over the pixel) seen through the jitter of its own pixels' windows —
//! the forward model of the `telemetry-model` countermeasure ([`crate::analysis::countermeasures::forward`]),
//! here fed with the true track. The stamps, laid side by side with each star's sub-pixel phase, go through the
//! analysis' own ePSF builder and fit ([`crate::analysis::epsf::build`]), so the ePSF is made as the pipeline
//! makes it: from the stars, on their fitted positions, smoothed and re-centred. A star's fitted minus true
//! position minus the linear response's prediction is its shape term. Binned in [`ROWS`] bands of Y, its band
//! mean (interpolated in Y) is added to every star's displacement, its spread about the band mean is a scatter
//! from star to star (pixel phase, the builder's own error). Noise-free stamps, not an image: ≈ 0.1 s per
//! exposure of 400 stars.

use crate::analysis::countermeasures::forward::Forward;
use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{BuildOptions, StarStart, build, initial_start};
use crate::analysis::epsf::fit::{PixelData, Profile};
use crate::analysis::response::{FitNoise, FitResponse};
use crate::integrate::track::Track;
use crate::readout::ReadoutTiming;
use rayon::prelude::*;

/// Bands of Y the shape term is averaged over.
pub const ROWS: usize = 16;

/// Most stars sampled (evenly strided through the scene's): the paper grid's 400 all.
pub const MAX_SAMPLE: usize = 400;

/// Nodes per pixel of the jitter histograms (the forward model's default is 16; an eighth of a pixel smooths
/// ψ by ≤ 0.002 px², a symmetric broadening that moves no star).
const NODES_PER_PX: usize = 8;

/// The shape term of one exposure.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeTerm {
    /// The bands' mean rows (px) and the shape term's mean there (px).
    rows_y: Vec<f64>,
    mean_px: Vec<(f64, f64)>,
    /// Its variance about the band means, px² per axis (averaged over the axes).
    pub scatter_px2: f64,
}

impl ShapeTerm {
    /// No shape term (a static ACE, or too few stars to build an ePSF from).
    pub fn none() -> Self {
        Self {
            rows_y: Vec::new(),
            mean_px: Vec::new(),
            scatter_px2: 0.0,
        }
    }

    /// The band mean at row `y` (px), interpolated linearly between the bands (held beyond them).
    pub fn at(&self, y: f64) -> (f64, f64) {
        let n = self.rows_y.len();
        if n == 0 {
            return (0.0, 0.0);
        }
        let k = self.rows_y.partition_point(|r| *r <= y);
        if k == 0 {
            return self.mean_px[0];
        }
        if k == n {
            return self.mean_px[n - 1];
        }
        let t = (y - self.rows_y[k - 1]) / (self.rows_y[k] - self.rows_y[k - 1]);
        let (a, b) = (self.mean_px[k - 1], self.mean_px[k]);
        (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
    }

    /// The shape term of an exposure whose jitter is `track`, for a scene's `stars` (px): ψ the static
    /// profile, `response` the linear response it corrects, the fit's noise and the builder's options those of
    /// the analysis, the detector `detector_px` square.
    #[allow(clippy::too_many_arguments)]
    pub fn build(
        psi: &Epsf,
        track: &Track,
        timing: &ReadoutTiming,
        response: &FitResponse,
        noise: &FitNoise,
        opts: &BuildOptions,
        detector_px: usize,
        stars: &[(f64, f64)],
    ) -> Self {
        let stride = stars.len().div_ceil(MAX_SAMPLE).max(1);
        let sample: Vec<(f64, f64)> = stars.iter().step_by(stride).copied().collect();
        if sample.len() < crate::analysis::pipeline::MIN_EPSF_STARS {
            return Self::none();
        }
        let fitted = fitted_displacements(psi, track, timing, noise, opts, detector_px, &sample);
        let linear = response.displacements(track, timing, &sample);
        let band =
            |y: f64| ((y / detector_px.max(1) as f64 * ROWS as f64).floor() as usize).min(ROWS - 1);
        let mut sums = vec![(0.0, 0.0, 0.0, 0usize); ROWS];
        let terms: Vec<(usize, f64, f64)> = sample
            .iter()
            .zip(fitted.iter().zip(&linear))
            .filter(|(_, (f, _))| f.0.is_finite() && f.1.is_finite())
            .map(|(p, (f, l))| (band(p.1), f.0 - l.0, f.1 - l.1))
            .collect();
        for (&(k, dx, dy), p) in terms.iter().zip(&sample) {
            let s = &mut sums[k];
            (s.0, s.1, s.2, s.3) = (s.0 + p.1, s.1 + dx, s.2 + dy, s.3 + 1);
        }
        let (mut rows_y, mut mean_px) = (Vec::new(), Vec::new());
        for s in sums.iter().filter(|s| s.3 > 0) {
            let n = s.3 as f64;
            rows_y.push(s.0 / n);
            mean_px.push((s.1 / n, s.2 / n));
        }
        let bands = rows_y.len();
        let spread: f64 = terms
            .iter()
            .map(|&(k, dx, dy)| {
                let s = &sums[k];
                let n = s.3 as f64;
                ((dx - s.1 / n).powi(2) + (dy - s.2 / n).powi(2)) / 2.0
            })
            .sum();
        let dof = terms.len().saturating_sub(bands).max(1) as f64;
        Self {
            rows_y,
            mean_px,
            scatter_px2: spread / dof,
        }
    }
}

/// The displacements (px) the analysis' ePSF build and fit give noise-free stars at `positions` of the
/// typical flux and sky, each imaged as ψ through its pixels' windows on its own stamp.
pub fn fitted_displacements(
    psi: &Epsf,
    track: &Track,
    timing: &ReadoutTiming,
    noise: &FitNoise,
    opts: &BuildOptions,
    detector_px: usize,
    positions: &[(f64, f64)],
) -> Vec<(f64, f64)> {
    let forward = Forward::new(psi, track, timing, NODES_PER_PX, detector_px);
    // a stamp holds the ePSF's reach and the sky annulus (as detection::sky_annulus), star at its centre pixel
    let r = opts.half_px as f64;
    let annulus = (r + 1.0, r + 4.0);
    let half = opts.half_px as i64 + 5;
    let reach = r + 1.0;
    let side = (2 * half + 1) as usize;
    let cols = (positions.len() as f64).sqrt().ceil().max(1.0) as usize;
    let rows = positions.len().div_ceil(cols);
    let (nx, ny) = (cols * side, rows * side);
    let stamps: Vec<Vec<f64>> = positions
        .par_iter()
        .map(|&(x, y)| {
            // the forward model over the ePSF's reach; beyond it (the sky annulus) the static profile's wings
            let star = forward.star(x, y, reach, detector_px, detector_px);
            let (cx, cy) = (x.round() as i64, y.round() as i64);
            let mut v = Vec::with_capacity(side * side);
            for ly in -half..=half {
                for lx in -half..=half {
                    let (gx, gy) = (cx + lx, cy + ly);
                    let p = if lx.abs().max(ly.abs()) as f64 <= reach {
                        let i = gy.max(0) as usize * detector_px + gx.max(0) as usize;
                        star.eval_at(i, gx as f64, gy as f64, x, y).0
                    } else {
                        psi.value(gx as f64 - x, gy as f64 - y)
                    };
                    v.push(noise.flux_e * p + noise.sky_e);
                }
            }
            v
        })
        .collect();
    let mut e = vec![noise.sky_e; nx * ny];
    let mut truth = Vec::with_capacity(positions.len());
    for (k, (stamp, &(x, y))) in stamps.iter().zip(positions).enumerate() {
        let (ox, oy) = ((k % cols) * side, (k / cols) * side);
        for ly in 0..side {
            let row = (oy + ly) * nx + ox;
            e[row..row + side].copy_from_slice(&stamp[ly * side..(ly + 1) * side]);
        }
        truth.push((
            ox as f64 + half as f64 + (x - x.round()),
            oy as f64 + half as f64 + (y - y.round()),
        ));
    }
    let bad = vec![false; e.len()];
    let pd = PixelData {
        nx,
        ny,
        e: &e,
        bad: &bad,
        var_floor_e2: noise.floor_e2,
        var_floor_px_e2: None,
        flat_sigma: 0.0,
    };
    // started as the pipeline starts them (a centroid, the annulus sky, the flux in 3 px): with a few
    // iterations the builder's ePSF still depends on where its stars started
    let starts: Vec<StarStart> = truth
        .iter()
        .map(|&(x, y)| initial_start(&pd, x, y, annulus))
        .collect();
    let built = build(&pd, &starts, &vec![true; starts.len()], opts, None, None);
    built
        .fits
        .iter()
        .zip(&truth)
        .map(|(f, t)| (f.x - t.0, f.y - t.1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_between_rows_and_held_beyond() {
        let s = ShapeTerm {
            rows_y: vec![10.0, 20.0],
            mean_px: vec![(0.0, 1.0), (1.0, 3.0)],
            scatter_px2: 0.0,
        };
        assert_eq!(s.at(15.0), (0.5, 2.0));
        assert_eq!(s.at(0.0), (0.0, 1.0));
        assert_eq!(s.at(99.0), (1.0, 3.0));
        assert_eq!(ShapeTerm::none().at(5.0), (0.0, 0.0));
    }
}
