//! 3D Slicer segmentations (`.seg.nrrd`): segment names, colours, label values and
//! layers from the `SegmentN_Name`, `SegmentN_Color` (RGB 0 … 1), `SegmentN_LabelValue`
//! and `SegmentN_Layer` key/value fields, and the voxels of every layer.
//!
//! Slicer stores overlapping segments on separate layers: a 4-D file whose *fastest*
//! axis (`kinds: list domain domain domain`, direction `none`) is the layer, so layers
//! are interleaved voxel by voxel. The volume loader refuses such a list axis; here the
//! whole payload is read and split.

use super::raw::{FileNames, Grid, RawLabels, SegmentKey, to_labels};
use super::table::TableEntry;
use crate::volume::nrrd::{self, Header, Layout};
use crate::volume::{LoadOptions, VolumeError, memory_budget};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

/// Whether `path` starts with NRRD's magic.
pub fn is_nrrd(path: &Path) -> bool {
    let mut magic = [0u8; 7];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok()
        && &magic == b"NRRD000"
}

/// Reads a NRRD label map: every layer's values and the segments its header names.
pub fn read(path: &Path, warnings: &mut Vec<String>) -> Result<RawLabels, VolumeError> {
    let h = nrrd::read_header_file(path)?;
    let (layers, grid) = match layer_axis(&h) {
        Some(n) => read_layers(&h, n, path, warnings)?,
        None => {
            let loaded = crate::volume::load(path, &LoadOptions::default())?;
            warnings.extend(loaded.warnings);
            let v = &loaded.volume;
            (vec![to_labels(&v.data, v.scaling, path)?], Grid::of(v))
        }
    };
    let names = segment_fields(&h.key_values, layers.len(), warnings);
    Ok(RawLabels {
        layers,
        grid,
        names,
    })
}

/// The number of layers when the fastest axis is a non-spatial list beside three
/// spatial axes (Slicer's layered segmentation); `None` for an ordinary volume.
fn layer_axis(h: &Header) -> Option<usize> {
    let is_list = h.kinds.first().is_some_and(|k| {
        let k = k.to_ascii_lowercase();
        k == "list" || k == "vector" || k == "none"
    }) || h.directions.first().is_some_and(Option::is_none);
    (h.sizes.len() == 4 && h.sizes[0] > 1 && is_list).then_some(h.sizes[0])
}

/// Reads a layered file's payload and splits it into one value list per layer.
fn read_layers(
    h: &Header,
    n: usize,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Vec<u16>>, Grid), VolumeError> {
    let dims = [h.sizes[1], h.sizes[2], h.sizes[3]];
    let values = nrrd::read_all_values(h, path, memory_budget())?;
    let all = to_labels(&values, crate::volume::Scaling::IDENTITY, path)?;
    let layers = (0..n)
        .map(|l| all.iter().skip(l).step_by(n).copied().collect())
        .collect();
    let lay = Layout {
        dims,
        axes: [Some(1), Some(2), Some(3)],
        frames: 1,
        frame_bytes: (dims.iter().product::<usize>() * h.ty.size()) as u64,
    };
    let (_, orientation) = nrrd::geometry(h, &lay, path, warnings);
    Ok((layers, Grid { dims, orientation }))
}

/// Segments named by `SegmentN_*` fields. A segment without `LabelValue` has value 1;
/// without `Layer`, layer N in a layered file and 0 otherwise (Slicer's older files).
pub fn segment_fields(
    pairs: &[(String, String)],
    layers: usize,
    warnings: &mut Vec<String>,
) -> FileNames {
    let mut by_index: BTreeMap<usize, BTreeMap<&str, &str>> = BTreeMap::new();
    for (key, value) in pairs {
        let Some(rest) = key.strip_prefix("Segment") else {
            continue;
        };
        let digits = rest.chars().take_while(char::is_ascii_digit).count();
        let (Ok(index), Some(field)) = (
            rest[..digits].parse::<usize>(),
            rest[digits..].strip_prefix('_'),
        ) else {
            continue;
        };
        by_index.entry(index).or_default().insert(field, value);
    }
    let mut names = FileNames::default();
    for (index, fields) in by_index {
        let number = |f: &str| fields.get(f).and_then(|v| v.trim().parse::<u16>().ok());
        let value = number("LabelValue").unwrap_or(1);
        let default_layer = if layers > 1 { index as u16 } else { 0 };
        let layer = number("Layer").unwrap_or(default_layer);
        if layer as usize >= layers {
            warnings.push(format!(
                "Segment{index} is on layer {layer} but the file has {layers} layer(s); left out"
            ));
            continue;
        }
        let color = fields.get("Color").and_then(|c| {
            let v: Vec<f64> = c
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .ok()?;
            match v.as_slice() {
                [r, g, b] if [r, g, b].iter().all(|x| (0.0..=1.0).contains(*x)) => {
                    Some([*r, *g, *b].map(|x| (x * 255.0).round() as u8))
                }
                _ => None,
            }
        });
        let name = fields
            .get("Name")
            .map(|n| n.trim().to_owned())
            .filter(|n| !n.is_empty());
        names
            .entries
            .insert(SegmentKey { layer, value }, TableEntry { name, color });
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_fields_give_keys_names_and_colours() {
        let pairs: Vec<(String, String)> = [
            ("Segment0_Name", "ribs"),
            ("Segment0_Color", "0.992157 0.909804 0.619608"),
            ("Segment0_LabelValue", "1"),
            ("Segment0_Layer", "0"),
            ("Segment7_Name", "overlapping sphere"),
            ("Segment7_LabelValue", "1"),
            ("Segment7_Layer", "1"),
            ("Segment9_Name", "on a missing layer"),
            ("Segment9_Layer", "4"),
            ("Segmentation_MasterRepresentation", "Binary labelmap"),
        ]
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        let mut warnings = Vec::new();
        let names = segment_fields(&pairs, 2, &mut warnings);
        assert_eq!(names.entries.len(), 2);
        let ribs = &names.entries[&SegmentKey { layer: 0, value: 1 }];
        assert_eq!(ribs.name.as_deref(), Some("ribs"));
        assert_eq!(ribs.color, Some([253, 232, 158]));
        let sphere = &names.entries[&SegmentKey { layer: 1, value: 1 }];
        assert_eq!(sphere.name.as_deref(), Some("overlapping sphere"));
        assert_eq!(sphere.color, None);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
    }
}
