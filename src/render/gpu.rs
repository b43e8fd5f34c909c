//! The GPU ray caster: [`RayCaster`] holds what lives as long as the device (pipeline,
//! layout, sampler); [`GpuVolume`] holds one volume's textures and its transfer function;
//! a [`Frame`] is all that changes per frame.

use super::extras::GpuLight;
use super::shadow::LightVolume;
use super::texels::{BlockRanges, UploadLimits, VolumeTexels};
pub use super::variant::Variant;
use super::{Frame, Image};
use crate::gpu::{
    Gpu, GpuError, bind_group, copy_texture_out, read_buffer, shaders, texture_readback,
    uniform_buffer, unpad, validated,
};
use crate::sample::bake_lut;
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// Largest tile rendered in one submission: keeps each dispatch short (no driver
/// watchdog on real GPUs) and lets any image size fit the 2-D texture limit.
pub const TILE: u32 = 2048;

pub use super::texels::MAX_VOLUME_BYTES;

/// Long-lived ray-casting state: built once per device.
#[derive(Debug)]
pub struct RayCaster {
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    /// One pipeline per [`Variant`] used so far, built on first use.
    pipelines: std::sync::Mutex<Vec<(Variant, wgpu::ComputePipeline)>>,
    layout: wgpu::BindGroupLayout,
    clip_layout: wgpu::BindGroupLayout,
    /// `@group(1)` with no clip shapes (zeroed uniforms, a blank map).
    no_clip: wgpu::BindGroup,
    sampler: wgpu::Sampler,
    /// Group 2: live positional AO and shadows (`render::shadow`).
    layout_2: wgpu::BindGroupLayout,
    placeholders: super::extras::Placeholders,
    surfaces: super::surface::SurfaceRenderer,
    /// Uniform buffers and bind groups per render target, written each frame and
    /// rebuilt only when the volume's resources change (egui's `custom3d_wgpu` pattern).
    bound: std::sync::Mutex<Vec<Bound>>,
    /// Tile textures of [`Self::render`], by size.
    tiles: std::sync::Mutex<Vec<wgpu::Texture>>,
}

/// Render targets whose bindings are kept (the viewport's strips and tiles, a
/// screenshot tile, a CLI tile).
const BOUND_TARGETS: usize = 12;

/// What one render target binds: its uniforms, written per frame, and bind groups 0 and
/// 2, valid while the volume's generation and the surface layer stay the same.
#[derive(Debug)]
struct Bound {
    target: wgpu::Texture,
    params: wgpu::Buffer,
    extras: wgpu::Buffer,
    generation: u64,
    /// Bound the LUT baked for the frame's own step ([`GpuVolume::prepare_step`]).
    step_lut: bool,
    /// Bound the AO stand-in ([`GpuVolume::read_stand_in`]).
    stand_in: bool,
    layer: Option<(wgpu::TextureView, wgpu::TextureView)>,
    group: wgpu::BindGroup,
    group_2: wgpu::BindGroup,
}

/// One volume on the GPU with its transfer function baked.
#[derive(Debug)]
pub struct GpuVolume {
    pub texels: VolumeTexels,
    ranges: BlockRanges,
    volume_view: wgpu::TextureView,
    ao_view: wgpu::TextureView,
    /// `ao_view` is an AO volume, not the 1×1×1 texel of 1 (see [`Variant`]).
    pub(super) ao_bound: bool,
    /// An AO volume of the same size and format read instead of `ao_view` while
    /// `reads_stand_in` (the viewer's images of a moving clip shape read CAO's `V_PAO`
    /// while its `V_AO` catches up).
    ao_stand_in: Option<wgpu::TextureView>,
    reads_stand_in: bool,
    modulation_view: wgpu::TextureView,
    /// `modulation_view` is a modulation volume, not the 1×1×1 texel of 1.
    pub(super) modulation_bound: bool,
    occupancy: wgpu::Texture,
    occupancy_view: wgpu::TextureView,
    /// (min, max) of `norm` per occupancy block: the projection and iso modes' skip test.
    block_range_view: wgpu::TextureView,
    lut_buffer: wgpu::Buffer,
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
    generation: u64,
}

/// A fresh value for [`GpuVolume::generation`], unique across volumes.
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

fn texture_3d(
    device: &wgpu::Device,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
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
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

fn write_3d(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    dims: [u32; 3],
    bytes_per_texel: u32,
    data: &[u8],
) {
    queue.write_texture(
        texture.as_image_copy(),
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(dims[0] * bytes_per_texel),
            rows_per_image: Some(dims[1]),
        },
        wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: dims[2],
        },
    );
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

    pub fn from_texels(
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
            let volume = texture_3d(device, "GpuVolume::volume", dims, texels.format.wgpu());
            write_3d(
                queue,
                &volume,
                dims,
                texels.format.bytes() as u32,
                &texels.bytes,
            );
            // No AO volume yet: a single texel of 1 makes A(x) = 1 everywhere.
            let ao = texture_3d(
                device,
                "GpuVolume::ambient_occlusion",
                [1, 1, 1],
                wgpu::TextureFormat::R32Float,
            );
            write_3d(queue, &ao, [1, 1, 1], 4, bytemuck::bytes_of(&1.0f32));
            let occupancy = texture_3d(
                device,
                "GpuVolume::occupancy",
                grid,
                wgpu::TextureFormat::R8Uint,
            );
            write_3d(queue, &occupancy, grid, 1, &occ);
            let block_range = texture_3d(
                device,
                "GpuVolume::block_range",
                grid,
                wgpu::TextureFormat::Rg32Float,
            );
            let range_texels: Vec<[f32; 2]> = ranges.ranges.iter().map(|&(a, b)| [a, b]).collect();
            write_3d(
                queue,
                &block_range,
                grid,
                8,
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
                ao_view: ao.create_view(&Default::default()),
                ao_bound: false,
                ao_stand_in: None,
                reads_stand_in: false,
                modulation_view: no_modulation(device, queue),
                modulation_bound: false,
                occupancy_view: occupancy.create_view(&Default::default()),
                block_range_view: block_range.create_view(&Default::default()),
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
    fn lut_buffer_for(&self, step_voxels: f32) -> &wgpu::Buffer {
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
        write_3d(
            &gpu.queue,
            &self.occupancy,
            self.ranges.grid.map(|d| d as u32),
            1,
            &occ,
        );
    }

    /// The volume texture (for compute passes such as LAO).
    pub fn volume_view(&self) -> &wgpu::TextureView {
        &self.volume_view
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the ambient factor A(x).
    ///
    /// Stored as R32Float (filtered with `FLOAT32_FILTERABLE`), the format CAO's compute
    /// passes write, so a precomputed and a per-frame AO volume shade alike.
    pub fn set_ambient_occlusion(&mut self, gpu: &Gpu, values: &[f32]) {
        self.generation = next_generation();
        let dims = self.texels.dims.map(|d| d as u32);
        let texture = texture_3d(
            &gpu.device,
            "GpuVolume::ambient_occlusion",
            dims,
            wgpu::TextureFormat::R32Float,
        );
        write_3d(&gpu.queue, &texture, dims, 4, bytemuck::cast_slice(values));
        self.ao_view = texture.create_view(&Default::default());
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
    fn ao_view_read(&self) -> &wgpu::TextureView {
        match (&self.ao_stand_in, self.reads_stand_in) {
            (Some(view), true) => view,
            _ => &self.ao_view,
        }
    }

    /// Back to no ambient occlusion (A = 1 everywhere), as right after upload. The viewer
    /// shows this while a new AO volume is computed for a changed transfer function.
    pub fn clear_ambient_occlusion(&mut self, gpu: &Gpu) {
        self.generation = next_generation();
        let ao = texture_3d(
            &gpu.device,
            "GpuVolume::ambient_occlusion",
            [1, 1, 1],
            wgpu::TextureFormat::R32Float,
        );
        write_3d(&gpu.queue, &ao, [1, 1, 1], 4, bytemuck::bytes_of(&1.0f32));
        self.ao_view = ao.create_view(&Default::default());
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
        let dims = self.texels.dims.map(|d| d as u32);
        let quantised: Vec<u16> = values
            .iter()
            .map(|&a| (a.clamp(0.0, 1.0) * 65535.0).round() as u16)
            .collect();
        let texture = texture_3d(
            &gpu.device,
            "GpuVolume::opacity_modulation",
            dims,
            wgpu::TextureFormat::R16Unorm,
        );
        write_3d(
            &gpu.queue,
            &texture,
            dims,
            2,
            bytemuck::cast_slice(&quantised),
        );
        self.modulation_view = texture.create_view(&Default::default());
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
    let texture = texture_3d(
        device,
        "GpuVolume::opacity_modulation",
        [1, 1, 1],
        wgpu::TextureFormat::R8Unorm,
    );
    write_3d(queue, &texture, [1, 1, 1], 1, &[255]);
    texture.create_view(&Default::default())
}

impl RayCaster {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "raycast.wgsl")?;
        let surfaces = super::surface::SurfaceRenderer::new(device)?;
        validated(device, "RayCaster::new", || {
            use crate::gpu::entry;
            use wgpu::TextureViewDimension::{D2, D3};
            let c = wgpu::ShaderStages::COMPUTE;
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RayCaster::layout"),
                entries: &[
                    entry::uniform(0, c),
                    entry::texture(1, c, D3, Some(true)),
                    entry::sampler(2, c),
                    entry::storage(3, c, true),
                    entry::texture(4, c, D3, Some(true)),
                    entry::texture(5, c, D3, None),
                    entry::storage_texture(6, c, wgpu::TextureFormat::Rgba8Unorm, D2),
                    entry::texture(7, c, D3, Some(true)),
                    entry::texture(8, c, D3, Some(false)),
                ],
            });
            let clip_layout = crate::clip::gpu::bind_group_layout(device);
            let layout_2 = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RayCaster::layout_2"),
                entries: &super::extras::layout_entries(),
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("RayCaster::pipeline_layout"),
                bind_group_layouts: &[Some(&layout), Some(&clip_layout), Some(&layout_2)],
                immediate_size: 0,
            });
            let sampler = crate::gpu::linear_sampler(device, "RayCaster::linear_clamp");
            let no_clip = crate::clip::gpu::empty_bind_group(device, &clip_layout);
            RayCaster {
                module,
                pipeline_layout,
                pipelines: Default::default(),
                layout,
                clip_layout,
                no_clip,
                sampler,
                layout_2,
                placeholders: super::extras::Placeholders::new(device),
                surfaces,
                bound: Default::default(),
                tiles: Default::default(),
            }
        })
    }

    /// Encodes the ray casting of one tile of `frame` into `encoder`, writing the caller's
    /// `target` (Rgba8Unorm with `STORAGE_BINDING`; its size is the tile's, `origin` where
    /// it sits in the frame), with no readback, clipped by `clip`'s shapes. The viewer
    /// draws `target` through a paint callback and copies screenshot tiles out of it
    /// asynchronously; the pixels are those [`Self::render`] reads back for the same frame.
    pub fn encode_tile(
        &self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        vol: &GpuVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        (target, origin): (&wgpu::Texture, (u32, u32)),
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        // The surfaces, rasterised for the whole frame (submitted before the caller's
        // encoder, so they are ready when the ray cast reads them).
        let layer = match vol.extras.surfaces.is_empty() {
            true => None,
            false => Some(self.surfaces.rasterise(
                (device, queue),
                &vol.extras.surfaces,
                frame,
                &vol.texels,
            )?),
        };
        let variant = Variant::of(vol, frame, clip, layer.is_some());
        self.encode(
            (device, queue),
            (vol, variant),
            frame,
            clip,
            layer.as_ref(),
            (target, origin),
            encoder,
        )
    }

    /// The pipeline of `variant`, built on first use (shader compilation: ~30 ms on
    /// lavapipe) and kept for the device's lifetime.
    fn pipeline(
        &self,
        device: &wgpu::Device,
        variant: Variant,
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        if let Some(p) = self.built(variant) {
            return Ok(p);
        }
        // Compiled outside the lock (~0.1 s on lavapipe): another thread may look up or
        // build other variants meanwhile.
        let constants = variant.constants();
        let pipeline = validated(device, "RayCaster::pipeline", || {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("RayCaster::pipeline"),
                layout: Some(&self.pipeline_layout),
                module: &self.module,
                entry_point: Some("main"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    ..Default::default()
                },
                cache: None,
            })
        })?;
        let mut pipelines = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, p)) = pipelines.iter().find(|(v, _)| *v == variant) {
            return Ok(p.clone());
        }
        pipelines.push((variant, pipeline.clone()));
        Ok(pipeline)
    }

    /// `variant`'s pipeline if it is built.
    fn built(&self, variant: Variant) -> Option<wgpu::ComputePipeline> {
        let pipelines = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        pipelines
            .iter()
            .find(|(v, _)| *v == variant)
            .map(|(_, p)| p.clone())
    }

    /// Whether the pipeline for `variant` is built (drawing with another compiles it
    /// first, ~0.1 s on lavapipe: the viewer builds it on a worker thread instead).
    pub fn has_pipeline(&self, variant: Variant) -> bool {
        self.built(variant).is_some()
    }

    /// Builds the pipeline for `variant` (any thread).
    pub fn build_pipeline(&self, device: &wgpu::Device, variant: Variant) -> Result<(), GpuError> {
        self.pipeline(device, variant).map(|_| ())
    }

    /// Writes this frame's uniforms for `target` and encodes its dispatch with `variant`'s
    /// pipeline; the bind groups are reused while `vol`'s resources and the surface layer
    /// stay the same.
    #[allow(
        clippy::too_many_arguments,
        reason = "one tile of one frame: every argument is a different input"
    )]
    fn encode(
        &self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        (vol, variant): (&GpuVolume, Variant),
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        layer: Option<&super::surface::SurfaceLayer>,
        (target, origin): (&wgpu::Texture, (u32, u32)),
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let params = frame.params(&vol.texels, &vol.lut, origin.0, origin.1);
        let pipeline = self.pipeline(device, variant)?;
        let clip_group = clip.map(|c| c.bind_group(device, &self.clip_layout));
        let clip_group = clip_group.as_ref().unwrap_or(&self.no_clip);
        let (tw, th) = (target.width(), target.height());
        let layer_views = layer.map(|l| (l.position.clone(), l.color.clone()));
        let lut = vol.lut_buffer_for(frame.settings.step_voxels);
        let step_lut = !std::ptr::eq(lut, &vol.lut_buffer);
        let stand_in = vol.reads_stand_in();
        let mut bound = self.bound.lock().unwrap_or_else(|e| e.into_inner());
        validated(device, "RayCaster::encode_tile", || {
            let slot = match bound.iter().position(|b| b.target == *target) {
                Some(i) => i,
                None => {
                    if bound.len() >= BOUND_TARGETS {
                        bound.remove(0);
                    }
                    let uniform = |label, bytes: &[u8]| uniform_buffer(device, queue, label, bytes);
                    let params_buffer = uniform("RayCaster::params", bytemuck::bytes_of(&params));
                    let extras = uniform(
                        "RayCaster::extras",
                        bytemuck::bytes_of(&vol.extras.params()),
                    );
                    let (group, group_2) = self.bind_groups(
                        device,
                        (vol, lut),
                        target,
                        &params_buffer,
                        &extras,
                        layer,
                    );
                    bound.push(Bound {
                        target: target.clone(),
                        params: params_buffer,
                        extras,
                        generation: vol.generation,
                        step_lut,
                        stand_in,
                        layer: layer_views.clone(),
                        group,
                        group_2,
                    });
                    bound.len() - 1
                }
            };
            let b = &mut bound[slot];
            if b.generation != vol.generation
                || b.layer != layer_views
                || b.step_lut != step_lut
                || b.stand_in != stand_in
            {
                let (group, group_2) =
                    self.bind_groups(device, (vol, lut), target, &b.params, &b.extras, layer);
                b.group = group;
                b.group_2 = group_2;
                b.generation = vol.generation;
                b.step_lut = step_lut;
                b.stand_in = stand_in;
                b.layer = layer_views.clone();
            }
            queue.write_buffer(&b.params, 0, bytemuck::bytes_of(&params));
            queue.write_buffer(&b.extras, 0, bytemuck::bytes_of(&vol.extras.params()));
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("RayCaster::encode_tile"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &b.group, &[]);
            pass.set_bind_group(1, clip_group, &[]);
            pass.set_bind_group(2, &b.group_2, &[]);
            pass.dispatch_workgroups(tw.div_ceil(8), th.div_ceil(8), 1);
        })
    }

    /// Bind groups 0 (volume, LUT, AO, occupancy, target, modulation, block ranges) and
    /// 2 (extras).
    fn bind_groups(
        &self,
        device: &wgpu::Device,
        (vol, lut): (&GpuVolume, &wgpu::Buffer),
        target: &wgpu::Texture,
        params: &wgpu::Buffer,
        extras: &wgpu::Buffer,
        layer: Option<&super::surface::SurfaceLayer>,
    ) -> (wgpu::BindGroup, wgpu::BindGroup) {
        let target_view = target.create_view(&Default::default());
        let group = bind_group(
            device,
            "RayCaster::bind_group",
            &self.layout,
            &[
                params.as_entire_binding(),
                wgpu::BindingResource::TextureView(&vol.volume_view),
                wgpu::BindingResource::Sampler(&self.sampler),
                lut.as_entire_binding(),
                wgpu::BindingResource::TextureView(vol.ao_view_read()),
                wgpu::BindingResource::TextureView(&vol.occupancy_view),
                wgpu::BindingResource::TextureView(&target_view),
                wgpu::BindingResource::TextureView(&vol.modulation_view),
                wgpu::BindingResource::TextureView(&vol.block_range_view),
            ],
        );
        let group_2 = super::extras::bind_group_2(
            device,
            &self.layout_2,
            &vol.extras,
            extras,
            layer,
            &self.placeholders,
            &self.sampler,
        );
        (group, group_2)
    }

    /// Renders a frame in tiles of at most [`TILE`]², with shadow-test clipping against
    /// `clip`'s shapes, and reads it back.
    pub fn render(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
    ) -> Result<Image, GpuError> {
        self.render_variant(gpu, vol, frame, clip, None)
    }

    /// [`Self::render`] with the pipeline of `variant` (`None`: the frame's own,
    /// [`Variant::of`]). A variant with more features than the frame uses draws the same
    /// pixels; tests compare them.
    pub fn render_variant(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        variant: Option<Variant>,
    ) -> Result<Image, GpuError> {
        let device = &gpu.device;
        let (w, h) = (frame.width.max(1), frame.height.max(1));
        let mut image = Image {
            width: w,
            height: h,
            pixels: vec![[0; 4]; (w * h) as usize],
        };
        let layer = match vol.extras.surfaces.is_empty() {
            true => None,
            false => Some(self.surfaces.rasterise(
                (device, &gpu.queue),
                &vol.extras.surfaces,
                frame,
                &vol.texels,
            )?),
        };
        let mut y0 = 0;
        while y0 < h {
            let mut x0 = 0;
            while x0 < w {
                let (tw, th) = ((w - x0).min(TILE), (h - y0).min(TILE));
                let target = self.tile_target(device, tw, th)?;
                let (readback, row) =
                    texture_readback(device, "RayCaster::readback", [tw, th, 1], 4);
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("RayCaster::tile"),
                });
                let variant =
                    variant.unwrap_or_else(|| Variant::of(vol, frame, clip, layer.is_some()));
                self.encode(
                    (device, &gpu.queue),
                    (vol, variant),
                    frame,
                    clip,
                    layer.as_ref(),
                    (&target, (x0, y0)),
                    &mut encoder,
                )?;
                copy_texture_out(&mut encoder, &target, &readback, row, [tw, th, 1]);
                gpu.queue.submit([encoder.finish()]);
                let bytes = read_buffer(device, &readback, "RayCaster::readback")?;
                let pixels: Vec<[u8; 4]> = unpad(&bytes, row, tw);
                let tile = Image {
                    width: tw,
                    height: th,
                    pixels,
                };
                image.blit(&tile, x0, y0);
                x0 += TILE;
            }
            y0 += TILE;
        }
        Ok(image)
    }

    /// A tile texture of `tw × th` for [`Self::render`], kept for the next frame of the
    /// same size (so are its bindings).
    fn tile_target(
        &self,
        device: &wgpu::Device,
        tw: u32,
        th: u32,
    ) -> Result<wgpu::Texture, GpuError> {
        let mut tiles = self.tiles.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = tiles.iter().find(|t| (t.width(), t.height()) == (tw, th)) {
            return Ok(t.clone());
        }
        let t = validated(device, "RayCaster::tile", || {
            crate::gpu::image_texture(
                device,
                "RayCaster::tile",
                (tw, th),
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
            )
        })?;
        if tiles.len() >= BOUND_TARGETS - 1 {
            tiles.remove(0);
        }
        tiles.push(t.clone());
        Ok(t)
    }
}

impl crate::gpu::Stage for RayCaster {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        RayCaster::new(device)
    }
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
