//! The mock Galactic-bulge field (`scene.kind = "bulge"`): stars uniform on the sky over the focal plane,
//! Hw from a power-law luminosity function, J − H from a clipped normal reddening distribution, all from
//! the bulge stream of the run seed; distances and proper motions from a stream of their own.
//! Parameters and their sources: [`crate::config::Bulge`].

use super::{MAX_CATALOGUE_STARS, SceneError, SkyStar};
use crate::config::{Bulge, Config, Layout};
use crate::rng::{self, Stream};
use crate::sky::apparent::Motion;
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};

/// The square region of focal-plane pixels (half side, from the optical axis) the field covers: the
/// arrays' full formats and gaps plus the reach of a star's light ([`super::placement::margin_px`]), so
/// that stars just off an array still light its edge.
pub fn half_side_px(cfg: &Config) -> f64 {
    let n = cfg.instrument.detector_px as f64;
    let margin = super::placement::margin_px(cfg);
    match cfg.focal_plane.layout {
        Layout::Single => n / 2.0 + margin,
        Layout::Quad => n + cfg.focal_plane.gap_px / 2.0 + margin,
    }
}

/// How many stars the field over the focal plane holds ([`count_over`] before rounding).
pub fn star_count(cfg: &Config) -> f64 {
    count_over(cfg, half_side_px(cfg))
}

/// The stars of a square of ±`h` focal-plane pixels: the stars drawn per arcmin²
/// ([`crate::config::Bulge::drawn_per_arcmin2`]) × its area.
fn count_over(cfg: &Config, h: f64) -> f64 {
    let side_arcmin = 2.0 * h * cfg.instrument.plate_scale_mas() / 6.0e4;
    cfg.scene.bulge.drawn_per_arcmin2() * side_arcmin * side_arcmin
}

/// Hw drawn from dN/dHw ∝ 10^(α·Hw) on [lo, hi] by inverting its cumulative distribution (uniform for α = 0).
pub fn luminosity_function_draw(u: f64, lo: f64, hi: f64, alpha: f64) -> f64 {
    if alpha.abs() < 1e-12 {
        return lo + u * (hi - lo);
    }
    let (a, b) = (10f64.powf(alpha * lo), 10f64.powf(alpha * hi));
    (a + u * (b - a)).log10() / alpha
}

/// The unit vectors of increasing Galactic longitude and latitude at (α, δ), as (α*, δ) components: the
/// turn between Galactic and equatorial proper motions (SOFA `icrs2g`/`g2icrs`, by a 10⁻⁶-rad step).
pub fn galactic_axes(ra_deg: f64, dec_deg: f64) -> ([f64; 2], [f64; 2]) {
    use sofars::coords::{g2icrs, icrs2g};
    let (ra, dec) = (ra_deg.to_radians(), dec_deg.to_radians());
    let (l, b) = icrs2g(ra, dec);
    let step = 1e-6;
    let axis = |dl: f64, db: f64| {
        let (a, d) = g2icrs(l + dl, b + db);
        let da = (a - ra + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        let v = [da * dec.cos(), d - dec];
        let n = v[0].hypot(v[1]);
        [v[0] / n, v[1] / n]
    };
    (axis(step / b.cos(), 0.0), axis(0.0, step))
}

/// One star's distance and proper motion, drawn from `r`.
fn draw_motion(b: &Bulge, ra_deg: f64, dec_deg: f64, r: &mut impl rand::Rng) -> Motion {
    let z: [f64; 3] = std::array::from_fn(|_| StandardNormal.sample(&mut *r));
    let d_kpc = (b.distance_kpc + b.distance_sigma_kpc * z[0]).clamp(5.0, 12.0);
    let mu_l = b.pm_l_mean_mas_per_yr + b.pm_l_sigma_mas_per_yr * z[1];
    let mu_b = b.pm_b_mean_mas_per_yr + b.pm_b_sigma_mas_per_yr * z[2];
    let (el, eb) = galactic_axes(ra_deg, dec_deg);
    Motion {
        pmra_mas_per_yr: mu_l * el[0] + mu_b * eb[0],
        pmdec_mas_per_yr: mu_l * el[1] + mu_b * eb[1],
        parallax_mas: 1.0 / d_kpc,
    }
}

/// Draw the field's stars (ids in drawing order) over the focal plane ([`half_side_px`]).
pub fn draw(cfg: &Config) -> Result<Vec<SkyStar>, SceneError> {
    draw_square(cfg, half_side_px(cfg))
}

/// Draw the field's stars over a square of ±`h` focal-plane pixels around the configured pointing (its
/// sides along the focal plane's axes at `sky.pa_deg`): a sequence's whole region.
pub fn draw_square(cfg: &Config, h: f64) -> Result<Vec<SkyStar>, SceneError> {
    let b = &cfg.scene.bulge;
    if !(h.is_finite() && h > 0.0) {
        return Err(SceneError::Invalid(format!(
            "the bulge field's half side {h} px: must be > 0"
        )));
    }
    let count = count_over(cfg, h).round();
    if count > MAX_CATALOGUE_STARS as f64 {
        return Err(SceneError::Invalid(format!(
            "scene.bulge.density_per_arcmin2 = {} gives {count:.0} stars over the focal plane: at most {} \
             are allowed",
            b.density_per_arcmin2, MAX_CATALOGUE_STARS
        )));
    }
    let n = count as usize;
    let projection = crate::sky::focal_plane_projection(cfg).map_err(SceneError::Invalid)?;
    let mut r = rng::stream(cfg.seed, Stream::Bulge, 0);
    let mut kinematics = rng::stream(cfg.seed, Stream::BulgeMotion, 0);
    let mut stars = Vec::with_capacity(n);
    for id in 0..n {
        let (fx, fy) = (
            (r.random::<f64>() * 2.0 - 1.0) * h,
            (r.random::<f64>() * 2.0 - 1.0) * h,
        );
        let hw = luminosity_function_draw(r.random::<f64>(), b.hw_min, b.hw_max, b.lf_slope);
        // the clipped normal by rejection (a bounded number of tries, then the clip)
        let mut jh = b.jh_mean;
        for _ in 0..64 {
            let z: f64 = StandardNormal.sample(&mut r);
            jh = b.jh_mean + b.jh_sigma * z;
            if (b.jh_min..=b.jh_max).contains(&jh) {
                break;
            }
        }
        let jh = jh.clamp(b.jh_min, b.jh_max);
        let (ra, dec) = projection
            .pixel_to_sky(fx, fy)
            .ok_or_else(|| SceneError::Invalid("the bulge field has no sky position".into()))?;
        stars.push(SkyStar {
            id,
            ra_deg: ra,
            dec_deg: dec,
            mag_hw: hw,
            j_minus_h: jh,
            motion: draw_motion(b, ra, dec, &mut kinematics),
        });
    }
    Ok(stars)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::stats;

    fn bulge_cfg() -> Config {
        let mut c = Config::default();
        c.scene.kind = crate::config::SceneKind::Bulge;
        c.focal_plane.layout = Layout::Quad;
        c
    }

    #[test]
    fn magnitudes_follow_the_luminosity_function() {
        // the fraction of stars brighter than m is (10^(α m) − 10^(α lo)) / (10^(α hi) − 10^(α lo))
        let mut c = bulge_cfg();
        c.scene.bulge.density_per_arcmin2 = 20.0; // ≈ 2.2e4 stars
        let s = draw(&c).expect("draw");
        let n = s.len() as f64;
        assert!((n - star_count(&c)).abs() <= 0.5, "{n}");
        let (lo, hi, a) = (8.0, 17.0, 0.30);
        for m in [11.0, 14.0, 16.0] {
            let expect = (10f64.powf(a * m) - 10f64.powf(a * lo))
                / (10f64.powf(a * hi) - 10f64.powf(a * lo));
            let got = s.iter().filter(|t| t.mag_hw < m).count() as f64 / n;
            let sigma = (expect * (1.0 - expect) / n).sqrt();
            assert!(
                (got - expect).abs() < 4.0 * sigma,
                "m {m}: {got} vs {expect} (σ {sigma})"
            );
        }
        // colours: inside the clip, mean and σ of the clipped normal (mean 2.2, σ 0.35 on [1.5, 3.0]:
        // the truncation at −2 σ and +2.29 σ moves the mean to 2.2 + 0.35·(φ(−2) − φ(2.29))/Z = 2.209)
        let jh: Vec<f64> = s.iter().map(|t| t.j_minus_h).collect();
        assert!(jh.iter().all(|v| (1.5..=3.0).contains(v)));
        let m = stats::mean(&jh);
        assert!((m - 2.209).abs() < 4.0 * 0.33 / n.sqrt() + 1e-3, "{m}");
        assert_eq!(draw(&c).expect("again"), s, "same seed, same field");
    }

    /// `hw_max` cuts the faint stars off the same field: the field drawn to Hw 15 holds as many stars as
    /// the default field (to Hw 17) has brighter than 15 (a binomial count of its draws, 4σ), none fainter;
    /// counted to its own limit (`density_hw_limit = hw_max`) the density is the count drawn.
    #[test]
    fn hw_max_cuts_the_same_field() {
        let mut c = bulge_cfg();
        c.scene.bulge.density_per_arcmin2 = 20.0;
        let full = draw(&c).expect("draw");
        let side_arcmin = 2.0 * half_side_px(&c) * c.instrument.plate_scale_mas() / 6.0e4;
        let area = side_arcmin * side_arcmin;
        assert_eq!(
            full.len() as f64,
            (20.0 * area).round(),
            "the default counts to its hw_max"
        );
        let bright = full.iter().filter(|t| t.mag_hw <= 15.0).count() as f64;
        c.scene.bulge.hw_max = 15.0;
        let cut = draw(&c).expect("draw");
        let n = full.len() as f64;
        let p = bright / n;
        let sigma = (n * p * (1.0 - p)).sqrt();
        assert!(
            (cut.len() as f64 - bright).abs() < 4.0 * sigma,
            "{} stars to Hw 15 against {bright} of the full field's (σ {sigma:.0})",
            cut.len()
        );
        assert!(cut.len() < full.len() / 3, "{}", cut.len());
        assert!(cut.iter().all(|t| t.mag_hw <= 15.0));
        c.scene.bulge.density_hw_limit = 15.0;
        assert_eq!(draw(&c).expect("draw").len() as f64, (20.0 * area).round());
    }

    #[test]
    fn the_field_is_uniform_over_the_focal_plane() {
        let mut c = bulge_cfg();
        c.scene.bulge.density_per_arcmin2 = 10.0;
        let s = draw(&c).expect("draw");
        let p = crate::sky::focal_plane_projection(&c).expect("projection");
        let h = half_side_px(&c);
        // quadrant counts agree within 4σ of a binomial(n, 1/4)
        let mut q = [0usize; 4];
        for t in &s {
            let (x, y) = p.sky_to_pixel(t.ra_deg, t.dec_deg).expect("on the plane");
            assert!(x.abs() <= h + 1e-6 && y.abs() <= h + 1e-6);
            q[(x > 0.0) as usize + 2 * (y > 0.0) as usize] += 1;
        }
        let n = s.len() as f64;
        for k in q {
            assert!(
                (k as f64 - n / 4.0).abs() < 4.0 * (n * 0.1875).sqrt(),
                "{q:?}"
            );
        }
    }

    #[test]
    fn the_cumulative_inverse_is_exact() {
        assert_eq!(luminosity_function_draw(0.0, 8.0, 17.0, 0.3), 8.0);
        assert!((luminosity_function_draw(1.0, 8.0, 17.0, 0.3) - 17.0).abs() < 1e-12);
        assert!((luminosity_function_draw(0.5, 8.0, 17.0, 0.0) - 12.5).abs() < 1e-12);
    }

    #[test]
    fn galactic_north_at_the_galactic_centre_is_at_position_angle_minus_58_6() {
        // spherical trigonometry to the north Galactic pole (α 192.859°, δ 27.128°; ICRS, Hipparcos' frame):
        // PA = atan2(sin Δα cos δp, cos δ sin δp − sin δ cos δp cos Δα) = −58.6° at Sgr A*
        let (ra, dec): (f64, f64) = (266.4168, -29.0078);
        let (ap, dp) = (192.859_48_f64.to_radians(), 27.128_25_f64.to_radians());
        let da = ap - ra.to_radians();
        let d = dec.to_radians();
        let pa = (da.sin() * dp.cos()).atan2(d.cos() * dp.sin() - d.sin() * dp.cos() * da.cos());
        let (el, eb) = galactic_axes(ra, dec);
        assert!(
            (eb[0] - pa.sin()).abs() < 1e-5 && (eb[1] - pa.cos()).abs() < 1e-5,
            "{eb:?}"
        );
        assert!((pa.to_degrees() + 58.6).abs() < 0.1, "{}", pa.to_degrees());
        // the axes are orthonormal and right-handed on the sky (l grows to the east of b's north)
        assert!((el[0] * eb[0] + el[1] * eb[1]).abs() < 1e-5);
        assert!((el[0].hypot(el[1]) - 1.0).abs() < 1e-12);
        assert!((el[0] * eb[1] - el[1] * eb[0] - 1.0).abs() < 1e-5);
    }

    #[test]
    fn motions_follow_the_kinematic_model_and_leave_the_field_unchanged() {
        let mut c = bulge_cfg();
        c.scene.bulge.density_per_arcmin2 = 20.0;
        let s = draw(&c).expect("draw");
        let n = s.len() as f64;
        let (mut mu_l, mut mu_b, mut plx) = (Vec::new(), Vec::new(), Vec::new());
        for t in &s {
            let (el, eb) = galactic_axes(t.ra_deg, t.dec_deg);
            let m = &t.motion;
            mu_l.push(m.pmra_mas_per_yr * el[0] + m.pmdec_mas_per_yr * el[1]);
            mu_b.push(m.pmra_mas_per_yr * eb[0] + m.pmdec_mas_per_yr * eb[1]);
            plx.push(m.parallax_mas);
        }
        let b = &c.scene.bulge;
        for (v, mean, sigma) in [
            (&mu_l, b.pm_l_mean_mas_per_yr, b.pm_l_sigma_mas_per_yr),
            (&mu_b, b.pm_b_mean_mas_per_yr, b.pm_b_sigma_mas_per_yr),
        ] {
            let (m, sd) = (stats::mean(v), stats::std_dev(v));
            assert!((m - mean).abs() < 4.0 * sigma / n.sqrt(), "{m} vs {mean}");
            // the sample σ of a normal: σ/√(2n) of its own
            assert!(
                (sd - sigma).abs() < 4.0 * sigma / (2.0 * n).sqrt(),
                "{sd} vs {sigma}"
            );
        }
        // parallax 1/d with d ~ N(8.2, 1.0) kpc clipped to [5, 12]: mean 1/8.2 · (1 + (1/8.2)² + …) = 0.1238
        assert!(plx.iter().all(|p| (1.0 / 12.0..=1.0 / 5.0).contains(p)));
        let m = stats::mean(&plx);
        assert!((m - 0.1238).abs() < 0.0015, "{m}");
        // the motions come from their own stream: positions and magnitudes are those of a field without them
        let mut still = c.clone();
        still.scene.bulge.pm_l_sigma_mas_per_yr = 0.0;
        let t = draw(&still).expect("draw");
        assert!(
            s.iter()
                .zip(&t)
                .all(|(a, b)| a.ra_deg == b.ra_deg && a.mag_hw == b.mag_hw)
        );
    }
}
