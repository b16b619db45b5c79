//! Countermeasures to the rolling-readout error, applied after the global ePSF fit of an image.
//!
//! * `yzones[:K]` / `yzones-shared[:K]` — position-dependent ePSF: K representative ePSFs for zones along Y,
//!   interpolated linearly in Y between zone centres (the paper's proposal; K defaults to the analysis
//!   configuration's `epsf_zones`). `yzones`: each zone's ePSF is
//!   built and re-centred on its own (centroid convention per zone). `yzones-shared`: each zone's ePSF is built
//!   with the stars held at their global-ePSF positions and not re-centred, so it stays in the global ePSF's
//!   centring frame. Neither can absorb a displacement common to the stars of a zone — an image translated
//!   by δ is fitted at its translated position by any ePSF with a fixed centring convention. The shared frame
//!   changes little; per-zone re-centring moves each zone's positions to its own (jitter-skewed) photocentre
//!   convention, so the zones disagree by what their stars' jitter did and the scatter grows. Displacements
//!   need a reference (plate model) or telemetry.
//! * `plate-affine`, `plate-poly:N` — per exposure, fit a smooth transformation of the fitted positions onto
//!   reference positions by least squares over all stars, as an astrometric pipeline does: affine
//!   (6 parameters) or `Δx = a₀ + a₁x + Σₖ₌₁..N bₖ yᵏ` and the same for Δy (2(N + 2) parameters). The
//!   parameters absorbed are reported (`dof_absorbed`): with n stars the residual variance of pure noise
//!   shrinks by (1 − p/n). The reference ([`Reference`]) is, by default, **the stare's own stack**: the mean
//!   position of each star over the stare's exposures, iterated with the per-exposure plates
//!   ([`stack`]; the instrument has it). `@catalogue` takes the reference catalogue product (a survey's,
//!   with its errors), cross-matched by position; `@oracle` the same fit onto the simulation's true
//!   positions, which only a simulation can hand over (an upper limit, never a default).
//! * `telemetry` — subtract, from each star, the displacement the attitude telemetry predicts for its fit:
//!   the ACE series sampled at `rate_hz`, delayed by `latency_s`, with Gaussian noise `noise_mas` per sample,
//!   linearly interpolated, and turned into each star's fitted shift through the fit's response to the jitter
//!   of its pixels' window ([`crate::analysis::response`]; the optical PSF is taken as known from calibration).
//! * `exact-epsf` — not a correction but the control of SPEC §8: the fit with the exact ePSF of a static
//!   simulation (the simulation's own kernel, so it is an oracle: it only runs when asked).
//!
//! The names are typed ([`Countermeasure`], `FromStr`/`Display`); [`Plan`] is a validated list of them.

pub mod forward;
pub mod forward_epsf;
pub mod plate;
pub mod stack;
pub mod telemetry;
pub mod wavefront;
pub mod wiener;
pub mod zones;

pub use plate::PlateModel;
pub use telemetry::Telemetry;

use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{BuildOptions, StarStart};
use crate::analysis::epsf::fit::{fit_star, flags};
use crate::analysis::image::AnalysisImage;
use crate::analysis::report::StarResult;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt;
use std::str::FromStr;

/// Every countermeasure name, as the CLI, the sweep files and the CSVs spell them.
pub const NAMES: &str = "none, yzones[:K], yzones-shared[:K], [telemetry-model+]plate-affine[@R], \
     [telemetry-model+]plate-poly:N[@R] (R: stack (default), catalogue, oracle), telemetry, telemetry-model, \
     exact-epsf";

/// The prefix of a plate model fitted after the telemetry forward model.
pub const FORWARD_PREFIX: &str = "telemetry-model+";

/// Default error of an external reference catalogue, mas: a Gaia-DR3-like star of G ≈ 17–18 propagated
/// ~15 years to the 2030s (position ≈ 0.1–0.3 mas at 2016 plus ≈ 0.1–0.2 mas/yr of proper-motion error;
/// Lindegren et al. 2021, A&A 649, A2). Most of JASMINE's reddened bulge stars are fainter in G or absent,
/// which is why the stack, not a catalogue, is the default reference.
pub const DEFAULT_CATALOGUE_ERROR_MAS: f64 = 2.0;

#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum CountermeasureError {
    #[error("unknown countermeasure `{0}` (one of: {NAMES})")]
    Unknown(String),
    #[error("countermeasure `{name}`: {why}")]
    BadParameter { name: String, why: String },
    #[error("countermeasure `{0}` is listed twice")]
    Duplicate(String),
    #[error("no countermeasure given: list at least one, e.g. none")]
    Empty,
    #[error("{what} needs at least {need} matched stars, found {have}")]
    TooFewStars {
        what: String,
        need: usize,
        have: usize,
    },
    #[error("{what}: the stars do not constrain the model (all in one row or column?)")]
    Degenerate { what: String },
    #[error(
        "{0} needs the true positions, which only a simulated exposure has (an oracle control)"
    )]
    NeedsTruth(String),
    #[error(
        "{0} needs the reference catalogue product (refcat.csv beside the image, or --refcat): none was given"
    )]
    NeedsReference(String),
    #[error(
        "{what}: the stack reference needs stars seen in at least 2 exposures of the stare, found {have}"
    )]
    ThinStack { what: String, have: usize },
    #[error("telemetry: {0}")]
    Telemetry(String),
    #[error("{0} is run by the analysis pipeline, not applied to fits")]
    NotACorrection(String),
}

/// Telemetry rate of the default telemetry, Hz.
pub const DEFAULT_TELEMETRY_RATE_HZ: f64 = 1000.0;
/// Highest telemetry rate accepted (a gyro reads at ≤ 10 kHz; above this the samples only cost memory).
pub const MAX_TELEMETRY_RATE_HZ: f64 = 1.0e5;
/// Largest |latency| accepted, s (longer than any exposure cycle).
pub const MAX_TELEMETRY_LATENCY_S: f64 = 60.0;
/// Largest reference-catalogue error and telemetry noise accepted, mas (far beyond any realistic value; a
/// number past it is a unit mistake).
pub const MAX_ERROR_MAS: f64 = 1.0e5;

/// Quality of the attitude telemetry used by the `telemetry` countermeasure. Its error is white noise per
/// sample (sensor read noise, which averages away over an exposure) plus a correlated part: a first-order
/// Gauss–Markov process of rms `correlated_mas` and correlation time `correlation_time_s` (PSD flat below the
/// knee 1/(2π τ), falling as f⁻² above) — the residual of gyro bias instability after star-tracker fusion, the
/// error that does *not* average away within an exposure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TelemetryQuality {
    /// Gaussian noise per sample, mas.
    pub noise_mas: f64,
    /// Sampling rate, Hz.
    pub rate_hz: f64,
    /// Latency, s: the sample reported at t is the attitude of t − latency.
    pub latency_s: f64,
    /// RMS of the correlated (Gauss–Markov) error, mas (0: none).
    pub correlated_mas: f64,
    /// Correlation time of the correlated error, s.
    pub correlation_time_s: f64,
}

impl TelemetryQuality {
    /// Ideal telemetry: noise-free, 1 kHz, no latency (an oracle: the true attitude).
    pub const IDEAL: TelemetryQuality = TelemetryQuality {
        noise_mas: 0.0,
        rate_hz: DEFAULT_TELEMETRY_RATE_HZ,
        latency_s: 0.0,
        correlated_mas: 0.0,
        correlation_time_s: 1.0,
    };

    /// The default: a plausible attitude-determination system, not a perfect one. Gyro samples at 1 kHz
    /// with 20 mas of white noise each (read noise: averages away within an exposure), no latency, and a
    /// correlated error of 5 mas rms with a 1-s correlation time. The correlated part is the gyro's angle
    /// random walk bounded by the fusion with the star tracker: its increments over Δt ≪ τ are
    /// σ√(2Δt/τ) ≈ 7 mas/√s, the angle random walk of an inertial reference unit of the class flown on
    /// imaging and astrometric missions (≈ 1e-4 °/√h ≈ 6 mas/√s); over the 1.2-s spread of the rolling
    /// readout's windows that is a few mas, the size of the effect it corrects. The numbers are
    /// not a JASMINE specification (none is public); `jsim experiment --telemetry-correlated-mas E` and
    /// docs/results.md shows the accuracy against E.
    pub const DEFAULT: TelemetryQuality = TelemetryQuality {
        noise_mas: 20.0,
        rate_hz: DEFAULT_TELEMETRY_RATE_HZ,
        latency_s: 0.0,
        correlated_mas: 5.0,
        correlation_time_s: 1.0,
    };

    /// Check the values, naming the offending one and its allowed range.
    pub fn validate(&self) -> Result<(), CountermeasureError> {
        let bad = |why: String| Err(CountermeasureError::Telemetry(why));
        if !(self.noise_mas >= 0.0 && self.noise_mas <= MAX_ERROR_MAS) {
            return bad(format!(
                "noise {} mas must be a finite number in [0, {MAX_ERROR_MAS}]",
                self.noise_mas
            ));
        }
        if !(self.rate_hz > 0.0 && self.rate_hz <= MAX_TELEMETRY_RATE_HZ) {
            return bad(format!(
                "rate {} Hz must be > 0 and ≤ {MAX_TELEMETRY_RATE_HZ}",
                self.rate_hz
            ));
        }
        if !(0.0..=MAX_ERROR_MAS).contains(&self.correlated_mas) {
            return bad(format!(
                "correlated error {} mas must be a finite number in [0, {MAX_ERROR_MAS}]",
                self.correlated_mas
            ));
        }
        if !(self.correlation_time_s > 0.0 && self.correlation_time_s <= 1e6) {
            return bad(format!(
                "correlation time {} s must be > 0 and ≤ 1e6",
                self.correlation_time_s
            ));
        }
        if !(self.latency_s.abs() <= MAX_TELEMETRY_LATENCY_S) {
            return bad(format!(
                "latency {} s must be finite, |latency| ≤ {MAX_TELEMETRY_LATENCY_S}",
                self.latency_s
            ));
        }
        Ok(())
    }
}

impl Default for TelemetryQuality {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A countermeasure and its parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Countermeasure {
    /// The global ePSF fit alone.
    None,
    /// Y-zoned ePSFs: `zones` (default: the analysis configuration's `epsf_zones`), re-centred per zone or
    /// held in the global frame (`shared`).
    YZones { zones: Option<usize>, shared: bool },
    /// A per-exposure plate model against a reference, fitted to the global fits or, with `forward`, to the
    /// telemetry forward model's refits at that telemetry quality (`telemetry-model+plate-…`: the forward model
    /// removes what the telemetry sees, the plate model what it cannot — its correlated error — as one
    /// countermeasure).
    Plate {
        model: PlateModel,
        reference: Reference,
        forward: Option<TelemetryQuality>,
    },
    /// The telemetry correction.
    Telemetry(TelemetryQuality),
    /// The telemetry forward model: each star refitted with the static profile seen through the jitter the
    /// telemetry records over its pixels' windows ([`forward`]).
    TelemetryModel(TelemetryQuality),
    /// The control fit with the exact ePSF (static ACE only).
    ExactEpsf,
}

/// The reference positions of a plate model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reference {
    /// The stare's own stack: each star's mean position over the stare's exposures (default; no truth).
    Stack,
    /// An external catalogue: the true positions with their own Gaussian error (mas, > 0), seeded.
    Catalogue { error_mas: f64 },
    /// The simulation's true positions: an oracle, for comparison only.
    Oracle,
}

impl Countermeasure {
    /// The countermeasures the explorer offers, with their default parameters.
    pub const OFFERED: [Countermeasure; 7] = [
        Countermeasure::None,
        Countermeasure::YZones {
            zones: None,
            shared: false,
        },
        Countermeasure::Plate {
            model: PlateModel::Affine,
            reference: Reference::Stack,
            forward: None,
        },
        Countermeasure::Plate {
            model: PlateModel::PolyY(3),
            reference: Reference::Stack,
            forward: None,
        },
        Countermeasure::Telemetry(TelemetryQuality::DEFAULT),
        Countermeasure::TelemetryModel(TelemetryQuality::DEFAULT),
        Countermeasure::Plate {
            model: PlateModel::PolyY(3),
            reference: Reference::Stack,
            forward: Some(TelemetryQuality::DEFAULT),
        },
    ];

    /// The same countermeasure with the given telemetry quality and catalogue error (for the variants that
    /// have them).
    pub fn with_quality(self, telemetry: TelemetryQuality, catalogue_error_mas: f64) -> Self {
        match self {
            Countermeasure::Telemetry(_) => Countermeasure::Telemetry(telemetry),
            Countermeasure::TelemetryModel(_) => Countermeasure::TelemetryModel(telemetry),
            Countermeasure::Plate {
                model,
                reference,
                forward,
            } => Countermeasure::Plate {
                model,
                reference: match reference {
                    Reference::Catalogue { .. } => Reference::Catalogue {
                        error_mas: catalogue_error_mas,
                    },
                    other => other,
                },
                forward: forward.map(|_| telemetry),
            },
            other => other,
        }
    }

    /// Whether this countermeasure needs the stare's other exposures (a stack-referenced plate model).
    pub fn needs_stare(&self) -> bool {
        matches!(
            self,
            Countermeasure::Plate {
                reference: Reference::Stack,
                ..
            }
        )
    }

    /// The telemetry quality of a countermeasure that corrects with telemetry (`telemetry`,
    /// `telemetry-model`, `telemetry-model+plate-…`).
    pub fn telemetry_quality(&self) -> Option<TelemetryQuality> {
        match self {
            Countermeasure::Telemetry(q) | Countermeasure::TelemetryModel(q) => Some(*q),
            Countermeasure::Plate { forward, .. } => *forward,
            _ => None,
        }
    }

    /// The telemetry quality of a countermeasure that refits each star with the telemetry forward model
    /// (`telemetry-model`, `telemetry-model+plate-…`).
    pub fn forward_model(&self) -> Option<TelemetryQuality> {
        match self {
            Countermeasure::TelemetryModel(q) => Some(*q),
            Countermeasure::Plate { forward, .. } => *forward,
            _ => None,
        }
    }

    /// Whether this countermeasure is a plate model referenced to the true positions (`@oracle`).
    pub fn is_oracle_plate(&self) -> bool {
        matches!(
            self,
            Countermeasure::Plate {
                reference: Reference::Oracle,
                ..
            }
        )
    }

    /// Whether this countermeasure is a plate model referenced to the reference catalogue (`@catalogue`,
    /// alone or after the forward model): its positions are in the catalogue's frame.
    pub fn is_catalogue_plate(&self) -> bool {
        matches!(
            self,
            Countermeasure::Plate {
                reference: Reference::Catalogue { .. },
                ..
            }
        )
    }

    /// Check the parameters.
    pub fn validate(&self) -> Result<(), CountermeasureError> {
        let bad = |why: String| {
            Err(CountermeasureError::BadParameter {
                name: self.to_string(),
                why,
            })
        };
        match *self {
            Countermeasure::YZones { zones: Some(k), .. } if !(2..=64).contains(&k) => {
                bad(format!("{k} zones: allowed 2..=64"))
            }
            Countermeasure::Plate {
                model,
                reference,
                forward,
            } => {
                if let Some(q) = forward {
                    q.validate()?;
                }
                if let PlateModel::PolyY(n) = model
                    && !(1..=plate::MAX_PLATE_ORDER).contains(&n)
                {
                    return bad(format!("order {n}: allowed 1..={}", plate::MAX_PLATE_ORDER));
                }
                if let Reference::Catalogue { error_mas } = reference
                    && !(error_mas > 0.0 && error_mas <= MAX_ERROR_MAS)
                {
                    return bad(format!(
                        "catalogue error {error_mas} mas: allowed (0, {MAX_ERROR_MAS}] (a catalogue \
                         without error is the truth: name it @oracle)"
                    ));
                }
                Ok(())
            }
            Countermeasure::Telemetry(q) | Countermeasure::TelemetryModel(q) => q.validate(),
            _ => Ok(()),
        }
    }
}

impl fmt::Display for Countermeasure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Countermeasure::None => write!(f, "none"),
            Countermeasure::YZones { zones, shared } => {
                write!(f, "{}", if *shared { "yzones-shared" } else { "yzones" })?;
                match zones {
                    Some(k) => write!(f, ":{k}"),
                    None => Ok(()),
                }
            }
            Countermeasure::Plate {
                model,
                reference,
                forward,
            } => {
                if forward.is_some() {
                    write!(f, "{FORWARD_PREFIX}")?;
                }
                match model {
                    PlateModel::Affine => write!(f, "plate-affine")?,
                    PlateModel::PolyY(n) => write!(f, "plate-poly:{n}")?,
                }
                match reference {
                    Reference::Stack => Ok(()),
                    Reference::Catalogue { .. } => write!(f, "@catalogue"),
                    Reference::Oracle => write!(f, "@oracle"),
                }
            }
            Countermeasure::Telemetry(_) => write!(f, "telemetry"),
            Countermeasure::TelemetryModel(_) => write!(f, "telemetry-model"),
            Countermeasure::ExactEpsf => write!(f, "exact-epsf"),
        }
    }
}

impl FromStr for Countermeasure {
    type Err = CountermeasureError;

    /// Parse a name with default parameters (the default telemetry, the default catalogue error) and
    /// check it.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        if let Some(plate) = s.strip_prefix(FORWARD_PREFIX) {
            return match plate.parse::<Countermeasure>() {
                Ok(Countermeasure::Plate {
                    model,
                    reference,
                    forward: None,
                }) => Ok(Countermeasure::Plate {
                    model,
                    reference,
                    forward: Some(TelemetryQuality::DEFAULT),
                }),
                Ok(_) | Err(CountermeasureError::Unknown(_)) => {
                    Err(CountermeasureError::Unknown(s.to_string()))
                }
                Err(CountermeasureError::BadParameter { name, why }) => {
                    Err(CountermeasureError::BadParameter {
                        name: format!("{FORWARD_PREFIX}{name}"),
                        why,
                    })
                }
                Err(e) => Err(e),
            };
        }
        let unknown = || CountermeasureError::Unknown(s.to_string());
        let (name, reference) = match s.split_once('@') {
            None => (s, Reference::Stack),
            Some((n, "stack")) => (n, Reference::Stack),
            Some((n, "catalogue")) => (
                n,
                Reference::Catalogue {
                    error_mas: DEFAULT_CATALOGUE_ERROR_MAS,
                },
            ),
            Some((n, "oracle")) => (n, Reference::Oracle),
            Some(_) => return Err(unknown()),
        };
        if name.len() != s.len() && !name.starts_with("plate-") {
            return Err(unknown());
        }
        let s = name;
        let (head, arg) = match s.split_once(':') {
            Some((h, a)) => (h, Some(a)),
            None => (s, None),
        };
        let number = |a: &str| -> Result<usize, CountermeasureError> {
            a.parse().map_err(|_| CountermeasureError::BadParameter {
                name: s.to_string(),
                why: format!("`{a}` is not a whole number"),
            })
        };
        let cm = match (head, arg) {
            ("none", None) => Countermeasure::None,
            ("exact-epsf", None) => Countermeasure::ExactEpsf,
            ("telemetry", None) => Countermeasure::Telemetry(TelemetryQuality::DEFAULT),
            ("telemetry-model", None) => Countermeasure::TelemetryModel(TelemetryQuality::DEFAULT),
            ("plate-affine", None) => Countermeasure::Plate {
                model: PlateModel::Affine,
                reference,
                forward: None,
            },
            ("plate-poly", Some(a)) => Countermeasure::Plate {
                model: PlateModel::PolyY(number(a)?),
                reference,
                forward: None,
            },
            ("yzones" | "yzones-shared", a) => Countermeasure::YZones {
                zones: a.map(number).transpose()?,
                shared: head == "yzones-shared",
            },
            _ => return Err(unknown()),
        };
        cm.validate()?;
        Ok(cm)
    }
}

impl Serialize for Countermeasure {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// A validated list of countermeasures to run on each image: no duplicates, at least one.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plan {
    pub countermeasures: Vec<Countermeasure>,
}

impl Default for Plan {
    fn default() -> Self {
        Self {
            countermeasures: vec![Countermeasure::None],
        }
    }
}

impl Plan {
    /// Parse names, give the telemetry and the catalogue-referenced plate models their quality, and
    /// validate: the one place a plan is checked (CLI, sweep files, the explorer).
    pub fn parse<S: AsRef<str>>(
        names: &[S],
        telemetry: TelemetryQuality,
        catalogue_error_mas: f64,
    ) -> Result<Plan, CountermeasureError> {
        let cms = names
            .iter()
            .map(|n| {
                n.as_ref()
                    .parse::<Countermeasure>()
                    .map(|c| c.with_quality(telemetry, catalogue_error_mas))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Plan::new(cms)
    }

    /// A plan of these countermeasures, validated.
    pub fn new(countermeasures: Vec<Countermeasure>) -> Result<Plan, CountermeasureError> {
        if countermeasures.is_empty() {
            return Err(CountermeasureError::Empty);
        }
        for (k, c) in countermeasures.iter().enumerate() {
            c.validate()?;
            if countermeasures[..k]
                .iter()
                .any(|o| o.to_string() == c.to_string())
            {
                return Err(CountermeasureError::Duplicate(c.to_string()));
            }
        }
        Ok(Plan { countermeasures })
    }

    /// The names, as the CSVs write them.
    pub fn names(&self) -> Vec<String> {
        self.countermeasures.iter().map(|c| c.to_string()).collect()
    }

    /// Whether any countermeasure needs the stare's other exposures.
    pub fn needs_stare(&self) -> bool {
        self.countermeasures.iter().any(|c| c.needs_stare())
    }

    /// Whether any countermeasure is referenced to the true positions (`plate-*@oracle`).
    pub fn asks_oracle_plate(&self) -> bool {
        self.countermeasures.iter().any(|c| c.is_oracle_plate())
    }
}

/// What a correction needs from the image beyond its fits.
pub struct Context<'a> {
    pub img: &'a AnalysisImage,
    pub starts: &'a [StarStart],
    pub usable: &'a [bool],
    pub build: &'a BuildOptions,
    /// The global ePSF the fits were made with.
    pub global: &'a Epsf,
    /// Zones of `yzones` without `:K` (the analysis configuration's `epsf_zones`).
    pub default_zones: usize,
    /// The exposure's telemetry; `None` when the ACE is static (nothing to correct).
    pub telemetry: Option<&'a Telemetry>,
    /// The reference positions (this image's pixels) of a plate model: the reference catalogue product for
    /// `plate-*@catalogue`, the true positions for `plate-*@oracle`.
    pub reference: Option<&'a [(f64, f64)]>,
}

/// Replace the star results by their refits (a neighbour found by the global analysis is still a neighbour).
fn take_refits(stars: &mut [StarResult], refits: Vec<crate::analysis::epsf::fit::StarFit>) {
    for (s, f) in stars.iter_mut().zip(refits) {
        s.x = f.x;
        s.y = f.y;
        s.flux_e = f.flux;
        s.crlb_x_px = f.crlb_x;
        s.crlb_y_px = f.crlb_y;
        s.flags = f.flags | (s.flags & flags::BLENDED);
    }
}

/// Refit every star with the telemetry forward model ([`forward`]) of the context's telemetry (none: a static
/// ACE, nothing to refit).
fn forward_refit(ctx: &Context<'_>, stars: &mut [StarResult]) {
    let Some(tel) = ctx.telemetry else {
        return;
    };
    let pd = ctx.img.pixels();
    let model = tel.forward(tel.profile.as_ref().unwrap_or(ctx.global), ctx.img.nx);
    let reach = forward::fit_reach_px(&ctx.build.fit);
    let refits: Vec<_> = stars
        .par_iter()
        .map(|s| {
            let profile = model.star(s.x, s.y, reach, ctx.img.nx, ctx.img.ny);
            fit_star(
                &pd,
                &profile,
                s.x,
                s.y,
                s.flux_e.max(1.0),
                s.sky_e,
                &ctx.build.fit,
            )
        })
        .collect();
    take_refits(stars, refits);
}

/// Apply a correction to the star results of an image; returns the parameters absorbed per exposure.
pub fn apply(
    cm: &Countermeasure,
    ctx: &Context<'_>,
    stars: &mut [StarResult],
) -> Result<usize, CountermeasureError> {
    let pd = ctx.img.pixels();
    match *cm {
        Countermeasure::None => Ok(0),
        Countermeasure::ExactEpsf => Err(CountermeasureError::NotACorrection(cm.to_string())),
        Countermeasure::YZones { zones, shared } => {
            let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
            let z = zones::build_zoned(
                &pd,
                ctx.img.ny,
                ctx.starts,
                ctx.usable,
                ctx.build,
                ctx.global,
                &pos,
                zones.unwrap_or(ctx.default_zones).max(2),
                shared,
            );
            let refits: Vec<_> = stars
                .par_iter()
                .zip(ctx.starts)
                .map(|(s, st)| {
                    fit_star(
                        &pd,
                        &z.at(s.y),
                        s.x,
                        s.y,
                        s.flux_e.max(1.0),
                        st.sky,
                        &ctx.build.fit,
                    )
                })
                .collect();
            take_refits(stars, refits);
            Ok(0)
        }
        Countermeasure::Plate {
            model,
            reference,
            forward,
        } => {
            if forward.is_some() {
                forward_refit(ctx, stars);
            }
            match reference {
                // the stack reference of a stare of one exposure is that exposure: nothing to correct (a
                // stare is corrected by `stack::stack_plate`, which the stare's analysis runs over all its
                // exposures)
                Reference::Stack => Ok(0),
                // a catalogue; or the oracle: the same fit onto the true positions, handed over as a
                // reference named so
                Reference::Catalogue { .. } | Reference::Oracle => match ctx.reference {
                    Some(r) => plate::plate_fit_to_catalogue(stars, r, model, &cm.to_string()),
                    None if reference == Reference::Oracle => {
                        Err(CountermeasureError::NeedsTruth(cm.to_string()))
                    }
                    None => Err(CountermeasureError::NeedsReference(cm.to_string())),
                },
            }
        }
        Countermeasure::TelemetryModel(_) => {
            forward_refit(ctx, stars);
            Ok(0)
        }
        Countermeasure::Telemetry(_) => {
            let Some(tel) = ctx.telemetry else {
                return Ok(0);
            };
            let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
            for (s, (px, py)) in stars.iter_mut().zip(tel.predicted_px(&pos)) {
                s.x -= px;
                s.y -= py;
            }
            Ok(0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_named_errors() {
        for name in [
            "none",
            "yzones",
            "yzones:6",
            "yzones-shared",
            "plate-affine",
            "plate-poly:3",
            "plate-affine@catalogue",
            "plate-poly:3@oracle",
            "telemetry",
            "telemetry-model",
            "telemetry-model+plate-poly:3",
            "telemetry-model+plate-affine@catalogue",
            "exact-epsf",
        ] {
            let c: Countermeasure = name.parse().expect(name);
            assert_eq!(c.to_string(), name);
        }
        for c in Countermeasure::OFFERED {
            assert_eq!(c.to_string().parse::<Countermeasure>(), Ok(c));
        }
        for bad in [
            "plate-poly:x",
            "plate-poly:0",
            "plate-poly:9",
            "yzones:1",
            "zones",
            "none:2",
            "plate-poly:3@truth",
            "none@oracle",
            "telemetry-model@oracle",
            "telemetry-model+none",
            "telemetry-model+telemetry",
            "telemetry-model+plate-poly:0",
        ] {
            let e = bad.parse::<Countermeasure>().expect_err(bad);
            assert!(
                e.to_string().contains(bad.split(':').next().unwrap_or(bad)),
                "{e}"
            );
        }
    }

    #[test]
    fn a_plan_is_validated_once_with_its_qualities() {
        let q = TelemetryQuality {
            noise_mas: 2.0,
            rate_hz: 100.0,
            latency_s: 0.01,
            ..TelemetryQuality::IDEAL
        };
        let p = Plan::parse(
            &[
                "none",
                "plate-poly:3@catalogue",
                "telemetry",
                "plate-affine",
            ],
            q,
            5.0,
        )
        .expect("plan");
        assert_eq!(
            p.names(),
            [
                "none",
                "plate-poly:3@catalogue",
                "telemetry",
                "plate-affine"
            ]
        );
        assert_eq!(p.countermeasures[2], Countermeasure::Telemetry(q));
        assert_eq!(
            p.countermeasures[1],
            Countermeasure::Plate {
                model: PlateModel::PolyY(3),
                reference: Reference::Catalogue { error_mas: 5.0 },
                forward: None,
            }
        );
        // the default reference is the stack, and the stack takes no catalogue error
        assert_eq!(
            p.countermeasures[3],
            Countermeasure::Plate {
                model: PlateModel::Affine,
                reference: Reference::Stack,
                forward: None,
            }
        );
        assert!(p.needs_stare());
        // the forward model before a plate model takes the plan's telemetry quality
        let f = Plan::parse(&["telemetry-model+plate-affine@catalogue"], q, 5.0).expect("plan");
        assert_eq!(
            f.countermeasures[0],
            Countermeasure::Plate {
                model: PlateModel::Affine,
                reference: Reference::Catalogue { error_mas: 5.0 },
                forward: Some(q),
            }
        );
        assert_eq!(f.countermeasures[0].telemetry_quality(), Some(q));
        assert!(!f.needs_stare());
        // a catalogue without error would be the truth under another name
        let e = Plan::parse(&["plate-affine@catalogue"], q, 0.0).expect_err("zero error");
        assert!(e.to_string().contains("@oracle"), "{e}");
        assert_eq!(
            Plan::parse(&["none", "none"], q, 0.0),
            Err(CountermeasureError::Duplicate("none".into()))
        );
        assert_eq!(
            Plan::parse::<&str>(&[], q, 0.0),
            Err(CountermeasureError::Empty)
        );
        for (bad, what) in [
            (TelemetryQuality { rate_hz: 1e7, ..q }, "rate"),
            (TelemetryQuality { rate_hz: 0.0, ..q }, "rate"),
            (
                TelemetryQuality {
                    noise_mas: f64::NAN,
                    ..q
                },
                "noise",
            ),
            (
                TelemetryQuality {
                    latency_s: f64::INFINITY,
                    ..q
                },
                "latency",
            ),
        ] {
            let e = Plan::parse(&["telemetry"], bad, 0.0).expect_err(what);
            assert!(e.to_string().contains(what), "{e}");
        }
        let e = Plan::parse(&["plate-affine@catalogue"], q, -1.0).expect_err("negative error");
        assert!(e.to_string().contains("catalogue error"), "{e}");
    }
}
