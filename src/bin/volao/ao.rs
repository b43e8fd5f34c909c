//! `volao ao`: an ambient-occlusion volume in the input's geometry, written to a file.

use crate::args::AoArgs;
use crate::progress::{load_with_bar, slice_bar};
use anyhow::{Context, Result, bail};
use volao::ao::sparse::Coverage;
use volao::ao::{Ambient, AoEngine, AoInput, AoRequest};
use volao::texels::{UploadLimits, VolumeTexels};
use volao::volume::{self, Volume, fmt_dims};

/// `volao ao`.
pub fn run(args: &AoArgs) -> Result<()> {
    use volao::ao::{AoMethod, AoSettings};
    use volao::tf::{Preset, TransferFunction};
    if args.method == AoMethod::None {
        bail!("--method none computes nothing; use lao, cao, vao, cdf, gauss, penner or cone");
    }
    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    let volume = load_with_bar(&args.input, &args.load.options())?.volume;
    let stats = volume.stats();
    let preset = match &args.tf {
        Some(name) => Preset::from_name(name)?,
        None => Preset::default_for(&stats),
    };
    let tf = TransferFunction::preset(preset, &stats);
    let mut settings = AoSettings {
        method: args.method,
        rays: args.rays,
        samples: args.samples,
        ..Default::default()
    };
    args.vao.apply(&mut settings.vao)?;
    args.clip.apply(&mut settings)?;
    let clip = args.clip.shapes_or(Vec::new());
    if !clip.is_empty() && !matches!(args.method, AoMethod::Cao | AoMethod::LaoFull) {
        bail!("--clip needs --method cao or lao-full (plain LAO ignores clipping)");
    }
    args.fast_ao.apply(&mut settings)?;
    let start = std::time::Instant::now();
    let bar = slice_bar("ambient occlusion", true);
    // The volume at full resolution: the engine says when it cannot go to the GPU.
    let texels = VolumeTexels::new(&volume, UploadLimits::NONE);
    let engine = AoEngine::new(&volao::gpu::GpuUse::from_flag(!args.cpu));
    // Live positional AO exported as a volume is the precomputed one.
    let mut precomputed = settings;
    if precomputed.method == AoMethod::VaoLive {
        precomputed.method = AoMethod::Vao;
    }
    let request = AoRequest {
        tf: &tf,
        settings: &precomputed,
        clip: Some(&clip),
        coverage: if args.visible_only {
            Coverage::Readable
        } else {
            Coverage::Every
        },
    };
    let computed = engine.compute(AoInput::Texels(&texels), &request, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    for note in &computed.notes {
        eprintln!("warning: {note}");
    }
    let values = match computed.ambient {
        Ambient::Values(values) => values,
        Ambient::Cao(c) => {
            let gpu = engine.gpu().context("CAO ran without a GPU")?;
            c.read(gpu, volao::ao::cao::CaoVolume::Ambient)?
        }
        Ambient::One | Ambient::Live => vec![1.0; texels.dims.iter().product()],
    };
    let (device, cao) = (computed.device, computed.cao);
    let ao = ao_volume(&volume, values, &settings, &tf);
    bar.finish_and_clear();
    if let Some(stats) = &cao {
        for e in &stats.clip_errors {
            eprintln!("warning: {e}");
        }
        print_cao(stats);
    }
    let seconds = start.elapsed().as_secs_f64();
    for w in volume::save(&ao, &args.output)? {
        eprintln!("warning: {}: {w}", args.output.display());
    }
    let s = ao.stats();
    let what = if volao::ao::fast::handles(settings.method) {
        volao::ao::fast::describe(&settings)
    } else {
        match settings.method {
            AoMethod::Vao | AoMethod::VaoLive => format!(
                "positional AO, {} directions × {} samples, r_max {} mm",
                settings.vao.directions, settings.vao.samples, settings.vao.r_max_mm
            ),
            method => format!(
                "{}, {} rays × {} samples",
                match method {
                    AoMethod::Cao => "CAO",
                    AoMethod::LaoFull => "LAO (every voxel, clipped)",
                    _ => "LAO",
                },
                settings.rays.name(),
                settings.samples
            ),
        }
    };
    println!(
        "{}: {} {what}, TF {}, in {:.1} s on {device}; A from {:.4} to {:.4}, mean {:.4}",
        args.output.display(),
        fmt_dims(ao.dims),
        tf.name,
        seconds,
        s.min,
        s.max,
        s.mean
    );
    Ok(())
}

/// The AO volume `volao ao` writes: `values` in the input's geometry, described.
fn ao_volume(
    volume: &Volume,
    values: Vec<f32>,
    settings: &volao::ao::AoSettings,
    tf: &volao::tf::TransferFunction,
) -> Volume {
    use volao::ao::AoMethod;
    let description = if volao::ao::fast::handles(settings.method) {
        format!(
            "ambient factor: {}, TF {}",
            volao::ao::fast::describe(settings),
            tf.name
        )
    } else if matches!(settings.method, AoMethod::Vao | AoMethod::VaoLive) {
        let s = &settings.vao;
        let iso = match s.isosurface {
            Some(i) => format!(", isosurface {} ± {}", i.value, i.tolerance),
            None => String::new(),
        };
        format!(
            "positional AO ambient factor 1 - A_P, {} directions x {} samples, r_max {} mm{iso}, TF {}",
            s.directions, s.samples, s.r_max_mm, tf.name
        )
    } else {
        let method = match settings.method {
            AoMethod::Cao => "CAO",
            AoMethod::LaoFull => "LAO (every frame, clipped)",
            _ => "LAO",
        };
        format!(
            "{method} ambient factor, {} rays x {} samples, TF {}",
            settings.rays.name(),
            settings.samples,
            tf.name
        )
    };
    Volume {
        dims: volume.dims,
        spacing: volume.spacing,
        data: volao::volume::VoxelData::F32(values),
        scaling: volao::volume::Scaling::IDENTITY,
        orientation: volume.orientation,
        descriptions: vec![("description".into(), description)],
    }
}

/// One line per stage of a CAO frame.
pub fn print_cao(stats: &volao::ao::cao::CaoStats) {
    println!(
        "{:.2} % of voxels ray cast ({} of {}; {} clipped); per frame: maps {:.1} ms, clip + mask {:.1} ms, ray cast {:.1} ms",
        stats.percent_recomputed(),
        stats.recomputed,
        stats.voxels,
        stats.clipped,
        stats.maps_seconds * 1e3,
        stats.clip_seconds * 1e3,
        stats.lao_seconds * 1e3
    );
}
