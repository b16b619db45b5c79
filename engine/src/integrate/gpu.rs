//! wgpu compute integration: the direct and fast methods of [`crate::integrate`] on a GPU (WGSL kernels in
//! `shaders/`). Same inputs, same [`Stamp`] output as the CPU path; the tests run both on lavapipe and
//! compare them.
//!
//! Design: one long-lived [`GpuIntegrator`] holds the device and the three pipelines (direct, deposit,
//! fast); each call uploads the per-star parameters, per-pixel windows, the jitter track and the distinct
//! pixel kernels (cached between calls), dispatches over all stars of a batch at once, and reads back the
//! stamps. Precision: f32 storage and arithmetic with blocked Kahan accumulation (≈ 1e-7 relative over an
//! 83 000-sample exposure); the fast method's histogram uses fixed-point integer atomics (deterministic).
//! If no adapter exists the engine says so and uses the CPU path; nothing here panics on a missing GPU.

use crate::config::Method;
pub use crate::integrate::Stamp;
use crate::integrate::track::{Track, WindowWeights};
use crate::integrate::{FrameSpec, Motion, StarJob, bounds_of};
use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use wgpu::util::DeviceExt;

const COMMON_WGSL: &str = include_str!("../../../shaders/common.wgsl");
const LOOKUP_WGSL: &str = include_str!("../../../shaders/lookup.wgsl");
const DIRECT_WGSL: &str = include_str!("../../../shaders/integrate_direct.wgsl");
const DEPOSIT_WGSL: &str = include_str!("../../../shaders/deposit.wgsl");
const FAST_WGSL: &str = include_str!("../../../shaders/integrate_fast.wgsl");

/// The complete WGSL source of each kernel (shared declarations prepended): (name, entry point, source).
pub fn shader_sources() -> Vec<(&'static str, &'static str, String)> {
    vec![
        (
            "integrate_direct",
            "direct",
            format!("{COMMON_WGSL}\n{LOOKUP_WGSL}\n{DIRECT_WGSL}"),
        ),
        (
            "deposit",
            "deposit",
            format!("{COMMON_WGSL}\n{DEPOSIT_WGSL}"),
        ),
        (
            "integrate_fast",
            "fast",
            format!("{COMMON_WGSL}\n{LOOKUP_WGSL}\n{FAST_WGSL}"),
        ),
    ]
}

/// GPU problems; the engine falls back to the CPU on [`GpuError::NoAdapter`] and [`GpuError::SoftwareOnly`].
#[derive(Debug, Clone, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found ({0}); using the CPU path")]
    NoAdapter(#[source] Arc<wgpu::RequestAdapterError>),
    #[error(
        "only a software Vulkan adapter ({0}) is available, slower than the CPU path; using the CPU path (set fidelity.backend = \"gpu\" to use it anyway)"
    )]
    SoftwareOnly(String),
    #[error("GPU device request failed: {0}")]
    Device(#[source] Arc<wgpu::RequestDeviceError>),
    #[error("GPU validation error: {0}")]
    Validation(#[source] Arc<wgpu::Error>),
    #[error("GPU readback failed: {0}")]
    Readback(#[source] Arc<dyn std::error::Error + Send + Sync>),
    #[error("the reference method runs on the CPU only")]
    Unsupported,
}

/// Mirror of WGSL `Star` (64 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuStar {
    pub x_rel: f32,
    pub y_rel: f32,
    pub nx: u32,
    pub ny: u32,
    pub pixel_offset: u32,
    pub kernel_offset: u32,
    pub kernel_half: u32,
    pub kernel_g: u32,
    pub scale: f32,
    pub hist_offset: u32,
    pub hist_u0: i32,
    pub hist_v0: i32,
    pub common_first: u32,
    pub common_last: u32,
    pub common_wf: f32,
    pub common_wl: f32,
}
const _: () = assert!(std::mem::size_of::<GpuStar>() == 64);

/// Mirror of WGSL `Window` (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuWindow {
    pub first: u32,
    pub last: u32,
    pub wf: f32,
    pub wl: f32,
}
const _: () = assert!(std::mem::size_of::<GpuWindow>() == 16);

/// Mirror of WGSL `Params` (32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuParams {
    pub hist_nu: u32,
    pub hist_nv: u32,
    pub fixed_scale: f32,
    pub star_base: u32,
    /// Samples (direct) or histogram rows (fast) `lo..=hi` of this pass.
    pub lo: u32,
    pub hi: u32,
    /// 0 on the first pass, 1 when adding to `out`.
    pub accumulate: u32,
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuParams>().is_multiple_of(16));

impl From<WindowWeights> for GpuWindow {
    fn from(w: WindowWeights) -> Self {
        Self {
            first: w.first as u32,
            last: w.last as u32,
            wf: w.w_first as f32,
            wl: w.w_last as f32,
        }
    }
}

/// Most pixels per dispatch (keeps every buffer far below the 128 MiB binding limit).
const MAX_PIXELS_PER_BATCH: usize = 2 << 20;
/// Most histogram nodes per dispatch (u32 each).
const MAX_HIST_NODES_PER_BATCH: usize = 16 << 20;
/// Loop iterations per invocation and pass on software adapters: llvmpipe stops an invocation's loops after
/// 65 535 iterations in total, so long sums are split into passes that accumulate into the output.
const SOFTWARE_ITERATION_BUDGET: usize = 32_768;

/// The device and pipelines, built once.
pub struct GpuIntegrator {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    direct: wgpu::ComputePipeline,
    deposit: wgpu::ComputePipeline,
    fast: wgpu::ComputePipeline,
    kernel_cache: Mutex<Option<(Vec<usize>, Arc<wgpu::Buffer>, HashMap<usize, u32>)>>,
}

static SHARED: OnceLock<Result<Arc<GpuIntegrator>, GpuError>> = OnceLock::new();

impl GpuIntegrator {
    /// The process-wide integrator (created on first use). With `accept_software = false` (backend "auto")
    /// a software adapter such as lavapipe is declined in favour of the faster CPU path.
    pub fn shared(accept_software: bool) -> Result<Arc<GpuIntegrator>, GpuError> {
        let g = SHARED.get_or_init(|| Self::new().map(Arc::new)).clone()?;
        if !accept_software && g.is_software() {
            return Err(GpuError::SoftwareOnly(g.adapter_name()));
        }
        Ok(g)
    }

    /// Find an adapter (honouring `WGPU_BACKEND`/`WGPU_ADAPTER_NAME`), create the device and pipelines.
    pub fn new() -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(Arc::new(e)))?;
        Self::from_adapter(adapter)
    }

    /// Build on a given adapter (tests inject lavapipe this way).
    pub fn from_adapter(adapter: wgpu::Adapter) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("jsim"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(Arc::new(e)))?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let make = |name: &str, entry: &str, src: &str| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let src = shader_sources();
        let direct = make(src[0].0, src[0].1, &src[0].2);
        let deposit = make(src[1].0, src[1].1, &src[1].2);
        let fast = make(src[2].0, src[2].1, &src[2].2);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(Arc::new(e)));
        }
        Ok(Self {
            device,
            queue,
            info,
            direct,
            deposit,
            fast,
            kernel_cache: Mutex::new(None),
        })
    }

    /// Adapter name and backend, e.g. "NVIDIA H100 (Vulkan)".
    pub fn adapter_name(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    /// Whether the adapter is a CPU (software) implementation.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    fn storage(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        // bindings may not be empty: pad to 16 bytes
        let mut padded;
        let data = if bytes.len() < 16 {
            padded = bytes.to_vec();
            padded.resize(16, 0);
            &padded[..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: data,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Upload the distinct kernels of `jobs` (cached while the same kernels are used).
    fn kernels(&self, jobs: &[StarJob]) -> (Arc<wgpu::Buffer>, HashMap<usize, u32>) {
        let mut keys: Vec<usize> = jobs
            .iter()
            .map(|j| Arc::as_ptr(&j.kernel) as usize)
            .collect();
        keys.sort_unstable();
        keys.dedup();
        let mut cache = self.kernel_cache.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, buf, offs)) = cache.as_ref().filter(|(k, _, _)| *k == keys) {
            return (buf.clone(), offs.clone());
        }
        let mut data: Vec<f32> = Vec::new();
        let mut offsets = HashMap::new();
        for j in jobs {
            let key = Arc::as_ptr(&j.kernel) as usize;
            if let std::collections::hash_map::Entry::Vacant(e) = offsets.entry(key) {
                e.insert(data.len() as u32);
                data.extend(j.kernel.data.iter().map(|v| *v as f32));
            }
        }
        let buf = Arc::new(self.storage("kernels", bytemuck::cast_slice(&data)));
        *cache = Some((keys, buf.clone(), offsets.clone()));
        (buf, offsets)
    }

    /// Integrate all stars (direct or fast method; the static case uses the direct kernel with one sample).
    pub fn integrate(
        &self,
        jobs: &[StarJob],
        motion: Motion<'_>,
        frame: &FrameSpec<'_>,
    ) -> Result<Vec<Stamp>, GpuError> {
        if frame.method == Method::Reference {
            return Err(GpuError::Unsupported);
        }
        let still = Track::new(frame.timing.exposure_s, 0.0, vec![0.0], vec![0.0]);
        let (track, is_static) = match motion {
            Motion::Static => (&still, true),
            Motion::Track(t) => (t, false),
        };
        let fast = frame.method == Method::Fast && !is_static;
        let placed: Vec<(&StarJob, (i64, i64, usize, usize))> = jobs
            .iter()
            .filter_map(|j| bounds_of(j, motion, frame).map(|b| (j, b)))
            .collect();
        if placed.is_empty() {
            return Ok(Vec::new());
        }
        let (kbuf, koffs) = self.kernels(jobs);
        let track_data: Vec<[f32; 2]> = track
            .dx_px
            .iter()
            .zip(&track.dy_px)
            .map(|(x, y)| [*x as f32, *y as f32])
            .collect();
        let track_buf = self.storage("track", bytemuck::cast_slice(&track_data));
        let (min_x, max_x, min_y, max_y) = track.extent();
        let mut stamps = Vec::with_capacity(placed.len());
        let mut start = 0;
        while start < placed.len() {
            // batch: bounded pixels, histogram nodes and stars per dispatch
            let mut end = start;
            let mut pixels = 0usize;
            let mut hist_nodes = 0usize;
            let (mut nu, mut nv) = (0usize, 0usize);
            while end < placed.len() && end - start < 65_535 {
                let (job, (_, _, nx, ny)) = placed[end];
                let g = job.kernel.nodes_per_px as f64;
                let (u, v) = if fast {
                    (
                        ((max_x - min_x) * g).ceil() as usize + 4,
                        ((max_y - min_y) * g).ceil() as usize + 4,
                    )
                } else {
                    (1, 1)
                };
                let (bu, bv) = (nu.max(u), nv.max(v));
                let nodes = bu * bv * (end - start + 1);
                if end > start
                    && (pixels + nx * ny > MAX_PIXELS_PER_BATCH || nodes > MAX_HIST_NODES_PER_BATCH)
                {
                    break;
                }
                nu = bu;
                nv = bv;
                hist_nodes = nodes;
                pixels += nx * ny;
                end += 1;
            }
            let batch = &placed[start..end];
            let out = self.run_batch(
                batch,
                track,
                &track_buf,
                &kbuf,
                &koffs,
                is_static,
                fast,
                (nu, nv),
                hist_nodes,
                frame,
                (min_x, min_y),
            )?;
            stamps.extend(out);
            start = end;
        }
        Ok(stamps)
    }

    #[allow(clippy::too_many_arguments)]
    fn run_batch(
        &self,
        batch: &[(&StarJob, (i64, i64, usize, usize))],
        track: &Track,
        track_buf: &wgpu::Buffer,
        kbuf: &wgpu::Buffer,
        koffs: &HashMap<usize, u32>,
        is_static: bool,
        fast: bool,
        (nu, nv): (usize, usize),
        hist_nodes: usize,
        frame: &FrameSpec<'_>,
        (min_x, min_y): (f64, f64),
    ) -> Result<Vec<Stamp>, GpuError> {
        let mut stars = Vec::with_capacity(batch.len());
        let mut windows: Vec<GpuWindow> = Vec::new();
        let mut max_pixels = 0usize;
        let mut no_common = false;
        let n_common_max = track.len();
        let fixed_scale = ((u32::MAX as f64) / (n_common_max as f64 + 4.0))
            .floor()
            .min((1u64 << 24) as f64) as f32;
        let per_star = pixel_windows(batch, track, frame, is_static);
        windows.reserve(per_star.iter().map(|p| p.0.len()).sum());
        for (k, ((job, (x0, y0, nx, ny)), (w, common))) in batch.iter().zip(per_star).enumerate() {
            let x_rel = job.star.x_px - *x0 as f64;
            let y_rel = job.star.y_px - *y0 as f64;
            let pixel_offset = windows.len() as u32;
            windows.extend(w);
            // a stamp whose pixels share no part of their windows (exposure shorter than its read spread)
            // has no histogram to build: the batch runs the direct method
            no_common |= fast && common.first > common.last;
            let g = job.kernel.nodes_per_px as f64;
            max_pixels = max_pixels.max(nx * ny);
            stars.push(GpuStar {
                x_rel: x_rel as f32,
                y_rel: y_rel as f32,
                nx: *nx as u32,
                ny: *ny as u32,
                pixel_offset,
                kernel_offset: koffs
                    .get(&(Arc::as_ptr(&job.kernel) as usize))
                    .copied()
                    .unwrap_or(0),
                kernel_half: job.kernel.half_nodes as u32,
                kernel_g: job.kernel.nodes_per_px as u32,
                scale: (job.star.rate_e_per_s
                    * if is_static {
                        frame.timing.exposure_s
                    } else {
                        track.dt_s
                    }) as f32,
                hist_offset: (k * nu * nv) as u32,
                hist_u0: ((x_rel + min_x) * g).floor() as i32 - 1,
                hist_v0: ((y_rel + min_y) * g).floor() as i32 - 1,
                common_first: common.first,
                common_last: common.last,
                common_wf: common.wf,
                common_wl: common.wl,
            });
        }
        let fast = fast && !no_common;
        let n_pixels = windows.len();
        let stars_buf = self.storage("stars", bytemuck::cast_slice(&stars));
        let windows_buf = self.storage("windows", bytemuck::cast_slice(&windows));
        let out_size = (n_pixels.max(4) * 4) as u64;
        let out_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("out"),
            size: out_size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("staging"),
            size: out_size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let passes = passes(fast, (nu, nv), track.len(), self.is_software(), fixed_scale);
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("integrate"),
            });
        let groups_x = max_pixels.div_ceil(64) as u32;
        let n_stars = stars.len() as u32;
        let uniform = |p: &GpuParams| {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("params"),
                    contents: bytemuck::bytes_of(p),
                    usage: wgpu::BufferUsages::UNIFORM,
                })
        };
        if fast {
            let hist_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hist"),
                size: (hist_nodes.max(4) * 4) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            enc.clear_buffer(&hist_buf, 0, None);
            let params_buf = uniform(&passes[0]);
            self.dispatch(
                &mut enc,
                &self.deposit,
                "deposit",
                &[&params_buf, &stars_buf, track_buf, &hist_buf],
                (n_stars, 1),
            );
            for p in &passes {
                let params_buf = uniform(p);
                let bufs = [
                    &params_buf,
                    &stars_buf,
                    &windows_buf,
                    track_buf,
                    kbuf,
                    &hist_buf,
                    &out_buf,
                ];
                self.dispatch(&mut enc, &self.fast, "fast", &bufs, (groups_x, n_stars));
            }
        } else {
            for p in &passes {
                let params_buf = uniform(p);
                let bufs = [
                    &params_buf,
                    &stars_buf,
                    &windows_buf,
                    track_buf,
                    kbuf,
                    &out_buf,
                ];
                self.dispatch(&mut enc, &self.direct, "direct", &bufs, (groups_x, n_stars));
            }
        }
        enc.copy_buffer_to_buffer(&out_buf, 0, &staging, 0, out_size);
        self.queue.submit(Some(enc.finish()));
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(Arc::new(e)));
        }
        let values = self.read_back(&staging, n_pixels)?;
        Ok(stamps(batch, &stars, &values))
    }

    /// Bind `buffers` to bindings 0, 1, … of `pipeline` and dispatch `groups` workgroups in a compute pass.
    fn dispatch(
        &self,
        enc: &mut wgpu::CommandEncoder,
        pipeline: &wgpu::ComputePipeline,
        label: &str,
        buffers: &[&wgpu::Buffer],
        groups: (u32, u32),
    ) {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| entry(i as u32, b))
            .collect();
        let bg = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bg, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
    }

    fn read_back(&self, staging: &wgpu::Buffer, n: usize) -> Result<Vec<f32>, GpuError> {
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(Arc::new(e)))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(Arc::new(e)))?
            .map_err(|e| GpuError::Readback(Arc::new(e)))?;
        let values = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| GpuError::Readback(Arc::new(e)))?;
            bytemuck::cast_slice::<u8, f32>(&view)[..n].to_vec()
        };
        staging.unmap();
        Ok(values)
    }
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// The CPU adapter (lavapipe) if present, for tests that must run the GPU code without a GPU.
pub fn software_adapter() -> Option<wgpu::Adapter> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let mut best = None;
    for a in adapters {
        if a.get_info().device_type == wgpu::DeviceType::Cpu {
            return Some(a);
        }
        best.get_or_insert(a);
    }
    best
}

/// Each stamp's per-pixel windows of the track and the window its pixels share (none: `first > last`), in
/// parallel over the stars; a static exposure's are the one whole sample.
fn pixel_windows(
    batch: &[(&StarJob, (i64, i64, usize, usize))],
    track: &Track,
    frame: &FrameSpec<'_>,
    is_static: bool,
) -> Vec<(Vec<GpuWindow>, GpuWindow)> {
    batch
        .par_iter()
        .map(|(_, (x0, y0, nx, ny))| {
            if is_static {
                return (
                    vec![
                        GpuWindow {
                            first: 0,
                            last: 0,
                            wf: 1.0,
                            wl: 1.0
                        };
                        nx * ny
                    ],
                    GpuWindow {
                        first: 1,
                        last: 0,
                        wf: 0.0,
                        wl: 0.0,
                    },
                );
            }
            let mut w = Vec::with_capacity(nx * ny);
            let (mut a_max, mut b_min) = (f64::NEG_INFINITY, f64::INFINITY);
            for iy in 0..*ny {
                for ix in 0..*nx {
                    let (a, b) = frame
                        .timing
                        .window_s((*x0 + ix as i64) as usize, (*y0 + iy as i64) as usize);
                    a_max = a_max.max(a);
                    b_min = b_min.min(b);
                    w.push(track.window(a, b).into());
                }
            }
            let common = if b_min > a_max {
                track.window(a_max, b_min).into()
            } else {
                GpuWindow {
                    first: 1,
                    last: 0,
                    wf: 0.0,
                    wl: 0.0,
                }
            };
            (w, common)
        })
        .collect()
}

/// The dispatch passes over the range (the histogram's rows with the fast method, the track's samples with
/// the direct one): the whole range at once on a hardware GPU, chunks of [`SOFTWARE_ITERATION_BUDGET`]
/// iterations on a software adapter.
fn passes(
    fast: bool,
    (nu, nv): (usize, usize),
    track_len: usize,
    software: bool,
    fixed_scale: f32,
) -> Vec<GpuParams> {
    let budget = if software {
        SOFTWARE_ITERATION_BUDGET
    } else {
        usize::MAX / 2
    };
    let (extent, per_pass) = if fast {
        (nv, (budget / nu.max(1)).max(1))
    } else {
        (track_len, budget)
    };
    (0..extent.div_ceil(per_pass))
        .map(|k| GpuParams {
            hist_nu: nu as u32,
            hist_nv: nv as u32,
            fixed_scale,
            star_base: 0,
            lo: (k * per_pass) as u32,
            hi: ((k + 1) * per_pass - 1).min(extent - 1) as u32,
            accumulate: u32::from(k > 0),
            pad: 0,
        })
        .collect()
}

/// The stamps of a batch from the values read back, each star's at its pixel offset.
fn stamps(
    batch: &[(&StarJob, (i64, i64, usize, usize))],
    stars: &[GpuStar],
    values: &[f32],
) -> Vec<Stamp> {
    batch
        .iter()
        .zip(stars)
        .map(|((_, (x0, y0, nx, ny)), s)| {
            let a = s.pixel_offset as usize;
            Stamp {
                x0: *x0,
                y0: *y0,
                nx: *nx,
                ny: *ny,
                data: values[a..a + nx * ny].iter().map(|v| *v as f64).collect(),
            }
        })
        .collect()
}
