//! Offscreen rendering for the CLI and tests: GPU when an adapter exists, else the CPU twin.

use super::gpu::{GpuVolume, RayCaster};
use super::texels::{UploadLimits, VolumeTexels};
use super::{Frame, Image, cpu};
use crate::ao::cao::{CaoGpu, CaoMode};
use crate::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
use crate::ao::{AoMethod, AoSettings};
use crate::clip::ClipShape;
use crate::clip::gpu::ClipMaps;
use crate::gpu::{self, GpuError};
use crate::tf::TransferFunction;
use crate::volume::Volume;

/// What rendered an image and how.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub image: Image,
    /// The adapter, or "CPU twin".
    pub device: String,
    /// How many times the volume was halved to fit the adapter.
    pub downsampled: u32,
    /// Seconds spent computing ambient occlusion (0 without).
    pub ao_seconds: f64,
    /// CAO / LAO-every-frame figures for the frame.
    pub cao: Option<crate::ao::cao::CaoStats>,
    /// Clip shapes left out, with why (the others clipped).
    pub clip_errors: Vec<String>,
}

/// Renders `volume` (already in RAS order) with ambient occlusion as `ao` says.
///
/// With `use_gpu` and no usable adapter, falls back to the CPU twin with a warning.
/// `progress(done, total)` reports AO precomputation in z-slices.
pub fn render(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    ao: &AoSettings,
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    render_clipped(volume, tf, frame, ao, &[], use_gpu, progress)
}

/// [`render`] with clip shapes (mm from the volume's centre). Clipping, CAO and its
/// baseline need the GPU: the clip shapes' depth maps are rasterised.
pub fn render_clipped(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    ao: &AoSettings,
    clip: &[ClipShape],
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let rays = Rays::uniform(ao.rays.directions());
    let clipped = !clip.is_empty() || matches!(ao.method, AoMethod::Cao | AoMethod::LaoFull);
    if clipped && !use_gpu {
        return Err(GpuError::Unsupported {
            what: "clipping, CAO and lao-full need a GPU adapter: the clip shapes' depth maps are rasterised (drop --cpu)".into(),
        });
    }
    if use_gpu {
        match gpu::request_device() {
            Ok(g) => {
                let rc = RayCaster::new(&g.device)?;
                let mut vol = GpuVolume::new(&g, volume, tf, frame.settings.step_voxels)?;
                let start = std::time::Instant::now();
                let mut cao_stats = None;
                let mut clip_errors = Vec::new();
                let mut cao_state = None;
                let mut maps = None;
                match ao.method {
                    AoMethod::Lao => {
                        let lut = lao_lut(tf, &vol.texels);
                        let a = LaoGpu::new(&g.device)?
                            .compute(&g, &vol, &lut, &rays, ao.samples, progress)?;
                        vol.set_ambient_occlusion(&g, &a);
                    }
                    AoMethod::Cao | AoMethod::LaoFull => {
                        let mut c =
                            CaoGpu::new(&g, &vol, tf, &rays, ao.samples, ao.msaa, progress)?;
                        let mode = if ao.method == AoMethod::Cao {
                            CaoMode::Selective
                        } else {
                            CaoMode::Full
                        };
                        let reach = c.reach_mm(&vol.texels);
                        let stats =
                            c.update(&g, &vol.texels, clip, ao.clip_resolution, reach, mode)?;
                        vol.set_ambient_occlusion_view(c.ao_view());
                        clip_errors = stats.clip_errors.clone();
                        cao_stats = Some(stats);
                        cao_state = Some(c);
                    }
                    AoMethod::None => {}
                }
                if cao_state.is_none() && !clip.is_empty() {
                    let mut m = ClipMaps::new(&g)?;
                    let radius = glam::Vec3::from(vol.texels.extent()).length() * 0.5;
                    // No AO depends on the clipping here: the dilation margin is unused.
                    let update = m.update(&g, clip, radius, 1.0, ao.clip_resolution)?;
                    clip_errors = update.errors.iter().map(|e| e.to_string()).collect();
                    maps = Some(m);
                }
                let ao_seconds = start.elapsed().as_secs_f64();
                let clip_maps = cao_state.as_ref().map(|c| &c.clip).or(maps.as_ref());
                let image = rc.render_clipped(&g, &vol, frame, clip_maps)?;
                return Ok(Rendered {
                    image,
                    device: g.describe(),
                    downsampled: vol.texels.downsampled,
                    ao_seconds,
                    cao: cao_stats,
                    clip_errors,
                });
            }
            Err(e) if clipped => return Err(e),
            Err(e) => eprintln!("warning: {e}\nwarning: rendering on the CPU instead (slow)"),
        }
    }
    let texels = VolumeTexels::new(
        volume,
        UploadLimits {
            max_dim: usize::MAX,
            max_bytes: u64::MAX,
        },
    );
    let lut = super::gpu::bake_lut(tf, &texels, frame.settings.step_voxels);
    let (mut cv, occ) = cpu::prepare(&texels, &lut);
    let start = std::time::Instant::now();
    if ao.method == AoMethod::Lao {
        let a = lao_cpu(&texels, &lao_lut(tf, &texels), &rays, ao.samples, progress);
        cv.ao = Some(a);
    }
    let ao_seconds = start.elapsed().as_secs_f64();
    let threads = rayon::current_num_threads();
    let image = cpu::render(&texels, &cv, &lut, &occ, frame);
    Ok(Rendered {
        image,
        device: format!("CPU twin ({threads} threads)"),
        downsampled: 0,
        ao_seconds,
        cao: None,
        clip_errors: Vec::new(),
    })
}
