//! Attitude-control-error (ACE) jitter: the PSD model, time series from it, and a Welch estimator to
//! check one against the other (SPEC §3).

pub mod psd;
pub mod series;
pub mod welch;

pub use psd::Psd;
pub use series::AceSeries;
