//! Local Ambient Occlusion (Hernell et al.; Eq. 2–3 of the CAO paper, §3.4 step I):
//! the precomputed volume `V_PAO`, on the GPU (`shaders/lao.wgsl`) and on the CPU (twin).
//!
//! For every voxel centre x and ray k, samples i = 1…M lie i mm away (physical space, so
//! anisotropic spacing is respected and the radius is M mm):
//! `A_k(x) = 1/M · Σ_{m=1..M} Π_{i<m} (1 − a_i)` and `A(x) = 1/K · Σ_k w_k A_k(x)`.
//! Opacities `a_i` come from the transfer function, corrected for a 1 mm step; samples
//! outside the volume are empty.

use crate::gpu::dispatch::{Grid, Pass, SlabDispatch, SlabOrigin, budget, slab_fields};
use crate::gpu::{Gpu, GpuError, output_buffer, readback_buffer, storage_buffer, validated};
use crate::render::gpu::GpuVolume;
use crate::render::texels::VolumeTexels;
use crate::sample::bake_lut;
use crate::sample::{alpha_column, lut_lerp, per_voxel, trilinear, voxel_centre};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

pub use super::settings::DEFAULT_SAMPLES;

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
    /// The volume's size and this dispatch's first z-slice.
    pub slab: SlabOrigin,
    /// One LAO step (1 mm) in texture coordinates per axis.
    pub mm_to_uvw: [f32; 3],
    pub _pad0: f32,
    /// LUT index = norm · lut_scale + lut_offset, clamped to lut_last.
    pub lut_scale: f32,
    pub lut_offset: f32,
    pub lut_last: f32,
    pub _pad1: f32,
    /// K and M.
    pub rays: u32,
    pub samples: u32,
    /// Voxels in this dispatch and invocations per row of workgroups.
    pub voxels: u32,
    pub row_stride: u32,
}

const _: () = assert!(std::mem::size_of::<LaoParams>() == 64);

slab_fields!(LaoParams, linear);

/// One LAO step ([`STEP_MM`]) in texture coordinates along each axis.
pub fn mm_to_uvw(texels: &VolumeTexels) -> [f32; 3] {
    let extent = texels.extent();
    [
        STEP_MM / extent[0],
        STEP_MM / extent[1],
        STEP_MM / extent[2],
    ]
}

fn params(texels: &VolumeTexels, lut: &Lut, rays: &Rays, samples: u32) -> LaoParams {
    let (a, b) = texels.lut_map(lut);
    LaoParams {
        slab: SlabOrigin::of(texels.dims.map(|d| d as u32)),
        mm_to_uvw: mm_to_uvw(texels),
        _pad0: 0.0,
        lut_scale: a,
        lut_offset: b,
        lut_last: (lut.rgba.len().max(2) - 1) as f32,
        _pad1: 0.0,
        rays: rays.directions.len() as u32,
        samples: samples.max(1),
        voxels: 0,
        row_stride: 0,
    }
}

fn alpha_at(p: &LaoParams, alpha: &[f32], norm: &[f32], dims: [usize; 3], uvw: Vec3) -> f32 {
    if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
        return 0.0;
    }
    let n = trilinear(norm, dims, uvw);
    lut_lerp(alpha, [p.lut_scale, p.lut_offset, p.lut_last], n)
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
    let centre = voxel_centre(voxel, dims);
    let samples = p.samples;
    let scale = Vec3::from(p.mm_to_uvw);
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
    let alpha = alpha_column(lut);
    let norm = texels.norm_values();
    let packed = rays.packed();
    per_voxel(texels.dims, progress, |v| {
        lao_voxel(&p, &alpha, &norm, texels.dims, &packed, v)
    })
}

crate::gpu::compute_stage!(
    /// Long-lived LAO compute state.
    LaoGpu,
    "Lao",
    "lao.wgsl"
);

impl LaoGpu {
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
        let base = params(texels, lut, rays, samples);
        let per_voxel = rays.directions.len() as u64 * samples.max(1) as u64;
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slabs = SlabDispatch::new(
            base.slab.dims,
            Grid::Linear,
            per_voxel,
            budget::LAO_SAMPLES,
            max_storage,
        );
        let alpha = alpha_column(lut);
        let (uniforms, out, readback, group) = validated(device, "Lao::buffers", || {
            let lut_buf = storage_buffer(
                gpu,
                "Lao::lut_alpha",
                bytemuck::cast_slice(&alpha),
                wgpu::BufferUsages::empty(),
            );
            let ray_buf = storage_buffer(
                gpu,
                "Lao::rays",
                bytemuck::cast_slice(&rays.packed()),
                wgpu::BufferUsages::empty(),
            );
            let size = slabs.max_slab_voxels() * 4;
            let out = output_buffer(device, "Lao::v_pao", size);
            let readback = readback_buffer(device, "Lao::readback", size);
            let bound = [&lut_buf, &ray_buf, &out].map(|b| b.as_entire_binding());
            let (uniforms, group) =
                self.0
                    .sampling_group(gpu, "Lao", &base, vol.volume_view(), &bound);
            (uniforms, out, readback, group)
        })?;
        let pass = Pass {
            label: "Lao::slab",
            pipeline: &self.0.pipeline,
            bind_groups: &[&group],
            uniforms: &uniforms,
        };
        slabs.run_readback(gpu, &pass, base, (&out, &readback), progress)
    }
}
