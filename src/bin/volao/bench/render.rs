//! `volao bench render`: frame times of the GPU ray caster.

use super::median;
use anyhow::Result;
use std::path::PathBuf;
use std::time::Instant;
use volao::clip::gpu::MapRequest;
use volao::volume::{self, LoadOptions};

/// Arguments of `volao bench render`.
#[derive(Debug, clap::Args)]
pub struct RenderBenchArgs {
    /// Volumes to time (any format `volao render` reads). Without files and options:
    /// the fixed tables (engine and cranium CT, 512² and 1024², shading, skipping).
    pub files: Vec<PathBuf>,
    /// Folder with the shared test data (raw/engine.raw and raw/cranium-ct.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Timed frames per configuration (after one warm-up frame); the median is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Render modes to time, comma-separated (composite, mip, minip, average, iso[:V]).
    #[arg(long, value_delimiter = ',', default_value = "composite")]
    pub mode: Vec<volao::render::RenderMode>,
    /// Shadings to time, comma-separated (none, phong).
    #[arg(long, value_delimiter = ',', default_value = "phong", value_parser = crate::args::parse_shading)]
    pub shading: Vec<volao::render::Shading>,
    /// AO method, computed once before the frames are timed (unclipped, so not cao or
    /// lao-full).
    #[arg(long, default_value = "none", value_parser = crate::args::ao_method())]
    pub ao: volao::ao::AoMethod,
    /// Transfer-function preset (default: chosen from the volume's range).
    #[arg(long)]
    pub tf: Option<String>,
    /// One JSON object per configuration on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Clip shapes to render with (repeatable, as `volao render --clip`; carving): the
    /// frames then pay the clip test of every sample.
    #[arg(long = "clip", value_name = "SHAPE", value_parser = volao::clip::ClipShape::parse)]
    pub clip: Vec<volao::clip::ClipShape>,
    /// Where shading takes its gradients, comma-separated: `volume` (the precomputed
    /// gradient volume, one fetch; what `volao render` uses) and `samples` (six density
    /// samples per gradient). Each configuration is timed with each, one after the other.
    #[arg(long, value_delimiter = ',', default_value = "volume")]
    pub gradient: Vec<GradientSource>,
    /// A segmentation of the (one) volume: each configuration is timed without and with
    /// it, and V_PAO's update after hiding a segment against its recomputation.
    #[command(flatten)]
    pub labels: crate::args::LabelArgs,
    /// How the segments show (as `volao render --segment`).
    #[arg(long, value_name = "SPEC")]
    pub segment: Vec<String>,
    /// The segments hidden for V_PAO's update (a name pattern or value; default: the one
    /// covering the most bricks below a tenth of them).
    #[arg(long, value_name = "PATTERN", requires = "labels")]
    pub hide: Option<String>,
}

/// `--gradient`: where the ray caster's shading takes its gradients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum GradientSource {
    /// The gradient volume (`volao::render::gradient`).
    Volume,
    /// Six density samples per gradient.
    Samples,
}

impl RenderBenchArgs {
    /// Whether only the fixed tables were asked for.
    fn is_fixed(&self) -> bool {
        self.files.is_empty() && !self.json && self.clip.is_empty() && self.labels.labels.is_none()
    }
}

/// One configuration's result, as `--json` prints it.
#[derive(serde::Serialize)]
struct Timed {
    file: String,
    size: [u32; 2],
    mode: String,
    shading: volao::render::Shading,
    gradient: GradientSource,
    /// Rendered with the segmentation.
    labels: bool,
    ao: volao::ao::AoMethod,
    median_frame_ms: f64,
    /// Time to compute the AO volume (once per file and method), 0 without.
    ao_ms: f64,
    /// Clip shapes the frames were clipped with.
    clip_shapes: usize,
    adapter: String,
}

/// `volao bench render FILE…`: the configurations asked for, warm frames.
fn render_files(args: &RenderBenchArgs) -> Result<()> {
    use std::sync::Arc;
    use volao::ao::{Ambient, AoEngine, AoInput, AoRequest, AoSettings};
    use volao::render::RenderSettings;
    use volao::render::gpu::RayCaster;
    use volao::texels::{UploadLimits, VolumeTexels};
    use volao::tf::{Preset, TransferFunction};

    let ao_name = serde_json::to_value(args.ao)?
        .as_str()
        .unwrap_or_default()
        .to_owned();
    if args.ao.is_clipped() {
        anyhow::bail!(
            "--ao {ao_name}: bench render computes the AO once, unclipped (--clip only clips the frames); use lao"
        );
    }
    if args.files.is_empty() {
        anyhow::bail!(
            "bench render: name the volumes to time (or give no options for the fixed tables)"
        );
    }
    let gpu = Arc::new(volao::gpu::request_device()?);
    let rc = gpu.stage::<RayCaster>()?;
    let adapter = gpu.describe();
    if !args.json {
        println!("adapter: {adapter}");
        println!();
        println!(
            "| volume | size | mode | shading | gradient | labels | AO | median frame | AO time |"
        );
        println!("|---|---|---|---|---|---|---|---|---|");
    }
    if args.labels.labels.is_some() && args.files.len() != 1 {
        anyhow::bail!("bench render --labels: name exactly one volume (the one it segments)");
    }
    for path in &args.files {
        let volume = volume::load(path, &LoadOptions::default())?.volume.to_ras();
        let segmentation = match &args.labels.labels {
            Some(seg) => Some(super::segments::Segmentation::load(
                seg,
                args.labels.label_table.as_deref(),
                &args.segment,
                &volume,
            )?),
            None => None,
        };
        let stats = volume.stats();
        let preset = match &args.tf {
            Some(name) => Preset::from_name(name)?,
            None => Preset::default_for(&stats),
        };
        let tf = TransferFunction::preset(preset, &stats);
        let name = path.display().to_string();
        let texels = VolumeTexels::new(&volume, UploadLimits::of(&gpu));
        // One volume per gradient source, without and with the segmentation (the AO of
        // the first shown on all: the frames' times are what is compared).
        let mut vols = Vec::new();
        for &gradient in &args.gradient {
            vols.push((
                (gradient, false),
                gradient_volume(&gpu, &texels, &tf, gradient)?,
            ));
            if let Some(s) = &segmentation {
                let mut vol = gradient_volume(&gpu, &texels, &tf, gradient)?;
                vol.set_segments(&gpu, Some(s.texels.clone()));
                vols.push(((gradient, true), vol));
            }
        }
        // The AO, computed once on the first and shown on each.
        let ao = AoSettings {
            method: args.ao,
            ..Default::default()
        };
        let start = Instant::now();
        let request = AoRequest {
            tf: &tf,
            settings: &ao,
            clip: None,
            // One AO for every mode timed: an isosurface reads AO wherever it lies.
            coverage: if args
                .mode
                .iter()
                .all(|m| *m == volao::render::RenderMode::Composite)
            {
                volao::ao::sparse::Coverage::Readable
            } else {
                volao::ao::sparse::Coverage::Every
            },
            view: None,
        };
        let computed = AoEngine::on(Some(Arc::clone(&gpu))).compute(
            AoInput::Uploaded(&vols[0].1),
            &request,
            &|_, _| {},
        )?;
        let ao_ms = start.elapsed().as_secs_f64() * 1e3;
        for (_, vol) in vols.iter_mut().skip(1) {
            let again = match &computed.ambient {
                Ambient::One => Ambient::One,
                Ambient::Live => Ambient::Live,
                Ambient::Values(a) => Ambient::Values(a.clone()),
                Ambient::Cao(_) => anyhow::bail!("{name}: bench render computes no CAO"),
            };
            volao::render::offscreen::show_ambient(&gpu, vol, &tf, &ao, again)?;
        }
        volao::render::offscreen::show_ambient(&gpu, &mut vols[0].1, &tf, &ao, computed.ambient)?;
        let maps = match args.clip.is_empty() {
            true => None,
            false => {
                let mut maps = volao::clip::gpu::ClipMaps::new(&gpu)?;
                let radius = glam::Vec3::from(vols[0].1.texels.extent()).length() * 0.5;
                // No AO depends on the clipping: the dilation margin is unused.
                let resolution = AoSettings::default().clip_resolution;
                let update =
                    maps.update(&gpu, MapRequest::clipping(&args.clip, radius, resolution))?;
                if let Some(e) = update.errors.first() {
                    anyhow::bail!("{}: --clip: {e}", path.display());
                }
                Some(maps)
            }
        };
        // Every mode, shading and gradient source, timed frame by frame in turn, so
        // that a drift of the machine's speed touches them alike.
        let configs: Vec<_> = args
            .mode
            .iter()
            .flat_map(|&mode| args.shading.iter().map(move |&shading| (mode, shading)))
            .flat_map(|(mode, shading)| vols.iter().map(move |v| (mode, shading, v)))
            .map(|(mode, shading, v)| {
                let settings = RenderSettings {
                    mode,
                    shading,
                    ..Default::default()
                };
                let mut frame = super::frame(20.0, settings, args.width);
                frame.height = args.height;
                (frame, v)
            })
            .collect();
        let timed: Vec<_> = configs.iter().map(|(f, (_, vol))| (*f, vol)).collect();
        let seconds = interleaved_frames(&gpu, &rc, &timed, maps.as_ref(), args.runs)?;
        for ((frame, ((gradient, labels), _)), seconds) in configs.iter().zip(seconds) {
            let t = Timed {
                file: name.clone(),
                size: [args.width, args.height],
                mode: frame.settings.mode.to_string(),
                shading: frame.settings.shading,
                gradient: *gradient,
                labels: *labels,
                ao: args.ao,
                median_frame_ms: seconds * 1e3,
                ao_ms,
                clip_shapes: args.clip.len(),
                adapter: adapter.clone(),
            };
            if args.json {
                println!("{}", serde_json::to_string(&t)?);
            } else {
                println!(
                    "| {} | {}×{} | {} | {:?} | {:?} | {} | {} | {:.1} ms | {:.0} ms |",
                    t.file,
                    args.width,
                    args.height,
                    t.mode,
                    t.shading,
                    gradient,
                    if t.labels { "yes" } else { "no" },
                    ao_name,
                    t.median_frame_ms,
                    ao_ms
                );
            }
        }
        if let Some(s) = &segmentation {
            let labelled = vols.iter().find(|((_, labels), _)| *labels).map(|(_, v)| v);
            if let Some(vol) = labelled {
                super::segments::pao_update(&gpu, vol, &tf, s, args.hide.as_deref(), args.json)?;
            }
        }
    }
    Ok(())
}

/// A ray-casting volume of `texels` whose shading takes its gradients from `gradient`.
fn gradient_volume(
    gpu: &volao::gpu::Gpu,
    texels: &volao::texels::VolumeTexels,
    tf: &volao::tf::TransferFunction,
    gradient: GradientSource,
) -> Result<volao::render::gpu::RenderVolume> {
    use volao::render::gpu::RenderVolume;
    let step = volao::render::RenderSettings::default().step_voxels;
    let texels = texels.clone();
    let vol = match gradient {
        GradientSource::Volume => RenderVolume::from_texels(gpu, texels, tf, step)?,
        GradientSource::Samples => RenderVolume::for_compute(gpu, texels, tf, step)?,
    };
    if vol.gradient_volume().is_some() != (gradient == GradientSource::Volume) {
        anyhow::bail!("--gradient volume: the gradient volume does not fit");
    }
    Ok(vol)
}

/// The median frame time of each configuration in seconds, image readback included:
/// one warm-up frame each (pipelines, caches), then `runs` rounds of one frame of each
/// in turn.
fn interleaved_frames(
    gpu: &volao::gpu::Gpu,
    rc: &volao::render::gpu::RayCaster,
    configs: &[(volao::render::Frame, &volao::render::gpu::RenderVolume)],
    clip: Option<&volao::clip::gpu::ClipMaps>,
    runs: usize,
) -> Result<Vec<f64>> {
    for (frame, vol) in configs {
        rc.render(gpu, vol, frame, clip)?;
    }
    let mut times = vec![Vec::new(); configs.len()];
    for _ in 0..runs.max(1) {
        for ((frame, vol), t) in configs.iter().zip(&mut times) {
            let start = Instant::now();
            rc.render(gpu, vol, frame, clip)?;
            t.push(start.elapsed().as_secs_f64());
        }
    }
    Ok(times.into_iter().map(median).collect())
}

/// Ray steps inside the volume box for a whole frame: the work a frame would do with
/// neither early termination nor empty-space skipping (both only reduce it).
fn box_steps(
    frame: &volao::render::Frame,
    texels: &volao::texels::VolumeTexels,
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
    if !args.is_fixed() {
        return render_files(args);
    }
    use volao::render::gpu::{RayCaster, RenderVolume};
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
        let vol = RenderVolume::new(&gpu, &volume, &tf, RenderSettings::default().step_voxels)?;
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
                    let t = interleaved_frames(&gpu, &rc, &[(frame, &vol)], None, args.runs)?[0];
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
