//! Volumetric shadows from a directional light: the light volume `T(x)` (transmittance
//! from each voxel centre towards the light) on the GPU (`shaders/light.wgsl`) and on the
//! CPU (twin: [`light_cpu`]), and the anti-aliased shadow factor the ray caster reads.
//!
//! Anti-aliasing follows Imagire et al. (2007, §3.3): the shadow at a view-ray sample
//! `s_i` is `¼ T(s_i − Δs/2) + ½ T(s_i) + ¼ T(s_i + Δs/2)` (their Eq. 3–4, the half-step
//! positions between neighbouring samples), and the light rays start at a per-voxel
//! jittered offset, so no stair-steps appear at shadow boundaries.

use crate::gpu::dispatch::{Grid, Pass, SlabDispatch, SlabOrigin, budget, slab_fields};
use crate::gpu::{Gpu, GpuError, output_buffer, readback_buffer, storage_buffer, validated};
use crate::render::jitter;
use crate::render::texels::VolumeTexels;
use crate::sample::bake_lut;
use crate::sample::{alpha_column, lut_lerp, per_voxel, trilinear, voxel_centre};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

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
    /// LUT index = stored · lut_scale + lut_offset, clamped to lut_last.
    pub lut_scale: f32,
    pub lut_offset: f32,
    pub lut_last: f32,
    pub _pad1: f32,
    /// Half the volume's extent (mm), for the clip test.
    pub half: [f32; 3],
    pub _pad2: f32,
}

const _: () = assert!(std::mem::size_of::<LightParams>() == 80);

slab_fields!(LightParams, linear);

fn params(texels: &VolumeTexels, lut: &Lut, direction: Vec3) -> LightParams {
    let extent = texels.extent();
    let h = LIGHT_STEP_VOXELS * texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    let diag = Vec3::from(extent).length();
    let (a, b) = crate::sample::f16_lut_map(texels, lut);
    let step = direction * h / Vec3::from(extent);
    LightParams {
        slab: SlabOrigin::of(texels.dims.map(|d| d as u32)),
        voxels: 0,
        row_stride: 0,
        max_steps: (diag / h).ceil() as u32 + 2,
        _pad0: 0,
        step_uvw: step.into(),
        h,
        lut_scale: a,
        lut_offset: b,
        lut_last: (lut.rgba.len().max(2) - 1) as f32,
        _pad1: 0.0,
        half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5],
        _pad2: 0.0,
    }
}

/// CPU twin of one invocation of `light.wgsl`: T at the centre of `voxel`.
fn light_voxel(
    p: &LightParams,
    alpha: &[f32],
    norm: &[f32],
    dims: [usize; 3],
    voxel: [usize; 3],
    clip: Option<&crate::clip::cpu::ClipMapsCpu>,
) -> f32 {
    let centre = voxel_centre(voxel, dims);
    let j = jitter((voxel[0] + dims[0] * voxel[2]) as u32, voxel[1] as u32);
    let step = Vec3::from(p.step_uvw);
    let mut t = 1.0f32;
    for i in 0..p.max_steps {
        let uvw = centre + step * (i as f32 + j);
        if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() || t < T_STOP {
            break;
        }
        if let Some(c) = clip
            && c.uniforms.counts[0] > 0
            && !c
                .classify((uvw - Vec3::splat(0.5)) * 2.0 * Vec3::from(p.half))
                .0
        {
            continue;
        }
        let n = trilinear(norm, dims, uvw);
        t *= 1.0 - lut_lerp(alpha, [p.lut_scale, p.lut_offset, p.lut_last], n);
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
    let p = params(texels, lut, direction);
    let alpha = alpha_column(lut);
    let norm = crate::sample::f16_texels(texels);
    per_voxel(texels.dims, progress, |v| {
        light_voxel(&p, &alpha, &norm, texels.dims, v, clip)
    })
}

crate::gpu::compute_stage!(
    /// Long-lived light-volume compute state.
    LightGpu,
    "Light",
    "light.wgsl"
);

impl LightGpu {
    /// The light volume of `texels` (uploaded as f16 for this pass), in z-slabs, read
    /// back. `direction`: unit, towards the light; `clip`'s carved space lets light through.
    pub fn compute(
        &self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        lut: &Lut,
        direction: Vec3,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let device = &gpu.device;
        let clip_layout = self.0.pipeline.get_bind_group_layout(1);
        let clip_group = match clip {
            Some(c) => c.bind_group(device, &clip_layout),
            None => crate::clip::gpu::empty_bind_group(device, &clip_layout),
        };
        let base = params(texels, lut, direction);
        let max_storage = device.limits().max_storage_buffer_binding_size / 4;
        let slabs = SlabDispatch::new(
            base.slab.dims,
            Grid::Linear,
            base.max_steps as u64,
            budget::COSTLY_SAMPLES,
            max_storage,
        );
        let alpha = alpha_column(lut);
        let size = slabs.max_slab_voxels() * 4;
        let chain = crate::sample::mip_chain(texels, 0);
        let (uniforms, out, readback, group) = validated(device, "Light::buffers", || {
            let volume = crate::gpu::f16_texture(device, &gpu.queue, "Light::texels", &chain)
                .create_view(&Default::default());
            let lut_buf = storage_buffer(
                gpu,
                "Light::lut_alpha",
                bytemuck::cast_slice(&alpha),
                wgpu::BufferUsages::empty(),
            );
            let out = output_buffer(device, "Light::transmittance", size);
            let readback = readback_buffer(device, "Light::readback", size);
            let bound = [&lut_buf, &out].map(|b| b.as_entire_binding());
            let (uniforms, group) = self.0.sampling_group(gpu, "Light", &base, &volume, &bound);
            (uniforms, out, readback, group)
        })?;
        let pass = Pass {
            label: "Light::slab",
            pipeline: &self.0.pipeline,
            bind_groups: &[&group, &clip_group],
            uniforms: &uniforms,
        };
        slabs.run_readback(gpu, &pass, base, (&out, &readback), progress)
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
