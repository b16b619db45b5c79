//! The JASMINE astrometry explorer: an egui/eframe front end over the `engine` crate.
//!
//! * [`app`] — the app: its settings and runtime state, the frame loop, the scheduling of work;
//! * [`settings`] — what the user set (the engine `Config`, the countermeasure, the curve's magnitudes, the
//!   view settings), persisted across restarts;
//! * [`state`] — what the panels read besides the settings: results, the work's status, what is on screen;
//! * [`action`] — what the panels ask the app to do;
//! * [`panels`] — free functions drawing the controls, the frame, the close-ups and the plots;
//! * [`reproduce`] — the configuration file and the `jsim` commands that reproduce a view;
//! * [`worker`] — the named engine thread: jobs in, results out, stale generations dropped;
//! * [`view`] — stretches and colour maps (presentation only).
//!
//! All physics is in `engine`; the app only wires controls to it and draws what it returns.

pub mod action;
pub mod app;
pub mod panels;
pub mod reproduce;
pub mod settings;
pub mod state;
pub mod view;
pub mod worker;

pub use app::ExplorerApp;
