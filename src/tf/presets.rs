//! The built-in transfer functions and their tables of control points: CT presets in
//! absolute HU, MR and the CAO paper's single-colour look relative to the volume's range.

use super::error::TfError;
use super::function::{ColorStop, OpacityPoint, TransferFunction, usable_range};
use crate::volume::Stats;

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
            .ok_or_else(|| TfError::UnknownPreset {
                name: s.to_owned(),
                valid: preset_names(),
            })
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
}
