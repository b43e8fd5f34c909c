//! The viewer's AO computation, as one function of its inputs: no UI state, run on a
//! worker thread by [`super::derived`]. [`crate::ao::AoEngine`] computes CAO (exact under
//! clipping, on a copy of the uploaded texels) or a precomputed AO volume (on the
//! viewer's device, or the CPU twin where that is faster or the volume does not fit).

use super::jobs::Progress;
use crate::ao::{Ambient, AoEngine, AoMethod, AoRequest, AoSettings};
use crate::gpu::Gpu;
use crate::texels::gpu::GpuVolume;
use crate::texels::segments::SegmentTexels;
use crate::texels::{UploadLimits, VolumeTexels};
use crate::tf::TransferFunction;
use crate::volume::Volume;
use std::sync::Arc;
use std::time::Instant;

/// What one AO computation needs, owned so that it can move to a worker thread.
#[derive(Debug)]
pub struct AoInput {
    /// The viewer's device (the viewport draws with it too).
    pub gpu: Arc<Gpu>,
    /// The volume as loaded (RAS order): the input of a precomputed AO volume.
    pub volume: Arc<Volume>,
    /// A copy of the texels the viewport's volume was made from: CAO's input (only
    /// with `clipping`; `None` when no volume was uploaded).
    pub texels: Option<VolumeTexels>,
    pub tf: TransferFunction,
    pub settings: AoSettings,
    /// The ray caster's step in voxels (CAO builds its own [`GpuVolume`] with it).
    pub step_voxels: f32,
    /// CAO (the AO stays exact while clip shapes move) instead of an AO volume.
    pub clipping: bool,
    /// Which voxels LAO and CAO compute.
    pub coverage: crate::ao::sparse::Coverage,
    /// The segmentation as the viewport shows it (LAO and CAO read its weights and
    /// carve bits, as in `volao render`).
    pub segments: Option<Arc<SegmentTexels>>,
    /// CAO made for another look of the segmentation, and the voxels whose opacity
    /// changed: `V_PAO` is updated near them instead of recomputed.
    pub update: Option<(Box<crate::ao::cao::CaoGpu>, Vec<bool>)>,
}

/// A finished AO computation.
#[derive(Debug)]
pub struct AoResult {
    pub kind: AoData,
    /// What ran it ("llvmpipe (Vulkan)", "CPU twin …").
    pub device: String,
    pub seconds: f64,
}

/// A precomputed AO volume, or CAO with its `V_PAO` ready for per-frame updates.
#[derive(Debug)]
pub enum AoData {
    Volume(Vec<f32>),
    Cao(Box<crate::ao::cao::CaoGpu>),
}

/// Computes the AO `input` asks for, reporting through `progress` (which also stops the
/// work when the job is cancelled).
pub fn compute_ao(input: AoInput, progress: &Progress) -> Result<AoResult, String> {
    let start = Instant::now();
    let AoInput {
        gpu,
        volume,
        texels,
        tf,
        settings,
        step_voxels,
        clipping,
        coverage,
        segments,
        update,
    } = input;
    if let (Some((mut cao, changed)), Some(s), Some(t)) = (update, &segments, &texels) {
        // The same classes on the same grid: new looks and cuts into CAO's textures,
        // then V_PAO near what changed.
        if cao.set_segments(&gpu, s) && changed.len() == t.dims.iter().product::<usize>() {
            let u = cao
                .update_pao(&gpu, t, &changed)
                .map_err(|e| e.to_string())?;
            return Ok(AoResult {
                kind: AoData::Cao(cao),
                device: format!(
                    "{} (V_PAO updated: {} voxels ray cast again)",
                    gpu.describe(),
                    u.recomputed
                ),
                seconds: start.elapsed().as_secs_f64(),
            });
        }
    }
    let report = |d: usize, t: usize| progress.set(d as u64, t as u64);
    let engine = AoEngine::on(Some(Arc::clone(&gpu)));
    let mut settings = settings;
    let (uploaded, texels) = if clipping {
        // CAO precomputes V_PAO on its own copy of the uploaded texels; V_AO follows the
        // clip shapes from the next sync. With clip shapes LAO runs as CAO.
        let texels = texels.ok_or("no volume uploaded")?;
        let mut vol =
            GpuVolume::for_compute(&gpu, texels, &tf, step_voxels).map_err(|e| e.to_string())?;
        vol.set_segments(&gpu, segments.as_deref().cloned());
        if !settings.method.is_clipped() {
            settings.method = AoMethod::Cao;
        }
        (Some(vol), None)
    } else {
        // The viewer's own device (the engine sends a filter map on a CPU adapter to the
        // twin), on the volume at full resolution.
        let full = VolumeTexels::new(&volume, UploadLimits::NONE);
        match &segments {
            // The stages that read a segmentation read it from the volume it is uploaded
            // with, as in `volao render` (the others read the texels as they would).
            Some(s) if UploadLimits::of(&gpu).fits(&full) => {
                let mut vol = GpuVolume::for_compute(&gpu, full, &tf, step_voxels)
                    .map_err(|e| e.to_string())?;
                vol.set_segments(&gpu, Some(SegmentTexels::clone(s)));
                (Some(vol), None)
            }
            _ => (None, Some(full)),
        }
    };
    let input = match (&uploaded, &texels) {
        (Some(vol), _) => crate::ao::AoInput::Uploaded(vol),
        (None, Some(t)) => crate::ao::AoInput::Texels(t),
        (None, None) => return Err("nothing to compute AO for".into()),
    };
    let request = AoRequest {
        tf: &tf,
        settings: &settings,
        clip: None,
        coverage,
        view: None,
    };
    let computed = engine
        .compute(input, &request, &report)
        .map_err(|e| e.to_string())?;
    let kind = match computed.ambient {
        Ambient::Cao(cao) => AoData::Cao(cao),
        Ambient::Values(values) => AoData::Volume(values),
        Ambient::One | Ambient::Live => {
            return Err("the AO came back in an unexpected form".into());
        }
    };
    Ok(AoResult {
        kind,
        device: computed.device,
        seconds: start.elapsed().as_secs_f64(),
    })
}
