//! Local Ambient Occlusion (Hernell et al.; Eq. 2–3 of the CAO paper, §3.4 step I):
//! the precomputed volume `V_PAO`, on the GPU (`shaders/lao.wgsl`) and on the CPU (twin).
//!
//! For every voxel centre x and ray k, samples i = 1…M lie i mm away (physical space, so
//! anisotropic spacing is respected and the radius is M mm):
//! `A_k(x) = 1/M · Σ_{m=1..M} Π_{i<m} (1 − a_i)` and `A(x) = 1/K · Σ_k w_k A_k(x)`.
//! Opacities `a_i` come from the transfer function, corrected for a 1 mm step; samples
//! outside the volume are empty.

use super::sparse::{Bricks, brick_voxels, empty_run};
use crate::gpu::dispatch::{BrickChunk, BrickDispatch, Pass, budget, chunk_fields};
use crate::gpu::{
    Gpu, GpuError, Segmentable, output_buffer, read_buffer, readback_buffer, storage_buffer,
    uniform_group, validated,
};
use crate::sample::{SegmentSampler, VolumeSampler, voxel_centre};
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::texels::gpu_data::VolumeMap;
use crate::texels::reader::{self, Reading, SegmentBindings, VOLUME_GROUP};
use crate::tf::Lut;
use glam::Vec3;
use rayon::prelude::*;

pub use super::settings::DEFAULT_SAMPLES;

pub use crate::sample::{LAO_STEP_MM as STEP_MM, lao_lut};

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
    /// The volume's size and this submission's bricks.
    pub bricks: BrickChunk,
    /// One LAO step (1 mm) in texture coordinates per axis.
    pub mm_to_uvw: [f32; 3],
    pub _pad0: f32,
    /// K and M.
    pub rays: u32,
    pub samples: u32,
    pub _pad2: [u32; 2],
    /// Cells per axis and whether rays step over empty ones (0/1; `RayCells::uniform`).
    pub grid: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<LaoParams>() == 80);

chunk_fields!(LaoParams);

/// One LAO step ([`STEP_MM`]) in texture coordinates along each axis.
pub fn mm_to_uvw(texels: &VolumeTexels) -> [f32; 3] {
    let extent = texels.extent();
    [
        STEP_MM / extent[0],
        STEP_MM / extent[1],
        STEP_MM / extent[2],
    ]
}

fn params(texels: &VolumeTexels, rays: &Rays, samples: u32, bricks: &Bricks) -> LaoParams {
    LaoParams {
        bricks: BrickChunk::of(texels.dims.map(|d| d as u32)),
        mm_to_uvw: mm_to_uvw(texels),
        _pad0: 0.0,
        rays: rays.directions.len() as u32,
        samples: samples.max(1),
        _pad2: [0; 2],
        grid: bricks.rays.uniform(bricks.skipping),
    }
}

/// A ray sample's opacity (`ray_opacity` in `lao_ray.wgsl`): 0 outside the volume.
fn alpha_at(volume: &VolumeSampler, uvw: Vec3) -> f32 {
    if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
        return 0.0;
    }
    volume.opacity_at(uvw)
}

/// CPU twin of one invocation of `lao.wgsl`: A(x) of the voxel at `voxel`.
fn lao_voxel(
    p: &LaoParams,
    volume: &VolumeSampler,
    rays: &[[f32; 4]],
    bricks: &Bricks,
    voxel: [usize; 3],
) -> f32 {
    let dims = volume.dims;
    let centre = voxel_centre(voxel, dims);
    let samples = p.samples;
    let scale = Vec3::from(p.mm_to_uvw);
    let mut total = 0.0;
    for ray in rays {
        let step = Vec3::new(ray[0], ray[1], ray[2]) * scale;
        let sum = ray_sum(centre, step, samples, bricks, dims, |uvw| {
            alpha_at(volume, uvw)
        });
        total += ray[3] * sum / samples as f32;
    }
    total / rays.len() as f32
}

/// One LAO ray's sum `Σ_{m=1..M} Π_{i<m} (1 − a_i)` (Eq. 2), sample `i` at
/// `centre + i · step`: the CPU twin of `lao_ray` in `shaders/lao_ray.wgsl`. With
/// `bricks` skipping, runs of samples of opacity exactly 0 are not fetched; the
/// transmittance is still added once per sample, so the sum is the dense one bit for bit.
pub fn ray_sum(
    centre: Vec3,
    step: Vec3,
    samples: u32,
    bricks: &Bricks,
    dims: [usize; 3],
    opacity: impl Fn(Vec3) -> f32,
) -> f32 {
    let mut transmittance = 1.0f32;
    let mut sum = transmittance;
    let mut m = 1;
    while m < samples {
        let run = empty_run(bricks, dims, centre, step, m, samples);
        if run > 0 {
            for _ in 0..run {
                sum += transmittance;
            }
            m += run;
            continue;
        }
        transmittance *= 1.0 - opacity(centre + step * m as f32);
        m += 1;
        sum += transmittance;
    }
    sum
}

/// `V_PAO` on the CPU (rayon), x fastest: the readable bricks of `bricks`, 1 elsewhere.
/// `progress(done, total)` counts bricks.
pub fn lao_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    rays: &Rays,
    samples: u32,
    bricks: &Bricks,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    let setup = LaoSetup { lut, rays, samples };
    lao_cpu_reading(texels, setup, None, bricks, progress)
}

/// [`lao_cpu`] reading `segments` beside the density (the twin of [`LaoGpu::compute`]
/// on a volume with a segmentation).
pub fn lao_cpu_reading(
    texels: &VolumeTexels,
    setup: LaoSetup<'_>,
    segments: Option<&SegmentSampler>,
    bricks: &Bricks,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    let LaoSetup { lut, rays, samples } = setup;
    let p = params(texels, rays, samples, bricks);
    let norm = texels.norm_values();
    let volume = VolumeSampler::density(&norm, texels, lut).with_segments(segments);
    let packed = rays.packed();
    let dims = texels.dims;
    let list = bricks.list(|i| bricks.readable[i] != 0);
    let readable = bricks.readable_mask(texels);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let values: Vec<Vec<f32>> = list
        .par_iter()
        .map(|&b| {
            let v = brick_voxels(b, dims)
                .map(|v| {
                    if readable[v[0] + dims[0] * (v[1] + dims[1] * v[2])] {
                        lao_voxel(&p, &volume, &packed, bricks, v)
                    } else {
                        1.0
                    }
                })
                .collect();
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n, list.len());
            v
        })
        .collect();
    let mut out = vec![1.0; dims.iter().product()];
    for (&b, v) in list.iter().zip(values) {
        for (voxel, a) in brick_voxels(b, dims).zip(v) {
            out[voxel[0] + dims[0] * (voxel[1] + dims[1] * voxel[2])] = a;
        }
    }
    out
}

/// What LAO computes with ([`LaoGpu::compute`]): the opacity table ([`lao_lut`]), the
/// rays and the samples per ray, M.
#[derive(Debug, Clone, Copy)]
pub struct LaoSetup<'a> {
    pub lut: &'a Lut,
    pub rays: &'a Rays,
    pub samples: u32,
}

/// Long-lived LAO compute state: its pipelines, by what they skip.
#[derive(Debug)]
pub struct LaoGpu {
    /// Rays step over empty cells (every voxel: `volao ao`).
    sparse: Segmentable,
    /// Readable voxels only, rays fetch every sample ([`super::sparse::READABLE`]).
    readable: Segmentable,
    /// Nothing skipped (`--no-skipping`).
    dense: Segmentable,
}

/// List entries per dispatched group (dispatched like a brick of 8³ voxels).
const GROUP: usize = 512;

/// A list entry no invocation computes (`NONE` in `lao.wgsl`).
const NONE: u32 = u32::MAX;

impl crate::gpu::Stage for LaoGpu {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        Ok(LaoGpu {
            sparse: Segmentable::new(device, "Lao", "lao.wgsl", &[])?,
            readable: Segmentable::new(
                device,
                "Lao::readable",
                "lao.wgsl",
                super::sparse::READABLE,
            )?,
            dense: Segmentable::new(device, "Lao::dense", "lao.wgsl", super::sparse::DENSE)?,
        })
    }
}

impl LaoGpu {
    /// `V_PAO` of an uploaded volume over the voxels of `bricks` the ray caster can
    /// read ([`Bricks::voxel_list`]; 1 elsewhere), in submissions of whole groups of 512
    /// of them, each read back. `progress(done, total)` counts groups.
    pub fn compute(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        setup: LaoSetup<'_>,
        bricks: &Bricks,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let LaoSetup { lut, rays, samples } = setup;
        let device = &gpu.device;
        let texels = &vol.texels;
        let dims = texels.dims;
        let stage = if !bricks.skipping {
            &self.dense
        } else if super::sparse::readable_only(bricks) {
            &self.readable
        } else {
            &self.sparse
        }
        .get(device, vol.segments.on)?;
        let base = params(texels, rays, samples, bricks);
        let list = bricks.voxel_list(texels);
        let groups = list.len().div_ceil(GROUP);
        let per_voxel = rays.directions.len() as u64 * samples.max(1) as u64;
        let max_groups = device.limits().max_storage_buffer_binding_size / (4 * GROUP as u64);
        let chunks = BrickDispatch::new(0, groups, per_voxel, budget::LAO_SAMPLES, max_groups);
        let mut out_values = vec![1.0f32; dims.iter().product()];
        if list.is_empty() {
            return Ok(out_values);
        }
        let occupied = bricks.rays.words();
        let (uniforms, out, readback, bound, list_buf) = validated(device, "Lao::buffers", || {
            let table = reader::table(gpu, "Lao::lut", lut);
            let map = VolumeMap::new(texels, lut);
            let segments = SegmentBindings::Look(&vol.segments);
            let reading =
                Reading::sampled(vol.volume_view(), &stage.sampler, map, &table, segments);
            let volume_group = reading.group_of(gpu, "Lao", &stage.pipeline);
            let ray_buf = storage_buffer(
                gpu,
                "Lao::rays",
                bytemuck::cast_slice(&rays.packed()),
                wgpu::BufferUsages::empty(),
            );
            let size = chunks.max_chunk() as u64 * GROUP as u64 * 4;
            let list_buf = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Lao::voxels"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let occupied_buf = storage_buffer(
                gpu,
                "Lao::occupied",
                bytemuck::cast_slice(&occupied),
                wgpu::BufferUsages::empty(),
            );
            let out = output_buffer(device, "Lao::v_pao", size);
            let readback = readback_buffer(device, "Lao::readback", size);
            let bound = [&ray_buf, &out, &list_buf, &occupied_buf].map(|b| b.as_entire_binding());
            let (uniforms, group) = uniform_group(gpu, "Lao", &stage.pipeline, &base, &bound);
            (uniforms, out, readback, [group, volume_group], list_buf)
        })?;
        // Submission `first`'s part of the list, padded to whole groups with NONE.
        let part = |first: u32, count: u32| {
            let start = first as usize * GROUP;
            let mut part = list[start..(start + count as usize * GROUP).min(list.len())].to_vec();
            part.resize(count as usize * GROUP, NONE);
            part
        };
        let pass = Pass {
            label: "Lao::voxels",
            pipeline: &stage.pipeline,
            bind_groups: &[(0, &bound[0]), (VOLUME_GROUP, &bound[1])],
            uniforms: &uniforms,
        };
        chunks.run(
            gpu,
            &pass,
            base,
            false,
            |first, count| {
                let back = read_buffer(device, &readback, pass.label)?;
                let values: &[f32] = bytemuck::cast_slice(&back);
                let start = first as usize * GROUP;
                let end = (start + count as usize * GROUP).min(list.len());
                for (&i, &a) in list[start..end].iter().zip(values) {
                    out_values[i as usize] = a;
                }
                progress((first + count) as usize, groups);
                Ok(())
            },
            |encoder, first, count| {
                // Written before this submission's commands run (queue order), after
                // the previous submission's.
                gpu.queue
                    .write_buffer(&list_buf, 0, bytemuck::cast_slice(&part(first, count)));
                encoder.copy_buffer_to_buffer(
                    &out,
                    0,
                    &readback,
                    0,
                    count as u64 * GROUP as u64 * 4,
                );
            },
        )?;
        Ok(out_values)
    }
}
