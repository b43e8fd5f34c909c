//! `volao bench …`: measurements recorded in `docs/benchmarks.md`, never asserted in tests.

pub mod raymarch;

use crate::volume::{self, LoadOptions, fmt_bytes};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Arguments of `volao bench load`.
#[derive(Debug, clap::Args)]
pub struct LoadBenchArgs {
    /// Folder with the shared test data (nifti/ch2.nii.gz and raw/cranium-ct.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Runs per file and reader; the median time is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Python interpreter with nibabel and numpy installed.
    #[arg(long, default_value = "python3")]
    pub python: String,
}

/// One load measured in a fresh process.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LoadSample {
    pub reader: String,
    pub seconds: f64,
    pub payload_bytes: u64,
    pub rss_before_kb: u64,
    pub hwm_kb: u64,
    /// Mean value, so both readers are seen to read the same numbers.
    pub checksum: f64,
}

impl LoadSample {
    /// Peak memory added by the load, relative to the voxel payload.
    pub fn peak_over_payload(&self) -> f64 {
        (self.hwm_kb.saturating_sub(self.rss_before_kb) * 1024) as f64 / self.payload_bytes as f64
    }
}

fn status_kb(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key) && l[key.len()..].starts_with(':'))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// `volao bench load-one FILE`: load once in this process, print a [`LoadSample`] as JSON.
pub fn load_one(path: &Path) -> Result<()> {
    let before = status_kb("VmRSS");
    let start = Instant::now();
    // cranium-ct.raw takes its layout from the InVesalius .plist beside it.
    let loaded = volume::load(path, &LoadOptions::default())?;
    let seconds = start.elapsed().as_secs_f64();
    let sample = LoadSample {
        reader: "volao".into(),
        seconds,
        payload_bytes: loaded.volume.data.byte_len() as u64,
        rss_before_kb: before,
        hwm_kb: status_kb("VmHWM"),
        checksum: loaded.volume.stats().mean,
    };
    println!("{}", serde_json::to_string(&sample)?);
    Ok(())
}

fn run_json(cmd: &mut Command) -> Result<LoadSample> {
    let out = cmd.output().with_context(|| format!("running {cmd:?}"))?;
    if !out.status.success() {
        bail!(
            "{cmd:?} failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim())
        .with_context(|| format!("parsing the output of {cmd:?}: {text}"))
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// `volao bench load`: volao vs nibabel/numpy, each load in a fresh process.
pub fn load_bench(args: &LoadBenchArgs) -> Result<()> {
    let exe = std::env::current_exe().context("finding the volao executable")?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/nibabel_load.py");
    let files = [
        args.data.join("nifti/ch2.nii.gz"),
        args.data.join("raw/cranium-ct.raw"),
        args.data.join("dicom/cranium-ct"),
        args.data.join("nrrd/cranium-ct.nrrd"),
    ];
    let runs = args.runs.max(1);
    println!(
        "| file | reader | median load | peak memory over payload | payload | ratio (python / volao time) |"
    );
    println!("|---|---|---|---|---|---|");
    for file in &files {
        if !file.exists() {
            bail!(
                "{}: not found (pass --data with the shared data folder)",
                file.display()
            );
        }
        let mut ours = Vec::new();
        let mut theirs = Vec::new();
        // A DICOM folder: dcm2niix's conversion to NIfTI, for scale (it also writes).
        let mut converted = Vec::new();
        for _ in 0..runs {
            if file.is_dir() {
                converted.push(run_json(
                    Command::new(&args.python)
                        .arg(&script)
                        .arg(file)
                        .arg("--dcm2niix"),
                )?);
            }
            ours.push(run_json(
                Command::new(&exe).args(["bench", "load-one"]).arg(file),
            )?);
            let mut py = Command::new(&args.python);
            py.arg(&script).arg(file);
            if file.extension().is_some_and(|e| e == "raw") {
                py.args(["--raw-dtype", "<i2", "--dims", "256", "256", "108"]);
            }
            theirs.push(run_json(&mut py)?);
        }
        let t_ours = median(ours.iter().map(|s| s.seconds).collect());
        let t_theirs = median(theirs.iter().map(|s| s.seconds).collect());
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let t_conv = if converted.is_empty() {
            0.0
        } else {
            median(converted.iter().map(|s| s.seconds).collect())
        };
        for (samples, t) in [(&ours, t_ours), (&theirs, t_theirs), (&converted, t_conv)] {
            let Some(s) = samples.first() else { continue };
            let peak = median(samples.iter().map(LoadSample::peak_over_payload).collect());
            let ratio = if s.reader == "volao" {
                format!("{:.2}", t_theirs / t_ours)
            } else {
                String::new()
            };
            println!(
                "| {name} | {} | {:.1} ms | {peak:.2}× | {} | {ratio} |",
                s.reader,
                t * 1e3,
                fmt_bytes(s.payload_bytes)
            );
        }
        if (ours[0].checksum - theirs[0].checksum).abs() > 1e-6 * ours[0].checksum.abs().max(1.0) {
            bail!(
                "{name}: volao and python read different values (means {} vs {})",
                ours[0].checksum,
                theirs[0].checksum
            );
        }
    }
    Ok(())
}

/// Arguments of `volao bench render`.
#[derive(Debug, clap::Args)]
pub struct RenderBenchArgs {
    /// Folder with the shared test data (raw/engine.raw and raw/cranium-ct.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Timed frames per configuration (after one warm-up frame); the median is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

/// Ray steps inside the volume box for a whole frame: the work a frame would do with
/// neither early termination nor empty-space skipping (both only reduce it).
fn box_steps(
    frame: &crate::render::Frame,
    texels: &crate::render::texels::VolumeTexels,
    lut: &crate::tf::Lut,
) -> f64 {
    use glam::{Mat4, Vec3, Vec4};
    let p = frame.params(texels, lut, 0, 0);
    let inv = Mat4::from_cols_array_2d(&p.inv_view_proj);
    let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
    let mut total = 0.0;
    for py in 0..frame.height {
        for px in 0..frame.width {
            let x = (px as f32 + 0.5) / frame.width as f32 * 2.0 - 1.0;
            let y = 1.0 - (py as f32 + 0.5) / frame.height as f32 * 2.0;
            let near = inv * Vec4::new(x, y, 0.0, 1.0);
            let far = inv * Vec4::new(x, y, 1.0, 1.0);
            let o = near.truncate() / near.w;
            let d = (far.truncate() / far.w - o).normalize();
            let a = (-half - o) / d;
            let b = (half - o) / d;
            let (t0, t1) = (a.min(b).max_element().max(0.0), a.max(b).min_element());
            if t1 > t0 {
                total += ((t1 - t0) / p.step[0]).ceil() as f64;
            }
        }
    }
    total
}

/// `volao bench render`: frame times of the GPU ray caster.
pub fn render_bench(args: &RenderBenchArgs) -> Result<()> {
    use crate::render::gpu::{GpuVolume, RayCaster};
    use crate::render::{Camera, Frame, RenderSettings, Shading};
    use crate::tf::{Preset, TransferFunction};

    let gpu = crate::gpu::request_device()?;
    let rc = RayCaster::new(&gpu.device)?;
    println!("adapter: {}", gpu.describe());
    println!();
    println!("| volume | size | shading | skipping | median frame | box steps/s |");
    println!("|---|---|---|---|---|---|");
    for file in ["raw/engine.raw", "raw/cranium-ct.raw"] {
        let path = args.data.join(file);
        let volume = volume::load(&path, &LoadOptions::default())?
            .volume
            .to_ras();
        let tf = TransferFunction::preset(Preset::CtBone, &volume.stats());
        let vol = GpuVolume::new(&gpu, &volume, &tf, RenderSettings::default().step_voxels)?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        for size in [512u32, 1024] {
            for shading in [Shading::None, Shading::Phong] {
                for skipping in [false, true] {
                    let frame = Frame {
                        camera: Camera {
                            azimuth_deg: 30.0,
                            elevation_deg: 20.0,
                            ..Default::default()
                        },
                        settings: RenderSettings {
                            shading,
                            empty_space_skipping: skipping,
                            ..Default::default()
                        },
                        width: size,
                        height: size,
                    };
                    rc.render(&gpu, &vol, &frame)?;
                    let mut times = Vec::new();
                    for _ in 0..args.runs.max(1) {
                        let start = Instant::now();
                        rc.render(&gpu, &vol, &frame)?;
                        times.push(start.elapsed().as_secs_f64());
                    }
                    let t = median(times);
                    let steps = box_steps(&frame, &vol.texels, &vol.lut);
                    println!(
                        "| {name} | {size}² | {shading:?} | {} | {:.1} ms | {:.2e} |",
                        if skipping { "on" } else { "off" },
                        t * 1e3,
                        steps / t
                    );
                }
            }
        }
    }
    println!();
    println!("Frame time includes the readback of the image to the host. Box steps/s counts the");
    println!(
        "steps rays would take through the whole box; early termination and skipping take fewer."
    );
    Ok(())
}

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
    #[arg(long, default_value_t = crate::ao::lao::DEFAULT_SAMPLES)]
    pub samples: u32,
    /// z-slices of the engine used for the GPU-vs-CPU throughput comparison.
    #[arg(long, default_value_t = 8)]
    pub cpu_slices: usize,
}

/// The CAO paper's Engine figures (Tables 5 and 6) for 6, 14, 26 and 54 rays.
const PAPER_VOXEL_RMS: [f64; 4] = [0.03907, 0.01203, 0.009759, 0.006937];
const PAPER_PIXEL_RMS: [f64; 4] = [11.771, 2.755, 1.936, 1.032];

fn rms(a: &[f32], b: &[f32]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64)
        .sqrt()
}

fn pixel_rms(a: &crate::render::Image, b: &crate::render::Image) -> f64 {
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
    use crate::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
    use crate::ao::rays::RaySet;
    use crate::render::gpu::{GpuVolume, RayCaster};
    use crate::render::texels::{UploadLimits, VolumeTexels};
    use crate::render::{Camera, Frame, RenderSettings, Shading};
    use crate::tf::{Preset, TransferFunction};

    let gpu = crate::gpu::request_device()?;
    let lao = LaoGpu::new(&gpu.device)?;
    let rc = RayCaster::new(&gpu.device)?;
    println!("adapter: {}", gpu.describe());
    let path = args.data.join("raw/engine.raw");
    let volume = volume::load(&path, &LoadOptions::default())?
        .volume
        .to_ras();
    let tf = TransferFunction::preset(Preset::CaoSingleColor, &volume.stats());
    let mut vol = GpuVolume::new(&gpu, &volume, &tf, RenderSettings::default().step_voxels)?;
    let lut = lao_lut(&tf, &vol.texels);
    let m = args.samples;
    // The AO term alone, as the paper's "LAO rendering": unshaded, k = 1.
    let frame = Frame {
        camera: Camera {
            azimuth_deg: 30.0,
            elevation_deg: 25.0,
            ..Default::default()
        },
        settings: RenderSettings {
            shading: Shading::None,
            ambient: 1.0,
            ..Default::default()
        },
        width: args.size,
        height: args.size,
    };
    let voxels = vol.texels.dims.iter().product::<usize>() as f64;
    let run = |vol: &GpuVolume, set: RaySet| -> Result<(Vec<f32>, f64)> {
        let start = Instant::now();
        let a = lao.compute(
            &gpu,
            vol,
            &lut,
            &Rays::uniform(set.directions()),
            m,
            &|_, _| {},
        )?;
        Ok((a, start.elapsed().as_secs_f64()))
    };
    eprintln!("computing the 512-ray ground truth…");
    let (truth, t_truth) = run(&vol, RaySet::GROUND_TRUTH)?;
    vol.set_ambient_occlusion(&gpu, &truth);
    let truth_image = rc.render(&gpu, &vol, &frame)?;
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
        let image = rc.render(&gpu, &vol, &frame)?;
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
    let crate::volume::VoxelData::U8(d) = &volume.data else {
        bail!("the engine is u8")
    };
    let part = crate::volume::Volume::new(
        [nx, ny, slab],
        volume.spacing,
        crate::volume::VoxelData::U8(d[z0 * nx * ny..(z0 + slab) * nx * ny].to_vec()),
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
    lao_cpu(&texels, &part_lut, &rays, m, &|_, _| {});
    let t_cpu = start.elapsed().as_secs_f64();
    let part_vol = GpuVolume::from_texels(&gpu, texels.clone(), &tf, 0.5)?;
    let start = Instant::now();
    lao.compute(&gpu, &part_vol, &part_lut, &rays, m, &|_, _| {})?;
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
