//! Exposure integration: every pixel integrates the jittering PSF over its own exposure window.
//!
//! * [`kernel`]: the pixel-response table K (subpixels + intra-pixel map folded in, exactly);
//! * [`track`]: the jitter track on the time grid and window weights;
//! * [`cpu`]: reference, direct and fast methods on the CPU (rayon over stars);
//! * the same direct and fast methods on the GPU live in [`crate::integrate::gpu`] (WGSL in `shaders/`).
//!
//! Cost grows with what the scene holds: stamps only around stars, one kernel per distinct PSF, and the
//! fast method integrates once the part of the exposure all pixels of a stamp share.

pub mod cpu;
pub mod gpu;
pub mod kernel;
pub mod track;

use crate::config::{Backend, Method};
use crate::optics::psf::PsfTable;
use crate::readout::ReadoutTiming;
pub use cpu::{Stamp, StarSpec};
use kernel::{IntraPixelMap, PixelKernel};
use rayon::prelude::*;
use std::sync::Arc;
use track::Track;

/// How the star moves during the exposure.
#[derive(Debug, Clone, Copy)]
pub enum Motion<'a> {
    /// No time dependence (Gaussian ACE folded into the kernel, or a still telescope).
    Static,
    /// A jitter track; every pixel integrates its own window.
    Track(&'a Track),
}

/// One star with the PSF/kernel it uses.
#[derive(Debug, Clone)]
pub struct StarJob {
    pub star: StarSpec,
    pub kernel: Arc<PixelKernel>,
    /// Needed by the reference method only.
    pub psf: Arc<PsfTable>,
    /// This star's stamp half-size before the jitter margin (its light's reach,
    /// `fidelity.wing_threshold_e`); 0 = the frame's rule.
    pub radius_px: usize,
}

/// Frame-level parameters of an integration.
#[derive(Debug, Clone)]
pub struct FrameSpec<'a> {
    pub timing: &'a ReadoutTiming,
    pub detector_px: usize,
    /// Stamp half-size before the jitter margin: 0 = each star's kernel reach (all light kept, the
    /// default); a positive value truncates the stamp there (an approximation `jsim bench` measures).
    pub stamp_radius_px: usize,
    pub method: Method,
    pub map: &'a IntraPixelMap,
    /// `fidelity.deposit_phases`: the CPU fast method deposits the part of the exposure every pixel shares
    /// once, at this many star phases per node, and interpolates ([`cpu::SharedCore`]); 0 = each star its
    /// whole track (exact). The GPU always deposits each star's whole track.
    pub deposit_phases: usize,
}

impl FrameSpec<'_> {
    /// The shared part of the exposure at `frame.deposit_phases` phases, when the CPU fast method uses one.
    pub fn shared_core(&self, motion: Motion<'_>, nodes_per_px: usize) -> Option<cpu::SharedCore> {
        match (motion, self.method) {
            (Motion::Track(t), Method::Fast) if self.deposit_phases > 0 => {
                let (a, b) = self.timing.shared_window_s(self.detector_px);
                cpu::SharedCore::new(t, a, b, nodes_per_px, self.deposit_phases)
            }
            _ => None,
        }
    }
}

/// Stamp bounds of a job, or `None` when it misses the detector.
pub fn bounds_of(
    job: &StarJob,
    motion: Motion<'_>,
    frame: &FrameSpec<'_>,
) -> Option<(i64, i64, usize, usize)> {
    let track = match motion {
        Motion::Static => None,
        Motion::Track(t) => Some(t),
    };
    let radius = match (job.radius_px, frame.stamp_radius_px) {
        (0, 0) => job.kernel.stamp_radius_px(),
        (0, r) => r,
        (own, 0) => own,
        (own, r) => own.min(r),
    };
    cpu::stamp_bounds(
        job.star.x_px,
        job.star.y_px,
        track,
        radius,
        frame.detector_px,
    )
}

/// Integrate one star on the CPU (`core`: the frame's shared part for the fast method, or none).
pub fn integrate_star_cpu(
    job: &StarJob,
    motion: Motion<'_>,
    frame: &FrameSpec<'_>,
    core: Option<&cpu::SharedCore>,
) -> Option<Stamp> {
    let b = bounds_of(job, motion, frame)?;
    Some(match motion {
        Motion::Static => cpu::static_stamp(&job.star, &job.kernel, frame.timing.exposure_s, b),
        Motion::Track(t) => match frame.method {
            Method::Reference => {
                cpu::reference_stamp(&job.star, &job.psf, frame.map, t, frame.timing, b)
            }
            Method::Direct => cpu::direct_stamp(&job.star, &job.kernel, t, frame.timing, b),
            Method::Fast => {
                // a core deposited on another kernel grid does not apply
                let core = core.filter(|c| c.nodes_per_px() == job.kernel.nodes_per_px);
                cpu::fast_stamp(&job.star, &job.kernel, t, frame.timing, b, core)
            }
        },
    })
}

/// Integrate all stars on the CPU (parallel over stars).
pub fn integrate_cpu(jobs: &[StarJob], motion: Motion<'_>, frame: &FrameSpec<'_>) -> Vec<Stamp> {
    let core = jobs
        .first()
        .and_then(|j| frame.shared_core(motion, j.kernel.nodes_per_px));
    jobs.par_iter()
        .filter_map(|j| integrate_star_cpu(j, motion, frame, core.as_ref()))
        .collect()
}

/// Where integration runs: the CPU (rayon over stars) or a GPU through wgpu.
#[derive(Clone)]
pub enum Integrator {
    Cpu,
    Gpu(Arc<gpu::GpuIntegrator>),
}

impl Integrator {
    /// The integrator a backend asks for — the one place the CPU-or-GPU choice is made. `cpu`: the CPU.
    /// `auto`: a hardware GPU when there is one, else the CPU. `gpu`: any adapter, a software one
    /// (lavapipe) included, else the CPU. When the CPU stands in for a GPU, the note says why (to be shown
    /// once). The GPU context is created once per process.
    pub fn choose(backend: Backend) -> (Integrator, Option<String>) {
        match backend {
            Backend::Cpu => (Integrator::Cpu, None),
            Backend::Gpu | Backend::Auto => {
                match gpu::GpuIntegrator::shared(backend == Backend::Gpu) {
                    Ok(g) => (Integrator::Gpu(g), None),
                    Err(e) => (Integrator::Cpu, Some(e.to_string())),
                }
            }
        }
    }

    /// "cpu" or the GPU adapter's name.
    pub fn name(&self) -> String {
        match self {
            Integrator::Cpu => "cpu".to_string(),
            Integrator::Gpu(g) => g.adapter_name(),
        }
    }

    /// The name of where `method` runs: the reference method is CPU-only.
    pub fn name_for(&self, method: Method) -> String {
        match method {
            Method::Reference => "cpu".to_string(),
            _ => self.name(),
        }
    }

    /// Integrate all stars (the reference method always on the CPU).
    pub fn integrate(
        &self,
        jobs: &[StarJob],
        motion: Motion<'_>,
        frame: &FrameSpec<'_>,
    ) -> Result<Vec<Stamp>, gpu::GpuError> {
        match (self, frame.method) {
            (Integrator::Gpu(g), Method::Direct | Method::Fast) => g.integrate(jobs, motion, frame),
            _ => Ok(integrate_cpu(jobs, motion, frame)),
        }
    }
}

/// Add stamps into a row-major `n × n` image.
pub fn add_stamps(image: &mut [f64], n: usize, stamps: &[Stamp]) {
    for s in stamps {
        for iy in 0..s.ny {
            let y = s.y0 as usize + iy;
            let row = &mut image[y * n + s.x0 as usize..y * n + s.x0 as usize + s.nx];
            for (o, v) in row.iter_mut().zip(&s.data[iy * s.nx..(iy + 1) * s.nx]) {
                *o += v;
            }
        }
    }
}
