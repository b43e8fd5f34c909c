//! Reading an OME-Zarr store (a local folder, NGFF 0.4/Zarr v2 or NGFF 0.5/Zarr v3): one
//! resolution level into a [`Volume`], chunk slab by chunk slab, and the list of levels.

use super::meta::{self, AxisKind, Multiscale, NgffVersion, one_line};
use crate::volume::orient::AffineSource;
use crate::volume::{
    Orientation, Reading, Volume, VolumeError, VoxelData, VoxelType, fmt_bytes, fmt_dims,
    frame_out_of_range,
};
use glam::{DMat3, DVec3};
use std::path::Path;
use std::sync::Arc;
use zarrs::array::data_type::{
    Float32DataType, Float64DataType, Int8DataType, Int16DataType, Int32DataType, UInt8DataType,
    UInt16DataType, UInt32DataType,
};
use zarrs::array::{Array, ArraySubset, ElementOwned};
use zarrs::filesystem::FilesystemStore;
use zarrs::group::Group;
use zarrs::metadata::GroupMetadata;
use zarrs::plugin::{ExtensionName, ZarrVersion};

/// Whether `path` is a folder that looks like a Zarr store: named `*.zarr`, or holding
/// Zarr metadata at its top (`zarr.json`, `.zgroup`, `.zattrs`).
pub fn is_zarr_store(path: &Path) -> bool {
    path.is_dir()
        && (path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("zarr"))
            || ["zarr.json", ".zgroup", ".zattrs"]
                .iter()
                .any(|f| path.join(f).is_file()))
}

/// One resolution level as `volao info` lists it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LevelInfo {
    /// The level's array, relative to the image group (`s0`, `0`, …).
    pub path: String,
    /// Voxels along volao's x, y, z (the arrays' last, middle and first spatial axis).
    pub dims: [usize; 3],
    /// Spacing in mm along x, y, z.
    pub spacing_mm: [f64; 3],
}

/// What a store holds: its versions and levels.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StoreInfo {
    /// NGFF version, "0.4" or "0.5".
    pub ngff: &'static str,
    /// Zarr format, 2 or 3.
    pub zarr_format: u8,
    pub levels: Vec<LevelInfo>,
}

/// One level read into a volume.
#[derive(Debug)]
pub struct ZarrLoaded {
    pub volume: Volume,
    pub ngff: NgffVersion,
    pub zarr_format: u8,
    pub level: usize,
    pub levels: usize,
}

/// An opened store: its image group and metadata.
struct Store {
    storage: Arc<FilesystemStore>,
    /// The image group's path in the store ("/", or "/0" under a bioformats2raw layout).
    group: String,
    zarr_format: u8,
    meta: Multiscale,
}

impl Store {
    fn open(path: &Path) -> Result<Self, VolumeError> {
        let bad = |m: String| VolumeError::invalid(path, m);
        let storage = Arc::new(
            FilesystemStore::new(path)
                .map_err(|e| bad(format!("cannot open as a Zarr store: {e}")))?,
        );
        let mut group_path = "/".to_owned();
        let mut group = open_group(&storage, &group_path).map_err(bad)?;
        // bioformats2raw's layout: the image is the group "0" below the root.
        if group.attributes().contains_key("bioformats2raw.layout")
            && !has_multiscales(group.attributes())
        {
            group_path = "/0".to_owned();
            group = open_group(&storage, &group_path).map_err(bad)?;
        }
        let zarr_format = match group.metadata() {
            GroupMetadata::V3(_) => 3,
            GroupMetadata::V2(_) => 2,
        };
        let meta = meta::parse(group.attributes()).map_err(bad)?;
        let expected = match meta.version {
            NgffVersion::V0_4 => 2,
            NgffVersion::V0_5 => 3,
        };
        if zarr_format != expected {
            return Err(bad(format!(
                "OME-Zarr {} metadata in a Zarr v{zarr_format} group (NGFF 0.4 is Zarr v2, 0.5 is Zarr v3)",
                meta.version.name()
            )));
        }
        Ok(Self {
            storage,
            group: group_path,
            zarr_format,
            meta,
        })
    }

    fn array(&self, path: &Path, level: usize) -> Result<Array<FilesystemStore>, VolumeError> {
        let rel = &self.meta.levels[level].path;
        let key = if self.group == "/" {
            format!("/{rel}")
        } else {
            format!("{}/{rel}", self.group)
        };
        let array = Array::open(self.storage.clone(), &key).map_err(|e| {
            VolumeError::invalid(
                path,
                format!(
                    "level {level} (array {rel:?}): {}",
                    one_line(&e.to_string())
                ),
            )
        })?;
        if array.dimensionality() != self.meta.axes.len() {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "level {level} (array {rel:?}) has {} dimensions but the metadata names {} axes",
                    array.dimensionality(),
                    self.meta.axes.len()
                ),
            ));
        }
        Ok(array)
    }

    /// Voxel counts along x, y, z of an array.
    fn dims(&self, array: &Array<FilesystemStore>) -> [usize; 3] {
        let shape = array.shape();
        self.meta.spatial.map(|a| shape[a] as usize)
    }

    /// Spacing (mm) along x, y, z of a level, with warnings for missing units.
    fn spacing(&self, level: usize) -> [f64; 3] {
        let l = &self.meta.levels[level];
        self.meta
            .spatial
            .map(|a| l.scale[a].abs() * self.meta.axes[a].mm_per_unit.unwrap_or(1.0))
    }
}

fn open_group(storage: &Arc<FilesystemStore>, at: &str) -> Result<Group<FilesystemStore>, String> {
    Group::open(storage.clone(), at).map_err(|e| match e {
        zarrs::group::GroupCreateError::MissingMetadata => {
            "not a Zarr store: no zarr.json (Zarr v3) or .zgroup (Zarr v2) at its top".to_owned()
        }
        e => format!("bad Zarr group metadata: {}", one_line(&e.to_string())),
    })
}

fn has_multiscales(attrs: &serde_json::Map<String, serde_json::Value>) -> bool {
    attrs.contains_key("multiscales")
        || attrs
            .get("ome")
            .is_some_and(|o| o.get("multiscales").is_some())
}

/// The versions and levels of the store at `path`.
pub fn store_info(path: &Path) -> Result<StoreInfo, VolumeError> {
    let store = Store::open(path)?;
    let mut levels = Vec::with_capacity(store.meta.levels.len());
    for k in 0..store.meta.levels.len() {
        let array = store.array(path, k)?;
        levels.push(LevelInfo {
            path: store.meta.levels[k].path.clone(),
            dims: store.dims(&array),
            spacing_mm: store.spacing(k),
        });
    }
    Ok(StoreInfo {
        ngff: store.meta.version.name(),
        zarr_format: store.zarr_format,
        levels,
    })
}

/// Reads resolution level `level` (0 = full resolution) of the store at `path`; `frame`
/// picks the index along a time axis (other non-spatial axes are read at index 0).
pub fn load(
    path: &Path,
    level: usize,
    frame: usize,
    reading: Reading<'_>,
) -> Result<ZarrLoaded, VolumeError> {
    let store = Store::open(path)?;
    let Reading {
        max_bytes,
        warnings,
        progress,
    } = reading;
    warnings.extend(store.meta.warnings.iter().cloned());
    let levels = store.meta.levels.len();
    if level >= levels {
        return Err(VolumeError::invalid(
            path,
            format!(
                "level {level} requested but the store has {levels} level{} (levels count from 0: 0 … {})",
                if levels == 1 { "" } else { "s" },
                levels - 1
            ),
        ));
    }
    let array = store.array(path, level)?;
    let shape = array.shape().to_vec();
    let axes = &store.meta.axes;

    // Non-spatial axes: the time axis at `frame`, the others at 0.
    let mut ranges: Vec<std::ops::Range<u64>> = shape.iter().map(|&n| 0..n).collect();
    let mut used_frame = false;
    for (a, axis) in axes.iter().enumerate() {
        if axis.kind == AxisKind::Space {
            continue;
        }
        let n = shape[a];
        let index = if axis.kind == AxisKind::Time {
            used_frame = true;
            if frame as u64 >= n {
                return Err(VolumeError::invalid(
                    path,
                    format!("time axis {}: {}", axis.name, frame_out_of_range(frame, n)),
                ));
            }
            frame as u64
        } else {
            0
        };
        if n > 1 && axis.kind != AxisKind::Time {
            let what = match &axis.kind {
                AxisKind::Channel => "channel".to_owned(),
                AxisKind::Other(t) => t.clone(),
                _ => String::new(),
            };
            warnings.push(format!(
                "axis {} ({what}) has {n} entries: reading index 0 only",
                axis.name
            ));
        }
        ranges[a] = index..index + 1;
    }
    if frame != 0 && !used_frame {
        return Err(VolumeError::invalid(
            path,
            "--frame: this OME-Zarr image has no time axis",
        ));
    }

    let dims = store.dims(&array);
    let spacing64 = store.spacing(level);
    let spacing = spacing64.map(|s| s as f32);
    let ty = voxel_type(&array).ok_or_else(|| {
        VolumeError::unsupported(
            path,
            format!(
                "voxel type {} is not supported (volao reads u8, i8, u16, i16, u32, i32, f32 and f64)",
                array
                    .data_type()
                    .name(ZarrVersion::V3)
                    .unwrap_or_else(|| array.data_type().to_string().into())
            ),
        )
    })?;
    let n = crate::volume::voxel_count(dims).ok_or_else(|| {
        VolumeError::invalid(path, format!("dimensions {} overflow", fmt_dims(dims)))
    })?;
    let bytes = n as u64 * ty.size() as u64;
    if bytes > max_bytes {
        return Err(VolumeError::TooLarge {
            path: path.to_owned(),
            dims: fmt_dims(dims),
            ty: ty.to_string(),
            bytes: fmt_bytes(bytes),
            limit: fmt_bytes(max_bytes),
        });
    }
    for &a in &store.meta.spatial {
        if axes[a].unit.is_none() {
            warnings.push(format!(
                "axis {} names no unit: its scale is taken as millimetres",
                axes[a].name
            ));
        }
    }

    let slab = Slabs {
        array: &array,
        ranges,
        z_axis: store.meta.spatial[2],
        n,
        bytes,
    };
    let err = |e: zarrs::array::ArrayError| {
        VolumeError::invalid(path, format!("level {level}: {}", one_line(&e.to_string())))
    };
    let alloc = || {
        VolumeError::invalid(
            path,
            format!("cannot allocate {} for the voxels", fmt_bytes(bytes)),
        )
    };
    let p = progress;
    let data = match ty {
        VoxelType::U8 => VoxelData::U8(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::I8 => VoxelData::I8(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::U16 => VoxelData::U16(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::I16 => VoxelData::I16(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::U32 => VoxelData::U32(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::I32 => VoxelData::I32(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::F32 => VoxelData::F32(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
        VoxelType::F64 => VoxelData::F64(slab.read(p).map_err(err)?.ok_or_else(alloc)?),
    };

    let mut volume = Volume::new(dims, spacing, data).map_err(|m| VolumeError::invalid(path, m))?;
    volume.orientation = orientation(&store, level, spacing64, warnings);
    Ok(ZarrLoaded {
        volume,
        ngff: store.meta.version,
        zarr_format: store.zarr_format,
        level,
        levels,
    })
}

fn voxel_type(array: &Array<FilesystemStore>) -> Option<VoxelType> {
    let dt = array.data_type();
    Some(if dt.is::<UInt8DataType>() {
        VoxelType::U8
    } else if dt.is::<Int8DataType>() {
        VoxelType::I8
    } else if dt.is::<UInt16DataType>() {
        VoxelType::U16
    } else if dt.is::<Int16DataType>() {
        VoxelType::I16
    } else if dt.is::<UInt32DataType>() {
        VoxelType::U32
    } else if dt.is::<Int32DataType>() {
        VoxelType::I32
    } else if dt.is::<Float32DataType>() {
        VoxelType::F32
    } else if dt.is::<Float64DataType>() {
        VoxelType::F64
    } else {
        return None;
    })
}

/// Reads the selected subset slab by slab along the slowest spatial axis (one chunk
/// thick), so progress can be reported and nothing but the result is held.
struct Slabs<'a> {
    array: &'a Array<FilesystemStore>,
    ranges: Vec<std::ops::Range<u64>>,
    z_axis: usize,
    n: usize,
    bytes: u64,
}

impl Slabs<'_> {
    /// The voxels, x fastest; `Ok(None)` when the buffer cannot be allocated.
    fn read<T: ElementOwned>(
        &self,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<Option<Vec<T>>, zarrs::array::ArrayError> {
        let mut out: Vec<T> = Vec::new();
        if out.try_reserve_exact(self.n).is_err() {
            return Ok(None);
        }
        let origin = vec![0u64; self.ranges.len()];
        let thick = self
            .array
            .chunk_shape(&origin)?
            .get(self.z_axis)
            .map_or(1, |c| c.get());
        let nz = self.ranges[self.z_axis].end;
        let per_z = self.bytes / nz.max(1);
        let mut z = 0;
        while z < nz {
            let end = (z + thick).min(nz);
            let mut ranges = self.ranges.clone();
            ranges[self.z_axis] = z..end;
            let part: Vec<T> = self
                .array
                .retrieve_array_subset(&ArraySubset::new_with_ranges(&ranges))?;
            out.extend(part);
            z = end;
            progress(per_z * z, self.bytes);
        }
        Ok(Some(out))
    }
}

/// The voxel-to-RAS transform of a level: each spatial axis along the world axis its
/// RFC-4 orientation names (or the documented default: x left-to-right, y
/// posterior-to-anterior, z inferior-to-superior), coordinate = index · scale +
/// translation in that direction.
fn orientation(
    store: &Store,
    level: usize,
    spacing: [f64; 3],
    warnings: &mut Vec<String>,
) -> Orientation {
    let meta = &store.meta;
    let (map, source) = match meta.orientation {
        Some(map) => (map, AffineSource::Header),
        None => {
            warnings.push(
                "no RFC-4 anatomical orientation in the OME-Zarr metadata: assuming x runs left-to-right, y posterior-to-anterior, z inferior-to-superior (RAS)"
                    .to_owned(),
            );
            (default_map(meta), AffineSource::Assumed)
        }
    };
    let l = &meta.levels[level];
    let mut cols = [DVec3::ZERO; 3];
    let mut offset = DVec3::ZERO;
    for (slot, &a) in meta.spatial.iter().enumerate() {
        let (w, positive) = map[slot];
        let sign = if positive { 1.0 } else { -1.0 };
        let mm = meta.axes[a].mm_per_unit.unwrap_or(1.0);
        let dir = sign * l.scale[a].signum();
        cols[slot][w] = dir * spacing[slot];
        offset[w] = sign * l.translation[a] * mm;
    }
    Orientation {
        linear: DMat3::from_cols(cols[0], cols[1], cols[2]),
        offset,
        source,
    }
}

/// Without RFC-4 metadata: axes named x, y, z go to R, A, S by name; otherwise volao's
/// x, y, z (the last three array axes, fastest first) go to R, A, S.
fn default_map(meta: &Multiscale) -> [(usize, bool); 3] {
    let by_name = meta.spatial.map(|a| match meta.axes[a].name.as_str() {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    });
    match by_name {
        [Some(a), Some(b), Some(c)] if a != b && b != c && a != c => {
            [(a, true), (b, true), (c, true)]
        }
        _ => [(0, true), (1, true), (2, true)],
    }
}
