//! Studies built on the pipeline: the paper's experiment, the speed-against-error benchmarks and the Monte
//! Carlo sweeps.

pub mod bench;
pub mod bench_field;
pub mod bench_forward;
pub mod bench_persistence;
pub mod bench_solution;
pub mod crowded;
pub mod experiment;
pub mod predict;
pub mod predict_shape;
pub mod sequence;
pub mod sweep;
pub mod transit;
