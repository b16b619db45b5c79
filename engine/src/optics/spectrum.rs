//! Wavelength grid and the weights of the polychromatic PSF (SPEC §2).
//!
//! Weight of wavelength λᵢ = (stellar photon rate per unit λ at λᵢ) × (throughput × QE at λᵢ) × Δλ,
//! normalised to unit sum. The stellar spectrum is a power law `F_ν ∝ ν^β` whose slope reproduces the
//! star's 2MASS J−H colour (Vega zero points F₀(J) = 1594 Jy at 1.235 µm, F₀(H) = 1024 Jy at 1.662 µm;
//! Cohen et al. 2003), so the photon rate per unit wavelength is `n_λ ∝ F_ν/λ ∝ λ^(−β−1)`.
//! J−H = 0 gives β ≈ 1.5 (a hot star); the paper's J−H = 2.0 gives β ≈ −4.7 (a reddened bulge giant).

use crate::config::Band;

const LAMBDA_J_UM: f64 = 1.235;
const LAMBDA_H_UM: f64 = 1.662;
const F0_J_JY: f64 = 1594.0;
const F0_H_JY: f64 = 1024.0;

/// Power-law slope β of `F_ν ∝ ν^β` that reproduces the J−H colour.
pub fn beta_from_j_minus_h(j_minus_h: f64) -> f64 {
    // J−H = −2.5 log10[(ν_J/ν_H)^β · F0_H/F0_J]
    (-j_minus_h / 2.5 - (F0_H_JY / F0_J_JY).log10()) / (LAMBDA_H_UM / LAMBDA_J_UM).log10()
}

/// Relative photon rate per unit wavelength, `λ^(−β−1)`.
pub fn photon_rate(lambda_um: f64, j_minus_h: f64) -> f64 {
    lambda_um.powf(-beta_from_j_minus_h(j_minus_h) - 1.0)
}

/// `(λ_um, weight)` of the polychromatic PSF, weights summing to 1.
pub fn weights(band: &Band, j_minus_h: f64) -> Vec<(f64, f64)> {
    let grid = band.wavelength_grid();
    let raw: Vec<(f64, f64)> = grid
        .iter()
        .map(|&l| {
            (
                l,
                photon_rate(l, j_minus_h) * band.response(l) * band.wavelength_step_um,
            )
        })
        .collect();
    let total: f64 = raw.iter().map(|p| p.1).sum();
    raw.into_iter().map(|(l, w)| (l, w / total)).collect()
}

/// Photon-weighted mean wavelength of the band for a colour, µm.
pub fn effective_wavelength_um(band: &Band, j_minus_h: f64) -> f64 {
    weights(band, j_minus_h).iter().map(|(l, w)| l * w).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_is_1p00_to_1p60() {
        let g = Band::default().wavelength_grid();
        assert_eq!(g.len(), 61);
        assert!((g[0] - 1.0).abs() < 1e-9 && (g[60] - 1.6).abs() < 1e-9);
    }

    #[test]
    fn colour_slope_reproduces_colour() {
        for jh in [0.0, 1.0, 2.0] {
            let beta = beta_from_j_minus_h(jh);
            // synthetic colour of F_ν ∝ ν^β
            let ratio = (LAMBDA_H_UM / LAMBDA_J_UM).powf(beta);
            let colour = -2.5 * (ratio * F0_H_JY / F0_J_JY).log10();
            assert!((colour - jh).abs() < 1e-12);
        }
        // redder star → longer effective wavelength
        let b = Band::default();
        assert!(effective_wavelength_um(&b, 2.0) > effective_wavelength_um(&b, 0.0) + 0.05);
        let w = weights(&b, 2.0);
        assert!((w.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
