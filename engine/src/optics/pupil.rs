//! The entrance pupil: circular aperture, central obstruction and thin radial spider vanes (SPEC §1–2).
//!
//! Sampled on an N×N grid of square cells of side `D/N` whose centres are at `(k + ½ − N/2)·D/N`, each
//! holding the fraction of its area that is open (anti-aliased by `SUPERSAMPLE`² sub-samples in cells that
//! an edge crosses), so the open area converges quickly with N.

use crate::config::Instrument;

/// Sub-samples per cell axis for cells crossed by an edge.
pub const SUPERSAMPLE: usize = 8;

/// Pupil geometry in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PupilGeometry {
    pub radius_m: f64,
    pub obstruction_radius_m: f64,
    pub spider_count: u32,
    pub spider_half_width_m: f64,
    pub spider_angle_rad: f64,
}

impl PupilGeometry {
    pub fn from_instrument(i: &Instrument) -> Self {
        Self {
            radius_m: 0.5 * i.aperture_diameter_m,
            obstruction_radius_m: 0.5 * i.obstruction_diameter_m,
            spider_count: i.spider_count,
            spider_half_width_m: 0.5 * i.spider_width_m,
            spider_angle_rad: i.spider_angle_deg.to_radians(),
        }
    }

    /// Without spiders (for the analytic Airy comparison).
    pub fn without_spiders(mut self) -> Self {
        self.spider_count = 0;
        self
    }

    /// Is the point (x, y) (metres) open?
    pub fn is_open(&self, x: f64, y: f64) -> bool {
        let r2 = x * x + y * y;
        if r2 > self.radius_m * self.radius_m
            || r2 < self.obstruction_radius_m * self.obstruction_radius_m
        {
            return false;
        }
        !self.on_spider(x, y)
    }

    fn on_spider(&self, x: f64, y: f64) -> bool {
        (0..self.spider_count).any(|k| {
            let phi =
                self.spider_angle_rad + std::f64::consts::TAU * k as f64 / self.spider_count as f64;
            let (s, c) = phi.sin_cos();
            let along = x * c + y * s;
            let across = -x * s + y * c;
            along >= 0.0 && across.abs() < self.spider_half_width_m
        })
    }

    /// Smallest distance from (x, y) to any edge of the mask (for deciding whether a cell is pure).
    fn edge_distance(&self, x: f64, y: f64) -> f64 {
        let r = (x * x + y * y).sqrt();
        let mut d = (r - self.radius_m)
            .abs()
            .min((r - self.obstruction_radius_m).abs());
        for k in 0..self.spider_count {
            let phi =
                self.spider_angle_rad + std::f64::consts::TAU * k as f64 / self.spider_count as f64;
            let (s, c) = phi.sin_cos();
            let along = x * c + y * s;
            let across = -x * s + y * c;
            let dv = if along >= 0.0 {
                (across.abs() - self.spider_half_width_m).abs()
            } else {
                // behind the vane's root: distance to its end cap corners
                (along * along + (across.abs() - self.spider_half_width_m).max(0.0).powi(2)).sqrt()
            };
            d = d.min(dv);
        }
        d
    }

    /// Analytic open area (annulus minus the vanes between obstruction and rim), m².
    pub fn open_area_m2(&self) -> f64 {
        let annulus =
            std::f64::consts::PI * (self.radius_m.powi(2) - self.obstruction_radius_m.powi(2));
        annulus
            - self.spider_count as f64
                * 2.0
                * self.spider_half_width_m
                * (self.radius_m - self.obstruction_radius_m)
    }
}

/// An N×N pupil transmission map (open fraction of each cell).
#[derive(Debug, Clone)]
pub struct Pupil {
    pub n: usize,
    /// Cell side, metres.
    pub spacing_m: f64,
    /// Row-major `[iy * n + ix]`.
    pub transmission: Vec<f64>,
}

impl Pupil {
    /// Sample `geom` on an `n`×`n` grid spanning the aperture diameter.
    pub fn sample(geom: &PupilGeometry, n: usize) -> Self {
        let spacing = 2.0 * geom.radius_m / n as f64;
        Self::sample_with_spacing(geom, n, spacing, SUPERSAMPLE)
    }

    /// Sample on an `n`×`n` grid of cells of side `spacing_m` centred on the optical axis, with
    /// `supersample`² sub-samples in edge cells (1 = a binary, point-sampled pupil).
    pub fn sample_with_spacing(
        geom: &PupilGeometry,
        n: usize,
        spacing_m: f64,
        supersample: usize,
    ) -> Self {
        let half_diag = spacing_m * std::f64::consts::FRAC_1_SQRT_2;
        let mut t = vec![0.0; n * n];
        for iy in 0..n {
            let y = (iy as f64 + 0.5 - n as f64 / 2.0) * spacing_m;
            for ix in 0..n {
                let x = (ix as f64 + 0.5 - n as f64 / 2.0) * spacing_m;
                t[iy * n + ix] = if supersample <= 1 || geom.edge_distance(x, y) > half_diag {
                    if geom.is_open(x, y) { 1.0 } else { 0.0 }
                } else {
                    let ss = supersample;
                    let mut open = 0usize;
                    for sy in 0..ss {
                        let yy = y + ((sy as f64 + 0.5) / ss as f64 - 0.5) * spacing_m;
                        for sx in 0..ss {
                            let xx = x + ((sx as f64 + 0.5) / ss as f64 - 0.5) * spacing_m;
                            if geom.is_open(xx, yy) {
                                open += 1;
                            }
                        }
                    }
                    open as f64 / (ss * ss) as f64
                };
            }
        }
        Self {
            n,
            spacing_m,
            transmission: t,
        }
    }

    /// Cell-centre coordinate (metres) of index `k`.
    pub fn coord_m(&self, k: usize) -> f64 {
        (k as f64 + 0.5 - self.n as f64 / 2.0) * self.spacing_m
    }

    /// Open area, m² (Σ transmission · cell area).
    pub fn area_m2(&self) -> f64 {
        self.transmission.iter().sum::<f64>() * self.spacing_m * self.spacing_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_area_matches_spec() {
        let g = PupilGeometry::from_instrument(&Instrument::default());
        assert!(
            (g.open_area_m2() - 0.0876).abs() < 1e-4,
            "analytic {}",
            g.open_area_m2()
        );
        let p = Pupil::sample(&g, 256);
        let rel = (p.area_m2() - g.open_area_m2()).abs() / g.open_area_m2();
        assert!(rel < 2e-4, "sampled area off by {rel}");
    }

    #[test]
    fn spiders_are_where_they_should_be() {
        let g = PupilGeometry::from_instrument(&Instrument::default());
        // On the +x vane, on the 120° vane, and between vanes (60°)
        assert!(!g.is_open(0.12, 0.0));
        let (s, c) = (120f64).to_radians().sin_cos();
        assert!(!g.is_open(0.12 * c, 0.12 * s));
        let (s, c) = (60f64).to_radians().sin_cos();
        assert!(g.is_open(0.12 * c, 0.12 * s));
        // the −x axis has no vane (Y shape, not a cross)
        assert!(g.is_open(-0.12, 0.0));
        assert!(!g.is_open(0.0, 0.0));
        assert!(!g.is_open(0.19, 0.0));
    }
}
