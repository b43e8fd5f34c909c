//! Picking: the first visible surface under a point of the 3-D view, where the opacity
//! accumulated front to back along the pixel's ray first passes a threshold — what the
//! viewer's shift-click (or double-click) moves the crosshair to.
//!
//! It marches the ray the ray caster casts through the pixel (the same camera, box and
//! clip shapes) over the full-resolution volume on the CPU, with the transfer function's
//! opacity, the segments' opacity weights and the shapes' cuts.

use crate::clip::{ClipMode, ClipShape};
use crate::render::Camera;
use crate::texels::segments::ClassLook;
use crate::tf::TransferFunction;
use crate::tf::correct_opacity;
use crate::volume::Volume;
use glam::{DVec3, Vec3, Vec4};

/// Accumulated opacity at which a ray has met "the surface".
pub const SURFACE_OPACITY: f32 = 0.5;

/// What a pick sees: the volume, its transfer function, the clip shapes and the
/// segmentation's classes (each voxel's class and the classes' looks).
#[derive(Debug, Clone, Copy)]
pub struct PickScene<'a> {
    pub volume: &'a Volume,
    pub tf: &'a TransferFunction,
    pub shapes: &'a [ClipShape],
    pub segments: Option<(&'a [u16], &'a [ClassLook])>,
}

impl PickScene<'_> {
    fn half(&self) -> Vec3 {
        Vec3::from_array(std::array::from_fn(|i| {
            self.volume.dims[i] as f32 * self.volume.spacing[i] / 2.0
        }))
    }

    /// The volume's value at `p` (volume-centred mm), trilinear.
    fn value(&self, p: Vec3) -> Option<f64> {
        let v = self.volume;
        let t = DVec3::from_array(std::array::from_fn(|i| {
            (f64::from(p[i]) + f64::from(self.half()[i])) / f64::from(v.spacing[i]) - 0.5
        }));
        super::trilinear(v, t)
    }

    /// The class look of the voxel nearest to `p`.
    fn look(&self, p: Vec3) -> Option<&ClassLook> {
        let (classes, looks) = self.segments?;
        let v = self.volume;
        let ijk: [usize; 3] = std::array::from_fn(|i| {
            let t = (p[i] + self.half()[i]) / v.spacing[i];
            (t.max(0.0) as usize).min(v.dims[i] - 1)
        });
        let class = classes.get(ijk[0] + v.dims[0] * (ijk[1] + v.dims[1] * ijk[2]))?;
        looks.get(usize::from(*class))
    }

    /// Whether the clip shapes leave the sample at `p` (carving shapes cut only the
    /// classes they cut).
    fn unclipped(&self, p: Vec3, look: Option<&ClassLook>) -> bool {
        self.shapes.iter().enumerate().all(|(s, shape)| {
            let cuts = look.is_none_or(|l| l.carved_by & (1 << s) != 0);
            match (shape.contains(p), shape.mode) {
                (None, _) => true,
                (Some(inside), ClipMode::Carve) => !(inside && cuts),
                (Some(inside), ClipMode::Probe) => inside || !cuts,
            }
        })
    }
}

/// The first point along the ray through `ndc` (normalised device coordinates, x right
/// and y up in −1..1) of a view with `camera` (framing a bounding sphere of `radius`
/// mm, as the ray caster's) and `aspect` (width / height) at which the
/// accumulated opacity reaches `threshold`, in volume-centred mm; `None` if the ray
/// leaves the volume first.
pub fn first_surface(
    scene: &PickScene,
    camera: &Camera,
    radius: f32,
    aspect: f32,
    ndc: [f32; 2],
    threshold: f32,
) -> Option<Vec3> {
    let half = scene.half();
    let inv = camera.view_proj(radius, aspect).inverse();
    let near = inv * Vec4::new(ndc[0], ndc[1], 0.0, 1.0);
    let far = inv * Vec4::new(ndc[0], ndc[1], 1.0, 1.0);
    let origin = near.truncate() / near.w;
    let dir = (far.truncate() / far.w - origin).normalize();
    // The ray's stretch inside the box.
    let inv_dir = dir.recip();
    let t0 = (-half - origin) * inv_dir;
    let t1 = (half - origin) * inv_dir;
    let enter = t0.min(t1).max_element().max(0.0);
    let exit = t0.max(t1).min_element();
    let finest = scene
        .volume
        .spacing
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    let step = finest / 2.0;
    let mut acc = 0.0f32;
    let mut t = enter;
    while t < exit {
        let p = origin + dir * t;
        let look = scene.look(p);
        if scene.unclipped(p, look)
            && let Some(value) = scene.value(p)
        {
            let weight = look.map_or(1.0, |l| l.opacity);
            let alpha = correct_opacity(scene.tf.eval(value)[3] * weight, step / finest);
            acc += (1.0 - acc) * alpha;
            if acc >= threshold {
                return Some(p);
            }
        }
        t += step;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clip::Shape;
    use crate::tf::{ColorStop, OpacityPoint};
    use crate::volume::voxels::VoxelData;

    /// A 40³ volume of 1 mm voxels holding a ball of radius 12 mm (value 100) in air (0).
    fn ball() -> Volume {
        let n = 40usize;
        let data: Vec<f32> = (0..n * n * n)
            .map(|i| {
                let [x, y, z] = crate::volume::voxel_of(i, [n; 3]);
                let d = Vec3::new(x as f32, y as f32, z as f32) + 0.5 - n as f32 / 2.0;
                if d.length() <= 12.0 { 100.0 } else { 0.0 }
            })
            .collect();
        Volume::new([n; 3], [1.0; 3], VoxelData::from(data)).expect("volume")
    }

    fn step_tf() -> TransferFunction {
        TransferFunction {
            name: "step".into(),
            opacity: OpacityPoint::list(&[(40.0, 0.0), (60.0, 1.0)]),
            color: ColorStop::list(&[(0.0, [1.0; 3])]),
        }
    }

    #[test]
    fn the_centre_pixel_hits_the_front_of_the_ball_and_a_carve_moves_it() {
        let volume = ball();
        let tf = step_tf();
        let scene = PickScene {
            volume: &volume,
            tf: &tf,
            shapes: &[],
            segments: None,
        };
        // The default camera looks from anterior (+y): the front of the ball is y = 12.
        let cam = Camera::default();
        let radius = 20.0 * 3f32.sqrt();
        let hit =
            first_surface(&scene, &cam, radius, 1.0, [0.0, 0.0], SURFACE_OPACITY).expect("hit");
        assert!((hit - Vec3::new(0.0, 12.0, 0.0)).length() < 1.0, "{hit}");
        // A sphere carving the front half moves the surface to its far side.
        let carve = [ClipShape::new(
            Shape::Sphere,
            Vec3::new(0.0, 12.0, 0.0),
            6.0,
        )];
        let scene = PickScene {
            shapes: &carve,
            ..scene
        };
        let hit =
            first_surface(&scene, &cam, radius, 1.0, [0.0, 0.0], SURFACE_OPACITY).expect("hit");
        assert!((hit - Vec3::new(0.0, 6.0, 0.0)).length() < 1.0, "{hit}");
        // Past the ball's edge the ray meets nothing.
        assert!(first_surface(&scene, &cam, radius, 1.0, [0.9, 0.9], SURFACE_OPACITY).is_none());
    }
}
