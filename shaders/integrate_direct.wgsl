// Direct integration: one invocation per (star, stamp pixel); each sums its own window of jitter samples,
// one bilinear pixel-kernel look-up per sample:  out = scale * sum_j w_j K(X - x - d_j).
// Bindings (group 0): 0 params (uniform), 1 stars, 2 windows (one per pixel), 3 track (vec2 px per sample),
// 4 kernels, 5 out. Each pass sums samples params.lo..=hi. Workgroup: 64 invocations along the stamp's pixels; dispatch (ceil(max_pixels/64),
// stars, 1). The static case (Gaussian ACE) is a one-sample track with weight 1 and scale = rate * T.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> stars: array<Star>;
@group(0) @binding(2) var<storage, read> windows: array<Window>;
@group(0) @binding(3) var<storage, read> track: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> kernels: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(64)
fn direct(@builtin(global_invocation_id) gid: vec3<u32>) {
    let s = stars[params.star_base + gid.y];
    let p = gid.x;
    if (p >= s.nx * s.ny) {
        return;
    }
    let bx = f32(p % s.nx) - s.x_rel;
    let by = f32(p / s.nx) - s.y_rel;
    let w = windows[s.pixel_offset + p];
    var acc = Acc(0.0, 0.0);
    var j = max(w.first, params.lo);
    let last = min(w.last, params.hi);
    loop {
        if (j > last) {
            break;
        }
        let end = min(last, j + 255u);
        var block = 0.0;
        for (var k = j; k <= end; k++) {
            let d = track[k];
            block += weight(w, k) * kernel_eval(s.kernel_offset, s.kernel_half, s.kernel_g, bx - d.x, by - d.y);
        }
        kahan(&acc, block);
        j = end + 1u;
    }
    let idx = s.pixel_offset + p;
    var prev = 0.0;
    if (params.accumulate != 0u) {
        prev = out[idx];
    }
    out[idx] = prev + acc.sum * s.scale;
}
