//! The command line's flags: one clap struct per command, the groups they share, and
//! the `parse_*` value parsers.

use anyhow::{Result, bail};
use clap::Args;
use std::path::PathBuf;
use volao::volume::{Endian, LoadOptions, RawOverrides, VoxelType};

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// Volume file (.nii, .nii.gz, .hdr/.img, .pvm, .raw/.dat). Omit for the demo volume.
    pub file: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Histogram bins.
    #[arg(long, default_value_t = 32)]
    pub bins: usize,
    #[command(flatten)]
    pub load: LoadArgs,
    #[command(flatten)]
    pub labels: LabelArgs,
}

/// A segmentation to show or measure beside the image.
#[derive(Args, Debug, Default, Clone)]
pub struct LabelArgs {
    /// Label map (segmentation) of the image: any volume format volao reads with
    /// integer labels, or a 3D Slicer .seg.nrrd; placed on the image by the affines.
    #[arg(long, value_name = "SEG")]
    pub labels: Option<PathBuf>,
    /// Names and colours of the labels (FreeSurferColorLUT/Slicer .ctbl/.txt, NiiVue
    /// .json, MRIcron .lut); wins over those in the label file.
    #[arg(long, value_name = "FILE", requires = "labels")]
    pub label_table: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Volume file (.nii, .nii.gz, .hdr/.img, .pvm, .raw/.dat) or scene (.json). Omit for
    /// the demo volume.
    pub file: Option<PathBuf>,
    /// Write a PNG of the viewport (and its scene beside it) after --exit-after-frames
    /// frames, then close. For scripted figures and smoke tests.
    #[arg(long, requires = "exit_after_frames")]
    pub screenshot: Option<PathBuf>,
    /// Close after this many frames showing the volume (with its ambient occlusion).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub exit_after_frames: Option<u64>,
    /// (benchmark) Show only the viewport; once AO is ready move the scene's first clip
    /// shape 1 mm per frame for N frames and print the frame times.
    #[arg(long, hide = true, value_name = "N")]
    pub bench_clip_drag: Option<u64>,
    /// Edge of the clip shapes' depth maps (default 1024; smaller builds faster on a CPU
    /// driver).
    #[arg(long, value_name = "PIXELS", value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub clip_maps: Option<u32>,
    /// Images per second wanted while the view moves (the Rendering panel's "Target
    /// rate", 1 to 60; default 10): interactive images are made smaller until they keep
    /// it. `off`: images at full size while the view moves too (the panel's
    /// "Interactive quality while moving" unticked).
    #[arg(long, value_name = "IMAGES_PER_S|off", value_parser = parse_target_rate)]
    pub target_rate: Option<TargetRate>,
    /// Window size in points, e.g. 1280x800.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<[f32; 2]>,
    /// Turn off every skip in the ray caster, LAO and CAO (the naive result; see
    /// `volao render --help`).
    #[arg(long)]
    pub no_skipping: bool,
    /// The panes: 2x2 (axial, 3-D, coronal, sagittal), 3d (the 3-D view alone) or 1+3;
    /// default: 2x2 for a file, 3d for the demo.
    #[arg(long, value_parser = volao::slice::Layout::parse)]
    pub layout: Option<volao::slice::Layout>,
    #[command(flatten)]
    pub load: LoadArgs,
    /// A segmentation to show with the volume (the Segments panel styles it).
    #[command(flatten)]
    pub labels: LabelArgs,
}

pub fn parse_size(s: &str) -> Result<[f32; 2], String> {
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

/// `volao view --target-rate`: images per second while the view moves, or none reduced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TargetRate {
    /// No interactive quality: the images of a moving view at full size.
    Off,
    /// Images per second, 1 to 60 (the Rendering panel's range).
    Images(f32),
}

/// `--target-rate`: images per second, 1 to 60, or `off`.
pub fn parse_target_rate(s: &str) -> Result<TargetRate, String> {
    if s.trim().eq_ignore_ascii_case("off") {
        return Ok(TargetRate::Off);
    }
    match s.trim().parse::<f32>() {
        Ok(r) if (1.0..=60.0).contains(&r) => Ok(TargetRate::Images(r)),
        _ => Err(format!(
            "{s:?}: expected images per second from 1 to 60, or off"
        )),
    }
}

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// IN OUT, or just OUT with --demo. OUT's extension picks the format.
    #[arg(num_args = 1..=2, value_names = ["IN", "OUT"], required = true)]
    pub files: Vec<PathBuf>,
    /// Write the built-in demo volume instead of reading a file.
    #[arg(long)]
    pub demo: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

/// `volao slice`.
#[derive(Args, Debug)]
pub struct SliceArgs {
    /// Volume file or scene (.json). Omit for the demo volume.
    pub input: Option<PathBuf>,
    /// The plane: axial, coronal or sagittal.
    #[arg(long, default_value = "axial", value_parser = volao::slice::SliceAxis::parse)]
    pub axis: volao::slice::SliceAxis,
    /// Slice number along the axis, from the inferior, posterior resp. left end (default:
    /// the middle one).
    #[arg(long, conflicts_with = "at")]
    pub index: Option<usize>,
    /// The slice through this point, in RAS millimetres.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub at: Option<[f64; 3]>,
    #[command(flatten)]
    pub labels: LabelArgs,
    /// How segments show (as `volao render --segment`; hidden segments are not drawn).
    #[arg(long, value_name = "SPEC")]
    pub segment: Vec<String>,
    /// Opacity of the segments' colours over the grey, 0 to 1.
    #[arg(long, default_value_t = volao::slice::LabelOverlay::DEFAULT_OPACITY, value_parser = parse_unit)]
    pub label_opacity: f32,
    /// Draw only the segments' outlines.
    #[arg(long)]
    pub outline: bool,
    /// Window/level of the greys in data units (e.g. HU); default: the transfer
    /// function's (the scene's, or the preset for the data).
    #[arg(long, value_name = "WINDOW,LEVEL", value_parser = parse_window_level, allow_hyphen_values = true)]
    pub window_level: Option<(f64, f64)>,
    /// The patient's left on the image's left (default: radiological, right on the left).
    #[arg(long)]
    pub neurological: bool,
    /// Trilinear sampling instead of the nearest voxel.
    #[arg(long)]
    pub linear: bool,
    /// An oblique acquisition in its own planes instead of resampled onto the patient's axes.
    #[arg(long)]
    pub acquisition_plane: bool,
    /// Orientation letters on the edges and a scale bar.
    #[arg(long)]
    pub annotate: bool,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub load: LoadArgs,
}

/// A point `X,Y,Z` in mm.
pub fn parse_point(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = numbers(s)?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "{s:?}: expected three numbers X,Y,Z in mm, e.g. 0,-20,35"
        )),
    }
}

/// A number from 0 to 1.
pub fn parse_unit(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: expected a number from 0 to 1")),
    }
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Volume file or scene (.json). Omit for the demo volume.
    pub input: Option<PathBuf>,
    #[command(flatten)]
    pub labels: LabelArgs,
    /// How segments show: PATTERN:CHANGE[,CHANGE…] with PATTERN a segment name (`*`
    /// matches any run of characters), a label value or `unlabelled`, and CHANGE one of
    /// hide, show, opacity=F, color=#rrggbb, tint, replace, outline, fill. Repeatable,
    /// applied in order.
    #[arg(long, value_name = "SPEC")]
    pub segment: Vec<String>,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The viewer's panes in one image: 2x2 (axial, 3-D, coronal, sagittal) or 1+3, the
    /// slices through the volume's centre (or --at) with the transfer function's
    /// window; 3d (the default) is the 3-D view alone.
    #[arg(long, value_parser = volao::slice::Layout::parse)]
    pub layout: Option<volao::slice::Layout>,
    /// An orientation marker (R, A, S axes) in the 3-D view's corner, and with --layout
    /// orientation letters and scale bars on the slices (off by default: pixels stay
    /// comparable).
    #[arg(long)]
    pub annotate: bool,
    /// With --layout: the slices through this point, in RAS millimetres.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true, requires = "layout")]
    pub at: Option<[f64; 3]>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Transfer-function preset: ct-bone, ct-soft-tissue, ct-vessels, mr-t1-brain, cao-single-color.
    #[arg(long)]
    pub tf: Option<String>,
    /// Window/level in data units (e.g. HU): stretches the transfer function's points
    /// over [level - window/2, level + window/2].
    #[arg(long, value_name = "WINDOW,LEVEL", value_parser = parse_window_level, allow_hyphen_values = true)]
    pub window_level: Option<(f64, f64)>,
    /// Orbit camera: azimuth and elevation in degrees, distance in bounding-sphere radii.
    #[arg(long, value_name = "AZIMUTH,ELEVATION,DISTANCE", value_parser = parse_camera, allow_hyphen_values = true)]
    pub camera: Option<[f32; 3]>,
    /// Orthographic projection.
    #[arg(long)]
    pub ortho: bool,
    /// Background: a name (black, white, grey), #rrggbb, or "transparent".
    #[arg(long)]
    pub background: Option<String>,
    #[arg(long, value_parser = parse_shading)]
    pub shading: Option<volao::render::Shading>,
    /// composite (the default), mip, minip, average (greys over the transfer function's
    /// window), iso or iso:VALUE (the first surface at VALUE, data units; default: where
    /// the opacity reaches half its maximum).
    #[arg(long, value_name = "MODE")]
    pub mode: Option<volao::render::RenderMode>,
    /// Step between samples in voxels.
    #[arg(long)]
    pub step: Option<f32>,
    /// Ambient coefficient k, 0 to 1: the ambient share of the light, C_TF·A_s·(k + (1 − k)·D) (1: ambient occlusion only).
    #[arg(long)]
    pub ambient: Option<f32>,
    /// AO strength s: the AO factor is clamp(1 − s·(1 − A), 0, 1) (0: no AO, 1: as
    /// computed, above 1: deeper; default 1).
    #[arg(long, value_name = "S")]
    pub ao_strength: Option<f32>,
    /// The AO factor scales the ambient term only (volao's shading before issue #18)
    /// instead of ambient and diffuse light.
    #[arg(long)]
    pub ao_ambient_only: bool,
    /// Read the AO this many voxels out of the material along the normal, 0 to 2
    /// (default 2; 0: at the sample itself, volao before issue #18).
    #[arg(long, value_name = "VOXELS")]
    pub ao_offset: Option<f32>,
    /// Ambient occlusion: none, lao, cao (exact under clipping), lao-full (LAO of every
    /// voxel each frame, CAO's baseline), vao / vao-live (positional AO, precomputed or
    /// at every sample), cdf, gauss, penner (filter maps) or cone (cone-traced).
    #[arg(long, value_parser = ao_method())]
    pub ao: Option<volao::ao::AoMethod>,
    /// AO ray pattern: 6, 14, 26, 54 (the CAO paper's) or fib:N (Fibonacci lattice).
    #[arg(long, value_parser = parse_rays)]
    pub rays: Option<volao::ao::rays::RaySet>,
    /// AO samples per ray (1 mm apart).
    #[arg(long)]
    pub samples: Option<u32>,
    #[command(flatten)]
    pub clip: ClipArgs,
    #[command(flatten)]
    pub vao: VaoArgs,
    /// Volumetric shadows from a directional light (see --light).
    #[arg(long)]
    pub shadows: bool,
    /// Turn off every skip (empty space in the ray caster; unreadable bricks, empty
    /// samples and bricks far from the clip shapes in LAO and CAO): the naive result,
    /// which the skips never change.
    #[arg(long)]
    pub no_skipping: bool,
    /// Compute LAO and CAO for every voxel the transfer function can make visible, not
    /// only for those this image reads (a visibility pass first; the same pixels).
    #[arg(long)]
    pub no_view_culling: bool,
    /// Directional light: the direction towards the light in volume space (RAS: x to the
    /// patient's left, y anterior, z superior), e.g. -0.5,0.6,0.62.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_light, allow_hyphen_values = true)]
    pub light: Option<[f32; 3]>,
    /// Draw a Wavefront OBJ mesh inside the volume (repeatable). Coordinates in mm, in the
    /// volume's RAS frame with the origin at the volume's centre.
    #[arg(long, value_name = "FILE.obj")]
    pub mesh: Vec<PathBuf>,
    /// Colour of the meshes: straight R,G,B,A in 0…1 (A < 1: translucent).
    #[arg(long, value_name = "R,G,B,A", value_parser = parse_rgba, default_value = "0.9,0.9,0.9,1")]
    pub mesh_rgba: [f32; 4],
    /// Draw the clip shapes as surfaces inside the rendering: straight R,G,B,A in 0…1
    /// (A < 1: translucent), e.g. 1,0.8,0.2,0.3.
    #[arg(long, value_name = "R,G,B,A", value_parser = parse_rgba)]
    pub show_clip: Option<[f32; 4]>,
    #[command(flatten)]
    pub fast_ao: FastAoArgs,
    /// Opacity modulation by local variance: α · min(σ²/σ²_max, 1) (Ruiz et al. §4.2),
    /// σ² of the normalised density in a box of radius RADIUS voxels (default 10).
    #[arg(long, value_name = "SIGMA2_MAX[,RADIUS]", value_parser = parse_modulation)]
    pub opacity_modulation: Option<volao::ao::filter::OpacityModulation>,
    /// Render on the CPU twin instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
    /// Also write the scene that reproduces this image.
    #[arg(long)]
    pub save_scene: Option<PathBuf>,
    #[command(flatten)]
    pub load: LoadArgs,
}

/// Flags of the filter-map and cone-traced AO methods (`volao render` and `volao ao`).
#[derive(Args, Debug)]
pub struct FastAoArgs {
    /// Filter maps (cdf, gauss, penner): box radius r, side 2r + 1 (default 10 voxels).
    #[arg(long)]
    pub radius: Option<f32>,
    /// The radius is in mm (rounded to voxels per axis) instead of voxels.
    #[arg(long)]
    pub radius_mm: bool,
    /// Filter maps: statistics of the density (the paper) or of the TF opacity.
    #[arg(long, value_parser = volao::ao::filter::StatisticSource::parse)]
    pub statistic: Option<volao::ao::filter::StatisticSource>,
    /// Cone tracing: 6, 14 or 26 cones (default 6).
    #[arg(long, value_parser = volao::ao::cone::ConeSet::parse)]
    pub cones: Option<volao::ao::cone::ConeSet>,
    /// Cone tracing: low, medium or high = 3, 5 or 7 spheres per cone (default medium).
    #[arg(long, value_parser = volao::ao::cone::ConePreset::parse)]
    pub cone_preset: Option<volao::ao::cone::ConePreset>,
}

impl FastAoArgs {
    pub fn apply(&self, ao: &mut volao::ao::AoSettings) -> Result<()> {
        if let Some(r) = self.radius {
            if !r.is_finite() || !(0.0..=1000.0).contains(&r) {
                bail!("--radius must be between 0 and 1000");
            }
            ao.radius = r;
        }
        if self.radius_mm {
            ao.radius_unit = volao::ao::filter::RadiusUnit::Mm;
        }
        set(&mut ao.statistic, self.statistic);
        set(&mut ao.cones, self.cones);
        set(&mut ao.cone_preset, self.cone_preset);
        Ok(())
    }
}

/// `--ao` / `--method`: the method codes, each listed by `--help` with the name the
/// viewer's AO panel gives it.
pub fn ao_method() -> impl clap::builder::TypedValueParser<Value = volao::ao::AoMethod> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    use volao::ao::AoMethod;
    PossibleValuesParser::new(AoMethod::ALL.map(|m| PossibleValue::new(m.code()).help(m.label())))
        .map(|code| {
            AoMethod::ALL
                .into_iter()
                .find(|m| m.code() == code)
                .unwrap_or_default()
        })
}

/// Overrides `setting` with a flag's value when the flag was given, refusing a value
/// outside `range` (NaN included) with `message`.
pub fn set_within<T: PartialOrd>(
    setting: &mut T,
    flag: Option<T>,
    range: std::ops::RangeInclusive<T>,
    message: &str,
) -> Result<()> {
    if let Some(v) = flag {
        if !range.contains(&v) {
            bail!("{message}");
        }
        *setting = v;
    }
    Ok(())
}

/// Overrides `setting` with a flag's value when the flag was given.
pub fn set<T>(setting: &mut T, flag: Option<T>) {
    if let Some(v) = flag {
        *setting = v;
    }
}

pub fn parse_modulation(s: &str) -> Result<volao::ao::filter::OpacityModulation, String> {
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
pub fn numbers<T: std::str::FromStr>(s: &str) -> Result<Vec<T>, String>
where
    T::Err: std::fmt::Display,
{
    s.split(',')
        .map(|x| x.trim().parse::<T>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))
}

pub fn parse_camera(s: &str) -> Result<[f32; 3], String> {
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
pub struct VaoArgs {
    /// Positional AO: rays over the sphere, N_dir (default 20).
    #[arg(long)]
    pub vao_directions: Option<u32>,
    /// Positional AO: stratified samples per ray, N_samples (default 8).
    #[arg(long)]
    pub vao_samples: Option<u32>,
    /// Positional AO: ray length r_max in mm (default 20).
    #[arg(long, value_name = "MM")]
    pub vao_radius: Option<f32>,
    /// Positional AO: an accepted sample at least this opaque stops a ray (default 0.95).
    #[arg(long)]
    pub vao_threshold: Option<f32>,
    /// Positional AO, isosurface variant: occluded where a sample lies within TOL of
    /// VALUE (data units).
    #[arg(long, value_name = "VALUE,TOL", value_parser = parse_iso, allow_hyphen_values = true)]
    pub vao_iso: Option<(f64, f64)>,
}

impl VaoArgs {
    /// Applies the flags to `s` and checks the result.
    pub fn apply(&self, s: &mut volao::ao::vao::VaoSettings) -> Result<()> {
        set(&mut s.directions, self.vao_directions);
        set(&mut s.samples, self.vao_samples);
        set(&mut s.r_max_mm, self.vao_radius);
        set(&mut s.v_thres, self.vao_threshold);
        if let Some((value, tolerance)) = self.vao_iso {
            s.isosurface = Some(volao::ao::vao::Isosurface { value, tolerance });
        }
        s.validate()?;
        Ok(())
    }
}

pub fn parse_iso(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = numbers(s)?;
    match v.as_slice() {
        [value, tol] if value.is_finite() && tol.is_finite() && *tol > 0.0 => Ok((*value, *tol)),
        _ => Err(format!(
            "{s:?}: expected VALUE,TOL with a positive tolerance, e.g. 300,50"
        )),
    }
}

pub fn parse_rgba(s: &str) -> Result<[f32; 4], String> {
    let v: Vec<f32> = numbers(s)?;
    match v.as_slice() {
        [r, g, b, a] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b, *a]),
        _ => Err(format!(
            "{s:?}: expected four numbers from 0 to 1, R,G,B,A, e.g. 1,0.8,0.2,1"
        )),
    }
}

pub fn parse_light(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = numbers(s)?;
    match v.as_slice() {
        [x, y, z] => volao::render::shadow::light_direction([*x, *y, *z]).map(|d| d.to_array()),
        _ => Err(format!(
            "{s:?}: expected three numbers X,Y,Z, e.g. -0.5,0.6,0.62"
        )),
    }
}

pub fn parse_window_level(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = numbers(s)?;
    match v.as_slice() {
        [w, l] if *w > 0.0 && w.is_finite() && l.is_finite() => Ok((*w, *l)),
        _ => Err(format!(
            "{s:?}: expected WINDOW,LEVEL with a positive window, e.g. 400,40"
        )),
    }
}

pub fn parse_rays(s: &str) -> Result<volao::ao::rays::RaySet, String> {
    volao::ao::rays::RaySet::parse(s).map_err(|e| e.to_string())
}

pub fn parse_shading(s: &str) -> Result<volao::render::Shading, String> {
    match s {
        "none" => Ok(volao::render::Shading::None),
        "phong" => Ok(volao::render::Shading::Phong),
        _ => Err(format!("unknown shading {s:?} (none or phong)")),
    }
}

/// Parses a background colour into straight RGBA.
pub fn parse_background(s: &str) -> Result<[f32; 4]> {
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
pub struct AoArgs {
    /// Volume file.
    pub input: PathBuf,
    /// Output volume (.nii.gz, .nii or .raw), f32 values in [0, 1].
    #[arg(short, long)]
    pub output: PathBuf,
    /// AO method: lao, cao, lao-full (with --clip), vao (positional AO; vao-live gives the
    /// same volume), cdf, gauss, penner or cone.
    #[arg(long, alias = "ao", default_value = "lao", value_parser = ao_method())]
    pub method: volao::ao::AoMethod,
    /// Ray pattern: 6, 14, 26, 54 or fib:N.
    #[arg(long, default_value = "54", value_parser = parse_rays)]
    pub rays: volao::ao::rays::RaySet,
    /// Samples per ray (1 mm apart).
    #[arg(long, default_value_t = volao::ao::lao::DEFAULT_SAMPLES)]
    pub samples: u32,
    /// Transfer-function preset giving the opacity (default: by the data's range).
    #[arg(long)]
    pub tf: Option<String>,
    #[command(flatten)]
    pub clip: ClipArgs,
    #[command(flatten)]
    pub vao: VaoArgs,
    #[command(flatten)]
    pub fast_ao: FastAoArgs,
    /// Compute on the CPU twin instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
    /// LAO, CAO and lao-full: compute only the voxels a composite rendering with this
    /// transfer function can read (much faster on sparse data); the others are written
    /// as 1. Without it every voxel is computed.
    #[arg(long)]
    pub visible_only: bool,
    #[command(flatten)]
    pub load: LoadArgs,
}

/// Clip shapes and CAO parameters.
#[derive(Args, Debug, Default)]
pub struct ClipArgs {
    /// A clip shape (repeatable, up to 8), lengths in mm from the volume's centre:
    /// plane:PX,PY,PZ,NX,NY,NZ (removes the side the normal points to),
    /// sphere:CX,CY,CZ,R, box:CX,CY,CZ,SX,SY,SZ[,RX,RY,RZ], cylinder:CX,CY,CZ,R,H[,RX,RY,RZ],
    /// torus:CX,CY,CZ,R,r[,RX,RY,RZ], mesh:FILE.obj|stl[,CX,CY,CZ[,SCALE]]. Replaces a scene's shapes.
    #[arg(long = "clip", value_name = "SHAPE", value_parser = volao::clip::ClipShape::parse)]
    pub shapes: Vec<volao::clip::ClipShape>,
    /// carve (remove the inside, default) or probe (keep only the inside) for --clip shapes.
    #[arg(long, value_parser = volao::clip::ClipMode::parse)]
    pub clip_mode: Option<volao::clip::ClipMode>,
    /// CAO: extra anti-aliasing samples for partly clipped voxels (default 32; 41 in all).
    #[arg(long)]
    pub msaa: Option<u32>,
    /// CAO: depth/dilation map size per clip shape in pixels (default 1024).
    #[arg(long)]
    pub clip_resolution: Option<u32>,
}

impl ClipArgs {
    /// The shapes given on the command line with the mode applied, or `fallback`.
    pub fn shapes_or(&self, fallback: Vec<volao::clip::ClipShape>) -> Vec<volao::clip::ClipShape> {
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

    pub fn apply(&self, ao: &mut volao::ao::AoSettings) -> Result<()> {
        set_within(
            &mut ao.msaa,
            self.msaa,
            0..=256,
            "--msaa: at most 256 extra samples",
        )?;
        set_within(
            &mut ao.clip_resolution,
            self.clip_resolution,
            16..=8192,
            "--clip-resolution must be 16 to 8192 pixels",
        )
    }
}

/// How to read the input: 4-D frame and raw layout.
#[derive(Args, Debug, Default)]
pub struct LoadArgs {
    /// 4-D volumes (NIfTI, NRRD, MGH/MGZ): which frame to load (0-based).
    #[arg(long, default_value_t = 0)]
    pub frame: usize,
    /// Raw: voxel counts along x, y, z.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"])]
    pub dims: Option<Vec<usize>>,
    /// Raw: voxel type (u8, i8, u16, i16, u32, i32, f32, f64).
    #[arg(long = "type", value_parser = parse_type)]
    pub ty: Option<VoxelType>,
    /// Raw: byte order.
    #[arg(long, value_parser = parse_endian)]
    pub endian: Option<Endian>,
    /// Raw: voxel spacing in mm along x, y, z.
    #[arg(long, num_args = 3, value_names = ["SX", "SY", "SZ"])]
    pub spacing: Option<Vec<f32>>,
    /// Raw: bytes to skip before the first voxel.
    #[arg(long)]
    pub offset: Option<u64>,
    /// DICOM folder: which series, by number (from 0, as `volao info` lists them) or
    /// SeriesInstanceUID; default: the one with the most slices.
    #[arg(long, value_name = "N|UID")]
    pub series: Option<String>,
    /// OME-Zarr store: which multiscale level to read (0 = full resolution; `volao info`
    /// lists them).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub level: usize,
}

pub fn parse_type(s: &str) -> Result<VoxelType, String> {
    VoxelType::from_name(s)
        .ok_or_else(|| format!("unknown voxel type {s:?} (u8, i8, u16, i16, u32, i32, f32, f64)"))
}

pub fn parse_endian(s: &str) -> Result<Endian, String> {
    match s.to_ascii_lowercase().as_str() {
        "little" | "le" => Ok(Endian::Little),
        "big" | "be" => Ok(Endian::Big),
        _ => Err(format!("unknown byte order {s:?} (little or big)")),
    }
}

impl LoadArgs {
    pub fn options(&self) -> LoadOptions {
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
            level: self.level,
        }
    }
}

#[derive(Args, Debug)]
pub struct BatchArgs {
    /// Scene files (.json), or folders whose .json files are all scenes.
    #[arg(required = true, value_name = "SCENE|DIR")]
    pub inputs: Vec<PathBuf>,
    /// Folder for the images: NAME.png for each scene NAME.json (created if missing).
    /// Outputs already there are skipped, so an interrupted batch resumes.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write each scene's ambient-occlusion volume, NAME.ao.nii.gz, in its volume
    /// file's geometry (`volao ao` with the scene's method, parameters and transfer
    /// function); scenes without AO get none.
    #[arg(long)]
    pub ao_volumes: bool,
    /// Render on the CPU twin instead of the GPU.
    #[arg(long)]
    pub cpu: bool,
}
