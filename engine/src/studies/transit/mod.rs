//! Transit photometry, JASMINE's second science case: a bright M dwarf stared at for hours with its
//! comparison stars, read in windows ([`observe`]), measured plate by plate
//! ([`crate::analysis::stare_photometry`]), its precision against the noise budget ([`budget`]) and the
//! transit searched for ([`search`], [`run`]).

pub mod budget;
pub mod observe;
pub mod outputs;
pub mod precision;
pub mod run;
pub mod search;
pub mod spec;

pub use observe::{Observation, StareError, observe};
pub use spec::Spec;
