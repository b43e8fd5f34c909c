//! Reusing an image's pixels while a clip shape moves (issue #15: a frame's work follows
//! what a change can reach, in the image too).
//!
//! Between two images of the same view (camera, size, render settings, volume, transfer
//! function and AO settings) whose clip shapes differ, a pixel can differ only if its ray
//! passes near a shape that moved: a carving shape clips only points within
//! [`ShapeReach::clip`] of its centre, and CAO's `V_AO` differs from `V_PAO` (the AO of
//! the uncut volume) only at voxels within the LAO reach of what it clips,
//! [`ShapeReach::ao`]. A frame given the balls where its inputs changed
//! ([`ImageInputs::changed`]) re-casts only the pixels whose rays meet one
//! (`meets_change` in `raycast.wgsl`, twin [`meets_change`]); every other pixel is the
//! previous image's, bit for bit. Probing shapes (they clip everything outside them),
//! shadows and live positional AO (their light and occlusion follow the cut everywhere
//! along the light and the AO's rays), surfaces and `--no-skipping` re-cast every pixel.

use crate::clip::ClipShape;
use crate::clip::camera::ClipCamera;
use crate::clip::gpu::ClipMaps;
use crate::render::{Frame, RaycastParams};
use crate::sample::AO_READ_REACH;
use crate::texels::VolumeTexels;
use glam::{Vec3, Vec4};

pub use super::{Ball, MAX_BALLS, set_balls};

impl Ball {
    fn contains(&self, other: &Ball) -> bool {
        self.centre.distance(other.centre) + other.radius <= self.radius
    }

    /// The smallest ball around the bounding box of `balls` (conservative, not minimal).
    fn enclosing(balls: &[Ball]) -> Ball {
        let lo = balls
            .iter()
            .fold(Vec3::INFINITY, |m, b| m.min(b.centre - b.radius));
        let hi = balls
            .iter()
            .fold(Vec3::NEG_INFINITY, |m, b| m.max(b.centre + b.radius));
        Ball {
            centre: (lo + hi) * 0.5,
            radius: (hi - lo).length() * 0.5,
        }
    }
}

/// One carving shape of an image: its pose and maps, and the balls its cut can reach.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeReach {
    pub shape: ClipShape,
    /// The shape's clipping camera (its maps' framing, resolution and reach).
    pub camera: ClipCamera,
    /// Where its clip test can say "carved": the mesh's bounding sphere, three map pixels
    /// for the maps' quantisation ([`ClipCamera::reach_bound`] without the dilation) and
    /// a voxel diagonal of margin.
    pub clip: Ball,
    /// Where a sample can read a `V_AO` that its cut changed: [`Self::clip`] widened by a
    /// voxel diagonal (a voxel's clipped opacity depends on clip samples in its cell),
    /// the LAO reach (`reach_mm`: every texel a voxel's rays read), the AO read offset
    /// ([`AO_READ_REACH`] voxels) and a diagonal for the read's trilinear cell.
    pub ao: Ball,
}

/// What an image's pixels depend on beyond its view, where a moved shape can change
/// them. `None` from [`Self::of`] where they can change anywhere.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ImageInputs {
    /// Every clip shape of the image, in order.
    pub shapes: Vec<ShapeReach>,
    /// The image read CAO's `V_AO` exact for `shapes` (else an AO that no shape changes:
    /// `V_PAO`, precomputed LAO, none).
    pub cut_ao: bool,
}

impl ImageInputs {
    /// The inputs of an image clipped by `maps` (none: no shapes) of a volume of
    /// `texels`, reading `V_AO` exact for the maps' shapes when `cut_ao` (CAO's LAO reach
    /// `reach_mm`). `None` when a shape probes (it clips everything outside it) or the
    /// maps' cameras do not match their shapes.
    pub fn of(
        maps: Option<&ClipMaps>,
        shapes: &[ClipShape],
        texels: &VolumeTexels,
        reach_mm: f32,
        cut_ao: bool,
    ) -> Option<ImageInputs> {
        let Some(maps) = maps else {
            return shapes.is_empty().then_some(ImageInputs {
                shapes: Vec::new(),
                cut_ao,
            });
        };
        let cameras = maps.cameras();
        let u = &maps.uniforms;
        let n = u.counts[0] as usize;
        if u.counts[1] > 0 || n != shapes.len() || cameras.len() < n {
            return None;
        }
        let spacing = Vec3::from(texels.spacing);
        let diag = spacing.length();
        let min_spacing = spacing.min_element();
        let mut out = Vec::with_capacity(n);
        for (i, (shape, camera)) in shapes.iter().zip(&cameras).enumerate() {
            let (centre, carved) = crate::clip::camera::carved_ball(&u.shapes[i], camera);
            if !centre.is_finite() {
                return None;
            }
            let clip = carved + diag;
            let ao = clip + diag + reach_mm + AO_READ_REACH as f32 * min_spacing + diag;
            if !(clip.is_finite() && ao.is_finite()) {
                return None;
            }
            out.push(ShapeReach {
                shape: shape.clone(),
                camera: *camera,
                clip: Ball {
                    centre,
                    radius: clip,
                },
                ao: Ball { centre, radius: ao },
            });
        }
        Some(ImageInputs {
            shapes: out,
            cut_ao,
        })
    }

    /// Balls outside of which an image with `self`'s inputs and one with `new`'s (of the
    /// same view) agree pixel for pixel: where a shape of one is not a shape of the other,
    /// its clip ball, and its AO ball when that image's AO holds the cut (`V_AO` exact
    /// for `P` differs from `V_PAO` only near `P`'s shapes, and from `V_AO` exact for `P'`
    /// only near the shapes of one pose and not the other). At most [`MAX_BALLS`].
    pub fn changed(&self, new: &ImageInputs) -> Vec<Ball> {
        let mut balls = Vec::new();
        let only_in = |a: &ImageInputs, b: &ImageInputs, balls: &mut Vec<Ball>| {
            for s in &a.shapes {
                if !b.shapes.contains(s) {
                    balls.push(s.clip);
                }
                // The AO one image read and the other did not hold this shape's cut.
                if a.cut_ao && !(b.cut_ao && b.shapes.contains(s)) {
                    balls.push(s.ao);
                }
            }
        };
        only_in(self, new, &mut balls);
        only_in(new, self, &mut balls);
        // Balls inside others add nothing (a shape's clip ball lies in its AO ball).
        let mut kept: Vec<Ball> = Vec::new();
        for (i, b) in balls.iter().enumerate() {
            let inside_another = balls
                .iter()
                .enumerate()
                .any(|(j, o)| j != i && o.contains(b) && (o != b || j < i));
            if !inside_another {
                kept.push(*b);
            }
        }
        if kept.len() > MAX_BALLS {
            kept = vec![Ball::enclosing(&kept)];
        }
        kept
    }
}

/// Whether a frame may keep pixels of an earlier one: skipping on (`--no-skipping`
/// re-casts everything), and no shadows, live positional AO or surfaces.
pub fn reusable(frame: &Frame, extras: &crate::render::extras::RayExtras) -> bool {
    frame.settings.empty_space_skipping
        && extras.light.is_none()
        && extras.live_vao.is_none()
        && extras.surfaces.is_empty()
}

/// Whether the ray `origin + t · dir` (`dir` unit) over `[t_enter, t_exit]` meets one of
/// the frame's balls; `raycast.wgsl`'s `meets_change`, line for line.
pub fn meets_change(p: &RaycastParams, origin: Vec3, dir: Vec3, t_enter: f32, t_exit: f32) -> bool {
    if t_exit <= t_enter {
        return false;
    }
    for b in &p.balls[..p.reuse[0] as usize] {
        let c = Vec3::new(b[0], b[1], b[2]);
        let t = (c - origin).dot(dir).clamp(t_enter, t_exit);
        let d = origin + dir * t - c;
        if d.dot(d) <= b[3] * b[3] {
            return true;
        }
    }
    false
}

/// The pixels `(x0, y0, x1, y1)` (exclusive ends) of a `width × height` frame whose rays
/// can meet `balls`: the projections of the balls' bounding cubes, one pixel wider each
/// side; the whole frame where a cube reaches behind the camera. `None`: no pixel.
pub fn screen_rect(
    frame: &Frame,
    texels: &VolumeTexels,
    balls: &[Ball],
) -> Option<(u32, u32, u32, u32)> {
    let (w, h) = (frame.width.max(1), frame.height.max(1));
    if balls.is_empty() {
        return None;
    }
    let radius = (Vec3::from(texels.extent()) * 0.5).length();
    let view_proj = frame.camera.view_proj(radius, w as f32 / h as f32);
    let (mut lo, mut hi) = (glam::Vec2::INFINITY, glam::Vec2::NEG_INFINITY);
    for b in balls {
        for c in 0..8 {
            let corner = b.centre
                + Vec3::new(
                    if c & 1 == 0 { -b.radius } else { b.radius },
                    if c & 2 == 0 { -b.radius } else { b.radius },
                    if c & 4 == 0 { -b.radius } else { b.radius },
                );
            let clip = view_proj * Vec4::new(corner.x, corner.y, corner.z, 1.0);
            if !(clip.w > 1e-6 && clip.is_finite()) {
                return Some((0, 0, w, h));
            }
            let ndc = glam::Vec2::new(clip.x, clip.y) / clip.w;
            // ndc → pixel coordinates (rows go down), as the ray caster's inverse.
            let px = glam::Vec2::new(
                (ndc.x + 1.0) * 0.5 * w as f32,
                (1.0 - ndc.y) * 0.5 * h as f32,
            );
            lo = lo.min(px);
            hi = hi.max(px);
        }
    }
    let x0 = (lo.x.floor() - 1.0).clamp(0.0, w as f32) as u32;
    let y0 = (lo.y.floor() - 1.0).clamp(0.0, h as f32) as u32;
    let x1 = (hi.x.ceil() + 1.0).clamp(0.0, w as f32) as u32;
    let y1 = (hi.y.ceil() + 1.0).clamp(0.0, h as f32) as u32;
    (x0 < x1 && y0 < y1).then_some((x0, y0, x1, y1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clip::Shape;
    use crate::render::{Camera, RenderSettings};
    use crate::texels::{UploadLimits, VolumeTexels};
    use crate::volume::{Volume, VoxelData};

    fn reach(x: f32, size: f32) -> ShapeReach {
        let shape = ClipShape::new(Shape::Sphere, Vec3::new(x, 0.0, 0.0), size);
        let mesh = shape.geometry(100.0).expect("a sphere");
        let camera = ClipCamera::frame(&mesh, 5.0, 64);
        let centre = Vec3::new(x, 0.0, 0.0);
        ShapeReach {
            shape,
            camera,
            clip: Ball {
                centre,
                radius: size + 1.0,
            },
            ao: Ball {
                centre,
                radius: size + 8.0,
            },
        }
    }

    fn inputs(shapes: Vec<ShapeReach>, cut_ao: bool) -> ImageInputs {
        ImageInputs { shapes, cut_ao }
    }

    #[test]
    fn what_changed_between_two_images() {
        let (a, b, c) = (reach(0.0, 10.0), reach(3.0, 10.0), reach(-40.0, 5.0));
        // Nothing moved: nothing to cast, whatever the AO (the same AO read).
        for cut in [false, true] {
            let same = inputs(vec![a.clone(), c.clone()], cut);
            assert!(same.changed(&same.clone()).is_empty());
        }
        // A shape moved, AO without the cut: its clip balls before and after only.
        let before = inputs(vec![a.clone(), c.clone()], false);
        let after = inputs(vec![b.clone(), c.clone()], false);
        assert_eq!(before.changed(&after), vec![a.clip, b.clip]);
        // With the cut's AO: its AO balls, which hold the clip balls; the shape that
        // stayed adds nothing.
        let before = inputs(vec![a.clone(), c.clone()], true);
        let after = inputs(vec![b.clone(), c.clone()], true);
        assert_eq!(before.changed(&after), vec![a.ao, b.ao]);
        // The same shapes, one image with the cut's AO and one with V_PAO: every shape's
        // AO ball.
        let stand_in = inputs(vec![a.clone(), c.clone()], false);
        assert_eq!(before.changed(&stand_in), vec![a.ao, c.ao]);
        assert_eq!(stand_in.changed(&before), vec![a.ao, c.ao]);
        // A shape added.
        let one = inputs(vec![a.clone()], true);
        assert_eq!(one.changed(&before), vec![c.ao]);
        // Too many balls: one that holds them all.
        let many: Vec<ShapeReach> = (0..10).map(|i| reach(i as f32 * 30.0, 4.0)).collect();
        let all = inputs(many.clone(), true).changed(&inputs(Vec::new(), true));
        assert_eq!(all.len(), 1);
        for s in &many {
            assert!(all[0].contains(&s.ao), "{:?} holds {:?}", all[0], s.ao);
        }
    }

    /// Every pixel whose ray meets a ball lies in the balls' rectangle on screen, and
    /// some pixels do not (the rectangle is not the whole frame).
    #[test]
    fn the_screen_rectangle_holds_every_ray_that_meets_a_ball() {
        let v = Volume::new([40, 30, 20], [1.0, 1.2, 2.0], VoxelData::U8(vec![0; 24000]))
            .expect("valid");
        let texels = VolumeTexels::new(&v, UploadLimits::NONE);
        let tf = crate::tf::TransferFunction::preset(crate::tf::Preset::CaoSingleColor, &v.stats());
        let lut = tf.bake(0.0, 255.0, 256);
        for (camera, balls) in [
            (
                Camera {
                    azimuth_deg: 30.0,
                    elevation_deg: 20.0,
                    ..Default::default()
                },
                vec![Ball {
                    centre: Vec3::new(5.0, -3.0, 4.0),
                    radius: 6.0,
                }],
            ),
            (
                Camera {
                    azimuth_deg: -70.0,
                    elevation_deg: -35.0,
                    orthographic: true,
                    ..Default::default()
                },
                vec![
                    Ball {
                        centre: Vec3::new(-12.0, 10.0, 0.0),
                        radius: 3.0,
                    },
                    Ball {
                        centre: Vec3::new(10.0, 0.0, -15.0),
                        radius: 5.0,
                    },
                ],
            ),
        ] {
            let frame = Frame {
                camera,
                settings: RenderSettings::default(),
                width: 120,
                height: 90,
            };
            let mut p = frame.params(&texels, &lut, 0, 0);
            set_balls(&mut p, &balls);
            let (x0, y0, x1, y1) = screen_rect(&frame, &texels, &balls).expect("on screen");
            let mut meeting = 0;
            for py in 0..frame.height {
                for px in 0..frame.width {
                    let (o, d, t0, t1) = crate::render::cpu::ray(&p, px, py);
                    if meets_change(&p, o, d, t0, t1) {
                        meeting += 1;
                        assert!(
                            (x0..x1).contains(&px) && (y0..y1).contains(&py),
                            "pixel ({px}, {py}) outside ({x0}, {y0})–({x1}, {y1})"
                        );
                    }
                }
            }
            assert!(meeting > 0, "no ray meets {balls:?}");
            assert!(
                (x1 - x0) * (y1 - y0) < frame.width * frame.height / 2,
                "({x0}, {y0})–({x1}, {y1}) is most of the frame"
            );
        }
    }
}
