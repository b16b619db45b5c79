//! The image as the analysis sees it: electrons with the bias removed, a mask of unusable pixels and the
//! noise floor of every pixel.

use crate::analysis::epsf::fit::PixelData;
use crate::config::Config;
use crate::detector::{DetectorImage, dq};

/// An image ready for analysis: electrons with bias removed, a mask, the noise floor.
#[derive(Debug, Clone)]
pub struct AnalysisImage {
    pub nx: usize,
    pub ny: usize,
    pub e: Vec<f64>,
    pub bad: Vec<bool>,
    /// RN² + g²/12 (e⁻²).
    pub var_floor_e2: f64,
    pub plate_scale_mas: f64,
}

impl AnalysisImage {
    /// From a simulated detector image.
    pub fn from_detector(cfg: &Config, img: &DetectorImage) -> Self {
        let g = cfg.detector.gain_e_per_adu;
        let bad_bits = dq::BORDER | dq::SATURATED | dq::ADC_HIGH;
        Self {
            nx: img.n,
            ny: img.n,
            e: img
                .adu
                .iter()
                .map(|v| (*v as f64 - cfg.detector.bias_adu) * g)
                .collect(),
            bad: img.dq.iter().map(|d| d & bad_bits != 0).collect(),
            var_floor_e2: cfg.detector.noise_floor_e2(),
            plate_scale_mas: cfg.instrument.plate_scale_mas(),
        }
    }

    pub fn pixels(&self) -> PixelData<'_> {
        PixelData {
            nx: self.nx,
            ny: self.ny,
            e: &self.e,
            bad: &self.bad,
            var_floor_e2: self.var_floor_e2,
        }
    }
}
