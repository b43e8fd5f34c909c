//! Ambient occlusion: ray sets and the precomputed LAO volume `V_PAO` (GPU and CPU twin).
//!
//! The renderer's ambient term is `k · A(x) · C_TF(x)`; a method here produces `A(x)`
//! per voxel in [0, 1] (1 = unoccluded).

pub mod cao;
pub mod cone;
pub mod fast;
pub mod filter;
pub mod lao;
pub mod rays;
pub mod vao;

use rays::RaySet;

/// Which ambient-occlusion method feeds `A(x)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AoMethod {
    /// `A = 1` everywhere.
    #[default]
    None,
    /// Local Ambient Occlusion, precomputed once per transfer function.
    Lao,
    /// Contextual AO: LAO kept exact under clipping by recomputing only the voxels the
    /// clip shapes affect (Titov et al.).
    Cao,
    /// The same clipping with a full LAO ray cast of every voxel each frame (the CAO
    /// paper's baseline).
    LaoFull,
    /// Positional AO by ray marching (Papaioannou et al. Eq. 8), precomputed per voxel.
    Vao,
    /// The same positional AO evaluated at every ray-cast sample, no precomputation.
    VaoLive,
    /// Ruiz et al.'s CDF reconstruction `t^β` from box min/max/mean.
    Cdf,
    /// Ruiz et al.'s Gaussian CDF from box mean/variance.
    Gauss,
    /// Penner's one-tailed Chebyshev bound (the baseline of Ruiz et al.).
    Penner,
    /// Cone tracing with tangent spheres on an opacity mip pyramid (Dalla Favera & Celes).
    Cone,
}

impl AoMethod {
    pub fn parse(s: &str) -> Result<AoMethod, String> {
        match s {
            "none" => Ok(AoMethod::None),
            "lao" => Ok(AoMethod::Lao),
            "cao" => Ok(AoMethod::Cao),
            "lao-full" => Ok(AoMethod::LaoFull),
            "vao" => Ok(AoMethod::Vao),
            "vao-live" => Ok(AoMethod::VaoLive),
            "cdf" => Ok(AoMethod::Cdf),
            "gauss" => Ok(AoMethod::Gauss),
            "penner" => Ok(AoMethod::Penner),
            "cone" => Ok(AoMethod::Cone),
            other => Err(format!(
                "unknown AO method {other:?} (available: none, lao, cao, lao-full, vao, vao-live, cdf, gauss, penner, cone)"
            )),
        }
    }
}

/// AO method and parameters, as saved in scene files.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AoSettings {
    pub method: AoMethod,
    /// Ray pattern (K rays): "6", "14", "26", "54" or "fib:N".
    #[serde(with = "ray_set_name")]
    pub rays: RaySet,
    /// Samples per ray (M), 1 mm apart; also the reach of the cones (M mm).
    pub samples: u32,
    /// CAO: extra anti-aliasing samples for partly clipped voxels (N; 9 + N in all).
    pub msaa: u32,
    /// CAO: size of each clip shape's depth and dilation maps (pixels, square).
    pub clip_resolution: u32,
    /// Parameters of positional AO (`vao`, `vao-live`).
    pub vao: vao::VaoSettings,
    /// Filter maps: box radius r (side 2r + 1).
    pub radius: f32,
    pub radius_unit: filter::RadiusUnit,
    /// Filter maps: statistics of the density or of the TF's opacity.
    pub statistic: filter::StatisticSource,
    /// Cone tracing: number of cones and spheres per cone.
    pub cones: cone::ConeSet,
    pub cone_preset: cone::ConePreset,
}

impl Default for AoSettings {
    fn default() -> Self {
        AoSettings {
            method: AoMethod::None,
            rays: RaySet::FiftyFour,
            samples: lao::DEFAULT_SAMPLES,
            radius: 10.0,
            radius_unit: filter::RadiusUnit::Voxels,
            statistic: filter::StatisticSource::Density,
            cones: cone::ConeSet::Six,
            cone_preset: cone::ConePreset::Medium,
            msaa: cao::DEFAULT_MSAA,
            clip_resolution: crate::clip::gpu::DEFAULT_RESOLUTION,
            vao: vao::VaoSettings::default(),
        }
    }
}

/// Ray sets are written by name in scene files ("54", "fib:512").
mod ray_set_name {
    use super::RaySet;

    pub fn serialize<S: serde::Serializer>(set: &RaySet, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&set.name())
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<RaySet, D::Error> {
        let name: String = serde::Deserialize::deserialize(d)?;
        RaySet::parse(&name).map_err(serde::de::Error::custom)
    }
}

/// Computes the AO volume of `volume` in its own geometry (same dims, spacing and
/// orientation), as f32 values in [0, 1]. Uses the GPU `gpu` names when it can hold the
/// volume at full resolution, else the CPU twin. Returns the volume and what computed it.
pub fn compute_volume(
    volume: &crate::volume::Volume,
    tf: &crate::tf::TransferFunction,
    settings: &AoSettings,
    gpu: &crate::gpu::GpuUse,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(crate::volume::Volume, String), crate::gpu::GpuError> {
    compute_volume_clipped(volume, tf, settings, &[], gpu, progress).map(|(v, d, _)| (v, d))
}

/// [`compute_volume`] with clip shapes (in mm from the volume's centre, along its voxel
/// axes) for CAO and the LAO-every-frame baseline, which also return their frame figures.
pub fn compute_volume_clipped(
    volume: &crate::volume::Volume,
    tf: &crate::tf::TransferFunction,
    settings: &AoSettings,
    clip: &[crate::clip::ClipShape],
    gpu: &crate::gpu::GpuUse,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(crate::volume::Volume, String, Option<cao::CaoStats>), crate::gpu::GpuError> {
    use crate::render::texels::{UploadLimits, VolumeTexels};
    if matches!(settings.method, AoMethod::Vao | AoMethod::VaoLive) {
        return vao::compute_volume(volume, tf, &settings.vao, gpu, progress)
            .map(|(v, d)| (v, d, None));
    }
    let rays = lao::Rays::uniform(settings.rays.directions());
    if matches!(settings.method, AoMethod::Cao | AoMethod::LaoFull) {
        let (values, device, stats) = clipped_on_gpu(volume, tf, settings, clip, gpu, progress)?;
        let out = ao_volume(volume, values, settings, tf);
        return Ok((out, device, Some(stats)));
    }
    let mut computed = None;
    // Set where the adapter is a CPU and the twin does the filter map faster.
    let mut twin_device = None;
    if let Some(device) = gpu.device() {
        match device {
            Ok(g) if fast::map_of(settings.method).is_some() && fast::twin_is_faster(&g) => {
                twin_device = Some(fast::statistics_device(&g));
            }
            Ok(g) => {
                let vol = crate::render::gpu::GpuVolume::new(&g, volume, tf, 0.5)?;
                if vol.texels.downsampled == 0 && fast::handles(settings.method) {
                    computed =
                        fast::compute_gpu(&g, &vol, tf, settings)?.map(|a| (a, g.describe()));
                } else if vol.texels.downsampled == 0 {
                    let lut = lao::lao_lut(tf, &vol.texels);
                    let a = lao::LaoGpu::new(&g.device)?.compute(
                        &g,
                        &vol,
                        &lut,
                        &rays,
                        settings.samples,
                        progress,
                    )?;
                    computed = Some((a, g.describe()));
                } else {
                    eprintln!(
                        "warning: the volume does not fit the adapter at full resolution; computing AO on the CPU"
                    );
                }
            }
            Err(e) => eprintln!("warning: {e}\nwarning: computing AO on the CPU instead (slow)"),
        }
    }
    let (values, device) = match computed {
        Some(c) => c,
        None => {
            let texels = VolumeTexels::new(
                volume,
                UploadLimits {
                    max_dim: usize::MAX,
                    max_bytes: u64::MAX,
                },
            );
            let a = if fast::handles(settings.method) {
                fast::compute_cpu(&texels, tf, settings).unwrap_or_default()
            } else {
                lao::lao_cpu(
                    &texels,
                    &lao::lao_lut(tf, &texels),
                    &rays,
                    settings.samples,
                    progress,
                )
            };
            let device = twin_device
                .unwrap_or_else(|| format!("CPU twin ({} threads)", rayon::current_num_threads()));
            (a, device)
        }
    };
    Ok((ao_volume(volume, values, settings, tf), device, None))
}

/// CAO or its baseline, one frame with `clip`, on the GPU (the clip maps are rasterised).
fn clipped_on_gpu(
    volume: &crate::volume::Volume,
    tf: &crate::tf::TransferFunction,
    settings: &AoSettings,
    clip: &[crate::clip::ClipShape],
    gpu: &crate::gpu::GpuUse,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(Vec<f32>, String, cao::CaoStats), crate::gpu::GpuError> {
    use crate::gpu::GpuError;
    let Some(g) = gpu.device() else {
        return Err(GpuError::Unsupported {
            what: "CAO and lao-full need a GPU adapter: the clip shapes' depth maps are rasterised (drop --cpu)".into(),
        });
    };
    let g = g?;
    let vol = crate::render::gpu::GpuVolume::new(&g, volume, tf, 0.5)?;
    if vol.texels.downsampled > 0 {
        return Err(GpuError::Unsupported {
            what: format!(
                "the volume ({:?}) does not fit the adapter at full resolution; CAO needs it whole",
                volume.dims
            ),
        });
    }
    let rays = lao::Rays::uniform(settings.rays.directions());
    let mut c = cao::CaoGpu::new(
        &g,
        &vol,
        tf,
        &rays,
        settings.samples,
        settings.msaa,
        progress,
    )?;
    let reach = c.reach_mm(&vol.texels);
    let mode = match settings.method {
        AoMethod::LaoFull => cao::CaoMode::Full,
        _ => cao::CaoMode::Selective,
    };
    let stats = c.update(&g, &vol.texels, clip, settings.clip_resolution, reach, mode)?;
    Ok((c.read(&g, 3)?, g.describe(), stats))
}

fn ao_volume(
    volume: &crate::volume::Volume,
    values: Vec<f32>,
    settings: &AoSettings,
    tf: &crate::tf::TransferFunction,
) -> crate::volume::Volume {
    let method = match settings.method {
        AoMethod::Cao => "CAO",
        AoMethod::LaoFull => "LAO (every frame, clipped)",
        _ => "LAO",
    };
    crate::volume::Volume {
        dims: volume.dims,
        spacing: volume.spacing,
        data: crate::volume::VoxelData::F32(values),
        scaling: crate::volume::Scaling::IDENTITY,
        orientation: volume.orientation,
        descriptions: vec![(
            "description".into(),
            if fast::handles(settings.method) {
                format!(
                    "ambient factor: {}, TF {}",
                    fast::describe(settings),
                    tf.name
                )
            } else {
                format!(
                    "{method} ambient factor, {} rays x {} samples, TF {}",
                    settings.rays.name(),
                    settings.samples,
                    tf.name
                )
            },
        )],
    }
}
