//! The one way volao gets a GPU device, used by the GUI, the CLI and the tests alike.
//!
//! We ask for the adapter's own limits (wgpu's defaults cap 3-D textures at 2048) and the
//! optional features volume work needs. OpenGL adapters are refused: wgpu's GL backend
//! silently writes 3-D storage textures to slice 0 only, which would corrupt every AO
//! volume without an error.

pub mod shaders;
pub mod smoke;

use std::time::Duration;

/// What can go wrong getting or using the GPU.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no usable GPU adapter found ({tried}). On Linux without a GPU install Mesa's CPU Vulkan driver: \
         sudo apt-get install -y mesa-vulkan-drivers libvulkan1"
    )]
    NoAdapter { tried: String },
    #[error(
        "only an OpenGL adapter was found ({name}); volao needs Vulkan, Metal or DX12 because wgpu's GL backend \
         writes 3-D storage textures wrongly. On Linux: sudo apt-get install -y mesa-vulkan-drivers libvulkan1"
    )]
    OpenGlOnly { name: String },
    #[error("the GPU adapter {name} refused to create a device: {source}")]
    RequestDevice {
        name: String,
        source: wgpu::RequestDeviceError,
    },
    #[error("GPU validation error in {stage}: {message}")]
    Validation { stage: String, message: String },
    #[error("GPU did not finish {stage} within {seconds} s")]
    Timeout { stage: String, seconds: u64 },
    #[error("reading back {stage} from the GPU failed: {message}")]
    Readback { stage: String, message: String },
    #[error("shader {name}: {message}")]
    Shader { name: String, message: String },
    #[error("{what}")]
    Unsupported { what: String },
}

/// Features volao uses when the adapter offers them (lavapipe and desktop GPUs do):
/// linear filtering of f32 textures, 16-bit normalised textures for CT, R8/R16 3-D
/// storage textures, and timestamps for per-stage timings.
pub fn wanted_features() -> wgpu::Features {
    wgpu::Features::FLOAT32_FILTERABLE
        | wgpu::Features::TEXTURE_FORMAT_16BIT_NORM
        | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES
        | wgpu::Features::TIMESTAMP_QUERY
}

/// An adapter, its device and queue.
#[derive(Debug)]
pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

impl Gpu {
    /// One line naming the adapter, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) — Vulkan, Cpu`.
    pub fn describe(&self) -> String {
        describe(&self.info)
    }
}

pub fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} — {:?}, {:?}", info.name, info.backend, info.device_type)
}

/// The instance volao uses: every backend but GL unless `WGPU_BACKEND` says otherwise.
pub fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if std::env::var_os("WGPU_BACKEND").is_none() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    wgpu::Instance::new(desc)
}

/// The device descriptor for an adapter: its full limits and the wanted features it has.
/// The GUI passes the same descriptor to eframe so every path gets the same device.
pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
    wgpu::DeviceDescriptor {
        label: Some("volao::device"),
        required_features: adapter.features() & wanted_features(),
        required_limits: adapter.limits(),
        ..Default::default()
    }
}

/// Which device a computation may use: none (the CPU twins), a fresh one, or one already
/// open (the viewer's, so that each recomputation does not open another).
#[derive(Debug, Clone, Default)]
pub enum GpuUse {
    Cpu,
    #[default]
    Request,
    Shared(std::sync::Arc<Gpu>),
}

impl GpuUse {
    /// A fresh device when `use_gpu`, else the CPU.
    pub fn from_flag(use_gpu: bool) -> Self {
        if use_gpu {
            GpuUse::Request
        } else {
            GpuUse::Cpu
        }
    }

    /// The device, opened if need be; `None` for the CPU.
    pub fn device(&self) -> Option<Result<std::sync::Arc<Gpu>, GpuError>> {
        match self {
            GpuUse::Cpu => None,
            GpuUse::Request => Some(request_device().map(std::sync::Arc::new)),
            GpuUse::Shared(g) => Some(Ok(std::sync::Arc::clone(g))),
        }
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
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout,
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// An R32Float 3-D texture of `dims` that a compute pass writes (storage) and the host
/// reads back (copy source).
pub fn output_volume(device: &wgpu::Device, label: &str, dims: [u32; 3]) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: dims[2],
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: wgpu::TextureFormat::R32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
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

/// Picks an adapter (high performance first) and creates the device. Blocks.
pub fn request_device() -> Result<Gpu, GpuError> {
    pollster::block_on(request_device_async())
}

async fn request_device_async() -> Result<Gpu, GpuError> {
    let instance = instance();
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        })
        .await
        .map_err(|e| GpuError::NoAdapter {
            tried: e.to_string(),
        })?;
    let info = adapter.get_info();
    if info.backend == wgpu::Backend::Gl && std::env::var_os("VOLAO_ALLOW_GL").is_none() {
        return Err(GpuError::OpenGlOnly { name: info.name });
    }
    let (device, queue) = adapter
        .request_device(&device_descriptor(&adapter))
        .await
        .map_err(|source| GpuError::RequestDevice {
            name: info.name.clone(),
            source,
        })?;
    Ok(Gpu {
        instance,
        adapter,
        device,
        queue,
        info,
    })
}

/// Default bound on any single wait for the GPU (a hung driver fails instead of hanging).
pub const WAIT: Duration = Duration::from_secs(60);

/// Blocks until all submitted work is done, or fails after `timeout`.
pub fn wait(device: &wgpu::Device, stage: &str, timeout: Duration) -> Result<(), GpuError> {
    device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: Some(timeout),
        })
        .map(|_| ())
        .map_err(|e| match e {
            wgpu::PollError::Timeout => GpuError::Timeout {
                stage: stage.into(),
                seconds: timeout.as_secs(),
            },
            other => GpuError::Readback {
                stage: stage.into(),
                message: other.to_string(),
            },
        })
}

/// Runs `f` inside a validation error scope and turns a captured error into [`GpuError`].
pub fn validated<T>(
    device: &wgpu::Device,
    stage: &str,
    f: impl FnOnce() -> T,
) -> Result<T, GpuError> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let value = f();
    match pollster::block_on(scope.pop()) {
        None => Ok(value),
        Some(e) => Err(GpuError::Validation {
            stage: stage.into(),
            message: e.to_string(),
        }),
    }
}

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
    match rx.try_recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            return Err(GpuError::Readback {
                stage: stage.into(),
                message: e.to_string(),
            });
        }
        Err(_) => {
            return Err(GpuError::Readback {
                stage: stage.into(),
                message: "map callback never ran".into(),
            });
        }
    }
    let bytes = buffer
        .slice(..)
        .get_mapped_range()
        .map_err(|e| GpuError::Readback {
            stage: stage.into(),
            message: e.to_string(),
        })?
        .to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// `bytes_per_row` for texture↔buffer copies, padded to wgpu's 256-byte alignment.
pub fn padded_row_bytes(unpadded: u32) -> u32 {
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
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

/// A uniform buffer initialised with `bytes`.
pub fn uniform_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    bytes: &[u8],
) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.len() as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, bytes);
    buffer
}

/// A host-readable buffer to copy results into.
pub fn readback_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Encodes one compute dispatch of `groups` workgroups, then whatever `after` adds
/// (typically copies to a readback buffer), and submits it.
pub fn submit_compute(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
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
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }
    after(&mut encoder);
    queue.submit([encoder.finish()]);
}

/// Like [`submit_compute`], with bind groups 0, 1, … set from `groups_bound`.
pub fn submit_compute_with(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups_bound: &[&wgpu::BindGroup],
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
        for (i, g) in groups_bound.iter().enumerate() {
            pass.set_bind_group(i as u32, *g, &[]);
        }
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
    }
    after(&mut encoder);
    queue.submit([encoder.finish()]);
}

/// Reads an `R32Float` texture (2-D array or 3-D; `size` = width, height, layers/depth)
/// back as f32 values, x fastest, then y, then layer.
pub fn read_texture_f32(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    size: [u32; 3],
    stage: &str,
) -> Result<Vec<f32>, GpuError> {
    let device = &gpu.device;
    let row = padded_row_bytes(size[0] * 4);
    let readback = validated(device, stage, || {
        let readback = readback_buffer(device, stage, row as u64 * size[1] as u64 * size[2] as u64);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(stage) });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(size[1]),
                },
            },
            wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: size[2],
            },
        );
        gpu.queue.submit([encoder.finish()]);
        readback
    })?;
    let bytes = read_buffer(device, &readback, stage)?;
    let mut out = Vec::with_capacity((size[0] * size[1] * size[2]) as usize);
    for r in bytes.chunks_exact(row as usize) {
        out.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
            &r[..(size[0] * 4) as usize],
        ));
    }
    Ok(out)
}
