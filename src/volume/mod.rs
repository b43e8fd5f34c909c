//! The volume model and its loaders and writers.
//!
//! A [`Volume`] keeps the voxels exactly as the file stored them (`u8`, `i16`, `f32`, …)
//! together with the linear map to physical units ([`Scaling`], NIfTI's
//! `scl_slope`/`scl_inter`), the voxel spacing in millimetres and the voxel-to-world
//! [`Orientation`]. Hounsfield units stay Hounsfield units: the transfer function maps
//! them for display, nothing here rescales them.
//!
//! Loaders validate every header field before allocating and stream the voxels straight
//! into their final buffer, so loading peaks at about one voxel payload (plus, for
//! PVM/DDS, the compressed bytes).

pub mod demo;
pub mod format;
pub mod nifti;
pub mod orient;
pub mod pvm;
pub mod raw;
pub mod stats;
pub mod voxels;

use std::path::{Path, PathBuf};

pub use format::{Format, LoadOptions, Loaded, load, load_with_progress, save};
pub use orient::Orientation;
pub use raw::{Endian, RawOverrides, RawSpec};
pub use stats::{Histogram, Stats};
pub(crate) use voxels::with_voxels;
pub use voxels::{VoxelData, VoxelType};

/// Everything that can go wrong while reading or writing a volume file.
///
/// Each message is one line that names the file and says what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: truncated: {what} needs {expected} bytes but the file holds {actual}")]
    Truncated {
        path: PathBuf,
        what: String,
        expected: u64,
        actual: u64,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Unsupported { path: PathBuf, message: String },
    #[error(
        "{path}: header claims {dims} {ty} = {bytes} of voxels, more than this machine can hold ({limit} available)"
    )]
    TooLarge {
        path: PathBuf,
        dims: String,
        ty: String,
        bytes: String,
        limit: String,
    },
    #[error(
        "{path}: unknown volume format (expected .nii, .nii.gz, .hdr/.img, .pvm, or .raw with a .dat sidecar or --dims/--type)"
    )]
    UnknownFormat { path: PathBuf },
}

impl VolumeError {
    pub(crate) fn invalid(path: &Path, message: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_owned(),
            message: message.into(),
        }
    }

    pub(crate) fn unsupported(path: &Path, message: impl Into<String>) -> Self {
        Self::Unsupported {
            path: path.to_owned(),
            message: message.into(),
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_owned(),
            source,
        }
    }
}

/// Linear map from stored voxel values to physical units: `value = slope · stored + inter`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Scaling {
    pub slope: f64,
    pub inter: f64,
}

impl Scaling {
    pub const IDENTITY: Self = Self {
        slope: 1.0,
        inter: 0.0,
    };

    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    #[inline]
    pub fn apply(&self, stored: f64) -> f64 {
        self.slope * stored + self.inter
    }
}

impl Default for Scaling {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// A scalar volume: voxels in file order (x fastest), their spacing and where they are.
#[derive(Debug, Clone)]
pub struct Volume {
    /// Voxel counts along x, y, z (x varies fastest in `data`).
    pub dims: [usize; 3],
    /// Voxel spacing in millimetres along x, y, z; always finite and positive.
    pub spacing: [f32; 3],
    /// Voxels as stored in the file.
    pub data: VoxelData,
    /// Stored → physical value map (NIfTI `scl_slope`/`scl_inter`).
    pub scaling: Scaling,
    /// Voxel index → world (RAS+, mm) transform and where it came from.
    pub orientation: Orientation,
    /// Free-text metadata as (label, text): PVM3 strings, NIfTI `descrip`, …
    pub descriptions: Vec<(String, String)>,
}

impl Volume {
    /// Builds a volume, checking that the buffer holds exactly `dims` voxels and the
    /// spacing is usable. The orientation defaults to "voxel axes are RAS", scaled by spacing.
    pub fn new(dims: [usize; 3], spacing: [f32; 3], data: VoxelData) -> Result<Self, String> {
        if dims.contains(&0) {
            return Err(format!("dimensions {} contain a zero", fmt_dims(dims)));
        }
        let n =
            voxel_count(dims).ok_or_else(|| format!("dimensions {} overflow", fmt_dims(dims)))?;
        if data.len() != n {
            return Err(format!(
                "{} voxels given for dimensions {} ({} expected)",
                data.len(),
                fmt_dims(dims),
                n
            ));
        }
        check_spacing(spacing)?;
        Ok(Self {
            dims,
            spacing,
            data,
            scaling: Scaling::IDENTITY,
            orientation: Orientation::from_spacing(spacing),
            descriptions: Vec::new(),
        })
    }

    pub fn voxel_count(&self) -> usize {
        self.data.len()
    }

    /// Physical value of voxel (x, y, z); `None` outside the volume.
    pub fn value(&self, x: usize, y: usize, z: usize) -> Option<f64> {
        let [nx, ny, nz] = self.dims;
        if x >= nx || y >= ny || z >= nz {
            return None;
        }
        Some(self.scaling.apply(self.data.get_f64(x + nx * (y + ny * z))))
    }

    /// Physical size of the volume's bounding box in mm (voxel centres span `dims - 1`
    /// spacings; we count full voxels, as a renderer draws them).
    pub fn extent_mm(&self) -> [f32; 3] {
        std::array::from_fn(|i| self.dims[i] as f32 * self.spacing[i])
    }
}

/// Number of voxels, or `None` if it overflows `usize`.
pub fn voxel_count(dims: [usize; 3]) -> Option<usize> {
    dims[0].checked_mul(dims[1])?.checked_mul(dims[2])
}

pub fn fmt_dims(dims: [usize; 3]) -> String {
    format!("{}×{}×{}", dims[0], dims[1], dims[2])
}

/// Spacing must be finite and positive on every axis.
pub fn check_spacing(spacing: [f32; 3]) -> Result<(), String> {
    if spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
        Ok(())
    } else {
        Err(format!(
            "voxel spacing {} {} {} is not finite and positive",
            spacing[0], spacing[1], spacing[2]
        ))
    }
}

/// Human-readable byte count ("7.1 MiB").
pub fn fmt_bytes(bytes: u64) -> String {
    const UNITS: [&str; 6] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}

/// How many bytes of voxels we are willing to allocate: the memory the OS says is
/// available (Linux `MemAvailable`), or 16 GiB where that cannot be read.
pub fn memory_budget() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map(|kb| kb * 1024)
        .unwrap_or(16 << 30)
}
