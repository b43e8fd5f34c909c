//! Contextual Ambient Occlusion: sparse CAO, sparse "LAO every frame" and the dense,
//! naive LAO every frame (`--no-skipping`) give the same pixels and, on every voxel the
//! ray caster can read, the same bits, for random poses of every shape, both modes and
//! overlapping shapes; the CPU twins of the clip maps, the mask and the ray cast; and
//! the dilation margin and the readability apron are what exactness rests on.
//! GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{crop, device, texels};
use volao::clip::gpu::MapRequest;

use common::{Rng, data, differing};
use glam::Vec3;
use volao::ao::cao::{
    CaoGpu, CaoMode, CaoSetup, CaoVolume, Pose, StepVInputs, clip_volume_cpu, lao_on_opacity_cpu,
    reach_mm,
};
use volao::ao::lao::{Rays, lao_lut};
use volao::ao::rays::RaySet;
use volao::ao::sparse::{Bricks, Coverage};
use volao::ao::view::Marking;
use volao::clip::camera::EMPTY;
use volao::clip::{ClipMode, ClipShape, Cuts, Shape};
use volao::gpu::Gpu;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::{Camera, Frame, RenderMode, RenderSettings};
use volao::texels::BlockRanges;
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, Volume};

/// Depth-map size in these tests (the default is 1024; small keeps lavapipe quick).
const MAP: u32 = 128;

/// A CAO frame's pose for `shapes` with maps of [`MAP`] pixels.
fn pose(shapes: &[ClipShape], reach_mm: f32, mode: CaoMode) -> Pose<'_> {
    Pose {
        shapes,
        resolution: MAP,
        reach_mm,
        mode,
    }
}
/// Samples per LAO ray here (the default is 20).
const SAMPLES: u32 = 8;

fn load(rel: &str, opts: LoadOptions) -> Volume {
    volume::format::load(&data(rel), &opts)
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras()
}

fn engine() -> Volume {
    crop(
        &load("raw/engine.raw", LoadOptions::default()),
        [96, 80, 40],
        [40, 40, 36],
    )
}

fn cranium() -> Volume {
    let opts = LoadOptions {
        raw: common::shared_files()
            .into_iter()
            .find(|(f, _)| *f == "raw/cranium-ct.raw")
            .map(|(_, o)| o)
            .unwrap_or_default(),
        ..Default::default()
    };
    crop(
        &load("raw/cranium-ct.raw", opts),
        [90, 60, 40],
        [40, 40, 28],
    )
}

struct Scene {
    gpu: Gpu,
    vol: RenderVolume,
    rc: RayCaster,
    /// Sparse, as rendering runs it.
    cao: CaoGpu,
    /// Dense: every voxel and sample (`--no-skipping`).
    dense: CaoGpu,
    /// Sparse and culled to each frame's view (issue #46): one across all poses, so
    /// bricks a view left out stale are tested too.
    viewed: CaoGpu,
    tf: TransferFunction,
    rays: Rays,
    /// Samples per LAO ray.
    samples: u32,
    frame: Frame,
    /// Frames whose step V ran over the list of the voxels to ray cast, and sparse CAO
    /// frames whose list was too short for them (step V over bricks instead).
    listed: usize,
    over_bricks: usize,
}

fn scene(v: &Volume, preset: Preset, set: RaySet) -> Scene {
    scene_with(v, preset, set, SAMPLES)
}

/// The same with `samples` per LAO ray.
fn scene_with(v: &Volume, preset: Preset, set: RaySet, samples: u32) -> Scene {
    let gpu = device();
    let tf = TransferFunction::preset(preset, &v.stats());
    let settings = RenderSettings {
        ambient: 0.8,
        ..Default::default()
    };
    let vol = RenderVolume::from_texels(&gpu, texels(v), &tf, settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let rays = Rays::uniform(set.directions());
    let make = |bricks: Bricks| {
        CaoGpu::new(&gpu, &vol, setup(&tf, &rays, samples), bricks, &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let sparse = Coverage::Readable.bricks(&vol.texels, vol.ranges(), &tf);
    // Readable bricks reach one brick past those with opacity (AO is read off the
    // surface), which covers these small crops: the voxel test still leaves voxels out.
    assert!(
        sparse.occupied.contains(&0) && sparse.readable_mask(&vol.texels).contains(&false),
        "the crop must have voxels and samples to skip"
    );
    let cao = make(sparse.clone());
    let viewed = make(sparse);
    let dense = make(Coverage::Dense.bricks(&vol.texels, vol.ranges(), &tf));
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let frame = common::oblique_frame(settings, 48);
    Scene {
        gpu,
        vol,
        rc,
        cao,
        dense,
        viewed,
        tf,
        rays,
        samples,
        frame,
        listed: 0,
        over_bricks: 0,
    }
}

impl Scene {
    fn reach(&self) -> f32 {
        reach_mm(self.samples, self.vol.texels.spacing)
    }

    /// V_AO, the rendered image and the percentage of category-b voxels after one frame
    /// of sparse CAO in `mode`.
    fn frame(
        &mut self,
        shapes: &[ClipShape],
        mode: CaoMode,
        reach: f32,
    ) -> (Vec<f32>, Vec<[u8; 4]>, f64) {
        let Scene {
            gpu,
            vol,
            rc,
            cao,
            frame,
            ..
        } = self;
        let (ao, pixels, category_b, listed) = run(gpu, vol, rc, frame, cao, shapes, mode, reach);
        self.listed += usize::from(listed);
        self.over_bricks += usize::from(mode == CaoMode::Selective && !listed);
        (ao, pixels, category_b)
    }

    /// One frame of sparse CAO, for its figures.
    fn update(&mut self, shapes: &[ClipShape], reach: f32) -> volao::ao::cao::CaoStats {
        let Scene { gpu, vol, cao, .. } = self;
        cao.update(gpu, &vol.texels, pose(shapes, reach, CaoMode::Selective))
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// The image of a frame of the view-culled CAO: maps posed, a visibility pass of
    /// the frame with them, step V only where it marked (as `volao bench cao`'s
    /// `cao-view`).
    fn frame_viewed(&mut self, shapes: &[ClipShape], reach: f32) -> Vec<[u8; 4]> {
        let Scene {
            gpu,
            vol,
            rc,
            viewed,
            frame,
            ..
        } = self;
        let pose = pose(shapes, reach, CaoMode::Selective);
        viewed
            .pose_maps(gpu, &vol.texels, &pose)
            .unwrap_or_else(|e| panic!("{e}"));
        let view = rc
            .mark_view(gpu, vol, frame, Some(&viewed.clip), Marking::BRICKS, None)
            .unwrap_or_else(|e| panic!("{e}"));
        viewed.set_view(Some(&view));
        run(
            gpu,
            vol,
            rc,
            frame,
            viewed,
            shapes,
            CaoMode::Selective,
            reach,
        )
        .1
    }

    /// The same with the dense CAO.
    fn frame_dense(
        &mut self,
        shapes: &[ClipShape],
        mode: CaoMode,
        reach: f32,
    ) -> (Vec<f32>, Vec<[u8; 4]>, f64) {
        let Scene {
            gpu,
            vol,
            rc,
            dense,
            frame,
            ..
        } = self;
        let (ao, pixels, category_b, _) = run(gpu, vol, rc, frame, dense, shapes, mode, reach);
        (ao, pixels, category_b)
    }
}

#[allow(clippy::too_many_arguments)]
fn run(
    gpu: &Gpu,
    vol: &mut RenderVolume,
    rc: &RayCaster,
    frame: &Frame,
    cao: &mut CaoGpu,
    shapes: &[ClipShape],
    mode: CaoMode,
    reach: f32,
) -> (Vec<f32>, Vec<[u8; 4]>, f64, bool) {
    let stats = cao
        .update(gpu, &vol.texels, pose(shapes, reach, mode))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(stats.clip_errors.is_empty(), "{:?}", stats.clip_errors);
    let ao = cao
        .read(gpu, CaoVolume::Ambient)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion_view(cao.ao_view());
    let image = rc
        .render(gpu, vol, frame, Some(&cao.clip))
        .unwrap_or_else(|e| panic!("{e}"));
    // Category b (Algorithm 2's "recompute") among the voxels step IV visited.
    let category_b = 100.0 * stats.category_b as f64 / stats.voxels.max(1) as f64;
    (ao, image.pixels, category_b, stats.listed)
}

/// Per voxel: whether the ray caster can read its AO, found here without the library's
/// brick and voxel tests: some sample of non-zero opacity weights it, i.e. one of the 8
/// cells around it has a density range over which the (uncorrected) LUT is not
/// transparent. A cell's corners are the texels at and above its lower corner.
fn readable_voxels(texels: &volao::texels::VolumeTexels, tf: &TransferFunction) -> Vec<bool> {
    let lut = volao::sample::bake_lut(tf, texels, 1.0);
    let d = texels.dims;
    let at = |x: usize, y: usize, z: usize| texels.norm_at(x + d[0] * (y + d[1] * z));
    let clamp = |c: isize, n: usize| c.clamp(0, n as isize - 1) as usize;
    // Cell c spans texels c..=c + 1 (clamped at the faces, as a sampler clamps).
    let cell_open = |c: [isize; 3]| {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for k in 0..8 {
            let t = [0, 1, 2].map(|a| clamp(c[a] + ((k >> a) & 1) as isize, d[a]));
            let n = at(t[0], t[1], t[2]);
            lo = lo.min(n);
            hi = hi.max(n);
        }
        let v = |n: f32| n as f64 * texels.value_scale + texels.value_offset;
        let (a, b) = (v(lo), v(hi));
        !lut.is_transparent_over(a.min(b), a.max(b))
    };
    // Cells −1 ..= d − 1 on each axis, open or not.
    let n = d.map(|x| x + 1);
    let mut open = vec![false; n.iter().product()];
    for (i, o) in open.iter_mut().enumerate() {
        let c = [i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])];
        *o = cell_open(c.map(|x| x as isize - 1));
    }
    // The ray caster reads AO up to AO_READ_REACH voxels off a sample in an open cell,
    // and the trilinear read weights the voxels within one of that point: voxel v is
    // read if a cell c with v − 1 − reach ≤ c ≤ v + reach is open.
    let r = volao::sample::AO_READ_REACH as isize;
    let is_open = |c: [isize; 3]| {
        let c = [0, 1, 2].map(|a| (c[a].clamp(-1, d[a] as isize - 1) + 1) as usize);
        open[c[0] + n[0] * (c[1] + n[1] * c[2])]
    };
    (0..d.iter().product::<usize>())
        .map(|i| {
            let v = volao::volume::voxel_of(i, d).map(|c| c as isize);
            (-1 - r..=r).any(|dz| {
                (-1 - r..=r)
                    .any(|dy| (-1 - r..=r).any(|dx| is_open([v[0] + dx, v[1] + dy, v[2] + dz])))
            })
        })
        .collect()
}

/// Voxels whose bits differ between `a` and `b` among the `readable` ones.
fn differing_readable(a: &[f32], b: &[f32], readable: &[bool]) -> usize {
    assert_eq!(a.len(), b.len());
    (0..a.len())
        .filter(|&i| readable[i] && a[i].to_bits() != b[i].to_bits())
        .count()
}

/// Sparse CAO, sparse LAO every frame and dense LAO every frame for `shapes`: 0
/// differing pixels, and the same bits on every readable voxel.
fn assert_exact(s: &mut Scene, shapes: &[ClipShape], reach: f32, what: &str) -> f64 {
    let (cao, cao_img, pct) = s.frame(shapes, CaoMode::Selective, reach);
    let (full, full_img, _) = s.frame(shapes, CaoMode::Full, reach);
    let (dense, dense_img, _) = s.frame_dense(shapes, CaoMode::Full, reach);
    // Readable as found independently of the library's tests, so that making those too
    // tight fails here (readable_bricks_one_voxel_too_tight_break_exactness).
    let readable = readable_voxels(&s.vol.texels, &s.tf);
    assert_eq!(
        differing_readable(&cao, &full, &readable),
        0,
        "{what}: {shapes:?}: sparse CAO's V_AO differs from sparse LAO every frame"
    );
    assert_eq!(
        differing_readable(&full, &dense, &readable),
        0,
        "{what}: {shapes:?}: sparse LAO every frame's V_AO differs from the dense one"
    );
    assert_eq!(
        differing(&cao_img, &full_img),
        0,
        "{what}: {shapes:?}: sparse CAO's image differs from sparse LAO every frame"
    );
    assert_eq!(
        differing(&cao_img, &dense_img),
        0,
        "{what}: {shapes:?}: sparse CAO's image differs from the dense LAO every frame"
    );
    let viewed_img = s.frame_viewed(shapes, reach);
    assert_eq!(
        differing(&viewed_img, &dense_img),
        0,
        "{what}: {shapes:?}: CAO culled to the view differs from the dense LAO every frame"
    );
    pct
}

/// A random pose for `shape`, sized for a volume of half-extent `half` (mm).
fn random_shape(rng: &mut Rng, shape: &Shape, half: Vec3, mode: ClipMode) -> ClipShape {
    let mut u = || (rng.next() >> 11) as f32 / (1u64 << 53) as f32;
    let r = half.min_element();
    let translation = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * half * 1.2;
    let rotation_deg = [u() * 360.0, u() * 360.0, u() * 360.0];
    let scale = match shape {
        Shape::Plane => [1.0; 3],
        Shape::Sphere => [r * (0.35 + 0.3 * u()); 3],
        Shape::Box => [
            r * (0.25 + 0.3 * u()),
            r * (0.25 + 0.3 * u()),
            r * (0.25 + 0.3 * u()),
        ],
        Shape::Cylinder => [
            r * (0.25 + 0.2 * u()),
            r * (0.25 + 0.2 * u()),
            r * (0.4 + 0.4 * u()),
        ],
        Shape::Torus { .. } | Shape::Mesh { .. } => [r * (0.45 + 0.2 * u()); 3],
    };
    ClipShape {
        shape: shape.clone(),
        translation: translation.to_array(),
        rotation_deg,
        scale,
        mode,
        cuts: Cuts::All,
    }
}

/// CAO vs the baseline for `poses` random poses of every shape, in `mode`.
fn exactness(v: &Volume, preset: Preset, set: RaySet, mode: ClipMode, seed: u64, poses: usize) {
    let mut s = scene(v, preset, set);
    let half = Vec3::from(s.vol.texels.extent()) * 0.5;
    let reach = s.reach();
    let shapes = [
        Shape::Plane,
        Shape::Sphere,
        Shape::Box,
        Shape::Cylinder,
        Shape::Torus { tube: 0.35 },
    ];
    let mut rng = Rng(seed);
    let mut recomputed = Vec::new();
    for shape in &shapes {
        // One geometry per shape: poses change only matrices (scale fixed per shape).
        let base = random_shape(&mut rng, shape, half, mode);
        for pose in 0..poses {
            let mut c = random_shape(&mut rng, shape, half, mode);
            c.scale = base.scale;
            let what = format!("{set:?} {mode:?} pose {pose}");
            recomputed.push(assert_exact(&mut s, std::slice::from_ref(&c), reach, &what));
        }
    }
    // The test means something only if voxels were both copied and recomputed. Sparse
    // CAO visits only bricks of visible material (bone in a CT crop, little of it), so
    // a probe holding none of it recomputes nothing: a quarter of the poses must.
    let busy = recomputed.iter().filter(|&&p| p > 0.0 && p < 100.0).count();
    assert!(
        busy * 4 >= recomputed.len(),
        "poses should recompute some but not all voxels: {recomputed:?}"
    );
    // Sparse CAO's frames ray cast over a list of their voxels where it holds them all
    // (ao::cao::listed): some frames here must have, or the list went untested.
    assert!(s.listed > 0, "no frame ray cast over the voxel list");
}

/// CAO's setup with 32 anti-aliasing samples, as these tests run it.
fn setup<'a>(tf: &'a TransferFunction, rays: &'a Rays, samples: u32) -> CaoSetup<'a> {
    CaoSetup {
        tf,
        rays,
        samples,
        msaa: 32,
    }
}
#[test]
fn cao_equals_lao_every_frame_carving_engine() {
    for set in [RaySet::Six, RaySet::TwentySix] {
        exactness(
            &engine(),
            Preset::CaoSingleColor,
            set,
            ClipMode::Carve,
            11,
            20,
        );
    }
}

#[test]
fn cao_equals_lao_every_frame_probing_cranium() {
    for set in [RaySet::Six, RaySet::TwentySix] {
        exactness(&cranium(), Preset::CtBone, set, ClipMode::Probe, 23, 20);
    }
}

#[test]
fn cao_equals_lao_every_frame_carving_cranium_and_probing_engine() {
    exactness(
        &cranium(),
        Preset::CtBone,
        RaySet::Six,
        ClipMode::Carve,
        5,
        20,
    );
    exactness(
        &engine(),
        Preset::CaoSingleColor,
        RaySet::TwentySix,
        ClipMode::Probe,
        7,
        20,
    );
}

#[test]
fn overlapping_shapes_stay_exact() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::TwentySix);
    let half = Vec3::from(s.vol.texels.extent()) * 0.5;
    let reach = s.reach();
    let mut rng = Rng(99);
    let combos = [
        (Shape::Sphere, ClipMode::Carve, Shape::Box, ClipMode::Carve),
        (
            Shape::Torus { tube: 0.35 },
            ClipMode::Carve,
            Shape::Cylinder,
            ClipMode::Carve,
        ),
        (
            Shape::Sphere,
            ClipMode::Probe,
            Shape::Plane,
            ClipMode::Carve,
        ),
        (Shape::Box, ClipMode::Probe, Shape::Sphere, ClipMode::Probe),
    ];
    for (a, ma, b, mb) in &combos {
        for pose in 0..5 {
            let mut first = random_shape(&mut rng, a, half, *ma);
            let mut second = random_shape(&mut rng, b, half, *mb);
            // Overlap: the second sits next to the first.
            second.translation =
                (Vec3::from(first.translation) + Vec3::splat(half.min_element() * 0.3)).to_array();
            first.translation = (Vec3::from(first.translation) * 0.5).to_array();
            let shapes = [first, second];
            let pct = assert_exact(&mut s, &shapes, reach, &format!("pose {pose}"));
            assert!(pct < 100.0, "{shapes:?}");
        }
    }
    // Probes clip most of this small volume: some frames have more voxels to ray cast
    // than the list holds (a quarter of them) and run step V over bricks, others list.
    assert!(
        s.listed > 0 && s.over_bricks > 0,
        "frames listed: {}, over bricks: {}",
        s.listed,
        s.over_bricks
    );
}

#[test]
fn a_margin_shorter_than_the_rays_breaks_exactness() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::TwentySix);
    let shape = ClipShape::new(Shape::Sphere, Vec3::new(2.0, -3.0, 1.0), 9.0);
    let reach = s.reach();
    let (full, _, _) = s.frame(std::slice::from_ref(&shape), CaoMode::Full, reach);
    let (exact, _, _) = s.frame(std::slice::from_ref(&shape), CaoMode::Selective, reach);
    assert_eq!(differing(&exact, &full), 0);
    let (short, _, _) = s.frame(
        std::slice::from_ref(&shape),
        CaoMode::Selective,
        reach * 0.4,
    );
    let wrong = differing(&short, &full);
    assert!(
        wrong > 100,
        "a 40 % margin must miss affected voxels, {wrong} differ"
    );
}

/// A sphere cutting only empty space next to material: its dilation reaches voxels that
/// can be read (Algorithm 2 puts them in category b), but no opacity changes, so sparse
/// CAO keeps `V_PAO` there (ao::sparse::Bricks::reached) and ray casts nothing, and the
/// frame stays exact; the same sphere moved into the material makes it ray cast.
#[test]
fn a_cut_into_empty_space_recomputes_nothing() {
    // A slab of material (x < 16) and empty space beyond; LAO rays of 20 samples (21.6 mm
    // reach) so that the dilation reaches the slab from farther than brick granularity.
    let v = common::u8_volume([64, 32, 32], |x, y, z| {
        if x < 16 {
            120 + ((x * 7 + y * 3 + z) % 100) as u8
        } else {
            0
        }
    });
    let mut s = scene_with(&v, Preset::CaoSingleColor, RaySet::Six, 20);
    let reach = s.reach();
    // Voxel x = 34: 16 mm of empty space to the slab's readable voxels (x ≤ 18).
    let mut shape = ClipShape::new(Shape::Sphere, Vec3::new(2.5, 0.0, 0.0), 4.0);
    let shapes = std::slice::from_ref(&shape);
    let stats = s.update(shapes, reach);
    let readable = readable_voxels(&s.vol.texels, &s.tf);
    let paper = s
        .cao
        .read(&s.gpu, CaoVolume::Mask)
        .unwrap_or_else(|e| panic!("{e}"));
    let marked_readable = (0..paper.len())
        .filter(|&i| paper[i] == 0.5 && readable[i])
        .count();
    assert!(
        marked_readable > 0,
        "the dilation reaches no readable voxel"
    );
    assert_eq!(
        stats.recomputed, 0,
        "a cut into empty space ray cast voxels"
    );
    assert_exact(&mut s, shapes, reach, "a cut into empty space");
    // Into the slab: now opacity changes and voxels are ray cast.
    shape.translation = [-22.0, 0.0, 0.0];
    let shapes = std::slice::from_ref(&shape);
    let stats = s.update(shapes, reach);
    assert!(stats.recomputed > 0, "a cut into material ray cast nothing");
    assert_exact(&mut s, shapes, reach, "a cut into material");
}

/// The viewer's images of a shape being moved read `V_PAO` while `V_AO` is updated for
/// another pose (`RenderVolume::read_stand_in`): such an image is the one of `V_PAO`'s
/// values uploaded as the AO volume, not the exact `V_AO`'s, and switching back (or
/// replacing the AO) reads `V_AO` again.
#[test]
fn the_stand_in_reads_v_pao_in_place_of_v_ao() {
    let mut s = scene(&engine(), Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    // A cut into the middle of the crop: CAO differs from V_PAO around it.
    let shapes = [ClipShape::new(Shape::Sphere, Vec3::ZERO, 10.0)];
    let stats = s.update(&shapes, reach);
    assert!(stats.recomputed > 0, "the cut changed no AO");
    let Scene {
        gpu,
        vol,
        rc,
        cao,
        frame,
        ..
    } = &mut s;
    let render = |vol: &RenderVolume| {
        rc.render(gpu, vol, frame, Some(&cao.clip))
            .unwrap_or_else(|e| panic!("{e}"))
            .pixels
    };
    vol.set_ambient_occlusion_view(cao.ao_view());
    vol.set_ambient_occlusion_stand_in(Some(cao.pao_view()));
    let exact = render(vol);
    vol.read_stand_in(true);
    assert!(vol.reads_stand_in());
    let stand_in = render(vol);
    vol.read_stand_in(false);
    assert_eq!(render(vol), exact, "switching back must read V_AO again");
    let pao = cao
        .read(gpu, CaoVolume::Precomputed)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion(gpu, &pao);
    vol.read_stand_in(true);
    assert!(!vol.reads_stand_in(), "a new AO volume drops the stand-in");
    let uploaded = render(vol);
    assert_eq!(
        differing(&stand_in, &uploaded),
        0,
        "the stand-in image is not V_PAO's"
    );
    assert!(
        differing(&stand_in, &exact) > 0,
        "V_PAO and the exact V_AO drew the same image: the test shows nothing"
    );
}

#[test]
fn readable_bricks_one_voxel_too_tight_break_exactness() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    // Bricks where a sample may have opacity, from block ranges without the one-voxel
    // apron and not grown by a brick for the AO read off the surface: the voxels such
    // samples weight are no longer all counted.
    let texels = &s.vol.texels;
    let tight = BlockRanges::of_cells(texels, volao::ao::sparse::BRICK, 0);
    let render = volao::sample::bake_lut(&s.tf, texels, 1.0);
    let mut bricks = Bricks::new(texels, &tight, Some(&render), &lao_lut(&s.tf, texels));
    bricks.readable = tight.occupancy(texels, &render);
    assert_ne!(bricks.readable, s.cao.bricks().readable);
    let mut wrong = CaoGpu::new(
        &s.gpu,
        &s.vol,
        setup(&s.tf, &s.rays, SAMPLES),
        bricks,
        &|_, _| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // The per-voxel test one voxel too tight: 5³ texels around each voxel where the AO
    // read AO_READ_REACH = 2 voxels off a sample needs 7³.
    let mut bricks = s.cao.bricks().clone();
    if let Some(t) = &mut bricks.voxels {
        t.below -= 1;
    }
    let mut wrong_voxels = CaoGpu::new(
        &s.gpu,
        &s.vol,
        setup(&s.tf, &s.rays, SAMPLES),
        bricks,
        &|_, _| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let shape = ClipShape::new(Shape::Sphere, Vec3::new(2.0, -3.0, 1.0), 9.0);
    let shapes = std::slice::from_ref(&shape);
    assert_exact(&mut s, shapes, reach, "the aprons kept");
    let (exact_ao, exact_img, _) = s.frame_dense(shapes, CaoMode::Full, reach);
    let readable = readable_voxels(&s.vol.texels, &s.tf);
    let Scene {
        gpu,
        vol,
        rc,
        frame,
        ..
    } = &mut s;
    for (what, cao) in [("bricks", &mut wrong), ("voxels", &mut wrong_voxels)] {
        let (broken_ao, broken, _, _) =
            run(gpu, vol, rc, frame, cao, shapes, CaoMode::Selective, reach);
        let wrong_pixels = differing(&broken, &exact_img);
        let wrong_voxels = differing_readable(&broken_ao, &exact_ao, &readable);
        eprintln!(
            "readable {what} one voxel too tight: {wrong_voxels} readable voxels and {wrong_pixels} pixels differ"
        );
        assert!(
            wrong_voxels > 0,
            "readable {what} one voxel too tight must break exactness"
        );
    }
}

#[test]
fn gpu_mask_and_opacity_match_the_cpu_twin() {
    for (v, preset) in [
        (engine(), Preset::CaoSingleColor),
        (cranium(), Preset::CtBone),
    ] {
        let mut s = scene(&v, preset, RaySet::TwentySix);
        let half = Vec3::from(s.vol.texels.extent()) * 0.5;
        let reach = s.reach();
        let mut rng = Rng(3);
        let mut classes = [false; 3];
        for shapes in [
            vec![random_shape(
                &mut rng,
                &Shape::Torus { tube: 0.35 },
                half,
                ClipMode::Carve,
            )],
            vec![
                random_shape(&mut rng, &Shape::Sphere, half, ClipMode::Carve),
                // Large enough that its contraction (reach ≈ 10 mm) is not empty.
                ClipShape {
                    scale: [16.0, 15.0, 14.0],
                    ..random_shape(&mut rng, &Shape::Box, half * 0.3, ClipMode::Probe)
                },
            ],
        ] {
            s.frame_dense(&shapes, CaoMode::Selective, reach);
            let maps = s
                .dense
                .clip
                .read_back(&s.gpu)
                .unwrap_or_else(|e| panic!("{e}"));
            let lut = lao_lut(&s.tf, &s.vol.texels);
            let (mut v_o, v_m) = clip_volume_cpu(&s.vol.texels, &lut, &maps, 32);
            s.dense.round_as_stored(&mut v_o);
            let g_o = s
                .dense
                .read(&s.gpu, CaoVolume::ClippedOpacity)
                .unwrap_or_else(|e| panic!("{e}"));
            let g_m = s
                .dense
                .read(&s.gpu, CaoVolume::Mask)
                .unwrap_or_else(|e| panic!("{e}"));
            // The CPU's f32 arithmetic may round a sample lying on a map boundary the
            // other way than the GPU's (fused multiply-adds). In V_m such a voxel moves to
            // the neighbouring class (partly clipped ↔ not or wholly); in V_o it differs by
            // one MSAA sample (TF_o / 41). Allow that for 0.1 % of voxels, nothing else.
            let mask_flips = v_m
                .iter()
                .zip(&g_m)
                .filter(|(a, b)| a != b)
                .inspect(|(a, b)| {
                    assert_eq!(
                        (*a - *b).abs(),
                        0.5,
                        "V_m jumps a class: {a} vs {b}, {shapes:?}"
                    )
                })
                .count();
            assert!(
                mask_flips * 1000 <= v_m.len(),
                "{mask_flips} voxels of V_m differ: {shapes:?}"
            );
            // (Within one f16 step the two agree: a GPU may round f32 to f16 either way.)
            let flips = v_o
                .iter()
                .zip(&g_o)
                .filter(|(a, b)| (*a - *b).abs() > a.abs().max(b.abs()) * 1e-3 + 1e-6)
                .inspect(|(a, b)| {
                    // TF_o ≤ 1, so one sample is at most 1/41.
                    let samples = (*a - *b).abs() * 41.0;
                    assert!(
                        samples <= 1.0 + 1e-4,
                        "V_o differs by more than a sample: {a} vs {b}"
                    );
                })
                .count();
            assert!(
                flips * 1000 <= v_o.len(),
                "{flips} voxels of V_o differ: {shapes:?}"
            );
            for (seen, class) in classes.iter_mut().zip([0.0, 0.5, 1.0]) {
                *seen |= g_m.contains(&class);
            }
            // Step V: the twin ray casts from the GPU's V_o, V_m, V_PAO.
            let pao = s
                .dense
                .read(&s.gpu, CaoVolume::Precomputed)
                .unwrap_or_else(|e| panic!("{e}"));
            let ao = s
                .dense
                .read(&s.gpu, CaoVolume::Ambient)
                .unwrap_or_else(|e| panic!("{e}"));
            let inputs = StepVInputs {
                v_o: &g_o,
                v_m: &g_m,
                v_pao: &pao,
            };
            let mut twin = lao_on_opacity_cpu(
                &s.vol.texels,
                inputs,
                &s.rays,
                SAMPLES,
                CaoMode::Selective,
                s.dense.bricks(),
            );
            s.dense.round_as_stored(&mut twin);
            let worst = twin
                .iter()
                .zip(&ao)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            // One f16 step at most (2⁻¹¹ below 1; V_AO is stored as f16 where it can be).
            assert!(worst <= 1e-3, "V_AO differs from the CPU twin by {worst}");
        }
        assert_eq!(classes, [true; 3], "every mask class occurs");
    }
}

#[test]
fn dilation_maps_match_the_cpu_twin() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    for (shape, mode) in [
        (Shape::Sphere, ClipMode::Carve),
        (Shape::Torus { tube: 0.35 }, ClipMode::Probe),
    ] {
        let c = ClipShape {
            mode,
            ..ClipShape::new(shape, Vec3::ZERO, 10.0)
        };
        s.frame(std::slice::from_ref(&c), CaoMode::Selective, reach);
        let maps = s
            .cao
            .clip
            .read_back(&s.gpu)
            .unwrap_or_else(|e| panic!("{e}"));
        let camera = s.cao.clip.cameras()[0];
        let (r_xy, r_z) = camera.dilation_radii();
        let z = [0, 1, 2, 3].map(|l| maps.layer(0, l));
        let f = volao::clip::gpu::block_size(r_xy);
        let d = volao::clip::cpu::dilate(z, maps.resolution, r_xy, r_z, mode == ClipMode::Probe, f);
        for (k, dk) in d.iter().enumerate() {
            let g = maps.layer(0, 4 + k as u32);
            let worst = dk
                .iter()
                .zip(g)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(worst < 1e-5, "{mode:?} layer {k}: {worst}");
        }
    }
}

#[test]
fn depth_maps_of_a_sphere_and_a_torus() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    let sphere = ClipShape::new(Shape::Sphere, Vec3::ZERO, 10.0);
    let torus = ClipShape::new(Shape::Torus { tube: 0.3 }, Vec3::ZERO, 10.0);
    s.frame(&[sphere, torus], CaoMode::Selective, reach);
    let maps = s
        .cao
        .clip
        .read_back(&s.gpu)
        .unwrap_or_else(|e| panic!("{e}"));
    let cams = s.cao.clip.cameras();
    let res = maps.resolution as usize;
    let at = |slot: usize, layer: u32, p: Vec3| {
        let c = cams[slot].project(p);
        maps.layer(slot, layer)[c.y as usize * res + c.x as usize]
    };
    // Sphere: front and back at the poles (shape space z = ±10), one layer only.
    let front = cams[0].project(Vec3::new(0.0, 0.0, 10.0)).z;
    let back = cams[0].project(Vec3::new(0.0, 0.0, -10.0)).z;
    let probe = Vec3::new(0.01, 0.01, 0.0);
    assert!(
        (at(0, 0, probe) - front).abs() < 2e-3,
        "{} vs {front}",
        at(0, 0, probe)
    );
    assert!((at(0, 1, probe) - back).abs() < 2e-3);
    assert_eq!(at(0, 2, probe), EMPTY, "a sphere has no second layer");
    // Torus edge-on: through its middle a view ray crosses the tube twice, with the
    // hole between: two layers, and the hole stays visible.
    let middle = Vec3::ZERO;
    for layer in 0..4 {
        assert!(
            at(1, layer, middle).abs() < 1.0,
            "layer {layer} must be present"
        );
    }
    assert!(at(1, 1, middle) < at(1, 2, middle), "back1 before front2");
    assert!(
        !maps.test(1, Vec3::ZERO).inside,
        "the torus's hole is not clipped (convex-hull clipping would clip it)"
    );
    assert!(
        maps.test(1, Vec3::new(0.0, 0.0, 10.0)).inside,
        "inside the tube is clipped"
    );
    assert!(
        maps.test(1, Vec3::new(10.0, 0.0, 0.0)).inside,
        "inside the tube is clipped"
    );
    assert!(
        !maps.test(1, Vec3::new(0.0, 5.0, 10.0)).inside,
        "beside the tube is not"
    );
}

#[test]
fn bad_shapes_are_reported_and_the_rest_still_clip() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    let good = ClipShape::new(Shape::Sphere, Vec3::ZERO, 8.0);
    let mut nan = good.clone();
    nan.translation[1] = f32::NAN;
    let mut flat = good.clone();
    flat.scale[2] = 0.0;
    let missing = ClipShape::new(
        Shape::Mesh {
            path: "/nonexistent/shape.stl".into(),
        },
        Vec3::ZERO,
        1.0,
    );
    let mut many = vec![nan, flat, missing, good.clone()];
    many.extend(std::iter::repeat_n(good.clone(), 8));
    let stats = s
        .cao
        .update(
            &s.gpu,
            &s.vol.texels,
            pose(&many, reach, CaoMode::Selective),
        )
        .unwrap_or_else(|e| panic!("{e}"));
    let errors = stats.clip_errors.join("\n");
    assert!(errors.contains("non-finite"), "{errors}");
    assert!(errors.contains("scale must be positive"), "{errors}");
    assert!(errors.contains("/nonexistent/shape.stl"), "{errors}");
    assert!(errors.contains("at most 8"), "{errors}");
    assert!(stats.clipped > 0, "the good shapes still clip");
}

#[test]
fn clipped_rendering_matches_the_cpu_twin() {
    use volao::render::cpu;
    use volao::render::image::{Image, Tolerance, check};
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::TwentySix);
    let reach = s.reach();
    let half = Vec3::from(s.vol.texels.extent()) * 0.5;
    let mut rng = Rng(17);
    let shapes = [
        random_shape(&mut rng, &Shape::Sphere, half, ClipMode::Carve),
        random_shape(
            &mut rng,
            &Shape::Torus { tube: 0.35 },
            half,
            ClipMode::Carve,
        ),
    ];
    // AO read at the sample: V_AO steps to 1 where the shapes clip, and a read point
    // 2 voxels off the surface, placed by each side's own rounding of the gradient,
    // lands on either side of that step at a few per cent of the pixels.
    s.frame.settings.ao_offset = 0.0;
    let (ao, gpu_pixels, _) = s.frame(&shapes, CaoMode::Selective, reach);
    let maps = s
        .cao
        .clip
        .read_back(&s.gpu)
        .unwrap_or_else(|e| panic!("{e}"));
    let (mut cv, occ) = cpu::prepare(&s.vol.texels, &s.vol.lut);
    cv.ao = Some(ao);
    cv.clip = Some(maps);
    let c = cpu::render(&s.vol.texels, &cv, &s.vol.lut, &occ, &s.frame);
    let g = Image {
        width: s.frame.width,
        height: s.frame.height,
        pixels: gpu_pixels,
    };
    let twin = Tolerance {
        max_channel_diff: 3,
        max_outlier_fraction: 0.01,
        max_outlier_diff: 64,
    };
    let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cao");
    check("twin_cao_clipped", &g, &c, twin, &out).unwrap_or_else(|e| panic!("{e}"));
    // The clipping shows: without it the twin renders another image (these two small
    // random shapes carve a few dozen pixels of the 48² frame), and the GPU's image is
    // nearer the clipped one.
    cv.clip = None;
    let unclipped = cpu::render(&s.vol.texels, &cv, &s.vol.lut, &occ, &s.frame);
    let carved = volao::render::image::compare(&c, &unclipped, twin);
    assert!(
        carved.outliers >= 10 && carved.max_diff >= 16,
        "the shapes carve nothing visible: {carved:?}"
    );
    let to_clipped = volao::render::image::compare(&g, &c, Tolerance::EXACT).mean_diff;
    let to_unclipped = volao::render::image::compare(&g, &unclipped, Tolerance::EXACT).mean_diff;
    assert!(
        to_clipped < to_unclipped,
        "GPU image {to_clipped} from the clipped twin, {to_unclipped} from the unclipped"
    );
}

/// A cut face is lit like an open surface: inside carved material the density's gradient
/// is not the cut's (here layers across the face, as a skull's diploë between its
/// tables), and AO read off the sample along it lands deeper in the material, where every
/// voxel is occluded: the face of a pocket carved into a layered block went dark. It is
/// now lit without a direction and its AO read back along the ray, in the carved space,
/// so with CAO it keeps the brightness it has without AO, composited and as an
/// isosurface (whose hit there follows a clipped point inside the material), GPU and
/// CPU twin.
#[test]
fn a_carved_pocket_keeps_its_light_with_cao_gpu_and_cpu() {
    use volao::render::cpu;
    use volao::render::image::{Image, Tolerance, check};
    let n = 40;
    let v = common::u8_volume([n; 3], |x, y, z| {
        let inside = |c: usize| (4..36).contains(&c);
        if inside(x) && inside(y) && inside(z) {
            (140.0 + 90.0 * (0.8 * x as f32).sin()) as u8
        } else {
            0
        }
    });
    let tf = common::ramp_tf(30.0, 50.0, 0.9);
    let gpu = device();
    let settings = RenderSettings::default();
    let mut vol = RenderVolume::from_texels(&gpu, texels(&v), &tf, settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let bricks = Coverage::Readable.bricks(&vol.texels, vol.ranges(), &tf);
    let mut cao = CaoGpu::new(&gpu, &vol, setup(&tf, &rays, SAMPLES), bricks, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    // Seen from +y (azimuth 0); the pocket is 20 × 20 mm and 10 deep, its face at y = 26.
    let frame = Frame {
        camera: Camera::default(),
        settings,
        width: 48,
        height: 48,
    };
    let pocket = ClipShape {
        shape: Shape::Box,
        translation: [0.0, 14.0, 0.0],
        rotation_deg: [0.0; 3],
        scale: [10.0, 8.0, 10.0],
        mode: ClipMode::Carve,
        cuts: Cuts::All,
    };
    let reach = reach_mm(SAMPLES, vol.texels.spacing);
    let stats = cao
        .update(
            &gpu,
            &vol.texels,
            pose(&[pocket], reach, CaoMode::Selective),
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        stats.clip_errors.is_empty() && stats.clipped > 0,
        "{stats:?}"
    );
    let ao = cao
        .read(&gpu, CaoVolume::Ambient)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion_view(cao.ao_view());
    for mode in [RenderMode::Composite, RenderMode::Iso(Some(40.0))] {
        let frame = Frame {
            settings: RenderSettings { mode, ..settings },
            ..frame
        };
        let with_ao = rc
            .render(&gpu, &vol, &frame, Some(&cao.clip))
            .unwrap_or_else(|e| panic!("{e}"));
        // Cut faces are found alike with and without the ray caster's skipping.
        let unskipped = Frame {
            settings: RenderSettings {
                empty_space_skipping: false,
                ..frame.settings
            },
            ..frame
        };
        let unskipped = rc
            .render(&gpu, &vol, &unskipped, Some(&cao.clip))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            unskipped.pixels == with_ao.pixels,
            "{mode:?}: skipping changed pixels"
        );
        let maps = cao.clip.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
        let (mut cv, occ) = cpu::prepare(&vol.texels, &vol.lut);
        cv.clip = Some(maps);
        let without_ao = cpu::render(&vol.texels, &cv, &vol.lut, &occ, &frame);
        cv.ao = Some(ao.clone());
        let twin = cpu::render(&vol.texels, &cv, &vol.lut, &occ, &frame);
        // The middle of the pocket's face: the central 8 × 8 pixels.
        let face = |pixels: &[[u8; 4]]| {
            let mut sum = 0.0;
            for y in 20..28 {
                for x in 20..28 {
                    sum += pixels[y * 48 + x][..3]
                        .iter()
                        .map(|&c| c as f64)
                        .sum::<f64>()
                        / 3.0;
                }
            }
            sum / 64.0
        };
        let (lit, bare) = (face(&with_ao.pixels), face(&without_ao.pixels));
        // Lit without a direction, the white face is nearly white (it was 110 in the
        // composite frame and 106 as an isosurface, lit along the layers' gradient).
        assert!(
            bare > 200.0,
            "{mode:?}: the face is lit without AO: {bare:.1}"
        );
        assert!(
            lit >= 0.95 * bare,
            "{mode:?}: the carved face with CAO {lit:.1} against {bare:.1} without AO"
        );
        assert!(
            (face(&twin.pixels) - lit).abs() < 2.0,
            "{mode:?}: the CPU twin's face {:.1}",
            face(&twin.pixels)
        );
        let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cao");
        let g = Image {
            width: 48,
            height: 48,
            pixels: with_ao.pixels,
        };
        let tolerance = Tolerance {
            max_channel_diff: 3,
            max_outlier_fraction: 0.01,
            max_outlier_diff: 64,
        };
        check(
            &format!("twin_cao_pocket_{mode:?}"),
            &g,
            &twin,
            tolerance,
            &out,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// The viewer clips an image being dragged with a copy of CAO's maps posed for the
/// image's shapes (`ClipMaps::posed`), so that CAO's update keeps its own pose: the copy
/// clips as the maps moved to that pose do, leaves the maps' pose alone, and is refused
/// where other maps would be needed.
#[test]
fn maps_posed_for_an_image_clip_like_the_maps_moved_there() {
    use volao::clip::gpu::ClipMaps;
    let v = engine();
    let s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    let radius = Vec3::from(s.vol.texels.extent()).length() * 0.5;
    let at = |x: f32| ClipShape::new(Shape::Sphere, Vec3::new(x, 4.0, 6.0), 14.0);
    let mut maps = ClipMaps::new(&s.gpu).unwrap_or_else(|e| panic!("{e}"));
    let render = |maps: &ClipMaps| {
        s.rc.render(&s.gpu, &s.vol, &s.frame, Some(maps))
            .unwrap_or_else(|e| panic!("{e}"))
            .pixels
    };
    let (left, right, far) = ([at(-6.0)], [at(6.0)], [at(-20.0)]);
    let both = [at(6.0), at(-6.0)];
    let request = |shapes, resolution| MapRequest {
        shapes,
        volume_radius: radius,
        reach_mm: reach,
        resolution,
    };
    let report = maps
        .update(&s.gpu, request(&left, MAP))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    let before = render(&maps);
    let posed = maps
        .posed(&s.gpu, request(&right, MAP))
        .expect("the same sphere elsewhere needs no new maps");
    let copy = render(&posed);
    assert_eq!(render(&maps), before, "the maps keep their pose");
    maps.update(&s.gpu, request(&right, MAP))
        .unwrap_or_else(|e| panic!("{e}"));
    let moved = render(&maps);
    assert_ne!(moved, before, "the shape's move shows");
    assert_eq!(copy, moved, "the copy clips as the maps moved there");
    let resized = ClipShape::new(Shape::Sphere, Vec3::new(6.0, 4.0, 6.0), 18.0);
    assert!(
        maps.posed(&s.gpu, request(std::slice::from_ref(&resized), MAP))
            .is_none()
    );
    // Whether an update would keep the copy valid (only re-pose the maps).
    assert!(maps.fits(&s.gpu, request(&far, MAP)));
    assert!(!maps.fits(&s.gpu, request(std::slice::from_ref(&resized), MAP)));
    assert!(!maps.fits(&s.gpu, request(&right, 2 * MAP)));
    assert!(maps.posed(&s.gpu, request(&both, MAP)).is_none());
}

/// Read back, the voxels no sample reads hold 1 in `V_PAO` and `V_AO` (what `volao ao
/// --visible-only` writes), never the GPU's `UNREAD` marker (2), including the voxels
/// the per-voxel test leaves out in bricks a frame did not visit.
#[test]
fn unread_voxels_read_back_as_one() {
    let mut s = scene(&engine(), Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    let shape = ClipShape::new(Shape::Sphere, Vec3::new(-12.0, -12.0, 0.0), 5.0);
    s.update(std::slice::from_ref(&shape), reach);
    let readable = s.cao.bricks().readable_mask(&s.vol.texels);
    assert!(readable.contains(&false), "the test needs unread voxels");
    for which in [CaoVolume::Precomputed, CaoVolume::Ambient] {
        let values = s.cao.read(&s.gpu, which).unwrap_or_else(|e| panic!("{e}"));
        let above = values.iter().filter(|&&v| v > 1.0).count();
        assert_eq!(above, 0, "{which:?}: {above} voxels above 1");
    }
}

/// Step IV's per-ray test (ao::sparse::Bricks::cut_balls): a voxel in a cut's dilation
/// none of whose LAO rays passes near the cut keeps `V_PAO`'s bits instead of being ray
/// cast. It leaves voxels out (fewer ray cast than with balls so wide that every ray
/// meets one), the frame stays exact, and without its margin (the texel's cell and the
/// sample's trilinear read, 1.5 voxel diagonals) it does not.
#[test]
fn rays_that_miss_every_cut_keep_v_pao() {
    let v = engine();
    let mut s = scene(&v, Preset::CaoSingleColor, RaySet::Six);
    let reach = s.reach();
    let diag = Vec3::from(s.vol.texels.spacing).length();
    let margin = s.cao.ray_test_margin_mm;
    assert_eq!(margin, volao::ao::sparse::RAY_TEST_MARGIN * diag);
    let shape = ClipShape::new(Shape::Sphere, Vec3::new(2.0, -3.0, 1.0), 9.0);
    let shapes = std::slice::from_ref(&shape);
    let tested = s.update(shapes, reach).recomputed;
    s.cao.ray_test_margin_mm = 1e4;
    let every_ray_meets = s.update(shapes, reach).recomputed;
    assert!(
        tested * 10 < every_ray_meets * 9,
        "the per-ray test should leave out voxels: {tested} ray cast against {every_ray_meets}"
    );
    s.cao.ray_test_margin_mm = margin;
    assert_exact(&mut s, shapes, reach, "the per-ray test");
    let (full, _, _) = s.frame(shapes, CaoMode::Full, reach);
    s.cao.ray_test_margin_mm = 0.0;
    let (tight, _, _) = s.frame(shapes, CaoMode::Selective, reach);
    let readable = readable_voxels(&s.vol.texels, &s.tf);
    let wrong = differing_readable(&tight, &full, &readable);
    assert!(
        wrong > 0,
        "the per-ray test without its margin must break exactness"
    );
}
