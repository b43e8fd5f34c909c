//! Positional ambient occlusion by ray marching (Papaioannou, Menexi and Papadopoulos
//! 2010, §5.2): Beer's-law obscurance along N_dir rays (Eq. 4–7) averaged over the
//! sphere (Eq. 8). On the GPU (`shaders/vao_common.wgsl`, shared by the precompute
//! kernel `shaders/vao.wgsl` and the ray caster's live mode) and on the CPU (twin:
//! [`PositionalAo`]).
//!
//! Design choices the paper leaves open:
//! - directions: a spherical Fibonacci lattice of N_dir points (20 by default, their
//!   Fig. 7c); each ray k has one constant jitter `j_k = frac(0.5 + k/Φ)` for all its
//!   samples (stratified sampling with constant jitter, their ref. [30]), the same at
//!   every point, so the result is deterministic and noise-free and the live and
//!   precomputed modes agree exactly at voxel centres;
//! - V is the transfer function's opacity per voxel length `v_s` (the smallest spacing),
//!   so Eq. 6 converts it to extinction over a stratum of Δ = r_max / N_samples mm;
//! - the mip level read is `⌊log2(Δ / v_s)⌋` (a box-filtered 2×2×2 chain of the texel
//!   values, classified after filtering), so long strata do not skip thin features;
//! - a ray stops at an accepted sample with V ≥ V_thres (the sample itself still counts,
//!   Eq. 7 is kept), or once γ is within 1/256 of 1.

use crate::gpu::{
    Gpu, GpuError, bind_group, read_buffer, readback_buffer, shaders, uniform_buffer, validated,
};
use crate::render::cpu::trilinear;
use crate::render::gpu::bake_lut;
use crate::render::texels::VolumeTexels;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;
use rayon::prelude::*;

/// Rays per point by default (the paper's Fig. 7c uses 20).
pub const DEFAULT_DIRECTIONS: u32 = 20;
/// Samples per ray by default (the paper uses 8–12, 8 for its figures).
pub const DEFAULT_SAMPLES: u32 = 8;
/// Ray length by default: the same 20 mm radius as LAO's 20 samples 1 mm apart.
pub const DEFAULT_R_MAX_MM: f32 = 20.0;
/// Opacity at which a ray stops by default.
pub const DEFAULT_V_THRES: f32 = 0.95;
/// A ray whose obscurance γ is within this of 1 stops (nothing further can matter).
pub const GAMMA_STOP: f32 = 1.0 / 256.0;
/// Coarsest mip level used (1/16 of the resolution).
pub const MAX_MIP_LEVEL: u32 = 4;
/// Most directions accepted (the live mode runs all of them at every ray-cast sample).
pub const MAX_DIRECTIONS: u32 = 4096;

/// The isosurface variant (§5.2.1): a ray is fully occluded when a sample beyond the
/// guard distance `v_s·√3/2` lies within `tolerance` of `value` (data units).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Isosurface {
    pub value: f64,
    pub tolerance: f64,
}

/// Parameters of positional AO, as saved in scene files (`ambient_occlusion.vao`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VaoSettings {
    /// N_dir: rays over the whole sphere (Fibonacci lattice).
    pub directions: u32,
    /// N_samples: stratified samples per ray.
    pub samples: u32,
    /// r_max: ray length in mm.
    pub r_max_mm: f32,
    /// V_thres: an accepted sample this opaque stops the ray.
    pub v_thres: f32,
    /// Use the isosurface variant instead of Beer's law.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub isosurface: Option<Isosurface>,
}

impl Default for VaoSettings {
    fn default() -> Self {
        VaoSettings {
            directions: DEFAULT_DIRECTIONS,
            samples: DEFAULT_SAMPLES,
            r_max_mm: DEFAULT_R_MAX_MM,
            v_thres: DEFAULT_V_THRES,
            isosurface: None,
        }
    }
}

/// Why positional-AO settings were refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum VaoError {
    #[error("positional AO: {what} is {value}; {need}")]
    Setting {
        what: &'static str,
        value: String,
        need: &'static str,
    },
}

impl VaoSettings {
    /// Checks every field, naming the first bad one.
    pub fn validate(&self) -> Result<(), VaoError> {
        let bad = |what, value: String, need| Err(VaoError::Setting { what, value, need });
        if self.directions == 0 || self.directions > MAX_DIRECTIONS {
            return bad(
                "the number of directions",
                self.directions.to_string(),
                "use 1 to 4096",
            );
        }
        if self.samples == 0 || self.samples > 1024 {
            return bad(
                "the number of samples per ray",
                self.samples.to_string(),
                "use 1 to 1024",
            );
        }
        if !(self.r_max_mm.is_finite() && self.r_max_mm > 0.0) {
            return bad(
                "r_max",
                self.r_max_mm.to_string(),
                "it must be a positive length in mm",
            );
        }
        if !(self.v_thres > 0.0 && self.v_thres <= 1.0) {
            return bad("V_thres", self.v_thres.to_string(), "it must be in (0, 1]");
        }
        if let Some(iso) = self.isosurface
            && !(iso.value.is_finite() && iso.tolerance.is_finite() && iso.tolerance > 0.0)
        {
            return bad(
                "the isosurface",
                format!("{} ± {}", iso.value, iso.tolerance),
                "value and a positive tolerance must be finite numbers",
            );
        }
        Ok(())
    }
}

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

/// The map from texel values to the f16 copy: `stored = (norm − lo) / scale`. Unorm
/// texels are already in [0, 1] (identity); float texels hold physical values, which
/// may exceed f16's range (65504), so they are normalised by their own range.
pub fn f16_map(texels: &VolumeTexels) -> (f64, f64) {
    match texels.format {
        crate::render::texels::TexelFormat::R32Float => {
            let (lo, hi) = texels.norm_range();
            let (lo, hi) = (lo as f64, hi as f64);
            if lo.is_finite() && hi > lo {
                (lo, hi - lo)
            } else {
                (if lo.is_finite() { lo } else { 0.0 }, 1.0)
            }
        }
        _ => (0.0, 1.0),
    }
}

/// The LUT map `t = stored · a + b` for values of the f16 copy (see [`f16_map`]).
pub fn f16_lut_map(texels: &VolumeTexels, lut: &Lut) -> (f32, f32) {
    let (a, b) = texels.lut_map(lut);
    let (lo, scale) = f16_map(texels);
    ((a as f64 * scale) as f32, (b as f64 + a as f64 * lo) as f32)
}

/// Rounds to the nearest f16 (what an R16Float texel holds).
fn to_f16(x: f32) -> u16 {
    half::f16::from_f32(x).to_bits()
}

/// Mip levels 0..=`levels` of the texel values as R16Float bits: level 0 the texels
/// mapped by [`f16_map`] and rounded to f16, each next one a 2×2×2 box filter of the one before (sizes halved
/// and rounded down, as a GPU's mip chain is), each with its dims.
///
/// f16 rather than the volume's own texture: lavapipe filters 8-bit unorm textures in
/// fixed point, which flips Eq. 4's comparisons of equal neighbours between GPU and CPU;
/// float texels filter identically on both. 11 significant bits are plenty for AO.
pub fn mip_chain(texels: &VolumeTexels, levels: u32) -> Vec<(Vec<u16>, [usize; 3])> {
    let (lo, scale) = f16_map(texels);
    let level0: Vec<u16> = (0..texels.dims.iter().product::<usize>())
        .into_par_iter()
        .map(|i| to_f16(((texels.norm_at(i) as f64 - lo) / scale) as f32))
        .collect();
    let mut chain = vec![(level0, texels.dims)];
    for _ in 0..levels {
        let Some((prev, prev_dims)) = chain.last() else {
            break;
        };
        let prev_dims = *prev_dims;
        let dims = prev_dims.map(|d| (d / 2).max(1));
        let values: Vec<u16> = (0..dims[0] * dims[1] * dims[2])
            .into_par_iter()
            .map(|i| {
                let v = [
                    i % dims[0],
                    (i / dims[0]) % dims[1],
                    i / (dims[0] * dims[1]),
                ];
                let mut sum = 0.0f32;
                for dz in 0..2 {
                    for dy in 0..2 {
                        for dx in 0..2 {
                            let c: [usize; 3] = std::array::from_fn(|a| {
                                (2 * v[a] + [dx, dy, dz][a]).min(prev_dims[a] - 1)
                            });
                            let bits = prev[c[0] + prev_dims[0] * (c[1] + prev_dims[1] * c[2])];
                            sum += half::f16::from_bits(bits).to_f32();
                        }
                    }
                }
                to_f16(sum / 8.0)
            })
            .collect();
        chain.push((values, dims));
    }
    chain
}

/// An R16Float 3-D texture holding `chain` as its mip levels (from [`mip_chain`]).
pub fn f16_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    chain: &[(Vec<u16>, [usize; 3])],
) -> wgpu::Texture {
    let first = chain[0].1.map(|d| d as u32);
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: first[0],
            height: first[1],
            depth_or_array_layers: first[2],
        },
        mip_level_count: chain.len() as u32,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: wgpu::TextureFormat::R16Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (l, (values, dims)) in chain.iter().enumerate() {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: l as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(values),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(dims[0] as u32 * 2),
                rows_per_image: Some(dims[1] as u32),
            },
            wgpu::Extent3d {
                width: dims[0] as u32,
                height: dims[1] as u32,
                depth_or_array_layers: dims[2] as u32,
            },
        );
    }
    texture
}

/// Uniforms of the positional-AO function. Mirrors `struct VaoParams` in
/// `shaders/vao_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VaoParams {
    /// 1 / extent (mm) per axis; w = stratum length Δ = r_max / N_samples (mm).
    pub mm_to_uvw: [f32; 4],
    /// LUT map a, b, entries − 1; w = Eq. 7's exponent Δ / v_s.
    pub lut_map: [f32; 4],
    /// N_dir, N_samples, mip level, mode (0 Beer's law, 1 isosurface).
    pub counts: [u32; 4],
    /// V_thres, product below which γ ≥ 1 − 1/256, d_iso and d_tol in texel units.
    pub limits: [f32; 4],
    /// Isosurface guard distance `v_s·√3/2` (mm), unused × 3.
    pub guard: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<VaoParams>() == 80);

/// The uniforms for `texels` with opacity table `lut`.
pub fn params(texels: &VolumeTexels, lut: &Lut, s: &VaoSettings) -> VaoParams {
    let extent = texels.extent();
    let (a, b) = f16_lut_map(texels, lut);
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
        lut_map: [a, b, (lut.rgba.len().max(2) - 1) as f32, exponent],
        counts: [
            s.directions.max(1),
            samples,
            mip_level(stratum, v_s, texels.dims),
            mode,
        ],
        limits: [s.v_thres, GAMMA_STOP.powf(1.0 / exponent), iso, tol],
        guard: [v_s * 3.0_f32.sqrt() / 2.0, 0.0, 0.0, 0.0],
    }
}

/// CPU twin of `vao_common.wgsl`: everything the per-point function reads.
#[derive(Debug, Clone)]
pub struct PositionalAo {
    pub params: VaoParams,
    /// Opacity per voxel length, one per LUT entry.
    pub alpha: Vec<f32>,
    /// Ray directions with their jitter (w).
    pub rays: Vec<[f32; 4]>,
    /// The level the function samples (texel values as f16, x fastest) and its dims.
    level: Vec<f32>,
    level_dims: [usize; 3],
    /// Clip shapes' maps: clipped space is empty (twin of `vao_clipped`).
    pub clip: Option<crate::clip::cpu::ClipMapsCpu>,
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
            alpha: lut.rgba.iter().map(|e| e[3]).collect(),
            rays: rays(s.directions),
            level,
            level_dims,
            clip: None,
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

    fn value(&self, uvw: Vec3) -> f32 {
        trilinear(&self.level, self.level_dims, uvw)
    }

    fn opacity(&self, norm: f32) -> f32 {
        let p = &self.params;
        let t = (norm * p.lut_map[0] + p.lut_map[1]).clamp(0.0, p.lut_map[2]);
        let i0 = t.floor() as usize;
        let i1 = (i0 + 1).min(p.lut_map[2] as usize);
        let f = t - t.floor();
        self.alpha[i0] + (self.alpha[i1] - self.alpha[i0]) * f
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
            self.opacity(self.value(x))
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
                self.opacity(self.value(uvw))
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
        1.0 - product.powf(p.lut_map[3])
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
    let [nx, ny, nz] = dims;
    let size = Vec3::new(nx as f32, ny as f32, nz as f32);
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..nz)
        .into_par_iter()
        .flat_map_iter(|z| {
            let slice: Vec<f32> = (0..nx * ny)
                .map(|i| {
                    let v = Vec3::new((i % nx) as f32, (i / nx) as f32, z as f32);
                    1.0 - pao.positional_ao((v + Vec3::splat(0.5)) / size)
                })
                .collect();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                nz,
            );
            slice
        })
        .collect()
}

/// Layout entries of bind group 1 (`vao_common.wgsl`), bindings 0–4, for compute.
pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    };
    let tex = wgpu::BindingType::Texture {
        sample_type: wgpu::TextureSampleType::Float { filterable: true },
        view_dimension: wgpu::TextureViewDimension::D3,
        multisampled: false,
    };
    let storage = wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Storage { read_only: true },
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    vec![
        entry(
            0,
            wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
        ),
        entry(1, tex),
        entry(
            2,
            wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        ),
        entry(3, storage),
        entry(4, storage),
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
            }
        })
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
        let (a, b) = f16_lut_map(texels, &lut);
        self.params.lut_map[0] = a;
        self.params.lut_map[1] = b;
        self.params.lut_map[2] = (lut.rgba.len().max(2) - 1) as f32;
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

/// Samples per submission: keeps every dispatch short. Lower than LAO's 2^30 because a
/// sample here costs more (branches, f16 fetch): at 2^30 one slab of the full Engine
/// outran the 60 s readback bound on a busy 2-core lavapipe.
pub const SAMPLES_PER_SUBMISSION: u64 = 1 << 27;

/// Long-lived state of the precompute kernel (`vao.wgsl`).
#[derive(Debug)]
pub struct VaoGpu {
    pipeline: wgpu::ComputePipeline,
    slab_layout: wgpu::BindGroupLayout,
    vao_layout: wgpu::BindGroupLayout,
    no_clip: wgpu::BindGroup,
}

/// Uniforms of `vao.wgsl`. Mirrors `struct Slab` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct SlabParams {
    dims: [u32; 4],
    work: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<SlabParams>() == 32);

impl VaoGpu {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "vao.wgsl")?;
        validated(device, "Vao::new", || {
            let slab_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Vao::slab_layout"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Storage { read_only: false },
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                ],
            });
            let vao_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Vao::inputs_layout"),
                entries: &layout_entries(),
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
                slab_layout,
                vao_layout,
            }
        })
    }

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
        let [nx, ny, nz] = dims;
        let slice = nx * ny;
        let per_voxel = inputs.params.counts[0] as u64 * (inputs.params.counts[1] as u64 + 1);
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slab = ((SAMPLES_PER_SUBMISSION / per_voxel.max(1)).min(max_storage) / slice as u64)
            .clamp(1, nz as u64) as usize;
        let size = (slab * slice * 4) as u64;
        let (out, readback, group1) = validated(device, "Vao::buffers", || {
            let out = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Vao::ambient"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let readback = readback_buffer(device, "Vao::readback", size);
            let group1 = bind_group(device, "Vao::inputs", &self.vao_layout, &inputs.resources());
            (out, readback, group1)
        })?;
        let mut result = Vec::with_capacity(nx * ny * nz);
        let mut z0 = 0;
        while z0 < nz {
            let depth = slab.min(nz - z0);
            let count = (depth * slice) as u32;
            let groups = count.div_ceil(64);
            let gx = groups.min(65535);
            let gy = groups.div_ceil(gx);
            let p = SlabParams {
                dims: [nx as u32, ny as u32, nz as u32, z0 as u32],
                work: [count, gx * 64, 0, 0],
            };
            validated(device, "Vao::slab", || {
                let uniforms =
                    uniform_buffer(device, &gpu.queue, "Vao::slab", bytemuck::bytes_of(&p));
                let group0 = bind_group(
                    device,
                    "Vao::slab",
                    &self.slab_layout,
                    &[uniforms.as_entire_binding(), out.as_entire_binding()],
                );
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("Vao::slab"),
                });
                {
                    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("Vao::slab"),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&self.pipeline);
                    pass.set_bind_group(0, &group0, &[]);
                    pass.set_bind_group(1, &self.no_clip, &[]);
                    pass.set_bind_group(2, &group1, &[]);
                    pass.dispatch_workgroups(gx, gy, 1);
                }
                encoder.copy_buffer_to_buffer(&out, 0, &readback, 0, count as u64 * 4);
                gpu.queue.submit([encoder.finish()]);
            })?;
            let bytes = read_buffer(device, &readback, "Vao::readback")?;
            result.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
                &bytes[..count as usize * 4],
            ));
            z0 += depth;
            progress(z0, nz);
        }
        Ok(result)
    }
}

/// The precomputed ambient factor `1 − A_P` of `volume` in its own geometry, as
/// [`crate::ao::compute_volume`] returns it: on the GPU `gpu` names when the volume fits
/// at full resolution, else the CPU twin.
pub fn compute_volume(
    volume: &crate::volume::Volume,
    tf: &TransferFunction,
    s: &VaoSettings,
    gpu: &crate::gpu::GpuUse,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(crate::volume::Volume, String), GpuError> {
    use crate::render::texels::UploadLimits;
    s.validate().map_err(|e| GpuError::Validation {
        stage: "positional AO settings".into(),
        message: e.to_string(),
    })?;
    let mut computed = None;
    if let Some(device) = gpu.device() {
        match device {
            Ok(g) => {
                let limits = g.device.limits();
                let texels = VolumeTexels::new(
                    volume,
                    UploadLimits {
                        max_dim: limits.max_texture_dimension_3d as usize,
                        max_bytes: crate::render::gpu::MAX_VOLUME_BYTES,
                    },
                );
                if texels.downsampled == 0 {
                    let inputs = VaoInputs::new(&g, &texels, tf, s)?;
                    let a = VaoGpu::new(&g.device)?.compute(&g, texels.dims, &inputs, progress)?;
                    computed = Some((a, g.describe()));
                } else {
                    eprintln!(
                        "warning: the volume does not fit the adapter at full resolution; computing AO on the CPU"
                    );
                }
            }
            Err(e) => eprintln!("warning: {e}\nwarning: computing AO on the CPU instead (slow)"),
        }
    }
    let (values, device) = match computed {
        Some(c) => c,
        None => {
            let texels = VolumeTexels::new(
                volume,
                UploadLimits {
                    max_dim: usize::MAX,
                    max_bytes: u64::MAX,
                },
            );
            let pao = PositionalAo::new(&texels, tf, s);
            (
                vao_cpu(&pao, texels.dims, progress),
                format!("CPU twin ({} threads)", rayon::current_num_threads()),
            )
        }
    };
    let iso = match s.isosurface {
        Some(i) => format!(", isosurface {} ± {}", i.value, i.tolerance),
        None => String::new(),
    };
    let out = crate::volume::Volume {
        dims: volume.dims,
        spacing: volume.spacing,
        data: crate::volume::VoxelData::F32(values),
        scaling: crate::volume::Scaling::IDENTITY,
        orientation: volume.orientation,
        descriptions: vec![(
            "description".into(),
            format!(
                "positional AO ambient factor 1 - A_P, {} directions x {} samples, r_max {} mm{iso}, TF {}",
                s.directions, s.samples, s.r_max_mm, tf.name
            ),
        )],
    };
    Ok((out, device))
}
