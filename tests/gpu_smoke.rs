//! The GPU path works end to end: the same device function the app uses, a compute
//! shader from shaders/, readback, and comparison with its CPU twin.
//!
//! Never skipped: without an adapter this fails and says how to install one.

use volao::gpu::{self, smoke};

fn device() -> gpu::Gpu {
    match gpu::request_device() {
        Ok(g) => g,
        Err(e) => panic!("{e}\n(GPU tests run on Mesa's lavapipe in CI; they are not skipped.)"),
    }
}

#[test]
fn adapter_is_not_the_opengl_fallback() {
    let g = device();
    eprintln!("adapter: {}", g.describe());
    assert_ne!(
        g.info.backend,
        wgpu::Backend::Gl,
        "GL writes 3-D storage textures wrongly; install mesa-vulkan-drivers"
    );
    assert!(g.device.limits().max_texture_dimension_3d >= 256);
}

#[test]
fn smoke_shader_matches_cpu_twin_on_every_slice() {
    let g = device();
    // A cube and an odd, non-multiple-of-workgroup grid.
    for dims in [[8, 8, 8], [5, 3, 7]] {
        let got = smoke::run(&g, dims).unwrap_or_else(|e| panic!("{e}"));
        let want = smoke::expected(dims);
        assert_eq!(got.linear, want.linear, "storage buffer, dims {dims:?}");
        let slice = (dims[0] * dims[1]) as usize;
        for (z, (a, b)) in got
            .volume
            .chunks(slice)
            .zip(want.volume.chunks(slice))
            .enumerate()
        {
            assert_eq!(a, b, "3-D texture slice z = {z}, dims {dims:?}");
        }
    }
}

#[test]
fn validation_errors_are_reported_not_ignored() {
    let g = device();
    let err = gpu::validated(&g.device, "Test::bad_buffer", || {
        // Mapped for reading and usable as storage at once is invalid.
        g.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Test::bad_buffer"),
            size: 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        })
    })
    .expect_err("invalid usage must be caught");
    assert!(err.to_string().contains("Test::bad_buffer"), "{err}");
}
