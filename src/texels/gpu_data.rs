//! The volume reader's uniform as the shaders see it (rerun's `gpu_data` pattern): one
//! `#[repr(C)]` struct mirroring `struct VolumeMap` in `shaders/volume.wgsl`, shared by
//! every GPU stage ([`super::reader`]) and the CPU twin ([`crate::sample::VolumeSampler`]).

use super::VolumeTexels;
use crate::tf::Lut;

/// How a stage reads texel values: the map to the transfer function's table and the map
/// to the values it wants. Mirrors `struct VolumeMap` in `volume.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VolumeMap {
    /// Table index `t = texel · lut[0] + lut[1]`, clamped to `[0, lut[2]]` (the last
    /// entry); `lut[3]` unused.
    pub lut: [f32; 4],
    /// The stage's value `texel · value[0] + value[1]` (the data's units, or the
    /// density normalised over its range); `value[2..]` unused.
    pub value: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<VolumeMap>() == 32);

impl VolumeMap {
    /// Texels of `texels` read through `lut`, values in the data's units.
    pub fn new(texels: &VolumeTexels, lut: &Lut) -> Self {
        let (a, b) = texels.lut_map(lut);
        Self::with_lut_map(a, b, lut)
            .with_value(texels.value_scale as f32, texels.value_offset as f32)
    }

    /// Texels mapped to the table by `t = texel · a + b` (an f16 copy of the volume, say,
    /// [`crate::sample::f16_lut_map`]).
    pub fn with_lut_map(a: f32, b: f32, lut: &Lut) -> Self {
        VolumeMap {
            lut: [a, b, Self::last_entry(lut), 0.0],
            value: [1.0, 0.0, 0.0, 0.0],
        }
    }

    /// The same with the value map `texel · scale + offset`.
    pub fn with_value(self, scale: f32, offset: f32) -> Self {
        VolumeMap {
            value: [scale, offset, 0.0, 0.0],
            ..self
        }
    }

    /// The index of `lut`'s last entry (a table has at least two).
    pub fn last_entry(lut: &Lut) -> f32 {
        (lut.rgba.len().max(2) - 1) as f32
    }

    /// `(scale, offset, last)` of the table map, as [`crate::sample::VolumeSampler`] reads it.
    pub fn lut_map(&self) -> [f32; 3] {
        [self.lut[0], self.lut[1], self.lut[2]]
    }
}
