//! What the analysis of an image reports about itself — no truth enters: each star's fit ([`StarResult`]) and
//! how the analysis went ([`Report`]: detections, rejections, the ePSF and how it was made, the countermeasure
//! and the parameters it absorbed). What the fits are worth against a truth is the scoring's
//! (`scoring::image`, the next layer).

use crate::analysis::epsf::fit::{StarFit, flags};
use serde::Serialize;

/// One star's measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StarResult {
    pub x: f64,
    pub y: f64,
    pub flux_e: f64,
    pub sky_e: f64,
    /// Cramér–Rao bound of the position per axis ([`crate::analysis::epsf::fit`]), px.
    pub crlb_x_px: f64,
    pub crlb_y_px: f64,
    /// [`flags`] of the fit.
    pub flags: u32,
}

impl StarResult {
    /// The measurement of a fit.
    pub fn of(f: &StarFit) -> Self {
        Self {
            x: f.x,
            y: f.y,
            flux_e: f.flux,
            sky_e: f.sky,
            crlb_x_px: f.crlb_x,
            crlb_y_px: f.crlb_y,
            flags: f.flags,
        }
    }

    /// Whether the position is usable: no rejection flag, finite.
    pub fn is_usable(&self) -> bool {
        self.flags & flags::REJECT == 0 && self.x.is_finite() && self.y.is_finite()
    }
}

/// Turn fits into star results.
pub fn star_results(fits: &[StarFit]) -> Vec<StarResult> {
    fits.iter().map(StarResult::of).collect()
}

/// How the analysis of an image went.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Report {
    pub n_detected: usize,
    /// Fits flagged for rejection (saturated, poorly fitted, blended, off the image).
    pub n_rejected: usize,
    pub epsf_iterations: usize,
    /// Isolated, unsaturated stars the ePSF could be built from.
    pub epsf_stars: usize,
    /// Empty when the ePSF was built from the image; else what stood in for it and why (too few stars).
    pub epsf_fallback: String,
    /// How the ePSF varies across the image (`analysis.epsf_variation`): `constant`, `linear`, `quadratic`, or
    /// why a varying ePSF asked for was kept constant.
    pub epsf_variation: String,
    pub countermeasure: String,
    /// Whether the crowded-field analysis measured the image ([`crate::analysis::crowding`]).
    pub crowded: bool,
    /// Parameters a countermeasure fitted per exposure (degrees of freedom absorbed).
    pub dof_absorbed: usize,
    /// Exposures of the stare whose stack referenced a plate model: 1 when the image stood alone (a stare
    /// of one, its own stack: nothing corrected), K for a stare of K; absent (`null`) when no plate model
    /// referenced to the stack was asked for.
    pub stare_exposures: Option<usize>,
    /// The static profile a telemetry countermeasure saw each star through, when it was not the design
    /// model PSF or the image's ePSF as configured: the design PSF corrected by the stars (its fitted terms and
    /// their errors, nm rms). Left out of the JSON when empty.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub static_profile: String,
    /// How evenly the usable stars' positions fall within their pixels: a check without a truth.
    pub pixel_phase: PixelPhase,
}

impl Report {
    /// Count the rejected fits of `stars`, and their pixel phases.
    pub fn count(&mut self, stars: &[StarResult]) {
        self.n_rejected = stars.iter().filter(|s| !s.is_usable()).count();
        self.pixel_phase = PixelPhase::of(stars);
    }
}

/// The pixel phases (fractional positions, −0.5 … 0.5 from the pixel centre) of the usable stars, and the
/// Rayleigh test of their uniformity per axis. A field's stars fall anywhere in their pixels; a biased ePSF
/// pulls the fitted positions towards the pixel centres (or edges), Anderson & King (2000)'s pixel-phase
/// error, which piles them up there. With θ = 2π·phase, R̄ = |Σ e^{iθ}|/N and the Rayleigh statistic
/// z = N·R̄²; for uniform phases P(Z ≥ z) = exp(−z)·(1 + (2z − z²)/(4N) − (24z − 132z² + 76z³ − 9z⁴)/(288N²))
/// (Mardia & Jupp 2000, eq. 6.3.6). The mean direction says where they pile: 0 at the centres, ±0.5 at the edges.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct PixelPhase {
    /// Stars counted.
    pub n: usize,
    /// Stars per tenth of a pixel, from −0.5 to 0.5, in x and in y.
    pub histogram_x: [usize; 10],
    pub histogram_y: [usize; 10],
    /// The Rayleigh statistic z per axis, and the probability of a z as large from uniform phases.
    pub rayleigh_z_x: f64,
    pub rayleigh_z_y: f64,
    pub p_uniform_x: f64,
    pub p_uniform_y: f64,
    /// The phase the stars lean towards per axis, px (0: the pixel centres).
    pub mean_phase_x: f64,
    pub mean_phase_y: f64,
}

impl PixelPhase {
    /// The pixel phases of the usable stars of `stars`.
    pub fn of(stars: &[StarResult]) -> Self {
        let usable: Vec<&StarResult> = stars.iter().filter(|s| s.is_usable()).collect();
        let (hx, zx, px, mx) = Self::axis(usable.iter().map(|s| s.x));
        let (hy, zy, py, my) = Self::axis(usable.iter().map(|s| s.y));
        Self {
            n: usable.len(),
            histogram_x: hx,
            histogram_y: hy,
            rayleigh_z_x: zx,
            rayleigh_z_y: zy,
            p_uniform_x: px,
            p_uniform_y: py,
            mean_phase_x: mx,
            mean_phase_y: my,
        }
    }

    /// Histogram, z, P and mean phase of one axis's positions.
    fn axis(positions: impl Iterator<Item = f64>) -> ([usize; 10], f64, f64, f64) {
        let mut hist = [0usize; 10];
        let (mut c, mut s, mut n) = (0.0, 0.0, 0usize);
        for v in positions {
            let phase = v - v.round();
            hist[(((phase + 0.5) * 10.0).floor() as usize).min(9)] += 1;
            let t = std::f64::consts::TAU * phase;
            c += t.cos();
            s += t.sin();
            n += 1;
        }
        if n == 0 {
            return (hist, f64::NAN, f64::NAN, f64::NAN);
        }
        let nf = n as f64;
        let z = (c * c + s * s) / nf;
        let p = (-z).exp()
            * (1.0 + (2.0 * z - z * z) / (4.0 * nf)
                - (24.0 * z - 132.0 * z * z + 76.0 * z.powi(3) - 9.0 * z.powi(4))
                    / (288.0 * nf * nf));
        (
            hist,
            z,
            p.clamp(0.0, 1.0),
            s.atan2(c) / std::f64::consts::TAU,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit::star_result as star;

    /// Uniform phases pass the test (its P is itself uniform: below 0.01 one time in a hundred, so a fixed
    /// seed is checked against 0.01); phases pulled towards the pixel centres by a tenth of their distance
    /// fail it at P < 1e-6 with 2000 stars, and the mean phase says where they pile.
    #[test]
    fn uniform_phases_pass_and_phases_piled_at_the_centres_fail() {
        use rand::RngExt;
        let mut r = crate::rng::stream(5, crate::rng::Stream::Test, 1);
        let uniform: Vec<StarResult> = (0..2000)
            .map(|i| star(i as f64 * 3.0 + r.random::<f64>(), 7.0 + r.random::<f64>()))
            .collect();
        let u = PixelPhase::of(&uniform);
        assert_eq!(u.n, 2000);
        assert_eq!(u.histogram_x.iter().sum::<usize>(), 2000);
        assert!(u.p_uniform_x > 0.01 && u.p_uniform_y > 0.01, "{u:?}");
        // a biased fit: x' = x − 0.3·sin(2πφ)/(2π) pulls every phase towards 0 (≤ 0.05 px)
        let biased: Vec<StarResult> = uniform
            .iter()
            .map(|s| {
                let f = s.x - s.x.round();
                star(
                    s.x - 0.3 * (std::f64::consts::TAU * f).sin() / std::f64::consts::TAU,
                    s.y,
                )
            })
            .collect();
        let b = PixelPhase::of(&biased);
        assert!(b.p_uniform_x < 1e-6, "{b:?}");
        assert!(b.mean_phase_x.abs() < 0.05, "{b:?}");
        assert!(b.p_uniform_y > 0.01);
        // a rejected star is not counted
        let mut flagged = uniform.clone();
        flagged[0].flags = crate::analysis::epsf::fit::flags::NOT_CONVERGED;
        assert_eq!(PixelPhase::of(&flagged).n, 1999);
    }
}
