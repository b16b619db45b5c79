//! The mission's error budget: a star's parallax and proper-motion precision at the end of the mission,
//! extrapolated from the errors a simulated sequence measures.
//!
//! Each exposure's measured position of a star errs by a part of its own (σ_e, independent between
//! exposures: photon and read noise, the jitter's share) and a part common to every exposure of one stare
//! (σ_s: the same pixels, the same neighbours, the same ePSF's shortcomings — what stops averaging down
//! within a stare, `jsim solve`'s precision against N). The mission's exposures of the star are grouped in
//! stares of m exposures each, spread evenly over the Galactic-centre seasons of its years. A stare lasts
//! minutes, so its exposures share one epoch: each stare is then one measurement of variance
//!
//! ```text
//!     σ²_stare = σ_e² / m + σ_s²
//! ```
//!
//! of the star's five parameters through its design row per axis: ξ = ξ₀ + μ_ξ t + ϖ P_ξ(t),
//! η = η₀ + μ_η t + ϖ P_η(t), with P the parallax factors at the stare's epoch (the Earth's barycentric place,
//! SOFA's `epv00`; the spacecraft's 600 km off the Earth are below 10⁻⁴ of an au and left out). The
//! covariance is the inverse of the 5 × 5 normal matrix Σ_stares AᵀA / σ²_stare.
//!
//! What it assumes, besides that model: the per-stare errors of different stares are independent (each
//! stare puts the star on other pixels, among other neighbours — the mission's pattern steps by a half
//! field and by the gap between visits); the calibration and the frame are known better than one star's
//! result (errors common to all stars do not enter a star's parallax relative to its neighbours); the
//! per-exposure errors are those of the simulated sequence (its ACE, countermeasure and detector).

use crate::numerics::linalg;
use crate::sky::apparent::parallax_factors;
use crate::time::Epoch;
use sofars::eph::epv00;

/// How the mission observes one star.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionPattern {
    /// Exposures of the star over the mission: ≈ 67 000 (the paper).
    pub exposures_per_star: usize,
    /// Exposures per stare (m): 26 (the toolkit's count at 6 fields per orbit).
    pub exposures_per_stare: usize,
    /// The mission's length, years: 3.
    pub years: f64,
    /// The first day of the mission (UTC, ISO 8601).
    pub start_utc: String,
    /// The Galactic-centre seasons are centred on the equinoxes (the Sun farthest from the solstices' transit
    /// targets and from the bulge): this half-width each, days. 45 d is a choice (the seasons then fill half
    /// the year; the mission's windows were not found).
    pub season_half_width_days: f64,
    /// The star: ICRS, degrees (default Sgr A*'s direction, the survey's centre).
    pub ra_deg: f64,
    pub dec_deg: f64,
}

impl Default for MissionPattern {
    fn default() -> Self {
        Self {
            exposures_per_star: 67_000,
            exposures_per_stare: 26,
            years: 3.0,
            start_utc: "2031-01-01T00:00:00".into(),
            season_half_width_days: 45.0,
            ra_deg: 266.416_837,
            dec_deg: -29.007_810,
        }
    }
}

impl MissionPattern {
    /// Every field in its allowed range, or the named field and that range.
    pub fn validate(&self) -> Result<(), String> {
        if self.exposures_per_star == 0 || self.exposures_per_star > 10_000_000 {
            return Err(format!(
                "mission exposures per star {}: allowed 1 … 10⁷",
                self.exposures_per_star
            ));
        }
        if self.exposures_per_stare == 0 || self.exposures_per_stare > self.exposures_per_star {
            return Err(format!(
                "mission exposures per stare {}: allowed 1 … the exposures per star ({})",
                self.exposures_per_stare, self.exposures_per_star
            ));
        }
        if !(self.years.is_finite() && (0.5..=20.0).contains(&self.years)) {
            return Err(format!(
                "mission years {}: allowed 0.5 … 20 (a parallax needs half a year at least)",
                self.years
            ));
        }
        if !(self.season_half_width_days.is_finite()
            && (1.0..=91.0).contains(&self.season_half_width_days))
        {
            return Err(format!(
                "season half-width {} days: allowed 1 … 91",
                self.season_half_width_days
            ));
        }
        if !(self.dec_deg.is_finite() && self.dec_deg.abs() <= 90.0 && self.ra_deg.is_finite()) {
            return Err(format!(
                "star ({}, {}) deg: RA finite, Dec within ±90",
                self.ra_deg, self.dec_deg
            ));
        }
        Epoch::from_utc_iso(&self.start_utc)
            .map(|_| ())
            .map_err(|e| format!("mission start {:?}: {e}", self.start_utc))
    }

    /// The stares' epochs: ⌈exposures / m⌉ stares spread evenly over the seasons' days (the seasons centred
    /// on each March 20 and September 22 within the mission), in Julian years TDB.
    pub fn stare_epochs(&self) -> Result<Vec<Epoch>, String> {
        self.validate()?;
        let start = Epoch::from_utc_iso(&self.start_utc)?;
        let first_year: i32 = self
            .start_utc
            .get(..4)
            .and_then(|y| y.parse().ok())
            .ok_or_else(|| format!("mission start {:?}: no year", self.start_utc))?;
        let mission_s = self.years * 365.25 * 86_400.0;
        let half_s = self.season_half_width_days * 86_400.0;
        // the seasons' [start, end) in seconds from the mission's start, clipped to the mission
        let mut seasons = Vec::new();
        for y in first_year - 1..=first_year + self.years.ceil() as i32 + 1 {
            for centre in [format!("{y}-03-20T12:00:00"), format!("{y}-09-22T12:00:00")] {
                let c = Epoch::from_utc_iso(&centre)?.seconds_since(&start);
                let (a, b) = ((c - half_s).max(0.0), (c + half_s).min(mission_s));
                if b > a {
                    seasons.push((a, b));
                }
            }
        }
        let total: f64 = seasons.iter().map(|(a, b)| b - a).sum();
        if total <= 0.0 {
            return Err("the mission holds no Galactic-centre season".into());
        }
        let stares = self.exposures_per_star.div_ceil(self.exposures_per_stare);
        let step = total / stares as f64;
        let mut epochs = Vec::with_capacity(stares);
        let (mut season, mut used) = (0usize, 0.0);
        for k in 0..stares {
            // the k-th stare at the middle of its share of the seasons' time
            let mut at = (k as f64 + 0.5) * step - used;
            while let Some(&(a, b)) = seasons.get(season) {
                if at < b - a {
                    epochs.push(start.plus_s(a + at));
                    break;
                }
                used += b - a;
                at -= b - a;
                season += 1;
            }
        }
        Ok(epochs)
    }
}

/// A star's errors per exposure (mas, per axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureErrors {
    /// Independent between exposures (σ_e).
    pub per_exposure_mas: f64,
    /// Common to the exposures of one stare (σ_s).
    pub per_stare_mas: f64,
}

/// The end-of-mission precision of one star (1σ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EndOfMission {
    pub position_mas: [f64; 2],
    pub pm_mas_per_yr: [f64; 2],
    pub parallax_mas: f64,
}

/// The star's five parameters' errors after the mission (see the module's model).
pub fn end_of_mission(
    pattern: &MissionPattern,
    errors: ExposureErrors,
) -> Result<EndOfMission, String> {
    let (e, s) = (errors.per_exposure_mas, errors.per_stare_mas);
    if !(e.is_finite() && s.is_finite() && e >= 0.0 && s >= 0.0 && e + s > 0.0) {
        return Err(format!(
            "per-exposure error {e} mas and per-stare error {s} mas: finite, ≥ 0, not both 0"
        ));
    }
    let epochs = pattern.stare_epochs()?;
    let m = pattern.exposures_per_stare as f64;
    let w = 1.0 / (e * e / m + s * s);
    // the epochs about their mean: the position is then the mean epoch's, uncorrelated with the motion
    let years: Vec<f64> = epochs.iter().map(Epoch::julian_year_tdb).collect();
    let mean = years.iter().sum::<f64>() / years.len().max(1) as f64;
    let mut normal = [0.0; 25];
    for (t, ep) in years.iter().zip(&epochs) {
        let (d1, d2) = ep.tdb_jd();
        let (_, [pb, _]) = epv00(d1, d2).unwrap_or(([[0.0; 3]; 2], [[0.0; 3]; 2]));
        let f = parallax_factors(pattern.ra_deg, pattern.dec_deg, pb);
        let dt = t - mean;
        // (ξ₀, η₀, μ_ξ, μ_η, ϖ)
        for row in [[1.0, 0.0, dt, 0.0, f[0]], [0.0, 1.0, 0.0, dt, f[1]]] {
            for i in 0..5 {
                for j in 0..5 {
                    normal[i * 5 + j] += w * row[i] * row[j];
                }
            }
        }
    }
    let cov = linalg::inverse(&normal, 5)
        .ok_or("the mission's stares cannot separate a parallax from a proper motion")?;
    let sd = |k: usize| cov[k * 5 + k].max(0.0).sqrt();
    Ok(EndOfMission {
        position_mas: [sd(0), sd(1)],
        pm_mas_per_yr: [sd(2), sd(3)],
        parallax_mas: sd(4),
    })
}

/// The per-exposure errors from a precision-against-N measurement within one stare: σ_e the
/// single-exposure accuracy, σ_s² = σ(N)² − σ_e²/n, σ(N) the combined error of n observations all from
/// one stare (0 where the combination is at or below √n scaling).
pub fn errors_from_one_stare(single_mas: f64, combined_mas: f64, n: f64) -> ExposureErrors {
    let left = combined_mas * combined_mas - single_mas * single_mas / n.max(1.0);
    ExposureErrors {
        per_exposure_mas: single_mas,
        per_stare_mas: left.max(0.0).sqrt(),
    }
}

/// One magnitude bin's budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BudgetRow {
    pub hw_lo: f64,
    pub hw_hi: f64,
    /// The sources the measurement rests on.
    pub sources: usize,
    /// What the sequence measured: σ_e (the single exposures' robust scatter, each exposure's common shift
    /// removed), and the combined error of one stare's exposures (robust, per axis).
    pub single_mas: f64,
    pub one_stare_mas: f64,
    pub errors: ExposureErrors,
    pub end: EndOfMission,
}

/// The budget of every magnitude bin (with at least 5 sources) measured at N = `measured_stare`, the
/// simulated sequence's exposures per stare: the precision-against-N row of its first full stare gives σ_e
/// and σ_s ([`errors_from_one_stare`]). Empty when no such row was measured.
pub fn budget_from_precision(
    pattern: &MissionPattern,
    table: &[super::solution::PrecisionRow],
    measured_stare: usize,
) -> Result<Vec<BudgetRow>, String> {
    let mut out = Vec::new();
    for r in table
        .iter()
        .filter(|r| r.exposures == measured_stare && r.bin.sources >= 5)
    {
        let b = &r.bin;
        let single = r.single.robust_mas;
        if !(single.is_finite() && b.position_robust_mas.is_finite()) {
            continue;
        }
        let errors = errors_from_one_stare(single, b.position_robust_mas, b.observations);
        out.push(BudgetRow {
            hw_lo: b.hw_lo,
            hw_hi: b.hw_hi,
            sources: b.sources,
            single_mas: single,
            one_stare_mas: b.position_robust_mas,
            errors,
            end: end_of_mission(pattern, errors)?,
        });
    }
    Ok(out)
}

/// The mission's requirements (the paper's full and extra success): parallax 40 / 25 µas (Hw ≤ 12.5),
/// proper motion 125 / 25 µas/yr.
pub const PARALLAX_FULL_MAS: f64 = 0.040;
pub const PARALLAX_EXTRA_MAS: f64 = 0.025;
pub const PM_FULL_MAS_PER_YR: f64 = 0.125;
pub const PM_EXTRA_MAS_PER_YR: f64 = 0.025;

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(n: usize, m: usize) -> MissionPattern {
        MissionPattern {
            exposures_per_star: n,
            exposures_per_stare: m,
            ..MissionPattern::default()
        }
    }

    #[test]
    fn the_stares_fill_the_seasons_evenly() {
        let p = pattern(26 * 600, 26);
        let e = p.stare_epochs().expect("epochs");
        assert_eq!(e.len(), 600);
        // every stare within 45 d of an equinox, about as many in spring as in autumn
        let mut spring = 0;
        for t in &e {
            let doy = (t.julian_year_tdb().fract() * 365.25) as i64;
            let near = |c: i64| (doy - c).abs() <= 46;
            assert!(near(79) || near(265), "day {doy}");
            spring += usize::from(near(79));
        }
        assert!((290..=310).contains(&spring), "{spring} of 600 in spring");
    }

    /// With no per-stare error and the parallax factors' time average removed, the proper motion's error is
    /// the textbook σ / √(Σ (t − t̄)²) per axis, and the position's σ / √N: an independent closed form.
    #[test]
    fn white_errors_average_as_the_least_squares_closed_form() {
        let p = pattern(26 * 240, 26);
        let sigma = 2.6;
        let r = end_of_mission(
            &p,
            ExposureErrors {
                per_exposure_mas: sigma,
                per_stare_mas: 0.0,
            },
        )
        .expect("budget");
        let years: Vec<f64> = p
            .stare_epochs()
            .expect("epochs")
            .iter()
            .map(Epoch::julian_year_tdb)
            .collect();
        let mean = years.iter().sum::<f64>() / years.len() as f64;
        let sxx: f64 = years.iter().map(|t| (t - mean).powi(2)).sum();
        // each stare is 26 exposures at one epoch
        let pm = sigma / (26.0 * sxx).sqrt();
        let pos = sigma / (26.0 * years.len() as f64).sqrt();
        // the parallax term correlates a little with the others: within 10 % of the closed forms, and never
        // better than them (a parameter more can only add to a variance)
        for k in 0..2 {
            assert!(r.pm_mas_per_yr[k] >= pm * 0.999 && r.pm_mas_per_yr[k] < pm * 1.1);
            assert!(r.position_mas[k] >= pos * 0.999 && r.position_mas[k] < pos * 1.1);
        }
        // at the equinoxes the Galactic centre's along-ecliptic parallax factor is ≈ ±1: σ_ϖ ≈ σ/√N
        let plx = sigma / (26.0 * years.len() as f64).sqrt();
        assert!(
            r.parallax_mas > plx * 0.9 && r.parallax_mas < plx * 1.3,
            "{} vs {plx}",
            r.parallax_mas
        );
    }

    /// A per-stare error averages over stares only: with σ_e = 0 the errors scale as 1/√stares, whatever m.
    #[test]
    fn a_per_stare_error_averages_over_stares_not_exposures() {
        let e = ExposureErrors {
            per_exposure_mas: 0.0,
            per_stare_mas: 0.5,
        };
        let a = end_of_mission(&pattern(2600, 26), e).expect("a");
        let b = end_of_mission(&pattern(2600 * 4, 26 * 4), e).expect("b");
        let c = end_of_mission(&pattern(2600 * 4, 26), e).expect("c");
        assert!((a.parallax_mas / b.parallax_mas - 1.0).abs() < 0.02);
        assert!((a.parallax_mas / c.parallax_mas - 2.0).abs() < 0.05);
    }

    #[test]
    fn errors_from_one_stare_take_out_the_averaging_part() {
        let e = errors_from_one_stare(2.0, 0.5, 25.0);
        assert!((e.per_stare_mas - 0.3).abs() < 1e-12);
        assert_eq!(errors_from_one_stare(2.0, 0.3, 25.0).per_stare_mas, 0.0);
    }

    #[test]
    fn bad_patterns_are_named() {
        let mut p = MissionPattern::default();
        p.years = 0.1;
        assert!(p.validate().expect_err("refused").contains("mission years"));
        let mut p = MissionPattern::default();
        p.exposures_per_stare = 0;
        assert!(p.validate().expect_err("refused").contains("per stare"));
        let mut p = MissionPattern::default();
        p.season_half_width_days = f64::NAN;
        assert!(p.validate().expect_err("refused").contains("season"));
        let e = ExposureErrors {
            per_exposure_mas: 0.0,
            per_stare_mas: 0.0,
        };
        assert!(end_of_mission(&MissionPattern::default(), e).is_err());
    }
}
