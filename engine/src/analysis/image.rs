//! The image as the analysis sees it: electrons with the bias removed, a mask of unusable pixels and the
//! noise floor of every pixel.

use crate::analysis::epsf::fit::PixelData;
use crate::config::{Config, FlatField};
use crate::detector::{self, DetectorImage, dq};

/// An image ready for analysis: electrons with bias removed, a mask, the noise floor.
#[derive(Debug, Clone)]
pub struct AnalysisImage {
    pub nx: usize,
    pub ny: usize,
    pub e: Vec<f64>,
    pub bad: Vec<bool>,
    /// RN² + g²/12 (e⁻²): the typical floor (the rms over the pixels where it varies).
    pub var_floor_e2: f64,
    /// Each pixel's floor, e⁻², where it varies across the image (amplifiers of different read noise);
    /// `None`: every pixel's is `var_floor_e2`.
    pub var_floor_px_e2: Option<Vec<f64>>,
    /// Relative flat-field error counted as noise in the fit (0 when the flat is ignored: uncalibrated).
    pub flat_sigma: f64,
    pub plate_scale_mas: f64,
}

impl AnalysisImage {
    /// From a simulated detector image, flat-fielded as `cfg.analysis.flat_field` says (the calibration
    /// flat made anew: `session::source::analysis_image` reuses a simulator's).
    pub fn from_detector(cfg: &Config, img: &DetectorImage) -> Self {
        let mut a = Self::from_detector_unflattened(cfg, img);
        a.flat_field(cfg, cfg.analysis.flat_field);
        a
    }

    /// Electrons, mask and noise floor, not flat-fielded.
    pub fn from_detector_unflattened(cfg: &Config, img: &DetectorImage) -> Self {
        let g = cfg.detector.gain_e_per_adu;
        let bad_bits = dq::UNUSABLE;
        // the pipeline's linearity correction, with its calibration's error (the NLCORR header)
        let beta_hat = cfg.detector.nonlinearity_correction_per_e();
        Self {
            nx: img.n,
            ny: img.n,
            e: img
                .adu
                .iter()
                .map(|v| detector::linearize((*v as f64 - cfg.detector.bias_adu) * g, beta_hat))
                .collect(),
            bad: img.dq.iter().map(|d| d & bad_bits != 0).collect(),
            var_floor_e2: cfg.detector.noise_floor_e2(),
            var_floor_px_e2: None,
            flat_sigma: 0.0,
            plate_scale_mas: cfg.instrument.plate_scale_mas(),
        }
    }

    /// Flat-field an image of a simulation of `image_cfg` as a pipeline would: `Uncalibrated` leaves it as it
    /// is (the fit ignores the flat); `Calibrated { error }` divides every pixel by the calibration flat
    /// ([`detector::calibration_flat`]: the true flat with its own relative error) and counts that error as
    /// noise on the star's signal in the fit.
    pub fn flat_field(&mut self, image_cfg: &Config, mode: FlatField) {
        let FlatField::Calibrated { error } = mode else {
            return;
        };
        self.divide_by(&detector::calibration_flat(image_cfg, error), error);
    }

    /// Divide by a calibration flat of relative error `error`, counted as noise in the fit.
    pub fn divide_by(&mut self, flat: &[f32], error: f64) {
        if flat.len() == self.e.len() {
            for (v, f) in self.e.iter_mut().zip(flat) {
                *v /= *f as f64;
            }
        }
        self.flat_sigma = error;
    }

    /// The read/quantisation floor of pixel `i`, e⁻².
    #[inline]
    pub fn floor_e2(&self, i: usize) -> f64 {
        self.var_floor_px_e2
            .as_ref()
            .map_or(self.var_floor_e2, |m| m[i])
    }

    pub fn pixels(&self) -> PixelData<'_> {
        PixelData {
            nx: self.nx,
            ny: self.ny,
            e: &self.e,
            bad: &self.bad,
            var_floor_e2: self.var_floor_e2,
            var_floor_px_e2: self.var_floor_px_e2.as_deref(),
            flat_sigma: self.flat_sigma,
        }
    }
}
