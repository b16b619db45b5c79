//! Step-stare observation sequences (issue #27's first part): a sequence file ([`spec`]) planned into
//! stares and exposures with their pointings, times and seeds ([`plan`]), and the coverage of the sky it
//! gives ([`coverage`]): how many exposures each position gets; and its run ([`run`]): each exposure
//! simulated and analysed, its catalogue kept, all gathered into one table, with the persistence
//! of the earlier exposures ([`persistence`]) when it is on; the astrometric solution of its products
//! ([`solution`]) and the mission's error budget extrapolated from what it measures ([`budget`]).

pub mod budget;
pub mod coverage;
pub mod persistence;
pub mod plan;
pub mod plan_files;
pub mod reference;
pub mod run;
pub mod slurm;
pub mod solution;
pub mod solve_study;
pub mod spec;

/// The field's sky catalogue in a sequence's output directory (what every exposure reads).
pub const FIELD_NAME: &str = crate::io::products::files::FIELD_CSV;

/// A sequence run failed.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    #[error("sequence: {0}")]
    Invalid(String),
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    #[error(transparent)]
    Simulation(#[from] crate::simulate::SimError),
    #[error(transparent)]
    Source(#[from] crate::session::source::SourceError),
}

pub use coverage::{Coverage, coverage};
pub use plan::{Plan, PlannedExposure, Stare, exposure_config, plan};
pub use spec::Spec;
