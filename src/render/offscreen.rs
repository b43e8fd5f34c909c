//! Offscreen rendering for the CLI and tests: GPU when an adapter exists, else the CPU twin.

use super::gpu::{GpuVolume, RayCaster};
use super::shadow::{LightGpu, LightVolume, light_cpu, light_direction, light_lut, quantise};
use super::texels::{UploadLimits, VolumeTexels};
use super::{Frame, Image, cpu};
use crate::ao::cao::{CaoGpu, CaoMode};
use crate::ao::lao::{LaoGpu, Rays, lao_cpu, lao_lut};
use crate::ao::{AoMethod, AoSettings, vao};
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

/// What is drawn besides the volume.
#[derive(Debug, Clone, Copy, Default)]
pub struct Extras<'a> {
    /// Clip shapes (mm from the volume's centre).
    pub clip: &'a [ClipShape],
    /// Triangle meshes drawn inside the volume (see `render::surface`).
    pub surfaces: &'a [super::surface::Surface],
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
    render_with(volume, tf, frame, ao, Extras::default(), use_gpu, progress)
}

/// [`render`] with clip shapes. Clipping, CAO and its baseline need the GPU: the clip
/// shapes' depth maps are rasterised.
pub fn render_clipped(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    ao: &AoSettings,
    clip: &[ClipShape],
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let extras = Extras {
        clip,
        ..Default::default()
    };
    render_with(volume, tf, frame, ao, extras, use_gpu, progress)
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
    let extras = Extras {
        surfaces,
        ..Default::default()
    };
    render_with(volume, tf, frame, ao, extras, use_gpu, progress)
}

/// [`render`] with clip shapes and surfaces.
pub fn render_with(
    volume: &Volume,
    tf: &TransferFunction,
    frame: &Frame,
    ao: &AoSettings,
    extras: Extras<'_>,
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let Extras { clip, surfaces } = extras;
    let mut surfaces = surfaces.to_vec();
    if let Some(rgba) = frame.settings.clip_surface {
        let radius = glam::Vec3::new(
            volume.dims[0] as f32 * volume.spacing[0],
            volume.dims[1] as f32 * volume.spacing[1],
            volume.dims[2] as f32 * volume.spacing[2],
        )
        .length()
            * 0.5;
        // Shapes that cannot be built are reported by the clipping below.
        surfaces.extend(clip.iter().filter_map(|c| {
            let m = c.posed_geometry(radius).ok()?;
            Some(super::surface::Surface {
                triangles: m
                    .triangles
                    .iter()
                    .map(|t| t.map(|i| m.vertices[i as usize]))
                    .collect(),
                rgba,
            })
        }));
    }
    let surfaces = surfaces.as_slice();
    let rays = Rays::uniform(ao.rays.directions());
    if matches!(ao.method, AoMethod::Vao | AoMethod::VaoLive) {
        ao.vao.validate().map_err(|e| GpuError::Validation {
            stage: "positional AO settings".into(),
            message: e.to_string(),
        })?;
    }
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
                vol.extras.surfaces = surfaces.to_vec();
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
                    AoMethod::Vao => {
                        let inputs = vao::VaoInputs::new(&g, &vol.texels, tf, &ao.vao)?;
                        let a = vao::VaoGpu::new(&g.device)?.compute(
                            &g,
                            vol.texels.dims,
                            &inputs,
                            progress,
                        )?;
                        vol.set_ambient_occlusion(&g, &a);
                    }
                    AoMethod::VaoLive => vol.set_live_vao(&g, tf, Some(&ao.vao))?,
                    _ => {
                        if let Some(a) = crate::ao::fast::compute(&g, &vol, tf, ao)? {
                            vol.set_ambient_occlusion(&g, &a);
                        }
                    }
                }
                if let Some(m) = &frame.settings.opacity_modulation {
                    let f = crate::ao::fast::modulation(&g, &vol, tf, m)?;
                    vol.set_opacity_modulation(&g, &f);
                }
                if cao_state.is_none() && !clip.is_empty() {
                    let mut m = ClipMaps::new(&g)?;
                    let radius = glam::Vec3::from(vol.texels.extent()).length() * 0.5;
                    // No AO depends on the clipping here: the dilation margin is unused.
                    let update = m.update(&g, clip, radius, 1.0, ao.clip_resolution)?;
                    clip_errors = update.errors.iter().map(|e| e.to_string()).collect();
                    maps = Some(m);
                }
                let clip_maps = cao_state.as_ref().map(|c| &c.clip).or(maps.as_ref());
                if frame.settings.shadows {
                    let dir = light_dir(frame)?;
                    let t = LightGpu::new(&g.device)?.compute_clipped(
                        &g,
                        &vol.texels,
                        &light_lut(tf, &vol.texels),
                        dir,
                        clip_maps,
                        progress,
                    )?;
                    vol.set_light_volume(&g, Some((&t, dir)))?;
                }
                let ao_seconds = start.elapsed().as_secs_f64();
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
    if !surfaces.is_empty() {
        cv.surfaces = Some(cpu::CpuSurfaces {
            surfaces: surfaces.to_vec(),
            frame: *frame,
            texels: texels.clone(),
        });
    }
    let start = std::time::Instant::now();
    // The GPU keeps AO volumes as f32 (R32Float), so the twin uses them as computed.
    if ao.method == AoMethod::Lao {
        cv.ao = Some(lao_cpu(
            &texels,
            &lao_lut(tf, &texels),
            &rays,
            ao.samples,
            progress,
        ));
    }
    if ao.method == AoMethod::Vao {
        let pao = vao::PositionalAo::new(&texels, tf, &ao.vao);
        cv.ao = Some(vao::vao_cpu(&pao, texels.dims, progress));
    }
    if ao.method == AoMethod::VaoLive {
        cv.live_vao = Some(vao::PositionalAo::new(&texels, tf, &ao.vao));
    }
    if let Some(a) = crate::ao::fast::compute_cpu(&texels, tf, ao) {
        cv.ao = Some(a);
    }
    if let Some(m) = &frame.settings.opacity_modulation {
        cv.modulation = Some(quantise16(&crate::ao::fast::modulation_cpu(&texels, tf, m)));
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
        cao: None,
        clip_errors: Vec::new(),
    })
}

/// The frame's light direction, checked (shadows need a real direction).
fn light_dir(frame: &Frame) -> Result<glam::Vec3, GpuError> {
    light_direction(frame.settings.light_direction).map_err(|message| GpuError::Validation {
        stage: "shadows".into(),
        message,
    })
}

/// As the GPU path stores modulation volumes (R16Unorm).
fn quantise16(values: &[f32]) -> Vec<f32> {
    values
        .iter()
        .map(|&x| (x.clamp(0.0, 1.0) * 65535.0).round() / 65535.0)
        .collect()
}
