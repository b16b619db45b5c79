//! The engine worker: one named thread owns the engine [`Session`](engine::session::Session) and runs the
//! jobs the UI sends over a bounded channel, cheapest preview first:
//!
//! 1. **predict** — the instant accuracy predictor for the current configuration (no image simulated);
//! 2. **image** — one simulated frame and its analysis through the engine's per-image pipeline (with the
//!    chosen countermeasure), the ACE series around that exposure with the Welch PSD of the generated
//!    series, and the Gaussian-ACE twin frame;
//! 3. **curve** — the accuracy-vs-magnitude curve: the predictor at every magnitude first, then the Monte
//!    Carlo datasets (`fidelity.images` images per magnitude, as `jsim experiment` runs them).
//!
//! Every job carries a generation number. The UI bumps the shared `latest` generation whenever a control
//! moves (or Cancel is pressed); the worker checks it between engine calls and abandons stale work, and the
//! UI drops any message of an old generation. No physics here: everything is an engine call.
//!
//! * [`protocol`] — the request, the job, the results and the messages;
//! * [`thread`] — the thread, its channel and the generation counter;
//! * [`out`] — where a running job reports, and how it stops;
//! * [`stages`] — the engine calls of the predict, image and twin stages; [`curve`] — the curve stage;
//! * [`views`] — reductions for drawing (envelopes, log bins, display limits).

pub mod curve;
pub mod out;
pub mod protocol;
pub mod stages;
pub mod thread;
pub mod transit;
pub mod views;

pub use protocol::{
    ArrayFits, CrowdedResult, CurvePoint, FittedStar, FocalPlaneArray, FocalPlaneResult,
    FrameResult, Job, Msg, Prediction, Request, SeriesView, Stage, Stages, TwinResult,
};
pub use thread::Worker;
