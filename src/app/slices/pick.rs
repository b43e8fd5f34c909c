//! The 3-D view's pick on the GPU ([`RayCaster::encode_pick`]): a shift-click or
//! double-click submits the pixel's ray cast, and later frames read where it stopped
//! once the map has come back, never waiting for it, as screenshots' tiles do.

use crate::gpu::Gpu;
use crate::render::gpu::{PickDraw, PickTarget, RayCaster};
use std::sync::{Arc, Mutex};

/// Whether the readback is mapped: `None` until the map's callback has run.
type MapState = Arc<Mutex<Option<Result<(), String>>>>;

/// A pick submitted and not read yet.
#[derive(Debug)]
pub(super) struct PendingPick {
    target: PickTarget,
    mapped: MapState,
    /// The volume it was cast in (the document's `Arc` address): a pick that comes back
    /// after another volume opened is dropped.
    pub(super) volume: usize,
}

impl PendingPick {
    /// Submits the pick of `draw` (a one-pixel dispatch) and asks for its readback.
    pub(super) fn submit(
        gpu: &Gpu,
        ray_caster: &RayCaster,
        draw: PickDraw<'_>,
        volume: usize,
    ) -> Result<Self, String> {
        let target = PickTarget::new(&gpu.device);
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("SliceViews::pick"),
            });
        ray_caster
            .encode_pick(gpu, draw, &target, &mut encoder)
            .map_err(|e| e.to_string())?;
        gpu.queue.submit([encoder.finish()]);
        let mapped: MapState = Arc::new(Mutex::new(None));
        let m = Arc::clone(&mapped);
        target
            .readback
            .map_async(wgpu::MapMode::Read, .., move |r| {
                if let Ok(mut s) = m.lock() {
                    *s = Some(r.map_err(|e| e.to_string()));
                }
            });
        Ok(PendingPick {
            target,
            mapped,
            volume,
        })
    }

    /// `None` while the GPU has not answered; then the picked point (volume-centred
    /// mm, `None` if the ray never reached the opacity) or the readback's error.
    pub(super) fn poll(&self, gpu: &Gpu) -> Option<Result<Option<glam::Vec3>, String>> {
        let _ = gpu.device.poll(wgpu::PollType::Poll);
        let state = self.mapped.lock().ok()?.clone()?;
        Some(state.and_then(|()| {
            let bytes = self
                .target
                .readback
                .slice(..)
                .get_mapped_range()
                .map_err(|e| e.to_string())?;
            Ok(PickTarget::decode(&bytes))
        }))
    }
}

/// The pixel of a `size` image filling `rect` under point `p` (clamped to the image).
pub fn pixel_under(rect: egui::Rect, p: egui::Pos2, size: (u32, u32)) -> (u32, u32) {
    let at = |v: f32, lo: f32, len: f32, n: u32| {
        (((v - lo) / len.max(1e-3)) * n as f32).clamp(0.0, n.max(1) as f32 - 1.0) as u32
    };
    (
        at(p.x, rect.left(), rect.width(), size.0),
        at(p.y, rect.top(), rect.height(), size.1),
    )
}
