//! A dataset's scored results, as the experiment keeps and writes them: per image the scored report of each
//! countermeasure ([`ImageResult`]), and per countermeasure the dataset's summary row ([`Row`]).

use super::image::{Report, ScoredStar};
use serde::Serialize;

/// Result of one countermeasure on one image.
#[derive(Debug, Clone, Serialize)]
pub struct Measured {
    pub countermeasure: String,
    pub report: Report,
}

/// One image's results.
#[derive(Debug, Clone, Serialize)]
pub struct ImageResult {
    pub index: usize,
    pub ace_sigma_mas: f64,
    pub ace_drift_mas: f64,
    pub simulate_s: f64,
    pub analyse_s: f64,
    pub measured: Vec<Measured>,
    /// The scored stars of the plain global-ePSF analysis (kept for image 0, for the vector map).
    #[serde(skip)]
    pub stars: Option<Vec<ScoredStar>>,
}

/// A dataset summary row per countermeasure.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub ace: String,
    pub readout: String,
    pub countermeasure: String,
    pub mag: f64,
    pub accuracy_mas: f64,
    pub sem_mas: f64,
    pub crlb_mas: f64,
    pub predicted_mas: f64,
    pub n_images: usize,
    pub time_s: f64,
}
