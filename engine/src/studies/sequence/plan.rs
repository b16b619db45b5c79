//! The exposures a sequence takes: stare centres on a grid in Galactic (l, b) a step apart, visited in a
//! boustrophedon (each row of stares walked the other way from the last; each visit's pattern shifted by
//! `visit_dither_px` in l and b), M exposures per stare at the
//! readout's cadence, a manoeuvre between stares; every stare pointed with its own error (a seeded draw)
//! and the focal plane's +y to Galactic north.
//!
//! Each exposure becomes a configuration of its own ([`exposure_config`]): the quad focal plane at the
//! stare's pointing, its UTC start (`observation.start_utc`, the orbit's phase carried on), and its own seed
//! for the jitter and the noise (derived from the master seed and its index).

use super::spec::Spec;
use crate::config::{Config, Layout};
use crate::rng::{self, Stream};
use crate::time::Epoch;
use rand_distr::{Distribution, StandardNormal};

/// One stare: where the telescope points for its exposures.
#[derive(Debug, Clone, PartialEq)]
pub struct Stare {
    /// In observing order over all visits.
    pub index: usize,
    pub visit: usize,
    /// Its place in the pattern (column along l, row along b).
    pub column: usize,
    pub row: usize,
    /// The planned centre, Galactic degrees.
    pub l_deg: f64,
    pub b_deg: f64,
    /// Where it points, with its pointing error: ICRS degrees and the position angle of the focal plane's
    /// +y (east of north) with its roll error.
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub pa_deg: f64,
    /// Its pointing error, (east, north) on the tangent plane at the planned axis, arcsec, and its roll
    /// error, arcsec: the as-built instrument's offsets for its exposures (`as_built.pointing_offset_arcsec`).
    pub pointing_offset_arcsec: [f64; 2],
    pub roll_offset_arcsec: f64,
}

/// One exposure of the sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedExposure {
    /// In observing order, from 0.
    pub index: usize,
    /// Its stare ([`Plan::stares`]).
    pub stare: usize,
    /// Its UTC start.
    pub start: Epoch,
    /// Its seed (jitter, noise, flat errors).
    pub seed: u64,
    /// The orbit's argument of latitude at its start, degrees.
    pub orbit_phase_deg: f64,
}

/// The planned sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub spec: Spec,
    pub stares: Vec<Stare>,
    pub exposures: Vec<PlannedExposure>,
    /// The focal plane's side on the sky, degrees.
    pub field_deg: f64,
}

impl Plan {
    /// The stares' centres' extent, Galactic degrees: (l_min, l_max, b_min, b_max).
    pub fn extent_deg(&self) -> (f64, f64, f64, f64) {
        self.stares.iter().fold(
            (f64::MAX, f64::MIN, f64::MAX, f64::MIN),
            |(a, b, c, d), s| {
                (
                    a.min(s.l_deg),
                    b.max(s.l_deg),
                    c.min(s.b_deg),
                    d.max(s.b_deg),
                )
            },
        )
    }
}

/// Galactic (l, b) → ICRS (α, δ), degrees (SOFA `g2icrs`).
pub fn galactic_to_icrs(l_deg: f64, b_deg: f64) -> (f64, f64) {
    let (ra, dec) = sofars::coords::g2icrs(l_deg.to_radians(), b_deg.to_radians());
    (ra.to_degrees().rem_euclid(360.0), dec.to_degrees())
}

/// The position angle (east of north) of Galactic north at (α, δ), degrees.
pub fn galactic_north_pa_deg(ra_deg: f64, dec_deg: f64) -> f64 {
    let (_, eb) = crate::scene::bulge::galactic_axes(ra_deg, dec_deg);
    eb[0].atan2(eb[1]).to_degrees()
}

/// The focal plane's side on the sky, degrees: 2N + gap pixels (quad).
pub fn field_deg(cfg: &Config) -> f64 {
    (2.0 * cfg.instrument.detector_px as f64 + cfg.focal_plane.gap_px)
        * cfg.instrument.plate_scale_mas()
        / 3.6e6
}

/// Plan `spec` with the instrument of `cfg` (its cadence, focal plane, orbit and master seed).
pub fn plan(spec: &Spec, cfg: &Config) -> Result<Plan, String> {
    spec.validate()?;
    let field = field_deg(cfg);
    let step = spec.step_fields * field;
    let cadence = cfg.exposure_cadence_s();
    let stare_span = spec.exposures_per_stare as f64 * cadence + spec.manoeuvre_s;
    let period = crate::sky::orbit(cfg)?.period_s();
    let visits: Vec<Epoch> = spec
        .visits_utc
        .iter()
        .map(|v| Epoch::from_utc_iso(v))
        .collect::<Result<_, _>>()?;
    let first = visits[0];
    let mut stares = Vec::new();
    let mut exposures = Vec::new();
    let dither_deg = spec.visit_dither_px * cfg.instrument.plate_scale_mas() / 3.6e6;
    for (v, start) in visits.iter().enumerate() {
        let mut s_in_visit = 0;
        let shift = v as f64 * dither_deg;
        for row in 0..spec.stares_b {
            for k in 0..spec.stares_l {
                let column = if row % 2 == 0 {
                    k
                } else {
                    spec.stares_l - 1 - k
                };
                let l = spec.centre_l_deg
                    + (column as f64 - (spec.stares_l as f64 - 1.0) / 2.0) * step
                    + shift;
                let b = spec.centre_b_deg
                    + (row as f64 - (spec.stares_b as f64 - 1.0) / 2.0) * step
                    + shift;
                let (ra0, dec0) = galactic_to_icrs(l, b);
                let index = stares.len();
                let mut r = rng::stream(cfg.seed, Stream::Sequence, index as u64);
                let z: [f64; 3] = std::array::from_fn(|_| StandardNormal.sample(&mut r));
                let offset = [
                    z[0] * spec.pointing_error_arcsec,
                    z[1] * spec.pointing_error_arcsec,
                ];
                let roll = z[2] * spec.roll_error_arcsec;
                // where it truly points: the planned axis moved on its tangent plane, as the instrument
                // as built moves it (`instrument::realise`)
                let (ra, dec) = crate::sky::apparent::plane_to_sky(
                    (ra0, dec0),
                    offset[0] * 1000.0,
                    offset[1] * 1000.0,
                );
                let pa = galactic_north_pa_deg(ra0, dec0) + roll / 3600.0;
                stares.push(Stare {
                    index,
                    visit: v,
                    column,
                    row,
                    l_deg: l,
                    b_deg: b,
                    ra_deg: ra,
                    dec_deg: dec,
                    pa_deg: pa,
                    pointing_offset_arcsec: offset,
                    roll_offset_arcsec: roll,
                });
                let stare_start = start.plus_s(s_in_visit as f64 * stare_span);
                for m in 0..spec.exposures_per_stare {
                    let t = stare_start.plus_s(m as f64 * cadence);
                    let i = exposures.len();
                    exposures.push(PlannedExposure {
                        index: i,
                        stare: index,
                        start: t,
                        seed: rng::derive_seed(cfg.seed, &[0x5E9, i as u64]),
                        orbit_phase_deg: (cfg.observation.orbit_phase_deg
                            + 360.0 * t.seconds_since(&first) / period)
                            .rem_euclid(360.0),
                    });
                }
                s_in_visit += 1;
            }
        }
    }
    Ok(Plan {
        spec: spec.clone(),
        stares,
        exposures,
        field_deg: field,
    })
}

/// The configuration of exposure `e` of `plan`: `base` on the quad focal plane at its stare's planned
/// pointing, with the stare's pointing and roll errors as the as-built instrument's offsets (they replace
/// any in `base`), its start (the ACE series' t = 0 set so that its image 0 starts at `e.start`), the
/// orbit's phase then, one image, its own seed.
pub fn exposure_config(base: &Config, plan: &Plan, e: &PlannedExposure) -> Config {
    let s = &plan.stares[e.stare];
    let mut c = base.clone();
    c.focal_plane.layout = Layout::Quad;
    (c.sky.ra_deg, c.sky.dec_deg, c.sky.pa_deg) = s.planned();
    c.as_built.pointing_offset_arcsec = s.pointing_offset_arcsec;
    c.as_built.roll_offset_arcsec = s.roll_offset_arcsec;
    let t0 = e.start.plus_s(-base.ace.first_exposure_start_s);
    c.observation.start_utc = t0.utc_iso();
    c.observation.orbit_phase_deg = e.orbit_phase_deg;
    c.seed = e.seed;
    c.fidelity.images = 1;
    c
}

/// What the pipeline knows of exposure `e`: [`exposure_config`] at its stare's **planned** pointing (no
/// pointing or roll error) on the focal plane **as designed** (no assembly offsets or turns) — the design
/// WCS its catalogue's sky positions come through, and what the astrometric solution starts from.
pub fn design_config(base: &Config, plan: &Plan, e: &PlannedExposure) -> Config {
    crate::instrument::design_of(&exposure_config(base, plan, e))
}

impl Stare {
    /// Where it was planned to point: (RA, Dec, PA) in degrees, Galactic north up.
    pub fn planned(&self) -> (f64, f64, f64) {
        let (ra, dec) = galactic_to_icrs(self.l_deg, self.b_deg);
        (ra, dec, galactic_north_pa_deg(ra, dec))
    }
}

/// The mid-exposure instant of exposure `e` of a configuration `cfg` (its start plus half the exposure).
pub fn mid_exposure(cfg: &Config, e: &PlannedExposure) -> Epoch {
    e.start.plus_s(cfg.detector.exposure_s / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stares_step_half_a_field_and_exposures_follow_the_cadence() {
        let cfg = Config::default();
        let spec = Spec {
            pointing_error_arcsec: 0.0,
            roll_error_arcsec: 0.0,
            ..Spec::default()
        };
        let p = plan(&spec, &cfg).expect("plan");
        assert_eq!(p.exposures.len(), 3 * 2 * 26 * 2);
        assert_eq!(p.stares.len(), 12);
        // the field: (2 · 1968 + 300) px × 472.1 mas = 0.5555°; neighbours half of it apart on the sky
        assert!((p.field_deg - 0.5555).abs() < 1e-3, "{}", p.field_deg);
        let sep = |a: &Stare, b: &Stare| {
            crate::sky::apparent::separation_mas((a.ra_deg, a.dec_deg), (b.ra_deg, b.dec_deg))
                / 3.6e6
        };
        assert!((sep(&p.stares[0], &p.stares[1]) - p.field_deg / 2.0).abs() < 1e-6);
        // boustrophedon: row 1 is walked back, so stare 2 and 3 are neighbours in b
        assert_eq!((p.stares[2].column, p.stares[3].column), (2, 2));
        assert!((sep(&p.stares[2], &p.stares[3]) - p.field_deg / 2.0).abs() < 1e-6);
        // the pattern is centred on (l, b) = (0, 0) and the focal plane's +y is Galactic north (PA −58.6°)
        let l_mean: f64 = p.stares[..6].iter().map(|s| s.l_deg).sum::<f64>() / 6.0;
        assert!(l_mean.abs() < 1e-12);
        assert!(
            (p.stares[0].pa_deg + 58.6).abs() < 0.2,
            "{}",
            p.stares[0].pa_deg
        );
        // exposures back to back at the cadence, a manoeuvre between stares, visits at their dates
        let cadence = cfg.exposure_cadence_s();
        let e = &p.exposures;
        assert!((e[1].start.seconds_since(&e[0].start) - cadence).abs() < 1e-6);
        assert!((e[26].start.seconds_since(&e[25].start) - cadence - 115.0).abs() < 1e-6);
        assert_eq!(e[156].start.utc_iso(), "2031-09-22T00:00:00.000");
        assert_eq!((e[155].stare, e[156].stare), (5, 6));
        // each exposure its own seed; its configuration starts its image 0 at its start
        assert_ne!(e[0].seed, e[1].seed);
        let c = exposure_config(&cfg, &p, &e[30]);
        assert_eq!(c.observation.start_utc, e[30].start.utc_iso());
        assert_eq!(c.focal_plane.layout, Layout::Quad);
        assert!(c.validate().is_ok());
    }

    /// The aberration the design WCS leaves at the default sequence's axes (docs/astrometric-solution.md):
    /// the apparent less the catalogue direction of each exposure's planned axis. Near the equinoxes the
    /// Earth moves nearly along the line of sight to the Galactic centre (θ ≈ 6–9°: 20.5″ sin θ ≈ 2–3″),
    /// and the orbit's 7.6 km/s adds or takes up to 5.2″ with its phase — not the ≈ 20″ of the solstices.
    #[test]
    fn the_default_sequence_sees_an_aberration_of_a_few_arcseconds() {
        let cfg = Config::default();
        let p = plan(&Spec::default(), &cfg).expect("plan");
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for e in &p.exposures {
            let c = exposure_config(&cfg, &p, e);
            let place = crate::sky::scene_place(&c)
                .expect("place")
                .expect("apparent place on");
            let axis = (c.sky.ra_deg, c.sky.dec_deg);
            let none = crate::sky::apparent::Motion::default();
            let mut astrometric = place;
            astrometric.apparent = false;
            let a = crate::sky::apparent::direction(axis.0, axis.1, &none, &astrometric);
            let b = crate::sky::apparent::direction(axis.0, axis.1, &none, &place);
            let s = crate::sky::apparent::separation_mas(a, b) / 1e3;
            (lo, hi) = (lo.min(s), hi.max(s));
        }
        eprintln!(
            "aberration over {} exposures: {lo:.2}–{hi:.2}″",
            p.exposures.len()
        );
        // 0.32–7.19″ over its 312 exposures: the orbit's part cancels the Earth's at some phases
        assert!(lo < 1.0 && hi > 6.0 && hi < 8.0, "{lo}–{hi}″");
    }

    #[test]
    fn pointing_errors_have_their_size() {
        let cfg = Config::default();
        let spec = Spec {
            stares_l: 20,
            stares_b: 20,
            exposures_per_stare: 1,
            visits_utc: vec!["2031-03-21T00:00:00".into()],
            ..Spec::default()
        };
        let errs = plan(&spec, &cfg).expect("plan");
        let exact = plan(
            &Spec {
                pointing_error_arcsec: 0.0,
                roll_error_arcsec: 0.0,
                ..spec.clone()
            },
            &cfg,
        )
        .expect("plan");
        let (mut d2, mut r2) = (0.0, 0.0);
        for (a, b) in errs.stares.iter().zip(&exact.stares) {
            let (dx, dy) =
                crate::sky::apparent::offset_mas((b.ra_deg, b.dec_deg), (a.ra_deg, a.dec_deg));
            d2 += (dx * dx + dy * dy) / 2.0;
            r2 += (a.pa_deg - b.pa_deg).powi(2);
        }
        let n = errs.stares.len() as f64;
        // 400 stares: the rms within 4σ of its own sampling error (σ/√(2n) per axis pair)
        let rms = (d2 / n).sqrt() / 1e3;
        assert!(
            (rms - 2.0).abs() < 4.0 * 2.0 / (2.0 * 2.0 * n).sqrt(),
            "{rms}″"
        );
        let roll = (r2 / n).sqrt() * 3600.0;
        assert!(
            (roll - 10.0).abs() < 4.0 * 10.0 / (2.0 * n).sqrt(),
            "{roll}″"
        );
    }

    #[test]
    fn bad_specs_are_named() {
        let cfg = Config::default();
        for (spec, needle) in [
            (
                Spec {
                    stares_l: 0,
                    ..Spec::default()
                },
                "sequence.stares_l = 0",
            ),
            (
                Spec {
                    visits_utc: vec!["2031-02-30".into()],
                    ..Spec::default()
                },
                "sequence.visits_utc[0]",
            ),
            (
                Spec {
                    step_fields: -1.0,
                    ..Spec::default()
                },
                "sequence.step_fields",
            ),
            (
                Spec {
                    exposures_per_stare: 10_000,
                    stares_l: 100,
                    ..Spec::default()
                },
                "at most 100000",
            ),
        ] {
            let e = plan(&spec, &cfg).expect_err(needle);
            assert!(e.contains(needle), "{e}");
        }
    }
}
