//! Scene files: versioned JSON holding everything needed to reproduce a rendering —
//! the volume (path relative to the scene file where possible), transfer function,
//! camera, light, render settings, image size, the ambient-occlusion method, clip shapes
//! and meshes. [`Scene::load_options`] says how to read its volume.

use crate::ao::AoSettings;
use crate::render::{Camera, RenderSettings};
use crate::tf::TransferFunction;
use crate::volume::{Endian, LoadOptions, RawOverrides, VoxelType};
use std::path::{Path, PathBuf};

/// Image side when neither a flag nor a scene gives one.
pub const DEFAULT_SIZE: u32 = 800;

/// The largest image side volao renders.
pub const MAX_SIZE: u32 = 32768;

/// The scene format this volao writes and the newest it reads.
pub const SCENE_VERSION: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: not a valid volao scene: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error(
        "{path}: scene version {found} is newer than this volao understands (up to {SCENE_VERSION}); update volao"
    )]
    TooNew { path: PathBuf, found: u64 },
}

/// Raw layout saved with the scene, so raw volumes reopen without flags.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawLayout {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dims: Option<[usize; 3]>,
    #[serde(rename = "type", skip_serializing_if = "Option::is_none")]
    pub ty: Option<VoxelType>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub endian: Option<Endian>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spacing: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset: Option<u64>,
}

impl From<&RawOverrides> for RawLayout {
    fn from(r: &RawOverrides) -> Self {
        RawLayout {
            dims: r.dims,
            ty: r.ty,
            endian: r.endian,
            spacing: r.spacing,
            offset: r.offset,
        }
    }
}

impl From<&RawLayout> for RawOverrides {
    fn from(r: &RawLayout) -> Self {
        RawOverrides {
            dims: r.dims,
            ty: r.ty,
            endian: r.endian,
            spacing: r.spacing,
            offset: r.offset,
        }
    }
}

/// Which volume to show.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeSource {
    /// File path; relative paths are relative to the scene file. `None`: the demo volume.
    pub path: Option<PathBuf>,
    #[serde(default)]
    pub frame: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw: Option<RawLayout>,
    /// OME-Zarr: the multiscale level read (0 = full resolution).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub level: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl VolumeSource {
    /// The source that reads `path` (`None`: the demo volume) with `options`' 4-D frame and
    /// raw layout; an empty layout is left out.
    pub fn from_load_options(path: Option<PathBuf>, options: &LoadOptions) -> VolumeSource {
        VolumeSource {
            path,
            frame: options.frame,
            raw: (!options.raw.is_empty()).then(|| RawLayout::from(&options.raw)),
            level: options.level,
        }
    }

    /// How to read this volume: its 4-D frame and raw layout (default memory budget).
    pub fn load_options(&self) -> LoadOptions {
        LoadOptions {
            frame: self.frame,
            raw: self
                .raw
                .as_ref()
                .map(RawOverrides::from)
                .unwrap_or_default(),
            max_bytes: None,
            series: None,
            level: self.level,
        }
    }
}

/// The light: a headlight, or a directional light (which volumetric shadows use).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Light {
    #[default]
    Headlight,
    /// Parallel light arriving from `direction` (towards the light, volume RAS space).
    Directional { direction: [f32; 3] },
}

/// A complete, reproducible view.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub version: u32,
    pub volume: VolumeSource,
    pub transfer_function: TransferFunction,
    #[serde(default)]
    pub camera: Camera,
    #[serde(default)]
    pub light: Light,
    #[serde(default)]
    pub render: RenderSettings,
    pub width: u32,
    pub height: u32,
    /// Ambient-occlusion method and parameters.
    #[serde(default)]
    pub ambient_occlusion: AoSettings,
    /// Clip shapes with their poses (mm from the volume's centre) and modes. Mesh
    /// paths, like the volume's, are relative to the scene file.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clip_shapes: Vec<crate::clip::ClipShape>,
    /// Meshes drawn inside the volume (OBJ, mm from the volume's centre); paths relative
    /// to the scene file.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub meshes: Vec<MeshSource>,
    /// A segmentation of the volume, with how its segments show (the clip shapes say
    /// which segments they cut); paths relative to the scene file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segmentation: Option<SegmentationSource>,
}

/// A label map beside the volume: its file, a colour table, and its segments' styles.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentationSource {
    pub path: PathBuf,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<PathBuf>,
    #[serde(default)]
    pub styles: crate::labels::style::Styles,
}

/// A mesh file drawn inside the volume, with its colour.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSource {
    pub path: PathBuf,
    /// Straight RGBA in 0…1 (A < 1: translucent).
    pub rgba: [f32; 4],
}

impl Scene {
    /// The scene of a plain volume: the TF preset for the data's range (`stats`), default
    /// camera, headlight, settings and AO, 800×800.
    pub fn default_for(volume: VolumeSource, stats: &crate::volume::Stats) -> Scene {
        use crate::tf::Preset;
        Scene {
            version: SCENE_VERSION,
            volume,
            transfer_function: TransferFunction::preset(Preset::default_for(stats), stats),
            camera: Default::default(),
            light: Light::Headlight,
            render: RenderSettings::default(),
            width: DEFAULT_SIZE,
            height: DEFAULT_SIZE,
            ambient_occlusion: AoSettings::default(),
            clip_shapes: Vec::new(),
            meshes: Vec::new(),
            segmentation: None,
        }
    }

    /// Points the ray caster's light where the scene's light is (a headlight shines from
    /// the eye) and checks the image size; done before every render.
    pub fn settle(&mut self) -> Result<(), String> {
        self.render.light_direction = match self.light {
            Light::Directional { direction } => direction,
            // Shadows of a headlight fall behind what casts them, from the eye's direction.
            Light::Headlight => self.camera.backward().to_array(),
        };
        if self.render.shadows {
            crate::render::shadow::light_direction(self.render.light_direction)?;
        }
        let (width, height) = (self.width, self.height);
        if width == 0 || height == 0 || width > MAX_SIZE || height > MAX_SIZE {
            return Err(format!(
                "image size {width}×{height}: each side must be 1 to {MAX_SIZE} pixels"
            ));
        }
        Ok(())
    }

    /// Reads a scene, checking its version before anything else.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|e| SceneError::Io {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        Self::parse(&text, path)
    }

    /// Reads a scene file with its paths resolved against it, ready to render (and to be
    /// saved elsewhere, in this volao's format).
    pub fn open(path: &Path) -> Result<Scene, SceneError> {
        let mut scene = Scene::load(path)?;
        scene.resolve_paths(path);
        scene.version = SCENE_VERSION;
        Ok(scene)
    }

    /// Parses scene JSON; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let invalid = |message: String| SceneError::Invalid {
            path: path.to_owned(),
            message,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| invalid(format!("malformed JSON ({e})")))?;
        let version = value
            .get("version")
            .ok_or_else(|| invalid("no \"version\" field".into()))?
            .as_u64()
            .ok_or_else(|| invalid("\"version\" is not a whole number".into()))?;
        if version > SCENE_VERSION as u64 {
            return Err(SceneError::TooNew {
                path: path.to_owned(),
                found: version,
            });
        }
        if version == 0 {
            return Err(invalid("version 0 does not exist".into()));
        }
        let scene: Scene = serde_json::from_value(value).map_err(|e| invalid(e.to_string()))?;
        scene
            .transfer_function
            .validate()
            .map_err(|e| invalid(format!("transfer function: {e}")))?;
        if scene.width == 0 || scene.height == 0 {
            return Err(invalid(format!(
                "image size {}×{} has a zero side",
                scene.width, scene.height
            )));
        }
        Ok(scene)
    }

    /// Writes the scene as pretty JSON, storing the volume path relative to the scene
    /// file when the volume lies in the same folder tree.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        let mut scene = self.clone();
        if let Some(vol) = &self.volume.path {
            scene.volume.path = Some(relative_to(vol, path.parent().unwrap_or(Path::new("."))));
        }
        let base = path.parent().unwrap_or(Path::new("."));
        for m in &mut scene.meshes {
            m.path = relative_to(&m.path, base);
        }
        if let Some(s) = &mut scene.segmentation {
            s.path = relative_to(&s.path, base);
            s.table = s.table.as_ref().map(|t| relative_to(t, base));
        }
        for c in &mut scene.clip_shapes {
            if let crate::clip::Shape::Mesh { path: mesh } = &mut c.shape {
                *mesh = relative_to(mesh, path.parent().unwrap_or(Path::new(".")));
            }
        }
        let text = serde_json::to_string_pretty(&scene).map_err(|e| SceneError::Io {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        std::fs::write(path, text + "\n").map_err(|e| SceneError::Io {
            path: path.to_owned(),
            message: e.to_string(),
        })
    }

    /// How to read the scene's volume: its 4-D frame and raw layout (the path is
    /// [`Scene::volume_path`]).
    pub fn load_options(&self) -> LoadOptions {
        self.volume.load_options()
    }

    /// Resolves the paths of the volume, the clip meshes and the meshes against the scene
    /// file's folder, so the scene can be used (and saved elsewhere) without it.
    pub fn resolve_paths(&mut self, scene_path: &Path) {
        self.volume.path = self.volume_path(scene_path);
        self.clip_shapes = self.clip_shapes_resolved(scene_path);
        self.meshes = self.meshes_resolved(scene_path);
        let base = scene_path.parent().unwrap_or(Path::new("."));
        if let Some(s) = &mut self.segmentation {
            s.path = base.join(&s.path);
            s.table = s.table.as_ref().map(|t| base.join(t));
        }
    }

    /// The clip shapes with mesh paths resolved against the scene file's folder.
    pub fn clip_shapes_resolved(&self, scene_path: &Path) -> Vec<crate::clip::ClipShape> {
        let base = scene_path.parent().unwrap_or(Path::new("."));
        self.clip_shapes
            .iter()
            .cloned()
            .map(|mut c| {
                if let crate::clip::Shape::Mesh { path } = &mut c.shape
                    && path.is_relative()
                {
                    *path = base.join(&*path);
                }
                c
            })
            .collect()
    }

    /// The meshes with paths resolved against the scene file's folder.
    pub fn meshes_resolved(&self, scene_path: &Path) -> Vec<MeshSource> {
        let base = scene_path.parent().unwrap_or(Path::new("."));
        self.meshes
            .iter()
            .map(|m| MeshSource {
                path: if m.path.is_relative() {
                    base.join(&m.path)
                } else {
                    m.path.clone()
                },
                rgba: m.rgba,
            })
            .collect()
    }

    /// The volume's path resolved against the scene file's folder.
    pub fn volume_path(&self, scene_path: &Path) -> Option<PathBuf> {
        let p = self.volume.path.as_ref()?;
        Some(if p.is_absolute() {
            p.clone()
        } else {
            scene_path.parent().unwrap_or(Path::new(".")).join(p)
        })
    }
}

/// `target` relative to the folder `base` (with `..` where needed), or absolute when the
/// two share no root (another drive on Windows).
fn relative_to(target: &Path, base: &Path) -> PathBuf {
    use std::path::Component;
    let abs = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_owned())
        })
    };
    let (t, b) = (abs(target), abs(base));
    let (tc, bc): (Vec<Component>, Vec<Component>) =
        (t.components().collect(), b.components().collect());
    let common = tc.iter().zip(&bc).take_while(|(x, y)| x == y).count();
    // Only the root in common (or not even that): a relative path would not help.
    if common <= 1 {
        return t;
    }
    let mut rel = PathBuf::new();
    for _ in common..bc.len() {
        rel.push("..");
    }
    for c in &tc[common..] {
        rel.push(c);
    }
    rel
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tf::Preset;

    fn scene() -> Scene {
        let stats = crate::volume::Stats {
            min: -1024.0,
            max: 3071.0,
            mean: 0.0,
            non_finite: 0,
            finite: 1,
        };
        Scene {
            version: SCENE_VERSION,
            volume: VolumeSource {
                path: Some("ct.raw".into()),
                frame: 0,
                level: 0,
                raw: Some(RawLayout {
                    dims: Some([4, 4, 4]),
                    ty: Some(VoxelType::I16),
                    ..Default::default()
                }),
            },
            transfer_function: TransferFunction::preset(Preset::CtBone, &stats),
            camera: Camera {
                azimuth_deg: 45.0,
                ..Default::default()
            },
            light: Light::Headlight,
            render: RenderSettings::default(),
            width: 320,
            height: 200,
            ambient_occlusion: AoSettings {
                method: crate::ao::AoMethod::Lao,
                rays: crate::ao::rays::RaySet::Fibonacci(96),
                samples: 12,
                ..Default::default()
            },
            clip_shapes: vec![
                crate::clip::ClipShape::new(
                    crate::clip::Shape::Sphere,
                    glam::Vec3::new(1.0, 2.0, 3.0),
                    10.0,
                ),
                crate::clip::ClipShape {
                    mode: crate::clip::ClipMode::Probe,
                    ..crate::clip::ClipShape::new(
                        crate::clip::Shape::Torus { tube: 0.3 },
                        glam::Vec3::ZERO,
                        20.0,
                    )
                },
            ],
            meshes: Vec::new(),
            segmentation: None,
        }
    }

    #[test]
    fn scenes_round_trip_with_reserved_fields() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("s.json");
        std::fs::write(dir.path().join("ct.raw"), [0u8; 128]).expect("write");
        let mut s = scene();
        s.volume.path = Some(dir.path().join("ct.raw"));
        s.save(&path).expect("save");
        let back = Scene::load(&path).expect("load");
        assert_eq!(
            back.volume.path.as_deref(),
            Some(Path::new("ct.raw")),
            "stored relative to the scene"
        );
        assert_eq!(back.volume_path(&path), Some(dir.path().join("ct.raw")));
        assert_eq!(
            Scene {
                volume: s.volume.clone(),
                ..back
            },
            s
        );
    }

    #[test]
    fn volume_paths_beside_the_scene_folder_are_relative() {
        let dir = tempfile::tempdir().expect("temp dir");
        std::fs::create_dir_all(dir.path().join("scenes/figures")).expect("mkdir");
        std::fs::create_dir_all(dir.path().join("data")).expect("mkdir");
        let volume = dir.path().join("data/ct.raw");
        std::fs::write(&volume, [0u8; 8]).expect("write");
        let base = dir.path().join("scenes/figures");
        assert_eq!(relative_to(&volume, &base), Path::new("../../data/ct.raw"));
        assert_eq!(
            relative_to(&volume, &dir.path().join("data")),
            Path::new("ct.raw")
        );
        let scene_path = base.join("s.json");
        let s = Scene {
            volume: VolumeSource {
                path: Some(volume.clone()),
                frame: 0,
                raw: None,
                level: 0,
            },
            ..scene()
        };
        s.save(&scene_path).expect("save");
        let back = Scene::load(&scene_path).expect("load");
        assert_eq!(
            back.volume_path(&scene_path)
                .map(|p| p.canonicalize().expect("exists")),
            Some(volume.canonicalize().expect("exists"))
        );
    }

    #[test]
    fn load_options_carry_the_frame_and_raw_layout() {
        let mut s = scene();
        s.volume.frame = 2;
        let o = s.load_options();
        assert_eq!(o.frame, 2);
        assert_eq!(o.raw.dims, Some([4, 4, 4]));
        assert_eq!(o.raw.ty, Some(VoxelType::I16));
        assert_eq!(o.max_bytes, None);
        assert_eq!(
            VolumeSource::from_load_options(s.volume.path.clone(), &o),
            s.volume
        );
        s.volume.raw = Some(RawLayout::default());
        let o = s.load_options();
        assert!(o.raw.is_empty());
        assert_eq!(
            VolumeSource::from_load_options(None, &o).raw,
            None,
            "empty layouts are left out"
        );
    }

    #[test]
    fn bad_scenes_are_refused_clearly() {
        let p = Path::new("bad.json");
        let msg = |t: &str| Scene::parse(t, p).expect_err("must fail").to_string();
        assert!(msg("{ not json").contains("malformed JSON"));
        assert!(msg("{}").contains("no \"version\""));
        let mut v = serde_json::to_value(scene()).expect("json");
        v["version"] = serde_json::json!(99);
        assert!(msg(&v.to_string()).contains("scene version 99 is newer"));
        v["version"] = serde_json::json!(1);
        v["width"] = serde_json::json!(0);
        assert!(msg(&v.to_string()).contains("zero side"));
        v["width"] = serde_json::json!(10);
        v["camra"] = serde_json::json!({});
        assert!(
            msg(&v.to_string()).contains("camra"),
            "unknown fields are named"
        );
    }
}
