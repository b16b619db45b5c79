//! Analysis of images: detection, the effective PSF (Anderson & King 2000), fits, countermeasures, the fit's
//! response to jitter, the instant predictor, the accuracy report and the deviation vector map — and the
//! one per-image [`pipeline`] that runs them in order.

pub mod countermeasures;
pub mod crowded;
pub mod crowding;
pub mod detection;
pub mod epsf;
pub mod image;
pub mod pipeline;
pub mod predict;
pub mod report;
pub mod response;
pub mod vectors;

pub use image::AnalysisImage;
pub use pipeline::{Analysis, ImageAnalysis, Options, Source, analyse_image};
pub use report::{Report, StarResult};

/// An analysis failure.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error("no star detected above {0} σ")]
    NoStars(f64),
    #[error("countermeasure: {0}")]
    Countermeasure(#[from] countermeasures::CountermeasureError),
    /// What the analysis asked of the simulation the image came from (its kernel, its stars).
    #[error(transparent)]
    Simulation(#[from] crate::simulate::SimError),
    #[error(
        "{countermeasure} does not apply to this image (exact-epsf needs a static-ACE image simulated by jsim)"
    )]
    NotApplicable { countermeasure: String },
    #[error(
        "{countermeasure} is not offered for a crowded field here (yzones and exact-epsf refit single stars; \
         the analysis of an image offers none, plate-*@catalogue, and plate-*@oracle with a truth; the \
         telemetry correction needs a single array's simulation: `jsim crowded` applies it)"
    )]
    NotInCrowdedField { countermeasure: String },
}
