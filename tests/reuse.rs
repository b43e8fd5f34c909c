//! Reusing an image's pixels while clip shapes move (`volao::render::reuse`): a frame
//! that casts only the rays passing near a change gives the full render bit for bit,
//! through moves, shapes added and removed and the AO switching between CAO's `V_AO`
//! and the uncut `V_PAO`; every pixel that changes lies on such a ray; the AO's reach
//! is needed (a cut changes AO beyond itself); and the shader decides which rays to
//! cast exactly as its CPU twin does. GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{crop, data, device, texels};
use glam::Vec3;
use volao::ao::cao::{CaoGpu, CaoMode, CaoSetup, Pose};
use volao::ao::lao::Rays;
use volao::ao::rays::RaySet;
use volao::ao::sparse::Coverage;
use volao::clip::{ClipShape, Shape};
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::reuse::{Ball, ImageInputs, set_balls};
use volao::render::{Frame, Image, RenderSettings};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions};

/// Depth-map size (small keeps lavapipe quick).
const MAP: u32 = 128;
/// Samples per LAO ray.
const SAMPLES: u32 = 8;

struct Scene {
    gpu: volao::gpu::Gpu,
    vol: RenderVolume,
    rc: RayCaster,
    cao: CaoGpu,
    frame: Frame,
}

fn scene() -> Scene {
    let engine = volume::format::load(&data("raw/engine.raw"), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras();
    let v = crop(&engine, [96, 80, 30], [64, 64, 48]);
    let gpu = device();
    let tf = TransferFunction::preset(Preset::CaoSingleColor, &v.stats());
    let settings = RenderSettings {
        ambient: 0.8,
        ..Default::default()
    };
    let vol = RenderVolume::from_texels(&gpu, texels(&v), &tf, settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let bricks = Coverage::Readable.bricks(&vol.texels, vol.ranges(), &tf);
    let rays = Rays::uniform(RaySet::Six.directions());
    let setup = CaoSetup {
        tf: &tf,
        rays: &rays,
        samples: SAMPLES,
        msaa: 32,
    };
    let cao = CaoGpu::new(&gpu, &vol, setup, bricks, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let frame = common::oblique_frame(settings, 96);
    Scene {
        gpu,
        vol,
        rc,
        cao,
        frame,
    }
}

impl Scene {
    /// Poses CAO for `shapes` (its `V_AO` exact for them) and says what an image reading
    /// `V_AO` (`exact`) or the uncut `V_PAO` depends on.
    fn pose(&mut self, shapes: &[ClipShape], exact: bool) -> ImageInputs {
        let reach = self.cao.reach_mm(&self.vol.texels);
        let stats = self
            .cao
            .update(
                &self.gpu,
                &self.vol.texels,
                Pose {
                    shapes,
                    resolution: MAP,
                    reach_mm: reach,
                    mode: CaoMode::Selective,
                },
            )
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(stats.clip_errors.is_empty(), "{:?}", stats.clip_errors);
        self.vol.set_ambient_occlusion_view(self.cao.ao_view());
        self.vol
            .set_ambient_occlusion_stand_in(Some(self.cao.pao_view()));
        self.vol.read_stand_in(!exact);
        ImageInputs::of(Some(&self.cao.clip), shapes, &self.vol.texels, reach, exact)
            .expect("carving shapes have bounded inputs")
    }

    fn render(&self) -> Image {
        self.rc
            .render(&self.gpu, &self.vol, &self.frame, Some(&self.cao.clip))
            .unwrap_or_else(|e| panic!("{e}"))
    }

    fn reusing(&self, previous: &Image, changed: &[Ball]) -> Image {
        self.rc
            .render_reusing(
                &self.gpu,
                &self.vol,
                &self.frame,
                Some(&self.cao.clip),
                previous,
                changed,
            )
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// Per pixel: whether its ray meets one of `balls` (the CPU twin's test).
    fn meeting(&self, balls: &[Ball]) -> Vec<bool> {
        let mut p = self.frame.params(&self.vol.texels, &self.vol.lut, 0, 0);
        set_balls(&mut p, balls);
        (0..self.frame.width * self.frame.height)
            .map(|i| {
                let (x, y) = (i % self.frame.width, i / self.frame.width);
                let (o, d, t0, t1) = volao::render::cpu::ray(&p, x, y);
                volao::render::reuse::meets_change(&p, o, d, t0, t1)
            })
            .collect()
    }
}

/// A carving sphere; the tests' shapes cut the faces the camera sees.
fn sphere(x: f32, y: f32, z: f32, r: f32) -> ClipShape {
    ClipShape::new(Shape::Sphere, Vec3::new(x, y, z), r)
}

/// The pixels that differ between two images whose rays meet none of `balls`.
fn changed_outside(a: &Image, b: &Image, meeting: &[bool]) -> usize {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .zip(meeting)
        .filter(|((x, y), m)| x != y && !**m)
        .count()
}

#[test]
fn a_frame_that_casts_only_rays_near_a_change_is_the_full_render_bit_for_bit() {
    let mut s = scene();
    let (a, b) = (sphere(4.0, 26.0, 6.0, 10.0), sphere(-16.0, 22.0, -6.0, 7.0));
    let moved = |c: &ClipShape, dx: f32| {
        let mut c = c.clone();
        c.translation[0] += dx;
        c
    };
    let boxed = ClipShape::new(Shape::Box, Vec3::from(b.translation), 5.0);
    // (what happens, the shapes, whether the image reads V_AO exact for them)
    let steps: Vec<(&str, Vec<ClipShape>, bool)> = vec![
        ("a shape moved", vec![moved(&a, 4.0)], true),
        ("moved, reading V_PAO", vec![moved(&a, 7.0)], false),
        ("the AO caught up", vec![moved(&a, 7.0)], true),
        ("a shape added", vec![moved(&a, 7.0), b.clone()], true),
        ("a shape removed", vec![b.clone()], true),
        ("nothing changed", vec![b.clone()], true),
        ("another shape at the pose", vec![boxed], true),
        ("no shapes, V_PAO", vec![], false),
    ];
    let mut inputs = s.pose(std::slice::from_ref(&a), true);
    let mut image = s.render();
    for (what, shapes, exact) in steps {
        let next = s.pose(&shapes, exact);
        let changed = inputs.changed(&next);
        let full = s.render();
        let reused = s.reusing(&image, &changed);
        let differing = common::differing(&reused.pixels, &full.pixels);
        assert_eq!(differing, 0, "{what}: {differing} pixels differ");
        // Every pixel the change changed lies on a ray that meets a ball.
        let meeting = s.meeting(&changed);
        assert_eq!(
            changed_outside(&image, &full, &meeting),
            0,
            "{what}: a pixel changed on a ray that meets no ball"
        );
        let cast = meeting.iter().filter(|&&m| m).count();
        let moved_pixels = common::differing(&image.pixels, &full.pixels);
        eprintln!(
            "{what}: {cast} of {} rays cast, {moved_pixels} pixels changed",
            meeting.len()
        );
        if what == "nothing changed" {
            assert_eq!((cast, moved_pixels), (0, 0));
        } else {
            assert!(moved_pixels > 0, "{what}: the test needs a change to see");
        }
        if what == "a shape moved" {
            assert!(
                cast < meeting.len() / 2,
                "{what}: {cast} rays cast, the test needs pixels to reuse"
            );
        }
        (inputs, image) = (next, full);
    }
}

/// A cut changes the AO beyond itself, up to the LAO reach: with only the shapes' clip
/// balls, pixels that changed would be kept.
#[test]
fn the_balls_must_reach_as_far_as_the_ao_of_the_cut() {
    let mut s = scene();
    let a = sphere(4.0, 26.0, 6.0, 10.0);
    let mut b = a.clone();
    b.translation[0] += 5.0;
    let old = s.pose(std::slice::from_ref(&a), true);
    let before = s.render();
    let new = s.pose(std::slice::from_ref(&b), true);
    let after = s.render();
    let clip_only = |i: &ImageInputs| {
        let mut i = i.clone();
        for shape in &mut i.shapes {
            shape.ao = shape.clip;
        }
        i
    };
    let too_small = clip_only(&old).changed(&clip_only(&new));
    let outside = changed_outside(&before, &after, &s.meeting(&too_small));
    assert!(
        outside > 0,
        "no pixel changed beyond the cut: the test cannot tell the AO's reach is needed"
    );
    let reused = s.reusing(&before, &too_small);
    assert_ne!(reused.pixels, after.pixels, "kept pixels that changed");
    assert_eq!(s.reusing(&before, &old.changed(&new)).pixels, after.pixels);
}

/// The shader casts exactly the rays that the CPU twin's test says meet a ball: over a
/// marker image, the pixels it leaves are those whose rays meet none.
#[test]
fn the_shader_and_its_twin_cast_the_same_rays() {
    let mut s = scene();
    let a = sphere(4.0, 26.0, 6.0, 10.0);
    let inputs = s.pose(std::slice::from_ref(&a), true);
    let balls = ImageInputs::default().changed(&inputs);
    assert!(!balls.is_empty());
    let marker = [1, 2, 3, 4];
    let blank = Image {
        width: s.frame.width,
        height: s.frame.height,
        pixels: vec![marker; (s.frame.width * s.frame.height) as usize],
    };
    let image = s.reusing(&blank, &balls);
    let meeting = s.meeting(&balls);
    let kept: Vec<bool> = image.pixels.iter().map(|p| *p == marker).collect();
    let mismatched = kept
        .iter()
        .zip(&meeting)
        .filter(|(k, m)| **k == **m)
        .count();
    assert_eq!(mismatched, 0, "pixels cast by one and not the other");
    let cast = meeting.iter().filter(|&&m| m).count();
    assert!(cast > 0 && cast < meeting.len(), "{cast} rays meet a ball");
}

/// What the AO balls rest on: CAO's `V_AO` for a cut differs from the uncut `V_PAO` only
/// at voxels within the LAO reach of what the cut can clip (the AO ball less the
/// ray caster's read margin), and it does change up to most of that reach past the cut.
#[test]
fn the_cut_changes_the_ao_only_within_its_reach_and_up_to_it() {
    use volao::ao::cao::CaoVolume;
    let mut s = scene();
    let a = sphere(4.0, 26.0, 6.0, 10.0);
    let inputs = s.pose(std::slice::from_ref(&a), true);
    let ao = s.cao.read(&s.gpu, CaoVolume::Ambient).expect("V_AO");
    let pao = s.cao.read(&s.gpu, CaoVolume::Precomputed).expect("V_PAO");
    let texels = &s.vol.texels;
    let spacing = Vec3::from(texels.spacing);
    let half = Vec3::from(texels.extent()) * 0.5;
    let reach = &inputs.shapes[0];
    let read_margin =
        volao::sample::AO_READ_REACH as f32 * spacing.min_element() + spacing.length();
    let bound = reach.ao.radius - read_margin;
    let mut farthest = 0.0f32;
    for (i, (x, y)) in ao.iter().zip(&pao).enumerate() {
        if x.to_bits() == y.to_bits() {
            continue;
        }
        let v = volao::volume::voxel_of(i, texels.dims);
        let centre = (Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32) + 0.5) * spacing - half;
        farthest = farthest.max(centre.distance(reach.ao.centre));
    }
    eprintln!("farthest changed voxel {farthest} mm from the centre; bound {bound} mm");
    assert!(farthest > 0.0, "the cut changed no AO");
    assert!(
        farthest <= bound,
        "a voxel {farthest} mm away changed: beyond {bound}"
    );
    // LAO samples lie 1 mm apart: the cut's AO reaches most of the rays' length past
    // the sphere (so a ball of the cut alone would not hold it).
    let past_cut = farthest - a.scale[0];
    assert!(
        past_cut > 0.75 * (SAMPLES - 1) as f32,
        "the AO changed only {past_cut} mm past the cut"
    );
}
