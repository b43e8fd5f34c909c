//! One volume on the GPU: [`GpuVolume`] holds its textures (the density, the occupancy
//! blocks and their ranges, AO, modulation), its transfer function baked into a LUT and
//! what bind group 2 reads (live positional AO, the light volume, surfaces). The ray
//! caster (`render::gpu`) binds them; [`GpuVolume::generation`] tells it when its cached
//! bind groups are stale.

use super::extras::GpuLight;
use super::gradient::GradientVolume;
use super::shadow::LightVolume;
use crate::gpu::{Gpu, GpuError, validated};
use crate::sample::bake_lut;
use crate::texels::{BlockRanges, UploadLimits, VolumeTexels};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// One volume on the GPU with its transfer function baked.
#[derive(Debug)]
pub struct GpuVolume {
    pub texels: VolumeTexels,
    ranges: BlockRanges,
    pub(super) volume_view: wgpu::TextureView,
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
    occupancy: wgpu::Texture,
    pub(super) occupancy_view: wgpu::TextureView,
    /// (min, max) of `norm` per occupancy block: the projection and iso modes' skip test.
    pub(super) block_range_view: wgpu::TextureView,
    /// The density's central differences per voxel ([`super::gradient`]), or `None`: the
    /// ray caster then takes six density samples per gradient (and binds a placeholder).
    gradient: Option<GradientVolume>,
    pub(super) lut_buffer: wgpu::Buffer,
    /// The baked LUT currently on the GPU (alpha corrected for `lut_step`).
    pub lut: Lut,
    lut_step: f32,
    /// The same transfer function baked for another step (the viewer's interactive
    /// images, [`Self::prepare_step`]), and the generation it was baked in.
    step_lut: Option<(f32, u64, wgpu::Buffer)>,
    tf: TransferFunction,
    /// Live positional AO, the light volume and surfaces (bind group 2), see
    /// `render::extras`.
    pub extras: super::extras::RayExtras,
    /// Changes whenever a resource the ray caster binds is replaced, so it knows when
    /// its cached bind groups are stale.
    pub(super) generation: u64,
}

/// A fresh value for [`GpuVolume::generation`], unique across volumes.
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// How the volume's textures are used: sampled by the shaders, written by the upload.
const SAMPLED: wgpu::TextureUsages =
    wgpu::TextureUsages::TEXTURE_BINDING.union(wgpu::TextureUsages::COPY_DST);

/// A volume texture of `dims` holding `bytes` (tightly packed texels of `format`).
fn filled(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
    bytes: &[u8],
) -> wgpu::Texture {
    let texture = crate::gpu::texture_3d(device, label, dims, format, SAMPLED);
    let texel = format.block_copy_size(None).unwrap_or(1);
    crate::gpu::write_texture_3d(queue, &texture, 0, dims, texel, bytes);
    texture
}

impl GpuVolume {
    /// Uploads a volume (halving it until it fits the adapter) with a transfer function.
    pub fn new(
        gpu: &Gpu,
        volume: &crate::volume::Volume,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let texels = VolumeTexels::new(volume, UploadLimits::of(gpu));
        Self::from_texels(gpu, texels, tf, step_voxels)
    }

    /// Uploads `texels` for ray casting: with the gradient volume shading reads
    /// ([`Self::set_gradient_volume`]).
    pub fn from_texels(
        gpu: &Gpu,
        texels: VolumeTexels,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let mut vol = Self::for_compute(gpu, texels, tf, step_voxels)?;
        // Optional: where the device cannot hold it, shading takes six samples instead,
        // the same pixels up to f16 rounding ([`Self::gradient_volume`] says which).
        let _ = vol.set_gradient_volume(gpu, true);
        Ok(vol)
    }

    /// Uploads `texels` for compute passes (AO, modulation) that read the density and
    /// the LUT: without the gradient volume, which only the ray caster's shading reads
    /// (8 bytes per voxel). Ray casting it is still correct, with six samples per
    /// gradient.
    pub fn for_compute(
        gpu: &Gpu,
        texels: VolumeTexels,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let (device, queue) = (&gpu.device, &gpu.queue);
        let dims = texels.dims.map(|d| d as u32);
        let ranges = BlockRanges::new(&texels);
        let lut = bake_lut(tf, &texels, step_voxels);
        let occ = ranges.occupancy(&texels, &lut);
        let grid = ranges.grid.map(|d| d as u32);
        validated(device, "GpuVolume::upload", || {
            let volume = filled(
                device,
                queue,
                "GpuVolume::volume",
                dims,
                texels.format.wgpu(),
                &texels.bytes,
            );
            let occupancy = filled(
                device,
                queue,
                "GpuVolume::occupancy",
                grid,
                wgpu::TextureFormat::R8Uint,
                &occ,
            );
            let range_texels: Vec<[f32; 2]> = ranges.ranges.iter().map(|&(a, b)| [a, b]).collect();
            let block_range = filled(
                device,
                queue,
                "GpuVolume::block_range",
                grid,
                wgpu::TextureFormat::Rg32Float,
                bytemuck::cast_slice(&range_texels),
            );
            let lut_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("GpuVolume::lut"),
                size: (lut.rgba.len() * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&lut_buffer, 0, bytemuck::cast_slice(&lut.rgba));
            GpuVolume {
                volume_view: volume.create_view(&Default::default()),
                // No AO volume yet: a single texel of 1 makes A(x) = 1 everywhere.
                ao_view: no_ambient_occlusion(device, queue),
                ao_bound: false,
                ao_stand_in: None,
                reads_stand_in: false,
                modulation_view: no_modulation(device, queue),
                modulation_bound: false,
                occupancy_view: occupancy.create_view(&Default::default()),
                block_range_view: block_range.create_view(&Default::default()),
                gradient: None,
                occupancy,
                lut_buffer,
                lut,
                lut_step: step_voxels,
                step_lut: None,
                tf: tf.clone(),
                extras: Default::default(),
                generation: next_generation(),
                ranges,
                texels,
            }
        })
    }

    /// Builds (`on`) or drops the gradient volume ([`super::gradient`]); whether one is
    /// bound afterwards (a volume whose gradient volume does not fit keeps none). The
    /// pixels are the same up to the gradient's f16 rounding.
    pub fn set_gradient_volume(&mut self, gpu: &Gpu, on: bool) -> Result<bool, GpuError> {
        if on == self.gradient.is_some() {
            return Ok(on);
        }
        self.gradient = None;
        self.generation = next_generation();
        if on {
            self.gradient =
                GradientVolume::new(gpu, &self.volume_view, &self.texels, &self.ranges)?;
        }
        Ok(self.gradient.is_some())
    }

    /// The gradient volume, if one is bound.
    pub fn gradient_volume(&self) -> Option<&GradientVolume> {
        self.gradient.as_ref()
    }

    /// Bakes the transfer function for frames of `step_voxels` too, unless it is the
    /// step of [`Self::set_transfer_function`] or was baked already: frames of either
    /// step then composite with opacity corrected for their own step. The occupancy
    /// grid stays valid (a step changes no opacity from zero to non-zero or back).
    pub fn prepare_step(&mut self, gpu: &Gpu, step_voxels: f32) {
        let baked = |l: &(f32, u64, wgpu::Buffer)| (l.0, l.1) == (step_voxels, self.generation);
        if step_voxels == self.lut_step || self.step_lut.as_ref().is_some_and(baked) {
            return;
        }
        let lut = bake_lut(&self.tf, &self.texels, step_voxels);
        let buffer = match self.step_lut.take() {
            Some((_, _, b)) if b.size() == (lut.rgba.len() * 16) as u64 => b,
            _ => gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("GpuVolume::step_lut"),
                size: (lut.rgba.len() * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        gpu.queue
            .write_buffer(&buffer, 0, bytemuck::cast_slice(&lut.rgba));
        self.step_lut = Some((step_voxels, self.generation, buffer));
    }

    /// The LUT buffer for frames of `step_voxels`: the one baked by
    /// [`Self::prepare_step`] for it, else the transfer function's own.
    pub(super) fn lut_buffer_for(&self, step_voxels: f32) -> &wgpu::Buffer {
        match &self.step_lut {
            Some((step, generation, buffer))
                if *step == step_voxels
                    && *generation == self.generation
                    && step_voxels != self.lut_step =>
            {
                buffer
            }
            _ => &self.lut_buffer,
        }
    }

    /// Re-bakes the transfer function (and the skip grid) if it or the step changed.
    pub fn set_transfer_function(&mut self, gpu: &Gpu, tf: &TransferFunction, step_voxels: f32) {
        if *tf == self.tf && step_voxels == self.lut_step {
            return;
        }
        self.generation = next_generation();
        self.lut = bake_lut(tf, &self.texels, step_voxels);
        self.tf = tf.clone();
        self.lut_step = step_voxels;
        if let Some(live) = &mut self.extras.live_vao {
            live.set_transfer_function(gpu, &self.texels, tf);
        }
        gpu.queue
            .write_buffer(&self.lut_buffer, 0, bytemuck::cast_slice(&self.lut.rgba));
        let occ = self.ranges.occupancy(&self.texels, &self.lut);
        let grid = self.ranges.grid.map(|d| d as u32);
        crate::gpu::write_texture_3d(&gpu.queue, &self.occupancy, 0, grid, 1, &occ);
    }

    /// The volume texture (for compute passes such as LAO).
    pub fn volume_view(&self) -> &wgpu::TextureView {
        &self.volume_view
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
        filled(&gpu.device, &gpu.queue, label, dims, format, bytes).create_view(&Default::default())
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the ambient factor A(x).
    ///
    /// Stored as R32Float (filtered with `FLOAT32_FILTERABLE`), the format CAO's compute
    /// passes write, so a precomputed and a per-frame AO volume shade alike.
    pub fn set_ambient_occlusion(&mut self, gpu: &Gpu, values: &[f32]) {
        self.generation = next_generation();
        let format = wgpu::TextureFormat::R32Float;
        let bytes = bytemuck::cast_slice(values);
        self.ao_view = self.per_voxel(gpu, "GpuVolume::ambient_occlusion", format, bytes);
        self.ao_bound = true;
        self.ao_stand_in = None;
    }

    /// Uses an AO volume already on the GPU (R32Float, the volume's dims), such as
    /// CAO's `V_AO`.
    pub fn set_ambient_occlusion_view(&mut self, view: &wgpu::TextureView) {
        self.generation = next_generation();
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
        self.generation = next_generation();
        self.ao_view = no_ambient_occlusion(&gpu.device, &gpu.queue);
        self.ao_bound = false;
        self.ao_stand_in = None;
    }

    /// Drops the opacity modulation (factor 1 everywhere).
    pub fn clear_opacity_modulation(&mut self, gpu: &Gpu) {
        self.generation = next_generation();
        self.modulation_view = no_modulation(&gpu.device, &gpu.queue);
        self.modulation_bound = false;
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the opacity factor of
    /// variance modulation. Stored as R16Unorm like the AO volume; returns the values as
    /// the GPU will sample them (for the CPU twin).
    pub fn set_opacity_modulation(&mut self, gpu: &Gpu, values: &[f32]) -> Vec<f32> {
        self.generation = next_generation();
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

    /// Per-block texel ranges (the occupancy grid's and sparse AO's source).
    pub fn ranges(&self) -> &BlockRanges {
        &self.ranges
    }

    /// The occupancy grid for the current LUT (for the CPU twin).
    pub fn occupancy(&self) -> Vec<u8> {
        self.ranges.occupancy(&self.texels, &self.lut)
    }
}

/// No opacity modulation: a single texel of 1.
fn no_modulation(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let format = wgpu::TextureFormat::R8Unorm;
    let label = "GpuVolume::opacity_modulation";
    filled(device, queue, label, [1, 1, 1], format, &[255]).create_view(&Default::default())
}

/// No ambient occlusion: a single texel of 1.
fn no_ambient_occlusion(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let (format, one) = (wgpu::TextureFormat::R32Float, bytemuck::bytes_of(&1.0f32));
    let label = "GpuVolume::ambient_occlusion";
    filled(device, queue, label, [1, 1, 1], format, one).create_view(&Default::default())
}

impl GpuVolume {
    /// Turns live positional AO on (`Some`) or off for this volume and transfer function.
    /// Returns the CPU twin's equivalent of what is now on the GPU.
    pub fn set_live_vao(
        &mut self,
        gpu: &Gpu,
        tf: &TransferFunction,
        settings: Option<&crate::ao::vao::VaoSettings>,
    ) -> Result<(), GpuError> {
        self.generation = next_generation();
        self.extras.live_vao = match settings {
            Some(s) => Some(crate::ao::vao::VaoInputs::new(gpu, &self.texels, tf, s)?),
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
        self.generation = next_generation();
        let Some((values, direction)) = light else {
            self.extras.light = None;
            return Ok(None);
        };
        let dims = self.texels.dims;
        if values.len() != dims.iter().product::<usize>() {
            return Err(GpuError::Validation {
                stage: "GpuVolume::set_light_volume".into(),
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
        let view = validated(&gpu.device, "GpuVolume::set_light_volume", || {
            crate::gpu::f16_texture(&gpu.device, &gpu.queue, "GpuVolume::light", &[(bits, dims)])
                .create_view(&Default::default())
        })?;
        self.extras.light = Some(GpuLight { view, direction });
        Ok(Some(sampled))
    }
}
