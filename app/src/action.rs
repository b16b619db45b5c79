//! What the panels ask the app to do: they draw from the state they are given and return these; `app.rs`
//! performs them after the frame is drawn.

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Load the configuration file at the path on screen.
    Open,
    /// Read the sequence directory on screen and show its products.
    OpenSequence,
    /// Write the configuration of what is on screen.
    Save,
    /// Save, then copy the `jsim experiment` / `jsim simulate` command that reproduces it.
    CopyExperimentCli,
    CopySimulateCli,
    /// Abandon the running work.
    Cancel,
    /// Recompute everything for the parameters on screen.
    RunAll,
    /// Run the magnitude curve.
    RunCurve,
}
