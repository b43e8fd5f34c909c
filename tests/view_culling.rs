//! View-dependent AO (issue #46): LAO and CAO computed only for the voxels a visibility
//! pass marks give the image of the dense computation (`--no-skipping
//! --no-view-culling`), 0 differing pixels, over an orbit of cameras around volumes
//! carved and probed by overlapping shapes; a footprint one voxel too small, or one that
//! ignores the AO read offset, breaks it; the CPU twin's pass agrees.
//! GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{device, differing, real_crops};
use std::sync::Arc;
use volao::ao::lao::{LaoGpu, LaoSetup, Rays, lao_lut};
use volao::ao::rays::RaySet;
use volao::ao::sparse::Coverage;
use volao::ao::view::{Footprint, ViewMask};
use volao::ao::{AoMethod, AoSettings};
use volao::clip::{ClipMode, ClipShape, Cuts, Shape};
use volao::gpu::Gpu;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::offscreen::{RenderJob, Rendered, render};
use volao::render::{Camera, Frame, RenderSettings};
use volao::tf::TransferFunction;
use volao::volume::Volume;

/// Samples per LAO ray here (the default is 20; fewer keeps lavapipe quick).
const SAMPLES: u32 = 8;

/// Eight cameras around the volume, above, level and below it.
fn orbit(settings: RenderSettings) -> Vec<Frame> {
    (0..8)
        .map(|k| Frame {
            camera: Camera {
                azimuth_deg: 45.0 * k as f32 + 10.0,
                elevation_deg: [25.0, 0.0, -30.0, 60.0][k % 4],
                ..Default::default()
            },
            settings,
            width: 48,
            height: 48,
        })
        .collect()
}

fn ao(method: AoMethod, rays: RaySet) -> AoSettings {
    AoSettings {
        method,
        rays,
        samples: SAMPLES,
        clip_resolution: 128,
        ..Default::default()
    }
}

fn rendered(gpu: &Arc<Gpu>, job: &RenderJob<'_>) -> Rendered {
    render(Some(gpu), job, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"))
}

/// A sphere carving and a box probing, overlapping near the volume's centre.
fn carve_and_probe(v: &Volume) -> Vec<ClipShape> {
    let half = glam::Vec3::new(
        v.dims[0] as f32 * v.spacing[0],
        v.dims[1] as f32 * v.spacing[1],
        v.dims[2] as f32 * v.spacing[2],
    ) * 0.5;
    let r = half.min_element();
    let shape = |shape, translation: glam::Vec3, scale: [f32; 3], mode| ClipShape {
        shape,
        translation: translation.to_array(),
        rotation_deg: [20.0, 35.0, 0.0],
        scale,
        mode,
        cuts: Cuts::All,
    };
    vec![
        shape(
            Shape::Sphere,
            half * glam::Vec3::new(0.3, 0.4, 0.3),
            [r * 0.7; 3],
            ClipMode::Carve,
        ),
        shape(
            Shape::Box,
            half * glam::Vec3::new(-0.1, 0.0, -0.1),
            [half.x * 0.8, half.y * 0.8, half.z * 0.9],
            ClipMode::Probe,
        ),
    ]
}

/// With view culling, `method`'s image equals the dense `baseline`'s (no skipping, no
/// view culling) from every camera of the orbit; returns the fractions of the readable
/// voxels each view needed.
fn orbit_is_exact(
    method: AoMethod,
    baseline: AoMethod,
    clip: &dyn Fn(&Volume) -> Vec<ClipShape>,
) -> Vec<f64> {
    let gpu = Arc::new(device());
    let mut fractions = Vec::new();
    for (name, v, tf) in real_crops() {
        let shapes = clip(&v);
        let (culled, dense) = (ao(method, RaySet::Fourteen), ao(baseline, RaySet::Fourteen));
        let dense_settings = RenderSettings {
            empty_space_skipping: false,
            view_culling: false,
            ..Default::default()
        };
        let frames = orbit(RenderSettings::default())
            .into_iter()
            .zip(orbit(dense_settings));
        for (k, (frame, dense_frame)) in frames.enumerate() {
            let job = |frame, ao| RenderJob {
                clip: &shapes,
                ..RenderJob::new(&v, &tf, frame, ao)
            };
            let a = rendered(&gpu, &job(&frame, &culled));
            let b = rendered(&gpu, &job(&dense_frame, &dense));
            assert!(a.clip_errors.is_empty(), "{:?}", a.clip_errors);
            let view = a.view.expect("a view-culled render says what it needed");
            assert!(b.view.is_none(), "--no-view-culling ran a visibility pass");
            assert_eq!(
                differing(&a.image.pixels, &b.image.pixels),
                0,
                "{name}, camera {k} ({:?}): {method:?} culled to the view differs from dense {baseline:?}",
                frame.camera
            );
            fractions.push(view.fraction());
        }
    }
    // The test means something only if views needed part of the readable voxels.
    assert!(
        fractions.iter().all(|&f| f > 0.0) && fractions.iter().any(|&f| f < 0.8),
        "views should need some but not all readable voxels: {fractions:?}"
    );
    fractions
}

#[test]
fn view_culled_lao_equals_dense_lao_around_the_volume() {
    let f = orbit_is_exact(AoMethod::Lao, AoMethod::Lao, &|_| Vec::new());
    eprintln!("fractions of readable voxels needed: {f:.2?}");
}

#[test]
fn view_culled_cao_equals_dense_lao_every_frame_carved_and_probed() {
    let f = orbit_is_exact(AoMethod::Cao, AoMethod::LaoFull, &carve_and_probe);
    eprintln!("fractions of readable voxels needed: {f:.2?}");
}

/// LAO computed for the voxels `footprint` marks (`None`: every voxel, nothing
/// skipped), rendered: the pixels, and how many voxels were marked. Voxels not computed
/// hold 1.
fn lao_image(
    gpu: &Gpu,
    vol: &mut RenderVolume,
    tf: &TransferFunction,
    frame: &Frame,
    footprint: Option<Footprint>,
) -> (Vec<[u8; 4]>, usize) {
    let rc = gpu.stage::<RayCaster>().unwrap_or_else(|e| panic!("{e}"));
    let (bricks, marked) = match footprint {
        Some(footprint) => {
            let view = rc
                .mark_view(gpu, vol, frame, None, footprint, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let marked = view.count();
            let bricks = Coverage::Readable.bricks(&vol.texels, vol.ranges(), tf);
            (bricks.within(Arc::new(view)), marked)
        }
        None => {
            let n = vol.texels.dims.iter().product();
            (Coverage::Dense.bricks(&vol.texels, vol.ranges(), tf), n)
        }
    };
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let lut = lao_lut(tf, &vol.texels);
    let setup = LaoSetup {
        lut: &lut,
        rays: &rays,
        samples: SAMPLES,
    };
    let a = gpu
        .stage::<LaoGpu>()
        .and_then(|s| s.compute(gpu, vol, setup, &bricks, &|_, _| {}))
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion(gpu, &a);
    let image = rc
        .render(gpu, vol, frame, None)
        .unwrap_or_else(|e| panic!("{e}"));
    (image.pixels, marked)
}

#[test]
fn a_footprint_too_small_or_without_the_read_offset_breaks_exactness() {
    let gpu = device();
    let (_, v, tf) = real_crops().remove(0);
    let mut vol = RenderVolume::from_texels(&gpu, common::texels(&v), &tf, 0.5)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut broken = [0usize; 2];
    for frame in orbit(RenderSettings::default()) {
        let (dense, _) = lao_image(&gpu, &mut vol, &tf, &frame, None);
        let exact = Some(Footprint::Trilinear);
        let (culled, n) = lao_image(&gpu, &mut vol, &tf, &frame, exact);
        assert_eq!(differing(&culled, &dense), 0, "{:?}", frame.camera);
        for (k, footprint) in [Footprint::Nearest, Footprint::AtSample]
            .into_iter()
            .enumerate()
        {
            let (pixels, m) = lao_image(&gpu, &mut vol, &tf, &frame, Some(footprint));
            assert!(m < n, "{footprint:?} marked {m} voxels, the footprint {n}");
            broken[k] += differing(&pixels, &dense);
        }
    }
    assert!(
        broken.iter().all(|&b| b > 0),
        "the nearest voxel alone and the sample's own footprint must miss AO the image reads: {broken:?} pixels differ"
    );
    eprintln!("pixels differing with a broken footprint (nearest, at the sample): {broken:?}");
}

#[test]
fn the_cpu_twin_marks_what_the_gpu_marks_and_stays_exact() {
    let gpu = device();
    let (_, v, tf) = real_crops().remove(1);
    let texels = common::texels(&v);
    let vol =
        RenderVolume::from_texels(&gpu, texels.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let rc = gpu.stage::<RayCaster>().unwrap_or_else(|e| panic!("{e}"));
    let settings = RenderSettings::default();
    let lut = volao::sample::bake_lut(&tf, &texels, settings.step_voxels);
    let (mut cv, occ) = volao::render::cpu::prepare(&texels, &lut);
    for frame in orbit(settings).into_iter().step_by(3) {
        let on_gpu = rc
            .mark_view(&gpu, &vol, &frame, None, Footprint::Trilinear, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let twin = volao::render::cpu::mark_view(
            &texels,
            &mut cv,
            &lut,
            &occ,
            &frame,
            Footprint::Trilinear,
        );
        let mut either = on_gpu.clone();
        either.union(&twin);
        let disagree = either.count() - on_gpu.count().min(twin.count());
        // The twins' arithmetic differs in the last bits (the project's tolerance), so
        // a read at a texel boundary may mark a neighbour on one side only.
        assert!(
            disagree * 100 <= either.count(),
            "GPU marked {}, the twin {}, either {}",
            on_gpu.count(),
            twin.count(),
            either.count()
        );
        assert!(on_gpu.count() > 0 && on_gpu != ViewMask::empty(v.dims));
    }
    // The twin's own render: culled to its view equals the dense twin.
    let frame = orbit(settings)[1];
    let method = ao(AoMethod::Lao, RaySet::Six);
    let culled = render(None, &RenderJob::new(&v, &tf, &frame, &method), &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let dense_frame = Frame {
        settings: RenderSettings {
            view_culling: false,
            empty_space_skipping: false,
            ..settings
        },
        ..frame
    };
    let dense = render(
        None,
        &RenderJob::new(&v, &tf, &dense_frame, &method),
        &|_, _| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(culled.view.is_some_and(|f| f.fraction() < 1.0));
    assert_eq!(differing(&culled.image.pixels, &dense.image.pixels), 0);
}
