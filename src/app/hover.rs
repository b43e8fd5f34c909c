//! The hover line: which segments the pointer is over in the 3-D view. The pixel's ray
//! (as the ray caster casts it, [`crate::render::cpu::ray`]) is walked on the CPU with
//! the stages' own reader ([`VolumeSampler`] with the segmentation) until it is nearly
//! opaque, and the class that took the largest share of it is named by the label map.
//!
//! Clipping is tested on the shapes themselves (inside a sphere, box, cylinder, torus,
//! beyond a plane), not on the clip maps the GPU reads: the two agree up to the maps'
//! resolution; a mesh shape is taken to cut nothing here.

use crate::clip::{ClipMode, ClipShape, Shape};
use crate::render::{Frame, RaycastParams};
use crate::sample::{SegmentSampler, VolumeSampler};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// What the hover line was computed for, and the CPU copies it reads (kept while they
/// stay valid: the texels per document, the table per transfer function, the
/// segmentation per build).
#[derive(Default)]
pub(super) struct Hover {
    pub(super) key: Option<HoverKey>,
    pub(super) text: Option<String>,
    pub(super) norm: Option<(u64, Vec<f32>)>,
    pub(super) lut: Option<((TransferFunction, f32), Lut)>,
    pub(super) sampler: Option<(u64, SegmentSampler)>,
}

#[derive(Debug, Clone, PartialEq)]
pub(super) struct HoverKey {
    pub(super) px: [u32; 2],
    pub(super) frame: Frame,
    pub(super) clip: Vec<ClipShape>,
    pub(super) tf: TransferFunction,
    pub(super) segments: u64,
    pub(super) generation: u64,
}

/// The class that shows most in pixel `px`: front to back along its ray, as the ray
/// caster composites it (unclipped samples, opacity with the segments' weights), the
/// class of the voxel each sample lies in takes its share `(1 − α_acc)·α` (unless that
/// class is hidden: then the share is its neighbours', left unnamed); the ray stops
/// once nearly opaque. (The very first visible sample is often a voxel outside every
/// segment at an organ's rim, where the segmentation is coarser than the image.)
pub(super) fn class_under(
    p: &RaycastParams,
    volume: &VolumeSampler,
    segments: &SegmentSampler,
    shapes: &[ClipShape],
    px: [u32; 2],
) -> Option<usize> {
    let (origin, dir, t_enter, t_exit) = crate::render::cpu::ray(p, px[0], px[1]);
    let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
    let dt = p.step[0].max(1e-3);
    let mut shares: Vec<(usize, f32)> = Vec::new();
    let mut acc = 0.0f32;
    let mut t = t_enter;
    while t < t_exit && acc < 0.95 {
        let pos = origin + dir * t;
        t += dt;
        let uvw = pos / (2.0 * half) + Vec3::splat(0.5);
        if !visible(shapes, pos, segments.carved_by_at(uvw)) {
            continue;
        }
        let a = volume.opacity_at(uvw).clamp(0.0, 1.0);
        if a <= 0.0 {
            continue;
        }
        let share = (1.0 - acc) * a;
        acc += share;
        // A hidden class's voxel shows only its neighbours' weight (the look is
        // filtered): the share is theirs, not its.
        let dims = segments.dims;
        let k: [usize; 3] =
            std::array::from_fn(|a| ((uvw[a].max(0.0) * dims[a] as f32) as usize).min(dims[a] - 1));
        if segments.weight_of_voxel(k) <= 0.0 {
            continue;
        }
        let class = segments.class_at(uvw);
        match shares.iter_mut().find(|(c, _)| *c == class) {
            Some((_, s)) => *s += share,
            None => shares.push((class, share)),
        }
    }
    shares
        .into_iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(class, _)| class)
}

/// Whether `pos` (mm from the volume's centre) in a voxel the shapes of `carve` (bit s)
/// cut is visible: `clip_visible_for` of `clip_common.wgsl` on the shapes themselves.
fn visible(shapes: &[ClipShape], pos: Vec3, carve: u32) -> bool {
    let (mut carved, mut probes, mut probed) = (false, false, false);
    for (s, shape) in shapes.iter().enumerate().take(32) {
        if (carve >> s) & 1 == 0 {
            continue;
        }
        let inside = inside(shape, pos);
        match shape.mode {
            ClipMode::Carve => carved |= inside,
            ClipMode::Probe => {
                probes = true;
                probed |= inside;
            }
        }
    }
    !carved && (!probes || probed)
}

/// Whether `pos` is inside `shape` (a plane's inside is its local +z side).
fn inside(shape: &ClipShape, pos: Vec3) -> bool {
    let local = shape.shape_to_volume().inverse().transform_point3(pos);
    let q = local / Vec3::from(shape.scale).max(Vec3::splat(1e-6));
    match &shape.shape {
        Shape::Plane => local.z > 0.0,
        Shape::Sphere => q.length_squared() < 1.0,
        Shape::Box => q.abs().max_element() < 1.0,
        Shape::Cylinder => q.x * q.x + q.y * q.y < 1.0 && q.z.abs() < 1.0,
        Shape::Torus { tube } => {
            let r = (q.x * q.x + q.z * q.z).sqrt() - 1.0;
            r * r + q.y * q.y < tube * tube
        }
        Shape::Mesh { .. } => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_hold_what_their_outlines_enclose() {
        let sphere = ClipShape::new(Shape::Sphere, Vec3::new(10.0, 0.0, 0.0), 5.0);
        assert!(inside(&sphere, Vec3::new(14.0, 0.0, 0.0)));
        assert!(!inside(&sphere, Vec3::new(16.0, 0.0, 0.0)));
        let plane = super::super::clip_panel::new_shape(Shape::Plane, 100.0);
        // A new plane removes +x (a sagittal cut).
        assert!(inside(&plane, Vec3::new(1.0, 0.0, 0.0)));
        assert!(!inside(&plane, Vec3::new(-1.0, 0.0, 0.0)));
        let torus = ClipShape::new(Shape::Torus { tube: 0.3 }, Vec3::ZERO, 10.0);
        assert!(inside(&torus, Vec3::new(10.0, 0.0, 0.0)));
        assert!(!inside(&torus, Vec3::ZERO));
        // Carved only where the voxel's class is cut by the shape.
        assert!(!visible(
            std::slice::from_ref(&sphere),
            Vec3::new(10.0, 0.0, 0.0),
            1
        ));
        assert!(visible(
            std::slice::from_ref(&sphere),
            Vec3::new(10.0, 0.0, 0.0),
            0
        ));
    }
}
