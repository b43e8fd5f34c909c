//! `volao view` (and `volao` alone): the viewer.

use crate::args::ViewArgs;
use anyhow::Result;

/// What `volao` and `volao view` say when built without the viewer.
#[cfg(not(feature = "viewer"))]
const NO_VIEWER: &str = "this volao was built without the viewer (cargo feature `viewer`): \
     rebuild with default features, or render headless with `volao render`";

/// `volao` alone: the viewer on the built-in demo volume.
pub fn run_demo() -> Result<()> {
    #[cfg(feature = "viewer")]
    return Ok(volao::app::run(volao::app::ViewerOptions::default())?);
    #[cfg(not(feature = "viewer"))]
    anyhow::bail!(NO_VIEWER)
}

/// `volao view`.
#[cfg(not(feature = "viewer"))]
pub fn run(_args: &ViewArgs) -> Result<()> {
    anyhow::bail!(NO_VIEWER)
}

/// `volao view`.
#[cfg(feature = "viewer")]
pub fn run(args: &ViewArgs) -> Result<()> {
    use crate::args::TargetRate;
    use anyhow::bail;
    use volao::app::{OpenRequest, ViewerOptions};
    use volao::scene::SegmentationSource;
    let open = match &args.file {
        None => OpenRequest::Demo,
        Some(p)
            if p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json")) =>
        {
            OpenRequest::Scene(p.clone())
        }
        Some(p) => OpenRequest::Volume {
            path: p.clone(),
            options: args.load.options(),
            labels: args.labels.labels.clone().map(|path| {
                Box::new(SegmentationSource {
                    path,
                    table: args.labels.label_table.clone(),
                    styles: Default::default(),
                })
            }),
        },
    };
    if args.labels.labels.is_some() && !matches!(open, OpenRequest::Volume { .. }) {
        bail!(
            "--labels needs a volume file: a scene keeps its own segmentation \
             (its \"segmentation\" entry)"
        );
    }
    for p in [&args.labels.labels, &args.labels.label_table]
        .into_iter()
        .flatten()
    {
        if !p.exists() {
            bail!("{}: no such file", p.display());
        }
    }
    if let Some(p) = &args.file
        && !p.exists()
    {
        bail!("{}: no such file", p.display());
    }
    let mut options = ViewerOptions {
        open,
        screenshot: args.screenshot.clone(),
        exit_after_frames: args.exit_after_frames,
        bench_clip_drag: args.bench_clip_drag,
        no_skipping: args.no_skipping,
        layout: args.layout,
        ..Default::default()
    };
    match args.target_rate {
        None => {}
        Some(TargetRate::Off) => options.interactive.on = false,
        Some(TargetRate::Images(r)) => options.interactive.target_fps = r,
    }
    if let Some(size) = args.size {
        options.window_size = size;
    }
    if let Some(n) = args.clip_maps {
        options.clip_resolution = Some(n);
    }
    // A scripted run must not touch the user's recent-files list.
    if args.exit_after_frames.is_some() || args.bench_clip_drag.is_some() {
        options.recent_file = None;
    }
    volao::app::run(options)?;
    if let Some(p) = &args.screenshot {
        println!("{}", p.display());
    }
    Ok(())
}
