//! `volao bench render`: frame times of the GPU ray caster.

use super::median;
use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use volao::volume::{self, LoadOptions};

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
    frame: &volao::render::Frame,
    texels: &volao::render::texels::VolumeTexels,
    lut: &volao::tf::Lut,
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
    use volao::render::gpu::{GpuVolume, RayCaster};
    use volao::render::{RenderSettings, Shading};
    use volao::tf::{Preset, TransferFunction};

    let gpu = volao::gpu::request_device()?;
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
                    let settings = RenderSettings {
                        shading,
                        empty_space_skipping: skipping,
                        ..Default::default()
                    };
                    let frame = super::frame(20.0, settings, size);
                    rc.render(&gpu, &vol, &frame, None)?;
                    let mut times = Vec::new();
                    for _ in 0..args.runs.max(1) {
                        let start = Instant::now();
                        rc.render(&gpu, &vol, &frame, None)?;
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
