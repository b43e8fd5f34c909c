//! [`AoEngine`]: the one place that turns [`AoSettings`] into an ambient factor `A(x)`.
//!
//! It chooses the stage for the method and whether it runs on the GPU or on its CPU
//! twin, and says why in [`AoComputed::notes`] (the library prints nothing; the CLI
//! prints the notes, the viewer shows them). The stages' pipelines live on the device
//! ([`crate::gpu::Gpu::stage`]), so an engine is cheap and every computation after the
//! first reuses them. CLI, offscreen rendering and the viewer all compute AO here.

use super::cao::{CaoGpu, CaoMode, CaoSetup, CaoStats};
use super::cone::{ConeGpu, MipPyramid, cone_cpu, opacity};
use super::fast::{box_radius, cone_reach, map_of, statistics_device, twin_is_faster};
use super::filter::{FilterGpu, Source};
use super::lao::{LaoGpu, LaoSetup, Rays, lao_cpu_reading, lao_lut};
use super::sparse::{Bricks, Coverage};
use super::vao::{PositionalAo, VaoGpu, VaoInputs, vao_cpu};
use super::view::ViewMask;
use super::{AoMethod, AoSettings};
use crate::clip::ClipShape;
use crate::gpu::{Gpu, GpuError, GpuUse};
use crate::texels::gpu::GpuVolume;
use crate::texels::segments::SegmentTexels;
use crate::texels::{BlockRanges, UploadLimits, VolumeTexels};
use crate::tf::TransferFunction;
use std::sync::Arc;

/// What to compute: the transfer function and the method's settings, and for CAO and
/// its baseline the clip shapes of the one frame to compute.
#[derive(Debug, Clone, Copy)]
pub struct AoRequest<'a> {
    pub tf: &'a TransferFunction,
    pub settings: &'a AoSettings,
    /// CAO and lao-full: the frame's clip shapes (mm from the volume's centre). `None`
    /// precomputes `V_PAO` only (`V_AO = V_PAO`); the viewer updates it per frame.
    pub clip: Option<&'a [ClipShape]>,
    /// Which voxels LAO, CAO and lao-full compute (the other methods compute all).
    pub coverage: Coverage,
    /// Of those, only the voxels one image reads the AO of (a visibility pass's,
    /// [`super::view`]); `None`: all.
    pub view: Option<&'a Arc<ViewMask>>,
}

impl AoRequest<'_> {
    /// The bricks (and voxels) LAO, CAO and lao-full compute for this request.
    fn bricks(&self, texels: &VolumeTexels, ranges: &BlockRanges) -> Bricks {
        let bricks = self.coverage.bricks(texels, ranges, self.tf);
        match self.view {
            Some(view) => bricks.within(Arc::clone(view)),
            None => bricks,
        }
    }
}

/// The volume AO is computed for: texels (uploaded here if a GPU stage runs), the same
/// with a segmentation on their grid, or a volume already on the engine's device.
#[derive(Debug, Clone, Copy)]
pub enum AoInput<'a> {
    Texels(&'a VolumeTexels),
    Segmented(&'a VolumeTexels, &'a SegmentTexels),
    Uploaded(&'a GpuVolume),
}

impl AoInput<'_> {
    fn texels(&self) -> &VolumeTexels {
        match self {
            AoInput::Texels(t) | AoInput::Segmented(t, _) => t,
            AoInput::Uploaded(v) => &v.texels,
        }
    }

    /// The segmentation uploaded with the volume, if any (the twins read it too).
    fn segments(&self) -> Option<&SegmentTexels> {
        match self {
            AoInput::Texels(_) => None,
            AoInput::Segmented(_, s) => Some(s),
            AoInput::Uploaded(v) => v.segment_texels.as_ref(),
        }
    }
}

/// The ambient factor as computed.
#[derive(Debug)]
pub enum Ambient {
    /// `A = 1` everywhere (no AO).
    One,
    /// Live positional AO: the ray caster evaluates it at every sample.
    Live,
    /// One value per voxel, x fastest, in [0, 1].
    Values(Vec<f32>),
    /// CAO (or its baseline) on the GPU: `V_AO` stays there, updated per frame.
    Cao(Box<CaoGpu>),
}

/// An ambient factor with what computed it.
#[derive(Debug)]
pub struct AoComputed {
    pub ambient: Ambient,
    /// The adapter, or "CPU twin (N threads)".
    pub device: String,
    /// Why the path taken was taken, one line each ("the volume does not fit the
    /// adapter at full resolution; computing AO on the CPU").
    pub notes: Vec<String>,
    /// CAO / LAO-every-frame figures of the frame computed.
    pub cao: Option<CaoStats>,
}

/// Computes AO volumes on one device (or on the CPU twins when it has none).
#[derive(Debug, Clone, Default)]
pub struct AoEngine {
    gpu: Option<Arc<Gpu>>,
    /// Why there is no device, when one was asked for.
    no_device: Option<String>,
}

impl AoEngine {
    /// An engine on the device `gpu` names (opened now for [`GpuUse::Request`]). When no
    /// device can be had, the engine runs the CPU twins and its computations say why.
    pub fn new(gpu: &GpuUse) -> Self {
        match gpu.device() {
            None => AoEngine::default(),
            Some(Ok(g)) => AoEngine::on(Some(g)),
            Some(Err(e)) => AoEngine {
                gpu: None,
                no_device: Some(e.to_string()),
            },
        }
    }

    /// An engine on `gpu`, or on the CPU twins for `None`.
    pub fn on(gpu: Option<Arc<Gpu>>) -> Self {
        AoEngine {
            gpu,
            no_device: None,
        }
    }

    pub fn gpu(&self) -> Option<&Arc<Gpu>> {
        self.gpu.as_ref()
    }

    /// Computes `A(x)` for `request` on `input` (texels in the volume's own geometry).
    /// `progress(done, total)` reports precomputation in z-slices.
    pub fn compute(
        &self,
        input: AoInput<'_>,
        request: &AoRequest<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<AoComputed, GpuError> {
        let s = request.settings;
        let texels = input.texels();
        let mut notes = Vec::new();
        if let Some(e) = &self.no_device {
            notes.push(e.clone());
            notes.push("computing AO on the CPU instead (slow)".into());
        }
        let fits = self.gpu.as_ref().map(|g| UploadLimits::of(g).fits(texels));
        let done = |ambient, device: String, notes| {
            Ok(AoComputed {
                ambient,
                device,
                notes,
                cao: None,
            })
        };
        if matches!(s.method, AoMethod::Vao | AoMethod::VaoLive) {
            s.vao.validate().map_err(|e| GpuError::Validation {
                stage: "positional AO settings".into(),
                message: e.to_string(),
            })?;
        }
        match s.method {
            AoMethod::None => done(Ambient::One, self.describe(), notes),
            AoMethod::VaoLive => done(Ambient::Live, self.describe(), notes),
            AoMethod::Cao | AoMethod::LaoFull => self.cao(input, request, progress, notes),
            method => {
                let map = map_of(method);
                match (&self.gpu, fits) {
                    // A CPU adapter runs the box statistics ~20× slower than the twin.
                    (Some(g), _) if map.is_some() && twin_is_faster(g) => {
                        let a = self.twin(input, request, progress);
                        done(Ambient::Values(a), statistics_device(g), notes)
                    }
                    (Some(g), Some(true)) => {
                        let mut uploaded = None;
                        let vol = on_device(g, input, request.tf, &mut uploaded)?;
                        let a = self.on_gpu(g, vol, request, progress)?;
                        done(Ambient::Values(a), g.describe(), notes)
                    }
                    (gpu, _) => {
                        if gpu.is_some() {
                            notes.push(
                                "the volume does not fit the adapter at full resolution; \
                                 computing AO on the CPU"
                                    .into(),
                            );
                        }
                        let a = self.twin(input, request, progress);
                        done(Ambient::Values(a), cpu_twin(), notes)
                    }
                }
            }
        }
    }

    /// What runs the computations: the adapter, or the CPU twins.
    fn describe(&self) -> String {
        self.gpu.as_ref().map_or_else(cpu_twin, |g| g.describe())
    }

    /// A precomputed `A(x)` on the GPU (every method but CAO, its baseline and live AO).
    fn on_gpu(
        &self,
        g: &Gpu,
        vol: &GpuVolume,
        request: &AoRequest<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Vec<f32>, GpuError> {
        let (s, tf, texels) = (request.settings, request.tf, &vol.texels);
        match s.method {
            AoMethod::Lao => {
                let rays = Rays::uniform(s.rays.directions());
                let lut = lao_lut(tf, texels);
                let bricks = request.bricks(texels, vol.ranges());
                g.stage::<LaoGpu>()?.compute(
                    g,
                    vol,
                    LaoSetup {
                        lut: &lut,
                        rays: &rays,
                        samples: s.samples,
                    },
                    &bricks,
                    progress,
                )
            }
            AoMethod::Vao => {
                let inputs = VaoInputs::new(g, texels, tf, &s.vao)?
                    .with_segments(g, vol.segment_texels.as_ref());
                g.stage::<VaoGpu>()?
                    .compute(g, texels.dims, &inputs, progress)
            }
            AoMethod::Cone => {
                let opacity = opacity(texels, tf, vol.segment_texels.as_ref());
                let pyramid = MipPyramid::new(texels.dims, opacity);
                g.stage::<ConeGpu>()?.compute(
                    g,
                    texels,
                    &pyramid,
                    s.cones,
                    s.cone_preset,
                    cone_reach(s),
                )
            }
            method => {
                let Some(map) = map_of(method) else {
                    return Ok(vec![1.0; texels.dims.iter().product()]);
                };
                let source = Source::new(texels, tf, s.statistic);
                let radius = box_radius(s, texels);
                let mut maps = g
                    .stage::<FilterGpu>()?
                    .compute(g, vol, &source, radius, &[map])?;
                Ok(maps.pop().unwrap_or_default())
            }
        }
    }

    /// The CPU twin of [`Self::on_gpu`].
    fn twin(
        &self,
        input: AoInput<'_>,
        request: &AoRequest<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Vec<f32> {
        let (texels, segments) = (input.texels(), input.segments());
        let (s, tf) = (request.settings, request.tf);
        let sampler = segments.map(crate::sample::SegmentSampler::new);
        match s.method {
            AoMethod::Lao => {
                let rays = Rays::uniform(s.rays.directions());
                let ranges = BlockRanges::new(texels);
                let bricks = request.bricks(texels, &ranges);
                let lut = lao_lut(tf, texels);
                let setup = LaoSetup {
                    lut: &lut,
                    rays: &rays,
                    samples: s.samples,
                };
                lao_cpu_reading(texels, setup, sampler.as_ref(), &bricks, progress)
            }
            AoMethod::Vao => vao_cpu(
                &PositionalAo::new(texels, tf, &s.vao).with_segments(segments),
                texels.dims,
                progress,
            ),
            AoMethod::Cone => {
                let pyramid = MipPyramid::new(texels.dims, opacity(texels, tf, segments));
                cone_cpu(texels, &pyramid, s.cones, s.cone_preset, cone_reach(s))
            }
            method => match map_of(method) {
                Some(map) => {
                    let source = Source::new(texels, tf, s.statistic).with_segments(segments);
                    let radius = box_radius(s, texels);
                    super::filter::compute_cpu(texels, &source, radius, &[map])
                        .pop()
                        .unwrap_or_default()
                }
                None => vec![1.0; texels.dims.iter().product()],
            },
        }
    }

    /// CAO or its baseline: `V_PAO`, then (with `request.clip`) one frame. Needs the GPU:
    /// the clip shapes' depth maps are rasterised.
    fn cao(
        &self,
        input: AoInput<'_>,
        request: &AoRequest<'_>,
        progress: &(dyn Fn(usize, usize) + Sync),
        notes: Vec<String>,
    ) -> Result<AoComputed, GpuError> {
        let s = request.settings;
        let Some(g) = &self.gpu else {
            return Err(match &self.no_device {
                Some(e) => GpuError::Unsupported { what: e.clone() },
                None => GpuError::Unsupported {
                    what: "CAO and lao-full need a GPU adapter: the clip shapes' depth maps \
                           are rasterised (drop --cpu)"
                        .into(),
                },
            });
        };
        let texels = input.texels();
        if !UploadLimits::of(g).fits(texels) {
            return Err(GpuError::Unsupported {
                what: format!(
                    "the volume ({:?}) does not fit the adapter at full resolution; CAO needs it whole",
                    texels.dims
                ),
            });
        }
        let mut uploaded = None;
        let vol = on_device(g, input, request.tf, &mut uploaded)?;
        let rays = Rays::uniform(s.rays.directions());
        let bricks = request.bricks(texels, vol.ranges());
        let setup = CaoSetup {
            tf: request.tf,
            rays: &rays,
            samples: s.samples,
            msaa: s.msaa,
        };
        let mut c = CaoGpu::new(g, vol, setup, bricks, progress)?;
        let mut stats = None;
        if let Some(clip) = request.clip {
            let reach = c.reach_mm(texels);
            let mode = match s.method {
                AoMethod::LaoFull => CaoMode::Full,
                _ => CaoMode::Selective,
            };
            let pose = crate::ao::cao::Pose {
                shapes: clip,
                resolution: s.clip_resolution,
                reach_mm: reach,
                mode,
            };
            stats = Some(c.update(g, texels, pose)?);
        }
        Ok(AoComputed {
            ambient: Ambient::Cao(Box::new(c)),
            device: g.describe(),
            notes,
            cao: stats,
        })
    }
}

/// `input` on `g`: as given if uploaded, else uploaded into `slot`.
fn on_device<'a>(
    g: &Gpu,
    input: AoInput<'a>,
    tf: &TransferFunction,
    slot: &'a mut Option<GpuVolume>,
) -> Result<&'a GpuVolume, GpuError> {
    Ok(match input {
        AoInput::Uploaded(v) => v,
        AoInput::Texels(t) => slot.insert(GpuVolume::for_compute(g, t.clone(), tf, 0.5)?),
        AoInput::Segmented(t, s) => {
            let vol = slot.insert(GpuVolume::for_compute(g, t.clone(), tf, 0.5)?);
            vol.set_segments(g, Some(s.clone()));
            vol
        }
    })
}

fn cpu_twin() -> String {
    format!("CPU twin ({} threads)", rayon::current_num_threads())
}
