//! One TOML file describes instrument + scene + simulation knobs. Every SPEC default is built in
//! (`Config::default()` is the paper's reference experiment), every field can be overridden, and
//! [`Config::validate`] names the offending field and the allowed range. [`DEFAULT_TOML`] is the same
//! configuration written out with comments (`jsim config --print-default`); a test keeps the two identical.
//!
//! Here: the types and their defaults, and derived quantities. `text` reads and writes the TOML (load,
//! overrides by dotted path, the hash), `validate` checks every field.

mod as_built;
mod detector;
pub(crate) mod seed;
mod sky;
mod text;
mod validate;
pub use as_built::{AsBuilt, InstrumentModel, Knowledge};
pub use detector::{Detector, IntraPixel, Persistence, Sampling, noise_floor_e2};
pub use sky::{Bulge, FocalPlaneLayout, Layout, Observation, SipTerm, Sky};
pub use validate::MAX_ACE_SIGMA_MAS;

pub use text::DEFAULT_TOML;

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A configuration problem, always naming the field.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("config field `{field}` = {value}: {allowed}")]
    Invalid {
        field: String,
        value: String,
        allowed: String,
    },
    #[error("cannot read config file {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("config file {path} is not valid: {message}")]
    Parse { path: PathBuf, message: String },
}

fn invalid(field: &str, value: impl std::fmt::Display, allowed: &str) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_string(),
        value: value.to_string(),
        allowed: allowed.to_string(),
    }
}

/// The whole simulation + analysis configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Master seed: every random stream (ACE, scene offsets, flat, noise) derives from it.
    #[serde(with = "seed")]
    pub seed: u64,
    pub instrument: Instrument,
    pub band: Band,
    pub optics: Optics,
    pub detector: Detector,
    pub readout: Readout,
    pub ace: Ace,
    pub photometry: Photometry,
    pub scene: Scene,
    pub sky: Sky,
    pub observation: Observation,
    pub focal_plane: FocalPlaneLayout,
    pub fidelity: Fidelity,
    pub analysis: Analysis,
    /// How the instrument as built departs from the design above (`[as_built]`; by default a typical
    /// instrument as built, [`AsBuilt::design`] for none). Always written: a file without it means the default.
    pub as_built: AsBuilt,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            seed: 20240601,
            instrument: Instrument::default(),
            band: Band::default(),
            optics: Optics::default(),
            detector: Detector::default(),
            readout: Readout::default(),
            ace: Ace::default(),
            photometry: Photometry::default(),
            scene: Scene::default(),
            sky: Sky::default(),
            observation: Observation::default(),
            focal_plane: FocalPlaneLayout::default(),
            fidelity: Fidelity::default(),
            analysis: Analysis::default(),
            as_built: AsBuilt::default(),
        }
    }
}

/// Telescope and focal-plane geometry (SPEC §1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Instrument {
    pub aperture_diameter_m: f64,
    pub obstruction_diameter_m: f64,
    pub spider_count: u32,
    pub spider_width_m: f64,
    /// Azimuth of the first vane, from +x towards +y; the others follow every 360°/count.
    pub spider_angle_deg: f64,
    pub focal_length_m: f64,
    pub pixel_pitch_um: f64,
    /// Full detector format (square), pixels.
    pub detector_px: usize,
    /// Central photosensitive region (square), pixels; the border around it sees no light.
    pub photosensitive_px: usize,
}

impl Default for Instrument {
    fn default() -> Self {
        Self {
            aperture_diameter_m: 0.36,
            obstruction_diameter_m: 0.126,
            spider_count: 3,
            spider_width_m: 0.005,
            spider_angle_deg: 0.0,
            focal_length_m: 4.369,
            pixel_pitch_um: 10.0,
            detector_px: 1968,
            photosensitive_px: 1952,
        }
    }
}

impl Instrument {
    /// Plate scale in mas per pixel: 206264.8″ · pitch / focal length.
    pub fn plate_scale_mas(&self) -> f64 {
        crate::ARCSEC_PER_RAD * 1e3 * self.pixel_pitch_um * 1e-6 / self.focal_length_m
    }
    /// Angular size of one pixel in radians.
    pub fn pixel_rad(&self) -> f64 {
        self.pixel_pitch_um * 1e-6 / self.focal_length_m
    }
    /// Width of the light-insensitive border on each side, pixels.
    pub fn border_px(&self) -> usize {
        (self.detector_px - self.photosensitive_px.min(self.detector_px)) / 2
    }
}

/// Band, wavelength grid and throughput × QE (SPEC §2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Band {
    pub wavelength_min_um: f64,
    pub wavelength_max_um: f64,
    pub wavelength_step_um: f64,
    /// Throughput × QE as `[wavelength_um, value]` points, linear in between, zero outside.
    pub response: Vec<[f64; 2]>,
}

impl Band {
    /// The configured wavelength grid (µm), restricted to points where throughput × QE > 0.
    pub fn wavelength_grid(&self) -> Vec<f64> {
        let band = self;
        if !(band.wavelength_step_um > 0.0) || !(band.wavelength_max_um >= band.wavelength_min_um) {
            return Vec::new();
        }
        let n = ((band.wavelength_max_um - band.wavelength_min_um) / band.wavelength_step_um + 1e-9)
            .floor() as usize;
        (0..=n)
            .map(|i| band.wavelength_min_um + i as f64 * band.wavelength_step_um)
            .filter(|&l| band.response(l) > 0.0)
            .collect()
    }

    /// Throughput × QE at λ (µm): piecewise linear through `band.response`, zero outside it.
    pub fn response(&self, lambda_um: f64) -> f64 {
        let r = &self.response;
        match r.len() {
            0 => 0.0,
            1 => {
                if (lambda_um - r[0][0]).abs() < 1e-9 {
                    r[0][1]
                } else {
                    0.0
                }
            }
            _ => {
                let tol = 1e-9;
                if lambda_um < r[0][0] - tol || lambda_um > r[r.len() - 1][0] + tol {
                    return 0.0;
                }
                for w in r.windows(2) {
                    let (a, b) = (w[0], w[1]);
                    if lambda_um <= b[0] + tol {
                        let span = b[0] - a[0];
                        if span <= 0.0 {
                            return b[1];
                        }
                        let f = ((lambda_um - a[0]) / span).clamp(0.0, 1.0);
                        return a[1] + f * (b[1] - a[1]);
                    }
                }
                r[r.len() - 1][1]
            }
        }
    }
}

impl Default for Band {
    fn default() -> Self {
        Self {
            wavelength_min_um: 0.99,
            wavelength_max_um: 1.61,
            wavelength_step_um: 0.01,
            response: vec![[1.0, 1.0], [1.6, 1.0]],
        }
    }
}

/// PSF computation method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PsfMethod {
    /// Matrix Fourier transform: exact output sampling for every wavelength, fast (default).
    Mft,
    /// Zero-padded FFT with the pupil resampled per wavelength: the simple reference.
    Fft,
}

/// Unit of the Zernike coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WfeUnit {
    /// Waves at `reference_wavelength_um` (CODE V / Zemax convention).
    Waves,
    /// Micrometres of wavefront.
    Um,
}

/// The shape of a field table: (distinct x, distinct y) when its rows cover every node of that rectangular
/// grid exactly once, else why not.
pub fn field_grid_shape(rows: &[FieldWfe]) -> Result<(Vec<f64>, Vec<f64>), String> {
    let distinct = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.dedup();
    };
    let mut xs: Vec<f64> = rows.iter().map(|r| r.x_px).collect();
    let mut ys: Vec<f64> = rows.iter().map(|r| r.y_px).collect();
    distinct(&mut xs);
    distinct(&mut ys);
    let mut seen = std::collections::HashSet::new();
    for r in rows {
        if !seen.insert((r.x_px.to_bits(), r.y_px.to_bits())) {
            return Err(format!("the node ({}, {}) is given twice", r.x_px, r.y_px));
        }
    }
    if rows.len() != xs.len() * ys.len() {
        return Err(format!(
            "{} rows on {} distinct x × {} distinct y: the rows must cover every (x, y) of a rectangular \
             grid exactly once",
            rows.len(),
            xs.len(),
            ys.len()
        ));
    }
    Ok((xs, ys))
}

/// Zernike coefficients at one field position (pixels, detector frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldWfe {
    pub x_px: f64,
    pub y_px: f64,
    pub fringe: Vec<f64>,
}

/// Optical PSF knobs (SPEC §2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Optics {
    /// Pupil samples across the aperture diameter (N of the N×N pupil grid).
    pub pupil_samples: usize,
    /// PSF table cells per detector pixel.
    pub psf_oversampling: usize,
    /// Half-width of the PSF table in pixels: light beyond it is not modelled (its fraction is reported).
    pub psf_radius_px: usize,
    pub psf_method: PsfMethod,
    pub wfe_unit: WfeUnit,
    /// Sign convention of the coefficients (of `fringe` and the field table): which way a positive tilt
    /// moves the image.
    pub opd_sign: OpdSign,
    pub reference_wavelength_um: f64,
    /// Fringe Zernike coefficients Z1..Z37 (index 0 is Z1, piston). Shorter lists are zero-padded.
    pub fringe: Vec<f64>,
    /// Optional field-dependent table on a rectangular grid of field positions; when non-empty it replaces
    /// `fringe`, interpolated bilinearly to each star.
    pub field_table: Vec<FieldWfe>,
    /// Tolerance of PSF sharing with a field table: a star's interpolated coefficients are rounded to
    /// multiples of this OPD (nm), and stars that round alike share one PSF (0: one PSF per distinct
    /// position). The speed-against-error knob of the field-dependent PSF.
    pub field_wfe_step_nm: f64,
    /// Zones of PSF sharing with a field table, px: a star takes the wavefront at the centre of its square
    /// zone of this side (0: at its own position; 656, the default: 3 × 3 zones of the 1968-px array). With a
    /// smooth field variation of gradient g (nm per px) a star's wavefront is off by at most g·side/√2;
    /// `jsim bench --parts knobs` ("field zones") gives the time and the error against 0.
    pub field_zone_px: usize,
}

impl Default for Optics {
    fn default() -> Self {
        Self {
            pupil_samples: 256,
            psf_oversampling: 16,
            psf_radius_px: 13,
            psf_method: PsfMethod::Mft,
            wfe_unit: WfeUnit::Waves,
            opd_sign: OpdSign::ImageAlongGradient,
            reference_wavelength_um: 1.4,
            fringe: default_fringe(),
            field_table: Vec::new(),
            field_wfe_step_nm: 1.0,
            field_zone_px: 656,
        }
    }
}

/// The sign convention of a wavefront table: which way the image moves for a positive wavefront slope.
///
/// The engine's pupil field is `t · exp(+2πi W/λ)` and its image plane the Fourier transform with
/// `exp(−2πi x·u/λ)`, so the image (every ray, and the PSF's centroid exactly: the centroid theorem) moves
/// by `+f ∇W` (f the focal length, ∇W per unit pupil coordinate in m): W > 0 where the wavefront *lags* the
/// reference sphere. In detector terms a positive Fringe Z2 (ρ cos θ, x tilt) moves the star toward +x
/// (higher column), a positive Z3 toward +y (higher row), and a positive Z7 (x coma) moves its centroid
/// toward +x and throws its flare that way. Lens-design texts write the transverse ray aberration as
/// `ε = −(R/n′) ∂W/∂y` (Welford, *Aberrations of Optical Systems*, 1986), the opposite sign: a table
/// written that way needs `image-against-gradient`. Which one a design code's Zernike export uses is stated
/// in its manual; a one-line check is a Z2-only table, whose star must move the way the code's spot
/// diagram shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum OpdSign {
    /// The image moves along +∇W (the engine's Fourier-optics sign; the default).
    #[default]
    ImageAlongGradient,
    /// The image moves along −∇W (ε = −R ∂W/∂y): the coefficients are negated on input.
    ImageAgainstGradient,
}

/// Default WFE: a small design-like residual at 1.4 µm dominated by defocus and astigmatism
/// (Z4 = 0.07, Z5 = 0.05, Z6 = −0.03 waves; 66 nm rms over the pupil: Fringe Z4 has rms 1/√3, Z5 and Z6
/// 1/√6 per unit), documented in docs/methods.md.
pub fn default_fringe() -> Vec<f64> {
    vec![0.0, 0.0, 0.0, 0.07, 0.05, -0.03]
}

/// Readout order (SPEC §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum ReadoutOrder {
    /// Every pixel reset and read in sequence: windows `[t₁, t₁+T]` with `t₁` rolling.
    Rolling,
    /// All pixels start together; reads still roll, so windows differ at the end only.
    GlobalReset,
    /// Sample-and-hold (global shutter): identical windows.
    SampleHold,
}

impl ReadoutOrder {
    pub const ALL: [ReadoutOrder; 3] = [
        ReadoutOrder::Rolling,
        ReadoutOrder::GlobalReset,
        ReadoutOrder::SampleHold,
    ];
    pub fn name(self) -> &'static str {
        match self {
            ReadoutOrder::Rolling => "rolling",
            ReadoutOrder::GlobalReset => "global-reset",
            ReadoutOrder::SampleHold => "sample-hold",
        }
    }
    pub fn parse(s: &str) -> Result<Self, ConfigError> {
        match s {
            "rolling" => Ok(ReadoutOrder::Rolling),
            "global-reset" => Ok(ReadoutOrder::GlobalReset),
            "sample-hold" => Ok(ReadoutOrder::SampleHold),
            _ => Err(invalid(
                "readout.order",
                s,
                "one of rolling, global-reset, sample-hold",
            )),
        }
    }
}

/// Direction in which rows are read within a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum RowDirection {
    /// Bottom row (Y = 0) first, as JASMINE.
    Up,
    /// Top row first.
    Down,
}

/// Readout timing (SPEC §4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Readout {
    pub order: ReadoutOrder,
    pub row_direction: RowDirection,
    pub channels: usize,
    pub channel_width_px: usize,
    pub pixel_time_us: f64,
    /// From the end of reset to the first pixel read.
    pub t_overhead_s: f64,
    /// Start-to-start time of consecutive exposures; 0 means back to back
    /// (`t_overhead + frame sweep + exposure`).
    pub exposure_cadence_s: f64,
}

impl Default for Readout {
    fn default() -> Self {
        Self {
            order: ReadoutOrder::Rolling,
            row_direction: RowDirection::Up,
            channels: 16,
            channel_width_px: 123,
            pixel_time_us: 5.0,
            t_overhead_s: 0.1,
            exposure_cadence_s: 0.0,
        }
    }
}

/// Which ACE model a simulation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum AceCase {
    /// The exposure-integrated jitter is an isotropic Gaussian of `sigma_mas`, identical everywhere.
    Gaussian,
    /// A time series from the PSD; every pixel integrates its own window.
    Realistic,
    /// A still telescope.
    None,
}

impl AceCase {
    pub fn name(self) -> &'static str {
        match self {
            AceCase::Gaussian => "gaussian",
            AceCase::Realistic => "realistic",
            AceCase::None => "none",
        }
    }
    pub fn parse(s: &str) -> Result<Self, ConfigError> {
        match s {
            "gaussian" => Ok(AceCase::Gaussian),
            "realistic" => Ok(AceCase::Realistic),
            "none" => Ok(AceCase::None),
            _ => Err(invalid("ace.case", s, "one of gaussian, realistic, none")),
        }
    }
}

/// How the realistic series is scaled to `sigma_mas`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum SigmaConvention {
    /// The median over exposures of the per-exposure standard deviation (the paper's realistic case).
    MedianExposure,
    /// The standard deviation of the whole series.
    WholeSeries,
}

/// A natural mode of the structure: a Lorentzian peak in the PSD.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mode {
    pub freq_hz: f64,
    pub width_hz: f64,
    pub amplitude: f64,
}

/// Attitude control error (SPEC §3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ace {
    pub case: AceCase,
    pub sigma_mas: f64,
    pub sigma_convention: SigmaConvention,
    /// PSD continuum: `A/f_b / (1 + (f/f_b)^index)`.
    pub boundary_freq_hz: f64,
    pub power_law_index: f64,
    pub continuum_amplitude: f64,
    pub modes: Vec<Mode>,
    /// Fractional Gaussian noise on the Fourier amplitudes.
    pub amplitude_noise: f64,
    pub sample_interval_ms: f64,
    pub span_s: f64,
    /// Start of the first exposure within the series.
    pub first_exposure_start_s: f64,
}

/// The paper's eight natural modes (SPEC §3).
pub fn reference_modes() -> Vec<Mode> {
    let f = [20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0];
    let h = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];
    let p = [
        1e-2, 5e-3, 1.875e-3, 6.25e-4, 1.953e-4, 5.859e-5, 1.709e-5, 4.883e-6,
    ];
    (0..8)
        .map(|i| Mode {
            freq_hz: f[i],
            width_hz: h[i],
            amplitude: p[i],
        })
        .collect()
}

impl Default for Ace {
    fn default() -> Self {
        Self {
            case: AceCase::Realistic,
            sigma_mas: 300.0,
            sigma_convention: SigmaConvention::MedianExposure,
            boundary_freq_hz: 0.1,
            power_law_index: 2.0,
            continuum_amplitude: 1.0,
            modes: reference_modes(),
            amplitude_noise: 0.2,
            sample_interval_ms: 0.15,
            span_s: 360.0,
            first_exposure_start_s: 0.0,
        }
    }
}

/// Photometric zero point (SPEC §5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Photometry {
    /// Photo-electrons per second for Hw = 0: 5.8e8 (the original simulator's throughput × QE with a
    /// 9500 K spectrum through the 0.0876 m² open pupil; a simpler ETC gives 3.9e8).
    pub zero_point_e_per_s: f64,
}

impl Default for Photometry {
    fn default() -> Self {
        Self {
            zero_point_e_per_s: 5.8e8,
        }
    }
}

/// Which stars are simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// The paper's regular grid (SPEC §6).
    Grid,
    /// A catalogue (CSV or FITS table): `x, y` in pixels of the single array, or `ra, dec` on the sky;
    /// `hw, j_h` or `j, h`; optional `a_hw` extinction (`scene::catalogue`).
    Catalogue,
    /// The built-in mock Galactic-bulge field on the sky (`scene.bulge`, `scene::bulge`).
    Bulge,
}

/// Scene (SPEC §6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scene {
    pub kind: SceneKind,
    pub grid_n: usize,
    pub grid_spacing_px: f64,
    /// Each grid star is offset by a uniform random amount in ±this, per axis.
    pub grid_random_px: f64,
    pub mag_hw: f64,
    pub j_minus_h: f64,
    pub catalogue: Option<PathBuf>,
    /// The mock bulge field (`kind = "bulge"`).
    pub bulge: Bulge,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            kind: SceneKind::Grid,
            grid_n: 20,
            grid_spacing_px: 98.4,
            grid_random_px: 0.5,
            mag_hw: 12.5,
            j_minus_h: 2.0,
            catalogue: None,
            bulge: Bulge::default(),
        }
    }
}

/// Integration method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Literal sum over subpixels × time samples of bilinear PSF look-ups: the slow reference.
    Reference,
    /// One pixel-kernel look-up per (pixel, sample): equal to the reference to rounding.
    Direct,
    /// Shared-window histogram ⊛ pixel kernel + per-pixel window edges: equal to direct to rounding.
    Fast,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Reference => "reference",
            Method::Direct => "direct",
            Method::Fast => "fast",
        }
    }
}

/// Where the integration runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The GPU when an adapter exists, else the CPU (said once).
    Auto,
    Cpu,
    Gpu,
}

/// Speed/accuracy knobs of the simulation (our `GSParams`); each has a benchmark (`jsim bench`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Fidelity {
    pub images: usize,
    /// Stamp half-size around each star's mean position, before the jitter margin is added: 0 = the
    /// pixel kernel's reach, so every photon the PSF table models lands in the image (the truth's
    /// `psf_fraction` is then what the image holds); a positive value truncates there (faster, drops the
    /// wings: `jsim bench` reports the flux kept).
    pub stamp_radius_px: usize,
    /// Subpixels per pixel axis (sampling of the pixel area and the intra-pixel map).
    pub subpixels: usize,
    /// Integration time step = this many ACE samples.
    pub time_stride: usize,
    pub method: Method,
    pub backend: Backend,
    /// Add the PSF halo (static, at 2 cells per pixel) out to this radius beyond the PSF table; 0 = off.
    pub halo_radius_px: usize,
    /// Stars share a PSF when their J − H round to the same multiple of this (mag); 0 = each colour its
    /// own PSF (to 1 mmag). The truth keeps every star's own colour; `jsim bench` reports the centroid
    /// and shape error the binning costs.
    pub colour_step_mag: f64,
    /// Each star's stamp reaches as far as its PSF puts more than this many electrons in a pixel
    /// (bright stars further, into the halo table when `halo_radius_px` > 0; faint ones less); 0 = every
    /// stamp the kernel's full reach. `jsim bench` reports the time and the light it drops.
    pub wing_threshold_e: f64,
    /// The CPU fast method deposits the part of the exposure every pixel of an array shares once, at this
    /// many star phases per kernel node, and interpolates each star's histogram of it (exact in the mean,
    /// smoother by ≤ a 1/(2Q) node in the spread); 0 = exact: that part is deposited once grouped by cell
    /// and read at each star's own phase (`integrate::exact_core`). The GPU always deposits whole
    /// tracks. `jsim bench --parts bulge` reports the time and the error.
    pub deposit_phases: usize,
}

impl Default for Fidelity {
    fn default() -> Self {
        Self {
            images: 11,
            stamp_radius_px: 0,
            subpixels: 8,
            time_stride: 1,
            method: Method::Fast,
            backend: Backend::Auto,
            halo_radius_px: 0,
            colour_step_mag: 0.05,
            wing_threshold_e: 0.0,
            deposit_phases: 0,
        }
    }
}

/// ePSF smoothing kernel (see `epsf::smooth`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Smoothing {
    /// No smoothing (the pixel-phase bias never decays: for comparison).
    None,
    /// Local quadratic fit over 5×5 ePSF nodes (Anderson & King 2000): damps 1 cycle/pixel only to 0.66.
    LocalQuadratic,
    /// Quadratic-preserving separable kernel with zeros at 1, 2, … cycles per pixel (default).
    Quadratic,
}

/// How the plain analysis' ePSF varies across the image (`analysis::epsf::varying`). A PSF that changes over
/// the field (an as-built wavefront's field gradient) fitted with one ePSF leaves a smooth displacement of each
/// star by the difference between its local profile and the mean one; a varying ePSF learns the local profile
/// from the stars, as DAOPHOT's variable PSF (Stetson 1987, PASP 99, 191: a lookup table plus its linear or
/// quadratic change over the frame) and Anderson & King's (2006, ISR ACS 2006-01) fiducial arrays do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EpsfVariation {
    /// One ePSF for the whole image (default).
    #[default]
    Constant,
    /// ψ(Δ; ξ, η) = ψ₀(Δ) + ξ ψ_ξ(Δ) + η ψ_η(Δ), ξ and η the star's position scaled to [−1, 1] across the image.
    Linear,
    /// The linear form plus ξ², ξη and η² planes.
    Quadratic,
}

impl EpsfVariation {
    /// The configuration's spelling.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Constant => "constant",
            Self::Linear => "linear",
            Self::Quadratic => "quadratic",
        }
    }
}

/// The PSF the telemetry correction's fit response is built from (`analysis::response`): the
/// response needs the PSF *before* the jitter, which it then blurs with the telemetry's own window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TelemetryKernel {
    /// The design model PSF product (`psf_model.fits`: design wavefront, pixel-integrated, no jitter); the
    /// image's own ePSF where no model PSF is supplied (default).
    ModelPsf,
    /// The image's own ePSF, which already holds the exposure's mean jitter blur (blurred twice: on the paper
    /// grid 3.65 ± 0.15 mas against 3.51 ± 0.13 with the model PSF).
    Epsf,
    /// The image's own stars' static profile: the ePSF rebuilt with each star modelled through the jitter
    /// of its own pixels' windows (deconvolved; `analysis::countermeasures::forward_epsf`), started from the
    /// image's ePSF — no design model needed.
    EpsfDeconvolved,
    /// The design model PSF corrected by the image's own stars: its low-order wavefront terms (Z4–Z11) fitted
    /// through the design's derivative planes, each star seen through its own windows' jitter
    /// (`analysis::countermeasures::wavefront`); the design model PSF alone where the planes are not supplied.
    DesignFitted,
}

/// How the telemetry forward model (`telemetry-model`) filters the attitude telemetry before it sees each star
/// through it (`analysis::countermeasures::telemetry::Smoothing`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TelemetryFilter {
    /// A boxcar chosen per record to minimise the model's blur error: the white noise it leaves against
    /// the jitter it removes (default).
    #[default]
    Auto,
    /// The samples as recorded (every sample's noise blurs the model: for comparison).
    Off,
    /// The Wiener smoother: each frequency kept in the proportion of the record's spectrum above its white
    /// noise (`analysis::countermeasures::wiener`).
    Wiener,
}

/// How the analysis pipeline treats crowding (`analysis::crowding`: the automatic choice from the measured
/// source density).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Crowding {
    /// From the measured source density.
    #[default]
    Auto,
    /// Always the crowded-field analysis.
    On,
    /// Always the isolated-star analysis.
    Off,
}

impl Crowding {
    /// The accepted names, for messages.
    pub const NAMES: &'static str = "auto, on, off";

    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "on" | "crowded" => Ok(Self::On),
            "off" | "isolated" => Ok(Self::Off),
            other => Err(format!(
                "crowding = {other:?}: allowed {} (or crowded, isolated)",
                Self::NAMES
            )),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::On => "on",
            Self::Off => "off",
        }
    }
}

/// ePSF analysis knobs (SPEC §7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Analysis {
    pub epsf_oversampling: usize,
    pub epsf_iterations: usize,
    /// ePSF half-width, pixels.
    pub epsf_radius_px: usize,
    /// Pixels within this radius of a star enter its fit.
    pub fit_radius_px: f64,
    /// Fit each star's local sky as a fourth parameter (x, y, flux, sky); otherwise the sky is the clipped
    /// median of an annulus just outside the ePSF (hundreds of pixels: known to ≪ 1 e⁻) and the fit and its
    /// bound have three parameters.
    pub fit_sky: bool,
    pub smoothing: Smoothing,
    /// Y zones of the position-dependent ePSF of the `yzones` countermeasures (at least 2 are used; the plain
    /// analysis builds one ePSF for the image).
    pub epsf_zones: usize,
    /// How the plain analysis' ePSF varies across the image: one table (`constant`) or a table with its
    /// linear or quadratic change over the field, learned from the stars.
    pub epsf_variation: EpsfVariation,
    /// Detection threshold (peak above sky) in units of the sky noise.
    pub detect_sigma: f64,
    /// Detection threshold of the crowded-field analysis (`analysis::crowded`): S/N of a peak in
    /// the matched-filtered (3 × 3 binomial) image, and of a residual peak against its local noise.
    pub crowded_detect_sigma: f64,
    /// Hold the reference catalogue's stars that the crowded-field detection missed at their catalogue
    /// positions with a fitted flux, their light subtracted from their neighbours' fits
    /// (`analysis::crowded::forced`); no effect without a reference catalogue.
    pub crowded_forced_catalogue: bool,
    /// Maximum Gauss–Newton iterations per star fit.
    pub fit_max_iter: usize,
    /// Sigma-clipping threshold for the ePSF stacking.
    pub clip_sigma: f64,
    /// What the analysis knows of the inter-pixel flat.
    pub flat_field: FlatField,
    /// The PSF the telemetry correction's response is built from.
    pub telemetry_kernel: TelemetryKernel,
    /// Nodes per pixel of the telemetry forward model's jitter histograms (`telemetry-model`; the knob of its
    /// one approximation, benchmarked by `jsim bench --parts forward`).
    pub telemetry_model_nodes_per_px: usize,
    /// How the forward model filters the telemetry.
    pub telemetry_filter: TelemetryFilter,
    /// Iterations of the deconvolved ePSF build (`telemetry_kernel = "epsf-deconvolved"`; its knob: the
    /// error left falls slowly with it, benchmarked in docs/equations.md §9.4).
    pub telemetry_deconvolution_iterations: usize,
    /// Isolated-star or crowded-field analysis, or chosen from the measured source density.
    pub crowding: Crowding,
}

/// Relative error (1σ) of the default calibration flat: 0.2 %. A laboratory flat of an H4RG-class array
/// built from ~10⁶ e⁻ per pixel (a few hundred well-exposed frames) has a shot-noise floor of ≈ 0.1 %, and
/// its transfer to orbit (illumination pattern, temperature) adds as much again; 0.1–0.3 % is what the
/// issue asks to cover, and any value in [0, 0.5] is accepted.
pub const DEFAULT_CALIBRATION_FLAT_ERROR: f64 = 0.002;

/// What the analysis knows of the detector's inter-pixel flat.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlatField {
    /// The paper's setting: the image is not flat-fielded and the fit's weights ignore the flat (the
    /// predictor counts it as noise).
    Uncalibrated,
    /// A calibrated pipeline: the image is divided by a calibration flat that is the true flat with its own
    /// relative error `error` (1σ; e.g. 0.002 = 0.2 %), and that residual is counted as noise, ∝ the star's
    /// signal, in the fit's weights, the Cramér–Rao bound and the predictor alike.
    Calibrated { error: f64 },
}

impl Default for Analysis {
    fn default() -> Self {
        Self {
            epsf_oversampling: 4,
            epsf_iterations: 3,
            epsf_radius_px: 6,
            fit_radius_px: 2.5,
            fit_sky: false,
            smoothing: Smoothing::Quadratic,
            epsf_zones: 4,
            epsf_variation: EpsfVariation::Constant,
            detect_sigma: 10.0,
            crowded_detect_sigma: 3.0,
            crowded_forced_catalogue: false,
            fit_max_iter: 30,
            clip_sigma: 3.0,
            flat_field: FlatField::Calibrated {
                error: DEFAULT_CALIBRATION_FLAT_ERROR,
            },
            telemetry_kernel: TelemetryKernel::ModelPsf,
            telemetry_model_nodes_per_px: 16,
            telemetry_filter: TelemetryFilter::Auto,
            telemetry_deconvolution_iterations: 8,
            crowding: Crowding::Auto,
        }
    }
}

// Derived quantities.
impl Config {
    /// Pixels of the ACE time series per time step, derived.
    pub fn integration_dt_s(&self) -> f64 {
        self.ace.sample_interval_ms * 1e-3 * self.fidelity.time_stride as f64
    }

    /// Duration of one read sweep of a channel, `W × rows × t_pix` (s): a derived readout quantity
    /// (the readout timing carries it).
    pub fn frame_sweep_s(&self) -> f64 {
        (self.readout.channel_width_px * self.instrument.detector_px) as f64
            * (self.readout.pixel_time_us * 1e-6)
    }

    /// Latest end of any pixel's window, `t_overhead + sweep + T`, s from the exposure start.
    pub fn exposure_span_s(&self) -> f64 {
        self.readout.t_overhead_s + self.frame_sweep_s() + self.detector.exposure_s
    }

    /// Start-to-start time of consecutive exposures: `readout.exposure_cadence_s` when set (> 0), else the
    /// span of one exposure.
    pub fn exposure_cadence_s(&self) -> f64 {
        if self.readout.exposure_cadence_s > 0.0 {
            self.readout.exposure_cadence_s
        } else {
            self.exposure_span_s()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plate_scale_matches_spec() {
        let s = Instrument::default().plate_scale_mas();
        assert!((s - 472.1).abs() < 0.1, "plate scale {s}");
    }
}
