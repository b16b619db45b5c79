//! What the UI and the engine thread say to each other: the [`Request`] (everything the results depend on),
//! the [`Job`] (a request, the stages to run and its generation), the results and the [`Msg`]s that carry
//! them back. Plain data: no engine call here.

use engine::analysis::countermeasures::{Countermeasure, CountermeasureError, Plan};
use engine::analysis::epsf::Epsf;
use engine::config::Config;
use engine::scoring::image::{Report, ScoredStar};
use engine::scoring::vectors::{Arrow, VectorMap};
use engine::studies::experiment::Row;
use std::sync::Arc;

/// What the UI wants computed: everything the results depend on.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub cfg: Config,
    pub countermeasure: Countermeasure,
    /// Which exposure of the dataset the frame panels show.
    pub image_index: usize,
    /// Magnitudes of the accuracy curve.
    pub mags: Vec<f64>,
}

impl Request {
    /// The plan of this request: the plain analysis, plus the chosen countermeasure.
    pub fn plan(&self) -> Result<Plan, CountermeasureError> {
        let mut cms = vec![Countermeasure::None];
        if self.countermeasure != Countermeasure::None {
            cms.push(self.countermeasure);
        }
        Plan::new(cms)
    }

    /// What the accuracy curve depends on (the magnitude of the single image excepted).
    pub fn curve_key(&self) -> String {
        let mut c = self.cfg.clone();
        c.scene.mag_hw = 0.0;
        let mags: Vec<String> = self.mags.iter().map(|m| m.to_string()).collect();
        format!(
            "{}|{}|{}",
            c.hash_hex(),
            self.countermeasure,
            mags.join(",")
        )
    }
}

/// Which stages a job runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stages {
    pub predict: bool,
    pub image: bool,
    pub curve: bool,
}

impl Stages {
    pub const ALL: Stages = Stages {
        predict: true,
        image: true,
        curve: true,
    };
    pub fn union(self, o: Stages) -> Stages {
        Stages {
            predict: self.predict || o.predict,
            image: self.image || o.image,
            curve: self.curve || o.curve,
        }
    }
    pub fn any(self) -> bool {
        self.predict || self.image || self.curve
    }
}

/// One unit of work.
#[derive(Debug, Clone)]
pub struct Job {
    pub generation: u64,
    pub request: Request,
    pub stages: Stages,
}

/// The stage a message or progress report belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Predict,
    Image,
    Twin,
    Curve,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Predict => "prediction",
            Stage::Image => "frame + analysis",
            Stage::Twin => "Gaussian twin",
            Stage::Curve => "magnitude curve",
        }
    }
}

/// The instant predictor's answer for the current configuration.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub generation: u64,
    pub cfg_hash: String,
    /// What the prediction models, when it is not the displayed configuration itself (the quad focal
    /// plane: an isolated star of one array at the explorer's magnitude).
    pub models: Option<String>,
    pub countermeasure: Countermeasure,
    pub image_index: usize,
    /// Dataset mean of the predicted single-image accuracy (mas), chosen countermeasure and `none`.
    pub dataset_mas: f64,
    pub dataset_none_mas: f64,
    /// Predicted accuracy of the displayed image (mas).
    pub image_mas: f64,
    /// Noise floor of the displayed image (mas): the predictor's figure for the exact-ePSF control, the
    /// phase-averaged Cramér–Rao bound of a star blurred by this exposure's ACE.
    pub noise_floor_mas: f64,
    pub elapsed_s: f64,
}

/// The ACE series around the displayed exposure and the Welch estimate of the generated series' PSD.
#[derive(Debug, Clone)]
pub struct SeriesView {
    pub generation: u64,
    /// The configuration the series was generated with (its readout windows, its ACE model).
    pub cfg: Config,
    pub cfg_hash: String,
    pub image_index: usize,
    /// Min/max envelope of x and y (mas) over the exposure cycle, times relative to the exposure start (s);
    /// empty for a static ACE (no series).
    pub x: Vec<[f64; 2]>,
    pub y: Vec<[f64; 2]>,
    /// Welch PSD of the x series in the model PSD's units (`engine::jitter::welch::welch_in_model_units`:
    /// the generator's own factor removed, nothing fitted), log-binned: `[log10 f, log10 psd]`.
    pub welch_log: Vec<[f64; 2]>,
    /// mas²/Hz of the series per model-PSD unit (x axis), when the generator's factor could be recovered.
    pub model_gain: Option<f64>,
    /// Achieved σ of the series under its convention (mas).
    pub achieved_sigma_mas: (f64, f64),
}

/// One simulated frame and its analysis.
#[derive(Debug, Clone)]
pub struct FrameResult {
    pub generation: u64,
    /// The configuration this frame was simulated and analysed with: its readout windows, channels, plate
    /// scale and star grid are what the panels draw, whatever is on screen now.
    pub cfg: Config,
    /// [`Config::hash_hex`] of `cfg`.
    pub cfg_hash: String,
    pub image_index: usize,
    pub countermeasure: Countermeasure,
    pub n: usize,
    pub adu: Vec<f32>,
    pub dq: Vec<u8>,
    /// Display limits: a low quantile (≈ sky) and the maximum, ADU.
    pub lo_adu: f32,
    pub hi_adu: f32,
    /// Sky noise estimate (ADU), for the asinh/log softening.
    pub noise_adu: f32,
    /// True star positions (px).
    pub truth_xy: Vec<(f64, f64)>,
    /// Report and star results under the chosen countermeasure.
    pub report: Report,
    pub stars: Vec<ScoredStar>,
    /// Report of the plain analysis (global ePSF, no countermeasure).
    pub report_none: Report,
    pub epsf: Epsf,
    /// The engine's deviation vector map of `stars` (measured arrows, per-axis accuracy, reference arrow).
    pub vectors: VectorMap,
    /// The fit displacement the ACE predicts for every used star (the mechanism; mean removed, mas): the
    /// predicted arrows of the plain analysis' vector map.
    pub predicted: Vec<Arrow>,
    pub t_start_s: f64,
    pub backend: String,
    /// Why the backend is not the one asked for, when the engine said so.
    pub backend_note: Option<String>,
    pub simulate_s: f64,
    pub analyse_s: f64,
}

/// One exposure of the quad focal plane, for the focal-plane view: each array's image turned into
/// focal-plane axes (so the view lays the four side by side as they sit on the sky), its WCS and its stars.
#[derive(Debug, Clone)]
pub struct FocalPlaneResult {
    pub generation: u64,
    pub cfg: Config,
    pub cfg_hash: String,
    pub image_index: usize,
    /// The layout (array size, gap, turns): where each array sits; `locate` says what is under the cursor.
    pub plane: engine::sky::focal_plane::FocalPlane,
    pub arrays: Vec<FocalPlaneArray>,
    /// Where the scene's stars fell (photosensitive, border, gap, off, duplicates).
    pub counts: Option<engine::scene::PlacementCounts>,
    /// Display limits shared by the arrays: low quantile, maximum and sky noise, ADU.
    pub lo_adu: f32,
    pub hi_adu: f32,
    pub noise_adu: f32,
    pub backend: String,
    pub simulate_s: f64,
}

/// One array of a [`FocalPlaneResult`].
#[derive(Debug, Clone)]
pub struct FocalPlaneArray {
    /// ADU in the array's own pixel axes (what the cursor reads) and turned into focal-plane axes (what is
    /// drawn), row-major, `plane.array_px` square.
    pub adu: Vec<f32>,
    pub adu_fp: Vec<f32>,
    /// Its WCS (pixel → RA, Dec); `None` if the engine could not make it.
    pub wcs: Option<Arc<engine::sky::wcs::ArrayWcs>>,
    /// Its stars on photosensitive pixels, in focal-plane pixels.
    pub stars_fp: Vec<(f64, f64)>,
}

/// The crowded-field analysis of the focal plane's exposure ([`engine::studies::crowded`]): every array
/// analysed with its own ePSF and the chosen countermeasure, binned by true Hw over the arrays, with each
/// array's deviation map in focal-plane axes.
#[derive(Debug, Clone)]
pub struct CrowdedResult {
    pub generation: u64,
    pub cfg_hash: String,
    pub image_index: usize,
    /// The countermeasure shown, and why it is not the one chosen (one that refits single stars).
    pub countermeasure: String,
    pub note: Option<String>,
    pub plane: engine::sky::focal_plane::FocalPlane,
    pub bins: Vec<engine::scoring::crowded::MagBin>,
    /// Per array: (f_x, f_y, dx_mas, dy_mas) per cell ([`engine::studies::crowded::ArrayAnalysis::binned_vectors`]).
    pub vectors: Vec<Vec<(f64, f64, f64, f64)>>,
    pub summaries: Vec<engine::studies::crowded::CrowdedSummary>,
    /// Per array: its ePSF and its fitted stars (what a click on the focal plane picks).
    pub fits: Vec<ArrayFits>,
    pub analyse_s: f64,
}

/// One array's crowded-field fits for the explorer: the array's own ePSF and every star it reported.
#[derive(Debug, Clone)]
pub struct ArrayFits {
    pub epsf: engine::analysis::epsf::Epsf,
    pub stars: Vec<FittedStar>,
}

/// A star the crowded-field analysis reported, in its array's pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedStar {
    pub x_px: f64,
    pub y_px: f64,
    pub flux_e: f64,
    /// The matched truth star's Hw (NaN when it matched none).
    pub hw: f64,
    /// Fitted − true (mas; NaN when unmatched) and the bound.
    pub dx_mas: f64,
    pub dy_mas: f64,
    pub crlb_mas: f64,
    pub flags: u32,
}

/// The Gaussian-ACE twin of the displayed frame (same configuration, `ace.case = gaussian`).
#[derive(Debug, Clone)]
pub struct TwinResult {
    pub generation: u64,
    /// Hash of the main configuration the twin belongs to.
    pub cfg_hash: String,
    pub image_index: usize,
    pub n: usize,
    pub adu: Vec<f32>,
    pub report: Option<Report>,
}

/// One magnitude of the accuracy curve.
#[derive(Debug, Clone)]
pub struct CurvePoint {
    pub generation: u64,
    pub mag: f64,
    /// Predictor: dataset mean for the chosen countermeasure and for `none`.
    pub predicted_mas: Option<f64>,
    pub predicted_none_mas: Option<f64>,
    /// Monte Carlo rows (one per countermeasure of the plan), when the dataset is done.
    pub rows: Option<Vec<Row>>,
}

/// Messages from the worker.
#[derive(Debug, Clone)]
pub enum Msg {
    Progress {
        generation: u64,
        stage: Stage,
        done: usize,
        total: usize,
        note: String,
    },
    Prediction(Box<Prediction>),
    Series(Box<SeriesView>),
    Frame(Box<FrameResult>),
    FocalPlane(Box<FocalPlaneResult>),
    Crowded(Box<CrowdedResult>),
    Twin(Box<TwinResult>),
    Curve(Box<CurvePoint>),
    /// The job ran to the end.
    Done {
        generation: u64,
        elapsed_s: f64,
    },
    /// The job was abandoned because a newer generation exists.
    Cancelled {
        generation: u64,
    },
    /// The engine refused or failed; the job stopped at this stage.
    Error {
        generation: u64,
        stage: Stage,
        message: String,
    },
}

impl Msg {
    pub fn generation(&self) -> u64 {
        match self {
            Msg::Progress { generation, .. }
            | Msg::Done { generation, .. }
            | Msg::Cancelled { generation }
            | Msg::Error { generation, .. } => *generation,
            Msg::Prediction(p) => p.generation,
            Msg::Series(s) => s.generation,
            Msg::Frame(f) => f.generation,
            Msg::FocalPlane(f) => f.generation,
            Msg::Crowded(c) => c.generation,
            Msg::Twin(t) => t.generation,
            Msg::Curve(c) => c.generation,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_always_has_the_plain_analysis() {
        let mut r = Request {
            cfg: Config::default(),
            countermeasure: "plate-poly:3".parse().expect("a countermeasure"),
            image_index: 0,
            mags: vec![12.5],
        };
        let names = |r: &Request| -> Vec<String> {
            let plan = r.plan().expect("a valid plan");
            plan.countermeasures.iter().map(|c| c.to_string()).collect()
        };
        assert_eq!(names(&r), vec!["none", "plate-poly:3"]);
        r.countermeasure = Countermeasure::None;
        assert_eq!(names(&r), vec!["none"]);
    }
}
