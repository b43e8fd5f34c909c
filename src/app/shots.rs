//! The viewer's side of screenshots: asked for, tiled through [`super::screenshot`],
//! written by a worker, retried after a failed write.

use super::document::file_name;
use super::jobs::Job;
use super::screenshot::*;
use super::{ShotSize, Viewer};
use crate::render::Frame;
use std::path::PathBuf;
use std::time::Duration;

impl Viewer {
    /// Advances screenshots: starts a requested one when the view is ready, pumps the
    /// tiles of the one in flight, collects the write.
    pub(super) fn update_screenshots(&mut self) {
        if let Some(job) = &mut self.shots.write_job
            && let Some(result) = job.poll()
        {
            self.shots.write_job = None;
            match result {
                Ok((png, scene)) => {
                    self.shots.failed = None;
                    self.toast(
                        format!(
                            "Screenshot saved: {} (scene: {})",
                            png.display(),
                            scene.display()
                        ),
                        false,
                    );
                    if self.options.screenshot.is_some() && self.options.exit_after_frames.is_some()
                    {
                        self.scripted.exit_requested = true;
                    }
                }
                Err(e) => {
                    let message = e.to_string();
                    self.toast(
                        format!("Screenshot not saved: {message} — use “Save elsewhere…”, the image is kept"),
                        true,
                    );
                    if self.options.exit_after_frames.is_some() {
                        self.fail_exit(message);
                    }
                }
            }
        }
        // The viewport's image must be current: CAO's V_AO is then posed for the shapes
        // the screenshot is clipped with (and the viewport leaves it alone meanwhile).
        if self.shots.pending.is_none()
            && self.opened.load_job.is_none()
            && self.derived_ready()
            && self.viewport.current
            && self.opened.doc.is_some()
            && let Some((path, size)) = self.shots.request.take()
            && let Some(doc) = &self.opened.doc
        {
            {
                let (w, h) = match size {
                    ShotSize::Window => (self.viewport.px.0.max(1), self.viewport.px.1.max(1)),
                    ShotSize::Fixed(w, h) => (w, h),
                };
                if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
                    self.toast(
                        format!(
                            "Screenshot size {w}×{h}: each side must be 1 to {}",
                            MAX_SIDE
                        ),
                        true,
                    );
                } else {
                    let mut scene = doc.scene(w, h, true);
                    if self.shots.transparent {
                        scene.render.background = [0.0; 4];
                    }
                    let frame = Frame {
                        camera: scene.camera,
                        settings: scene.render,
                        width: w,
                        height: h,
                    };
                    let tile = shot_tile(self.viewport.pacer.rate(super::viewport::STRIP));
                    self.shots.pending = Some(PendingShot::new(frame, scene, path, tile));
                }
            }
        }
        if let Some(shot) = &mut self.shots.pending {
            let result = match self.viewport.gpu.for_screenshot() {
                Some((ray_caster, vol, clip)) => shot.pump(&self.gpu, ray_caster, vol, clip),
                None => Err("no volume to render".into()),
            };
            match result {
                Ok(None) => self.ctx.request_repaint_after(Duration::from_millis(5)),
                Ok(Some(done)) => {
                    self.shots.pending = None;
                    self.start_write(done);
                }
                Err(e) => {
                    self.shots.pending = None;
                    self.toast(format!("Screenshot failed: {e}"), true);
                    if self.options.exit_after_frames.is_some() {
                        self.fail_exit(e);
                    }
                }
            }
        }
    }

    pub(super) fn start_write(&mut self, shot: Shot) {
        let label = format!("Saving {}", file_name(&shot.path));
        let kept = shot.clone();
        self.shots.failed = None;
        self.shots.write_job = Some(Job::spawn(label, self.repaint_fn(), move |_| shot.write()));
        // Kept until the write succeeds: a failure loses nothing.
        self.shots.failed = Some(kept);
    }

    /// The next free `volao-N.png` in the screenshot folder (F12).
    pub fn next_screenshot_path(&self) -> PathBuf {
        (1..)
            .map(|n| self.options.screenshot_dir.join(format!("volao-{n}.png")))
            .find(|p| !p.exists() && !scene_path(p).exists())
            .unwrap_or_else(|| self.options.screenshot_dir.join("volao.png"))
    }
}

/// Screenshot tiles of about a tenth of a second each at the viewport's measured ray-cast
/// rate (pixels per second): the UI's frames wait behind one tile at most. A power of two
/// from 256 to [`super::screenshot`]'s largest; the largest before anything was measured.
fn shot_tile(rate: Option<f64>) -> u32 {
    match rate {
        Some(r) if r > 0.0 => {
            let side = (r * 0.1)
                .sqrt()
                .clamp(256.0, crate::render::gpu::TILE as f64) as u32;
            1 << side.ilog2()
        }
        _ => crate::render::gpu::TILE,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn screenshot_tiles_follow_the_measured_rate() {
        use super::shot_tile;
        use crate::render::gpu::TILE;
        assert_eq!(shot_tile(None), TILE);
        // lavapipe on two cores: ~2.4 Mpx/s, a 256² tile takes ~27 ms.
        assert_eq!(shot_tile(Some(2.4e6)), 256);
        assert_eq!(shot_tile(Some(1e7)), 512);
        assert_eq!(shot_tile(Some(1e10)), TILE);
    }
}
