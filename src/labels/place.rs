//! Placing a label map on an image's grid: each image voxel centre goes through the
//! image's affine to world (RAS mm) and through the inverse of the label map's affine to
//! a label voxel, rounded to the nearest; outside the label grid is background (0).

use super::raw::{Grid, RawLabels};
use crate::volume::{VolumeError, display_path};
use glam::DVec3;
use std::path::Path;

/// Grids whose affines differ by less than this (mm) are the same grid.
const SAME_GRID_MM: f64 = 1e-4;

/// The label map's layers on the image grid, and a warning when it covers only part
/// of the image.
#[derive(Debug, Clone)]
pub struct Placed {
    pub layers: Vec<Vec<u16>>,
    pub warning: Option<String>,
}

/// Whether two grids have the same dims and affines equal within 1e-4 mm.
pub fn same_grid(a: Grid, b: Grid) -> bool {
    let (oa, ob) = (a.orientation, b.orientation);
    a.dims == b.dims
        && (oa.offset - ob.offset).abs().max_element() <= SAME_GRID_MM
        && (0..3).all(|i| (oa.linear.col(i) - ob.linear.col(i)).abs().max_element() <= SAME_GRID_MM)
}

/// Samples `raw`'s layers at every voxel centre of `image` (nearest neighbour).
/// `image_name` is how the image is named in the error when the two do not overlap.
pub fn place(
    raw: &RawLabels,
    image: Grid,
    path: &Path,
    image_name: &str,
) -> Result<Placed, VolumeError> {
    if same_grid(raw.grid, image) {
        return Ok(Placed {
            layers: raw.layers.clone(),
            warning: None,
        });
    }
    let lab = raw.grid.orientation;
    if !lab.is_valid() {
        return Err(VolumeError::invalid(
            path,
            "the label map's affine is not invertible; it cannot be placed on the image",
        ));
    }
    let inv = lab.linear.inverse();
    // label index = m · image index + t
    let m = inv * image.orientation.linear;
    let t = inv * (image.orientation.offset - lab.offset);
    let [nx, ny, nz] = image.dims;
    let [lx, ly, lz] = raw.grid.dims;
    let limit = DVec3::new(lx as f64, ly as f64, lz as f64);
    let mut src = vec![usize::MAX; nx * ny * nz];
    let mut covered = 0usize;
    for z in 0..nz {
        for y in 0..ny {
            let row = m * DVec3::new(0.0, y as f64, z as f64) + t;
            let base = (y + ny * z) * nx;
            for x in 0..nx {
                let q = (row + m.x_axis * x as f64 + 0.5).floor();
                if q.cmpge(DVec3::ZERO).all() && q.cmplt(limit).all() {
                    let (i, j, k) = (q.x as usize, q.y as usize, q.z as usize);
                    src[base + x] = i + lx * (j + ly * k);
                    covered += 1;
                }
            }
        }
    }
    if covered == 0 {
        return Err(VolumeError::invalid(
            path,
            format!(
                "the label map does not overlap {image_name} (label box {} mm, image box {} mm)",
                world_box(raw.grid),
                world_box(image)
            ),
        ));
    }
    let total = src.len();
    let warning = (covered < total).then(|| {
        format!(
            "{} covers {:.1}% of the image's voxels ({covered} of {total}); the rest is background",
            display_path(path),
            100.0 * covered as f64 / total as f64
        )
    });
    let layers = raw
        .layers
        .iter()
        .map(|values| {
            src.iter()
                .map(|&s| if s == usize::MAX { 0 } else { values[s] })
                .collect()
        })
        .collect();
    Ok(Placed { layers, warning })
}

/// The world-space (RAS mm) bounding box of a grid's voxels, edges included:
/// "[x0, x1] × [y0, y1] × [z0, z1]".
pub fn world_box(g: Grid) -> String {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for corner in 0..8 {
        let idx = DVec3::from_array(std::array::from_fn(|a| {
            if corner >> a & 1 == 1 {
                g.dims[a] as f64 - 0.5
            } else {
                -0.5
            }
        }));
        let p = g.orientation.linear * idx + g.orientation.offset;
        lo = lo.min(p);
        hi = hi.max(p);
    }
    format!(
        "[{:.1}, {:.1}] × [{:.1}, {:.1}] × [{:.1}, {:.1}]",
        lo.x, hi.x, lo.y, hi.y, lo.z, hi.z
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::raw::FileNames;
    use crate::volume::Orientation;

    fn raw(dims: [usize; 3], orientation: Orientation) -> RawLabels {
        let n = dims.iter().product::<usize>();
        RawLabels {
            layers: vec![(0..n as u16).collect()],
            grid: Grid { dims, orientation },
            names: FileNames::default(),
        }
    }

    #[test]
    fn a_half_resolution_map_covers_two_image_voxels_per_label_voxel() {
        let image = Grid {
            dims: [4, 2, 1],
            orientation: Orientation::from_spacing([1.0, 1.0, 1.0]),
        };
        let mut o = Orientation::from_spacing([2.0, 1.0, 1.0]);
        o.offset.x = 0.5; // label voxel 0 spans image voxels 0 and 1
        let p = place(&raw([2, 2, 1], o), image, Path::new("l"), "img").expect("overlaps");
        assert_eq!(p.layers[0], vec![0, 0, 1, 1, 2, 2, 3, 3]);
        assert!(p.warning.is_none());
    }

    #[test]
    fn partial_overlap_warns_and_none_is_an_error() {
        let image = Grid {
            dims: [4, 1, 1],
            orientation: Orientation::from_spacing([1.0, 1.0, 1.0]),
        };
        let mut o = Orientation::from_spacing([1.0, 1.0, 1.0]);
        o.offset.x = 2.0;
        let p = place(&raw([4, 1, 1], o), image, Path::new("l"), "img").expect("overlaps");
        assert_eq!(p.layers[0], vec![0, 0, 0, 1]);
        assert!(p.warning.as_deref().is_some_and(|w| w.contains("50.0%")));
        o.offset.x = 500.0;
        let e = place(&raw([4, 1, 1], o), image, Path::new("l"), "img").expect_err("apart");
        assert_eq!(
            e.to_string(),
            "l: the label map does not overlap img (label box [499.5, 503.5] × [-0.5, 0.5] × [-0.5, 0.5] mm, image box [-0.5, 3.5] × [-0.5, 0.5] × [-0.5, 0.5] mm)"
        );
    }
}
