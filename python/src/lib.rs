//! `volao._volao`: the native module of the `volao` Python package, a thin layer over the
//! library's headless path (`volao::headless`): the same loaders, scene files, renderer
//! and AO engine as `volao render`, `volao ao` and `volao batch`, so an image rendered
//! here has the CLI's bytes.
//!
//! - [`volume`]: `Volume` (a file, a numpy array or a nibabel image) and `load`.
//! - [`scene`]: `Scene` (a scene file's fields as keywords), `render`.
//! - [`ao`]: `ambient_occlusion`, an AO volume as a numpy array.
//! - [`convert`]: numpy arrays and Python values to and from the library's types.
//!
//! The GIL is released while files load and while the GPU (or a CPU twin) works; one
//! device is opened per process, at the first render, and reused. Notes go to the
//! `volao` logger, never to stdout; progress to the logger (DEBUG) and an optional
//! callback.

mod ao;
mod convert;
mod scene;
mod volume;

use pyo3::prelude::*;
use std::sync::{LazyLock, Mutex};
use volao::headless::{DeviceSlot, HeadlessError};
use volao::volume::VolumeError;

pyo3::create_exception!(
    volao,
    VolaoError,
    pyo3::exceptions::PyException,
    "A volume, scene or GPU error, with the one-line message the volao CLI prints."
);

/// The process's one device: opened by the first render or AO volume, reused by all.
static DEVICE: LazyLock<DeviceSlot> = LazyLock::new(DeviceSlot::default);

/// One GPU job at a time in a process (Python threads, a Dask worker's threads): the
/// device's queue runs them in order anyway, and two volumes resident at once could
/// exhaust its memory.
static GPU_TURN: Mutex<()> = Mutex::new(());

/// Runs `f` holding the process's GPU turn.
fn gpu_turn<T>(f: impl FnOnce() -> T) -> T {
    let _turn = GPU_TURN.lock().unwrap_or_else(|e| e.into_inner());
    f()
}

/// A library error as the Python exception users catch: `FileNotFoundError` for a file
/// that is not there, [`VolaoError`] for everything else; the message is the CLI's line.
fn py_error(e: HeadlessError) -> PyErr {
    match e {
        HeadlessError::Volume(v) => volume_error(v),
        other => VolaoError::new_err(other.to_string()),
    }
}

fn volume_error(e: VolumeError) -> PyErr {
    match &e {
        VolumeError::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
            pyo3::exceptions::PyFileNotFoundError::new_err(e.to_string())
        }
        _ => VolaoError::new_err(e.to_string()),
    }
}

/// A failure to read `path`: `FileNotFoundError` when nothing is there, else as
/// [`volume_error`]; the message is the library's either way.
fn load_error(e: VolumeError, path: Option<&std::path::Path>) -> PyErr {
    match path {
        Some(p) if !p.exists() => pyo3::exceptions::PyFileNotFoundError::new_err(e.to_string()),
        _ => volume_error(e),
    }
}

/// Sends `message` to the `volao` logger at `level` ("debug", "info", "warning").
fn log(py: Python<'_>, level: &str, message: &str) -> PyResult<()> {
    logger(py)?.call_method1(level, ("%s", message))?;
    Ok(())
}

fn logger(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    py.import("logging")?.call_method1("getLogger", ("volao",))
}

/// Progress of a long call, reported to an optional Python callback
/// `progress(stage, done, total)` and to the logger at DEBUG, at most once per percent.
/// It is called from threads that do not hold the GIL; a callback's exception is kept
/// and raised when the call returns.
#[derive(Debug)]
struct Progress {
    callback: Option<Py<PyAny>>,
    debug: bool,
    /// (stage, last percent reported)
    last: Mutex<(String, i64)>,
    failed: Mutex<Option<PyErr>>,
}

impl Progress {
    fn new(py: Python<'_>, callback: Option<Py<PyAny>>) -> PyResult<Self> {
        let debug = logger(py)?
            .call_method1("isEnabledFor", (10,))?
            .extract::<bool>()?;
        Ok(Progress {
            callback,
            debug,
            last: Mutex::new((String::new(), -1)),
            failed: Mutex::new(None),
        })
    }

    /// `done` of `total` units of `stage` are done.
    fn report(&self, stage: &str, done: u64, total: u64) {
        if self.callback.is_none() && !self.debug {
            return;
        }
        let percent = (done.saturating_mul(100) / total.max(1)) as i64;
        {
            let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
            if last.0 == stage && last.1 == percent {
                return;
            }
            *last = (stage.to_owned(), percent);
        }
        Python::attach(|py| {
            let mut failed = self.failed.lock().unwrap_or_else(|e| e.into_inner());
            if failed.is_some() {
                return;
            }
            if let Some(cb) = &self.callback
                && let Err(e) = cb.call1(py, (stage, done, total))
            {
                *failed = Some(e);
            }
            if self.debug {
                // Logging must not fail a render; a broken handler shows in its own way.
                let _ = log(py, "debug", &format!("{stage}: {done}/{total}"));
            }
        });
    }

    /// The callback's exception, if it raised one.
    fn finish(self) -> PyResult<()> {
        match self.failed.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// The adapter volao renders on in this process, in words (e.g. `llvmpipe (LLVM 15.0.6,
/// 256 bits) — Vulkan, Cpu`); opens the process's device if none is open yet.
#[pyfunction]
fn adapter(py: Python<'_>) -> PyResult<String> {
    py.detach(|| DEVICE.get())
        .map(|g| g.describe())
        .map_err(VolaoError::new_err)
}

/// A private runtime folder for Mesa's window-system layer when `XDG_RUNTIME_DIR` is
/// unset (the CLI's, see `volao::process`), or None when it is set.
#[pyfunction]
fn private_runtime_dir() -> Option<std::path::PathBuf> {
    volao::process::private_runtime_dir()
}

#[pymodule]
fn _volao(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("VolaoError", m.py().get_type::<VolaoError>())?;
    m.add_class::<volume::PyVolume>()?;
    m.add_class::<scene::PyScene>()?;
    m.add_function(wrap_pyfunction!(volume::load, m)?)?;
    m.add_function(wrap_pyfunction!(ao::ambient_occlusion, m)?)?;
    m.add_function(wrap_pyfunction!(convert::encode_png, m)?)?;
    m.add_function(wrap_pyfunction!(convert::save_png, m)?)?;
    m.add_function(wrap_pyfunction!(adapter, m)?)?;
    m.add_function(wrap_pyfunction!(private_runtime_dir, m)?)?;
    Ok(())
}
