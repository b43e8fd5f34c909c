//! The 3-D viewport: the same [`RayCaster`] and [`GpuVolume`] as `volao render`, drawn
//! through an `egui_wgpu` paint callback (`shaders/viewport.wgsl`). Same scene, same
//! pixels.
//!
//! [`ViewportGpu`] is the long-lived part and lives in egui_wgpu's callback resources.
//! The picture is made off the paint path, in slices (see "making the image in slices" below): each UI
//! frame submits the part of CAO's update and of the ray cast (in strips of rows) that
//! fits in the [`Pacer`]'s slice into a back image, and the
//! paint callback draws the last complete image — 1:1 at full quality, scaled up while
//! the view moves at interactive quality. A [`ViewportCallback`] carries only the
//! rectangle to draw into.

use super::tiles::{RECENT_TILES, Tile, TileCosts, next_tile, strip_texture};
use crate::ao::cao::{CaoFrame, CaoGpu, CaoMode, CaoStats};
use crate::clip::ClipShape;
use crate::clip::gpu::ClipMaps;
use crate::gpu::pacer::Pacer;
use crate::gpu::{Gpu, GpuError, shaders, validated};
use crate::render::Frame;
use crate::render::gpu::{GpuVolume, RayCaster, Variant};
use std::time::Instant;

mod paint;
pub use paint::{ViewportCallback, size_in_pixels};

/// Set by the thread building a pipeline: `Some(error)` when it failed.
type Compiled = std::sync::Arc<std::sync::Mutex<Option<Option<String>>>>;

/// Format of the ray caster's output (its storage texture is Rgba8Unorm).
pub const IMAGE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Everything the viewport keeps on the GPU between frames.
#[derive(Debug)]
pub struct ViewportGpu {
    /// Shared with the thread that builds a pipeline variant before it is first used.
    pub ray_caster: std::sync::Arc<RayCaster>,
    /// The ray caster's pipeline being built on a worker thread, and how that went.
    compiling: Option<(Variant, Compiled)>,
    /// Draws an image 1:1 (exact) or scaled up (interactive quality).
    pipelines: [wgpu::RenderPipeline; 2],
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// The last complete image and what it shows.
    pub(super) shown: Option<Shown>,
    /// The image being made.
    pub(super) work: Option<Work>,
    /// A texture to reuse for the next image.
    pub(super) spare: Option<Target>,
    /// The strips the ray cast writes before they are copied into the image, one per
    /// height in use.
    pub(super) strips: Vec<wgpu::Texture>,
    /// What the parts of recent images cost, to cut the next one into tiles that fit.
    tile_costs: TileCosts,
    /// Tiles submitted and not timed yet: tag, image size, step, tile.
    tiles_in_flight: Vec<(u64, (u32, u32), f32, Tile)>,
    /// The next strip's tag.
    next_strip_tag: u64,
    /// The volume shown; `None` until the first one is uploaded.
    pub volume: Option<GpuVolume>,
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
}

/// The share of a frame's slice kept for CAO's update once it has waited [`CAO_PATIENCE`]
/// behind the images, which come first until then.
const CAO_SHARE: f64 = 0.5;
const CAO_PATIENCE: std::time::Duration = std::time::Duration::from_millis(500);

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
}

/// A complete image.
#[derive(Debug)]
pub(super) struct Shown {
    pub(super) target: Target,
    pub(super) key: ViewKey,
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
            let srgb = target_format.is_srgb();
            let pipeline = |fragment: &str| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
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
                })
            };
            let pipelines = match srgb {
                true => [pipeline("fs_srgb"), pipeline("fs_scaled_srgb")],
                false => [pipeline("fs_main"), pipeline("fs_scaled")],
            };
            ViewportGpu {
                ray_caster: std::sync::Arc::new(ray_caster),
                compiling: None,
                pipelines,
                layout,
                sampler: crate::gpu::linear_sampler(device, "Viewport::sampler"),
                shown: None,
                work: None,
                spare: None,
                strips: Vec::new(),
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
            }
        })
    }

    /// Replaces the volume shown.
    pub fn set_volume(&mut self, volume: GpuVolume) {
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
    pub(super) fn for_screenshot(&mut self) -> Option<(&RayCaster, &GpuVolume, Option<&ClipMaps>)> {
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
            wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let view = texture.create_view(&Default::default());
        let bind_group = crate::gpu::bind_group(
            device,
            "Viewport::bind_group",
            &self.layout,
            &[
                wgpu::BindingResource::TextureView(&view),
                wgpu::BindingResource::Sampler(&self.sampler),
            ],
        );
        Target {
            texture,
            bind_group,
        }
    }
}

// ----- making the image in slices ------------------------------------------------------
//
// Making the viewport's image without ever waiting for the GPU on the UI thread.
//
// Each UI frame the viewer says what it wants on screen ([`Want`]: the frame, the clip
// shapes' poses and the interactive scale) and [`ViewportGpu::pump`] moves one image
// ([`Work`]) towards it, submitting only what fits in the [`Pacer`]'s slice:
//
// 1. when the shapes moved, CAO's update for their new pose ([`CaoGpu::begin`] /
// [`CaoGpu::advance`]: steps IV and V in chunks of bricks) or, without CAO, the clip
// maps re-posed;
// 2. the ray cast of the frame in strips of rows into a back image;
// 3. once every strip is submitted the back image becomes the one drawn. The queue is
// in order, so the paint that follows sees it complete.
//
// An image is consistent with the pose it was made for: its clipping and its `V_AO` come
// from the same CAO frame, and nothing else changes them until it is shown; an image made
// while `V_AO` is not exact for its pose reads `V_PAO` instead. Requests
// coalesce: while an image is made, newer poses only replace the wanted one, and the
// next image is made for the newest (a CAO update is never abandoned half-way, since
// the next one relies on what it restored). A full-quality image still being ray-cast
// when the view moves again is dropped for an interactive one. A change to the volume,
// its transfer function or AO during a ray cast starts the strips again.
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
    /// LAO samples per ray (the clip maps' reach without CAO).
    pub samples: u32,
    /// Depth-map edge in pixels.
    pub resolution: u32,
    pub cao_mode: CaoMode,
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
}

/// An image being made.
#[derive(Debug)]
pub(super) struct Work {
    key: ViewKey,
    target: Target,
    next_row: u32,
    /// The next column of a band of rows being made in tiles (0: none).
    next_column: u32,
    started: Instant,
}

impl Work {
    /// Fraction of the rows submitted, in [0, 1].
    pub(super) fn fraction(&self) -> f32 {
        (self.next_row as f32 / self.key.frame.height.max(1) as f32).min(1.0)
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
    /// An image was completed: seconds since its work started.
    pub completed: Option<f64>,
}

impl ViewportGpu {
    /// What an image made for `want` would show now.
    fn key_of(&self, want: &Want) -> ViewKey {
        let s = want.scale.max(1);
        let mut frame = Frame {
            width: want.frame.width.max(1).div_ceil(s),
            height: want.frame.height.max(1).div_ceil(s),
            ..want.frame
        };
        if s > 1 {
            frame.settings.step_voxels *= want.step_factor.clamp(1.0, MAX_INTERACTIVE_STEP);
        }
        ViewKey {
            frame,
            revision: self.revision,
            clip: want.clip.clone(),
            scale: s,
            ao_exact: true,
        }
    }

    /// Whether an image started now would read an exact `V_AO` for `clip`.
    fn ao_exact(&self, clip: &[ClipShape]) -> bool {
        self.cao.is_none()
            || (self.cao_work.is_none() && self.ao_exact_for.as_deref() == Some(clip))
    }

    /// Whether the image drawn is the full-quality one of `want`.
    pub(super) fn is_current(&self, want: &Want) -> bool {
        self.work.is_none()
            && self.cao_work.is_none()
            && want.scale <= 1
            && self
                .shown
                .as_ref()
                .is_some_and(|s| s.key == self.key_of(want))
    }

    /// Whether an image or CAO's update is being made.
    pub(super) fn working(&self) -> bool {
        self.work.is_some() || self.cao_work.is_some()
    }

    /// How far the image being made is, or else CAO's update (then true), if either is.
    pub(super) fn work_fraction(&self) -> Option<(f32, bool)> {
        match (&self.work, &self.cao_work) {
            (Some(w), _) => Some((w.fraction(), false)),
            (None, Some(c)) => Some((c.fraction(), true)),
            (None, None) => None,
        }
    }

    /// Whether a CAO update is being submitted or its figures have not come back.
    pub(super) fn cao_in_flight(&self) -> bool {
        self.cao_work.is_some() || self.stats_pending.is_some()
    }

    /// Whether the image drawn read an exact `V_AO` for its shapes (false: it read
    /// `V_PAO`, while CAO's update caught up with a shape being dragged).
    pub fn shown_ao_exact(&self) -> bool {
        self.shown.as_ref().is_none_or(|s| s.key.ao_exact)
    }

    /// The interactive scale of the image drawn (1: full quality).
    pub(super) fn shown_scale(&self) -> u32 {
        self.shown.as_ref().map_or(1, |s| s.key.scale)
    }

    /// Moves the viewport's image towards `want` within the pacer's slice (see the
    /// module's documentation). Never waits for the GPU.
    pub(super) fn pump(&mut self, gpu: &Gpu, want: &Want, pacer: &mut Pacer) -> Pumped {
        let mut out = Pumped::default();
        if let (Some(cao), Some(f)) = (&self.cao, &mut self.stats_pending)
            && let Some(result) = cao.poll_stats(f)
        {
            match result {
                Ok(stats) => out.stats = Some(stats),
                Err(e) => out.error = Some(e.to_string()),
            }
            self.stats_pending = None;
        }
        if self.volume.is_none() {
            self.work = None;
            self.cao_work = None;
            return out;
        }
        let key = self.key_of(want);
        if self
            .cao_work
            .as_ref()
            .is_some_and(|c| c.generation != self.cao_generation)
        {
            self.cao_work = None;
            self.synced_clip = None;
        }
        if let Some(w) = &mut self.work {
            if w.key.scale == 1 && key.scale > 1 {
                // The view moves again: an interactive image comes sooner.
                self.work = None;
            } else if w.key.revision != self.revision {
                w.key.revision = self.revision;
                w.next_row = 0;
            }
        }
        // CAO's update for the shapes wanted, unless its V_AO is exact for them already.
        if self.cao.is_some()
            && self.cao_work.is_none()
            && self.ao_exact_for.as_ref() != Some(&key.clip)
        {
            // The update poses the clip maps for these shapes and rewrites V_AO: an image
            // being made for other shapes, or reading V_AO, would mix two poses. It is
            // dropped, and one that reads V_PAO takes its place if the view moves.
            if self
                .work
                .as_ref()
                .is_some_and(|w| w.key.ao_exact || w.key.clip != key.clip)
            {
                self.work = None;
            }
            match self.begin_cao(gpu, &key.clip, want.setup) {
                Ok(errors) => out.clip_errors = errors,
                Err(e) => {
                    out.error = Some(e);
                    return out;
                }
            }
        }
        // An image that reads V_AO is never made while an update is on its way (which
        // rewrites it): dropped above, or started reading V_PAO (`start`).
        debug_assert!(
            self.cao_work.is_none() || self.work.as_ref().is_none_or(|w| !w.key.ao_exact),
            "an image reads a V_AO being updated"
        );
        for (tag, took) in pacer.timed(STRIP) {
            if let Some(i) = self.tiles_in_flight.iter().position(|s| s.0 == tag) {
                let (_, size, step, tile) = self.tiles_in_flight.swap_remove(i);
                self.tile_costs.record(size, step, tile, took.as_secs_f64());
            }
        }
        if self.work.is_none() && self.should_start(&key) {
            match self.start(gpu, key, want) {
                Ok(errors) => out.clip_errors.extend(errors),
                Err(e) => {
                    out.error = Some(e);
                    return out;
                }
            }
        }
        // The image first (the view follows the mouse), then CAO with what is left of
        // the slice, and at least CAO_SHARE of it once the update has waited
        // CAO_PATIENCE: interactive images come every frame while a shape is dragged,
        // and would otherwise leave CAO nothing until the drag stops.
        let waited = |c: &CaoWork| c.began.elapsed() > CAO_PATIENCE;
        let held = match self.cao_work.as_ref().is_some_and(waited) {
            true => pacer.hold(CAO_SHARE),
            false => 0.0,
        };
        let advanced = self.advance(gpu, pacer);
        pacer.release(held);
        match advanced {
            Ok(false) => {}
            Ok(true) => {
                if let Some(w) = self.work.take() {
                    out.completed = Some(w.started.elapsed().as_secs_f64());
                    if let Some(old) = self.shown.take() {
                        self.spare = Some(old.target);
                    }
                    self.shown = Some(Shown {
                        target: w.target,
                        key: w.key,
                    });
                    self.frames_rendered += 1;
                    self.last_error = None;
                }
            }
            Err(e) => {
                self.work = None;
                self.last_error = Some(e.to_string());
                out.error = Some(e.to_string());
            }
        }
        if let Err(e) = self.advance_cao(gpu, pacer) {
            self.cao_work = None;
            self.synced_clip = None;
            self.last_error = Some(e.to_string());
            out.error = Some(e.to_string());
        }
        out
    }

    /// Whether to start an image for `key` now. Not while CAO's update is on its way,
    /// unless the view moves (an interactive image, `key.scale > 1`) and the image drawn
    /// shows another view: dragging a shape, the clipping follows the mouse with
    /// `V_PAO` for AO; at rest the image waits for the exact AO.
    fn should_start(&self, key: &ViewKey) -> bool {
        let shown = self.shown.as_ref().map(|s| &s.key);
        if shown == Some(key) {
            return false;
        }
        if self.cao_work.is_none() {
            return true;
        }
        key.scale > 1 && !shown.is_some_and(|s| s.same_view(key))
    }

    /// Begins CAO's update for `clip` (posing the clip maps for it). Returns the shapes
    /// left out, with why.
    fn begin_cao(
        &mut self,
        gpu: &Gpu,
        clip: &[ClipShape],
        setup: ClipSetup,
    ) -> Result<Vec<String>, String> {
        let (Some(cao), Some(vol)) = (&mut self.cao, &self.volume) else {
            return Ok(Vec::new());
        };
        self.synced_clip = Some(clip.to_vec());
        let reach = cao.reach_mm(&vol.texels);
        let frame = cao
            .begin(
                gpu,
                &vol.texels,
                clip,
                setup.resolution,
                reach,
                setup.cao_mode,
            )
            .map_err(|e| e.to_string())?;
        let errors = frame.clip_errors().to_vec();
        self.cao_work = Some(CaoWork {
            generation: self.cao_generation,
            clip: clip.to_vec(),
            frame,
            tainted: false,
            began: Instant::now(),
        });
        Ok(errors)
    }

    /// Submits what fits of CAO's update; once all of it is submitted, its `V_AO` is
    /// exact for its shapes unless the clip maps moved meanwhile.
    fn advance_cao(&mut self, gpu: &Gpu, pacer: &mut Pacer) -> Result<(), GpuError> {
        let (Some(c), Some(cao)) = (&mut self.cao_work, &self.cao) else {
            return Ok(());
        };
        if !cao.advance(gpu, &mut c.frame, pacer)? {
            return Ok(());
        }
        if let Some(c) = self.cao_work.take() {
            self.ao_exact_for = (!c.tainted).then_some(c.clip);
            self.stats_pending = Some(c.frame);
        }
        Ok(())
    }

    /// Starts an image for `key`: poses CAO or the clip maps when the shapes moved,
    /// allocates the back image. Returns the shapes left out, with why.
    fn start(&mut self, gpu: &Gpu, key: ViewKey, want: &Want) -> Result<Vec<String>, String> {
        if let Some(vol) = &mut self.volume {
            vol.prepare_step(gpu, key.frame.settings.step_voxels);
        }
        let mut errors = Vec::new();
        if self.synced_clip.as_ref() != Some(&key.clip) {
            // Whatever happens, these shapes are done with (an error is not retried).
            self.synced_clip = Some(key.clip.clone());
            let Some(vol) = &self.volume else {
                return Err("no volume".into());
            };
            let setup = want.setup;
            let (maps, reach) = if let Some(cao) = &mut self.cao {
                // Posed for the image of a shape being dragged while CAO's update for
                // an earlier pose is on its way: that update is no longer exact.
                if let Some(c) = &mut self.cao_work
                    && c.clip != key.clip
                {
                    c.tainted = true;
                }
                if self.ao_exact_for.as_ref() != Some(&key.clip) {
                    self.ao_exact_for = None;
                }
                let reach = cao.reach_mm(&vol.texels);
                (Some(&mut cao.clip), reach)
            } else if key.clip.is_empty() {
                self.clip = None;
                (None, 0.0)
            } else {
                if self.clip.is_none() {
                    self.clip = Some(ClipMaps::new(gpu).map_err(|e| e.to_string())?);
                }
                let reach = crate::ao::cao::reach_mm(setup.samples, vol.texels.spacing);
                (self.clip.as_mut(), reach)
            };
            if let Some(maps) = maps {
                let report = maps
                    .update(gpu, &key.clip, setup.radius, reach, setup.resolution)
                    .map_err(|e| e.to_string())?;
                errors = report.errors.iter().map(|e| e.to_string()).collect();
            }
        }
        let key = ViewKey {
            ao_exact: self.ao_exact(&key.clip),
            ..key
        };
        // Without an exact V_AO for these shapes the image reads V_PAO (the stand-in
        // set with CAO), so that its AO and its clipping never come from two poses.
        if let Some(vol) = &mut self.volume {
            vol.read_stand_in(!key.ao_exact);
        }
        let (width, height) = (key.frame.width, key.frame.height);
        let target = self.target(&gpu.device, (width, height));
        self.work = Some(Work {
            key,
            target,
            next_row: 0,
            next_column: 0,
            started: Instant::now(),
        });
        Ok(errors)
    }

    /// Submits what fits of the image being made, in the pieces [`next_tile`] cuts (each
    /// costed by [`TileCosts`], else the pacer's mean rate); true once all is submitted.
    fn advance(&mut self, gpu: &Gpu, pacer: &mut Pacer) -> Result<bool, crate::gpu::GpuError> {
        let ViewportGpu {
            work,
            cao,
            volume,
            clip,
            ray_caster,
            strips,
            compiling,
            tile_costs,
            tiles_in_flight,
            next_strip_tag,
            ..
        } = self;
        let (Some(w), Some(vol)) = (work.as_mut(), volume.as_ref()) else {
            return Ok(false);
        };
        let clip = cao.as_ref().map(|c| &c.clip).or(clip.as_ref());
        let (width, height) = (w.key.frame.width, w.key.frame.height);
        // A pipeline variant not built yet compiles on a worker thread (~0.1 s on
        // lavapipe), not in the UI's frame; the image waits for it.
        let surfaces = !vol.extras.surfaces.is_empty();
        let variant = Variant::of(vol, &w.key.frame, clip, surfaces);
        if !ray_caster.has_pipeline(variant) {
            match compiling {
                Some((v, state)) if *v == variant => {
                    let failed = state.lock().ok().and_then(|s| s.clone());
                    match failed {
                        // Still compiling.
                        None => return Ok(false),
                        // It failed there: the ray cast below builds it again and
                        // reports the error.
                        Some(_) => *compiling = None,
                    }
                }
                _ => {
                    let state: Compiled = Default::default();
                    let (rc, device, s) = (
                        std::sync::Arc::clone(ray_caster),
                        gpu.device.clone(),
                        std::sync::Arc::clone(&state),
                    );
                    let spawned = std::thread::Builder::new()
                        .name("volao-pipeline".into())
                        .spawn(move || {
                            let r = rc.build_pipeline(&device, variant);
                            if let Ok(mut s) = s.lock() {
                                *s = Some(r.err().map(|e| e.to_string()));
                            }
                        });
                    if spawned.is_ok() {
                        *compiling = Some((variant, state));
                        return Ok(false);
                    }
                }
            }
        }
        // An image reads V_AO only when it is exact for its shapes, else V_PAO.
        debug_assert!(
            cao.is_none() || vol.reads_stand_in() != w.key.ao_exact,
            "an image reads the wrong AO volume"
        );
        let pixel_rate = pacer.rate(STRIP).unwrap_or_else(|| first_pixel_rate(gpu));
        let step = w.key.frame.settings.step_voxels;
        let estimate = |t: Tile| {
            tile_costs
                .estimate((width, height), step, t)
                .unwrap_or_else(|| {
                    ((t.2.min(width - t.0) * t.3.min(height - t.1)) as f64) / pixel_rate
                })
        };
        while w.next_row < height {
            let (x0, y0) = (w.next_column, w.next_row);
            let idle = pacer.has_time() && !pacer.busy();
            let slice = (pacer.slice.as_secs_f64(), pacer.left());
            let Some(tile) = next_tile((width, (x0, y0)), slice, idle, estimate) else {
                return Ok(false);
            };
            let (tx, ty, tw, th) = tile;
            let strip = strip_texture(strips, &gpu.device, ((tw, th), IMAGE_FORMAT));
            let tag = *next_strip_tag;
            *next_strip_tag += 1;
            let (cw, ch) = (tw.min(width - tx), th.min(height - ty));
            pacer.submit_estimated(
                gpu,
                (STRIP, (cw * ch) as u64),
                (estimate(tile), tag),
                || -> Result<(), crate::gpu::GpuError> {
                    let mut encoder = gpu.device.create_command_encoder(&Default::default());
                    ray_caster.encode_tile(
                        (&gpu.device, &gpu.queue),
                        vol,
                        &w.key.frame,
                        clip,
                        (strip, (tx, ty)),
                        &mut encoder,
                    )?;
                    encoder.copy_texture_to_texture(
                        strip.as_image_copy(),
                        wgpu::TexelCopyTextureInfo {
                            texture: &w.target.texture,
                            mip_level: 0,
                            origin: wgpu::Origin3d { x: tx, y: ty, z: 0 },
                            aspect: wgpu::TextureAspect::All,
                        },
                        wgpu::Extent3d {
                            width: cw,
                            height: ch,
                            depth_or_array_layers: 1,
                        },
                    );
                    gpu.queue.submit([encoder.finish()]);
                    Ok(())
                },
            )?;
            tiles_in_flight.push((tag, (width, height), step, tile));
            if tiles_in_flight.len() > 4 * RECENT_TILES {
                // Never timed (the pacer was replaced): forgotten.
                tiles_in_flight.remove(0);
            }
            if tx + tw >= width {
                w.next_column = 0;
                w.next_row += th;
            } else {
                w.next_column = tx + tw;
            }
        }
        Ok(true)
    }
}
