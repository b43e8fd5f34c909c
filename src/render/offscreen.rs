//! Offscreen rendering for the CLI and tests: GPU when an adapter exists, else the CPU twin.

use super::gpu::{GpuVolume, RayCaster};
use super::shadow::{LightGpu, LightVolume, light_cpu, light_direction, light_lut, quantise};
use super::texels::{UploadLimits, VolumeTexels};
use super::{Frame, Image, cpu};
use crate::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
use crate::ao::{AoMethod, AoSettings, vao};
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
    render_with_surfaces(volume, tf, frame, ao, &[], use_gpu, progress)
}

/// As [`render`], with triangle meshes drawn inside the volume (see `render::surface`).
pub fn render_with_surfaces(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    ao: &AoSettings,
    surfaces: &[super::surface::Surface],
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let rays = Rays::uniform(ao.rays.directions());
    if matches!(ao.method, AoMethod::Vao | AoMethod::VaoLive) {
        ao.vao.validate().map_err(|e| GpuError::Validation {
            stage: "positional AO settings".into(),
            message: e.to_string(),
        })?;
    }
    if use_gpu {
        match gpu::request_device() {
            Ok(g) => {
                let rc = RayCaster::new(&g.device)?;
                let mut vol = GpuVolume::new(&g, volume, tf, frame.settings.step_voxels)?;
                vol.extras.surfaces = surfaces.to_vec();
                let start = std::time::Instant::now();
                if ao.method == AoMethod::Lao {
                    let lut = lao_lut(tf, &vol.texels);
                    let a = LaoGpu::new(&g.device)?
                        .compute(&g, &vol, &lut, &rays, ao.samples, progress)?;
                    vol.set_ambient_occlusion(&g, &a);
                }
                if ao.method == AoMethod::Vao {
                    let inputs = vao::VaoInputs::new(&g, &vol.texels, tf, &ao.vao)?;
                    let a = vao::VaoGpu::new(&g.device)?.compute(
                        &g,
                        vol.texels.dims,
                        &inputs,
                        progress,
                    )?;
                    vol.set_ambient_occlusion(&g, &a);
                }
                if ao.method == AoMethod::VaoLive {
                    vol.set_live_vao(&g, tf, Some(&ao.vao))?;
                }
                if frame.settings.shadows {
                    let dir = light_dir(frame)?;
                    let t = LightGpu::new(&g.device)?.compute(
                        &g,
                        &vol.texels,
                        &light_lut(tf, &vol.texels),
                        dir,
                        progress,
                    )?;
                    vol.set_light_volume(&g, Some((&t, dir)))?;
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
    if !surfaces.is_empty() {
        cv.surfaces = Some(cpu::CpuSurfaces {
            surfaces: surfaces.to_vec(),
            frame: *frame,
            texels: texels.clone(),
        });
    }
    let start = std::time::Instant::now();
    if ao.method == AoMethod::Lao {
        let a = lao_cpu(&texels, &lao_lut(tf, &texels), &rays, ao.samples, progress);
        // As the GPU path stores it (R16Unorm), so both paths shade alike.
        cv.ao = Some(
            a.iter()
                .map(|&x| (x.clamp(0.0, 1.0) * 65535.0).round() / 65535.0)
                .collect(),
        );
    }
    if ao.method == AoMethod::Vao {
        let pao = vao::PositionalAo::new(&texels, tf, &ao.vao);
        let a = vao::vao_cpu(&pao, texels.dims, progress);
        cv.ao = Some(
            a.iter()
                .map(|&x| (x.clamp(0.0, 1.0) * 65535.0).round() / 65535.0)
                .collect(),
        );
    }
    if ao.method == AoMethod::VaoLive {
        cv.live_vao = Some(vao::PositionalAo::new(&texels, tf, &ao.vao));
    }
    if frame.settings.shadows {
        let dir = light_dir(frame)?;
        let t = light_cpu(&texels, &light_lut(tf, &texels), dir, progress);
        cv.light = Some(LightVolume {
            direction: dir,
            values: quantise(&t),
        });
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

/// The frame's light direction, checked (shadows need a real direction).
fn light_dir(frame: &Frame) -> Result<glam::Vec3, GpuError> {
    light_direction(frame.settings.light_direction).map_err(|message| GpuError::Validation {
        stage: "shadows".into(),
        message,
    })
}
