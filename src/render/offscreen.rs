//! Offscreen rendering for the CLI and tests: GPU when an adapter exists, else the CPU twin.

use super::gpu::{GpuVolume, RayCaster};
use super::texels::{UploadLimits, VolumeTexels};
use super::{Frame, Image, cpu};
use crate::gpu::{self, GpuError};
use crate::tf::TransferFunction;
use crate::volume::Volume;

/// Renders `volume` (already in RAS order) and returns the image, the name of what
/// rendered it and how many times the volume was halved to fit.
///
/// With `use_gpu` and no usable adapter, falls back to the CPU twin with a warning.
pub fn render(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    use_gpu: bool,
) -> Result<(Image, String, u32), GpuError> {
    if use_gpu {
        match gpu::request_device() {
            Ok(g) => {
                let rc = RayCaster::new(&g.device)?;
                let vol = GpuVolume::new(&g, volume, tf, frame.settings.step_voxels)?;
                let image = rc.render(&g, &vol, frame)?;
                return Ok((image, g.describe(), vol.texels.downsampled));
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
    let (cv, occ) = cpu::prepare(&texels, &lut);
    let threads = rayon::current_num_threads();
    Ok((
        cpu::render(&texels, &cv, &lut, &occ, frame),
        format!("CPU twin ({threads} threads)"),
        0,
    ))
}
