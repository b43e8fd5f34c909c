//! Volumetric shadows: the light volume (GPU vs CPU twin on cropped real data, analytic
//! cases) and shadows in the ray caster. GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{device, flat_tf, real_crops, texels, u8_volume};
use volao::clip::gpu::MapRequest;

use glam::Vec3;
use volao::gpu::Gpu;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::shadow::{
    LIGHT_START_STEPS, LightGpu, LightVolume, Lit, filtered_occlusion, light_cpu, light_direction,
    light_lut,
};
use volao::render::{Camera, Frame, Image, RenderSettings, Shading, cpu};
use volao::tf::TransferFunction;
use volao::volume::Volume;

fn gpu_light(gpu: &Gpu, v: &Volume, tf: &TransferFunction, dir: Vec3) -> Vec<f32> {
    let t = texels(v);
    gpu.stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(
            gpu,
            Lit {
                texels: &t,
                segments: None,
                lut: &light_lut(tf, &t),
            },
            dir,
            None,
            &|_, _| {},
        )
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
fn uniform_medium_attenuates_by_beers_law_over_the_light_samples() {
    // Constant opacity α per voxel step: T = (1 − α)^N with N the light samples
    // t_i = (i + s)·h (h = 1 mm, s = LIGHT_START_STEPS, the same for every voxel) before
    // the ray leaves the box.
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
                let s = exit - LIGHT_START_STEPS;
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

use common::TWIN;

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
            let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
                .unwrap_or_else(|e| panic!("{e}"));
            let light = gpu
                .stage::<LightGpu>()
                .unwrap_or_else(|e| panic!("{e}"))
                .compute(
                    &gpu,
                    Lit {
                        texels: &t,
                        segments: None,
                        lut: &light_lut(&tf, &t),
                    },
                    dir,
                    None,
                    &|_, _| {},
                )
                .unwrap_or_else(|e| panic!("{e}"));
            let sampled = vol
                .set_light_volume(&gpu, Some((&light, dir)))
                .unwrap_or_else(|e| panic!("{e}"));
            let g = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
            let c = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
            cv.light = Some(LightVolume::new(&c, t.dims, dir));
            assert_eq!(sampled.map(|l| l.values.len()), Some(light.len()));
            let c = cpu::render(&t, &cv, &vol.lut, &occ, &f);
            let label = format!("shadow_twin_{name}_{shading:?}");
            common::twin(&label, &g, &c, TWIN, &out).unwrap_or_else(|e| panic!("{e}"));
            // Shadows darken: the same frame lit without them is brighter. (Not by 10 % any
            // more: most of that was the lit surfaces shadowing themselves, which the
            // start offset and guard limit remove; the slab test checks both sides.)
            vol.set_light_volume(&gpu, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let lit = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let lum = |img: &Image| img.pixels.iter().map(|p| p[0] as u64).sum::<u64>();
            assert!(
                (lum(&g) as f64) < 0.97 * lum(&lit) as f64,
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
        let got = filtered_occlusion(&linear, dims, at(x), half_step, half_step);
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
    let filtered = steepest(&|x| filtered_occlusion(&edge, dims, at(x), half_step, half_step));
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
    maps.update(
        &gpu,
        MapRequest::clipping(std::slice::from_ref(&plane), radius, 128),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let g = gpu
        .stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(
            &gpu,
            Lit {
                texels: &t,
                segments: None,
                lut: &light_lut(&tf, &t),
            },
            dir,
            Some(&maps),
            &|_, _| {},
        )
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

/// The device for a shadow test: lavapipe in CI, never the GL fallback (whose 3-D
/// storage writes land in slice 0 only).
fn vulkan_device() -> Gpu {
    let gpu = device();
    assert_ne!(
        gpu.info.backend,
        wgpu::Backend::Gl,
        "shadow tests need Vulkan (lavapipe) or a real GPU backend, not GL"
    );
    gpu
}

/// Two opaque slabs across a 64³ volume, lit head-on along +y: the back one fills
/// y ∈ [16, 24), the front one (if `front`) y ∈ [40, 46) over x < 32 only, so its shadow
/// covers x < 32 of the back slab's face.
fn slabs(front: bool) -> (Volume, TransferFunction) {
    use volao::tf::{ColorStop, OpacityPoint};
    let v = u8_volume([64, 64, 64], |x, y, _| {
        let back = (16..24).contains(&y);
        let ahead = front && (40..46).contains(&y) && x < 32;
        if back || ahead { 255 } else { 0 }
    });
    let tf = TransferFunction {
        name: "slab".into(),
        opacity: vec![
            OpacityPoint {
                value: 100.0,
                alpha: 0.0,
            },
            OpacityPoint {
                value: 255.0,
                alpha: 0.95,
            },
        ],
        color: vec![ColorStop {
            value: 0.0,
            rgb: [0.9, 0.85, 0.8],
        }],
    };
    (v, tf)
}

/// A view from 40° beside the light, so that the back slab's face shows both in the
/// front slab's shadow (x < 32) and beside it.
fn slab_frame() -> Frame {
    Frame {
        camera: Camera {
            azimuth_deg: 40.0,
            elevation_deg: 10.0,
            ..Default::default()
        },
        settings: RenderSettings {
            shadows: true,
            light_direction: [0.0, 1.0, 0.0],
            ..Default::default()
        },
        width: 96,
        height: 96,
    }
}

/// Where each pixel's ray meets the back slab's face (y = 24 voxels), as the voxel x of
/// the hit; `None` where it misses the face, or the front slab (if `front`) is in the way.
fn face_hits(
    t: &volao::texels::VolumeTexels,
    lut: &volao::tf::Lut,
    f: &Frame,
    front: bool,
) -> Vec<Option<f32>> {
    use glam::{Mat4, Vec4};
    let p = f.params(t, lut, 0, 0);
    let inv = Mat4::from_cols_array_2d(&p.inv_view_proj);
    (0..f.width * f.height)
        .map(|i| {
            let (px, py) = (i % f.width, i / f.width);
            let x = (px as f32 + 0.5) / f.width as f32 * 2.0 - 1.0;
            let y = 1.0 - (py as f32 + 0.5) / f.height as f32 * 2.0;
            let near = inv * Vec4::new(x, y, 0.0, 1.0);
            let far = inv * Vec4::new(x, y, 1.0, 1.0);
            let o = near.truncate() / near.w;
            let d = (far.truncate() / far.w - o).normalize();
            // Voxel coordinates: mm + 32 (unit spacing, box centred on the origin).
            let at_y = |y_voxel: f32| {
                let s = (y_voxel - 32.0 - o.y) / d.y;
                o + d * s + Vec3::splat(32.0)
            };
            let hit = at_y(24.0);
            let inside = |v: f32| (4.0..60.0).contains(&v);
            let blocked = front && [40.0, 46.0].iter().any(|&y| at_y(y).x < 35.0);
            (d.y < 0.0 && inside(hit.x) && inside(hit.z) && !blocked).then_some(hit.x)
        })
        .collect()
}

/// Mean luminance ratio `shadowed / unshadowed` over the pixels whose face hit lies in
/// `range`, with the worst single pixel's ratio and the pixel count.
fn ratio_over(
    shadowed: &Image,
    unshadowed: &Image,
    hits: &[Option<f32>],
    range: std::ops::Range<f32>,
) -> (f64, f64, usize) {
    let lum = |p: &[u8; 4]| (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0;
    let (mut a, mut b, mut worst, mut n) = (0.0, 0.0, 1.0f64, 0);
    for (i, h) in hits.iter().enumerate() {
        if h.is_some_and(|x| range.contains(&x)) {
            let (s, u) = (lum(&shadowed.pixels[i]), lum(&unshadowed.pixels[i]));
            a += s;
            b += u;
            if (s - u).abs() > 1.0 {
                // Beyond the rounding of one 8-bit level.
                worst = worst.min(s / u.max(1.0)).min(2.0 - s / u.max(1.0));
            }
            n += 1;
        }
    }
    (a / b.max(1e-9), worst, n)
}

#[test]
fn a_lit_slab_does_not_shadow_itself_and_an_occluder_darkens_what_it_hides_gpu_and_cpu() {
    let gpu = vulkan_device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let dir = light_direction([0.0, 1.0, 0.0]).expect("valid");
    let f = slab_frame();
    for front in [false, true] {
        let (v, tf) = slabs(front);
        let t = texels(&v);
        let ones = vec![1.0f32; t.dims.iter().product()];
        let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
            .unwrap_or_else(|e| panic!("{e}"));
        let hits = face_hits(&t, &vol.lut, &f, front);
        // GPU: the light volume of the slabs, and one of no occlusion at all.
        let light = gpu_light(&gpu, &v, &tf, dir);
        let mut gpu_frame = |values: &[f32]| {
            vol.set_light_volume(&gpu, Some((values, dir)))
                .unwrap_or_else(|e| panic!("{e}"));
            rc.render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"))
        };
        let g = (gpu_frame(&light), gpu_frame(&ones));
        // CPU twin: the same from its own light volume.
        let (mut cv, occ) = cpu::prepare(&t, &vol.lut);
        let c_light = light_cpu(&t, &light_lut(&tf, &t), dir, None, &|_, _| {});
        let mut cpu_frame = |values: &[f32]| {
            cv.light = Some(LightVolume::new(values, t.dims, dir));
            cpu::render(&t, &cv, &vol.lut, &occ, &f)
        };
        let c = (cpu_frame(&c_light), cpu_frame(&ones));
        for (who, (shadowed, unshadowed)) in [("GPU", &g), ("CPU twin", &c)] {
            let lit_range = if front { 40.0..60.0 } else { 4.0..60.0 };
            let (lit, worst, n) = ratio_over(shadowed, unshadowed, &hits, lit_range);
            eprintln!(
                "{who}, front slab {front}: lit face {lit:.4} (worst pixel {worst:.4}) over {n} pixels"
            );
            assert!(n > 200, "{who}: {n} pixels of the lit face in view");
            assert!(
                (lit - 1.0).abs() <= 0.02 && worst >= 0.98,
                "{who}, front slab {front}: the lit face keeps {lit:.4} of its unshadowed brightness (worst pixel {worst:.4}); a lit surface must not shadow itself"
            );
            if front {
                let (dark, _, n) = ratio_over(shadowed, unshadowed, &hits, 4.0..26.0);
                eprintln!("{who}: hidden region {dark:.4} over {n} pixels");
                assert!(n > 100, "{who}: {n} pixels of the hidden region in view");
                assert!(
                    dark < 0.7,
                    "{who}: the region the front slab hides from the light keeps {dark:.4} of its brightness"
                );
            }
        }
    }
}

#[test]
fn shadows_add_no_high_frequency_energy_to_the_cranium() {
    // Issue #18's measure (Image::high_frequency_energy: mean |Laplacian| of the
    // luminance over the object after a 2× box downsampling), with shadows from the eye's
    // direction (as `volao render --shadows` without --light) against the same frame
    // without. The cranium halved (128×128×54) at 256² has as many pixels per voxel as
    // the full one at 512², the size the issue measures, for a quarter of the work.
    use volao::texels::{UploadLimits, VolumeTexels};
    let gpu = vulkan_device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let volume = volao::volume::load(&common::data("raw/cranium-ct.raw"), &Default::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras();
    let tf = TransferFunction::preset(volao::tf::Preset::CtBone, &volume.stats());
    let t = VolumeTexels::new(
        &volume,
        UploadLimits {
            max_dim: 128,
            max_bytes: 1 << 30,
        },
    );
    assert_eq!((t.dims, t.downsampled), ([128, 128, 54], 1));
    let camera = Camera {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        distance: 3.2,
        ..Default::default()
    };
    let dir = camera.backward();
    let f = Frame {
        camera,
        settings: RenderSettings {
            shadows: true,
            light_direction: dir.to_array(),
            ..Default::default()
        },
        width: 256,
        height: 256,
    };
    let mut vol = RenderVolume::from_texels(&gpu, t.clone(), &tf, f.settings.step_voxels)
        .unwrap_or_else(|e| panic!("{e}"));
    let plain = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let light = gpu
        .stage::<LightGpu>()
        .unwrap_or_else(|e| panic!("{e}"))
        .compute(
            &gpu,
            Lit {
                texels: &t,
                segments: None,
                lut: &light_lut(&tf, &t),
            },
            dir,
            None,
            &|_, _| {},
        )
        .unwrap_or_else(|e| panic!("{e}"));
    vol.set_light_volume(&gpu, Some((&light, dir)))
        .unwrap_or_else(|e| panic!("{e}"));
    let shadowed = rc
        .render(&gpu, &vol, &f, None)
        .unwrap_or_else(|e| panic!("{e}"));
    let energy = |img: &Image| {
        img.high_frequency_energy([0, 0, 0])
            .expect("the cranium is in view")
    };
    let (off, on) = (energy(&plain), energy(&shadowed));
    eprintln!(
        "high-frequency energy: {off:.3} without shadows, {on:.3} with ({:.3}×)",
        on / off
    );
    assert!(
        off > 5.0,
        "the unshadowed cranium has texture to measure ({off})"
    );
    assert!(
        on <= off,
        "shadows add high-frequency energy: {on:.3} vs {off:.3} without ({:.3}×)",
        on / off
    );
    // And they are there: the frame is darker where the light does not reach.
    let lum = |img: &Image| img.pixels.iter().map(|p| p[1] as u64).sum::<u64>();
    assert!(lum(&shadowed) < lum(&plain), "shadows darken somewhere");
}

#[test]
fn the_light_volume_filter_keeps_linear_light_and_spreads_a_point() {
    use volao::render::shadow::{FILTER_PASSES, filter_light};
    let dims = [40, 3, 2];
    let mut ramp: Vec<f32> = (0..240).map(|i| (i % 40) as f32 / 39.0).collect();
    let before = ramp.clone();
    filter_light(&mut ramp, dims);
    // Unchanged away from the ends (the edge voxel repeats there).
    for i in 0..240 {
        let x = i % 40;
        if (FILTER_PASSES..40 - FILTER_PASSES).contains(&x) {
            assert!(
                (ramp[i] - before[i]).abs() < 1e-6,
                "x = {x}: {} vs {}",
                ramp[i],
                before[i]
            );
        }
    }
    // A single dark voxel in the light becomes a binomial dip: the darkness is kept,
    // spread over 2·passes + 1 voxels along each axis.
    let dims = [41, 41, 41];
    let n: usize = dims.iter().product();
    let mut t = vec![1.0f32; n];
    let centre = 20 + 41 * (20 + 41 * 20);
    t[centre] = 0.0;
    filter_light(&mut t, dims);
    let missing: f64 = t.iter().map(|&v| 1.0 - v as f64).sum();
    assert!((missing - 1.0).abs() < 1e-3, "total darkness {missing}");
    let peak = 1.0 - t[centre] as f64;
    // Binomial centre weight C(2p, p) / 4^p per axis, cubed.
    let p = FILTER_PASSES as u32;
    let w = (1..=p).fold(1.0f64, |c, k| c * (p + k) as f64 / k as f64) / 4f64.powi(p as i32);
    assert!(
        (peak - w.powi(3)).abs() < 1e-4,
        "dip {peak} vs {}",
        w.powi(3)
    );
    assert_eq!(
        t[centre + FILTER_PASSES + 1],
        1.0,
        "nothing beyond the kernel"
    );
}
