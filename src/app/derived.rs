//! The volumes the viewer derives from the document on the GPU — ambient occlusion,
//! opacity modulation, the light volume of shadows — and the transfer function and
//! clipping they are drawn with, kept in step with what the document says.

use super::ao_job::AoResult;
use super::jobs::Keyed;
use crate::ao::AoSettings;
use crate::ao::cao::CaoStats;
use crate::ao::filter::OpacityModulation;
use crate::texels::segments::SegmentTexels;
use crate::tf::TransferFunction;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How long the transfer function must rest before AO is recomputed for it.
pub(super) const AO_DEBOUNCE: Duration = Duration::from_millis(400);

/// What the AO volume on the GPU was computed for.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct AoKey {
    pub(super) settings: AoSettings,
    /// With clip shapes LAO runs as CAO (exact under clipping every frame).
    pub(super) clipping: bool,
    /// LAO depends on the transfer function's opacity only.
    pub(super) opacity: Vec<crate::tf::OpacityPoint>,
    /// Which voxels LAO and CAO compute (the render mode and skipping decide).
    pub(super) coverage: crate::ao::sparse::Coverage,
    /// What the AO sees of the segmentation ([`seen`]).
    pub(super) segments: Option<Vec<[u32; 3]>>,
    pub(super) doc_generation: u64,
}

/// What AO and shadows see of a segmentation: per class its opacity weight (bits),
/// whether only its outline shows, and the shapes that carve it. Colours and
/// tint/replace are left out: they change no opacity, so no AO.
pub(super) fn seen(s: &SegmentTexels) -> Vec<[u32; 3]> {
    s.table
        .iter()
        .map(|c| [c.opacity.to_bits(), u32::from(c.outline), c.carved_by])
        .collect()
}

/// What the segmentation's classes and looks were built for: the styles, each clip
/// shape's cuts (carve bits are per shape index) and the document.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SegmentsKey {
    pub(super) styles: crate::labels::style::Styles,
    pub(super) cuts: Vec<crate::clip::Cuts>,
    pub(super) doc_generation: u64,
}

/// The segmentation as last built, and whether the viewport's volume has it.
#[derive(Debug)]
pub(super) struct SegmentsBuilt {
    pub(super) key: SegmentsKey,
    pub(super) texels: Arc<SegmentTexels>,
    pub(super) uploaded: bool,
    /// Bumped by every build (the hover line's copy follows it).
    pub(super) version: u64,
}

/// What the viewer derives from the document and keeps on the GPU, each keyed by what it
/// was computed for, and the state of the transfer function and clipping they are drawn
/// with.
#[derive(Debug)]
pub(super) struct Derived {
    /// The AO volume, CAO's state or live positional AO.
    pub(super) ao: Keyed<AoKey, AoResult>,
    /// The cheap ambient map shown while a slow AO is computed (progressive AO).
    pub(super) preview: Keyed<AoKey, Vec<f32>>,
    /// Which ambient term the viewport shows.
    pub(super) shown: AoShown,
    /// Opacity modulation factors (Ruiz et al. §4.2).
    pub(super) modulation: Keyed<ModulationKey, Vec<f32>>,
    /// The light volume of shadows.
    pub(super) light: Keyed<LightKey, Vec<f32>>,
    /// The light volume last wanted, since when (a headlight's waits for the view to
    /// rest).
    pub(super) light_wanted: Option<(LightKey, Instant)>,
    /// When the transfer function last changed (AO waits for it to rest).
    pub(super) tf_changed_at: Instant,
    /// What the viewport's GPU volume has: view TF and step.
    pub(super) uploaded_tf: Option<(TransferFunction, f32)>,
    /// The last AO computation's seconds and device.
    pub(super) ao_seconds: Option<(f64, String)>,
    /// The last CAO frame's figures.
    pub(super) cao_stats: Option<CaoStats>,
    /// The segmentation's classes and looks (`None`: the document has none).
    pub(super) segments: Option<SegmentsBuilt>,
    /// CAO's state made for the AO key given, kept when only what the AO sees of the
    /// segmentation moved on: its `V_PAO` is then updated near the segments whose
    /// opacity changed ([`crate::ao::cao::CaoGpu::update_pao`]) instead of recomputed.
    pub(super) reusable_cao: Option<(AoKey, Box<crate::ao::cao::CaoGpu>)>,
}

impl AoKey {
    /// Whether `self` and `other` differ only in what the AO sees of the segmentation,
    /// with the same classes.
    pub(super) fn differs_in_segments_only(&self, other: &AoKey) -> bool {
        let classes = |k: &AoKey| k.segments.as_ref().map(Vec::len);
        classes(self).is_some()
            && classes(self) == classes(other)
            && AoKey {
                segments: None,
                ..self.clone()
            } == AoKey {
                segments: None,
                ..other.clone()
            }
    }

    /// Per class of the segmentation: whether `other` sees its opacity other than
    /// `self` (weight or outline; cuts change no `V_PAO`).
    pub(super) fn opacity_changes(&self, other: &AoKey) -> Vec<bool> {
        let (Some(a), Some(b)) = (&self.segments, &other.segments) else {
            return Vec::new();
        };
        a.iter().zip(b).map(|(x, y)| x[..2] != y[..2]).collect()
    }
}

impl Default for Derived {
    fn default() -> Self {
        Derived {
            ao: Keyed::default(),
            preview: Keyed::default(),
            shown: Default::default(),
            modulation: Keyed::default(),
            light: Keyed::default(),
            light_wanted: None,
            tf_changed_at: Instant::now(),
            uploaded_tf: None,
            ao_seconds: None,
            cao_stats: None,
            segments: None,
            reusable_cao: None,
        }
    }
}

/// What the opacity modulation factors on the GPU were computed for.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ModulationKey {
    pub(super) settings: OpacityModulation,
    /// The opacity points, when the variance is that of the opacity.
    pub(super) opacity: Option<Vec<crate::tf::OpacityPoint>>,
    pub(super) doc_generation: u64,
}

/// What the light volume of shadows on the GPU was computed for.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct LightKey {
    /// Towards the light, volume RAS (a headlight's follows the camera).
    pub(super) direction: [f32; 3],
    pub(super) opacity: Vec<crate::tf::OpacityPoint>,
    /// Light passes through what the shapes carve away.
    pub(super) clip: Vec<crate::clip::ClipShape>,
    /// What the light sees of the segmentation ([`seen`]).
    pub(super) segments: Option<Vec<[u32; 3]>>,
    pub(super) doc_generation: u64,
}

/// What the viewport's ambient term is right now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AoShown {
    /// No AO (none chosen, or nothing computed yet).
    #[default]
    Nothing,
    /// The AO of the previous settings, kept on screen until the approximation for the
    /// new ones arrives (one ambient map's time).
    Previous,
    /// The cheap ambient map, until the exact AO is ready.
    Approximate,
    /// The AO the settings ask for.
    Exact,
}
