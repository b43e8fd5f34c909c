//! Positional ambient occlusion by ray marching (Papaioannou et al. 2010, Eq. 4–8):
//! analytic cases, GPU vs CPU twin on cropped real data, live vs precomputed.
//! GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{crop, device, flat_tf, real_crops, texels, u8_volume};
use volao::clip::gpu::MapRequest;

use common::data;
use glam::Vec3;
use volao::ao::vao::{Isosurface, PositionalAo, VaoGpu, VaoInputs, VaoSettings, vao_cpu};
use volao::gpu::Gpu;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::image::{Tolerance, check, compare};
use volao::render::{Camera, Frame, Image, RenderSettings, Shading, cpu};
use volao::tf::TransferFunction;
use volao::volume::{self, LoadOptions, Volume, VoxelData};

/// Opacity rising linearly from 0 at value 0 to `top` at 255 (u8 data).
fn ramp_tf(top: f32) -> TransferFunction {
    common::ramp_tf(0.0, 255.0, top)
}

/// Texture coordinates of the centre of voxel `v`.
fn centre(v: [usize; 3], dims: [usize; 3]) -> Vec3 {
    (Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32) + 0.5)
        / Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32)
}

fn gpu_vao(gpu: &Gpu, v: &Volume, tf: &TransferFunction, s: &VaoSettings) -> Vec<f32> {
    let t = texels(v);
    let inputs = VaoInputs::new(gpu, &t, tf, s).unwrap_or_else(|e| panic!("{e}"));
    gpu.stage::<VaoGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(gpu, t.dims, &inputs, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn empty_volume_is_unoccluded_on_cpu_and_gpu() {
    let v = u8_volume([12, 10, 8], |_, _, _| 0);
    let tf = ramp_tf(1.0);
    for samples in [8, 12] {
        let s = VaoSettings {
            samples,
            r_max_mm: 6.0,
            ..Default::default()
        };
        let t = texels(&v);
        let c = vao_cpu(&PositionalAo::new(&t, &tf, &s), t.dims, &|_, _| {});
        assert!(c.iter().all(|&a| a == 1.0), "CPU: 1 − A_P = 1 everywhere");
        let g = gpu_vao(&device(), &v, &tf, &s);
        assert!(
            g.iter().all(|&a| a == 1.0),
            "GPU: 1 − A_P = 1 everywhere, min {}",
            g.iter().copied().fold(1.0, f32::min)
        );
    }
}

#[test]
fn uniform_medium_gives_the_closed_form_of_eq_7() {
    // Constant opacity V per voxel, every sample accepted (V(x_k) = V(x_{k−1})), no ray
    // leaving the box: γ = 1 − [(1 − V)^N]^(r_max / (v_s N)) = 1 − (1 − V)^(r_max / v_s)
    // for every ray, hence A_P the same, whatever N (and mip level: 4 samples read level 1).
    let n = 40;
    let v = u8_volume([n, n, n], |_, _, _| 128);
    let alpha = 0.3f32;
    let r_max = 12.0f32;
    let expected = 1.0 - (1.0 - alpha).powf(r_max);
    let gpu = device();
    for samples in [4u32, 8, 12] {
        let s = VaoSettings {
            samples,
            r_max_mm: r_max,
            v_thres: 1.0,
            ..Default::default()
        };
        let t = texels(&v);
        let pao = PositionalAo::new(&t, &flat_tf(alpha), &s);
        assert_eq!(pao.params.counts[2], u32::from(samples == 4), "mip level");
        let g = gpu_vao(&gpu, &v, &flat_tf(alpha), &s);
        // Voxels at least r_max + 1 from every face: all samples inside the box.
        let lo = r_max as usize + 1;
        for z in lo..n - lo {
            for y in lo..n - lo {
                for x in lo..n - lo {
                    let cpu = pao.positional_ao(centre([x, y, z], t.dims));
                    assert!(
                        (cpu - expected).abs() < 2e-5,
                        "N = {samples}: CPU A_P({x},{y},{z}) = {cpu}, closed form {expected}"
                    );
                    let gpu_a = 1.0 - g[x + n * (y + n * z)];
                    assert!(
                        (gpu_a - expected).abs() < 2e-5,
                        "N = {samples}: GPU A_P({x},{y},{z}) = {gpu_a}, closed form {expected}"
                    );
                }
            }
        }
        // Near a face, rays leave into empty space: less occlusion.
        let corner = pao.positional_ao(centre([0, 0, 0], t.dims));
        assert!(corner < expected - 0.2, "corner A_P {corner}");
    }
}

#[test]
fn decreasing_density_along_a_ray_is_fully_rejected() {
    // Density falls along +x and is constant in y and z, so along any ray with a +x
    // component every sample is below the one before it: R = 0 throughout (Eq. 4), γ = 0.
    // The same rays through the mirrored field climb the slope and are occluded.
    let n = [64, 24, 24];
    let falling = u8_volume(n, |x, _, _| 255 - (4 * x) as u8);
    let rising = u8_volume(n, |x, _, _| (4 * (n[0] - 1 - x)) as u8);
    let s = VaoSettings {
        directions: 64,
        samples: 8,
        r_max_mm: 10.0,
        ..Default::default()
    };
    let tf = ramp_tf(1.0);
    let (tf_, tr) = (texels(&falling), texels(&rising));
    let pf = PositionalAo::new(&tf_, &tf, &s);
    let pr = PositionalAo::new(&tr, &tf, &s);
    let mut checked = 0;
    for ray in pf.rays.iter().filter(|r| r[0] > 0.2) {
        let at = centre([16, 12, 12], n);
        let g = pf.obscurance(at, *ray);
        assert_eq!(g, 0.0, "falling density along {ray:?}: γ = {g}");
        // Mirrored point and ray direction: the same samples in increasing order.
        let mirrored = [-ray[0], ray[1], ray[2], ray[3]];
        let back = pr.obscurance(centre([n[0] - 1 - 16, 12, 12], n), mirrored);
        assert!(back > 0.1, "rising density along {mirrored:?}: γ = {back}");
        checked += 1;
    }
    assert!(checked > 10, "{checked} rays checked");
}

#[test]
fn bad_settings_are_refused_with_a_reason() {
    let bad = [
        VaoSettings {
            directions: 0,
            ..Default::default()
        },
        VaoSettings {
            samples: 0,
            ..Default::default()
        },
        VaoSettings {
            r_max_mm: f32::NAN,
            ..Default::default()
        },
        VaoSettings {
            v_thres: 0.0,
            ..Default::default()
        },
        VaoSettings {
            isosurface: Some(Isosurface {
                value: 100.0,
                tolerance: -1.0,
            }),
            ..Default::default()
        },
    ];
    for s in bad {
        let e = s.validate().expect_err("must be refused");
        assert!(e.to_string().starts_with("positional AO: "), "{e}");
    }
    assert!(VaoSettings::default().validate().is_ok());
}

#[test]
fn gpu_matches_cpu_twin_on_real_data() {
    let gpu = device();
    for (name, v, tf) in real_crops() {
        let t = texels(&v);
        let stats = v.stats();
        let iso = Isosurface {
            value: stats.min + 0.4 * (stats.max - stats.min),
            tolerance: 0.05 * (stats.max - stats.min),
        };
        let cases = [
            (
                "N_dir 20, N_samples 8 (mip level 1)",
                VaoSettings::default(),
            ),
            (
                "N_dir 54, N_samples 12 (level 0)",
                VaoSettings {
                    directions: 54,
                    samples: 12,
                    ..Default::default()
                },
            ),
            (
                "isosurface",
                VaoSettings {
                    isosurface: Some(iso),
                    ..Default::default()
                },
            ),
        ];
        for (what, s) in cases {
            let g = gpu_vao(&gpu, &v, &tf, &s);
            let c = vao_cpu(&PositionalAo::new(&t, &tf, &s), t.dims, &|_, _| {});
            let diffs: Vec<f32> = g.iter().zip(&c).map(|(a, b)| (a - b).abs()).collect();
            let max = diffs.iter().copied().fold(0.0f32, f32::max);
            eprintln!("{name} {what}: max |GPU − CPU| = {max:.2e}");
            // Both read the same f16 texels with float trilinear weights, so only the
            // last bits of f32 arithmetic differ (≈1e-6 measured on lavapipe). A sample
            // within those bits of V_thres, of its predecessor (Eq. 4) or of the
            // isosurface band's edge could still decide a ray differently; none does on
            // these crops, and a failure here means a real divergence to look at.
            assert!(max <= 1e-4, "{name} {what}: max |GPU − CPU| = {max}");
            let occluded = c.iter().filter(|&&a| a < 0.9).count();
            assert!(
                occluded * 20 > c.len(),
                "{name} {what}: the crop should contain occluded voxels ({occluded})"
            );
        }
    }
}

fn out_dir() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("vao")
}

use common::TWIN;

#[test]
fn live_mode_gpu_matches_cpu_twin() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let (_, v, tf) = real_crops().remove(0);
    let t = texels(&v);
    let s = VaoSettings {
        r_max_mm: 8.0,
        ..Default::default()
    };
    let f = Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings: RenderSettings {
            ambient: 0.8,
            ..Default::default()
        },
        width: 64,
        height: 64,
    };
    let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_live_vao(&gpu, &tf, Some(&s))
        .unwrap_or_else(|e| panic!("{e}"));
    let g = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
    cv.live_vao = Some(PositionalAo::new(&t, &tf, &s));
    let c = cpu::render(&t, &cv, &vol.lut, &occ, &f);
    common::twin("live_twin", &g, &c, TWIN, &out_dir()).unwrap_or_else(|e| panic!("{e}"));
    // And live AO visibly darkens the image compared with no AO.
    cv.live_vao = None;
    let plain = cpu::render(&t, &cv, &vol.lut, &occ, &f);
    let lum = |img: &Image| img.pixels.iter().map(|p| p[0] as u64).sum::<u64>();
    assert!(
        (lum(&c) as f64) < 0.97 * lum(&plain) as f64,
        "live AO must darken: {} vs {}",
        lum(&c),
        lum(&plain)
    );
}

#[test]
fn live_and_precomputed_agree_at_voxel_centres() {
    // An orthographic camera inside the box, looking along −y, one pixel per voxel and
    // one ray step per voxel without jitter: every ray-cast sample sits on a voxel centre,
    // where the precomputed volume's trilinear lookup returns its stored value. So the
    // live image (A_P evaluated at each sample by the ray caster) must match the image
    // shaded from the precomputed volume (A_P evaluated by the precompute kernel).
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let full = volume::load(&data("raw/engine.raw"), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume;
    let n = [16usize, 24, 16];
    let v = crop(&full, [100, 90, 40], n);
    let tf = TransferFunction::preset(volao::tf::Preset::CtBone, &v.stats());
    let t = texels(&v);
    let half = Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32) * 0.5;
    let radius = half.length();
    // Orthographic half height = radius · 1.05 · distance / DEFAULT_DISTANCE = 8 mm.
    let distance = 8.0 * volao::render::camera::DEFAULT_DISTANCE / (radius * 1.05);
    let eye_y = half.y - 2.5; // a voxel centre
    let f = Frame {
        camera: Camera {
            orthographic: true,
            distance,
            target: [0.0, eye_y - distance * radius, 0.0],
            ..Default::default()
        },
        settings: RenderSettings {
            shading: Shading::None,
            ambient: 1.0,
            step_voxels: 1.0,
            jitter: false,
            // Read the AO at the samples themselves (voxel centres), not off the surface.
            ao_offset: 0.0,
            ..Default::default()
        },
        width: n[0] as u32,
        height: n[2] as u32,
    };
    for s in [
        VaoSettings {
            r_max_mm: 6.0,
            ..Default::default()
        },
        VaoSettings {
            directions: 26,
            samples: 4,
            r_max_mm: 10.0,
            ..Default::default()
        },
    ] {
        let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        let inputs = VaoInputs::new(&gpu, &t, &tf, &s).unwrap_or_else(|e| panic!("{e}"));
        let a = gpu
            .stage::<VaoGpu>()
            .unwrap_or_else(|e| panic!("{e}"))
            .compute(&gpu, t.dims, &inputs, &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"));
        vol.set_ambient_occlusion(&gpu, &a);
        let precomputed = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        vol.set_live_vao(&gpu, &tf, Some(&s))
            .unwrap_or_else(|e| panic!("{e}"));
        let live = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        // The precomputed volume is stored as 16-bit unorm (±1/131070) and the sample
        // positions carry f32 rounding of the camera matrices: one level of 255.
        let cmp = compare(
            &live,
            &precomputed,
            Tolerance {
                max_channel_diff: 1,
                max_outlier_fraction: 0.0,
                max_outlier_diff: 1,
            },
        );
        eprintln!(
            "live vs precomputed ({} dirs, {} samples): max diff {}, mean {:.3}",
            s.directions, s.samples, cmp.max_diff, cmp.mean_diff
        );
        assert!(cmp.passed, "live vs precomputed: {cmp:?}");
        let visible = live.pixels.iter().filter(|p| p[3] > 0).count();
        assert!(visible * 2 > live.pixels.len(), "{visible} visible pixels");
        // The check has teeth: without AO the image differs.
        vol.set_live_vao(&gpu, &tf, None)
            .unwrap_or_else(|e| panic!("{e}"));
        let plain = rc
            .render(&gpu, &vol, &f, None)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(compare(&plain, &precomputed, Tolerance::EXACT).max_diff > 10);
    }
}

#[test]
fn live_mode_follows_a_transfer_function_change_at_once() {
    // Switch the TF of a live-AO volume: the next frame equals a fresh volume built with
    // the new TF, and differs from the old one (no precomputation to redo).
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let (_, v, bone) = real_crops().remove(0);
    let soft = TransferFunction::preset(volao::tf::Preset::CtSoftTissue, &v.stats());
    let t = texels(&v);
    let s = VaoSettings {
        r_max_mm: 8.0,
        ..Default::default()
    };
    let f = Frame {
        camera: Camera::default(),
        settings: RenderSettings {
            ambient: 0.9,
            ..Default::default()
        },
        width: 48,
        height: 48,
    };
    let fresh = |tf: &TransferFunction| {
        let mut vol = RenderVolume::from_texels(&gpu, t.clone(), tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        vol.set_live_vao(&gpu, tf, Some(&s))
            .unwrap_or_else(|e| panic!("{e}"));
        vol
    };
    let mut vol = fresh(&bone);
    let before = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_transfer_function(&gpu, &soft, f.settings.step_voxels);
    let after = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let expected = rc
        .render(&gpu, &fresh(&soft), &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        after.pixels, expected.pixels,
        "the switched volume renders as a fresh one"
    );
    assert!(compare(&after, &before, Tolerance::EXACT).max_diff > 10);
}

#[test]
fn scene_files_with_and_without_positional_ao_load() {
    use volao::ao::AoMethod;
    use volao::scene::{Light, Scene};
    let base = r#"{"version": 1, "volume": {"path": null},
        "transfer_function": {"name": "t", "opacity": [{"value": 0, "alpha": 0}, {"value": 1, "alpha": 1}],
                              "color": [{"value": 0, "rgb": [1, 1, 1]}]},
        "width": 8, "height": 8"#;
    let path = std::path::Path::new("scene.json");
    // An older scene: no vao block, no light, no shadows.
    let old = Scene::parse(
        &format!("{base}, \"ambient_occlusion\": {{\"method\": \"lao\"}}}}"),
        path,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(old.ambient_occlusion.vao, VaoSettings::default());
    assert!(!old.render.shadows);
    // A new one with every field.
    let new = Scene::parse(
        &format!(
            "{base}, \"light\": {{\"kind\": \"directional\", \"direction\": [1, 0, 0]}},
             \"render\": {{\"shadows\": true}},
             \"ambient_occlusion\": {{\"method\": \"vao-live\", \"vao\": {{\"directions\": 32,
               \"samples\": 12, \"r_max_mm\": 10, \"v_thres\": 0.9,
               \"isosurface\": {{\"value\": 300, \"tolerance\": 40}}}}}}}}"
        ),
        path,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(new.ambient_occlusion.method, AoMethod::VaoLive);
    assert_eq!(new.ambient_occlusion.vao.directions, 32);
    assert_eq!(
        new.ambient_occlusion.vao.isosurface.map(|i| i.value),
        Some(300.0)
    );
    assert_eq!(
        new.light,
        Light::Directional {
            direction: [1.0, 0.0, 0.0]
        }
    );
    assert!(new.render.shadows);
    // A misspelt field is an error that names it.
    let bad = Scene::parse(
        &format!(
            "{base}, \"ambient_occlusion\": {{\"method\": \"vao\", \"vao\": {{\"rays\": 3}}}}}}"
        ),
        path,
    )
    .expect_err("unknown field");
    assert!(bad.to_string().contains("rays"), "{bad}");
}

#[test]
fn cli_renders_and_computes_positional_ao_and_shadows() {
    use std::process::Command;
    let dir = tempfile::tempdir().expect("temp dir");
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_volao"))
            .args(args)
            .output()
            .expect("volao runs");
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned()
                + &String::from_utf8_lossy(&out.stderr),
        )
    };
    let png = dir.path().join("live.png");
    let scene = dir.path().join("live.json");
    let p = |x: &std::path::Path| x.to_str().expect("utf-8").to_owned();
    let (ok, text) = run(&[
        "render",
        "-o",
        &p(&png),
        "--width",
        "48",
        "--height",
        "48",
        "--ao",
        "vao-live",
        "--vao-directions",
        "14",
        "--vao-samples",
        "6",
        "--shadows",
        "--light",
        "1,0.5,0.5",
        "--save-scene",
        &p(&scene),
    ]);
    assert!(ok, "{text}");
    assert!(
        text.contains("positional AO live, 14 directions × 6 samples"),
        "{text}"
    );
    let saved = volao::scene::Scene::load(&scene).unwrap_or_else(|e| panic!("{e}"));
    assert!(saved.render.shadows);
    assert_eq!(saved.ambient_occlusion.vao.samples, 6);
    assert!(matches!(
        saved.light,
        volao::scene::Light::Directional { .. }
    ));
    // The scene reproduces the image.
    let again = dir.path().join("again.png");
    let (ok, text) = run(&["render", &p(&scene), "-o", &p(&again)]);
    assert!(ok, "{text}");
    let a = Image::load_png(&png).unwrap_or_else(|e| panic!("{e}"));
    let b = Image::load_png(&again).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(a.pixels, b.pixels);
    // volao ao --method vao writes a volume of ambient factors.
    let bucky = data("pvm/Bucky.pvm");
    let out = dir.path().join("bucky_vao.nii");
    let (ok, text) = run(&[
        "ao",
        &p(&bucky),
        "-o",
        &p(&out),
        "--method",
        "vao",
        "--vao-radius",
        "6",
    ]);
    assert!(ok, "{text}");
    assert!(
        text.contains("positional AO, 20 directions × 8 samples, r_max 6 mm"),
        "{text}"
    );
    let v = volume::load(&out, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(v.volume.dims, [32, 32, 32]);
    // Bad values are one-line errors.
    let (ok, text) = run(&[
        "render",
        "-o",
        &p(&png),
        "--ao",
        "vao",
        "--vao-samples",
        "0",
    ]);
    assert!(
        !ok && text.contains("positional AO: the number of samples per ray is 0"),
        "{text}"
    );
    let (ok, text) = run(&["render", "-o", &p(&png), "--light", "0,0,0"]);
    assert!(!ok && text.contains("light direction"), "{text}");
}

#[test]
fn float_volumes_beyond_the_f16_range_give_the_same_ao_and_light() {
    // The f16 copy normalises float texels by their range: values up to 255 000 (far
    // above f16's 65 504) must give what the 8-bit original gives with the same ramp.
    let (_, v, _) = real_crops().remove(0);
    let VoxelData::U8(mut bytes) = v.data.clone() else {
        panic!("the engine is u8")
    };
    bytes[0] = 0;
    bytes[1] = 255;
    let small = Volume::new(v.dims, v.spacing, VoxelData::U8(bytes.clone())).expect("valid");
    let big = Volume::new(
        v.dims,
        v.spacing,
        VoxelData::F32(bytes.iter().map(|&b| b as f32 * 1000.0).collect()),
    )
    .expect("valid");
    let ramp = |top: f64| common::ramp_tf(0.0, top, 0.9);
    let gpu = device();
    let s = VaoSettings::default();
    let a8 = gpu_vao(&gpu, &small, &ramp(255.0), &s);
    let a32 = gpu_vao(&gpu, &big, &ramp(255_000.0), &s);
    let (t8, t32) = (texels(&small), texels(&big));
    let c32 = vao_cpu(
        &PositionalAo::new(&t32, &ramp(255_000.0), &s),
        t32.dims,
        &|_, _| {},
    );
    let max = |x: &[f32], y: &[f32]| {
        x.iter()
            .zip(y)
            .map(|(a, b)| (a - b).abs())
            .fold(
                0.0f32,
                |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
            )
    };
    eprintln!(
        "VAO u8 vs f32×1000: {:.2e}; f32 GPU vs CPU {:.2e}",
        max(&a8, &a32),
        max(&a32, &c32)
    );
    assert!(max(&a8, &a32) <= 1e-3, "u8 vs f32: {}", max(&a8, &a32));
    // Measured 1.6e-4: the float LUT map's last bits (the GPU may fuse `norm·a + b`)
    // tip one of Eq. 4's near-equal comparisons; still far below what shading can show.
    assert!(
        max(&a32, &c32) <= 1e-3,
        "f32 GPU vs CPU: {}",
        max(&a32, &c32)
    );
    assert!(a32.iter().any(|&a| a < 0.9), "some occlusion");
    use volao::render::shadow::{light_cpu, light_direction, light_lut};
    let dir = light_direction([0.3, 0.2, 1.0]).expect("valid");
    let l8 = light_cpu(&t8, &light_lut(&ramp(255.0), &t8), dir, None, &|_, _| {});
    let l32 = light_cpu(
        &t32,
        &light_lut(&ramp(255_000.0), &t32),
        dir,
        None,
        &|_, _| {},
    );
    assert!(
        max(&l8, &l32) <= 1e-3,
        "light u8 vs f32: {}",
        max(&l8, &l32)
    );
}

#[test]
fn v_thres_and_near_full_obscurance_stop_a_ray() {
    // Uniform medium, as in the closed-form test. With V ≥ V_thres the first (accepted)
    // sample ends every ray: γ = 1 − (1 − V)^(Δ / v_s), one stratum's worth. With a dense
    // medium and V_thres = 1 the rays stop once γ ≥ 1 − 1/256 instead of running on.
    let n = 40;
    let v = u8_volume([n, n, n], |_, _, _| 128);
    let t = texels(&v);
    let at = centre([20, 20, 20], t.dims);
    let s = VaoSettings {
        samples: 8,
        r_max_mm: 12.0,
        v_thres: 0.25,
        ..Default::default()
    };
    let stratum = 12.0f32 / 8.0;
    let stopped = PositionalAo::new(&t, &flat_tf(0.3), &s).positional_ao(at);
    let one_stratum = 1.0 - 0.7f32.powf(stratum);
    assert!(
        (stopped - one_stratum).abs() < 1e-5,
        "V_thres: A_P = {stopped}, one stratum {one_stratum}"
    );
    let g = gpu_vao(&device(), &v, &flat_tf(0.3), &s);
    let gpu_a = 1.0 - g[20 + n * (20 + n * 20)];
    assert!((gpu_a - one_stratum).abs() < 1e-5, "GPU: {gpu_a}");
    let dense = PositionalAo::new(&t, &flat_tf(0.6), &VaoSettings { v_thres: 1.0, ..s });
    let a = dense.positional_ao(at);
    // Without the stop: 1 − 0.4^12 = 0.99998; with it the ray ends at the first sample
    // where γ ≥ 1 − 1/256: after 5 samples, γ = 1 − 0.4^7.5 = 0.99899.
    let five = 1.0 - 0.4f32.powf(5.0 * stratum);
    assert!((a - five).abs() < 1e-5, "A_P = {a}, five samples {five}");
}

#[test]
fn live_mode_treats_clipped_space_as_empty_and_matches_its_twin() {
    use volao::clip::ClipShape;
    use volao::clip::gpu::ClipMaps;
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let (_, v, tf) = real_crops().remove(0);
    let t = texels(&v);
    let s = VaoSettings {
        r_max_mm: 8.0,
        ..Default::default()
    };
    let f = Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings: RenderSettings {
            ambient: 1.0,
            shading: volao::render::Shading::None,
            ..Default::default()
        },
        width: 64,
        height: 64,
    };
    let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_live_vao(&gpu, &tf, Some(&s))
        .unwrap_or_else(|e| panic!("{e}"));
    let extent = Vec3::from(t.extent());
    // A slab carving the front half: the cut face loses the occluders in front of it.
    let shape = ClipShape::parse(&format!("plane:0,{},0,0,1,0", -extent.y * 0.1))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut maps = ClipMaps::new(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let request = MapRequest::clipping(std::slice::from_ref(&shape), extent.length() * 0.5, 256);
    maps.update(&gpu, request).unwrap_or_else(|e| panic!("{e}"));
    let g = rc
        .render(&gpu, &vol, &f, Some(&maps))
        .unwrap_or_else(|e| panic!("{e}"));
    let cpu_maps = maps.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
    let mut pao = PositionalAo::new(&t, &tf, &s);
    pao.clip = Some(cpu_maps.clone());
    cv.live_vao = Some(pao);
    cv.clip = Some(cpu_maps);
    let c = cpu::render(&t, &cv, &vol.lut, &occ, &f);
    check("live_clipped_twin", &g, &c, TWIN, &out_dir()).unwrap_or_else(|e| panic!("{e}"));
    // Clip-blind positional AO (clipped occluders still counted) is darker on the cut.
    cv.live_vao = Some(PositionalAo::new(&t, &tf, &s));
    let blind = cpu::render(&t, &cv, &vol.lut, &occ, &f);
    let lum = |img: &Image| img.pixels.iter().map(|p| p[0] as u64).sum::<u64>();
    assert!(
        lum(&c) > lum(&blind),
        "clipped space must not occlude: {} vs {}",
        lum(&c),
        lum(&blind)
    );
}
