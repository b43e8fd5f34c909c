//! `volao info`: a volume's format, size, spacing, type, value range, orientation and
//! histogram, as text or JSON.

use crate::args::InfoArgs;
use crate::progress::load_with_bar;
use anyhow::{Context, Result};
use std::path::Path;
use volao::labels::SegmentStats;
use volao::volume::{self, Loaded, Volume, VoxelType, fmt_bytes, fmt_dims};

/// `volao info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    if args.file.is_none() && args.labels.labels.is_some() {
        anyhow::bail!("--labels needs an image file: the demo volume has no label map");
    }
    let report = match &args.file {
        Some(path) => {
            let loaded = load_with_bar(path, &args.load.options())?;
            let mut report = describe_loaded(path, &loaded, args.bins);
            if matches!(loaded.format, volume::Format::OmeZarr { .. }) {
                report.levels = Some(volume::zarr::store_info(path)?.levels);
            }
            if let Some(seg) = &args.labels.labels {
                let name = volume::display_path(path);
                let table = args.labels.label_table.as_deref();
                let labels = volao::labels::load_named(seg, table, &loaded.volume, &name)?;
                report.segments = Some(volao::labels::statistics(&loaded.volume, &labels.labels));
                report.label_warnings = labels.warnings;
            }
            report
        }
        None => describe_demo(&volume::demo::head_phantom(128), args.bins),
    };
    print_info(&report, args.json)
}

/// Everything `volao info` reports, in the shape its JSON takes.
#[derive(serde::Serialize)]
struct Report {
    file: String,
    format: String,
    dims: [usize; 3],
    spacing_mm: [f32; 3],
    voxel_type: VoxelType,
    payload_bytes: usize,
    scaling: volume::Scaling,
    stats: volume::Stats,
    orientation: String,
    orientation_source: volume::orient::AffineSource,
    affine: [[f64; 4]; 3],
    descriptions: Vec<(String, String)>,
    warnings: Vec<String>,
    histogram: volume::Histogram,
    /// With `--labels`: statistics of the image under each present segment.
    #[serde(skip_serializing_if = "Option::is_none")]
    segments: Option<Vec<SegmentStats>>,
    /// With `--labels`: what the user should know about the label map.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    label_warnings: Vec<String>,
    /// OME-Zarr: the store's multiscale levels (dims and spacing along x, y, z).
    #[serde(skip_serializing_if = "Option::is_none")]
    levels: Option<Vec<volume::zarr::LevelInfo>>,
}

fn describe(file: String, format: String, v: &Volume, warnings: &[String], bins: usize) -> Report {
    let stats = v.stats();
    Report {
        file,
        format,
        dims: v.dims,
        spacing_mm: v.spacing,
        voxel_type: v.data.voxel_type(),
        payload_bytes: v.data.byte_len(),
        scaling: v.scaling,
        histogram: v.histogram(bins, &stats),
        stats,
        orientation: v.orientation.axis_codes(),
        orientation_source: v.orientation.source,
        affine: v.orientation.rows(),
        descriptions: v.descriptions.clone(),
        warnings: warnings.to_vec(),
        segments: None,
        label_warnings: Vec::new(),
        levels: None,
    }
}

fn describe_loaded(path: &Path, loaded: &Loaded, bins: usize) -> Report {
    describe(
        path.display().to_string(),
        loaded.format.to_string(),
        &loaded.volume,
        &loaded.warnings,
        bins,
    )
}

fn describe_demo(v: &Volume, bins: usize) -> Report {
    describe(
        "(built-in demo)".into(),
        volume::Format::Demo.to_string(),
        v,
        &[],
        bins,
    )
}

/// Integers as integers, other values to 6 decimals without trailing zeros.
fn fmt_value(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{x:.0}")
    } else {
        let s = format!("{x:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

fn print_info(r: &Report, json: bool) -> Result<()> {
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(r).context("encoding the report as JSON")?
        );
        return Ok(());
    }
    let [nx, ny, nz] = r.dims;
    let s = &r.stats;
    println!("file:         {}", r.file);
    println!("format:       {}", r.format);
    println!(
        "dimensions:   {} ({} voxels)",
        fmt_dims(r.dims),
        nx * ny * nz
    );
    println!(
        "spacing:      {} × {} × {} mm",
        r.spacing_mm[0], r.spacing_mm[1], r.spacing_mm[2]
    );
    println!(
        "type:         {} ({})",
        r.voxel_type,
        fmt_bytes(r.payload_bytes as u64)
    );
    if !r.scaling.is_identity() {
        println!(
            "scaling:      value = {} · stored + {}",
            r.scaling.slope, r.scaling.inter
        );
    }
    println!("value range:  {} … {}", fmt_value(s.min), fmt_value(s.max));
    println!("mean:         {:.4}", s.mean);
    if s.non_finite > 0 {
        println!(
            "non-finite:   {} voxels are NaN or ±Inf (treated as empty)",
            s.non_finite
        );
    }
    let source = match r.orientation_source {
        volume::orient::AffineSource::Sform => "from sform",
        volume::orient::AffineSource::Qform => "from qform",
        volume::orient::AffineSource::Assumed => "assumed: the file has no orientation",
        volume::orient::AffineSource::Header => "from the file's geometry fields",
    };
    println!("orientation:  {} ({source})", r.orientation);
    for row in &r.affine {
        println!(
            "              [{:>10.4} {:>10.4} {:>10.4} {:>10.4}]",
            row[0], row[1], row[2], row[3]
        );
    }
    for (label, text) in &r.descriptions {
        // Continuation lines of multi-line strings (PVM courtesy lines) stay in the column.
        let text = text.trim_end().replace('\n', "\n              ");
        println!("{:<13} {text}", format!("{label}:"));
    }
    if let Some(levels) = &r.levels {
        print_levels(levels);
    }
    println!("histogram ({} bins, log scale):", r.histogram.counts.len());
    print!("{}", r.histogram.to_text(48));
    if let Some(segments) = &r.segments {
        print_segments(segments, &r.label_warnings);
    }
    Ok(())
}

/// An OME-Zarr store's levels, one line each.
fn print_levels(levels: &[volume::zarr::LevelInfo]) {
    println!("levels:       {} (--level N reads level N)", levels.len());
    for (k, l) in levels.iter().enumerate() {
        let [sx, sy, sz] = l.spacing_mm.map(fmt_value);
        println!(
            "  {k:>2}  {:<8} {:<16} {sx} × {sy} × {sz} mm",
            l.path,
            fmt_dims(l.dims)
        );
    }
}

/// The `--labels` table: one row per present segment.
fn print_segments(segments: &[SegmentStats], warnings: &[String]) {
    for w in warnings {
        println!("labels:       warning: {w}");
    }
    println!("segments ({} present):", segments.len());
    let layered = segments.iter().any(|s| s.layer > 0);
    let width = segments
        .iter()
        .map(|s| s.name.chars().count())
        .max()
        .unwrap_or(4)
        .clamp(4, 40);
    let layer_head = if layered { "layer " } else { "" };
    println!(
        "  {layer_head}{:>5}  {:<width$}  {:>10}  {:>10}  {:>10}  {:>10}  {:>10}  {:>10}",
        "id", "name", "voxels", "mL", "mean", "median", "min", "max"
    );
    for s in segments {
        let layer = if layered {
            format!("{:>5} ", s.layer)
        } else {
            String::new()
        };
        let name: String = s.name.chars().take(width).collect();
        println!(
            "  {layer}{:>5}  {:<width$}  {:>10}  {:>10.3}  {:>10.2}  {:>10}  {:>10}  {:>10}",
            s.id,
            volume::escape_controls(&name),
            s.voxels,
            s.volume_ml,
            s.mean,
            fmt_value(s.median),
            fmt_value(s.min),
            fmt_value(s.max)
        );
    }
}
