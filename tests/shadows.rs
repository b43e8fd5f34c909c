//! Volumetric shadows: the light volume (GPU vs CPU twin on cropped real data, analytic
//! cases) and shadows in the ray caster. GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{device, flat_tf, real_crops, texels, u8_volume};

use glam::Vec3;
use volao::gpu::Gpu;
use volao::render::gpu::{GpuVolume, RayCaster};
use volao::render::image::{Tolerance, check};
use volao::render::shadow::{
    LightGpu, LightVolume, light_cpu, light_direction, light_lut, quantise, shadow_factor,
};
use volao::render::{Camera, Frame, Image, RenderSettings, Shading, cpu};
use volao::tf::TransferFunction;
use volao::volume::Volume;

fn gpu_light(gpu: &Gpu, v: &Volume, tf: &TransferFunction, dir: Vec3) -> Vec<f32> {
    let t = texels(v);
    gpu.stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(gpu, &t, &light_lut(tf, &t), dir, None, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn empty_volume_casts_no_shadow() {
    let v = u8_volume([10, 12, 9], |_, _, _| 0);
    let tf = flat_tf(0.0);
    let dir = light_direction([1.0, -2.0, 0.5]).expect("valid");
    let t = texels(&v);
    let c = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
    assert!(c.iter().all(|&x| x == 1.0));
    let g = gpu_light(&device(), &v, &tf, dir);
    assert!(g.iter().all(|&x| x == 1.0));
}

#[test]
fn uniform_medium_attenuates_by_beers_law_over_the_jittered_samples() {
    // Constant opacity α per voxel step: T = (1 − α)^N with N the light samples
    // t_i = (i + j)·h (h = 1 mm) before the ray leaves the box.
    let n = [20, 16, 24];
    let v = u8_volume(n, |_, _, _| 77);
    let alpha = 0.05f32;
    let tf = flat_tf(alpha);
    let dir = light_direction([0.3, -0.5, 0.8]).expect("valid");
    let t = texels(&v);
    let c = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
    let g = gpu_light(&device(), &v, &tf, dir);
    let extent = Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32);
    let mut checked = 0;
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let p = Vec3::new(x as f32, y as f32, z as f32) + 0.5;
                // Distance to the box exit along dir (slab method).
                let exit = ((Vec3::select(dir.cmpgt(Vec3::ZERO), extent, Vec3::ZERO) - p) / dir)
                    .min_element();
                let j = volao::render::jitter((x + n[0] * z) as u32, y as u32);
                let s = exit - j;
                // Skip samples that fall within rounding of the box face.
                if (s - s.round()).abs() < 1e-3 {
                    continue;
                }
                let count = if s < 0.0 { 0 } else { s.floor() as i32 + 1 };
                let expected = (1.0 - alpha).powi(count);
                let i = x + n[0] * (y + n[1] * z);
                assert!(
                    (c[i] - expected).abs() < 1e-5,
                    "CPU T({x},{y},{z}) = {} vs (1 − α)^{count} = {expected}",
                    c[i]
                );
                assert!(
                    (g[i] - expected).abs() < 1e-5,
                    "GPU T({x},{y},{z}) = {} vs (1 − α)^{count} = {expected}",
                    g[i]
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 7000, "{checked} voxels checked");
}

#[test]
fn bad_light_directions_are_refused() {
    for d in [[0.0; 3], [f32::NAN, 1.0, 0.0], [f32::INFINITY, 0.0, 0.0]] {
        assert!(light_direction(d).is_err(), "{d:?}");
    }
}

#[test]
fn light_volume_gpu_matches_cpu_twin_on_real_data() {
    let gpu = device();
    for (name, v, tf) in real_crops() {
        let t = texels(&v);
        for d in [[0.0, 0.0, 1.0], [-0.5, 0.6, 0.62], [0.9, -0.2, -0.3]] {
            let dir = light_direction(d).expect("valid");
            let g = gpu_light(&gpu, &v, &tf, dir);
            let c = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
            let max = g
                .iter()
                .zip(&c)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            eprintln!("{name} light {d:?}: max |GPU − CPU| = {max:.2e}");
            // Both sample the same f16 texels with float weights: only f32 rounding
            // differs (and the T < 1e-4 stop, which moves T by less than 1e-4).
            assert!(max <= 2e-4, "{name} {d:?}: max difference {max}");
            let shadowed = c.iter().filter(|&&x| x < 0.5).count();
            assert!(
                shadowed * 20 > c.len() && shadowed < c.len(),
                "{name}: the crop should be partly in shadow ({shadowed} of {})",
                c.len()
            );
        }
    }
}

/// As tests/render.rs: lavapipe filters the 8-bit volume texture in fixed point, so a
/// sample's opacity and colour may differ slightly from the CPU's f32 trilinear.
const TWIN: Tolerance = Tolerance {
    max_channel_diff: 3,
    max_outlier_fraction: 0.01,
    max_outlier_diff: 64,
};

#[test]
fn shadowed_rendering_gpu_matches_cpu_twin_and_darkens() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("shadows");
    for (name, v, tf) in real_crops() {
        let t = texels(&v);
        for shading in [Shading::None, Shading::Phong] {
            let dir = light_direction([1.0, -0.3, 0.4]).expect("valid");
            let f = Frame {
                camera: Camera {
                    azimuth_deg: 30.0,
                    elevation_deg: 20.0,
                    ..Default::default()
                },
                settings: RenderSettings {
                    shading,
                    ambient: 0.2,
                    shadows: true,
                    light_direction: dir.to_array(),
                    ..Default::default()
                },
                width: 64,
                height: 64,
            };
            let mut vol = GpuVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
                .unwrap_or_else(|e| panic!("{e}"));
            let light = gpu
                .stage::<LightGpu>()
                .unwrap_or_else(|e| panic!("{e}"))
                .compute(&gpu, &t, &light_lut(&tf, &t), dir, None, &|_, _| {})
                .unwrap_or_else(|e| panic!("{e}"));
            let sampled = vol
                .set_light_volume(&gpu, Some((&light, dir)))
                .unwrap_or_else(|e| panic!("{e}"));
            let g = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
            cv.light = Some(LightVolume {
                direction: dir,
                values: quantise(&light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {})),
            });
            assert_eq!(sampled.map(|l| l.values.len()), Some(light.len()));
            let c = cpu::render(&t, &cv, &vol.lut, &occ, &f);
            let label = format!("shadow_twin_{name}_{shading:?}");
            let cmp = check(&label, &g, &c, TWIN, &out).unwrap_or_else(|e| panic!("{e}"));
            eprintln!(
                "{label}: max diff {}, mean {:.3}, outliers {}",
                cmp.max_diff, cmp.mean_diff, cmp.outliers
            );
            // Shadows darken: the same frame lit without them is brighter.
            vol.set_light_volume(&gpu, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let lit = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let lum = |img: &Image| img.pixels.iter().map(|p| p[0] as u64).sum::<u64>();
            assert!(
                (lum(&g) as f64) < 0.9 * lum(&lit) as f64,
                "{label}: shadows must darken ({} vs {})",
                lum(&g),
                lum(&lit)
            );
        }
    }
}

#[test]
fn imagire_filter_keeps_linear_light_and_softens_a_hard_edge() {
    // A light volume with a hard shadow edge at x = 8 (two voxels wide along x).
    let dims = [16, 2, 2];
    let edge: Vec<f32> = (0..64)
        .map(|i| if i % 16 < 8 { 0.0 } else { 1.0 })
        .collect();
    let linear: Vec<f32> = (0..64).map(|i| (i % 16) as f32 / 15.0).collect();
    let half_step = Vec3::new(1.0 / 16.0, 0.0, 0.0); // view step of two voxels
    let at = |x: f32| Vec3::new(x / 16.0, 0.5, 0.5);
    // Weights ¼ + ½ + ¼ = 1 and symmetric: a linear ramp (inside the clamped border)
    // comes back unchanged.
    for i in 4..44 {
        let x = 1.0 + i as f32 * 0.3;
        let got = shadow_factor(&linear, dims, at(x), half_step);
        let want = (x - 0.5) / 15.0;
        assert!((got - want).abs() < 1e-5, "x = {x}: {got} vs {want}");
    }
    // Across the hard edge (a one-voxel ramp once trilinear), the steepest jump between
    // view samples two voxels apart is 1 without the filter and 3/4 with it.
    let steepest = |f: &dyn Fn(f32) -> f32| {
        (0..40)
            .map(|i| {
                let x = 5.0 + i as f32 * 0.125;
                (f(x + 2.0) - f(x)).abs()
            })
            .fold(0.0f32, f32::max)
    };
    let plain = steepest(&|x| volao::sample::trilinear(&edge, dims, at(x)));
    let filtered = steepest(&|x| shadow_factor(&edge, dims, at(x), half_step));
    assert!(
        (plain - 1.0).abs() < 1e-6 && (filtered - 0.75).abs() < 1e-6,
        "filtered jump {filtered} vs unfiltered {plain}"
    );
}

#[test]
fn light_passes_through_clipped_space_on_gpu_and_cpu_alike() {
    use volao::clip::ClipShape;
    use volao::clip::gpu::ClipMaps;
    // A uniform medium with the upper half carved away, light from above: voxels just
    // below the cut see the light through empty space.
    let n = [20, 18, 24];
    let v = u8_volume(n, |_, _, _| 90);
    let tf = flat_tf(0.08);
    let dir = light_direction([0.1, 0.2, 1.0]).expect("valid");
    let t = texels(&v);
    let gpu = device();
    let plane = ClipShape::parse("plane:0,0,0,0,0,1").expect("plane");
    let mut maps = ClipMaps::new(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let radius = Vec3::from(t.extent()).length() * 0.5;
    maps.update(&gpu, std::slice::from_ref(&plane), radius, 1.0, 128)
        .unwrap_or_else(|e| panic!("{e}"));
    let g = gpu
        .stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(&gpu, &t, &light_lut(&tf, &t), dir, Some(&maps), &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let cpu_maps = maps.read_back(&gpu).unwrap_or_else(|e| panic!("{e}"));
    let c = light_cpu(&t, &light_lut(&tf, &t), dir, Some(&cpu_maps), &|_, _| {});
    let worst = g
        .iter()
        .zip(&c)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(worst < 1e-4, "GPU vs CPU: {worst}");
    let unclipped = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
    // Just below the cut (z = 11, the plane is at z = 12 mm): brighter when clipped.
    let at = |values: &[f32], x: usize, y: usize, z: usize| values[x + n[0] * (y + n[1] * z)];
    let (lit, shaded) = (at(&c, 10, 9, 11), at(&unclipped, 10, 9, 11));
    assert!(
        lit > 0.8 && shaded < 0.5,
        "clipped {lit} vs unclipped {shaded}"
    );
}
