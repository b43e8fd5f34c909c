//! The eframe viewer: `volao` opens it on the demo volume, `volao view FILE` on a file.
//!
//! [`Viewer`] owns what the user sees (a [`Document`]: volume, transfer function,
//! camera, AO settings — everything a scene file holds) and the background [`jobs`]
//! (loading, AO precomputation, writing screenshots). The GPU side of the viewport
//! ([`viewport::ViewportGpu`]) is the viewer's too, the same
//! [`RayCaster`](crate::render::gpu::RayCaster) +
//! [`GpuVolume`](crate::render::gpu::GpuVolume) pair `volao render` uses, on a device
//! requested with [`crate::gpu::device_descriptor`]; egui_wgpu's callback resources hold
//! only the pipelines that draw its images ([`viewport::ViewportPaint`]).
//!
//! The viewer's state comes in parts that name themselves: what is open (`Opened`: the
//! document and its loading, in `document.rs`), what is derived from it on the GPU
//! (`Derived`: AO, opacity modulation, shadows; kept in step by `sync.rs`), the
//! viewport's image and the work that makes it (`Viewport`), the UI around it
//! (`Chrome`, drawn by `panels.rs`) and the screenshots (`screenshot.rs`, `shots.rs`);
//! this file has the viewer's API and one frame's wiring.
//!
//! The UI thread never waits for a file, for AO or for the GPU: loads and AO run on
//! worker threads (whose GPU work is cut into short submissions, [`crate::gpu::dispatch::Slicing`]),
//! screenshots are read back asynchronously and written by a worker, and the viewport's
//! image — CAO's per-frame update included — is made in slices between UI frames
//! ([`viewport`]), at interactive quality while the view moves.

mod ao_job;
pub mod ao_panel;
pub mod camera_input;
pub mod clip_panel;
pub mod demo;
mod derived;
mod document;
mod hover;
pub mod jobs;
mod panels;
mod pointer;
mod preview;
pub mod screenshot;
mod scripted;
pub mod segments;
mod shots;
pub mod slices;
mod sync;
pub mod tf_editor;
mod tiles;
pub mod viewport;
mod watchdog;

pub use derived::AoShown;
pub use document::{
    DEMO_SIZE, Document, LoadedDocument, OpenRequest, ViewerOptions, default_recent_file,
    load_document,
};
pub use screenshot::ShotSize;

use crate::gpu::Gpu;
use crate::render::Frame;
use derived::Derived;
use document::Opened;
use jobs::{Job, JobError};
use screenshot::{Screenshots, Shot};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use viewport::{Viewport, ViewportGpu, ViewportPaint};

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

/// The viewer application.
pub struct Viewer {
    gpu: Arc<Gpu>,
    ctx: egui::Context,
    options: ViewerOptions,
    /// The document and its loading.
    opened: Opened,
    /// AO, opacity modulation and shadows, computed in the background.
    derived: Derived,
    /// The viewport's image and the work that makes it.
    viewport: Viewport,
    /// The UI around the viewport.
    chrome: Chrome,
    shots: Screenshots,
    scripted: Scripted,
    /// Says where everything stands when the viewer stops moving on (`watchdog.rs`).
    watchdog: Watchdog,
    /// Draw over the 3-D view: the clip shapes' outlines, the crosshair, the orientation
    /// marker.
    pub show_outlines: bool,
    /// GPU errors reported outside any error scope.
    gpu_errors: Arc<Mutex<Vec<String>>>,
    /// Set when a `--screenshot` could not be written (the process exits non-zero).
    pub exit_error: Arc<Mutex<Option<String>>>,
}

/// The UI around the viewport: the editors' state, the toasts, the unsaved-changes
/// prompt, the recent files and the window's title.
#[derive(Default)]
struct Chrome {
    tf_editor: tf_editor::TfEditor,
    clip_editor: clip_panel::ClipEditor,
    segments_panel: segments::SegmentsPanel,
    /// The slice panes, the layout and the crosshair.
    slices: slices::SliceViews,
    /// The hover line: the segment under the pointer.
    hover: hover::Hover,
    toasts: Vec<Toast>,
    recent: Vec<PathBuf>,
    prompt: Option<Pending>,
    /// Quitting was confirmed (or a scripted run ended): the window may close.
    quit_confirmed: bool,
    last_title: String,
}

/// Where a scripted run stands: `--exit-after-frames` and `--bench-clip-drag`
/// (`scripted.rs`).
#[derive(Debug, Default)]
struct Scripted {
    /// Frames shown with the volume (and its AO) ready, for `--exit-after-frames`.
    ready_frames: u64,
    exit_requested: bool,
    /// UI frame intervals (s) of `--bench-clip-drag`, while dragging.
    bench: Vec<f64>,
    bench_last: Option<Instant>,
    /// When the counted frames began and the viewport's images by then.
    bench_start: Option<(Instant, u64)>,
    /// Images completed: when, seconds each took from its start, and its interactive
    /// scale (1: full size).
    images: Vec<(Instant, f64, u32)>,
    /// When each CAO update's counters came back (one per update completed).
    cao_updates: Vec<Instant>,
}

/// Nothing moved on for this long: the watchdog (`watchdog.rs`) says where everything stands, once.
const STALL_REPORT: Duration = Duration::from_secs(30);

/// ... and a scripted run ends with that as its error after this long.
const STALL_FAIL: Duration = Duration::from_secs(180);

/// The watchdog's memory between frames.
#[derive(Debug, Default)]
struct Watchdog {
    /// What the viewer waited for when it last moved on, and when.
    rest: Option<(String, Instant)>,
    /// Images completed as of the last frame, and the image being made then: when it
    /// started and the most of it submitted.
    image: Option<(u64, Option<(Instant, u64)>)>,
    /// While the scripted drag runs: images and CAO updates completed when each last
    /// moved on, and when.
    drag: Option<[(u64, Instant); 2]>,
    /// The stall of at least [`STALL_REPORT`] seen at the last frame, with where
    /// everything stood when it was first reported.
    stall: Option<String>,
    /// `VOLAO_TRACE`: the interval, and when the state was last printed.
    trace: Option<(Duration, Option<Instant>)>,
}

impl Watchdog {
    /// A watchdog that traces every `VOLAO_TRACE` seconds, if that is set.
    fn from_env() -> Self {
        let trace = std::env::var("VOLAO_TRACE").ok().map(|s| {
            let seconds = s.trim().parse::<f64>().ok().filter(|s| *s > 0.0);
            (Duration::from_secs_f64(seconds.unwrap_or(1.0)), None)
        });
        Watchdog {
            trace,
            ..Default::default()
        }
    }
}

/// GPU time the viewport's work may take in one UI frame.
const VIEWPORT_SLICE: std::time::Duration = std::time::Duration::from_millis(25);

/// How long one submission of a background job (AO, light volume) may take. Shorter
/// slices cost the job dearly on lavapipe (the Engine's 14-ray CAO precomputation in the
/// viewer: 17 s at 100 ms, 20 s at 60 ms, 42 s at 30 ms; 16 s unsliced, with the UI
/// frozen for seconds at a time), while a UI frame waits at most one slice behind it.
const JOB_SLICE: std::time::Duration = std::time::Duration::from_millis(60);

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer")
            .field("doc", &self.opened.doc.as_ref().map(|d| &d.title))
            .finish_non_exhaustive()
    }
}

/// The [`Gpu`] of egui's render state: the same device the viewport draws with.
pub fn gpu_of(rs: &egui_wgpu::RenderState) -> Gpu {
    Gpu::new(
        rs.instance.clone(),
        rs.adapter.clone(),
        rs.device.clone(),
        rs.queue.clone(),
    )
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
    .map_err(|e| {
        // Without a usable adapter eframe fails making the window's surface: say what
        // `volao gpu` says (which driver to install), not that the display is missing.
        match crate::gpu::request_device() {
            Err(gpu) => AppError::Gpu(gpu),
            Ok(_) => AppError::Window(e.to_string()),
        }
    })?;
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
        // Long GPU work of background jobs goes in short submissions, so that the UI's
        // frames slip in between (one in-order queue).
        gpu.slicing.set_target(Some(JOB_SLICE));
        if gpu.info.backend == wgpu::Backend::Gl && std::env::var_os("VOLAO_ALLOW_GL").is_none() {
            return Err(AppError::OpenGl(gpu.info.name.clone()));
        }
        let (paint, binding) = ViewportPaint::new(&gpu.device, render_state.target_format)?;
        render_state
            .renderer
            .write()
            .callback_resources
            .insert(paint);
        let viewport = ViewportGpu::new(&gpu.device, binding)?;
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
        let pacer = crate::gpu::pacer::Pacer::new(&gpu, VIEWPORT_SLICE);
        let mut viewer = Viewer {
            gpu: Arc::new(gpu),
            ctx: ctx.clone(),
            opened: Opened::default(),
            derived: Derived::default(),
            viewport: Viewport::new(viewport, pacer, options.interactive),
            chrome: Chrome {
                recent,
                ..Chrome::default()
            },
            shots: Screenshots::default(),
            scripted: Scripted::default(),
            watchdog: Watchdog::from_env(),
            show_outlines: true,
            gpu_errors,
            exit_error: Arc::default(),
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
            self.chrome.prompt = Some(Pending::Open(request));
        } else {
            self.start_load(request);
        }
    }

    /// The document shown (`None` until the first load finishes).
    pub fn document(&self) -> Option<&Document> {
        self.opened.doc.as_ref()
    }

    /// What the AO on screen was last computed on, and how (the AO panel's
    /// "AO precomputation" line): its device, or that `V_PAO` was updated.
    pub fn ao_computed_on(&self) -> Option<&str> {
        self.derived.ao_seconds.as_ref().map(|(_, d)| d.as_str())
    }

    /// The document, for edits through the API (marks the transfer function as changed).
    /// The slice panes: layout, crosshair, where each pane is.
    pub fn slices(&self) -> &slices::SliceViews {
        &self.chrome.slices
    }

    pub fn slices_mut(&mut self) -> &mut slices::SliceViews {
        &mut self.chrome.slices
    }

    pub fn document_mut(&mut self) -> Option<&mut Document> {
        self.derived.tf_changed_at = Instant::now();
        self.opened.doc.as_mut()
    }

    /// Whether a load, an AO computation, the viewport's full-quality image or a
    /// screenshot is still on its way.
    pub fn is_busy(&self) -> bool {
        self.opened.load_job.is_some()
            || (self.opened.doc.is_some() && !self.viewport.current)
            || self.derived.ao.pending(self.ao_key().as_ref())
            || self
                .derived
                .modulation
                .pending(self.modulation_key().as_ref())
            || self.derived.light.pending(self.light_key().as_ref())
            || self.segments_waiting()
            || self.shots.request.is_some()
            || self.shots.pending.is_some()
            || self.shots.write_job.is_some()
    }

    /// Whether the AO for the current settings is on the GPU (or none is wanted).
    pub fn ao_ready(&self) -> bool {
        self.derived.ao.ready(self.ao_key().as_ref())
    }

    /// Whether the opacity modulation for the current settings is on the GPU (or none is
    /// wanted).
    pub fn modulation_ready(&self) -> bool {
        self.derived
            .modulation
            .ready(self.modulation_key().as_ref())
    }

    /// Why the opacity modulation for the current settings failed, if it did.
    pub fn modulation_error(&self) -> Option<&str> {
        self.derived
            .modulation
            .error(self.modulation_key().as_ref())
    }

    /// Whether the light volume for the current shadows is on the GPU (or none is
    /// wanted).
    pub fn light_ready(&self) -> bool {
        self.derived.light.ready(self.light_key().as_ref())
    }

    /// Why the light volume for the current shadows failed, if it did.
    pub fn light_error(&self) -> Option<&str> {
        self.derived.light.error(self.light_key().as_ref())
    }

    /// AO, modulation and shadows all computed for what the document says.
    fn derived_ready(&self) -> bool {
        self.ao_ready() && self.modulation_ready() && self.light_ready()
    }

    /// Why the AO for the current settings failed, if it did.
    pub fn ao_error(&self) -> Option<&str> {
        self.derived.ao.error(self.ao_key().as_ref())
    }

    /// Whether an update of CAO for moved clip shapes is being submitted or is still
    /// running on the GPU (the viewport shows the previous pose meanwhile).
    pub fn cao_update_in_flight(&self) -> bool {
        self.viewport.gpu.cao_in_flight()
    }

    /// Whether the image drawn read CAO's exact `V_AO` for its clip shapes (true without
    /// CAO); false: it read `V_PAO`, while CAO's update for the shapes was on its way.
    pub fn viewport_ao_exact(&self) -> bool {
        self.viewport.gpu.shown_ao_exact()
    }

    /// Images the viewport has completed so far.
    pub fn viewport_images(&self) -> u64 {
        self.viewport.gpu.frames_rendered
    }

    /// Of those, images that cast only the rays near a change since an earlier image
    /// of the same view and kept its other pixels ([`crate::render::reuse`]).
    pub fn viewport_images_reused(&self) -> u64 {
        self.viewport.gpu.frames_reused
    }

    /// Interactive quality while the view moves (the Rendering panel's, set from a
    /// script or a test).
    pub fn set_interactive(&mut self, quality: viewport::Interactive) {
        self.viewport.interactive = quality;
    }

    /// Images made while CAO's update was on its way and dropped unfinished because the
    /// next update began: while shapes only move, none is (each has its own copy of the
    /// clip maps).
    pub fn viewport_images_dropped_by_cao(&self) -> u64 {
        self.viewport.gpu.frames_dropped_by_cao
    }

    /// Voxels CAO recomputed in its last frame, in percent (`None` without CAO).
    pub fn cao_percent_recomputed(&self) -> Option<f64> {
        self.derived
            .cao_stats
            .as_ref()
            .map(|c| c.percent_recomputed())
    }

    pub fn toasts(&self) -> &[Toast] {
        &self.chrome.toasts
    }

    /// A screenshot whose write failed, kept for "Save elsewhere…".
    pub fn failed_shot(&self) -> Option<&Shot> {
        self.shots.failed.as_ref()
    }

    pub fn recent_files(&self) -> &[PathBuf] {
        &self.chrome.recent
    }

    /// The viewport's size in physical pixels (as of the last frame).
    pub fn viewport_size(&self) -> (u32, u32) {
        self.viewport.px
    }

    /// The viewport's rectangle in points (as of the last frame).
    pub fn viewport_rect(&self) -> egui::Rect {
        self.viewport.rect
    }

    /// The frame the viewport draws, at the viewport's size.
    pub fn view_frame(&self) -> Option<Frame> {
        let doc = self.opened.doc.as_ref()?;
        Some(Frame {
            camera: doc.camera,
            settings: doc.view_settings(),
            width: self.viewport.px.0.max(1),
            height: self.viewport.px.1.max(1),
        })
    }

    /// Whether the scene differs from the one last loaded or saved.
    pub fn has_unsaved_changes(&self) -> bool {
        match (&self.opened.doc, &self.opened.saved) {
            (Some(doc), Some(saved)) => doc.scene(saved.width, saved.height, false) != *saved,
            _ => false,
        }
    }

    /// Saves the scene (the same JSON `volao render` reads).
    pub fn save_scene(&mut self, path: &Path) -> Result<(), String> {
        let (w, h) = self.viewport.px;
        let doc = self.opened.doc.as_mut().ok_or("nothing to save yet")?;
        let scene = doc.scene(w.max(1), h.max(1), false);
        scene.save(path).map_err(|e| e.to_string())?;
        doc.scene_path = Some(path.to_owned());
        self.opened.saved = Some(scene);
        self.push_recent(path.to_owned());
        self.toast(format!("Saved scene {}", path.display()), false);
        Ok(())
    }

    /// Asks for a screenshot: rendered offscreen at `size`, written to `path` with the
    /// scene beside it. Waits (without blocking) for loads and AO to finish first.
    pub fn request_screenshot(&mut self, path: PathBuf, size: ShotSize) {
        self.shots.request = Some((path, size));
        self.ctx.request_repaint();
    }

    /// Writes a screenshot whose first write failed to another path.
    pub fn retry_screenshot(&mut self, path: PathBuf) {
        if let Some(mut shot) = self.shots.failed.take() {
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
        if let Some(old) = self.opened.load_job.take() {
            old.cancel();
        }
        let gpu = Arc::clone(&self.gpu);
        let label = format!("Loading {}", request.label());
        let ao_on_open = self.options.ao_on_open;
        self.opened.load_job = Some(Job::spawn(label, self.repaint_fn(), move |p| {
            load_document(&gpu, &request, ao_on_open, p)
        }));
    }

    fn poll_load(&mut self) {
        let Some(job) = &mut self.opened.load_job else {
            return;
        };
        let Some(result) = job.poll() else {
            return;
        };
        self.opened.load_job = None;
        match result {
            Ok(loaded) => {
                for w in &loaded.warnings {
                    self.toast(format!("warning: {w}"), false);
                }
                let mut doc = loaded.doc;
                if self.options.no_skipping {
                    doc.render.empty_space_skipping = false;
                }
                if let Some(n) = self.options.clip_resolution {
                    doc.ao.clip_resolution = n;
                }
                if doc.downsampled > 0 {
                    self.toast(
                        format!(
                            "The volume was halved {}× to fit the GPU's texture limits",
                            doc.downsampled
                        ),
                        false,
                    );
                }
                let (w, h) = (self.viewport.px.0.max(1), self.viewport.px.1.max(1));
                self.opened.saved = Some(doc.scene(w, h, false));
                if let Some(p) = doc.scene_path.clone().or(doc.source.path.clone()) {
                    self.push_recent(p);
                }
                self.derived.uploaded_tf = Some((doc.tf.clone(), doc.render.step_voxels));
                self.viewport.gpu.set_volume(loaded.gpu_volume);
                self.opened.doc = Some(doc);
                self.opened.generation += 1;
                // The new volume has no AO yet; what was computed for the old one is gone.
                self.derived.ao.reset();
                self.derived.preview.reset();
                self.derived.shown = AoShown::Nothing;
                self.scripted.ready_frames = 0;
                self.chrome.tf_editor = Default::default();
                // Files open on the slices and the 3-D view; the demo on its 3-D view
                // (carved, with AO: what volao is for), unless a layout was asked for.
                let demo = doc_is_demo(self.opened.doc.as_ref());
                let slices = &mut self.chrome.slices;
                slices.reset();
                slices.layout = self.options.layout.unwrap_or(if demo {
                    slices::Layout::ThreeD
                } else {
                    slices::Layout::Quad
                });
                slices.maximised = None;
            }
            Err(JobError::Cancelled) => {}
            Err(JobError::Failed(e)) => {
                let what = if self.opened.doc.is_some() {
                    " (the current volume stays)"
                } else {
                    ""
                };
                self.toast(format!("Could not open: {e}{what}"), true);
                if self.opened.doc.is_none()
                    && (self.options.exit_after_frames.is_some()
                        || self.options.bench_clip_drag.is_some())
                {
                    self.fail_exit(format!("could not open: {e}"));
                }
            }
        }
    }

    /// Ends the run with an error: the process exits non-zero (`--exit-after-frames`,
    /// `--bench-clip-drag`).
    fn fail_exit(&mut self, message: String) {
        if let Ok(mut e) = self.exit_error.lock() {
            *e = Some(message);
        }
        self.scripted.exit_requested = true;
    }

    // ----- small state --------------------------------------------------------------------

    fn toast(&mut self, text: String, error: bool) {
        if error {
            eprintln!("volao: {text}");
        }
        self.chrome.toasts.push(Toast {
            text,
            error,
            born: Instant::now(),
        });
        self.ctx.request_repaint();
    }

    fn push_recent(&mut self, path: PathBuf) {
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.chrome.recent.retain(|p| *p != path);
        self.chrome.recent.insert(0, path);
        self.chrome.recent.truncate(RECENT_MAX);
        if let Some(file) = &self.options.recent_file
            && let Err(e) = save_recent(file, &self.chrome.recent)
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
        let gpu = Arc::clone(&self.gpu);
        self.viewport.pacer.begin_frame(&gpu);
        self.poll_load();
        self.handle_input(ui);
        self.sync_segments();
        self.update_ao();
        self.update_modulation();
        self.update_light();
        self.sync_transfer_function();
        self.update_screenshots();
        let errors: Vec<String> = self
            .gpu_errors
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default();
        for e in errors {
            self.toast(format!("GPU error: {e}"), true);
        }
        self.watch();

        if self.options.bench_clip_drag.is_some() {
            self.central_viewport(ui);
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
        self.central_viewport(ui);
        self.show_prompt(ui.ctx());
        self.show_toasts(ui.ctx());
        self.update_title(ui.ctx());
        self.exit_logic(ui.ctx());
    }

    /// The viewport in the central panel: laid out, then (after the panels: the camera
    /// and shapes as this frame's input left them) its GPU work pumped and painted.
    fn central_viewport(&mut self, ui: &mut egui::Ui) {
        let bench = self.options.bench_clip_drag.is_some();
        if let Some(doc) = &self.opened.doc {
            let polled = self.chrome.slices.poll_pick(&self.gpu, doc);
            if let Err(e) = polled {
                self.toast(format!("Picking failed: {e}"), true);
            }
            if self.chrome.slices.picking() {
                ui.ctx().request_repaint();
            }
        }
        let slot = egui::CentralPanel::no_frame()
            .show(ui, |ui| {
                let rect = ui.available_rect_before_wrap();
                // The benchmark shows the 3-D view alone unless a layout was asked for.
                let open = self.opened.doc.is_some() && (!bench || self.options.layout.is_some());
                let mut slot = None;
                for (pane, r) in self.chrome.slices.pane_rects(rect, open) {
                    match pane {
                        slices::Pane::ThreeD => slot = self.viewport(ui, r),
                        slices::Pane::Slice(axis) => {
                            if let Some(doc) = &mut self.opened.doc {
                                let binding = self.viewport.gpu.binding();
                                self.chrome
                                    .slices
                                    .show(ui, doc, axis, r, &self.gpu, binding);
                            }
                        }
                    }
                }
                slot
            })
            .inner;
        self.update_hover(ui);
        self.pump_viewport();
        self.paint_viewport(slot);
    }
}

/// Whether the document is the built-in demo volume.
fn doc_is_demo(doc: Option<&Document>) -> bool {
    doc.is_some_and(|d| d.source.path.is_none())
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
