//! Drawing the viewport's last complete image through egui_wgpu's paint callback, as
//! egui's `custom3d_wgpu.rs` does: the long-lived draw pipelines are egui's callback
//! resources ([`ViewportPaint`]); the image to draw comes with each frame's
//! [`ViewportCallback`].

use crate::gpu::{GpuError, shaders, validated};

/// The viewport's draw pipelines, built once and kept in egui_wgpu's callback
/// resources: all that painting needs besides the image.
#[derive(Debug)]
pub struct ViewportPaint {
    /// Draws an image 1:1 (exact) or scaled up (interactive quality).
    pipelines: [wgpu::RenderPipeline; 2],
    /// Fills the callback's rectangle with opaque black (the slice panes' margins:
    /// cheaper on a CPU rasteriser than an egui rectangle, whose shader dithers).
    black: wgpu::RenderPipeline,
}

/// How an image is bound for drawing: the draw pipelines' bind-group layout and their
/// sampler. The viewer keeps it to bind each image it makes.
#[derive(Debug)]
pub struct ImageBinding {
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
}

impl ImageBinding {
    /// The bind group that draws `view`.
    pub fn bind(&self, device: &wgpu::Device, view: &wgpu::TextureView) -> wgpu::BindGroup {
        crate::gpu::bind_group(
            device,
            "Viewport::bind_group",
            &self.layout,
            &[
                wgpu::BindingResource::TextureView(view),
                wgpu::BindingResource::Sampler(&self.sampler),
            ],
        )
    }
}

impl ViewportPaint {
    /// Builds the draw pipelines for egui's render target format, and the binding their
    /// images need.
    pub fn new(
        device: &wgpu::Device,
        target_format: wgpu::TextureFormat,
    ) -> Result<(Self, ImageBinding), GpuError> {
        let module = shaders::module(device, "viewport.wgsl")?;
        validated(device, "Viewport::new", || {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("Viewport::layout"),
                entries: &[
                    crate::gpu::entry::texture(
                        0,
                        wgpu::ShaderStages::FRAGMENT,
                        wgpu::TextureViewDimension::D2,
                        Some(true),
                    ),
                    crate::gpu::entry::sampler(1, wgpu::ShaderStages::FRAGMENT),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("Viewport::pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let no_bindings = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("Viewport::no_bindings"),
                bind_group_layouts: &[],
                immediate_size: 0,
            });
            let srgb = target_format.is_srgb();
            let pipeline_in = |layout: &wgpu::PipelineLayout, fragment: &str| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("Viewport::pipeline"),
                    layout: Some(layout),
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
                })
            };
            let pipeline = |fragment: &str| pipeline_in(&pipeline_layout, fragment);
            let pipelines = match srgb {
                true => [pipeline("fs_srgb"), pipeline("fs_scaled_srgb")],
                false => [pipeline("fs_main"), pipeline("fs_scaled")],
            };
            let binding = ImageBinding {
                layout,
                sampler: crate::gpu::linear_sampler(device, "Viewport::sampler"),
            };
            let black = pipeline_in(&no_bindings, "fs_black");
            (ViewportPaint { pipelines, black }, binding)
        })
    }

    /// Draws `image` into the callback's viewport: 1:1 when it has the viewport's size,
    /// else scaled with bilinear filtering, or with the nearest texel if it asks for it.
    fn paint(
        &self,
        pass: &mut wgpu::RenderPass<'static>,
        image: &PaintImage,
        viewport_px: (u32, u32),
    ) {
        let texels = image.size == viewport_px || image.nearest;
        pass.set_pipeline(&self.pipelines[usize::from(!texels)]);
        pass.set_bind_group(0, &image.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// An image to draw: its bind group ([`ImageBinding::bind`]), its size in pixels and
/// whether it is scaled with the nearest texel (a slice's nearest sampling) rather than
/// bilinear filtering.
#[derive(Debug, Clone)]
pub struct PaintImage {
    pub bind_group: wgpu::BindGroup,
    pub size: (u32, u32),
    pub nearest: bool,
}

/// The per-frame part of the paint callback: where to draw, and the last complete image
/// (`None`: nothing to draw yet).
#[derive(Debug, Clone)]
pub struct ViewportCallback {
    /// The callback's rectangle in points.
    pub rect: egui::Rect,
    pub image: Option<PaintImage>,
}

/// The image size egui will give a paint callback covering `rect` (in points).
pub fn size_in_pixels(rect: egui::Rect, pixels_per_point: f32, screen_px: [u32; 2]) -> (u32, u32) {
    let v = egui::epaint::ViewportInPixels::from_points(&rect, pixels_per_point, screen_px);
    (v.width_px.max(0) as u32, v.height_px.max(0) as u32)
}

impl egui_wgpu::CallbackTrait for ViewportCallback {
    fn paint(
        &self,
        info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        let v = info.viewport_in_pixels();
        let size = (v.width_px.max(0) as u32, v.height_px.max(0) as u32);
        if let (Some(paint), Some(image)) = (resources.get::<ViewportPaint>(), &self.image) {
            paint.paint(pass, image, size);
        }
    }
}

/// Fills its rectangle with opaque black ([`ViewportPaint`]'s `fs_black`).
#[derive(Debug, Clone, Copy)]
pub struct BlackCallback;

impl egui_wgpu::CallbackTrait for BlackCallback {
    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(paint) = resources.get::<ViewportPaint>() {
            pass.set_pipeline(&paint.black);
            pass.draw(0..3, 0..1);
        }
    }
}
