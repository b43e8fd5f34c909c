//! What a label file holds before placement: the values of each layer on the file's own
//! grid, and the names and colours it carries.

use super::table::TableEntry;
use crate::volume::{Volume, VolumeError, VoxelData};
use std::collections::BTreeMap;
use std::path::Path;

/// One segment: a label value on one layer.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct SegmentKey {
    pub layer: u16,
    pub value: u16,
}

/// Names and colours a label file carries for its own values.
#[derive(Debug, Clone, Default)]
pub struct FileNames {
    pub entries: BTreeMap<SegmentKey, TableEntry>,
}

/// A label file's voxels before placement: one volume per layer (same grid), with the
/// names and colours the file carries.
#[derive(Debug, Clone)]
pub struct RawLabels {
    /// Each layer's values on the label grid; layer 0 first.
    pub layers: Vec<Vec<u16>>,
    /// The label grid: dims and orientation (its `data` is empty).
    pub grid: Grid,
    pub names: FileNames,
}

/// A voxel grid: dims and voxel index → world (RAS mm) map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub dims: [usize; 3],
    pub orientation: crate::volume::Orientation,
}

impl Grid {
    pub fn of(v: &Volume) -> Self {
        Self {
            dims: v.dims,
            orientation: v.orientation,
        }
    }
}

/// Stored values → label values, refusing anything that is not a whole number in
/// 0 … 65535.
pub fn to_labels(
    data: &VoxelData,
    scaling: crate::volume::Scaling,
    path: &Path,
) -> Result<Vec<u16>, VolumeError> {
    if scaling.is_identity() {
        if let VoxelData::U8(v) = data {
            return Ok(v.iter().map(|&x| x as u16).collect());
        }
        if let VoxelData::U16(v) = data {
            return Ok(v.clone());
        }
    }
    let mut out = Vec::with_capacity(data.len());
    let mut bad = None;
    for i in 0..data.len() {
        let f = scaling.apply(data.get_f64(i));
        if f.fract() != 0.0 || !(0.0..=65535.0).contains(&f) {
            bad = Some(f);
            break;
        }
        out.push(f as u16);
    }
    // f32 values printed as f32 ("0.37", not "0.3700000047683716").
    let show = |f: f64| match data {
        VoxelData::F32(_) => format!("{}", f as f32),
        _ => format!("{f}"),
    };
    match bad {
        None => Ok(out),
        Some(f) if !f.is_finite() || f.fract() != 0.0 => Err(VolumeError::invalid(
            path,
            format!(
                "a label map must hold integer labels; this one holds {} values such as {}",
                if data.voxel_type().is_float() {
                    "float"
                } else {
                    "scaled"
                },
                show(f)
            ),
        )),
        Some(f) => Err(VolumeError::invalid(
            path,
            format!("label values must lie in 0 … 65535; this label map holds {f}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_must_be_whole_and_in_range() {
        let p = Path::new("seg.nii");
        let id = crate::volume::Scaling::IDENTITY;
        let ok = to_labels(&VoxelData::I32(vec![0, 5, 300]), id, p).expect("whole");
        assert_eq!(ok, vec![0, 5, 300]);
        let e = to_labels(&VoxelData::F32(vec![0.0, 0.37]), id, p).expect_err("float");
        assert_eq!(
            e.to_string(),
            "seg.nii: a label map must hold integer labels; this one holds float values such as 0.37"
        );
        let e = to_labels(&VoxelData::I16(vec![0, -3]), id, p).expect_err("negative");
        assert!(e.to_string().contains("0 … 65535"), "{e}");
        let e = to_labels(&VoxelData::I32(vec![70000]), id, p).expect_err("too big");
        assert!(e.to_string().contains("70000"), "{e}");
    }
}
