//! Segmentations inside the ray cast, on the label maps of `../shared/data/labels/`:
//! segment-aware CAO equals LAO recomputed every frame with the same clipping (0
//! differing pixels, sparse and `--no-skipping`, several poses); the ray caster with a
//! segmentation matches its CPU twin in every mode; golden images of colour, hidden
//! segments, outlines and segment-aware carving; a segmentation's look changes only what
//! it should. GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{data, device, differing};
use glam::{DVec3, Vec3};
use volao::ao::cao::{CaoGpu, CaoMode, CaoSetup, Pose, reach_mm};
use volao::ao::lao::Rays;
use volao::ao::rays::RaySet;
use volao::ao::sparse::Coverage;
use volao::clip::{ClipMode, ClipShape, Cuts, Shape};
use volao::labels::style::{self, SegmentStyle, Styles};
use volao::labels::{LabelMap, SegmentKey};
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::{Frame, Image, RenderMode, RenderSettings, Shading, cpu};
use volao::sample::SegmentSampler;
use volao::texels::segments::SegmentTexels;
use volao::tf::{Preset, TransferFunction};
use volao::volume::Volume;

fn out_dir() -> std::path::PathBuf {
    let d = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("segments");
    std::fs::create_dir_all(&d).expect("output dir");
    d
}

/// The `size` voxels of `v` from `origin`, placed where they were (the affine moved by
/// the origin), so that a label map lands on them by the affines.
fn crop_placed(v: &Volume, origin: [usize; 3], size: [usize; 3]) -> Volume {
    let mut out = common::crop(v, origin, size);
    let o = DVec3::new(origin[0] as f64, origin[1] as f64, origin[2] as f64);
    out.orientation = v.orientation;
    out.orientation.offset += v.orientation.linear * o;
    out
}

/// A CT crop and its segmentation placed on it.
struct Pair {
    name: &'static str,
    image: Volume,
    labels: LabelMap,
}

fn pair(name: &'static str, image: &str, seg: &str, origin: [usize; 3], size: [usize; 3]) -> Pair {
    let full = volao::volume::load(&data(image), &Default::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras();
    let image = crop_placed(&full, origin, size);
    let labels = volao::labels::load(&data(seg), None, &image)
        .unwrap_or_else(|e| panic!("{e}"))
        .labels;
    Pair {
        name,
        image,
        labels,
    }
}

/// The lumbar spine of the TotalSegmentator example with the aorta and vena cava.
fn totalsegmentator() -> Pair {
    pair(
        "totalsegmentator",
        "labels/totalsegmentator/example_ct.nii.gz",
        "labels/totalsegmentator/example_seg_fast_force_split.nii.gz",
        [36, 14, 56],
        [48, 48, 40],
    )
}

/// The middle of the Slicer chest CT: spine, ribs, both lungs, with the overlapping layer.
fn slicer() -> Pair {
    pair(
        "slicer",
        "labels/slicer/CTChest4.nrrd",
        "labels/slicer/SegmentationOverlapping.seg.nrrd",
        [40, 40, 0],
        [48, 48, 34],
    )
}

/// Default styles with the segments `pattern` names hidden (`--segment PATTERN:hide`).
fn hiding(p: &Pair, pattern: &str) -> Styles {
    let mut styles = Styles::default();
    styles
        .apply(&p.labels, &format!("{pattern}:hide"))
        .unwrap_or_else(|e| panic!("{e}"));
    styles
}

/// What stays standing inside a cut: bones and vessels.
fn skeleton_and_vessels(p: &Pair) -> Vec<String> {
    let names: &[&str] = match p.name {
        "totalsegmentator" => &[
            "vertebrae*",
            "rib*",
            "sacrum",
            "hip*",
            "aorta",
            "inferior_vena_cava",
        ],
        _ => &["ribs", "*vertebral*"],
    };
    names
        .iter()
        .filter(|n| !p.labels.find(n).is_empty())
        .map(|n| n.to_string())
        .collect()
}

fn texels_of(p: &Pair, styles: &Styles, shapes: &[ClipShape]) -> SegmentTexels {
    let classes = style::Classes::of(&p.labels).unwrap_or_else(|e| panic!("{e}"));
    style::segment_texels(&p.labels, &classes, styles, shapes)
}

fn frame(settings: RenderSettings, size: u32) -> Frame {
    common::oblique_frame(settings, size)
}

const MAP: u32 = 128;
const SAMPLES: u32 = 8;

/// A sphere at `centre` (mm from the volume's centre) of radius `r` cutting `cuts`.
fn sphere(centre: Vec3, r: f32, cuts: Cuts) -> ClipShape {
    ClipShape {
        cuts,
        ..ClipShape::new(Shape::Sphere, centre, r)
    }
}

/// Sparse CAO, sparse LAO every frame and dense LAO every frame, with segment-aware
/// carving and a hidden segment: the same pixels for every pose.
fn cao_exactness(p: &Pair, seed: u64) {
    let gpu = device();
    let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
    let settings = RenderSettings {
        ambient: 0.8,
        ..Default::default()
    };
    let keep = skeleton_and_vessels(p);
    assert!(!keep.is_empty(), "{}: nothing to keep standing", p.name);
    let half = Vec3::from(p.image.extent_mm()) * 0.5;
    let r = half.min_element() * 0.6;
    let mut styles = Styles::default();
    // One segment hidden: V_PAO, V_o and the image all read the weight.
    let hidden = p
        .labels
        .segments
        .iter()
        .find(|s| s.voxels > 500)
        .map(|s| s.key);
    if let Some(k) = hidden {
        styles.set(
            k,
            SegmentStyle {
                visible: false,
                ..Default::default()
            },
        );
    }
    let shape = |c: Vec3| sphere(c, r, Cuts::Except(keep.clone()));
    let segments = texels_of(p, &styles, &[shape(Vec3::ZERO)]);
    // The same sphere cutting everything (which segments a shape cuts is the class
    // table's: the pose's shape leaves it alone).
    let cut_all = texels_of(p, &styles, &[sphere(Vec3::ZERO, r, Cuts::All)]);
    let mut vol = RenderVolume::from_texels(&gpu, common::texels(&p.image), &tf, 1.0)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_segments(&gpu, Some(segments.clone()));
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let setup = CaoSetup {
        tf: &tf,
        rays: &rays,
        samples: SAMPLES,
        msaa: 32,
    };
    let make = |coverage: Coverage| {
        let bricks = coverage.bricks(&vol.texels, vol.ranges(), &tf);
        CaoGpu::new(&gpu, &vol, setup, bricks, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"))
    };
    let mut sparse = make(Coverage::Readable);
    let mut dense = make(Coverage::Dense);
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let f = frame(settings, 48);
    let reach = reach_mm(SAMPLES, vol.texels.spacing);
    let mut run = |cao: &mut CaoGpu, shapes: &[ClipShape], mode: CaoMode, s: &SegmentTexels| {
        // The class table changes in place (the same classes): CAO's bind groups hold it.
        vol.set_segments(&gpu, Some(s.clone()));
        let pose = Pose {
            shapes,
            resolution: MAP,
            reach_mm: reach,
            mode,
        };
        let stats = cao
            .update(&gpu, &vol.texels, pose)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(stats.clip_errors.is_empty(), "{:?}", stats.clip_errors);
        vol.set_ambient_occlusion_view(cao.ao_view());
        let image = rc
            .render(&gpu, &vol, &f, Some(&cao.clip))
            .unwrap_or_else(|e| panic!("{e}"));
        (image.pixels, stats.category_b)
    };
    let mut rng = common::Rng(seed);
    let mut u = || (rng.next() >> 11) as f32 / (1u64 << 53) as f32;
    let mut recomputed = 0;
    let mut kept_something = false;
    for pose in 0..4 {
        let c = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * half * 0.8;
        let shapes = [shape(c)];
        let (cao, b) = run(&mut sparse, &shapes, CaoMode::Selective, &segments);
        let (full, _) = run(&mut sparse, &shapes, CaoMode::Full, &segments);
        let (naive, _) = run(&mut dense, &shapes, CaoMode::Full, &segments);
        let what = format!("{} pose {pose} at {c}", p.name);
        assert_eq!(differing(&cao, &full), 0, "{what}: CAO vs LAO every frame");
        assert_eq!(
            differing(&cao, &naive),
            0,
            "{what}: CAO vs dense LAO every frame"
        );
        recomputed += b;
        // The kept segments must make a difference.
        let (everything, _) = run(&mut sparse, &shapes, CaoMode::Selective, &cut_all);
        kept_something |= differing(&cao, &everything) > 0;
    }
    assert!(recomputed > 0, "{}: no pose recomputed a voxel", p.name);
    assert!(
        kept_something,
        "{}: keeping {keep:?} changed no pixel",
        p.name
    );
}

#[test]
fn segment_aware_cao_equals_lao_every_frame_totalsegmentator() {
    cao_exactness(&totalsegmentator(), 7);
}

#[test]
fn segment_aware_cao_equals_lao_every_frame_slicer_with_its_overlapping_layer() {
    let p = slicer();
    assert_eq!(p.labels.layers.len(), 2, "the overlapping layer loads");
    cao_exactness(&p, 11);
}

/// Styles that show every feature: a replaced colour, a tinted one, a hidden segment,
/// an outline, unlabelled voxels faint.
fn showcase(p: &Pair) -> Styles {
    let mut styles = Styles {
        unlabelled: SegmentStyle {
            opacity: 0.3,
            ..Default::default()
        },
        segments_default: SegmentStyle {
            replace: true,
            ..Default::default()
        },
        ..Default::default()
    };
    let present: Vec<SegmentKey> = p
        .labels
        .segments
        .iter()
        .filter(|s| s.voxels > 200)
        .map(|s| s.key)
        .collect();
    let mut change = |i: usize, f: &dyn Fn(&mut SegmentStyle)| {
        if let Some(&k) = present.get(i) {
            let mut s = styles.get(k);
            f(&mut s);
            styles.set(k, s);
        }
    };
    change(0, &|s| s.visible = false);
    change(1, &|s| s.outline = true);
    change(2, &|s| s.replace = false);
    styles
}

/// The twin tolerance of an isosurface with a segmentation: as [`common::TWIN`], but an
/// outlier may differ by anything. Where the surface meets a segment boundary, the
/// nearest voxel's class (tint or replace) and whether the filtered weight reaches ½
/// decide; the GPU filters the 8-bit look in fixed point, so a hit a bisection step away
/// or the other class's colour shows at a few pixels (0.1 % of them here).
const SEGMENT_ISO_TWIN: volao::render::image::Tolerance = volao::render::image::Tolerance {
    max_outlier_diff: 255,
    ..common::TWIN
};

/// The ray caster with a segmentation (GPU) against its CPU twin, in every mode, and
/// with segment-aware carving.
#[test]
fn segmentation_rendering_matches_the_cpu_twin_in_every_mode() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for p in [totalsegmentator(), slicer()] {
        let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
        let styles = showcase(&p);
        let segments = texels_of(&p, &styles, &[]);
        let t = common::texels(&p.image);
        let mut vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        vol.set_segments(&gpu, Some(segments.clone()));
        for (mode, shading) in [
            (RenderMode::Composite, Shading::Phong),
            (RenderMode::Composite, Shading::None),
            (RenderMode::Mip, Shading::None),
            (RenderMode::Iso(Some(100.0)), Shading::Phong),
        ] {
            let settings = RenderSettings {
                mode,
                shading,
                jitter: false,
                step_voxels: 0.5,
                ..Default::default()
            };
            let f = frame(settings, 96);
            let image = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let lut = volao::sample::bake_lut(&tf, &t, 0.5);
            let (mut cv, occ) = cpu::prepare(&t, &lut);
            cv.segments = Some(SegmentSampler::new(&segments));
            let twin = cpu::render(&t, &cv, &lut, &occ, &f);
            let label = format!("segments_{}_{mode}_{shading:?}", p.name);
            let tol = match mode {
                RenderMode::Iso(_) => SEGMENT_ISO_TWIN,
                _ => common::TWIN,
            };
            if let Err(e) = common::twin(&label, &image, &twin, tol, &out_dir()) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A label map whose look changes nothing (every segment visible, white tint) renders
/// the pixels of the volume without one; hiding a segment changes only where it shows.
#[test]
fn a_plain_look_is_the_image_without_a_segmentation_and_hiding_changes_it() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtBone, &p.image.stats());
    let plain_style = SegmentStyle {
        color: Some([255; 3]),
        ..Default::default()
    };
    let plain = Styles {
        segments_default: plain_style,
        ..Default::default()
    };
    let t = common::texels(&p.image);
    let f = frame(RenderSettings::default(), 96);
    let mut vol = RenderVolume::from_texels(&gpu, t, &tf, 1.0).unwrap_or_else(|e| panic!("{e}"));
    let render = |vol: &RenderVolume| -> Image {
        rc.render(&gpu, vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let without = render(&vol);
    vol.set_segments(&gpu, Some(texels_of(&p, &plain, &[])));
    let with = render(&vol);
    // The only difference the weight gradient makes is where two classes meet (every
    // weight is 1 here, so none): the same pixels.
    assert_eq!(differing(&without.pixels, &with.pixels), 0);
    let mut hidden = plain.clone();
    for k in p.labels.find("vertebrae*") {
        hidden.set(
            k,
            SegmentStyle {
                visible: false,
                ..plain_style
            },
        );
    }
    vol.set_segments(&gpu, Some(texels_of(&p, &hidden, &[])));
    let without_spine = render(&vol);
    let changed = differing(&with.pixels, &without_spine.pixels);
    assert!(
        changed > 200,
        "hiding the vertebrae of a bone rendering changed {changed} pixels"
    );
}

/// Golden images (≤ 256²) of colour, hidden segments, outlines and segment-aware
/// carving with AO.
#[test]
fn golden_images_of_segmentations() {
    let gpu = std::sync::Arc::new(device());
    let mut failures = Vec::new();
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
    let settings = RenderSettings {
        step_voxels: 0.5,
        ..Default::default()
    };
    let f = frame(settings, 160);
    let keep = skeleton_and_vessels(&p);
    let carve = [sphere(
        Vec3::new(10.0, 40.0, 10.0),
        50.0,
        Cuts::Except(keep),
    )];
    let mut colour = Styles::default();
    colour.segments_default.replace = true;
    let mut hidden = colour.clone();
    hidden.unlabelled.visible = false;
    let mut outline = hidden.clone();
    outline.segments_default.outline = true;
    let ao = volao::ao::AoSettings {
        method: volao::ao::AoMethod::Cao,
        rays: RaySet::Fourteen,
        samples: SAMPLES,
        clip_resolution: MAP,
        ..Default::default()
    };
    for (stem, styles, shapes, ao) in [
        (
            "segments_colour",
            &colour,
            &[][..],
            volao::ao::AoSettings::default(),
        ),
        (
            "segments_hidden",
            &hidden,
            &[][..],
            volao::ao::AoSettings::default(),
        ),
        (
            "segments_outline",
            &outline,
            &[][..],
            volao::ao::AoSettings::default(),
        ),
        ("segments_carved_cao", &colour, &carve[..], ao),
    ] {
        let segments = texels_of(&p, styles, shapes);
        let job = volao::render::offscreen::RenderJob {
            clip: shapes,
            segments: Some(&segments),
            ..volao::render::offscreen::RenderJob::new(&p.image, &tf, &f, &ao)
        };
        let out = volao::render::offscreen::render(Some(&gpu), &job, &|_, _| {})
            .unwrap_or_else(|e| panic!("{stem}: {e}"));
        if let Err(e) = common::golden(stem, &out.image, &out_dir()) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Probing with a segment set keeps only the inside of the shape for those segments;
/// the others stay whole.
#[test]
fn a_probe_cuts_only_its_segments() {
    let p = totalsegmentator();
    let styles = Styles::default();
    let probe = ClipShape {
        mode: ClipMode::Probe,
        cuts: Cuts::Only(vec!["vertebrae*".into()]),
        ..ClipShape::new(Shape::Sphere, Vec3::ZERO, 10.0)
    };
    let t = texels_of(&p, &styles, &[probe]);
    let spine: Vec<SegmentKey> = p.labels.find("vertebrae*");
    // Class 0 (unlabelled) is not cut by the probe; a vertebra's class is.
    assert_eq!(t.table[0].carved_by, 0);
    let vertebra = t
        .classes
        .iter()
        .zip(0..)
        .find(|&(_, i)| {
            spine.contains(&SegmentKey {
                layer: 0,
                value: p.labels.layers[0][i],
            })
        })
        .map(|(&c, _)| c)
        .expect("a vertebra in the crop");
    assert_eq!(t.table[vertebra as usize].carved_by, 1);
}

/// Hiding a segment updates `V_PAO` only within the rays' reach of its bricks, to the
/// bits a recomputation gives; a carved frame after it gives the recomputation's pixels.
#[test]
fn hiding_a_segment_updates_v_pao_near_it_to_the_bits_of_a_recomputation() {
    use volao::ao::cao::CaoVolume;
    let gpu = device();
    for p in [totalsegmentator(), slicer()] {
        let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
        let keep = skeleton_and_vessels(&p);
        let shapes = [sphere(Vec3::new(0.0, 20.0, 0.0), 30.0, Cuts::Except(keep))];
        let shown = Styles::default();
        let mut hidden = shown.clone();
        // The smallest segment with voxels here: few bricks change.
        let small = p
            .labels
            .segments
            .iter()
            .filter(|s| s.voxels > 0)
            .min_by_key(|s| s.voxels)
            .expect("a segment")
            .key;
        hidden.set(
            small,
            SegmentStyle {
                visible: false,
                ..Default::default()
            },
        );
        let before = texels_of(&p, &shown, &shapes);
        let after = texels_of(&p, &hidden, &shapes);
        let changed = before.voxels_changed_by(&after.table);
        let rays = Rays::uniform(RaySet::Fourteen.directions());
        let setup = CaoSetup {
            tf: &tf,
            rays: &rays,
            samples: SAMPLES,
            msaa: 32,
        };
        let upload = |s: &SegmentTexels| {
            let mut vol = RenderVolume::from_texels(&gpu, common::texels(&p.image), &tf, 1.0)
                .unwrap_or_else(|e| panic!("{e}"));
            vol.set_segments(&gpu, Some(s.clone()));
            vol
        };
        let new_cao = |vol: &RenderVolume| {
            let bricks = Coverage::Readable.bricks(&vol.texels, vol.ranges(), &tf);
            CaoGpu::new(&gpu, vol, setup, bricks, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"))
        };
        let reach = reach_mm(SAMPLES, p.image.spacing);
        let pose = Pose {
            shapes: &shapes,
            resolution: MAP,
            reach_mm: reach,
            mode: CaoMode::Selective,
        };
        // Recomputed from scratch with the segment hidden.
        let fresh_vol = upload(&after);
        let mut fresh = new_cao(&fresh_vol);
        let fresh_pao = fresh
            .read(&gpu, CaoVolume::Precomputed)
            .unwrap_or_else(|e| panic!("{e}"));
        // Shown, carved for a frame, then the segment hidden and V_PAO updated.
        let mut vol = upload(&before);
        let mut cao = new_cao(&vol);
        cao.update(&gpu, &vol.texels, pose)
            .unwrap_or_else(|e| panic!("{e}"));
        vol.set_segments(&gpu, Some(after.clone()));
        let update = cao
            .update_pao(&gpu, &vol.texels, &changed)
            .unwrap_or_else(|e| panic!("{e}"));
        let pao = cao
            .read(&gpu, CaoVolume::Precomputed)
            .unwrap_or_else(|e| panic!("{e}"));
        let differ = (0..pao.len())
            .filter(|&i| pao[i].to_bits() != fresh_pao[i].to_bits())
            .count();
        assert_eq!(
            differ, 0,
            "{}: V_PAO after the update vs recomputed",
            p.name
        );
        assert!(
            update.lao_bricks > 0 && update.lao_bricks < update.bricks,
            "{}: the update should ray cast some bricks, not all: {update:?}",
            p.name
        );
        // The next carved frame: the recomputation's pixels.
        let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
        let f = frame(RenderSettings::default(), 48);
        let image = |cao: &mut CaoGpu, vol: &mut RenderVolume| {
            cao.update(&gpu, &vol.texels, pose)
                .unwrap_or_else(|e| panic!("{e}"));
            vol.set_ambient_occlusion_view(cao.ao_view());
            rc.render(&gpu, vol, &f, Some(&cao.clip))
                .unwrap_or_else(|e| panic!("{e}"))
                .pixels
        };
        let mut fresh_vol = fresh_vol;
        let (a, b) = (image(&mut cao, &mut vol), image(&mut fresh, &mut fresh_vol));
        assert_eq!(
            differing(&a, &b),
            0,
            "{}: the carved frame after the update",
            p.name
        );
    }
}

/// LAO with a segment hidden (GPU) against its CPU twin, and CAO's step IV with
/// segment-aware carving (`V_o`, the mask) against its twin: as close as without a
/// segmentation (`tests/lao.rs`, `tests/cao.rs`).
#[test]
fn lao_and_cao_step_iv_with_a_segmentation_match_their_cpu_twins() {
    use volao::ao::cao::{CaoVolume, clip_volume_cpu_reading};
    use volao::ao::lao::{LaoGpu, LaoSetup, lao_cpu_reading, lao_lut};
    let gpu = device();
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    for p in [totalsegmentator(), slicer()] {
        let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
        let keep = skeleton_and_vessels(&p);
        let shapes = [sphere(Vec3::new(0.0, 15.0, 0.0), 35.0, Cuts::Except(keep))];
        let mut styles = Styles::default();
        let biggest = p
            .labels
            .segments
            .iter()
            .max_by_key(|s| s.voxels)
            .expect("a segment");
        styles.set(
            biggest.key,
            SegmentStyle {
                opacity: 0.3,
                ..Default::default()
            },
        );
        let segments = texels_of(&p, &styles, &shapes);
        let sampler = SegmentSampler::new(&segments);
        let t = common::texels(&p.image);
        let mut vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 1.0).unwrap_or_else(|e| panic!("{e}"));
        vol.set_segments(&gpu, Some(segments));
        // LAO: dense, every voxel.
        let lut = lao_lut(&tf, &t);
        let rays = Rays::uniform(RaySet::Fourteen.directions());
        let setup = LaoSetup {
            lut: &lut,
            rays: &rays,
            samples: 12,
        };
        let dense = Coverage::Dense.bricks(&t, vol.ranges(), &tf);
        let g = lao
            .compute(&gpu, &vol, setup, &dense, &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"));
        let c = lao_cpu_reading(&t, setup, Some(&sampler), &dense, &|_, _| {});
        let max = g
            .iter()
            .zip(&c)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        eprintln!("{}: LAO max |GPU − CPU| = {max:.2e}", p.name);
        // As without a segmentation (tests/lao.rs).
        assert!(
            max <= 1.0 / 255.0,
            "{}: LAO GPU vs CPU twin differ by {max}",
            p.name
        );
        // The weight changes LAO: without it the twin differs.
        let plain = volao::ao::lao::lao_cpu(&t, &lut, &rays, 12, &dense, &|_, _| {});
        let changed = plain
            .iter()
            .zip(&c)
            .filter(|(a, b)| (*a - *b).abs() > 0.01)
            .count();
        assert!(
            changed > 100,
            "{}: the weight changed {changed} voxels' LAO",
            p.name
        );
        // CAO step IV, dense (the paper's mask).
        let cao_setup = CaoSetup {
            tf: &tf,
            rays: &rays,
            samples: SAMPLES,
            msaa: 32,
        };
        let mut cao = CaoGpu::new(&gpu, &vol, cao_setup, dense.clone(), &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"));
        let pose = Pose {
            shapes: &shapes,
            resolution: MAP,
            reach_mm: reach_mm(SAMPLES, t.spacing),
            mode: CaoMode::Selective,
        };
        cao.update(&gpu, &t, pose).unwrap_or_else(|e| panic!("{e}"));
        let maps = cao.clip.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
        let (mut v_o, v_m) = clip_volume_cpu_reading(&t, &lut, &maps, 32, Some(&sampler));
        cao.round_as_stored(&mut v_o);
        let g_o = cao
            .read(&gpu, CaoVolume::ClippedOpacity)
            .unwrap_or_else(|e| panic!("{e}"));
        let g_m = cao
            .read(&gpu, CaoVolume::Mask)
            .unwrap_or_else(|e| panic!("{e}"));
        // As in tests/cao.rs: a sample on a map boundary may round the other way (one
        // mask class, one MSAA sample of V_o) for 0.1 % of voxels, nothing else.
        let mask_flips = v_m.iter().zip(&g_m).filter(|(a, b)| a != b).count();
        assert!(
            mask_flips * 1000 <= v_m.len(),
            "{}: {mask_flips} voxels of V_m differ",
            p.name
        );
        let flips = v_o
            .iter()
            .zip(&g_o)
            .filter(|(a, b)| (*a - *b).abs() > a.abs().max(b.abs()) * 1e-3 + 1e-6)
            .count();
        assert!(
            flips * 1000 <= v_o.len(),
            "{}: {flips} voxels of V_o differ",
            p.name
        );
        assert!(g_m.contains(&0.0), "{}: something is clipped", p.name);
    }
}

/// The AO methods read the segmentation's weights through the engine (GPU stages, or
/// the twins where the engine picks them: the filters on a CPU adapter): hiding a
/// segment changes LAO's, cone tracing's, positional AO's and the filters' factors.
#[test]
fn ao_methods_read_the_segment_weights() {
    use volao::ao::{AoEngine, AoInput, AoMethod, AoRequest, AoSettings};
    let gpu = std::sync::Arc::new(device());
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtBone, &p.image.stats());
    let hidden = hiding(&p, "vertebrae*");
    for method in [AoMethod::Lao, AoMethod::Cone, AoMethod::Vao, AoMethod::Cdf] {
        let settings = AoSettings {
            method,
            rays: RaySet::Fourteen,
            samples: SAMPLES,
            statistic: volao::ao::StatisticSource::Opacity,
            ..Default::default()
        };
        let request = AoRequest {
            tf: &tf,
            settings: &settings,
            clip: None,
            coverage: Coverage::Dense,
            view: None,
        };
        let ambient = |styles: &Styles| {
            let mut vol = RenderVolume::from_texels(&gpu, common::texels(&p.image), &tf, 1.0)
                .unwrap_or_else(|e| panic!("{e}"));
            vol.set_segments(&gpu, Some(texels_of(&p, styles, &[])));
            let computed = AoEngine::on(Some(std::sync::Arc::clone(&gpu)))
                .compute(AoInput::Uploaded(&vol), &request, &|_, _| {})
                .unwrap_or_else(|e| panic!("{e}"));
            match computed.ambient {
                volao::ao::Ambient::Values(v) => v,
                other => panic!("{method:?}: {other:?}"),
            }
        };
        let (shown, without_spine) = (ambient(&Styles::default()), ambient(&hidden));
        let changed = shown
            .iter()
            .zip(&without_spine)
            .filter(|(a, b)| (*a - *b).abs() > 0.01)
            .count();
        assert!(
            changed > 500,
            "{method:?}: hiding the spine changed {changed} voxels' AO"
        );
    }
}

/// The light volume with a segmentation (GPU) against its CPU twin: the weights dim it
/// and a shape lets light through only where it cuts the segments.
#[test]
fn the_light_volume_with_a_segmentation_matches_its_cpu_twin() {
    use volao::clip::gpu::{ClipMaps, MapRequest};
    use volao::render::shadow::{LightGpu, Lit, light_cpu_reading, light_direction, light_lut};
    let gpu = device();
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtSoftTissue, &p.image.stats());
    let keep = skeleton_and_vessels(&p);
    let shapes = [sphere(Vec3::new(0.0, 25.0, 0.0), 30.0, Cuts::Except(keep))];
    let mut styles = Styles::default();
    let biggest = p
        .labels
        .segments
        .iter()
        .max_by_key(|s| s.voxels)
        .expect("a segment");
    styles.set(
        biggest.key,
        SegmentStyle {
            opacity: 0.2,
            ..Default::default()
        },
    );
    let segments = texels_of(&p, &styles, &shapes);
    let t = common::texels(&p.image);
    let dir = light_direction([0.2, 0.9, 0.3]).expect("a direction");
    let mut maps = ClipMaps::new(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let radius = Vec3::from(t.extent()).length() * 0.5;
    maps.update(&gpu, MapRequest::clipping(&shapes, radius, MAP))
        .unwrap_or_else(|e| panic!("{e}"));
    let lut = light_lut(&tf, &t);
    let g = gpu
        .stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(
            &gpu,
            Lit {
                texels: &t,
                segments: Some(&segments),
                lut: &lut,
            },
            dir,
            Some(&maps),
            &|_, _| {},
        )
        .unwrap_or_else(|e| panic!("{e}"));
    let cpu_maps = maps.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let sampler = SegmentSampler::new(&segments);
    let c = light_cpu_reading(&t, &lut, Some(&sampler), dir, Some(&cpu_maps), &|_, _| {});
    let worst = g
        .iter()
        .zip(&c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    eprintln!("light with a segmentation: max |GPU − CPU| = {worst:.2e}");
    assert!(worst < 2e-3, "GPU vs CPU: {worst}");
    let plain = light_cpu_reading(&t, &lut, None, dir, Some(&cpu_maps), &|_, _| {});
    let changed = plain
        .iter()
        .zip(&c)
        .filter(|(a, b)| (*a - *b).abs() > 0.01)
        .count();
    assert!(
        changed > 100,
        "the segmentation changed {changed} voxels' light"
    );
}

/// The filter AO methods with the opacity statistic read the segmentation's weights:
/// GPU against its CPU twin as close as without one (`tests/filter.rs`), and hiding
/// the spine changes the maps.
#[test]
fn filter_ao_of_opacity_reads_the_segment_weights_on_gpu_and_cpu_alike() {
    use volao::ao::StatisticSource;
    use volao::ao::filter::{AmbientMap, FilterGpu, Source, compute_cpu};
    let gpu = device();
    let filter = gpu.stage::<FilterGpu>().unwrap_or_else(|e| panic!("{e}"));
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtBone, &p.image.stats());
    let hidden = hiding(&p, "vertebrae*");
    let t = common::texels(&p.image);
    let maps = [AmbientMap::Cdf, AmbientMap::Gauss, AmbientMap::Penner];
    let r = [5u32; 3];
    let mut results = Vec::new();
    for styles in [&Styles::default(), &hidden] {
        let segments = texels_of(&p, styles, &[]);
        let mut vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        vol.set_segments(&gpu, Some(segments.clone()));
        let source = Source::new(&t, &tf, StatisticSource::Opacity);
        let g = filter
            .compute(&gpu, &vol, &source, r, &maps)
            .unwrap_or_else(|e| panic!("{e}"));
        let c = compute_cpu(&t, &source.with_segments(Some(&segments)), r, &maps);
        for ((map, gm), cm) in maps.iter().zip(&g).zip(&c) {
            let max = gm
                .iter()
                .zip(cm)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(max <= 1e-3, "{map:?}: max |GPU − CPU| = {max}");
        }
        results.push(g);
    }
    for (i, map) in maps.iter().enumerate() {
        let changed = results[0][i]
            .iter()
            .zip(&results[1][i])
            .filter(|(a, b)| (*a - *b).abs() > 0.01)
            .count();
        assert!(
            changed > 200,
            "{map:?}: hiding the spine changed {changed} voxels"
        );
    }
}

/// Positional AO reads the segmentation's weights: the precomputed volume (GPU) against
/// its CPU twin, and hiding the spine changes it; the live mode in the ray caster
/// against the ray caster's twin.
#[test]
fn positional_ao_reads_the_segment_weights_on_gpu_and_cpu_alike() {
    use volao::ao::vao::{PositionalAo, VaoGpu, VaoInputs, VaoSettings, vao_cpu};
    let gpu = device();
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtBone, &p.image.stats());
    let s = VaoSettings {
        directions: 8,
        samples: 6,
        r_max_mm: 12.0,
        ..Default::default()
    };
    let hidden = hiding(&p, "vertebrae*");
    let t = common::texels(&p.image);
    let mut results = Vec::new();
    for styles in [&Styles::default(), &hidden] {
        let segments = texels_of(&p, styles, &[]);
        let mut vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        vol.set_segments(&gpu, Some(segments.clone()));
        let inputs = VaoInputs::new(&gpu, &t, &tf, &s)
            .unwrap_or_else(|e| panic!("{e}"))
            .with_segments(&gpu, Some(&segments));
        let g = gpu
            .stage::<VaoGpu>()
            .unwrap_or_else(|e| panic!("{e}"))
            .compute(&gpu, t.dims, &inputs, &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"));
        let twin = PositionalAo::new(&t, &tf, &s).with_segments(Some(&segments));
        let c = vao_cpu(&twin, t.dims, &|_, _| {});
        let max = g
            .iter()
            .zip(&c)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        eprintln!("positional AO with a segmentation: max |GPU − CPU| = {max:.2e}");
        // As without one (tests/vao.rs): the weights are read as f16, filtered in float.
        assert!(max <= 1e-4, "max |GPU − CPU| = {max}");
        // Live: the ray caster evaluates it per sample, GPU and twin.
        vol.set_live_vao(&gpu, &tf, Some(&s))
            .unwrap_or_else(|e| panic!("{e}"));
        let f = frame(
            RenderSettings {
                jitter: false,
                ..Default::default()
            },
            64,
        );
        let image = RayCaster::new(&gpu.device)
            .unwrap_or_else(|e| panic!("{e}"))
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let lut = volao::sample::bake_lut(&tf, &t, f.settings.step_voxels);
        let (mut cv, occ) = cpu::prepare(&t, &lut);
        cv.segments = Some(SegmentSampler::new(&segments));
        cv.live_vao = Some(twin);
        let twin_image = cpu::render(&t, &cv, &lut, &occ, &f);
        common::twin(
            "segments_live_vao",
            &image,
            &twin_image,
            common::TWIN,
            &out_dir(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        results.push(g);
    }
    let changed = results[0]
        .iter()
        .zip(&results[1])
        .filter(|(a, b)| (*a - *b).abs() > 0.01)
        .count();
    assert!(
        changed > 200,
        "hiding the spine changed {changed} voxels' positional AO"
    );
}

/// `volao render` with a segmentation and LAO, on the GPU and on the CPU twin
/// (`--cpu`): the twin's AO reads the segmentation too, so the images agree.
#[test]
fn rendering_with_a_segmentation_and_lao_on_gpu_and_cpu_alike() {
    use volao::render::offscreen::{RenderJob, render};
    let gpu = std::sync::Arc::new(device());
    let p = totalsegmentator();
    let tf = TransferFunction::preset(Preset::CtBone, &p.image.stats());
    let styles = hiding(&p, "vertebrae_L3");
    let segments = texels_of(&p, &styles, &[]);
    let ao = volao::ao::AoSettings {
        method: volao::ao::AoMethod::Lao,
        rays: RaySet::Fourteen,
        samples: SAMPLES,
        ..Default::default()
    };
    let f = frame(
        RenderSettings {
            jitter: false,
            ..Default::default()
        },
        96,
    );
    let job = RenderJob {
        segments: Some(&segments),
        ..RenderJob::new(&p.image, &tf, &f, &ao)
    };
    let g = render(Some(&gpu), &job, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let c = render(None, &job, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    assert!(c.notes.is_empty(), "{:?}", c.notes);
    common::twin(
        "segments_lao_cpu",
        &g.image,
        &c.image,
        common::TWIN,
        &out_dir(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
}
