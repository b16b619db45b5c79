//! Every WGSL kernel parses and validates with naga (the compiler wgpu uses), so a broken kernel fails CI
//! here and not on a user's GPU; and the host-side mirrors of the WGSL structs have the WGSL sizes.

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

#[test]
fn host_mirrors_match_wgsl_layouts() {
    for (name, _, src) in engine::integrate::gpu::shader_sources() {
        let module = naga::front::wgsl::parse_str(&src).expect("parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        for (handle, ty) in module.types.iter() {
            let size = layouter[handle].size as usize;
            match ty.name.as_deref() {
                Some("Star") => assert_eq!(
                    size,
                    std::mem::size_of::<engine::integrate::gpu::GpuStar>(),
                    "{name}: Star"
                ),
                Some("Window") => assert_eq!(
                    size,
                    std::mem::size_of::<engine::integrate::gpu::GpuWindow>(),
                    "{name}: Window"
                ),
                Some("Params") => assert_eq!(
                    size,
                    std::mem::size_of::<engine::integrate::gpu::GpuParams>(),
                    "{name}: Params"
                ),
                _ => {}
            }
        }
    }
}
