//! Segmentation label maps beside an image: their voxels placed on the image's grid,
//! their names and colours, and statistics of the image under each segment.
//!
//! A label map is any volume [`crate::volume::load`] reads with integer values 0 … 65535
//! (0 is background), or a 3D Slicer `.seg.nrrd`, whose segments may lie on several
//! layers. Names and colours come from the file itself ([`seg_nrrd`]'s `SegmentN_*`
//! fields, [`nifti_ext`]'s CaretExtension label table) or from a table file
//! ([`table`]), which wins; ids named nowhere get a [`palette`] colour. [`place`] samples
//! the map at each image voxel centre through the two affines (nearest neighbour), so
//! the map may have another grid, axis order or extent than the image.

pub mod nifti_ext;
pub mod palette;
pub mod place;
pub mod raw;
pub mod seg_nrrd;
pub mod stats;
pub mod style;
pub mod table;

use crate::volume::{LoadOptions, Volume, VolumeError, display_path};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use palette::palette_color;
pub use raw::{FileNames, Grid, RawLabels, SegmentKey, to_labels};
pub use stats::{SegmentStats, statistics};
pub use table::{LabelTable, TableEntry, read_table};

/// A segment's name, colour and size on the image's grid.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Segment {
    pub key: SegmentKey,
    /// From the table or the file; "label N" if neither names it.
    pub name: String,
    /// From the table or the file; else [`palette_color`].
    pub color: [u8; 3],
    /// How many image voxels it covers (0 = named but absent).
    pub voxels: u64,
}

/// A label map resampled onto an image's voxel grid.
#[derive(Debug, Clone)]
pub struct LabelMap {
    /// The image's dims.
    pub dims: [usize; 3],
    /// Per layer, the label value of each image voxel (x fastest); 0 = background.
    pub layers: Vec<Vec<u16>>,
    /// Every segment named or present, sorted by key; never value 0.
    pub segments: Vec<Segment>,
    pub path: PathBuf,
}

/// A label map and what the user should know about how it was read and placed.
#[derive(Debug, Clone)]
pub struct LoadedLabels {
    pub labels: LabelMap,
    pub warnings: Vec<String>,
}

/// Loads `path` (a label volume in any format volao reads, or a Slicer `.seg.nrrd`) and
/// places it on `image`'s grid by the two affines (nearest neighbour). Names and
/// colours from `table` win over the file's own.
pub fn load(
    path: &Path,
    table: Option<&Path>,
    image: &Volume,
) -> Result<LoadedLabels, VolumeError> {
    load_named(path, table, image, "the image")
}

/// [`load`], naming the image `image_name` in the error when the two do not overlap.
pub fn load_named(
    path: &Path,
    table: Option<&Path>,
    image: &Volume,
    image_name: &str,
) -> Result<LoadedLabels, VolumeError> {
    let mut warnings = Vec::new();
    let raw = read_raw(path, &mut warnings)?;
    let table = table.map(read_table).transpose()?;
    let placed = place::place(&raw, Grid::of(image), path, image_name)?;
    if let Some(w) = placed.warning {
        warnings.push(w);
    }
    let segments = segments(&placed.layers, &raw.names, table.as_ref());
    Ok(LoadedLabels {
        labels: LabelMap {
            dims: image.dims,
            layers: placed.layers,
            segments,
            path: path.to_owned(),
        },
        warnings,
    })
}

/// Reads a label file's voxels and own names on its own grid.
pub fn read_raw(path: &Path, warnings: &mut Vec<String>) -> Result<RawLabels, VolumeError> {
    if seg_nrrd::is_nrrd(path) {
        return seg_nrrd::read(path, warnings);
    }
    let loaded = crate::volume::load(path, &LoadOptions::default())?;
    warnings.extend(loaded.warnings);
    let names = nifti_ext::read_names(path, warnings);
    let v = &loaded.volume;
    let values = to_labels(&v.data, v.scaling, path)?;
    Ok(RawLabels {
        layers: vec![values],
        grid: Grid::of(v),
        names,
    })
}

/// Segments named (by the table or the file) or present, sorted by key. The table's
/// entries name a value on every layer; those absent from the map are listed on layer 0.
fn segments(layers: &[Vec<u16>], file: &FileNames, table: Option<&LabelTable>) -> Vec<Segment> {
    let mut counts: BTreeMap<SegmentKey, u64> = BTreeMap::new();
    for (l, values) in layers.iter().enumerate() {
        let mut hist = vec![0u64; 1 << 16];
        for &v in values {
            hist[v as usize] += 1;
        }
        for (value, &n) in hist.iter().enumerate().skip(1) {
            if n > 0 {
                let key = SegmentKey {
                    layer: l as u16,
                    value: value as u16,
                };
                counts.insert(key, n);
            }
        }
    }
    let mut keys: Vec<SegmentKey> = counts.keys().copied().collect();
    keys.extend(
        file.entries
            .iter()
            .filter(|(_, e)| e.name.is_some())
            .map(|(k, _)| *k),
    );
    if let Some(t) = table {
        for (&value, e) in &t.entries {
            let on_some_layer = keys.iter().any(|k| k.value == value);
            if e.name.is_some() && !on_some_layer {
                keys.push(SegmentKey { layer: 0, value });
            }
        }
    }
    keys.retain(|k| k.value != 0);
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .map(|key| {
            let own = file.entries.get(&key);
            let from_table = table.and_then(|t| t.entries.get(&key.value));
            let name = from_table
                .and_then(|e| e.name.clone())
                .or_else(|| own.and_then(|e| e.name.clone()))
                .unwrap_or_else(|| format!("label {}", key.value));
            let color = from_table
                .and_then(|e| e.color)
                .or_else(|| own.and_then(|e| e.color))
                .unwrap_or_else(|| palette_color(key.value));
            Segment {
                key,
                name,
                color,
                voxels: counts.get(&key).copied().unwrap_or(0),
            }
        })
        .collect()
}

impl LabelMap {
    /// The segment index (into `segments`) of `key`, if any.
    pub fn index_of(&self, key: SegmentKey) -> Option<usize> {
        self.segments.binary_search_by(|s| s.key.cmp(&key)).ok()
    }

    /// Segments whose name matches `pattern` (case-insensitive; `*` matches any run of
    /// characters) or, when `pattern` is a number, whose value equals it.
    pub fn find(&self, pattern: &str) -> Vec<SegmentKey> {
        let number = pattern.trim().parse::<u16>().ok();
        let pattern = pattern.to_lowercase();
        self.segments
            .iter()
            .filter(|s| number == Some(s.key.value) || glob_match(&pattern, &s.name.to_lowercase()))
            .map(|s| s.key)
            .collect()
    }

    /// The file this map was read from, fit for a message.
    pub fn display_path(&self) -> String {
        display_path(&self.path)
    }
}

/// Whether `text` matches `pattern`, where `*` stands for any run of characters.
fn glob_match(pattern: &str, text: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == text;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !text.starts_with(first) || text.len() < first.len() + last.len() || !text.ends_with(last) {
        return false;
    }
    let mut rest = &text[first.len()..text.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(i) => rest = &rest[i + part.len()..],
            None => return false,
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glob_matches_stars_anywhere() {
        assert!(glob_match("liver", "liver"));
        assert!(glob_match("lung*", "lung_upper_lobe_left"));
        assert!(glob_match("*left", "lung_upper_lobe_left"));
        assert!(glob_match("*lobe*", "lung_upper_lobe_left"));
        assert!(glob_match("l*g*t", "lung_upper_lobe_left"));
        assert!(!glob_match("lung*right", "lung_upper_lobe_left"));
        assert!(!glob_match("a*a", "a"));
        assert!(glob_match("*", ""));
    }

    #[test]
    fn find_by_name_or_value() {
        let seg = |value, name: &str| Segment {
            key: SegmentKey { layer: 0, value },
            name: name.into(),
            color: [1, 2, 3],
            voxels: 1,
        };
        let map = LabelMap {
            dims: [1, 1, 1],
            layers: vec![vec![0]],
            segments: vec![seg(1, "Spleen"), seg(5, "liver"), seg(10, "lung_left")],
            path: PathBuf::from("x"),
        };
        let v = |keys: Vec<SegmentKey>| keys.iter().map(|k| k.value).collect::<Vec<_>>();
        assert_eq!(v(map.find("SPLEEN")), vec![1]);
        assert_eq!(v(map.find("l*")), vec![5, 10]);
        assert_eq!(v(map.find("10")), vec![10]);
        assert_eq!(map.index_of(SegmentKey { layer: 0, value: 5 }), Some(1));
        assert_eq!(map.index_of(SegmentKey { layer: 1, value: 5 }), None);
    }
}
