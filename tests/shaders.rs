//! Every WGSL kernel parses and validates with naga (the compiler wgpu uses), so a broken kernel fails CI
//! here and not on a user's GPU; and the host-side mirrors of the WGSL structs have the WGSL members, offsets and sizes.

#[test]
fn every_kernel_parses_and_validates() {
    let sources = engine::integrate::gpu::shader_sources();
    assert_eq!(sources.len(), 3);
    for (name, entry, src) in sources {
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&src)));
        assert!(
            module.entry_points.iter().any(|e| e.name == entry),
            "{name}: entry point {entry} missing"
        );
        let mut v = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        );
        v.validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&src)));
    }
}

/// A host struct's layout: (field name, byte offset) in declaration order, and its size.
type Layout = (&'static str, Vec<(&'static str, usize)>, usize);

fn host_layouts() -> Vec<Layout> {
    use engine::integrate::gpu::{GpuParams, GpuStar, GpuWindow};
    use std::mem::{offset_of, size_of};
    macro_rules! fields {
        ($t:ty; $($f:ident),*) => { vec![$((stringify!($f), offset_of!($t, $f))),*] };
    }
    vec![
        (
            "Star",
            fields!(GpuStar; x_rel, y_rel, nx, ny, pixel_offset, kernel_offset, kernel_half, kernel_g,
                    scale, hist_offset, hist_u0, hist_v0, common_first, common_last, common_wf, common_wl),
            size_of::<GpuStar>(),
        ),
        (
            "Window",
            fields!(GpuWindow; first, last, wf, wl),
            size_of::<GpuWindow>(),
        ),
        (
            "Params",
            fields!(GpuParams; hist_nu, hist_nv, fixed_scale, star_base, lo, hi, accumulate, pad),
            size_of::<GpuParams>(),
        ),
    ]
}

/// Every host mirror matches its WGSL struct member by member — names, order, byte offsets — and in size,
/// in every kernel; a kernel that lacks one of the structs fails the test.
#[test]
fn host_mirrors_match_wgsl_layouts() {
    for (name, _, src) in engine::integrate::gpu::shader_sources() {
        let module = naga::front::wgsl::parse_str(&src).expect("parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        for (st, fields, size) in host_layouts() {
            let Some((handle, ty)) = module
                .types
                .iter()
                .find(|(_, ty)| ty.name.as_deref() == Some(st))
            else {
                panic!("{name}: struct {st} not found in the WGSL");
            };
            let naga::TypeInner::Struct { members, .. } = &ty.inner else {
                panic!("{name}: {st} is not a struct");
            };
            let wgsl: Vec<(String, usize)> = members
                .iter()
                .map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize))
                .collect();
            let host: Vec<(String, usize)> =
                fields.iter().map(|(f, o)| (f.to_string(), *o)).collect();
            assert_eq!(wgsl, host, "{name}: members of {st} (name, offset)");
            assert_eq!(layouter[handle].size as usize, size, "{name}: size of {st}");
        }
    }
}
