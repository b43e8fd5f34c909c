//! `volao bench lao`: the CAO paper's Tables 5–6 (LAO accuracy vs rays) on the Engine,
//! and LAO throughput, GPU vs CPU twin.

use super::rms;
use anyhow::{Result, bail};
use std::path::PathBuf;
use std::time::Instant;
use volao::ao::sparse::Bricks;

/// Arguments of `volao bench lao`.
#[derive(Debug, clap::Args)]
pub struct LaoBenchArgs {
    /// Folder with the shared test data (raw/engine.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Image size for Table 6.
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Samples per ray (the paper's M).
    #[arg(long, default_value_t = volao::ao::lao::DEFAULT_SAMPLES)]
    pub samples: u32,
    /// z-slices of the engine used for the GPU-vs-CPU throughput comparison.
    #[arg(long, default_value_t = 8)]
    pub cpu_slices: usize,
}

/// The CAO paper's Engine figures (Tables 5 and 6) for 6, 14, 26 and 54 rays.
const PAPER_VOXEL_RMS: [f64; 4] = [0.03907, 0.01203, 0.009759, 0.006937];
const PAPER_PIXEL_RMS: [f64; 4] = [11.771, 2.755, 1.936, 1.032];

fn pixel_rms(a: &volao::render::Image, b: &volao::render::Image) -> f64 {
    let sum: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] as f64 - q[c] as f64).powi(2)))
        .sum();
    (sum / (3 * a.pixels.len().max(1)) as f64).sqrt()
}

/// `volao bench lao`: the CAO paper's Tables 5–6 on the Engine, and LAO throughput.
pub fn lao_bench(args: &LaoBenchArgs) -> Result<()> {
    use volao::ao::lao::{LaoGpu, LaoSetup, Rays, lao_cpu, lao_lut};
    use volao::ao::rays::RaySet;
    use volao::render::gpu::{RayCaster, RenderVolume};
    use volao::render::{RenderSettings, Shading};
    use volao::texels::{UploadLimits, VolumeTexels};

    let gpu = volao::gpu::request_device()?;
    let lao = gpu.stage::<LaoGpu>()?;
    let rc = RayCaster::new(&gpu.device)?;
    println!("adapter: {}", gpu.describe());
    let (volume, tf) = super::engine_volume(&args.data)?;
    let mut vol = RenderVolume::new(&gpu, &volume, &tf, RenderSettings::default().step_voxels)?;
    let lut = lao_lut(&tf, &vol.texels);
    let m = args.samples;
    // The AO term alone, as the paper's "LAO rendering": unshaded, k = 1.
    let frame = super::frame(
        25.0,
        RenderSettings {
            shading: Shading::None,
            ambient: 1.0,
            ..Default::default()
        },
        args.size,
    );
    let voxels = vol.texels.dims.iter().product::<usize>() as f64;
    let run = |vol: &RenderVolume, set: RaySet| -> Result<(Vec<f32>, f64)> {
        let start = Instant::now();
        let setup = LaoSetup {
            lut: &lut,
            rays: &Rays::uniform(set.directions()),
            samples: m,
        };
        let a = lao.compute(
            &gpu,
            vol,
            setup,
            &Bricks::dense(vol.texels.dims),
            &|_, _| {},
        )?;
        Ok((a, start.elapsed().as_secs_f64()))
    };
    eprintln!("computing the 512-ray ground truth…");
    let (truth, t_truth) = run(&vol, RaySet::GROUND_TRUTH)?;
    vol.set_ambient_occlusion(&gpu, &truth);
    let truth_image = rc.render(&gpu, &vol, &frame, None)?;
    println!(
        "Engine {:?}, TF {}, M = {m}, image {}², ground truth fib:512 in {:.1} s",
        vol.texels.dims, tf.name, args.size, t_truth
    );
    println!();
    println!(
        "| rays | voxel RMS (volao) | voxel RMS (paper) | pixel RMS (volao) | pixel RMS (paper) | LAO time | samples/s |"
    );
    println!("|---|---|---|---|---|---|---|");
    let sets = [
        (RaySet::Six, Some(0)),
        (RaySet::Fourteen, Some(1)),
        (RaySet::TwentySix, Some(2)),
        (RaySet::FiftyFour, Some(3)),
        (RaySet::Fibonacci(6), None),
        (RaySet::Fibonacci(14), None),
        (RaySet::Fibonacci(26), None),
        (RaySet::Fibonacci(54), None),
    ];
    for (set, paper) in sets {
        let (a, t) = run(&vol, set)?;
        vol.set_ambient_occlusion(&gpu, &a);
        let image = rc.render(&gpu, &vol, &frame, None)?;
        let (pv, pp) = match paper {
            Some(i) => (
                format!("{}", PAPER_VOXEL_RMS[i]),
                format!("{}", PAPER_PIXEL_RMS[i]),
            ),
            None => ("—".into(), "—".into()),
        };
        let samples = voxels * set.count() as f64 * (m.max(2) - 1) as f64;
        println!(
            "| {} | {:.5} | {pv} | {:.3} | {pp} | {:.2} s | {:.2e} |",
            set.name(),
            rms(&a, &truth),
            pixel_rms(&image, &truth_image),
            t,
            samples / t
        );
    }

    // Throughput, GPU vs CPU twin, on the same slab of the engine in this run.
    let z0 = volume.dims[2] / 2;
    let slab = args.cpu_slices.clamp(1, volume.dims[2] - z0);
    let [nx, ny, _] = volume.dims;
    let volao::volume::VoxelData::U8(d) = &volume.data else {
        bail!("the engine is u8")
    };
    let part = volao::volume::Volume::new(
        [nx, ny, slab],
        volume.spacing,
        volao::volume::VoxelData::U8(d[z0 * nx * ny..(z0 + slab) * nx * ny].to_vec()),
    )
    .map_err(|e| anyhow::anyhow!(e))?;
    let texels = VolumeTexels::new(
        &part,
        UploadLimits {
            max_dim: usize::MAX,
            max_bytes: u64::MAX,
        },
    );
    let rays = Rays::uniform(RaySet::FiftyFour.directions());
    let part_lut = lao_lut(&tf, &texels);
    let start = Instant::now();
    lao_cpu(
        &texels,
        &part_lut,
        &rays,
        m,
        &Bricks::dense(texels.dims),
        &|_, _| {},
    );
    let t_cpu = start.elapsed().as_secs_f64();
    let part_vol = RenderVolume::from_texels(&gpu, texels.clone(), &tf, 0.5)?;
    let start = Instant::now();
    let setup = LaoSetup {
        lut: &part_lut,
        rays: &rays,
        samples: m,
    };
    lao.compute(
        &gpu,
        &part_vol,
        setup,
        &Bricks::dense(part_vol.texels.dims),
        &|_, _| {},
    )?;
    let t_gpu = start.elapsed().as_secs_f64();
    let samples = (nx * ny * slab) as f64 * 54.0 * (m.max(2) - 1) as f64;
    println!();
    println!(
        "Throughput on {nx}×{ny}×{slab} engine slices, 54 rays × {m} samples: GPU {:.2e} samples/s ({t_gpu:.2} s), CPU twin ({} threads) {:.2e} samples/s ({t_cpu:.2} s), GPU/CPU {:.1}×",
        samples / t_gpu,
        rayon::current_num_threads(),
        samples / t_cpu,
        t_cpu / t_gpu
    );
    Ok(())
}
