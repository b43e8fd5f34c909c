//! The 3-D viewport: an `egui_wgpu` paint callback that ray-casts the volume with the
//! same [`RayCaster`] and [`GpuVolume`] as `volao render` into a storage texture (a
//! compute pass in `prepare`) and draws that texture 1:1 (`paint`,
//! `shaders/viewport.wgsl`). Same scene, same pixels.
//!
//! [`ViewportGpu`] is the long-lived part and lives in egui_wgpu's callback resources;
//! a [`ViewportCallback`] carries only what changes per frame (the [`Frame`]).

use crate::ao::cao::CaoGpu;
use crate::clip::gpu::ClipMaps;
use crate::gpu::{GpuError, shaders, validated};
use crate::render::Frame;
use crate::render::gpu::{GpuVolume, RayCaster};

/// Format of the ray caster's output (its storage texture is Rgba8Unorm).
pub const IMAGE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Everything the viewport keeps on the GPU between frames.
#[derive(Debug)]
pub struct ViewportGpu {
    pub ray_caster: RayCaster,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    target: Option<Target>,
    /// The volume shown; `None` until the first one is uploaded.
    pub volume: Option<GpuVolume>,
    /// Clip shapes' maps when clipping without CAO.
    pub clip: Option<ClipMaps>,
    /// Contextual AO (LAO with clip shapes): its clip maps clip the picture too.
    pub cao: Option<CaoGpu>,
    /// Bumped by every change to the volume, its transfer function or its AO, so an
    /// unchanged frame is not ray-cast again (egui repaints on every mouse move).
    pub revision: u64,
    drawn: Option<(Frame, u64)>,
    /// The last GPU error while rendering (shown in the status bar).
    pub last_error: Option<String>,
    /// Ray-cast frames encoded so far (for `--exit-after-frames` and statistics).
    pub frames_rendered: u64,
}

#[derive(Debug)]
struct Target {
    texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
}

impl ViewportGpu {
    /// Builds the pipelines; `target_format` is egui's render target format.
    pub fn new(
        device: &wgpu::Device,
        target_format: wgpu::TextureFormat,
    ) -> Result<Self, GpuError> {
        let ray_caster = RayCaster::new(device)?;
        let module = shaders::module(device, "viewport.wgsl")?;
        validated(device, "Viewport::new", || {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Viewport::layout"),
                entries: &[crate::gpu::entry::texture(
                    0,
                    wgpu::ShaderStages::FRAGMENT,
                    wgpu::TextureViewDimension::D2,
                    Some(false),
                )],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("Viewport::pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let fragment = if target_format.is_srgb() {
                "fs_srgb"
            } else {
                "fs_main"
            };
            let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("Viewport::pipeline"),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fragment),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: target_format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
            ViewportGpu {
                ray_caster,
                pipeline,
                layout,
                target: None,
                volume: None,
                clip: None,
                cao: None,
                revision: 0,
                drawn: None,
                last_error: None,
                frames_rendered: 0,
            }
        })
    }

    /// Replaces the volume shown.
    pub fn set_volume(&mut self, volume: GpuVolume) {
        self.volume = Some(volume);
        self.revision += 1;
    }

    /// The clip maps the picture is clipped with: CAO's when it runs, else the plain ones.
    pub fn clip_maps(&self) -> Option<&ClipMaps> {
        self.cao.as_ref().map(|c| &c.clip).or(self.clip.as_ref())
    }

    /// Marks the volume's transfer function or AO as changed.
    pub fn touch(&mut self) {
        self.revision += 1;
    }

    /// Ray-casts `frame` into the target texture unless the same frame of the same
    /// volume revision is already there.
    fn prepare_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        frame: &Frame,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        let Some(volume) = &self.volume else {
            return;
        };
        if self.drawn == Some((*frame, self.revision)) {
            return;
        }
        let size = (frame.width.max(1), frame.height.max(1));
        let same_size = self
            .target
            .as_ref()
            .is_some_and(|t| (t.texture.width(), t.texture.height()) == size);
        if !same_size {
            let texture = crate::gpu::image_texture(
                device,
                "Viewport::image",
                size,
                IMAGE_FORMAT,
                wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            );
            let view = texture.create_view(&Default::default());
            let bind_group = crate::gpu::bind_group(
                device,
                "Viewport::bind_group",
                &self.layout,
                &[wgpu::BindingResource::TextureView(&view)],
            );
            self.target = Some(Target {
                texture,
                bind_group,
            });
        }
        let Some(target) = &self.target else {
            return;
        };
        let clip = self.clip_maps();
        match self.ray_caster.encode_tile(
            (device, queue),
            volume,
            frame,
            clip,
            (&target.texture, (0, 0)),
            encoder,
        ) {
            Ok(()) => {
                self.drawn = Some((*frame, self.revision));
                self.frames_rendered += 1;
                self.last_error = None;
            }
            Err(e) => {
                self.drawn = None;
                self.last_error = Some(e.to_string());
            }
        }
    }

    fn paint(&self, pass: &mut wgpu::RenderPass<'static>) {
        if self.volume.is_none() || self.drawn.is_none() {
            return;
        }
        if let Some(target) = &self.target {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &target.bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
    }
}

/// The per-frame part of the paint callback: the frame to show (its size is replaced by
/// the callback's viewport in physical pixels).
#[derive(Debug, Clone, Copy)]
pub struct ViewportCallback {
    pub frame: Frame,
    /// The callback's rectangle in points (to size the image in physical pixels).
    pub rect: egui::Rect,
}

/// The image size egui will give a paint callback covering `rect` (in points).
pub fn size_in_pixels(rect: egui::Rect, pixels_per_point: f32, screen_px: [u32; 2]) -> (u32, u32) {
    let v = egui::epaint::ViewportInPixels::from_points(&rect, pixels_per_point, screen_px);
    (v.width_px.max(0) as u32, v.height_px.max(0) as u32)
}

impl egui_wgpu::CallbackTrait for ViewportCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        screen: &egui_wgpu::ScreenDescriptor,
        encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let (width, height) =
            size_in_pixels(self.rect, screen.pixels_per_point, screen.size_in_pixels);
        if width == 0 || height == 0 {
            return Vec::new();
        }
        if let Some(v) = resources.get_mut::<ViewportGpu>() {
            let frame = Frame {
                width,
                height,
                ..self.frame
            };
            v.prepare_frame(device, queue, &frame, encoder);
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(v) = resources.get::<ViewportGpu>() {
            v.paint(pass);
        }
    }
}
