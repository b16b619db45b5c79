//! Exposure integration: every pixel integrates the jittering PSF over its own exposure window.
//!
//! * [`kernel`]: the pixel-response table K (subpixels + intra-pixel map folded in, exactly);
//! * [`track`]: the jitter track on the time grid and window weights;
//! * [`cpu`]: reference, direct and fast methods on the CPU (rayon over stars);
//! * [`convolve`]: the fast method's histogram ⊛ K at the pixel centres, blocked for the vector units;
//! * [`own_samples`]: the fast method's pixels' own few samples, looked up across a row at once;
//! * the same direct and fast methods on the GPU live in [`crate::integrate::gpu`] (WGSL in `shaders/`).
//!
//! Cost grows with what the scene holds: stamps only around stars, one kernel per distinct PSF, and the
//! fast method integrates once the part of the exposure all pixels of a stamp share.

pub mod convolve;
pub mod cpu;
pub mod exact_core;
pub mod gpu;
pub mod histogram;
pub mod kernel;
pub mod own_samples;
pub mod polyphase;
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
    /// once, at this many star phases per node, and interpolates ([`cpu::SharedCore`]); 0 = deposited once
    /// grouped by cell and read exactly at each star's phase ([`exact_core`]). The GPU always deposits each
    /// star's whole track.
    pub deposit_phases: usize,
}

impl FrameSpec<'_> {
    /// The shared part of the exposure for the CPU fast method (exact, or at `frame.deposit_phases` phases).
    pub fn shared_core(&self, motion: Motion<'_>, nodes_per_px: usize) -> Option<cpu::SharedCore> {
        match (motion, self.method) {
            (Motion::Track(t), Method::Fast) => {
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
    core: Option<&mut cpu::CoreReader<'_>>,
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
                let core = core.filter(|c| c.core.nodes_per_px() == job.kernel.nodes_per_px);
                cpu::fast_stamp(&job.star, &job.kernel, t, frame.timing, b, core)
            }
        },
    })
}

/// Stars that read the shared core through one reader, in order (a fixed number, whatever the threads).
const READ_RUN: usize = 64;
/// Strips of the phase square in the stars' reading order.
const PHASE_STRIPS: usize = 8;

/// Integrate all stars on the CPU (parallel over stars).
pub fn integrate_cpu(jobs: &[StarJob], motion: Motion<'_>, frame: &FrameSpec<'_>) -> Vec<Stamp> {
    let core = jobs
        .first()
        .and_then(|j| frame.shared_core(motion, j.kernel.nodes_per_px));
    // stars taken kernel by kernel (each thread works through one kernel's stars while its table is in the
    // caches: a 10⁵-star field cycles through ≈ 10² kernels of a few MB each), each kernel's stars in order
    // of their phase on the node grid (the shared core's reader then moves few samples from one star to
    // the next), in fixed runs of stars that each read the core from a fresh reader — the stamps do not
    // depend on the number of threads. They are returned in the jobs' order, so the image is summed in the
    // same order whatever the grouping.
    let g = jobs.first().map_or(1, |j| j.kernel.nodes_per_px) as f64;
    let key = |i: usize| {
        let s = &jobs[i].star;
        let (fu, fv) = ((s.x_px * g).rem_euclid(1.0), (s.y_px * g).rem_euclid(1.0));
        // a boustrophedon through the unit square of phases: strips along u, v up one strip and down
        // the next
        let strip = (fu * PHASE_STRIPS as f64) as usize;
        let along = if strip.is_multiple_of(2) {
            fv
        } else {
            1.0 - fv
        };
        (Arc::as_ptr(&jobs[i].kernel) as usize, strip, along, fu)
    };
    // each star's key worked out once (the sort runs before the threads start)
    let keys: Vec<(usize, usize, f64, f64)> = (0..jobs.len()).map(key).collect();
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by(|&i, &j| {
        let (a, b) = (keys[i], keys[j]);
        (a.0, a.1)
            .cmp(&(b.0, b.1))
            .then(a.2.total_cmp(&b.2))
            .then(a.3.total_cmp(&b.3))
            .then(i.cmp(&j))
    });
    let mut done: Vec<Option<Stamp>> = order
        .par_chunks(READ_RUN)
        .flat_map_iter(|run| {
            let mut reader = core.as_ref().map(|c| c.reader());
            run.iter()
                .map(|&i| integrate_star_cpu(&jobs[i], motion, frame, reader.as_mut()))
                .collect::<Vec<_>>()
        })
        .collect();
    let mut stamps: Vec<Option<Stamp>> = vec![None; jobs.len()];
    for (k, &i) in order.iter().enumerate() {
        stamps[i] = done[k].take();
    }
    stamps.into_iter().flatten().collect()
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
    // bands of rows side by side on the threads, each adding the stamps that reach it in the stamps' order:
    // every pixel sums its stamps in the same order whatever the threads
    const BAND_ROWS: usize = 64;
    if n == 0 {
        return;
    }
    image
        .par_chunks_mut(BAND_ROWS * n)
        .enumerate()
        .for_each(|(b, band)| {
            let (y_lo, y_hi) = (b * BAND_ROWS, b * BAND_ROWS + band.len() / n);
            for s in stamps {
                let (sy0, sy1) = (s.y0 as usize, s.y0 as usize + s.ny);
                for y in sy0.max(y_lo)..sy1.min(y_hi) {
                    let iy = y - sy0;
                    let at = (y - y_lo) * n + s.x0 as usize;
                    let row = &mut band[at..at + s.nx];
                    for (o, v) in row.iter_mut().zip(&s.data[iy * s.nx..(iy + 1) * s.nx]) {
                        *o += v;
                    }
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, ReadoutOrder};

    /// Stamps that overlap each other and the bands of rows the threads take: the image holds, bit for bit,
    /// what adding them one after another gives (each pixel sums its stamps in their order).
    #[test]
    fn stamps_add_band_by_band_as_one_after_another() {
        let n = 150;
        let stamps: Vec<Stamp> = (0..40)
            .map(|k| {
                let (nx, ny) = (3 + k % 17, 2 + (k * 7) % 23);
                Stamp {
                    x0: ((k * 37) % (n - nx)) as i64,
                    y0: ((k * 53) % (n - ny)) as i64,
                    nx,
                    ny,
                    data: (0..nx * ny)
                        .map(|i| 0.1 + (i * 13 + k) as f64 * 1.7e-3)
                        .collect(),
                }
            })
            .collect();
        assert!(
            stamps
                .iter()
                .any(|s| s.y0 < 64 && s.y0 as usize + s.ny > 64)
        );
        let mut one_by_one = vec![0.25; n * n];
        for s in &stamps {
            for iy in 0..s.ny {
                for ix in 0..s.nx {
                    one_by_one[(s.y0 as usize + iy) * n + s.x0 as usize + ix] +=
                        s.data[iy * s.nx + ix];
                }
            }
        }
        let mut banded = vec![0.25; n * n];
        add_stamps(&mut banded, n, &stamps);
        assert!(
            banded
                .iter()
                .zip(&one_by_one)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        add_stamps(&mut [], 0, &stamps);
    }

    /// Stars of several kernels, interleaved: the stamps come back in the jobs' order (the image is summed
    /// in that order), each equal to the star integrated on its own (to rounding: the shared core's reader
    /// sums the same terms in another order), and the same bits whatever the number of threads.
    #[test]
    fn stamps_come_back_in_the_jobs_order() {
        let mut cfg = Config::default();
        cfg.readout.order = ReadoutOrder::Rolling;
        cfg.detector.exposure_s = 1.0;
        let timing = ReadoutTiming::new(&cfg);
        let map = IntraPixelMap::uniform(4);
        let kernels: Vec<(Arc<PsfTable>, Arc<PixelKernel>)> = [4usize, 5, 6]
            .into_iter()
            .map(|half| {
                let psf = Arc::new(crate::testkit::synthetic_psf(8, half));
                let k = Arc::new(PixelKernel::build(&psf, &map).expect("kernel"));
                (psf, k)
            })
            .collect();
        let n = 4000;
        let dx = (0..n).map(|j| 0.3 * (j as f64 * 0.01).sin()).collect();
        let dy = (0..n).map(|j| 0.2 * (j as f64 * 0.013).cos()).collect();
        let track = Track::new(timing.span_s() / n as f64, 0.0, dx, dy);
        // more stars than one reader's run, at phases all over the node
        let jobs: Vec<StarJob> = (0..150)
            .map(|i| {
                let (psf, kernel) = kernels[(i * 7) % 3].clone();
                StarJob {
                    star: StarSpec {
                        x_px: 20.0 + 2.37 * i as f64,
                        y_px: 30.0 + (1.91 * i as f64) % 330.0,
                        rate_e_per_s: 100.0 + i as f64,
                    },
                    kernel,
                    psf,
                    radius_px: 0,
                }
            })
            .collect();
        let frame = FrameSpec {
            timing: &timing,
            detector_px: 400,
            stamp_radius_px: 0,
            method: Method::Fast,
            map: &map,
            deposit_phases: 0,
        };
        let motion = Motion::Track(&track);
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool")
                .install(|| integrate_cpu(&jobs, motion, &frame))
        };
        let all = on(2);
        assert_eq!(all, on(1), "one thread against two");
        assert_eq!(all, on(3), "three threads against two");
        let core = frame.shared_core(motion, kernels[0].1.nodes_per_px);
        assert_eq!(all.len(), jobs.len());
        for (job, stamp) in jobs.iter().zip(&all) {
            let own = integrate_star_cpu(
                job,
                motion,
                &frame,
                core.as_ref().map(|c| c.reader()).as_mut(),
            )
            .expect("on the detector");
            assert_eq!(
                (own.x0, own.y0, own.nx, own.ny),
                (stamp.x0, stamp.y0, stamp.nx, stamp.ny)
            );
            let peak = own.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, b) in own.data.iter().zip(&stamp.data) {
                assert!((a - b).abs() <= 1e-12 * peak, "{a} vs {b}");
            }
        }
    }
}
