//! The cheap methods' parameters and the opacity modulation: the filter maps of Ruiz
//! et al. ([`super::filter`]) and cone tracing ([`super::cone`]) take a fraction of a
//! second, so callers recompute them whenever the transfer function changes instead of
//! caching. [`super::engine::AoEngine`] runs them.

use super::filter::{self, AmbientMap, FilterGpu, OpacityModulation, RadiusUnit, Source};
use super::{AoMethod, AoSettings};
use crate::gpu::{Gpu, GpuError};
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::tf::TransferFunction;

/// The filter map a method asks for, if it is one.
pub fn map_of(method: AoMethod) -> Option<AmbientMap> {
    match method {
        AoMethod::Cdf => Some(AmbientMap::Cdf),
        AoMethod::Gauss => Some(AmbientMap::Gauss),
        AoMethod::Penner => Some(AmbientMap::Penner),
        _ => None,
    }
}

/// True for the methods this module computes.
pub fn handles(method: AoMethod) -> bool {
    map_of(method).is_some() || method == AoMethod::Cone
}

/// Box radius in voxels per axis for these settings on these texels.
pub fn box_radius(settings: &AoSettings, texels: &VolumeTexels) -> [u32; 3] {
    filter::radius_voxels(
        settings.radius,
        settings.radius_unit == RadiusUnit::Mm,
        texels.spacing,
    )
}

/// Reach of the cones in mm: LAO's, `samples × 1 mm`, so the two compare like for like.
pub fn cone_reach(settings: &AoSettings) -> f32 {
    settings.samples.max(1) as f32 * super::lao::STEP_MM
}

/// One line saying what was computed, for descriptions and the CLI.
pub fn describe(settings: &AoSettings) -> String {
    let unit = match settings.radius_unit {
        RadiusUnit::Voxels => "voxels",
        RadiusUnit::Mm => "mm",
    };
    match settings.method {
        AoMethod::Cone => format!(
            "cone-traced AO, {} cones × {} spheres ({}), reach {} mm",
            settings.cones.count(),
            settings.cone_preset.spheres(),
            settings.cone_preset.name(),
            cone_reach(settings)
        ),
        m => format!(
            "{m:?} map of the {:?} box statistics, radius {} {unit}",
            settings.statistic, settings.radius
        )
        .to_lowercase(),
    }
}

/// True when the box statistics (filter maps, opacity modulation) are better left to the
/// CPU twin than given to this adapter: a CPU adapter such as llvmpipe runs the same
/// work on the same cores, ~20× slower than the twin (docs/benchmarks.md, Table 1).
/// Cone tracing stays on any adapter (llvmpipe runs it 2–3× faster than its twin).
pub fn twin_is_faster(gpu: &Gpu) -> bool {
    gpu.info.device_type == wgpu::DeviceType::Cpu
}

/// What ran the box statistics of the ambient maps and of [`modulation`] on `gpu`.
pub fn statistics_device(gpu: &Gpu) -> String {
    if twin_is_faster(gpu) {
        format!(
            "CPU twin ({} threads; faster than the CPU adapter {})",
            rayon::current_num_threads(),
            gpu.info.name
        )
    } else {
        gpu.describe()
    }
}

/// Opacity modulation factors with `gpu` at hand: [`modulation_gpu`], or the CPU twin
/// on the uploaded texels where [`twin_is_faster`].
pub fn modulation(
    gpu: &Gpu,
    vol: &GpuVolume,
    tf: &TransferFunction,
    m: &OpacityModulation,
) -> Result<Vec<f32>, GpuError> {
    if twin_is_faster(gpu) {
        return Ok(modulation_cpu(&vol.texels, tf, m));
    }
    modulation_gpu(gpu, vol, tf, m)
}

fn modulation_radius(m: &OpacityModulation) -> [u32; 3] {
    filter::radius_voxels(m.radius, false, [1.0; 3])
}

/// Opacity modulation factors `min(σ²/σ²_max, 1)` per voxel on the GPU.
pub fn modulation_gpu(
    gpu: &Gpu,
    vol: &GpuVolume,
    tf: &TransferFunction,
    m: &OpacityModulation,
) -> Result<Vec<f32>, GpuError> {
    let source = Source::new(&vol.texels, tf, m.source);
    let mut maps = gpu.stage::<FilterGpu>()?.compute(
        gpu,
        vol,
        &source,
        modulation_radius(m),
        &[AmbientMap::Variance],
    )?;
    Ok(filter::modulation(
        &maps.pop().unwrap_or_default(),
        m.sigma2_max,
    ))
}

/// CPU twin of [`modulation_gpu`].
pub fn modulation_cpu(
    texels: &VolumeTexels,
    tf: &TransferFunction,
    m: &OpacityModulation,
) -> Vec<f32> {
    let source = Source::new(texels, tf, m.source);
    let mut maps = filter::compute_cpu(
        texels,
        &source,
        modulation_radius(m),
        &[AmbientMap::Variance],
    );
    filter::modulation(&maps.pop().unwrap_or_default(), m.sigma2_max)
}
