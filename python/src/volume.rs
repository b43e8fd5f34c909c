//! `volao.Volume` and `volao.load`: a volume from a file, a numpy array or a nibabel
//! image, with its dims, spacing, affine, dtype, statistics and voxels as numpy.

use crate::convert::{array_of, numpy_name, voxels_of};
use crate::{Progress, VolaoError, load_error, log, volume_error};
use numpy::PyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use volao::scene::VolumeSource;
use volao::volume::orient::AffineSource;
use volao::volume::{LoadOptions, Orientation, Stats, Volume};

/// A scalar volume: voxels as stored (x fastest), spacing in mm, the voxel-to-RAS
/// affine. Made by `volao.load(path)` or `volao.Volume(array, spacing=…, affine=…)`.
#[pyclass(name = "Volume", module = "volao", frozen)]
#[derive(Debug)]
pub struct PyVolume {
    pub volume: Arc<Volume>,
    /// The file it was read from and how (None: made from an array).
    pub source: Option<VolumeSource>,
    /// The DICOM series asked for, which scene files do not record.
    pub series: Option<String>,
    format: Option<String>,
    stats: OnceLock<Stats>,
}

impl PyVolume {
    pub fn new(volume: Volume, source: Option<VolumeSource>, series: Option<String>) -> Self {
        PyVolume {
            volume: Arc::new(volume),
            source,
            series,
            format: None,
            stats: OnceLock::new(),
        }
    }

    pub fn cached_stats(&self) -> Stats {
        *self.stats.get_or_init(|| self.volume.stats())
    }

    /// `obj` as a volume: a `Volume` as it is, anything else through the constructor.
    pub fn coerce(obj: &Bound<'_, PyAny>) -> PyResult<Py<PyVolume>> {
        if let Ok(v) = obj.cast::<PyVolume>() {
            return Ok(v.clone().unbind());
        }
        Py::new(obj.py(), PyVolume::py_new(obj, None, None)?)
    }
}

/// Reads a volume file (NIfTI, Analyze, NRRD, MGH, DICOM folder, OME-Zarr store, PVM,
/// raw with a sidecar) as `volao load` does; the GIL is released while it reads.
/// `level`: an OME-Zarr store's multiscale level (0 = full resolution).
#[pyfunction]
#[pyo3(signature = (path, frame=None, series=None, progress=None, level=None))]
pub fn load(
    py: Python<'_>,
    path: PathBuf,
    frame: Option<usize>,
    series: Option<String>,
    progress: Option<Py<PyAny>>,
    level: Option<usize>,
) -> PyResult<PyVolume> {
    let options = LoadOptions {
        frame: frame.unwrap_or(0),
        series: series.clone(),
        level: level.unwrap_or(0),
        ..Default::default()
    };
    let reporter = Progress::new(py, progress)?;
    let loaded = py.detach(|| {
        volao::volume::load_with_progress(&path, &options, &mut |done, total| {
            reporter.report("loading", done, total)
        })
    });
    reporter.finish()?;
    let loaded = loaded.map_err(|e| load_error(e, Some(&path)))?;
    for w in &loaded.warnings {
        log(
            py,
            "warning",
            &format!("{}: {w}", volao::volume::display_path(&path)),
        )?;
    }
    let source = VolumeSource::from_load_options(Some(std::path::absolute(&path)?), &options);
    let mut volume = PyVolume::new(loaded.volume, Some(source), series);
    volume.format = Some(format!("{:?}", loaded.format));
    Ok(volume)
}

#[pymethods]
impl PyVolume {
    /// `Volume(array, spacing=None, affine=None)`: a numpy array indexed `[x, y, z]` (C
    /// or Fortran order) of uint8, int8, uint16, int16, uint32, int32, float32 or
    /// float64, or a nibabel image (its data and affine). Without an affine the voxel
    /// axes are RAS scaled by `spacing` (default 1 mm); with one, the spacing defaults
    /// to the affine's column lengths.
    #[new]
    #[pyo3(signature = (array, spacing=None, affine=None))]
    fn py_new(
        array: &Bound<'_, PyAny>,
        spacing: Option<[f32; 3]>,
        affine: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let py = array.py();
        // A nibabel image: its (scaled) data and its affine.
        let (data, affine) = if array.hasattr("dataobj")? && array.hasattr("affine")? {
            let data = py
                .import("numpy")?
                .call_method1("asanyarray", (array.getattr("dataobj")?,))?;
            let image_affine = array.getattr("affine")?;
            (data, Some(affine.cloned().unwrap_or(image_affine)))
        } else {
            (array.clone(), affine.cloned())
        };
        let (dims, voxels) = voxels_of(&data)?;
        let orientation = match &affine {
            None => None,
            Some(a) => Some(orientation_of(a)?),
        };
        let spacing = match (spacing, &orientation) {
            (Some(s), _) => s,
            (None, Some(o)) => {
                let l = o.linear;
                [l.x_axis, l.y_axis, l.z_axis].map(|c| c.length() as f32)
            }
            (None, None) => [1.0; 3],
        };
        let mut volume = Volume::new(dims, spacing, voxels)
            .map_err(|e| PyValueError::new_err(format!("volao.Volume: {e}")))?;
        if let Some(o) = orientation {
            volume.orientation = o;
        }
        Ok(PyVolume::new(volume, None, None))
    }

    /// Voxel counts along x, y, z.
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        let [x, y, z] = self.volume.dims;
        (x, y, z)
    }

    /// Voxel spacing in mm along x, y, z.
    #[getter]
    fn spacing(&self) -> (f32, f32, f32) {
        let [x, y, z] = self.volume.spacing;
        (x, y, z)
    }

    /// The numpy dtype name of the stored voxels (`int16`, `float32`, …).
    #[getter]
    fn dtype(&self) -> &'static str {
        numpy_name(self.volume.data.voxel_type())
    }

    /// The 4×4 voxel-index → world (RAS+, mm) affine, as nibabel's `img.affine`.
    #[getter]
    fn affine<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows = self.volume.orientation.rows();
        let mut m: Vec<Vec<f64>> = rows.iter().map(|r| r.to_vec()).collect();
        m.push(vec![0.0, 0.0, 0.0, 1.0]);
        PyArray2::from_vec2(py, &m).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The voxels as stored, a numpy array of shape `(x, y, z)` in Fortran order (x
    /// fastest); a copy made at each access.
    #[getter]
    fn array<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        array_of(py, &self.volume.data, self.volume.dims)
    }

    /// `{min, max, mean, non_finite}` over the physical values (cached).
    #[getter(stats)]
    fn py_stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.cached_stats();
        let d = PyDict::new(py);
        d.set_item("min", s.min)?;
        d.set_item("max", s.max)?;
        d.set_item("mean", s.mean)?;
        d.set_item("non_finite", s.non_finite)?;
        Ok(d)
    }

    /// `(slope, inter)`: physical value = slope · stored + inter (NIfTI's scl_*).
    #[getter]
    fn scaling(&self) -> (f64, f64) {
        (self.volume.scaling.slope, self.volume.scaling.inter)
    }

    /// The file it was read from, or None for a volume made from an array.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.source.as_ref().and_then(|s| s.path.clone())
    }

    /// The file format it was read from, or None.
    #[getter]
    fn format(&self) -> Option<String> {
        self.format.clone()
    }

    /// Writes the volume; the extension picks the format (.nii, .nii.gz, .pvm, .raw).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let volume = Arc::clone(&self.volume);
        let warnings = py
            .detach(|| volao::volume::save(&volume, &path))
            .map_err(volume_error)?;
        for w in warnings {
            log(py, "warning", &format!("{}: {w}", path.display()))?;
        }
        Ok(())
    }

    /// A `nibabel.Nifti1Image` of the stored voxels and the affine (needs nibabel).
    fn to_nibabel<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let image = py
            .import("nibabel")?
            .getattr("Nifti1Image")?
            .call1((self.array(py)?, self.affine(py)?))?;
        let s = self.volume.scaling;
        if !s.is_identity() {
            image
                .getattr("header")?
                .call_method1("set_slope_inter", (s.slope, s.inter))?;
        }
        Ok(image)
    }

    fn __repr__(&self) -> String {
        format!(
            "volao.Volume({} {}, spacing {:?} mm{})",
            volao::volume::fmt_dims(self.volume.dims),
            self.dtype(),
            self.volume.spacing,
            match self.path() {
                Some(p) => format!(", from {}", p.display()),
                None => String::new(),
            }
        )
    }
}

/// A 4×4 (or 3×4) affine as the library's orientation.
fn orientation_of(affine: &Bound<'_, PyAny>) -> PyResult<Orientation> {
    let bad = |why: &str| {
        VolaoError::new_err(format!(
            "volao.Volume: the affine must be a 4×4 voxel-to-RAS matrix of finite numbers with \
             independent axes ({why})"
        ))
    };
    let rows: Vec<Vec<f64>> = affine
        .call_method0("tolist")
        .unwrap_or_else(|_| affine.clone())
        .extract()
        .map_err(|_| bad("not a matrix of numbers"))?;
    if !(rows.len() == 4 || rows.len() == 3) || rows.iter().any(|r| r.len() != 4) {
        return Err(bad("wrong shape"));
    }
    let r = |i: usize| [rows[i][0], rows[i][1], rows[i][2], rows[i][3]];
    let o = Orientation::from_rows([r(0), r(1), r(2)], AffineSource::Sform);
    if !o.is_valid() {
        return Err(bad("singular or not finite"));
    }
    Ok(o)
}
