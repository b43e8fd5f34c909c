//! Filter-based ambient occlusion (Ruiz et al. 2010): separable box statistics against
//! brute force, analytic cases of the maps, GPU vs CPU twin on real data.
//! GPU tests run on lavapipe in CI; never skipped.

mod common;

use common::{crop, device, texels, u8_volume};

use common::{Rng, data};
use volao::ao::filter::{
    AmbientMap, BoxStats, FilterCpu, FilterGpu, Source, StatisticSource, box_stats_cpu,
    compute_cpu, map_cpu,
};
use volao::render::gpu::RenderVolume;
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, Volume, VoxelData};

/// `(min, max, Σv, Σv², N)` of the cropped box by brute force, in f64.
fn brute(values: &[f32], dims: [usize; 3], r: [u32; 3], at: [usize; 3]) -> [f64; 5] {
    let lo: [usize; 3] = std::array::from_fn(|i| at[i].saturating_sub(r[i] as usize));
    let hi: [usize; 3] = std::array::from_fn(|i| (at[i] + r[i] as usize).min(dims[i] - 1));
    let (mut mn, mut mx, mut s, mut s2, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0, 0.0);
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                let v = values[x + dims[0] * (y + dims[1] * z)] as f64;
                mn = mn.min(v);
                mx = mx.max(v);
                s += v;
                s2 += v * v;
                n += 1.0;
            }
        }
    }
    [mn, mx, s, s2, n]
}

/// Checks every voxel of `stats` against brute force: min/max exactly, sums ≤ 1e-5
/// relative, and the count.
fn assert_matches_brute(what: &str, stats: &BoxStats, values: &[f32]) {
    let dims = stats.dims;
    let mut worst = 0.0f64;
    for i in 0..values.len() {
        let at = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        let [mn, mx, s, s2, n] = brute(values, dims, stats.radius, at);
        let got = stats.raw(i);
        assert_eq!(got[0] as f64, mn, "{what}: min at {at:?}");
        assert_eq!(got[1] as f64, mx, "{what}: max at {at:?}");
        assert_eq!(
            stats.count(at[0], at[1], at[2]) as f64,
            n,
            "{what}: count at {at:?}"
        );
        for (g, want) in [(got[2] as f64, s), (got[3] as f64, s2)] {
            let rel = (g - want).abs() / want.abs().max(1e-30);
            worst = worst.max(if want == 0.0 { g.abs() } else { rel });
            assert!(
                rel <= 1e-5 || (want == 0.0 && g == 0.0),
                "{what}: sum {g} vs brute force {want} at {at:?}"
            );
        }
    }
    eprintln!("{what}: worst relative error of the sums {worst:.2e}");
}

fn random_values(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n)
        .map(|_| (rng.below(1 << 20) as f32) / (1 << 20) as f32)
        .collect()
}

/// Radii that exercise one-voxel boxes, boxes wider than the volume, segments shorter
/// than the window (r > 31) and anisotropic boxes.
const RADII: [[u32; 3]; 6] = [
    [0, 0, 0],
    [1, 2, 3],
    [5, 5, 5],
    [3, 0, 7],
    [20, 1, 2],
    [40, 33, 2],
];

#[test]
fn separable_statistics_equal_brute_force_cpu() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    // [40, 30, 23]: slices wider than one z-pass tile, rows not a multiple of the x
    // pass's interleave, and more slices than the ring of planes holds for small r_z.
    for dims in [[13, 7, 9], [1, 1, 5], [90, 5, 4], [3, 70, 6], [40, 30, 23]] {
        let values = random_values(&mut rng, dims.iter().product());
        for r in RADII {
            let stats = box_stats_cpu(&values, dims, r);
            assert_matches_brute(&format!("CPU {dims:?} r {r:?}"), &stats, &values);
        }
    }
}

/// A `FilterCpu` reused for another radius gives the maps of fresh buffers on one worker
/// thread too. A thread keeps the box sizes of the tile it last did (by tile and z
/// window); until 2026-12-07 it kept them from one run to the next, so a run whose first
/// tile had the index and z window of the last tile before read the other radius's sizes
/// (`reused_cpu_buffers_give_the_same_maps_as_fresh_ones` failed now and then under load,
/// when a thread took no tile of the run between). One tile per slice, one thread: the
/// first tile of the second run is the last of the first, with the same z window.
#[test]
fn a_thread_keeps_no_box_sizes_from_an_earlier_run() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a thread pool");
    let mut rng = Rng(0x0bad_5eed_0000_0001);
    let v = u8_volume([12, 10, 9], |_, _, _| rng.below(256) as u8);
    let t = texels(&v);
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let source = Source::new(&t, &tf, StatisticSource::Density);
    let mut filter = FilterCpu::default();
    let mut reused = Vec::new();
    for r in [[1, 1, 2], [3, 3, 2]] {
        pool.install(|| filter.compute_into(&t, &source, r, &MAPS, &mut reused));
        let fresh = compute_cpu(&t, &source, r, &MAPS);
        for ((map, a), b) in MAPS.iter().zip(&reused).zip(&fresh) {
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "r {r:?} {map:?}: a reused FilterCpu differs from fresh buffers"
            );
        }
    }
}

/// A `FilterCpu` reused across volumes of other sizes, radii and maps gives the same
/// bits as fresh buffers: stale ring planes and output contents are never read.
#[test]
fn reused_cpu_buffers_give_the_same_maps_as_fresh_ones() {
    let mut rng = Rng(0x5151_7777_0000_abcd);
    let mut filter = FilterCpu::default();
    let mut reused = Vec::new();
    for (dims, r) in [
        ([40, 30, 23], [5, 5, 5]),
        ([17, 9, 31], [1, 2, 1]),
        ([40, 30, 23], [2, 7, 3]),
        ([8, 8, 8], [0, 0, 0]),
    ] {
        let n = dims.iter().product::<usize>();
        let v = u8_volume(dims, |_, _, _| rng.below(256) as u8);
        let t = texels(&v);
        let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
        let source = Source::new(&t, &tf, StatisticSource::Density);
        filter.compute_into(&t, &source, r, &MAPS, &mut reused);
        let fresh = compute_cpu(&t, &source, r, &MAPS);
        for ((map, a), b) in MAPS.iter().zip(&reused).zip(&fresh) {
            assert_eq!(a.len(), n);
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{dims:?} r {r:?} {map:?}: reused buffers differ from fresh ones"
            );
        }
        // The fused path (maps straight from the z pass) equals maps from whole
        // statistics volumes.
        let values = source.values(&t);
        let stats = filter.box_stats(&values, dims, r);
        assert_eq!(stats, box_stats_cpu(&values, dims, r), "{dims:?} r {r:?}");
        for (map, a) in MAPS.iter().zip(&reused) {
            let b = map_cpu(*map, &stats, &values);
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{dims:?} r {r:?} {map:?}: fused maps differ from maps of the statistics"
            );
        }
    }
}

/// The twin's AVX2 build (chosen at run time where the CPU has it) gives the same bits
/// as the baseline build: the same IEEE operations, only wider.
#[test]
fn wide_and_baseline_builds_of_the_cpu_twin_agree_bit_for_bit() {
    let full = volume::load(&data("raw/cranium-ct.raw"), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume;
    let v = crop(&full, [60, 70, 30], [70, 50, 40]);
    let t = texels(&v);
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    for kind in [StatisticSource::Density, StatisticSource::Opacity] {
        let source = Source::new(&t, &tf, kind);
        let values = source.values(&t);
        for r in [[5u32; 3], [10, 10, 7], [2, 9, 1]] {
            let wide = FilterCpu::default().compute(&t, &source, r, &MAPS);
            let base = FilterCpu::baseline().compute(&t, &source, r, &MAPS);
            for ((map, a), b) in MAPS.iter().zip(&wide).zip(&base) {
                assert!(
                    a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{kind:?} r {r:?} {map:?}: the builds differ"
                );
            }
            let wide = FilterCpu::default().box_stats(&values, t.dims, r);
            assert_eq!(wide, FilterCpu::baseline().box_stats(&values, t.dims, r));
        }
    }
}

#[test]
fn separable_statistics_equal_brute_force_gpu() {
    let gpu = device();
    let filter = gpu.stage::<FilterGpu>().unwrap_or_else(|e| panic!("{e}"));
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for dims in [[13, 7, 9], [90, 5, 4], [3, 70, 6]] {
        // f32 texels (an 8-bit unorm texel may convert 1 ulp away from k/255 on a GPU).
        // 0 and 1 are present, so the density map is v = norm · 1 + 0: exact on both
        // sides whether or not the GPU fuses the multiply-add.
        let n = dims.iter().product::<usize>();
        let mut values = random_values(&mut rng, n);
        values[0] = 0.0;
        values[n - 1] = 1.0;
        let v = Volume::new(dims, [1.0; 3], VoxelData::F32(values)).expect("valid volume");
        let t = texels(&v);
        let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
        let source = Source::new(&t, &tf, StatisticSource::Density);
        let values = source.values(&t);
        let vol = RenderVolume::from_texels(&gpu, t, &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        for r in RADII {
            let stats = filter
                .box_stats(&gpu, &vol, &source, r)
                .unwrap_or_else(|e| panic!("{e}"));
            assert_matches_brute(&format!("GPU {dims:?} r {r:?}"), &stats, &values);
        }
    }
}

/// The paper's equations evaluated in f64 from brute-force moments.
fn expected(map: AmbientMap, v_x: f64, [mn, mx, s, s2, n]: [f64; 5]) -> f64 {
    let mean = s / n;
    let var = (s2 / n - mean * mean).max(0.0);
    if map == AmbientMap::Variance {
        return var;
    }
    if mx == mn {
        return 1.0;
    }
    match map {
        AmbientMap::Cdf => {
            let t = (v_x - mn) / (mx - mn);
            let beta = (mean - mn) / (mx - mean);
            if t <= 0.0 {
                0.0
            } else if t >= 1.0 {
                1.0
            } else {
                t.powf(beta)
            }
        }
        AmbientMap::Gauss => {
            let x = (v_x - mean) / (var.sqrt() * 2f64.sqrt());
            let a = 8.0 * (std::f64::consts::PI - 3.0)
                / (3.0 * std::f64::consts::PI * (4.0 - std::f64::consts::PI));
            let x2 = x * x;
            let e =
                (1.0 - (-x2 * (4.0 / std::f64::consts::PI + a * x2) / (1.0 + a * x2)).exp()).sqrt();
            0.5 * (1.0 + e.copysign(x))
        }
        AmbientMap::Penner => {
            if v_x >= mean {
                1.0
            } else {
                var / (var + (mean - v_x).powi(2))
            }
        }
        AmbientMap::Variance => var,
    }
}

const MAPS: [AmbientMap; 4] = [
    AmbientMap::Penner,
    AmbientMap::Cdf,
    AmbientMap::Gauss,
    AmbientMap::Variance,
];

fn density_maps(v: &Volume, r: [u32; 3]) -> (Vec<f32>, Vec<Vec<f32>>) {
    let t = texels(v);
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let source = Source::new(&t, &tf, StatisticSource::Density);
    (source.values(&t), compute_cpu(&t, &source, r, &MAPS))
}

fn check_against_equations(what: &str, v: &Volume, r: [u32; 3]) -> Vec<Vec<f32>> {
    let (values, maps) = density_maps(v, r);
    for (map, got) in MAPS.iter().zip(&maps) {
        for i in 0..values.len() {
            let d = v.dims;
            let at = [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])];
            let want = expected(*map, values[i] as f64, brute(&values, d, r, at));
            assert!(
                (got[i] as f64 - want).abs() < 2e-5,
                "{what}: {map:?} at {at:?} = {}, equations give {want}",
                got[i]
            );
        }
    }
    maps
}

#[test]
fn constant_volume_is_unoccluded_and_has_no_variance() {
    let v = u8_volume([9, 8, 7], |_, _, _| 77);
    let maps = check_against_equations("constant", &v, [3, 3, 3]);
    for (map, m) in MAPS.iter().zip(&maps) {
        let want = if *map == AmbientMap::Variance {
            0.0
        } else {
            1.0
        };
        assert!(m.iter().all(|&x| x == want), "{map:?}: {m:?}");
    }
}

#[test]
fn single_bright_voxel() {
    let (n, r) = (11, 2u32);
    let v = u8_volume(
        [n, n, n],
        |x, y, z| if (x, y, z) == (5, 5, 5) { 255 } else { 0 },
    );
    let maps = check_against_equations("bright voxel", &v, [r; 3]);
    let at = |x: usize, y: usize, z: usize| x + n * (y + n * z);
    let (cdf, gauss, penner, var) = (&maps[1], &maps[2], &maps[0], &maps[3]);
    // A dark neighbour sees one bright voxel in its N = 125 box: t = 0, so F = 0;
    // Gaussian: μ = 1/N, σ² = (N−1)/N², z = −μ/σ = −1/√(N−1).
    let big_n = 125.0f64;
    let z = -1.0 / (big_n - 1.0).sqrt();
    let phi = 0.5 * (1.0 + libm_erf(z / 2f64.sqrt()));
    assert_eq!(cdf[at(4, 5, 5)], 0.0);
    assert!(
        (gauss[at(4, 5, 5)] as f64 - phi).abs() < 4e-4,
        "{} vs Φ {phi}",
        gauss[at(4, 5, 5)]
    );
    assert!((var[at(4, 5, 5)] as f64 - (big_n - 1.0) / big_n.powi(2)).abs() < 1e-6);
    assert!((penner[at(4, 5, 5)] as f64 - (big_n - 1.0) / big_n).abs() < 1e-5);
    // The bright voxel itself is the maximum: F = 1, Penner 1, Gaussian Φ(√(N−1)) ≈ 1.
    assert_eq!(cdf[at(5, 5, 5)], 1.0);
    assert_eq!(penner[at(5, 5, 5)], 1.0);
    assert!(gauss[at(5, 5, 5)] > 0.999);
    // Voxels whose box misses it see a constant neighbourhood: 1.
    assert_eq!(cdf[at(0, 0, 0)], 1.0);
    assert_eq!(gauss[at(5, 5, 8)], 1.0);
    assert_eq!(var[at(5, 5, 8)], 0.0);
}

/// erf to 1e-7 by its Maclaurin series (|x| < 1 here), independent of the approximation.
fn libm_erf(x: f64) -> f64 {
    let mut term = x;
    let mut sum = x;
    for k in 1..40 {
        term *= -x * x / k as f64;
        sum += term / (2 * k + 1) as f64;
    }
    2.0 / std::f64::consts::PI.sqrt() * sum
}

#[test]
fn step_edge_and_staircase() {
    // Step edge along x: dark (0) then bright (255) from x = 6.
    let v = u8_volume([12, 4, 4], |x, _, _| if x < 6 { 0 } else { 255 });
    let maps = check_against_equations("step edge", &v, [2, 1, 1]);
    // On the bright side next to the edge, the 5×3×3 box (cropped to 5×3×3 at y = 1)
    // holds 2 dark columns of 5: μ = 3/5, v_x = 1 = v_max, so the CDF is 1 and Penner 1.
    let i = 6 + 12 * (1 + 4);
    assert_eq!(maps[1][i], 1.0);
    assert_eq!(maps[0][i], 1.0);
    // Dark side next to the edge: v_x = v_min, CDF 0; Penner σ²/(σ²+μ²) with μ = 2/5.
    let i = 5 + 12 * (1 + 4);
    assert_eq!(maps[1][i], 0.0);
    let (mu, var) = (0.4f64, 0.4 * 0.6);
    assert!((maps[0][i] as f64 - var / (var + mu * mu)).abs() < 1e-5);
    // A staircase 0 | 128 | 255 gives the CDF a non-trivial t and β.
    let v = u8_volume([9, 3, 3], |x, _, _| match x {
        0..=2 => 0,
        3..=5 => 128,
        _ => 255,
    });
    let maps = check_against_equations("staircase", &v, [4, 1, 1]);
    // Voxel x = 4 sees the whole row: t = 128/255, μ = (3·128/255 + 3)/9 … per column.
    let i = 4 + 9 * (1 + 3);
    let t = 128.0 / 255.0f64;
    let mean = (3.0 * t + 3.0) / 9.0;
    let beta = mean / (1.0 - mean);
    assert!(
        (maps[1][i] as f64 - t.powf(beta)).abs() < 1e-5,
        "{} vs {}",
        maps[1][i],
        t.powf(beta)
    );
    assert!(maps[1][i] > 0.0 && maps[1][i] < 1.0);
}

#[test]
fn gpu_matches_cpu_twin_for_every_map_on_real_data() {
    let gpu = device();
    let filter = gpu.stage::<FilterGpu>().unwrap_or_else(|e| panic!("{e}"));
    let cases = [
        ("engine", "raw/engine.raw", [96, 96, 40], [48, 40, 32]),
        ("cranium", "raw/cranium-ct.raw", [30, 100, 40], [40, 48, 32]),
    ];
    for (name, file, origin, size) in cases {
        let full = volume::load(&data(file), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume;
        let v = crop(&full, origin, size);
        let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
        let t = texels(&v);
        let vol =
            RenderVolume::from_texels(&gpu, t.clone(), &tf, 0.5).unwrap_or_else(|e| panic!("{e}"));
        for kind in [StatisticSource::Density, StatisticSource::Opacity] {
            let source = Source::new(&t, &tf, kind);
            for r in [[5u32; 3], [10, 10, 7]] {
                let g = filter
                    .compute(&gpu, &vol, &source, r, &MAPS)
                    .unwrap_or_else(|e| panic!("{e}"));
                let values = source.values(&t);
                let stats = box_stats_cpu(&values, t.dims, r);
                for (map, gm) in MAPS.iter().zip(&g) {
                    let c = map_cpu(*map, &stats, &values);
                    let max = gm
                        .iter()
                        .zip(&c)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0f32, f32::max);
                    eprintln!("{name} {kind:?} r {r:?} {map:?}: max |GPU − CPU| = {max:.2e}");
                    // The GPU may fuse multiply-adds (1 ulp in the source values and
                    // sums); the Gaussian's steep erf near σ → 0 amplifies that to
                    // ~1e-4. 1e-3 is still a quarter of the 8-bit display step.
                    assert!(max <= 1e-3, "{name} {kind:?} r {r:?} {map:?}: {max}");
                    if *map != AmbientMap::Variance {
                        let spread = c.iter().copied().fold(f32::INFINITY, f32::min);
                        assert!(
                            spread < 0.5,
                            "{name} {map:?}: the crop should be occluded somewhere"
                        );
                    }
                }
            }
        }
    }
}

/// The filter maps, cone tracing and opacity modulation through `volao render`'s path
/// (`offscreen::render`), GPU against the CPU twin.
#[test]
fn offscreen_render_gpu_matches_cpu_for_every_method_and_modulation() {
    use volao::ao::filter::OpacityModulation;
    use volao::ao::{AoMethod, AoSettings};
    use volao::render::image::check;
    use volao::render::offscreen::{RenderJob, Rendered};
    // `volao render`'s path on a fresh device (`on_gpu`) or on the CPU twin.
    let render = |v: &volume::Volume,
                  tf: &TransferFunction,
                  frame: &Frame,
                  ao: &AoSettings,
                  on_gpu: bool,
                  progress: &(dyn Fn(usize, usize) + Sync)|
     -> Result<Rendered, volao::gpu::GpuError> {
        let gpu = on_gpu.then(|| std::sync::Arc::new(device()));
        let job = RenderJob::new(v, tf, frame, ao);
        volao::render::offscreen::render(gpu.as_ref(), &job, progress)
    };
    use common::TWIN;
    use volao::render::{Camera, Frame, Image, RenderSettings};
    let out = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("filter");
    let v = volume::demo::head_phantom(48);
    let tf = TransferFunction::preset(Preset::CtBone, &v.stats());
    let frame = |modulation| Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings: RenderSettings {
            ambient: 0.8,
            opacity_modulation: modulation,
            ..Default::default()
        },
        width: 96,
        height: 96,
    };
    let lum = |img: &Image| {
        img.pixels
            .iter()
            .map(|p| p[0] as u64 + p[1] as u64 + p[2] as u64)
            .sum::<u64>()
    };
    let plain = render(
        &v,
        &tf,
        &frame(None),
        &AoSettings::default(),
        false,
        &|_, _| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for method in [
        AoMethod::Cdf,
        AoMethod::Gauss,
        AoMethod::Penner,
        AoMethod::Cone,
    ] {
        let ao = AoSettings {
            method,
            radius: 4.0,
            samples: 8,
            ..AoSettings::default()
        };
        // Penner's Chebyshev bound stays at or above ½ on this phantom, which the default
        // shading (AO factor min(2A, 1) on ambient and diffuse, A_open = ½) counts as an open
        // surface: its darkening is checked with the ambient-only shading of before #18.
        let mut f = frame(None);
        f.settings.ao_ambient_only = method == AoMethod::Penner;
        let g = render(&v, &tf, &f, &ao, true, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            !g.device.starts_with("CPU twin"),
            "the GPU path must run: {}",
            g.device
        );
        let c = render(&v, &tf, &f, &ao, false, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
        let label = format!("twin_{method:?}");
        let cmp = check(&label, &g.image, &c.image, TWIN, &out).unwrap_or_else(|e| panic!("{e}"));
        eprintln!(
            "{label}: max diff {}, outliers {}",
            cmp.max_diff, cmp.outliers
        );
        assert!(lum(&c.image) < lum(&plain.image), "{method:?} must darken");
    }
    let m = OpacityModulation {
        // σ² of a [0, 1] density is at most 1/4, so every opacity drops to a quarter or
        // less: the volume must turn clearly more transparent.
        sigma2_max: 1.0,
        radius: 3.0,
        ..Default::default()
    };
    let ao = AoSettings::default();
    let g =
        render(&v, &tf, &frame(Some(m)), &ao, true, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let c =
        render(&v, &tf, &frame(Some(m)), &ao, false, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let cmp =
        check("twin_modulation", &g.image, &c.image, TWIN, &out).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "twin_modulation: max diff {}, outliers {}",
        cmp.max_diff, cmp.outliers
    );
    // The volume fades into the black background: the image darkens.
    assert!(
        lum(&c.image) * 10 < lum(&plain.image) * 9,
        "modulation must make the volume more transparent ({} vs {})",
        lum(&c.image),
        lum(&plain.image)
    );
}

fn volao_cli(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_volao"))
        .args(args)
        .output()
        .expect("volao runs")
}

#[test]
fn volao_ao_writes_the_map_the_cpu_twin_computes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("pvm/Bucky.pvm");
    let src = volume::load(&input, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume;
    let t = texels(&src);
    let tf = TransferFunction::preset(Preset::default_for(&src.stats()), &src.stats());
    let gpu = volao::gpu::request_device().unwrap_or_else(|e| {
        panic!("{e}\n(GPU tests run on Mesa's lavapipe in CI; they are not skipped.)")
    });
    for (flag, map) in [
        ("cdf", AmbientMap::Cdf),
        ("gauss", AmbientMap::Gauss),
        ("penner", AmbientMap::Penner),
    ] {
        let out_path = dir.path().join(format!("{flag}.nii"));
        let out = volao_cli(&[
            "ao",
            input.to_str().expect("utf-8 path"),
            "-o",
            out_path.to_str().expect("utf-8 path"),
            "--ao",
            flag,
            "--radius",
            "3",
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{stderr}");
        // A CPU adapter leaves the statistics to the twin, and says so.
        let said = format!("{}{stderr}", String::from_utf8_lossy(&out.stdout));
        let device = if volao::ao::fast::twin_is_faster(&gpu) {
            format!("faster than the CPU adapter {}", gpu.info.name)
        } else {
            gpu.info.name.clone()
        };
        assert!(
            said.contains(&device),
            "{flag}: {said:?} does not name {device:?}"
        );
        let ao = volume::load(&out_path, &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume;
        assert_eq!(ao.dims, src.dims);
        let want = compute_cpu(
            &t,
            &Source::new(&t, &tf, StatisticSource::Density),
            [3; 3],
            &[map],
        )
        .pop()
        .expect("one map");
        let max = (0..want.len())
            .map(|i| (ao.data.get_f64(i) as f32 - want[i]).abs())
            .fold(0.0f32, f32::max);
        // GPU (or CPU) result vs the CPU twin: as in the twin test above.
        assert!(max <= 1e-3, "{flag}: max difference {max}");
    }
}

#[test]
fn volao_render_with_cone_and_modulation_saves_a_scene_that_reproduces_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = |p: &std::path::Path| p.to_str().expect("utf-8 path").to_owned();
    let (png, again, scene) = (
        dir.path().join("a.png"),
        dir.path().join("b.png"),
        dir.path().join("s.json"),
    );
    let bucky = data("pvm/Bucky.pvm");
    let out = volao_cli(&[
        "render",
        &p(&bucky),
        "-o",
        &p(&png),
        "--width",
        "48",
        "--height",
        "48",
        "--ao",
        "cone",
        "--cones",
        "14",
        "--cone-preset",
        "high",
        "--samples",
        "8",
        "--opacity-modulation",
        "0.01,4",
        "--save-scene",
        &p(&scene),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("14 cones × 7 spheres"), "{stdout}");
    let out = volao_cli(&["render", &p(&scene), "-o", &p(&again)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read(&png).expect("png"),
        std::fs::read(&again).expect("png"),
        "the saved scene reproduces the image byte for byte"
    );
    let text = std::fs::read_to_string(&scene).expect("scene");
    let j: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    assert_eq!(j["ambient_occlusion"]["method"], "cone");
    assert_eq!(j["ambient_occlusion"]["cones"], "14");
    assert_eq!(j["ambient_occlusion"]["cone_preset"], "high");
    assert_eq!(j["render"]["opacity_modulation"]["radius"], 4.0);
    // A scene written before these fields existed still loads, with the defaults.
    let mut old = j.clone();
    for key in ["radius", "radius_unit", "statistic", "cones", "cone_preset"] {
        old["ambient_occlusion"]
            .as_object_mut()
            .expect("object")
            .remove(key);
    }
    old["render"]
        .as_object_mut()
        .expect("object")
        .remove("opacity_modulation");
    let s = volao::scene::Scene::parse(&old.to_string(), &scene).unwrap_or_else(|e| panic!("{e}"));
    let d = volao::ao::AoSettings::default();
    assert_eq!(
        (s.ambient_occlusion.radius, s.ambient_occlusion.cones),
        (d.radius, d.cones)
    );
    assert_eq!(s.render.opacity_modulation, None);
}

#[test]
fn bad_filter_and_cone_flags_fail_with_one_error_line() {
    for args in [
        vec!["render", "-o", "/tmp/x.png", "--ao", "box"],
        vec!["render", "-o", "/tmp/x.png", "--ao", "cone", "--cones", "7"],
        vec![
            "render",
            "-o",
            "/tmp/x.png",
            "--ao",
            "cone",
            "--cone-preset",
            "max",
        ],
        vec![
            "render",
            "-o",
            "/tmp/x.png",
            "--ao",
            "cdf",
            "--radius",
            "-2",
        ],
        vec![
            "render",
            "-o",
            "/tmp/x.png",
            "--ao",
            "cdf",
            "--statistic",
            "gradient",
        ],
        vec!["render", "-o", "/tmp/x.png", "--opacity-modulation", "0"],
        vec![
            "render",
            "-o",
            "/tmp/x.png",
            "--opacity-modulation",
            "0.1,-3",
        ],
    ] {
        let out = volao_cli(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("error"), "{args:?}: {err}");
    }
}
