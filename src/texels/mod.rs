//! The volume as the GPU sees it: texture format, normalised texel values, the map from
//! a texel value back to the data's units, and the occupancy grid for empty-space skipping.
//!
//! Both the GPU upload and the CPU twin start from [`VolumeTexels`], so they sample the
//! same numbers.

use crate::tf::Lut;

pub mod gpu;
pub mod gpu_data;
pub mod reader;
pub mod segments;
use crate::volume::{Volume, VoxelData};

/// Texture format chosen to keep the data's precision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TexelFormat {
    /// 8-bit data (`u8`, `i8` shifted by 128).
    R8Unorm,
    /// 16-bit data (`u16`, `i16` shifted by 32768) — CT keeps every Hounsfield unit.
    R16Unorm,
    /// Everything else, as f32 physical values.
    R32Float,
}

impl TexelFormat {
    pub fn wgpu(self) -> wgpu::TextureFormat {
        match self {
            TexelFormat::R8Unorm => wgpu::TextureFormat::R8Unorm,
            TexelFormat::R16Unorm => wgpu::TextureFormat::R16Unorm,
            TexelFormat::R32Float => wgpu::TextureFormat::R32Float,
        }
    }

    pub fn bytes(self) -> usize {
        match self {
            TexelFormat::R8Unorm => 1,
            TexelFormat::R16Unorm => 2,
            TexelFormat::R32Float => 4,
        }
    }
}

/// A volume ready for upload: raw texel bytes plus the same texels as f32 for the CPU twin.
#[derive(Debug, Clone)]
pub struct VolumeTexels {
    pub dims: [usize; 3],
    /// Spacing in mm (after any downsampling).
    pub spacing: [f32; 3],
    pub format: TexelFormat,
    /// Texel bytes in `format`, x fastest.
    pub bytes: Vec<u8>,
    /// Physical value of a texel: `value = norm * value_scale + value_offset`, where `norm`
    /// is what the GPU returns when sampling (unorm in [0, 1], or the float itself).
    pub value_scale: f64,
    pub value_offset: f64,
    /// How many times the volume was halved to fit the adapter (0 = full resolution).
    pub downsampled: u32,
}

/// Bytes of voxels we upload before halving the resolution.
pub const MAX_VOLUME_BYTES: u64 = 2 << 30;

/// Limits the upload must respect.
#[derive(Debug, Clone, Copy)]
pub struct UploadLimits {
    pub max_dim: usize,
    pub max_bytes: u64,
}

impl UploadLimits {
    /// No limits: the volume at full resolution (for the CPU twins).
    pub const NONE: UploadLimits = UploadLimits {
        max_dim: usize::MAX,
        max_bytes: u64::MAX,
    };

    /// What `gpu` holds: its 3-D texture size and [`MAX_VOLUME_BYTES`].
    pub fn of(gpu: &crate::gpu::Gpu) -> Self {
        UploadLimits {
            max_dim: gpu.device.limits().max_texture_dimension_3d as usize,
            max_bytes: MAX_VOLUME_BYTES,
        }
    }

    /// Whether `texels` fit as they are (the test [`VolumeTexels::new`] halves until).
    pub fn fits(&self, texels: &VolumeTexels) -> bool {
        texels.dims.iter().all(|&d| d <= self.max_dim)
            && texels.bytes.len() as u64 <= self.max_bytes
    }
}

impl VolumeTexels {
    /// Converts a volume, halving its resolution until it fits `limits`.
    pub fn new(volume: &Volume, limits: UploadLimits) -> Self {
        let mut v = std::borrow::Cow::Borrowed(volume);
        let mut downsampled = 0;
        loop {
            let format = format_for(&v.data);
            let bytes = v.voxel_count() as u64 * format.bytes() as u64;
            if v.dims.iter().all(|&d| d <= limits.max_dim) && bytes <= limits.max_bytes
                || v.dims.iter().all(|&d| d <= 1)
            {
                break;
            }
            v = std::borrow::Cow::Owned(halve(&v));
            downsampled += 1;
        }
        let (format, bytes, scale, offset) = encode(&v.data);
        let s = v.scaling;
        VolumeTexels {
            dims: v.dims,
            spacing: v.spacing,
            format,
            bytes,
            // value = slope · stored + inter, stored = norm · scale + offset.
            value_scale: s.slope * scale,
            value_offset: s.slope * offset + s.inter,
            downsampled,
        }
    }

    /// Texel `i` (x fastest) as the GPU reads it: normalised for unorm formats.
    #[inline]
    pub fn norm_at(&self, i: usize) -> f32 {
        let b = &self.bytes;
        match self.format {
            TexelFormat::R8Unorm => b[i] as f32 / 255.0,
            TexelFormat::R16Unorm => u16::from_le_bytes([b[2 * i], b[2 * i + 1]]) as f32 / 65535.0,
            TexelFormat::R32Float => {
                f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]])
            }
        }
    }

    /// All texels as [`Self::norm_at`] reads them, for the CPU twins.
    pub fn norm_values(&self) -> Vec<f32> {
        (0..self.bytes.len() / self.format.bytes())
            .map(|i| self.norm_at(i))
            .collect()
    }

    /// Smallest and largest texel value (as [`Self::norm_at`] reads them).
    pub fn norm_range(&self) -> (f32, f32) {
        use rayon::prelude::*;
        (0..self.bytes.len() / self.format.bytes())
            .into_par_iter()
            .map(|i| self.norm_at(i))
            .fold(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), v| (a.min(v), b.max(v)),
            )
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            )
    }

    /// Physical size of the box in mm.
    pub fn extent(&self) -> [f32; 3] {
        std::array::from_fn(|i| self.dims[i] as f32 * self.spacing[i])
    }

    /// The `(a, b)` with `t = norm · a + b` giving the LUT's fractional entry index.
    pub fn lut_map(&self, lut: &Lut) -> (f32, f32) {
        let n = (lut.rgba.len().max(2) - 1) as f64;
        let span = (lut.max - lut.min).max(f64::MIN_POSITIVE);
        let a = self.value_scale / span * n;
        let b = (self.value_offset - lut.min) / span * n;
        (a as f32, b as f32)
    }
}

fn format_for(data: &VoxelData) -> TexelFormat {
    match data {
        VoxelData::U8(_) | VoxelData::I8(_) => TexelFormat::R8Unorm,
        VoxelData::U16(_) | VoxelData::I16(_) => TexelFormat::R16Unorm,
        _ => TexelFormat::R32Float,
    }
}

/// Texel bytes and the map `stored = norm · scale + offset`.
///
/// Non-finite floats become the lowest finite value of the volume, so they render as
/// whatever the transfer function gives the bottom of the range (normally transparent).
fn encode(data: &VoxelData) -> (TexelFormat, Vec<u8>, f64, f64) {
    match data {
        VoxelData::U8(v) => (TexelFormat::R8Unorm, v.clone(), 255.0, 0.0),
        VoxelData::I8(v) => (
            TexelFormat::R8Unorm,
            v.iter().map(|&x| (x as i16 + 128) as u8).collect(),
            255.0,
            -128.0,
        ),
        VoxelData::U16(v) => (
            TexelFormat::R16Unorm,
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            65535.0,
            0.0,
        ),
        VoxelData::I16(v) => (
            TexelFormat::R16Unorm,
            v.iter()
                .flat_map(|&x| ((x as i32 + 32768) as u16).to_le_bytes())
                .collect(),
            65535.0,
            -32768.0,
        ),
        other => {
            let n = other.len();
            let vals: Vec<f64> = (0..n).map(|i| other.get_f64(i)).collect();
            let lowest = vals
                .iter()
                .copied()
                .filter(|x| x.is_finite())
                .fold(f64::INFINITY, f64::min);
            let lowest = if lowest.is_finite() { lowest } else { 0.0 };
            // f64 beyond f32's range (see volume::f64_scale_for_f32): texels hold
            // stored / scale, and the map below multiplies it back.
            let scale = crate::volume::f64_scale_for_f32(other).unwrap_or(1.0);
            let bytes = vals
                .iter()
                .flat_map(|&x| {
                    ((if x.is_finite() { x } else { lowest } / scale) as f32).to_le_bytes()
                })
                .collect();
            (TexelFormat::R32Float, bytes, scale, 0.0)
        }
    }
}

/// Halves each dimension above 1 with a 2×2×2 box filter (stored values averaged as f64,
/// kept in the stored type), doubling the spacing.
fn halve(v: &Volume) -> Volume {
    let old = v.dims;
    let dims: [usize; 3] = std::array::from_fn(|i| old[i].div_ceil(2).max(1));
    let factor: [usize; 3] = std::array::from_fn(|i| if old[i] > 1 { 2 } else { 1 });
    let spacing: [f32; 3] = std::array::from_fn(|i| v.spacing[i] * factor[i] as f32);
    let avg = |x: usize, y: usize, z: usize| -> f64 {
        let (mut sum, mut n) = (0.0, 0.0);
        for dz in 0..factor[2] {
            for dy in 0..factor[1] {
                for dx in 0..factor[0] {
                    let (a, b, c) = (x * factor[0] + dx, y * factor[1] + dy, z * factor[2] + dz);
                    if a < old[0] && b < old[1] && c < old[2] {
                        let s = v.data.get_f64(a + old[0] * (b + old[1] * c));
                        if s.is_finite() {
                            sum += s;
                            n += 1.0;
                        }
                    }
                }
            }
        }
        if n > 0.0 { sum / n } else { f64::NAN }
    };
    let n = dims[0] * dims[1] * dims[2];
    let idx = |i: usize| {
        let [x, y, z] = crate::volume::voxel_of(i, dims);
        (x, y, z)
    };
    macro_rules! rebuild {
        ($variant:ident, $t:ty) => {
            VoxelData::$variant(
                (0..n)
                    .map(|i| {
                        let (x, y, z) = idx(i);
                        avg(x, y, z).round() as $t
                    })
                    .collect(),
            )
        };
    }
    let data = match &v.data {
        VoxelData::U8(_) => rebuild!(U8, u8),
        VoxelData::I8(_) => rebuild!(I8, i8),
        VoxelData::U16(_) => rebuild!(U16, u16),
        VoxelData::I16(_) => rebuild!(I16, i16),
        VoxelData::U32(_) => rebuild!(U32, u32),
        VoxelData::I32(_) => rebuild!(I32, i32),
        VoxelData::F32(_) => VoxelData::F32(
            (0..n)
                .map(|i| {
                    let (x, y, z) = idx(i);
                    avg(x, y, z) as f32
                })
                .collect(),
        ),
        VoxelData::F64(_) => VoxelData::F64(
            (0..n)
                .map(|i| {
                    let (x, y, z) = idx(i);
                    avg(x, y, z)
                })
                .collect(),
        ),
    };
    Volume {
        dims,
        spacing,
        data,
        scaling: v.scaling,
        orientation: v.orientation,
        descriptions: v.descriptions.clone(),
    }
}

/// Edge length of the ray caster's occupancy blocks in voxels. 4³ rather than 8³: the
/// finer grid lets compositing step over more of the empty space around surfaces
/// (cranium at 1024²: 28 % off an unshaded frame, docs/benchmarks.md); the AO stages
/// keep their 8³ bricks ([`BlockRanges::merged`]).
pub const BLOCK: usize = 4;

/// Per-block min/max of the texel values (with a one-voxel apron, so every trilinear
/// sample taken inside a block reads only voxels counted in its range). Computed once per
/// volume; [`BlockRanges::occupancy`] turns it into the skip grid for a given TF.
#[derive(Debug, Clone)]
pub struct BlockRanges {
    /// Edge of a block in voxels.
    pub edge: usize,
    pub grid: [usize; 3],
    /// (min, max) of `norm` per block, x fastest.
    pub ranges: Vec<(f32, f32)>,
}

impl BlockRanges {
    pub fn new(texels: &VolumeTexels) -> Self {
        Self::with_apron(texels, 1)
    }

    /// Ranges over each block widened by `apron` voxels: 1 is what a trilinear sample
    /// needs ([`Self::new`]); tests use 0 to show that exactness rests on it.
    pub fn with_apron(texels: &VolumeTexels, apron: usize) -> Self {
        Self::of_cells(texels, BLOCK, apron)
    }

    /// Ranges over cubes of `edge` voxels (not the ray caster's blocks: LAO rays skip
    /// over finer cells, `ao::sparse::RAY_CELL`), each widened by `apron` voxels.
    pub fn of_cells(texels: &VolumeTexels, edge: usize, apron: usize) -> Self {
        use rayon::prelude::*;
        let dims = texels.dims;
        let grid: [usize; 3] = std::array::from_fn(|i| dims[i].div_ceil(edge));
        let ranges = (0..grid[0] * grid[1] * grid[2])
            .into_par_iter()
            .map(|b| {
                let bi = crate::volume::voxel_of(b, grid);
                let lo: [usize; 3] = std::array::from_fn(|i| (bi[i] * edge).saturating_sub(apron));
                let hi: [usize; 3] =
                    std::array::from_fn(|i| ((bi[i] + 1) * edge + apron).min(dims[i]));
                let (mut mn, mut mx) = (f32::INFINITY, f32::NEG_INFINITY);
                for z in lo[2]..hi[2] {
                    for y in lo[1]..hi[1] {
                        let row = dims[0] * (y + dims[1] * z);
                        for v in (row + lo[0]..row + hi[0]).map(|i| texels.norm_at(i)) {
                            mn = mn.min(v);
                            mx = mx.max(v);
                        }
                    }
                }
                (mn, mx)
            })
            .collect();
        BlockRanges { edge, grid, ranges }
    }

    /// The ranges over blocks `factor` times larger per axis, from these alone: a
    /// larger block widened by the apron covers the same voxels as its widened
    /// sub-blocks together, so each range is the one [`Self::of_cells`] gives.
    pub fn merged(&self, factor: usize) -> BlockRanges {
        let grid = self.grid.map(|g| g.div_ceil(factor));
        let mut ranges = vec![(f32::INFINITY, f32::NEG_INFINITY); grid.iter().product()];
        for (i, &(mn, mx)) in self.ranges.iter().enumerate() {
            let b = crate::volume::voxel_of(i, self.grid).map(|c| c / factor);
            let r = &mut ranges[b[0] + grid[0] * (b[1] + grid[1] * b[2])];
            *r = (r.0.min(mn), r.1.max(mx));
        }
        BlockRanges {
            edge: self.edge * factor,
            grid,
            ranges,
        }
    }

    /// 1 where a block may be visible under `lut`, 0 where every sample in it is
    /// transparent. Conservative: skipping the zeros cannot change the image.
    pub fn occupancy(&self, texels: &VolumeTexels, lut: &Lut) -> Vec<u8> {
        self.ranges
            .iter()
            .map(|&(mn, mx)| {
                let a = mn as f64 * texels.value_scale + texels.value_offset;
                let b = mx as f64 * texels.value_scale + texels.value_offset;
                u8::from(!lut.is_transparent_over(a.min(b), a.max(b)))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn i16_keeps_every_hounsfield_unit() {
        let v =
            Volume::new([3, 1, 1], [1.0; 3], VoxelData::I16(vec![-1024, 0, 3071])).expect("valid");
        let t = VolumeTexels::new(
            &v,
            UploadLimits {
                max_dim: 4096,
                max_bytes: 1 << 30,
            },
        );
        assert_eq!(t.format, TexelFormat::R16Unorm);
        let phys: Vec<f64> = t
            .norm_values()
            .iter()
            .map(|&n| n as f64 * t.value_scale + t.value_offset)
            .collect();
        for (p, want) in phys.iter().zip([-1024.0, 0.0, 3071.0]) {
            assert!((p - want).abs() < 0.01, "{p} vs {want}");
        }
    }

    /// The AO stages' 8³ bricks take their ranges from the ray caster's 4³ blocks: the
    /// same numbers as computing them over 8³ cubes, with and without an apron, on
    /// dimensions that leave partial blocks at every far edge.
    #[test]
    fn merged_block_ranges_equal_ranges_of_the_larger_blocks() {
        let dims = [13, 9, 6];
        let n = dims.iter().product::<usize>();
        let data = (0..n).map(|i| ((i * 7919) % 251) as u8).collect();
        let v = Volume::new(dims, [1.0; 3], VoxelData::U8(data)).expect("valid");
        let t = VolumeTexels::new(
            &v,
            UploadLimits {
                max_dim: 4096,
                max_bytes: 1 << 30,
            },
        );
        for apron in [0, 1] {
            let fine = BlockRanges::of_cells(&t, 4, apron);
            let merged = fine.merged(2);
            let direct = BlockRanges::of_cells(&t, 8, apron);
            assert_eq!((merged.edge, merged.grid), (direct.edge, direct.grid));
            assert_eq!(merged.ranges, direct.ranges, "apron {apron}");
        }
    }

    #[test]
    fn oversized_volumes_are_halved_until_they_fit() {
        let v = Volume::new(
            [10, 6, 3],
            [1.0, 2.0, 3.0],
            VoxelData::U8((0..180).map(|i| i as u8).collect()),
        )
        .expect("valid");
        let t = VolumeTexels::new(
            &v,
            UploadLimits {
                max_dim: 4,
                max_bytes: 1 << 30,
            },
        );
        assert_eq!((t.dims, t.downsampled), ([3, 2, 1], 2));
        assert_eq!(t.spacing, [4.0, 8.0, 12.0], "z halves twice: 3 → 2 → 1");
        let t = VolumeTexels::new(
            &v,
            UploadLimits {
                max_dim: 4096,
                max_bytes: 100,
            },
        );
        assert!(t.bytes.len() <= 100);
    }
}
