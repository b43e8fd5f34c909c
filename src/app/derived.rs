//! The volumes the viewer derives from the document on the GPU — ambient occlusion,
//! opacity modulation, the light volume of shadows — and the transfer function and
//! clipping they are drawn with, kept in step with what the document says.

use super::ao_job::AoResult;
use super::jobs::Keyed;
use crate::ao::AoSettings;
use crate::ao::cao::CaoStats;
use crate::ao::filter::OpacityModulation;
use crate::tf::TransferFunction;
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
    pub(super) doc_generation: u64,
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
