//! The JASMINE astrometry explorer: an egui/eframe front end over the `engine` crate.
//!
//! * [`app`] — the one struct of parameters (the engine `Config` + view settings) and runtime state;
//! * [`worker`] — the named engine thread: jobs in, results out, stale generations dropped;
//! * [`panels`] — free functions drawing the controls, the frame, the close-ups and the plots;
//! * [`view`] — stretches and colour maps (presentation only).
//!
//! All physics is in `engine`; the app only wires controls to it and draws what it returns.

pub mod app;
pub mod panels;
pub mod view;
pub mod worker;

pub use app::ExplorerApp;
