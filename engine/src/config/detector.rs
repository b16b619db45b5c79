//! Configuration of the detector and its electronics (`[detector]`): exposure, dark, read noise and how an
//! image is formed from reads, gain and ADC, flats, intra-pixel response, and the switches of the detector
//! effects (cosmic rays, inter-pixel capacitance, nonlinearity, persistence).

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Intra-pixel sensitivity over the subpixels of one pixel (mean normalised to 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum IntraPixel {
    Uniform,
    /// A planar photodiode's charge collection, weaker towards the pixel's edges: along each axis
    /// `1 + a·(1 − 12 (u − ½)²)`, u ∈ [0, 1] across the pixel — mean 1, 1 + a at the centre, 1 − 2a at the
    /// edges — and the map their product. a = 0.12 spans 0.76 … 1.12 per axis, the range of JASMINE-imagesim's
    /// measured-like profiles (0.71–1.13 in x, 0.75–1.21 in y); InGaAs figures for JASMINE's arrays were not
    /// found, so the amplitude is a knob (`kind = "parabolic"`, `amplitude = 0.12`).
    Parabolic {
        amplitude: f64,
    },
    /// Separable map: `profile_x[i] · profile_y[j]`, each resampled to the subpixel count.
    Separable {
        profile_x: Vec<f64>,
        profile_y: Vec<f64>,
    },
    /// A CSV of rows (y) and columns (x) of sensitivities; its size sets the subpixel count.
    Csv {
        path: PathBuf,
    },
}

/// Detector and electronics (SPEC §1, §4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Detector {
    pub exposure_s: f64,
    /// Dark current + stray light, e⁻/pix/s.
    pub dark_e_per_s: f64,
    /// Read noise of ONE read of a pixel, e⁻ (the paper's table: 15 e⁻). The noise of an image depends on
    /// how it is formed from reads ([`Sampling`]): [`Detector::image_read_noise_e`].
    pub read_noise_per_read_e: f64,
    /// How an image is formed from the reads of a pixel.
    pub sampling: Sampling,
    pub gain_e_per_adu: f64,
    pub full_well_e: f64,
    pub adc_bits: u32,
    pub bias_adu: f64,
    /// Pixel-to-pixel sensitivity, 1σ fraction.
    pub inter_pixel_flat_sigma: f64,
    pub intra_pixel: IntraPixel,
    /// Switches for the stochastic terms (for tests and noise-free truth images).
    pub shot_noise: bool,
    pub read_noise: bool,
    pub digitise: bool,
    /// Cosmic-ray hits per cm² per second (`detector::cosmic_rays`); 0 switches them off (the default).
    /// 4 is a suggested value for a 600-km sun-synchronous orbit outside the South Atlantic Anomaly.
    pub cosmic_ray_rate_per_cm2_s: f64,
    /// Charge a cosmic ray leaves per µm of path, e⁻ (a choice of order a minimum-ionising particle's).
    pub cosmic_ray_e_per_um: f64,
    /// Thickness of the absorbing layer, µm (a choice: JASMINE's InGaAs figure was not found).
    pub absorber_thickness_um: f64,
    /// Inter-pixel capacitance to each edge neighbour (`detector::ipc`); 0 (the default) switches it off,
    /// ≈ 0.015 for HgCdTe.
    pub ipc_alpha: f64,
    /// … and to each corner neighbour (≈ 0.002 for HgCdTe).
    pub ipc_alpha_diagonal: f64,
    /// Nonlinearity of the pixel response, β in e⁻⁻¹: measured = N − β N² (`detector::expose`); 0 (the
    /// default) switches it off. 2 × 10⁻⁷ is romanisim's example (6 × 10⁻⁷ per ADU at 3 e⁻/ADU): 2 % at
    /// 10⁵ e⁻; JASMINE's InGaAs figure was not found.
    pub nonlinearity_per_e: f64,
    /// Relative error of the linearity calibration: the correction the pipeline applies (the `NLCORR`
    /// header) is β (1 + this) — a choice of 5 %.
    pub nonlinearity_calibration_error: f64,
    /// The detector's memory of bright light (`detector::persistence`), off by default.
    pub persistence: Persistence,
}

/// Persistence (`[detector.persistence]`): trap populations after Tulloch et al. (2019) with
/// JASMINE-imagesim's parameters; it acts along a sequence (`jsim sequence`), where each exposure
/// collects what the traps filled by the earlier ones release.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Persistence {
    pub enabled: bool,
    /// Time constants of the trap populations, s.
    pub tau_s: Vec<f64>,
    /// Their densities: the fraction of a pixel's charge each holds at equilibrium.
    pub rho: Vec<f64>,
    /// Pixels whose collected star charge is below this fill no traps, e⁻ (a speed knob: such a pixel
    /// releases ≈ 7 × 10⁻⁴ of it into the next exposure, 0.14 e⁻ at the default).
    pub threshold_e: f64,
    /// Exposures that ended more than this before an exposure starts leave nothing in it, s (a speed knob).
    pub lookback_s: f64,
}

impl Default for Persistence {
    fn default() -> Self {
        Self {
            enabled: false,
            tau_s: vec![1.0, 10.0, 100.0, 1.0e3, 1.0e4],
            rho: vec![1.0e-3, 1.5e-3, 1.5e-3, 2.0e-3, 3.0e-3],
            threshold_e: 200.0,
            lookback_s: 600.0,
        }
    }
}

impl Default for Detector {
    fn default() -> Self {
        Self {
            exposure_s: 12.5,
            dark_e_per_s: 24.5,
            read_noise_per_read_e: 15.0,
            sampling: Sampling::Cds,
            gain_e_per_adu: 3.0,
            full_well_e: 150_000.0,
            adc_bits: 16,
            bias_adu: 0.0,
            inter_pixel_flat_sigma: 0.01,
            intra_pixel: IntraPixel::Uniform,
            shot_noise: true,
            read_noise: true,
            digitise: true,
            cosmic_ray_rate_per_cm2_s: 0.0,
            cosmic_ray_e_per_um: 100.0,
            absorber_thickness_um: 10.0,
            ipc_alpha: 0.0,
            ipc_alpha_diagonal: 0.0,
            nonlinearity_per_e: 0.0,
            nonlinearity_calibration_error: 0.05,
            persistence: Persistence::default(),
        }
    }
}

/// How an image is formed from the non-destructive reads of a pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Sampling {
    /// Correlated double sampling: the image is (read after − read before), so the read noises of two
    /// reads add: σ = √2 · σ_read. The JASMINE detector's mode and the original simulator's (√2 · 15 e⁻).
    Cds,
    /// Fowler-N: the mean of N reads after minus the mean of N reads before: σ = σ_read · √(2/N).
    Fowler { pairs: usize },
}

impl Sampling {
    /// Read noise of an image formed this way from reads of noise `per_read_e` (e⁻): √2 σ for CDS,
    /// σ √(2/N) for Fowler-N.
    pub fn image_read_noise_e(self, per_read_e: f64) -> f64 {
        match self {
            Sampling::Cds => std::f64::consts::SQRT_2 * per_read_e,
            Sampling::Fowler { pairs } => per_read_e * (2.0 / pairs.max(1) as f64).sqrt(),
        }
    }

    /// The `SAMPLING` header value: `CDS` or `FOWLER-N`.
    pub fn header(self) -> String {
        match self {
            Sampling::Cds => "CDS".to_string(),
            Sampling::Fowler { pairs } => format!("FOWLER-{pairs}"),
        }
    }

    /// From a `SAMPLING` header value.
    pub fn from_header(s: &str) -> Option<Sampling> {
        match s.trim() {
            "CDS" => Some(Sampling::Cds),
            other => other
                .strip_prefix("FOWLER-")
                .and_then(|n| n.parse().ok())
                .map(|pairs| Sampling::Fowler { pairs }),
        }
    }
}

impl Detector {
    /// The linearity correction the pipeline holds, β̂ = β (1 + calibration error), e⁻⁻¹.
    pub fn nonlinearity_correction_per_e(&self) -> f64 {
        self.nonlinearity_per_e * (1.0 + self.nonlinearity_calibration_error)
    }

    /// Read noise of an image (e⁻): √2 σ_read for CDS, σ_read √(2/N) for Fowler-N.
    pub fn image_read_noise_e(&self) -> f64 {
        self.sampling.image_read_noise_e(self.read_noise_per_read_e)
    }

    /// The variance floor of a pixel of an image, e⁻²: image read noise² plus the quantisation of the
    /// ADC, g²/12 (g in e⁻/ADU).
    pub fn noise_floor_e2(&self) -> f64 {
        noise_floor_e2(self.image_read_noise_e(), self.gain_e_per_adu)
    }
}

/// Variance floor of a pixel from its image read noise (e⁻) and gain (e⁻/ADU): `σ_RN² + g²/12`.
pub fn noise_floor_e2(image_read_noise_e: f64, gain_e_per_adu: f64) -> f64 {
    image_read_noise_e.powi(2) + gain_e_per_adu.powi(2) / 12.0
}
