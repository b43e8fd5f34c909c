//! One volume as the ray caster draws it: [`RenderVolume`] is the [`GpuVolume`] every
//! stage reads (density, occupancy, block ranges, baked table) with what the ray caster
//! reads beside it: the AO volume (or its stand-in), opacity modulation, the gradient
//! volume and what bind group 2 reads (live positional AO, the light volume, surfaces).
//! The ray caster (`render::gpu`) binds them, in bind groups built for each tile.

use super::extras::GpuLight;
use super::gradient::GradientVolume;
use super::shadow::LightVolume;
use crate::gpu::filled_texture_3d;
use crate::gpu::{Gpu, GpuError, validated};
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::tf::TransferFunction;
use glam::Vec3;

/// One volume on the GPU with what the ray caster reads beside it. Reads through to its
/// [`GpuVolume`] (`texels`, `lut`, `volume_view()`, …), which AO stages take.
#[derive(Debug)]
pub struct RenderVolume {
    volume: GpuVolume,
    ao_view: wgpu::TextureView,
    /// `ao_view` is an AO volume, not the 1×1×1 texel of 1 (see [`Variant`]).
    pub(super) ao_bound: bool,
    /// An AO volume of the same size and format read instead of `ao_view` while
    /// `reads_stand_in` (the viewer's images of a moving clip shape read CAO's `V_PAO`
    /// while its `V_AO` catches up).
    ao_stand_in: Option<wgpu::TextureView>,
    reads_stand_in: bool,
    pub(super) modulation_view: wgpu::TextureView,
    /// `modulation_view` is a modulation volume, not the 1×1×1 texel of 1.
    pub(super) modulation_bound: bool,
    /// The density's central differences per voxel ([`super::gradient`]), or `None`: the
    /// ray caster then takes six density samples per gradient (and binds a placeholder).
    gradient: Option<GradientVolume>,
    /// Live positional AO, the light volume and surfaces (bind group 2), see
    /// `render::extras`.
    pub extras: super::extras::RayExtras,
}

impl std::ops::Deref for RenderVolume {
    type Target = GpuVolume;

    fn deref(&self) -> &GpuVolume {
        &self.volume
    }
}

impl RenderVolume {
    /// Uploads a volume (halving it until it fits the adapter, [`GpuVolume::new`]) for
    /// ray casting, with the gradient volume shading reads.
    pub fn new(
        gpu: &Gpu,
        volume: &crate::volume::Volume,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let volume = GpuVolume::new(gpu, volume, tf, step_voxels)?;
        Ok(Self::around(gpu, volume).with_gradient(gpu))
    }

    /// Uploads `texels` for ray casting, with the gradient volume shading reads.
    pub fn from_texels(
        gpu: &Gpu,
        texels: VolumeTexels,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        Ok(Self::for_compute(gpu, texels, tf, step_voxels)?.with_gradient(gpu))
    }

    /// With the gradient volume ([`Self::set_gradient_volume`]), where it fits: where
    /// the device cannot hold it, shading takes six samples instead, the same pixels up
    /// to f16 rounding ([`Self::gradient_volume`] says which).
    fn with_gradient(mut self, gpu: &Gpu) -> Self {
        let _ = self.set_gradient_volume(gpu, true);
        self
    }

    /// Uploads `texels` without the gradient volume, which only the ray caster's shading
    /// reads (8 bytes per voxel): for compute passes (AO, modulation) that may also ray
    /// cast it, correctly, with six samples per gradient.
    pub fn for_compute(
        gpu: &Gpu,
        texels: VolumeTexels,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let volume = GpuVolume::for_compute(gpu, texels, tf, step_voxels)?;
        Ok(Self::around(gpu, volume))
    }

    /// `volume` with no AO, modulation, gradient or extras yet.
    pub fn around(gpu: &Gpu, volume: GpuVolume) -> Self {
        let (device, queue) = (&gpu.device, &gpu.queue);
        RenderVolume {
            volume,
            // No AO volume yet: a single texel of 1 makes A(x) = 1 everywhere.
            ao_view: no_ambient_occlusion(device, queue),
            ao_bound: false,
            ao_stand_in: None,
            reads_stand_in: false,
            modulation_view: no_modulation(device, queue),
            modulation_bound: false,
            gradient: None,
            extras: Default::default(),
        }
    }

    /// Builds (`on`) or drops the gradient volume ([`super::gradient`]); whether one is
    /// bound afterwards (a volume whose gradient volume does not fit keeps none). The
    /// pixels are the same up to the gradient's f16 rounding.
    pub fn set_gradient_volume(&mut self, gpu: &Gpu, on: bool) -> Result<bool, GpuError> {
        if on == self.gradient.is_some() {
            return Ok(on);
        }
        self.gradient = None;
        if on {
            let v = &self.volume;
            self.gradient = GradientVolume::new(gpu, v.volume_view(), &v.texels, v.ranges())?;
        }
        Ok(self.gradient.is_some())
    }

    /// The gradient volume, if one is bound.
    pub fn gradient_volume(&self) -> Option<&GradientVolume> {
        self.gradient.as_ref()
    }

    /// Sets the segmentation every stage reads ([`GpuVolume::set_segments`]); whether
    /// anything changed.
    pub fn set_segments(
        &mut self,
        gpu: &Gpu,
        segments: Option<crate::texels::segments::SegmentTexels>,
    ) -> bool {
        self.volume.set_segments(gpu, segments)
    }

    /// Bakes the transfer function for frames of `step_voxels` too
    /// ([`GpuVolume::prepare_step`]).
    pub fn prepare_step(&mut self, gpu: &Gpu, step_voxels: f32) {
        self.volume.prepare_step(gpu, step_voxels);
    }

    /// Re-bakes the transfer function (and the skip grid, and live positional AO's
    /// table) if it or the step changed.
    pub fn set_transfer_function(&mut self, gpu: &Gpu, tf: &TransferFunction, step_voxels: f32) {
        if !self.volume.set_transfer_function(gpu, tf, step_voxels) {
            return;
        }
        if let Some(live) = &mut self.extras.live_vao {
            live.set_transfer_function(gpu, &self.volume.texels, tf);
        }
    }

    /// A texture of one texel per voxel holding `bytes` (of `format`), and its view.
    fn per_voxel(
        &self,
        gpu: &Gpu,
        label: &str,
        format: wgpu::TextureFormat,
        bytes: &[u8],
    ) -> wgpu::TextureView {
        let dims = self.texels.dims.map(|d| d as u32);
        filled_texture_3d(&gpu.device, &gpu.queue, label, dims, format, bytes)
            .create_view(&Default::default())
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the ambient factor A(x).
    ///
    /// Stored as R32Float (filtered with `FLOAT32_FILTERABLE`), the format CAO's compute
    /// passes write, so a precomputed and a per-frame AO volume shade alike.
    pub fn set_ambient_occlusion(&mut self, gpu: &Gpu, values: &[f32]) {
        let format = wgpu::TextureFormat::R32Float;
        let bytes = bytemuck::cast_slice(values);
        self.ao_view = self.per_voxel(gpu, "GpuVolume::ambient_occlusion", format, bytes);
        self.ao_bound = true;
        self.ao_stand_in = None;
    }

    /// Uses an AO volume already on the GPU (R32Float, the volume's dims), such as
    /// CAO's `V_AO`.
    pub fn set_ambient_occlusion_view(&mut self, view: &wgpu::TextureView) {
        self.ao_view = view.clone();
        self.ao_bound = true;
        self.ao_stand_in = None;
    }

    /// An AO volume of the same dims and format as the one set, read instead of it
    /// while [`Self::read_stand_in`] says so: CAO's `V_PAO`, which the viewer's images
    /// of a moving clip shape read while `V_AO` is being updated for another pose.
    pub fn set_ambient_occlusion_stand_in(&mut self, view: Option<&wgpu::TextureView>) {
        self.ao_stand_in = view.cloned();
    }

    /// Whether frames encoded from now on read the stand-in (when one is set) instead of
    /// the AO volume. Switching changes no other binding and bakes nothing.
    pub fn read_stand_in(&mut self, yes: bool) {
        self.reads_stand_in = yes;
    }

    /// Whether frames encoded now read the stand-in.
    pub fn reads_stand_in(&self) -> bool {
        self.reads_stand_in && self.ao_stand_in.is_some()
    }

    /// The AO volume frames encoded now read.
    pub(super) fn ao_view_read(&self) -> &wgpu::TextureView {
        match (&self.ao_stand_in, self.reads_stand_in) {
            (Some(view), true) => view,
            _ => &self.ao_view,
        }
    }

    /// Back to no ambient occlusion (A = 1 everywhere), as right after upload. The viewer
    /// shows this while a new AO volume is computed for a changed transfer function.
    pub fn clear_ambient_occlusion(&mut self, gpu: &Gpu) {
        self.ao_view = no_ambient_occlusion(&gpu.device, &gpu.queue);
        self.ao_bound = false;
        self.ao_stand_in = None;
    }

    /// Drops the opacity modulation (factor 1 everywhere).
    pub fn clear_opacity_modulation(&mut self, gpu: &Gpu) {
        self.modulation_view = no_modulation(&gpu.device, &gpu.queue);
        self.modulation_bound = false;
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the opacity factor of
    /// variance modulation. Stored as R16Unorm like the AO volume; returns the values as
    /// the GPU will sample them (for the CPU twin).
    pub fn set_opacity_modulation(&mut self, gpu: &Gpu, values: &[f32]) -> Vec<f32> {
        let quantised: Vec<u16> = values
            .iter()
            .map(|&a| (a.clamp(0.0, 1.0) * 65535.0).round() as u16)
            .collect();
        let format = wgpu::TextureFormat::R16Unorm;
        let bytes = bytemuck::cast_slice(&quantised);
        self.modulation_view = self.per_voxel(gpu, "GpuVolume::opacity_modulation", format, bytes);
        self.modulation_bound = true;
        quantised.iter().map(|&q| q as f32 / 65535.0).collect()
    }
}

/// No opacity modulation: a single texel of 1.
fn no_modulation(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let format = wgpu::TextureFormat::R8Unorm;
    let label = "GpuVolume::opacity_modulation";
    filled_texture_3d(device, queue, label, [1, 1, 1], format, &[255])
        .create_view(&Default::default())
}

/// No ambient occlusion: a single texel of 1.
fn no_ambient_occlusion(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let (format, one) = (wgpu::TextureFormat::R32Float, bytemuck::bytes_of(&1.0f32));
    let label = "GpuVolume::ambient_occlusion";
    filled_texture_3d(device, queue, label, [1, 1, 1], format, one).create_view(&Default::default())
}

impl RenderVolume {
    /// Turns live positional AO on (`Some`) or off for this volume and transfer function.
    /// Returns the CPU twin's equivalent of what is now on the GPU.
    pub fn set_live_vao(
        &mut self,
        gpu: &Gpu,
        tf: &TransferFunction,
        settings: Option<&crate::ao::vao::VaoSettings>,
    ) -> Result<(), GpuError> {
        self.extras.live_vao = match settings {
            Some(s) => Some(
                crate::ao::vao::VaoInputs::new(gpu, &self.texels, tf, s)?
                    .with_segments(gpu, self.segment_texels.as_ref()),
            ),
            None => None,
        };
        Ok(())
    }

    /// Uses `values` (transmittance per voxel, x fastest) as the light volume for shadows
    /// from `direction` (unit, towards the light), filtered ([`LightVolume::new`]); `None`
    /// turns shadows off. Returns the values as the GPU samples them (for the CPU twin).
    pub fn set_light_volume(
        &mut self,
        gpu: &Gpu,
        light: Option<(&[f32], Vec3)>,
    ) -> Result<Option<LightVolume>, GpuError> {
        let Some((values, direction)) = light else {
            self.extras.light = None;
            return Ok(None);
        };
        let dims = self.texels.dims;
        if values.len() != dims.iter().product::<usize>() {
            return Err(GpuError::Validation {
                stage: "RenderVolume::set_light_volume".into(),
                message: format!(
                    "{} light values for a {}×{}×{} volume",
                    values.len(),
                    dims[0],
                    dims[1],
                    dims[2]
                ),
            });
        }
        // Filtered and rounded as the CPU twin gets it.
        let sampled = LightVolume::new(values, dims, direction);
        let bits: Vec<u16> = sampled
            .values
            .iter()
            .map(|&v| half::f16::from_f32(v).to_bits())
            .collect();
        let view = validated(&gpu.device, "RenderVolume::set_light_volume", || {
            crate::gpu::f16_texture(&gpu.device, &gpu.queue, "GpuVolume::light", &[(bits, dims)])
                .create_view(&Default::default())
        })?;
        self.extras.light = Some(GpuLight { view, direction });
        Ok(Some(sampled))
    }
}
