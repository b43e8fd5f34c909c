//! Positional ambient occlusion by ray marching (Papaioannou, Menexi and Papadopoulos
//! 2010, §5.2): Beer's-law obscurance along N_dir rays (Eq. 4–7) averaged over the
//! sphere (Eq. 8). On the GPU (`shaders/vao_common.wgsl`, shared by the precompute
//! kernel `shaders/vao.wgsl` and the ray caster's live mode) and on the CPU (twin:
//! [`PositionalAo`]).
//!
//! Design choices the paper leaves open:
//! - directions: a spherical Fibonacci lattice of N_dir points (20 by default, their
//!   Fig. 7c); each ray k has one constant jitter `j_k = frac(0.5 + k/Φ)` for all its
//!   samples (stratified sampling with constant jitter, their ref. \[30\]), the same at
//!   every point, so the result is deterministic and noise-free and the live and
//!   precomputed modes agree exactly at voxel centres;
//! - V is the transfer function's opacity per voxel length `v_s` (the smallest spacing),
//!   so Eq. 6 converts it to extinction over a stratum of Δ = r_max / N_samples mm;
//! - the mip level read is `⌊log2(Δ / v_s)⌋` (a box-filtered 2×2×2 chain of the texel
//!   values, classified after filtering), so long strata do not skip thin features;
//! - a ray stops at an accepted sample with V ≥ V_thres (the sample itself still counts,
//!   Eq. 7 is kept), or once γ is within 1/256 of 1.

use crate::gpu::dispatch::{Grid, Pass, SlabDispatch, SlabOrigin, budget, slab_fields};
use crate::gpu::{
    Gpu, GpuError, bind_group, f16_texture, output_buffer, readback_buffer, shaders,
    uniform_buffer, validated,
};
use crate::sample::{
    VolumeSampler, bake_lut, f16_map, f16_volume_map, mip_chain, per_voxel, voxel_centre,
};
use crate::texels::VolumeTexels;
use crate::texels::gpu_data::VolumeMap;
use crate::texels::segments::SegmentTexels;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// Coarsest mip level used (1/16 of the resolution).
pub const MAX_MIP_LEVEL: u32 = 4;

pub use super::settings::{
    DEFAULT_DIRECTIONS, DEFAULT_R_MAX_MM, DEFAULT_V_THRES, DEFAULT_VAO_SAMPLES as DEFAULT_SAMPLES,
    GAMMA_STOP, Isosurface, MAX_DIRECTIONS, VaoError, VaoSettings,
};

/// Ray directions (unit, physical space) with their constant jitter in [0, 1) as w.
pub fn rays(directions: u32) -> Vec<[f32; 4]> {
    let inv_phi = (5.0_f64.sqrt() - 1.0) / 2.0;
    crate::ao::rays::RaySet::Fibonacci(directions.max(1) as usize)
        .directions()
        .into_iter()
        .enumerate()
        .map(|(k, d)| [d.x, d.y, d.z, (0.5 + k as f64 * inv_phi).fract() as f32])
        .collect()
}

/// The opacity table: the transfer function's alpha per voxel length `v_s` (the
/// smallest spacing), Eq. 6's V.
pub fn vao_lut(tf: &TransferFunction, texels: &VolumeTexels) -> Lut {
    bake_lut(tf, texels, 1.0)
}

fn min_spacing(texels: &VolumeTexels) -> f32 {
    texels.spacing.iter().copied().fold(f32::INFINITY, f32::min)
}

/// Mip level whose voxel matches a stratum of `stratum_mm`: ⌊log2(Δ / v_s)⌋, within the
/// chain the volume has (every level at least one voxel along its largest axis).
pub fn mip_level(stratum_mm: f32, v_s: f32, dims: [usize; 3]) -> u32 {
    let ratio = stratum_mm / v_s;
    if ratio.is_nan() || ratio < 2.0 {
        return 0;
    }
    let largest = dims.iter().copied().max().unwrap_or(1).max(1);
    let available = usize::BITS - 1 - largest.leading_zeros();
    (ratio.log2().floor() as u32)
        .min(MAX_MIP_LEVEL)
        .min(available)
}

/// Uniforms of the positional-AO function. Mirrors `struct VaoParams` in
/// `shaders/vao_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VaoParams {
    /// 1 / extent (mm) per axis; w = stratum length Δ = r_max / N_samples (mm).
    pub mm_to_uvw: [f32; 4],
    /// How the f16 level's values map to the opacity table.
    pub map: VolumeMap,
    /// N_dir, N_samples, mip level, mode (0 Beer's law, 1 isosurface).
    pub counts: [u32; 4],
    /// V_thres, product below which γ ≥ 1 − 1/256, d_iso and d_tol in texel units.
    pub limits: [f32; 4],
    /// Isosurface guard distance `v_s·√3/2` (mm), Eq. 7's exponent Δ / v_s, unused × 2.
    pub guard: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<VaoParams>() == 96);

/// The uniforms for `texels` with opacity table `lut`.
pub fn params(texels: &VolumeTexels, lut: &Lut, s: &VaoSettings) -> VaoParams {
    let extent = texels.extent();
    let (lo, scale) = f16_map(texels);
    let v_s = min_spacing(texels);
    let samples = s.samples.max(1);
    let stratum = s.r_max_mm / samples as f32;
    let exponent = stratum / v_s;
    let (mode, iso, tol) = match s.isosurface {
        Some(i) => (
            1,
            (((i.value - texels.value_offset) / texels.value_scale - lo) / scale) as f32,
            (i.tolerance / (texels.value_scale * scale).abs()) as f32,
        ),
        None => (0, 0.0, 0.0),
    };
    VaoParams {
        mm_to_uvw: [1.0 / extent[0], 1.0 / extent[1], 1.0 / extent[2], stratum],
        map: f16_volume_map(texels, lut),
        counts: [
            s.directions.max(1),
            samples,
            mip_level(stratum, v_s, texels.dims),
            mode,
        ],
        limits: [s.v_thres, GAMMA_STOP.powf(1.0 / exponent), iso, tol],
        guard: [v_s * 3.0_f32.sqrt() / 2.0, exponent, 0.0, 0.0],
    }
}

/// CPU twin of `vao_common.wgsl`: everything the per-point function reads.
#[derive(Debug, Clone)]
pub struct PositionalAo {
    pub params: VaoParams,
    /// Ray directions with their jitter (w).
    pub rays: Vec<[f32; 4]>,
    /// The level the function samples (texel values as f16, x fastest) and its dims.
    level: Vec<f32>,
    level_dims: [usize; 3],
    /// How the level's values map to the table (`params.map`).
    map: VolumeMap,
    /// The opacity table (opacity per voxel length in alpha, one entry per LUT entry).
    table: Vec<[f32; 4]>,
    /// Clip shapes' maps: clipped space is empty (twin of `vao_clipped`).
    pub clip: Option<crate::clip::cpu::ClipMapsCpu>,
    /// A segmentation's weights on the opacity, as the f16 texture holds them, and
    /// their dims (twin of `vao_weight`).
    weights: Option<(Vec<f32>, [usize; 3])>,
}

impl PositionalAo {
    pub fn new(texels: &VolumeTexels, tf: &TransferFunction, s: &VaoSettings) -> Self {
        let lut = vao_lut(tf, texels);
        let params = params(texels, &lut, s);
        let (bits, level_dims) = mip_chain(texels, params.counts[2])
            .pop()
            .unwrap_or_else(|| (Vec::new(), texels.dims));
        let level = bits
            .iter()
            .map(|&b| half::f16::from_bits(b).to_f32())
            .collect();
        PositionalAo {
            params,
            rays: rays(s.directions),
            level,
            level_dims,
            map: params.map,
            table: lut.rgba,
            clip: None,
            weights: None,
        }
    }

    /// The same reading `segments`' weights on the opacity.
    pub fn with_segments(self, segments: Option<&SegmentTexels>) -> Self {
        let weights = segments.map(|s| {
            let bits = f16_weights(s);
            (
                bits.iter()
                    .map(|&b| half::f16::from_bits(b).to_f32())
                    .collect(),
                s.dims,
            )
        });
        PositionalAo { weights, ..self }
    }

    /// `vao_weight`: the segmentation's weight at `uvw` (1 without one).
    fn weight(&self, uvw: Vec3) -> f32 {
        self.weights
            .as_ref()
            .map_or(1.0, |(w, dims)| crate::sample::trilinear(w, *dims, uvw))
    }

    /// The level read through the opacity table, as [`VolumeSampler`] reads a volume.
    fn volume(&self) -> VolumeSampler<'_> {
        VolumeSampler {
            values: &self.level,
            dims: self.level_dims,
            map: self.map,
            table: &self.table,
            segments: None,
        }
    }

    /// `vao_clipped` of `vao_common.wgsl`.
    fn clipped(&self, uvw: Vec3) -> bool {
        let Some(c) = &self.clip else {
            return false;
        };
        if c.uniforms.counts[0] == 0 {
            return false;
        }
        let m = &self.params.mm_to_uvw;
        !c.classify((uvw - Vec3::splat(0.5)) / Vec3::new(m[0], m[1], m[2]))
            .0
    }

    /// `vao_value`: the texel value at `uvw` from the level.
    fn value(&self, uvw: Vec3) -> f32 {
        self.volume().value_at(uvw)
    }

    /// `vao_opacity`: opacity per voxel length v_s (Eq. 6's V).
    fn opacity(&self, norm: f32) -> f32 {
        self.volume().opacity(norm)
    }

    /// γ(x, ω) of one ray (Eq. 7, or §5.2.1 in isosurface mode); `x` in texture
    /// coordinates, `ray` = direction and jitter.
    pub fn obscurance(&self, x: Vec3, ray: [f32; 4]) -> f32 {
        let p = &self.params;
        let inside = |u: Vec3| u.cmpge(Vec3::ZERO).all() && u.cmple(Vec3::ONE).all();
        let stratum = p.mm_to_uvw[3];
        let step = Vec3::new(ray[0], ray[1], ray[2])
            * Vec3::new(p.mm_to_uvw[0], p.mm_to_uvw[1], p.mm_to_uvw[2])
            * stratum;
        let n = p.counts[1];
        if p.counts[3] == 1 {
            for i in 0..n {
                let s = i as f32 + ray[3];
                let uvw = x + step * s;
                if !inside(uvw) {
                    break;
                }
                if self.clipped(uvw) {
                    continue;
                }
                if s * stratum >= p.guard[0] && (self.value(uvw) - p.limits[2]).abs() < p.limits[3]
                {
                    return 1.0;
                }
            }
            return 0.0;
        }
        let mut prev = if inside(x) && !self.clipped(x) {
            self.opacity(self.value(x)) * self.weight(x)
        } else {
            0.0
        };
        let mut product = 1.0f32;
        for i in 0..n {
            let uvw = x + step * (i as f32 + ray[3]);
            if !inside(uvw) {
                break;
            }
            let v = if self.clipped(uvw) {
                0.0
            } else {
                self.opacity(self.value(uvw)) * self.weight(uvw)
            };
            let accepted = v >= prev;
            prev = v;
            if accepted {
                product *= 1.0 - v;
                if v >= p.limits[0] || product <= p.limits[1] {
                    break;
                }
            }
        }
        if product <= 0.0 {
            return 1.0;
        }
        1.0 - product.powf(p.guard[1])
    }

    /// A_P(x) of Eq. 8 at `x` (texture coordinates).
    pub fn positional_ao(&self, x: Vec3) -> f32 {
        let total: f32 = self.rays.iter().map(|&r| self.obscurance(x, r)).sum();
        total / self.rays.len().max(1) as f32
    }
}

/// The precomputed ambient factor `1 − A_P` at every voxel centre, on the CPU (rayon),
/// x fastest. `progress(done, total)` counts z-slices.
pub fn vao_cpu(
    pao: &PositionalAo,
    dims: [usize; 3],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    per_voxel(dims, progress, |v| {
        1.0 - pao.positional_ao(voxel_centre(v, dims))
    })
}

/// A segmentation's weights (the look's alpha) as f16 bits, x fastest.
fn f16_weights(s: &SegmentTexels) -> Vec<u16> {
    s.look
        .iter()
        .map(|l| half::f16::from_f32(l[3] as f32 / 255.0).to_bits())
        .collect()
}

/// An R16Float volume of `dims` holding `bits`.
fn weight_texture(gpu: &Gpu, dims: [u32; 3], bits: &[u16]) -> wgpu::TextureView {
    crate::gpu::filled_texture_3d(
        &gpu.device,
        &gpu.queue,
        "Vao::segment_weight",
        dims,
        wgpu::TextureFormat::R16Float,
        bytemuck::cast_slice(bits),
    )
    .create_view(&Default::default())
}

/// Layout entries of bind group 1 (`vao_common.wgsl`), bindings 0–4, for compute.
pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    use crate::gpu::entry;
    let c = wgpu::ShaderStages::COMPUTE;
    vec![
        entry::uniform(0, c),
        entry::texture(1, c, wgpu::TextureViewDimension::D3, Some(true)),
        entry::sampler(2, c),
        entry::storage(3, c, true),
        entry::storage(4, c, true),
    ]
}

/// The GPU side of the per-point function's inputs (bind group 1, bindings 0–4):
/// uniforms, the f16 mip chain, opacity table, rays.
#[derive(Debug)]
pub struct VaoInputs {
    pub params: VaoParams,
    uniforms: wgpu::Buffer,
    levels: wgpu::TextureView,
    alpha: wgpu::Buffer,
    rays: wgpu::Buffer,
    sampler: wgpu::Sampler,
    /// A segmentation's weights as f16 (binding 9), and whether one is read
    /// ([`Self::with_segments`]); a texel of 1 otherwise.
    segment_weight: wgpu::TextureView,
    segments: bool,
}

impl VaoInputs {
    /// Uploads what the function needs for `texels`.
    pub fn new(
        gpu: &Gpu,
        texels: &VolumeTexels,
        tf: &TransferFunction,
        s: &VaoSettings,
    ) -> Result<Self, GpuError> {
        s.validate().map_err(|e| GpuError::Validation {
            stage: "Vao::inputs".into(),
            message: e.to_string(),
        })?;
        let device = &gpu.device;
        let lut = vao_lut(tf, texels);
        let params = params(texels, &lut, s);
        let level = params.counts[2];
        let chain = mip_chain(texels, level);
        let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
        let rays = rays(s.directions);
        validated(device, "Vao::inputs", || {
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
            let texture = f16_texture(device, &gpu.queue, "Vao::levels", &chain);
            VaoInputs {
                params,
                uniforms: uniform_buffer(
                    device,
                    &gpu.queue,
                    "Vao::params",
                    bytemuck::bytes_of(&params),
                ),
                levels: texture.create_view(&Default::default()),
                alpha: storage("Vao::alpha", bytemuck::cast_slice(&alpha)),
                rays: storage("Vao::rays", bytemuck::cast_slice(&rays)),
                sampler: crate::gpu::linear_sampler(device, "Vao::linear_clamp"),
                segment_weight: weight_texture(gpu, [1, 1, 1], &[half::f16::ONE.to_bits()]),
                segments: false,
            }
        })
    }

    /// The same reading `segments`' weights on the opacity (uploaded as f16).
    pub fn with_segments(self, gpu: &Gpu, segments: Option<&SegmentTexels>) -> Self {
        let Some(s) = segments else {
            return self;
        };
        let dims = s.dims.map(|d| d as u32);
        VaoInputs {
            segment_weight: weight_texture(gpu, dims, &f16_weights(s)),
            segments: true,
            ..self
        }
    }

    /// The segmentation's weights it reads (binding 9).
    pub fn segment_weight(&self) -> &wgpu::TextureView {
        &self.segment_weight
    }

    /// Re-bakes the opacity table for a new transfer function (the live mode follows TF
    /// edits at once: nothing else depends on the TF).
    pub fn set_transfer_function(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        tf: &TransferFunction,
    ) {
        let lut = vao_lut(tf, texels);
        let alpha: Vec<f32> = lut.rgba.iter().map(|e| e[3]).collect();
        self.params.map = f16_volume_map(texels, &lut);
        gpu.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&self.params));
        if (alpha.len() * 4) as u64 == self.alpha.size() {
            gpu.queue
                .write_buffer(&self.alpha, 0, bytemuck::cast_slice(&alpha));
        } else {
            self.alpha = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Vao::alpha"),
                size: (alpha.len() * 4).max(16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            gpu.queue
                .write_buffer(&self.alpha, 0, bytemuck::cast_slice(&alpha));
        }
    }

    /// Bindings 0–4 of group 1.
    pub fn resources(&self) -> Vec<wgpu::BindingResource<'_>> {
        vec![
            self.uniforms.as_entire_binding(),
            wgpu::BindingResource::TextureView(&self.levels),
            wgpu::BindingResource::Sampler(&self.sampler),
            self.alpha.as_entire_binding(),
            self.rays.as_entire_binding(),
        ]
    }
}

/// Long-lived state of the precompute kernel (`vao.wgsl`).
#[derive(Debug)]
pub struct VaoGpu {
    pipeline: wgpu::ComputePipeline,
    /// The same reading a segmentation (`SEGMENTS`), built on first use.
    segmented: std::sync::OnceLock<wgpu::ComputePipeline>,
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    slab_layout: wgpu::BindGroupLayout,
    vao_layout: wgpu::BindGroupLayout,
    no_clip: wgpu::BindGroup,
}

/// Uniforms of `vao.wgsl`. Mirrors `struct Slab` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct VaoSlab {
    /// The volume's size and this dispatch's first z-slice.
    slab: SlabOrigin,
    /// Voxels in this dispatch and invocations per row of workgroups.
    voxels: u32,
    row_stride: u32,
    _pad: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<VaoSlab>() == 32);

slab_fields!(VaoSlab, linear);

impl crate::gpu::Stage for VaoGpu {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "vao.wgsl")?;
        validated(device, "Vao::new", || {
            let c = wgpu::ShaderStages::COMPUTE;
            let slab_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Vao::slab_layout"),
                entries: &[
                    crate::gpu::entry::uniform(0, c),
                    crate::gpu::entry::storage(1, c, false),
                ],
            });
            let mut entries = layout_entries();
            entries.push(crate::gpu::entry::texture(
                9,
                c,
                wgpu::TextureViewDimension::D3,
                Some(true),
            ));
            let vao_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Vao::inputs_layout"),
                entries: &entries,
            });
            let clip_layout = crate::clip::gpu::bind_group_layout(device);
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("Vao::pipeline_layout"),
                // Group 1: clip shapes (none here: the precomputed volume is unclipped).
                bind_group_layouts: &[Some(&slab_layout), Some(&clip_layout), Some(&vao_layout)],
                immediate_size: 0,
            });
            VaoGpu {
                pipeline: crate::gpu::compute_pipeline(
                    device,
                    "Vao::pipeline",
                    &module,
                    "main",
                    Some(&pipeline_layout),
                ),
                no_clip: crate::clip::gpu::empty_bind_group(device, &clip_layout),
                segmented: std::sync::OnceLock::new(),
                module: module.clone(),
                pipeline_layout: pipeline_layout.clone(),
                slab_layout,
                vao_layout,
            }
        })
    }
}

impl VaoGpu {
    /// The ambient factor `1 − A_P` at every voxel centre of a volume of `dims`, in
    /// z-slabs, read back. `progress(done, total)` counts z-slices.
    pub fn compute(
        &self,
        gpu: &Gpu,
        dims: [usize; 3],
        inputs: &VaoInputs,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let device = &gpu.device;
        let dims = dims.map(|d| d as u32);
        let per_voxel = inputs.params.counts[0] as u64 * (inputs.params.counts[1] as u64 + 1);
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slabs = SlabDispatch::new(
            dims,
            Grid::Linear,
            per_voxel,
            budget::COSTLY_SAMPLES,
            max_storage,
        );
        let size = slabs.max_slab_voxels() * 4;
        let base = VaoSlab {
            slab: SlabOrigin::of(dims),
            voxels: 0,
            row_stride: 0,
            _pad: [0; 2],
        };
        let (uniforms, out, readback, group0, group2) = validated(device, "Vao::buffers", || {
            let out = output_buffer(device, "Vao::ambient", size);
            let readback = readback_buffer(device, "Vao::readback", size);
            let uniforms =
                uniform_buffer(device, &gpu.queue, "Vao::slab", bytemuck::bytes_of(&base));
            let group0 = bind_group(
                device,
                "Vao::slab",
                &self.slab_layout,
                &[uniforms.as_entire_binding(), out.as_entire_binding()],
            );
            let mut resources: Vec<wgpu::BindGroupEntry<'_>> = inputs
                .resources()
                .into_iter()
                .zip(0..)
                .map(|(resource, binding)| wgpu::BindGroupEntry { binding, resource })
                .collect();
            resources.push(wgpu::BindGroupEntry {
                binding: 9,
                resource: wgpu::BindingResource::TextureView(inputs.segment_weight()),
            });
            let group2 = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("Vao::inputs"),
                layout: &self.vao_layout,
                entries: &resources,
            });
            (uniforms, out, readback, group0, group2)
        })?;
        let pipeline = match inputs.segments {
            false => &self.pipeline,
            true => self.segmented.get_or_init(|| {
                crate::gpu::specialised_pipeline(
                    device,
                    "Vao::pipeline_segments",
                    &self.module,
                    Some(&self.pipeline_layout),
                    &[("SEGMENTS", 1.0)],
                    "main",
                )
            }),
        };
        let pass = Pass {
            label: "Vao::slab",
            pipeline,
            bind_groups: &[(0, &group0), (1, &self.no_clip), (2, &group2)],
            uniforms: &uniforms,
        };
        slabs.run_readback(gpu, &pass, base, &out, &readback, progress)
    }
}
