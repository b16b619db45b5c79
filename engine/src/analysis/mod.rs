//! Analysis of images: detection, the effective PSF (Anderson & King 2000), fits, countermeasures, the fit's
//! response to jitter, the instant predictor and the accuracy report.

pub mod astrometry;
pub mod countermeasures;
pub mod epsf;
pub mod predict;
pub mod response;
