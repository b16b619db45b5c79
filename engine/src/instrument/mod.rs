//! The two instruments: the one designed and the one built.
//!
//! A configuration describes the **design** (its `instrument`, `optics`, `detector` and `focal_plane`
//! sections) and, in `[as_built]`, how the telescope that takes the images departs from it. [`realise`] draws
//! that telescope: a configuration whose optics, distortion and detector are the as-built ones, and whose
//! `[as_built]` deviations are spent (so realising it again changes nothing). The simulator images with the
//! realised configuration; the products beside the images come from the design (`docs/ARCHITECTURE.md`: only
//! the simulation and the scoring may see the as-built instrument).
//!
//! The deviations, each a knob of `[as_built]` drawn from the instrument's own seed:
//! * **Wavefront**: Fringe Z4–Z11, a static part and a part linear in x and y across the array, each drawn
//!   N(0, 1) per term in rms-normalised units and scaled to exactly its rms (nm of wavefront); the Fringe
//!   polynomials' rms over the unit disk are 1/√3 (Z4), 1/√6 (Z5, Z6), 1/√8 (Z7, Z8, Z10, Z11), 1/√5 (Z9)
//!   (`optics::zernike::fringe_norm`; the terms are orthogonal, so their rms add in quadrature).
//! * **Focus breathing**: Z4 of rms `A sin(2π t/P + φ)` at the dataset's first mid-exposure t (TT seconds
//!   since J2000), φ drawn once: one phase per dataset (over a dataset of minutes the focus moves by
//!   ≲ 2π·minutes/P of A).
//! * **Distortion**: quadratic SIP terms added to A and B (drawn N(0, 1), scaled so that the added
//!   displacement's rms length over the four corners at r = (N − 1)/√2 px from the optical axis is
//!   `distortion_px`).
//! * **Gain and read noise**: the design's values × exp(σ z), z ~ N(0, 1) (log-normal: always positive, a
//!   relative spread σ for small σ).
//! * **Pointing and roll**: the axis where it truly points (`pointing_offset_arcsec`, `roll_offset_arcsec`:
//!   values, not draws: a sequence draws one per stare from its own seed). The sky is drawn where the telescope
//!   was planned to point; the stars land through the as-built pointing.
//! * **Array placement**: `focal_plane.array_offsets_px` and `array_rotation_errors_deg` are the arrays as
//!   assembled, the as-built instrument's; the design puts every array at its nominal place ([`design_of`]).

use crate::config::{Config, FieldWfe, SipTerm};
use crate::optics::zernike::LOW_ORDER_TERMS;
use crate::optics::{add_term, coefficient_of_nm_rms};
use crate::rng::{self, Stream};
use rand_distr::{Distribution, StandardNormal};

/// Why an as-built instrument could not be drawn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the as-built instrument: {0}")]
pub struct InstrumentError(pub String);

/// The as-built configuration of `design`: its optics, distortion and detector with the `[as_built]`
/// deviations drawn in, the deviations spent (`as_built.realised()`). Without deviations it is `design`
/// itself, bit for bit.
pub fn realise(design: &Config) -> Result<Config, InstrumentError> {
    let a = &design.as_built;
    let mut built = design.clone();
    built.as_built = a.realised();
    if a.has_no_deviation() {
        return Ok(built);
    }
    add_wavefront(&mut built, design)?;
    add_distortion(&mut built, design);
    add_pointing(&mut built, design);
    let mut r = rng::stream(a.seed, Stream::AsBuilt, 4);
    let d = &mut built.detector;
    d.gain_e_per_adu *= log_normal(&mut r, a.gain_error);
    d.read_noise_per_read_e *= log_normal(&mut r, a.read_noise_error);
    Ok(built)
}

/// The design of a configuration: the same with no as-built deviation and the design's knowledge (what
/// `design.toml` holds).
pub fn design_of(cfg: &Config) -> Config {
    let mut d = cfg.clone();
    place_arrays_nominally(&mut d);
    d.as_built = crate::config::AsBuilt {
        seed: cfg.as_built.seed,
        ..crate::config::AsBuilt::design()
    };
    d
}

/// `cfg` with the quad's arrays where the design draws them (no assembly offsets or turns); a single array
/// has none, and its configuration is left as it is (so that its products are those of before, bit for bit).
fn nominal_arrays(cfg: &Config) -> Config {
    let mut d = cfg.clone();
    if d.focal_plane.layout == crate::config::Layout::Quad {
        place_arrays_nominally(&mut d);
    }
    d
}

/// Every array at its design place: no assembly offset or turn.
fn place_arrays_nominally(c: &mut Config) {
    c.focal_plane.array_offsets_px = [[0.0; 2]; 4];
    c.focal_plane.array_rotation_errors_deg = [0.0; 4];
}

/// The configuration the products beside the images are made from: the design, or the realised as-built
/// instrument under the `oracle` control `as_built.knowledge = "as-built"`.
pub fn products_config(design: &Config, built: &Config) -> Config {
    match design.as_built.knowledge {
        crate::config::Knowledge::Design => nominal_arrays(design),
        crate::config::Knowledge::AsBuilt => built.clone(),
    }
}

fn log_normal(r: &mut rng::Rng, sigma: f64) -> f64 {
    let z: f64 = StandardNormal.sample(r);
    (sigma * z).exp()
}

/// Eight N(0, 1) draws scaled to a total of `rms` (rms-normalised units); zeros for `rms` = 0.
fn scaled_draw(r: &mut rng::Rng, rms: f64) -> [f64; 8] {
    let mut v = [0.0; 8];
    for x in v.iter_mut() {
        *x = StandardNormal.sample(r);
    }
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if rms == 0.0 || norm == 0.0 {
        return [0.0; 8];
    }
    v.map(|x| x * rms / norm)
}

/// The wavefront deviation (nm rms per term, rms-normalised) at the centre and its change per half-width of
/// the array along x and y.
struct WavefrontDeviation {
    centre: [f64; 8],
    per_x: [f64; 8],
    per_y: [f64; 8],
}

impl WavefrontDeviation {
    fn draw(design: &Config) -> Result<Self, InstrumentError> {
        let a = &design.as_built;
        let mut centre = scaled_draw(
            &mut rng::stream(a.seed, Stream::AsBuilt, 0),
            a.wavefront_rms_nm,
        );
        // one joint draw for both axes, so that the rms at a corner, √(|gx|² + |gy|²), is the knob
        let mut r = rng::stream(a.seed, Stream::AsBuilt, 1);
        let g: Vec<f64> = (0..16).map(|_| StandardNormal.sample(&mut r)).collect();
        let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
        let k = if norm > 0.0 {
            a.wavefront_field_rms_nm / norm
        } else {
            0.0
        };
        let mut per_x = [0.0; 8];
        let mut per_y = [0.0; 8];
        for j in 0..8 {
            per_x[j] = g[j] * k;
            per_y[j] = g[8 + j] * k;
        }
        if a.focus_breathing_nm > 0.0 {
            let t = crate::sky::scene_epoch(design).map_err(InstrumentError)?;
            let t_s = (t.julian_year_tdb() - 2000.0) * 365.25 * 86_400.0;
            let mut r = rng::stream(a.seed, Stream::AsBuilt, 2);
            let phase = std::f64::consts::TAU * rand::RngExt::random::<f64>(&mut r);
            let w = std::f64::consts::TAU * t_s / a.breathing_period_s + phase;
            centre[0] += a.focus_breathing_nm * w.sin();
        }
        Ok(Self {
            centre,
            per_x,
            per_y,
        })
    }

    /// The deviation of each term Z4 … Z11 (nm rms of wavefront) at (u, v) half-widths from the array's centre.
    fn rms_nm(&self, u: f64, v: f64) -> [f64; 8] {
        let mut c = [0.0; 8];
        for j in 0..8 {
            c[j] = self.centre[j] + u * self.per_x[j] + v * self.per_y[j];
        }
        c
    }
}

/// Add the drawn wavefront deviation to the optics: to every node of the design's field table, or as a
/// 2 × 2 table at the array's corners (bilinear interpolation is exact for a field linear in x and y).
fn add_wavefront(built: &mut Config, design: &Config) -> Result<(), InstrumentError> {
    let a = &design.as_built;
    if a.wavefront_rms_nm == 0.0 && a.wavefront_field_rms_nm == 0.0 && a.focus_breathing_nm == 0.0 {
        return Ok(());
    }
    let dev = WavefrontDeviation::draw(design)?;
    let n = design.instrument.detector_px as f64;
    let half = ((n - 1.0) / 2.0).max(0.5);
    // the deviation in the table's units and sign
    let add = |row: &mut FieldWfe| {
        let c = dev.rms_nm((row.x_px - half) / half, (row.y_px - half) / half);
        for (&j, nm) in LOW_ORDER_TERMS.iter().zip(c) {
            add_term(
                &mut row.fringe,
                j,
                coefficient_of_nm_rms(&design.optics, j, nm),
            );
        }
    };
    let o = &mut built.optics;
    if o.field_table.is_empty() {
        o.field_table = [
            (0.0, 0.0),
            (n - 1.0, 0.0),
            (0.0, n - 1.0),
            (n - 1.0, n - 1.0),
        ]
        .iter()
        .map(|&(x_px, y_px)| FieldWfe {
            x_px,
            y_px,
            fringe: o.fringe.clone(),
        })
        .collect();
    }
    o.field_table.iter_mut().for_each(add);
    Ok(())
}

/// Point the as-built telescope where it truly points: the planned axis moved by the pointing offset on the
/// tangent plane there (gnomonic, `sky::apparent::plane_to_sky`), the focal plane turned by the roll offset.
fn add_pointing(built: &mut Config, design: &Config) {
    let a = &design.as_built;
    let [east, north] = a.pointing_offset_arcsec;
    if east != 0.0 || north != 0.0 {
        let (ra, dec) = crate::sky::apparent::plane_to_sky(
            (design.sky.ra_deg, design.sky.dec_deg),
            east * 1000.0,
            north * 1000.0,
        );
        (built.sky.ra_deg, built.sky.dec_deg) = (ra, dec);
    }
    built.sky.pa_deg += a.roll_offset_arcsec / 3600.0;
}

/// Add the drawn quadratic distortion to the SIP polynomials (terms of the same order summed).
fn add_distortion(built: &mut Config, design: &Config) {
    let a = &design.as_built;
    if a.distortion_px == 0.0 {
        return;
    }
    let mut r = rng::stream(a.seed, Stream::AsBuilt, 3);
    // A: x², xy, y²; B: the same
    let mut c = [0.0f64; 6];
    for x in c.iter_mut() {
        *x = StandardNormal.sample(&mut r);
    }
    let half = (design.instrument.detector_px as f64 - 1.0) / 2.0;
    let corners = [(half, half), (-half, half), (half, -half), (-half, -half)];
    let shift = |c: &[f64; 6], x: f64, y: f64| {
        (
            c[0] * x * x + c[1] * x * y + c[2] * y * y,
            c[3] * x * x + c[4] * x * y + c[5] * y * y,
        )
    };
    let ms = corners
        .iter()
        .map(|&(x, y)| {
            let (dx, dy) = shift(&c, x, y);
            dx * dx + dy * dy
        })
        .sum::<f64>()
        / 4.0;
    let k = if ms > 0.0 {
        a.distortion_px / ms.sqrt()
    } else {
        0.0
    };
    let pq = [(2, 0), (1, 1), (0, 2)];
    let fp = &mut built.focal_plane;
    for (terms, coeffs) in [(&mut fp.sip_a, &c[0..3]), (&mut fp.sip_b, &c[3..6])] {
        for (&(p, q), v) in pq.iter().zip(coeffs) {
            match terms.iter_mut().find(|t| t.p == p && t.q == q) {
                Some(t) => t.value += v * k,
                None => terms.push(SipTerm { p, q, value: v * k }),
            }
        }
    }
}

#[cfg(test)]
mod tests;
