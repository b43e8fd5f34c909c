//! What can go wrong reading or writing PVM, and allocation that reports it.

use std::fmt;

/// How many bytes a decompressed DDS stream may hold beyond `max_voxel_bytes`: room for
/// the ASCII header and the PVM3 strings.
pub const HEADER_ALLOWANCE: u64 = 1 << 20;

/// How a PVM file lays out its voxels: dimensions and bytes per voxel (components),
/// "301×324×56 × 1 byte" in messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    pub dims: [u64; 3],
    pub components: u64,
}

impl fmt::Display for Layout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.dims;
        let unit = if self.components == 1 {
            "byte"
        } else {
            "bytes"
        };
        write!(f, "{x}×{y}×{z} × {} {unit}", self.components)
    }
}

/// Everything that can go wrong reading or writing a PVM file. Messages are one line.
#[derive(Debug, thiserror::Error)]
pub enum PvmError {
    #[error(
        "not a PVM file (starts with \"{start}\"; expected PVM, PVM2, PVM3, DDS v3d or DDS v3e)"
    )]
    NotPvm { start: String },
    #[error(
        "DDS-compressed file holds no PVM volume (its decompressed data starts with \"{start}\")"
    )]
    NotPvmInDds { start: String },
    #[error(
        "unsupported PVM variant \"{0}\" (only PVM, PVM2 and PVM3 with 1 or 2 bytes per voxel are supported)"
    )]
    UnsupportedVariant(String),
    #[error("truncated: the data ends inside the PVM header, before the end of its {0} line")]
    TruncatedHeader(&'static str),
    #[error("bad PVM header: {0}")]
    BadHeader(String),
    #[error("PVM header has a zero dimension ({}×{}×{})", dims[0], dims[1], dims[2])]
    ZeroDims { dims: [u64; 3] },
    #[error("PVM voxel spacing {} {} {} is not finite and positive", spacing[0], spacing[1], spacing[2])]
    BadSpacing { spacing: [f32; 3] },
    #[error(
        "unsupported PVM component count {0} (only 1 or 2 bytes per voxel; libmini's 3/4-component RGB/RGBA volumes are not supported)"
    )]
    UnsupportedComponents(u64),
    #[error(
        "truncated: header says {layout} = {expected} bytes of voxels but only {actual} follow"
    )]
    Truncated {
        layout: Layout,
        expected: u128,
        actual: u64,
    },
    #[error(
        "volume too large: header says {layout} = {bytes} bytes of voxels, more than the limit of {limit} bytes"
    )]
    TooLarge {
        layout: Layout,
        bytes: u128,
        limit: u64,
    },
    #[error(
        "truncated: the PVM3 file ends inside its {0} string (four NUL-terminated strings must follow the voxels)"
    )]
    TruncatedStrings(&'static str),
    #[error("{count} unexpected bytes after the {after}")]
    TrailingBytes { count: u64, after: &'static str },
    #[error("corrupt DDS stream: {0}")]
    CorruptDds(String),
    #[error(
        "DDS stream decompresses to {bytes} bytes, more than the limit of {limit} bytes of voxels plus {} bytes of header",
        HEADER_ALLOWANCE
    )]
    DdsTooLarge { bytes: u64, limit: u64 },
    #[error("out of memory: cannot allocate {0} bytes for PVM data")]
    OutOfMemory(u64),
    #[error("cannot write PVM: {0}")]
    InvalidInput(String),
    #[error("I/O error while writing PVM: {0}")]
    Io(#[from] std::io::Error),
}

/// Allocation that reports failure instead of aborting.
pub(super) fn try_with_capacity<T>(n: usize) -> Result<Vec<T>, PvmError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| PvmError::OutOfMemory((n as u64).saturating_mul(size_of::<T>() as u64)))?;
    Ok(v)
}

pub(super) fn zeroed<T: Copy + Default>(n: usize) -> Result<Vec<T>, PvmError> {
    let mut v = try_with_capacity(n)?;
    v.resize(n, T::default());
    Ok(v)
}

pub(super) fn copy_bytes(bytes: &[u8]) -> Result<Vec<u8>, PvmError> {
    let mut v = try_with_capacity(bytes.len())?;
    v.extend_from_slice(bytes);
    Ok(v)
}

/// Big-endian byte pairs → native `u16` (an odd last byte cannot occur: the length is 2·n).
pub(super) fn u16_from_be(bytes: &[u8]) -> Result<Vec<u16>, PvmError> {
    let (pairs, _) = bytes.as_chunks::<2>();
    let mut v = try_with_capacity(pairs.len())?;
    v.extend(pairs.iter().map(|&p| u16::from_be_bytes(p)));
    Ok(v)
}
