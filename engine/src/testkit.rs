//! Test support shared by the engine's unit tests, the workspace tests (`tests/`) and the explorer's tests
//! (feature `testkit`, off in builds for users): a reduced but physical configuration, a synthetic PSF, the
//! software GPU adapter with the CI rule, and scratch directories.

use crate::analysis::StarResult;
use crate::config::{Backend, Config};
use crate::integrate::gpu::{GpuIntegrator, software_adapter};
use crate::optics::psf::PsfTable;
use crate::scoring::image::ScoredStar;
use crate::truth::TruthRow;

/// The default configuration with coarse PSF tables (`pupil_samples` across the pupil, `oversampling` cells
/// per pixel out to `radius_px`, 0.2-µm wavelength steps): PSF-bank tests that count and compare tables.
pub fn coarse_psf_config(pupil_samples: usize, oversampling: usize, radius_px: usize) -> Config {
    let mut cfg = Config::default();
    cfg.optics.pupil_samples = pupil_samples;
    cfg.optics.psf_oversampling = oversampling;
    cfg.optics.psf_radius_px = radius_px;
    cfg.band.wavelength_step_um = 0.2;
    cfg
}

/// A 512² detector (4 channels of 128 columns), an 8 × 8 grid of stars 56 px apart, a coarser PSF grid and
/// wavelength sampling, and a 2-minute ACE series; the instrument exactly as designed (no `[as_built]`
/// deviation, each star its own wavefront: a component test switches on what it tests); everything else
/// (optics, noise, photometry) as the paper. Runs in seconds in the dev profile.
pub fn small_config() -> Config {
    let mut c = Config::default();
    c.instrument.detector_px = 512;
    c.instrument.photosensitive_px = 496;
    c.readout.channels = 4;
    c.readout.channel_width_px = 128;
    c.scene.grid_n = 8;
    c.scene.grid_spacing_px = 56.0;
    c.optics.pupil_samples = 128;
    c.optics.psf_oversampling = 8;
    c.optics.psf_radius_px = 10;
    c.band.wavelength_step_um = 0.05;
    c.fidelity.subpixels = 4;
    c.fidelity.images = 3;
    c.fidelity.backend = Backend::Cpu;
    c.ace.span_s = 120.0;
    c.as_built = crate::config::AsBuilt::design();
    c.optics.field_zone_px = 0;
    if let Err(e) = c.validate() {
        panic!("the small test config must be valid: {e}");
    }
    c
}

/// Switch off every noise of the detector — shot and read noise, rounding, dark, the flat's scatter — so
/// that a pixel holds the signal alone.
pub fn signal_only(c: &mut Config) {
    c.detector.shot_noise = false;
    c.detector.read_noise = false;
    c.detector.digitise = false;
    c.detector.dark_e_per_s = 0.0;
    c.detector.inter_pixel_flat_sigma = 0.0;
}

/// A synthetic, asymmetric PSF table (`os` cells per pixel, `half_px` pixels each side, unit sum): an
/// elliptical Gaussian core (σ 0.7 px, y squeezed by 0.7) tilted by a linear ramp in x, plus a faint
/// exponential halo — no symmetry a method could exploit by accident.
pub fn synthetic_psf(os: usize, half_px: usize) -> PsfTable {
    let half = half_px * os;
    let n = 2 * half + 1;
    let mut data = vec![0.0; n * n];
    for iy in 0..n {
        for ix in 0..n {
            let (x, y) = (
                (ix as f64 - half as f64) / os as f64,
                (iy as f64 - half as f64) / os as f64,
            );
            data[iy * n + ix] = (-(x * x + 0.7 * y * y) / (2.0 * 0.7 * 0.7)).exp()
                * (1.0 + 0.25 * x).max(0.0)
                + 0.01 * (-(x * x + y * y).sqrt() / 2.0).exp();
        }
    }
    let s: f64 = data.iter().sum();
    data.iter_mut().for_each(|v| *v /= s);
    PsfTable {
        oversampling: os,
        half_cells: half,
        data,
    }
}

/// Whether this run must have a GPU adapter: in CI (`CI` set and not `false`/`0`) or when
/// `JSIM_REQUIRE_GPU` is set. `.ci/run` installs lavapipe and sets `CI=true`.
pub fn gpu_required() -> bool {
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0");
    ci || std::env::var_os("JSIM_REQUIRE_GPU").is_some()
}

/// The software Vulkan adapter (lavapipe; any adapter if there is no software one) as an integrator.
/// Without one: panics when [`gpu_required`] (a GPU test that skips silently in CI is a defect), else says
/// so on stderr and returns `None` so the caller skips.
pub fn software_gpu() -> Option<GpuIntegrator> {
    let Some(adapter) = software_adapter() else {
        assert!(
            !gpu_required(),
            "no Vulkan adapter found, and this run requires one (CI or JSIM_REQUIRE_GPU): install \
             mesa-vulkan-drivers (lavapipe)"
        );
        eprintln!(
            "no Vulkan adapter: GPU test skipped (set JSIM_REQUIRE_GPU=1 to make this a failure)"
        );
        return None;
    };
    match GpuIntegrator::from_adapter(adapter) {
        Ok(g) => Some(g),
        Err(e) => panic!("a Vulkan adapter exists but the integrator failed: {e}"),
    }
}

/// A fresh, empty scratch directory for one test (under the system temporary directory), removed with
/// everything in it when the value is dropped — at the test's end, passed or panicked.
pub fn temp_dir(name: &str) -> Scratch {
    let d = std::env::temp_dir().join(format!("jsim-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    if let Err(e) = std::fs::create_dir_all(&d) {
        panic!("cannot create {}: {e}", d.display());
    }
    Scratch(d)
}

/// A test's scratch directory: derefs to its path; removed (recursively) on drop.
#[derive(Debug)]
pub struct Scratch(std::path::PathBuf);

impl std::ops::Deref for Scratch {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for Scratch {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A measured star matched to truth star `truth`, fitted at `(x + dx, y + dy)` for a true position `(x, y)`
/// (px), with a 0.01-px bound and no prediction attached.
pub fn scored_star(truth: usize, x: f64, y: f64, dx: f64, dy: f64) -> ScoredStar {
    let t = TruthRow {
        x_px: x,
        y_px: y,
        ..Default::default()
    };
    ScoredStar::new(star_result(x + dx, y + dy), Some((truth, &t)))
}

/// A measured star at `(x, y)` (px) of 10⁴ e⁻ with a 0.01-px bound, unflagged.
pub fn star_result(x: f64, y: f64) -> StarResult {
    StarResult {
        x,
        y,
        flux_e: 1e4,
        sky_e: 0.0,
        crlb_x_px: 0.01,
        crlb_y_px: 0.01,
        flags: 0,
    }
}

/// erf by Abramowitz & Stegun 7.1.26 (|error| < 1.5·10⁻⁷): enough for a test image.
pub fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_429 * t - 1.453_152_027) * t) + 1.421_413_741) * t - 0.284_496_736) * t
            + 0.254_829_592)
            * t
            * (-x * x).exp();
    y.copysign(x)
}

/// Ranks of a solution as threads of this process, talking over channels with MPI's semantics (the
/// distributed solution's tests without MPI): start one thread per element, each calling
/// `solve_on(…, &ranks[r])`.
pub fn thread_ranks(size: usize) -> Vec<ThreadRanks> {
    use std::sync::mpsc::channel;
    // to[a][b] sends from a to b; from[b][a] receives it
    let mut to: Vec<Vec<Sender<Vec<f64>>>> = vec![Vec::new(); size];
    let mut from: Vec<Vec<Option<Receiver<Vec<f64>>>>> = (0..size)
        .map(|_| (0..size).map(|_| None).collect())
        .collect();
    for (a, row) in to.iter_mut().enumerate() {
        for inbox in from.iter_mut() {
            let (tx, rx) = channel();
            row.push(tx);
            inbox[a] = Some(rx);
        }
    }
    to.into_iter()
        .zip(from)
        .enumerate()
        .map(|(rank, (to, from))| ThreadRanks {
            rank,
            size,
            to,
            from: from.into_iter().flatten().map(Mutex::new).collect(),
        })
        .collect()
}

use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender};

/// `f` run on each of `size` [`thread_ranks`] at once; their results in rank order.
pub fn on_thread_ranks<T: Send>(size: usize, f: impl Fn(&ThreadRanks) -> T + Sync) -> Vec<T> {
    std::thread::scope(|s| {
        let f = &f;
        let handles: Vec<_> = thread_ranks(size)
            .into_iter()
            .map(|r| s.spawn(move || f(&r)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    })
}

/// One of [`thread_ranks`].
pub struct ThreadRanks {
    rank: usize,
    size: usize,
    to: Vec<Sender<Vec<f64>>>,
    from: Vec<Mutex<Receiver<Vec<f64>>>>,
}

impl ThreadRanks {
    fn recv(&self, from: usize) -> Vec<f64> {
        match self.from[from].lock().map(|rx| rx.recv()) {
            Ok(Ok(v)) => v,
            _ => panic!("rank {from} hung up on rank {}", self.rank),
        }
    }

    fn send(&self, to: usize, v: &[f64]) {
        if self.to[to].send(v.to_vec()).is_err() {
            panic!("rank {to} hung up on rank {}", self.rank);
        }
    }
}

impl crate::solution::Ranks for ThreadRanks {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    fn exchange(&self, partner: usize, mine: &[f64]) -> Vec<f64> {
        self.send(partner, mine);
        self.recv(partner)
    }
    fn max_in_place(&self, v: &mut [f64]) {
        for theirs in self.gather_all(v) {
            for (a, b) in v.iter_mut().zip(theirs) {
                *a = a.max(b);
            }
        }
    }
    fn gather_all(&self, mine: &[f64]) -> Vec<Vec<f64>> {
        for r in 0..self.size {
            self.send(r, mine);
        }
        (0..self.size).map(|r| self.recv(r)).collect()
    }
}
