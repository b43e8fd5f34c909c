//! The 3-D viewport: the same [`RayCaster`] and [`RenderVolume`] as `volao render`, drawn
//! through an `egui_wgpu` paint callback (`shaders/viewport.wgsl`). Same scene, same
//! pixels.
//!
//! [`ViewportGpu`] is the viewer's own: the ray caster, the volume, CAO and the clip
//! maps, and the image being made. The picture is made off the paint path, in slices
//! (`viewport/pump.rs`): each UI frame submits the part of CAO's update and of the ray
//! cast (in strips of rows) that fits in the [`Pacer`]'s slice into a back image. egui's
//! callback resources hold only the draw pipelines ([`ViewportPaint`]); each frame's
//! [`ViewportCallback`] carries the rectangle to draw into and the last complete image,
//! drawn 1:1 at full quality, scaled up while the view moves at interactive quality.

use super::tiles::{RECENT_TILES, Tile, TileCosts, next_tile};
use crate::ao::cao::{CaoFrame, CaoGpu, CaoMode, CaoStats, Pose};
use crate::clip::ClipShape;
use crate::clip::gpu::ClipMaps;
use crate::clip::gpu::MapRequest;
use crate::gpu::pacer::Pacer;
use crate::gpu::{Gpu, GpuError};
use crate::render::Frame;
use crate::render::gpu::{RayCaster, RenderVolume, Variant};
use crate::render::reuse::{Ball, ImageInputs};
use std::time::Instant;

mod paint;
mod pump;
pub use paint::{
    BlackCallback, ImageBinding, PaintImage, ViewportCallback, ViewportPaint, size_in_pixels,
};

/// Set by the thread building a pipeline: `Some(error)` when it failed.
type Compiled = std::sync::Arc<std::sync::Mutex<Option<Option<String>>>>;

/// Format of the ray caster's output (its storage texture is Rgba8Unorm).
pub const IMAGE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// The viewport's image and the work that makes it, as the viewer drives it: the GPU
/// side, the pacer that budgets it, the interactive quality and the motion that asks for
/// it, the viewport's size and its frame time.
#[derive(Debug)]
pub(super) struct Viewport {
    pub(super) gpu: ViewportGpu,
    /// The per-frame budget of GPU work the viewport may submit.
    pub(super) pacer: Pacer,
    /// Interactive quality while the view moves (the Rendering panel).
    pub(super) interactive: Interactive,
    /// When the view (camera, clip shapes) last changed.
    pub(super) motion: Motion,
    /// The viewport shows the full-quality image of what the document says.
    pub(super) current: bool,
    /// The viewport's size in physical pixels and its rectangle in points, as of the
    /// last frame.
    pub(super) px: (u32, u32),
    pub(super) rect: egui::Rect,
    /// The interval between frames that ray-cast something new (ms, smoothed), and the
    /// images completed as of the last frame.
    pub(super) frame_ms: Option<f32>,
    pub(super) frames_seen: u64,
    /// CAO updates whose figures came back so far (the watchdog's progress).
    pub(super) cao_updates: u64,
}

impl Viewport {
    pub(super) fn new(gpu: ViewportGpu, pacer: Pacer, interactive: Interactive) -> Self {
        Viewport {
            gpu,
            pacer,
            interactive,
            motion: Motion {
                last: None,
                changed_at: Instant::now(),
            },
            current: false,
            px: (0, 0),
            rect: egui::Rect::NOTHING,
            frame_ms: None,
            frames_seen: 0,
            cao_updates: 0,
        }
    }
}

/// The last view wanted and since when.
#[derive(Debug)]
pub(super) struct Motion {
    pub(super) last: Option<(Frame, Vec<ClipShape>)>,
    pub(super) changed_at: Instant,
}

/// Everything the viewport keeps on the GPU between frames.
#[derive(Debug)]
pub struct ViewportGpu {
    /// Shared with the thread that builds a pipeline variant before it is first used.
    pub ray_caster: std::sync::Arc<RayCaster>,
    /// The ray caster's pipeline being built on a worker thread, and how that went.
    compiling: Option<(Variant, Compiled)>,
    /// Binds each image for the paint callback's draw pipelines.
    binding: ImageBinding,
    /// The last complete image and what it shows.
    pub(super) shown: Option<Shown>,
    /// The last complete image of another scale than [`Self::shown`] (the full-quality
    /// one while a drag's interactive images are shown): the next image at its scale
    /// re-casts only what changed since ([`crate::render::reuse`]).
    pub(super) kept: Option<Shown>,
    /// The image being made.
    pub(super) work: Option<Work>,
    /// A texture to reuse for the next image.
    pub(super) spare: Option<Target>,
    /// The strips the ray cast writes before they are copied into the image, one per
    /// height in use.
    pub(super) strips: crate::render::gpu::TileTargets,
    /// What the parts of recent images cost, to cut the next one into tiles that fit.
    tile_costs: TileCosts,
    /// Tiles submitted and not timed yet: tag, image size, step, tile.
    tiles_in_flight: Vec<(u64, (u32, u32), f32, Tile)>,
    /// The next strip's tag.
    next_strip_tag: u64,
    /// The volume shown; `None` until the first one is uploaded.
    pub volume: Option<RenderVolume>,
    /// Clip shapes' maps when clipping without CAO.
    pub clip: Option<ClipMaps>,
    /// Contextual AO (LAO with clip shapes): its clip maps clip the picture too.
    pub(super) cao: Option<CaoGpu>,
    /// Bumped whenever [`Self::cao`] is replaced (a CAO frame belongs to one).
    pub(super) cao_generation: u64,
    /// The shapes the clip maps are posed for; `None`: out of date.
    pub(super) synced_clip: Option<Vec<ClipShape>>,
    /// CAO's update being submitted, behind the images while the view moves.
    pub(super) cao_work: Option<CaoWork>,
    /// The shapes CAO's `V_AO` is exact for: an update for them was submitted whole with
    /// the clip maps posed for them throughout.
    pub(super) ao_exact_for: Option<Vec<ClipShape>>,
    /// A submitted CAO frame whose figures have not come back yet.
    pub(super) stats_pending: Option<CaoFrame>,
    /// Bumped by every change to the volume, its transfer function or its AO, so an
    /// unchanged view is not ray-cast again (egui repaints on every mouse move).
    pub revision: u64,
    /// The last GPU error while rendering (shown in the status bar).
    pub last_error: Option<String>,
    /// Images completed so far (for `--exit-after-frames` and statistics).
    pub frames_rendered: u64,
    /// Of those, images that started as a copy of an earlier one and cast only the rays
    /// near a change ([`crate::render::reuse`]).
    pub frames_reused: u64,
    /// Images made while CAO's update was on its way (reading `V_PAO`) and dropped
    /// unfinished because the next update began and re-posed the clip maps they clipped
    /// with: while shapes only move, none is (each has its own copy of the maps).
    pub frames_dropped_by_cao: u64,
    /// When the last image was started.
    pub(super) last_start: Option<Instant>,
}

/// A texture the ray cast's strips are copied into, and its bind group for drawing.
#[derive(Debug)]
pub(super) struct Target {
    pub(super) texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
}

/// What an image shows: the frame it was cast for (at its own size), the volume
/// revision, the clip shapes' poses, the interactive scale (1: full quality) and whether
/// CAO's `V_AO` was exact for those shapes.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ViewKey {
    pub(super) frame: Frame,
    pub(super) revision: u64,
    pub(super) clip: Vec<ClipShape>,
    pub(super) scale: u32,
    /// False for an image made while CAO's `V_AO` was not exact for its shapes (its
    /// update still on its way): such an image reads `V_PAO` instead, LAO of the
    /// unclipped volume, never a `V_AO` posed for other shapes or half updated.
    pub(super) ao_exact: bool,
}

impl ViewKey {
    /// The same view, whatever the state of the AO.
    fn same_view(&self, other: &ViewKey) -> bool {
        self.frame == other.frame
            && self.revision == other.revision
            && self.clip == other.clip
            && self.scale == other.scale
    }
}

/// CAO's update for a pose of the shapes, submitted piece by piece.
#[derive(Debug)]
pub(super) struct CaoWork {
    /// The [`ViewportGpu::cao_generation`] it belongs to.
    generation: u64,
    clip: Vec<ClipShape>,
    frame: CaoFrame,
    /// The clip maps were posed for other shapes while it was being submitted (for an
    /// image of a shape being dragged): its `V_AO` is not exact for `clip`, and the next
    /// update makes it so.
    tainted: bool,
    /// When it began.
    began: Instant,
    /// An image was shown since it began: from then on it keeps its share of each slice.
    imaged: bool,
}

/// A complete image.
#[derive(Debug)]
pub(super) struct Shown {
    pub(super) target: Target,
    pub(super) key: ViewKey,
    /// What its pixels depend on beyond the view (`None`: they may depend on the shapes
    /// anywhere, so no later image reuses them).
    pub(super) inputs: Option<ImageInputs>,
}

impl ViewportGpu {
    /// Builds the ray caster; its images are bound for drawing with `binding`.
    pub fn new(device: &wgpu::Device, binding: ImageBinding) -> Result<Self, GpuError> {
        let ray_caster = RayCaster::new(device)?;
        Ok(ViewportGpu {
            ray_caster: std::sync::Arc::new(ray_caster),
            compiling: None,
            binding,
            shown: None,
            kept: None,
            work: None,
            spare: None,
            strips: crate::render::gpu::TileTargets::new("Viewport::strip"),
            tile_costs: TileCosts::default(),
            tiles_in_flight: Vec::new(),
            next_strip_tag: 0,
            volume: None,
            clip: None,
            cao: None,
            cao_generation: 0,
            synced_clip: None,
            cao_work: None,
            ao_exact_for: None,
            stats_pending: None,
            revision: 0,
            last_error: None,
            frames_rendered: 0,
            frames_reused: 0,
            frames_dropped_by_cao: 0,
            last_start: None,
        })
    }

    /// The last complete image, for this frame's paint callback.
    pub fn paint_image(&self) -> Option<PaintImage> {
        let shown = self.shown.as_ref()?;
        let t = &shown.target.texture;
        Some(PaintImage {
            bind_group: shown.target.bind_group.clone(),
            size: (t.width(), t.height()),
            nearest: false,
        })
    }

    /// How images are bound for the paint callback's pipelines (the slice panes' too).
    pub fn binding(&self) -> &ImageBinding {
        &self.binding
    }

    /// Replaces the volume shown.
    pub fn set_volume(&mut self, volume: RenderVolume) {
        self.volume = Some(volume);
        self.tile_costs.clear();
        self.set_cao(None);
        self.clip = None;
        self.revision += 1;
    }

    /// Installs (or removes) Contextual AO; its `V_AO` is posed for the shapes by the
    /// next image, which the ray caster then reads.
    pub fn set_cao(&mut self, cao: Option<CaoGpu>) {
        if let (Some(c), Some(v)) = (&cao, &mut self.volume) {
            v.set_ambient_occlusion_view(c.ao_view());
            v.set_ambient_occlusion_stand_in(Some(c.pao_view()));
        }
        self.cao = cao;
        self.cao_generation += 1;
        self.synced_clip = None;
        self.cao_work = None;
        self.ao_exact_for = None;
        self.stats_pending = None;
        self.revision += 1;
    }

    /// Whether Contextual AO is installed.
    pub fn has_cao(&self) -> bool {
        self.cao.is_some()
    }

    /// The clip maps the picture is clipped with: CAO's when it runs, else the plain ones.
    pub fn clip_maps(&self) -> Option<&ClipMaps> {
        self.cao.as_ref().map(|c| &c.clip).or(self.clip.as_ref())
    }

    /// What a screenshot renders with: the ray caster, the volume (reading `V_AO`: a
    /// screenshot waits for a current image, whose `V_AO` is exact, never the stand-in)
    /// and the clip maps; `None` before a volume is uploaded.
    pub(super) fn for_screenshot(
        &mut self,
    ) -> Option<(&RayCaster, &RenderVolume, Option<&ClipMaps>)> {
        self.volume.as_mut()?.read_stand_in(false);
        Some((&*self.ray_caster, self.volume.as_ref()?, self.clip_maps()))
    }

    /// Marks the volume's transfer function or AO as changed.
    pub fn touch(&mut self) {
        self.revision += 1;
    }

    /// A texture of `size` for an image, with its bind group (the spare one if it fits).
    pub(super) fn target(&mut self, device: &wgpu::Device, size: (u32, u32)) -> Target {
        if let Some(t) = self.spare.take()
            && (t.texture.width(), t.texture.height()) == size
        {
            return t;
        }
        let texture = crate::gpu::image_texture(
            device,
            "Viewport::image",
            size,
            IMAGE_FORMAT,
            // COPY_SRC: the next image starts as a copy of this one where it reuses it.
            wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let view = texture.create_view(&Default::default());
        let bind_group = self.binding.bind(device, &view);
        Target {
            texture,
            bind_group,
        }
    }
}

/// Pass label of the viewport's strips (the pacer's rate is in pixels per second).
pub(super) const STRIP: &str = "Viewport::strip";

/// How long after the last change of the view (camera, clip shapes) the full-quality
/// image is made.
pub(super) const INTERACTIVE_REST: std::time::Duration = std::time::Duration::from_millis(250);

/// The smallest interactive image is 1/this of the viewport on each axis.
pub(super) const MAX_INTERACTIVE_SCALE: u32 = 4;

/// Interactive quality: while the view moves, the image is ray-cast at a lower resolution
/// chosen to keep the viewport at `target_fps` (like 3D Slicer's adaptive quality), with
/// a longer step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interactive {
    pub on: bool,
    /// Images per second wanted while the view moves.
    pub target_fps: f32,
    /// The step of a reduced image, in steps of the full-quality image (1: the same);
    /// its opacity is corrected for it, so the picture keeps its look.
    pub step_factor: f32,
}

/// The longest step of a reduced image, in steps of the full-quality one.
pub const MAX_INTERACTIVE_STEP: f32 = 4.0;

impl Default for Interactive {
    fn default() -> Self {
        Interactive {
            on: true,
            target_fps: 10.0,
            step_factor: 2.0,
        }
    }
}

/// Pixels per second assumed for the ray cast before it was measured: about lavapipe's
/// on two cores for a CPU adapter, a hundred times that for a GPU.
fn first_pixel_rate(gpu: &Gpu) -> f64 {
    match gpu.info.device_type {
        wgpu::DeviceType::Cpu => 3e5,
        _ => 3e7,
    }
}

/// How the clip maps and CAO are posed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ClipSetup {
    /// The volume's bounding radius (mm; sizes planes).
    pub radius: f32,
    /// Depth-map edge in pixels.
    pub resolution: u32,
    pub cao_mode: CaoMode,
}

impl ClipSetup {
    /// The clip maps wanted for `shapes`, dilated by `reach_mm`.
    pub fn maps<'a>(&self, shapes: &'a [ClipShape], reach_mm: f32) -> MapRequest<'a> {
        MapRequest {
            shapes,
            volume_radius: self.radius,
            reach_mm,
            resolution: self.resolution,
        }
    }
}

/// What the viewer wants on screen this frame.
#[derive(Debug, Clone)]
pub(super) struct Want {
    /// The full-quality frame, at the viewport's size in pixels.
    pub frame: Frame,
    pub clip: Vec<ClipShape>,
    pub setup: ClipSetup,
    /// 1: full quality; n: the frame at 1/n of the size, scaled up when drawn.
    pub scale: u32,
    /// The step of a reduced image (`scale` > 1), in steps of the full-quality one.
    pub step_factor: f32,
    /// While CAO's update is on its way, interactive images start at most this often
    /// (the interactive target rate): the GPU's other time goes to the update, which
    /// brings the cut's AO. `None`: as often as they can.
    pub image_interval: Option<std::time::Duration>,
    /// The view (camera, clip shapes) changed in the last [`INTERACTIVE_REST`]: images
    /// follow it while CAO's update is on its way, whatever their scale (a GPU fast
    /// enough for the target rate at full size draws them at scale 1).
    pub moving: bool,
}

/// An image being made.
#[derive(Debug)]
pub(super) struct Work {
    key: ViewKey,
    /// What its pixels depend on beyond the view ([`Shown::inputs`]).
    inputs: Option<ImageInputs>,
    /// Where it changed since the image it started as a copy of: only pixels whose rays
    /// meet these balls are cast (empty: every pixel).
    changed: Vec<Ball>,
    /// The rows to cast (the balls' rectangle on screen; every row without `changed`).
    rows: std::ops::Range<u32>,
    /// The columns whose pixels may be cast, for the pieces' estimates.
    columns: std::ops::Range<u32>,
    /// It started as a copy of an earlier image.
    reused: bool,
    /// The image's own copy of CAO's clip maps, posed for its shapes
    /// ([`ClipMaps::posed`]), when CAO's maps are posed for another update's.
    clip: Option<ClipMaps>,
    target: Target,
    next_row: u32,
    /// The next column of a band of rows being made in tiles (0: none).
    next_column: u32,
    started: Instant,
}

impl Work {
    /// Fraction of the rows submitted, in [0, 1].
    pub(super) fn fraction(&self) -> f32 {
        let done = self.next_row.saturating_sub(self.rows.start) as f32;
        (done / self.rows.len().max(1) as f32).min(1.0)
    }
}

impl CaoWork {
    /// Fraction of its bricks submitted, in [0, 1].
    pub(super) fn fraction(&self) -> f32 {
        let (done, all) = self.frame.progress();
        done as f32 / all.max(1) as f32
    }
}

/// What one frame's pump did, for the viewer to report.
#[derive(Debug, Default)]
pub(super) struct Pumped {
    /// The figures of a CAO frame whose counters came back.
    pub stats: Option<CaoStats>,
    /// Shapes left out by the clip maps, with why.
    pub clip_errors: Vec<String>,
    pub error: Option<String>,
    /// An image was completed: seconds since its work started, and its interactive
    /// scale (1: full size).
    pub completed: Option<(f64, u32)>,
}
