//! Volumetric shadows from a directional light: the light volume `T(x)` (transmittance
//! from each voxel centre towards the light) on the GPU (`shaders/light.wgsl`) and on the
//! CPU (twin: [`light_cpu`]), and the anti-aliased shadow factor the ray caster reads.
//!
//! No self-shadowing, no speckle: light rays start [`LIGHT_START_STEPS`] out of the
//! voxel (the same for every voxel: a per-voxel jittered start put a speckle into the
//! light itself); the light volume is low-pass filtered ([`filter_light`]) before the ray
//! caster samples it; the lookup is moved from the sample towards the light by a guard
//! limit (Papaioannou et al. §5.1, [`GUARD_VOXELS`]); and the shadow at a view-ray sample
//! `s_i` is `¼ T(s_i − Δs/2) + ½ T(s_i) + ¼ T(s_i + Δs/2)` (Imagire et al. 2007, Eq. 3–4,
//! the half-step positions between neighbouring samples on the valid sampling path).

use crate::gpu::dispatch::{Grid, Pass, SlabDispatch, SlabOrigin, budget, slab_fields};
use crate::gpu::{Gpu, GpuError, output_buffer, readback_buffer, uniform_group, validated};
use crate::sample::bake_lut;
use crate::sample::{
    SegmentSampler, VolumeSampler, f16_volume_map, per_voxel, trilinear, voxel_centre,
};
use crate::texels::VolumeTexels;
use crate::texels::reader::{self, Reading, SegmentBindings, VOLUME_GROUP};
use crate::texels::segments::{GpuSegments, SegmentTexels};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// Distance between samples along a light ray, in voxels of the smallest spacing.
pub const LIGHT_STEP_VOXELS: f32 = 1.0;

/// Where a light ray's first sample lies, in steps from the voxel centre; the next ones
/// follow one step apart. One and a half: the voxel's own opacity (its trilinear
/// footprint reaches one voxel) does not dim the light that reaches it.
pub const LIGHT_START_STEPS: f32 = 1.5;

/// A light ray stops once its transmittance falls below this.
pub const T_STOP: f32 = 1e-4;

pub use super::DEFAULT_LIGHT;

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
    /// The volume's size and this dispatch's first z-slice.
    pub slab: SlabOrigin,
    /// Voxels in this dispatch and invocations per row of workgroups.
    pub voxels: u32,
    pub row_stride: u32,
    /// Most steps a light ray takes (the volume's diagonal, plus two).
    pub max_steps: u32,
    pub _pad0: u32,
    /// One step towards the light in texture coordinates; `h`, its length in mm.
    pub step_uvw: [f32; 3],
    pub h: f32,
    /// Where light rays start, in steps from the voxel centre ([`LIGHT_START_STEPS`]).
    pub start: f32,
    pub _pad1: [f32; 3],
    /// Half the volume's extent (mm), for the clip test.
    pub half: [f32; 3],
    pub _pad2: f32,
}

const _: () = assert!(std::mem::size_of::<LightParams>() == 80);

slab_fields!(LightParams, linear);

fn params(texels: &VolumeTexels, direction: Vec3) -> LightParams {
    let extent = texels.extent();
    let h = LIGHT_STEP_VOXELS * texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    let diag = Vec3::from(extent).length();
    let step = direction * h / Vec3::from(extent);
    LightParams {
        slab: SlabOrigin::of(texels.dims.map(|d| d as u32)),
        voxels: 0,
        row_stride: 0,
        max_steps: (diag / h).ceil() as u32 + 2,
        _pad0: 0,
        step_uvw: step.into(),
        h,
        start: LIGHT_START_STEPS,
        _pad1: [0.0; 3],
        half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5],
        _pad2: 0.0,
    }
}

/// CPU twin of one invocation of `light.wgsl`: T at the centre of `voxel`.
fn light_voxel(
    p: &LightParams,
    volume: &VolumeSampler,
    voxel: [usize; 3],
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
) -> f32 {
    let dims = volume.dims;
    let centre = voxel_centre(voxel, dims);
    let step = Vec3::from(p.step_uvw);
    let mut t = 1.0f32;
    for i in 0..p.max_steps {
        let uvw = centre + step * (i as f32 + p.start);
        if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() || t < T_STOP {
            break;
        }
        let pos = (uvw - Vec3::splat(0.5)) * 2.0 * Vec3::from(p.half);
        if let Some(c) = clip
            && c.uniforms.counts[0] > 0
            && !match volume.segments {
                Some(_) => c.visible_for(pos, volume.carved_by_at(uvw)),
                None => c.classify(pos).0,
            }
        {
            continue;
        }
        t *= 1.0 - volume.opacity_at(uvw);
    }
    t
}

/// The light volume on the CPU (rayon), x fastest. `direction`: unit, towards the
/// light; with `clip` (maps read back from the GPU), clipped space lets light through.
pub fn light_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    direction: Vec3,
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    light_cpu_reading(texels, lut, None, direction, clip, progress)
}

/// [`light_cpu`] reading `segments` beside the density (their weights, and the shapes
/// that cut each sample's segment), as [`LightGpu::compute`] with a segmentation.
pub fn light_cpu_reading(
    texels: &VolumeTexels,
    lut: &Lut,
    segments: Option<&SegmentSampler>,
    direction: Vec3,
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<f32> {
    let p = params(texels, direction);
    let norm = crate::sample::f16_texels(texels);
    let volume = VolumeSampler {
        values: &norm,
        dims: texels.dims,
        map: f16_volume_map(texels, lut),
        table: &lut.rgba,
        segments,
    };
    per_voxel(texels.dims, progress, |v| light_voxel(&p, &volume, v, clip))
}

/// What the light volume is computed of: the texels (uploaded as f16), a segmentation
/// beside them, and the opacity table ([`light_lut`]).
#[derive(Debug, Clone, Copy)]
pub struct Lit<'a> {
    pub texels: &'a VolumeTexels,
    pub segments: Option<&'a SegmentTexels>,
    pub lut: &'a Lut,
}

/// Long-lived light-volume compute state: its pipeline, and the one reading a
/// segmentation.
#[derive(Debug)]
pub struct LightGpu(crate::gpu::Segmentable);

impl crate::gpu::Stage for LightGpu {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        crate::gpu::Segmentable::new(device, "Light", "light.wgsl", &[]).map(LightGpu)
    }
}

impl LightGpu {
    /// The light volume of `texels` (uploaded as f16 for this pass), in z-slabs, read
    /// back. `direction`: unit, towards the light; `clip`'s carved space lets light
    /// through, and so do a segmentation's hidden segments.
    pub fn compute(
        &self,
        gpu: &Gpu,
        lit: Lit<'_>,
        direction: Vec3,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let Lit {
            texels,
            segments,
            lut,
        } = lit;
        let device = &gpu.device;
        let stage = self.0.get(device, segments.is_some())?;
        let clip_layout = stage.pipeline.get_bind_group_layout(1);
        let clip_group = match clip {
            Some(c) => c.bind_group(device, &clip_layout),
            None => crate::clip::gpu::empty_bind_group(device, &clip_layout),
        };
        let base = params(texels, direction);
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slabs = SlabDispatch::new(
            base.slab.dims,
            Grid::Linear,
            base.max_steps as u64,
            budget::COSTLY_SAMPLES,
            max_storage,
        );
        let size = slabs.max_slab_voxels() * 4;
        let chain = crate::sample::mip_chain(texels, 0);
        let (uniforms, out, readback, group) = validated(device, "Light::buffers", || {
            let volume = crate::gpu::f16_texture(device, &gpu.queue, "Light::texels", &chain)
                .create_view(&Default::default());
            let table = reader::table(gpu, "Light::lut", lut);
            let map = f16_volume_map(texels, lut);
            let segments = match segments {
                Some(s) => GpuSegments::new(gpu, s),
                None => GpuSegments::none(gpu),
            };
            let cuts = SegmentBindings::Cuts(&segments);
            let reading = Reading::sampled(&volume, &stage.sampler, map, &table, cuts);
            let volume_group = reading.group_of(gpu, "Light", &stage.pipeline);
            let out = output_buffer(device, "Light::transmittance", size);
            let readback = readback_buffer(device, "Light::readback", size);
            let bound = [out.as_entire_binding()];
            let (uniforms, group) = uniform_group(gpu, "Light", &stage.pipeline, &base, &bound);
            (uniforms, out, readback, [group, volume_group])
        })?;
        let pass = Pass {
            label: "Light::slab",
            pipeline: &stage.pipeline,
            bind_groups: &[(0, &group[0]), (1, &clip_group), (VOLUME_GROUP, &group[1])],
            uniforms: &uniforms,
        };
        slabs.run_readback(gpu, &pass, base, &out, &readback, progress)
    }
}

/// Rounds light-volume values as the R16Float texture the ray caster samples holds them.
pub fn quantise(values: &[f32]) -> Vec<f32> {
    values
        .iter()
        .map(|&v| half::f16::from_f32(v.clamp(0.0, 1.0)).to_f32())
        .collect()
}

/// Passes of the (¼, ½, ¼) filter along each axis that [`filter_light`] makes: twelve
/// make a binomial kernel of 25 taps, σ = √6 ≈ 2.45 voxels (chosen on the cranium CT:
/// fewer leave the light volume's slice stair-steps and hard shadow edges in the image;
/// eight, σ = 2, added texture at 2048² with a step of 0.125, see docs/benchmarks.md,
/// "Shadows").
pub const FILTER_PASSES: usize = 12;

/// Low-pass filters a light volume (x fastest) in place: [`FILTER_PASSES`] passes of
/// (¼, ½, ¼) along x, y and z, the edge voxel repeated. The transmittance computed at the
/// voxel centres changes by a whole surface's opacity from one voxel to the next where a
/// light ray grazes a surface, and the stair-steps of slices show in it; read back at
/// the samples of a view ray that alias. The filter keeps linear variation unchanged.
pub fn filter_light(values: &mut [f32], dims: [usize; 3]) {
    use rayon::prelude::*;
    let mut tmp = vec![0.0f32; values.len()];
    for _ in 0..FILTER_PASSES {
        for axis in 0..3 {
            let stride = [1, dims[0], dims[0] * dims[1]][axis];
            let n = dims[axis];
            if n < 2 {
                continue;
            }
            let src: &[f32] = values;
            tmp.par_iter_mut().enumerate().for_each(|(i, out)| {
                let c = (i / stride) % n;
                let lo = if c > 0 { i - stride } else { i };
                let hi = if c + 1 < n { i + stride } else { i };
                *out = 0.25 * src[lo] + 0.5 * src[i] + 0.25 * src[hi];
            });
            values.copy_from_slice(&tmp);
        }
    }
}

/// A light volume for the CPU twin of the ray caster: values as the GPU samples them.
#[derive(Debug, Clone)]
pub struct LightVolume {
    /// Unit direction towards the light.
    pub direction: Vec3,
    /// Transmittance per voxel (x fastest), filtered ([`filter_light`]) and rounded as
    /// [`quantise`] does.
    pub values: Vec<f32>,
}

impl LightVolume {
    /// The light volume the ray caster samples for the transmittance `t` computed at the
    /// voxel centres of a `dims` volume (by [`LightGpu`] or [`light_cpu`]): filtered,
    /// then rounded to f16.
    pub fn new(t: &[f32], dims: [usize; 3], direction: Vec3) -> LightVolume {
        let mut values = t.to_vec();
        filter_light(&mut values, dims);
        LightVolume {
            direction,
            values: quantise(&values),
        }
    }
}

/// The guard limit `g` of the shadow lookup, in voxels of the smallest spacing: the
/// light volume is read `g / cos θ` from the sample towards the light (see
/// [`shadow_factor`]). Four voxels: one for the depth a view ray reaches into an opaque
/// surface before it stops, one for the trilinear footprint of the light volume, two for
/// what [`filter_light`] spreads of the dark inside of a surface (its σ ≈ 2.45 voxels).
pub const GUARD_VOXELS: f32 = 4.0;

/// How far `d` (texture coordinates) may be followed from `uvw` inside the box, as a
/// fraction of it in [0, 1].
fn inside_box(uvw: Vec3, d: Vec3) -> f32 {
    let room = Vec3::select(d.cmpgt(Vec3::ZERO), Vec3::ONE - uvw, uvw);
    let ad = d.abs();
    let r = Vec3::select(
        ad.cmpgt(Vec3::ZERO),
        (room / ad.max(Vec3::splat(1e-20))).clamp(Vec3::ZERO, Vec3::ONE),
        Vec3::ONE,
    );
    r.min_element()
}

/// The shadow factor at a view-ray sample `uvw` (CPU twin of `shadow` in raycast.wgsl).
///
/// Guard limit (Papaioannou et al. §5.1): the light volume is read at `o`, the sample
/// moved towards the light (`direction`) by `d0 = g / cos θ` mm (g = [`GUARD_VOXELS`] of
/// the smallest spacing, cos θ between the light and the normal, at least ½), so the
/// surface layer the sample lies in does not shadow itself. Filtered occlusion (Imagire et
/// al. Eq. 3–4): `¼ T(o − Δs/2) + ½ T(o) + ¼ T(o + Δs/2)`, Δs the view ray's step, the
/// half steps kept on the valid sampling path (inside the box).
pub fn shadow_factor(
    light: &[f32],
    dims: [usize; 3],
    p: &crate::render::RaycastParams,
    uvw: Vec3,
    view: Vec3,
    direction: Vec3,
    cos_theta: f32,
) -> f32 {
    let to_uvw = Vec3::ONE / (2.0 * Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]));
    let guard = GUARD_VOXELS * p.voxel_uvw[3] / cos_theta.max(0.5);
    let o = uvw + direction * guard * to_uvw;
    let half_step = -view * (0.5 * p.step[0]) * to_uvw;
    filtered_occlusion(
        light,
        dims,
        o,
        half_step * inside_box(uvw, -half_step),
        half_step * inside_box(uvw, half_step),
    )
}

/// Imagire et al.'s filtered occlusion (Eq. 3–4) at `o`: `¼ T(o − behind) + ½ T(o) +
/// ¼ T(o + ahead)`, the offsets being half the view ray's step back and forth.
pub fn filtered_occlusion(
    light: &[f32],
    dims: [usize; 3],
    o: Vec3,
    behind: Vec3,
    ahead: Vec3,
) -> f32 {
    0.25 * trilinear(light, dims, o - behind)
        + 0.5 * trilinear(light, dims, o)
        + 0.25 * trilinear(light, dims, o + ahead)
}
