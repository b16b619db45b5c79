//! One simulated exposure, end to end: scene → PSF bank → pixel kernels → ACE track → integration
//! (CPU or GPU) → detector → image + truth. [`Simulator`] holds everything that is shared between the
//! exposures of a dataset (PSFs, kernels, the ACE series, the flat), so a dataset costs one PSF per
//! distinct colour/zone and one integration per exposure.

use crate::config::{AceCase, Config, FlatField};
use crate::detector::{self, DetectorImage};
use crate::integrate::kernel::{IntraPixelMap, KernelCache, KernelError, PixelKernel};
use crate::integrate::track::Track;
use crate::integrate::{self, FrameSpec, Integrator, Motion, StarJob, StarSpec};
use crate::jitter::AceSeries;
use crate::optics::PsfBank;
use crate::optics::psf::PsfTable;
use crate::photometry;
use crate::readout::ReadoutTiming;
use crate::scene::{PlacementCounts, SceneError, Star};
pub use crate::truth::TruthRow;
use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Kernel(#[from] KernelError),
    #[error(
        "this simulation needs ≈ {need_gib:.1} GiB of memory and {available_gib:.1} GiB are available: \
         lower instrument.detector_px, the number of stars, ace.span_s or raise ace.sample_interval_ms"
    )]
    Memory { need_gib: f64, available_gib: f64 },
    #[error("GPU integration failed: {0}")]
    Gpu(#[from] crate::integrate::gpu::GpuError),
    #[error(
        "focal_plane.layout = \"quad\" images four arrays: {0} works on one array (set focal_plane.layout = \
         \"single\"; `jsim simulate` writes the quad's exposures)"
    )]
    NotSingleArray(&'static str),
    #[error("a persistence map of {got} pixels for a {n} × {n} detector")]
    PersistenceMap { got: usize, n: usize },
    #[error(transparent)]
    Instrument(#[from] crate::instrument::InstrumentError),
}

pub mod focal_plane;
mod windows;
pub use focal_plane::{FocalPlaneExposure, FocalPlaneSimulator};
pub use windows::WindowRead;

/// The array a simulator images: its place in the focal plane and its stars.
#[derive(Debug, Clone, PartialEq)]
pub struct ArraySpec {
    pub place: ArrayPlace,
    pub stars: Vec<Star>,
}

/// An array's place in the focal plane and its own random streams.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrayPlace {
    /// 0 for the single array; 0 … 3 in the quad (lower left, lower right, upper left, upper right).
    pub index: usize,
    /// The array's turn on the sky (degrees): the common jitter is turned into its pixel axes.
    pub rotation_deg: f64,
    /// Seed of the array's flat and noise streams ([`array_seed`]).
    pub seed: u64,
}

/// The seed of array k's flat and noise streams: the master seed for array 0 (so the single array's
/// images are those of before the focal plane existed), a derived seed for the others.
pub fn array_seed(master: u64, k: usize) -> u64 {
    if k == 0 {
        master
    } else {
        crate::rng::derive_seed(master, &[crate::rng::Stream::Array as u64, k as u64])
    }
}

/// The J − H whose PSF a star of colour `j_minus_h` uses: rounded to a multiple of
/// `fidelity.colour_step_mag` (unchanged when it is 0).
pub fn psf_colour(j_minus_h: f64, step_mag: f64) -> f64 {
    if step_mag > 0.0 {
        (j_minus_h / step_mag).round() * step_mag
    } else {
        j_minus_h
    }
}

/// The low-order Fringe terms whose derivative planes come with the design model PSF
/// ([`crate::optics::zernike::LOW_ORDER_TERMS`]).
pub const DESIGN_TERMS: [usize; 8] = crate::optics::zernike::LOW_ORDER_TERMS;

/// The step of the derivative planes' central differences, nm rms of wavefront per term: small against the
/// wavefront's own scale, large against the tables' rounding.
pub const TERM_STEP_NM: f64 = 10.0;

/// Per-exposure ACE statistics over the nominal window (mas).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AceStats {
    pub mean_x_mas: f64,
    pub mean_y_mas: f64,
    pub sigma_x_mas: f64,
    pub sigma_y_mas: f64,
    /// |mean over the last 10 % − mean over the first 10 %| of the window, combined.
    pub drift_mas: f64,
}

/// Wall-clock times of the stages of one exposure, seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    pub integrate_s: f64,
    pub detector_s: f64,
}

/// One simulated exposure.
#[derive(Debug, Clone)]
pub struct Exposure {
    pub index: usize,
    /// Start of the exposure in the ACE series, s.
    pub t_start_s: f64,
    /// Noise-free star electrons per pixel (before the flat), row-major.
    pub star_e: Vec<f64>,
    pub image: DetectorImage,
    pub truth: Vec<TruthRow>,
    pub ace: AceStats,
    pub times: StageTimes,
    /// Where the integration ran: "cpu" or the GPU adapter's name.
    pub backend: String,
}

const GIB: f64 = 1024.0 * 1024.0 * 1024.0;

/// Peak memory of a simulator of `cfg` with `n_stars` stars and of one exposure's analysis, bytes — an
/// estimate meant to be within a factor 2: the frame arrays (noise-free electrons f64, ADU f32, DQ, flat f32,
/// the analysis image f64 + mask: 26 B/pixel), the ACE series and its spectrum (2 axes × 48 B/sample), the
/// stamps (f64, radius + 3σ of the ACE each side) and the PSF and kernel tables (16 B per cell for each
/// of at most 64 colours × field zones).
pub fn memory_estimate_bytes(cfg: &Config, n_stars: usize) -> f64 {
    let n = cfg.instrument.detector_px as f64;
    let frame = 26.0 * n * n;
    let series = match cfg.ace.case {
        AceCase::Realistic => 96.0 * cfg.ace.span_s / (cfg.ace.sample_interval_ms * 1e-3),
        _ => 0.0,
    };
    let radius = match cfg.fidelity.stamp_radius_px {
        0 => cfg.optics.psf_radius_px as f64 + 2.0, // the kernel's reach
        r => r as f64,
    };
    let reach = radius + 3.0 * cfg.ace.sigma_mas / cfg.instrument.plate_scale_mas();
    let stamps = n_stars as f64 * 8.0 * (2.0 * reach + 1.0).powi(2);
    let cells =
        (2.0 * (cfg.optics.psf_radius_px * cfg.optics.psf_oversampling) as f64 + 1.0).powi(2);
    let tables = 16.0 * cells * 64.0;
    frame + series + stamps + tables
}

/// Fail when a simulation of `n_stars` over `arrays` arrays needs more memory than is available.
pub fn check_memory(cfg: &Config, n_stars: usize, arrays: usize) -> Result<(), SimError> {
    if let Some(avail) = available_memory_bytes() {
        let per_array = memory_estimate_bytes(cfg, 0);
        let need = per_array * (arrays.max(1) - 1) as f64 + memory_estimate_bytes(cfg, n_stars);
        if need > avail {
            return Err(SimError::Memory {
                need_gib: need / GIB,
                available_gib: avail / GIB,
            });
        }
    }
    Ok(())
}

/// Memory available to this process now (Linux: `MemAvailable` of /proc/meminfo), bytes.
pub fn available_memory_bytes() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// Shared state of a dataset's simulation.
///
/// Two instruments: `cfg` is the configuration the products beside the images are made from (the design;
/// the as-built instrument only under the `oracle` control `as_built.knowledge = "as-built"`), `built` the
/// instrument as built (`instrument::realise`), which takes the images: its PSFs, distortion, gain and read
/// noise. Only the simulation and the scoring may read `built` (docs/ARCHITECTURE.md).
pub struct Simulator {
    pub cfg: Config,
    /// The instrument as built: the images' optics, distortion and detector.
    built: Config,
    /// The stars this array simulates (for a sky scene, some just off the array for their light).
    pub stars: Vec<Star>,
    /// Which array, its turn and its streams' seed.
    pub array: ArrayPlace,
    /// This array's WCS as built (`sky::array_wcs`): where the stars truly land; made on first use.
    wcs: std::sync::OnceLock<Option<crate::sky::wcs::ArrayWcs>>,
    /// This array's WCS from the products' configuration (the design): what the headers state.
    design_wcs: std::sync::OnceLock<Option<crate::sky::wcs::ArrayWcs>>,
    /// The PSF bank of the products' optics (the design), when it is not the images' bank.
    design_bank: std::sync::OnceLock<Arc<PsfBank>>,
    /// The design kernels with each low-order term moved ± [`TERM_STEP_NM`] ([`Simulator::design_term_kernels`]).
    term_kernels: std::sync::OnceLock<Vec<(Arc<PixelKernel>, Arc<PixelKernel>)>>,
    /// Where a sky scene's stars fell (the whole focal plane's account; `None` for pixel scenes).
    pub counts: Option<PlacementCounts>,
    pub timing: ReadoutTiming,
    bank: Arc<PsfBank>,
    map: IntraPixelMap,
    kernels: Arc<KernelCache>,
    series: Option<Arc<AceSeries>>,
    flat: Vec<f32>,
    /// The calibration flat of `analysis.flat_field` (made on first use, once per simulator).
    calibration: std::sync::OnceLock<Arc<Vec<f32>>>,
    integrator: Integrator,
    /// The bank's PSFs turned into this array's axes (keyed by the bank table's address; the bank table is
    /// kept with its turn, so the address stays unique).
    turned: std::sync::Mutex<HashMap<usize, (Arc<PsfTable>, Arc<PsfTable>)>>,
}

/// `cfg` valid and of one array: the quad is refused before any of its four arrays is built.
pub(crate) fn check_single_array(cfg: &Config) -> Result<(), SimError> {
    cfg.validate()?;
    if crate::sky::array_count(cfg) != 1 {
        return Err(SimError::NotSingleArray("a single-array simulator"));
    }
    Ok(())
}

impl Simulator {
    /// Build with a fresh PSF bank and kernel cache, on the configured backend (a session shares these
    /// between simulators: the engine session's `simulator`).
    pub fn new(cfg: &Config) -> Result<Self, SimError> {
        let (integrator, _) = Integrator::choose(cfg.fidelity.backend);
        Self::build(
            cfg,
            Arc::new(PsfBank::new(cfg)),
            Arc::new(KernelCache::default()),
            integrator,
        )
    }

    /// Build from shared parts: a PSF bank (replaced by a fresh one if it does not serve `cfg`), a kernel
    /// cache and the integrator. One array only: this is the single array of a one-array focal plane
    /// ([`FocalPlaneSimulator::build`] is the one way a simulator is made; the quad is a
    /// [`FocalPlaneSimulator`] of four).
    pub fn build(
        cfg: &Config,
        bank: Arc<PsfBank>,
        kernels: Arc<KernelCache>,
        integrator: Integrator,
    ) -> Result<Self, SimError> {
        check_single_array(cfg)?;
        FocalPlaneSimulator::build(cfg, bank, kernels, integrator)?.into_single()
    }

    /// Build the simulator of one array from its spec, with the dataset's ACE series when another array
    /// already made it (the jitter is common to the focal plane), else its own from the master seed.
    pub fn build_array(
        cfg: &Config,
        array: ArraySpec,
        counts: Option<PlacementCounts>,
        bank: Arc<PsfBank>,
        kernels: Arc<KernelCache>,
        integrator: Integrator,
        series: Option<Arc<AceSeries>>,
    ) -> Result<Self, SimError> {
        let built = crate::instrument::realise(cfg)?;
        let bank = PsfBank::serving(bank, &built);
        let timing = ReadoutTiming::new(cfg);
        let map = IntraPixelMap::from_config(&cfg.detector, cfg.fidelity.subpixels)?;
        let series = match (cfg.ace.case, series) {
            (AceCase::Realistic, Some(s)) => Some(s),
            (AceCase::Realistic, None) => {
                let need = cfg.ace.first_exposure_start_s
                    + (cfg.fidelity.images.saturating_sub(1)) as f64 * timing.cadence_s()
                    + timing.span_s();
                if need > cfg.ace.span_s {
                    return Err(crate::config::ConfigError::Invalid {
                        field: "ace.span_s".into(),
                        value: cfg.ace.span_s.to_string(),
                        allowed: format!(
                            "must cover {} exposures of {:.2} s cadence: at least {need:.1} s (or lower fidelity.images)",
                            cfg.fidelity.images,
                            timing.cadence_s()
                        ),
                    }
                    .into());
                }
                Some(Arc::new(AceSeries::generate(cfg, cfg.seed, 0)))
            }
            _ => None,
        };
        let mut sim = Self {
            cfg: crate::instrument::products_config(cfg, &built),
            built,
            stars: array.stars,
            array: array.place,
            wcs: std::sync::OnceLock::new(),
            design_wcs: std::sync::OnceLock::new(),
            design_bank: std::sync::OnceLock::new(),
            term_kernels: std::sync::OnceLock::new(),
            counts,
            timing,
            bank,
            map,
            kernels,
            series,
            flat: Vec::new(),
            calibration: std::sync::OnceLock::new(),
            integrator,
            turned: Default::default(),
        };
        sim.flat = detector::inter_pixel_flat(&sim.detector_cfg());
        Ok(sim)
    }

    /// The configuration the detector stages use: the instrument as built with this array's seed (the flat
    /// and the noise are the array's own; the gain and read noise the as-built ones).
    pub fn detector_cfg(&self) -> Cow<'_, Config> {
        if self.array.seed == self.built.seed {
            Cow::Borrowed(&self.built)
        } else {
            let mut c = self.built.clone();
            c.seed = self.array.seed;
            Cow::Owned(c)
        }
    }

    /// `oracle`: the instrument as built (its optics, distortion and detector). For the simulation and the
    /// scoring only; products come from [`Simulator::cfg`].
    pub fn as_built_oracle(&self) -> &Config {
        &self.built
    }

    /// This array's WCS as built: where the stars truly land (`sky::array_wcs` of the as-built instrument;
    /// made once: with a distortion it fits the inverse). The truth's sky columns use it; headers use
    /// [`Simulator::design_wcs`].
    pub fn wcs(&self) -> Option<&crate::sky::wcs::ArrayWcs> {
        self.wcs
            .get_or_init(|| crate::sky::array_wcs(&self.built, self.array.index).ok())
            .as_ref()
    }

    /// This array's WCS as the products state it: the design distortion at the planned pointing (the
    /// as-built one under the oracle control). What an image header carries.
    pub fn design_wcs(&self) -> Option<&crate::sky::wcs::ArrayWcs> {
        if !self.wcs_deviates() {
            return self.wcs();
        }
        self.design_wcs
            .get_or_init(|| crate::sky::array_wcs(&self.cfg, self.array.index).ok())
            .as_ref()
    }

    /// Where the header's WCS puts the sky place of true pixel (x, y): its true sky place through the WCS as
    /// built, then the header's (design) WCS; (x, y) itself when the two agree. The catalogue's frame.
    pub fn in_header_frame_px(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        if !self.wcs_deviates() {
            return Some((x, y));
        }
        let (ra, dec) = self.wcs()?.pixel_to_sky(x, y)?;
        self.design_wcs()?.sky_to_pixel(ra, dec)
    }

    /// Whether the header's WCS differs from where the stars truly land (a distortion beyond the design).
    pub fn wcs_deviates(&self) -> bool {
        self.cfg.focal_plane != self.built.focal_plane || self.cfg.sky != self.built.sky
    }

    /// The PSF bank (shareable with other simulators of the same optics).
    pub fn bank(&self) -> Arc<PsfBank> {
        self.bank.clone()
    }

    /// The ACE series (realistic case).
    pub fn series(&self) -> Option<&AceSeries> {
        self.series.as_deref()
    }

    /// The ACE series, shareable.
    pub fn series_arc(&self) -> Option<Arc<AceSeries>> {
        self.series.clone()
    }

    /// The backend integration runs on: "cpu" or the adapter name.
    pub fn backend_name(&self) -> String {
        self.integrator.name_for(self.cfg.fidelity.method)
    }

    /// The integrator (CPU or GPU) this simulator uses.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }

    /// Jitter blur folded into the kernels (Gaussian ACE), px.
    fn blur_px(&self) -> f64 {
        match self.cfg.ace.case {
            AceCase::Gaussian => self.cfg.ace.sigma_mas / self.cfg.instrument.plate_scale_mas(),
            _ => 0.0,
        }
    }

    /// Compute the PSFs (`halo_px` 0) or halo tables of every star's colour and wavefront not yet in the
    /// bank, wavefront by wavefront ([`PsfBank::prepare`]).
    fn prepare_psfs(&self, halo_px: usize) {
        let wanted = self
            .stars
            .iter()
            .map(|s| (self.psf_colour(s), self.bank.field_key(s.x_px, s.y_px)));
        self.bank.prepare(wanted, halo_px);
    }

    /// The PSF of a star (from the bank).
    pub fn psf_for(&self, star: &Star) -> Arc<PsfTable> {
        self.in_array_axes(self.bank.get(
            self.psf_colour(star),
            &self.bank.field_key(star.x_px, star.y_px),
        ))
    }

    /// A bank PSF (focal-plane axes) as this array sees it: turned by the array's rotation (the same
    /// table on an unturned array).
    pub fn in_array_axes(&self, table: Arc<PsfTable>) -> Arc<PsfTable> {
        if self.array.rotation_deg == 0.0 {
            return table;
        }
        let key = Arc::as_ptr(&table) as usize;
        let mut m = self.turned.lock().unwrap_or_else(|e| e.into_inner());
        m.entry(key)
            .or_insert_with(|| {
                let t = Arc::new(table.turned_into_array(self.array.rotation_deg));
                (table, t)
            })
            .1
            .clone()
    }

    /// The colour whose PSF a star uses ([`psf_colour`]).
    pub fn psf_colour(&self, star: &Star) -> f64 {
        psf_colour(star.j_minus_h, self.cfg.fidelity.colour_step_mag)
    }

    /// The pixel kernel of a PSF with this simulation's blur and intra-pixel map (cached).
    pub fn kernel_for(&self, psf: &Arc<PsfTable>) -> Result<Arc<PixelKernel>, SimError> {
        self.kernel_with_blur(psf, self.blur_px())
    }

    /// The pixel kernel of a PSF blurred by a Gaussian of `blur` px (cached).
    pub fn kernel_with_blur(
        &self,
        psf: &Arc<PsfTable>,
        blur: f64,
    ) -> Result<Arc<PixelKernel>, SimError> {
        Ok(self.kernels.get(psf, blur, &self.map)?)
    }

    /// The unblurred pixel kernel of a typical star (its PSF with this simulation's pixel model): the PSF
    /// a calibrated pipeline would know.
    pub fn optical_kernel(&self) -> Result<Arc<PixelKernel>, SimError> {
        let psf = match self.stars.first() {
            Some(s) => self.psf_for(s),
            None => self.in_array_axes(
                self.bank
                    .get(self.cfg.scene.j_minus_h, &self.bank.centre_key()),
            ),
        };
        self.kernel_with_blur(&psf, 0.0)
    }

    /// The design's PSF of a star (its colour and field position through the products' bank: the design's
    /// optics, the as-built ones only under the oracle control); the star's own PSF without deviations.
    pub fn design_psf_for(&self, star: &Star) -> Arc<PsfTable> {
        let bank = self.design_bank();
        self.in_array_axes(bank.get(self.psf_colour(star), &bank.field_key(star.x_px, star.y_px)))
    }

    /// The design's PSF of a colour at the field's centre.
    pub fn design_psf_for_colour(&self, j_minus_h: f64) -> Arc<PsfTable> {
        let bank = self.design_bank();
        self.in_array_axes(bank.get(j_minus_h, &bank.centre_key()))
    }

    /// [`Simulator::optical_kernel`] of the design: the first star's [`Simulator::design_psf_for`] with
    /// this simulation's pixel model — what a planner knows before the instrument is built.
    pub fn design_optical_kernel(&self) -> Result<Arc<PixelKernel>, SimError> {
        let psf = match self.stars.first() {
            Some(s) => self.design_psf_for(s),
            None => self.design_psf_for_colour(self.cfg.scene.j_minus_h),
        };
        self.kernel_with_blur(&psf, 0.0)
    }

    /// The design pixel kernel: the PSF of the design wavefront at the field's centre for the scene's
    /// colour (no star's own field-dependent wavefront error), with this simulation's pixel model, in this
    /// array's axes — the model PSF an instrument team hands the analysis.
    pub fn design_kernel(&self) -> Result<Arc<PixelKernel>, SimError> {
        self.design_kernel_with_blur(0.0)
    }

    /// The design pixel kernel blurred by a Gaussian of `blur_px` (a jitter's σ the telemetry reports): the
    /// PSF of the products' optics (the design; the as-built optics only under the oracle control).
    pub fn design_kernel_with_blur(&self, blur_px: f64) -> Result<Arc<PixelKernel>, SimError> {
        let bank = self.design_bank();
        let psf = self.in_array_axes(bank.get(self.cfg.scene.j_minus_h, &bank.centre_key()));
        self.kernel_with_blur(&psf, blur_px)
    }

    /// The design pixel kernels (as [`Simulator::design_kernel`]) with each of the Fringe terms
    /// [`DESIGN_TERMS`] moved by −/+ [`TERM_STEP_NM`] nm rms of wavefront: what the design model PSF's derivative
    /// planes are differenced from (`io::instrument::model_psf_terms`). Computed once (2 PSFs a term).
    pub fn design_term_kernels(&self) -> Result<&[(Arc<PixelKernel>, Arc<PixelKernel>)], SimError> {
        if let Some(k) = self.term_kernels.get() {
            return Ok(k);
        }
        let mut out = Vec::with_capacity(DESIGN_TERMS.len());
        for &j in DESIGN_TERMS.iter() {
            let delta = crate::optics::coefficient_of_nm_rms(&self.cfg.optics, j, TERM_STEP_NM);
            let kernel = |sign: f64| -> Result<Arc<PixelKernel>, SimError> {
                let mut c = self.cfg.clone();
                crate::optics::add_term(&mut c.optics.fringe, j, sign * delta);
                for r in c.optics.field_table.iter_mut() {
                    crate::optics::add_term(&mut r.fringe, j, sign * delta);
                }
                // the images' store: the sequence's exposures and the focal plane's arrays compute them once
                let bank = PsfBank::serving(self.bank.clone(), &c);
                let psf = self.in_array_axes(bank.get(c.scene.j_minus_h, &bank.centre_key()));
                self.kernel_with_blur(&psf, 0.0)
            };
            out.push((kernel(-1.0)?, kernel(1.0)?));
        }
        Ok(self.term_kernels.get_or_init(|| out))
    }

    /// The PSF bank of the products' optics: the images' bank when the optics are the same, else one sharing
    /// its store when only the wavefront differs (the design against the as-built: a PSF is keyed by its
    /// wavefront, so the design's PSFs are computed once for a whole sequence and every array of a focal
    /// plane, not once per simulator; [`PsfBank::serving`]).
    fn design_bank(&self) -> Arc<PsfBank> {
        if self.bank.serves(&self.cfg) {
            return self.bank.clone();
        }
        self.design_bank
            .get_or_init(|| PsfBank::serving(self.bank.clone(), &self.cfg))
            .clone()
    }

    /// The nominal window (first pixel's) of exposure `index` on its track.
    pub fn nominal_window(&self, track: &Track) -> crate::integrate::track::WindowWeights {
        track.window(
            self.timing.t_overhead_s,
            self.timing.t_overhead_s + self.timing.exposure_s,
        )
    }

    /// Start time of exposure `index` in the ACE series.
    pub fn exposure_start_s(&self, index: usize) -> f64 {
        self.cfg.ace.first_exposure_start_s + index as f64 * self.timing.cadence_s()
    }

    /// The jitter track of exposure `index` (realistic case), in this array's pixel axes.
    pub fn track(&self, index: usize) -> Option<Track> {
        self.series.as_ref().map(|s| {
            Track::from_series(
                s,
                self.exposure_start_s(index),
                self.timing.span_s(),
                self.cfg.fidelity.time_stride,
                self.cfg.instrument.plate_scale_mas(),
            )
            .turned_into_array(self.array.rotation_deg)
        })
    }

    /// Star jobs for integration (PSF, kernel, rate). Stars of one PSF share its one kernel: the shared
    /// [`KernelCache`] keeps every kernel a job still holds, however many colour × zone PSFs the field has.
    pub fn jobs(&self) -> Result<Vec<StarJob>, SimError> {
        self.prepare_psfs(0);
        self.stars
            .iter()
            .map(|s| {
                let psf = self.psf_for(s);
                let kernel = self.kernel_for(&psf)?;
                let rate =
                    photometry::electrons_per_s(s.mag_hw, self.cfg.photometry.zero_point_e_per_s);
                let threshold = self.cfg.fidelity.wing_threshold_e;
                Ok(StarJob {
                    star: StarSpec {
                        x_px: s.x_px,
                        y_px: s.y_px,
                        rate_e_per_s: rate,
                    },
                    radius_px: if threshold > 0.0 {
                        kernel.reach_px(rate * self.cfg.detector.exposure_s, threshold)
                    } else {
                        0
                    },
                    kernel,
                    psf,
                })
            })
            .collect()
    }

    /// Noise-free star electrons of exposure `index` (the integration stage alone).
    pub fn integrate(
        &self,
        index: usize,
        jobs: &[StarJob],
    ) -> Result<(Vec<f64>, Option<Track>), SimError> {
        let n = self.cfg.instrument.detector_px;
        let track = self.track(index);
        let stamps = self.stamps(jobs, track.as_ref())?;
        let mut img = vec![0.0; n * n];
        integrate::add_stamps(&mut img, n, &stamps);
        if self.cfg.fidelity.halo_radius_px > 0 {
            integrate::add_stamps(&mut img, n, &self.halo_stamps()?);
        }
        Ok((img, track))
    }

    /// Noise-free star electrons of the jobs as stamps (only the pixels each star reaches), the star moving
    /// along `track` (or still).
    pub fn stamps(
        &self,
        jobs: &[StarJob],
        track: Option<&Track>,
    ) -> Result<Vec<integrate::Stamp>, SimError> {
        let motion = match track {
            Some(t) => Motion::Track(t),
            None => Motion::Static,
        };
        let frame = FrameSpec {
            timing: &self.timing,
            detector_px: self.cfg.instrument.detector_px,
            stamp_radius_px: self.cfg.fidelity.stamp_radius_px,
            method: self.cfg.fidelity.method,
            map: &self.map,
            deposit_phases: self.cfg.fidelity.deposit_phases,
        };
        Ok(self.integrator.integrate(jobs, motion, &frame)?)
    }

    /// The static PSF halo of every star (`fidelity.halo_radius_px` > 0): the PSF beyond the main table,
    /// integrated over 2 × 2 subpixels, jitter neglected (it moves the faint halo by ≪ its scale). With
    /// `fidelity.wing_threshold_e` > 0 only the stars that put more than that in a pixel beyond the main
    /// table get one, reaching as far as they do.
    pub fn halo_stamps(&self) -> Result<Vec<integrate::Stamp>, SimError> {
        let r = self.cfg.optics.psf_radius_px + self.cfg.fidelity.halo_radius_px;
        let map = IntraPixelMap::uniform(2);
        let mut out = Vec::with_capacity(self.stars.len());
        let mut kernels: HashMap<usize, Arc<PixelKernel>> = HashMap::new();
        self.prepare_psfs(self.cfg.fidelity.halo_radius_px);
        for s in &self.stars {
            let halo = self.in_array_axes(self.bank.halo(
                self.psf_colour(s),
                &self.bank.field_key(s.x_px, s.y_px),
                self.cfg.fidelity.halo_radius_px,
            ));
            let key = Arc::as_ptr(&halo) as usize;
            let k = match kernels.get(&key) {
                Some(k) => k.clone(),
                None => {
                    let k = Arc::new(PixelKernel::build(&halo, &map)?);
                    kernels.insert(key, k.clone());
                    k
                }
            };
            let star = StarSpec {
                x_px: s.x_px,
                y_px: s.y_px,
                rate_e_per_s: photometry::electrons_per_s(
                    s.mag_hw,
                    self.cfg.photometry.zero_point_e_per_s,
                ),
            };
            // with a wing threshold, only the stars bright enough to light pixels beyond the main table
            // get a halo, as far as they light them
            let threshold = self.cfg.fidelity.wing_threshold_e;
            let reach = if threshold > 0.0 {
                let flux = star.rate_e_per_s * self.cfg.detector.exposure_s;
                let reach = k.reach_px(flux, threshold);
                if reach <= self.cfg.optics.psf_radius_px {
                    continue;
                }
                reach
            } else {
                r + 1
            };
            if let Some(b) = integrate::cpu::stamp_bounds(
                s.x_px,
                s.y_px,
                None,
                reach,
                self.cfg.instrument.detector_px,
            ) {
                out.push(integrate::cpu::static_stamp(
                    &star,
                    &k,
                    self.cfg.detector.exposure_s,
                    b,
                ));
            }
        }
        Ok(out)
    }

    /// Fraction of a star's light the simulation models: what its kernel delivers (the PSF table, after the
    /// Gaussian-ACE blur when there is one), plus the halo when enabled.
    pub fn modelled_fraction(&self, star: &Star, kernel: &PixelKernel) -> f64 {
        let h = self.cfg.fidelity.halo_radius_px;
        if h == 0 {
            return kernel.light_fraction;
        }
        kernel.light_fraction
            + self
                .bank
                .halo(
                    self.psf_colour(star),
                    &self.bank.field_key(star.x_px, star.y_px),
                    h,
                )
                .sum()
    }

    /// The detector's true flat (what the charge is multiplied by), row-major.
    pub fn flat(&self) -> &[f32] {
        &self.flat
    }

    /// The calibration flat a pipeline holds for this detector (its true flat with the relative error of
    /// `analysis.flat_field`), made once; `None` when the analysis is uncalibrated.
    pub fn calibration_flat(&self) -> Option<Arc<Vec<f32>>> {
        let FlatField::Calibrated { error } = self.cfg.analysis.flat_field else {
            return None;
        };
        Some(
            self.calibration
                .get_or_init(|| {
                    Arc::new(detector::calibration_flat_of(
                        &self.detector_cfg(),
                        self.flat.clone(),
                        error,
                    ))
                })
                .clone(),
        )
    }

    /// Simulate exposure `index` of the dataset.
    pub fn exposure(&self, index: usize) -> Result<Exposure, SimError> {
        self.exposure_with(index, None)
    }

    /// Simulate exposure `index` with the persistence `released_e` (e⁻ per pixel, row-major: what the
    /// traps filled by earlier exposures release into it, `detector::persistence`) added to its charge.
    pub fn exposure_with(
        &self,
        index: usize,
        released_e: Option<&[f32]>,
    ) -> Result<Exposure, SimError> {
        if let Some(r) = released_e {
            let n = self.cfg.instrument.detector_px;
            if r.len() != n * n {
                return Err(SimError::PersistenceMap { got: r.len(), n });
            }
        }
        let jobs = self.jobs()?;
        let t0 = Instant::now();
        let (star_e, track) = self.integrate(index, &jobs)?;
        let t1 = Instant::now();
        let image = detector::expose(
            &self.detector_cfg(),
            &self.timing,
            &star_e,
            &self.flat,
            released_e,
            index as u64,
        );
        let t2 = Instant::now();
        let truth = self.truth(&jobs, track.as_ref());
        let ace = self.ace_stats(index);
        Ok(Exposure {
            index,
            t_start_s: self.exposure_start_s(index),
            star_e,
            image,
            truth,
            ace,
            times: StageTimes {
                integrate_s: (t1 - t0).as_secs_f64(),
                detector_s: (t2 - t1).as_secs_f64(),
            },
            backend: self.backend_name(),
        })
    }

    /// The star charge exposure `index` collects in each pixel (noise-free electrons × the flat, before
    /// dark and noise): what fills the traps of `detector::persistence`.
    pub fn collected_star_e(&self, index: usize) -> Result<Vec<f64>, SimError> {
        let (e, _) = self.integrate(index, &self.jobs()?)?;
        Ok(self.collected(&e))
    }

    /// The charge noise-free star electrons `star_e` (an exposure's) leave in each pixel: × the flat.
    pub fn collected(&self, star_e: &[f64]) -> Vec<f64> {
        star_e
            .iter()
            .zip(&self.flat)
            .map(|(v, f)| v * *f as f64)
            .collect()
    }

    /// Truth rows for the jobs of an exposure: the stars in this array's truth (`Star::in_truth`).
    pub fn truth(&self, jobs: &[StarJob], track: Option<&Track>) -> Vec<TruthRow> {
        let n = self.cfg.instrument.detector_px as i64;
        self.stars
            .iter()
            .zip(jobs)
            .filter(|(s, _)| s.in_truth)
            .map(|(s, j)| {
                let (cx, cy) = (
                    s.x_px.round().clamp(0.0, (n - 1) as f64) as usize,
                    s.y_px.round().clamp(0.0, (n - 1) as f64) as usize,
                );
                let (a, b) = self.timing.window_s(cx, cy);
                let (jx, jy) = match track {
                    Some(t) => t.window_mean(&t.window(a, b)),
                    None => (0.0, 0.0),
                };
                let (a, b) = if track.is_some() {
                    (a, b)
                } else {
                    (
                        self.timing.t_overhead_s,
                        self.timing.t_overhead_s + self.timing.exposure_s,
                    )
                };
                TruthRow {
                    id: s.id,
                    x_px: s.x_px,
                    y_px: s.y_px,
                    mag_hw: s.mag_hw,
                    j_minus_h: s.j_minus_h,
                    flux_e: j.star.rate_e_per_s * (b - a),
                    modelled_fraction: self.modelled_fraction(s, &j.kernel),
                    t_start_s: a,
                    exptime_s: b - a,
                    jitter_dx_px: jx,
                    jitter_dy_px: jy,
                }
            })
            .collect()
    }

    /// ACE statistics over exposure `index`'s nominal window.
    pub fn ace_stats(&self, index: usize) -> AceStats {
        let Some(s) = &self.series else {
            return AceStats::default();
        };
        let t0 = self.exposure_start_s(index) + self.timing.t_overhead_s;
        let t1 = t0 + self.timing.exposure_s;
        let ((mx, sx), (my, sy)) = s.window_stats(t0, t1);
        let tenth = 0.1 * self.timing.exposure_s;
        let ((ax, _), (ay, _)) = s.window_stats(t0, t0 + tenth);
        let ((bx, _), (by, _)) = s.window_stats(t1 - tenth, t1);
        AceStats {
            mean_x_mas: mx,
            mean_y_mas: my,
            sigma_x_mas: sx,
            sigma_y_mas: sy,
            drift_mas: ((bx - ax).powi(2) + (by - ay).powi(2)).sqrt(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    /// A 256-px array of `grid_n`² stars `spacing_px` apart, coarse optics, an as-built wavefront changing by
    /// 20 nm rms across the array, shared over zones of `zone_px`.
    fn zoned_field(grid_n: usize, spacing_px: f64, zone_px: usize) -> Config {
        let mut c = crate::testkit::small_config();
        c.instrument.detector_px = 256;
        c.instrument.photosensitive_px = 240;
        c.readout.channels = 2;
        c.scene.grid_n = grid_n;
        c.scene.grid_spacing_px = spacing_px;
        c.optics.pupil_samples = 32;
        c.optics.psf_oversampling = 4;
        c.optics.psf_radius_px = 4;
        c.band.wavelength_step_um = 0.2;
        c.fidelity.stamp_radius_px = 4;
        c.as_built.wavefront_field_rms_nm = 20.0;
        c.optics.field_zone_px = zone_px;
        c
    }

    /// More colour × zone PSFs than the shared kernel cache's size (an as-built wavefront changing across
    /// the array): every star's job still shares its PSF's one kernel. The cache once forgot all its entries
    /// as it filled, held or not, and the jobs held a fresh kernel per star — the as-built bulge exposure grew
    /// past 19 GB without finishing.
    #[test]
    fn a_field_of_many_psfs_builds_one_kernel_per_psf() {
        // four stars to a zone, the zones visited row after row of stars: a key comes back after others
        let c = zoned_field(30, 7.0, 12);
        let sim = Simulator::new(&c).expect("simulator");
        let jobs = sim.jobs().expect("jobs");
        let psfs: HashSet<usize> = jobs.iter().map(|j| Arc::as_ptr(&j.psf) as usize).collect();
        let kernels: HashSet<usize> = jobs
            .iter()
            .map(|j| Arc::as_ptr(&j.kernel) as usize)
            .collect();
        assert!(
            psfs.len() > KernelCache::MAX_ENTRIES,
            "{} PSFs: the case needs more than the cache holds",
            psfs.len()
        );
        assert_eq!(kernels.len(), psfs.len());
    }

    /// Each wavefront's monochromatic set is computed once however the stars are ordered: a bank that keeps
    /// one set at a time, stars of three colours row by row across 16 zones (a zone's next colour comes after
    /// the other zones), computes one set per wavefront (asked star by star it computed one per PSF: 48).
    #[test]
    fn a_field_of_many_wavefronts_computes_each_monochromatic_set_once() {
        let c = zoned_field(16, 14.0, 64);
        let built = crate::instrument::realise(&c).expect("as built");
        let bank = Arc::new(PsfBank::new(&built).with_mono_cache_bytes(1));
        let (integrator, _) = Integrator::choose(c.fidelity.backend);
        let mut sim = Simulator::build(
            &c,
            bank.clone(),
            Arc::new(KernelCache::default()),
            integrator,
        )
        .expect("simulator");
        // three colours, row after row of 16 stars: a zone's next colour comes after the other zones
        for (i, s) in sim.stars.iter_mut().enumerate() {
            s.j_minus_h = 1.0 + 0.5 * ((i / 16) % 3) as f64;
        }
        // the wavefronts: one per zone, less any two zones that round alike
        let zones: HashSet<crate::optics::FieldKey> = sim
            .stars
            .iter()
            .map(|s| bank.field_key(s.x_px, s.y_px))
            .collect();
        let colours: HashSet<i64> = sim
            .stars
            .iter()
            .map(|s| (sim.psf_colour(s) * 1000.0).round() as i64)
            .collect();
        assert!(
            zones.len() >= 9 && colours.len() >= 3,
            "{zones:?} {colours:?}"
        );
        sim.jobs().expect("jobs");
        let psfs: HashSet<(i64, crate::optics::FieldKey)> = sim
            .stars
            .iter()
            .map(|s| {
                let c = (sim.psf_colour(s) * 1000.0).round() as i64;
                (c, bank.field_key(s.x_px, s.y_px))
            })
            .collect();
        assert_eq!(bank.len(), psfs.len());
        assert_eq!(bank.monochromatic_sets_built(), zones.len());
    }
}
