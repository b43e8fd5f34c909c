//! Statistics of an image's physical values under each segment.

use super::LabelMap;
use crate::volume::Volume;

/// One present segment's size and the image's physical values under it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SegmentStats {
    pub layer: u16,
    pub id: u16,
    pub name: String,
    pub voxels: u64,
    /// voxels × the image's voxel volume (spacing product, mm³) / 1000.
    pub volume_ml: f64,
    pub mean: f64,
    /// numpy's convention: the mean of the two middle values when the count is even.
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

/// Statistics of the image's physical values (stored values through its scaling: HU
/// for CT) under each present segment, in segment order. The median is numpy's
/// (`np.median`: for an even count, the mean of the two middle values). NaN and ±Inf
/// voxels count towards `voxels` but not the value statistics; a segment with no finite
/// value has NaN statistics.
pub fn statistics(image: &Volume, labels: &LabelMap) -> Vec<SegmentStats> {
    let voxel_ml = image.spacing.iter().map(|&s| s as f64).product::<f64>() / 1000.0;
    let n = image.data.len();
    let mut out = Vec::new();
    for (l, values) in labels.layers.iter().enumerate() {
        let present: Vec<_> = labels
            .segments
            .iter()
            .filter(|s| s.key.layer as usize == l && s.voxels > 0)
            .collect();
        if present.is_empty() || values.len() != n {
            continue;
        }
        // Group the image's values by label (a counting sort): label v's values are
        // grouped[start[v] .. start[v + 1]].
        let mut start = vec![0usize; (1 << 16) + 1];
        for &v in values {
            start[v as usize + 1] += 1;
        }
        for v in 0..1 << 16 {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut grouped = vec![0f64; n - start[1]];
        let first = start[1];
        for (i, &v) in values.iter().enumerate() {
            if v != 0 {
                grouped[fill[v as usize] - first] = image.scaling.apply(image.data.get_f64(i));
                fill[v as usize] += 1;
            }
        }
        for seg in present {
            let v = seg.key.value as usize;
            let group = &mut grouped[start[v] - first..start[v + 1] - first];
            let voxels = group.len() as u64;
            let (mean, median, min, max) = summary(group);
            out.push(SegmentStats {
                layer: seg.key.layer,
                id: seg.key.value,
                name: seg.name.clone(),
                voxels,
                volume_ml: voxels as f64 * voxel_ml,
                mean,
                median,
                min,
                max,
            });
        }
    }
    out
}

/// (mean, median, min, max) of the finite values; reorders `values`.
fn summary(values: &mut [f64]) -> (f64, f64, f64, f64) {
    let mut finite: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    finite.sort_unstable_by(f64::total_cmp);
    let k = finite.len();
    let median = if k % 2 == 1 {
        finite[k / 2]
    } else {
        (finite[k / 2 - 1] + finite[k / 2]) / 2.0
    };
    let mean = finite.iter().sum::<f64>() / k as f64;
    (mean, median, finite[0], finite[k - 1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{Segment, SegmentKey};
    use std::path::PathBuf;

    #[test]
    fn median_is_numpy_style_and_volume_uses_spacing() {
        let image = Volume::new(
            [6, 1, 1],
            [2.0, 5.0, 10.0],
            vec![10i16, 20, 30, 40, 7, 100].into(),
        )
        .expect("volume");
        let seg = |value, voxels| Segment {
            key: SegmentKey { layer: 0, value },
            name: format!("s{value}"),
            color: [0; 3],
            voxels,
        };
        let labels = LabelMap {
            dims: [6, 1, 1],
            layers: vec![vec![1, 1, 1, 1, 0, 2]],
            segments: vec![seg(1, 4), seg(2, 1), seg(3, 0)],
            path: PathBuf::from("l"),
        };
        let s = statistics(&image, &labels);
        assert_eq!(s.len(), 2, "absent segment 3 has no statistics");
        assert_eq!(s[0].median, 25.0);
        assert_eq!(s[0].mean, 25.0);
        assert_eq!((s[0].min, s[0].max), (10.0, 40.0));
        assert_eq!(s[0].volume_ml, 0.4);
        assert_eq!((s[1].id, s[1].median), (2, 100.0));
    }
}
