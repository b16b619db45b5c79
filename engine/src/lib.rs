//! # JASMINE image simulator and ePSF astrometry engine
//!
//! The data flow is one way; its layers, what each module owns and where to look are in
//! `docs/ARCHITECTURE.md`, which `tests/architecture.rs` holds the code to.
//!
//! Front ends (the `jsim` CLI in `src/bin/jsim`, the explorer in `app/`, the Python module in `python/`)
//! parse, call a [`session::Session`] and print; every number, schema and reduction lives here.
//!
//! ## Conventions (used everywhere)
//! * **Pixels**: 0-based; pixel `(X, Y)` covers `X − ½ ≤ x < X + ½`, so integer coordinates are pixel *centres*.
//!   FITS viewers count from 1 (add 1 for ds9). Images are stored row-major, `data[Y * nx + X]`, Y up.
//! * **Angles on the sky**: milliarcseconds (`_mas`); the plate scale is `206264.806·pitch/focal` arcsec/px.
//! * **Time**: seconds (`_s`) from the start of the ACE series; exposure `i` starts at `first_exposure_start_s + i·cadence`.
//! * **Flux**: electrons (`_e`) until the detector converts to ADU with the gain (`e_per_adu`).
//! * **PSF tables** hold the fraction of the total flux per table cell (they sum to the encircled energy inside
//!   the table), on a square grid with `oversampling` cells per detector pixel whose central node is the optical axis.
//! * **FFT normalisation**: rustfft's unnormalised transforms; every use documents its own scaling.
//! * **Randomness**: every draw comes from a ChaCha stream derived from the run seed and a named stream id
//!   ([`rng`]); the seed is written to every FITS header, and the same seed gives the same image.

pub mod analysis;
pub mod config;
pub mod detector;
pub mod digest;
pub mod error;
pub mod formats;
pub mod instrument;
pub mod integrate;
pub mod io;
pub mod jitter;
pub mod numerics;
pub mod optics;
pub mod photometry;
pub mod readout;
pub mod rng;
pub mod scene;
pub mod scoring;
pub mod session;
pub mod simulate;
pub mod sky;
pub mod solution;
pub mod studies;
#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
pub mod time;
pub mod truth;

pub use config::Config;
pub use error::{Error, Result};

/// Engine version recorded in every output header.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Arcseconds per radian.
pub const ARCSEC_PER_RAD: f64 = 206_264.806_247_096_36;
