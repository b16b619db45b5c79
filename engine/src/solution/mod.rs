//! The astrometric solution (issue #28's core): many exposures' measured positions of the same sources turned
//! into each source's astrometric parameters and each exposure's attitude, anchored to a reference
//! catalogue — from instrument products only (the analysis layer: it never sees the truth).
//!
//! **The model.** Everything lives on one tangent plane of the sequence, in mas. A source's place at an
//! exposure's epoch t (years from the reference epoch) is
//!
//! ```text
//! s = (ξ₀ + μ_ξ t, η₀ + μ_η t) + ϖ (P_ξ(t), P_η(t))
//! ```
//!
//! with P the exposure's parallax factors (the displacement per mas of parallax, from the observer's
//! barycentric position). The exposure sees it through its attitude, a similarity transform about its centre
//! c — offset a, rotation θ and scale 1 + k, written exactly linearly as `o = c + A (s − c) + a` with
//! `A = [[p, −q], [q, p]]`, p = (1 + k) cos θ, q = (1 + k) sin θ. The measured places came through the
//! focal plane's design model; with [`Options::calibration`] the solution also solves what the instrument does
//! differently — each array's affine offsets and a global distortion polynomial ([`calibration`]) — as a
//! third block.
//!
//! **The solution** is Gaia's AGIS in miniature (Lindegren et al. 2012; [`Method`]): with the attitudes
//! fixed every source is a small weighted least-squares fit of its own observations (plus its
//! reference-catalogue entry as a prior, which anchors the frame); with the sources fixed every exposure's
//! (p, q, a) is one too (with a calibration, the third block follows the attitudes). The block iteration
//! alternates them until nothing moves by more than `tolerance_mas`; the default, conjugate gradients
//! preconditioned by the same blocks ([`cg`]), solves all of them at once until no update exceeds
//! `tolerance_sigma` of its formal error. Then observations beyond `clip_sigma` are rejected and it runs
//! again. A source's covariance is its block's, the attitudes held fixed (with hundreds of sources per
//! exposure the attitude's share is small; the χ² test in `tests` checks the pulls).
//!
//! **The frame.** A uniform shift, rotation or scale of every source — and for a sequence over time, a
//! uniform proper motion or parallax — is absorbed by the attitudes: only the reference catalogue fixes
//! them, so with several epochs its entries must carry proper motions and parallaxes (a survey such as Gaia's
//! does), and at least two sources must be anchored.

mod blocks;
pub mod calibration;
mod cg;
pub mod checkpoint;
pub mod excess;
pub mod feed;
mod groups;
#[cfg(feature = "mpi")]
pub mod mpi;
pub mod ranks;
mod solve;
mod tiles;

pub use calibration::{Calibration, CalibrationModel};
pub use checkpoint::CheckpointStore;
pub use excess::{ExcessBin, ExcessNoise};
pub use ranks::{Ranks, Single};
pub use solve::{Checkpointing, solve, solve_on, solve_with};

/// One measured position of a source in one exposure, on the tangent plane (mas), with its 1σ error per axis.
///
/// Held compactly, 48 bytes, since a solution holds every one of them (≈ 7 × 10⁹ at the mission's size): the
/// exposure and source as `u32` (an index beyond `u32::MAX` saturates there, and the solver's range check
/// refuses it), the array as `u16` and the design focal-plane place as `f32` — 2 × 10⁻⁴ px at 4 000 px from
/// the axis, where the calibration's correction changes by < 10⁻⁸ px (its gradient is ≲ 10⁻⁵ px per px).
/// The plane places and the error stay `f64`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub xi_mas: f64,
    pub eta_mas: f64,
    pub sigma_mas: f64,
    exposure: u32,
    source: u32,
    focal_px: [f32; 2],
    array: u16,
}

const _: () = assert!(std::mem::size_of::<Observation>() == 48);

/// `i` as a compact index: itself, or the type's maximum where it does not fit (refused downstream).
fn compact<T: TryFrom<usize> + Bounded>(i: usize) -> T {
    T::try_from(i).unwrap_or(T::MAX)
}

/// The largest value of a compact index type.
trait Bounded {
    const MAX: Self;
}
impl Bounded for u32 {
    const MAX: Self = u32::MAX;
}
impl Bounded for u16 {
    const MAX: Self = u16::MAX;
}

impl Observation {
    /// Source `source` seen in exposure `exposure` on array `array` at `plane_mas` (ξ, η) ± `sigma_mas`, at
    /// the design focal-plane place `focal_px` (px from the optical axis; only the calibration reads it and
    /// the array).
    pub fn new(
        exposure: usize,
        source: usize,
        plane_mas: [f64; 2],
        sigma_mas: f64,
        array: usize,
        focal_px: [f64; 2],
    ) -> Self {
        Self {
            xi_mas: plane_mas[0],
            eta_mas: plane_mas[1],
            sigma_mas,
            exposure: compact(exposure),
            source: compact(source),
            focal_px: [focal_px[0] as f32, focal_px[1] as f32],
            array: compact(array),
        }
    }
    /// The exposure it was measured in.
    pub fn exposure(&self) -> usize {
        self.exposure as usize
    }
    /// The source it measures.
    pub fn source(&self) -> usize {
        self.source as usize
    }
    /// The array it was measured on (0 … arrays − 1; only the calibration reads it).
    pub fn array(&self) -> usize {
        self.array as usize
    }
    /// Its design focal-plane position, px from the optical axis (only the calibration reads it).
    pub fn focal_px(&self) -> [f64; 2] {
        [self.focal_px[0] as f64, self.focal_px[1] as f64]
    }
    /// The same measurement given to source `source` (a renumbering of the sources).
    pub fn with_source(mut self, source: usize) -> Self {
        self.source = compact(source);
        self
    }
    /// The same measurement given to exposure `exposure` (a renumbering of the exposures).
    pub fn with_exposure(mut self, exposure: usize) -> Self {
        self.exposure = compact(exposure);
        self
    }
    /// The same measurement on array `array`.
    pub fn with_array(mut self, array: usize) -> Self {
        self.array = compact(array);
        self
    }
}

/// What the solution knows of an exposure (never its attitude error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureGeometry {
    /// Its epoch, years from the reference epoch.
    pub t_yr: f64,
    /// (P_ξ, P_η): the displacement of a source on the plane per mas of parallax at this epoch.
    pub parallax_factor: [f64; 2],
    /// The point its attitude turns and scales about (its pointing), mas.
    pub centre_mas: [f64; 2],
    /// Its design map from focal-plane px to the plane's mas (row-major 2 × 2: scale, position angle and the
    /// sky's handedness; only the calibration reads it).
    pub to_plane: [f64; 4],
    /// The stare it belongs to: the exposures of one pointing within one visit, which see a source on the
    /// same pixels among the same neighbours (only the excess noise reads it, [`ExcessNoise`]).
    pub stare: usize,
    /// The visit it belongs to: the stares of one season (only the excess noise reads it).
    pub visit: usize,
}

impl ExposureGeometry {
    /// Where a source of parameters `p` is at this exposure's epoch:
    /// `(ξ₀ + μ_ξ t + ϖ P_ξ, η₀ + μ_η t + ϖ P_η)`, mas.
    pub fn place(&self, p: &Params) -> [f64; 2] {
        [
            p[0] + p[2] * self.t_yr + p[4] * self.parallax_factor[0],
            p[1] + p[3] * self.t_yr + p[4] * self.parallax_factor[1],
        ]
    }
}

/// A reference-catalogue entry of a source: its parameters at the reference epoch with their 1σ errors
/// ([`Params`]' order: ξ₀, η₀ mas; μ_ξ, μ_η mas/yr; ϖ mas). An error of 0 or ∞ leaves that parameter free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    pub source: usize,
    pub params: Params,
    pub sigma: Params,
}

/// A source's astrometric parameters: [ξ₀, η₀, μ_ξ, μ_η, ϖ] (mas, mas, mas/yr, mas/yr, mas).
pub type Params = [f64; 5];

/// Which of a source's parameters are solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceModel {
    /// Position only (one epoch, or a short sequence): ξ₀, η₀.
    Position,
    /// Position, proper motion and parallax.
    Full,
}

impl SourceModel {
    /// How many parameters a source has.
    pub fn len(self) -> usize {
        match self {
            SourceModel::Position => 2,
            SourceModel::Full => 5,
        }
    }

    /// Never empty (for clippy's `len` rule).
    pub fn is_empty(self) -> bool {
        false
    }

    /// The model a front end names: `position` or `full`. The error says what is allowed; each front end
    /// puts its own option's name before it.
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "position" => Ok(SourceModel::Position),
            "full" => Ok(SourceModel::Full),
            _ => Err(format!("{name:?}: allowed position, full")),
        }
    }

    /// [`SourceModel::parse`], or `auto` as None: chosen from the sequence's span (by the sequence's
    /// solution study).
    pub fn parse_or_auto(name: &str) -> Result<Option<Self>, String> {
        match name {
            "auto" => Ok(None),
            _ => Self::parse(name)
                .map(Some)
                .map_err(|_| format!("{name:?}: allowed auto, position, full")),
        }
    }
}

/// How the joint least-squares problem is iterated to its solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// The block iteration (Gauss–Seidel over the blocks, AGIS's "simple iteration", Lindegren et al. 2012
    /// §5.2): sources with the instrument held, then the instrument with the sources held. Its iterations
    /// grow with the exposures; kept as the reference the accelerated one is checked against.
    Block,
    /// Conjugate gradients on the normal equations of all unknowns at once, preconditioned by the same
    /// blocks (source, exposure, calibration: Bombrun et al. 2012, A&A 538, A77), inside a Gauss–Newton
    /// loop for the attitude's bilinear term. The default.
    #[default]
    ConjugateGradient,
}

/// The solution's knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    pub model: SourceModel,
    pub method: Method,
    /// Iterations at most per rejection round: the block iteration's alternations, or the conjugate
    /// gradients' steps (each one pass over the observations).
    pub max_iterations: usize,
    /// The block iteration stops when no source and no exposure's offset moves by more than this, mas.
    pub tolerance_mas: f64,
    /// The conjugate gradients stop when the largest update of any unknown is below this fraction of its
    /// formal error (its preconditioner block's σ).
    pub tolerance_sigma: f64,
    /// Reject an observation whose normalised residual exceeds this (per axis, in its σ); 0 keeps all.
    pub clip_sigma: f64,
    /// Rounds of rejection at most.
    pub max_rejection_rounds: usize,
    /// The calibration unknowns solved (none by default).
    pub calibration: CalibrationModel,
    /// L, px: the calibration's focal-plane positions are in units of it (a focal plane's reach keeps its
    /// terms of order 1 and the fit well conditioned).
    pub focal_norm_px: f64,
    /// The error beyond each observation's σ that the sources' formal errors carry (none by default).
    pub excess: ExcessNoise,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            model: SourceModel::Full,
            method: Method::ConjugateGradient,
            max_iterations: 500,
            tolerance_mas: 1e-7,
            tolerance_sigma: 1e-3,
            clip_sigma: 5.0,
            max_rejection_rounds: 5,
            calibration: CalibrationModel::NONE,
            focal_norm_px: calibration::DEFAULT_FOCAL_NORM_PX,
            excess: ExcessNoise::None,
        }
    }
}

/// An exposure's solved attitude: `o = c + A (s − c) + a`, A = [[p, −q], [q, p]].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    pub p: f64,
    pub q: f64,
    pub offset_mas: [f64; 2],
}

impl Attitude {
    pub const IDENTITY: Attitude = Attitude {
        p: 1.0,
        q: 0.0,
        offset_mas: [0.0, 0.0],
    };

    /// The rotation, rad.
    pub fn roll_rad(&self) -> f64 {
        self.q.atan2(self.p)
    }

    /// The scale error k (1 + k = |A|^½).
    pub fn scale_error(&self) -> f64 {
        self.p.hypot(self.q) - 1.0
    }

    /// Where this exposure sees a source at `s` (mas), about centre `c`.
    pub fn apply(&self, c: [f64; 2], s: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (s[0] - c[0], s[1] - c[1]);
        [
            c[0] + self.p * dx - self.q * dy + self.offset_mas[0],
            c[1] + self.q * dx + self.p * dy + self.offset_mas[1],
        ]
    }

    /// The source position an observation `o` at centre `c` means (the inverse of [`Attitude::apply`]).
    pub fn invert(&self, c: [f64; 2], o: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (
            o[0] - c[0] - self.offset_mas[0],
            o[1] - c[1] - self.offset_mas[1],
        );
        let det = self.p * self.p + self.q * self.q;
        [
            c[0] + (self.p * dx + self.q * dy) / det,
            c[1] + (-self.q * dx + self.p * dy) / det,
        ]
    }
}

/// A solved source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolvedSource {
    /// Its parameters (those the model does not solve are 0, or its reference's).
    pub params: Params,
    /// Their 1σ errors (the block's covariance; NaN where not solved).
    pub sigma: Params,
    /// Observations used (after rejection).
    pub observations: usize,
    /// Σ of its normalised squared residuals.
    pub chi2: f64,
}

/// The solution.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    pub sources: Vec<SolvedSource>,
    /// Each exposure's attitude (NaN for one left out).
    pub attitudes: Vec<Attitude>,
    /// Exposures left out, in rising order: each saw fewer than two sources tied to the reference catalogue
    /// or to another exposure (none at all, say), so its attitude is undetermined.
    pub skipped_exposures: Vec<usize>,
    /// The calibration solved (zero when none was asked).
    pub calibration: Calibration,
    /// Block alternations over all rounds.
    pub iterations: usize,
    /// The last round stopped at the tolerance (not at `max_iterations`).
    pub converged: bool,
    /// Observations rejected as outliers.
    pub rejected: usize,
    /// χ² of the observations kept over its degrees of freedom (NaN when none are left).
    pub chi2_per_dof: f64,
    /// The error shared within a stare, per bin of per-observation σ, that the sources' σ carry
    /// ([`Options::excess`]; empty when none is asked or too few sources are seen in two stares).
    pub excess: Vec<ExcessBin>,
}

/// A list of indices for a message: all of them up to ten, else the first ten and the count.
fn list_of(v: &[usize]) -> String {
    let shown: Vec<String> = v.iter().take(10).map(|e| e.to_string()).collect();
    if v.len() > 10 {
        format!("{} … ({} in all)", shown.join(", "), v.len())
    } else {
        shown.join(", ")
    }
}

/// A solution that cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolutionError {
    #[error("observation {index}: {field} is {value} (must be finite{extra})")]
    NotFinite {
        index: usize,
        field: &'static str,
        value: f64,
        extra: &'static str,
    },
    #[error("observation {index}: {what} {value} is out of range (0 … {limit})")]
    OutOfRange {
        index: usize,
        what: &'static str,
        value: usize,
        limit: usize,
    },
    #[error("source {source_id} is observed twice in exposure {exposure} (duplicate ids)")]
    Duplicate { source_id: usize, exposure: usize },
    #[error(
        "no exposure shares 2 sources with the rest of the sequence and the reference catalogue ({0} \
         exposures): no attitude is determined (no overlap)"
    )]
    NoOverlap(usize),
    #[error("{0} reference sources anchor the frame: at least 2 are needed")]
    TooFewReferences(usize),
    #[error(
        "exposures {} are tied to one another but not to the rest, and hold {anchors} reference source(s): their \
         frame (shift, turn, scale) is undetermined — a singular gauge; add reference stars there, or leave those \
         exposures out",
        list_of(exposures)
    )]
    UnanchoredGroup {
        exposures: Vec<usize>,
        anchors: usize,
    },
    #[error(
        "the sequence spans {span_yr:.3} yr: proper motions and parallaxes are unconstrained (degenerate); solve \
         positions only (SourceModel::Position) or observe over more epochs"
    )]
    Degenerate { span_yr: f64 },
    #[error(
        "every exposure points within {spread_mas:.0} mas of the others: a global distortion is unconstrained \
         (each source is seen at one place of the focal plane: degenerate); dither the pattern, or solve the \
         arrays' offsets alone (distortion order 0)"
    )]
    DistortionUnconstrained { spread_mas: f64 },
    #[error(
        "the calibration cannot be solved: array {0} (or a distortion term) has no observation that constrains \
         it"
    )]
    CalibrationUnconstrained(usize),
    #[error("solution option {field} = {value}: allowed {allowed}")]
    Knob {
        field: &'static str,
        value: f64,
        allowed: &'static str,
    },
    #[error("calibration: {field} = {value}: allowed {allowed}")]
    CalibrationModel {
        field: &'static str,
        value: f64,
        allowed: &'static str,
    },
    #[error(
        "the reference catalogue must carry proper motions and parallaxes (with errors) to anchor {0}"
    )]
    FrameUnanchored(&'static str),
    #[error("solution checkpoint {path}: {why}")]
    Checkpoint { path: String, why: String },
    #[error(
        "the solution was interrupted after {0} checkpoint(s), as asked (interrupt_after): rerun with the same \
         checkpoint to resume"
    )]
    Interrupted(usize),
}

#[cfg(test)]
mod tests {
    use super::SourceModel;

    #[test]
    fn a_source_model_is_parsed_once_for_every_front_end() {
        assert_eq!(SourceModel::parse("full"), Ok(SourceModel::Full));
        assert_eq!(
            SourceModel::parse_or_auto("position"),
            Ok(Some(SourceModel::Position))
        );
        assert_eq!(SourceModel::parse_or_auto("auto"), Ok(None));
        let e = SourceModel::parse("auto").expect_err("no auto here");
        assert_eq!(e, "\"auto\": allowed position, full");
        let e = SourceModel::parse_or_auto("five").expect_err("unknown");
        assert_eq!(e, "\"five\": allowed auto, position, full");
    }
}
