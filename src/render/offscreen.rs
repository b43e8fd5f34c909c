//! Offscreen rendering for the CLI and tests: GPU when an adapter exists, else the CPU twin.

use super::gpu::{GpuVolume, RayCaster};
use super::texels::{UploadLimits, VolumeTexels};
use super::{Frame, Image, cpu};
use crate::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
use crate::ao::{AoMethod, AoSettings};
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
    let rays = Rays::uniform(ao.rays.directions());
    if use_gpu {
        match gpu::request_device() {
            Ok(g) => {
                let rc = RayCaster::new(&g.device)?;
                let mut vol = GpuVolume::new(&g, volume, tf, frame.settings.step_voxels)?;
                let start = std::time::Instant::now();
                if ao.method == AoMethod::Lao {
                    let lut = lao_lut(tf, &vol.texels);
                    let a = LaoGpu::new(&g.device)?
                        .compute(&g, &vol, &lut, &rays, ao.samples, progress)?;
                    vol.set_ambient_occlusion(&g, &a);
                }
                let ao_seconds = start.elapsed().as_secs_f64();
                let image = rc.render(&g, &vol, frame)?;
                return Ok(Rendered {
                    image,
                    device: g.describe(),
                    downsampled: vol.texels.downsampled,
                    ao_seconds,
                });
            }
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
    })
}
