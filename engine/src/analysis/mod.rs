//! Analysis of images: detection, the effective PSF (Anderson & King 2000), fits, countermeasures, the fit's
//! response to jitter, the accuracy report and the deviation vector map — and the
//! one per-image [`pipeline`] that runs them in order; the astrometric [`solution`] of many exposures; the
//! light curves of transit photometry ([`lightcurve`]: binned scatter, box least squares).

pub mod countermeasures;
pub mod crowded;
pub mod crowding;
pub mod detection;
pub mod epsf;
pub mod image;
pub mod lacosmic;
pub mod lightcurve;
pub mod pipeline;
pub mod registration;
pub mod repeat;
pub mod report;
pub mod response;
pub mod sky;
pub mod stare_photometry;

pub use image::AnalysisImage;
pub use pipeline::{Analysis, ImageAnalysis, Options, Supplied, analyse_image};
pub use report::{Report, StarResult};

/// An analysis failure.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error("no star detected above {0} σ")]
    NoStars(f64),
    #[error("countermeasure: {0}")]
    Countermeasure(#[from] countermeasures::CountermeasureError),
    #[error(
        "the telemetry correction needs the image's readout timing (headers READOUT, PIXTIME, TOVERHD, EXPTIME, \
         or a simulator's): none was given"
    )]
    NoReadoutTiming,
    #[error(
        "{countermeasure} does not apply to this image (exact-epsf needs a static-ACE image simulated by jsim)"
    )]
    NotApplicable { countermeasure: String },
    #[error(
        "{countermeasure} is not offered for a crowded field (yzones and exact-epsf refit single stars, a stack \
         reference needs a stare; offered: none, plate-*@catalogue with the reference catalogue, \
         plate-*@oracle on a simulated exposure, telemetry with the telemetry product)"
    )]
    NotInCrowdedField { countermeasure: String },
}
