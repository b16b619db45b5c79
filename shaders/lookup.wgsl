// Pixel-kernel look-up, shared by the direct and fast kernels (prepended after common.wgsl; it reads the
// `kernels` storage buffer that each of them declares).

// Bilinear look-up of a pixel kernel at (dx, dy) px; zero beyond the table (its outer ring is zero).
fn kernel_eval(off: u32, half: u32, g: u32, dx: f32, dy: f32) -> f32 {
    let n = 2u * half + 1u;
    let u = dx * f32(g) + f32(half);
    let v = dy * f32(g) + f32(half);
    let fu = floor(u);
    let fv = floor(v);
    if (fu < 0.0 || fv < 0.0 || fu >= f32(n - 1u) || fv >= f32(n - 1u)) {
        return 0.0;
    }
    let tu = u - fu;
    let tv = v - fv;
    let i = off + u32(fv) * n + u32(fu);
    let a = (1.0 - tu) * kernels[i] + tu * kernels[i + 1u];
    let b = (1.0 - tu) * kernels[i + n] + tu * kernels[i + n + 1u];
    return (1.0 - tv) * a + tv * b;
}
