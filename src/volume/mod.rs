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

pub mod analyze;
pub mod demo;
pub mod dicom;
mod fields;
pub mod format;
pub mod gzip;
pub mod mgh;
pub mod nifti;
pub mod nrrd;
pub mod orient;
pub mod pvm;
pub mod raw;
pub mod stats;
pub mod voxels;
pub mod zarr;

use glam::{DMat3, DVec3};
use std::path::{Path, PathBuf};

pub use format::{Format, LoadOptions, Loaded, load, load_with_progress, save};
pub use orient::Orientation;
pub use raw::{Endian, RawOverrides, RawSpec};
pub use stats::{Histogram, Stats};
pub(crate) use voxels::with_voxels;
pub use voxels::{VoxelData, VoxelType};

/// What every format's loader is given besides the file: the size limit, where
/// non-fatal problems go and how far it has read.
pub struct Reading<'a> {
    /// Refuse more voxel bytes than this.
    pub max_bytes: u64,
    pub warnings: &'a mut Vec<String>,
    /// (bytes read, bytes in all)
    pub progress: &'a mut dyn FnMut(u64, u64),
}

/// The voxel `[x, y, z]` at linear index `i` (x fastest) of a volume of `dims`.
pub fn voxel_of(i: usize, dims: [usize; 3]) -> [usize; 3] {
    [
        i % dims[0],
        (i / dims[0]) % dims[1],
        i / (dims[0] * dims[1]),
    ]
}

impl std::fmt::Debug for Reading<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reading")
            .field("max_bytes", &self.max_bytes)
            .field("warnings", &self.warnings)
            .finish_non_exhaustive()
    }
}

/// Everything that can go wrong while reading or writing a volume file.
///
/// Each message is one line that names the file and says what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// The OS error is part of the message, not a `source`: printing the chain with
    /// `{:#}` would otherwise repeat it.
    #[error("{}: {}", display_path(.path), .error)]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: truncated: {what} needs {expected} bytes but the file holds {actual}", display_path(.path))]
    Truncated {
        path: PathBuf,
        what: String,
        expected: u64,
        actual: u64,
    },
    #[error("{}: {message}", display_path(.path))]
    Invalid { path: PathBuf, message: String },
    #[error("{}: {message}", display_path(.path))]
    Unsupported { path: PathBuf, message: String },
    /// A problem on one line of a text file (a label table).
    #[error("{}:{line}: {message}", display_path(.path))]
    AtLine {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error(
        "{}: header claims {dims} {ty} = {bytes} of voxels, more than this machine can hold ({limit} available)", display_path(.path)
    )]
    TooLarge {
        path: PathBuf,
        dims: String,
        ty: String,
        bytes: String,
        limit: String,
    },
    #[error(
        "{}: unknown volume format (expected .nii, .nii.gz, .hdr/.img, .nrrd/.nhdr, .mgh/.mgz, DICOM (.dcm or a folder), an OME-Zarr store (.zarr folder), .pvm, or .raw with a .dat sidecar or --dims/--type)", display_path(.path)
    )]
    UnknownFormat { path: PathBuf },
    /// A problem in a file that `path` (the one the user gave) refers to.
    #[error("{} ({what}): {inner}", display_path(.path))]
    Within {
        path: PathBuf,
        what: String,
        inner: Box<VolumeError>,
    },
}

/// Wraps `e` (about a file the user did not name) with the file the user gave.
pub fn with_context(e: VolumeError, path: &Path, what: impl Into<String>) -> VolumeError {
    VolumeError::Within {
        path: path.to_owned(),
        what: what.into(),
        inner: Box::new(e),
    }
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

    pub(crate) fn io(path: &Path, error: std::io::Error) -> Self {
        Self::Io {
            path: path.to_owned(),
            error,
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

    /// The same volume with its voxel axes permuted and flipped so they run R, A, S.
    ///
    /// Only permutations and flips are applied: voxels are moved, never resampled, so
    /// values are untouched. Any remaining obliquity stays in the orientation matrix.
    pub fn to_ras(&self) -> Volume {
        let map = self.orientation.axis_map();
        if map == [(0, true), (1, true), (2, true)] {
            return self.clone();
        }
        // new axis i comes from old axis src[i], flipped if flip[i].
        let mut src = [0usize; 3];
        let mut flip = [false; 3];
        for (j, &(i, pos)) in map.iter().enumerate() {
            src[i] = j;
            flip[i] = !pos;
        }
        let old = self.dims;
        let dims: [usize; 3] = std::array::from_fn(|i| old[src[i]]);
        let spacing: [f32; 3] = std::array::from_fn(|i| self.spacing[src[i]]);

        // Old-index stride of one step along each new axis, and the old index of new (0,0,0).
        let old_stride = [1, old[0], old[0] * old[1]];
        let mut start = 0isize;
        let mut step = [0isize; 3];
        for i in 0..3 {
            let s = old_stride[src[i]] as isize;
            if flip[i] {
                start += (old[src[i]] as isize - 1) * s;
                step[i] = -s;
            } else {
                step[i] = s;
            }
        }
        let gather = |i: usize| -> usize {
            let [x, y, z] = voxel_of(i, dims);
            (start + x as isize * step[0] + y as isize * step[1] + z as isize * step[2]) as usize
        };
        let data = with_voxels!(&self.data, v => {
            let out: Vec<_> = (0..v.len()).map(|i| v[gather(i)]).collect();
            VoxelData::from(out)
        });

        // world = L · old + o, with old = start_idx + P · new  ⇒  L' = L·P, o' = L·start_idx + o.
        let l = self.orientation.linear;
        let cols = [l.x_axis, l.y_axis, l.z_axis];
        let mut offset = self.orientation.offset;
        let mut new_cols = [DVec3::ZERO; 3];
        for i in 0..3 {
            let c = cols[src[i]];
            if flip[i] {
                offset += c * (old[src[i]] as f64 - 1.0);
                new_cols[i] = -c;
            } else {
                new_cols[i] = c;
            }
        }
        Volume {
            dims,
            spacing,
            data,
            scaling: self.scaling,
            orientation: Orientation {
                linear: DMat3::from_cols(new_cols[0], new_cols[1], new_cols[2]),
                offset,
                source: self.orientation.source,
            },
            descriptions: self.descriptions.clone(),
        }
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

/// Text from a file fit for one line: control characters (newlines, escape sequences)
/// written as Rust escapes, everything else unchanged.
pub fn escape_controls(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// A user-supplied name or header value fit for a one-line message: quoted, control
/// characters escaped, cut to 120 characters.
pub fn short_name(s: &str) -> String {
    const MAX: usize = 120;
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i == MAX {
            out.push('…');
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    format!("\"{out}\"")
}

/// A path fit for a one-line message: control characters escaped, long names cut in
/// the middle so both the folder and the file name stay readable.
pub fn display_path(path: &Path) -> String {
    const MAX: usize = 160;
    let s = path.to_string_lossy();
    let escaped: String = s
        .chars()
        .flat_map(|c| {
            if c.is_control() {
                c.escape_default().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect();
    let n = escaped.chars().count();
    if n <= MAX {
        return escaped;
    }
    let head: String = escaped.chars().take(MAX / 2).collect();
    let tail: String = escaped.chars().skip(n - MAX / 2).collect();
    format!("{head}…{tail}")
}

/// Which 3-D frame a loader wants and the most voxel bytes it may allocate for it: what
/// each format's `layout` is given and checks before anything is allocated.
#[derive(Debug, Clone, Copy)]
pub struct FrameRequest {
    pub frame: usize,
    pub max_bytes: u64,
}

impl FrameRequest {
    /// Refuses a frame of `frame_bytes` (`dims` voxels of type `ty`) larger than
    /// `max_bytes`, or frame `frame` of a file of `frames` frames.
    pub fn check(
        self,
        path: &Path,
        dims: [usize; 3],
        ty: String,
        frame_bytes: u64,
        frames: u64,
    ) -> Result<(), VolumeError> {
        let Self { frame, max_bytes } = self;
        if frame_bytes > max_bytes {
            return Err(VolumeError::TooLarge {
                path: path.to_owned(),
                dims: fmt_dims(dims),
                ty,
                bytes: fmt_bytes(frame_bytes),
                limit: fmt_bytes(max_bytes),
            });
        }
        if frame as u64 >= frames {
            return Err(VolumeError::invalid(
                path,
                frame_out_of_range(frame, frames),
            ));
        }
        Ok(())
    }
}

/// "frame 3 requested but the file has 3 frames (frames count from 0: 0 … 2)".
pub fn frame_out_of_range(frame: usize, frames: u64) -> String {
    if frames == 1 {
        format!("frame {frame} requested but the file has 1 frame (frames count from 0: use 0)")
    } else {
        format!(
            "frame {frame} requested but the file has {frames} frames (frames count from 0: 0 … {})",
            frames.saturating_sub(1)
        )
    }
}

/// Smallest and largest voxel spacing (mm) we accept; anything else is a broken header.
pub const SPACING_RANGE: (f32, f32) = (1e-4, 1e4);

/// Replaces each spacing outside [`SPACING_RANGE`] (or not finite) by 1 mm, with a
/// warning naming `fields[axis]`, and rescales that column of the affine to match so
/// spacing and orientation keep agreeing.
pub fn fix_spacing(
    spacing: &mut [f32; 3],
    orientation: &mut Orientation,
    fields: &[&str; 3],
    warnings: &mut Vec<String>,
) {
    let (lo, hi) = SPACING_RANGE;
    for i in 0..3 {
        let s = spacing[i];
        if s.is_finite() && (lo..=hi).contains(&s) {
            continue;
        }
        warnings.push(format!(
            "{} = {s} mm is outside [{lo}, {hi}] mm; using 1 mm",
            fields[i]
        ));
        spacing[i] = 1.0;
        let col = orientation.linear.col(i);
        let len = col.length();
        let dir = if len.is_finite() && len > 0.0 {
            col / len
        } else {
            DVec3::AXES[i]
        };
        *orientation.linear.col_mut(i) = dir;
    }
    if !orientation.is_valid() {
        *orientation = Orientation::from_spacing(*spacing);
    }
}

/// The physical values `slope · stored + inter`, as the narrowest type that holds them
/// exactly: i16 or i32 when slope and intercept are whole and the range fits, else f32.
pub fn physical_values(volume: &Volume) -> VoxelData {
    let s = volume.scaling;
    let n = volume.data.len();
    let whole = s.slope.fract() == 0.0 && s.inter.fract() == 0.0;
    let st = volume.stats();
    let fits = |lo: f64, hi: f64| st.non_finite == 0 && st.min >= lo && st.max <= hi;
    if whole && fits(i16::MIN as f64, i16::MAX as f64) {
        VoxelData::I16(
            (0..n)
                .map(|i| s.apply(volume.data.get_f64(i)) as i16)
                .collect(),
        )
    } else if whole && fits(i32::MIN as f64, i32::MAX as f64) {
        VoxelData::I32(
            (0..n)
                .map(|i| s.apply(volume.data.get_f64(i)) as i32)
                .collect(),
        )
    } else {
        VoxelData::F32(
            (0..n)
                .map(|i| s.apply(volume.data.get_f64(i)) as f32)
                .collect(),
        )
    }
}

/// A slope or intercept that is not finite cannot describe values: warn and use none.
pub fn check_scaling(
    scaling: Scaling,
    data: VoxelData,
    path: &Path,
    warnings: &mut Vec<String>,
) -> (Scaling, VoxelData) {
    let _ = path;
    if scaling.slope.is_finite() && scaling.inter.is_finite() && scaling.slope != 0.0 {
        return (scaling, data);
    }
    warnings.push(format!(
        "rescale slope {} / intercept {} is not usable; showing stored values unscaled",
        scaling.slope, scaling.inter
    ));
    (Scaling::IDENTITY, data)
}

/// For f64 voxels whose magnitude the GPU's f32 cannot hold (beyond ~1e30, or all
/// below ~1e-30): the power of ten the texels are divided by (the texel map multiplies
/// it back, so rendered values are physical). `None` when f32 holds them.
pub fn f64_scale_for_f32(data: &VoxelData) -> Option<f64> {
    let VoxelData::F64(v) = data else {
        return None;
    };
    let max_abs = v
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |m, x| m.max(x.abs()));
    if max_abs == 0.0 || (1e-30..=1e30).contains(&max_abs) {
        return None;
    }
    let factor = 10f64.powf(max_abs.log10().floor());
    (factor.is_finite() && factor != 0.0).then_some(factor)
}

/// Warns when f64 voxels are beyond f32's range: the stored values are kept exactly,
/// the GPU copy is scaled by a power of ten ([`f64_scale_for_f32`]).
pub fn fit_f64_to_f32(volume: &mut Volume, warnings: &mut Vec<String>) -> bool {
    let Some(factor) = f64_scale_for_f32(&volume.data) else {
        return false;
    };
    warnings.push(format!(
        "f64 values reach beyond what the GPU's f32 holds: the GPU copy is divided by {factor:e} (and multiplied back when rendering); stored values are kept"
    ));
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use orient::AffineSource;

    fn ramp(dims: [usize; 3]) -> Volume {
        let n = dims[0] * dims[1] * dims[2];
        let data: Vec<u16> = (0..n as u16).collect();
        Volume::new(dims, [1.0, 2.0, 3.0], data.into()).expect("valid volume")
    }

    #[test]
    fn to_ras_keeps_world_positions() {
        let mut v = ramp([4, 3, 2]);
        v.orientation = Orientation::from_rows(
            [
                [0.0, 0.0, 3.0, 10.0],
                [-1.0, 0.0, 0.0, 20.0],
                [0.0, -2.0, 0.0, 30.0],
            ],
            AffineSource::Sform,
        );
        v.spacing = [1.0, 2.0, 3.0];
        let r = v.to_ras();
        assert_eq!(r.orientation.axis_codes(), "RAS");
        assert_eq!(r.dims, [2, 4, 3]);
        assert_eq!(r.spacing, [3.0, 1.0, 2.0]);
        // Every voxel keeps its value and its world position.
        let world = |o: &Orientation, idx: [usize; 3]| {
            o.linear * DVec3::new(idx[0] as f64, idx[1] as f64, idx[2] as f64) + o.offset
        };
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..4 {
                    let p = world(&v.orientation, [x, y, z]);
                    let q = r.orientation.linear.inverse() * (p - r.orientation.offset);
                    let idx = q.round();
                    assert!((q - idx).abs().max_element() < 1e-9);
                    let (a, b, c) = (idx.x as usize, idx.y as usize, idx.z as usize);
                    assert_eq!(v.value(x, y, z), r.value(a, b, c));
                }
            }
        }
    }

    #[test]
    fn to_ras_on_ras_is_identity() {
        let v = ramp([3, 2, 2]);
        let r = v.to_ras();
        assert_eq!(r.dims, v.dims);
        assert!(r.data.bits_eq(&v.data));
    }
}
