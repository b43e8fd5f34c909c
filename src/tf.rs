//! Transfer functions: data value → colour and opacity, in the data's own units.
//!
//! A [`TransferFunction`] holds two piecewise-linear lists over the physical value
//! (Hounsfield units for CT, scanner units for MR): opacity points and colour stops.
//! [`Preset`]s give the starting points a radiologist expects; the CT presets are in
//! absolute HU, the MR and the CAO paper's single-colour preset are placed relative to
//! the volume's value range and resolved to data units when they are built.
//!
//! For the GPU a function is baked into a [`Lut`] of [`LUT_ENTRIES`] straight-RGBA
//! entries over the volume's value range; [`Lut::sample`] is the CPU twin of the
//! shader's filtered fetch and [`Lut::is_transparent_over`] the empty-space test.
//! Opacities are per unit step (one voxel); [`correct_opacity`] rescales them to the
//! ray caster's step.

use crate::volume::Stats;

/// Entries in a baked [`Lut`] (≥ 1024 required).
///
/// 4096 is the 12-bit range CT scanners store (−1024…3071 HU), so a LUT over a typical
/// CT volume has exactly one entry per HU and every integer-HU control point lands on an
/// entry. As `Rgba32Float` it is 64 KiB, inside wgpu's default `max_texture_dimension_1d`
/// (8192).
pub const LUT_ENTRIES: usize = 4096;

/// One opacity control point: data value (physical units) → opacity in [0, 1].
///
/// The opacity is per unit step (one voxel); see [`correct_opacity`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OpacityPoint {
    pub value: f64,
    pub alpha: f32,
}

/// One colour stop: data value → linear RGB in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColorStop {
    pub value: f64,
    pub rgb: [f32; 3],
}

/// A 1-D transfer function: piecewise-linear opacity and colour over the data's units.
///
/// Both lists are sorted by value; two points with the same value make a step (the
/// function takes the later point's value from there on). Outside a list's range the
/// end points hold. A function read from a file must pass [`TransferFunction::validate`]
/// before use.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TransferFunction {
    pub name: String,
    pub opacity: Vec<OpacityPoint>,
    pub color: Vec<ColorStop>,
}

/// Built-in transfer functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// CT bone: transparent below +150 HU, opaque ivory from about +400 HU.
    CtBone,
    /// CT soft tissue: faint fat, semi-transparent red skin and muscle, ivory bone.
    CtSoftTissue,
    /// CT angiography: contrast-filled vessels (+150…+400 HU) red, bone white.
    CtVessels,
    /// MR T1 brain, relative to the volume's range: grey to warm over the upper intensities.
    MrT1Brain,
    /// The CAO paper's evaluation look (Titov et al. §4): one colour, an opacity ramp.
    CaoSingleColor,
}

/// Everything that can make a transfer function or a preset name unusable.
#[derive(Debug, thiserror::Error)]
pub enum TfError {
    #[error("transfer function \"{tf}\": the {list} list is empty; give at least one point")]
    Empty { tf: String, list: &'static str },
    #[error(
        "transfer function \"{tf}\": {list} point {index} has value {value}, not a finite number"
    )]
    NonFinite {
        tf: String,
        list: &'static str,
        index: usize,
        value: f64,
    },
    #[error(
        "transfer function \"{tf}\": {list} point {index} at {value} comes after a point at {previous}; sort the points by value (equal values make a step)"
    )]
    Unsorted {
        tf: String,
        list: &'static str,
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error("transfer function \"{tf}\": opacity point {index} has alpha {alpha}, outside [0, 1]")]
    AlphaOutOfRange {
        tf: String,
        index: usize,
        alpha: f32,
    },
    #[error(
        "transfer function \"{tf}\": colour stop {index} has rgb {rgb:?}, outside [0, 1] (colours are linear RGB in [0, 1], not 0–255)"
    )]
    RgbOutOfRange {
        tf: String,
        index: usize,
        rgb: [f32; 3],
    },
    #[error("unknown transfer-function preset \"{name}\"; valid presets are {valid}", valid = preset_names())]
    UnknownPreset { name: String },
}

/// Where a preset's point values live.
#[derive(Clone, Copy)]
enum Units {
    /// Absolute data units (HU).
    Absolute,
    /// Fractions of the volume's value range [`Stats::min`, `Stats::max`].
    Relative,
}

/// A preset's points before resolving: (value, alpha) and (value, rgb).
struct PresetPoints {
    units: Units,
    opacity: &'static [(f64, f32)],
    color: &'static [(f64, [f32; 3])],
}

/// Bone: nothing below +150 HU (soft tissue, contrast-free blood), a brownish rim at the
/// transition, ivory and nearly opaque from +400…+500 HU (cortical bone ≈ +700…+1900).
const CT_BONE: PresetPoints = PresetPoints {
    units: Units::Absolute,
    opacity: &[(150.0, 0.0), (300.0, 0.45), (500.0, 0.8), (1500.0, 0.9)],
    color: &[
        (150.0, [0.60, 0.30, 0.20]),
        (300.0, [0.90, 0.80, 0.62]),
        (1500.0, [1.0, 0.98, 0.94]),
    ],
};

/// Soft tissue: fat (−100…−50 HU) faint yellow, skin and muscle (+20…+80 HU)
/// semi-transparent red, bone ivory and nearly opaque.
const CT_SOFT_TISSUE: PresetPoints = PresetPoints {
    units: Units::Absolute,
    opacity: &[
        (-200.0, 0.0),
        (-60.0, 0.04),
        (20.0, 0.10),
        (80.0, 0.20),
        (250.0, 0.45),
        (700.0, 0.85),
        (1500.0, 0.9),
    ],
    color: &[
        (-200.0, [0.80, 0.55, 0.40]),
        (-60.0, [0.90, 0.72, 0.45]),
        (20.0, [0.75, 0.30, 0.25]),
        (80.0, [0.80, 0.25, 0.20]),
        (250.0, [0.92, 0.78, 0.62]),
        (700.0, [0.98, 0.95, 0.88]),
        (1500.0, [1.0, 1.0, 1.0]),
    ],
};

/// Vessels (CT angiography): unenhanced tissue (< +100 HU) hidden, contrast
/// (+150…+400 HU) red, bone (> +600 HU) white.
const CT_VESSELS: PresetPoints = PresetPoints {
    units: Units::Absolute,
    opacity: &[
        (100.0, 0.0),
        (150.0, 0.3),
        (300.0, 0.6),
        (600.0, 0.85),
        (1500.0, 0.9),
    ],
    color: &[
        (100.0, [0.45, 0.0, 0.02]),
        (150.0, [0.70, 0.05, 0.05]),
        (400.0, [0.85, 0.15, 0.10]),
        (600.0, [1.0, 0.95, 0.90]),
        (1500.0, [1.0, 1.0, 1.0]),
    ],
};

/// MR T1 brain, as fractions of the value range: background and CSF hidden, a grey to
/// warm ramp over grey matter, white matter and the bright scalp fat.
const MR_T1_BRAIN: PresetPoints = PresetPoints {
    units: Units::Relative,
    opacity: &[
        (0.10, 0.0),
        (0.25, 0.05),
        (0.45, 0.25),
        (0.70, 0.50),
        (1.0, 0.60),
    ],
    color: &[
        (0.10, [0.20, 0.20, 0.20]),
        (0.25, [0.50, 0.50, 0.50]),
        (0.45, [0.80, 0.72, 0.62]),
        (0.70, [0.95, 0.80, 0.60]),
        (1.0, [1.0, 0.92, 0.80]),
    ],
};

/// The CAO paper's evaluation transfer function. Titov et al. §4: "We used a
/// single-color transfer function for each volume to better highlight the effect of LAO
/// rendering on the dataset." The paper gives neither the colour nor the opacity curve,
/// so: one light neutral grey (AO darkening reads best on it) and a linear opacity ramp
/// from 0 at 15 % of the value range (the ImageVis3D Engine, Beetle and Skeleton
/// volumes keep their background below that) to 1 at the maximum.
const CAO_SINGLE_COLOR: PresetPoints = PresetPoints {
    units: Units::Relative,
    opacity: &[(0.15, 0.0), (1.0, 1.0)],
    color: &[(0.15, [0.9, 0.9, 0.9])],
};

impl Preset {
    pub const ALL: [Preset; 5] = [
        Preset::CtBone,
        Preset::CtSoftTissue,
        Preset::CtVessels,
        Preset::MrT1Brain,
        Preset::CaoSingleColor,
    ];

    /// The name used on the command line and in scene files (same as serde's).
    pub fn name(self) -> &'static str {
        match self {
            Preset::CtBone => "ct-bone",
            Preset::CtSoftTissue => "ct-soft-tissue",
            Preset::CtVessels => "ct-vessels",
            Preset::MrT1Brain => "mr-t1-brain",
            Preset::CaoSingleColor => "cao-single-color",
        }
    }

    /// Looks a preset up by [`Preset::name`] (ASCII case ignored).
    pub fn from_name(s: &str) -> Result<Preset, TfError> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| TfError::UnknownPreset { name: s.to_owned() })
    }

    /// A sensible first look for a volume: CT-looking ranges (min ≤ −500 and max ≥ 500,
    /// i.e. air and bone in HU) get [`Preset::CtBone`], everything else the relative
    /// [`Preset::MrT1Brain`].
    pub fn default_for(stats: &Stats) -> Preset {
        if stats.min <= -500.0 && stats.max >= 500.0 {
            Preset::CtBone
        } else {
            Preset::MrT1Brain
        }
    }

    fn points(self) -> &'static PresetPoints {
        match self {
            Preset::CtBone => &CT_BONE,
            Preset::CtSoftTissue => &CT_SOFT_TISSUE,
            Preset::CtVessels => &CT_VESSELS,
            Preset::MrT1Brain => &MR_T1_BRAIN,
            Preset::CaoSingleColor => &CAO_SINGLE_COLOR,
        }
    }
}

impl std::fmt::Display for Preset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Preset {
    type Err = TfError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::from_name(s)
    }
}

fn preset_names() -> String {
    Preset::ALL.map(Preset::name).join(", ")
}

/// A usable, non-empty range from `[min, max]`: swapped if reversed, widened around the
/// value if empty (a constant volume), `[0, 1]` if not finite.
fn usable_range(min: f64, max: f64) -> (f64, f64) {
    if !(min.is_finite() && max.is_finite()) {
        return (0.0, 1.0);
    }
    let (lo, hi) = (min.min(max), min.max(max));
    if hi > lo {
        (lo, hi)
    } else {
        let d = 0.5f64.max(lo.abs() * 1e-9);
        (lo - d, lo + d)
    }
}

/// Linear interpolation in f64, exact at `t == 0`.
fn lerp(a: f32, b: f32, t: f64) -> f32 {
    (f64::from(a) + (f64::from(b) - f64::from(a)) * t) as f32
}

/// The segment of a sorted list around `value`: (index of left point, index of right
/// point, t in [0, 1)). Right-continuous at steps; clamps outside; `None` if empty.
fn segment(values: impl Fn(usize) -> f64, len: usize, value: f64) -> Option<(usize, usize, f64)> {
    if len == 0 {
        return None;
    }
    // First point strictly right of `value` (binary search; the list is sorted).
    let (mut lo, mut hi) = (0, len);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if values(mid) <= value {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    Some(match lo {
        0 => (0, 0, 0.0),
        i if i == len => (len - 1, len - 1, 0.0),
        i => {
            let (a, b) = (values(i - 1), values(i));
            (i - 1, i, (value - a) / (b - a))
        }
    })
}

impl TransferFunction {
    /// Builds a preset in the data units of a volume with these statistics.
    ///
    /// CT presets are absolute (HU) and ignore `stats`. MR and the single-colour preset
    /// are fractions of `[stats.min, stats.max]`, resolved here so the result is always
    /// in data units (a constant volume gets a small range starting at its value).
    pub fn preset(p: Preset, stats: &Stats) -> TransferFunction {
        let points = p.points();
        // A constant volume (all empty, say) sits at the bottom of the ramp: it must
        // render as nothing, not as a haze filling the box.
        let (lo, hi) = if stats.max > stats.min {
            usable_range(stats.min, stats.max)
        } else {
            let (lo, hi) = usable_range(stats.min, stats.max);
            (stats.min, stats.min + (hi - lo))
        };
        let place = |x: f64| match points.units {
            Units::Absolute => x,
            Units::Relative => lo + (hi - lo) * x,
        };
        TransferFunction {
            name: p.name().to_owned(),
            opacity: points
                .opacity
                .iter()
                .map(|&(v, alpha)| OpacityPoint {
                    value: place(v),
                    alpha,
                })
                .collect(),
            color: points
                .color
                .iter()
                .map(|&(v, rgb)| ColorStop {
                    value: place(v),
                    rgb,
                })
                .collect(),
        }
    }

    /// Checks that both lists are non-empty, finite and sorted by value (ties allowed
    /// for steps), alphas are in [0, 1] and colours in [0, 1].
    pub fn validate(&self) -> Result<(), TfError> {
        check_values(&self.name, "opacity", self.opacity.iter().map(|p| p.value))?;
        check_values(&self.name, "colour", self.color.iter().map(|c| c.value))?;
        if let Some((index, p)) = self
            .opacity
            .iter()
            .enumerate()
            .find(|(_, p)| !(0.0..=1.0).contains(&p.alpha))
        {
            return Err(TfError::AlphaOutOfRange {
                tf: self.name.clone(),
                index,
                alpha: p.alpha,
            });
        }
        if let Some((index, c)) = self
            .color
            .iter()
            .enumerate()
            .find(|(_, c)| !c.rgb.iter().all(|x| (0.0..=1.0).contains(x)))
        {
            return Err(TfError::RgbOutOfRange {
                tf: self.name.clone(),
                index,
                rgb: c.rgb,
            });
        }
        Ok(())
    }

    /// Piecewise-linear evaluation, clamped to the end points outside their range.
    /// Returns straight RGBA. At a step (equal values) the later point wins. NaN (an
    /// empty voxel) and empty lists give 0.
    pub fn eval(&self, value: f64) -> [f32; 4] {
        if value.is_nan() {
            return [0.0; 4];
        }
        let alpha = segment(|i| self.opacity[i].value, self.opacity.len(), value)
            .map_or(0.0, |(i, j, t)| {
                lerp(self.opacity[i].alpha, self.opacity[j].alpha, t)
            });
        let rgb = segment(|i| self.color[i].value, self.color.len(), value).map_or(
            [0.0; 3],
            |(i, j, t)| {
                let (a, b) = (self.color[i].rgb, self.color[j].rgb);
                std::array::from_fn(|c| lerp(a[c], b[c], t))
            },
        );
        [rgb[0], rgb[1], rgb[2], alpha]
    }

    /// The smallest closed value range outside which opacity is 0, or `None` if the
    /// function is fully transparent. An end is infinite when the first/last opacity
    /// point is visible (evaluation clamps). Used for empty-space skipping and for
    /// choosing the LUT range (intersect it with the volume's range).
    pub fn visible_range(&self) -> Option<(f64, f64)> {
        let pts = &self.opacity;
        let first = pts.iter().position(|p| p.alpha > 0.0)?;
        let last = pts.iter().rposition(|p| p.alpha > 0.0)?;
        let lo = if first == 0 {
            f64::NEG_INFINITY
        } else {
            pts[first - 1].value
        };
        let hi = if last + 1 == pts.len() {
            f64::INFINITY
        } else {
            pts[last + 1].value
        };
        Some((lo, hi))
    }

    /// Bakes `entries` samples over `[min, max]` (the caller passes the volume's value
    /// range): entry `i` is [`TransferFunction::eval`] at [`Lut::entry_value`]`(i)`.
    /// At least 2 entries are made; an empty or non-finite range is made usable as
    /// for relative presets (widened around a constant value, `[0, 1]` if not finite).
    pub fn bake(&self, min: f64, max: f64, entries: usize) -> Lut {
        let (min, max) = usable_range(min, max);
        let len = entries.max(2);
        Lut {
            min,
            max,
            rgba: (0..len)
                .map(|i| self.eval(entry_value(min, max, len, i)))
                .collect(),
        }
    }

    /// Window/level: a copy whose points are linearly remapped so the span of its points
    /// (first to last value over both lists) becomes `[level − window/2, level + window/2]`.
    ///
    /// `window` must be > 0; a window ≤ 0 is taken as 0, which collapses the function
    /// into a step at `level`. A function whose points all share one value is moved to
    /// `level`. A non-finite window or level, or a function without points, returns an
    /// unchanged copy.
    pub fn with_window_level(&self, window: f64, level: f64) -> TransferFunction {
        let Some((lo, hi)) = self.span() else {
            return self.clone();
        };
        if !(window.is_finite() && level.is_finite()) {
            return self.clone();
        }
        let window = window.max(0.0);
        let start = level - window / 2.0;
        let span = hi - lo;
        let remap = |v: f64| {
            if span > 0.0 {
                start + (v - lo) / span * window
            } else {
                level
            }
        };
        TransferFunction {
            name: self.name.clone(),
            opacity: self
                .opacity
                .iter()
                .map(|p| OpacityPoint {
                    value: remap(p.value),
                    ..*p
                })
                .collect(),
            color: self
                .color
                .iter()
                .map(|c| ColorStop {
                    value: remap(c.value),
                    ..*c
                })
                .collect(),
        }
    }

    /// The current (window, level) of the point span: (last − first, (first + last) / 2)
    /// over both lists; (0, 0) for a function without points.
    pub fn window_level(&self) -> (f64, f64) {
        match self.span() {
            Some((lo, hi)) => (hi - lo, lo + (hi - lo) / 2.0),
            None => (0.0, 0.0),
        }
    }

    /// Smallest and largest point value over both lists (NaN ignored).
    fn span(&self) -> Option<(f64, f64)> {
        let values = self
            .opacity
            .iter()
            .map(|p| p.value)
            .chain(self.color.iter().map(|c| c.value))
            .filter(|v| !v.is_nan());
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        (lo <= hi).then_some((lo, hi))
    }
}

/// Non-empty, finite, sorted (ties allowed).
fn check_values(
    tf: &str,
    list: &'static str,
    values: impl Iterator<Item = f64>,
) -> Result<(), TfError> {
    let mut previous: Option<f64> = None;
    for (index, value) in values.enumerate() {
        if !value.is_finite() {
            return Err(TfError::NonFinite {
                tf: tf.to_owned(),
                list,
                index,
                value,
            });
        }
        if let Some(previous) = previous
            && value < previous
        {
            return Err(TfError::Unsorted {
                tf: tf.to_owned(),
                list,
                index,
                value,
                previous,
            });
        }
        previous = Some(value);
    }
    match previous {
        Some(_) => Ok(()),
        None => Err(TfError::Empty {
            tf: tf.to_owned(),
            list,
        }),
    }
}

/// A transfer function baked for the GPU: entry `i` holds the function at
/// `min + (max − min) · i / (len − 1)`, as straight (not premultiplied) RGBA.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut {
    pub min: f64,
    pub max: f64,
    pub rgba: Vec<[f32; 4]>,
}

/// Data value of entry `i` of a `len`-entry table over `[min, max]`. Multiplying
/// before dividing keeps integer-spaced tables (one HU per entry) exact.
fn entry_value(min: f64, max: f64, len: usize, i: usize) -> f64 {
    if len < 2 {
        return min;
    }
    min + (max - min) * i as f64 / (len - 1) as f64
}

impl Lut {
    /// Data value that entry `i` holds: `min + (max − min) · i / (len − 1)`.
    pub fn entry_value(&self, i: usize) -> f64 {
        entry_value(self.min, self.max, self.rgba.len(), i)
    }

    /// Continuous entry coordinate `t = (value − min) · (len − 1) / (max − min)`,
    /// clamped to `[0, len − 1]`. Needs `len ≥ 2` and a non-NaN value.
    fn coord(&self, value: f64) -> f64 {
        let last = (self.rgba.len() - 1) as f64;
        let span = self.max - self.min;
        let t = if span > 0.0 {
            (value - self.min) * last / span
        } else {
            0.0
        };
        t.clamp(0.0, last)
    }

    /// Linear interpolation between entries, as a GPU's linear filter on a 1-D texture
    /// with clamp-to-edge does.
    ///
    /// The mapping, which the shader must use too:
    /// `t = clamp((value − min) · (len − 1) / (max − min), 0, len − 1)`,
    /// `i = min(floor(t), len − 2)`, `f = t − i`,
    /// result `= rgba[i] · (1 − f) + rgba[i + 1] · f`.
    /// With hardware filtering this is texture coordinate `u = (t + 0.5) / len` (texel
    /// `i` sits at `u = (i + 0.5) / len`), up to the filter's weight precision; an
    /// `Rgba32Float` table is not filterable without `FLOAT32_FILTERABLE`, so there the
    /// shader does this lerp itself with two `textureLoad`s. NaN gives 0.
    pub fn sample(&self, value: f64) -> [f32; 4] {
        match self.rgba.len() {
            _ if value.is_nan() => [0.0; 4],
            0 => [0.0; 4],
            1 => self.rgba[0],
            len => {
                let t = self.coord(value);
                let i = (t.floor() as usize).min(len - 2);
                let f = (t - i as f64) as f32;
                let (a, b) = (self.rgba[i], self.rgba[i + 1]);
                std::array::from_fn(|c| a[c] * (1.0 - f) + b[c] * f)
            }
        }
    }

    /// True if every entry that [`Lut::sample`] can touch for a value in `[lo, hi]`
    /// (data units, either order) has alpha exactly 0 — the conservative test for
    /// empty-space skipping.
    ///
    /// It covers entries `floor(t(lo)) − 1 ..= floor(t(hi)) + 2` (clamped): the two
    /// neighbours linear interpolation reads plus one more on each side for the
    /// shader's f32 rounding of `t`. It speaks for the table, i.e. what is rendered: a
    /// function feature narrower than one entry is lost when baking, not here. NaN
    /// bounds answer false.
    pub fn is_transparent_over(&self, lo: f64, hi: f64) -> bool {
        if lo.is_nan() || hi.is_nan() {
            return false;
        }
        let len = self.rgba.len();
        if len < 2 {
            return self.rgba.iter().all(|e| e[3] == 0.0);
        }
        let (lo, hi) = (lo.min(hi), lo.max(hi));
        let first = (self.coord(lo).floor() as usize).saturating_sub(1);
        let last = (self.coord(hi).floor() as usize + 2).min(len - 1);
        self.rgba[first..=last].iter().all(|e| e[3] == 0.0)
    }
}

/// Opacity correction for a step of `step` voxels when opacities are defined per one
/// voxel: α' = 1 − (1 − α)^step — the standard correction (Engel et al., *Real-Time
/// Volume Graphics*, 2006; Eq. 6, Appendix A.1 of Imagire et al., with step = Δd/Δd₀).
///
/// Computed as `−expm1(step · ln_1p(−α))` in f64 so small opacities keep their digits
/// and `step == 1` returns `alpha` unchanged; the shader's `1 − pow(1 − α, step)` in
/// f32 agrees to f32 rounding. `alpha` is clamped to [0, 1] (NaN → 0); a step ≤ 0
/// (or NaN) gives 0, an infinite step 1 for any α > 0.
pub fn correct_opacity(alpha: f32, step: f32) -> f32 {
    let alpha = if alpha.is_nan() {
        0.0
    } else {
        alpha.clamp(0.0, 1.0)
    };
    if step.is_nan() || step <= 0.0 || alpha == 0.0 {
        return 0.0;
    }
    if alpha == 1.0 {
        return 1.0;
    }
    let a = f64::from(alpha);
    (-(f64::from(step) * (-a).ln_1p()).exp_m1()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(min: f64, max: f64) -> Stats {
        Stats {
            min,
            max,
            mean: (min + max) / 2.0,
            non_finite: 0,
            finite: 1000,
        }
    }

    fn ct() -> Stats {
        stats(-1024.0, 3071.0)
    }

    fn mr() -> Stats {
        stats(0.0, 812.0)
    }

    /// SplitMix64: a deterministic source of test values without a rand dependency.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        /// Uniform in [lo, hi).
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn simple() -> TransferFunction {
        TransferFunction {
            name: "test".into(),
            opacity: vec![
                OpacityPoint {
                    value: 0.0,
                    alpha: 0.0,
                },
                OpacityPoint {
                    value: 100.0,
                    alpha: 1.0,
                },
                OpacityPoint {
                    value: 200.0,
                    alpha: 0.5,
                },
            ],
            color: vec![
                ColorStop {
                    value: 0.0,
                    rgb: [0.0, 0.0, 0.0],
                },
                ColorStop {
                    value: 200.0,
                    rgb: [1.0, 0.5, 0.0],
                },
            ],
        }
    }

    fn close(a: [f32; 4], b: [f32; 4], tol: f32) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn eval_hits_points_interpolates_and_clamps() {
        let tf = simple();
        tf.validate().expect("simple TF is valid");
        assert_eq!(tf.eval(0.0), [0.0, 0.0, 0.0, 0.0]);
        assert_eq!(tf.eval(100.0)[3], 1.0);
        assert_eq!(tf.eval(200.0), [1.0, 0.5, 0.0, 0.5]);
        assert!(close(tf.eval(50.0), [0.25, 0.125, 0.0, 0.5], 1e-6));
        assert!(close(tf.eval(150.0), [0.75, 0.375, 0.0, 0.75], 1e-6));
        assert!(close(tf.eval(100.0), [0.5, 0.25, 0.0, 1.0], 1e-6));
        // Linear: the midpoint of any two points inside one segment is their mean.
        for (a, b) in [(10.0, 90.0), (120.0, 190.0)] {
            let (ea, eb, em) = (tf.eval(a), tf.eval(b), tf.eval((a + b) / 2.0));
            let mean: [f32; 4] = std::array::from_fn(|c| (ea[c] + eb[c]) / 2.0);
            assert!(close(em, mean, 1e-6), "{em:?} vs {mean:?}");
        }
        assert_eq!(tf.eval(-1e6), tf.eval(0.0));
        assert_eq!(tf.eval(f64::NEG_INFINITY), tf.eval(0.0));
        assert_eq!(tf.eval(1e6), tf.eval(200.0));
        assert_eq!(tf.eval(f64::NAN), [0.0; 4]);
    }

    #[test]
    fn steps_are_right_continuous() {
        let mut tf = simple();
        tf.opacity = vec![
            OpacityPoint {
                value: 100.0,
                alpha: 0.0,
            },
            OpacityPoint {
                value: 100.0,
                alpha: 0.7,
            },
        ];
        tf.validate().expect("ties are allowed");
        assert_eq!(tf.eval(99.999)[3], 0.0);
        assert_eq!(tf.eval(100.0)[3], 0.7);
        assert_eq!(tf.eval(100.001)[3], 0.7);
        assert_eq!(tf.visible_range(), Some((100.0, f64::INFINITY)));
    }

    #[test]
    fn presets_hit_their_control_points_exactly() {
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            for o in &tf.opacity {
                assert_eq!(tf.eval(o.value)[3], o.alpha, "{p} opacity at {}", o.value);
            }
            for c in &tf.color {
                assert_eq!(tf.eval(c.value)[..3], c.rgb, "{p} colour at {}", c.value);
            }
        }
    }

    #[test]
    fn bake_matches_eval_and_sample_interpolates() {
        const { assert!(LUT_ENTRIES >= 1024) };
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            // −1024…3071 in 4096 entries: one HU per entry, every position exact.
            let lut = tf.bake(-1024.0, 3071.0, LUT_ENTRIES);
            assert_eq!(lut.rgba.len(), LUT_ENTRIES);
            for (i, e) in lut.rgba.iter().enumerate() {
                let v = lut.entry_value(i);
                assert_eq!(v, -1024.0 + i as f64);
                assert_eq!(*e, tf.eval(v), "{p} entry {i}");
                assert_eq!(lut.sample(v), *e, "{p} sample at entry {i}");
            }
            // Between entries: the lerp of the two neighbours.
            for i in [0, 100, 1174, 1500, 4094] {
                let (a, b) = (lut.rgba[i], lut.rgba[i + 1]);
                let s = lut.sample(lut.entry_value(i) + 0.25);
                let want: [f32; 4] = std::array::from_fn(|c| a[c] * 0.75 + b[c] * 0.25);
                assert!(close(s, want, 1e-6), "{p} between {i} and {}", i + 1);
            }
            // Clamp to the edge entries outside the range.
            assert_eq!(lut.sample(-5000.0), lut.rgba[0]);
            assert_eq!(lut.sample(1e9), lut.rgba[LUT_ENTRIES - 1]);
        }
    }

    #[test]
    fn bake_over_an_unaligned_range_matches_eval() {
        let tf = TransferFunction::preset(Preset::MrT1Brain, &mr());
        let lut = tf.bake(-3.7, 812.0, LUT_ENTRIES);
        assert_eq!(lut.entry_value(0), -3.7);
        assert!((lut.entry_value(LUT_ENTRIES - 1) - 812.0).abs() < 1e-12);
        for (i, e) in lut.rgba.iter().enumerate() {
            let v = lut.entry_value(i);
            assert_eq!(*e, tf.eval(v));
            // t is not exactly i here; the lerp weight is off by ~1e-13.
            assert!(close(lut.sample(v), *e, 1e-6), "entry {i}");
        }
        // A linear TF segment is reproduced between entries up to f32 rounding.
        let mut rng = Rng(7);
        for _ in 0..1000 {
            let v = rng.range(0.26 * 812.0, 0.44 * 812.0);
            assert!(close(lut.sample(v), tf.eval(v), 1e-5), "at {v}");
        }
    }

    #[test]
    fn bake_makes_degenerate_ranges_usable() {
        let tf = simple();
        let lut = tf.bake(50.0, 50.0, 0);
        assert_eq!(lut.rgba.len(), 2);
        assert!(lut.min < 50.0 && lut.max > 50.0);
        let lut = tf.bake(200.0, 0.0, 16);
        assert_eq!((lut.min, lut.max), (0.0, 200.0));
        let lut = tf.bake(f64::NAN, 1.0, 16);
        assert_eq!((lut.min, lut.max), (0.0, 1.0));
    }

    #[test]
    fn correct_opacity_is_the_step_power_law() {
        for i in 0..=1000 {
            let a = i as f32 / 1000.0;
            assert_eq!(correct_opacity(a, 1.0), a, "step 1 is identity at {a}");
            let half = correct_opacity(a, 0.5);
            let two = 1.0 - (1.0 - f64::from(half)).powi(2);
            assert!((two - f64::from(a)).abs() < 1e-6, "two half steps at {a}");
            let double = correct_opacity(a, 2.0);
            assert!((double - correct_opacity(half, 4.0)).abs() < 1e-6);
        }
        for step in [0.01, 0.5, 1.0, 1.7, 100.0] {
            assert_eq!(correct_opacity(0.0, step), 0.0);
            assert_eq!(correct_opacity(1.0, step), 1.0);
        }
        assert_eq!(correct_opacity(1e-9, 1.0), 1e-9);
        assert_eq!(correct_opacity(0.5, 0.0), 0.0);
        assert_eq!(correct_opacity(f32::NAN, 1.0), 0.0);
        assert_eq!(correct_opacity(0.3, f32::INFINITY), 1.0);
    }

    #[test]
    fn is_transparent_over_is_conservative() {
        let mut rng = Rng(42);
        // Presets over CT and unaligned ranges: the claim holds for the table and the
        // function (their opacity features are much wider than one entry).
        let ranges = [(-1024.0, 3071.0), (-2048.0, 3071.0), (-1000.3, 2000.7)];
        let mut said_transparent = 0;
        for p in Preset::ALL {
            for &(min, max) in &ranges {
                let tf = TransferFunction::preset(p, &stats(min, max));
                let lut = tf.bake(min, max, LUT_ENTRIES);
                for _ in 0..300 {
                    let a = rng.range(min, max);
                    let b = (a + rng.range(0.0, 400.0)).min(max);
                    if !lut.is_transparent_over(b, a) {
                        continue;
                    }
                    said_transparent += 1;
                    for k in 0..=200 {
                        let v = a + (b - a) * k as f64 / 200.0;
                        assert_eq!(lut.sample(v)[3], 0.0, "{p} sample at {v} in [{a}, {b}]");
                        assert_eq!(tf.eval(v)[3], 0.0, "{p} eval at {v} in [{a}, {b}]");
                    }
                }
            }
        }
        assert!(said_transparent > 100, "test must exercise the true case");

        // Random functions: the claim always holds for what the table renders.
        for _ in 0..200 {
            let mut v = rng.range(-100.0, 100.0);
            let opacity = (0..6)
                .map(|_| {
                    v += rng.range(0.0, 30.0);
                    let alpha = if rng.next().is_multiple_of(2) {
                        0.0
                    } else {
                        rng.range(0.0, 1.0) as f32
                    };
                    OpacityPoint { value: v, alpha }
                })
                .collect();
            let tf = TransferFunction {
                name: "random".into(),
                opacity,
                color: vec![ColorStop {
                    value: 0.0,
                    rgb: [1.0; 3],
                }],
            };
            tf.validate().expect("random TF is valid");
            let lut = tf.bake(-120.0, 300.0, 1024);
            for _ in 0..50 {
                let a = rng.range(-200.0, 350.0);
                let b = a + rng.range(0.0, 20.0);
                if lut.is_transparent_over(a, b) {
                    for k in 0..=100 {
                        let v = a + (b - a) * k as f64 / 100.0;
                        assert_eq!(lut.sample(v)[3], 0.0, "sample at {v} in [{a}, {b}]");
                    }
                }
            }
        }

        // One entry per unit; opacity 0 up to 100, rising after. The test reaches two
        // entries past floor(t(hi)): 98.5 → entries ..=100 (all 0), 99 → entry 101.
        let mut tf = simple();
        tf.opacity = vec![
            OpacityPoint {
                value: 100.0,
                alpha: 0.0,
            },
            OpacityPoint {
                value: 150.0,
                alpha: 1.0,
            },
        ];
        let lut = tf.bake(0.0, 200.0, 201);
        assert!(lut.is_transparent_over(-10.0, 50.0));
        assert!(lut.is_transparent_over(98.5, 10.0));
        assert!(!lut.is_transparent_over(10.0, 99.0));
        assert!(!lut.is_transparent_over(120.0, 130.0));
        assert!(!lut.is_transparent_over(f64::NAN, 1.0));
    }

    #[test]
    fn window_level_round_trips() {
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            let (w, l) = tf.window_level();
            let moved = tf.with_window_level(400.0, 40.0);
            moved.validate().expect("remapped preset stays valid");
            let (w2, l2) = moved.window_level();
            assert!((w2 - 400.0).abs() < 1e-9 && (l2 - 40.0).abs() < 1e-9);
            // The shape moves with the points.
            let map = |v: f64| 40.0 - 200.0 + (v - (l - w / 2.0)) / w * 400.0;
            // map() rounds differently from the remap, so allow an ulp-sized lerp weight.
            for o in &tf.opacity {
                assert!((moved.eval(map(o.value))[3] - o.alpha).abs() < 1e-6);
            }
            let back = moved.with_window_level(w, l);
            for (a, b) in tf.opacity.iter().zip(&back.opacity) {
                assert!((a.value - b.value).abs() < 1e-9 && a.alpha == b.alpha);
            }
            for (a, b) in tf.color.iter().zip(&back.color) {
                assert!((a.value - b.value).abs() < 1e-9 && a.rgb == b.rgb);
            }
        }
        let bone = TransferFunction::preset(Preset::CtBone, &ct());
        assert_eq!(bone.window_level(), (1350.0, 825.0));
        assert_eq!(bone.with_window_level(f64::NAN, 0.0), bone);
        let step = bone.with_window_level(-5.0, 300.0);
        step.validate().expect("a collapsed TF is a valid step");
        assert_eq!(step.window_level(), (0.0, 300.0));
    }

    #[test]
    fn presets_validate_and_names_round_trip() {
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()).expect("own name"), p);
            assert_eq!(p.name().parse::<Preset>().expect("FromStr"), p);
            let json = serde_json::to_string(&p).expect("serialize preset");
            assert_eq!(json, format!("\"{}\"", p.name()));
            let back: Preset = serde_json::from_str(&json).expect("deserialize preset");
            assert_eq!(back, p);
            for s in [ct(), mr(), stats(5.0, 5.0), stats(-1e6, 1e6)] {
                let tf = TransferFunction::preset(p, &s);
                assert_eq!(tf.name, p.name());
                tf.validate()
                    .unwrap_or_else(|e| panic!("{p} over {s:?} is invalid: {e}"));
                assert!(tf.visible_range().is_some());
            }
        }
        assert_eq!(
            Preset::from_name(" CT-Bone ").expect("case"),
            Preset::CtBone
        );
        let err = Preset::from_name("bone").expect_err("not a preset");
        let msg = err.to_string();
        assert!(msg.contains("\"bone\""), "{msg}");
        for p in Preset::ALL {
            assert!(msg.contains(p.name()), "{msg}");
        }
    }

    #[test]
    fn presets_are_what_a_radiologist_expects() {
        let at = |p, v| TransferFunction::preset(p, &ct()).eval(v);
        // Bone: air, fat, muscle invisible; bone opaque and light.
        for v in [-1000.0, -100.0, 40.0, 150.0] {
            assert_eq!(at(Preset::CtBone, v)[3], 0.0, "bone at {v}");
        }
        let b = at(Preset::CtBone, 1000.0);
        assert!(b[3] > 0.8 && b[0] > 0.9 && b[1] > 0.85 && b[2] > 0.75);
        // Soft tissue: muscle semi-transparent red.
        let m = at(Preset::CtSoftTissue, 50.0);
        assert!(m[3] > 0.05 && m[3] < 0.3 && m[0] > 2.0 * m[1]);
        // Vessels: contrast red, bone white, unenhanced tissue hidden.
        assert_eq!(at(Preset::CtVessels, 50.0)[3], 0.0);
        let c = at(Preset::CtVessels, 300.0);
        assert!(c[3] > 0.4 && c[0] > 3.0 * c[1]);
        let w = at(Preset::CtVessels, 900.0);
        assert!(w.iter().all(|&x| x > 0.85));
        // Relative presets follow the volume's range.
        let tf = TransferFunction::preset(Preset::MrT1Brain, &mr());
        let (lo, hi) = tf.visible_range().expect("visible");
        assert!((lo - 0.10 * 812.0).abs() < 1e-9 && hi == f64::INFINITY);
        assert!(tf.opacity.iter().all(|o| (0.0..=812.0).contains(&o.value)));
        // CAO: one colour everywhere, opacity a non-decreasing ramp to 1.
        let cao = TransferFunction::preset(Preset::CaoSingleColor, &mr());
        let mut last = 0.0;
        for k in 0..=100 {
            let e = cao.eval(812.0 * k as f64 / 100.0);
            assert_eq!(e[..3], [0.9, 0.9, 0.9]);
            assert!(e[3] >= last);
            last = e[3];
        }
        assert_eq!(last, 1.0);
    }

    #[test]
    fn default_preset_follows_the_range() {
        assert_eq!(Preset::default_for(&ct()), Preset::CtBone);
        assert_eq!(Preset::default_for(&mr()), Preset::MrT1Brain);
        assert_eq!(Preset::default_for(&stats(0.0, 255.0)), Preset::MrT1Brain);
    }

    #[test]
    fn visible_range_brackets_the_visible_part() {
        let tf = simple();
        assert_eq!(tf.visible_range(), Some((0.0, f64::INFINITY)));
        let mut peak = simple();
        peak.opacity.push(OpacityPoint {
            value: 300.0,
            alpha: 0.0,
        });
        assert_eq!(peak.visible_range(), Some((0.0, 300.0)));
        peak.opacity.iter_mut().for_each(|o| o.alpha = 0.0);
        assert_eq!(peak.visible_range(), None);
    }

    #[test]
    fn serde_round_trips_a_tf() {
        let tf = TransferFunction::preset(Preset::CtSoftTissue, &ct());
        let json = serde_json::to_string_pretty(&tf).expect("serialize");
        assert!(json.contains("\"alpha\"") && json.contains("\"rgb\""));
        let back: TransferFunction = serde_json::from_str(&json).expect("deserialize");
        assert_eq!(back, tf);
    }

    #[test]
    fn invalid_tfs_are_rejected_with_clear_messages() {
        let check = |tf: TransferFunction, needles: &[&str]| {
            let msg = tf.validate().expect_err("must be invalid").to_string();
            for n in needles {
                assert!(msg.contains(n), "{msg:?} lacks {n:?}");
            }
        };
        let mut tf = simple();
        tf.opacity.clear();
        check(tf, &["\"test\"", "opacity list is empty"]);
        let mut tf = simple();
        tf.color.clear();
        check(tf, &["colour list is empty"]);
        let mut tf = simple();
        tf.opacity[1].value = f64::NAN;
        check(tf, &["opacity point 1", "NaN", "not a finite"]);
        let mut tf = simple();
        tf.opacity[2].value = 50.0;
        check(
            tf,
            &["opacity point 2 at 50", "after a point at 100", "sort"],
        );
        let mut tf = simple();
        tf.opacity[1].alpha = 1.5;
        check(tf, &["opacity point 1", "alpha 1.5", "[0, 1]"]);
        let mut tf = simple();
        tf.color[1].rgb = [255.0, 128.0, 0.0];
        check(tf, &["colour stop 1", "not 0–255"]);
        let mut tf = simple();
        tf.color[0].rgb[2] = f32::NAN;
        check(tf, &["colour stop 0"]);
    }
}
