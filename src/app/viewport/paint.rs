//! Drawing the viewport's last complete image through egui_wgpu's paint callback.

use super::ViewportGpu;

impl ViewportGpu {
    /// Draws the last complete image into the callback's viewport: 1:1 when it has the
    /// viewport's size, else scaled up with bilinear filtering.
    fn paint(&self, pass: &mut wgpu::RenderPass<'static>, viewport_px: (u32, u32)) {
        let Some(shown) = &self.shown else {
            return;
        };
        let t = &shown.target.texture;
        let exact = (t.width(), t.height()) == viewport_px;
        pass.set_pipeline(&self.pipelines[usize::from(!exact)]);
        pass.set_bind_group(0, &shown.target.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The per-frame part of the paint callback: where to draw.
#[derive(Debug, Clone, Copy)]
pub struct ViewportCallback {
    /// The callback's rectangle in points.
    pub rect: egui::Rect,
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
        if let Some(vp) = resources.get::<ViewportGpu>() {
            vp.paint(pass, size);
        }
    }
}
