//! numpy arrays and Python values to and from the library's types: voxels (index
//! `[x, y, z]`, x fastest in the library's buffers), RGBA images `(H, W, 4)`, and plain
//! Python values as the JSON of scene files.

use numpy::ndarray::Array3;
use numpy::npyffi::NPY_ORDER;
use numpy::{
    IntoPyArray, PyArray1, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use volao::render::Image;
use volao::volume::{VoxelData, VoxelType};

/// The numpy name of a voxel type (`int16`, `float32`, …).
pub fn numpy_name(ty: VoxelType) -> &'static str {
    match ty {
        VoxelType::U8 => "uint8",
        VoxelType::I8 => "int8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::U32 => "uint32",
        VoxelType::I32 => "int32",
        VoxelType::F32 => "float32",
        VoxelType::F64 => "float64",
    }
}

/// A numpy array's voxels: its shape as `(x, y, z)` and the values with x fastest,
/// whatever its memory order (C, Fortran or strided).
pub fn voxels_of(array: &Bound<'_, PyAny>) -> PyResult<([usize; 3], VoxelData)> {
    let py = array.py();
    let untyped = array.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "volao.Volume: expected a numpy array or a nibabel image, got {}",
            type_name(array)
        ))
    })?;
    let shape = untyped.shape().to_vec();
    let dims: [usize; 3] = shape.as_slice().try_into().map_err(|_| {
        PyValueError::new_err(format!(
            "volao.Volume: the array has {} dimension{} (shape {:?}); a volume needs 3 (x, y, z){}",
            shape.len(),
            if shape.len() == 1 { "" } else { "s" },
            shape,
            if shape.len() == 4 {
                ": take one frame, e.g. array[..., 0]"
            } else {
                ""
            }
        ))
    })?;
    if dims.contains(&0) {
        return Err(PyValueError::new_err(format!(
            "volao.Volume: the array's shape {shape:?} has a zero side"
        )));
    }
    let dtype = untyped.dtype();
    macro_rules! try_type {
        ($t:ty, $variant:ident) => {
            if dtype.is_equiv_to(&numpy::dtype::<$t>(py)) {
                let a: PyReadonlyArrayDyn<'_, $t> = array.extract()?;
                // Reversed axes iterate (z, y, x) in logical order: x fastest.
                let v: Vec<$t> = a.as_array().t().iter().copied().collect();
                return Ok((dims, VoxelData::$variant(v)));
            }
        };
    }
    try_type!(u8, U8);
    try_type!(i8, I8);
    try_type!(u16, U16);
    try_type!(i16, I16);
    try_type!(u32, U32);
    try_type!(i32, I32);
    try_type!(f32, F32);
    try_type!(f64, F64);
    Err(PyTypeError::new_err(format!(
        "volao.Volume: unsupported dtype {}; volumes hold uint8, int8, uint16, int16, uint32, \
         int32, float32 or float64 in native byte order: convert with array.astype(...)",
        dtype.str()?
    )))
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "an unknown object".into())
}

/// Voxels as a numpy array of shape `(x, y, z)` (Fortran order: x fastest, as stored);
/// a copy of `data`.
pub fn array_of<'py>(
    py: Python<'py>,
    data: &VoxelData,
    dims: [usize; 3],
) -> PyResult<Bound<'py, PyAny>> {
    macro_rules! fortran {
        ($v:expr) => {
            PyArray1::from_slice(py, $v)
                .reshape_with_order(dims, NPY_ORDER::NPY_FORTRANORDER)?
                .into_any()
        };
    }
    Ok(match data {
        VoxelData::U8(v) => fortran!(v),
        VoxelData::I8(v) => fortran!(v),
        VoxelData::U16(v) => fortran!(v),
        VoxelData::I16(v) => fortran!(v),
        VoxelData::U32(v) => fortran!(v),
        VoxelData::I32(v) => fortran!(v),
        VoxelData::F32(v) => fortran!(v),
        VoxelData::F64(v) => fortran!(v),
    })
}

/// An image as a numpy `(H, W, 4)` uint8 array, rows from the top.
pub fn image_array<'py>(py: Python<'py>, image: Image) -> PyResult<Bound<'py, PyAny>> {
    let shape = (image.height as usize, image.width as usize, 4);
    let bytes: Vec<u8> = image.pixels.into_iter().flatten().collect();
    let array = Array3::from_shape_vec(shape, bytes)
        .map_err(|e| PyValueError::new_err(format!("image of {shape:?}: {e}")))?;
    Ok(array.into_pyarray(py).into_any())
}

/// A numpy `(H, W, 4)` uint8 array as an image.
fn image_of(array: &Bound<'_, PyAny>) -> PyResult<Image> {
    let bad = || {
        PyValueError::new_err(format!(
            "expected an RGBA image: a numpy uint8 array of shape (height, width, 4), got {}",
            array
                .getattr("shape")
                .map(|s| s.to_string())
                .unwrap_or_else(|_| type_name(array))
        ))
    };
    let a: PyReadonlyArrayDyn<'_, u8> = array.extract().map_err(|_| bad())?;
    let view = a.as_array();
    let [h, w, 4] = view.shape() else {
        return Err(bad());
    };
    let (width, height) = (
        u32::try_from(*w).map_err(|_| bad())?,
        u32::try_from(*h).map_err(|_| bad())?,
    );
    let flat: Vec<u8> = view.iter().copied().collect();
    Ok(Image {
        width,
        height,
        pixels: flat
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect(),
    })
}

/// The PNG file of an RGBA image array, as bytes (`Image._repr_png_`).
#[pyfunction]
pub fn encode_png<'py>(
    py: Python<'py>,
    array: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyBytes>> {
    let image = image_of(array)?;
    let png = py
        .detach(|| image.png_bytes())
        .map_err(|e| crate::VolaoError::new_err(e.to_string()))?;
    Ok(PyBytes::new(py, &png))
}

/// Writes an RGBA image array as PNG, the bytes `volao render` writes (`Image.save`).
#[pyfunction]
pub fn save_png(
    py: Python<'_>,
    array: &Bound<'_, PyAny>,
    path: std::path::PathBuf,
) -> PyResult<()> {
    let image = image_of(array)?;
    py.detach(|| image.save_png(&path))
        .map_err(|e| crate::VolaoError::new_err(e.to_string()))
}

/// A plain Python value (dict, list, tuple, str, int, float, bool, None, numpy scalars
/// and arrays) as JSON, for the scene file's fields given as keywords.
pub fn json_of(value: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    use serde_json::Value;
    if value.is_none() {
        return Ok(Value::Null);
    }
    if let Ok(b) = value.cast::<PyBool>() {
        return Ok(Value::Bool(b.is_true()));
    }
    if value.is_instance_of::<PyInt>() {
        if let Ok(i) = value.extract::<i64>() {
            return Ok(i.into());
        }
        return Ok(value.extract::<u64>()?.into());
    }
    if let Ok(f) = value.cast::<PyFloat>() {
        return serde_json::Number::from_f64(f.value())
            .map(Value::Number)
            .ok_or_else(|| PyValueError::new_err(format!("{} is not a finite number", f.value())));
    }
    if let Ok(s) = value.cast::<PyString>() {
        return Ok(Value::String(s.to_cow()?.into_owned()));
    }
    if let Ok(d) = value.cast::<PyDict>() {
        let mut map = serde_json::Map::new();
        for (k, v) in d.iter() {
            let key = k
                .extract::<String>()
                .map_err(|_| PyTypeError::new_err(format!("setting names are strings, not {k}")))?;
            map.insert(key, json_of(&v)?);
        }
        return Ok(Value::Object(map));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        return value
            .try_iter()?
            .map(|v| json_of(&v?))
            .collect::<PyResult<Vec<_>>>()
            .map(Value::Array);
    }
    if let Ok(p) = value.extract::<std::path::PathBuf>() {
        return Ok(Value::String(p.to_string_lossy().into_owned()));
    }
    // numpy scalars and arrays: their plain Python value.
    if value.hasattr("tolist")? {
        return json_of(&value.call_method0("tolist")?);
    }
    Err(PyTypeError::new_err(format!(
        "a setting cannot be {}: use numbers, strings, lists and dicts",
        type_name(value)
    )))
}
