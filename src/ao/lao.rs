//! Local Ambient Occlusion (Hernell et al.; Eq. 2–3 of the CAO paper, §3.4 step I):
//! the precomputed volume `V_PAO`, on the GPU (`shaders/lao.wgsl`) and on the CPU (twin).
//!
//! For every voxel centre x and ray k, samples i = 1…M lie i mm away (physical space, so
//! anisotropic spacing is respected and the radius is M mm):
//! `A_k(x) = 1/M · Σ_{m=1..M} Π_{i<m} (1 − a_i)` and `A(x) = 1/K · Σ_k w_k A_k(x)`.
//! Opacities `a_i` come from the transfer function, corrected for a 1 mm step; samples
//! outside the volume are empty.

use crate::gpu::{
    Gpu, GpuError, bind_group, read_buffer, readback_buffer, shaders, submit_compute,
    uniform_buffer, validated,
};
use crate::render::cpu::trilinear;
use crate::render::gpu::{GpuVolume, bake_lut};
use crate::render::texels::VolumeTexels;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;
use rayon::prelude::*;

/// Samples per ray by default (the paper's M).
pub const DEFAULT_SAMPLES: u32 = 20;

/// Distance between samples along an LAO ray.
pub const STEP_MM: f32 = 1.0;

/// The opacity table for LAO: the transfer function's alpha, corrected from its
/// reference length (one voxel of the smallest spacing) to a 1 mm step.
pub fn lao_lut(tf: &TransferFunction, texels: &VolumeTexels) -> Lut {
    let min_spacing = texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    bake_lut(tf, texels, STEP_MM / min_spacing)
}

/// Ray directions with their Eq. 3 weights `w_k` (mean 1).
#[derive(Debug, Clone, PartialEq)]
pub struct Rays {
    pub directions: Vec<Vec3>,
    pub weights: Vec<f32>,
}

impl Rays {
    pub fn uniform(directions: Vec<Vec3>) -> Self {
        let weights = vec![1.0; directions.len()];
        Rays {
            directions,
            weights,
        }
    }

    /// As the shader reads them: xyz direction, w weight.
    fn packed(&self) -> Vec<[f32; 4]> {
        self.directions
            .iter()
            .zip(&self.weights)
            .map(|(d, w)| [d.x, d.y, d.z, *w])
            .collect()
    }
}

/// Uniforms of `lao.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LaoParams {
    pub dims: [u32; 4],
    pub mm_to_uvw: [f32; 4],
    pub lut_map: [f32; 4],
    pub counts: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<LaoParams>() == 64);

fn params(texels: &VolumeTexels, lut: &Lut, rays: &Rays, samples: u32) -> LaoParams {
    let extent = texels.extent();
    let (a, b) = texels.lut_map(lut);
    LaoParams {
        dims: [
            texels.dims[0] as u32,
            texels.dims[1] as u32,
            texels.dims[2] as u32,
            0,
        ],
        mm_to_uvw: [
            STEP_MM / extent[0],
            STEP_MM / extent[1],
            STEP_MM / extent[2],
            0.0,
        ],
        lut_map: [a, b, (lut.rgba.len().max(2) - 1) as f32, 0.0],
        counts: [rays.directions.len() as u32, samples.max(1), 0, 0],
    }
}

fn alpha_at(p: &LaoParams, alpha: &[f32], norm: &[f32], dims: [usize; 3], uvw: Vec3) -> f32 {
    if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
        return 0.0;
    }
    let n = trilinear(norm, dims, uvw);
    let t = (n * p.lut_map[0] + p.lut_map[1]).clamp(0.0, p.lut_map[2]);
    let i0 = t.floor() as usize;
    let i1 = (i0 + 1).min(p.lut_map[2] as usize);
    let f = t - t.floor();
    alpha[i0] + (alpha[i1] - alpha[i0]) * f
}

/// CPU twin of one invocation of `lao.wgsl`: A(x) of the voxel at `voxel`.
fn lao_voxel(
    p: &LaoParams,
    alpha: &[f32],
    norm: &[f32],
    dims: [usize; 3],
    rays: &[[f32; 4]],
    voxel: [usize; 3],
) -> f32 {
    let centre = (Vec3::new(voxel[0] as f32, voxel[1] as f32, voxel[2] as f32) + Vec3::splat(0.5))
        / Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32);
    let samples = p.counts[1];
    let scale = Vec3::new(p.mm_to_uvw[0], p.mm_to_uvw[1], p.mm_to_uvw[2]);
    let mut total = 0.0;
    for ray in rays {
        let step = Vec3::new(ray[0], ray[1], ray[2]) * scale;
        let mut transmittance = 1.0;
        let mut sum = 0.0;
        for m in 1..=samples {
            sum += transmittance;
            if m < samples {
                transmittance *= 1.0 - alpha_at(p, alpha, norm, dims, centre + step * m as f32);
            }
        }
        total += ray[3] * sum / samples as f32;
    }
    total / rays.len() as f32
}

/// `V_PAO` on the CPU (rayon), x fastest. `progress(done, total)` counts z-slices.
pub fn lao_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    rays: &Rays,
    samples: u32,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    let p = params(texels, lut, rays, samples);
    let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
    let norm = texels.norm_values();
    let packed = rays.packed();
    let [nx, ny, nz] = texels.dims;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..nz)
        .into_par_iter()
        .flat_map_iter(|z| {
            let slice: Vec<f32> = (0..nx * ny)
                .map(|i| lao_voxel(&p, &alpha, &norm, texels.dims, &packed, [i % nx, i / nx, z]))
                .collect();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                nz,
            );
            slice
        })
        .collect()
}

/// Samples per submission on the GPU: small enough that no dispatch runs into a driver
/// watchdog (about a second on a mid-range GPU), large enough to keep it busy.
pub const SAMPLES_PER_SUBMISSION: u64 = 1 << 30;

/// Long-lived LAO compute state.
#[derive(Debug)]
pub struct LaoGpu {
    pipeline: wgpu::ComputePipeline,
    sampler: wgpu::Sampler,
}

impl LaoGpu {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "lao.wgsl")?;
        validated(device, "Lao::new", || LaoGpu {
            pipeline: crate::gpu::compute_pipeline(device, "Lao::pipeline", &module, "main", None),
            sampler: crate::gpu::linear_sampler(device, "Lao::linear_clamp"),
        })
    }

    /// `V_PAO` of an uploaded volume, computed in z-slabs (one submission each) and read
    /// back. `progress(done, total)` counts z-slices.
    pub fn compute(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        lut: &Lut,
        rays: &Rays,
        samples: u32,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let device = &gpu.device;
        let texels = &vol.texels;
        let [nx, ny, nz] = texels.dims;
        let slice = nx * ny;
        let per_voxel = rays.directions.len() as u64 * samples.max(1) as u64;
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slab = ((SAMPLES_PER_SUBMISSION / per_voxel.max(1)).min(max_storage) / slice as u64)
            .clamp(1, nz as u64) as usize;
        let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
        let base = params(texels, lut, rays, samples);
        let (lut_buf, ray_buf, out, readback) = validated(device, "Lao::buffers", || {
            let storage = |label, bytes: &[u8]| {
                let b = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes.len().max(16) as u64,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                gpu.queue.write_buffer(&b, 0, bytes);
                b
            };
            let lut_buf = storage("Lao::lut_alpha", bytemuck::cast_slice(&alpha));
            let ray_buf = storage("Lao::rays", bytemuck::cast_slice(&rays.packed()));
            let size = (slab * slice * 4) as u64;
            let out = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Lao::v_pao"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let readback = readback_buffer(device, "Lao::readback", size);
            (lut_buf, ray_buf, out, readback)
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
            p.counts[2] = count;
            p.counts[3] = gx * 64;
            validated(device, "Lao::slab", || {
                let uniforms =
                    uniform_buffer(device, &gpu.queue, "Lao::params", bytemuck::bytes_of(&p));
                let group = bind_group(
                    device,
                    "Lao::bind_group",
                    &self.pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(vol.volume_view()),
                        wgpu::BindingResource::Sampler(&self.sampler),
                        lut_buf.as_entire_binding(),
                        ray_buf.as_entire_binding(),
                        out.as_entire_binding(),
                    ],
                );
                submit_compute(
                    device,
                    &gpu.queue,
                    "Lao::slab",
                    &self.pipeline,
                    &group,
                    [gx, gy, 1],
                    |encoder| {
                        encoder.copy_buffer_to_buffer(&out, 0, &readback, 0, count as u64 * 4);
                    },
                );
            })?;
            let bytes = read_buffer(device, &readback, "Lao::readback")?;
            result.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
                &bytes[..count as usize * 4],
            ));
            z0 += depth;
            progress(z0, nz);
        }
        Ok(result)
    }
}
