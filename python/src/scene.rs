//! `volao.Scene`: a scene file's fields (volume, transfer function, camera, light,
//! render settings, size, AO, clip shapes, meshes, segmentation) given as keywords or
//! read from a file, rendered into a numpy `(H, W, 4)` uint8 image with the bytes of
//! `volao render` of the saved scene.

use crate::convert::{image_array, json_of};
use crate::volume::PyVolume;
use crate::{DEVICE, Progress, VolaoError, gpu_turn, load_error, log, py_error};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::Value;
use std::path::{Path, PathBuf};
use volao::headless::{self, Prepared};
use volao::scene::{Scene, SegmentationSource, VolumeSource};
use volao::tf::{Preset, TransferFunction};

/// Keywords that replace (or, for objects, update) the scene file's field of that name.
const FIELDS: [&str; 10] = [
    "transfer_function",
    "camera",
    "light",
    "render",
    "width",
    "height",
    "ambient_occlusion",
    "clip_shapes",
    "meshes",
    "segmentation",
];

/// Shorthand keywords for one field inside the scene file's JSON.
const SHORTHANDS: [(&str, [&str; 2]); 9] = [
    ("shading", ["render", "shading"]),
    ("background", ["render", "background"]),
    ("shadows", ["render", "shadows"]),
    ("step", ["render", "step_voxels"]),
    ("ambient", ["render", "ambient"]),
    ("ao", ["ambient_occlusion", "method"]),
    ("rays", ["ambient_occlusion", "rays"]),
    ("samples", ["ambient_occlusion", "samples"]),
    ("ortho", ["camera", "orthographic"]),
];

/// Keywords handled on their own (they need the volume's statistics, a parser or a file).
const SPECIAL: [&str; 7] = [
    "tf",
    "window_level",
    "mode",
    "labels",
    "label_table",
    "segment",
    "light_direction",
];

/// A reproducible view of a volume: `Scene(volume, **settings)` or `Scene.load(path)`.
#[pyclass(name = "Scene", module = "volao")]
#[derive(Debug)]
pub struct PyScene {
    scene: Scene,
    /// The volume, once loaded (a scene read from a file loads it at first use).
    volume: Option<Py<PyVolume>>,
}

impl PyScene {
    /// The scene's volume, loaded now if need be (GIL released while it reads).
    fn volume(&mut self, py: Python<'_>) -> PyResult<Py<PyVolume>> {
        if let Some(v) = &self.volume {
            return Ok(v.clone_ref(py));
        }
        let scene = &self.scene;
        let (volume, warnings) = py
            .detach(|| headless::load_volume(scene, &mut |_, _| {}))
            .map_err(|e| load_error(e, scene.volume.path.as_deref()))?;
        for w in &warnings {
            log(py, "warning", w)?;
        }
        let v = Py::new(
            py,
            PyVolume::new(volume, Some(self.scene.volume.clone()), None),
        )?;
        self.volume = Some(v.clone_ref(py));
        Ok(v)
    }

    /// Applies keyword settings, then checks the whole scene as a scene file is checked.
    fn apply(&mut self, py: Python<'_>, settings: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        let Some(settings) = settings else {
            return Ok(());
        };
        let volume = self.volume(py)?;
        let stats = volume.get().cached_stats();
        let mut json =
            serde_json::to_value(&self.scene).map_err(|e| VolaoError::new_err(e.to_string()))?;
        let mut specs = Vec::new();
        // Whole fields first, then shorthands into them, then what needs parsing.
        for (key, value) in settings.iter() {
            let key: String = key.extract()?;
            if key == "camera" && value.extract::<[f64; 3]>().is_ok() {
                // (azimuth, elevation, distance): below.
            } else if FIELDS.contains(&key.as_str()) {
                merge(&mut json[key.as_str()], json_of(&value)?);
            } else if !SHORTHANDS.iter().any(|(k, _)| *k == key) && !SPECIAL.contains(&key.as_str())
            {
                return Err(PyTypeError::new_err(format!(
                    "Scene: unknown setting {key:?}: use a scene file field ({}) or one of {}",
                    FIELDS.join(", "),
                    SHORTHANDS
                        .iter()
                        .map(|(k, _)| *k)
                        .chain(SPECIAL)
                        .collect::<Vec<_>>()
                        .join(", ")
                )));
            }
        }
        for (key, [field, inner]) in SHORTHANDS {
            if let Some(value) = settings.get_item(key)? {
                let mut v = json_of(&value)?;
                if key == "rays"
                    && let Value::Number(n) = &v
                {
                    // Ray sets are named in scene files: 14 → "14".
                    v = Value::String(n.to_string());
                }
                set_inner(&mut json, field, inner, v)?;
            }
        }
        if let Some(camera) = settings.get_item("camera")?
            && let Ok([azimuth, elevation, distance]) = camera.extract::<[f64; 3]>()
        {
            set_inner(&mut json, "camera", "azimuth_deg", azimuth.into())?;
            set_inner(&mut json, "camera", "elevation_deg", elevation.into())?;
            set_inner(&mut json, "camera", "distance", distance.into())?;
        }
        if let Some(mode) = settings.get_item("mode")? {
            let mode: volao::render::RenderMode = mode
                .extract::<String>()?
                .parse()
                .map_err(PyValueError::new_err)?;
            let mode =
                serde_json::to_value(mode).map_err(|e| VolaoError::new_err(e.to_string()))?;
            set_inner(&mut json, "render", "mode", mode)?;
        }
        if let Some(direction) = settings.get_item("light_direction")? {
            json["light"] = serde_json::json!({
                "kind": "directional",
                "direction": json_of(&direction)?,
            });
        }
        if let Some(tf) = settings.get_item("tf")? {
            json["transfer_function"] = match tf.extract::<String>() {
                Ok(name) => tf_json(&TransferFunction::preset(
                    Preset::from_name(&name).map_err(|e| PyValueError::new_err(e.to_string()))?,
                    &stats,
                ))?,
                Err(_) => json_of(&tf)?,
            };
        }
        if let Some(labels) = settings.get_item("labels")? {
            let path: PathBuf = std::path::absolute(labels.extract::<PathBuf>()?)?;
            let table = match settings.get_item("label_table")? {
                Some(t) => Some(std::path::absolute(t.extract::<PathBuf>()?)?),
                None => None,
            };
            let styles = json["segmentation"]["styles"].take();
            json["segmentation"] = serde_json::to_value(SegmentationSource {
                path,
                table,
                styles: Default::default(),
            })
            .map_err(|e| VolaoError::new_err(e.to_string()))?;
            if !styles.is_null() {
                json["segmentation"]["styles"] = styles;
            }
        } else if settings.contains("label_table")? {
            return Err(PyValueError::new_err("Scene: label_table goes with labels"));
        }
        if let Some(segment) = settings.get_item("segment")? {
            specs = match segment.extract::<String>() {
                Ok(one) => vec![one],
                Err(_) => segment.extract::<Vec<String>>()?,
            };
        }
        let mut scene = Scene::parse(&json.to_string(), Path::new("Scene settings"))
            .map_err(|e| VolaoError::new_err(e.to_string()))?;
        if let Some(wl) = settings.get_item("window_level")? {
            let (window, level): (f64, f64) = wl.extract()?;
            scene.transfer_function = scene.transfer_function.with_window_level(window, level);
        }
        scene.settle().map_err(VolaoError::new_err)?;
        if !specs.is_empty() {
            // Segment styles are matched against the label map: load it once now.
            let volume = volume.get().volume.to_ras();
            let prepared = py.detach(|| Prepared::new(&mut scene, volume, &specs));
            prepared.map_err(py_error)?;
        }
        self.scene = scene;
        Ok(())
    }
}

/// Sets `json[field][inner]`, refusing a field that was set to something not a dict.
fn set_inner(json: &mut Value, field: &str, inner: &str, value: Value) -> PyResult<()> {
    match &mut json[field] {
        Value::Object(map) => {
            map.insert(inner.to_owned(), value);
            Ok(())
        }
        Value::Null => {
            json[field] = serde_json::json!({ inner: value });
            Ok(())
        }
        other => Err(PyValueError::new_err(format!(
            "Scene: {field} is {other}, not a dict, so {inner} cannot be set in it"
        ))),
    }
}

/// The JSON of a transfer function, as scene files hold it.
fn tf_json(tf: &TransferFunction) -> PyResult<Value> {
    serde_json::to_value(tf).map_err(|e| VolaoError::new_err(e.to_string()))
}

/// Merges `patch` into `target`: objects key by key (recursively), anything else replaced.
fn merge(target: &mut Value, patch: Value) {
    match (target, patch) {
        (Value::Object(t), Value::Object(p)) => {
            for (k, v) in p {
                merge(t.entry(k).or_insert(Value::Null), v);
            }
        }
        (t, p) => *t = p,
    }
}

#[pymethods]
impl PyScene {
    /// `Scene(volume, **settings)`: the default scene of `volume` (a `Volume`, numpy array
    /// or nibabel image; TF preset by its value range, 800×800), changed by `settings`:
    /// any scene file field (`transfer_function`, `camera`, `light`, `render`, `width`,
    /// `height`, `ambient_occlusion`, `clip_shapes`, `meshes`, `segmentation`; dicts
    /// update), or the shorthands `tf` (preset name or points), `window_level=(w, l)`,
    /// `camera=(azimuth, elevation, distance)`, `mode`, `shading`, `background`,
    /// `shadows`, `step`, `ambient`, `ao` (method), `rays`, `samples`, `ortho`,
    /// `light_direction`, `labels`, `label_table`, `segment` (`volao render --segment`
    /// specs).
    #[new]
    #[pyo3(signature = (volume, **settings))]
    fn py_new(
        py: Python<'_>,
        volume: &Bound<'_, PyAny>,
        settings: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let volume = PyVolume::coerce(volume)?;
        let v = volume.get();
        let source = v.source.clone().unwrap_or(VolumeSource {
            path: None,
            frame: 0,
            raw: None,
            level: 0,
        });
        let mut scene = Scene::default_for(source, &v.cached_stats());
        scene.settle().map_err(VolaoError::new_err)?;
        let mut this = PyScene {
            scene,
            volume: Some(volume),
        };
        this.apply(py, settings)?;
        Ok(this)
    }

    /// Reads a scene file (paths relative to it); its volume loads at first use.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let mut scene = Scene::open(&path).map_err(|e| VolaoError::new_err(e.to_string()))?;
        scene.settle().map_err(VolaoError::new_err)?;
        Ok(PyScene {
            scene,
            volume: None,
        })
    }

    /// Changes settings, with the keywords of `Scene(volume, **settings)`.
    #[pyo3(signature = (**settings))]
    fn set(&mut self, py: Python<'_>, settings: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        self.apply(py, settings)
    }

    /// Writes the scene file (paths relative to it where they share a folder tree);
    /// `volao render` of it gives the bytes `render()` gives.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        if self.scene.volume.path.is_none() && self.volume.is_some() {
            return Err(VolaoError::new_err(
                "Scene.save: the volume was made from an array and has no file; write it with \
                 volume.save(\"x.nii.gz\") and build the scene from volao.load(\"x.nii.gz\")",
            ));
        }
        if self
            .volume
            .as_ref()
            .is_some_and(|v| v.get().series.is_some())
        {
            return Err(VolaoError::new_err(
                "Scene.save: scene files do not record a DICOM series (volao.load(..., series=…)); \
                 save the series with volume.save(\"x.nii.gz\") and build the scene from that",
            ));
        }
        let scene = &self.scene;
        py.detach(|| scene.save(&path))
            .map_err(|e| VolaoError::new_err(e.to_string()))
    }

    /// Renders the scene (at `width` × `height` if given, else the scene's size) into a
    /// `volao.Image`: a numpy `(H, W, 4)` uint8 array, straight alpha, rows from the top.
    /// The GIL is released while it renders; `progress(stage, done, total)` is called
    /// as AO slices are computed.
    #[pyo3(signature = (width=None, height=None, progress=None))]
    fn render<'py>(
        &mut self,
        py: Python<'py>,
        width: Option<u32>,
        height: Option<u32>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let volume = self.volume(py)?;
        let mut scene = self.scene.clone();
        scene.width = width.unwrap_or(scene.width);
        scene.height = height.unwrap_or(scene.height);
        scene.settle().map_err(VolaoError::new_err)?;
        let volume = std::sync::Arc::clone(&volume.get().volume);
        let reporter = Progress::new(py, progress)?;
        let mut notes = Vec::new();
        let start = std::time::Instant::now();
        let rendered = py.detach(|| {
            let ras = volume.to_ras();
            // What `volao render` does to a projection without a window of its own
            // (with the statistics it takes: of the volume in RAS order).
            notes.extend(headless::projection_window(&mut scene, &ras.stats()));
            let prepared = Prepared::new(&mut scene, ras, &[])?;
            notes.extend(prepared.warnings.iter().cloned());
            let device = DEVICE.for_scene(&scene, &mut notes)?;
            gpu_turn(|| {
                headless::render(&scene, &prepared, device.as_ref(), &|done, total| {
                    reporter.report("ambient occlusion", done as u64, total as u64)
                })
            })
            .map_err(headless::HeadlessError::from)
        });
        reporter.finish()?;
        let out = rendered.map_err(py_error)?;
        for note in notes.iter().chain(&out.notes) {
            log(py, "warning", note)?;
        }
        for e in &out.clip_errors {
            log(py, "warning", &format!("{e} (rendered without it)"))?;
        }
        log(
            py,
            "info",
            &format!(
                "rendered {}×{} in {:.0} ms on {}",
                scene.width,
                scene.height,
                start.elapsed().as_secs_f64() * 1e3,
                out.device
            ),
        )?;
        let info = PyDict::new(py);
        info.set_item("device", &out.device)?;
        info.set_item("ao_seconds", out.ao_seconds)?;
        info.set_item("downsampled", out.downsampled)?;
        info.set_item("notes", out.notes.clone())?;
        let array = image_array(py, out.image)?;
        py.import("volao")?.getattr("Image")?.call1((array, info))
    }

    /// The scene's volume (read from its file at first use).
    #[getter(volume)]
    fn get_volume(&mut self, py: Python<'_>) -> PyResult<Py<PyVolume>> {
        self.volume(py)
    }

    #[getter]
    fn width(&self) -> u32 {
        self.scene.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.scene.height
    }

    /// The scene as scene-file JSON (paths absolute).
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.scene).map_err(|e| VolaoError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!(
            "volao.Scene({}, {}×{}, tf {}, AO {})",
            match &self.scene.volume.path {
                Some(p) => p.display().to_string(),
                None => "volume from an array".into(),
            },
            self.scene.width,
            self.scene.height,
            self.scene.transfer_function.name,
            self.scene.ambient_occlusion.method.code()
        )
    }
}
