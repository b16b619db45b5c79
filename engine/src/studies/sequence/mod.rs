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
pub mod reference;
pub mod run;
pub mod slurm;
pub mod solution;
pub mod spec;

pub use coverage::{Coverage, coverage};
pub use plan::{Plan, PlannedExposure, Stare, exposure_config, plan};
pub use spec::Spec;
