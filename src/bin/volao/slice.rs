//! `volao slice`: one axial, coronal or sagittal slice to PNG, headless, in patient
//! orientation ([`volao::slice`]): a report's figure, and what the orientation tests
//! compare with nibabel.

use crate::args::SliceArgs;
use crate::progress::load_with_bar;
use anyhow::{Context, Result, bail};
use glam::DVec3;
use volao::labels::{self, style};
use volao::scene::Scene;
use volao::slice::{Convention, LabelOverlay, Plane, Sampling, SliceGeometry};
use volao::tf::{Preset, TransferFunction};
use volao::volume;

/// `volao slice`.
pub fn run(args: &SliceArgs) -> Result<()> {
    let scene = match &args.input {
        Some(p)
            if p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json")) =>
        {
            Some(Scene::open(p)?)
        }
        _ => None,
    };
    let (path, options) = match &scene {
        Some(s) => (s.volume.path.clone(), s.load_options()),
        None => (args.input.clone(), args.load.options()),
    };
    let volume = match &path {
        Some(p) => load_with_bar(p, &options)?.volume,
        None => volume::demo::head_phantom(128),
    };
    let stats = volume.stats();
    let (window, level) = match args.window_level {
        Some(wl) => wl,
        None => scene
            .as_ref()
            .map(|s| s.transfer_function.clone())
            .unwrap_or_else(|| TransferFunction::preset(Preset::default_for(&stats), &stats))
            .window_level(),
    };
    let plane = if args.acquisition_plane {
        Plane::Acquisition
    } else {
        Plane::Patient
    };
    let convention = if args.neurological {
        Convention::Neurological
    } else {
        Convention::Radiological
    };
    let sampling = if args.linear {
        Sampling::Linear
    } else {
        Sampling::Nearest
    };
    let axis = args.axis;
    let geometry = SliceGeometry::new(&volume, plane);
    let count = geometry.count(axis);
    let index = match (args.index, args.at) {
        (Some(i), _) if i >= count => bail!(
            "--index {i}: the {} slices are numbered 0 to {}",
            axis.name(),
            count - 1
        ),
        (Some(i), _) => i,
        (None, Some(at)) => geometry.index_at(axis, DVec3::from_array(at)),
        (None, None) => geometry.middle(axis),
    };
    let slice = geometry.cut(&volume, axis, convention, index, sampling);

    // The segmentation: --labels, else the scene's.
    let mut source = scene.and_then(|s| s.segmentation);
    if let Some(p) = &args.labels.labels {
        source = Some(volao::scene::SegmentationSource {
            path: p.clone(),
            table: args.labels.label_table.clone(),
            styles: source.map(|s| s.styles).unwrap_or_default(),
        });
    }
    let overlay = match &mut source {
        Some(src) => {
            let loaded = labels::load(&src.path, src.table.as_deref(), &volume)?;
            for w in &loaded.warnings {
                eprintln!("warning: {w}");
            }
            for spec in &args.segment {
                src.styles
                    .apply(&loaded.labels, spec)
                    .map_err(anyhow::Error::msg)?;
            }
            let classes = style::Classes::of(&loaded.labels).map_err(anyhow::Error::msg)?;
            let looks = style::looks(&loaded.labels, &classes, &src.styles, &[]);
            Some((classes, looks))
        }
        None if !args.segment.is_empty() => {
            bail!("--segment needs a segmentation: give --labels SEG")
        }
        None => None,
    };
    let overlay = overlay.as_ref().map(|(classes, looks)| LabelOverlay {
        classes: &classes.of_voxel,
        looks,
        opacity: args.label_opacity,
        outline: args.outline,
    });

    let (w, h) = (slice.width, slice.height);
    let mut rgb = slice.rgb(window, level, overlay.as_ref());
    if args.annotate {
        volao::slice::annotate(
            &mut rgb,
            w,
            geometry.edge_letters(axis, convention),
            geometry.pixel_mm(axis),
        );
    }
    let (wu, hu) = (w as u32, h as u32);
    let saved = if overlay.is_some() {
        image::RgbImage::from_raw(wu, hu, rgb).map(|i| i.save(&args.output))
    } else {
        let grey: Vec<u8> = rgb.chunks(3).map(|p| p[0]).collect();
        image::GrayImage::from_raw(wu, hu, grey).map(|i| i.save(&args.output))
    };
    saved
        .context("slice image of the wrong size")?
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    let letters = geometry.edge_letters(axis, convention);
    println!(
        "{}: {} slice {index} of {count} ({} = {:.2} mm), {w}×{h} px at {:.3} mm, {}–{} left to right, window {window}/{level}",
        args.output.display(),
        axis.name(),
        ['x', 'y', 'z'][axis.normal()],
        geometry.position(axis, index),
        geometry.pixel_mm(axis),
        letters[0],
        letters[1],
    );
    Ok(())
}
