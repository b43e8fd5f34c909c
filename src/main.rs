//! The `volao` command line: `volao` (viewer), `info`, `convert`, `gpu`, `bench`.

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};
use volao::volume::{
    self, Endian, LoadOptions, Loaded, RawOverrides, Volume, VoxelType, fmt_bytes, fmt_dims,
};

#[derive(Parser, Debug)]
#[command(
    name = "volao",
    version,
    about = "Direct volume rendering with exact, clip-aware ambient occlusion"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Open the viewer on a volume file or a scene (.json). `volao` alone opens it on the
    /// built-in demo volume.
    View(Box<ViewArgs>),
    /// Describe a volume: format, size, spacing, type, value range, orientation, histogram.
    /// Without FILE, describes the built-in demo volume.
    Info(InfoArgs),
    /// Convert between formats, chosen by the output's extension (.nii, .nii.gz, .pvm, .raw).
    Convert(ConvertArgs),
    /// Render a volume or a scene file to PNG, headless.
    Render(Box<RenderArgs>),
    /// Compute an ambient-occlusion volume in the input's geometry and write it.
    Ao(AoArgs),
    /// Show the GPU adapter volao will use and run a compute self-test on it.
    Gpu,
    /// Benchmarks (results go to docs/benchmarks.md).
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Args, Debug)]
struct InfoArgs {
    /// Volume file (.nii, .nii.gz, .hdr/.img, .pvm, .raw/.dat). Omit for the demo volume.
    file: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Histogram bins.
    #[arg(long, default_value_t = 32)]
    bins: usize,
    #[command(flatten)]
    load: LoadArgs,
}

#[derive(Args, Debug)]
struct ViewArgs {
    /// Volume file (.nii, .nii.gz, .hdr/.img, .pvm, .raw/.dat) or scene (.json). Omit for
    /// the demo volume.
    file: Option<PathBuf>,
    /// Write a PNG of the viewport (and its scene beside it) after --exit-after-frames
    /// frames, then close. For scripted figures and smoke tests.
    #[arg(long, requires = "exit_after_frames")]
    screenshot: Option<PathBuf>,
    /// Close after this many frames showing the volume (with its ambient occlusion).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    exit_after_frames: Option<u64>,
    /// (benchmark) Show only the viewport; once AO is ready move the scene's first clip
    /// shape 1 mm per frame for N frames and print the frame times.
    #[arg(long, hide = true, value_name = "N")]
    bench_clip_drag: Option<u64>,
    /// Edge of the clip shapes' depth maps (default 1024; smaller builds faster on a CPU
    /// driver).
    #[arg(long, value_name = "PIXELS", value_parser = clap::value_parser!(u32).range(16..=8192))]
    clip_maps: Option<u32>,
    /// Window size in points, e.g. 1280x800.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    size: Option<[f32; 2]>,
    #[command(flatten)]
    load: LoadArgs,
}

fn parse_size(s: &str) -> Result<[f32; 2], String> {
    let bad = || format!("{s:?}: expected WIDTHxHEIGHT, e.g. 1280x800");
    let (w, h) = s.split_once(['x', 'X', '×']).ok_or_else(bad)?;
    let (w, h) = (
        w.trim().parse::<u32>().map_err(|_| bad())?,
        h.trim().parse::<u32>().map_err(|_| bad())?,
    );
    if !(64..=16384).contains(&w) || !(64..=16384).contains(&h) {
        return Err(format!("{s:?}: each side must be 64 to 16384"));
    }
    Ok([w as f32, h as f32])
}

#[derive(Args, Debug)]
struct ConvertArgs {
    /// IN OUT, or just OUT with --demo. OUT's extension picks the format.
    #[arg(num_args = 1..=2, value_names = ["IN", "OUT"], required = true)]
    files: Vec<PathBuf>,
    /// Write the built-in demo volume instead of reading a file.
    #[arg(long)]
    demo: bool,
    #[command(flatten)]
    load: LoadArgs,
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Volume file or scene (.json). Omit for the demo volume.
    input: Option<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    /// Transfer-function preset: ct-bone, ct-soft-tissue, ct-vessels, mr-t1-brain, cao-single-color.
    #[arg(long)]
    tf: Option<String>,
    /// Window/level in data units (e.g. HU): stretches the transfer function's points
    /// over [level - window/2, level + window/2].
    #[arg(long, value_name = "WINDOW,LEVEL", value_parser = parse_window_level, allow_hyphen_values = true)]
    window_level: Option<(f64, f64)>,
    /// Orbit camera: azimuth and elevation in degrees, distance in bounding-sphere radii.
    #[arg(long, value_name = "AZIMUTH,ELEVATION,DISTANCE", value_parser = parse_camera, allow_hyphen_values = true)]
    camera: Option<[f32; 3]>,
    /// Orthographic projection.
    #[arg(long)]
    ortho: bool,
    /// Background: a name (black, white, grey), #rrggbb, or "transparent".
    #[arg(long)]
    background: Option<String>,
    #[arg(long, value_parser = parse_shading)]
    shading: Option<volao::render::Shading>,
    /// Step between samples in voxels.
    #[arg(long)]
    step: Option<f32>,
    /// Ambient coefficient k of k·A(x)·C_TF(x), 0 to 1 (1: ambient occlusion only).
    #[arg(long)]
    ambient: Option<f32>,
    /// Ambient occlusion: none, lao, cao (exact under clipping), lao-full (LAO of every
    /// voxel each frame, CAO's baseline), vao / vao-live (positional AO, precomputed or
    /// at every sample), cdf, gauss, penner (filter maps) or cone (cone-traced).
    #[arg(long, value_parser = volao::ao::AoMethod::parse)]
    ao: Option<volao::ao::AoMethod>,
    /// AO ray pattern: 6, 14, 26, 54 (the CAO paper's) or fib:N (Fibonacci lattice).
    #[arg(long, value_parser = parse_rays)]
    rays: Option<volao::ao::rays::RaySet>,
    /// AO samples per ray (1 mm apart).
    #[arg(long)]
    samples: Option<u32>,
    #[command(flatten)]
    clip: ClipArgs,
    #[command(flatten)]
    vao: VaoArgs,
    /// Volumetric shadows from a directional light (see --light).
    #[arg(long)]
    shadows: bool,
    /// Directional light: the direction towards the light in volume space (RAS: x to the
    /// patient's left, y anterior, z superior), e.g. -0.5,0.6,0.62.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_light, allow_hyphen_values = true)]
    light: Option<[f32; 3]>,
    /// Draw a Wavefront OBJ mesh inside the volume (repeatable). Coordinates in mm, in the
    /// volume's RAS frame with the origin at the volume's centre.
    #[arg(long, value_name = "FILE.obj")]
    mesh: Vec<PathBuf>,
    /// Colour of the meshes: straight R,G,B,A in 0…1 (A < 1: translucent).
    #[arg(long, value_name = "R,G,B,A", value_parser = parse_rgba, default_value = "0.9,0.9,0.9,1")]
    mesh_rgba: [f32; 4],
    /// Draw the clip shapes as surfaces inside the rendering: straight R,G,B,A in 0…1
    /// (A < 1: translucent), e.g. 1,0.8,0.2,0.3.
    #[arg(long, value_name = "R,G,B,A", value_parser = parse_rgba)]
    show_clip: Option<[f32; 4]>,
    #[command(flatten)]
    fast_ao: FastAoArgs,
    /// Opacity modulation by local variance: α · min(σ²/σ²_max, 1) (Ruiz et al. §4.2),
    /// σ² of the normalised density in a box of radius RADIUS voxels (default 10).
    #[arg(long, value_name = "SIGMA2_MAX[,RADIUS]", value_parser = parse_modulation)]
    opacity_modulation: Option<volao::ao::filter::OpacityModulation>,
    /// Render on the CPU twin instead of the GPU.
    #[arg(long)]
    cpu: bool,
    /// Also write the scene that reproduces this image.
    #[arg(long)]
    save_scene: Option<PathBuf>,
    #[command(flatten)]
    load: LoadArgs,
}

/// Flags of the filter-map and cone-traced AO methods (`volao render` and `volao ao`).
#[derive(Args, Debug)]
struct FastAoArgs {
    /// Filter maps (cdf, gauss, penner): box radius r, side 2r + 1 (default 10 voxels).
    #[arg(long)]
    radius: Option<f32>,
    /// The radius is in mm (rounded to voxels per axis) instead of voxels.
    #[arg(long)]
    radius_mm: bool,
    /// Filter maps: statistics of the density (the paper) or of the TF opacity.
    #[arg(long, value_parser = volao::ao::filter::StatisticSource::parse)]
    statistic: Option<volao::ao::filter::StatisticSource>,
    /// Cone tracing: 6, 14 or 26 cones (default 6).
    #[arg(long, value_parser = volao::ao::cone::ConeSet::parse)]
    cones: Option<volao::ao::cone::ConeSet>,
    /// Cone tracing: low, medium or high = 3, 5 or 7 spheres per cone (default medium).
    #[arg(long, value_parser = volao::ao::cone::ConePreset::parse)]
    cone_preset: Option<volao::ao::cone::ConePreset>,
}

impl FastAoArgs {
    fn apply(&self, ao: &mut volao::ao::AoSettings) -> Result<()> {
        if let Some(r) = self.radius {
            if !r.is_finite() || !(0.0..=1000.0).contains(&r) {
                bail!("--radius must be between 0 and 1000");
            }
            ao.radius = r;
        }
        if self.radius_mm {
            ao.radius_unit = volao::ao::filter::RadiusUnit::Mm;
        }
        if let Some(s) = self.statistic {
            ao.statistic = s;
        }
        if let Some(c) = self.cones {
            ao.cones = c;
        }
        if let Some(p) = self.cone_preset {
            ao.cone_preset = p;
        }
        Ok(())
    }
}

fn parse_modulation(s: &str) -> Result<volao::ao::filter::OpacityModulation, String> {
    let v: Vec<f32> = numbers(s)?;
    let mut m = volao::ao::filter::OpacityModulation::default();
    match v.as_slice() {
        [s2] if *s2 > 0.0 && s2.is_finite() => m.sigma2_max = *s2,
        [s2, r] if *s2 > 0.0 && s2.is_finite() && (0.0..=1000.0).contains(r) => {
            m.sigma2_max = *s2;
            m.radius = *r;
        }
        _ => {
            return Err(format!(
                "{s:?}: expected SIGMA2_MAX[,RADIUS] with σ²_max > 0 and a radius of 0 to 1000 voxels, e.g. 0.001,10"
            ));
        }
    }
    Ok(m)
}

/// Comma-separated numbers, e.g. "30,20,3.2"; the error names the input.
fn numbers<T: std::str::FromStr>(s: &str) -> Result<Vec<T>, String>
where
    T::Err: std::fmt::Display,
{
    s.split(',')
        .map(|x| x.trim().parse::<T>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))
}

fn parse_camera(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = numbers(s)?;
    match v.as_slice() {
        [a, e, d] if v.iter().all(|x| x.is_finite()) => Ok([*a, *e, *d]),
        _ => Err(format!(
            "{s:?}: expected three numbers AZIMUTH,ELEVATION,DISTANCE, e.g. 30,20,3.2"
        )),
    }
}

/// Positional AO (`--ao vao`, `vao-live`) parameters; unset flags keep the scene's or the
/// defaults.
#[derive(Args, Debug, Default)]
struct VaoArgs {
    /// Positional AO: rays over the sphere, N_dir (default 20).
    #[arg(long)]
    vao_directions: Option<u32>,
    /// Positional AO: stratified samples per ray, N_samples (default 8).
    #[arg(long)]
    vao_samples: Option<u32>,
    /// Positional AO: ray length r_max in mm (default 20).
    #[arg(long, value_name = "MM")]
    vao_radius: Option<f32>,
    /// Positional AO: an accepted sample at least this opaque stops a ray (default 0.95).
    #[arg(long)]
    vao_threshold: Option<f32>,
    /// Positional AO, isosurface variant: occluded where a sample lies within TOL of
    /// VALUE (data units).
    #[arg(long, value_name = "VALUE,TOL", value_parser = parse_iso, allow_hyphen_values = true)]
    vao_iso: Option<(f64, f64)>,
}

impl VaoArgs {
    /// Applies the flags to `s` and checks the result.
    fn apply(&self, s: &mut volao::ao::vao::VaoSettings) -> Result<()> {
        if let Some(n) = self.vao_directions {
            s.directions = n;
        }
        if let Some(n) = self.vao_samples {
            s.samples = n;
        }
        if let Some(r) = self.vao_radius {
            s.r_max_mm = r;
        }
        if let Some(t) = self.vao_threshold {
            s.v_thres = t;
        }
        if let Some((value, tolerance)) = self.vao_iso {
            s.isosurface = Some(volao::ao::vao::Isosurface { value, tolerance });
        }
        s.validate()?;
        Ok(())
    }
}

fn parse_iso(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = numbers(s)?;
    match v.as_slice() {
        [value, tol] if value.is_finite() && tol.is_finite() && *tol > 0.0 => Ok((*value, *tol)),
        _ => Err(format!(
            "{s:?}: expected VALUE,TOL with a positive tolerance, e.g. 300,50"
        )),
    }
}

fn parse_rgba(s: &str) -> Result<[f32; 4], String> {
    let v: Vec<f32> = numbers(s)?;
    match v.as_slice() {
        [r, g, b, a] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b, *a]),
        _ => Err(format!(
            "{s:?}: expected four numbers from 0 to 1, R,G,B,A, e.g. 1,0.8,0.2,1"
        )),
    }
}

fn parse_light(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = numbers(s)?;
    match v.as_slice() {
        [x, y, z] => volao::render::shadow::light_direction([*x, *y, *z]).map(|d| d.to_array()),
        _ => Err(format!(
            "{s:?}: expected three numbers X,Y,Z, e.g. -0.5,0.6,0.62"
        )),
    }
}

fn parse_window_level(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = numbers(s)?;
    match v.as_slice() {
        [w, l] if *w > 0.0 && w.is_finite() && l.is_finite() => Ok((*w, *l)),
        _ => Err(format!(
            "{s:?}: expected WINDOW,LEVEL with a positive window, e.g. 400,40"
        )),
    }
}

fn parse_rays(s: &str) -> Result<volao::ao::rays::RaySet, String> {
    volao::ao::rays::RaySet::parse(s).map_err(|e| e.to_string())
}

fn parse_shading(s: &str) -> Result<volao::render::Shading, String> {
    match s {
        "none" => Ok(volao::render::Shading::None),
        "phong" => Ok(volao::render::Shading::Phong),
        _ => Err(format!("unknown shading {s:?} (none or phong)")),
    }
}

/// Parses a background colour into straight RGBA.
fn parse_background(s: &str) -> Result<[f32; 4]> {
    let hex = |h: &str| u8::from_str_radix(h, 16).map(|v| v as f32 / 255.0);
    Ok(match s.to_ascii_lowercase().as_str() {
        "transparent" => [0.0; 4],
        "black" => [0.0, 0.0, 0.0, 1.0],
        "white" => [1.0; 4],
        "grey" | "gray" => [0.5, 0.5, 0.5, 1.0],
        c if c.len() == 7 && c.starts_with('#') => {
            let parse = || -> Result<[f32; 4], std::num::ParseIntError> {
                Ok([hex(&c[1..3])?, hex(&c[3..5])?, hex(&c[5..7])?, 1.0])
            };
            parse().map_err(|_| anyhow::anyhow!("background {s:?}: not a #rrggbb colour"))?
        }
        _ => bail!("background {s:?}: use black, white, grey, #rrggbb or transparent"),
    })
}

#[derive(Args, Debug)]
struct AoArgs {
    /// Volume file.
    input: PathBuf,
    /// Output volume (.nii.gz, .nii or .raw), f32 values in [0, 1].
    #[arg(short, long)]
    output: PathBuf,
    /// AO method: lao, cao, lao-full (with --clip), vao (positional AO; vao-live gives the
    /// same volume), cdf, gauss, penner or cone.
    #[arg(long, alias = "ao", default_value = "lao", value_parser = volao::ao::AoMethod::parse)]
    method: volao::ao::AoMethod,
    /// Ray pattern: 6, 14, 26, 54 or fib:N.
    #[arg(long, default_value = "54", value_parser = parse_rays)]
    rays: volao::ao::rays::RaySet,
    /// Samples per ray (1 mm apart).
    #[arg(long, default_value_t = volao::ao::lao::DEFAULT_SAMPLES)]
    samples: u32,
    /// Transfer-function preset giving the opacity (default: by the data's range).
    #[arg(long)]
    tf: Option<String>,
    #[command(flatten)]
    clip: ClipArgs,
    #[command(flatten)]
    vao: VaoArgs,
    #[command(flatten)]
    fast_ao: FastAoArgs,
    /// Compute on the CPU twin instead of the GPU.
    #[arg(long)]
    cpu: bool,
    #[command(flatten)]
    load: LoadArgs,
}

/// Clip shapes and CAO parameters.
#[derive(Args, Debug, Default)]
struct ClipArgs {
    /// A clip shape (repeatable, up to 8), lengths in mm from the volume's centre:
    /// plane:PX,PY,PZ,NX,NY,NZ (removes the side the normal points to),
    /// sphere:CX,CY,CZ,R, box:CX,CY,CZ,SX,SY,SZ[,RX,RY,RZ], cylinder:CX,CY,CZ,R,H[,RX,RY,RZ],
    /// torus:CX,CY,CZ,R,r[,RX,RY,RZ], mesh:FILE.obj|stl[,CX,CY,CZ[,SCALE]]. Replaces a scene's shapes.
    #[arg(long = "clip", value_name = "SHAPE", value_parser = volao::clip::ClipShape::parse)]
    shapes: Vec<volao::clip::ClipShape>,
    /// carve (remove the inside, default) or probe (keep only the inside) for --clip shapes.
    #[arg(long, value_parser = volao::clip::ClipMode::parse)]
    clip_mode: Option<volao::clip::ClipMode>,
    /// CAO: extra anti-aliasing samples for partly clipped voxels (default 32; 41 in all).
    #[arg(long)]
    msaa: Option<u32>,
    /// CAO: depth/dilation map size per clip shape in pixels (default 1024).
    #[arg(long)]
    clip_resolution: Option<u32>,
}

impl ClipArgs {
    /// The shapes given on the command line with the mode applied, or `fallback`.
    fn shapes_or(&self, fallback: Vec<volao::clip::ClipShape>) -> Vec<volao::clip::ClipShape> {
        if self.shapes.is_empty() {
            return fallback;
        }
        let mode = self.clip_mode.unwrap_or_default();
        self.shapes
            .iter()
            .cloned()
            .map(|mut s| {
                s.mode = mode;
                s
            })
            .collect()
    }

    fn apply(&self, ao: &mut volao::ao::AoSettings) -> Result<()> {
        if let Some(n) = self.msaa {
            if n > 256 {
                bail!("--msaa: at most 256 extra samples");
            }
            ao.msaa = n;
        }
        if let Some(r) = self.clip_resolution {
            if !(16..=8192).contains(&r) {
                bail!("--clip-resolution must be 16 to 8192 pixels");
            }
            ao.clip_resolution = r;
        }
        Ok(())
    }
}

/// One line per stage of a CAO frame.
fn print_cao(stats: &volao::ao::cao::CaoStats) {
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

/// How to read the input: 4-D frame and raw layout.
#[derive(Args, Debug, Default)]
struct LoadArgs {
    /// 4-D NIfTI: which frame to load (0-based).
    #[arg(long, default_value_t = 0)]
    frame: usize,
    /// Raw: voxel counts along x, y, z.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"])]
    dims: Option<Vec<usize>>,
    /// Raw: voxel type (u8, i8, u16, i16, u32, i32, f32, f64).
    #[arg(long = "type", value_parser = parse_type)]
    ty: Option<VoxelType>,
    /// Raw: byte order.
    #[arg(long, value_parser = parse_endian)]
    endian: Option<Endian>,
    /// Raw: voxel spacing in mm along x, y, z.
    #[arg(long, num_args = 3, value_names = ["SX", "SY", "SZ"])]
    spacing: Option<Vec<f32>>,
    /// Raw: bytes to skip before the first voxel.
    #[arg(long)]
    offset: Option<u64>,
    /// DICOM folder: which series, by number (from 0, as `volao info` lists them) or
    /// SeriesInstanceUID; default: the one with the most slices.
    #[arg(long, value_name = "N|UID")]
    series: Option<String>,
}

fn parse_type(s: &str) -> Result<VoxelType, String> {
    VoxelType::from_name(s)
        .ok_or_else(|| format!("unknown voxel type {s:?} (u8, i8, u16, i16, u32, i32, f32, f64)"))
}

fn parse_endian(s: &str) -> Result<Endian, String> {
    match s.to_ascii_lowercase().as_str() {
        "little" | "le" => Ok(Endian::Little),
        "big" | "be" => Ok(Endian::Big),
        _ => Err(format!("unknown byte order {s:?} (little or big)")),
    }
}

impl LoadArgs {
    fn options(&self) -> LoadOptions {
        let three = |v: &Option<Vec<usize>>| v.as_ref().map(|v| [v[0], v[1], v[2]]);
        LoadOptions {
            frame: self.frame,
            raw: RawOverrides {
                dims: three(&self.dims),
                ty: self.ty,
                endian: self.endian,
                spacing: self.spacing.as_ref().map(|v| [v[0], v[1], v[2]]),
                offset: self.offset,
            },
            max_bytes: None,
            series: self.series.clone(),
        }
    }
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Load time and peak memory of volao vs Python nibabel on the same files.
    Load(volao::bench::LoadBenchArgs),
    /// Frame times of the GPU ray caster (engine and cranium CT, 512² and 1024²).
    Render(volao::bench::RenderBenchArgs),
    /// The CAO paper's Tables 5–6 (LAO accuracy vs rays) on the Engine, and LAO throughput.
    Lao(volao::bench::LaoBenchArgs),
    /// The CAO paper's Tables 2–4: voxels recomputed, LAO every frame vs CAO, one vs
    /// two meshes, per-stage times and GPU memory.
    Cao(volao::bench_cao::CaoBenchArgs),
    /// Positional AO by ray marching (time and RMS vs 512-ray LAO, live vs precomputed
    /// frame times) and the cost of volumetric shadows, on the Engine.
    Raymarch(volao::bench::raymarch::RaymarchBenchArgs),
    /// Ruiz et al.'s Table 1 (filter maps on the cranium CT) and every cheap AO method's
    /// RMS against 512-ray LAO with its compute time.
    Filter(volao::bench_filter::FilterBenchArgs),
    /// (internal) load one file and print time and peak memory as JSON.
    #[command(hide = true)]
    LoadOne { file: PathBuf },
}

#[allow(unsafe_code, reason = "set_var before any thread exists; see SAFETY")]
fn main() {
    if let Some(dir) = volao::process::private_runtime_dir() {
        // SAFETY: first statement of main: no other thread exists yet that could read
        // the environment concurrently.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir) };
    }
    volao::process::exit_quietly_on_broken_pipe();
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        // One line: the error and its causes, joined.
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => Ok(volao::app::run(volao::app::ViewerOptions::default())?),
        Some(Command::View(args)) => view(&args),
        Some(Command::Info(args)) => {
            let report = match &args.file {
                Some(path) => {
                    let loaded = load_with_bar(path, &args.load.options())?;
                    describe_loaded(path, &loaded, args.bins)
                }
                None => describe_demo(&volume::demo::head_phantom(128), args.bins),
            };
            print_info(&report, args.json)
        }
        Some(Command::Convert(args)) => {
            let (volume, output) = match (args.demo, args.files.as_slice()) {
                (false, [input, output]) => {
                    (load_with_bar(input, &args.load.options())?.volume, output)
                }
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
            Ok(())
        }
        Some(Command::Gpu) => {
            let start = std::time::Instant::now();
            let gpu = volao::gpu::request_device()?;
            println!("adapter:  {}", gpu.describe());
            println!("driver:   {} {}", gpu.info.driver, gpu.info.driver_info);
            let limits = gpu.device.limits();
            println!(
                "3-D textures up to {}³, storage buffers up to {}",
                limits.max_texture_dimension_3d,
                fmt_bytes(limits.max_storage_buffer_binding_size as u64)
            );
            println!("features: {:?}", gpu.device.features());
            let dims = [16, 16, 16];
            let out = volao::gpu::smoke::run(&gpu, dims)?;
            if out != volao::gpu::smoke::expected(dims) {
                bail!("GPU self-test: the compute shader's output differs from the CPU reference");
            }
            println!(
                "self-test: compute shader output matches the CPU reference ({:.0} ms)",
                start.elapsed().as_secs_f64() * 1e3
            );
            Ok(())
        }
        Some(Command::Render(args)) => render(&args),
        Some(Command::Ao(args)) => ambient_occlusion(&args),
        Some(Command::Bench(BenchCommand::Render(args))) => volao::bench::render_bench(&args),
        Some(Command::Bench(BenchCommand::Lao(args))) => volao::bench::lao_bench(&args),
        Some(Command::Bench(BenchCommand::Raymarch(args))) => {
            volao::bench::raymarch::raymarch_bench(&args)
        }
        Some(Command::Bench(BenchCommand::Filter(args))) => {
            volao::bench_filter::filter_bench(&args)
        }
        Some(Command::Bench(BenchCommand::Load(args))) => volao::bench::load_bench(&args),
        Some(Command::Bench(BenchCommand::Cao(args))) => volao::bench_cao::cao_bench(&args),
        Some(Command::Bench(BenchCommand::LoadOne { file })) => volao::bench::load_one(&file),
    }
}

fn view(args: &ViewArgs) -> Result<()> {
    use volao::app::{OpenRequest, ViewerOptions};
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
        },
    };
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
        ..Default::default()
    };
    if let Some(size) = args.size {
        options.window_size = size;
    }
    if let Some(n) = args.clip_maps {
        options.clip_resolution = n;
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

fn ambient_occlusion(args: &AoArgs) -> Result<()> {
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

fn render(args: &RenderArgs) -> Result<()> {
    use volao::render::{Frame, RenderSettings};
    use volao::scene::{Light, RawLayout, SCENE_VERSION, Scene, VolumeSource};
    use volao::tf::{Preset, TransferFunction};

    let scene_path = args.input.as_ref().filter(|p| {
        p.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    });
    let scene = scene_path.map(|p| Scene::load(p)).transpose()?;
    // Which volume, and how to read it: the scene's, unless flags say otherwise.
    let (volume_path, mut opts) = match (&scene, scene_path) {
        (Some(s), Some(sp)) => {
            let raw = s
                .volume
                .raw
                .as_ref()
                .map(RawOverrides::from)
                .unwrap_or_default();
            (
                s.volume_path(sp),
                LoadOptions {
                    frame: s.volume.frame,
                    raw,
                    max_bytes: None,
                    series: None,
                },
            )
        }
        _ => (args.input.clone(), args.load.options()),
    };
    if scene.is_some() && !args.load.options().raw.is_empty() {
        opts.raw = args.load.options().raw;
    }
    let volume = match &volume_path {
        Some(p) => load_with_bar(p, &opts)?.volume,
        None => volume::demo::head_phantom(128),
    }
    .to_ras();
    let stats = volume.stats();
    let tf = match (&args.tf, &scene) {
        (Some(name), _) => TransferFunction::preset(Preset::from_name(name)?, &stats),
        (None, Some(s)) => s.transfer_function.clone(),
        (None, None) => TransferFunction::preset(Preset::default_for(&stats), &stats),
    };
    let tf = match args.window_level {
        Some((w, l)) => tf.with_window_level(w, l),
        None => tf,
    };
    let mut camera = scene.as_ref().map(|s| s.camera).unwrap_or_default();
    if let Some(c) = &args.camera {
        (camera.azimuth_deg, camera.elevation_deg, camera.distance) = (c[0], c[1], c[2]);
        if camera.distance <= 0.0 {
            bail!(
                "--camera: the distance must be positive (it is in bounding-sphere radii; {} is the default)",
                volao::render::camera::DEFAULT_DISTANCE
            );
        }
    }
    camera.orthographic |= args.ortho;
    let mut settings = scene
        .as_ref()
        .map(|s| s.render)
        .unwrap_or_else(RenderSettings::default);
    if let Some(b) = &args.background {
        settings.background = parse_background(b)?;
    }
    if let Some(k) = args.ambient {
        if !(0.0..=1.0).contains(&k) {
            bail!("--ambient must be between 0 and 1");
        }
        settings.ambient = k;
    }
    if let Some(sh) = args.shading {
        settings.shading = sh;
    }
    if let Some(step) = args.step {
        if step.is_nan() || step <= 0.0 || step.is_infinite() {
            bail!("--step must be positive (voxels between samples)");
        }
        settings.step_voxels = step;
    }
    settings.shadows |= args.shadows;
    let light = match (args.light, scene.as_ref().map(|s| s.light)) {
        (Some(direction), _) => Light::Directional { direction },
        (None, Some(l)) => l,
        (None, None) => Light::Headlight,
    };
    settings.light_direction = match light {
        Light::Directional { direction } => direction,
        // Shadows of a headlight fall behind what casts them, from the eye's direction.
        Light::Headlight => camera.backward().to_array(),
    };
    if settings.shadows {
        volao::render::shadow::light_direction(settings.light_direction)
            .map_err(anyhow::Error::msg)?;
    }
    if args.opacity_modulation.is_some() {
        settings.opacity_modulation = args.opacity_modulation;
    }
    if args.show_clip.is_some() {
        settings.clip_surface = args.show_clip;
    }
    let width = args
        .width
        .or(scene.as_ref().map(|s| s.width))
        .unwrap_or(800);
    let height = args
        .height
        .or(scene.as_ref().map(|s| s.height))
        .unwrap_or(800);
    if width == 0 || height == 0 || width > 32768 || height > 32768 {
        bail!("image size {width}×{height}: each side must be 1 to 32768 pixels");
    }
    let frame = Frame {
        camera,
        settings,
        width,
        height,
    };

    let mut ao = scene
        .as_ref()
        .map(|s| s.ambient_occlusion)
        .unwrap_or_default();
    if let Some(m) = args.ao {
        ao.method = m;
    }
    if let Some(r) = args.rays {
        ao.rays = r;
    }
    if let Some(m) = args.samples {
        if m == 0 {
            bail!("--samples must be at least 1");
        }
        ao.samples = m;
    }
    args.vao.apply(&mut ao.vao)?;

    args.clip.apply(&mut ao)?;
    let scene_clip = match (&scene, scene_path) {
        (Some(s), Some(sp)) => s.clip_shapes_resolved(sp),
        _ => Vec::new(),
    };
    let clip = args.clip.shapes_or(scene_clip);
    // Meshes: the flags', or else the scene's.
    let mesh_sources: Vec<volao::scene::MeshSource> = if args.mesh.is_empty() {
        match (&scene, scene_path) {
            (Some(s), Some(sp)) => s.meshes_resolved(sp),
            _ => Vec::new(),
        }
    } else {
        args.mesh
            .iter()
            .map(|p| volao::scene::MeshSource {
                path: p.clone(),
                rgba: args.mesh_rgba,
            })
            .collect()
    };
    let meshes = mesh_sources
        .iter()
        .map(|m| volao::render::surface::load_obj(&m.path, m.rgba))
        .collect::<Result<Vec<_>, _>>()?;
    args.fast_ao.apply(&mut ao)?;

    let start = std::time::Instant::now();
    let bar = slice_bar("ambient occlusion", ao.method != volao::ao::AoMethod::None);
    let out = volao::render::offscreen::render_with(
        &volume,
        &tf,
        &frame,
        &ao,
        volao::render::offscreen::Extras {
            clip: &clip,
            surfaces: &meshes,
        },
        !args.cpu,
        &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
    bar.finish_and_clear();
    for e in &out.clip_errors {
        eprintln!("warning: {e} (rendered without it)");
    }
    let seconds = start.elapsed().as_secs_f64();
    if out.downsampled > 0 {
        eprintln!(
            "note: the volume was halved {}× to fit the adapter's 3-D texture limits",
            out.downsampled
        );
    }
    out.image.save_png(&args.output)?;
    let ao_note = if ao.method == volao::ao::AoMethod::None {
        String::new()
    } else if matches!(
        ao.method,
        volao::ao::AoMethod::Vao | volao::ao::AoMethod::VaoLive
    ) {
        format!(
            " (positional AO{}, {} directions × {} samples, r_max {} mm: {:.0} ms)",
            if ao.method == volao::ao::AoMethod::VaoLive {
                " live"
            } else {
                ""
            },
            ao.vao.directions,
            ao.vao.samples,
            ao.vao.r_max_mm,
            out.ao_seconds * 1e3
        )
    } else if volao::ao::fast::handles(ao.method) {
        format!(
            " (AO {}: {:.0} ms)",
            volao::ao::fast::describe(&ao),
            out.ao_seconds * 1e3
        )
    } else {
        format!(
            " (AO {} rays × {} samples: {:.0} ms)",
            ao.rays.name(),
            ao.samples,
            out.ao_seconds * 1e3
        )
    };
    println!(
        "{}: {width}×{height} in {:.0} ms on {}{ao_note}",
        args.output.display(),
        seconds * 1e3,
        out.device
    );
    if let Some(stats) = &out.cao {
        print_cao(stats);
    }

    if let Some(path) = &args.save_scene {
        let s = Scene {
            version: SCENE_VERSION,
            volume: VolumeSource {
                path: volume_path.clone(),
                frame: opts.frame,
                raw: (!opts.raw.is_empty()).then(|| RawLayout::from(&opts.raw)),
            },
            transfer_function: tf,
            camera,
            light,
            render: settings,
            width,
            height,
            ambient_occlusion: ao,
            clip_shapes: clip,
            meshes: mesh_sources,
        };
        s.save(path)?;
        println!("scene: {}", path.display());
    }
    Ok(())
}

/// A progress bar over z-slices for AO precomputation (hidden when not a terminal).
fn slice_bar(what: &str, visible: bool) -> indicatif::ProgressBar {
    if !visible {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(1);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} slices {{eta}}"
    )) {
        bar.set_style(style);
    }
    bar
}

/// Loads a file, with a progress bar on the terminal for anything large.
fn load_with_bar(path: &Path, opts: &LoadOptions) -> Result<Loaded> {
    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut progress = |done: u64, total: u64| {
        if total < 32 << 20 {
            return;
        }
        let b = bar.get_or_insert_with(|| {
            let b = indicatif::ProgressBar::new(total);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "loading {bar:40} {bytes}/{total_bytes} {eta}",
            ) {
                b.set_style(style);
            }
            b
        });
        b.set_position(done);
    };
    let loaded = volume::load_with_progress(path, opts, &mut progress);
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let loaded = loaded?;
    for w in &loaded.warnings {
        eprintln!("warning: {}: {w}", volume::display_path(path));
    }
    Ok(loaded)
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
    println!("histogram ({} bins, log scale):", r.histogram.counts.len());
    print!("{}", r.histogram.to_text(48));
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        super::Cli::command().debug_assert();
    }
}
