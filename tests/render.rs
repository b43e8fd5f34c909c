//! GPU ray caster vs its CPU twin, golden images, empty-space skipping, jitter.
//! Runs on lavapipe in CI; never skipped.

mod common;

use common::device;
use volao::clip::gpu::MapRequest;

use common::data;
use std::path::PathBuf;
use volao::gpu::Gpu;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::image::{Tolerance, check};
use volao::render::{Camera, Frame, Image, RenderSettings, Shading, cpu};
use volao::texels::{UploadLimits, VolumeTexels};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, Volume};

fn out_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("render")
}

use common::small_texels as small;

fn load(rel: &str) -> Volume {
    volume::load(&data(rel), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras()
}

/// Renders on GPU and CPU with the same everything.
fn both(
    gpu: &Gpu,
    rc: &RayCaster,
    texels: &VolumeTexels,
    tf: &TransferFunction,
    frame: &Frame,
) -> (Image, Image) {
    let vol = RenderVolume::from_texels(gpu, texels.clone(), tf, frame.settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let g = rc
        .render(gpu, &vol, frame, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let (cv, occ) = cpu::prepare(texels, &vol.lut);
    let c = cpu::render(texels, &cv, &vol.lut, &occ, frame);
    (g, c)
}

fn frame(size: u32, shading: Shading) -> Frame {
    Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings: RenderSettings {
            shading,
            ..Default::default()
        },
        width: size,
        height: size,
    }
}

use common::TWIN;

#[test]
fn gpu_matches_cpu_twin() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let demo = volume::demo::head_phantom(64);
    let cases: Vec<(&str, Volume)> = vec![
        ("demo", demo),
        ("engine", load("raw/engine.raw")),
        ("lobster", load("pvm/Lobster.pvm")),
        ("cranium", load("raw/cranium-ct.raw")),
        ("ch2", load("nifti/ch2.nii.gz")),
    ];
    let mut failures = Vec::new();
    for (name, v) in &cases {
        let texels = small(v);
        let tf = TransferFunction::preset(Preset::default_for(&v.stats()), &v.stats());
        for shading in [Shading::None, Shading::Phong] {
            let f = frame(96, shading);
            let (g, c) = both(&gpu, &rc, &texels, &tf, &f);
            let label = format!("twin_{name}_{shading:?}");
            if std::env::var_os("VOLAO_DUMP").is_some() {
                let _ = std::fs::create_dir_all(out_dir());
                let _ = g.save_png(&out_dir().join(format!("{label}.gpu.png")));
                let _ = c.save_png(&out_dir().join(format!("{label}.cpu.png")));
            }
            if let Err(e) = common::twin(&label, &g, &c, TWIN, &out_dir()) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn golden_images_with_the_ct_bone_preset() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for (name, file, camera) in [
        ("engine", "raw/engine.raw", (40.0, 25.0)),
        ("lobster", "pvm/Lobster.pvm", (0.0, 60.0)),
        ("cranium", "raw/cranium-ct.raw", (20.0, 10.0)),
    ] {
        let v = load(file);
        let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
        let f = Frame {
            camera: Camera {
                azimuth_deg: camera.0,
                elevation_deg: camera.1,
                ..Default::default()
            },
            settings: RenderSettings::default(),
            width: 160,
            height: 160,
        };
        let vol = RenderVolume::new(&gpu, &v, &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        let image = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        if let Err(e) = common::golden(&format!("{name}_ct_bone"), &image, &out_dir()) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn empty_space_skipping_does_not_change_the_image() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    for (name, v) in [
        ("engine", load("raw/engine.raw")),
        ("demo", volume::demo::head_phantom(64)),
    ] {
        let texels = small(&v);
        let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
        let mut f = frame(96, Shading::Phong);
        let vol = RenderVolume::from_texels(&gpu, texels.clone(), &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        let occ = vol.occupancy();
        let skipped = occ.iter().filter(|&&o| o == 0).count();
        assert!(
            skipped > occ.len() / 10,
            "{name}: only {skipped} of {} blocks are empty: the test would prove nothing",
            occ.len()
        );
        f.settings.empty_space_skipping = true;
        let on = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        f.settings.empty_space_skipping = false;
        let off = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        // Skipping visits exactly the samples it would have found transparent, so the
        // image must not change at all.
        check(
            &format!("skip_{name}_gpu"),
            &on,
            &off,
            Tolerance::EXACT,
            &out_dir(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let (cv, _) = cpu::prepare(&texels, &vol.lut);
        let all = vec![1u8; occ.len()];
        f.settings.empty_space_skipping = true;
        let c_on = cpu::render(&texels, &cv, &vol.lut, &occ, &f);
        let c_off = cpu::render(&texels, &cv, &vol.lut, &all, &f);
        check(
            &format!("skip_{name}_cpu"),
            &c_on,
            &c_off,
            Tolerance::EXACT,
            &out_dir(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// A hard-edged ball: without jitter, every pixel at the same distance from the centre
/// takes the same number of samples inside it, so a semi-transparent ball shows rings.
fn ball(n: usize) -> Volume {
    let c = (n as f32 - 1.0) / 2.0;
    let data: Vec<u8> = (0..n * n * n)
        .map(|i| {
            let (x, y, z) = ((i % n) as f32, ((i / n) % n) as f32, (i / (n * n)) as f32);
            let r = ((x - c).powi(2) + (y - c).powi(2) + (z - c).powi(2)).sqrt() / c;
            if r < 0.8 { 255 } else { 0 }
        })
        .collect();
    Volume::new([n, n, n], [1.0; 3], volume::VoxelData::U8(data)).expect("valid ball")
}

/// High-frequency energy of the image's radial profile inside the ball's silhouette: the
/// mean grey value in 1-pixel rings around the centre, minus its 5-ring moving average,
/// squared and summed. Rings show up here; per-pixel noise averages out around a ring.
fn ring_energy(img: &Image) -> f64 {
    let (w, h) = (img.width as usize, img.height as usize);
    let mut sum = vec![0.0f64; w];
    let mut count = vec![0.0f64; w];
    for y in 0..h {
        for x in 0..w {
            let r =
                ((x as f64 + 0.5 - w as f64 / 2.0).hypot(y as f64 + 0.5 - h as f64 / 2.0)) as usize;
            sum[r] += img.pixels[y * w + x][0] as f64;
            count[r] += 1.0;
        }
    }
    let profile: Vec<f64> = sum
        .iter()
        .zip(&count)
        .take_while(|(_, c)| **c > 0.0)
        .map(|(s, c)| s / c)
        .collect();
    // The silhouette: where the profile falls below half its centre value. Stay well inside.
    let edge = profile
        .iter()
        .position(|&v| v < profile[0] / 2.0)
        .unwrap_or(profile.len());
    let inner = edge * 4 / 5;
    (2..inner.saturating_sub(2))
        .map(|i| {
            let smooth = profile[i - 2..=i + 2].iter().sum::<f64>() / 5.0;
            (profile[i] - smooth).powi(2)
        })
        .sum()
}

#[test]
fn jittered_ray_starts_remove_wood_grain_rings() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let v = ball(48);
    let tf = TransferFunction {
        name: "faint".into(),
        opacity: vec![
            volao::tf::OpacityPoint {
                value: 0.0,
                alpha: 0.0,
            },
            volao::tf::OpacityPoint {
                value: 127.0,
                alpha: 0.0,
            },
            volao::tf::OpacityPoint {
                value: 128.0,
                alpha: 0.06,
            },
        ],
        color: vec![volao::tf::ColorStop {
            value: 0.0,
            rgb: [1.0; 3],
        }],
    };
    let mut energies = Vec::new();
    for jitter in [false, true] {
        let f = Frame {
            camera: Camera {
                orthographic: true,
                ..Default::default()
            },
            settings: RenderSettings {
                jitter,
                shading: Shading::None,
                step_voxels: 2.0,
                ..Default::default()
            },
            width: 192,
            height: 192,
        };
        let vol = RenderVolume::new(&gpu, &v, &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        let img = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        if std::env::var_os("VOLAO_DUMP").is_some() {
            let _ = std::fs::create_dir_all(out_dir());
            let _ = img.save_png(&out_dir().join(format!("ball_jitter_{jitter}.png")));
        }
        energies.push(ring_energy(&img));
    }
    let (rings, jittered) = (energies[0], energies[1]);
    eprintln!("radial high-frequency energy: {rings:.1} without jitter, {jittered:.1} with");
    assert!(
        rings > 20.0,
        "the test scene should show rings without jitter (energy {rings:.1})"
    );
    // Measured on lavapipe: 33.0 without jitter, 5.9 with. What remains with jitter is
    // per-pixel noise that small central rings (few pixels each) do not average away.
    assert!(
        jittered < 0.3 * rings,
        "jitter should remove the rings: {jittered:.1} vs {rings:.1}"
    );
}

#[test]
fn an_all_zero_volume_renders_the_background() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let v = load("pvm/Storm-t01.pvm");
    let stats = v.stats();
    for preset in [Preset::default_for(&stats), Preset::CtBone] {
        let tf = TransferFunction::preset(preset, &stats);
        for background in [[0.1, 0.2, 0.3, 1.0], [0.0; 4]] {
            let f = Frame {
                settings: RenderSettings {
                    background,
                    ..Default::default()
                },
                ..frame(64, Shading::Phong)
            };
            let vol = RenderVolume::new(&gpu, &v, &tf, f.settings.step_voxels)
                .unwrap_or_else(|e| panic!("{e}"));
            let img = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let want = background.map(|c| (c * 255.0).round() as u8);
            // ±1: 0.3 × 255 = 76.5 may round either way in the GPU's unorm8 store.
            let off = img
                .pixels
                .iter()
                .find(|p| p.iter().zip(&want).any(|(a, b)| a.abs_diff(*b) > 1));
            assert!(
                off.is_none(),
                "{preset:?} on {background:?}: pixel {off:?}, background {want:?}"
            );
        }
    }
}

#[test]
fn a_saved_scene_renders_the_same_image() {
    use volao::scene::{Light, SCENE_VERSION, Scene, VolumeSource};
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let dir = tempfile::tempdir().expect("temp dir");
    let path = data("pvm/Bucky.pvm");
    let v = load("pvm/Bucky.pvm");
    let scene = Scene {
        version: SCENE_VERSION,
        volume: VolumeSource {
            path: Some(path.clone()),
            frame: 0,
            raw: None,
            level: 0,
        },
        transfer_function: TransferFunction::preset(Preset::MrT1Brain, &v.stats()),
        camera: Camera {
            azimuth_deg: 33.0,
            elevation_deg: -12.0,
            distance: 2.9,
            orthographic: true,
            ..Default::default()
        },
        light: Light::Headlight,
        render: RenderSettings {
            background: [1.0, 1.0, 1.0, 1.0],
            step_voxels: 0.7,
            ..Default::default()
        },
        width: 120,
        height: 90,
        ambient_occlusion: Default::default(),
        clip_shapes: Vec::new(),
        meshes: Vec::new(),
        segmentation: None,
    };
    let render = |s: &Scene, scene_path: &std::path::Path| {
        let p = s.volume_path(scene_path).expect("scene names a volume");
        let v = volume::load(&p, &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume
            .to_ras();
        let f = Frame {
            camera: s.camera,
            settings: s.render,
            width: s.width,
            height: s.height,
        };
        let vol = RenderVolume::new(&gpu, &v, &s.transfer_function, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        rc.render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let scene_path = dir.path().join("view.json");
    let before = render(&scene, &scene_path);
    scene.save(&scene_path).unwrap_or_else(|e| panic!("{e}"));
    let loaded = Scene::load(&scene_path).unwrap_or_else(|e| panic!("{e}"));
    let after = render(&loaded, &scene_path);
    check(
        "scene_round_trip",
        &after,
        &before,
        Tolerance::EXACT,
        &out_dir(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn gpu_matches_cpu_twin_with_lao() {
    use volao::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
    use volao::ao::rays::RaySet;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    let v = volume::demo::head_phantom(48);
    let texels = small(&v);
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let f = Frame {
        settings: RenderSettings {
            ambient: 0.8,
            ..Default::default()
        },
        ..frame(96, Shading::Phong)
    };
    let mut vol = RenderVolume::from_texels(&gpu, texels.clone(), &tf, f.settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let lut = lao_lut(&tf, &texels);
    // Sparse, as rendering computes it: the readable voxels, rays stepping over empty bricks.
    let bricks = volao::ao::sparse::Coverage::Readable.bricks(&texels, vol.ranges(), &tf);
    assert!(bricks.readable.contains(&0) && bricks.occupied.contains(&0));
    let setup = volao::ao::lao::LaoSetup {
        lut: &lut,
        rays: &rays,
        samples: 10,
    };
    let a = lao
        .compute(&gpu, &vol, setup, &bricks, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion(&gpu, &a);
    let g = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    // The CPU twin computes its own LAO (the GPU keeps it as f32 too).
    let (mut cv, occ) = cpu::prepare(&texels, &vol.lut);
    let cpu_a = lao_cpu(&texels, &lut, &rays, 10, &bricks, &|_, _| {});
    cv.ao = Some(cpu_a);
    let c = cpu::render(&texels, &cv, &vol.lut, &occ, &f);
    check("twin_demo_lao", &g, &c, TWIN, &out_dir()).unwrap_or_else(|e| panic!("{e}"));
    // And the AO visibly darkens the image compared with A = 1.
    let (mut flat, _) = cpu::prepare(&texels, &vol.lut);
    flat.ao = None;
    let unoccluded = cpu::render(&texels, &flat, &vol.lut, &occ, &f);
    let lum = |img: &Image| {
        img.pixels
            .iter()
            .map(|p| p[0] as u64 + p[1] as u64 + p[2] as u64)
            .sum::<u64>()
    };
    assert!(lum(&c) < lum(&unoccluded), "AO must darken");
    assert!(a.iter().all(|&x| (0.0..=1.0).contains(&x)));
}

/// One grey of `level`, opacity ramping linearly between two (value, alpha) points.
fn grey_tf(from: (f64, f32), to: (f64, f32), level: f32) -> TransferFunction {
    let point = |(value, alpha)| volao::tf::OpacityPoint { value, alpha };
    TransferFunction {
        name: "grey".into(),
        opacity: vec![point(from), point(to)],
        color: vec![volao::tf::ColorStop {
            value: 0.0,
            rgb: [level; 3],
        }],
    }
}

#[test]
fn ao_scales_ambient_and_diffuse_light_or_the_ambient_term_only_gpu_and_cpu() {
    // A homogeneous opaque cube with A(x) = 0.3 everywhere, unshaded (D = 1, no shadows):
    // the pixel at the centre is C_TF · α_acc · F with, by default, F = A_s·(k + 1 − k) =
    // A_s, A_s = clamp(1 − s(1 − min(A / A_open, 1)), 0, 1) with A_open = ½ (AO from no
    // method in particular); with ao_ambient_only F = k·A_s + 1 − k,
    // A_s = clamp(1 − s(1 − A), 0, 1).
    let gpu = device();
    assert_ne!(
        gpu.info.backend,
        wgpu::Backend::Gl,
        "lavapipe or a real GPU, not GL"
    );
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let n = [24, 24, 24];
    let v = Volume::new(n, [1.0; 3], volume::VoxelData::U8(vec![200; 24 * 24 * 24]))
        .expect("valid volume");
    let tf = grey_tf((0.0, 0.9), (255.0, 0.9), 1.0);
    let t = VolumeTexels::new(&v, UploadLimits::NONE);
    let ao = vec![0.3f32; n.iter().product()];
    let mut vol =
        RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion(&gpu, &ao);
    let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
    cv.ao = Some(ao.clone());
    let k = 0.4f32;
    let centre = |img: &Image| img.pixels[(32 * 64 + 32) as usize][1] as f32 / 255.0;
    let mut unoccluded = None;
    for (strength, ambient_only) in [
        (0.0, false),
        (1.0, false),
        (1.0, true),
        (2.0, false),
        (2.0, true),
        (1.5, false),
    ] {
        let f = Frame {
            camera: Camera::default(),
            settings: RenderSettings {
                shading: Shading::None,
                ambient: k,
                ao_strength: strength,
                ao_ambient_only: ambient_only,
                ..Default::default()
            },
            width: 64,
            height: 64,
        };
        let g = centre(
            &rc.render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}")),
        );
        let c = centre(&cpu::render(&t, &cv, &vol.lut, &occ, &f));
        assert!(
            (g - c).abs() <= 1.5 / 255.0,
            "s = {strength}, ambient only {ambient_only}: GPU {g} vs CPU {c}"
        );
        // s = 0 ignores the AO: the reference brightness C_TF · α_acc.
        let base = *unoccluded.get_or_insert(g);
        let want = if ambient_only {
            k * (1.0 - strength * 0.7f32).clamp(0.0, 1.0) + 1.0 - k
        } else {
            (1.0 - strength * 0.4f32).clamp(0.0, 1.0)
        };
        eprintln!(
            "s = {strength}, ambient only {ambient_only}: {g:.4} = {:.4} × unoccluded (want {want:.4})",
            g / base
        );
        assert!(
            (g - want * base).abs() <= 1.5 / 255.0,
            "s = {strength}, ambient only {ambient_only}: {g} vs {} expected",
            want * base
        );
    }
    assert!(
        unoccluded.is_some_and(|b| b > 0.9),
        "the cube is in view and nearly opaque"
    );
}

/// A slab whose face looks at the camera, with a slot cut into it. LAO is taken over the
/// whole sphere, so inside the material every voxel is occluded: read at the sample, the
/// AO greys a flat lit face (issue #18's "AO barely reads"); read `ao_offset` voxels out
/// of the material along the normal, the face keeps its brightness and the slot's floor,
/// which its walls hide, darkens. GPU and CPU twin.
#[test]
fn ao_read_off_the_surface_keeps_a_flat_face_bright_and_darkens_a_slot_gpu_and_cpu() {
    use volao::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
    use volao::ao::rays::RaySet;
    let gpu = device();
    assert_ne!(
        gpu.info.backend,
        wgpu::Backend::Gl,
        "lavapipe or a real GPU, not GL"
    );
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    // Opacity 0.9 in the material, like ct-bone's bone.
    // The default camera looks along −y: material for y < 30, the slot 8 voxels wide
    // (x ∈ [20, 28)) and 12 deep, across the whole of z.
    let n = 48usize;
    let data: Vec<u8> = (0..n * n * n)
        .map(|i| {
            let (x, y) = (i % n, (i / n) % n);
            let slot = (20..28).contains(&x) && y >= 18;
            if y < 30 && !slot { 200 } else { 0 }
        })
        .collect();
    let v = Volume::new([n; 3], [1.0; 3], volume::VoxelData::U8(data)).expect("valid volume");
    let tf = grey_tf((0.0, 0.0), (200.0, 0.9), 0.7);
    let t = VolumeTexels::new(&v, UploadLimits::NONE);
    let mut vol =
        RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let lut = lao_lut(&tf, &t);
    let bricks = volao::ao::sparse::Coverage::Readable.bricks(&t, vol.ranges(), &tf);
    let setup = volao::ao::lao::LaoSetup {
        lut: &lut,
        rays: &rays,
        samples: 12,
    };
    let a = lao
        .compute(&gpu, &vol, setup, &bricks, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_ambient_occlusion(&gpu, &a);
    let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
    cv.ao = Some(lao_cpu(&t, &lut, &rays, 12, &bricks, &|_, _| {}));
    let size = 64u32;
    let frame = |offset: f32| Frame {
        camera: Camera::default(),
        settings: RenderSettings {
            ao_offset: offset,
            ao_reference: volao::render::AoReference::Rays {
                set: RaySet::Fourteen,
                samples: 12,
            },
            specular: 0.0,
            ..Default::default()
        },
        width: size,
        height: size,
    };
    // Green of the middle row's pixel in column `x`.
    let at = |img: &Image, x: u32| img.pixels[((size / 2) * size + x) as usize][1] as f32;
    let (face, floor) = (14, size / 2);
    // A = 1: the reference brightness.
    let no_ao = {
        let mut flat = cv.clone();
        flat.ao = None;
        cpu::render(&t, &flat, &vol.lut, &occ, &frame(2.0))
    };
    let mut looks = Vec::new();
    for offset in [0.0, 2.0] {
        let f = frame(offset);
        let g = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let c = cpu::render(&t, &cv, &vol.lut, &occ, &f);
        check(
            &format!("twin_ao_offset_{offset}"),
            &g,
            &c,
            TWIN,
            &out_dir(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let (face_ratio, floor_ratio) = (
            at(&g, face) / at(&no_ao, face),
            at(&g, floor) / at(&no_ao, floor),
        );
        eprintln!(
            "offset {offset}: flat face {:.0} ({face_ratio:.2} × no AO), slot floor {:.0} ({floor_ratio:.2} × no AO)",
            at(&g, face),
            at(&g, floor)
        );
        looks.push((face_ratio, floor_ratio));
    }
    eprintln!(
        "no AO: face {} floor {}",
        at(&no_ao, face),
        at(&no_ao, floor)
    );
    assert!(
        at(&no_ao, face) > 100.0 && at(&no_ao, floor) > 50.0,
        "both in view and lit"
    );
    let [(face_0, _), (face_2, floor_2)] = looks[..] else {
        unreachable!()
    };
    assert!(
        face_0 < 0.75,
        "read at the sample, the AO greys the flat face ({face_0:.2})"
    );
    assert!(
        face_2 > 0.85,
        "read off the surface, the flat face keeps its light ({face_2:.2})"
    );
    assert!(
        floor_2 < 0.85 * face_2,
        "the slot's floor is darker than the open face ({floor_2:.2} vs {face_2:.2})"
    );
}

#[test]
fn scenes_keep_where_the_ao_applies_and_its_strength_and_old_ones_get_the_new_shading() {
    use volao::render::DEFAULT_AO_STRENGTH;
    use volao::scene::Scene;
    let base = r#"{"version": 1, "volume": {"path": null},
        "transfer_function": {"name": "t", "opacity": [{"value": 0, "alpha": 0}, {"value": 1, "alpha": 1}],
                              "color": [{"value": 0, "rgb": [1, 1, 1]}]},
        "width": 8, "height": 8"#;
    let path = std::path::Path::new("scene.json");
    // A scene from before the fields: AO on ambient and diffuse, the default strength.
    let old = Scene::parse(&format!("{base}, \"render\": {{\"ambient\": 0.6}}}}"), path)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(!old.render.ao_ambient_only);
    assert_eq!(old.render.ao_strength, DEFAULT_AO_STRENGTH);
    assert_eq!(old.render.ao_offset, volao::render::DEFAULT_AO_OFFSET);
    assert_eq!(old.render.ambient, 0.6);
    // The old shading, asked for, survives a save and a load.
    let mut scene = Scene::parse(
        &format!("{base}, \"render\": {{\"ao_ambient_only\": true, \"ao_strength\": 1.5}}}}"),
        path,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(scene.render.ao_ambient_only);
    assert_eq!(scene.render.ao_strength, 1.5);
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("s.json");
    scene.render.ao_strength = 0.75;
    scene.render.ao_offset = 0.0;
    scene.save(&file).unwrap_or_else(|e| panic!("{e}"));
    let back = Scene::load(&file).unwrap_or_else(|e| panic!("{e}"));
    assert!(back.render.ao_ambient_only);
    assert_eq!(back.render.ao_strength, 0.75);
    assert_eq!(
        back.render.ao_offset, 0.0,
        "the old read point survives a save"
    );
}

const MODES: [volao::render::RenderMode; 5] = [
    volao::render::RenderMode::Composite,
    volao::render::RenderMode::Mip,
    volao::render::RenderMode::Minip,
    volao::render::RenderMode::Average,
    volao::render::RenderMode::Iso(None),
];

/// The pipeline specialised for a frame (`render::gpu::Variant`) draws the general
/// shader's pixels, in every mode, shaded and not (bit for bit: specialising only
/// leaves out code for what is off).
#[test]
fn specialised_pipelines_draw_the_general_pixels() {
    use volao::render::gpu::Variant;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let v = load("raw/engine.raw");
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let mut vol =
        RenderVolume::from_texels(&gpu, small(&v), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    // With the gradient volume (the general shader's uniform says so) and without.
    for gradient in [true, false] {
        let bound = vol
            .set_gradient_volume(&gpu, gradient)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bound, gradient);
        for mode in MODES {
            for shading in [Shading::None, Shading::Phong] {
                let mut f = frame(48, shading);
                f.settings.mode = mode;
                let render = |variant| {
                    rc.render_variant(&gpu, &vol, &f, None, variant)
                        .unwrap_or_else(|e| panic!("{e}"))
                };
                if render(None).pixels != render(Some(Variant::general(mode))).pixels {
                    failures.push(format!("{mode} {shading:?} gradient volume {gradient}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "differ: {}", failures.join(", "));
}

/// The gradient volume holds each voxel's central differences, with a border of one
/// voxel: the known values around one bright voxel, and the CPU's differences of real
/// crops (16-bit CT) and of float data (whose texels are scaled by their largest |value|
/// to fit f16), rounded to f16.
#[test]
fn the_gradient_volume_holds_each_voxels_central_differences() {
    use volao::render::gradient::{central_differences, padded};
    let gpu = device();
    let tf = common::flat_tf(0.5);
    let one = common::u8_volume(
        [8, 8, 8],
        |x, y, z| if (x, y, z) == (3, 4, 5) { 255 } else { 0 },
    );
    let vol = RenderVolume::new(&gpu, &one, &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let g = vol
        .gradient_volume()
        .expect("an 8³ volume's gradient volume fits")
        .read_back(&gpu)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.len(), 10 * 10 * 10);
    // Texel (x, y, z) of the padded volume is voxel (x − 1, y − 1, z − 1).
    let at = |x: usize, y: usize, z: usize| g[(x + 1) + 10 * ((y + 1) + 10 * (z + 1))];
    assert_eq!(at(2, 4, 5), [1.0, 0.0, 0.0]);
    assert_eq!(at(4, 4, 5), [-1.0, 0.0, 0.0]);
    assert_eq!(at(3, 3, 5), [0.0, 1.0, 0.0]);
    assert_eq!(at(3, 5, 5), [0.0, -1.0, 0.0]);
    assert_eq!(at(3, 4, 4), [0.0, 0.0, 1.0]);
    assert_eq!(at(3, 4, 6), [0.0, 0.0, -1.0]);
    assert_eq!(at(3, 4, 5), [0.0; 3]);
    let nonzero = g.iter().filter(|v| v.iter().any(|&c| c != 0.0)).count();
    assert_eq!(nonzero, 6, "only the six neighbours along the axes");
    // Compute passes' uploads go without it (8 bytes per voxel).
    let texels = common::texels(&one);
    let compute =
        RenderVolume::for_compute(&gpu, texels, &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    assert!(compute.gradient_volume().is_none());

    let wave = Volume::new(
        [20, 18, 16],
        [1.0, 1.2, 0.8],
        volume::VoxelData::F32(
            (0..20 * 18 * 16)
                .map(|i| 3000.0 * ((i % 20) as f32 * 0.7).sin() + 0.25 * (i / 20) as f32)
                .collect(),
        ),
    )
    .expect("valid volume");
    let mut cases: Vec<(&str, Volume)> = vec![("float wave", wave)];
    cases.extend(
        common::real_crops()
            .into_iter()
            .map(|(name, v, _)| (name, v)),
    );
    for (name, v) in cases {
        let texels = common::texels(&v);
        let vol = RenderVolume::from_texels(&gpu, texels.clone(), &tf, 0.5)
            .unwrap_or_else(|e| panic!("{e}"));
        let gv = vol
            .gradient_volume()
            .expect("a small volume's gradient volume fits");
        let gpu_g = gv.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
        let cpu_g = central_differences(&texels);
        assert_eq!(gpu_g.len(), padded(texels.dims).iter().product::<usize>());
        assert_eq!(gpu_g.len(), cpu_g.len());
        // One step of f16 (11 significant bits; below 2⁻¹⁴ of M, steps of 2⁻²⁴): a
        // driver may round the f32 → f16 conversion towards zero.
        let worst = gpu_g
            .iter()
            .zip(&cpu_g)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c], b[c])))
            .map(|(a, b)| (a - b).abs() / (b.abs() * 2f32.powi(-10) + gv.scale * 2f32.powi(-24)))
            .fold(0.0f32, f32::max);
        eprintln!("{name}: worst {worst:.3} f16 steps");
        assert!(worst <= 1.0, "{name}: {worst} f16 steps");
        let changing = cpu_g.iter().filter(|v| v.iter().any(|&c| c != 0.0)).count();
        assert!(
            changing > cpu_g.len() / 4,
            "{name}: a volume with gradients"
        );
    }
}

/// Phong frames shaded from the gradient volume are those shaded from six density
/// samples per gradient, up to the gradient's f16 rounding, on real crops, with and
/// without AO read off the surface along the gradient.
#[test]
fn shading_from_the_gradient_volume_matches_six_samples() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for (name, v, tf) in common::real_crops() {
        let mut vol = RenderVolume::new(&gpu, &v, &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        for ao in [false, true] {
            if ao {
                // A stand-in AO volume: what matters is where along the gradient it is read.
                let n: usize = vol.texels.dims.iter().product();
                let a: Vec<f32> = (0..n).map(|i| 0.3 + 0.7 * ((i % 7) as f32 / 6.0)).collect();
                vol.set_ambient_occlusion(&gpu, &a);
            }
            let f = frame(96, Shading::Phong);
            let mut images = Vec::new();
            for gradient in [true, false] {
                vol.set_gradient_volume(&gpu, gradient)
                    .unwrap_or_else(|e| panic!("{e}"));
                images.push(
                    rc.render(&gpu, &vol, &f, None)
                        .unwrap_or_else(|e| panic!("{e}")),
                );
            }
            let background = images[0].pixels[0];
            let shown = images[0]
                .pixels
                .iter()
                .filter(|&&p| p != background)
                .count();
            assert!(
                shown * 10 > images[0].pixels.len(),
                "{name}: the crop shows"
            );
            let label = format!("gradient_volume_{name}_ao_{ao}");
            if let Err(e) = common::twin(&label, &images[0], &images[1], TWIN, &out_dir()) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// With clip shapes, a frame's pipeline is built for their number (`CLIP_SHAPES`, a
/// constant loop bound): it draws the pixels of the pipeline that reads the number from
/// the uniforms, for one to three carving and probing shapes, in composite and MIP.
#[test]
fn a_pipeline_built_for_its_number_of_clip_shapes_draws_the_general_pixels() {
    use glam::Vec3;
    use volao::clip::gpu::ClipMaps;
    use volao::clip::{ClipMode, ClipShape, Shape};
    use volao::render::RenderMode;
    use volao::render::gpu::Variant;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let v = load("raw/engine.raw");
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let vol =
        RenderVolume::from_texels(&gpu, small(&v), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let shapes = [
        ClipShape::new(Shape::Sphere, Vec3::new(0.0, 0.0, 10.0), 20.0),
        ClipShape {
            mode: ClipMode::Probe,
            ..ClipShape::new(Shape::Box, Vec3::ZERO, 60.0)
        },
        ClipShape::new(Shape::Sphere, Vec3::new(20.0, -10.0, 0.0), 12.0),
    ];
    let radius = glam::Vec3::from(vol.texels.extent()).length() * 0.5;
    let mut maps = ClipMaps::new(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let unclipped = rc
        .render(&gpu, &vol, &frame(32, Shading::Phong), None)
        .unwrap_or_else(|e| panic!("{e}"));
    for n in 1..=shapes.len() {
        let report = maps
            .update(&gpu, MapRequest::clipping(&shapes[..n], radius, 128))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(report.errors.is_empty(), "{:?}", report.errors);
        for mode in [RenderMode::Composite, RenderMode::Mip] {
            let mut f = frame(32, Shading::Phong);
            f.settings.mode = mode;
            let variant = Variant::of(&vol, &f, Some(&maps), false);
            assert_eq!(variant.clip_shapes, n as u32);
            let render = |variant| {
                rc.render_variant(&gpu, &vol, &f, Some(&maps), Some(variant))
                    .unwrap_or_else(|e| panic!("{e}"))
                    .pixels
            };
            let built = render(variant);
            assert!(
                built == render(Variant::general(mode)),
                "{mode} with {n} shapes: the pipeline built for them draws other pixels"
            );
            if mode == RenderMode::Composite {
                assert!(
                    built != unclipped.pixels,
                    "{n} shapes clip nothing: the test shows nothing"
                );
            }
        }
    }
}

/// Every variant `Variant::of` can choose, with the frame's features off at run time,
/// draws the general shader's pixels: 5 modes × 256 pipelines (~2 min on lavapipe).
/// `cargo test --release --test render every_variant -- --ignored`
#[test]
#[ignore = "sweep of 1280 pipelines, ~2 min on lavapipe"]
fn every_variant_draws_the_general_pixels() {
    use volao::render::gpu::Variant;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let v = load("raw/engine.raw");
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let vol =
        RenderVolume::from_texels(&gpu, small(&v), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for mode in MODES {
        for bits in 0u32..256 {
            let on = |i: u32| bits & (1 << i) != 0;
            let variant = Variant {
                mode: mode.code(),
                phong: on(7),
                ao_volume: on(0),
                live_vao: on(1),
                shadows: on(2),
                surfaces: on(3),
                clip: on(4),
                clip_shapes: 0,
                modulation: on(5),
                skipping: on(6),
                gradient: Some(true),
                // Half the variants read the (absent) segmentation: the same pixels.
                segments: on(0) ^ on(5),
                segment_modes: 2,
                segment_edges: on(1),
                segment_weights: on(2),
                pick: false,
                mark_ao: false,
            };
            // Never chosen: lavapipe crashes on it (see `Variant::of`).
            if variant.shadows && !variant.surfaces {
                continue;
            }
            let mut f = frame(24, if on(7) { Shading::Phong } else { Shading::None });
            f.settings.mode = mode;
            f.settings.empty_space_skipping = on(6);
            let render = |variant| {
                rc.render_variant(&gpu, &vol, &f, None, Some(variant))
                    .unwrap_or_else(|e| panic!("{e}"))
            };
            if render(variant).pixels != render(Variant::general(mode)).pixels {
                failures.push(format!("{mode} {variant:?}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The viewer's interactive images use a longer step than the volume's transfer function
/// was baked for: `prepare_step` bakes a second table, so such a frame is the one a
/// volume baked for that step draws (and not the more transparent one drawn with the
/// first table).
#[test]
fn a_frame_at_another_step_reads_the_table_baked_for_it() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let volume = load("raw/engine.raw");
    let tf = TransferFunction::preset(Preset::CtBone, &volume.stats());
    let v = small(&volume);
    let at = |step: f32| {
        let mut f = frame(64, Shading::Phong);
        f.settings.step_voxels = step;
        f
    };
    let baked_for = |step: f32| {
        RenderVolume::from_texels(&gpu, v.clone(), &tf, step).unwrap_or_else(|e| panic!("{e}"))
    };
    let draw = |vol: &RenderVolume, step: f32| {
        rc.render(&gpu, vol, &at(step), None)
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let reference = draw(&baked_for(1.0), 1.0);
    let mut vol = baked_for(0.5);
    let unprepared = draw(&vol, 1.0);
    vol.prepare_step(&gpu, 1.0);
    let prepared = draw(&vol, 1.0);
    assert!(
        prepared.pixels == reference.pixels,
        "the prepared table draws the step's own image"
    );
    let differing = common::differing(&unprepared.pixels, &reference.pixels);
    assert!(
        differing > reference.pixels.len() / 20,
        "the step-0.5 table at step 1 should look different: {differing} pixels differ"
    );
    // Back at the baked step, the first table again.
    assert!(draw(&vol, 0.5).pixels == draw(&baked_for(0.5), 0.5).pixels);
}

/// The GPU pick (a `PICK` pipeline of raycast.wgsl: the pixel's ray stops where its
/// opacity first reaches ½) lands where the CPU twin's does, with jitter, Phong and a
/// carving sphere: on a 40³ ball of 1 mm voxels, every pixel of the 15² block around the
/// ball in a 32² frame either misses on both or stops at the same sample on both.
#[test]
fn gpu_pick_matches_the_cpu_twin() {
    use glam::Vec3;
    use volao::clip::gpu::ClipMaps;
    use volao::clip::{ClipShape, Shape};
    use volao::render::gpu::PickDraw;
    use volao::tf::{ColorStop, OpacityPoint};
    use volao::volume::voxels::VoxelData;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let n = 40usize;
    let data: Vec<f32> = (0..n * n * n)
        .map(|i| {
            let [x, y, z] = volume::voxel_of(i, [n; 3]);
            let d = Vec3::new(x as f32, y as f32, z as f32) + 0.5 - n as f32 / 2.0;
            if d.length() <= 12.0 { 100.0 } else { 0.0 }
        })
        .collect();
    let ball =
        Volume::new([n; 3], [1.0; 3], VoxelData::from(data)).unwrap_or_else(|e| panic!("{e}"));
    let tf = TransferFunction {
        name: "step".into(),
        opacity: OpacityPoint::list(&[(40.0, 0.0), (60.0, 0.3)]),
        color: ColorStop::list(&[(0.0, [1.0; 3])]),
    };
    let texels = small(&ball);
    let vol =
        RenderVolume::from_texels(&gpu, texels.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let (mut cv, occ) = cpu::prepare(&texels, &vol.lut);
    let mut f = frame(32, Shading::Phong);
    f.settings.jitter = true;
    let carve = [ClipShape::new(
        Shape::Sphere,
        Vec3::new(0.0, 12.0, 4.0),
        7.0,
    )];
    let radius = Vec3::from(texels.extent()).length() * 0.5;
    let mut maps = ClipMaps::new(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let report = maps
        .update(&gpu, MapRequest::clipping(&carve, radius, 128))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    let mut picks = Vec::new();
    for clip in [None, Some(&maps)] {
        cv.clip = clip.map(|m| m.read_back(&gpu).unwrap_or_else(|e| panic!("{e}")));
        for py in 9..24 {
            for px in 9..24 {
                let draw = PickDraw {
                    volume: &vol,
                    frame: &f,
                    clip,
                    pixel: (px, py),
                };
                let g = rc.pick(&gpu, draw).unwrap_or_else(|e| panic!("{e}"));
                let c = cpu::pick_pixel(&texels, &cv, &vol.lut, &occ, &f, (px, py));
                match (g, c) {
                    (None, None) => {}
                    // The same sample (steps are 0.5 mm apart); not bit for bit, as the
                    // driver may fuse origin + dir · t into a multiply-add.
                    (Some(g), Some(c)) => assert!(
                        (g - c).length() <= 0.01,
                        "pixel ({px}, {py}), clipped {}: GPU {g}, twin {c}",
                        clip.is_some()
                    ),
                    _ => panic!("pixel ({px}, {py}): GPU {g:?}, twin {c:?}"),
                }
                picks.push(g);
            }
        }
    }
    let (open, carved) = picks.split_at(picks.len() / 2);
    let hits = open.iter().flatten().count();
    assert!(
        hits >= 60,
        "only {hits} of {} rays hit the ball",
        open.len()
    );
    assert!(
        open.iter().zip(carved).any(|(a, b)| a != b),
        "the carving sphere moved no pick"
    );
}
