//! Volumetric shadows from a directional light: the light volume `T(x)` (transmittance
//! from each voxel centre towards the light) on the GPU (`shaders/light.wgsl`) and on the
//! CPU (twin: [`light_cpu`]), and the anti-aliased shadow factor the ray caster reads.
//!
//! Anti-aliasing follows Imagire et al. (2007, §3.3): the shadow at a view-ray sample
//! `s_i` is `¼ T(s_i − Δs/2) + ½ T(s_i) + ¼ T(s_i + Δs/2)` (their Eq. 3–4, the half-step
//! positions between neighbouring samples), and the light rays start at a per-voxel
//! jittered offset, so no stair-steps appear at shadow boundaries.

use crate::gpu::{
    Gpu, GpuError, bind_group, read_buffer, readback_buffer, shaders, submit_compute,
    uniform_buffer, validated,
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
}

const _: () = assert!(std::mem::size_of::<LightParams>() == 64);

fn params(texels: &VolumeTexels, lut: &Lut, direction: Vec3) -> LightParams {
    let extent = texels.extent();
    let h = LIGHT_STEP_VOXELS * texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    let diag = Vec3::from(extent).length();
    let (a, b) = texels.lut_map(lut);
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
    }
}

/// CPU twin of one invocation of `light.wgsl`: T at the centre of `voxel`.
fn light_voxel(
    p: &LightParams,
    alpha: &[f32],
    norm: &[f32],
    dims: [usize; 3],
    voxel: [usize; 3],
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
    let p = params(texels, lut, direction);
    let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
    let norm = f16_texels(texels);
    let [nx, ny, nz] = texels.dims;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..nz)
        .into_par_iter()
        .flat_map_iter(|z| {
            let slice: Vec<f32> = (0..nx * ny)
                .map(|i| light_voxel(&p, &alpha, &norm, texels.dims, [i % nx, i / nx, z]))
                .collect();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                nz,
            );
            slice
        })
        .collect()
}

/// Samples per submission: keeps each dispatch short.
pub const SAMPLES_PER_SUBMISSION: u64 = 1 << 30;

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
            pipeline: device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("Light::pipeline"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            }),
            sampler: device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("Light::linear_clamp"),
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            }),
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
        let device = &gpu.device;
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
                submit_compute(
                    device,
                    &gpu.queue,
                    "Light::slab",
                    &self.pipeline,
                    &group,
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
