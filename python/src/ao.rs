//! `volao.ambient_occlusion`: an AO volume of a volume, in its grid, as numpy float32
//! (what `volao ao` writes).

use crate::convert::{array_of, json_of};
use crate::volume::PyVolume;
use crate::{DEVICE, Progress, gpu_turn, log, py_error};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use volao::ao::AoSettings;
use volao::ao::sparse::Coverage;
use volao::clip::ClipShape;
use volao::gpu::GpuUse;
use volao::tf::{Preset, TransferFunction};

/// The ambient factor `A(x)` in [0, 1] of every voxel of `volume` (a `Volume`, numpy
/// array or nibabel image), as a float32 array of its shape `(x, y, z)`: the values
/// `volao ao` writes for the same method, parameters and transfer function.
///
/// `method`: lao, cao, lao-full, vao, cdf, gauss, penner or cone. `tf`: a preset name,
/// transfer-function points (a scene file's `transfer_function`) or None (the preset for
/// the data's range). `clip`: clip shapes as in scene files (cao and lao-full).
/// `visible_only`: LAO/CAO only where a composite rendering can read (the rest 1).
/// `settings`: a scene file's `ambient_occlusion` fields (`rays`, `samples`, `vao`,
/// `radius`, `statistic`, `cones`, …). `cpu`: the CPU twins instead of the GPU.
#[pyfunction]
#[pyo3(signature = (volume, method="lao", *, tf=None, clip=None, visible_only=false, cpu=false, progress=None, **settings))]
#[allow(clippy::too_many_arguments, reason = "Python keywords")]
pub fn ambient_occlusion<'py>(
    py: Python<'py>,
    volume: &Bound<'py, PyAny>,
    method: &str,
    tf: Option<&Bound<'py, PyAny>>,
    clip: Option<&Bound<'py, PyAny>>,
    visible_only: bool,
    cpu: bool,
    progress: Option<Py<PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let volume = PyVolume::coerce(volume)?;
    let v = volume.get();
    let mut json = serde_json::json!({ "method": method });
    if let Some(settings) = settings {
        for (key, value) in settings.iter() {
            let key: String = key.extract()?;
            let mut value = json_of(&value)?;
            if key == "rays"
                && let serde_json::Value::Number(n) = &value
            {
                value = serde_json::Value::String(n.to_string());
            }
            json[key] = value;
        }
    }
    let ao: AoSettings = serde_json::from_value(json)
        .map_err(|e| PyValueError::new_err(format!("ambient_occlusion: {e}")))?;
    let stats = v.cached_stats();
    let tf = match tf {
        None => TransferFunction::preset(Preset::default_for(&stats), &stats),
        Some(t) => match t.extract::<String>() {
            Ok(name) => TransferFunction::preset(
                Preset::from_name(&name).map_err(|e| PyValueError::new_err(e.to_string()))?,
                &stats,
            ),
            Err(_) => {
                let tf: TransferFunction = serde_json::from_value(json_of(t)?)
                    .map_err(|e| PyValueError::new_err(format!("ambient_occlusion: tf: {e}")))?;
                tf.validate()
                    .map_err(|e| PyValueError::new_err(format!("ambient_occlusion: tf: {e}")))?;
                tf
            }
        },
    };
    let clip: Vec<ClipShape> = match clip {
        None => Vec::new(),
        Some(c) => serde_json::from_value(json_of(c)?)
            .map_err(|e| PyValueError::new_err(format!("ambient_occlusion: clip: {e}")))?,
    };
    let coverage = if visible_only {
        Coverage::Readable
    } else {
        Coverage::Every
    };
    let reporter = Progress::new(py, progress)?;
    let data = std::sync::Arc::clone(&v.volume);
    let computed = py.detach(|| {
        let gpu = if cpu { GpuUse::Cpu } else { DEVICE.gpu_use() };
        gpu_turn(|| {
            volao::headless::ao_volume(&data, &tf, &ao, &clip, coverage, &gpu, &|done, total| {
                reporter.report("ambient occlusion", done as u64, total as u64)
            })
        })
    });
    reporter.finish()?;
    let computed = computed.map_err(py_error)?;
    if !cpu && let Err(e) = DEVICE.get() {
        log(
            py,
            "warning",
            &format!("{e}; computing AO on the CPU instead (slow)"),
        )?;
    }
    for note in &computed.notes {
        log(py, "warning", note)?;
    }
    log(
        py,
        "info",
        &format!(
            "ambient occlusion {} on {}",
            volao::headless::ao_method_words(&ao),
            computed.device
        ),
    )?;
    array_of(py, &computed.volume.data, computed.volume.dims)
}
