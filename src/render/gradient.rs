//! The gradient volume: the density's central differences per voxel, precomputed once
//! per volume (`shaders/gradient.wgsl`) so that the ray caster's shading reads one
//! RGBA16F texel instead of six density samples.
//!
//! `f(x + e) − f(x − e)` of the trilinear field `f` is the trilinear interpolation of the
//! voxels' own differences `v(k + e) − v(k − e)` (shifting by one voxel shifts the lattice,
//! not the weights), so the texture, with a border of one voxel for the sampler's edge
//! clamping, gives the same gradient as the six fetches, rounded to f16. It costs 8 bytes
//! per voxel of GPU memory: a volume whose gradient volume would not fit
//! [`GRADIENT_BUDGET`] (or the adapter's 3-D texture size) keeps the six fetches.

use crate::gpu::{Gpu, GpuError, validated};
use crate::texels::reader::{Reading, SegmentBindings, VOLUME_GROUP};
use crate::texels::{BlockRanges, TexelFormat, VolumeTexels};

/// The most GPU memory a gradient volume may take (8 bytes per texel).
pub const GRADIENT_BUDGET: u64 = 1 << 30;

/// A gradient volume on the GPU.
#[derive(Debug)]
pub struct GradientVolume {
    texture: wgpu::Texture,
    pub(super) view: wgpu::TextureView,
    /// `M`: the texels hold the differences divided by `M` (1 for unorm data; the
    /// largest |value| for float data, so that any range fits f16). The ray caster
    /// multiplies them back.
    pub scale: f32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GradientParams {
    dims: [u32; 4],
    scale: [f32; 4],
}

crate::gpu::compute_stage!(
    /// Long-lived gradient-volume compute state.
    GradientGpu,
    "Gradient",
    "gradient.wgsl"
);

/// The dims of the gradient volume of a volume of `dims`: a border of one voxel.
pub fn padded(dims: [usize; 3]) -> [usize; 3] {
    dims.map(|d| d + 2)
}

/// `M` of [`GradientVolume::scale`] for texels of `format` whose blocks span `ranges`
/// (every texel lies in a block, so their extremes are the texels'), or `None` when a
/// float volume holds no finite largest value.
fn scale_of(format: TexelFormat, ranges: &BlockRanges) -> Option<f32> {
    match format {
        TexelFormat::R8Unorm | TexelFormat::R16Unorm => Some(1.0),
        TexelFormat::R32Float => {
            let m = ranges
                .ranges
                .iter()
                // A block of NaNs alone keeps its empty (∞, −∞) range: nothing to count.
                .filter(|(lo, hi)| lo <= hi)
                .map(|&(lo, hi)| lo.abs().max(hi.abs()))
                .fold(0.0f32, f32::max);
            match m {
                m if !m.is_finite() => None,
                m if m > 0.0 => Some(m),
                _ => Some(1.0),
            }
        }
    }
}

impl GradientVolume {
    /// Computes the gradient volume of `texels` (already uploaded as `volume`, its
    /// blocks spanning `ranges`) on the GPU, or `None` when it would not fit
    /// [`GRADIENT_BUDGET`] or the adapter.
    pub fn new(
        gpu: &Gpu,
        volume: &wgpu::TextureView,
        texels: &VolumeTexels,
        ranges: &BlockRanges,
    ) -> Result<Option<Self>, GpuError> {
        let dims = padded(texels.dims).map(|d| d as u32);
        let bytes = dims.iter().map(|&d| u64::from(d)).product::<u64>() * 8;
        let max_dim = gpu.device.limits().max_texture_dimension_3d;
        if bytes > GRADIENT_BUDGET || dims.iter().any(|&d| d > max_dim) {
            return Ok(None);
        }
        let Some(scale) = scale_of(texels.format, ranges) else {
            return Ok(None);
        };
        let stage = gpu.stage::<GradientGpu>()?;
        let device = &gpu.device;
        let params = GradientParams {
            dims: [dims[0] - 2, dims[1] - 2, dims[2] - 2, 0],
            scale: [1.0 / scale, 0.0, 0.0, 0.0],
        };
        validated(device, "Gradient::compute", || {
            let texture = crate::gpu::texture_3d(
                device,
                "Gradient::volume",
                dims,
                wgpu::TextureFormat::Rgba16Float,
                wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            );
            let view = texture.create_view(&Default::default());
            let (_uniforms, group) = crate::gpu::uniform_group(
                gpu,
                "Gradient",
                &stage.0.pipeline,
                &params,
                &[wgpu::BindingResource::TextureView(&view)],
            );
            let reading = Reading {
                texels: volume,
                sampler: None,
                lut: None,
                segments: SegmentBindings::None,
            };
            let volume_group = reading.group_of(gpu, "Gradient", &stage.0.pipeline);
            crate::gpu::submit_compute_with(
                device,
                &gpu.queue,
                "Gradient::compute",
                &stage.0.pipeline,
                &[(0, &group), (VOLUME_GROUP, &volume_group)],
                dims.map(|d| d.div_ceil(4)),
                |_| {},
            );
            Some(GradientVolume {
                texture,
                view,
                scale,
            })
        })
    }

    /// The texels read back, `(x, y, z)` differences times [`Self::scale`], x fastest
    /// over the padded dims (tests).
    pub fn read_back(&self, gpu: &Gpu) -> Result<Vec<[f32; 3]>, GpuError> {
        let size = [
            self.texture.width(),
            self.texture.height(),
            self.texture.depth_or_array_layers(),
        ];
        let rgba = crate::gpu::read_texture_f32(gpu, &self.texture, size, "Gradient::read_back")?;
        Ok(rgba
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2]].map(|v| v * self.scale))
            .collect())
    }
}

/// The gradient volume computed on the CPU (f32, not rounded): what
/// [`GradientVolume::read_back`] holds up to f16 rounding.
pub fn central_differences(texels: &VolumeTexels) -> Vec<[f32; 3]> {
    let dims = texels.dims;
    let [px, py, pz] = padded(dims);
    let at = |k: [i64; 3]| {
        let c: [usize; 3] = std::array::from_fn(|a| k[a].clamp(0, dims[a] as i64 - 1) as usize);
        texels.norm_at(c[0] + dims[0] * (c[1] + dims[1] * c[2]))
    };
    let mut out = Vec::with_capacity(px * py * pz);
    for z in 0..pz {
        for y in 0..py {
            for x in 0..px {
                let k = [x as i64 - 1, y as i64 - 1, z as i64 - 1];
                out.push(std::array::from_fn(|a| {
                    let (mut hi, mut lo) = (k, k);
                    hi[a] += 1;
                    lo[a] -= 1;
                    at(hi) - at(lo)
                }));
            }
        }
    }
    out
}
