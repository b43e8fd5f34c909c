//! The clipping camera (CAO paper §3.2, §3.4 step II): an orthographic camera attached
//! to a clip mesh, looking down the mesh's local −z axis, framing the mesh with room for
//! the dilation shape around it.
//!
//! A point in shape space maps to `(px, py, depth)`: pixel coordinates of the depth
//! maps (`floor` gives the texel) and a depth in (0, 1), larger = farther. Square pixels
//! and a linear depth keep the dilation a sphere: `r_xy` pixels across, `r_z` deep.

use super::gpu_data::ShapeUniform;
use super::mesh::TriMesh;
use glam::{Mat4, Vec3, Vec4};

/// Depth written where a map has no surface (front maps use `EMPTY`, back maps `-EMPTY`):
/// far outside the (0, 1) depth range so an empty pixel is never "inside".
pub const EMPTY: f32 = 3.0;

/// An orthographic camera framing one clip mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipCamera {
    /// Shape space → wgpu clip space (x, y in [-1, 1], depth in [0, 1]).
    pub projection: Mat4,
    /// Shape space → (pixel x, pixel y, depth).
    pub to_map: Mat4,
    /// Depth-map size in pixels (square).
    pub resolution: u32,
    pub pixels_per_mm: f32,
    pub depth_per_mm: f32,
    /// The dilation (carve) or contraction (probe) radius this camera leaves room for, mm.
    pub margin_mm: f32,
    /// A sphere holding the mesh (shape space): centre and radius, mm.
    pub bound_centre: Vec3,
    pub bound_radius: f32,
}

impl ClipCamera {
    /// Frames `mesh` (in shape space) so that every point within `reach_mm` of it, and
    /// the dilation of radius `margin_mm(pixel)` that [`dilation_margin`] derives from
    /// `reach_mm`, lies inside the image and the depth range.
    pub fn frame(mesh: &TriMesh, reach_mm: f32, resolution: u32) -> ClipCamera {
        let res = resolution.max(16);
        let (lo, hi) = mesh.bounds();
        let centre = (lo + hi) * 0.5;
        let half_xy = ((hi.x - lo.x).max(hi.y - lo.y) * 0.5).max(1e-3);
        // The margin depends on the pixel size, which depends on the margin: with
        // half = (half_xy + margin)·k and pixel = 2·half/res, `dilation_margin` is
        // c + a·(half_xy + margin), so the fixed point is margin = (c + a·half_xy)/(1 − a)
        // (a < 1 for res ≥ 16), taken 0.1 % larger against rounding. (A bound from the
        // shape's size alone fell short for shapes much larger than the reach, such as a
        // plane's slab at a low resolution.)
        let k = 1.0 + 16.0 / res as f32;
        let c = dilation_margin(reach_mm, 0.0);
        let a = dilation_margin(0.0, 2.0 * k / res as f32) - dilation_margin(0.0, 0.0);
        let margin = (c + a * half_xy) / (1.0 - a) * 1.001;
        let half = (half_xy + margin) * k;
        let pixel = 2.0 * half / res as f32;
        debug_assert!(margin >= dilation_margin(reach_mm, pixel));
        let pad = margin * 1.1 + 1.0;
        let (z_near, z_far) = (hi.z + pad, lo.z - pad);
        let depth = z_near - z_far;
        // ndc.x = (x − cx) / half, ndc.y = (y − cy) / half, depth = (z_near − z) / depth.
        let projection = Mat4::from_cols(
            Vec4::new(1.0 / half, 0.0, 0.0, 0.0),
            Vec4::new(0.0, 1.0 / half, 0.0, 0.0),
            Vec4::new(0.0, 0.0, -1.0 / depth, 0.0),
            Vec4::new(-centre.x / half, -centre.y / half, z_near / depth, 1.0),
        );
        // Pixels: x = (ndc.x + 1) / 2 · res, y = (1 − ndc.y) / 2 · res (rows go down).
        let ndc_to_pixels = Mat4::from_cols(
            Vec4::new(res as f32 * 0.5, 0.0, 0.0, 0.0),
            Vec4::new(0.0, -(res as f32) * 0.5, 0.0, 0.0),
            Vec4::new(0.0, 0.0, 1.0, 0.0),
            Vec4::new(res as f32 * 0.5, res as f32 * 0.5, 0.0, 1.0),
        );
        let bound_radius = mesh
            .vertices
            .iter()
            .map(|v| v.distance(centre))
            .fold(0.0f32, f32::max);
        ClipCamera {
            projection,
            to_map: ndc_to_pixels * projection,
            resolution: res,
            pixels_per_mm: 1.0 / pixel,
            depth_per_mm: 1.0 / depth,
            margin_mm: margin,
            bound_centre: centre,
            bound_radius,
        }
    }

    /// `r_xy` (pixels) and `r_z` (depth units) of Algorithm 1 for this camera's margin.
    pub fn dilation_radii(&self) -> (f32, f32) {
        (
            self.margin_mm * self.pixels_per_mm,
            self.margin_mm * self.depth_per_mm,
        )
    }

    /// How far from [`Self::bound_centre`] a point the maps call inside or near can lie
    /// (mm): the mesh's bound, the dilation margin and three pixels for the maps'
    /// quantisation (a point is looked up in its texel, the kernel measured between
    /// texel centres).
    pub fn reach_bound(&self) -> f32 {
        self.bound_radius + self.margin_mm + 3.0 / self.pixels_per_mm
    }

    /// Where a shape-space point lands: (pixel x, pixel y, depth).
    pub fn project(&self, p: Vec3) -> Vec3 {
        self.to_map.transform_point3(p)
    }
}

/// The dilation radius that keeps CAO exact for an LAO neighbourhood of `reach_mm`, with
/// depth maps of `pixel_mm` pixels.
///
/// A clipped point q can change the ambient factor of a voxel centre x only if
/// |q − x| ≤ reach. The clip test looks q up in the texel `floor(q)`, and the dilation
/// loop measures distances between texels, so a texel-index distance can exceed the true
/// one by up to √2 pixels; with `R' > reach + √2·pixel` the spherical kernel of
/// Algorithm 1 still reaches x strictly (see docs/algorithms.md). 1 % and 0.01 mm more
/// absorb f32 rounding.
pub fn dilation_margin(reach_mm: f32, pixel_mm: f32) -> f32 {
    (reach_mm + std::f32::consts::SQRT_2 * pixel_mm) * 1.01 + 0.01
}

/// Where shape `s`'s maps can say "carved", in volume mm: the centre of the mesh's
/// bounding sphere and its radius with three map pixels for the maps' quantisation
/// ([`ClipCamera::reach_bound`] without the dilation).
pub fn carved_ball(s: &ShapeUniform, camera: &ClipCamera) -> (Vec3, f32) {
    let (_, centre) = bound_in_volume(s, camera);
    (centre, camera.bound_radius + 3.0 / camera.pixels_per_mm)
}

/// A shape's clipping camera back in volume mm: map → volume, and the centre of the
/// mesh's bounding sphere (the pose is rigid: the radius stays).
pub fn bound_in_volume(s: &ShapeUniform, camera: &ClipCamera) -> (Mat4, Vec3) {
    let to_volume = Mat4::from_cols_array_2d(&s.volume_to_map).inverse();
    let centre = to_volume.transform_point3(camera.project(camera.bound_centre));
    (to_volume, centre)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clip::mesh::TriMesh;

    /// A flat square of half side `h` (all the framing looks at is the bounds).
    fn square(h: f32) -> TriMesh {
        TriMesh {
            vertices: vec![
                Vec3::new(-h, -h, 0.0),
                Vec3::new(h, -h, 0.0),
                Vec3::new(h, h, 0.0),
                Vec3::new(-h, h, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn the_margin_covers_the_dilation_for_any_size_reach_and_resolution() {
        for h in [0.01, 1.0, 50.0, 1e3, 1e5] {
            for reach in [0.0, 1.0, 20.0, 200.0] {
                for res in [16, 128, 1024, 8192] {
                    let c = ClipCamera::frame(&square(h), reach, res);
                    let pixel = 1.0 / c.pixels_per_mm;
                    let need = dilation_margin(reach, pixel);
                    assert!(
                        c.margin_mm >= need,
                        "h {h}, reach {reach}, res {res}: margin {} < {need}",
                        c.margin_mm
                    );
                    // And the shape with its margin lies inside the image.
                    let corner = c.project(Vec3::splat(h + c.margin_mm).with_z(0.0));
                    assert!(corner.x <= res as f32 && corner.y >= 0.0, "{corner}");
                }
            }
        }
    }
}
