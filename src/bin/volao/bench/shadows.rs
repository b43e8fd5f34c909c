//! `volao bench shadows`: does `--shadows` add texture? The high-frequency energy
//! ([`volao::render::Image::high_frequency_energy`]) of the cranium CT with and without
//! shadows, and the light volume's time. Results go to `docs/benchmarks.md`.

use anyhow::{Context, Result};
use std::path::PathBuf;
use volao::ao::AoSettings;
use volao::render::offscreen::{RenderJob, render};
use volao::render::{Camera, Frame, Image, RenderSettings};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions};

/// Arguments of `volao bench shadows`.
#[derive(Debug, clap::Args)]
pub struct ShadowBenchArgs {
    /// Folder with the shared test data (raw/cranium-ct.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Image side in pixels.
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Step between samples in voxels.
    #[arg(long, default_value_t = 0.5)]
    pub step: f32,
    /// Box-downsample the images by this factor before measuring (e.g. 4 for a 2048²
    /// reference compared at 512²).
    #[arg(long, default_value_t = 1)]
    pub downsample: u32,
    /// Directional light (towards the light, volume RAS); default: from the eye, as
    /// `volao render --shadows` without `--light`.
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::parse_light, allow_hyphen_values = true)]
    pub light: Option<[f32; 3]>,
    /// Render on the CPU twin instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
    /// Write the two images here (shadows_off.png, shadows_on.png).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Measure these PNG files instead of rendering (background: black).
    #[arg(long, num_args = 1.., value_name = "PNG")]
    pub measure: Vec<PathBuf>,
}

/// `volao bench shadows`.
pub fn shadow_bench(args: &ShadowBenchArgs) -> Result<()> {
    if !args.measure.is_empty() {
        for path in &args.measure {
            let image = Image::load_png(path)?.box_downsample(args.downsample);
            println!("{}: {}", path.display(), energy(&image)?);
        }
        return Ok(());
    }
    let path = args.data.join("raw/cranium-ct.raw");
    let volume = volume::load(&path, &LoadOptions::default())
        .with_context(|| format!("{}", path.display()))?
        .volume
        .to_ras();
    let tf = TransferFunction::preset(Preset::CtBone, &volume.stats());
    let camera = Camera {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        distance: 3.2,
        ..Default::default()
    };
    let gpu = match args.cpu {
        true => None,
        false => Some(std::sync::Arc::new(volao::gpu::request_device()?)),
    };
    let device = gpu.as_ref().map_or("CPU twin".into(), |g| g.describe());
    let light = args.light.unwrap_or(camera.backward().to_array());
    println!(
        "cranium CT, ct-bone, {0}×{0}, step {1} voxels, light {light:?}, measured at {2}×{2}; {device}",
        args.size,
        args.step,
        args.size / args.downsample.max(1),
    );
    let mut results = Vec::new();
    for shadows in [false, true] {
        let frame = Frame {
            camera,
            settings: RenderSettings {
                step_voxels: args.step,
                shadows,
                light_direction: light,
                ..Default::default()
            },
            width: args.size,
            height: args.size,
        };
        let ao = AoSettings::default();
        let start = std::time::Instant::now();
        let out = render(
            gpu.as_ref(),
            &RenderJob::new(&volume, &tf, &frame, &ao),
            &|_, _| {},
        )?;
        let seconds = start.elapsed().as_secs_f64();
        if let Some(dir) = &args.out {
            std::fs::create_dir_all(dir)?;
            let name = if shadows { "shadows_on" } else { "shadows_off" };
            out.image.save_png(&dir.join(format!("{name}.png")))?;
        }
        let e = energy(&out.image.box_downsample(args.downsample))?;
        println!(
            "shadows {}: high-frequency energy {e:.2} (frame {:.0} ms{})",
            if shadows { "on " } else { "off" },
            seconds * 1e3,
            if shadows {
                format!(", light volume {:.0} ms", out.light_seconds * 1e3)
            } else {
                String::new()
            }
        );
        results.push(e);
    }
    println!("ratio on/off: {:.3}", results[1] / results[0]);
    Ok(())
}

fn energy(image: &Image) -> Result<f64> {
    image
        .high_frequency_energy([0, 0, 0])
        .context("no object pixels to measure")
}
