// Fast method, step 2: one invocation per (star, stamp pixel).
//   shared part: sum_u H(u) K(P - u) over the star's histogram nodes (P = the pixel centre, a node of K's
//                grid, so no interpolation is needed: exact);
//   own part:    this pixel's samples outside the shared window, (w_own - w_shared) K(X - x - d_j).
// Bindings (group 0): 0 params, 1 stars, 2 windows (per pixel), 3 track, 4 kernels, 5 hist (u32), 6 out.
// Each pass covers histogram rows params.lo..=hi; the first pass also adds the edge samples.
// Workgroup 64 along the stamp's pixels; dispatch (ceil(max_pixels/64), stars, 1).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> stars: array<Star>;
@group(0) @binding(2) var<storage, read> windows: array<Window>;
@group(0) @binding(3) var<storage, read> track: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> kernels: array<f32>;
@group(0) @binding(5) var<storage, read> hist: array<u32>;
@group(0) @binding(6) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(64)
fn fast(@builtin(global_invocation_id) gid: vec3<u32>) {
    let s = stars[params.star_base + gid.y];
    let p = gid.x;
    if (p >= s.nx * s.ny) {
        return;
    }
    let ix = p % s.nx;
    let iy = p / s.nx;
    let n = i32(2u * s.kernel_half + 1u);
    let half = i32(s.kernel_half);
    let g = i32(s.kernel_g);
    let nu = params.hist_nu;
    let nv = params.hist_nv;
    // shared window: histogram ⊛ kernel at the pixel centre (one Kahan step per histogram row)
    var acc = Acc(0.0, 0.0);
    for (var r = params.lo; r <= min(params.hi, nv - 1u); r++) {
        let ky = i32(iy) * g - (s.hist_v0 + i32(r)) + half;
        if (ky < 0 || ky >= n) {
            continue;
        }
        let krow = s.kernel_offset + u32(ky * n);
        let hrow = s.hist_offset + r * nu;
        // columns whose kernel index lies inside the table
        let base = i32(ix) * g - s.hist_u0 + half;
        let c_lo = max(base - (n - 1), 0);
        let c_hi = min(base, i32(nu) - 1);
        if (c_hi < c_lo) {
            continue;
        }
        var row_sum = 0.0;
        for (var c = u32(c_lo); c <= u32(c_hi); c++) {
            let h = hist[hrow + c];
            if (h != 0u) {
                row_sum += f32(h) * kernels[krow + u32(base - i32(c))];
            }
        }
        kahan(&acc, row_sum);
    }
    let idx = s.pixel_offset + p;
    var total = acc.sum / params.fixed_scale;
    if (params.accumulate != 0u) {
        out[idx] += total * s.scale;
        return;
    }
    // first pass only: this pixel's own samples outside the shared window (a few per row of the stamp: ≤ 256 per block)
    let own = windows[s.pixel_offset + p];
    let cw = Window(s.common_first, s.common_last, s.common_wf, s.common_wl);
    let bx = f32(ix) - s.x_rel;
    let by = f32(iy) - s.y_rel;
    var edge = Acc(0.0, 0.0);
    let head_end = min(cw.first, own.last);
    let tail_start = max(max(cw.last, head_end + 1u), own.first);
    // two ranges: [own.first, head_end] and [tail_start, own.last], walked in blocks of 256
    for (var part = 0u; part < 2u; part++) {
        var j = select(tail_start, own.first, part == 0u);
        let stop = select(own.last, head_end, part == 0u);
        loop {
            if (j > stop || (part == 0u && head_end < own.first)) {
                break;
            }
            let end = min(stop, j + 255u);
            var block = 0.0;
            for (var k = j; k <= end; k++) {
                let e = weight(own, k) - weight(cw, k);
                if (e != 0.0) {
                    let d = track[k];
                    block += e * kernel_eval(s.kernel_offset, s.kernel_half, s.kernel_g, bx - d.x, by - d.y);
                }
            }
            kahan(&edge, block);
            j = end + 1u;
        }
    }
    total += edge.sum;
    out[idx] = total * s.scale;
}
