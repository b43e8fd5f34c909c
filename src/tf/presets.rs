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
#[derive(Clone, Copy, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum Units {
    /// Absolute data units (HU).
    Absolute,
    /// Fractions of the volume's value range [`Stats::min`, `Stats::max`].
    Relative,
}

/// A preset's points before resolving: (value, alpha) and (value, rgb), as
/// `presets.json` lists them.
#[derive(serde::Deserialize)]
struct PresetPoints {
    name: String,
    /// What the preset shows, and where its numbers come from (for readers of the file).
    #[serde(rename = "about")]
    _about: String,
    units: Units,
    opacity: Vec<(f64, f32)>,
    color: Vec<(f64, [f32; 3])>,
}

/// The presets' control points, a data file like 3D Slicer's `presets.xml`: one entry
/// per [`Preset`], by [`Preset::name`].
const PRESETS_JSON: &str = include_str!("presets.json");

fn table() -> &'static [PresetPoints] {
    static TABLE: std::sync::OnceLock<Vec<PresetPoints>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        // Compiled in; `tf::tests` builds and validates every preset from it.
        serde_json::from_str(PRESETS_JSON).expect("tf/presets.json is valid JSON")
    })
}

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

    /// The preset's entry in `presets.json`.
    fn points(self) -> &'static PresetPoints {
        table()
            .iter()
            .find(|p| p.name == self.name())
            .expect("tf/presets.json lists every preset")
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
        let mut tf = TransferFunction {
            name: p.name().to_owned(),
            opacity: OpacityPoint::list(&points.opacity),
            color: ColorStop::list(&points.color),
        };
        tf.opacity.iter_mut().for_each(|o| o.value = place(o.value));
        tf.color.iter_mut().for_each(|c| c.value = place(c.value));
        tf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_has_each_preset_once_and_each_is_valid() {
        assert_eq!(table().len(), Preset::ALL.len());
        let stats = Stats {
            min: -1024.0,
            max: 3071.0,
            mean: 0.0,
            non_finite: 0,
            finite: 1,
        };
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &stats);
            tf.validate().unwrap_or_else(|e| panic!("{p}: {e}"));
            assert_eq!(tf.name, p.name());
        }
        // CT bone, point for point as documented (absolute HU).
        let bone = TransferFunction::preset(Preset::CtBone, &stats);
        let points: Vec<(f64, f32)> = bone.opacity.iter().map(|o| (o.value, o.alpha)).collect();
        assert_eq!(
            points,
            [(150.0, 0.0), (300.0, 0.45), (500.0, 0.8), (1500.0, 0.9)]
        );
    }
}
