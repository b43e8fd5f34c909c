//! Screenshots for reports: the current view rendered offscreen at any size, written as
//! PNG with the scene beside it (`NAME.json`), so `volao render NAME.json` reproduces it.
//!
//! Nothing here waits for the GPU on the UI thread. A [`PendingShot`] encodes one tile
//! (at most [`TILE`]²) at a time with [`RayCaster::encode_tile`], copies it into a
//! mapped-on-completion buffer and checks each UI frame whether the map finished; the
//! finished image is written by a worker thread ([`super::jobs::Job`]). The viewer's side
//! (a request waits for the volume and its derived volumes, then pumps and writes) is at
//! the end of this file.

use super::jobs::Job;
use crate::clip::gpu::ClipMaps;
use crate::gpu::{Gpu, padded_row_bytes, readback_buffer};
use crate::render::gpu::{RayCaster, RenderVolume, TILE, TileDraw};
use crate::render::{Frame, Image};
use crate::scene::Scene;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Screenshot size choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShotSize {
    /// The viewport's size in pixels.
    Window,
    Fixed(u32, u32),
}

/// Sizes offered besides the window's own.
pub const PRESET_SIZES: [(u32, u32); 4] = [(1920, 1080), (2560, 1440), (3840, 2160), (7680, 4320)];

/// Largest side accepted (as `volao render`).
pub const MAX_SIDE: u32 = 32768;

/// The scene file written beside `png`: the same name with `.json`.
pub fn scene_path(png: &Path) -> PathBuf {
    png.with_extension("json")
}

/// A finished screenshot waiting to be written (kept after a failed write, so a retry
/// elsewhere loses nothing).
#[derive(Debug, Clone)]
pub struct Shot {
    pub image: Image,
    pub scene: Scene,
    pub path: PathBuf,
}

impl Shot {
    /// Writes the PNG and the scene beside it. Returns both paths.
    pub fn write(&self) -> Result<(PathBuf, PathBuf), String> {
        self.image.save_png(&self.path).map_err(|e| e.to_string())?;
        let scene = scene_path(&self.path);
        self.scene.save(&scene).map_err(|e| e.to_string())?;
        Ok((self.path.clone(), scene))
    }
}

type MapState = Arc<Mutex<Option<Result<(), String>>>>;

#[derive(Debug)]
struct TileInFlight {
    origin: (u32, u32),
    size: (u32, u32),
    row: u32,
    buffer: wgpu::Buffer,
    mapped: MapState,
}

/// A screenshot being rendered tile by tile.
#[derive(Debug)]
pub struct PendingShot {
    frame: Frame,
    scene: Scene,
    path: PathBuf,
    image: Image,
    tiles: Vec<(u32, u32)>,
    /// Edge of the tiles (one submission each).
    tile: u32,
    next: usize,
    in_flight: Option<TileInFlight>,
}

impl PendingShot {
    /// Plans the tiles of `frame` (whose size is the screenshot's), of at most `tile`²
    /// pixels (at most [`TILE`]): one tile is one submission, which the UI's frames wait
    /// behind.
    pub fn new(frame: Frame, scene: Scene, path: PathBuf, tile: u32) -> Self {
        let (w, h) = (frame.width.max(1), frame.height.max(1));
        let tile = tile.clamp(1, TILE);
        let tiles = (0..h.div_ceil(tile))
            .flat_map(|ty| (0..w.div_ceil(tile)).map(move |tx| (tx * tile, ty * tile)))
            .collect();
        PendingShot {
            frame,
            scene,
            path,
            image: Image {
                width: w,
                height: h,
                pixels: vec![[0; 4]; (w as usize) * (h as usize)],
            },
            tiles,
            tile,
            next: 0,
            in_flight: None,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Fraction of tiles done.
    pub fn fraction(&self) -> f32 {
        self.next
            .saturating_sub(usize::from(self.in_flight.is_some())) as f32
            / self.tiles.len().max(1) as f32
    }

    /// Advances without blocking: collects a finished tile, submits the next one.
    /// Returns the finished shot once every tile is in.
    pub fn pump(
        &mut self,
        gpu: &Gpu,
        ray_caster: &RayCaster,
        volume: &RenderVolume,
        clip: Option<&ClipMaps>,
    ) -> Result<Option<Shot>, String> {
        let _ = gpu.device.poll(wgpu::PollType::Poll);
        if let Some(t) = &self.in_flight {
            let state = t.mapped.lock().map_err(|e| e.to_string())?.clone();
            match state {
                None => return Ok(None),
                Some(Err(e)) => return Err(format!("reading the screenshot back failed: {e}")),
                Some(Ok(())) => {
                    self.collect()?;
                }
            }
        }
        if self.next == self.tiles.len() {
            let image = Image {
                width: self.image.width,
                height: self.image.height,
                pixels: std::mem::take(&mut self.image.pixels),
            };
            return Ok(Some(Shot {
                image,
                scene: self.scene.clone(),
                path: self.path.clone(),
            }));
        }
        self.submit(gpu, ray_caster, volume, clip)?;
        Ok(None)
    }

    fn submit(
        &mut self,
        gpu: &Gpu,
        ray_caster: &RayCaster,
        volume: &RenderVolume,
        clip: Option<&ClipMaps>,
    ) -> Result<(), String> {
        let (x0, y0) = self.tiles[self.next];
        let size = (
            (self.image.width - x0).min(self.tile),
            (self.image.height - y0).min(self.tile),
        );
        let device = &gpu.device;
        let texture = crate::gpu::image_texture(
            device,
            "Screenshot::tile",
            size,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        let row = padded_row_bytes(size.0 * 4);
        let buffer = readback_buffer(device, "Screenshot::readback", row as u64 * size.1 as u64);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("Screenshot::tile"),
        });
        ray_caster
            .encode_tile(
                gpu,
                TileDraw {
                    volume,
                    frame: &self.frame,
                    clip,
                    target: &texture,
                    origin: (x0, y0),
                    changed: &[],
                },
                &mut encoder,
            )
            .map_err(|e| e.to_string())?;
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(size.1),
                },
            },
            wgpu::Extent3d {
                width: size.0,
                height: size.1,
                depth_or_array_layers: 1,
            },
        );
        gpu.queue.submit([encoder.finish()]);
        let mapped: MapState = Arc::new(Mutex::new(None));
        let m = Arc::clone(&mapped);
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            if let Ok(mut s) = m.lock() {
                *s = Some(r.map_err(|e| e.to_string()));
            }
        });
        self.in_flight = Some(TileInFlight {
            origin: (x0, y0),
            size,
            row,
            buffer,
            mapped,
        });
        self.next += 1;
        Ok(())
    }

    fn collect(&mut self) -> Result<(), String> {
        let Some(t) = self.in_flight.take() else {
            return Ok(());
        };
        {
            let bytes = t
                .buffer
                .slice(..)
                .get_mapped_range()
                .map_err(|e| e.to_string())?;
            let (w, h) = t.size;
            for y in 0..h {
                let src = &bytes[(y * t.row) as usize..][..(w * 4) as usize];
                let start = ((t.origin.1 + y) * self.image.width + t.origin.0) as usize;
                for (x, px) in src.chunks_exact(4).enumerate() {
                    self.image.pixels[start + x] = [px[0], px[1], px[2], px[3]];
                }
            }
        }
        t.buffer.unmap();
        Ok(())
    }
}

// ----- the viewer's screenshots ---------------------------------------------------------

/// The viewer's screenshots: the choices in the panel, a request waiting for the view to
/// be ready, the shot being rendered, the one being written and one whose write failed.
#[derive(Debug)]
pub(super) struct Screenshots {
    pub(super) size: ShotSize,
    pub(super) transparent: bool,
    pub(super) request: Option<(PathBuf, ShotSize)>,
    pub(super) pending: Option<PendingShot>,
    pub(super) write_job: Option<Job<(PathBuf, PathBuf)>>,
    /// A screenshot whose write failed, kept for "Save elsewhere…".
    pub(super) failed: Option<Shot>,
}

impl Default for Screenshots {
    fn default() -> Self {
        Screenshots {
            size: ShotSize::Window,
            transparent: false,
            request: None,
            pending: None,
            write_job: None,
            failed: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_image_once() {
        let frame = Frame {
            camera: Default::default(),
            settings: Default::default(),
            width: 7680,
            height: 4320,
        };
        let scene: Scene = serde_json::from_value(serde_json::json!({
            "version": 1,
            "volume": {"path": null},
            "transfer_function": {"name": "t", "opacity": [{"value": 0.0, "alpha": 0.0}],
                                  "color": [{"value": 0.0, "rgb": [1.0, 1.0, 1.0]}]},
            "width": 7680, "height": 4320
        }))
        .expect("scene");
        for (tile, count) in [(TILE, 4 * 3), (4096, 4 * 3), (512, 15 * 9), (1000, 8 * 5)] {
            let shot = PendingShot::new(frame, scene.clone(), "x.png".into(), tile);
            assert_eq!(shot.tiles.len(), count, "{tile}");
            let t = tile.min(TILE);
            let covered: u64 = shot
                .tiles
                .iter()
                .map(|&(x, y)| ((7680 - x).min(t) as u64) * ((4320 - y).min(t) as u64))
                .sum();
            assert_eq!(covered, 7680 * 4320);
        }
        assert_eq!(
            scene_path(Path::new("/a/fig.png")),
            Path::new("/a/fig.json")
        );
    }
}
