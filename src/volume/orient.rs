//! Voxel-to-world orientation and axis codes (`RAS`, `LAS`, `LPI`, …); [`super::Volume::to_ras`]
//! reorients a volume by its axis map.
//!
//! World space is RAS+ in millimetres, as in NIfTI: +x = Right, +y = Anterior,
//! +z = Superior. An axis code names, for each voxel axis, the world direction in which
//! the index grows: `LAS` means x grows towards the patient's Left.

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
