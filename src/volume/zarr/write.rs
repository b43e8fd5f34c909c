//! Writing a volume as an OME-Zarr store: NGFF 0.5 (Zarr v3, what the Python `ome-zarr`
//! package writes and reads by default), a pyramid of 2× means, 64³ chunks compressed
//! with zstd, scale and translation from the spacing and origin, and RFC-4 anatomical
//! orientation on every spatial axis, so volao reads its own stores back exactly.

use super::meta::{self, orientation_name};
use crate::volume::{
    Volume, VolumeError, VoxelData, VoxelType, physical_values, voxel_of, with_voxels,
};
use rayon::prelude::*;
use serde_json::{Value, json};
use std::path::Path;
use std::sync::Arc;
use zarrs::array::codec::ZstdCodec;
use zarrs::array::{ArrayBuilder, ArraySubset, BytesToBytesCodecTraits, DataType, data_type};
use zarrs::filesystem::FilesystemStore;
use zarrs::group::GroupBuilder;

/// The pyramid stops at the first level whose longest axis is at most this.
pub const COARSEST_EDGE: usize = 64;
/// Chunk edge (voxels) of every level.
pub const CHUNK_EDGE: u64 = 64;
/// zstd level: 3 is zstd's own default (fast, and about as small as higher levels for
/// medical images).
const ZSTD_LEVEL: i32 = 3;

/// Writes `volume` as a new OME-Zarr store at `path` (which must not exist yet or be an
/// empty folder). Returns the warnings (values rescaled, obliquity lost).
pub fn save(volume: &Volume, path: &Path, warnings: &mut Vec<String>) -> Result<(), VolumeError> {
    if path.exists() {
        let empty = std::fs::read_dir(path).is_ok_and(|mut d| d.next().is_none());
        if !empty {
            return Err(VolumeError::invalid(
                path,
                "already exists: an OME-Zarr store is a folder, and volao does not write into an existing one (remove it first)",
            ));
        }
    }
    let data = if volume.scaling.is_identity() {
        None
    } else {
        let values = physical_values(volume);
        warnings.push(format!(
            "OME-Zarr has no rescale slope/intercept: writing the values (slope {} · stored + {}) as {}",
            volume.scaling.slope,
            volume.scaling.inter,
            values.voxel_type()
        ));
        Some(values)
    };
    let data = data.as_ref().unwrap_or(&volume.data);

    let map = volume.orientation.axis_map();
    if is_oblique(volume) {
        warnings.push(format!(
            "the affine is oblique; OME-Zarr 0.5 holds no rotation, so the axes are written along their nearest anatomical directions ({})",
            volume.orientation.axis_codes()
        ));
    }

    std::fs::create_dir_all(path).map_err(|e| VolumeError::io(path, e))?;
    let storage = Arc::new(
        FilesystemStore::new(path).map_err(|e| VolumeError::invalid(path, e.to_string()))?,
    );
    let fail = |what: &str, e: String| VolumeError::invalid(path, format!("{what}: {e}"));

    // Levels: each a 2× mean of the one before, until the longest axis is ≤ 64.
    let mut datasets = Vec::new();
    let mut current: Option<VoxelData> = None;
    let pyramid = pyramid_dims(volume.dims);
    for (level, &dims) in pyramid.iter().enumerate() {
        if level > 0 {
            let before = current.as_ref().unwrap_or(data);
            current = Some(downsample(before, pyramid[level - 1]).0);
        }
        let voxels = current.as_ref().unwrap_or(data);
        let name = format!("s{level}");
        write_level(&storage, &name, voxels, dims).map_err(|e| fail(&name, e))?;
        let factor = (1u64 << level) as f64;
        let scale: Vec<f64> = (0..3)
            .rev()
            .map(|a| volume.spacing[a] as f64 * factor)
            .collect();
        // A level's voxel 0 is the mean of a factor³ block: its centre sits
        // (factor − 1)/2 voxels of level 0 further along each axis.
        let translation: Vec<f64> = (0..3)
            .rev()
            .map(|a| {
                let (w, positive) = map[a];
                let sign = if positive { 1.0 } else { -1.0 };
                sign * volume.orientation.offset[w]
                    + (factor - 1.0) / 2.0 * volume.spacing[a] as f64
            })
            .collect();
        datasets.push(json!({
            "path": name,
            "coordinateTransformations": [
                {"type": "scale", "scale": scale},
                {"type": "translation", "translation": translation},
            ],
        }));
    }

    let axes: Vec<Value> = (0..3)
        .rev()
        .map(|a| {
            let (w, positive) = map[a];
            let name = ["x", "y", "z"][a];
            json!({
                "name": name,
                "type": "space",
                "unit": "millimeter",
                "orientation": {"type": "anatomical", "value": orientation_name(w, positive)},
            })
        })
        .collect();
    let name = volume
        .descriptions
        .iter()
        .find(|(k, _)| k == "name" || k == "description")
        .map(|(_, v)| v.clone())
        .unwrap_or_else(|| "image".to_owned());
    let ome = json!({
        "version": "0.5",
        "multiscales": [{
            "name": name,
            "axes": axes,
            "datasets": datasets,
            "type": "mean",
            "metadata": {
                "description": "2×2×2 means (at odd edges, of the voxels there are), by volao convert",
                "method": "volao",
            },
        }],
    });
    let mut attributes = serde_json::Map::new();
    attributes.insert("ome".to_owned(), ome);
    // What we write must be what we read: validate it as a reader would.
    meta::parse(&attributes).map_err(|e| fail("metadata written", e))?;
    GroupBuilder::new()
        .attributes(attributes)
        .build(storage.clone(), "/")
        .map_err(|e| fail("group", e.to_string()))?
        .store_metadata()
        .map_err(|e| fail("group", e.to_string()))?;
    Ok(())
}

/// Whether any voxel axis is not along a world axis.
fn is_oblique(volume: &Volume) -> bool {
    let l = volume.orientation.linear;
    [l.x_axis, l.y_axis, l.z_axis].iter().any(|c| {
        let a = c.abs();
        a.max_element() < c.length() * (1.0 - 1e-9)
    })
}

fn zarr_type(ty: VoxelType) -> DataType {
    match ty {
        VoxelType::U8 => data_type::uint8(),
        VoxelType::I8 => data_type::int8(),
        VoxelType::U16 => data_type::uint16(),
        VoxelType::I16 => data_type::int16(),
        VoxelType::U32 => data_type::uint32(),
        VoxelType::I32 => data_type::int32(),
        VoxelType::F32 => data_type::float32(),
        VoxelType::F64 => data_type::float64(),
    }
}

/// One level: a (z, y, x) array of `dims` (x, y, z) in 64³ chunks.
fn write_level(
    storage: &Arc<FilesystemStore>,
    name: &str,
    data: &VoxelData,
    dims: [usize; 3],
) -> Result<(), String> {
    let shape: Vec<u64> = dims.iter().rev().map(|&n| n as u64).collect();
    let chunks: Vec<u64> = shape.iter().map(|&n| n.clamp(1, CHUNK_EDGE)).collect();
    let ty = data.voxel_type();
    let fill = zarrs::array::FillValueMetadata::Number(serde_json::Number::from(0u8));
    let zstd: Arc<dyn BytesToBytesCodecTraits> = Arc::new(ZstdCodec::new(ZSTD_LEVEL, false));
    let array = ArrayBuilder::new(shape, chunks, zarr_type(ty), fill)
        .bytes_to_bytes_codecs(vec![zstd])
        .dimension_names(Some(["z", "y", "x"]))
        .build(storage.clone(), &format!("/{name}"))
        .map_err(|e| e.to_string())?;
    array.store_metadata().map_err(|e| e.to_string())?;
    let all = ArraySubset::new_with_shape(array.shape().to_vec());
    with_voxels!(data, v => array.store_array_subset(&all, v.as_slice()))
        .map_err(|e| e.to_string())?;
    Ok(())
}

/// The 2× mean of a volume: each output voxel the mean of the (up to) 2×2×2 input
/// voxels it covers (odd edges average what is there); integers rounded to nearest.
pub fn downsample(data: &VoxelData, dims: [usize; 3]) -> (VoxelData, [usize; 3]) {
    let out_dims = dims.map(|n| n.div_ceil(2));
    let data = match data {
        VoxelData::U8(v) => VoxelData::U8(half(v, dims, out_dims, |m| m.round() as u8)),
        VoxelData::I8(v) => VoxelData::I8(half(v, dims, out_dims, |m| m.round() as i8)),
        VoxelData::U16(v) => VoxelData::U16(half(v, dims, out_dims, |m| m.round() as u16)),
        VoxelData::I16(v) => VoxelData::I16(half(v, dims, out_dims, |m| m.round() as i16)),
        VoxelData::U32(v) => VoxelData::U32(half(v, dims, out_dims, |m| m.round() as u32)),
        VoxelData::I32(v) => VoxelData::I32(half(v, dims, out_dims, |m| m.round() as i32)),
        VoxelData::F32(v) => VoxelData::F32(half(v, dims, out_dims, |m| m as f32)),
        VoxelData::F64(v) => VoxelData::F64(half(v, dims, out_dims, |m| m)),
    };
    (data, out_dims)
}

fn half<T: Copy + Into<f64> + Send + Sync>(
    v: &[T],
    dims: [usize; 3],
    out: [usize; 3],
    back: impl Fn(f64) -> T + Sync,
) -> Vec<T> {
    let [nx, ny, nz] = dims;
    let n = out[0] * out[1] * out[2];
    (0..n)
        .into_par_iter()
        .map(|i| {
            let [x, y, z] = voxel_of(i, out);
            let mut sum = 0.0f64;
            let mut count = 0u32;
            for zz in 2 * z..(2 * z + 2).min(nz) {
                for yy in 2 * y..(2 * y + 2).min(ny) {
                    for xx in 2 * x..(2 * x + 2).min(nx) {
                        sum += v[xx + nx * (yy + ny * zz)].into();
                        count += 1;
                    }
                }
            }
            back(sum / count as f64)
        })
        .collect()
}

/// The dims of every level `save` writes for a volume of `dims`.
pub fn pyramid_dims(dims: [usize; 3]) -> Vec<[usize; 3]> {
    let mut out = vec![dims];
    let mut d = dims;
    while d.iter().max().copied().unwrap_or(0) > COARSEST_EDGE {
        d = d.map(|n| n.div_ceil(2));
        out.push(d);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downsample_means_with_odd_edges() {
        // 3×2×1: x pairs (0,1) and the lone 2.
        let v = VoxelData::U8(vec![10, 20, 30, 40, 50, 61]);
        let (d, dims) = downsample(&v, [3, 2, 1]);
        assert_eq!(dims, [2, 1, 1]);
        // (10+20+40+50)/4 = 30; (30+61)/2 = 45.5 → 46.
        assert_eq!(d, VoxelData::U8(vec![30, 46]));
    }

    #[test]
    fn pyramid_stops_at_64() {
        assert_eq!(
            pyramid_dims([91, 109, 91]),
            vec![[91, 109, 91], [46, 55, 46]]
        );
        assert_eq!(pyramid_dims([64, 10, 3]), vec![[64, 10, 3]]);
        assert_eq!(pyramid_dims([256, 256, 108]).len(), 3);
    }
}
