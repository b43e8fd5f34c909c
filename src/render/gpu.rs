//! The GPU ray caster: [`RayCaster`] holds what lives as long as the device (pipeline,
//! layout, sampler); [`RenderVolume`] holds one volume's textures and its transfer function;
//! a [`Frame`] is all that changes per frame.

pub use super::gpu_volume::RenderVolume;
use super::reuse::Ball;
pub use super::variant::Variant;
use super::{Frame, Image, RaycastParams, TileAt};
use crate::ao::view::{Marking, ViewMask};
use crate::gpu::{
    Gpu, GpuError, bind_group, copy_texture_out, read_buffer, shaders, texture_readback,
    uniform_buffer, unpad, validated,
};
use crate::texels::gpu_data::VolumeMap;
use crate::texels::reader::{self, Reading, SegmentBindings, VOLUME_GROUP};

/// Largest tile rendered in one submission: keeps each dispatch short (no driver
/// watchdog on real GPUs) and lets any image size fit the 2-D texture limit.
pub const TILE: u32 = 2048;

pub use crate::texels::MAX_VOLUME_BYTES;

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
    /// The volume reader's group (`volume.wgsl`).
    volume_layout: wgpu::BindGroupLayout,
    placeholders: super::extras::Placeholders,
    surfaces: super::surface::SurfaceRenderer,
    /// Binding 8 of pipelines that do not pick (they never write it).
    no_pick: wgpu::Buffer,
}

/// One frame to ray cast and read back ([`RayCaster::render`] and its variants).
#[derive(Debug, Clone, Copy)]
struct FrameDraw<'a> {
    volume: &'a RenderVolume,
    frame: &'a Frame,
    clip: Option<&'a crate::clip::gpu::ClipMaps>,
    /// The pipeline to draw with; `None`: the frame's own ([`Variant::of`]).
    variant: Option<Variant>,
    /// An image of the same view and the balls outside which this frame's inputs are
    /// the same ([`RayCaster::render_reusing`]).
    previous: Option<(&'a Image, &'a [Ball])>,
    /// A visibility pass ([`RayCaster::mark_view`]): where its AO reads mark voxels.
    marks: Option<Marks<'a>>,
}

/// What a tile's dispatch writes or reads besides its image: the frame's rasterised
/// surfaces, a visibility pass's marks, a pick's output.
#[derive(Debug, Clone, Copy, Default)]
struct Outputs<'a> {
    layer: Option<&'a super::surface::SurfaceLayer>,
    marks: Option<Marks<'a>>,
    picked: Option<&'a wgpu::Buffer>,
}

impl<'a> Outputs<'a> {
    /// The surfaces alone (an image).
    fn layer(layer: Option<&'a super::surface::SurfaceLayer>) -> Self {
        Outputs {
            layer,
            ..Default::default()
        }
    }
}

/// Where a visibility pass marks the voxels its AO reads weigh, and how.
#[derive(Debug, Clone, Copy)]
struct Marks<'a> {
    buffer: &'a wgpu::Buffer,
    marking: Marking,
}

/// One tile of one frame to ray cast ([`RayCaster::encode_tile`]).
#[derive(Debug, Clone, Copy)]
pub struct TileDraw<'a> {
    pub volume: &'a RenderVolume,
    pub frame: &'a Frame,
    /// Clip shapes' maps: every sample is tested against them.
    pub clip: Option<&'a crate::clip::gpu::ClipMaps>,
    /// Rgba8Unorm with `STORAGE_BINDING`, the tile's size.
    pub target: &'a wgpu::Texture,
    /// Where the tile sits in the frame.
    pub origin: (u32, u32),
    /// Balls holding every change since the image `target` holds ([`super::reuse`]):
    /// only pixels whose rays meet one are cast, the others keep what `target` holds.
    /// Empty: every pixel is cast.
    pub changed: &'a [Ball],
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
                    entry::sampler(1, c),
                    entry::texture(2, c, D3, Some(true)),
                    entry::texture(3, c, D3, None),
                    entry::storage_texture(4, c, wgpu::TextureFormat::Rgba8Unorm, D2),
                    entry::texture(5, c, D3, Some(true)),
                    entry::texture(6, c, D3, Some(false)),
                    entry::texture(7, c, D3, Some(true)),
                    entry::storage(8, c, false),
                ],
            });
            let clip_layout = crate::clip::gpu::bind_group_layout(device);
            let layout_2 = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RayCaster::layout_2"),
                entries: &super::extras::layout_entries(),
            });
            let volume_layout = reader::layout(device);
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("RayCaster::pipeline_layout"),
                bind_group_layouts: &[
                    Some(&layout),
                    Some(&clip_layout),
                    Some(&layout_2),
                    Some(&volume_layout),
                ],
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
                volume_layout,
                placeholders: super::extras::Placeholders::new(device),
                surfaces,
                no_pick: PickTarget::storage(device, "RayCaster::no_pick"),
            }
        })
    }

    /// Encodes the ray casting of `tile` into `encoder`, with no readback. The viewer
    /// draws the target through a paint callback and copies screenshot tiles out of it
    /// asynchronously; the pixels are those [`Self::render`] reads back for the same frame.
    pub fn encode_tile(
        &self,
        gpu: &Gpu,
        tile: TileDraw<'_>,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let vol = tile.volume;
        // The surfaces, rasterised for the whole frame (submitted before the caller's
        // encoder, so they are ready when the ray cast reads them).
        let layer = self.surface_layer(gpu, vol, tile.frame)?;
        let variant = Variant::of(vol, tile.frame, tile.clip, layer.is_some());
        self.encode(gpu, tile, variant, Outputs::layer(layer.as_ref()), encoder)
    }

    /// `vol`'s surfaces rasterised for `frame` (submitted now, so they are ready when a
    /// ray cast encoded after reads them); `None` without surfaces.
    fn surface_layer(
        &self,
        gpu: &Gpu,
        vol: &RenderVolume,
        frame: &Frame,
    ) -> Result<Option<super::surface::SurfaceLayer>, GpuError> {
        if vol.extras.surfaces.is_empty() {
            return Ok(None);
        }
        let layer = self.surfaces.rasterise(
            (&gpu.device, &gpu.queue),
            &vol.extras.surfaces,
            frame,
            &vol.texels,
        )?;
        Ok(Some(layer))
    }

    /// Encodes the pick of pixel `pixel` of `frame` into `target`: the ray of that pixel,
    /// cast as the image casts it, stops where its opacity first reaches
    /// [`super::cpu::PICK_OPACITY`] ([`PickTarget::read`] says where). Composite frames
    /// only: other modes pick nothing.
    pub fn encode_pick(
        &self,
        gpu: &Gpu,
        draw: PickDraw<'_>,
        target: &PickTarget,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let vol = draw.volume;
        let layer = self.surface_layer(gpu, vol, draw.frame)?;
        let variant = Variant {
            pick: true,
            ..Variant::of(vol, draw.frame, draw.clip, layer.is_some())
        };
        let (x, y) = draw.pixel;
        let (w, h) = (draw.frame.width.max(1), draw.frame.height.max(1));
        let tile = TileDraw {
            volume: vol,
            frame: draw.frame,
            clip: draw.clip,
            target: &target.pixel,
            origin: (x.min(w - 1), y.min(h - 1)),
            changed: &[],
        };
        encoder.clear_buffer(&target.picked, 0, None);
        let outputs = Outputs {
            picked: Some(&target.picked),
            ..Outputs::layer(layer.as_ref())
        };
        self.encode(gpu, tile, variant, outputs, encoder)?;
        encoder.copy_buffer_to_buffer(&target.picked, 0, &target.readback, 0, PICK_BYTES);
        Ok(())
    }

    /// [`Self::encode_pick`], submitted and waited for (tests, the CLI): where the pixel's
    /// ray first reaches the opacity, volume-centred mm, or `None`.
    pub fn pick(&self, gpu: &Gpu, draw: PickDraw<'_>) -> Result<Option<glam::Vec3>, GpuError> {
        let target = PickTarget::new(&gpu.device);
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("RayCaster::pick"),
            });
        self.encode_pick(gpu, draw, &target, &mut encoder)?;
        gpu.queue.submit([encoder.finish()]);
        let bytes = read_buffer(&gpu.device, &target.readback, "RayCaster::pick")?;
        Ok(PickTarget::decode(&bytes))
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

    /// Encodes `tile`'s dispatch with `variant`'s pipeline. Its uniforms and bind groups
    /// are built for it (per-frame data, as rerun's draw data): nothing is cached between
    /// tiles, so nothing can go stale.
    fn encode(
        &self,
        gpu: &Gpu,
        tile: TileDraw<'_>,
        variant: Variant,
        outputs: Outputs<'_>,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let device = &gpu.device;
        let vol = tile.volume;
        let at = TileAt {
            origin: tile.origin,
            gradient_scale: vol.gradient_volume().map_or(0.0, |g| g.scale),
            changed: tile.changed,
        };
        let params = tile.frame.uniforms(&vol.texels, &vol.lut, at);
        let pipeline = self.pipeline(device, variant)?;
        let clip_group = tile.clip.map(|c| c.bind_group(device, &self.clip_layout));
        let clip_group = clip_group.as_ref().unwrap_or(&self.no_clip);
        let (tw, th) = (tile.target.width(), tile.target.height());
        validated(device, "RayCaster::encode_tile", || {
            let picked = outputs.picked.unwrap_or(&self.no_pick);
            let [group, group_2, group_3] = self.bind_groups(gpu, &tile, &params, outputs, picked);
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("RayCaster::encode_tile"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.set_bind_group(1, clip_group, &[]);
            pass.set_bind_group(2, &group_2, &[]);
            pass.set_bind_group(VOLUME_GROUP, &group_3, &[]);
            pass.dispatch_workgroups(tw.div_ceil(8), th.div_ceil(8), 1);
        })
    }

    /// `tile`'s bind groups 0 (its uniforms `params`, AO, occupancy, target, modulation,
    /// block ranges, gradient, the pick's output), 2 (extras) and 3 (the volume and the
    /// table for the frame's step, `volume.wgsl`).
    fn bind_groups(
        &self,
        gpu: &Gpu,
        tile: &TileDraw<'_>,
        params: &RaycastParams,
        outputs: Outputs<'_>,
        picked: &wgpu::Buffer,
    ) -> [wgpu::BindGroup; 3] {
        let Outputs { layer, marks, .. } = outputs;
        let (device, queue) = (&gpu.device, &gpu.queue);
        let vol = tile.volume;
        let lut = vol.lut_buffer_for(tile.frame.settings.step_voxels);
        let uniform = |label, bytes: &[u8]| uniform_buffer(device, queue, label, bytes);
        let params = uniform("RayCaster::params", bytemuck::bytes_of(params));
        let mut extras = vol.extras.params();
        if let Some(m) = marks {
            extras.marks[0] = m.marking.footprint.code();
            extras.marks[1] = m.marking.edge.max(1) as u32;
        }
        let extras = uniform("RayCaster::extras", bytemuck::bytes_of(&extras));
        let target_view = tile.target.create_view(&Default::default());
        let group = bind_group(
            device,
            "RayCaster::bind_group",
            &self.layout,
            &[
                params.as_entire_binding(),
                wgpu::BindingResource::Sampler(&self.sampler),
                wgpu::BindingResource::TextureView(vol.ao_view_read()),
                wgpu::BindingResource::TextureView(&vol.occupancy_view),
                wgpu::BindingResource::TextureView(&target_view),
                wgpu::BindingResource::TextureView(&vol.modulation_view),
                wgpu::BindingResource::TextureView(&vol.block_range_view),
                wgpu::BindingResource::TextureView(
                    vol.gradient_volume()
                        .map_or(&self.placeholders.texture, |g| &g.view),
                ),
                picked.as_entire_binding(),
            ],
        );
        let group_2 = super::extras::bind_group_2(
            device,
            &self.layout_2,
            &vol.extras,
            &extras,
            (layer, marks.map(|m| m.buffer)),
            &self.placeholders,
            &self.sampler,
        );
        let map = VolumeMap::new(&vol.texels, &vol.lut);
        let segments = SegmentBindings::All(&vol.segments);
        let reading = Reading::sampled(vol.volume_view(), &self.sampler, map, lut, segments);
        let group_3 = reading.bind_group((device, &gpu.queue), "RayCaster", &self.volume_layout);
        [group, group_2, group_3]
    }

    /// Renders a frame in tiles of at most [`TILE`]², with shadow-test clipping against
    /// `clip`'s shapes, and reads it back.
    pub fn render(
        &self,
        gpu: &Gpu,
        vol: &RenderVolume,
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
        vol: &RenderVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        variant: Option<Variant>,
    ) -> Result<Image, GpuError> {
        let draw = FrameDraw {
            volume: vol,
            frame,
            clip,
            variant,
            previous: None,
            marks: None,
        };
        self.render_tiles(gpu, draw)
    }

    /// The visibility pass of view-dependent AO ([`crate::ao::view`]): ray casts `frame`
    /// as [`Self::render`] would once `vol`'s AO is bound, and returns the voxels (or
    /// cells, `marking.edge`) whose AO its reads weigh, under `marking.footprint` (only
    /// [`crate::ao::view::Footprint::Trilinear`] is exact). Nothing is marked for a
    /// mode that reads no AO.
    ///
    /// With `previous` (the pass of an image of the same view, that image, and the balls
    /// holding every change since, as [`Self::render_reusing`] takes them), only the rays
    /// that meet a change are cast and their marks added to the previous pass's: the
    /// other rays read what they read then. A superset of the image's voxels, so exact.
    pub fn mark_view(
        &self,
        gpu: &Gpu,
        vol: &RenderVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        marking: impl Into<Marking>,
        previous: Option<(&ViewMask, &Image, &[Ball])>,
    ) -> Result<ViewMask, GpuError> {
        let marking: Marking = marking.into();
        let (dims, edge) = (vol.texels.dims, marking.edge.max(1));
        if !frame.settings.mode.uses_ao() {
            return Ok(ViewMask::from_words(dims, edge, Vec::new()));
        }
        let previous = previous.filter(|(v, _, _)| (v.dims, v.edge) == (dims, edge));
        let device = &gpu.device;
        let bytes = 4 * crate::ao::view::words_for(dims, edge) as u64;
        let (buffer, readback) = validated(device, "RayCaster::marks", || {
            let usage = wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST;
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("RayCaster::marks"),
                size: bytes,
                usage,
                mapped_at_creation: false,
            });
            let readback = crate::gpu::readback_buffer(device, "RayCaster::marks_readback", bytes);
            (buffer, readback)
        })?;
        if let Some((view, _, _)) = previous {
            gpu.queue
                .write_buffer(&buffer, 0, bytemuck::cast_slice(&view.words));
        }
        let draw = FrameDraw {
            volume: vol,
            frame,
            clip,
            variant: None,
            previous: previous.map(|(_, image, changed)| (image, changed)),
            marks: Some(Marks {
                buffer: &buffer,
                marking,
            }),
        };
        self.render_tiles(gpu, draw)?;
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&buffer, 0, &readback, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        let words = read_buffer(device, &readback, "RayCaster::marks")?;
        Ok(ViewMask::from_words(
            dims,
            edge,
            bytemuck::pod_collect_to_vec(&words),
        ))
    }

    /// [`Self::render`] over `previous`, an image of the same view (camera, size,
    /// settings, volume, transfer function, AO settings) whose inputs differ from this
    /// frame's only inside `changed` ([`super::reuse::ImageInputs::changed`]): only the
    /// pixels whose rays meet one of the balls are cast, within the balls' rectangle on
    /// screen; the others are `previous`'s. The same image as [`Self::render`], bit for
    /// bit (tests/reuse.rs).
    pub fn render_reusing(
        &self,
        gpu: &Gpu,
        vol: &RenderVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        previous: &Image,
        changed: &[Ball],
    ) -> Result<Image, GpuError> {
        let draw = FrameDraw {
            volume: vol,
            frame,
            clip,
            variant: None,
            previous: Some((previous, changed)),
            marks: None,
        };
        self.render_tiles(gpu, draw)
    }

    fn render_tiles(&self, gpu: &Gpu, draw: FrameDraw<'_>) -> Result<Image, GpuError> {
        let FrameDraw {
            volume: vol,
            frame,
            clip,
            variant,
            previous,
            marks,
        } = draw;
        let device = &gpu.device;
        let (w, h) = (frame.width.max(1), frame.height.max(1));
        let (mut image, rect, changed) = match previous {
            Some((old, changed)) if (old.width, old.height) == (w, h) => {
                let rect = super::reuse::screen_rect(frame, &vol.texels, changed);
                (old.clone(), rect, changed)
            }
            _ => {
                let blank = Image {
                    width: w,
                    height: h,
                    pixels: vec![[0; 4]; (w * h) as usize],
                };
                (blank, Some((0, 0, w, h)), &[][..])
            }
        };
        let Some((rx0, ry0, rx1, ry1)) = rect else {
            return Ok(image);
        };
        let layer = self.surface_layer(gpu, vol, frame)?;
        // Tile textures by size, for this frame.
        let mut targets = TileTargets::new("RayCaster::tile");
        let mut y0 = ry0;
        while y0 < ry1 {
            let mut x0 = rx0;
            while x0 < rx1 {
                let (tw, th) = ((rx1 - x0).min(TILE), (ry1 - y0).min(TILE));
                let target = validated(device, "RayCaster::tile", || {
                    targets.of_size(device, (tw, th)).clone()
                })?;
                if !changed.is_empty() {
                    // The pixels no ray meeting a change will overwrite.
                    gpu.queue.write_texture(
                        target.as_image_copy(),
                        bytemuck::cast_slice(&image.crop(x0, y0, tw, th).pixels),
                        wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(tw * 4),
                            rows_per_image: Some(th),
                        },
                        crate::gpu::extent([tw, th, 1]),
                    );
                }
                let (readback, row) =
                    texture_readback(device, "RayCaster::readback", [tw, th, 1], 4);
                let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("RayCaster::tile"),
                });
                let variant = variant.unwrap_or_else(|| match marks {
                    Some(_) => Variant::marking(vol, frame, clip, layer.is_some()),
                    None => Variant::of(vol, frame, clip, layer.is_some()),
                });
                let tile = TileDraw {
                    volume: vol,
                    frame,
                    clip,
                    target: &target,
                    origin: (x0, y0),
                    changed,
                };
                let outputs = Outputs {
                    marks,
                    ..Outputs::layer(layer.as_ref())
                };
                self.encode(gpu, tile, variant, outputs, &mut encoder)?;
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
}

/// One pick to cast ([`RayCaster::encode_pick`]): the pixel `pixel` of `frame`.
#[derive(Debug, Clone, Copy)]
pub struct PickDraw<'a> {
    pub volume: &'a RenderVolume,
    pub frame: &'a Frame,
    pub clip: Option<&'a crate::clip::gpu::ClipMaps>,
    pub pixel: (u32, u32),
}

/// Bytes of the pick's output: `picked` of raycast.wgsl, a `vec4<f32>`.
const PICK_BYTES: u64 = 16;

/// Where a pick is written: the shader's `picked` (position, w = 1 when found), a
/// mappable copy of it, and the one-pixel tile the pick's dispatch draws into.
#[derive(Debug)]
pub struct PickTarget {
    picked: wgpu::Buffer,
    pub readback: wgpu::Buffer,
    pixel: wgpu::Texture,
}

impl PickTarget {
    pub fn new(device: &wgpu::Device) -> Self {
        PickTarget {
            picked: Self::storage(device, "RayCaster::picked"),
            readback: crate::gpu::readback_buffer(device, "RayCaster::pick_readback", PICK_BYTES),
            pixel: crate::gpu::image_texture(
                device,
                "RayCaster::pick_pixel",
                (1, 1),
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::STORAGE_BINDING,
            ),
        }
    }

    fn storage(device: &wgpu::Device, label: &str) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: PICK_BYTES,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// The picked position (volume-centred mm) in `bytes` read from
    /// [`Self::readback`], or `None` when the ray never reached the opacity.
    pub fn decode(bytes: &[u8]) -> Option<glam::Vec3> {
        let v: [f32; 4] = bytemuck::pod_read_unaligned(bytes.get(..PICK_BYTES as usize)?);
        (v[3] > 0.0).then(|| glam::Vec3::new(v[0], v[1], v[2]))
    }
}

/// Textures the ray caster writes tiles into (Rgba8Unorm, `STORAGE_BINDING`), one per
/// size in use: [`RayCaster::render`]'s tiles and the viewer's strips. `COPY_DST`: a
/// tile that re-casts only some pixels starts with the image's own ([`super::reuse`]).
#[derive(Debug)]
pub struct TileTargets {
    label: &'static str,
    textures: Vec<wgpu::Texture>,
}

impl TileTargets {
    /// Sizes kept at a time (a few are in use; past this many the others go).
    const KEPT: usize = 8;

    pub fn new(label: &'static str) -> Self {
        TileTargets {
            label,
            textures: Vec::new(),
        }
    }

    /// The texture of `size`, made if there is none.
    pub fn of_size(&mut self, device: &wgpu::Device, size: (u32, u32)) -> &wgpu::Texture {
        let at = self
            .textures
            .iter()
            .position(|t| (t.width(), t.height()) == size);
        let i = match at {
            Some(i) => i,
            None => {
                if self.textures.len() >= Self::KEPT {
                    self.textures.clear();
                }
                let usage = wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::COPY_DST;
                let format = wgpu::TextureFormat::Rgba8Unorm;
                let texture = crate::gpu::image_texture(device, self.label, size, format, usage);
                self.textures.push(texture);
                self.textures.len() - 1
            }
        };
        &self.textures[i]
    }
}

impl crate::gpu::Stage for RayCaster {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        RayCaster::new(device)
    }
}
