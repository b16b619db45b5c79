// Shared declarations of the integration kernels (prepended to each kernel by the host; see gpu/mod.rs).
//
// Units: positions in detector pixels, times folded into per-sample weights by the host, fluxes in
// electrons. `Star` mirrors `gpu::GpuStar` (64 bytes), `Window` mirrors `gpu::GpuWindow` (16 bytes),
// `Params` mirrors `gpu::GpuParams` (32 bytes).
//
// lavapipe (llvmpipe) caps the loop iterations of one invocation at 65 535 *in total*; the host therefore
// splits long loops into passes (`lo..=hi` below) on software adapters, accumulating into `out`.

struct Star {
    x_rel: f32,          // star position relative to the stamp origin (px)
    y_rel: f32,
    nx: u32,             // stamp size (px)
    ny: u32,
    pixel_offset: u32,   // first pixel of this stamp in `windows` / `out`
    kernel_offset: u32,  // first value of this star's pixel kernel in `kernels`
    kernel_half: u32,    // kernel table has (2 half + 1)^2 nodes
    kernel_g: u32,       // kernel nodes per pixel
    scale: f32,          // rate * dt (electrons per unit weight)
    hist_offset: u32,    // fast method: first node of this star's histogram
    hist_u0: i32,        // node coordinates of hist[0] relative to the stamp origin
    hist_v0: i32,
    common_first: u32,   // fast method: the window shared by all pixels of the stamp
    common_last: u32,
    common_wf: f32,
    common_wl: f32,
}

struct Window {
    first: u32,          // samples first..=last, weight wf at first, wl at last, 1 between
    last: u32,
    wf: f32,
    wl: f32,
}

struct Params {
    hist_nu: u32,        // histogram size (nodes) per star
    hist_nv: u32,
    fixed_scale: f32,    // histogram fixed-point scale (counts per unit weight)
    star_base: u32,      // index of the first star of this dispatch
    lo: u32,             // this pass covers samples (direct) or histogram rows (fast) lo..=hi
    hi: u32,
    accumulate: u32,     // 0: first pass (write, and the fast method's edge samples); 1: add to `out`
    pad: u32,
}

fn weight(w: Window, j: u32) -> f32 {
    if (j < w.first || j > w.last) {
        return 0.0;
    }
    if (j == w.first) {
        return w.wf;
    }
    if (j == w.last) {
        return w.wl;
    }
    return 1.0;
}

// Compensated f32 accumulation: callers sum samples in blocks of at most 256 in plain f32 and add each
// block sum here with Kahan's correction, keeping an 83 000-sample exposure at ~1e-7 relative.
struct Acc {
    sum: f32,
    c: f32,
}

fn kahan(a: ptr<function, Acc>, x: f32) {
    let y = x - (*a).c;
    let t = (*a).sum + y;
    (*a).c = (t - (*a).sum) - y;
    (*a).sum = t;
}
