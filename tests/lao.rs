//! Local Ambient Occlusion: analytic cases, GPU vs CPU twin, ray sets in use.
//! GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{crop, device, texels};

use common::data;
use volao::ao::lao::{LaoGpu, LaoSetup, Rays, lao_cpu, lao_lut};
use volao::ao::rays::RaySet;
use volao::ao::sparse::Coverage;
use volao::render::gpu::RenderVolume;
use volao::texels::BlockRanges;
use volao::tf::{ColorStop, OpacityPoint, TransferFunction};
use volao::volume::{self, LoadOptions, Volume, VoxelData};

/// Opacity 0 below 100, 1 from 155 up (u8 data): a sharp, fully opaque material.
fn step_tf() -> TransferFunction {
    TransferFunction {
        name: "step".into(),
        opacity: vec![
            OpacityPoint {
                value: 100.0,
                alpha: 0.0,
            },
            OpacityPoint {
                value: 155.0,
                alpha: 1.0,
            },
        ],
        color: vec![ColorStop {
            value: 0.0,
            rgb: [1.0; 3],
        }],
    }
}

fn cpu(v: &Volume, tf: &TransferFunction, set: RaySet, samples: u32) -> Vec<f32> {
    let t = texels(v);
    // Every voxel, rays stepping over empty bricks (what `volao ao` writes).
    let bricks = Coverage::Every.bricks(&t, &BlockRanges::new(&t), tf);
    lao_cpu(
        &t,
        &lao_lut(tf, &t),
        &Rays::uniform(set.directions()),
        samples,
        &bricks,
        &|_, _| {},
    )
}

fn filled(n: usize, f: impl Fn(usize, usize, usize) -> u8) -> Volume {
    let data = (0..n * n * n)
        .map(|i| f(i % n, (i / n) % n, i / (n * n)))
        .collect();
    Volume::new([n, n, n], [1.0; 3], VoxelData::U8(data)).expect("valid volume")
}

#[test]
fn empty_volume_is_unoccluded() {
    let a = cpu(&filled(12, |_, _, _| 0), &step_tf(), RaySet::FiftyFour, 20);
    assert!(a.iter().all(|&x| x == 1.0), "A = 1 everywhere");
}

#[test]
fn opaque_volume_gives_one_over_m_inside() {
    let n = 30;
    for (set, m) in [(RaySet::Six, 5u32), (RaySet::TwentySix, 8)] {
        let a = cpu(&filled(n, |_, _, _| 255), &step_tf(), set, m);
        // Eq. 2 with a_i = 1: only the m = 1 term survives, A_k = 1/M, so A = 1/M.
        // Voxels at least M mm from every face see no outside (empty) samples.
        let r = m as usize + 1;
        for z in r..n - r {
            for y in r..n - r {
                for x in r..n - r {
                    let v = a[x + n * (y + n * z)];
                    assert!(
                        (v - 1.0 / m as f32).abs() < 1e-6,
                        "{set:?}: A({x},{y},{z}) = {v}"
                    );
                }
            }
        }
        // Near a face, rays leave into empty space: more light.
        assert!(
            a[0] > 1.0 / m as f32 + 0.1,
            "{set:?}: corner voxel {}",
            a[0]
        );
    }
}

#[test]
fn opaque_half_space_occludes_the_rays_pointing_into_it() {
    // Voxels with z < 16 are opaque; the voxel under test sits in the first empty layer,
    // its centre half a voxel above the interface.
    let n = 32;
    let m = 20u32;
    let v = filled(n, |_, _, z| if z < 16 { 255 } else { 0 });
    for set in [
        RaySet::Six,
        RaySet::Fourteen,
        RaySet::TwentySix,
        RaySet::FiftyFour,
        RaySet::Fibonacci(128),
    ] {
        let a = cpu(&v, &step_tf(), set, m);
        let got = a[16 + n * (16 + n * 16)];
        // A ray going down with slope dz reaches the opaque side at sample ⌈0.5/|dz|⌉:
        // its A_k counts the samples before that; a ray going up or sideways sees nothing.
        let dirs = set.directions();
        let expected: f32 = dirs
            .iter()
            .map(|d| {
                if d.z >= 0.0 {
                    1.0
                } else {
                    ((0.5 / -d.z).ceil() as u32).min(m) as f32 / m as f32
                }
            })
            .sum::<f32>()
            / dirs.len() as f32;
        let down = dirs.iter().filter(|d| d.z < -0.5).count() as f32 / dirs.len() as f32;
        // The transfer function's ramp (100…155 of 255) and trilinear blending make the
        // crossing sample partly opaque: allow one sample per ray, 1/M.
        assert!(
            (got - expected).abs() <= 1.0 / m as f32 + 1e-4,
            "{set:?}: A = {got}, expected {expected}"
        );
        // And the gist: roughly the fraction of rays not pointing into the half-space.
        assert!(
            got < 1.0 - 0.8 * down,
            "{set:?}: A = {got} with {down} of the rays pointing down"
        );
    }
}

/// The shading divides A by what LAO gives a point in front of an open flat surface
/// (`AoReference::open_plane`): that value, computed from the rays alone, is what LAO
/// really computes there, at every distance from the surface.
#[test]
fn open_plane_reference_is_what_lao_computes_in_front_of_an_opaque_plane() {
    use volao::render::AoReference;
    let n = 40;
    let m = 12u32;
    // Opaque for z < 16; the step TF puts the surface at z = 15.5 (half-way between the
    // last full and the first empty voxel), so voxel 16 + k is k + 0.5 mm in front of it.
    let v = filled(n, |_, _, z| if z < 16 { 255 } else { 0 });
    for set in [
        RaySet::Six,
        RaySet::Fourteen,
        RaySet::TwentySix,
        RaySet::FiftyFour,
    ] {
        let a = cpu(&v, &step_tf(), set, m);
        let reference = AoReference::Rays { set, samples: m };
        let mut previous = 0.0;
        for k in 0..6 {
            let h = k as f32 + 0.5;
            let got = a[20 + n * (20 + n * (16 + k))];
            let open = reference.open_plane(h);
            eprintln!("{set:?}, {h} mm in front: LAO {got:.4}, reference {open:.4}");
            // The crossing sample is partly opaque (the TF's ramp): one sample per ray.
            assert!(
                (got - open).abs() <= 1.0 / m as f32 + 1e-4,
                "{set:?}, {h} mm in front: LAO {got}, reference {open}"
            );
            assert!(open > previous, "farther from the surface, less occluded");
            previous = open;
        }
    }
    // Without rays to go by, half the sphere.
    assert_eq!(AoReference::Half.open_plane(3.0), 0.5);
}

#[test]
fn anisotropic_spacing_is_respected() {
    // The same physical scene at 1 mm and at 2 mm slices: A agrees where both sample.
    let iso = filled(24, |_, _, z| if z < 12 { 255 } else { 0 });
    let data: Vec<u8> = (0..24 * 24 * 12)
        .map(|i| if i / (24 * 24) < 6 { 255 } else { 0 })
        .collect();
    let aniso = Volume::new([24, 24, 12], [1.0, 1.0, 2.0], VoxelData::U8(data)).expect("valid");
    let a = cpu(&iso, &step_tf(), RaySet::Six, 6);
    let b = cpu(&aniso, &step_tf(), RaySet::Six, 6);
    // Voxel centre 4.5 mm above the interface in both: rays down reach it at sample 5.
    let ai = a[12 + 24 * (12 + 24 * 16)];
    let bi = b[12 + 24 * (12 + 24 * 8)];
    assert!((ai - bi).abs() < 0.02, "iso {ai} vs aniso {bi}");
}

#[test]
fn gpu_matches_cpu_twin_for_every_ray_set() {
    let gpu = device();
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    let cases = [
        ("engine", "raw/engine.raw", [96, 96, 40], [40, 40, 20]),
        ("cranium", "raw/cranium-ct.raw", [30, 108, 40], [40, 32, 24]),
    ];
    for (name, file, origin, size) in cases {
        let full = volume::load(&data(file), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume;
        let v = crop(&full, origin, size);
        let tf = TransferFunction::preset(volao::tf::Preset::CtBone, &v.stats());
        let t = texels(&v);
        let vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        let lut = lao_lut(&tf, &t);
        let sparse = Coverage::Readable.bricks(&t, vol.ranges(), &tf);
        let dense = Coverage::Dense.bricks(&t, vol.ranges(), &tf);
        assert!(
            sparse.readable.contains(&0),
            "{name}: some bricks must be unreadable"
        );
        assert!(
            sparse.occupied.contains(&0),
            "{name}: some bricks must be empty"
        );
        for set in [
            RaySet::Six,
            RaySet::Fourteen,
            RaySet::TwentySix,
            RaySet::FiftyFour,
            RaySet::Fibonacci(32),
        ] {
            let rays = Rays::uniform(set.directions());
            let setup = LaoSetup {
                lut: &lut,
                rays: &rays,
                samples: 20,
            };
            let g = lao
                .compute(&gpu, &vol, setup, &dense, &|_, _| {})
                .unwrap_or_else(|e| panic!("{e}"));
            let c = lao_cpu(&t, &lut, &rays, 20, &dense, &|_, _| {});
            // Sparse: the readable voxels bit for bit (empty samples skipped, their
            // transmittance still added in order), the others 1; on the GPU and the twin.
            let gs = lao
                .compute(&gpu, &vol, setup, &sparse, &|_, _| {})
                .unwrap_or_else(|e| panic!("{e}"));
            let cs = lao_cpu(&t, &lut, &rays, 20, &sparse, &|_, _| {});
            let readable = sparse.readable_mask(&t);
            for (which, full, part) in [("GPU", &g, &gs), ("CPU", &c, &cs)] {
                let mut unread = 0;
                for (i, (a, b)) in full.iter().zip(part.iter()).enumerate() {
                    if readable[i] {
                        assert_eq!(a.to_bits(), b.to_bits(), "{name} {which} voxel {i}");
                    } else if which == "CPU" || *b == 1.0 {
                        // (The GPU's test is one LUT entry wider: it may compute more.)
                        assert_eq!(*b, 1.0);
                        unread += 1;
                    } else {
                        assert_eq!(a.to_bits(), b.to_bits(), "{name} {which} voxel {i}");
                    }
                }
                assert!(unread > 0);
            }
            let max = g
                .iter()
                .zip(&c)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            eprintln!("{name} {}: max |GPU − CPU| = {max:.2e}", set.name());
            assert!(
                max <= 1.0 / 255.0,
                "{name} {}: max difference {max}",
                set.name()
            );
            assert!(
                c.iter().any(|&a| a < 0.9),
                "{name}: the crop should contain occluded voxels"
            );
        }
    }
}

/// A 48×48×40 piece of the cranium CT with bone and air, under `ct-bone`, as texels.
fn cranium_bone_crop() -> (TransferFunction, volao::texels::VolumeTexels) {
    let full = volume::load(&data("raw/cranium-ct.raw"), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume;
    let v = crop(&full, [30, 100, 30], [48, 48, 40]);
    let tf = TransferFunction::preset(volao::tf::Preset::CtBone, &v.stats());
    let t = texels(&v);
    (tf, t)
}

/// Sparse LAO as rendering computes it (the voxel list: readable voxels only, rays
/// stepping over empty bricks) gives the image of the dense computation, pixel for
/// pixel; with the per-voxel readability test one voxel too tight, readable voxels lose
/// their AO.
#[test]
fn sparse_lao_renders_the_dense_image_and_one_voxel_tighter_loses_readable_voxels() {
    use volao::render::gpu::RayCaster;
    use volao::render::{Camera, Frame, RenderSettings};
    let gpu = device();
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let (tf, t) = cranium_bone_crop();
    let mut vol =
        RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let lut = lao_lut(&tf, &t);
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let frame = Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings: RenderSettings::default(),
        width: 96,
        height: 96,
    };
    let sparse = Coverage::Readable.bricks(&t, vol.ranges(), &tf);
    let dense_bricks = Coverage::Dense.bricks(&t, vol.ranges(), &tf);
    let mut render = |bricks: &volao::ao::sparse::Bricks| {
        let a = lao
            .compute(
                &gpu,
                &vol,
                LaoSetup {
                    lut: &lut,
                    rays: &rays,
                    samples: 12,
                },
                bricks,
                &|_, _| {},
            )
            .unwrap_or_else(|e| panic!("{e}"));
        vol.set_ambient_occlusion(&gpu, &a);
        let img = rc
            .render(&gpu, &vol, &frame, None)
            .unwrap_or_else(|e| panic!("{e}"));
        (a, img.pixels)
    };
    let listed = sparse.voxel_list(&t).len();
    assert!(
        listed > 0 && listed < t.dims.iter().product::<usize>() / 2,
        "the crop must hold readable and unreadable voxels ({listed} listed)"
    );
    let (dense_ao, dense) = render(&dense_bricks);
    let (_, skipped) = render(&sparse);
    assert_eq!(
        common::differing(&skipped, &dense),
        0,
        "sparse LAO changed pixels"
    );
    let mut tight = sparse.clone();
    if let Some(test) = &mut tight.voxels {
        test.below -= 1;
    }
    let (tight_ao, tight_img) = render(&tight);
    let readable = sparse.readable_mask(&t);
    let lost = (0..readable.len())
        .filter(|&i| readable[i] && tight_ao[i] != dense_ao[i])
        .count();
    eprintln!(
        "one voxel too tight: {lost} readable voxels and {} pixels differ",
        common::differing(&tight_img, &dense)
    );
    assert!(
        lost > 0,
        "a test one voxel too tight must miss readable voxels"
    );
}

/// LAO rays skip only cells whose texels, widened by the one voxel a trilinear sample
/// reads beyond them, are all transparent: without that apron the sums change.
#[test]
fn ray_cells_without_their_apron_change_the_sums() {
    use volao::ao::sparse::RAY_CELL;
    let gpu = device();
    let lao = gpu.stage::<LaoGpu>().unwrap_or_else(|e| panic!("{e}"));
    let (tf, t) = cranium_bone_crop();
    let vol =
        RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
    let lut = lao_lut(&tf, &t);
    let rays = Rays::uniform(RaySet::Fourteen.directions());
    let every = Coverage::Every.bricks(&t, vol.ranges(), &tf);
    let dense = Coverage::Dense.bricks(&t, vol.ranges(), &tf);
    let mut tight = every.clone();
    tight.rays.occupied = BlockRanges::of_cells(&t, RAY_CELL, 0).occupancy(&t, &lut);
    assert_ne!(tight.rays.occupied, every.rays.occupied);
    let run = |b: &volao::ao::sparse::Bricks| {
        let setup = LaoSetup {
            lut: &lut,
            rays: &rays,
            samples: 12,
        };
        lao.compute(&gpu, &vol, setup, b, &|_, _| {})
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let want = run(&dense);
    let bits = |a: &[f32]| a.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(common::differing(&bits(&run(&every)), &bits(&want)), 0);
    let wrong = common::differing(&bits(&run(&tight)), &bits(&want));
    eprintln!("cells without their apron: {wrong} voxels differ");
    assert!(wrong > 0, "cells without their apron must change some sums");
    // And the CPU twin with the proper cells gives the same bits as the GPU's.
    let cpu = lao_cpu(&t, &lut, &rays, 12, &every, &|_, _| {});
    let cpu_dense = lao_cpu(&t, &lut, &rays, 12, &dense, &|_, _| {});
    assert_eq!(common::differing(&bits(&cpu), &bits(&cpu_dense)), 0);
}
