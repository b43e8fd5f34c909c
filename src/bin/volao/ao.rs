//! `volao ao`: an ambient-occlusion volume in the input's geometry, written to a file.

use crate::args::AoArgs;
use crate::progress::{load_with_bar, slice_bar};
use anyhow::{Result, bail};
use volao::ao::sparse::Coverage;
use volao::headless;
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
    let coverage = if args.visible_only {
        Coverage::Readable
    } else {
        Coverage::Every
    };
    let gpu = volao::gpu::GpuUse::from_flag(!args.cpu);
    let computed = headless::ao_volume(
        &volume,
        &tf,
        &settings,
        &clip,
        coverage,
        &gpu,
        &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
    bar.finish_and_clear();
    for note in &computed.notes {
        eprintln!("warning: {note}");
    }
    if let Some(stats) = &computed.cao {
        print_cao(stats);
    }
    let ao = computed.volume;
    let seconds = start.elapsed().as_secs_f64();
    for w in volume::save(&ao, &args.output)? {
        eprintln!("warning: {}: {w}", args.output.display());
    }
    let s = ao.stats();
    println!(
        "{}: {} {}, TF {}, in {:.1} s on {}; A from {:.4} to {:.4}, mean {:.4}",
        args.output.display(),
        fmt_dims(ao.dims),
        headless::ao_method_words(&settings),
        tf.name,
        seconds,
        computed.device,
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
