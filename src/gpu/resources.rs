//! Buffers, textures, bind groups and readbacks: the few shapes every stage creates,
//! each spelled out once. Labels follow `"Stage::what"` so validation errors say where.

use super::{Gpu, GpuError, WAIT, validated, wait};

/// `bytes_per_row` for texture↔buffer copies, padded to wgpu's 256-byte alignment.
pub fn padded_row_bytes(unpadded: u32) -> u32 {
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
}

/// The extent of a 3-D texture (or a 2-D array: `dims[2]` layers).
pub fn extent(dims: [u32; 3]) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    }
}

/// The compute pipeline of entry point `entry` in `module`; without `layout`, the layout
/// is derived from the shader.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    entry: &str,
    layout: Option<&wgpu::PipelineLayout>,
) -> wgpu::ComputePipeline {
    specialised_pipeline(device, label, module, layout, &[], entry)
}

/// The compute pipeline of entry point `entry` in `module` with its `override`
/// constants set to `constants` (a variant, see [`super::shaders::Constants`]).
pub fn specialised_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: Option<&wgpu::PipelineLayout>,
    constants: &[(&str, f64)],
    entry: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout,
        module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

/// Trilinear filtering within a mip level, the nearest level, clamped at the edges (the
/// sampler every volume pass uses).
pub fn linear_sampler(device: &wgpu::Device, label: &str) -> wgpu::Sampler {
    device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        mipmap_filter: wgpu::MipmapFilterMode::Nearest,
        ..Default::default()
    })
}

/// Bind group layout entries by kind (visible to `visibility`).
pub mod entry {
    use wgpu::{
        BindGroupLayoutEntry, BindingType, ShaderStages, TextureSampleType, TextureViewDimension,
    };

    fn entry(binding: u32, visibility: ShaderStages, ty: BindingType) -> BindGroupLayoutEntry {
        BindGroupLayoutEntry {
            binding,
            visibility,
            ty,
            count: None,
        }
    }

    pub fn uniform(binding: u32, visibility: ShaderStages) -> BindGroupLayoutEntry {
        let ty = wgpu::BufferBindingType::Uniform;
        entry(binding, visibility, buffer(ty))
    }

    pub fn storage(
        binding: u32,
        visibility: ShaderStages,
        read_only: bool,
    ) -> BindGroupLayoutEntry {
        let ty = wgpu::BufferBindingType::Storage { read_only };
        entry(binding, visibility, buffer(ty))
    }

    fn buffer(ty: wgpu::BufferBindingType) -> BindingType {
        BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        }
    }

    /// A sampled texture; `filterable` float, or unsigned integers for `None`.
    pub fn texture(
        binding: u32,
        visibility: ShaderStages,
        view_dimension: TextureViewDimension,
        filterable: Option<bool>,
    ) -> BindGroupLayoutEntry {
        let sample_type = match filterable {
            Some(filterable) => TextureSampleType::Float { filterable },
            None => TextureSampleType::Uint,
        };
        let ty = BindingType::Texture {
            sample_type,
            view_dimension,
            multisampled: false,
        };
        entry(binding, visibility, ty)
    }

    pub fn sampler(binding: u32, visibility: ShaderStages) -> BindGroupLayoutEntry {
        let ty = BindingType::Sampler(wgpu::SamplerBindingType::Filtering);
        entry(binding, visibility, ty)
    }

    pub fn storage_texture(
        binding: u32,
        visibility: ShaderStages,
        format: wgpu::TextureFormat,
        view_dimension: TextureViewDimension,
    ) -> BindGroupLayoutEntry {
        let ty = BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension,
        };
        entry(binding, visibility, ty)
    }
}

/// A compute pipeline of one shader's `main` with the linear sampler its volumes are
/// read with: the long-lived state of most stages.
#[derive(Debug)]
pub struct ComputeStage {
    pub pipeline: wgpu::ComputePipeline,
    pub sampler: wgpu::Sampler,
}

impl ComputeStage {
    /// Builds `shader`'s pipeline, labelled `"{name}::pipeline"`.
    pub fn new(device: &wgpu::Device, name: &str, shader: &str) -> Result<Self, GpuError> {
        Self::specialised(device, name, shader, &[])
    }

    /// The same with `shader`'s `override` constants set to `constants` (a variant).
    pub fn specialised(
        device: &wgpu::Device,
        name: &str,
        shader: &str,
        constants: &[(&str, f64)],
    ) -> Result<Self, GpuError> {
        let module = super::shaders::module(device, shader)?;
        let label = format!("{name}::pipeline");
        validated(device, &format!("{name}::new"), || ComputeStage {
            pipeline: specialised_pipeline(device, &label, &module, None, constants, "main"),
            sampler: linear_sampler(device, &format!("{name}::linear_clamp")),
        })
    }

    /// The uniform buffer holding `params` and the bind group of a shader whose
    /// bindings are `params`, the sampled `volume`, this stage's sampler, then `rest`.
    pub fn sampling_group<P: bytemuck::Pod>(
        &self,
        gpu: &Gpu,
        name: &str,
        params: &P,
        volume: &wgpu::TextureView,
        rest: &[wgpu::BindingResource<'_>],
    ) -> (wgpu::Buffer, wgpu::BindGroup) {
        let mut resources = vec![
            wgpu::BindingResource::TextureView(volume),
            wgpu::BindingResource::Sampler(&self.sampler),
        ];
        resources.extend(rest.iter().cloned());
        uniform_group(gpu, name, &self.pipeline, params, &resources)
    }
}

/// Declares a stage that is one [`ComputeStage`] (a shader's pipeline and sampler),
/// built once per device by [`crate::gpu::Gpu::stage`].
macro_rules! compute_stage {
    ($(#[$doc:meta])* $name:ident, $label:literal, $shader:literal) => {
        $(#[$doc])*
        #[derive(Debug)]
        pub struct $name($crate::gpu::ComputeStage);

        impl $crate::gpu::Stage for $name {
            fn create(device: &wgpu::Device) -> Result<Self, $crate::gpu::GpuError> {
                $crate::gpu::ComputeStage::new(device, $label, $shader).map($name)
            }
        }
    };
}
pub(crate) use compute_stage;

/// A 3-D texture of `dims` with one mip level.
pub fn texture_3d(
    device: &wgpu::Device,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    mip_texture_3d(device, label, dims, 1, format, usage)
}

/// A 3-D texture of `dims` with `levels` mip levels.
pub fn mip_texture_3d(
    device: &wgpu::Device,
    label: &str,
    dims: [u32; 3],
    levels: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: extent(dims),
        mip_level_count: levels,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format,
        usage,
        view_formats: &[],
    })
}

/// Writes `data` (tightly packed, x fastest) into mip level `level` of `texture`, whose
/// size at that level is `dims`.
pub fn write_texture_3d(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    level: u32,
    dims: [u32; 3],
    bytes_per_texel: u32,
    data: &[u8],
) {
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: level,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(dims[0] * bytes_per_texel),
            rows_per_image: Some(dims[1]),
        },
        extent(dims),
    );
}

/// How the volume's textures are used: sampled by the shaders, written by the upload.
const SAMPLED: wgpu::TextureUsages =
    wgpu::TextureUsages::TEXTURE_BINDING.union(wgpu::TextureUsages::COPY_DST);

/// A volume texture of `dims` holding `bytes` (tightly packed texels of `format`).
pub fn filled_texture_3d(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    bytes: &[u8],
) -> wgpu::Texture {
    let texture = texture_3d(device, label, dims, format, SAMPLED);
    let texel = format.block_copy_size(None).unwrap_or(1);
    write_texture_3d(queue, &texture, 0, dims, texel, bytes);
    texture
}

/// A 2-D texture of `size` (an image, a tile, a render target).
pub fn image_texture(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: extent([width, height, 1]),
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// An R32Float 3-D texture of `dims` that a compute pass writes (storage) and the host
/// reads back (copy source).
pub fn output_volume(device: &wgpu::Device, label: &str, dims: [u32; 3]) -> wgpu::Texture {
    texture_3d(
        device,
        label,
        dims,
        wgpu::TextureFormat::R32Float,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
    )
}

/// An R16Float 3-D texture holding `chain` as its mip levels (level 0 first, each with
/// its dims; see [`crate::sample::mip_chain`]).
pub fn f16_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    chain: &[(Vec<u16>, [usize; 3])],
) -> wgpu::Texture {
    let first = chain[0].1.map(|d| d as u32);
    let texture = mip_texture_3d(
        device,
        label,
        first,
        chain.len() as u32,
        wgpu::TextureFormat::R16Float,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    for (l, (values, dims)) in chain.iter().enumerate() {
        let dims = dims.map(|d| d as u32);
        write_texture_3d(
            queue,
            &texture,
            l as u32,
            dims,
            2,
            bytemuck::cast_slice(values),
        );
    }
    texture
}

/// A buffer of `usage | COPY_DST` initialised with `bytes` (`min_size` bytes at least).
fn filled_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    bytes: &[u8],
    min_size: usize,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.len().max(min_size) as u64,
        usage: usage | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, bytes);
    buffer
}

/// A storage buffer initialised with `bytes` (at least 16 bytes, so an empty table
/// still binds), with `extra` usages besides `STORAGE | COPY_DST`.
pub fn storage_buffer(
    gpu: &Gpu,
    label: &str,
    bytes: &[u8],
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::STORAGE | extra;
    filled_buffer(&gpu.device, &gpu.queue, label, bytes, 16, usage)
}

/// An uninitialised buffer of `size` bytes.
fn buffer(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}

/// A storage buffer of `size` bytes a compute pass writes and the host copies out.
pub fn output_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    buffer(device, label, size, usage)
}

/// A uniform buffer initialised with `bytes`.
pub fn uniform_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    bytes: &[u8],
) -> wgpu::Buffer {
    filled_buffer(device, queue, label, bytes, 0, wgpu::BufferUsages::UNIFORM)
}

/// A host-readable buffer to copy results into.
pub fn readback_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
    buffer(device, label, size, usage)
}

/// A bind group whose entries are `resources` at bindings 0, 1, 2, … in order.
pub fn bind_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource<'_>],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
        .iter()
        .enumerate()
        .map(|(i, r)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: r.clone(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// A uniform buffer holding `params` and bind group 0 of `pipeline` with it at binding
/// 0 and `resources` at 1, 2, …, labelled `"{name}::params"` and `"{name}::bind_group"`.
pub fn uniform_group<P: bytemuck::Pod>(
    gpu: &Gpu,
    name: &str,
    pipeline: &wgpu::ComputePipeline,
    params: &P,
    resources: &[wgpu::BindingResource<'_>],
) -> (wgpu::Buffer, wgpu::BindGroup) {
    let device = &gpu.device;
    let bytes = bytemuck::bytes_of(params);
    let uniforms = uniform_buffer(device, &gpu.queue, &format!("{name}::params"), bytes);
    let mut all = vec![uniforms.as_entire_binding()];
    all.extend(resources.iter().cloned());
    let layout = pipeline.get_bind_group_layout(0);
    let group = bind_group(device, &format!("{name}::bind_group"), &layout, &all);
    (uniforms, group)
}

/// Encodes one compute dispatch of `groups` workgroups with the bind groups `bound`
/// (index, group), then whatever `after` adds (typically copies to a readback buffer), and
/// submits it.
pub fn submit_compute_with(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bound: &[(u32, &wgpu::BindGroup)],
    groups: [u32; 3],
    after: impl FnOnce(&mut wgpu::CommandEncoder),
) {
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        for &(i, g) in bound {
            pass.set_bind_group(i, g, &[]);
        }
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }
    after(&mut encoder);
    queue.submit([encoder.finish()]);
}

/// [`submit_compute_with`] with one bind group.
pub fn submit_compute(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: [u32; 3],
    after: impl FnOnce(&mut wgpu::CommandEncoder),
) {
    submit_compute_with(
        device,
        queue,
        label,
        pipeline,
        &[(0, bind_group)],
        groups,
        after,
    );
}

/// How long a map callback may lag behind the wait that completed its map.
const CALLBACK_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// Maps a `MAP_READ` buffer, copies its bytes out and unmaps it.
pub fn read_buffer(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    stage: &str,
) -> Result<Vec<u8>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    wait(device, stage, WAIT)?;
    let failed = |message: String| GpuError::Readback {
        stage: stage.into(),
        message,
    };
    // The map is done once the wait returns, but another thread polling the same device
    // (the viewer's pacer) may have taken its callback and not yet run it: give it a
    // moment rather than a spurious failure.
    match rx.recv_timeout(CALLBACK_GRACE) {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(failed(e.to_string())),
        Err(_) => return Err(failed("map callback never ran".into())),
    }
    let bytes = buffer
        .slice(..)
        .get_mapped_range()
        .map_err(|e| failed(e.to_string()))?
        .to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// Encodes a copy of `texture` (mip 0; `size` = width, height, layers/depth) into
/// `buffer` with rows padded to `row` bytes.
pub fn copy_texture_out(
    encoder: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    buffer: &wgpu::Buffer,
    row: u32,
    size: [u32; 3],
) {
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(size[1]),
            },
        },
        extent(size),
    );
}

/// Rows of `bytes` padded to `row` bytes, cut to `width` texels of `T` each.
pub fn unpad<T: bytemuck::Pod>(bytes: &[u8], row: u32, width: u32) -> Vec<T> {
    let texel = std::mem::size_of::<T>() as u32;
    let mut out = Vec::with_capacity(bytes.len() / texel.max(1) as usize);
    for r in bytes.chunks_exact(row as usize) {
        out.extend(bytemuck::pod_collect_to_vec::<u8, T>(
            &r[..(width * texel) as usize],
        ));
    }
    out
}

/// A buffer to copy a texture of `size` texels of `texel_bytes` into, and its padded row.
pub fn texture_readback(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 3],
    texel_bytes: u32,
) -> (wgpu::Buffer, u32) {
    let row = padded_row_bytes(size[0] * texel_bytes);
    let buffer = readback_buffer(device, label, row as u64 * size[1] as u64 * size[2] as u64);
    (buffer, row)
}

/// Reads an `R32Float`, `R16Float`, `Rgba32Float` or `Rgba16Float` texture (2-D array or
/// 3-D; `size` = width, height, layers/depth) back as f32 values, channels fastest (RGBA),
/// then x, then y, then layer.
pub fn read_texture_f32(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    size: [u32; 3],
    stage: &str,
) -> Result<Vec<f32>, GpuError> {
    use wgpu::TextureFormat::{R16Float, Rgba16Float, Rgba32Float};
    let device = &gpu.device;
    let half = matches!(texture.format(), R16Float | Rgba16Float);
    let channels = match texture.format() {
        Rgba32Float | Rgba16Float => 4,
        _ => 1,
    };
    let texel = if half { 2 * channels } else { 4 * channels };
    let (readback, row) = validated(device, stage, || {
        let (readback, row) = texture_readback(device, stage, size, texel);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(stage) });
        copy_texture_out(&mut encoder, texture, &readback, row, size);
        gpu.queue.submit([encoder.finish()]);
        (readback, row)
    })?;
    let bytes = read_buffer(device, &readback, stage)?;
    Ok(if half {
        unpad::<u16>(&bytes, row, size[0] * channels)
            .into_iter()
            .map(|h| half::f16::from_bits(h).to_f32())
            .collect()
    } else {
        unpad::<f32>(&bytes, row, size[0] * channels)
    })
}

/// A render pipeline that draws triangles from one vertex buffer with `module`'s `vs`
/// and `fs` entry points, keeping the nearest fragment in a `Depth32Float` buffer.
pub fn depth_tested_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    vertices: wgpu::VertexBufferLayout,
    primitive: wgpu::PrimitiveState,
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: None,
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(vertices)],
        },
        primitive,
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A stage's pipeline of one variant and, built the first time a volume with a
/// segmentation needs it, the same variant reading the segmentation (`SEGMENTS` in
/// `volume.wgsl`): volumes without one run the pipeline they always ran.
#[derive(Debug)]
pub struct Segmentable {
    plain: ComputeStage,
    segments: std::sync::OnceLock<ComputeStage>,
    name: String,
    shader: &'static str,
    constants: super::shaders::Constants,
}

impl Segmentable {
    /// `shader`'s pipeline with `constants` (see [`ComputeStage::specialised`]).
    pub fn new(
        device: &wgpu::Device,
        name: &str,
        shader: &'static str,
        constants: super::shaders::Constants,
    ) -> Result<Self, GpuError> {
        Ok(Segmentable {
            plain: ComputeStage::specialised(device, name, shader, constants)?,
            segments: std::sync::OnceLock::new(),
            name: name.to_owned(),
            shader,
            constants,
        })
    }

    /// The pipeline for a volume with a segmentation (`segments`) or without.
    pub fn get(&self, device: &wgpu::Device, segments: bool) -> Result<&ComputeStage, GpuError> {
        if !segments {
            return Ok(&self.plain);
        }
        if let Some(stage) = self.segments.get() {
            return Ok(stage);
        }
        let mut constants = self.constants.to_vec();
        constants.push(("SEGMENTS", 1.0));
        let name = format!("{}::segments", self.name);
        let stage = ComputeStage::specialised(device, &name, self.shader, &constants)?;
        Ok(self.segments.get_or_init(|| stage))
    }
}
