//! Voxel-to-world orientation, axis codes (`RAS`, `LAS`, `LPI`, …) and reorientation to RAS.
//!
//! World space is RAS+ in millimetres, as in NIfTI: +x = Right, +y = Anterior,
//! +z = Superior. An axis code names, for each voxel axis, the world direction in which
//! the index grows: `LAS` means x grows towards the patient's Left.

use super::{Volume, VoxelData, with_voxels};
use glam::{DMat3, DVec3};

/// Where an orientation came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AffineSource {
    /// NIfTI sform (`sform_code > 0`).
    Sform,
    /// NIfTI qform quaternion (`qform_code > 0`).
    Qform,
    /// No orientation in the file: voxel axes are taken as RAS, scaled by the spacing.
    Assumed,
    /// The format's own geometry fields: NRRD `space directions`/`space origin`, DICOM
    /// ImagePositionPatient/ImageOrientationPatient.
    Header,
}

/// Voxel index → world (RAS+, mm): `world = linear · index + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation {
    /// Columns are the world-space steps of one voxel along x, y, z.
    pub linear: DMat3,
    /// World position of the centre of voxel (0, 0, 0).
    pub offset: DVec3,
    pub source: AffineSource,
}

impl Orientation {
    /// Axis-aligned RAS with the given spacing and the origin at voxel 0.
    pub fn from_spacing(spacing: [f32; 3]) -> Self {
        Self {
            linear: DMat3::from_diagonal(DVec3::new(
                spacing[0] as f64,
                spacing[1] as f64,
                spacing[2] as f64,
            )),
            offset: DVec3::ZERO,
            source: AffineSource::Assumed,
        }
    }

    /// For each voxel axis, the world axis (0 = R/L, 1 = A/P, 2 = S/I) it runs closest
    /// to, and whether it runs in the positive (R, A, S) direction.
    ///
    /// Axes are assigned greedily by largest absolute cosine, so an oblique affine still
    /// maps to a permutation (as nibabel's `aff2axcodes` does for near-axial data).
    pub fn axis_map(&self) -> [(usize, bool); 3] {
        let mut used = [false; 3];
        let mut map = [(0usize, true); 3];
        // Visit voxel axes in order of how decisively they point along one world axis.
        let cols = [self.linear.x_axis, self.linear.y_axis, self.linear.z_axis];
        let mut order = [0usize, 1, 2];
        let dominance = |c: DVec3| {
            let a = c.abs();
            let n = a.length();
            if n > 0.0 { a.max_element() / n } else { 0.0 }
        };
        order.sort_by(|&a, &b| dominance(cols[b]).total_cmp(&dominance(cols[a])));
        for &j in &order {
            let c = cols[j];
            let mut best = None;
            for i in 0..3 {
                if used[i] {
                    continue;
                }
                if best.is_none_or(|b: usize| c[i].abs() > c[b].abs()) {
                    best = Some(i);
                }
            }
            let i = best.unwrap_or(j);
            used[i] = true;
            map[j] = (i, c[i] >= 0.0);
        }
        map
    }

    /// Axis codes such as `RAS`, `LAS`, `LPI`.
    pub fn axis_codes(&self) -> String {
        const POS: [char; 3] = ['R', 'A', 'S'];
        const NEG: [char; 3] = ['L', 'P', 'I'];
        self.axis_map()
            .iter()
            .map(|&(i, pos)| if pos { POS[i] } else { NEG[i] })
            .collect()
    }

    /// The 3×4 affine as rows, for display and for writing NIfTI `srow_*`.
    pub fn rows(&self) -> [[f64; 4]; 3] {
        let m = self.linear;
        std::array::from_fn(|r| [m.x_axis[r], m.y_axis[r], m.z_axis[r], self.offset[r]])
    }

    /// Builds an orientation from 3×4 affine rows (NIfTI `srow_x/y/z`).
    pub fn from_rows(rows: [[f64; 4]; 3], source: AffineSource) -> Self {
        Self {
            linear: DMat3::from_cols(
                DVec3::new(rows[0][0], rows[1][0], rows[2][0]),
                DVec3::new(rows[0][1], rows[1][1], rows[2][1]),
                DVec3::new(rows[0][2], rows[1][2], rows[2][2]),
            ),
            offset: DVec3::new(rows[0][3], rows[1][3], rows[2][3]),
            source,
        }
    }

    /// Whether the linear part is usable (finite and invertible).
    pub fn is_valid(&self) -> bool {
        let d = self.linear.determinant();
        d.is_finite() && d != 0.0 && self.offset.is_finite()
    }
}

impl Volume {
    /// The same volume with its voxel axes permuted and flipped so they run R, A, S.
    ///
    /// Only permutations and flips are applied: voxels are moved, never resampled, so
    /// values are untouched. Any remaining obliquity stays in the orientation matrix.
    pub fn to_ras(&self) -> Volume {
        let map = self.orientation.axis_map();
        if map == [(0, true), (1, true), (2, true)] {
            return self.clone();
        }
        // new axis i comes from old axis src[i], flipped if flip[i].
        let mut src = [0usize; 3];
        let mut flip = [false; 3];
        for (j, &(i, pos)) in map.iter().enumerate() {
            src[i] = j;
            flip[i] = !pos;
        }
        let old = self.dims;
        let dims: [usize; 3] = std::array::from_fn(|i| old[src[i]]);
        let spacing: [f32; 3] = std::array::from_fn(|i| self.spacing[src[i]]);

        // Old-index stride of one step along each new axis, and the old index of new (0,0,0).
        let old_stride = [1, old[0], old[0] * old[1]];
        let mut start = 0isize;
        let mut step = [0isize; 3];
        for i in 0..3 {
            let s = old_stride[src[i]] as isize;
            if flip[i] {
                start += (old[src[i]] as isize - 1) * s;
                step[i] = -s;
            } else {
                step[i] = s;
            }
        }
        let gather = |i: usize| -> usize {
            let [x, y, z] = super::voxel_of(i, dims);
            (start + x as isize * step[0] + y as isize * step[1] + z as isize * step[2]) as usize
        };
        let data = with_voxels!(&self.data, v => {
            let out: Vec<_> = (0..v.len()).map(|i| v[gather(i)]).collect();
            VoxelData::from(out)
        });

        // world = L · old + o, with old = start_idx + P · new  ⇒  L' = L·P, o' = L·start_idx + o.
        let l = self.orientation.linear;
        let cols = [l.x_axis, l.y_axis, l.z_axis];
        let mut offset = self.orientation.offset;
        let mut new_cols = [DVec3::ZERO; 3];
        for i in 0..3 {
            let c = cols[src[i]];
            if flip[i] {
                offset += c * (old[src[i]] as f64 - 1.0);
                new_cols[i] = -c;
            } else {
                new_cols[i] = c;
            }
        }
        Volume {
            dims,
            spacing,
            data,
            scaling: self.scaling,
            orientation: Orientation {
                linear: DMat3::from_cols(new_cols[0], new_cols[1], new_cols[2]),
                offset,
                source: self.orientation.source,
            },
            descriptions: self.descriptions.clone(),
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(dims: [usize; 3]) -> Volume {
        let n = dims[0] * dims[1] * dims[2];
        let data: Vec<u16> = (0..n as u16).collect();
        Volume::new(dims, [1.0, 2.0, 3.0], data.into()).expect("valid volume")
    }

    #[test]
    fn axis_codes_of_common_affines() {
        let mut o = Orientation::from_spacing([2.0, 2.0, 2.0]);
        assert_eq!(o.axis_codes(), "RAS");
        o.linear.x_axis = DVec3::new(-2.0, 0.0, 0.0);
        assert_eq!(o.axis_codes(), "LAS");
        o.linear.y_axis = DVec3::new(0.0, -1.0, 0.0);
        o.linear.z_axis = DVec3::new(0.0, 0.0, -1.0);
        assert_eq!(o.axis_codes(), "LPI");
        // Sagittal slices: x runs A→P, y runs S→I, z runs L→R.
        let sag = Orientation::from_rows(
            [
                [0.0, 0.0, 1.0, 0.0],
                [-1.0, 0.0, 0.0, 0.0],
                [0.0, -1.0, 0.0, 0.0],
            ],
            AffineSource::Sform,
        );
        assert_eq!(sag.axis_codes(), "PIR");
    }

    #[test]
    fn to_ras_keeps_world_positions() {
        let mut v = ramp([4, 3, 2]);
        v.orientation = Orientation::from_rows(
            [
                [0.0, 0.0, 3.0, 10.0],
                [-1.0, 0.0, 0.0, 20.0],
                [0.0, -2.0, 0.0, 30.0],
            ],
            AffineSource::Sform,
        );
        v.spacing = [1.0, 2.0, 3.0];
        let r = v.to_ras();
        assert_eq!(r.orientation.axis_codes(), "RAS");
        assert_eq!(r.dims, [2, 4, 3]);
        assert_eq!(r.spacing, [3.0, 1.0, 2.0]);
        // Every voxel keeps its value and its world position.
        let world = |o: &Orientation, idx: [usize; 3]| {
            o.linear * DVec3::new(idx[0] as f64, idx[1] as f64, idx[2] as f64) + o.offset
        };
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..4 {
                    let p = world(&v.orientation, [x, y, z]);
                    let q = r.orientation.linear.inverse() * (p - r.orientation.offset);
                    let idx = q.round();
                    assert!((q - idx).abs().max_element() < 1e-9);
                    let (a, b, c) = (idx.x as usize, idx.y as usize, idx.z as usize);
                    assert_eq!(v.value(x, y, z), r.value(a, b, c));
                }
            }
        }
    }

    #[test]
    fn to_ras_on_ras_is_identity() {
        let v = ramp([3, 2, 2]);
        let r = v.to_ras();
        assert_eq!(r.dims, v.dims);
        assert!(r.data.bits_eq(&v.data));
    }
}
