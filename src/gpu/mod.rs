//! The one way volao gets a GPU device, used by the GUI, the CLI and the tests alike.
//!
//! We ask for the adapter's own limits (wgpu's defaults cap 3-D textures at 2048) and the
//! optional features volume work needs. OpenGL adapters are refused: wgpu's GL backend
//! silently writes 3-D storage textures to slice 0 only, which would corrupt every AO
//! volume without an error.

pub mod dispatch;
pub mod pacer;
pub mod resources;
pub mod shaders;
pub mod slicing;
pub mod smoke;

pub use resources::*;

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
    /// Each stage's long-lived state (pipelines, layouts, samplers), built on first use.
    stages: StageCache,
    /// How long one submission of a long stage may take (the viewer's slices).
    pub slicing: slicing::Slicing,
}

/// Long-lived GPU state of one pipeline stage, built once per device (rerun's
/// `ctx.renderer::<T>()` pattern): [`Gpu::stage`] creates it on first use and keeps it.
pub trait Stage: std::fmt::Debug + Send + Sync + 'static {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError>
    where
        Self: Sized;
}

type StageMap =
    std::collections::HashMap<std::any::TypeId, std::sync::Arc<dyn std::any::Any + Send + Sync>>;

#[derive(Debug, Default)]
struct StageCache(std::sync::Mutex<StageMap>);

impl Gpu {
    /// Wraps a device opened elsewhere (the viewer's, from eframe).
    pub fn new(
        instance: wgpu::Instance,
        adapter: wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Self {
        let info = adapter.get_info();
        Gpu {
            instance,
            adapter,
            device,
            queue,
            info,
            stages: StageCache::default(),
            slicing: slicing::Slicing::default(),
        }
    }

    /// The device's one instance of stage `T`, created on first use.
    pub fn stage<T: Stage>(&self) -> Result<std::sync::Arc<T>, GpuError> {
        let key = std::any::TypeId::of::<T>();
        let existing = self
            .stages
            .0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
            .cloned();
        if let Some(any) = existing
            && let Ok(stage) = any.downcast::<T>()
        {
            return Ok(stage);
        }
        // Built outside the lock: creating a pipeline compiles shaders (tens of ms).
        let stage = std::sync::Arc::new(T::create(&self.device)?);
        self.stages
            .0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, stage.clone());
        Ok(stage)
    }

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
    Ok(Gpu::new(instance, adapter, device, queue))
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
