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
use crate::gpu::dispatch::{Grid, Pass, SlabDispatch, SlabOrigin, budget, slab_fields};
use crate::gpu::{
    Gpu, GpuError, compute_pipeline, read_buffer, read_texture_f32, readback_buffer, shaders,
    storage_buffer, uniform_group, validated,
};
use crate::render::gpu::GpuVolume;
use crate::render::texels::VolumeTexels;
use crate::sample::trilinear;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

pub use super::settings::DEFAULT_MSAA;

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

/// Uniforms of step IV. Mirrors `struct Params` in `cao_clip.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ClipParams {
    /// The volume's size and this dispatch's first z-slice.
    slab: SlabOrigin,
    spacing: [f32; 3],
    /// N, the extra anti-aliasing samples.
    msaa: f32,
    /// Half the volume's extent (mm).
    half: [f32; 3],
    _pad0: f32,
    /// LUT index = norm · lut_scale + lut_offset, clamped to lut_last.
    lut_scale: f32,
    lut_offset: f32,
    lut_last: f32,
    _pad1: f32,
}

const _: () = assert!(std::mem::size_of::<ClipParams>() == 64);

slab_fields!(ClipParams, tiles);

/// Uniforms of step V. Mirrors `struct Params` in `cao_lao.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LaoParams {
    /// The volume's size and this dispatch's first z-slice.
    slab: SlabOrigin,
    mm_to_uvw: [f32; 3],
    _pad0: f32,
    rays: u32,
    samples: u32,
    /// 1: ray cast every unclipped voxel (the baseline), 0: only category b.
    full: u32,
    _pad1: u32,
}

const _: () = assert!(std::mem::size_of::<LaoParams>() == 48);

slab_fields!(LaoParams, tiles);

/// Which CAO volume to read back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaoVolume {
    /// `V_o`, the clipped opacity volume.
    ClippedOpacity,
    /// `V_m`, the mask (0 clipped, ½ recompute, 1 copy).
    Mask,
    /// `V_PAO`, LAO of the unclipped volume.
    Precomputed,
    /// `V_AO`, this frame's ambient factor.
    Ambient,
}

/// CAO's pipelines and sampler, built once per device.
#[derive(Debug)]
pub struct CaoPipelines {
    clip: wgpu::ComputePipeline,
    lao: wgpu::ComputePipeline,
    sampler: wgpu::Sampler,
}

impl crate::gpu::Stage for CaoPipelines {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        let [clip_module, lao_module] =
            shaders::modules(device, ["cao_clip.wgsl", "cao_lao.wgsl"])?;
        validated(device, "CaoPipelines::create", || CaoPipelines {
            clip: compute_pipeline(device, "Cao::clip", &clip_module, "main", None),
            lao: compute_pipeline(device, "Cao::lao", &lao_module, "main", None),
            sampler: crate::gpu::linear_sampler(device, "Cao::linear_clamp"),
        })
    }
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
    crate::gpu::texture_3d(
        device,
        label,
        dims,
        wgpu::TextureFormat::R32Float,
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
    )
}

/// The CAO volumes and pipelines for one uploaded volume.
#[derive(Debug)]
pub struct CaoGpu {
    pipelines: std::sync::Arc<CaoPipelines>,
    pub clip: ClipMaps,
    v_o: wgpu::Texture,
    v_m: wgpu::Texture,
    v_pao: wgpu::Texture,
    v_ao: wgpu::Texture,
    views: [wgpu::TextureView; 4],
    counters: wgpu::Buffer,
    counters_readback: wgpu::Buffer,
    /// Uniforms of steps IV and V, rewritten per slab, and the bind groups reading them.
    clip_uniforms: wgpu::Buffer,
    lao_uniforms: wgpu::Buffer,
    clip_group: wgpu::BindGroup,
    lao_group: wgpu::BindGroup,
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
        let pipelines = gpu.stage::<CaoPipelines>()?;
        let lut = lao_lut(tf, texels);
        let alpha = crate::sample::alpha_column(&lut);
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
            slab: SlabOrigin::of(dims),
            spacing: texels.spacing,
            msaa: msaa as f32,
            half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5],
            _pad0: 0.0,
            lut_scale: a,
            lut_offset: b,
            lut_last: (lut.rgba.len().max(2) - 1) as f32,
            _pad1: 0.0,
        };
        let lao_params = LaoParams {
            slab: SlabOrigin::of(dims),
            mm_to_uvw: super::lao::mm_to_uvw(texels),
            _pad0: 0.0,
            rays: rays.directions.len() as u32,
            samples: samples.max(1),
            full: 0,
            _pad1: 0,
        };
        let mut cao = validated(device, "CaoGpu::new", || {
            let storage = |label, bytes: &[u8]| {
                storage_buffer(gpu, label, bytes, wgpu::BufferUsages::empty())
            };
            let v_o = volume_texture(device, "Cao::v_o", dims);
            let v_m = volume_texture(device, "Cao::v_m", dims);
            let v_pao = volume_texture(device, "Cao::v_pao", dims);
            let v_ao = volume_texture(device, "Cao::v_ao", dims);
            let views = [&v_o, &v_m, &v_pao, &v_ao].map(|t| t.create_view(&Default::default()));
            let lut_buffer = storage("Cao::lut_alpha", bytemuck::cast_slice(&alpha));
            let msaa_buffer = storage("Cao::msaa", bytemuck::cast_slice(&offsets));
            let ray_buffer = storage("Cao::rays", bytemuck::cast_slice(&packed));
            let counters = storage_buffer(
                gpu,
                "Cao::counters",
                &[0u8; 16],
                wgpu::BufferUsages::COPY_SRC,
            );
            let volume_view = vol.volume_view();
            let (clip_uniforms, clip_group) = uniform_group(
                gpu,
                "Cao::clip",
                &pipelines.clip,
                &clip_params,
                &[
                    wgpu::BindingResource::TextureView(volume_view),
                    lut_buffer.as_entire_binding(),
                    msaa_buffer.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&views[0]),
                    wgpu::BindingResource::TextureView(&views[1]),
                    counters.as_entire_binding(),
                ],
            );
            let (lao_uniforms, lao_group) = uniform_group(
                gpu,
                "Cao::lao",
                &pipelines.lao,
                &lao_params,
                &[
                    wgpu::BindingResource::TextureView(&views[0]),
                    wgpu::BindingResource::Sampler(&pipelines.sampler),
                    ray_buffer.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&views[1]),
                    wgpu::BindingResource::TextureView(&views[2]),
                    wgpu::BindingResource::TextureView(&views[3]),
                ],
            );
            CaoGpu {
                pipelines,
                clip,
                v_o,
                v_m,
                v_pao,
                v_ao,
                views,
                counters,
                counters_readback: readback_buffer(device, "Cao::counters_readback", 16),
                clip_uniforms,
                lao_uniforms,
                clip_group,
                lao_group,
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
        // Bound each submission's clip samples (41 per voxel per shape at worst).
        let per_voxel = (9 + self.msaa as u64) * self.clip.uniforms.counts[0].max(1) as u64;
        let slabs = SlabDispatch::new(
            self.dims,
            Grid::Tiles,
            per_voxel,
            budget::LAO_SAMPLES,
            u64::MAX,
        );
        gpu.queue.write_buffer(&self.counters, 0, &[0u8; 16]);
        let clip_group = self
            .clip
            .bind_group(device, &self.pipelines.clip.get_bind_group_layout(1));
        let pass = Pass {
            label: "Cao::step_iv",
            pipeline: &self.pipelines.clip,
            bind_groups: &[&self.clip_group, &clip_group],
            uniforms: &self.clip_uniforms,
        };
        slabs.run(gpu, &pass, self.clip_params, false, &|_, _| {})?;
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
        let per_voxel = self.rays as u64 * self.samples as u64;
        let slabs = SlabDispatch::new(
            self.dims,
            Grid::Tiles,
            per_voxel,
            budget::LAO_SAMPLES,
            u64::MAX,
        );
        let mut params = self.lao_params;
        params.full = u32::from(mode == CaoMode::Full);
        let pass = Pass {
            label: "Cao::step_v",
            pipeline: &self.pipelines.lao,
            bind_groups: &[&self.lao_group],
            uniforms: &self.lao_uniforms,
        };
        slabs.run(gpu, &pass, params, true, progress)
    }

    /// `V_AO` for the ray caster.
    pub fn ao_view(&self) -> &wgpu::TextureView {
        &self.views[3]
    }

    /// Reads one of the CAO volumes back, x fastest.
    pub fn read(&self, gpu: &Gpu, which: CaoVolume) -> Result<Vec<f32>, GpuError> {
        let t = match which {
            CaoVolume::ClippedOpacity => &self.v_o,
            CaoVolume::Mask => &self.v_m,
            CaoVolume::Precomputed => &self.v_pao,
            CaoVolume::Ambient => &self.v_ao,
        };
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
