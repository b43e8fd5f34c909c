//! `volao bench filter`: Ruiz et al.'s Table 1 (ms per ambient map on the cranium CT)
//! for the CPU twin and the GPU, and a quality/time table of every cheap AO method
//! against 512-ray LAO. Results go to `docs/benchmarks.md`, never into test assertions.

use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use volao::ao::cone::{ConeGpu, ConePreset, ConeSet, MipPyramid, cone_cpu, opacity};
use volao::ao::filter::{self, AmbientMap, FilterCpu, FilterGpu, Source, StatisticSource};
use volao::ao::lao::{LaoGpu, LaoSetup, Rays, lao_lut};
use volao::ao::rays::RaySet;
use volao::ao::sparse::Bricks;
use volao::texels::gpu::GpuVolume;
use volao::texels::{UploadLimits, VolumeTexels};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, RawOverrides};

/// Arguments of `volao bench filter`.
#[derive(Debug, clap::Args)]
pub struct FilterBenchArgs {
    /// Folder with the shared test data (raw/cranium-ct.raw, raw/engine.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Runs per measurement after one warm-up; the median is reported.
    #[arg(long, default_value_t = 9)]
    pub runs: usize,
    /// Largest engine side for the quality table (the engine is halved until it fits;
    /// 128 gives 128×128×55, where 512-ray LAO takes about a minute and a half).
    #[arg(long, default_value_t = 128)]
    pub engine_max_dim: usize,
    /// LAO samples per ray (1 mm apart) for the ground truth and the cones' reach.
    #[arg(long, default_value_t = volao::ao::lao::DEFAULT_SAMPLES)]
    pub samples: u32,
    /// Cache of the 512-ray ground truth (raw little-endian f32): read if it exists and
    /// has the right size, else computed and written there.
    #[arg(long)]
    pub truth_cache: Option<PathBuf>,
    /// Skip Table 1 (only the quality table).
    #[arg(long)]
    pub skip_table_1: bool,
    /// Skip the quality table (only Table 1).
    #[arg(long)]
    pub skip_quality: bool,
}

/// Ruiz et al. Table 1, CT-head (256×256×113) on a GTX 280, ms: (r, Penner, CDF, Gauss).
const PAPER_TABLE_1: [(u32, [f64; 3]); 2] =
    [(5, [200.0, 161.0, 203.0]), (10, [268.0, 205.0, 270.0])];

const MAPS: [(&str, AmbientMap); 3] = [
    ("Penner", AmbientMap::Penner),
    ("CDF", AmbientMap::Cdf),
    ("Gaussian", AmbientMap::Gauss),
];

/// CPU time of this process so far, all threads, in ms (from the scheduler's
/// nanosecond counters in /proc; 0 where they are missing). On a machine shared with
/// other work, wall-clock times stretch with the load but CPU time does not.
fn cpu_ms() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .filter_map(|t| t.ok())
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        / 1e6
}

/// Median wall-clock ms of `runs` runs after a warm-up.
fn median_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    Ok(in_turns(runs, 1, |_| f())?[0].0)
}

/// Mean of `a` and Pearson correlation of `a` with `b` over the voxels in `mask`.
fn mean_and_correlation(a: &[f32], b: &[f32], mask: &[bool]) -> (f64, f64) {
    let pairs: Vec<(f64, f64)> = (0..a.len())
        .filter(|&i| mask[i])
        .map(|i| (a[i] as f64, b[i] as f64))
        .collect();
    let n = pairs.len().max(1) as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(x, y), (p, q)| (x + p / n, y + q / n));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (p, q) in &pairs {
        sab += (p - ma) * (q - mb);
        saa += (p - ma).powi(2);
        sbb += (q - mb).powi(2);
    }
    (ma, sab / (saa * sbb).sqrt().max(f64::MIN_POSITIVE))
}

fn rms(a: &[f32], b: &[f32], mask: Option<&[bool]>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for i in 0..a.len() {
        if mask.is_none_or(|m| m[i]) {
            sum += ((a[i] - b[i]) as f64).powi(2);
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// `volao bench filter`.
pub fn filter_bench(args: &FilterBenchArgs) -> Result<()> {
    let gpu = volao::gpu::request_device()?;
    let fg = gpu.stage::<FilterGpu>()?;
    let cg = gpu.stage::<ConeGpu>()?;
    println!("adapter: {}", gpu.describe());
    println!("CPU twin: {} rayon threads", rayon::current_num_threads());

    if !args.skip_table_1 {
        table_1(args, &gpu, &fg)?;
    }
    if !args.skip_quality {
        quality(args, &gpu, &fg, &cg)?;
    }
    Ok(())
}

/// Ruiz et al.'s Table 1 on the cranium CT, density statistics as in the paper.
fn table_1(args: &FilterBenchArgs, gpu: &volao::gpu::Gpu, fg: &FilterGpu) -> Result<()> {
    let opts = LoadOptions {
        raw: RawOverrides {
            dims: Some([256, 256, 108]),
            ty: Some(volume::VoxelType::I16),
            endian: Some(volume::Endian::Little),
            spacing: Some([0.957_031, 0.957_031, 1.5]),
            offset: None,
        },
        ..Default::default()
    };
    let cranium = volume::load(&args.data.join("raw/cranium-ct.raw"), &opts)?.volume;
    let tf = TransferFunction::preset(Preset::CtBone, &cranium.stats());
    let vol = GpuVolume::new(gpu, &cranium, &tf, 0.5)?;
    let texels = &vol.texels;
    let source = Source::new(texels, &tf, StatisticSource::Density);
    println!();
    println!(
        "Cranium CT {:?}, density statistics, median of {} runs (ms per map: source values, statistics and map; GPU includes reading the map back, not the volume upload)",
        texels.dims, args.runs
    );
    println!();
    println!(
        "| r | map | CPU twin, first call | CPU twin, again | CPU time / threads | GPU, wall | paper (GTX 280, CT-head 256×256×113) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let threads = rayon::current_num_threads() as f64;
    for (r, paper) in PAPER_TABLE_1 {
        // First call: fresh buffers and a fresh output, as `volao ao --cpu` runs it.
        let first: Vec<f64> = MAPS
            .iter()
            .map(|(_, map)| {
                let start = Instant::now();
                filter::compute_cpu(texels, &source, [r; 3], &[*map]);
                start.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        // Again: the buffers and the output kept, as after a transfer-function edit. The
        // maps take turns, so that the machine's drift spreads over all of them.
        let (mut cpu, mut out) = (FilterCpu::default(), Vec::new());
        let again = in_turns(args.runs, MAPS.len(), |k| {
            cpu.compute_into(texels, &source, [r; 3], &[MAPS[k].1], &mut out);
            Ok(())
        })?;
        for (k, (name, map)) in MAPS.iter().enumerate() {
            let gpu_ms = median_ms(args.runs, || {
                fg.compute(gpu, &vol, &source, [r; 3], &[*map])?;
                Ok(())
            })?;
            let (wall, cpu_time) = again[k];
            println!(
                "| {r} | {name} | {:.1} ms | {wall:.1} ms | {:.1} ms | {gpu_ms:.1} ms | {:.0} ms |",
                first[k],
                cpu_time / threads,
                paper[k]
            );
        }
    }
    Ok(())
}

/// Median wall-clock ms and median CPU ms (all threads) of `runs` runs of each of
/// `items`, taking turns (`f(0)`, `f(1)`, …, then again), after one warm-up each.
fn in_turns(
    runs: usize,
    items: usize,
    mut f: impl FnMut(usize) -> Result<()>,
) -> Result<Vec<(f64, f64)>> {
    for k in 0..items {
        f(k)?;
    }
    let mut times = vec![(Vec::new(), Vec::new()); items];
    for _ in 0..runs.max(1) {
        for (k, (wall, cpu)) in times.iter_mut().enumerate() {
            let (start, c0) = (Instant::now(), cpu_ms());
            f(k)?;
            wall.push(start.elapsed().as_secs_f64() * 1e3);
            cpu.push(cpu_ms() - c0);
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Ok(times
        .into_iter()
        .map(|(wall, cpu)| (median(wall), median(cpu)))
        .collect())
}

/// Every cheap method's RMS against 512-ray LAO on a downsampled engine, with its time.
fn quality(
    args: &FilterBenchArgs,
    gpu: &volao::gpu::Gpu,
    fg: &FilterGpu,
    cg: &ConeGpu,
) -> Result<()> {
    let engine = volume::load(&args.data.join("raw/engine.raw"), &LoadOptions::default())?
        .volume
        .to_ras();
    let etf = TransferFunction::preset(Preset::CaoSingleColor, &engine.stats());
    let et = VolumeTexels::new(
        &engine,
        UploadLimits {
            max_dim: args.engine_max_dim.max(8),
            max_bytes: u64::MAX,
        },
    );
    let evol = GpuVolume::for_compute(gpu, et.clone(), &etf, 0.5)?;
    let lao = gpu.stage::<LaoGpu>()?;
    let lut = lao_lut(&etf, &et);
    let m = args.samples.max(1);
    let start = Instant::now();
    let voxels = et.dims.iter().product::<usize>();
    let cached = args
        .truth_cache
        .as_ref()
        .and_then(|p| std::fs::read(p).ok())
        .filter(|b| b.len() == voxels * 4)
        .map(|b| bytemuck::pod_collect_to_vec::<u8, f32>(&b));
    let from_cache = cached.is_some();
    let truth = match cached {
        Some(t) => t,
        None => {
            let setup = LaoSetup {
                lut: &lut,
                rays: &Rays::uniform(RaySet::GROUND_TRUTH.directions()),
                samples: m,
            };
            let every = Bricks::dense(evol.texels.dims);
            let t = lao.compute(gpu, &evol, setup, &every, &|_, _| {})?;
            if let Some(p) = &args.truth_cache {
                std::fs::write(p, bytemuck::cast_slice(&t))?;
            }
            t
        }
    };
    let t_truth = start.elapsed().as_secs_f64();
    let truth_note = if from_cache {
        " (read from the cache)"
    } else {
        ""
    };
    let alpha = opacity(&et, &etf, None);
    // Surface voxels: visible (α > 0) with a transparent or missing 6-neighbour. They
    // are the voxels a viewer sees; the interior of opaque parts never shows.
    let [ex, ey, ez] = et.dims;
    let surface: Vec<bool> = (0..alpha.len())
        .map(|i| {
            let (x, y, z) = (i % ex, (i / ex) % ey, i / (ex * ey));
            let open = |dx: i64, dy: i64, dz: i64| {
                let (a, b, c) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                if a < 0 || b < 0 || c < 0 || a >= ex as i64 || b >= ey as i64 || c >= ez as i64 {
                    return true;
                }
                alpha[a as usize + ex * (b as usize + ey * c as usize)] == 0.0
            };
            alpha[i] > 0.0
                && (open(1, 0, 0)
                    || open(-1, 0, 0)
                    || open(0, 1, 0)
                    || open(0, -1, 0)
                    || open(0, 0, 1)
                    || open(0, 0, -1))
        })
        .collect();
    println!();
    println!(
        "Engine halved {}× to {:?} (spacing {:?} mm), TF {}, ground truth: LAO fib:512 × {m} samples (reach {m} mm) in {t_truth:.1} s on the GPU{truth_note}; {} of {} voxels on the surface (α > 0 beside α = 0)",
        et.downsampled,
        et.dims,
        et.spacing,
        etf.name,
        surface.iter().filter(|&&v| v).count(),
        surface.len()
    );
    println!();
    let (truth_mean, _) = mean_and_correlation(&truth, &truth, &surface);
    println!("mean A of the ground truth over surface voxels: {truth_mean:.3}");
    println!();
    println!(
        "| method | parameters | RMS, all voxels | RMS, surface voxels | mean A, surface | correlation with LAO, surface | GPU | CPU twin |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let row = |method: &str, params: String, a: &[f32], gpu_ms: f64, cpu_ms: f64| {
        let (mean, corr) = mean_and_correlation(a, &truth, &surface);
        println!(
            "| {method} | {params} | {:.4} | {:.4} | {mean:.3} | {corr:.3} | {gpu_ms:.1} ms | {cpu_ms:.1} ms |",
            rms(a, &truth, None),
            rms(a, &truth, Some(&surface))
        );
    };
    // The reference is dense LAO, every voxel and sample.
    let dense = Bricks::dense(evol.texels.dims);
    for set in [RaySet::Six, RaySet::Fourteen, RaySet::TwentySix] {
        let rays = Rays::uniform(set.directions());
        let setup = LaoSetup {
            lut: &lut,
            rays: &rays,
            samples: m,
        };
        let a = lao.compute(gpu, &evol, setup, &dense, &|_, _| {})?;
        let g = median_ms(1, || {
            lao.compute(gpu, &evol, setup, &dense, &|_, _| {})?;
            Ok(())
        })?;
        let c = median_ms(1, || {
            volao::ao::lao::lao_cpu(&et, &lut, &rays, m, &dense, &|_, _| {});
            Ok(())
        })?;
        row("LAO", format!("{} rays × {m}", set.name()), &a, g, c);
    }
    for kind in [StatisticSource::Density, StatisticSource::Opacity] {
        let src = Source::new(&et, &etf, kind);
        for r in [5u32, 10] {
            for (name, map) in MAPS {
                let a = fg
                    .compute(gpu, &evol, &src, [r; 3], &[map])?
                    .pop()
                    .unwrap_or_default();
                let g = median_ms(args.runs, || {
                    fg.compute(gpu, &evol, &src, [r; 3], &[map])?;
                    Ok(())
                })?;
                let c = median_ms(args.runs, || {
                    filter::compute_cpu(&et, &src, [r; 3], &[map]);
                    Ok(())
                })?;
                row(name, format!("{kind:?}, r = {r}").to_lowercase(), &a, g, c);
            }
        }
    }
    let reach = m as f32 * volao::ao::lao::STEP_MM;
    for cones in [ConeSet::Six, ConeSet::Fourteen, ConeSet::TwentySix] {
        for preset in [ConePreset::Low, ConePreset::Medium, ConePreset::High] {
            // Timed from the opacity volume on: pyramid (CPU) + cones (GPU or CPU).
            let build = || MipPyramid::new(et.dims, opacity(&et, &etf, None));
            let pyramid = build();
            let a = cg.compute(gpu, &et, &pyramid, cones, preset, reach)?;
            let g = median_ms(args.runs, || {
                cg.compute(gpu, &et, &build(), cones, preset, reach)?;
                Ok(())
            })?;
            let c = median_ms(args.runs, || {
                cone_cpu(&et, &build(), cones, preset, reach);
                Ok(())
            })?;
            row(
                "cone",
                format!(
                    "{} cones, {} ({} spheres), reach {reach} mm",
                    cones.count(),
                    preset.name(),
                    preset.spheres()
                ),
                &a,
                g,
                c,
            );
        }
    }
    Ok(())
}
