//! ACE power spectral density, per axis (arbitrary units; the series is scaled to a σ afterwards):
//!
//! `PSD(f) = A·(1/f_b) / (1 + (f/f_b)^α) + Σᵢ (pᵢ/hᵢ) / (1 + ((f − fᵢ)/hᵢ)²)`
//!
//! flat (white) below the boundary frequency f_b, ∝ f^−α above (α = 2 in the paper), plus Lorentzian
//! natural modes at fᵢ with half-widths hᵢ and amplitudes pᵢ (SPEC §3 reference values).

use crate::config::{Ace, Mode};

#[derive(Debug, Clone, PartialEq)]
pub struct Psd {
    pub continuum_amplitude: f64,
    pub boundary_freq_hz: f64,
    pub power_law_index: f64,
    pub modes: Vec<Mode>,
}

impl Psd {
    pub fn from_config(a: &Ace) -> Self {
        Self {
            continuum_amplitude: a.continuum_amplitude,
            boundary_freq_hz: a.boundary_freq_hz,
            power_law_index: a.power_law_index,
            modes: a.modes.clone(),
        }
    }

    /// The continuum term alone.
    pub fn continuum(&self, f: f64) -> f64 {
        let fb = self.boundary_freq_hz;
        self.continuum_amplitude / fb / (1.0 + (f.abs() / fb).powf(self.power_law_index))
    }

    /// The sum of the mode terms alone.
    pub fn modes_only(&self, f: f64) -> f64 {
        self.modes
            .iter()
            .map(|m| {
                (m.amplitude / m.width_hz) / (1.0 + ((f.abs() - m.freq_hz) / m.width_hz).powi(2))
            })
            .sum()
    }

    /// PSD at frequency f (Hz).
    pub fn eval(&self, f: f64) -> f64 {
        self.continuum(f) + self.modes_only(f)
    }

    /// ∫ PSD over [f0, f1] by the trapezoid rule on a log-spaced grid fine enough for the mode widths.
    pub fn integral(&self, f0: f64, f1: f64, part: impl Fn(&Self, f64) -> f64) -> f64 {
        let n = 200_000;
        let (a, b) = (f0.max(1e-6), f1);
        let (la, lb) = (a.ln(), b.ln());
        let mut s = 0.0;
        let mut prev_f = a;
        let mut prev_v = part(self, a);
        for k in 1..=n {
            let f = (la + (lb - la) * k as f64 / n as f64).exp();
            let v = part(self, f);
            s += 0.5 * (v + prev_v) * (f - prev_f);
            prev_f = f;
            prev_v = v;
        }
        s + if f0 <= 1e-6 { part(self, 0.0) * a } else { 0.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn continuum_holds_about_97_percent() {
        let p = Psd::from_config(&Ace::default());
        // up to the Nyquist frequency of the reference sampling (0.15 ms)
        let fny = 0.5 / 0.15e-3;
        let c = p.integral(0.0, fny, |p, f| p.continuum(f));
        let m = p.integral(0.0, fny, |p, f| p.modes_only(f));
        let frac = c / (c + m);
        assert!((frac - 0.97).abs() < 0.01, "continuum fraction {frac}");
        // flat below f_b, f^-2 above
        assert!((p.continuum(0.001) / p.continuum(0.002) - 1.0).abs() < 1e-3);
        assert!((p.continuum(10.0) / p.continuum(20.0) - 4.0).abs() < 1e-3);
        // mode peaks
        assert!(p.eval(40.0) > 100.0 * p.eval(30.0));
    }
}
