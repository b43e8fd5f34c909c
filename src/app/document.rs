//! The document the viewer shows (what a scene file holds plus the loaded data) and
//! how it is read: [`load_document`] runs on a worker thread and uploads the volume.

use super::jobs::{Job, Progress};
use super::segments::Segmentation;
use crate::ao::AoSettings;
use crate::gpu::Gpu;
use crate::render::gpu::RenderVolume;
use crate::render::{Camera, RenderSettings, Shading};
use crate::scene::{Light, MeshSource, SCENE_VERSION, Scene, SegmentationSource, VolumeSource};
use crate::texels::{UploadLimits, VolumeTexels};
use crate::tf::{Preset, TransferFunction};
use crate::volume::{self, Histogram, LoadOptions, Stats, Volume};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Edge of the built-in demo volume (the same phantom `volao render` uses without a file).
pub const DEMO_SIZE: usize = 128;

/// Bins of the transfer-function editor's histogram.
const HISTOGRAM_BINS: usize = 256;

/// What to open.
#[derive(Debug, Clone)]
pub enum OpenRequest {
    /// The built-in demo volume.
    Demo,
    /// A volume file with the options (raw layout, 4-D frame) to read it, and a
    /// segmentation to show with it.
    Volume {
        path: PathBuf,
        options: LoadOptions,
        labels: Option<Box<SegmentationSource>>,
    },
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
                labels: None,
            }
        }
    }

    pub(super) fn label(&self) -> String {
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
    /// Edge of the clip shapes' depth maps (`--clip-maps N`), replacing the opened
    /// scene's (a scene saved from the viewer keeps it, so `volao render` clips alike).
    /// The maps are rebuilt only when a shape's geometry changes; moving a shape changes
    /// a matrix.
    pub clip_resolution: Option<u32>,
    /// Benchmark (`volao view --bench-clip-drag N`): the viewport alone fills the window;
    /// once AO is ready, the first clip shape moves 1 mm every frame for N frames, then the
    /// frame times are printed and the viewer closes.
    pub bench_clip_drag: Option<u64>,
    /// Every volume opens with every skip off (`--no-skipping`: the naive result).
    pub no_skipping: bool,
    /// Interactive quality while the view moves, as the viewer starts (`--target-rate`;
    /// the Rendering panel changes it).
    pub interactive: super::viewport::Interactive,
    /// The layout every opened volume starts in (`--layout`); `None`: 2×2 for a file,
    /// the 3-D view alone for the demo.
    pub layout: Option<crate::slice::Layout>,
    /// A volume file opens with the best AO the adapter affords within the demo's budget
    /// (off: without AO, as the tests of other things want).
    pub ao_on_open: bool,
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
            clip_resolution: None,
            bench_clip_drag: None,
            no_skipping: false,
            interactive: Default::default(),
            layout: None,
            ao_on_open: true,
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

pub(super) fn file_name(path: &Path) -> String {
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
    /// A line for the status bar about how the document was set up (the demo's AO).
    pub note: Option<String>,
    /// The segmentation shown with the volume, with its styles (the Segments panel).
    pub segmentation: Option<Segmentation>,
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
        s.ao_reference = self.ao.reference();
        // As `volao render` does: a headlight's shadows fall from the eye's direction.
        s.light_direction = match self.light {
            Light::Directional { direction } => direction,
            Light::Headlight => self.camera.backward().to_array(),
        };
        // As `volao render` does: a window for the average where the TF's shows nothing.
        if s.projection_window.is_none()
            && s.mode == crate::render::RenderMode::Average
            && let Some((w, _)) = crate::render::readable_window(s.mode, &self.tf, &self.stats)
        {
            s.projection_window = Some(w);
        }
        if self.ao_only {
            // The ambient term alone: C_TF · A_s with A_s = 1 − s·(1 − A).
            s.ambient = 1.0;
            s.shading = Shading::None;
            s.ao_ambient_only = true;
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
            segmentation: self.segmentation.as_ref().map(Segmentation::source),
        }
    }
}

/// A loaded document with its volume uploaded (the result of a load job).
#[derive(Debug)]
pub struct LoadedDocument {
    pub doc: Document,
    pub gpu_volume: RenderVolume,
    pub warnings: Vec<String>,
}

/// What the viewer has open: the document, the load on its way and the scene as last
/// saved.
#[derive(Default)]
pub(super) struct Opened {
    /// The document shown (`None` until the first load finishes).
    pub(super) doc: Option<Document>,
    /// Bumped by every load: what was derived from an earlier document is stale.
    pub(super) generation: u64,
    /// The scene as last loaded or saved (for the unsaved-changes prompt).
    pub(super) saved: Option<Scene>,
    pub(super) load_job: Option<Job<LoadedDocument>>,
}

/// Reads and uploads what `request` names (runs on a worker thread).
pub fn load_document(
    gpu: &Gpu,
    request: &OpenRequest,
    ao_on_open: bool,
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
        (OpenRequest::Volume { path, options, .. }, _, _) => (Some(path.clone()), options.clone()),
        (OpenRequest::Scene(_), Some(s), Some(sp)) => (s.volume_path(sp), s.load_options()),
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
    // The segmentation is placed on the volume as uploaded (RAS), as `volao render` does.
    let segmentation_source = match (request, &scene, &scene_path) {
        (OpenRequest::Volume { labels, .. }, _, _) => labels.as_deref().cloned(),
        (OpenRequest::Scene(_), Some(s), Some(sp)) => s.segmentation.clone().map(|mut s| {
            let base = sp.parent().unwrap_or(Path::new("."));
            s.path = base.join(&s.path);
            s.table = s.table.as_ref().map(|t| base.join(t));
            s
        }),
        _ => None,
    };
    let segmentation = match segmentation_source {
        Some(source) => {
            let (seg, notes) = Segmentation::load(source, &volume, &clip_shapes)?;
            warnings.extend(notes);
            Some(seg)
        }
        None => None,
    };
    progress.check();
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
    let uploaded = RenderVolume::from_texels(gpu, texels, &tf, render.step_voxels);
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
    // The demo opens carved and with AO, the AO chosen from the adapter's measured rate.
    let demo = matches!(request, OpenRequest::Demo).then(|| super::demo::start(gpu, &volume, &tf));
    // A file opens with the best AO the adapter affords within the same budget.
    let file_ao = (ao_on_open && matches!(request, OpenRequest::Volume { .. }))
        .then(|| super::demo::file_ao(gpu, volume.dims.iter().product(), &tf));
    let title = match &path {
        Some(p) => file_name(p),
        None => "demo head phantom".into(),
    };
    let source = VolumeSource::from_load_options(path.clone(), &options);
    let doc = Document {
        source,
        scene_path,
        title,
        info,
        volume: Arc::new(volume),
        stats,
        histogram,
        tf,
        camera: match (&scene, &demo) {
            (Some(s), _) => s.camera,
            (None, Some(d)) => d.camera,
            (None, None) => Camera::default(),
        },
        render,
        ao: match (&scene, &demo, &file_ao) {
            (Some(s), _, _) => s.ambient_occlusion,
            (None, Some(d), _) => d.ao,
            (None, None, Some((ao, _))) => *ao,
            (None, None, None) => AoSettings::default(),
        },
        ao_only: false,
        clip_shapes: match &demo {
            Some(d) => d.clip_shapes.clone(),
            None => clip_shapes,
        },
        light,
        meshes,
        radius,
        downsampled,
        note: demo.map(|d| d.note).or(file_ao.map(|(_, note)| note)),
        segmentation,
    };
    Ok(LoadedDocument {
        doc,
        gpu_volume,
        warnings,
    })
}
