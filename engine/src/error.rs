//! The engine's error: one variant per module's own error type, each kept whole as the source (`#[from]`,
//! never flattened to text), so a caller can match on what failed and `{:#}`/`source()` shows the chain.

use crate::analysis::AnalysisError;
use crate::analysis::countermeasures::CountermeasureError;
use crate::config::ConfigError;
use crate::integrate::gpu::GpuError;
use crate::integrate::kernel::KernelError;
use crate::io::IoError;
use crate::io::plot::PlotError;
use crate::scene::SceneError;
use crate::session::SourceError;
use crate::simulate::SimError;
use crate::studies::bench::BenchError;
use crate::studies::experiment::ExperimentError;
use crate::studies::predict::PredictError;
use crate::studies::sweep::SweepError;

/// Any failure of the engine.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Kernel(#[from] KernelError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Simulation(#[from] SimError),
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error(transparent)]
    Countermeasure(#[from] CountermeasureError),
    #[error(transparent)]
    Predict(#[from] PredictError),
    #[error(transparent)]
    Source(#[from] SourceError),
    #[error(transparent)]
    Io(#[from] IoError),
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error(transparent)]
    Experiment(#[from] ExperimentError),
    #[error(transparent)]
    Bench(#[from] BenchError),
    #[error(transparent)]
    Sweep(#[from] SweepError),
}

/// A result with the engine's error.
pub type Result<T> = std::result::Result<T, Error>;
