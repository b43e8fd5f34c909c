//! Volumetric shadows from a directional light: the light volume `T(x)` (transmittance
//! from each voxel centre towards the light) on the GPU (`shaders/light.wgsl`) and on the
//! CPU (twin: [`light_cpu`]), and the anti-aliased shadow factor the ray caster reads.
//!
//! Anti-aliasing follows Imagire et al. (2007, §3.3): the shadow at a view-ray sample
//! `s_i` is `¼ T(s_i − Δs/2) + ½ T(s_i) + ¼ T(s_i + Δs/2)` (their Eq. 3–4, the half-step
//! positions between neighbouring samples), and the light rays start at a per-voxel
//! jittered offset, so no stair-steps appear at shadow boundaries.

use crate::gpu::{
    Gpu, GpuError, bind_group, read_buffer, readback_buffer, shaders, uniform_buffer, validated,
};
use crate::render::cpu::trilinear;
use crate::render::gpu::bake_lut;
use crate::render::jitter;
use crate::render::texels::VolumeTexels;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;
use rayon::prelude::*;

/// Distance between samples along a light ray, in voxels of the smallest spacing.
pub const LIGHT_STEP_VOXELS: f32 = 1.0;

/// A light ray stops once its transmittance falls below this.
pub const T_STOP: f32 = 1e-4;

/// The default direction towards the light (volume RAS space): from the patient's left,
/// front and above, so shadows fall visibly in an anterior view.
pub const DEFAULT_LIGHT: [f32; 3] = [-0.5, 0.6, 0.62];

/// The opacity table for light rays: alpha corrected for a step of [`LIGHT_STEP_VOXELS`].
pub fn light_lut(tf: &TransferFunction, texels: &VolumeTexels) -> Lut {
    bake_lut(tf, texels, LIGHT_STEP_VOXELS)
}

/// Unit direction towards the light, or an error for a zero or non-finite vector.
pub fn light_direction(d: [f32; 3]) -> Result<Vec3, String> {
    let v = Vec3::from(d);
    if !v.is_finite() || v.length() < 1e-6 {
        return Err(format!(
            "light direction {d:?}: need a non-zero vector of finite numbers"
        ));
    }
    Ok(v.normalize())
}

/// Uniforms of `light.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightParams {
    pub dims: [u32; 4],
    pub work: [u32; 4],
    pub step_uvw: [f32; 4],
    pub lut_map: [f32; 4],
    /// Half the volume's extent (mm), for the clip test.
    pub half: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<LightParams>() == 80);

fn params(texels: &VolumeTexels, lut: &Lut, direction: Vec3) -> LightParams {
    let extent = texels.extent();
    let h = LIGHT_STEP_VOXELS * texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    let diag = Vec3::from(extent).length();
    let (a, b) = crate::ao::vao::f16_lut_map(texels, lut);
    let step = direction * h / Vec3::from(extent);
    LightParams {
        dims: [
            texels.dims[0] as u32,
            texels.dims[1] as u32,
            texels.dims[2] as u32,
            0,
        ],
        work: [0, 0, (diag / h).ceil() as u32 + 2, 0],
        step_uvw: [step.x, step.y, step.z, h],
        lut_map: [a, b, (lut.rgba.len().max(2) - 1) as f32, 0.0],
        half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5, 0.0],
    }
}

/// CPU twin of one invocation of `light.wgsl`: T at the centre of `voxel`.
fn light_voxel(
    p: &LightParams,
    alpha: &[f32],
    norm: &[f32],
    dims: [usize; 3],
    voxel: [usize; 3],
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
) -> f32 {
    let centre = (Vec3::new(voxel[0] as f32, voxel[1] as f32, voxel[2] as f32) + 0.5)
        / Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32);
    let j = jitter((voxel[0] + dims[0] * voxel[2]) as u32, voxel[1] as u32);
    let step = Vec3::new(p.step_uvw[0], p.step_uvw[1], p.step_uvw[2]);
    let mut t = 1.0f32;
    for i in 0..p.work[2] {
        let uvw = centre + step * (i as f32 + j);
        if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() || t < T_STOP {
            break;
        }
        if let Some(c) = clip
            && c.uniforms.counts[0] > 0
            && !c
                .classify(
                    (uvw - Vec3::splat(0.5)) * 2.0 * Vec3::new(p.half[0], p.half[1], p.half[2]),
                )
                .0
        {
            continue;
        }
        let n = trilinear(norm, dims, uvw);
        let x = (n * p.lut_map[0] + p.lut_map[1]).clamp(0.0, p.lut_map[2]);
        let i0 = x.floor() as usize;
        let i1 = (i0 + 1).min(p.lut_map[2] as usize);
        let a = alpha[i0] + (alpha[i1] - alpha[i0]) * (x - x.floor());
        t *= 1.0 - a;
    }
    t
}

/// The texel values as the light pass samples them: rounded to f16 (see
/// [`crate::ao::vao::mip_chain`] for why float texels).
fn f16_texels(texels: &VolumeTexels) -> Vec<f32> {
    crate::ao::vao::mip_chain(texels, 0)
        .pop()
        .map(|(bits, _)| {
            bits.iter()
                .map(|&b| half::f16::from_bits(b).to_f32())
                .collect()
        })
        .unwrap_or_default()
}

/// The light volume on the CPU (rayon), x fastest. `direction`: unit, towards the light.
pub fn light_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    direction: Vec3,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    light_cpu_clipped(texels, lut, direction, None, progress)
}

/// [`light_cpu`] with clip shapes (maps read back from the GPU): clipped space is empty.
pub fn light_cpu_clipped(
    texels: &VolumeTexels,
    lut: &Lut,
    direction: Vec3,
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    let p = params(texels, lut, direction);
    let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
    let norm = f16_texels(texels);
    let [nx, ny, nz] = texels.dims;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..nz)
        .into_par_iter()
        .flat_map_iter(|z| {
            let slice: Vec<f32> = (0..nx * ny)
                .map(|i| light_voxel(&p, &alpha, &norm, texels.dims, [i % nx, i / nx, z], clip))
                .collect();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                nz,
            );
            slice
        })
        .collect()
}

/// Samples per submission: keeps each dispatch well inside the 60 s readback bound.
pub const SAMPLES_PER_SUBMISSION: u64 = 1 << 27;

/// Long-lived light-volume compute state.
#[derive(Debug)]
pub struct LightGpu {
    pipeline: wgpu::ComputePipeline,
    sampler: wgpu::Sampler,
}

impl LightGpu {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "light.wgsl")?;
        validated(device, "Light::new", || LightGpu {
            pipeline: crate::gpu::compute_pipeline(
                device,
                "Light::pipeline",
                &module,
                "main",
                None,
            ),
            sampler: crate::gpu::linear_sampler(device, "Light::linear_clamp"),
        })
    }

    /// The light volume of `texels` (uploaded as f16 for this pass), in z-slabs, read
    /// back. `direction`: unit, towards the light.
    pub fn compute(
        &self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        lut: &Lut,
        direction: Vec3,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        self.compute_clipped(gpu, texels, lut, direction, None, progress)
    }

    /// [`Self::compute`] through the clipped volume: clipped space lets light through.
    pub fn compute_clipped(
        &self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        lut: &Lut,
        direction: Vec3,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let device = &gpu.device;
        let clip_layout = self.pipeline.get_bind_group_layout(1);
        let clip_group = match clip {
            Some(c) => c.bind_group(device, &clip_layout),
            None => crate::clip::gpu::empty_bind_group(device, &clip_layout),
        };
        let [nx, ny, nz] = texels.dims;
        let slice = nx * ny;
        let base = params(texels, lut, direction);
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slab = ((SAMPLES_PER_SUBMISSION / base.work[2].max(1) as u64).min(max_storage)
            / slice as u64)
            .clamp(1, nz as u64) as usize;
        let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
        let size = (slab * slice * 4) as u64;
        let chain = crate::ao::vao::mip_chain(texels, 0);
        let (volume, lut_buf, out, readback) = validated(device, "Light::buffers", || {
            let volume = crate::ao::vao::f16_texture(device, &gpu.queue, "Light::texels", &chain)
                .create_view(&Default::default());
            let lut_buf = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Light::lut_alpha"),
                size: (alpha.len() * 4).max(16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            gpu.queue
                .write_buffer(&lut_buf, 0, bytemuck::cast_slice(&alpha));
            let out = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Light::transmittance"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let readback = readback_buffer(device, "Light::readback", size);
            (volume, lut_buf, out, readback)
        })?;
        let mut result = Vec::with_capacity(nx * ny * nz);
        let mut z0 = 0;
        while z0 < nz {
            let depth = slab.min(nz - z0);
            let count = (depth * slice) as u32;
            let groups = count.div_ceil(64);
            let gx = groups.min(65535);
            let gy = groups.div_ceil(gx);
            let mut p = base;
            p.dims[3] = z0 as u32;
            p.work[0] = count;
            p.work[1] = gx * 64;
            validated(device, "Light::slab", || {
                let uniforms =
                    uniform_buffer(device, &gpu.queue, "Light::params", bytemuck::bytes_of(&p));
                let group = bind_group(
                    device,
                    "Light::bind_group",
                    &self.pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&volume),
                        wgpu::BindingResource::Sampler(&self.sampler),
                        lut_buf.as_entire_binding(),
                        out.as_entire_binding(),
                    ],
                );
                crate::gpu::submit_compute_with(
                    device,
                    &gpu.queue,
                    "Light::slab",
                    &self.pipeline,
                    &[&group, &clip_group],
                    [gx, gy, 1],
                    |encoder| {
                        encoder.copy_buffer_to_buffer(&out, 0, &readback, 0, count as u64 * 4);
                    },
                );
            })?;
            let bytes = read_buffer(device, &readback, "Light::readback")?;
            result.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
                &bytes[..count as usize * 4],
            ));
            z0 += depth;
            progress(z0, nz);
        }
        Ok(result)
    }
}

/// Rounds light-volume values as the R16Float texture the ray caster samples holds them.
pub fn quantise(values: &[f32]) -> Vec<f32> {
    values
        .iter()
        .map(|&v| half::f16::from_f32(v.clamp(0.0, 1.0)).to_f32())
        .collect()
}

/// A light volume for the CPU twin of the ray caster: values as the GPU samples them.
#[derive(Debug, Clone)]
pub struct LightVolume {
    /// Unit direction towards the light.
    pub direction: Vec3,
    /// Transmittance per voxel (x fastest), rounded as [`quantise`] does.
    pub values: Vec<f32>,
}

/// The anti-aliased shadow factor at a view-ray sample (Imagire et al. Eq. 3–4):
/// `¼ T(uvw − half_step) + ½ T(uvw) + ¼ T(uvw + half_step)`, `half_step` = half the view
/// ray's step in texture coordinates.
pub fn shadow_factor(light: &[f32], dims: [usize; 3], uvw: Vec3, half_step: Vec3) -> f32 {
    0.25 * trilinear(light, dims, uvw - half_step)
        + 0.5 * trilinear(light, dims, uvw)
        + 0.25 * trilinear(light, dims, uvw + half_step)
}

/// What the ray caster reads in its bind group 1 beyond the core volume: live positional
/// AO and the light volume. Owned by [`crate::render::gpu::GpuVolume`]; `None` = off.
#[derive(Debug, Default)]
pub struct RayExtras {
    pub live_vao: Option<crate::ao::vao::VaoInputs>,
    pub light: Option<GpuLight>,
    /// Geometry drawn inside the volume (rasterised per frame, see `render::surface`).
    pub surfaces: Vec<crate::render::surface::Surface>,
}

/// A light volume on the GPU (R16Float) with its direction.
#[derive(Debug)]
pub struct GpuLight {
    pub view: wgpu::TextureView,
    /// Unit direction towards the light.
    pub direction: Vec3,
}

/// Uniforms of the ray caster's group 1. Mirrors `struct Extras` in `raycast.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ExtrasParams {
    /// Live positional AO on, shadows on, surfaces on (0/1).
    pub flags: [u32; 4],
    /// Unit direction towards the light.
    pub light: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<ExtrasParams>() == 32);

impl RayExtras {
    pub fn params(&self) -> ExtrasParams {
        let d = self.light.as_ref().map_or(Vec3::Z, |l| l.direction);
        ExtrasParams {
            flags: [
                u32::from(self.live_vao.is_some()),
                u32::from(self.light.is_some()),
                u32::from(!self.surfaces.is_empty()),
                0,
            ],
            light: [d.x, d.y, d.z, 0.0],
        }
    }
}

/// Stand-ins bound when a feature of group 1 is off (so one pipeline serves all cases).
#[derive(Debug)]
pub struct Placeholders {
    uniform: wgpu::Buffer,
    texture: wgpu::TextureView,
    storage: wgpu::Buffer,
    layer: wgpu::TextureView,
}

impl Placeholders {
    pub fn new(device: &wgpu::Device) -> Self {
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("RayCaster::placeholder_3d"),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::R16Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        Placeholders {
            uniform: buffer(
                "RayCaster::placeholder_uniform",
                std::mem::size_of::<crate::ao::vao::VaoParams>() as u64,
                wgpu::BufferUsages::UNIFORM,
            ),
            texture: texture.create_view(&Default::default()),
            storage: buffer(
                "RayCaster::placeholder_storage",
                16,
                wgpu::BufferUsages::STORAGE,
            ),
            layer: device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some("RayCaster::placeholder_2d"),
                    size: wgpu::Extent3d {
                        width: 1,
                        height: 1,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: crate::render::surface::LAYER_FORMAT,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&Default::default()),
        }
    }
}

/// Layout entries of the ray caster's group 1: positional AO (0–4), extras uniform (5),
/// light volume (6), surface position and colour (7, 8).
pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    let mut entries = crate::ao::vao::layout_entries();
    entries.push(wgpu::BindGroupLayoutEntry {
        binding: 5,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    });
    entries.push(wgpu::BindGroupLayoutEntry {
        binding: 6,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            view_dimension: wgpu::TextureViewDimension::D3,
            multisampled: false,
        },
        count: None,
    });
    for binding in [7, 8] {
        entries.push(wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        });
    }
    entries
}

/// The ray caster's bind group 1 for `extras` (placeholders where a feature is off);
/// `layer` is this frame's rasterised surfaces.
pub fn bind_group_2(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    layout: &wgpu::BindGroupLayout,
    extras: &RayExtras,
    layer: Option<&crate::render::surface::SurfaceLayer>,
    placeholders: &Placeholders,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    let uniforms = uniform_buffer(
        device,
        queue,
        "RayCaster::extras",
        bytemuck::bytes_of(&extras.params()),
    );
    let mut resources = match &extras.live_vao {
        Some(v) => v.resources(),
        None => vec![
            placeholders.uniform.as_entire_binding(),
            wgpu::BindingResource::TextureView(&placeholders.texture),
            wgpu::BindingResource::Sampler(sampler),
            placeholders.storage.as_entire_binding(),
            placeholders.storage.as_entire_binding(),
        ],
    };
    resources.push(uniforms.as_entire_binding());
    resources.push(wgpu::BindingResource::TextureView(
        extras
            .light
            .as_ref()
            .map_or(&placeholders.texture, |l| &l.view),
    ));
    resources.push(wgpu::BindingResource::TextureView(
        layer.map_or(&placeholders.layer, |l| &l.position),
    ));
    resources.push(wgpu::BindingResource::TextureView(
        layer.map_or(&placeholders.layer, |l| &l.color),
    ));
    bind_group(device, "RayCaster::bind_group_2", layout, &resources)
}

impl crate::render::gpu::GpuVolume {
    /// Turns live positional AO on (`Some`) or off for this volume and transfer function.
    /// Returns the CPU twin's equivalent of what is now on the GPU.
    pub fn set_live_vao(
        &mut self,
        gpu: &Gpu,
        tf: &TransferFunction,
        settings: Option<&crate::ao::vao::VaoSettings>,
    ) -> Result<(), GpuError> {
        self.extras.live_vao = match settings {
            Some(s) => Some(crate::ao::vao::VaoInputs::new(gpu, &self.texels, tf, s)?),
            None => None,
        };
        Ok(())
    }

    /// Uses `values` (transmittance per voxel, x fastest) as the light volume for shadows
    /// from `direction` (unit, towards the light); `None` turns shadows off. Returns the
    /// values as the GPU samples them (for the CPU twin).
    pub fn set_light_volume(
        &mut self,
        gpu: &Gpu,
        light: Option<(&[f32], Vec3)>,
    ) -> Result<Option<LightVolume>, GpuError> {
        let Some((values, direction)) = light else {
            self.extras.light = None;
            return Ok(None);
        };
        let dims = self.texels.dims;
        if values.len() != dims.iter().product::<usize>() {
            return Err(GpuError::Validation {
                stage: "GpuVolume::set_light_volume".into(),
                message: format!(
                    "{} light values for a {}×{}×{} volume",
                    values.len(),
                    dims[0],
                    dims[1],
                    dims[2]
                ),
            });
        }
        let bits: Vec<u16> = values
            .iter()
            .map(|&v| half::f16::from_f32(v.clamp(0.0, 1.0)).to_bits())
            .collect();
        let view = validated(&gpu.device, "GpuVolume::set_light_volume", || {
            crate::ao::vao::f16_texture(
                &gpu.device,
                &gpu.queue,
                "GpuVolume::light",
                &[(bits, dims)],
            )
            .create_view(&Default::default())
        })?;
        self.extras.light = Some(GpuLight { view, direction });
        Ok(Some(LightVolume {
            direction,
            values: quantise(values),
        }))
    }
}
