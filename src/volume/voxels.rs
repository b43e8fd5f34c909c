//! Typed voxel buffers: the stored type is kept, never widened behind the user's back.

use std::fmt;

/// The element type of a voxel buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VoxelType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl VoxelType {
    pub const ALL: [VoxelType; 8] = [
        VoxelType::U8,
        VoxelType::I8,
        VoxelType::U16,
        VoxelType::I16,
        VoxelType::U32,
        VoxelType::I32,
        VoxelType::F32,
        VoxelType::F64,
    ];

    pub fn size(self) -> usize {
        match self {
            VoxelType::U8 | VoxelType::I8 => 1,
            VoxelType::U16 | VoxelType::I16 => 2,
            VoxelType::U32 | VoxelType::I32 | VoxelType::F32 => 4,
            VoxelType::F64 => 8,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            VoxelType::U8 => "u8",
            VoxelType::I8 => "i8",
            VoxelType::U16 => "u16",
            VoxelType::I16 => "i16",
            VoxelType::U32 => "u32",
            VoxelType::I32 => "i32",
            VoxelType::F32 => "f32",
            VoxelType::F64 => "f64",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|t| t.name() == name.to_ascii_lowercase())
    }

    pub fn is_float(self) -> bool {
        matches!(self, VoxelType::F32 | VoxelType::F64)
    }
}

impl fmt::Display for VoxelType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Voxels in their stored type, x fastest.
#[derive(Clone, PartialEq)]
pub enum VoxelData {
    U8(Vec<u8>),
    I8(Vec<i8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    U32(Vec<u32>),
    I32(Vec<i32>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

/// Runs `$body` with `$v` bound to the typed `Vec` inside a [`VoxelData`].
macro_rules! with_voxels {
    ($data:expr, $v:ident => $body:expr) => {
        match $data {
            $crate::volume::VoxelData::U8($v) => $body,
            $crate::volume::VoxelData::I8($v) => $body,
            $crate::volume::VoxelData::U16($v) => $body,
            $crate::volume::VoxelData::I16($v) => $body,
            $crate::volume::VoxelData::U32($v) => $body,
            $crate::volume::VoxelData::I32($v) => $body,
            $crate::volume::VoxelData::F32($v) => $body,
            $crate::volume::VoxelData::F64($v) => $body,
        }
    };
}
pub(crate) use with_voxels;

impl fmt::Debug for VoxelData {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "VoxelData::{}[{}]", self.voxel_type(), self.len())
    }
}

/// A zero-filled buffer of `n` elements, or `None` if the allocator refuses.
///
/// Uses `alloc_zeroed` (calloc): large buffers get lazily zeroed pages from the OS, so
/// filling them from a file touches each page once instead of twice.
fn try_zeroed<T: bytemuck::Zeroable + bytemuck::Pod>(n: usize) -> Option<Vec<T>> {
    if n == 0 {
        return Some(Vec::new());
    }
    bytemuck::allocation::try_zeroed_vec(n).ok()
}

impl VoxelData {
    /// A zero-filled buffer; `None` if the memory cannot be had (never aborts).
    pub fn try_zeroed(ty: VoxelType, n: usize) -> Option<Self> {
        Some(match ty {
            VoxelType::U8 => VoxelData::U8(try_zeroed(n)?),
            VoxelType::I8 => VoxelData::I8(try_zeroed(n)?),
            VoxelType::U16 => VoxelData::U16(try_zeroed(n)?),
            VoxelType::I16 => VoxelData::I16(try_zeroed(n)?),
            VoxelType::U32 => VoxelData::U32(try_zeroed(n)?),
            VoxelType::I32 => VoxelData::I32(try_zeroed(n)?),
            VoxelType::F32 => VoxelData::F32(try_zeroed(n)?),
            VoxelType::F64 => VoxelData::F64(try_zeroed(n)?),
        })
    }

    pub fn voxel_type(&self) -> VoxelType {
        match self {
            VoxelData::U8(_) => VoxelType::U8,
            VoxelData::I8(_) => VoxelType::I8,
            VoxelData::U16(_) => VoxelType::U16,
            VoxelData::I16(_) => VoxelType::I16,
            VoxelData::U32(_) => VoxelType::U32,
            VoxelData::I32(_) => VoxelType::I32,
            VoxelData::F32(_) => VoxelType::F32,
            VoxelData::F64(_) => VoxelType::F64,
        }
    }

    pub fn len(&self) -> usize {
        with_voxels!(self, v => v.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Size of the voxel payload in bytes.
    pub fn byte_len(&self) -> usize {
        self.len() * self.voxel_type().size()
    }

    /// Stored value of voxel `i` as f64 (panics if `i` is out of range, like indexing).
    #[inline]
    #[allow(
        clippy::unnecessary_cast,
        reason = "the cast is a no-op only for the f64 variant"
    )]
    pub fn get_f64(&self, i: usize) -> f64 {
        with_voxels!(self, v => v[i] as f64)
    }

    /// The voxels as native-endian bytes.
    pub fn as_bytes(&self) -> &[u8] {
        with_voxels!(self, v => bytemuck::cast_slice(v))
    }

    /// The voxels as mutable native-endian bytes, for readers that fill the buffer in place.
    pub fn as_bytes_mut(&mut self) -> &mut [u8] {
        with_voxels!(self, v => bytemuck::cast_slice_mut(v))
    }

    /// Reverses the byte order of every element (big ↔ little endian).
    pub fn swap_bytes(&mut self) {
        match self {
            VoxelData::U8(_) | VoxelData::I8(_) => {}
            VoxelData::U16(v) => v.iter_mut().for_each(|x| *x = x.swap_bytes()),
            VoxelData::I16(v) => v.iter_mut().for_each(|x| *x = x.swap_bytes()),
            VoxelData::U32(v) => v.iter_mut().for_each(|x| *x = x.swap_bytes()),
            VoxelData::I32(v) => v.iter_mut().for_each(|x| *x = x.swap_bytes()),
            VoxelData::F32(v) => v
                .iter_mut()
                .for_each(|x| *x = f32::from_bits(x.to_bits().swap_bytes())),
            VoxelData::F64(v) => v
                .iter_mut()
                .for_each(|x| *x = f64::from_bits(x.to_bits().swap_bytes())),
        }
    }

    /// Converts stored bytes with the given byte order to native order in place.
    pub fn fix_endianness(&mut self, little_endian: bool) {
        if little_endian != cfg!(target_endian = "little") {
            self.swap_bytes();
        }
    }

    /// Bitwise equality (treats NaNs with equal bits as equal, unlike `==`).
    pub fn bits_eq(&self, other: &Self) -> bool {
        self.voxel_type() == other.voxel_type() && self.as_bytes() == other.as_bytes()
    }
}

macro_rules! impl_from_vec {
    ($($t:ty => $variant:ident),*) => {
        $(impl From<Vec<$t>> for VoxelData {
            fn from(v: Vec<$t>) -> Self {
                VoxelData::$variant(v)
            }
        })*
    };
}
impl_from_vec!(u8 => U8, i8 => I8, u16 => U16, i16 => I16, u32 => U32, i32 => I32, f32 => F32, f64 => F64);
