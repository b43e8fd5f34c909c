//! `volao ao`: an ambient-occlusion volume in the input's geometry, written to a file.

use crate::args::AoArgs;
use crate::progress::{load_with_bar, slice_bar};
use anyhow::{Result, bail};
use volao::volume::{self, fmt_dims};

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
    let (ao, device, cao) = volao::ao::compute_volume_clipped(
        &volume,
        &tf,
        &settings,
        &clip,
        &volao::gpu::GpuUse::from_flag(!args.cpu),
        &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
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
