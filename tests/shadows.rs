//! Volumetric shadows: the light volume (GPU vs CPU twin on cropped real data, analytic
//! cases) and shadows in the ray caster. GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::data;
use glam::Vec3;
use volao::gpu::{self, Gpu};
use volao::render::shadow::{LightGpu, light_cpu, light_direction, light_lut};
use volao::render::texels::{UploadLimits, VolumeTexels};
use volao::tf::{ColorStop, OpacityPoint, TransferFunction};
use volao::volume::{self, LoadOptions, Volume, VoxelData};

fn device() -> Gpu {
    gpu::request_device().unwrap_or_else(|e| {
        panic!("{e}\n(GPU tests run on Mesa's lavapipe in CI; they are not skipped.)")
    })
}

fn texels(v: &Volume) -> VolumeTexels {
    VolumeTexels::new(
        v,
        UploadLimits {
            max_dim: 4096,
            max_bytes: 1 << 30,
        },
    )
}

fn filled(n: [usize; 3], f: impl Fn(usize, usize, usize) -> u8) -> Volume {
    let data = (0..n[0] * n[1] * n[2])
        .map(|i| f(i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])))
        .collect();
    Volume::new(n, [1.0; 3], VoxelData::U8(data)).expect("valid volume")
}

fn flat_tf(alpha: f32) -> TransferFunction {
    TransferFunction {
        name: "flat".into(),
        opacity: vec![
            OpacityPoint { value: 0.0, alpha },
            OpacityPoint {
                value: 255.0,
                alpha,
            },
        ],
        color: vec![ColorStop {
            value: 0.0,
            rgb: [1.0; 3],
        }],
    }
}

fn gpu_light(gpu: &Gpu, v: &Volume, tf: &TransferFunction, dir: Vec3) -> Vec<f32> {
    let t = texels(v);
    LightGpu::new(&gpu.device)
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(gpu, &t, &light_lut(tf, &t), dir, &|_, _| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn empty_volume_casts_no_shadow() {
    let v = filled([10, 12, 9], |_, _, _| 0);
    let tf = flat_tf(0.0);
    let dir = light_direction([1.0, -2.0, 0.5]).expect("valid");
    let t = texels(&v);
    let c = light_cpu(&t, &light_lut(&tf, &t), dir, &|_, _| {});
    assert!(c.iter().all(|&x| x == 1.0));
    let g = gpu_light(&device(), &v, &tf, dir);
    assert!(g.iter().all(|&x| x == 1.0));
}

#[test]
fn uniform_medium_attenuates_by_beers_law_over_the_jittered_samples() {
    // Constant opacity α per voxel step: T = (1 − α)^N with N the light samples
    // t_i = (i + j)·h (h = 1 mm) before the ray leaves the box.
    let n = [20, 16, 24];
    let v = filled(n, |_, _, _| 77);
    let alpha = 0.05f32;
    let tf = flat_tf(alpha);
    let dir = light_direction([0.3, -0.5, 0.8]).expect("valid");
    let t = texels(&v);
    let c = light_cpu(&t, &light_lut(&tf, &t), dir, &|_, _| {});
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

/// A sub-box of a volume (same type and spacing).
fn crop(v: &Volume, origin: [usize; 3], size: [usize; 3]) -> Volume {
    let [nx, ny, _] = v.dims;
    let idx = |i: usize| {
        let (x, y, z) = (
            i % size[0],
            (i / size[0]) % size[1],
            i / (size[0] * size[1]),
        );
        origin[0] + x + nx * (origin[1] + y + ny * (origin[2] + z))
    };
    let n = size.iter().product::<usize>();
    let data = match &v.data {
        VoxelData::U8(d) => VoxelData::U8((0..n).map(|i| d[idx(i)]).collect()),
        VoxelData::I16(d) => VoxelData::I16((0..n).map(|i| d[idx(i)]).collect()),
        other => panic!("crop: {:?} not needed here", other.voxel_type()),
    };
    Volume::new(size, v.spacing, data).expect("valid crop")
}

fn real_crops() -> Vec<(&'static str, Volume, TransferFunction)> {
    [
        ("engine", "raw/engine.raw", [96, 96, 40], [40, 40, 24]),
        ("cranium", "raw/cranium-ct.raw", [30, 108, 40], [40, 32, 24]),
    ]
    .into_iter()
    .map(|(name, file, origin, size)| {
        let full = volume::load(&data(file), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume;
        let v = crop(&full, origin, size);
        let tf = TransferFunction::preset(volao::tf::Preset::CtBone, &v.stats());
        (name, v, tf)
    })
    .collect()
}

#[test]
fn light_volume_gpu_matches_cpu_twin_on_real_data() {
    let gpu = device();
    for (name, v, tf) in real_crops() {
        let t = texels(&v);
        for d in [[0.0, 0.0, 1.0], [-0.5, 0.6, 0.62], [0.9, -0.2, -0.3]] {
            let dir = light_direction(d).expect("valid");
            let g = gpu_light(&gpu, &v, &tf, dir);
            let c = light_cpu(&t, &light_lut(&tf, &t), dir, &|_, _| {});
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
