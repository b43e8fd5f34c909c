//! Ray casting: the GPU ray caster ([`gpu::RayCaster`]), its CPU twin ([`cpu`]), the
//! camera, the shared per-frame parameters and images.
//!
//! Both paths build the same [`RaycastParams`] and follow the same steps per pixel:
//! ray through the pixel centre → box intersection in physical space → jittered start →
//! fixed steps of `step_voxels` voxels, the last one shortened to the box exit and its
//! opacity corrected for its true length (Imagire et al.'s valid sampling path) →
//! transfer-function lookup → optional Blinn–Phong headlight, the AO factor on ambient
//! and diffuse light (docs/algorithms.md, "Shading") → front-to-back compositing,
//! stopping at α > 0.99. The other [`RenderMode`]s walk the same samples: MIP, MinIP
//! and average reduce the values of the unclipped ones to a grey; iso stops at the
//! first one inside the surface, places the hit by bisection and shades it there.

pub mod camera;
pub mod cpu;
pub mod extras;
pub mod gpu;
mod gpu_volume;
pub mod gradient;
pub mod image;
pub mod offscreen;
pub mod reuse;
pub mod shadow;
pub mod surface;
mod variant;

pub use camera::Camera;
pub use image::Image;

use crate::sample::AO_READ_REACH;
use crate::texels::gpu_data::VolumeMap;
use crate::texels::{BLOCK, VolumeTexels};
use crate::tf::Lut;

/// The default direction towards the light (volume RAS space): from the patient's left,
/// front and above, so shadows fall visibly in an anterior view.
pub const DEFAULT_LIGHT: [f32; 3] = [-0.5, 0.6, 0.62];

/// The most balls a frame's uniforms hold ([`reuse`]: where shapes that moved can
/// change an image); more are merged into one that holds them all.
pub const MAX_BALLS: usize = 8;

/// Opacity at which a ray stops (early ray termination).
pub const OPAQUE: f32 = 0.99;

/// How to shade samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shading {
    /// Transfer-function colour times the ambient term only.
    None,
    /// Blinn–Phong with a headlight, gradient normals by central differences.
    #[default]
    Phong,
}

/// What a ray makes of its samples.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum RenderMode {
    /// Front-to-back compositing of the transfer function's colour and opacity.
    #[default]
    Composite,
    /// Maximum intensity projection: the largest value along the ray, in grey from
    /// black to white over the transfer function's window (first to last point).
    Mip,
    /// Minimum intensity projection (airways, vessels in black-blood MR), same grey.
    Minip,
    /// Mean value along the ray, same grey (a simulated radiograph).
    Average,
    /// The first surface where the value reaches this (data units; `None`: where the
    /// transfer function's opacity first reaches half its maximum), refined between
    /// samples, coloured by the transfer function, lit and ambient-occluded.
    Iso(Option<f64>),
}

impl RenderMode {
    /// The shader's code for the mode (`MODE_*` in raycast.wgsl).
    pub fn code(self) -> u32 {
        match self {
            RenderMode::Composite => 0,
            RenderMode::Mip => 1,
            RenderMode::Minip => 2,
            RenderMode::Average => 3,
            RenderMode::Iso(_) => 4,
        }
    }

    /// Whether the mode reads the ambient-occlusion volume (MIP, MinIP and average
    /// show values, not light).
    pub fn uses_ao(self) -> bool {
        matches!(self, RenderMode::Composite | RenderMode::Iso(_))
    }

    pub fn is_composite(&self) -> bool {
        *self == RenderMode::Composite
    }
}

impl std::str::FromStr for RenderMode {
    type Err = String;

    /// `composite`, `mip`, `minip`, `average`, `iso` or `iso:VALUE`.
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        let lower = s.to_ascii_lowercase();
        Ok(match lower.as_str() {
            "composite" => RenderMode::Composite,
            "mip" => RenderMode::Mip,
            "minip" => RenderMode::Minip,
            "average" => RenderMode::Average,
            "iso" => RenderMode::Iso(None),
            _ => match lower.strip_prefix("iso:").map(|v| v.trim().parse::<f64>()) {
                Some(Ok(v)) if v.is_finite() => RenderMode::Iso(Some(v)),
                _ => {
                    return Err(format!(
                        "render mode {s:?}: expected composite, mip, minip, average, iso or iso:VALUE (a finite number in data units)"
                    ));
                }
            },
        })
    }
}

impl std::fmt::Display for RenderMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RenderMode::Composite => f.write_str("composite"),
            RenderMode::Mip => f.write_str("mip"),
            RenderMode::Minip => f.write_str("minip"),
            RenderMode::Average => f.write_str("average"),
            RenderMode::Iso(None) => f.write_str("iso"),
            RenderMode::Iso(Some(v)) => write!(f, "iso:{v}"),
        }
    }
}

impl TryFrom<String> for RenderMode {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<RenderMode> for String {
    fn from(m: RenderMode) -> String {
        m.to_string()
    }
}
/// The default AO strength of [`RenderSettings::ao_strength`].
pub const DEFAULT_AO_STRENGTH: f32 = 1.0;

/// The default [`RenderSettings::ao_offset`], in voxels.
pub const DEFAULT_AO_OFFSET: f32 = 2.0;

/// What the AO method gives a point in front of an open, flat, opaque surface, `A_open`:
/// the shading reads `A' = min(A / A_open, 1)`, so a flat face in the open keeps its light
/// and only what is occluded more than that darkens (docs/algorithms.md).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AoReference {
    /// Half the sphere, `A_open = 1/2` at any offset: positional AO, filter maps, cones,
    /// and AO from elsewhere.
    #[default]
    Half,
    /// LAO's rays (Eq. 2, also CAO's): `M` samples 1 mm apart along each direction.
    Rays {
        set: crate::ao::rays::RaySet,
        samples: u32,
    },
}

impl AoReference {
    /// `A_open` at `offset_mm` in front of the surface. For LAO's rays, exactly what
    /// Eq. 2 gives there with opaque material behind the plane: a ray into it counts its
    /// samples up to the first one past the plane, `min(⌊h / cos θ⌋ + 1, M) / M`; every
    /// other ray counts 1. The mean over the rays, as `lao_cpu` weighs them.
    pub fn open_plane(&self, offset_mm: f32) -> f32 {
        match *self {
            AoReference::Half => 0.5,
            AoReference::Rays { set, samples } => {
                let m = samples.max(1) as f32;
                let h = offset_mm.max(0.0);
                let directions = set.directions();
                let sum: f32 = directions
                    .iter()
                    .map(|d| {
                        // The plane's normal is +z: a ray with d.z < 0 goes into it.
                        let c = -d.normalize_or_zero().z;
                        if c > 1e-6 {
                            ((h / c).floor() + 1.0).min(m) / m
                        } else {
                            1.0
                        }
                    })
                    .sum();
                sum / directions.len().max(1) as f32
            }
        }
    }
}

/// Render settings that are not the camera or the transfer function.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RenderSettings {
    /// Composite (the default), an intensity projection or an isosurface.
    #[serde(skip_serializing_if = "RenderMode::is_composite")]
    pub mode: RenderMode,
    /// Distance between samples in voxels (of the smallest spacing).
    pub step_voxels: f32,
    pub shading: Shading,
    /// Ambient coefficient `k`: the ambient part of the light; the directional part gets
    /// `1 − k` (see [`RenderSettings::ao_ambient_only`] for where the AO applies).
    pub ambient: f32,
    /// AO strength `s`: the AO factor is `A_s = clamp(1 − s · (1 − A'), 0, 1)`; 0 ignores
    /// the AO, 1 uses it as computed, above 1 deepens it (docs/algorithms.md).
    pub ao_strength: f32,
    /// The AO factor scales the ambient term only, `C = C_TF · (k · A_s + (1 − k) · D · S)
    /// + spec · S` with `A' = A` (volao before issue #18); when false (the default) it
    /// scales ambient and diffuse light, `C = C_TF · A_s · (k + (1 − k) · D · S) + spec · S`
    /// with `A' = min(A / A_open, 1)` (`A_open`: what the method gives an open flat surface,
    /// [`RenderSettings::ao_reference`]).
    pub ao_ambient_only: bool,
    /// Where a sample reads the AO: this many voxels out of the material along the
    /// normal, times how much of an edge the sample is (0: at the sample, volao before
    /// issue #18). The AO just outside a surface is the occlusion the surface sees;
    /// inside the material every voxel is occluded, so reading there greys the surface
    /// (docs/algorithms.md).
    pub ao_offset: f32,
    /// What the AO method gives an open flat surface at `ao_offset` (set with the AO,
    /// not saved: scenes keep the AO settings it comes from).
    #[serde(skip)]
    pub ao_reference: AoReference,
    pub specular: f32,
    pub shininess: f32,
    /// Per-pixel jittered ray start (removes wood-grain rings).
    pub jitter: bool,
    /// Skip blocks the transfer function makes fully transparent (never changes the image).
    pub empty_space_skipping: bool,
    /// Straight RGBA; alpha 0 gives a transparent background.
    pub background: [f32; 4],
    /// Volumetric shadows from the directional light (see [`shadow`]).
    pub shadows: bool,
    /// Unit direction towards the light in volume space (RAS), for shadows. Not saved
    /// here: scene files keep it in their `light`.
    #[serde(skip)]
    pub light_direction: [f32; 3],
    /// Multiply each sample's opacity by `min(σ²/σ²_max, 1)` (Ruiz et al. §4.2); off
    /// when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub opacity_modulation: Option<crate::ao::OpacityModulation>,
    /// Draw the clip shapes as surfaces of this straight RGBA (A < 1: translucent).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip_surface: Option<[f32; 4]>,
    /// Greys of the projections (MIP, MinIP, average) over this `[lo, hi]` (data units)
    /// instead of the transfer function's window ([`readable_window`] picks one where
    /// that window would show nothing).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub projection_window: Option<[f64; 2]>,
    /// Compute LAO and CAO only for the voxels this image reads (issue #46,
    /// [`crate::ao::view`]): a visibility pass first, the same pixels. False
    /// (`--no-view-culling`): every voxel the transfer function can make visible.
    #[serde(skip_serializing_if = "is_true")]
    pub view_culling: bool,
}

fn is_true(b: &bool) -> bool {
    *b
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            mode: RenderMode::Composite,
            step_voxels: 0.5,
            shading: Shading::Phong,
            ambient: 0.4,
            ao_strength: DEFAULT_AO_STRENGTH,
            ao_ambient_only: false,
            ao_offset: DEFAULT_AO_OFFSET,
            ao_reference: AoReference::Half,
            specular: 0.3,
            shininess: 24.0,
            jitter: true,
            empty_space_skipping: true,
            background: [0.0, 0.0, 0.0, 1.0],
            shadows: false,
            light_direction: DEFAULT_LIGHT,
            opacity_modulation: None,
            clip_surface: None,
            projection_window: None,
            view_culling: true,
        }
    }
}

/// A window for `mode`'s greys where the transfer function's would show nothing, and a
/// note saying so: the average of the rays lies near the data's mean, so when the
/// window misses the mean (the cranium's bone window: every ray is mostly air) the greys
/// span from the minimum to as far above the mean. MinIP keeps the window (every ray
/// through a whole scan meets its surroundings: look inside a probe shape) and says so.
pub fn readable_window(
    mode: RenderMode,
    tf: &crate::tf::TransferFunction,
    stats: &crate::volume::Stats,
) -> Option<([f64; 2], String)> {
    let (w, l) = tf.window_level();
    let (lo, hi) = (l - w / 2.0, l + w / 2.0);
    let fmt = |v: f64| format!("{v:.0}");
    match mode {
        RenderMode::Average if !(lo..=hi).contains(&stats.mean) && stats.max > stats.min => {
            let top = (2.0 * stats.mean - stats.min).min(stats.max);
            let note = format!(
                "average: the transfer function's window ({} to {}) misses the data's mean \
                 ({}), so the greys span {} to {}",
                fmt(lo),
                fmt(hi),
                fmt(stats.mean),
                fmt(stats.min),
                fmt(top)
            );
            Some(([stats.min, top], note))
        }
        RenderMode::Minip if stats.min < lo => {
            let note = format!(
                "MinIP: rays through the surroundings meet {}, below the window ({} to {}): \
                 they are black; probe with a clip shape inside the data to see it",
                fmt(stats.min),
                fmt(lo),
                fmt(hi)
            );
            Some(([lo, hi], note))
        }
        _ => None,
    }
}

/// Per-frame uniforms. Mirrors `struct Params` in `shaders/raycast.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RaycastParams {
    /// Clip space → volume-centred physical space (mm).
    pub inv_view_proj: [[f32; 4]; 4],
    /// Half the box extent in mm (the box is `[-h, h]`); w: the gradient volume's scale
    /// `M` ([`gradient::GradientVolume::scale`]), 0 when there is none (set by the ray
    /// caster; the general shader reads it, the CPU twin does not).
    pub box_half: [f32; 4],
    /// Straight RGBA background.
    pub background: [f32; 4],
    /// ambient k, specular, shininess, shading on (0/1).
    pub shading: [f32; 4],
    /// One voxel in texture coordinates along x, y, z; w = smallest spacing (mm).
    pub voxel_uvw: [f32; 4],
    /// x: the gradient scale for "is this an edge" (with the LUT map's scale,
    /// [`crate::texels::gpu_data::VolumeMap`]); yzw unused.
    pub edge: [f32; 4],
    /// dt (mm), jitter on (0/1), max steps, skipping on (0/1).
    pub step: [f32; 4],
    /// Full image width, height; this tile's x0, y0.
    pub image: [u32; 4],
    /// Occupancy grid dims, block edge in voxels.
    pub grid: [u32; 4],
    /// [`RenderMode::code`], then the map `u = norm · y + z` of the mode's value: the
    /// grey of the projections (the TF's window → [0, 1]), or value − iso for iso.
    pub mode: [f32; 4],
    /// AO strength, AO on the ambient term only (0/1), AO read offset (voxels of the
    /// smallest spacing), `A_open` ([`AoReference::open_plane`] at that offset).
    pub ao: [f32; 4],
    /// x: how many of `balls` hold every change since the image the target holds
    /// ([`reuse`]): only pixels whose rays meet one are cast. 0: every pixel.
    pub reuse: [u32; 4],
    /// Centre (volume-centred mm) and radius of each ball of `reuse`.
    pub balls: [[f32; 4]; MAX_BALLS],
}

const _: () = assert!(std::mem::size_of::<RaycastParams>() == 64 + 11 * 16 + MAX_BALLS * 16);

/// Everything a frame needs besides the volume and the LUT data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub camera: Camera,
    pub settings: RenderSettings,
    pub width: u32,
    pub height: u32,
}

/// A ball in volume-centred mm (the ray caster's space): where something changed since
/// an image ([`reuse`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ball {
    pub centre: glam::Vec3,
    pub radius: f32,
}

/// Writes `balls` into a frame's uniforms: the ray cast then leaves every pixel whose ray
/// meets none of them as the target holds it. Empty: every pixel is cast.
pub fn set_balls(params: &mut RaycastParams, balls: &[Ball]) {
    debug_assert!(balls.len() <= MAX_BALLS);
    let n = balls.len().min(MAX_BALLS);
    params.reuse = [n as u32, 0, 0, 0];
    params.balls = [[0.0; 4]; MAX_BALLS];
    for (slot, b) in params.balls.iter_mut().zip(&balls[..n]) {
        *slot = [b.centre.x, b.centre.y, b.centre.z, b.radius];
    }
}

/// What a tile's uniforms hold besides its [`Frame`], the texels and the LUT.
#[derive(Debug, Clone, Copy, Default)]
pub struct TileAt<'a> {
    /// Where the tile starts in the frame, in pixels.
    pub origin: (u32, u32),
    /// The gradient volume's scale `M` ([`gradient::GradientVolume::scale`]), 0 when
    /// none is bound (the CPU twin takes six samples either way).
    pub gradient_scale: f32,
    /// Balls holding every change since the image the target holds ([`reuse`]): only
    /// rays meeting one are cast. Empty: every pixel.
    pub changed: &'a [Ball],
}

impl Frame {
    /// The uniforms of a whole frame: every pixel cast, no gradient volume.
    pub fn params(&self, texels: &VolumeTexels, lut: &Lut, x0: u32, y0: u32) -> RaycastParams {
        let at = TileAt {
            origin: (x0, y0),
            ..Default::default()
        };
        self.uniforms(texels, lut, at)
    }

    /// The uniforms of the tile `at` of this frame: the one place they are assembled.
    pub fn uniforms(&self, texels: &VolumeTexels, lut: &Lut, at: TileAt) -> RaycastParams {
        let (x0, y0) = at.origin;
        let extent = texels.extent();
        let half = glam::Vec3::from(extent) * 0.5;
        let radius = half.length();
        let aspect = self.width as f32 / self.height.max(1) as f32;
        let inv = self.camera.view_proj(radius, aspect).inverse();
        let min_spacing = texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
        let dt = self.settings.step_voxels.max(0.01) * min_spacing;
        let entries = VolumeMap::last_entry(lut);
        let diag = 2.0 * radius;
        let s = &self.settings;
        let grid: [usize; 3] = std::array::from_fn(|i| texels.dims[i].div_ceil(BLOCK));
        let ao_offset = s.ao_offset.clamp(0.0, AO_READ_REACH as f32);
        let mut params = RaycastParams {
            inv_view_proj: inv.to_cols_array_2d(),
            box_half: [half.x, half.y, half.z, 0.0],
            background: s.background,
            shading: [
                s.ambient,
                s.specular,
                s.shininess,
                f32::from(u8::from(s.shading == Shading::Phong)),
            ],
            voxel_uvw: [
                1.0 / texels.dims[0] as f32,
                1.0 / texels.dims[1] as f32,
                1.0 / texels.dims[2] as f32,
                min_spacing,
            ],
            // A gradient of 2 % of the LUT's range per voxel counts as a full edge.
            edge: [1.0 / (0.02 * entries), 0.0, 0.0, 0.0],
            step: [
                dt,
                f32::from(u8::from(s.jitter)),
                (diag / dt).ceil() + 2.0,
                f32::from(u8::from(s.empty_space_skipping)),
            ],
            image: [self.width, self.height, x0, y0],
            grid: [grid[0] as u32, grid[1] as u32, grid[2] as u32, BLOCK as u32],
            mode: mode_map(s.mode, texels, lut, s.projection_window),
            ao: [
                s.ao_strength,
                f32::from(u8::from(s.ao_ambient_only)),
                ao_offset,
                s.ao_reference.open_plane(ao_offset * min_spacing),
            ],
            reuse: [0; 4],
            balls: [[0.0; 4]; MAX_BALLS],
        };
        params.box_half[3] = at.gradient_scale;
        set_balls(&mut params, at.changed);
        params
    }
}

/// [`RaycastParams::mode`]: with `value = norm · scale + offset`, projections get
/// `u = (value − lo) / (hi − lo)` over `window` (default: the LUT's), iso `u = value − iso`.
fn mode_map(
    mode: RenderMode,
    texels: &VolumeTexels,
    lut: &Lut,
    window: Option<[f64; 2]>,
) -> [f32; 4] {
    let (scale, offset) = (texels.value_scale, texels.value_offset);
    let (a, b) = match mode {
        RenderMode::Iso(value) => (scale, offset - value.unwrap_or(lut.iso)),
        _ => {
            let [lo, hi] = window.unwrap_or(lut.window);
            let span = (hi - lo).max(f64::MIN_POSITIVE);
            (scale / span, (offset - lo) / span)
        }
    };
    [mode.code() as f32, a as f32, b as f32, 0.0]
}

/// Per-pixel jitter in [0, 1): a PCG hash of the pixel, identical on CPU and GPU.
pub fn jitter(x: u32, y: u32) -> f32 {
    let mut h = x
        .wrapping_mul(1973)
        .wrapping_add(y.wrapping_mul(9277))
        .wrapping_add(26699);
    h = h.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((h >> ((h >> 28).wrapping_add(4))) ^ h).wrapping_mul(277_803_737);
    let r = (word >> 22) ^ word;
    (r >> 8) as f32 / 16_777_216.0
}
