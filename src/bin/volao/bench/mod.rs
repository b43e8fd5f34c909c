//! `volao bench …`: measurements recorded in `docs/benchmarks.md`, never asserted in tests.

mod cao;
mod filter;
mod lao;
mod load;
mod raymarch;
mod render;
mod segments;
mod shadows;

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Load time and peak memory of volao vs Python nibabel on the same files.
    Load(load::LoadBenchArgs),
    /// Frame times of the GPU ray caster (engine and cranium CT, 512² and 1024²).
    Render(render::RenderBenchArgs),
    /// The CAO paper's Tables 5–6 (LAO accuracy vs rays) on the Engine, and LAO throughput.
    Lao(lao::LaoBenchArgs),
    /// The CAO paper's Tables 2–4: voxels recomputed, LAO every frame vs CAO, one vs
    /// two meshes, per-stage times and GPU memory.
    Cao(cao::CaoBenchArgs),
    /// Positional AO by ray marching (time and RMS vs 512-ray LAO, live vs precomputed
    /// frame times) and the cost of volumetric shadows, on the Engine.
    Raymarch(raymarch::RaymarchBenchArgs),
    /// Ruiz et al.'s Table 1 (filter maps on the cranium CT) and every cheap AO method's
    /// RMS against 512-ray LAO with its compute time.
    Filter(filter::FilterBenchArgs),
    /// Whether `--shadows` adds texture: high-frequency energy of the cranium CT with and
    /// without shadows (or of PNG files given by --measure), and the light volume's time.
    Shadows(shadows::ShadowBenchArgs),
    /// (internal) load one file and print time and peak memory as JSON.
    #[command(hide = true)]
    LoadOne { file: PathBuf },
}

/// Runs one benchmark.
pub fn run(command: &BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Render(args) => render::render_bench(args),
        BenchCommand::Lao(args) => lao::lao_bench(args),
        BenchCommand::Raymarch(args) => raymarch::raymarch_bench(args),
        BenchCommand::Filter(args) => filter::filter_bench(args),
        BenchCommand::Load(args) => load::load_bench(args),
        BenchCommand::Cao(args) => cao::cao_bench(args),
        BenchCommand::Shadows(args) => shadows::shadow_bench(args),
        BenchCommand::LoadOne { file } => load::load_one(file),
    }
}

/// The Engine (`raw/engine.raw` under `data`) in RAS order with the CAO paper's
/// single-colour transfer function: the volume of the paper's tables.
pub fn engine_volume(
    data: &std::path::Path,
) -> Result<(volao::volume::Volume, volao::tf::TransferFunction)> {
    use volao::tf::{Preset, TransferFunction};
    let path = data.join("raw/engine.raw");
    let volume = volao::volume::load(&path, &volao::volume::LoadOptions::default())?
        .volume
        .to_ras();
    let tf = TransferFunction::preset(Preset::CaoSingleColor, &volume.stats());
    Ok((volume, tf))
}

/// The median of `xs` (the upper one of an even count).
pub fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// The benchmarks' view: a square image of `size` pixels from azimuth 30° and
/// `elevation_deg`, at the default distance.
pub fn frame(
    elevation_deg: f32,
    settings: volao::render::RenderSettings,
    size: u32,
) -> volao::render::Frame {
    volao::render::Frame {
        camera: volao::render::Camera {
            azimuth_deg: 30.0,
            elevation_deg,
            ..Default::default()
        },
        settings,
        width: size,
        height: size,
    }
}

/// Root-mean-square difference of two AO volumes.
pub fn rms(a: &[f32], b: &[f32]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64)
        .sqrt()
}
