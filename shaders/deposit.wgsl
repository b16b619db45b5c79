// Fast method, step 1: deposit each star's jitter track over its shared window onto the pixel kernel's
// node grid (cloud-in-cell), as fixed-point counts (params.fixed_scale per unit weight) with integer
// atomics: integer addition is associative, so the histogram is bit-identical whatever the thread order.
// The four corner shares are split so they sum exactly to the sample's count (no rounding drift).
// Bindings (group 0): 0 params, 1 stars, 2 track, 3 hist (atomic u32). One workgroup of 256 per star;
// dispatch (stars, 1, 1).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> stars: array<Star>;
@group(0) @binding(2) var<storage, read> track: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> hist: array<atomic<u32>>;

@compute @workgroup_size(256)
fn deposit(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let s = stars[params.star_base + wid.x];
    let g = f32(s.kernel_g);
    let nu = params.hist_nu;
    let nv = params.hist_nv;
    let cw = Window(s.common_first, s.common_last, s.common_wf, s.common_wl);
    for (var j = s.common_first + lid.x; j <= s.common_last; j += 256u) {
        let d = track[j];
        let u = (s.x_rel + d.x) * g - f32(s.hist_u0);
        let v = (s.y_rel + d.y) * g - f32(s.hist_v0);
        let fu = floor(u);
        let fv = floor(v);
        if (fu < 0.0 || fv < 0.0 || fu >= f32(nu - 1u) || fv >= f32(nv - 1u)) {
            continue;
        }
        let tu = u - fu;
        let tv = v - fv;
        let q = u32(round(weight(cw, j) * params.fixed_scale));
        let qx0 = min(q, u32(round(f32(q) * (1.0 - tu))));
        let qx1 = q - qx0;
        let q00 = min(qx0, u32(round(f32(qx0) * (1.0 - tv))));
        let q01 = qx0 - q00;
        let q10 = min(qx1, u32(round(f32(qx1) * (1.0 - tv))));
        let q11 = qx1 - q10;
        let base = s.hist_offset + u32(fv) * nu + u32(fu);
        atomicAdd(&hist[base], q00);
        atomicAdd(&hist[base + 1u], q10);
        atomicAdd(&hist[base + nu], q01);
        atomicAdd(&hist[base + nu + 1u], q11);
    }
}
