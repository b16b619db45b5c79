//! Persistence: the detector's memory of bright light (off by default; `[detector.persistence]`).
//!
//! The model of Tulloch et al. (2019), as JASMINE-imagesim's `pixsim/persistence.py` uses it: trap
//! populations k with time constants τ_k and densities ρ_k (defaults τ = 1, 10, 100, 10³, 10⁴ s and
//! ρ = (1, 1.5, 1.5, 2, 3) × 10⁻³). While a pixel's charge rises linearly to E over an exposure of length
//! T the traps relax toward ρ_k S(t), dq/dt = (ρ_k S − q)/τ_k, and hold at its end
//!
//! ```text
//! q_k = ρ_k E [1 + (e^{−T/τ_k} − 1)/(T/τ_k)]
//! ```
//!
//! After the reset they empty as q_k e^{−t/τ_k}; what they release while a later exposure integrates,
//! t ∈ [a, a + T] after the filling exposure's end, is collected in that pixel:
//!
//! ```text
//! R = Σ_k q_k (e^{−a/τ_k} − e^{−(a+T)/τ_k}).
//! ```
//!
//! The equation is linear in S and q, so an exposure's persistence is the sum of what each earlier exposure
//! left, and an exposure's share depends only on its own charge: sharded, resumed and straight runs of a
//! sequence agree. Choices, stated: the capture during an exposure does not take charge from its signal
//! (the traps fill from the undepleted part of the junction, Smith et al. 2008); only pixels whose star
//! charge reaches `threshold_e` fill traps (below it a pixel leaves ≈ 7 × 10⁻⁴ of it in the next exposure,
//! 0.14 e⁻ at the default); exposures more than `lookback_s` before the one being made leave
//! nothing (the 10³- and 10⁴-s traps hold 1 % and 0.04 % of a short exposure's charge: the benchmark
//! `persistence` reports what the cut costs).

use crate::config::{Config, Persistence};

/// The charge of one exposure's pixels that fill traps: (pixel index, e⁻), the pixels at or above the
/// threshold only, each capped at the full well.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChargeMap {
    pub pixels: Vec<(u32, f32)>,
}

impl ChargeMap {
    /// The pixels of `charge_e` (collected star charge, row-major) that reach `p.threshold_e`.
    pub fn bright(charge_e: &[f64], p: &Persistence, full_well_e: f64) -> Self {
        let pixels = charge_e
            .iter()
            .enumerate()
            .filter(|(_, e)| **e >= p.threshold_e)
            .map(|(i, e)| (i as u32, e.min(full_well_e) as f32))
            .collect();
        Self { pixels }
    }

    /// These pixels' charge × `factor`, added to `out` (row-major, the same detector).
    pub fn add_scaled(&self, factor: f64, out: &mut [f32]) {
        for (i, e) in &self.pixels {
            if let Some(v) = out.get_mut(*i as usize) {
                *v += (*e as f64 * factor) as f32;
            }
        }
    }
}

/// The fraction of its equilibrium ρE that a trap of time constant `tau_s` holds at the end of an
/// exposure of `exposure_s` whose charge rose linearly: `1 + (e^{−x} − 1)/x`, x = T/τ.
pub fn fill_fraction(exposure_s: f64, tau_s: f64) -> f64 {
    let x = exposure_s / tau_s;
    if x < 1e-6 {
        return x / 2.0; // the series 1 + (−x + x²/2 − …)/x
    }
    1.0 + (-x).exp_m1() / x
}

/// Electrons released per electron of charge E into a later exposure of length `exposure_s` that starts
/// integrating `gap_s` after the filling exposure ended: `Σ_k ρ_k f_k (e^{−a/τ_k} − e^{−(a+T)/τ_k})`.
pub fn released_per_e(p: &Persistence, exposure_s: f64, gap_s: f64) -> f64 {
    p.tau_s
        .iter()
        .zip(&p.rho)
        .map(|(tau, rho)| {
            rho * fill_fraction(exposure_s, *tau)
                * ((-gap_s / tau).exp() - (-(gap_s + exposure_s) / tau).exp())
        })
        .sum()
}

/// The persistence of an exposure on one `n × n` detector, e⁻ per pixel: what each earlier exposure
/// (its bright pixels and the gap from its end to this one's start, s) releases into it; those more than
/// `lookback_s` before are skipped.
pub fn released_e(cfg: &Config, n: usize, earlier: &[(f64, &ChargeMap)]) -> Vec<f32> {
    let p = &cfg.detector.persistence;
    let t = cfg.detector.exposure_s;
    let mut out = vec![0.0f32; n * n];
    for (gap_s, map) in earlier {
        if *gap_s >= 0.0 && *gap_s <= p.lookback_s {
            map.add_scaled(released_per_e(p, t, *gap_s), &mut out);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// dq/dt = (ρ S(t) − q)/τ with S = E t/T, integrated by fourth-order Runge–Kutta: the fill, then the
    /// release over [a, a + T] as q(a) − q(a + T) — an independent check of the closed forms.
    fn numeric_release(rho: f64, tau: f64, e: f64, t: f64, a: f64) -> f64 {
        let steps = 20_000;
        let h = t / steps as f64;
        let f = |time: f64, q: f64| (rho * e * time / t - q) / tau;
        let mut q = 0.0;
        for i in 0..steps {
            let s = i as f64 * h;
            let k1 = f(s, q);
            let k2 = f(s + h / 2.0, q + h / 2.0 * k1);
            let k3 = f(s + h / 2.0, q + h / 2.0 * k2);
            let k4 = f(s + h, q + h * k3);
            q += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
        }
        // after the reset S = 0: q decays, dq/dt = −q/τ, integrated the same way over [0, a + T]
        let decay = |q0: f64, span: f64| {
            let n = 20_000;
            let h = span / n as f64;
            let mut q = q0;
            for _ in 0..n {
                let k1 = -q / tau;
                let k2 = -(q + h / 2.0 * k1) / tau;
                let k3 = -(q + h / 2.0 * k2) / tau;
                let k4 = -(q + h * k3) / tau;
                q += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            }
            q
        };
        decay(q, a) - decay(q, a + t)
    }

    #[test]
    fn closed_forms_match_the_integrated_trap_equation() {
        let d = Persistence::default();
        let (e, t) = (1.2e5, 12.5);
        for a in [0.3, 5.0, 40.0, 400.0] {
            let numeric: f64 = d
                .tau_s
                .iter()
                .zip(&d.rho)
                .map(|(tau, rho)| numeric_release(*rho, *tau, e, t, a))
                .sum();
            let closed = e * released_per_e(&d, t, a);
            assert!(
                (closed - numeric).abs() < 1e-6 * numeric.abs() + 1e-9,
                "gap {a} s: {closed} vs {numeric}"
            );
        }
        // a very long trap: x/2 of its equilibrium, the series and the closed form agree at the switch
        assert!((fill_fraction(1e-7, 1.0) - 5e-8).abs() < 1e-15);
        assert!((fill_fraction(2e-6, 1.0) - 1e-6).abs() < 1e-12);
    }

    #[test]
    fn only_bright_pixels_fill_capped_at_the_full_well_and_old_exposures_are_forgotten() {
        let mut cfg = Config::default();
        cfg.detector.persistence.threshold_e = 1000.0;
        cfg.detector.persistence.lookback_s = 100.0;
        let charge = [10.0, 999.0, 1000.0, 5e5];
        let map = ChargeMap::bright(&charge, &cfg.detector.persistence, 1.5e5);
        assert_eq!(map.pixels, vec![(2, 1000.0), (3, 1.5e5)]);
        let out = released_e(&cfg, 2, &[(1.0, &map), (150.0, &map)]);
        let f = released_per_e(&cfg.detector.persistence, 12.5, 1.0);
        assert_eq!(out[0], 0.0);
        assert!((out[3] as f64 - 1.5e5 * f).abs() < 1e-3, "{}", out[3]);
    }
}
