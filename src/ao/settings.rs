//! What a scene file says about ambient occlusion: the method and every method's
//! parameters, with their defaults from the papers. Plain data, no GPU: the renderer,
//! the viewer and the stages all read it.

use super::rays::RaySet;
use glam::Vec3;

/// Samples per LAO ray by default (the CAO paper's M).
pub const DEFAULT_SAMPLES: u32 = 20;

/// Extra anti-aliasing samples for partly clipped voxels (the CAO paper's N; 41 in all).
pub const DEFAULT_MSAA: u32 = 32;

/// Which ambient-occlusion method feeds `A(x)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AoMethod {
    /// `A = 1` everywhere.
    #[default]
    None,
    /// Local Ambient Occlusion, precomputed once per transfer function.
    Lao,
    /// Contextual AO: LAO kept exact under clipping by recomputing only the voxels the
    /// clip shapes affect (Titov et al.).
    Cao,
    /// The same clipping with a full LAO ray cast of every voxel each frame (the CAO
    /// paper's baseline).
    LaoFull,
    /// Positional AO by ray marching (Papaioannou et al. Eq. 8), precomputed per voxel.
    Vao,
    /// The same positional AO evaluated at every ray-cast sample, no precomputation.
    VaoLive,
    /// Ruiz et al.'s CDF reconstruction `t^β` from box min/max/mean.
    Cdf,
    /// Ruiz et al.'s Gaussian CDF from box mean/variance.
    Gauss,
    /// Penner's one-tailed Chebyshev bound (the baseline of Ruiz et al.).
    Penner,
    /// Cone tracing with tangent spheres on an opacity mip pyramid (Dalla Favera & Celes).
    Cone,
}

/// What an AO method is for, the way the viewer groups them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AoGroup {
    /// No ambient occlusion.
    Off,
    /// Exact while clip shapes move (recomputed as they do).
    FollowsCuts,
    /// Precomputed once per transfer function; clip shapes do not change it.
    Precomputed,
    /// Cheap approximations, precomputed in milliseconds; they ignore cuts too.
    Approximate,
}

impl AoGroup {
    /// Every group, in the order the viewer lists them.
    pub const ALL: [AoGroup; 4] = [
        AoGroup::Off,
        AoGroup::FollowsCuts,
        AoGroup::Precomputed,
        AoGroup::Approximate,
    ];

    /// A heading for the group ("Exact while you cut").
    pub fn title(self) -> &'static str {
        match self {
            AoGroup::Off => "Off",
            AoGroup::FollowsCuts => "Exact while you cut",
            AoGroup::Precomputed => "Precomputed (ignore cuts)",
            AoGroup::Approximate => "Fast approximations (ignore cuts)",
        }
    }
}

impl AoMethod {
    /// Every method, in the order the viewer lists them (grouped by [`AoGroup`]).
    pub const ALL: [AoMethod; 10] = [
        AoMethod::None,
        AoMethod::Cao,
        AoMethod::VaoLive,
        AoMethod::LaoFull,
        AoMethod::Lao,
        AoMethod::Vao,
        AoMethod::Cdf,
        AoMethod::Gauss,
        AoMethod::Penner,
        AoMethod::Cone,
    ];

    /// The code scene files and the CLI use (`--ao cao`).
    pub fn code(self) -> &'static str {
        match self {
            AoMethod::None => "none",
            AoMethod::Lao => "lao",
            AoMethod::Cao => "cao",
            AoMethod::LaoFull => "lao-full",
            AoMethod::Vao => "vao",
            AoMethod::VaoLive => "vao-live",
            AoMethod::Cdf => "cdf",
            AoMethod::Gauss => "gauss",
            AoMethod::Penner => "penner",
            AoMethod::Cone => "cone",
        }
    }

    /// The method's name for people ("Contextual AO").
    pub fn label(self) -> &'static str {
        match self {
            AoMethod::None => "No AO",
            AoMethod::Cao => "Contextual AO",
            AoMethod::VaoLive => "Positional AO (live)",
            AoMethod::LaoFull => "Local AO, recomputed every frame",
            AoMethod::Lao => "Local AO",
            AoMethod::Vao => "Positional AO",
            AoMethod::Cdf => "Ambient map (CDF)",
            AoMethod::Gauss => "Ambient map (Gaussian)",
            AoMethod::Penner => "Ambient map (Chebyshev bound)",
            AoMethod::Cone => "Cone-traced AO",
        }
    }

    /// One line on what the method does for the user.
    pub fn summary(self) -> &'static str {
        match self {
            AoMethod::None => "Flat ambient light: no occlusion, the fastest",
            AoMethod::Cao => "Exact while you cut; recomputes only near the cut",
            AoMethod::VaoLive => {
                "Exact while you cut or edit the transfer function; costly every frame"
            }
            AoMethod::LaoFull => "Exact while you cut; recomputes every voxel (CAO's baseline)",
            AoMethod::Lao => "Precomputed, ignores cuts",
            AoMethod::Vao => "Precomputed with longer reach, ignores cuts",
            AoMethod::Cdf => "Fast approximation from box statistics, ignores cuts",
            AoMethod::Gauss => "Fast approximation from box mean and variance, ignores cuts",
            AoMethod::Penner => "Fast, darker approximation from a variance bound, ignores cuts",
            AoMethod::Cone => "Fast approximation by cone tracing, ignores cuts",
        }
    }

    /// A few sentences for a tooltip: how the method works, its cost, its source.
    pub fn details(self) -> &'static str {
        match self {
            AoMethod::None => "Every sample gets the same ambient light (A = 1).",
            AoMethod::Cao => {
                "Local AO kept exact under clipping: when a clip shape moves, only the voxels                  within the ray reach of its surface are recomputed, from a precomputed                  partial AO (V_PAO). Titov et al., Contextual Ambient Occlusion."
            }
            AoMethod::VaoLive => {
                "Positional AO (Papaioannou et al. Eq. 8) evaluated at every ray-cast sample:                  nothing is precomputed, so it follows clip shapes and the transfer function                  at once, at a cost in every frame."
            }
            AoMethod::LaoFull => {
                "The same exact AO under clipping as Contextual AO, by casting Local AO's rays                  from every voxel each frame: the reference CAO is compared with, slow."
            }
            AoMethod::Lao => {
                "K rays of M samples (1 mm apart) from every voxel, accumulating opacity;                  computed once per transfer function. Clip shapes cut the picture but not                  the occlusion."
            }
            AoMethod::Vao => {
                "Positional AO by ray marching (Papaioannou et al. Eq. 8): rays over the whole                  sphere with a longer reach, computed once per transfer function."
            }
            AoMethod::Cdf => {
                "Ambient occlusion from the min/max/mean of a box around each voxel, through                  a reconstructed CDF t^β (Ruiz et al.); computed in milliseconds."
            }
            AoMethod::Gauss => {
                "Ambient occlusion from the mean and variance of a box around each voxel,                  through a Gaussian CDF (Ruiz et al.); computed in milliseconds."
            }
            AoMethod::Penner => {
                "Penner's one-tailed Chebyshev bound on the box statistics (the baseline of                  Ruiz et al.); computed in milliseconds."
            }
            AoMethod::Cone => {
                "Cones with tangent spheres traced through an opacity mip pyramid (Dalla                  Favera & Celes)."
            }
        }
    }

    /// What the method is for.
    pub fn group(self) -> AoGroup {
        match self {
            AoMethod::None => AoGroup::Off,
            AoMethod::Cao | AoMethod::VaoLive | AoMethod::LaoFull => AoGroup::FollowsCuts,
            AoMethod::Lao | AoMethod::Vao => AoGroup::Precomputed,
            AoMethod::Cdf | AoMethod::Gauss | AoMethod::Penner | AoMethod::Cone => {
                AoGroup::Approximate
            }
        }
    }

    /// CAO and its baseline: AO that follows the clip shapes (they need the GPU).
    pub fn is_clipped(self) -> bool {
        matches!(self, AoMethod::Cao | AoMethod::LaoFull)
    }

    pub fn parse(s: &str) -> Result<AoMethod, String> {
        AoMethod::ALL
            .into_iter()
            .find(|m| m.code() == s)
            .ok_or_else(|| {
                let codes: Vec<&str> = AoMethod::ALL.iter().map(|m| m.code()).collect();
                format!("unknown AO method {s:?} (available: {})", codes.join(", "))
            })
    }
}

/// AO method and parameters, as saved in scene files.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AoSettings {
    pub method: AoMethod,
    /// Ray pattern (K rays): "6", "14", "26", "54" or "fib:N".
    #[serde(with = "ray_set_name")]
    pub rays: RaySet,
    /// Samples per ray (M), 1 mm apart; also the reach of the cones (M mm).
    pub samples: u32,
    /// CAO: extra anti-aliasing samples for partly clipped voxels (N; 9 + N in all).
    pub msaa: u32,
    /// CAO: size of each clip shape's depth and dilation maps (pixels, square).
    pub clip_resolution: u32,
    /// Parameters of positional AO (`vao`, `vao-live`).
    pub vao: VaoSettings,
    /// Filter maps: box radius r (side 2r + 1).
    pub radius: f32,
    pub radius_unit: RadiusUnit,
    /// Filter maps: statistics of the density or of the TF's opacity.
    pub statistic: StatisticSource,
    /// Cone tracing: number of cones and spheres per cone.
    pub cones: ConeSet,
    pub cone_preset: ConePreset,
}

impl AoSettings {
    /// What this method gives an open flat surface, which the shading normalises by.
    pub fn reference(&self) -> crate::render::AoReference {
        match self.method {
            AoMethod::Lao | AoMethod::Cao | AoMethod::LaoFull => crate::render::AoReference::Rays {
                set: self.rays,
                samples: self.samples,
            },
            _ => crate::render::AoReference::Half,
        }
    }
}

impl Default for AoSettings {
    fn default() -> Self {
        AoSettings {
            method: AoMethod::None,
            rays: RaySet::FiftyFour,
            samples: DEFAULT_SAMPLES,
            radius: 10.0,
            radius_unit: RadiusUnit::Voxels,
            statistic: StatisticSource::Density,
            cones: ConeSet::Six,
            cone_preset: ConePreset::Medium,
            msaa: DEFAULT_MSAA,
            clip_resolution: crate::clip::gpu_data::DEFAULT_RESOLUTION,
            vao: VaoSettings::default(),
        }
    }
}

/// Ray sets are written by name in scene files ("54", "fib:512").
mod ray_set_name {
    use super::RaySet;

    pub fn serialize<S: serde::Serializer>(set: &RaySet, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&set.name())
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<RaySet, D::Error> {
        let name: String = serde::Deserialize::deserialize(d)?;
        RaySet::parse(&name).map_err(serde::de::Error::custom)
    }
}

/// Rays per point by default (the paper's Fig. 7c uses 20).
pub const DEFAULT_DIRECTIONS: u32 = 20;
/// Positional AO: samples per ray by default (the paper uses 8–12, 8 for its figures).
pub const DEFAULT_VAO_SAMPLES: u32 = 8;
/// Ray length by default: the same 20 mm radius as LAO's 20 samples 1 mm apart.
pub const DEFAULT_R_MAX_MM: f32 = 20.0;
/// Opacity at which a ray stops by default.
pub const DEFAULT_V_THRES: f32 = 0.95;
/// A ray whose obscurance γ is within this of 1 stops (nothing further can matter).
pub const GAMMA_STOP: f32 = 1.0 / 256.0;
/// Most directions accepted (the live mode runs all of them at every ray-cast sample).
pub const MAX_DIRECTIONS: u32 = 4096;

/// The isosurface variant (§5.2.1): a ray is fully occluded when a sample beyond the
/// guard distance `v_s·√3/2` lies within `tolerance` of `value` (data units).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Isosurface {
    pub value: f64,
    pub tolerance: f64,
}

/// Parameters of positional AO, as saved in scene files (`ambient_occlusion.vao`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VaoSettings {
    /// N_dir: rays over the whole sphere (Fibonacci lattice).
    pub directions: u32,
    /// N_samples: stratified samples per ray.
    pub samples: u32,
    /// r_max: ray length in mm.
    pub r_max_mm: f32,
    /// V_thres: an accepted sample this opaque stops the ray.
    pub v_thres: f32,
    /// Use the isosurface variant instead of Beer's law.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub isosurface: Option<Isosurface>,
}

impl Default for VaoSettings {
    fn default() -> Self {
        VaoSettings {
            directions: DEFAULT_DIRECTIONS,
            samples: DEFAULT_VAO_SAMPLES,
            r_max_mm: DEFAULT_R_MAX_MM,
            v_thres: DEFAULT_V_THRES,
            isosurface: None,
        }
    }
}

/// Why positional-AO settings were refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum VaoError {
    #[error("positional AO: {what} is {value}; {need}")]
    Setting {
        what: &'static str,
        value: String,
        need: &'static str,
    },
}

impl VaoSettings {
    /// Checks every field, naming the first bad one.
    pub fn validate(&self) -> Result<(), VaoError> {
        let bad = |what, value: String, need| Err(VaoError::Setting { what, value, need });
        if self.directions == 0 || self.directions > MAX_DIRECTIONS {
            return bad(
                "the number of directions",
                self.directions.to_string(),
                "use 1 to 4096",
            );
        }
        if self.samples == 0 || self.samples > 1024 {
            return bad(
                "the number of samples per ray",
                self.samples.to_string(),
                "use 1 to 1024",
            );
        }
        if !(self.r_max_mm.is_finite() && self.r_max_mm > 0.0) {
            return bad(
                "r_max",
                self.r_max_mm.to_string(),
                "it must be a positive length in mm",
            );
        }
        if !(self.v_thres > 0.0 && self.v_thres <= 1.0) {
            return bad("V_thres", self.v_thres.to_string(), "it must be in (0, 1]");
        }
        if let Some(iso) = self.isosurface
            && !(iso.value.is_finite() && iso.tolerance.is_finite() && iso.tolerance > 0.0)
        {
            return bad(
                "the isosurface",
                format!("{} ± {}", iso.value, iso.tolerance),
                "value and a positive tolerance must be finite numbers",
            );
        }
        Ok(())
    }
}

/// What the box statistics are taken of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StatisticSource {
    /// The texel value mapped linearly onto [0, 1] over the volume's range (the paper).
    #[default]
    Density,
    /// The transfer function's opacity (for one voxel of path length).
    Opacity,
}

impl StatisticSource {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "density" => Ok(Self::Density),
            "opacity" => Ok(Self::Opacity),
            o => Err(format!(
                "unknown statistic source {o:?} (available: density, opacity)"
            )),
        }
    }
}

/// Unit of the box radius in settings and on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RadiusUnit {
    #[default]
    Voxels,
    Mm,
}

/// Opacity modulation by local variance (Ruiz et al. §4.2): each sample's opacity is
/// multiplied by `min(σ²/σ²_max, 1)`, so homogeneous regions fade and boundaries stay.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OpacityModulation {
    /// `σ²_max`, in units of the source value squared (density normalised to [0, 1]).
    pub sigma2_max: f32,
    /// Box radius in voxels.
    pub radius: f32,
    pub source: StatisticSource,
}

impl Default for OpacityModulation {
    fn default() -> Self {
        OpacityModulation {
            // About the paper's σ²_max = 5 on 0…255 data is 8e-5; CT's wider range makes
            // a larger default read better.
            sigma2_max: 1e-3,
            radius: 10.0,
            source: StatisticSource::Density,
        }
    }
}

/// Spheres per cone: low / medium / high = 3 / 5 / 7 (the paper's quality presets).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ConePreset {
    Low,
    #[default]
    Medium,
    High,
}

impl ConePreset {
    pub fn spheres(self) -> u32 {
        match self {
            ConePreset::Low => 3,
            ConePreset::Medium => 5,
            ConePreset::High => 7,
        }
    }

    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "low" => Ok(Self::Low),
            "medium" => Ok(Self::Medium),
            "high" => Ok(Self::High),
            o => Err(format!(
                "unknown cone preset {o:?} (available: low, medium, high)"
            )),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ConePreset::Low => "low",
            ConePreset::Medium => "medium",
            ConePreset::High => "high",
        }
    }
}

/// Cone axes over the whole sphere: 6 (faces), 14 (+ corners), 26 (+ edges).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ConeSet {
    #[default]
    #[serde(rename = "6")]
    Six,
    #[serde(rename = "14")]
    Fourteen,
    #[serde(rename = "26")]
    TwentySix,
}

impl ConeSet {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "6" => Ok(Self::Six),
            "14" => Ok(Self::Fourteen),
            "26" => Ok(Self::TwentySix),
            o => Err(format!("unknown cone count {o:?} (available: 6, 14, 26)")),
        }
    }

    pub fn directions(self) -> Vec<Vec3> {
        use super::rays::RaySet;
        match self {
            ConeSet::Six => RaySet::Six,
            ConeSet::Fourteen => RaySet::Fourteen,
            ConeSet::TwentySix => RaySet::TwentySix,
        }
        .directions()
    }

    pub fn count(self) -> usize {
        match self {
            ConeSet::Six => 6,
            ConeSet::Fourteen => 14,
            ConeSet::TwentySix => 26,
        }
    }
}
