//! `volao convert`: between formats, chosen by the output's extension.

use crate::args::ConvertArgs;
use crate::progress::load_with_bar;
use anyhow::{Result, bail};
use volao::volume::{self, fmt_bytes, fmt_dims};

/// `volao convert`.
pub fn run(args: &ConvertArgs) -> Result<()> {
    let (volume, output) = match (args.demo, args.files.as_slice()) {
        (false, [input, output]) => (load_with_bar(input, &args.load.options())?.volume, output),
        (true, [output]) => (volume::demo::head_phantom(128), output),
        (false, _) => bail!("convert needs an input and an output file (or --demo OUT)"),
        (true, _) => bail!("with --demo, give only the output file"),
    };
    for w in volume::save(&volume, output)? {
        eprintln!("warning: {}: {w}", output.display());
    }
    eprintln!(
        "wrote {} ({} {}, {})",
        output.display(),
        fmt_dims(volume.dims),
        volume.data.voxel_type(),
        fmt_bytes(volume.data.byte_len() as u64)
    );
    if volume::zarr::is_zarr_store(output) {
        let info = volume::zarr::store_info(output)?;
        eprintln!(
            "OME-Zarr {} (Zarr v{}), {} level{}:",
            info.ngff,
            info.zarr_format,
            info.levels.len(),
            if info.levels.len() == 1 { "" } else { "s" }
        );
        for l in &info.levels {
            // f32, as volao holds spacing: 0.957031, not 0.9570310115814209.
            let [sx, sy, sz] = l.spacing_mm.map(|s| s as f32);
            eprintln!(
                "  {:<4} {:<16} {sx} × {sy} × {sz} mm",
                l.path,
                fmt_dims(l.dims)
            );
        }
    }
    Ok(())
}
