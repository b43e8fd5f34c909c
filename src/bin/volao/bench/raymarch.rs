//! `volao bench raymarch`: positional AO by ray marching (precomputed and live) and
//! volumetric shadows, on the Engine. Results go to `docs/benchmarks.md`.

use super::{median, rms};
use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use volao::ao::lao::{LaoGpu, Rays, lao_lut};
use volao::ao::rays::RaySet;
use volao::ao::vao::{VaoGpu, VaoInputs, VaoSettings};
use volao::render::RenderSettings;
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::shadow::{LightGpu, Lit, light_direction, light_lut};
use volao::texels::{UploadLimits, VolumeTexels};
use volao::tf::TransferFunction;

/// Arguments of `volao bench raymarch`.
#[derive(Debug, clap::Args)]
pub struct RaymarchBenchArgs {
    /// Folder with the shared test data (raw/engine.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Image size for the frame times.
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Timed frames per configuration (after one warm-up frame); the median is reported.
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// Largest axis of the engine used for the accuracy table (the 512-ray LAO
    /// reference of the full engine takes ~15 min on lavapipe).
    #[arg(long, default_value_t = 128)]
    pub accuracy_dim: usize,
    /// Only the frame-time table (skips the accuracy table and its LAO reference).
    #[arg(long)]
    pub frames_only: bool,
}

/// `volao bench raymarch`.
pub fn raymarch_bench(args: &RaymarchBenchArgs) -> Result<()> {
    let gpu = volao::gpu::request_device()?;
    println!("adapter: {}", gpu.describe());
    let (volume, tf) = super::engine_volume(&args.data)?;

    let kernel = gpu.stage::<VaoGpu>()?;
    let bench = Bench {
        gpu: &gpu,
        kernel: &kernel,
        volume: &volume,
        tf: &tf,
        args,
    };
    if !args.frames_only {
        accuracy(bench)?;
    }
    frames(bench)
}

/// What both parts of the benchmark run on.
#[derive(Clone, Copy)]
struct Bench<'a> {
    gpu: &'a volao::gpu::Gpu,
    kernel: &'a VaoGpu,
    volume: &'a volao::volume::Volume,
    tf: &'a TransferFunction,
    args: &'a RaymarchBenchArgs,
}

type Parts<'a> = (
    &'a volao::gpu::Gpu,
    &'a VaoGpu,
    &'a volao::volume::Volume,
    &'a TransferFunction,
    &'a RaymarchBenchArgs,
);

impl<'a> Bench<'a> {
    fn parts(self) -> Parts<'a> {
        (self.gpu, self.kernel, self.volume, self.tf, self.args)
    }
}

/// Accuracy: positional AO (1 − A_P) against 512-ray LAO (A), on a halved engine.
fn accuracy(bench: Bench) -> Result<()> {
    let (gpu, kernel, volume, tf, args) = bench.parts();
    let small = VolumeTexels::new(
        volume,
        UploadLimits {
            max_dim: args.accuracy_dim.max(8),
            max_bytes: u64::MAX,
        },
    );
    let small_vol = RenderVolume::from_texels(gpu, small.clone(), tf, 0.5)?;
    let voxels = small.dims.iter().product::<usize>() as f64;
    let start = Instant::now();
    let setup = volao::ao::lao::LaoSetup {
        lut: &lao_lut(tf, &small),
        rays: &Rays::uniform(RaySet::GROUND_TRUTH.directions()),
        samples: volao::ao::lao::DEFAULT_SAMPLES,
    };
    let every = volao::ao::sparse::Bricks::dense(small.dims);
    let truth = gpu
        .stage::<LaoGpu>()?
        .compute(gpu, &small_vol, setup, &every, &|_, _| {})?;
    let t_truth = start.elapsed().as_secs_f64();
    println!();
    println!(
        "Engine halved {}× to {:?} ({} mm voxels), TF {}; reference: LAO fib:512 × {} samples (1 mm apart) in {:.1} s",
        small.downsampled,
        small.dims,
        small.spacing[0],
        tf.name,
        volao::ao::lao::DEFAULT_SAMPLES,
        t_truth
    );
    println!();
    println!(
        "| N_dir | N_samples | mip level | time | samples/s | RMS vs LAO-512 | RMS vs VAO-512 dirs | mean 1 − A_P |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let run = |s: &VaoSettings| -> Result<(Vec<f32>, f64, u32)> {
        let inputs = VaoInputs::new(gpu, &small, tf, s)?;
        let start = Instant::now();
        let a = kernel.compute(gpu, small.dims, &inputs, &|_, _| {})?;
        Ok((a, start.elapsed().as_secs_f64(), inputs.params.counts[2]))
    };
    for samples in [8u32, 12] {
        let (dense, _, _) = run(&VaoSettings {
            directions: 512,
            samples,
            ..Default::default()
        })?;
        for directions in [20u32, 54] {
            let s = VaoSettings {
                directions,
                samples,
                ..Default::default()
            };
            let (a, t, level) = run(&s)?;
            let mean = a.iter().map(|&x| x as f64).sum::<f64>() / voxels;
            println!(
                "| {directions} | {samples} | {level} | {:.2} s | {:.2e} | {:.4} | {:.4} | {mean:.4} |",
                t,
                voxels * directions as f64 * (samples as f64 + 1.0) / t,
                rms(&a, &truth),
                rms(&a, &dense),
            );
        }
    }
    let lao_mean = truth.iter().map(|&x| x as f64).sum::<f64>() / voxels;
    println!();
    println!("LAO-512 mean A = {lao_mean:.4}");
    Ok(())
}

/// Frame times on the full engine: no AO, precomputed and live positional AO, shadows.
fn frames(bench: Bench) -> Result<()> {
    let (gpu, kernel, volume, tf, args) = bench.parts();
    let rc = RayCaster::new(&gpu.device)?;
    let frame = super::frame(20.0, RenderSettings::default(), args.size);
    let time_frames = |vol: &RenderVolume| -> Result<f64> {
        rc.render(gpu, vol, &frame, None)?;
        let mut times = Vec::new();
        for _ in 0..args.runs.max(1) {
            let start = Instant::now();
            rc.render(gpu, vol, &frame, None)?;
            times.push(start.elapsed().as_secs_f64());
        }
        Ok(median(times))
    };
    let s = VaoSettings::default();
    let mut vol = RenderVolume::new(gpu, volume, tf, frame.settings.step_voxels)?;
    println!();
    println!(
        "Full engine {:?}, {}² frames, Phong, step 0.5 voxel, skipping on; median of {} after a warm-up",
        vol.texels.dims,
        args.size,
        args.runs.max(1)
    );
    println!();
    println!("| configuration | precomputation | median frame |");
    println!("|---|---|---|");
    let plain = time_frames(&vol)?;
    println!("| no AO, no shadows | — | {:.0} ms |", plain * 1e3);
    let start = Instant::now();
    let inputs = VaoInputs::new(gpu, &vol.texels, tf, &s)?;
    let a = kernel.compute(gpu, vol.texels.dims, &inputs, &|_, _| {})?;
    let t_pre = start.elapsed().as_secs_f64();
    vol.set_ambient_occlusion(gpu, &a);
    let pre = time_frames(&vol)?;
    println!(
        "| positional AO precomputed ({} dirs × {} samples) | {:.1} s | {:.0} ms |",
        s.directions,
        s.samples,
        t_pre,
        pre * 1e3
    );
    let mut live_vol = RenderVolume::new(gpu, volume, tf, frame.settings.step_voxels)?;
    let start = Instant::now();
    live_vol.set_live_vao(gpu, tf, Some(&s))?;
    let t_live_setup = start.elapsed().as_secs_f64();
    let live = time_frames(&live_vol)?;
    println!(
        "| positional AO live ({} dirs × {} samples) | {:.2} s (upload) | {:.0} ms |",
        s.directions,
        s.samples,
        t_live_setup,
        live * 1e3
    );
    let dir = light_direction(volao::render::shadow::DEFAULT_LIGHT).map_err(anyhow::Error::msg)?;
    let start = Instant::now();
    let light = gpu.stage::<LightGpu>()?.compute(
        gpu,
        Lit {
            texels: &vol.texels,
            segments: vol.segment_texels.as_ref(),
            lut: &light_lut(tf, &vol.texels),
        },
        dir,
        None,
        &|_, _| {},
    )?;
    vol.set_light_volume(gpu, Some((&light, dir)))?;
    let t_light = start.elapsed().as_secs_f64();
    let shadowed = time_frames(&vol)?;
    println!(
        "| positional AO precomputed + shadows | {:.1} s (light volume) | {:.0} ms |",
        t_light,
        shadowed * 1e3
    );
    println!();
    println!(
        "Live/precomputed frame time: {:.1}×; shadows add {:.0} ms per frame ({:+.0} %)",
        live / pre,
        (shadowed - pre) * 1e3,
        (shadowed / pre - 1.0) * 100.0
    );
    Ok(())
}
