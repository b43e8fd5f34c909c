//! The GPU smoke test (`shaders/smoke.wgsl`) and its CPU twin: proves a device runs
//! compute work, writes every slice of a 3-D storage texture and reads back correctly.

use super::{
    Gpu, GpuError, bind_group, padded_row_bytes, read_buffer, shaders, submit_compute, validated,
};

/// What the smoke shader wrote, read back from the GPU.
#[derive(Debug, Clone, PartialEq)]
pub struct SmokeOutput {
    /// The 3-D texture, x fastest.
    pub volume: Vec<f32>,
    /// The storage buffer.
    pub linear: Vec<u32>,
}

/// CPU twin of `smoke.wgsl`.
pub fn expected(dims: [u32; 3]) -> SmokeOutput {
    let n = (dims[0] * dims[1] * dims[2]) as usize;
    let volume = (0..n)
        .map(|i| {
            let i = i as u32;
            let (x, y, z) = (
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            );
            x as f32 + 100.0 * y as f32 + 10000.0 * z as f32
        })
        .collect();
    let linear = (0..n as u32).map(|i| i * 3 + 1).collect();
    SmokeOutput { volume, linear }
}

/// Runs the smoke shader on a `dims` grid and reads both outputs back.
pub fn run(gpu: &Gpu, dims: [u32; 3]) -> Result<SmokeOutput, GpuError> {
    let device = &gpu.device;
    let module = shaders::module(device, "smoke.wgsl")?;
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let size = wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    };
    let row = padded_row_bytes(dims[0] * 4);

    let (pipeline, texture, linear, tex_readback, lin_readback) =
        validated(device, "Smoke::setup", || {
            let pipeline =
                super::compute_pipeline(device, "Smoke::pipeline", &module, "main", None);
            let texture = super::output_volume(device, "Smoke::volume", dims);
            let linear = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Smoke::linear"),
                size: n * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let tex_readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Smoke::volume_readback"),
                size: row as u64 * dims[1] as u64 * dims[2] as u64,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let lin_readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Smoke::linear_readback"),
                size: n * 4,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            (pipeline, texture, linear, tex_readback, lin_readback)
        })?;

    validated(device, "Smoke::dispatch", || {
        let view = texture.create_view(&Default::default());
        let group = bind_group(
            device,
            "Smoke::bind_group",
            &pipeline.get_bind_group_layout(0),
            &[
                wgpu::BindingResource::TextureView(&view),
                linear.as_entire_binding(),
            ],
        );
        let groups = [
            dims[0].div_ceil(4),
            dims[1].div_ceil(4),
            dims[2].div_ceil(4),
        ];
        submit_compute(
            device,
            &gpu.queue,
            "Smoke::dispatch",
            &pipeline,
            &group,
            groups,
            |encoder| {
                encoder.copy_texture_to_buffer(
                    texture.as_image_copy(),
                    wgpu::TexelCopyBufferInfo {
                        buffer: &tex_readback,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(dims[1]),
                        },
                    },
                    size,
                );
                encoder.copy_buffer_to_buffer(&linear, 0, &lin_readback, 0, n * 4);
            },
        );
    })?;

    let padded = read_buffer(device, &tex_readback, "Smoke::volume")?;
    let mut volume = Vec::with_capacity(n as usize);
    for r in padded.chunks_exact(row as usize) {
        // Copy through pod_collect: the mapped bytes need not be 4-byte aligned.
        volume.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
            &r[..dims[0] as usize * 4],
        ));
    }
    let linear =
        bytemuck::pod_collect_to_vec(&read_buffer(device, &lin_readback, "Smoke::linear")?);
    Ok(SmokeOutput { volume, linear })
}
