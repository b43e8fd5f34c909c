//! Cone-traced ambient occlusion for volumes (Dalla Favera & Celes 2012, §III-C,
//! adapted from surfaces to every voxel), on the GPU (`shaders/cone.wgsl`) with a CPU
//! twin.
//!
//! The transfer function's opacity per voxel is averaged into a mip pyramid (2×2×2 box
//! per level, built on the CPU: about 1/7 of a volume pass). From each voxel centre,
//! cones along 6, 14 or 26 directions cover the whole sphere. Each cone is sampled by
//! `n` tangent spheres between one voxel and the reach `R`: sphere `k` spans
//! `[e_k, e_k+1]` along the axis with `e_k = d₀ (R/d₀)^(k/n)`, so consecutive spheres
//! touch and their radii grow with the distance, as in the paper's Fig. 5b (the
//! aperture follows from `n`: 3 spheres over 1…20 mm is the paper's ≈ 30°). A sphere's
//! occlusion `o_k` is the mean opacity inside it, read at its centre from the mip level
//! whose texel matches its diameter (linear between the two nearest levels). Along a
//! cone the spheres combine front to back (their Fig. 8): `A_cone = Π_k (1 − o_k)`;
//! `A(x)` is the mean over cones. A sphere whose centre lies outside the volume is empty
//! (as LAO treats samples outside).

use crate::gpu::dispatch::{Grid, SlabDispatch};
use crate::gpu::{
    Gpu, GpuError, copy_texture_out, read_buffer, storage_buffer, submit_compute, texture_readback,
    unpad, validated,
};
use crate::sample::{VolumeSampler, bake_lut, trilinear};
use crate::texels::VolumeTexels;
use crate::texels::segments::SegmentTexels;
use crate::tf::TransferFunction;
use glam::Vec3;
use rayon::prelude::*;

pub use super::settings::{ConePreset, ConeSet};

/// An averaged opacity pyramid; level 0 is the volume, x fastest in each level.
#[derive(Debug, Clone, PartialEq)]
pub struct MipPyramid {
    pub levels: Vec<([usize; 3], Vec<f32>)>,
}

impl MipPyramid {
    /// Level `l + 1` has `max(1, d/2)` texels per axis (as a GPU mip chain); texel `j`
    /// averages the 2×2×2 texels `2j + {0, 1}` of level `l` (clamped at the edge).
    pub fn new(dims: [usize; 3], alpha: Vec<f32>) -> Self {
        let mut levels = vec![(dims, alpha)];
        loop {
            let (d, src) = levels.last().expect("level 0 exists");
            if d.iter().all(|&n| n <= 1) {
                break;
            }
            let nd: [usize; 3] = std::array::from_fn(|i| (d[i] / 2).max(1));
            let d = *d;
            let next: Vec<f32> = (0..nd[0] * nd[1] * nd[2])
                .into_par_iter()
                .map(|i| {
                    let j = [i % nd[0], (i / nd[0]) % nd[1], i / (nd[0] * nd[1])];
                    let mut sum = 0.0;
                    for k in 0..8 {
                        let s: [usize; 3] =
                            std::array::from_fn(|a| (2 * j[a] + ((k >> a) & 1)).min(d[a] - 1));
                        sum += src[s[0] + d[0] * (s[1] + d[1] * s[2])];
                    }
                    sum / 8.0
                })
                .collect();
            levels.push((nd, next));
        }
        MipPyramid { levels }
    }
}

/// Opacity per voxel for one voxel of path, from the transfer function and a
/// segmentation's weights: each voxel read through [`VolumeSampler`] (the pyramid the
/// cones read is built from these).
pub fn opacity(
    texels: &VolumeTexels,
    tf: &TransferFunction,
    segments: Option<&SegmentTexels>,
) -> Vec<f32> {
    let lut = bake_lut(tf, texels, 1.0);
    let values = texels.norm_values();
    let volume = VolumeSampler::density(&values, texels, &lut);
    let weight = |i: usize| segments.map_or(1.0, |s| s.look[i][3] as f32 / 255.0);
    values
        .par_iter()
        .enumerate()
        .map(|(i, &v)| volume.opacity(v) * weight(i))
        .collect()
}

/// Where the spheres of a cone sit: `(distance of the centre in mm, mip level)`.
pub fn spheres(spheres: u32, reach_mm: f32, texels: &VolumeTexels, levels: usize) -> Vec<[f32; 2]> {
    let voxel = texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    let d0 = voxel;
    let reach = reach_mm.max(2.0 * d0);
    let n = spheres.max(1);
    let e = |k: u32| d0 * (reach / d0).powf(k as f32 / n as f32);
    (0..n)
        .map(|k| {
            let (a, b) = (e(k), e(k + 1));
            let lod = ((b - a) / voxel).log2().clamp(0.0, (levels - 1) as f32);
            [(a + b) / 2.0, lod]
        })
        .collect()
}

/// Uniforms of `cone.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ConeParams {
    /// x, y, z, levels.
    pub dims: [u32; 4],
    /// 1 / extent in mm per axis.
    pub mm_to_uvw: [f32; 4],
    /// cones, spheres per cone.
    pub counts: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<ConeParams>() == 48);

fn sample(pyramid: &MipPyramid, uvw: Vec3, lod: f32) -> f32 {
    let l0 = lod.floor() as usize;
    let l1 = (l0 + 1).min(pyramid.levels.len() - 1);
    let (d0, v0) = &pyramid.levels[l0];
    let a = trilinear(v0, *d0, uvw);
    let f = lod - lod.floor();
    if f == 0.0 {
        return a;
    }
    let (d1, v1) = &pyramid.levels[l1];
    a + (trilinear(v1, *d1, uvw) - a) * f
}

/// CPU twin of one invocation of `cone.wgsl`.
fn cone_voxel(
    p: &ConeParams,
    pyramid: &MipPyramid,
    dirs: &[Vec3],
    spheres: &[[f32; 2]],
    voxel: [usize; 3],
) -> f32 {
    let dims = Vec3::new(p.dims[0] as f32, p.dims[1] as f32, p.dims[2] as f32);
    let centre =
        (Vec3::new(voxel[0] as f32, voxel[1] as f32, voxel[2] as f32) + Vec3::splat(0.5)) / dims;
    let scale = Vec3::new(p.mm_to_uvw[0], p.mm_to_uvw[1], p.mm_to_uvw[2]);
    let mut total = 0.0;
    for d in dirs {
        let mut visible = 1.0;
        for s in spheres {
            let uvw = centre + *d * scale * s[0];
            if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
                continue;
            }
            visible *= 1.0 - sample(pyramid, uvw, s[1]);
        }
        total += visible;
    }
    total / dirs.len() as f32
}

fn params(texels: &VolumeTexels, levels: usize, cones: usize, spheres: usize) -> ConeParams {
    let extent = texels.extent();
    ConeParams {
        dims: [
            texels.dims[0] as u32,
            texels.dims[1] as u32,
            texels.dims[2] as u32,
            levels as u32,
        ],
        mm_to_uvw: [1.0 / extent[0], 1.0 / extent[1], 1.0 / extent[2], 0.0],
        counts: [cones as u32, spheres as u32, 0, 0],
    }
}

/// Cone-traced `A(x)` on the CPU (rayon), x fastest.
pub fn cone_cpu(
    texels: &VolumeTexels,
    pyramid: &MipPyramid,
    cones: ConeSet,
    preset: ConePreset,
    reach_mm: f32,
) -> Vec<f32> {
    let dirs = cones.directions();
    let sph = spheres(preset.spheres(), reach_mm, texels, pyramid.levels.len());
    let p = params(texels, pyramid.levels.len(), dirs.len(), sph.len());
    let [nx, ny, nz] = texels.dims;
    (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            cone_voxel(
                &p,
                pyramid,
                &dirs,
                &sph,
                crate::volume::voxel_of(i, [nx, ny, nz]),
            )
        })
        .collect()
}

crate::gpu::compute_stage!(
    /// Long-lived cone-tracing state.
    ConeGpu,
    "Cone",
    "cone.wgsl"
);

impl ConeGpu {
    /// Uploads the pyramid (R32Float, one mip level per pyramid level), traces the cones
    /// and reads `A(x)` back, x fastest.
    pub fn compute(
        &self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        pyramid: &MipPyramid,
        cones: ConeSet,
        preset: ConePreset,
        reach_mm: f32,
    ) -> Result<Vec<f32>, GpuError> {
        let device = &gpu.device;
        let dirs = cones.directions();
        let sph = spheres(preset.spheres(), reach_mm, texels, pyramid.levels.len());
        let p = params(texels, pyramid.levels.len(), dirs.len(), sph.len());
        let dims = texels.dims.map(|d| d as u32);
        let packed_dirs: Vec<[f32; 4]> = dirs.iter().map(|d| [d.x, d.y, d.z, 0.0]).collect();
        let packed_spheres: Vec<[f32; 4]> = sph.iter().map(|s| [s[0], s[1], 0.0, 0.0]).collect();
        let (out, readback, row) = validated(device, "Cone::compute", || {
            let mip = crate::gpu::mip_texture_3d(
                device,
                "Cone::opacity_mips",
                dims,
                pyramid.levels.len() as u32,
                wgpu::TextureFormat::R32Float,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            for (level, (d, values)) in pyramid.levels.iter().enumerate() {
                let d = d.map(|x| x as u32);
                let bytes = bytemuck::cast_slice(values);
                crate::gpu::write_texture_3d(&gpu.queue, &mip, level as u32, d, 4, bytes);
            }
            let storage = |label, bytes: &[u8]| {
                storage_buffer(gpu, label, bytes, wgpu::BufferUsages::empty())
            };
            let dir_buf = storage("Cone::directions", bytemuck::cast_slice(&packed_dirs));
            let sphere_buf = storage("Cone::spheres", bytemuck::cast_slice(&packed_spheres));
            let out = crate::gpu::output_volume(device, "Cone::ambient", dims);
            let (readback, row) = texture_readback(device, "Cone::readback", dims, 4);
            let mip_view = mip.create_view(&Default::default());
            let out_view = out.create_view(&Default::default());
            let (_uniforms, group) = self.0.sampling_group(
                gpu,
                "Cone",
                &p,
                &mip_view,
                &[
                    dir_buf.as_entire_binding(),
                    sphere_buf.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&out_view),
                ],
            );
            // The shader covers the whole volume in one dispatch (a fraction of a second).
            let slab = SlabDispatch::whole(dims, Grid::Tiles).slabs().next();
            let groups = slab.map_or([1, 1, 1], |s| s.groups);
            submit_compute(
                device,
                &gpu.queue,
                "Cone::trace",
                &self.0.pipeline,
                &group,
                groups,
                |e| copy_texture_out(e, &out, &readback, row, dims),
            );
            (out, readback, row)
        })?;
        let bytes = read_buffer(device, &readback, "Cone::readback")?;
        drop(out);
        Ok(unpad::<f32>(&bytes, row, dims[0]))
    }
}
