//! Contextual Ambient Occlusion (Titov et al.): LAO that stays exact under clipping by
//! recomputing only the voxels whose neighbourhood a clip shape touches.
//!
//! Once per transfer function (§3.4 step I): `V_PAO`, LAO of every voxel on the
//! unclipped opacity volume. Every frame (§3.5):
//!
//! - step IV (`shaders/cao_clip.wgsl`, Algorithm 2): anti-aliased shadow-test clipping
//!   into the clipped opacity volume `V_o` and the mask `V_m` (0 clipped, ½ recompute,
//!   1 copy);
//! - step V (`shaders/cao_lao.wgsl`): `V_AO` = 1, a full LAO ray cast on `V_o`, or a copy
//!   of `V_PAO`, by the mask;
//! - step VI: the ray caster clips with the same test and reads `V_AO`.
//!
//! [`CaoMode::Full`] is the paper's baseline ("LAO every frame"): the same clipping, and
//! a ray cast for every unclipped voxel. `V_PAO` is made by that very pipeline with no
//! clip shapes, so a copied voxel holds the bits a recomputation would produce: CAO and
//! the baseline agree bit for bit (tests/cao.rs).
//!
//! LAO here interpolates the classified opacity `V_o` (the paper's `TF_o`), where
//! `--ao lao` classifies interpolated densities; both use 1 mm steps and Eq. 2–3.

use super::lao::{Rays, STEP_MM, lao_lut};
use crate::clip::ClipShape;
use crate::clip::cpu::ClipMapsCpu;
use crate::clip::gpu::{ClipMaps, ClipUpdate};
use crate::gpu::{
    Gpu, GpuError, bind_group, read_buffer, read_texture_f32, readback_buffer, shaders,
    submit_compute_with, uniform_buffer, validated,
};
use crate::render::cpu::trilinear;
use crate::render::gpu::GpuVolume;
use crate::render::texels::VolumeTexels;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Extra anti-aliasing samples for partly clipped voxels (the paper's N; 41 in all).
pub const DEFAULT_MSAA: u32 = 32;

/// Ray samples per GPU submission in step V (see [`super::lao::SAMPLES_PER_SUBMISSION`]).
const SAMPLES_PER_SUBMISSION: u64 = 1 << 30;

/// Selective recomputation (CAO) or the baseline that ray casts every voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaoMode {
    Selective,
    Full,
}

/// The N extra sample offsets (voxels, within the voxel's cell): a Halton sequence in
/// bases 2, 3, 5, identical on the GPU and the CPU.
pub fn msaa_offsets(n: u32) -> Vec<Vec3> {
    let halton = |mut i: u32, base: u32| {
        let (mut f, mut r) = (1.0f64, 0.0f64);
        while i > 0 {
            f /= base as f64;
            r += f * (i % base) as f64;
            i /= base;
        }
        r as f32
    };
    (1..=n)
        .map(|i| Vec3::new(halton(i, 2), halton(i, 3), halton(i, 5)) - Vec3::splat(0.5))
        .collect()
}

/// How far (mm) a clipped point can change a voxel's ambient factor: the LAO ray
/// reaches (M − 1) mm (the last sample's opacity is never used), trilinear
/// interpolation reads voxels up to one voxel away, and a voxel's opacity depends on
/// clip samples anywhere in its cell (half a voxel): 1.5 voxel diagonals in all.
pub fn reach_mm(samples: u32, spacing: [f32; 3]) -> f32 {
    (samples.max(1) - 1) as f32 * STEP_MM + 1.5 * Vec3::from(spacing).length()
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ClipParams {
    dims: [u32; 4],
    spacing: [f32; 4],
    half: [f32; 4],
    lut_map: [f32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LaoParams {
    dims: [u32; 4],
    mm_to_uvw: [f32; 4],
    counts: [u32; 4],
}

/// Per-frame figures.
#[derive(Debug, Clone, Default)]
pub struct CaoStats {
    pub voxels: u64,
    /// Voxels ray cast this frame (category b; every unclipped voxel in the baseline).
    pub recomputed: u64,
    /// Voxels fully clipped (category a).
    pub clipped: u64,
    /// Seconds: depth/dilation maps (only when a shape's geometry changed), clip + mask
    /// (step IV), ray casting (step V).
    pub maps_seconds: f64,
    pub clip_seconds: f64,
    pub lao_seconds: f64,
    /// Shapes left out, with why.
    pub clip_errors: Vec<String>,
}

impl CaoStats {
    pub fn percent_recomputed(&self) -> f64 {
        100.0 * self.recomputed as f64 / self.voxels.max(1) as f64
    }
}

fn volume_texture(device: &wgpu::Device, label: &str, dims: [u32; 3]) -> wgpu::Texture {
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
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

/// The CAO volumes and pipelines for one uploaded volume.
#[derive(Debug)]
pub struct CaoGpu {
    clip_pipeline: wgpu::ComputePipeline,
    lao_pipeline: wgpu::ComputePipeline,
    sampler: wgpu::Sampler,
    pub clip: ClipMaps,
    v_o: wgpu::Texture,
    v_m: wgpu::Texture,
    v_pao: wgpu::Texture,
    v_ao: wgpu::Texture,
    views: [wgpu::TextureView; 4],
    /// The density volume V (the ray caster's texture).
    volume_view: wgpu::TextureView,
    lut_buffer: wgpu::Buffer,
    msaa_buffer: wgpu::Buffer,
    ray_buffer: wgpu::Buffer,
    counters: wgpu::Buffer,
    counters_readback: wgpu::Buffer,
    clip_params: ClipParams,
    lao_params: LaoParams,
    dims: [u32; 3],
    rays: usize,
    samples: u32,
    msaa: u32,
    /// Seconds spent on `V_PAO`.
    pub precompute_seconds: f64,
}

impl CaoGpu {
    /// Allocates the five CAO volumes (V, V_o, V_m, V_PAO, V_AO; V is `vol`'s) and
    /// precomputes `V_PAO` for `tf`.
    pub fn new(
        gpu: &Gpu,
        vol: &GpuVolume,
        tf: &TransferFunction,
        rays: &Rays,
        samples: u32,
        msaa: u32,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Self, GpuError> {
        let device = &gpu.device;
        if !device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE)
        {
            return Err(GpuError::Validation {
                stage: "CaoGpu::new".into(),
                message: "the adapter cannot filter 32-bit float textures (FLOAT32_FILTERABLE), which CAO's opacity volume needs".into(),
            });
        }
        let texels = &vol.texels;
        let dims = texels.dims.map(|d| d as u32);
        let clip_module = shaders::module(device, "cao_clip.wgsl")?;
        let lao_module = shaders::module(device, "cao_lao.wgsl")?;
        let lut = lao_lut(tf, texels);
        let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
        let offsets: Vec<[f32; 4]> = msaa_offsets(msaa.max(1))
            .iter()
            .map(|o| [o.x, o.y, o.z, 0.0])
            .collect();
        let packed: Vec<[f32; 4]> = rays
            .directions
            .iter()
            .zip(&rays.weights)
            .map(|(d, w)| [d.x, d.y, d.z, *w])
            .collect();
        let clip = ClipMaps::new(gpu)?;
        let extent = texels.extent();
        let (a, b) = texels.lut_map(&lut);
        let clip_params = ClipParams {
            dims: [dims[0], dims[1], dims[2], 0],
            spacing: [
                texels.spacing[0],
                texels.spacing[1],
                texels.spacing[2],
                msaa as f32,
            ],
            half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5, 0.0],
            lut_map: [a, b, (lut.rgba.len().max(2) - 1) as f32, 0.0],
        };
        let lao_params = LaoParams {
            dims: [dims[0], dims[1], dims[2], 0],
            mm_to_uvw: [
                STEP_MM / extent[0],
                STEP_MM / extent[1],
                STEP_MM / extent[2],
                0.0,
            ],
            counts: [rays.directions.len() as u32, samples.max(1), 0, 0],
        };
        let mut cao = validated(device, "CaoGpu::new", || {
            let storage = |label, bytes: &[u8], extra| {
                let b = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes.len().max(16) as u64,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
                    mapped_at_creation: false,
                });
                gpu.queue.write_buffer(&b, 0, bytes);
                b
            };
            let pipeline =
                |label, module| crate::gpu::compute_pipeline(device, label, module, "main", None);
            let v_o = volume_texture(device, "Cao::v_o", dims);
            let v_m = volume_texture(device, "Cao::v_m", dims);
            let v_pao = volume_texture(device, "Cao::v_pao", dims);
            let v_ao = volume_texture(device, "Cao::v_ao", dims);
            let views = [&v_o, &v_m, &v_pao, &v_ao].map(|t| t.create_view(&Default::default()));
            CaoGpu {
                clip_pipeline: pipeline("Cao::clip", &clip_module),
                lao_pipeline: pipeline("Cao::lao", &lao_module),
                sampler: crate::gpu::linear_sampler(device, "Cao::linear_clamp"),
                clip,
                v_o,
                v_m,
                v_pao,
                v_ao,
                views,
                volume_view: vol.volume_view().clone(),
                lut_buffer: storage(
                    "Cao::lut_alpha",
                    bytemuck::cast_slice(&alpha),
                    wgpu::BufferUsages::empty(),
                ),
                msaa_buffer: storage(
                    "Cao::msaa",
                    bytemuck::cast_slice(&offsets),
                    wgpu::BufferUsages::empty(),
                ),
                ray_buffer: storage(
                    "Cao::rays",
                    bytemuck::cast_slice(&packed),
                    wgpu::BufferUsages::empty(),
                ),
                counters: storage("Cao::counters", &[0u8; 16], wgpu::BufferUsages::COPY_SRC),
                counters_readback: readback_buffer(device, "Cao::counters_readback", 16),
                clip_params,
                lao_params,
                dims,
                rays: rays.directions.len(),
                samples: samples.max(1),
                msaa,
                precompute_seconds: 0.0,
            }
        })?;
        let start = Instant::now();
        // V_PAO: the baseline pipeline with nothing clipped, copied aside.
        cao.clip.update(gpu, &[], 1.0, 1.0, 16)?;
        cao.step_iv(gpu)?;
        cao.step_v(gpu, CaoMode::Full, progress)?;
        validated(device, "Cao::v_pao", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_texture_to_texture(
                cao.v_ao.as_image_copy(),
                cao.v_pao.as_image_copy(),
                cao.v_ao.size(),
            );
            gpu.queue.submit([encoder.finish()]);
        })?;
        crate::gpu::wait(device, "Cao::v_pao", crate::gpu::WAIT)?;
        cao.precompute_seconds = start.elapsed().as_secs_f64();
        Ok(cao)
    }

    /// How far a clipped point can reach (mm): the dilation radius before pixel margins.
    pub fn reach_mm(&self, texels: &VolumeTexels) -> f32 {
        reach_mm(self.samples, texels.spacing)
    }

    /// One frame: update the clip maps for `shapes` (moved shapes only change matrices),
    /// clip (step IV) and compute `V_AO` (step V). `reach_mm` is normally
    /// [`Self::reach_mm`]; tests shrink it to show exactness depends on it.
    pub fn update(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        shapes: &[ClipShape],
        resolution: u32,
        reach_mm: f32,
        mode: CaoMode,
    ) -> Result<CaoStats, GpuError> {
        let device = &gpu.device;
        let radius = Vec3::from(texels.extent()).length() * 0.5;
        let t0 = Instant::now();
        let ClipUpdate { errors, .. } = self
            .clip
            .update(gpu, shapes, radius, reach_mm, resolution)?;
        crate::gpu::wait(device, "Cao::maps", crate::gpu::WAIT)?;
        let t1 = Instant::now();
        let (recomputed, clipped) = self.step_iv(gpu)?;
        let t2 = Instant::now();
        self.step_v(gpu, mode, &|_, _| {})?;
        crate::gpu::wait(device, "Cao::lao", crate::gpu::WAIT)?;
        let t3 = Instant::now();
        let voxels = self.dims.iter().map(|&d| d as u64).product::<u64>();
        Ok(CaoStats {
            voxels,
            recomputed: match mode {
                CaoMode::Selective => recomputed,
                CaoMode::Full => voxels - clipped,
            },
            clipped,
            maps_seconds: (t1 - t0).as_secs_f64(),
            clip_seconds: (t2 - t1).as_secs_f64(),
            lao_seconds: (t3 - t2).as_secs_f64(),
            clip_errors: errors.iter().map(|e| e.to_string()).collect(),
        })
    }

    /// Step IV over the whole volume; returns (voxels to recompute, voxels clipped).
    fn step_iv(&self, gpu: &Gpu) -> Result<(u64, u64), GpuError> {
        let device = &gpu.device;
        let [nx, ny, nz] = self.dims;
        // Bound each submission's clip samples (41 per voxel per shape at worst).
        let per_slice = nx as u64
            * ny as u64
            * (9 + self.msaa as u64)
            * self.clip.uniforms.counts[0].max(1) as u64;
        let slab = ((SAMPLES_PER_SUBMISSION / per_slice.max(1)) as u32).clamp(1, nz);
        gpu.queue.write_buffer(&self.counters, 0, &[0u8; 16]);
        let clip_group = self
            .clip
            .bind_group(device, &self.clip_pipeline.get_bind_group_layout(1));
        let mut z0 = 0;
        while z0 < nz {
            let depth = slab.min(nz - z0);
            let mut p = self.clip_params;
            p.dims[3] = z0;
            validated(device, "Cao::step_iv", || {
                let uniforms = uniform_buffer(
                    device,
                    &gpu.queue,
                    "Cao::clip_params",
                    bytemuck::bytes_of(&p),
                );
                let group = bind_group(
                    device,
                    "Cao::clip",
                    &self.clip_pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&self.volume_view),
                        self.lut_buffer.as_entire_binding(),
                        self.msaa_buffer.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&self.views[0]),
                        wgpu::BindingResource::TextureView(&self.views[1]),
                        self.counters.as_entire_binding(),
                    ],
                );
                submit_compute_with(
                    device,
                    &gpu.queue,
                    "Cao::step_iv",
                    &self.clip_pipeline,
                    &[&group, &clip_group],
                    [nx.div_ceil(8), ny.div_ceil(8), depth],
                    |_| {},
                );
            })?;
            z0 += depth;
        }
        validated(device, "Cao::counters", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.counters, 0, &self.counters_readback, 0, 16);
            gpu.queue.submit([encoder.finish()]);
        })?;
        let bytes = read_buffer(device, &self.counters_readback, "Cao::counters")?;
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok((c[0] as u64, c[1] as u64))
    }

    fn step_v(
        &self,
        gpu: &Gpu,
        mode: CaoMode,
        progress: &dyn Fn(usize, usize),
    ) -> Result<(), GpuError> {
        let device = &gpu.device;
        let [nx, ny, nz] = self.dims;
        let per_slice = nx as u64 * ny as u64 * self.rays as u64 * self.samples as u64;
        let slab = ((SAMPLES_PER_SUBMISSION / per_slice.max(1)) as u32).clamp(1, nz);
        let mut z0 = 0;
        while z0 < nz {
            let depth = slab.min(nz - z0);
            let mut p = self.lao_params;
            p.dims[3] = z0;
            p.counts[2] = u32::from(mode == CaoMode::Full);
            validated(device, "Cao::step_v", || {
                let uniforms = uniform_buffer(
                    device,
                    &gpu.queue,
                    "Cao::lao_params",
                    bytemuck::bytes_of(&p),
                );
                let group = bind_group(
                    device,
                    "Cao::lao",
                    &self.lao_pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&self.views[0]),
                        wgpu::BindingResource::Sampler(&self.sampler),
                        self.ray_buffer.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&self.views[1]),
                        wgpu::BindingResource::TextureView(&self.views[2]),
                        wgpu::BindingResource::TextureView(&self.views[3]),
                    ],
                );
                submit_compute_with(
                    device,
                    &gpu.queue,
                    "Cao::step_v",
                    &self.lao_pipeline,
                    &[&group],
                    [nx.div_ceil(8), ny.div_ceil(8), depth],
                    |_| {},
                );
            })?;
            if slab < nz {
                crate::gpu::wait(device, "Cao::step_v", crate::gpu::WAIT)?;
            }
            z0 += depth;
            progress(z0 as usize, nz as usize);
        }
        Ok(())
    }

    /// `V_AO` for the ray caster.
    pub fn ao_view(&self) -> &wgpu::TextureView {
        &self.views[3]
    }

    /// Reads `V_o`, `V_m`, `V_PAO` or `V_AO` (0–3) back, x fastest.
    pub fn read(&self, gpu: &Gpu, which: usize) -> Result<Vec<f32>, GpuError> {
        let t = [&self.v_o, &self.v_m, &self.v_pao, &self.v_ao][which.min(3)];
        read_texture_f32(gpu, t, self.dims, "Cao::read")
    }

    /// GPU memory of the CAO volumes per voxel, in bytes (V_o, V_m, V_PAO, V_AO; the
    /// density volume V is the ray caster's).
    pub fn bytes_per_voxel(&self) -> u32 {
        4 * 4
    }
}

/// Step IV on the CPU: (`V_o`, `V_m`) from the GPU's clip maps, for the twin tests.
pub fn clip_volume_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    maps: &ClipMapsCpu,
    msaa: u32,
) -> (Vec<f32>, Vec<f32>) {
    let [nx, ny, nz] = texels.dims;
    let norm = texels.norm_values();
    let (a, b) = texels.lut_map(lut);
    let top = (lut.rgba.len().max(2) - 1) as f32;
    let spacing = Vec3::from(texels.spacing);
    let half = Vec3::from(texels.extent()) * 0.5;
    let offsets = msaa_offsets(msaa.max(1));
    let opacity = |n: f32| {
        let t = (n * a + b).clamp(0.0, top);
        let i0 = t.floor() as usize;
        let i1 = (i0 + 1).min(top as usize);
        let f = t - t.floor();
        lut.rgba[i0][3] + (lut.rgba[i1][3] - lut.rgba[i0][3]) * f
    };
    let per_voxel: Vec<(f32, f32)> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let v = Vec3::new(
                (i % nx) as f32,
                ((i / nx) % ny) as f32,
                (i / (nx * ny)) as f32,
            );
            let at = |o: Vec3| (v + Vec3::splat(0.5) + o) * spacing - half;
            let (mut visible, mut dilated) = (0u32, 0u32);
            for k in 0..9u32 {
                let o = if k == 0 {
                    Vec3::ZERO
                } else {
                    let c = k - 1;
                    Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32)
                        - Vec3::splat(0.5)
                };
                let (vis, aff) = maps.classify(at(o));
                visible += u32::from(vis);
                dilated += u32::from(aff);
            }
            let mut o = 0.0;
            if visible == 9 {
                o = opacity(norm[i]);
            } else if visible > 0 {
                for off in offsets.iter().take(msaa as usize) {
                    let (vis, aff) = maps.classify(at(*off));
                    visible += u32::from(vis);
                    dilated += u32::from(aff);
                }
                o = visible as f32 / (msaa + 9) as f32 * opacity(norm[i]);
            }
            let m = if dilated == 0 {
                1.0
            } else if visible > 0 {
                0.5
            } else {
                0.0
            };
            (o, m)
        })
        .collect();
    per_voxel.into_iter().unzip()
}

/// Step V on the CPU: `V_AO` from `V_o`, `V_m` and `V_PAO` (twin of `cao_lao.wgsl`).
pub fn lao_on_opacity_cpu(
    texels: &VolumeTexels,
    v_o: &[f32],
    v_m: &[f32],
    v_pao: &[f32],
    rays: &Rays,
    samples: u32,
    mode: CaoMode,
) -> Vec<f32> {
    let dims = texels.dims;
    let [nx, ny, nz] = dims;
    let extent = Vec3::from(texels.extent());
    let scale = Vec3::splat(STEP_MM) / extent;
    let samples = samples.max(1);
    let size = Vec3::new(nx as f32, ny as f32, nz as f32);
    let opacity_at = |uvw: Vec3| {
        if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
            0.0
        } else {
            trilinear(v_o, dims, uvw)
        }
    };
    (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let m = v_m[i];
            if m == 1.0 && mode == CaoMode::Selective {
                return v_pao[i];
            }
            if m <= 0.0 {
                return 1.0;
            }
            let v = Vec3::new(
                (i % nx) as f32,
                ((i / nx) % ny) as f32,
                (i / (nx * ny)) as f32,
            );
            let centre = (v + Vec3::splat(0.5)) / size;
            let mut total = 0.0;
            for (d, w) in rays.directions.iter().zip(&rays.weights) {
                let step = *d * scale;
                let mut transmittance = 1.0;
                let mut sum = 0.0;
                for s in 1..=samples {
                    sum += transmittance;
                    if s < samples {
                        transmittance *= 1.0 - opacity_at(centre + step * s as f32);
                    }
                }
                total += w * sum / samples as f32;
            }
            total / rays.directions.len() as f32
        })
        .collect()
}
