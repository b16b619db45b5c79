//! `jsim sweep`, `jsim merge`, `jsim report`: Monte Carlo sweeps, sharded, resumable, and their reports.
//! (Stub: to be implemented.)

use anyhow::{Result, bail};
use clap::Args;
use std::path::PathBuf;

/// `jsim sweep`
#[derive(Args, Clone, Debug)]
pub struct SweepArgs {
    /// Sweep file (TOML).
    #[arg(long)]
    pub config: PathBuf,
    #[arg(long, default_value = "out/sweep")]
    pub out: PathBuf,
}

/// `jsim merge`
#[derive(Args, Clone, Debug)]
pub struct MergeArgs {
    /// Sweep output directory.
    pub dir: PathBuf,
}

/// `jsim report`
#[derive(Args, Clone, Debug)]
pub struct ReportArgs {
    /// Sweep output directory.
    pub dir: PathBuf,
}

pub fn sweep(_a: &SweepArgs) -> Result<()> {
    bail!("jsim sweep is not implemented yet")
}

pub fn merge(_a: &MergeArgs) -> Result<()> {
    bail!("jsim merge is not implemented yet")
}

pub fn report(_a: &ReportArgs) -> Result<()> {
    bail!("jsim report is not implemented yet")
}
