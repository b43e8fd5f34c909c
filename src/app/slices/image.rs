//! A slice pane's image on the GPU, drawn through the 3-D viewport's paint pipelines
//! (`shaders/viewport.wgsl`: one unblended triangle, the nearest texel or bilinear)
//! rather than as an egui textured mesh, and the margins around it black with the same
//! pipelines' `fs_black`. On a CPU rasteriser (lavapipe) egui's fragment shader (sRGB
//! conversions, dithering, blending) over three pane-sized images and their black
//! backgrounds cost more per frame than the 3-D view itself, and still a third of the
//! rasteriser's time for the margins alone (docs/benchmarks.md, slice panes). The
//! image is uploaded only when what it shows changes; each frame draws the texture kept.

use crate::app::viewport::{BlackCallback, ImageBinding, PaintImage, ViewportCallback};
use crate::gpu::Gpu;
use egui::Rect;

/// A slice image's texture and the bind group that draws it.
#[derive(Debug)]
pub(super) struct SliceTexture {
    texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
}

impl SliceTexture {
    /// Uploads `rgb` (`size`, rows top to bottom), into `old`'s texture when it has that
    /// size, else into a new one.
    pub(super) fn upload(
        gpu: &Gpu,
        binding: &ImageBinding,
        old: Option<SliceTexture>,
        size: [usize; 2],
        rgb: &[u8],
    ) -> SliceTexture {
        let [w, h] = size.map(|v| v.max(1) as u32);
        let old = old.filter(|t| t.texture.width() == w && t.texture.height() == h);
        let (texture, bind_group) = match old {
            Some(t) => (t.texture, t.bind_group),
            None => {
                let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("SliceViews::image"),
                    size: wgpu::Extent3d {
                        width: w,
                        height: h,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: crate::app::viewport::IMAGE_FORMAT,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                });
                let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                let bind_group = binding.bind(&gpu.device, &view);
                (texture, bind_group)
            }
        };
        let mut rgba = vec![255u8; (w * h * 4) as usize];
        for (px, c) in rgba.chunks_exact_mut(4).zip(rgb.chunks_exact(3)) {
            px[..3].copy_from_slice(c);
        }
        crate::gpu::write_texture_3d(&gpu.queue, &texture, 0, [w, h, 1], 4, &rgba);
        SliceTexture {
            texture,
            bind_group,
        }
    }

    /// Draws the image into `placed` (points; the nearest texel or bilinear) and paints
    /// the rest of `pane` black.
    pub(super) fn paint(&self, painter: &egui::Painter, pane: Rect, placed: Rect, nearest: bool) {
        for margin in margins(pane, placed) {
            painter.add(egui_wgpu::Callback::new_paint_callback(
                margin,
                BlackCallback,
            ));
        }
        let image = PaintImage {
            bind_group: self.bind_group.clone(),
            size: (self.texture.width(), self.texture.height()),
            nearest,
        };
        painter.add(egui_wgpu::Callback::new_paint_callback(
            placed,
            ViewportCallback {
                rect: placed,
                image: Some(image),
            },
        ));
    }
}

/// The parts of `pane` outside `inner` (a letterboxed image's margins): at most four
/// rectangles, none where `inner` reaches the edge.
fn margins(pane: Rect, inner: Rect) -> Vec<Rect> {
    let inner = inner.intersect(pane);
    let (l, t, r, b) = (pane.left(), pane.top(), pane.right(), pane.bottom());
    [
        Rect::from_min_max(egui::pos2(l, t), egui::pos2(r, inner.top())),
        Rect::from_min_max(egui::pos2(l, inner.bottom()), egui::pos2(r, b)),
        Rect::from_min_max(
            egui::pos2(l, inner.top()),
            egui::pos2(inner.left(), inner.bottom()),
        ),
        Rect::from_min_max(
            egui::pos2(inner.right(), inner.top()),
            egui::pos2(r, inner.bottom()),
        ),
    ]
    .into_iter()
    .filter(|m| m.width() > 0.0 && m.height() > 0.0)
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margins_cover_the_pane_around_the_image_and_nothing_else() {
        let pane = Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(100.0, 60.0));
        let inner = Rect::from_min_max(egui::pos2(20.0, 0.0), egui::pos2(80.0, 60.0));
        let m = margins(pane, inner);
        assert_eq!(m.len(), 2);
        let area: f32 = m.iter().map(|r| r.area()).sum();
        assert_eq!(area, pane.area() - inner.area());
        assert!(m.iter().all(|r| r.intersect(inner).area() <= 0.0));
        assert!(margins(pane, pane).is_empty());
    }
}
