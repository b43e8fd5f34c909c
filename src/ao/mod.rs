//! Ambient occlusion: ray sets and the precomputed LAO volume `V_PAO` (GPU and CPU twin).
//!
//! The renderer's ambient term is `k · A(x) · C_TF(x)`; a method here produces `A(x)`
//! per voxel in [0, 1] (1 = unoccluded).

pub mod cao;
pub mod lao;
pub mod rays;

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
}

impl AoMethod {
    pub fn parse(s: &str) -> Result<AoMethod, String> {
        match s {
            "none" => Ok(AoMethod::None),
            "lao" => Ok(AoMethod::Lao),
            other => Err(format!(
                "unknown AO method {other:?} (available: none, lao)"
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
    /// Samples per ray (M), 1 mm apart.
    pub samples: u32,
}

impl Default for AoSettings {
    fn default() -> Self {
        AoSettings {
            method: AoMethod::None,
            rays: RaySet::FiftyFour,
            samples: lao::DEFAULT_SAMPLES,
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
/// orientation), as f32 values in [0, 1]. Uses the GPU when `use_gpu` and an adapter can
/// hold the volume at full resolution, else the CPU twin. Returns the volume and what
/// computed it.
pub fn compute_volume(
    volume: &crate::volume::Volume,
    tf: &crate::tf::TransferFunction,
    settings: &AoSettings,
    use_gpu: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(crate::volume::Volume, String), crate::gpu::GpuError> {
    use crate::render::texels::{UploadLimits, VolumeTexels};
    let rays = lao::Rays::uniform(settings.rays.directions());
    let mut computed = None;
    if use_gpu {
        match crate::gpu::request_device() {
            Ok(g) => {
                let vol = crate::render::gpu::GpuVolume::new(&g, volume, tf, 0.5)?;
                if vol.texels.downsampled == 0 {
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
            let a = lao::lao_cpu(
                &texels,
                &lao::lao_lut(tf, &texels),
                &rays,
                settings.samples,
                progress,
            );
            (
                a,
                format!("CPU twin ({} threads)", rayon::current_num_threads()),
            )
        }
    };
    let out = crate::volume::Volume {
        dims: volume.dims,
        spacing: volume.spacing,
        data: crate::volume::VoxelData::F32(values),
        scaling: crate::volume::Scaling::IDENTITY,
        orientation: volume.orientation,
        descriptions: vec![(
            "description".into(),
            format!(
                "LAO ambient factor, {} rays x {} samples, TF {}",
                settings.rays.name(),
                settings.samples,
                tf.name
            ),
        )],
    };
    Ok((out, device))
}
