//! Photometry: Hw magnitude → photo-electrons per second through a documented zero point (SPEC §5).
//!
//! `rate = ZP · 10^(−0.4·Hw)` with `ZP = photometry.zero_point_e_per_s` (default 5.8e8 e⁻/s at Hw = 0: the
//! original simulator's throughput × QE and a 9500 K spectrum through the 0.0876 m² open pupil, giving
//! ≈ 5.8e3 e⁻/s and ≈ 7.3e4 e⁻ per 12.5-s exposure at Hw = 12.5). The J−H colour enters only the shape
//! of the polychromatic PSF (`optics::spectrum`); Hw is already a band magnitude.

/// Photo-electrons per second of a star of magnitude `hw`.
pub fn electrons_per_s(hw: f64, zero_point_e_per_s: f64) -> f64 {
    zero_point_e_per_s * 10f64.powf(-0.4 * hw)
}

/// Hw − H from the 2MASS J−H colour (SPEC §5): `1.08(J−H) − 0.15(J−H)² + 0.01(J−H)³`.
pub fn hw_minus_h(j_minus_h: f64) -> f64 {
    1.08 * j_minus_h - 0.15 * j_minus_h.powi(2) + 0.01 * j_minus_h.powi(3)
}

/// Hw from 2MASS J and H magnitudes.
pub fn hw_from_2mass(j: f64, h: f64) -> f64 {
    h + hw_minus_h(j - h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_mag_2p5_is_factor_10() {
        let a = electrons_per_s(12.5, 5.8e8);
        let b = electrons_per_s(10.0, 5.8e8);
        assert!((b / a - 10.0).abs() < 1e-12);
    }

    #[test]
    fn reference_rate_at_12p5() {
        let r = electrons_per_s(12.5, 5.8e8);
        assert!((r - 5800.0).abs() < 1e-6, "{r}");
        assert!((r * 12.5 - 72_500.0).abs() < 1e-3);
    }

    #[test]
    fn colour_transform() {
        assert!((hw_minus_h(2.0) - (2.16 - 0.6 + 0.08)).abs() < 1e-12);
        assert_eq!(hw_minus_h(0.0), 0.0);
        assert!((hw_from_2mass(14.0, 12.0) - 13.64).abs() < 1e-12);
    }
}
