//! Headless work from scene files, one code path for `volao render`, `volao ao`,
//! `volao batch` and the Python module: a scene's volume, segmentation and meshes made
//! ready ([`Prepared`]), its frame rendered ([`render`]) on the process's one device
//! ([`DeviceSlot`]), and an ambient-occlusion volume in a volume's own geometry
//! ([`ao_volume`]). Nothing here prints: notes and warnings come back as lines.

use crate::ao::cao::{CaoStats, CaoVolume};
use crate::ao::sparse::Coverage;
use crate::ao::{Ambient, AoEngine, AoInput, AoMethod, AoRequest, AoSettings};
use crate::clip::ClipShape;
use crate::gpu::{Gpu, GpuError, GpuUse};
use crate::labels::{self, style};
use crate::render::Frame;
use crate::render::offscreen::{RenderJob, Rendered};
use crate::render::surface::{Surface, SurfaceError};
use crate::scene::{Scene, SceneError};
use crate::texels::segments::SegmentTexels;
use crate::texels::{UploadLimits, VolumeTexels};
use crate::tf::TransferFunction;
use crate::volume::{self, Scaling, Volume, VolumeError, VoxelData};
use std::sync::{Arc, OnceLock};

/// What can stop a scene from rendering or an AO volume from being computed; each
/// message is the one line the CLI prints after `error:`.
#[derive(Debug, thiserror::Error)]
pub enum HeadlessError {
    #[error(transparent)]
    Volume(#[from] VolumeError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Mesh(#[from] SurfaceError),
    /// A setting that cannot work, said in the user's terms.
    #[error("{0}")]
    Invalid(String),
}

/// Loads the volume a scene names, in the file's own geometry (`volao ao`'s; the ray
/// caster wants [`Volume::to_ras`] of it), with the loader's warnings; the built-in demo
/// phantom when the scene names none. `progress(bytes read, bytes in all)`.
pub fn load_volume(
    scene: &Scene,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Volume, Vec<String>), VolumeError> {
    match &scene.volume.path {
        Some(path) => {
            let loaded = volume::load_with_progress(path, &scene.load_options(), progress)?;
            let warnings = loaded
                .warnings
                .iter()
                .map(|w| format!("{}: {w}", volume::display_path(path)))
                .collect();
            Ok((loaded.volume, warnings))
        }
        None => Ok((volume::demo::head_phantom(128), Vec::new())),
    }
}

/// A scene's data made ready to render: the volume in RAS order, its segmentation's
/// texels and its meshes.
#[derive(Debug)]
pub struct Prepared {
    pub volume: Volume,
    pub segments: Option<SegmentTexels>,
    pub surfaces: Vec<Surface>,
    /// Non-fatal problems met on the way, one line each.
    pub warnings: Vec<String>,
}

impl Prepared {
    /// Loads `scene`'s segmentation onto `volume` (already in RAS order), applies the
    /// style changes `specs` (`volao render --segment`'s `PATTERN:CHANGE,…`) to the
    /// scene's styles, and loads its meshes.
    pub fn new(scene: &mut Scene, volume: Volume, specs: &[String]) -> Result<Self, HeadlessError> {
        let mut warnings = Vec::new();
        let segments = match &mut scene.segmentation {
            None if !specs.is_empty() => {
                return Err(HeadlessError::Invalid(
                    "segment styles need a segmentation: the scene has none".into(),
                ));
            }
            None => None,
            Some(source) => {
                let loaded = labels::load(&source.path, source.table.as_deref(), &volume)?;
                warnings.extend(loaded.warnings);
                let map = loaded.labels;
                for spec in specs {
                    source
                        .styles
                        .apply(&map, spec)
                        .map_err(HeadlessError::Invalid)?;
                }
                style::check_cuts(&map, &scene.clip_shapes).map_err(HeadlessError::Invalid)?;
                let classes = style::Classes::of(&map).map_err(HeadlessError::Invalid)?;
                Some(style::segment_texels(
                    &map,
                    &classes,
                    &source.styles,
                    &scene.clip_shapes,
                ))
            }
        };
        let surfaces = scene
            .meshes
            .iter()
            .map(|m| crate::render::surface::load_obj(&m.path, m.rgba))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Prepared {
            volume,
            segments,
            surfaces,
            warnings,
        })
    }
}

/// Gives an intensity projection (MIP, average) without a window of its own the window
/// its values are readable in, as `volao render` does (MinIP keeps the transfer
/// function's window); returns the note that says what was chosen or why it is dark.
pub fn projection_window(scene: &mut Scene, stats: &volume::Stats) -> Option<String> {
    if scene.render.projection_window.is_some() {
        return None;
    }
    let (window, note) =
        crate::render::readable_window(scene.render.mode, &scene.transfer_function, stats)?;
    if scene.render.mode != crate::render::RenderMode::Minip {
        scene.render.projection_window = Some(window);
    }
    Some(note)
}

/// Whether `scene` cannot be rendered without a GPU: clip shapes' depth maps are
/// rasterised, and CAO and lao-full clip.
pub fn needs_gpu(scene: &Scene) -> bool {
    !scene.clip_shapes.is_empty() || scene.ambient_occlusion.method.is_clipped()
}

/// A process's one device for headless work: opened on first use, then reused by every
/// scene and AO volume (`volao batch`, the Python module). Remembers why there is none.
#[derive(Debug, Default)]
pub struct DeviceSlot(OnceLock<Result<Arc<Gpu>, String>>);

impl DeviceSlot {
    /// The device, opened now if this is the first call.
    pub fn get(&self) -> Result<Arc<Gpu>, String> {
        self.0
            .get_or_init(|| {
                crate::gpu::request_device()
                    .map(Arc::new)
                    .map_err(|e| e.to_string())
            })
            .clone()
    }

    /// The device to render `scene` on: the slot's, or the CPU twin (`None`, with why in
    /// `notes`) when there is no adapter and the scene can do without one.
    pub fn for_scene(
        &self,
        scene: &Scene,
        notes: &mut Vec<String>,
    ) -> Result<Option<Arc<Gpu>>, HeadlessError> {
        match self.get() {
            Ok(g) => Ok(Some(g)),
            Err(e) if needs_gpu(scene) => Err(HeadlessError::Invalid(e)),
            Err(e) => {
                notes.push(e);
                notes.push("rendering on the CPU instead (slow)".into());
                Ok(None)
            }
        }
    }

    /// How AO computations use the slot's device (the CPU twins when there is none).
    pub fn gpu_use(&self) -> GpuUse {
        match self.get() {
            Ok(g) => GpuUse::Shared(g),
            Err(_) => GpuUse::Cpu,
        }
    }
}

/// Renders `scene` (its data in `prepared`) on `gpu`, or on the CPU twin for `None`.
/// `progress(done, total)` reports AO precomputation in z-slices.
pub fn render(
    scene: &Scene,
    prepared: &Prepared,
    gpu: Option<&Arc<Gpu>>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let frame = Frame {
        camera: scene.camera,
        settings: scene.render,
        width: scene.width,
        height: scene.height,
    };
    let job = RenderJob {
        volume: &prepared.volume,
        tf: &scene.transfer_function,
        frame: &frame,
        ao: &scene.ambient_occlusion,
        clip: &scene.clip_shapes,
        surfaces: &prepared.surfaces,
        segments: prepared.segments.as_ref(),
    };
    crate::render::offscreen::render(gpu, &job, progress)
}

/// An ambient-occlusion volume with what computed it.
#[derive(Debug)]
pub struct AoVolume {
    /// `A(x)` as f32 in the input's geometry, described (what `volao ao` writes).
    pub volume: Volume,
    /// The adapter, or "CPU twin (N threads)".
    pub device: String,
    /// How the AO was computed, where that needs saying.
    pub notes: Vec<String>,
    /// CAO / lao-full figures.
    pub cao: Option<CaoStats>,
}

/// Computes the ambient factor of `volume` in its own geometry with `tf` and `settings`
/// (clipped by `clip` for CAO and lao-full). `progress(done, total)` in z-slices.
pub fn ao_volume(
    volume: &Volume,
    tf: &TransferFunction,
    settings: &AoSettings,
    clip: &[ClipShape],
    coverage: Coverage,
    gpu: &GpuUse,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<AoVolume, HeadlessError> {
    if settings.method == AoMethod::None {
        return Err(HeadlessError::Invalid(
            "AO method none computes nothing; use lao, cao, vao, cdf, gauss, penner or cone".into(),
        ));
    }
    if settings.samples == 0 {
        return Err(HeadlessError::Invalid(
            "AO samples per ray must be at least 1".into(),
        ));
    }
    if !clip.is_empty() && !matches!(settings.method, AoMethod::Cao | AoMethod::LaoFull) {
        return Err(HeadlessError::Invalid(
            "clip shapes need the AO method cao or lao-full (plain LAO ignores clipping)".into(),
        ));
    }
    // The volume at full resolution: the engine says when it cannot go to the GPU.
    let texels = VolumeTexels::new(volume, UploadLimits::NONE);
    let engine = AoEngine::new(gpu);
    // Live positional AO exported as a volume is the precomputed one.
    let mut precomputed = *settings;
    if precomputed.method == AoMethod::VaoLive {
        precomputed.method = AoMethod::Vao;
    }
    let request = AoRequest {
        tf,
        settings: &precomputed,
        clip: Some(clip),
        coverage,
        view: None,
    };
    let computed = engine.compute(AoInput::Texels(&texels), &request, progress)?;
    let values = match computed.ambient {
        Ambient::Values(values) => values,
        Ambient::Cao(c) => {
            let gpu = engine
                .gpu()
                .ok_or_else(|| HeadlessError::Invalid("CAO ran without a GPU".into()))?;
            c.read(gpu, CaoVolume::Ambient)?
        }
        Ambient::One | Ambient::Live => vec![1.0; texels.dims.iter().product()],
    };
    let mut notes = computed.notes;
    if let Some(stats) = &computed.cao {
        notes.extend(stats.clip_errors.iter().cloned());
    }
    Ok(AoVolume {
        volume: Volume {
            dims: volume.dims,
            spacing: volume.spacing,
            data: VoxelData::F32(values),
            scaling: Scaling::IDENTITY,
            orientation: volume.orientation,
            descriptions: vec![("description".into(), ao_description(settings, tf))],
        },
        device: computed.device,
        notes,
        cao: computed.cao,
    })
}

/// What computed an AO volume, in words (`volao ao`'s summary line says the same).
pub fn ao_method_words(settings: &AoSettings) -> String {
    if crate::ao::fast::handles(settings.method) {
        return crate::ao::fast::describe(settings);
    }
    match settings.method {
        AoMethod::Vao | AoMethod::VaoLive => format!(
            "positional AO, {} directions × {} samples, r_max {} mm",
            settings.vao.directions, settings.vao.samples, settings.vao.r_max_mm
        ),
        method => format!(
            "{}, {} rays × {} samples",
            match method {
                AoMethod::Cao => "CAO",
                AoMethod::LaoFull => "LAO (every voxel, clipped)",
                _ => "LAO",
            },
            settings.rays.name(),
            settings.samples
        ),
    }
}

/// The description an AO volume file carries.
fn ao_description(settings: &AoSettings, tf: &TransferFunction) -> String {
    if crate::ao::fast::handles(settings.method) {
        format!(
            "ambient factor: {}, TF {}",
            crate::ao::fast::describe(settings),
            tf.name
        )
    } else if matches!(settings.method, AoMethod::Vao | AoMethod::VaoLive) {
        let s = &settings.vao;
        let iso = match s.isosurface {
            Some(i) => format!(", isosurface {} ± {}", i.value, i.tolerance),
            None => String::new(),
        };
        format!(
            "positional AO ambient factor 1 - A_P, {} directions x {} samples, r_max {} mm{iso}, TF {}",
            s.directions, s.samples, s.r_max_mm, tf.name
        )
    } else {
        let method = match settings.method {
            AoMethod::Cao => "CAO",
            AoMethod::LaoFull => "LAO (every frame, clipped)",
            _ => "LAO",
        };
        format!(
            "{method} ambient factor, {} rays x {} samples, TF {}",
            settings.rays.name(),
            settings.samples,
            tf.name
        )
    }
}
