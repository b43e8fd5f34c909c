//! The eframe viewer: `volao` opens it on the demo volume, `volao view FILE` on a file.
//!
//! [`Viewer`] owns what the user sees (a [`Document`]: volume, transfer function,
//! camera, AO settings — everything a scene file holds) and the background [`jobs`]
//! (loading, AO precomputation, writing screenshots). The GPU side of the viewport
//! ([`viewport::ViewportGpu`]) lives in egui_wgpu's callback resources and is the same
//! [`RayCaster`](crate::render::gpu::RayCaster) + [`GpuVolume`] pair `volao render`
//! uses, on a device requested with [`crate::gpu::device_descriptor`].
//!
//! The UI thread never waits for the GPU or a file: loads and AO run on worker threads,
//! screenshots are read back asynchronously and written by a worker.

pub mod ao_panel;
pub mod camera_input;
pub mod clip_panel;
mod derived;
pub mod jobs;
pub mod screenshot;
pub mod tf_editor;
pub mod viewport;

use crate::ao::filter::{OpacityModulation, StatisticSource};
use crate::ao::{AoMethod, AoSettings};
use crate::gpu::Gpu;
use crate::render::gpu::GpuVolume;
use crate::render::texels::{UploadLimits, VolumeTexels};
use crate::render::{Camera, Frame, RenderSettings, Shading};
use crate::scene::{Light, MeshSource, RawLayout, SCENE_VERSION, Scene, VolumeSource};
use crate::tf::{Preset, TransferFunction};
use crate::volume::{self, Histogram, LoadOptions, RawOverrides, Stats, Volume};
use derived::{Derived, Polled};
use jobs::{Job, JobError, Progress};
use screenshot::{PendingShot, Shot};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use viewport::{ViewportCallback, ViewportGpu};

/// Edge of the built-in demo volume (the same phantom `volao render` uses without a file).
pub const DEMO_SIZE: usize = 128;

/// Bins of the transfer-function editor's histogram.
const HISTOGRAM_BINS: usize = 256;

/// How long the transfer function must rest before AO is recomputed for it.
const AO_DEBOUNCE: Duration = Duration::from_millis(400);

/// Entries kept in the recent-files list.
const RECENT_MAX: usize = 10;

/// What went wrong starting or running the viewer.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(
        "cannot open the viewer window: {0}. The viewer needs a display (X11 or Wayland); \
         `volao render` works headless"
    )]
    Window(String),
    #[error("the viewer has no wgpu render state (eframe started without its wgpu renderer)")]
    NoWgpu,
    #[error(
        "the viewer got an OpenGL adapter ({0}); volao needs Vulkan, Metal or DX12. \
         On Linux: sudo apt-get install -y mesa-vulkan-drivers libvulkan1"
    )]
    OpenGl(String),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error("screenshot: {0}")]
    Screenshot(String),
}

/// What to open.
#[derive(Debug, Clone)]
pub enum OpenRequest {
    /// The built-in demo volume.
    Demo,
    /// A volume file with the options (raw layout, 4-D frame) to read it.
    Volume { path: PathBuf, options: LoadOptions },
    /// A scene file: its volume, transfer function, camera and settings.
    Scene(PathBuf),
}

impl OpenRequest {
    /// A file dropped or picked: a scene when it ends in `.json`, else a volume.
    pub fn for_path(path: PathBuf) -> Self {
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        {
            OpenRequest::Scene(path)
        } else {
            OpenRequest::Volume {
                path,
                options: LoadOptions::default(),
            }
        }
    }

    fn label(&self) -> String {
        match self {
            OpenRequest::Demo => "the demo volume".into(),
            OpenRequest::Volume { path, .. } | OpenRequest::Scene(path) => file_name(path),
        }
    }
}

/// How the viewer starts.
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    pub open: OpenRequest,
    /// Write a screenshot of the viewport here once `exit_after_frames` frames are drawn.
    pub screenshot: Option<PathBuf>,
    /// Close after this many frames showing the volume (with its AO, if any).
    pub exit_after_frames: Option<u64>,
    /// Where the recent-files list is kept; `None` keeps it in memory only.
    pub recent_file: Option<PathBuf>,
    /// Folder for screenshots taken with the shortcut (F12).
    pub screenshot_dir: PathBuf,
    /// Window size in points.
    pub window_size: [f32; 2],
    /// Edge of the clip shapes' depth maps (rebuilt only when a shape's geometry
    /// changes; moving a shape changes a matrix).
    pub clip_resolution: u32,
    /// Benchmark (`volao view --bench-clip-drag N`): the viewport alone fills the window;
    /// once AO is ready, the first clip shape moves 1 mm every frame for N frames, then the
    /// frame times are printed and the viewer closes.
    pub bench_clip_drag: Option<u64>,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        ViewerOptions {
            open: OpenRequest::Demo,
            screenshot: None,
            exit_after_frames: None,
            recent_file: default_recent_file(),
            screenshot_dir: std::env::current_dir().unwrap_or_else(|_| PathBuf::from(".")),
            window_size: [1280.0, 800.0],
            clip_resolution: crate::clip::gpu::DEFAULT_RESOLUTION,
            bench_clip_drag: None,
        }
    }
}

/// `$XDG_CONFIG_HOME/volao/recent.json` (or `~/.config/volao/recent.json`).
pub fn default_recent_file() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config")))?;
    Some(base.join("volao").join("recent.json"))
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// Everything the viewer shows: what a scene file holds plus the loaded data.
#[derive(Debug, Clone)]
pub struct Document {
    pub source: VolumeSource,
    /// The scene file this came from or was last saved to.
    pub scene_path: Option<PathBuf>,
    pub title: String,
    /// One line on the data: format, dims, spacing, type.
    pub info: String,
    /// The volume in RAS order, kept for AO computation.
    pub volume: Arc<Volume>,
    pub stats: Stats,
    pub histogram: Histogram,
    pub tf: TransferFunction,
    pub camera: Camera,
    pub render: RenderSettings,
    pub ao: AoSettings,
    /// Show the ambient term alone (white transfer-function colours, k = 1, no Phong).
    pub ao_only: bool,
    /// Clip shapes with their poses and modes.
    pub clip_shapes: Vec<crate::clip::ClipShape>,
    /// The scene's light and meshes (paths resolved), saved again with it.
    pub light: Light,
    pub meshes: Vec<MeshSource>,
    /// Bounding-sphere radius of the volume in mm (camera pan speed).
    pub radius: f32,
    /// How many times the volume was halved to fit the GPU.
    pub downsampled: u32,
}

impl Document {
    /// The transfer function the viewport uses (white in the "AO only" view).
    pub fn view_tf(&self) -> TransferFunction {
        let mut tf = self.tf.clone();
        if self.ao_only {
            for c in &mut tf.color {
                c.rgb = [1.0; 3];
            }
        }
        tf
    }

    /// The render settings the viewport uses.
    pub fn view_settings(&self) -> RenderSettings {
        let mut s = self.render;
        // As `volao render` does: a headlight's shadows fall from the eye's direction.
        s.light_direction = match self.light {
            Light::Directional { direction } => direction,
            Light::Headlight => self.camera.backward().to_array(),
        };
        if self.ao_only {
            s.ambient = 1.0;
            s.shading = Shading::None;
        }
        s
    }

    /// The scene of this view at `width`×`height`. With `as_shown`, the "AO only" view is
    /// written out as the transfer function and settings that produce it, so `volao
    /// render` reproduces the picture.
    pub fn scene(&self, width: u32, height: u32, as_shown: bool) -> Scene {
        let (tf, render) = if as_shown {
            (self.view_tf(), self.view_settings())
        } else {
            (self.tf.clone(), self.render)
        };
        Scene {
            version: SCENE_VERSION,
            volume: self.source.clone(),
            transfer_function: tf,
            camera: self.camera,
            light: self.light,
            render,
            width: width.max(1),
            height: height.max(1),
            ambient_occlusion: self.ao,
            clip_shapes: self.clip_shapes.clone(),
            meshes: self.meshes.clone(),
        }
    }
}

/// A loaded document with its volume uploaded (the result of a load job).
#[derive(Debug)]
pub struct LoadedDocument {
    pub doc: Document,
    pub gpu_volume: GpuVolume,
    pub warnings: Vec<String>,
}

/// Reads and uploads what `request` names (runs on a worker thread).
pub fn load_document(
    gpu: &Gpu,
    request: &OpenRequest,
    progress: &Progress,
) -> Result<LoadedDocument, String> {
    let (scene, scene_path) = match request {
        OpenRequest::Scene(p) => (
            Some(Scene::load(p).map_err(|e| e.to_string())?),
            Some(p.clone()),
        ),
        _ => (None, None),
    };
    let (path, options) = match (request, &scene, &scene_path) {
        (OpenRequest::Volume { path, options }, _, _) => (Some(path.clone()), options.clone()),
        (OpenRequest::Scene(_), Some(s), Some(sp)) => (
            s.volume_path(sp),
            LoadOptions {
                frame: s.volume.frame,
                raw: s
                    .volume
                    .raw
                    .as_ref()
                    .map(RawOverrides::from)
                    .unwrap_or_default(),
                max_bytes: None,
                series: None,
            },
        ),
        _ => (None, LoadOptions::default()),
    };
    let mut warnings = Vec::new();
    let (volume, info) = match &path {
        Some(p) => {
            let loaded = volume::load_with_progress(p, &options, &mut |done, total| {
                progress.set(done, total.max(1));
            })
            .map_err(|e| e.to_string())?;
            warnings.extend(
                loaded
                    .warnings
                    .iter()
                    .map(|w| format!("{}: {w}", p.display())),
            );
            let info = loaded.format.to_string();
            (loaded.volume, info)
        }
        None => (
            volume::demo::head_phantom(DEMO_SIZE),
            volume::Format::Demo.to_string(),
        ),
    };
    progress.check();
    let volume = volume.to_ras();
    let stats = volume.stats();
    let histogram = volume.histogram(HISTOGRAM_BINS, &stats);
    progress.check();
    let tf = match &scene {
        Some(s) => s.transfer_function.clone(),
        None => TransferFunction::preset(Preset::default_for(&stats), &stats),
    };
    let render = scene.as_ref().map(|s| s.render).unwrap_or_default();
    // Mesh paths in a scene are relative to it; the document keeps them resolved.
    let (light, meshes, clip_shapes) = match (&scene, &scene_path) {
        (Some(s), Some(sp)) => (s.light, s.meshes_resolved(sp), s.clip_shapes_resolved(sp)),
        _ => Default::default(),
    };
    let info = format!(
        "{info}, {} {}, {} × {} × {} mm",
        volume::fmt_dims(volume.dims),
        volume.data.voxel_type(),
        volume.spacing[0],
        volume.spacing[1],
        volume.spacing[2]
    );
    let limits = gpu.device.limits();
    let texels = VolumeTexels::new(
        &volume,
        UploadLimits {
            max_dim: limits.max_texture_dimension_3d as usize,
            max_bytes: crate::render::gpu::MAX_VOLUME_BYTES,
        },
    );
    let extent = texels.extent();
    let radius = glam::Vec3::from(extent).length() * 0.5;
    let downsampled = texels.downsampled;
    progress.check();
    // Out of GPU memory is an error message, not a crash: catch it in a scope.
    let oom = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let uploaded = GpuVolume::from_texels(gpu, texels, &tf, render.step_voxels);
    if let Some(e) = pollster::block_on(oom.pop()) {
        return Err(format!(
            "the GPU has too little memory for this volume: {e}"
        ));
    }
    let mut gpu_volume = uploaded.map_err(|e| e.to_string())?;
    // A mesh that cannot be read is left out (and kept in the scene), with a warning.
    for m in &meshes {
        match crate::render::surface::load_obj(&m.path, m.rgba) {
            Ok(surface) => gpu_volume.extras.surfaces.push(surface),
            Err(e) => warnings.push(format!("mesh left out: {e}")),
        }
    }
    let title = match &path {
        Some(p) => file_name(p),
        None => "demo head phantom".into(),
    };
    let source = VolumeSource {
        path: path.clone(),
        frame: options.frame,
        raw: (!options.raw.is_empty()).then(|| RawLayout::from(&options.raw)),
    };
    let doc = Document {
        source,
        scene_path,
        title,
        info,
        volume: Arc::new(volume),
        stats,
        histogram,
        tf,
        camera: scene.as_ref().map(|s| s.camera).unwrap_or_default(),
        render,
        ao: scene
            .as_ref()
            .map(|s| s.ambient_occlusion)
            .unwrap_or_default(),
        ao_only: false,
        clip_shapes,
        light,
        meshes,
        radius,
        downsampled,
    };
    Ok(LoadedDocument {
        doc,
        gpu_volume,
        warnings,
    })
}

/// What the AO volume on the GPU was computed for.
#[derive(Debug, Clone, PartialEq)]
struct AoKey {
    settings: AoSettings,
    /// With clip shapes LAO runs as CAO (exact under clipping every frame).
    clipping: bool,
    /// LAO depends on the transfer function's opacity only.
    opacity: Vec<crate::tf::OpacityPoint>,
    doc_generation: u64,
}

/// A finished AO computation.
#[derive(Debug)]
struct AoResult {
    kind: AoData,
    device: String,
    seconds: f64,
}

/// A precomputed AO volume, or CAO with its `V_PAO` ready for per-frame updates.
#[derive(Debug)]
enum AoData {
    Volume(Vec<f32>),
    Cao(Box<crate::ao::cao::CaoGpu>),
}

#[derive(Debug)]
enum AoState {
    /// No AO on the GPU (A = 1).
    Off,
    Computing {
        key: AoKey,
        job: Job<AoResult>,
    },
    Ready {
        key: AoKey,
    },
    Failed {
        key: AoKey,
        message: String,
    },
}

/// What the opacity modulation factors on the GPU were computed for.
#[derive(Debug, Clone, PartialEq)]
struct ModulationKey {
    settings: OpacityModulation,
    /// The opacity points, when the variance is that of the opacity.
    opacity: Option<Vec<crate::tf::OpacityPoint>>,
    doc_generation: u64,
}

/// What the light volume of shadows on the GPU was computed for.
#[derive(Debug, Clone, PartialEq)]
struct LightKey {
    /// Towards the light, volume RAS (a headlight's follows the camera).
    direction: [f32; 3],
    opacity: Vec<crate::tf::OpacityPoint>,
    /// Light passes through what the shapes carve away.
    clip: Vec<crate::clip::ClipShape>,
    doc_generation: u64,
}

/// A message in the corner: where a screenshot went, what failed.
#[derive(Debug, Clone)]
pub struct Toast {
    pub text: String,
    pub error: bool,
    born: Instant,
}

/// What the unsaved-changes prompt is asking about.
#[derive(Debug, Clone)]
enum Pending {
    Quit,
    Open(OpenRequest),
}

/// Screenshot size choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShotSize {
    /// The viewport's size in pixels.
    Window,
    Fixed(u32, u32),
}

/// The viewer application.
pub struct Viewer {
    gpu: Arc<Gpu>,
    render_state: egui_wgpu::RenderState,
    ctx: egui::Context,
    options: ViewerOptions,
    doc: Option<Document>,
    doc_generation: u64,
    /// The scene as last loaded or saved (for the unsaved-changes prompt).
    saved: Option<Scene>,
    load_job: Option<Job<LoadedDocument>>,
    ao_state: AoState,
    /// Opacity modulation (Ruiz et al. §4.2) and the light volume of shadows.
    modulation: Derived<ModulationKey>,
    light: Derived<LightKey>,
    /// The light volume last wanted, since when (a headlight's waits for the view to
    /// rest).
    light_wanted: Option<(LightKey, Instant)>,
    /// When the transfer function last changed (AO waits for it to rest).
    tf_changed_at: Instant,
    /// What the viewport's GPU volume has: view TF and step.
    uploaded_tf: Option<(TransferFunction, f32)>,
    ao_seconds: Option<(f64, String)>,
    tf_editor: tf_editor::TfEditor,
    clip_editor: clip_panel::ClipEditor,
    /// The shapes the GPU clips with (and CAO's V_AO was made for); `None`: out of date.
    synced_clip: Option<Vec<crate::clip::ClipShape>>,
    /// The last CAO frame's figures.
    cao_stats: Option<crate::ao::cao::CaoStats>,
    shot_size: ShotSize,
    shot_transparent: bool,
    /// Draw the clip shapes' outlines over the viewport.
    pub show_outlines: bool,
    shot_request: Option<(PathBuf, ShotSize)>,
    pending_shot: Option<PendingShot>,
    write_job: Option<Job<(PathBuf, PathBuf)>>,
    /// A screenshot whose write failed, kept for "Save elsewhere…".
    pub failed_shot: Option<Shot>,
    /// The viewport's size in physical pixels and its rectangle in points, as of the
    /// last frame.
    viewport_px: (u32, u32),
    viewport_rect: egui::Rect,
    toasts: Vec<Toast>,
    recent: Vec<PathBuf>,
    prompt: Option<Pending>,
    quit_confirmed: bool,
    /// GPU errors reported outside any error scope.
    gpu_errors: Arc<Mutex<Vec<String>>>,
    frame_ms: Option<f32>,
    frames_seen: u64,
    /// Frames shown with the volume (and its AO) ready, for `--exit-after-frames`.
    ready_frames: u64,
    exit_requested: bool,
    /// Set when a `--screenshot` could not be written (the process exits non-zero).
    pub exit_error: Arc<Mutex<Option<String>>>,
    last_title: String,
    /// Frame times (s) and CAO shares (%) of `--bench-clip-drag`.
    bench: Vec<(f64, f64)>,
    bench_last: Option<Instant>,
    bench_warmup: u32,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer")
            .field("doc", &self.doc.as_ref().map(|d| &d.title))
            .finish_non_exhaustive()
    }
}

/// The [`Gpu`] of egui's render state: the same device the viewport draws with.
pub fn gpu_of(rs: &egui_wgpu::RenderState) -> Gpu {
    Gpu {
        instance: rs.instance.clone(),
        adapter: rs.adapter.clone(),
        device: rs.device.clone(),
        queue: rs.queue.clone(),
        info: rs.adapter.get_info(),
    }
}

/// eframe's wgpu setup with volao's device: the adapter's limits and the features
/// [`crate::gpu::device_descriptor`] asks for, on the backends [`crate::gpu::instance`]
/// uses (no OpenGL unless `WGPU_BACKEND` says so).
pub fn wgpu_setup() -> egui_wgpu::WgpuSetup {
    let mut setup = egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    if std::env::var_os("WGPU_BACKEND").is_none() {
        setup.instance_descriptor.backends = wgpu::Backends::PRIMARY;
    }
    setup.device_descriptor = Arc::new(crate::gpu::device_descriptor);
    egui_wgpu::WgpuSetup::CreateNew(setup)
}

/// Opens the viewer window and runs until it closes.
pub fn run(options: ViewerOptions) -> Result<(), AppError> {
    let exit_error: Arc<Mutex<Option<String>>> = Arc::new(Mutex::new(None));
    let exit = Arc::clone(&exit_error);
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("volao")
            .with_inner_size(options.window_size)
            .with_drag_and_drop(true),
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: egui_wgpu::WgpuConfiguration {
            wgpu_setup: wgpu_setup(),
            ..Default::default()
        },
        ..Default::default()
    };
    eframe::run_native(
        "volao",
        native,
        Box::new(move |cc| {
            let rs = cc.wgpu_render_state.clone().ok_or(AppError::NoWgpu)?;
            let mut viewer = Viewer::new(&cc.egui_ctx, rs, options)?;
            viewer.exit_error = exit;
            Ok(Box::new(viewer))
        }),
    )
    .map_err(|e| AppError::Window(e.to_string()))?;
    let failure = exit_error.lock().ok().and_then(|mut e| e.take());
    match failure {
        Some(message) => Err(AppError::Screenshot(message)),
        None => Ok(()),
    }
}

impl eframe::App for Viewer {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }
}

impl Viewer {
    /// Builds the viewer on egui's wgpu render state and starts opening `options.open`.
    pub fn new(
        ctx: &egui::Context,
        render_state: egui_wgpu::RenderState,
        options: ViewerOptions,
    ) -> Result<Self, AppError> {
        let gpu = gpu_of(&render_state);
        if gpu.info.backend == wgpu::Backend::Gl && std::env::var_os("VOLAO_ALLOW_GL").is_none() {
            return Err(AppError::OpenGl(gpu.info.name.clone()));
        }
        let viewport = ViewportGpu::new(&gpu.device, render_state.target_format)?;
        render_state
            .renderer
            .write()
            .callback_resources
            .insert(viewport);
        let gpu_errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = Arc::clone(&gpu_errors);
        let repaint = ctx.clone();
        gpu.device
            .on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                if let Ok(mut v) = sink.lock() {
                    v.push(e.to_string());
                }
                repaint.request_repaint();
            }));
        let recent = options
            .recent_file
            .as_deref()
            .map(load_recent)
            .unwrap_or_default();
        let mut viewer = Viewer {
            gpu: Arc::new(gpu),
            render_state,
            ctx: ctx.clone(),
            doc: None,
            doc_generation: 0,
            saved: None,
            load_job: None,
            ao_state: AoState::Off,
            modulation: Derived::default(),
            light: Derived::default(),
            light_wanted: None,
            tf_changed_at: Instant::now(),
            uploaded_tf: None,
            ao_seconds: None,
            tf_editor: Default::default(),
            clip_editor: Default::default(),
            synced_clip: None,
            cao_stats: None,
            shot_size: ShotSize::Window,
            shot_transparent: false,
            show_outlines: true,
            shot_request: None,
            pending_shot: None,
            write_job: None,
            failed_shot: None,
            viewport_px: (0, 0),
            viewport_rect: egui::Rect::NOTHING,
            toasts: Vec::new(),
            recent,
            prompt: None,
            quit_confirmed: false,
            gpu_errors,
            frame_ms: None,
            frames_seen: 0,
            ready_frames: 0,
            exit_requested: false,
            exit_error: Arc::default(),
            last_title: String::new(),
            bench: Vec::new(),
            bench_last: None,
            bench_warmup: 0,
            options: options.clone(),
        };
        viewer.start_load(options.open);
        Ok(viewer)
    }

    // ----- the API the UI and the tests drive -------------------------------------------

    /// Opens a file, scene or the demo; asks first when the current scene has unsaved
    /// changes.
    pub fn open(&mut self, request: OpenRequest) {
        if self.has_unsaved_changes() {
            self.prompt = Some(Pending::Open(request));
        } else {
            self.start_load(request);
        }
    }

    /// The document shown (`None` until the first load finishes).
    pub fn document(&self) -> Option<&Document> {
        self.doc.as_ref()
    }

    /// The document, for edits through the API (marks the transfer function as changed).
    pub fn document_mut(&mut self) -> Option<&mut Document> {
        self.tf_changed_at = Instant::now();
        self.doc.as_mut()
    }

    /// Whether a load, an AO computation or a screenshot is still running.
    pub fn is_busy(&self) -> bool {
        self.load_job.is_some()
            || matches!(self.ao_state, AoState::Computing { .. })
            || self.ao_wanted_but_waiting()
            || !self.modulation_ready() && self.modulation_error().is_none()
            || !self.light_ready() && self.light_error().is_none()
            || self.shot_request.is_some()
            || self.pending_shot.is_some()
            || self.write_job.is_some()
    }

    /// Whether the AO for the current settings is on the GPU (or none is wanted).
    pub fn ao_ready(&self) -> bool {
        match (&self.ao_state, self.ao_key()) {
            (_, None) => true,
            (AoState::Ready { key }, Some(want)) => *key == want,
            _ => false,
        }
    }

    /// Whether the opacity modulation for the current settings is on the GPU (or none is
    /// wanted).
    pub fn modulation_ready(&self) -> bool {
        self.modulation.ready(self.modulation_key().as_ref())
    }

    /// Why the opacity modulation for the current settings failed, if it did.
    pub fn modulation_error(&self) -> Option<&str> {
        self.modulation.error(self.modulation_key().as_ref())
    }

    /// Whether the light volume for the current shadows is on the GPU (or none is
    /// wanted).
    pub fn light_ready(&self) -> bool {
        self.light.ready(self.light_key().as_ref())
    }

    /// Why the light volume for the current shadows failed, if it did.
    pub fn light_error(&self) -> Option<&str> {
        self.light.error(self.light_key().as_ref())
    }

    /// AO, modulation and shadows all computed for what the document says.
    fn derived_ready(&self) -> bool {
        self.ao_ready() && self.modulation_ready() && self.light_ready()
    }

    /// The last AO error, if the current settings failed.
    pub fn ao_error(&self) -> Option<&str> {
        match &self.ao_state {
            AoState::Failed { message, .. } => Some(message),
            _ => None,
        }
    }

    /// Voxels CAO recomputed in its last frame, in percent (`None` without CAO).
    pub fn cao_percent_recomputed(&self) -> Option<f64> {
        self.cao_stats.as_ref().map(|c| c.percent_recomputed())
    }

    pub fn toasts(&self) -> &[Toast] {
        &self.toasts
    }

    pub fn recent_files(&self) -> &[PathBuf] {
        &self.recent
    }

    /// The viewport's size in physical pixels (as of the last frame).
    pub fn viewport_size(&self) -> (u32, u32) {
        self.viewport_px
    }

    /// The viewport's rectangle in points (as of the last frame).
    pub fn viewport_rect(&self) -> egui::Rect {
        self.viewport_rect
    }

    /// The frame the viewport draws, at the viewport's size.
    pub fn view_frame(&self) -> Option<Frame> {
        let doc = self.doc.as_ref()?;
        Some(Frame {
            camera: doc.camera,
            settings: doc.view_settings(),
            width: self.viewport_px.0.max(1),
            height: self.viewport_px.1.max(1),
        })
    }

    /// Whether the scene differs from the one last loaded or saved.
    pub fn has_unsaved_changes(&self) -> bool {
        match (&self.doc, &self.saved) {
            (Some(doc), Some(saved)) => doc.scene(saved.width, saved.height, false) != *saved,
            _ => false,
        }
    }

    /// Saves the scene (the same JSON `volao render` reads).
    pub fn save_scene(&mut self, path: &Path) -> Result<(), String> {
        let (w, h) = self.viewport_px;
        let doc = self.doc.as_mut().ok_or("nothing to save yet")?;
        let scene = doc.scene(w.max(1), h.max(1), false);
        scene.save(path).map_err(|e| e.to_string())?;
        doc.scene_path = Some(path.to_owned());
        self.saved = Some(scene);
        self.push_recent(path.to_owned());
        self.toast(format!("Saved scene {}", path.display()), false);
        Ok(())
    }

    /// Asks for a screenshot: rendered offscreen at `size`, written to `path` with the
    /// scene beside it. Waits (without blocking) for loads and AO to finish first.
    pub fn request_screenshot(&mut self, path: PathBuf, size: ShotSize) {
        self.shot_request = Some((path, size));
        self.ctx.request_repaint();
    }

    /// Writes a screenshot whose first write failed to another path.
    pub fn retry_screenshot(&mut self, path: PathBuf) {
        if let Some(mut shot) = self.failed_shot.take() {
            shot.path = path;
            self.start_write(shot);
        }
    }

    // ----- jobs ---------------------------------------------------------------------------

    fn repaint_fn(&self) -> impl Fn() + Send + Sync + 'static {
        let ctx = self.ctx.clone();
        move || ctx.request_repaint()
    }

    fn start_load(&mut self, request: OpenRequest) {
        if let Some(old) = self.load_job.take() {
            old.cancel();
        }
        let gpu = Arc::clone(&self.gpu);
        let label = format!("Loading {}", request.label());
        self.load_job = Some(Job::spawn(label, self.repaint_fn(), move |p| {
            load_document(&gpu, &request, p)
        }));
    }

    fn poll_load(&mut self) {
        let Some(job) = &mut self.load_job else {
            return;
        };
        let Some(result) = job.poll() else {
            return;
        };
        self.load_job = None;
        match result {
            Ok(loaded) => {
                for w in &loaded.warnings {
                    self.toast(format!("warning: {w}"), false);
                }
                let doc = loaded.doc;
                if doc.downsampled > 0 {
                    self.toast(
                        format!(
                            "The volume was halved {}× to fit the GPU's texture limits",
                            doc.downsampled
                        ),
                        false,
                    );
                }
                let (w, h) = (self.viewport_px.0.max(1), self.viewport_px.1.max(1));
                self.saved = Some(doc.scene(w, h, false));
                if let Some(p) = doc.scene_path.clone().or(doc.source.path.clone()) {
                    self.push_recent(p);
                }
                self.uploaded_tf = Some((doc.tf.clone(), doc.render.step_voxels));
                self.with_viewport(|v| v.set_volume(loaded.gpu_volume));
                self.doc = Some(doc);
                self.doc_generation += 1;
                self.cancel_ao();
                self.ready_frames = 0;
                self.tf_editor = Default::default();
            }
            Err(JobError::Cancelled) => {}
            Err(JobError::Failed(e)) => {
                let what = if self.doc.is_some() {
                    " (the current volume stays)"
                } else {
                    ""
                };
                self.toast(format!("Could not open: {e}{what}"), true);
                if self.doc.is_none()
                    && (self.options.exit_after_frames.is_some()
                        || self.options.bench_clip_drag.is_some())
                {
                    self.fail_exit(format!("could not open: {e}"));
                }
            }
        }
    }

    fn ao_key(&self) -> Option<AoKey> {
        let doc = self.doc.as_ref()?;
        (doc.ao.method != AoMethod::None).then(|| AoKey {
            settings: doc.ao,
            // CAO and its baseline keep the AO exact under clipping, as in `volao render`.
            clipping: matches!(doc.ao.method, AoMethod::Cao | AoMethod::LaoFull),
            opacity: doc.tf.opacity.clone(),
            doc_generation: self.doc_generation,
        })
    }

    fn ao_wanted_but_waiting(&self) -> bool {
        let Some(want) = self.ao_key() else {
            return false;
        };
        match &self.ao_state {
            AoState::Off => true,
            AoState::Computing { .. } => false,
            AoState::Ready { key } | AoState::Failed { key, .. } => *key != want,
        }
    }

    fn cancel_ao(&mut self) {
        if let AoState::Computing { job, .. } = &self.ao_state {
            job.cancel();
        }
        self.ao_state = AoState::Off;
    }

    /// Keeps the AO volume on the GPU in step with the settings and the transfer
    /// function; shows the volume without AO while a new one is computed.
    fn update_ao(&mut self) {
        let want = self.ao_key();
        // Collect a finished job.
        if let AoState::Computing { key, job } = &mut self.ao_state
            && let Some(result) = job.poll()
        {
            let key = key.clone();
            self.ao_state = match result {
                Ok(r) => {
                    let gpu = Arc::clone(&self.gpu);
                    let applied = self
                        .with_viewport(|v| match (r.kind, &mut v.volume) {
                            (AoData::Volume(values), Some(g)) => {
                                if values.len() != g.texels.dims.iter().product::<usize>() {
                                    return Err("the AO volume does not match the uploaded \
                                                volume (it was halved to fit the GPU); AO \
                                                needs the full resolution"
                                        .to_owned());
                                }
                                g.set_ambient_occlusion(&gpu, &values);
                                v.cao = None;
                                v.touch();
                                Ok(())
                            }
                            (AoData::Cao(cao), Some(_)) => {
                                v.cao = Some(*cao);
                                Ok(())
                            }
                            (_, None) => Err("no volume".to_owned()),
                        })
                        .unwrap_or_else(|| Err("no viewport".into()));
                    match applied {
                        Ok(()) => {
                            // CAO's V_AO is made for the current shapes on the next sync.
                            self.synced_clip = None;
                            self.ao_seconds = Some((r.seconds, r.device));
                            AoState::Ready { key }
                        }
                        Err(message) => AoState::Failed { key, message },
                    }
                }
                Err(JobError::Cancelled) => AoState::Off,
                Err(JobError::Failed(message)) => {
                    self.toast(format!("Ambient occlusion failed: {message}"), true);
                    AoState::Failed { key, message }
                }
            };
        }
        let current = match &self.ao_state {
            AoState::Off => None,
            AoState::Computing { key, .. }
            | AoState::Ready { key }
            | AoState::Failed { key, .. } => Some(key.clone()),
        };
        if current == want {
            return;
        }
        // The settings moved on: drop the stale AO at once (never show a wrong one).
        let had_ao = matches!(self.ao_state, AoState::Ready { .. });
        self.cancel_ao();
        if had_ao {
            let gpu = Arc::clone(&self.gpu);
            let tf = self.doc.as_ref().map(|d| d.tf.clone());
            self.with_viewport(|v| {
                v.cao = None;
                if let Some(g) = &mut v.volume {
                    g.clear_ambient_occlusion(&gpu);
                    if let Some(tf) = &tf {
                        // Turning live positional AO off cannot fail (nothing is uploaded).
                        let _ = g.set_live_vao(&gpu, tf, None);
                    }
                    v.touch();
                }
            });
            self.synced_clip = None;
        }
        let Some(key) = want else {
            return;
        };
        // Live positional AO needs no precomputation: the ray caster evaluates it at every
        // sample, so it follows the transfer function and the clip shapes at once.
        if key.settings.method == AoMethod::VaoLive {
            let gpu = Arc::clone(&self.gpu);
            let Some(tf) = self.doc.as_ref().map(|d| d.tf.clone()) else {
                return;
            };
            let vao = key.settings.vao;
            let applied = self.with_viewport(|v| {
                let g = v.volume.as_mut()?;
                let r = g
                    .set_live_vao(&gpu, &tf, Some(&vao))
                    .map_err(|e| e.to_string());
                v.touch();
                Some(r)
            });
            self.ao_state = match applied.flatten() {
                Some(Ok(())) => AoState::Ready { key },
                Some(Err(message)) => {
                    self.toast(format!("Ambient occlusion failed: {message}"), true);
                    AoState::Failed { key, message }
                }
                None => AoState::Off,
            };
            return;
        }
        if !self.resting() {
            return;
        }
        let Some(doc) = &self.doc else {
            return;
        };
        let volume = Arc::clone(&doc.volume);
        let tf = doc.tf.clone();
        let settings = doc.ao;
        let step = doc.render.step_voxels;
        let label = format!(
            "Ambient occlusion ({}{})",
            ao_panel::method_name(settings.method),
            if key.clipping { ", CAO" } else { "" }
        );
        let job = if key.clipping {
            // CAO precomputes V_PAO on its own copy of the uploaded texels.
            let texels = self
                .with_viewport(|v| v.volume.as_ref().map(|g| g.texels.clone()))
                .flatten();
            let gpu = Arc::clone(&self.gpu);
            Job::spawn(label, self.repaint_fn(), move |p| {
                let start = Instant::now();
                let texels = texels.ok_or("no volume uploaded")?;
                let vol =
                    GpuVolume::from_texels(&gpu, texels, &tf, step).map_err(|e| e.to_string())?;
                let rays = crate::ao::lao::Rays::uniform(settings.rays.directions());
                let cao = crate::ao::cao::CaoGpu::new(
                    &gpu,
                    &vol,
                    &tf,
                    &rays,
                    settings.samples,
                    settings.msaa,
                    &|d, t| p.set(d as u64, t as u64),
                )
                .map_err(|e| e.to_string())?;
                Ok(AoResult {
                    kind: AoData::Cao(Box::new(cao)),
                    device: gpu.describe(),
                    seconds: start.elapsed().as_secs_f64(),
                })
            })
        } else {
            // The viewer's own device; a filter map on a CPU adapter goes to the twin.
            let gpu = if crate::ao::fast::map_of(settings.method).is_some()
                && crate::ao::fast::twin_is_faster(&self.gpu)
            {
                crate::gpu::GpuUse::Cpu
            } else {
                crate::gpu::GpuUse::Shared(Arc::clone(&self.gpu))
            };
            Job::spawn(label, self.repaint_fn(), move |p| {
                let start = Instant::now();
                let (ao, device) =
                    crate::ao::compute_volume(&volume, &tf, &settings, &gpu, &|d, t| {
                        p.set(d as u64, t as u64)
                    })
                    .map_err(|e| e.to_string())?;
                let volume::VoxelData::F32(values) = ao.data else {
                    return Err("the AO volume came back in an unexpected voxel type".into());
                };
                Ok(AoResult {
                    kind: AoData::Volume(values),
                    device,
                    seconds: start.elapsed().as_secs_f64(),
                })
            })
        };
        self.ao_state = AoState::Computing { key, job };
    }

    fn modulation_key(&self) -> Option<ModulationKey> {
        let doc = self.doc.as_ref()?;
        let settings = doc.render.opacity_modulation?;
        Some(ModulationKey {
            settings,
            opacity: (settings.source == StatisticSource::Opacity).then(|| doc.tf.opacity.clone()),
            doc_generation: self.doc_generation,
        })
    }

    /// Keeps the opacity modulation on the GPU in step with its settings (and with the
    /// transfer function when the variance is the opacity's), as [`Self::update_ao`] does
    /// for AO: a stale modulation is dropped at once, the new one computed off the UI
    /// thread on the uploaded texels.
    fn update_modulation(&mut self) {
        let want = self.modulation_key();
        match self.modulation.poll(want.as_ref()) {
            Polled::Nothing => {}
            Polled::Ready(key, values) => {
                let gpu = Arc::clone(&self.gpu);
                let fits = |g: &GpuVolume| values.len() == g.texels.dims.iter().product::<usize>();
                if self.upload(|g| {
                    let fit = fits(g);
                    if fit {
                        g.set_opacity_modulation(&gpu, &values);
                    }
                    fit
                }) {
                    self.modulation.uploaded(key);
                }
            }
            Polled::Failed(message) => {
                self.toast(format!("Opacity modulation failed: {message}"), true)
            }
        }
        if self.modulation.settled(want.as_ref()) {
            return;
        }
        if self.modulation.reset() {
            let gpu = Arc::clone(&self.gpu);
            self.upload(|g| {
                g.clear_opacity_modulation(&gpu);
                true
            });
        }
        let Some(key) = want else {
            return;
        };
        if !self.resting() {
            return;
        }
        let (Some(doc), Some(texels)) = (&self.doc, self.uploaded_texels()) else {
            return;
        };
        let (gpu, tf, step, m) = (
            Arc::clone(&self.gpu),
            doc.tf.clone(),
            doc.render.step_voxels,
            key.settings,
        );
        let job = Job::spawn("Opacity modulation", self.repaint_fn(), move |_| {
            if crate::ao::fast::twin_is_faster(&gpu) {
                return Ok(crate::ao::fast::modulation_cpu(&texels, &tf, &m));
            }
            let vol = GpuVolume::from_texels(&gpu, texels, &tf, step).map_err(|e| e.to_string())?;
            crate::ao::fast::modulation_gpu(&gpu, &vol, &tf, &m).map_err(|e| e.to_string())
        });
        self.modulation.start(key, job);
    }

    /// What the light volume of shadows must be computed for, if shadows are on.
    fn light_key(&self) -> Option<LightKey> {
        let doc = self.doc.as_ref()?;
        doc.render.shadows.then(|| LightKey {
            direction: doc.view_settings().light_direction,
            opacity: doc.tf.opacity.clone(),
            clip: doc.clip_shapes.clone(),
            doc_generation: self.doc_generation,
        })
    }

    /// Keeps the light volume of shadows in step with the light (a headlight follows the
    /// camera), the transfer function's opacity and the clip shapes, recomputed once they
    /// rest. Unlike AO, the previous light volume stays on screen meanwhile: shadows that
    /// lag a moving camera or shape read better than shadows that blink off.
    fn update_light(&mut self) {
        let want = self.light_key();
        match self.light.poll(want.as_ref()) {
            Polled::Nothing => {}
            Polled::Ready(key, values) => {
                let gpu = Arc::clone(&self.gpu);
                let dir = glam::Vec3::from(key.direction);
                let mut error = None;
                let uploaded =
                    self.upload(|g| match g.set_light_volume(&gpu, Some((&values, dir))) {
                        Ok(_) => true,
                        Err(e) => {
                            error = Some(e.to_string());
                            false
                        }
                    });
                if uploaded {
                    self.light.uploaded(key);
                } else if let Some(e) = error {
                    self.toast(format!("Shadows failed: {e}"), true);
                }
            }
            Polled::Failed(message) => self.toast(format!("Shadows failed: {message}"), true),
        }
        if want != self.light_wanted.as_ref().map(|(k, _)| k.clone()) {
            self.light_wanted = want.clone().map(|k| (k, Instant::now()));
        }
        if self.light.settled(want.as_ref()) {
            return;
        }
        if self.light.reset() && want.is_none() {
            let gpu = Arc::clone(&self.gpu);
            self.upload(|g| g.set_light_volume(&gpu, None).is_ok());
        }
        let Some(key) = want else {
            return;
        };
        let still = self
            .light_wanted
            .as_ref()
            .is_some_and(|(_, since)| since.elapsed() >= AO_DEBOUNCE);
        if !self.resting() || !still {
            self.ctx.request_repaint_after(AO_DEBOUNCE);
            return;
        }
        let (Some(doc), Some(texels)) = (&self.doc, self.uploaded_texels()) else {
            return;
        };
        let (gpu, tf) = (Arc::clone(&self.gpu), doc.tf.clone());
        let (shapes, radius, resolution) =
            (key.clip.clone(), doc.radius, self.options.clip_resolution);
        let dir = match crate::render::shadow::light_direction(key.direction) {
            Ok(d) => d,
            Err(message) => {
                self.toast(format!("Shadows: {message}"), true);
                return;
            }
        };
        let job = Job::spawn("Shadows", self.repaint_fn(), move |p| {
            let lut = crate::render::shadow::light_lut(&tf, &texels);
            // Its own clip maps, as `volao render` makes them (the margin is unused).
            let maps = match shapes.is_empty() {
                true => None,
                false => {
                    let mut m = crate::clip::gpu::ClipMaps::new(&gpu).map_err(|e| e.to_string())?;
                    m.update(&gpu, &shapes, radius, 1.0, resolution)
                        .map_err(|e| e.to_string())?;
                    Some(m)
                }
            };
            crate::render::shadow::LightGpu::new(&gpu.device)
                .and_then(|l| {
                    let progress = |d: usize, t: usize| p.set(d as u64, t as u64);
                    l.compute_clipped(&gpu, &texels, &lut, dir, maps.as_ref(), &progress)
                })
                .map_err(|e| e.to_string())
        });
        self.light.start(key, job);
    }

    /// Whether the transfer function has rested long enough to recompute what depends on
    /// it (asks for a repaint when it has not).
    fn resting(&self) -> bool {
        let resting = self.tf_changed_at.elapsed() >= AO_DEBOUNCE && !self.tf_editor_dragging();
        if !resting {
            self.ctx.request_repaint_after(AO_DEBOUNCE);
        }
        resting
    }

    /// A copy of the texels the viewport's volume was made from.
    fn uploaded_texels(&self) -> Option<VolumeTexels> {
        self.with_viewport(|v| v.volume.as_ref().map(|g| g.texels.clone()))
            .flatten()
    }

    /// Runs `f` on the viewport's volume and redraws; false when there is none or `f`
    /// says the values did not fit.
    fn upload(&self, f: impl FnOnce(&mut GpuVolume) -> bool) -> bool {
        self.with_viewport(|v| {
            let done = v.volume.as_mut().is_some_and(f);
            v.touch();
            done
        })
        .unwrap_or(false)
    }

    fn tf_editor_dragging(&self) -> bool {
        self.ctx.input(|i| i.pointer.any_down())
    }

    /// Sends the transfer function and step to the GPU volume when they changed.
    fn sync_transfer_function(&mut self) {
        let Some(doc) = &self.doc else {
            return;
        };
        let want = (doc.view_tf(), doc.render.step_voxels);
        if self.uploaded_tf.as_ref() == Some(&want) {
            return;
        }
        let gpu = Arc::clone(&self.gpu);
        self.with_viewport(|v| {
            if let Some(g) = &mut v.volume {
                g.set_transfer_function(&gpu, &want.0, want.1);
                v.touch();
            }
        });
        self.uploaded_tf = Some(want);
    }

    /// Brings the GPU's clipping up to date with the shapes: CAO's per-frame update (the
    /// AO stays exact while a shape moves) or, without CAO, the clip maps alone.
    fn sync_clip(&mut self) {
        let Some(doc) = &self.doc else {
            return;
        };
        if self.synced_clip.as_ref() == Some(&doc.clip_shapes) {
            return;
        }
        let shapes = doc.clip_shapes.clone();
        let (radius, samples) = (doc.radius, doc.ao.samples);
        let cao_mode = if doc.ao.method == AoMethod::LaoFull {
            crate::ao::cao::CaoMode::Full
        } else {
            crate::ao::cao::CaoMode::Selective
        };
        let gpu = Arc::clone(&self.gpu);
        let resolution = self.options.clip_resolution;
        let result = self
            .with_viewport(|v| -> Result<Option<crate::ao::cao::CaoStats>, String> {
                let Some(vol) = &mut v.volume else {
                    return Ok(None);
                };
                let out = if let Some(cao) = &mut v.cao {
                    let reach = cao.reach_mm(&vol.texels);
                    let stats = cao
                        .update(&gpu, &vol.texels, &shapes, resolution, reach, cao_mode)
                        .map_err(|e| e.to_string())?;
                    vol.set_ambient_occlusion_view(cao.ao_view());
                    Some(stats)
                } else if shapes.is_empty() {
                    v.clip = None;
                    None
                } else {
                    if v.clip.is_none() {
                        v.clip =
                            Some(crate::clip::gpu::ClipMaps::new(&gpu).map_err(|e| e.to_string())?);
                    }
                    let reach = crate::ao::cao::reach_mm(samples, vol.texels.spacing);
                    if let Some(clip) = &mut v.clip {
                        let report = clip
                            .update(&gpu, &shapes, radius, reach, resolution)
                            .map_err(|e| e.to_string())?;
                        if let Some(e) = report.errors.first() {
                            return Err(e.to_string());
                        }
                    }
                    None
                };
                v.touch();
                Ok(out)
            })
            .unwrap_or(Ok(None));
        self.synced_clip = Some(shapes);
        match result {
            Ok(stats) => {
                if let Some(e) = stats.as_ref().and_then(|s| s.clip_errors.first()) {
                    self.toast(format!("Clip shape left out: {e}"), true);
                }
                self.cao_stats = stats;
            }
            Err(e) => self.toast(format!("Clipping failed: {e}"), true),
        }
    }

    fn with_viewport<R>(&self, f: impl FnOnce(&mut ViewportGpu) -> R) -> Option<R> {
        let mut renderer = self.render_state.renderer.write();
        renderer.callback_resources.get_mut::<ViewportGpu>().map(f)
    }

    /// Advances screenshots: starts a requested one when the view is ready, pumps the
    /// tiles of the one in flight, collects the write.
    fn update_screenshots(&mut self) {
        if let Some(job) = &mut self.write_job
            && let Some(result) = job.poll()
        {
            self.write_job = None;
            match result {
                Ok((png, scene)) => {
                    self.failed_shot = None;
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
                        self.exit_requested = true;
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
        if self.pending_shot.is_none()
            && self.load_job.is_none()
            && self.derived_ready()
            && self.doc.is_some()
            && let Some((path, size)) = self.shot_request.take()
            && let Some(doc) = &self.doc
        {
            {
                let (w, h) = match size {
                    ShotSize::Window => (self.viewport_px.0.max(1), self.viewport_px.1.max(1)),
                    ShotSize::Fixed(w, h) => (w, h),
                };
                if w == 0 || h == 0 || w > screenshot::MAX_SIDE || h > screenshot::MAX_SIDE {
                    self.toast(
                        format!(
                            "Screenshot size {w}×{h}: each side must be 1 to {}",
                            screenshot::MAX_SIDE
                        ),
                        true,
                    );
                } else {
                    let mut scene = doc.scene(w, h, true);
                    if self.shot_transparent {
                        scene.render.background = [0.0; 4];
                    }
                    let frame = Frame {
                        camera: scene.camera,
                        settings: scene.render,
                        width: w,
                        height: h,
                    };
                    self.pending_shot = Some(PendingShot::new(frame, scene, path));
                }
            }
        }
        if let Some(shot) = &mut self.pending_shot {
            let gpu = Arc::clone(&self.gpu);
            let renderer = self.render_state.renderer.read();
            let result = match renderer.callback_resources.get::<ViewportGpu>() {
                Some(
                    v @ ViewportGpu {
                        volume: Some(vol), ..
                    },
                ) => shot.pump(&gpu, &v.ray_caster, vol, v.clip_maps()),
                _ => Err("no volume to render".into()),
            };
            drop(renderer);
            match result {
                Ok(None) => self.ctx.request_repaint_after(Duration::from_millis(5)),
                Ok(Some(done)) => {
                    self.pending_shot = None;
                    self.start_write(done);
                }
                Err(e) => {
                    self.pending_shot = None;
                    self.toast(format!("Screenshot failed: {e}"), true);
                    if self.options.exit_after_frames.is_some() {
                        self.fail_exit(e);
                    }
                }
            }
        }
    }

    fn start_write(&mut self, shot: Shot) {
        let label = format!("Saving {}", file_name(&shot.path));
        let kept = shot.clone();
        self.failed_shot = None;
        self.write_job = Some(Job::spawn(label, self.repaint_fn(), move |_| shot.write()));
        // Kept until the write succeeds: a failure loses nothing.
        self.failed_shot = Some(kept);
    }

    fn fail_exit(&mut self, message: String) {
        if let Ok(mut e) = self.exit_error.lock() {
            *e = Some(message);
        }
        self.exit_requested = true;
    }

    /// The next free `volao-N.png` in the screenshot folder (F12).
    pub fn next_screenshot_path(&self) -> PathBuf {
        (1..)
            .map(|n| self.options.screenshot_dir.join(format!("volao-{n}.png")))
            .find(|p| !p.exists() && !screenshot::scene_path(p).exists())
            .unwrap_or_else(|| self.options.screenshot_dir.join("volao.png"))
    }

    // ----- small state --------------------------------------------------------------------

    fn toast(&mut self, text: String, error: bool) {
        if error {
            eprintln!("volao: {text}");
        }
        self.toasts.push(Toast {
            text,
            error,
            born: Instant::now(),
        });
        self.ctx.request_repaint();
    }

    fn push_recent(&mut self, path: PathBuf) {
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.recent.retain(|p| *p != path);
        self.recent.insert(0, path);
        self.recent.truncate(RECENT_MAX);
        if let Some(file) = &self.options.recent_file
            && let Err(e) = save_recent(file, &self.recent)
        {
            eprintln!(
                "volao: could not remember recent files in {}: {e}",
                file.display()
            );
        }
    }

    // ----- the UI -------------------------------------------------------------------------

    /// One frame of the whole UI.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        self.poll_load();
        self.handle_input(ui);
        self.update_ao();
        self.update_modulation();
        self.update_light();
        self.sync_transfer_function();
        self.sync_clip();
        self.update_screenshots();
        let errors: Vec<String> = self
            .gpu_errors
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default();
        for e in errors {
            self.toast(format!("GPU error: {e}"), true);
        }

        if self.options.bench_clip_drag.is_some() {
            egui::CentralPanel::no_frame().show(ui, |ui| self.viewport(ui));
            self.bench_step(ui.ctx());
            return;
        }
        egui::Panel::top("menu").show(ui, |ui| self.menu_bar(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar(ui));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical()
                    .auto_shrink([false, false])
                    .show(ui, |ui| self.side_panel(ui));
            });
        egui::CentralPanel::no_frame().show(ui, |ui| self.viewport(ui));
        self.show_prompt(ui.ctx());
        self.show_toasts(ui.ctx());
        self.update_title(ui.ctx());
        self.exit_logic(ui.ctx());
    }

    fn handle_input(&mut self, ui: &egui::Ui) {
        let ctx = ui.ctx().clone();
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_owned())
                .collect()
        });
        if let Some(p) = dropped.into_iter().next() {
            self.open(OpenRequest::for_path(p));
        }
        let (open, save, shot) = ctx.input_mut(|i| {
            (
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::O),
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::S),
                i.consume_key(egui::Modifiers::NONE, egui::Key::F12),
            )
        });
        if open {
            self.open_dialog();
        }
        if save {
            self.save_dialog(false);
        }
        if shot {
            let path = self.next_screenshot_path();
            self.request_screenshot(path, self.shot_size);
        }
        if ctx.input(|i| i.viewport().close_requested())
            && self.has_unsaved_changes()
            && !self.quit_confirmed
        {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.prompt = Some(Pending::Quit);
        }
    }

    fn open_dialog(&mut self) {
        let picked = rfd::FileDialog::new()
            .set_title("Open a volume or a scene")
            .add_filter(
                "Volumes and scenes",
                &[
                    "nii", "gz", "hdr", "img", "nrrd", "nhdr", "dcm", "pvm", "raw", "dat", "json",
                ],
            )
            .add_filter("All files", &["*"])
            .pick_file();
        if let Some(p) = picked {
            self.open(OpenRequest::for_path(p));
        }
    }

    /// Save dialog for the scene; with `then_quit`, closes after saving (the prompt).
    fn save_dialog(&mut self, then_quit: bool) -> bool {
        let Some(doc) = &self.doc else {
            return false;
        };
        let start = doc
            .scene_path
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("{}.json", doc.title)));
        let picked = rfd::FileDialog::new()
            .set_title("Save scene")
            .set_file_name(file_name(&start))
            .add_filter("volao scene", &["json"])
            .save_file();
        let Some(path) = picked else {
            return false;
        };
        match self.save_scene(&path) {
            Ok(()) => {
                if then_quit {
                    self.quit_confirmed = true;
                    self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                }
                true
            }
            Err(e) => {
                self.toast(format!("Scene not saved: {e}"), true);
                false
            }
        }
    }

    fn screenshot_dialog(&mut self) {
        let picked = rfd::FileDialog::new()
            .set_title("Save screenshot")
            .set_directory(&self.options.screenshot_dir)
            .set_file_name("volao.png")
            .add_filter("PNG image", &["png"])
            .save_file();
        if let Some(p) = picked {
            self.request_screenshot(p, self.shot_size);
        }
    }

    fn menu_bar(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open…  (Ctrl+O)").clicked() {
                    self.open_dialog();
                }
                if ui.button("Open folder…  (DICOM series)").clicked() {
                    let picked = rfd::FileDialog::new()
                        .set_title("Open a folder of DICOM files")
                        .pick_folder();
                    if let Some(p) = picked {
                        self.open(OpenRequest::for_path(p));
                    }
                }
                ui.menu_button("Open recent", |ui| {
                    if self.recent.is_empty() {
                        ui.weak("(none yet)");
                    }
                    for p in self.recent.clone() {
                        if ui.button(p.display().to_string()).clicked() {
                            self.open(OpenRequest::for_path(p));
                        }
                    }
                });
                if ui.button("Open demo volume").clicked() {
                    self.open(OpenRequest::Demo);
                }
                ui.separator();
                if ui.button("Save scene…  (Ctrl+S)").clicked() {
                    self.save_dialog(false);
                }
                if ui.button("Screenshot…").clicked() {
                    self.screenshot_dialog();
                }
                ui.separator();
                if ui.button("Quit").clicked() {
                    ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                }
            });
            ui.menu_button("View", |ui| {
                let Some(doc) = &mut self.doc else {
                    ui.weak("(no volume)");
                    return;
                };
                for v in camera_input::StandardView::ALL {
                    if ui.button(v.name()).clicked() {
                        v.apply(&mut doc.camera);
                    }
                }
                ui.separator();
                if ui.button("Reset camera").clicked() {
                    camera_input::reset(&mut doc.camera);
                }
                ui.checkbox(&mut doc.camera.orthographic, "Orthographic");
            });
        });
    }

    fn side_panel(&mut self, ui: &mut egui::Ui) {
        let viewport_px = self.viewport_px;
        let ao_stats = self.ao_stats();
        let light_status = match self.light_error() {
            Some(e) => format!("failed: {e}"),
            None if self.light.computing() => "computing the light volume…".to_owned(),
            None => String::new(),
        };
        let modulation_status = match self.modulation_error() {
            Some(e) => format!("failed: {e}"),
            None if self.modulation.computing() => "computing…".to_owned(),
            None => String::new(),
        };
        let Some(doc) = &mut self.doc else {
            ui.spinner();
            return;
        };
        ui.heading(&doc.title);
        ui.weak(&doc.info);
        ui.separator();
        egui::CollapsingHeader::new("Camera")
            .default_open(true)
            .show(ui, |ui| {
                ui.horizontal_wrapped(|ui| {
                    for v in camera_input::StandardView::ALL {
                        if ui.button(v.name()).clicked() {
                            v.apply(&mut doc.camera);
                        }
                    }
                });
                ui.horizontal(|ui| {
                    if ui.button("Reset").clicked() {
                        camera_input::reset(&mut doc.camera);
                    }
                    ui.selectable_value(&mut doc.camera.orthographic, false, "Perspective");
                    ui.selectable_value(&mut doc.camera.orthographic, true, "Orthographic");
                });
            });
        egui::CollapsingHeader::new("Transfer function")
            .default_open(true)
            .show(ui, |ui| {
                if self
                    .tf_editor
                    .show(ui, &mut doc.tf, &doc.histogram, &doc.stats)
                {
                    self.tf_changed_at = Instant::now();
                }
                tf_editor::modulation_controls(
                    ui,
                    &mut doc.render.opacity_modulation,
                    &modulation_status,
                );
            });
        egui::CollapsingHeader::new("Ambient occlusion")
            .default_open(true)
            .show(ui, |ui| {
                ao_panel::show(
                    ui,
                    &mut doc.ao,
                    &mut doc.render.ambient,
                    &mut doc.ao_only,
                    &ao_stats,
                );
            });
        egui::CollapsingHeader::new("Rendering").show(ui, |ui| {
            let r = &mut doc.render;
            ui.add(ao_panel::slider(&mut r.step_voxels, 0.1..=2.0).text("Step (voxels)"));
            ui.horizontal(|ui| {
                ui.label("Shading");
                ui.selectable_value(&mut r.shading, Shading::Phong, "Phong");
                ui.selectable_value(&mut r.shading, Shading::None, "None");
            });
            ui.checkbox(&mut r.jitter, "Jittered ray start");
            ui.horizontal(|ui| {
                ui.label("Background");
                let mut rgb = r
                    .background
                    .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8);
                let mut c = [rgb[0], rgb[1], rgb[2]];
                if egui::color_picker::color_edit_button_srgb(ui, &mut c).changed() {
                    rgb[..3].copy_from_slice(&c);
                    r.background = [
                        rgb[0] as f32 / 255.0,
                        rgb[1] as f32 / 255.0,
                        rgb[2] as f32 / 255.0,
                        r.background[3],
                    ];
                }
            });
            shadow_controls(ui, doc, &light_status);
        });
        let radius = doc.radius;
        egui::CollapsingHeader::new("Clipping")
            .default_open(true)
            .show(ui, |ui| {
                self.clip_editor.panel(ui, &mut doc.clip_shapes, radius);
            });
        egui::CollapsingHeader::new("Screenshot")
            .default_open(true)
            .show(ui, |ui| {
                let label = |s: ShotSize| match s {
                    ShotSize::Window => format!("Window ({}×{})", viewport_px.0, viewport_px.1),
                    ShotSize::Fixed(w, h) => format!("{w}×{h}"),
                };
                egui::ComboBox::from_label("Size")
                    .selected_text(label(self.shot_size))
                    .show_ui(ui, |ui| {
                        ui.selectable_value(
                            &mut self.shot_size,
                            ShotSize::Window,
                            label(ShotSize::Window),
                        );
                        for (w, h) in screenshot::PRESET_SIZES {
                            let s = ShotSize::Fixed(w, h);
                            ui.selectable_value(&mut self.shot_size, s, label(s));
                        }
                    });
                if let ShotSize::Fixed(w, h) = &mut self.shot_size {
                    ui.horizontal(|ui| {
                        ui.label("Width");
                        ui.add(egui::DragValue::new(w).range(1..=screenshot::MAX_SIDE))
                            .accessible_name("Width");
                        ui.label("Height");
                        ui.add(egui::DragValue::new(h).range(1..=screenshot::MAX_SIDE))
                            .accessible_name("Height");
                    });
                }
                ui.checkbox(&mut self.shot_transparent, "Transparent background");
                ui.horizontal(|ui| {
                    if ui.button("Screenshot…").clicked() {
                        self.screenshot_dialog();
                    }
                    if ui
                        .button("Quick (F12)")
                        .on_hover_text("Saves volao-N.png and its scene in the screenshot folder")
                        .clicked()
                    {
                        let path = self.next_screenshot_path();
                        self.request_screenshot(path, self.shot_size);
                    }
                });
                if let Some(shot) = &self.failed_shot
                    && self.write_job.is_none()
                {
                    let name = file_name(&shot.path);
                    if ui
                        .button(format!("Save elsewhere… (unsaved {name})"))
                        .clicked()
                        && let Some(p) = rfd::FileDialog::new()
                            .set_file_name(&name)
                            .add_filter("PNG image", &["png"])
                            .save_file()
                    {
                        self.retry_screenshot(p);
                    }
                }
            });
    }

    fn ao_stats(&self) -> ao_panel::AoStats {
        let status = match &self.ao_state {
            AoState::Off if self.ao_key().is_some() => {
                "waiting for the transfer function to rest".into()
            }
            AoState::Off => "off".into(),
            AoState::Computing { job, .. } => match job.fraction() {
                Some(f) => format!("computing… {:.0} %", f * 100.0),
                None => "computing…".into(),
            },
            AoState::Ready { .. } => "ready".into(),
            AoState::Failed { message, .. } => format!("failed: {message}"),
        };
        let frames = self
            .with_viewport(|v| v.frames_rendered)
            .unwrap_or_default();
        ao_panel::AoStats {
            frame_ms: self.frame_ms,
            frames,
            ao_seconds: self.ao_seconds.as_ref().map(|(s, _)| *s),
            ao_device: self.ao_seconds.as_ref().map(|(_, d)| d.clone()),
            // Precomputed AO: a frame recomputes no voxel; CAO reports its own share.
            recomputed_percent: match (&self.ao_state, &self.cao_stats) {
                (AoState::Ready { key }, Some(c)) if key.clipping => Some(c.percent_recomputed()),
                (AoState::Ready { .. }, _) => Some(0.0),
                _ => None,
            },
            stages: self
                .cao_stats
                .as_ref()
                .filter(|_| self.ao_key().is_some_and(|k| k.clipping))
                .map(|c| {
                    format!(
                        "maps {:.0} ms, clip {:.0} ms, LAO {:.0} ms",
                        c.maps_seconds * 1e3,
                        c.clip_seconds * 1e3,
                        c.lao_seconds * 1e3
                    )
                }),
            status,
        }
    }

    fn status_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let mut cancel_load = false;
            let mut cancel_ao = false;
            if let Some(job) = &self.load_job {
                ui.label(&job.label);
                progress_bar(ui, job.fraction());
                cancel_load = ui.button("Cancel").clicked();
            }
            if let AoState::Computing { job, .. } = &self.ao_state {
                ui.label(&job.label);
                progress_bar(ui, job.fraction());
                cancel_ao = ui.button("Cancel").clicked();
            }
            if let Some(shot) = &self.pending_shot {
                ui.label(format!("Rendering {}", file_name(shot.path())));
                progress_bar(ui, Some(shot.fraction()));
            }
            if let Some(job) = &self.write_job {
                ui.label(&job.label);
                ui.spinner();
            }
            if cancel_load && let Some(job) = self.load_job.take() {
                job.cancel();
                self.toast("Loading cancelled".into(), false);
            }
            if cancel_ao {
                self.cancel_ao();
                // Keep the method but stop retrying until something changes.
                if let Some(key) = self.ao_key() {
                    self.ao_state = AoState::Failed {
                        key,
                        message: "cancelled".into(),
                    };
                }
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                ui.weak(&self.gpu.info.name);
                if let Some(e) = self.with_viewport(|v| v.last_error.clone()).flatten() {
                    ui.colored_label(ui.visuals().error_fg_color, e);
                }
            });
        });
    }

    fn viewport(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        self.viewport_rect = rect;
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        response
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, true, "3-D viewport"));
        let ppp = ui.ctx().pixels_per_point();
        let screen = ui.ctx().content_rect().size() * ppp;
        self.viewport_px = viewport::size_in_pixels(
            rect,
            ppp,
            [screen.x.round() as u32, screen.y.round() as u32],
        );
        let hovering_files = ui.ctx().input(|i| !i.raw.hovered_files.is_empty());
        let Some(doc) = &mut self.doc else {
            ui.put(rect, egui::Spinner::new().size(32.0));
            return;
        };
        let used =
            self.clip_editor
                .handle(ui, &response, &doc.camera, doc.radius, &mut doc.clip_shapes);
        if !used {
            camera_input::handle(ui, &response, &mut doc.camera, doc.radius);
        }
        let frame = Frame {
            camera: doc.camera,
            settings: doc.view_settings(),
            width: self.viewport_px.0.max(1),
            height: self.viewport_px.1.max(1),
        };
        ui.painter().add(egui_wgpu::Callback::new_paint_callback(
            rect,
            ViewportCallback { frame, rect },
        ));
        if self.show_outlines {
            self.clip_editor.paint(
                &ui.painter().with_clip_rect(rect),
                rect,
                &doc.camera,
                doc.radius,
                &doc.clip_shapes,
            );
        }
        if hovering_files {
            ui.painter()
                .rect_filled(rect, 0.0, egui::Color32::from_black_alpha(160));
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "Drop to open",
                egui::FontId::proportional(28.0),
                egui::Color32::WHITE,
            );
        }
        // Frame time: the interval between frames that ray-cast something new.
        let frames = self
            .with_viewport(|v| v.frames_rendered)
            .unwrap_or_default();
        if frames > self.frames_seen {
            let dt = ui.ctx().input(|i| i.unstable_dt) * 1e3;
            if self.frames_seen > 0 && frames == self.frames_seen + 1 {
                self.frame_ms = Some(match self.frame_ms {
                    Some(m) => 0.8 * m + 0.2 * dt,
                    None => dt,
                });
            }
            self.frames_seen = frames;
        }
    }

    /// One frame of `--bench-clip-drag`: time since the last frame, then move the shape.
    fn bench_step(&mut self, ctx: &egui::Context) {
        let Some(n) = self.options.bench_clip_drag else {
            return;
        };
        ctx.request_repaint();
        if let Some(e) = self.ao_error() {
            let message = format!("ambient occlusion failed: {e}");
            self.fail_exit(message);
        }
        if self.exit_requested {
            self.quit_confirmed = true;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        if self.load_job.is_some() || !self.derived_ready() {
            return;
        }
        let now = Instant::now();
        // The first two frames build the clip maps and warm up: not counted.
        if let Some(last) = self.bench_last.filter(|_| self.bench_warmup >= 2) {
            let share = self.cao_percent_recomputed().unwrap_or(0.0);
            self.bench.push(((now - last).as_secs_f64(), share));
        }
        self.bench_last = Some(now);
        self.bench_warmup += 1;
        if self.bench.len() as u64 >= n {
            let mut t: Vec<f64> = self.bench.iter().map(|b| b.0).collect();
            t.sort_by(f64::total_cmp);
            let mean = t.iter().sum::<f64>() / t.len() as f64;
            let share = self.bench.iter().map(|b| b.1).sum::<f64>() / t.len() as f64;
            println!(
                "viewport {}×{}: {} frames dragging a clip shape, mean {:.0} ms, median {:.0} ms, \
                 min {:.0} ms; CAO recomputed {:.2} % of voxels per frame; {}",
                self.viewport_px.0,
                self.viewport_px.1,
                t.len(),
                mean * 1e3,
                t[t.len() / 2] * 1e3,
                t[0] * 1e3,
                share,
                self.gpu.describe()
            );
            self.exit_requested = true;
            return;
        }
        if let Some(doc) = &mut self.doc
            && let Some(s) = doc.clip_shapes.first_mut()
        {
            // Back and forth by 1 mm, as a slow drag.
            let dir = if (self.bench.len() / 8).is_multiple_of(2) {
                1.0
            } else {
                -1.0
            };
            s.translation[0] += dir;
        } else {
            self.fail_exit("--bench-clip-drag needs a scene with a clip shape".into());
        }
    }

    fn show_prompt(&mut self, ctx: &egui::Context) {
        let Some(pending) = self.prompt.clone() else {
            return;
        };
        let what = match &pending {
            Pending::Quit => "before quitting".to_owned(),
            Pending::Open(r) => format!("before opening {}", r.label()),
        };
        let mut choice = None;
        egui::Modal::new(egui::Id::unique("unsaved_changes")).show(ctx, |ui| {
            ui.heading("Unsaved changes");
            ui.label(format!(
                "The scene has changes that are not saved. Save them {what}?"
            ));
            ui.horizontal(|ui| {
                if ui.button("Save…").clicked() {
                    choice = Some(0);
                }
                if ui.button("Discard").clicked() {
                    choice = Some(1);
                }
                if ui.button("Cancel").clicked() {
                    choice = Some(2);
                }
            });
        });
        match choice {
            Some(0) if self.save_dialog(false) => {
                self.prompt = None;
                self.proceed(pending);
            }
            // Saving was cancelled or failed: keep asking.
            Some(0) | None => {}
            Some(1) => {
                self.prompt = None;
                self.proceed(pending);
            }
            Some(_) => self.prompt = None,
        }
    }

    fn proceed(&mut self, pending: Pending) {
        match pending {
            Pending::Quit => {
                self.quit_confirmed = true;
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Pending::Open(r) => self.start_load(r),
        }
    }

    fn show_toasts(&mut self, ctx: &egui::Context) {
        const LIFE: Duration = Duration::from_secs(8);
        self.toasts.retain(|t| t.error || t.born.elapsed() < LIFE);
        self.toasts.truncate(8);
        if self.toasts.is_empty() {
            return;
        }
        let mut dismiss = None;
        egui::Area::new(egui::Id::unique("toasts"))
            .anchor(egui::Align2::RIGHT_BOTTOM, egui::vec2(-12.0, -36.0))
            .show(ctx, |ui| {
                for (i, t) in self.toasts.iter().enumerate() {
                    egui::Frame::popup(ui.style()).show(ui, |ui| {
                        ui.set_max_width(420.0);
                        ui.horizontal(|ui| {
                            if t.error {
                                ui.colored_label(ui.visuals().error_fg_color, &t.text);
                            } else {
                                ui.label(&t.text);
                            }
                            if ui.small_button("×").clicked() {
                                dismiss = Some(i);
                            }
                        });
                    });
                }
            });
        if let Some(i) = dismiss {
            self.toasts.remove(i);
        }
        if self.toasts.iter().any(|t| !t.error) {
            ctx.request_repaint_after(Duration::from_secs(1));
        }
    }

    fn update_title(&mut self, ctx: &egui::Context) {
        let title = match &self.doc {
            Some(d) => format!(
                "{}{} — volao",
                d.title,
                if self.has_unsaved_changes() {
                    " •"
                } else {
                    ""
                }
            ),
            None => "volao".into(),
        };
        if title != self.last_title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.last_title = title;
        }
    }

    /// `--exit-after-frames N [--screenshot PNG]`: count frames that show the volume with
    /// its AO, then take the screenshot and close once it is written.
    fn exit_logic(&mut self, ctx: &egui::Context) {
        if self.exit_requested {
            self.quit_confirmed = true;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        let Some(n) = self.options.exit_after_frames else {
            return;
        };
        if let Some(e) = self.ao_error() {
            let message = format!("ambient occlusion failed: {e}");
            self.fail_exit(message);
            return;
        }
        if self.doc.is_some() && self.load_job.is_none() && self.derived_ready() {
            self.ready_frames += 1;
        }
        if self.ready_frames < n {
            ctx.request_repaint();
            return;
        }
        if self.ready_frames == n {
            match self.options.screenshot.clone() {
                Some(path) => self.request_screenshot(path, ShotSize::Window),
                None => self.exit_requested = true,
            }
        }
        ctx.request_repaint();
    }
}

/// Shadows on or off, and where the light comes from: the eye (a headlight, as `volao
/// render` without `--light`) or a fixed direction by azimuth and elevation (as the
/// camera's, volume RAS).
fn shadow_controls(ui: &mut egui::Ui, doc: &mut Document, status: &str) {
    ui.checkbox(&mut doc.render.shadows, "Shadows");
    if !doc.render.shadows {
        return;
    }
    let mut fixed = matches!(doc.light, Light::Directional { .. });
    ui.horizontal(|ui| {
        ui.selectable_value(&mut fixed, false, "Headlight");
        ui.selectable_value(&mut fixed, true, "Fixed light");
    });
    match (fixed, doc.light) {
        (true, Light::Headlight) => {
            doc.light = Light::Directional {
                direction: doc.camera.backward().to_array(),
            }
        }
        (false, Light::Directional { .. }) => doc.light = Light::Headlight,
        _ => {}
    }
    if let Light::Directional { direction } = &mut doc.light {
        let d = glam::Vec3::from(*direction).normalize_or(glam::Vec3::Z);
        let (mut az, mut el) = (
            d.x.atan2(d.y).to_degrees(),
            d.z.clamp(-1.0, 1.0).asin().to_degrees(),
        );
        let moved = ui
            .add(ao_panel::slider(&mut az, -180.0..=180.0).text("Light azimuth (°)"))
            .changed()
            | ui.add(ao_panel::slider(&mut el, -90.0..=90.0).text("Light elevation (°)"))
                .changed();
        if moved {
            let towards = Camera {
                azimuth_deg: az,
                elevation_deg: el,
                ..Default::default()
            };
            *direction = towards.backward().to_array();
        }
    }
    if !status.is_empty() {
        ui.weak(status);
    }
}

fn progress_bar(ui: &mut egui::Ui, fraction: Option<f32>) {
    let bar = egui::ProgressBar::new(fraction.unwrap_or(0.0))
        .desired_width(160.0)
        .show_percentage();
    ui.add(if fraction.is_none() {
        bar.animate(true)
    } else {
        bar
    });
}

fn load_recent(file: &Path) -> Vec<PathBuf> {
    std::fs::read_to_string(file)
        .ok()
        .and_then(|t| serde_json::from_str::<Vec<PathBuf>>(&t).ok())
        .unwrap_or_default()
}

fn save_recent(file: &Path, list: &[PathBuf]) -> Result<(), String> {
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    }
    let text = serde_json::to_string_pretty(list).map_err(|e| e.to_string())?;
    std::fs::write(file, text).map_err(|e| e.to_string())
}
