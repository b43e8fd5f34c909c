//! Filter-based ambient occlusion (Ruiz et al. 2010): separable box statistics over the
//! bounding box of the tangent sphere and the ambient maps built from them, on the GPU
//! (`shaders/box_stats.wgsl`, `shaders/ambient_maps.wgsl`) with a CPU (rayon) twin.
//!
//! Per voxel x the box of side `2r + 1` voxels per axis (cropped at the volume's faces)
//! gives `v_min`, `v_max`, `E[v]` and `E[v²]` of a source value `v`: the normalised
//! density (as the paper) or the transfer function's opacity. Each axis is one pass of
//! the van Herk / Gil-Werman algorithm with the operation `(min, max, +, +)`: the line is
//! cut into segments of `L = min(2r + 1, 64)` outputs that all contain one pivot voxel
//! `m`; a backward run gives suffixes `S[a] = op(v[a..m))`, a forward run prefixes
//! `P[b] = op(v[m..=b])`, and each window is `op(S[i − r], P[i + r])`. For `r ≤ 31`
//! that is three operations per voxel per axis whatever the radius; the sums never
//! subtract, so they carry no running-sum drift.
//!
//! The maps (all in [0, 1], 1 = unoccluded), with `v_x` the voxel's own value:
//! - CDF reconstruction (§3.2): `O = t^β`, `t = (v_x − v_min)/(v_max − v_min)`,
//!   `β = (E[v] − v_min)/(v_max − E[v])`; `O = 0` for `t ≤ 0`, 1 for `t ≥ 1`.
//! - Gaussian CDF (§3.3, Eq. 4): `O = ½(1 + erf((v_x − μ)/(σ√2)))` with Winitzki's
//!   `erf(x) ≈ sgn(x)·√(1 − exp(−x²(4/π + a x²)/(1 + a x²)))`, `a = 8(π−3)/(3π(4−π))`.
//! - Penner's baseline: Cantelli's one-tailed Chebyshev bound on `P(v ≤ v_x)`,
//!   `O = σ²/(σ² + (μ − v_x)²)` below the mean, 1 at or above it.
//!
//! Where the box is homogeneous (`v_max = v_min`, hence `σ² = 0`) every neighbour is
//! `≤ v_x`, so all three maps give exactly 1. A variance floor of 1e-12 keeps the
//! Gaussian and Penner maps finite where rounding leaves `E[v²] − E[v]²` at 0.

use crate::gpu::{
    Gpu, GpuError, bind_group, padded_row_bytes, read_buffer, readback_buffer, shaders,
    submit_compute, uniform_buffer, validated,
};
use crate::render::gpu::{GpuVolume, bake_lut};
use crate::render::texels::VolumeTexels;
use crate::tf::{Lut, TransferFunction};
use rayon::prelude::*;

/// Most outputs one segment (one GPU invocation) produces; bounds its private array.
pub const SEGMENT_MAX: usize = 64;

/// Identity of `min` / `max` in the passes (finite, so WGSL can write it too).
const BIG: f32 = 3.0e38;

/// Variance floor for the Gaussian and Penner maps.
pub const VARIANCE_FLOOR: f32 = 1e-12;

/// Winitzki's constant `a = 8(π − 3)/(3π(4 − π))` of the erf approximation.
pub const ERF_A: f32 = 0.140_012_3;

/// What the box statistics are taken of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StatisticSource {
    /// The texel value mapped linearly onto [0, 1] over the volume's range (the paper).
    #[default]
    Density,
    /// The transfer function's opacity (for one voxel of path length).
    Opacity,
}

impl StatisticSource {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "density" => Ok(Self::Density),
            "opacity" => Ok(Self::Opacity),
            o => Err(format!(
                "unknown statistic source {o:?} (available: density, opacity)"
            )),
        }
    }
}

/// Unit of the box radius in settings and on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RadiusUnit {
    #[default]
    Voxels,
    Mm,
}

/// Opacity modulation by local variance (Ruiz et al. §4.2): each sample's opacity is
/// multiplied by `min(σ²/σ²_max, 1)`, so homogeneous regions fade and boundaries stay.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OpacityModulation {
    /// `σ²_max`, in units of the source value squared (density normalised to [0, 1]).
    pub sigma2_max: f32,
    /// Box radius in voxels.
    pub radius: f32,
    pub source: StatisticSource,
}

impl Default for OpacityModulation {
    fn default() -> Self {
        OpacityModulation {
            // About the paper's σ²_max = 5 on 0…255 data is 8e-5; CT's wider range makes
            // a larger default read better.
            sigma2_max: 1e-3,
            radius: 10.0,
            source: StatisticSource::Density,
        }
    }
}

/// Which map to build from the statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AmbientMap {
    Penner,
    Cdf,
    Gauss,
    /// `σ² = E[v²] − E[v]²` itself, for opacity modulation (§4.2).
    Variance,
}

impl AmbientMap {
    /// Index used by `ambient_maps.wgsl`.
    fn code(self) -> u32 {
        match self {
            AmbientMap::Penner => 0,
            AmbientMap::Cdf => 1,
            AmbientMap::Gauss => 2,
            AmbientMap::Variance => 3,
        }
    }
}

/// Box radius in voxels per axis for `radius` in voxels, or in mm when `in_mm`
/// (rounded per axis, so anisotropic spacing gives a box that is square in mm).
pub fn radius_voxels(radius: f32, in_mm: bool, spacing: [f32; 3]) -> [u32; 3] {
    let r = if radius.is_finite() {
        radius.max(0.0)
    } else {
        0.0
    };
    std::array::from_fn(|i| {
        let s = spacing[i];
        let v = if in_mm && s > 0.0 { r / s } else { r };
        v.round().min(u16::MAX as f32) as u32
    })
}

/// How a texel becomes the source value `v`: `params = [a, b, entries − 1, opacity?]`;
/// density is `norm · a + b`, opacity interpolates `alpha` at `clamp(norm · a + b)`.
#[derive(Debug, Clone)]
pub struct Source {
    pub params: [f32; 4],
    pub alpha: Vec<f32>,
}

impl Source {
    pub fn new(texels: &VolumeTexels, tf: &TransferFunction, kind: StatisticSource) -> Self {
        match kind {
            StatisticSource::Density => {
                let (lo, hi) = texels.norm_range();
                let (a, b) = if hi > lo && hi.is_finite() && lo.is_finite() {
                    (1.0 / (hi - lo), -lo / (hi - lo))
                } else {
                    (0.0, 0.0)
                };
                Source {
                    params: [a, b, 0.0, 0.0],
                    alpha: vec![0.0],
                }
            }
            StatisticSource::Opacity => {
                // Opacity for one voxel of path, as the transfer function defines it.
                let lut = bake_lut(tf, texels, 1.0);
                Self::from_lut(texels, &lut)
            }
        }
    }

    /// Opacity source from an already baked LUT.
    pub fn from_lut(texels: &VolumeTexels, lut: &Lut) -> Self {
        let (a, b) = texels.lut_map(lut);
        Source {
            params: [a, b, (lut.rgba.len().max(2) - 1) as f32, 1.0],
            alpha: lut.rgba.iter().map(|e| e[3]).collect(),
        }
    }

    /// `v` for a normalised texel (CPU twin of `source_value` in the shaders).
    #[inline]
    pub fn value(&self, norm: f32) -> f32 {
        let p = &self.params;
        if p[3] == 0.0 {
            return norm * p[0] + p[1];
        }
        let t = (norm * p[0] + p[1]).clamp(0.0, p[2]);
        let i0 = t.floor() as usize;
        let i1 = (i0 + 1).min(p[2] as usize);
        let f = t - t.floor();
        self.alpha[i0] + (self.alpha[i1] - self.alpha[i0]) * f
    }

    /// `v` for every voxel, x fastest.
    pub fn values(&self, texels: &VolumeTexels) -> Vec<f32> {
        use crate::render::texels::TexelFormat;
        let b = &texels.bytes;
        // Decoded per format (the same numbers as `VolumeTexels::norm_at`).
        match texels.format {
            TexelFormat::R8Unorm => b
                .par_iter()
                .map(|&x| self.value(x as f32 / 255.0))
                .collect(),
            TexelFormat::R16Unorm => b
                .par_chunks_exact(2)
                .map(|c| self.value(u16::from_le_bytes([c[0], c[1]]) as f32 / 65535.0))
                .collect(),
            TexelFormat::R32Float => b
                .par_chunks_exact(4)
                .map(|c| self.value(f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
                .collect(),
        }
    }
}

/// Number of voxels of the cropped window `[i − r, i + r] ∩ [0, n)`.
#[inline]
pub fn window_count(i: usize, r: usize, n: usize) -> usize {
    (i + r).min(n - 1) - i.saturating_sub(r) + 1
}

/// Outputs per segment for radius `r`.
pub fn segment_len(r: usize) -> usize {
    (2 * r + 1).min(SEGMENT_MAX)
}

/// One segment of a line of `n` elements, each `elem` contiguous floats (1 for an
/// x-line, a row for y, a z-slice for z, so the CPU works on whole rows and slices at
/// once): writes the windows `[i − r, i + r]` of outputs `i ∈ [c, c + L)` into `out`.
/// The same runs in the same order as `main` in `box_stats.wgsl`: suffixes
/// `S = op(v, S)` backward from the pivot, prefixes `P = op(P, v)` forward, `op(S, P)`.
#[allow(
    clippy::too_many_arguments,
    reason = "one flat kernel; a struct would hide the loop it mirrors"
)]
fn segment<F: Fn(f32, f32) -> f32>(
    input: &[f32],
    out: &mut [f32],
    acc: &mut [f32],
    n: usize,
    elem: usize,
    r: usize,
    c: usize,
    (op, identity): (F, f32),
) {
    let outs = segment_len(r).min(n - c);
    let (ci, ri, ni) = (c as i64, r as i64, n as i64);
    let (m, first) = (ci + ri, ci - ri);
    // S[j] for j = a − first; the run reaches j ≤ 2r − 1, so S[2r] (when L = 2r + 1) is
    // the empty suffix.
    for j in (2 * r).min(outs)..outs {
        out[j * elem..(j + 1) * elem].fill(identity);
    }
    acc.fill(identity);
    let mut a = m - 1;
    while a >= first {
        // Outside the line the run is cropped: a < 0 repeats S[0], a ≥ n adds nothing.
        if a >= 0 && a < ni {
            let src = &input[a as usize * elem..][..elem];
            for (x, &v) in acc.iter_mut().zip(src) {
                *x = op(v, *x);
            }
        }
        let j = a - first;
        if j < outs as i64 {
            out[j as usize * elem..][..elem].copy_from_slice(acc);
        }
        a -= 1;
    }
    acc.fill(identity);
    for j in 0..outs {
        let b = m as usize + j;
        if b < n {
            let src = &input[b * elem..][..elem];
            for (x, &v) in acc.iter_mut().zip(src) {
                *x = op(*x, v);
            }
        }
        for (o, &p) in out[j * elem..][..elem].iter_mut().zip(acc.iter()) {
            *o = op(*o, p);
        }
    }
}

/// [`segment`] for single-float elements (the x pass), without the per-element slices.
fn segment_scalar<F: Fn(f32, f32) -> f32>(
    input: &[f32],
    out: &mut [f32],
    r: usize,
    c: usize,
    (op, identity): (F, f32),
) {
    let n = input.len();
    let outs = segment_len(r).min(n - c);
    let (ci, ri, ni) = (c as i64, r as i64, n as i64);
    let (m, first) = (ci + ri, ci - ri);
    for o in out.iter_mut().take(outs).skip((2 * r).min(outs)) {
        *o = identity;
    }
    let mut acc = identity;
    let mut a = m - 1;
    while a >= first {
        if a >= 0 && a < ni {
            acc = op(input[a as usize], acc);
        }
        let j = a - first;
        if j < outs as i64 {
            out[j as usize] = acc;
        }
        a -= 1;
    }
    let mut acc = identity;
    for (j, o) in out.iter_mut().enumerate().take(outs) {
        let b = m as usize + j;
        if b < n {
            acc = op(acc, input[b]);
        }
        *o = op(*o, acc);
    }
}

/// Box statistics over the cropped box of every voxel, x fastest, one array per
/// statistic.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxStats {
    pub dims: [usize; 3],
    pub radius: [u32; 3],
    pub min: Vec<f32>,
    pub max: Vec<f32>,
    /// Σv and Σv² (divide by [`BoxStats::count`] for the means).
    pub sum: Vec<f32>,
    pub sum_sq: Vec<f32>,
}

/// `(v_min, v_max, E[v], E[v²])` of one voxel's box.
pub type Moments = [f32; 4];

impl BoxStats {
    /// Voxels in the box of voxel `(x, y, z)`.
    pub fn count(&self, x: usize, y: usize, z: usize) -> usize {
        let r = self.radius.map(|r| r as usize);
        window_count(x, r[0], self.dims[0])
            * window_count(y, r[1], self.dims[1])
            * window_count(z, r[2], self.dims[2])
    }

    /// `(v_min, v_max, Σv, Σv²)` of voxel `i`.
    pub fn raw(&self, i: usize) -> [f32; 4] {
        [self.min[i], self.max[i], self.sum[i], self.sum_sq[i]]
    }

    /// Moments of voxel `i` (x fastest). Mirrors `main` in `ambient_maps.wgsl`.
    pub fn moments(&self, i: usize) -> Moments {
        let [nx, ny, _] = self.dims;
        let n = self.count(i % nx, (i / nx) % ny, i / (nx * ny)) as f32;
        [
            self.min[i],
            self.max[i],
            self.sum[i] / n,
            self.sum_sq[i] / n,
        ]
    }
}

/// One statistic through the three separable passes (x, then y, then z).
fn separable<F: Fn(f32, f32) -> f32 + Copy + Sync>(
    values: &[f32],
    dims: [usize; 3],
    r: [usize; 3],
    op: (F, f32),
) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let slice = nx * ny;
    // x: one chunk per line.
    let mut a = vec![0.0; slice * nz];
    a.par_chunks_mut(nx).enumerate().for_each(|(line, out)| {
        let input = &values[line * nx..(line + 1) * nx];
        let len = segment_len(r[0]);
        for c in (0..nx).step_by(len) {
            let end = (c + len).min(nx);
            segment_scalar(input, &mut out[c..end], r[0], c, op);
        }
    });
    // y: one chunk per z-slice; elements are rows.
    let mut b = vec![0.0; slice * nz];
    b.par_chunks_mut(slice).enumerate().for_each(|(z, out)| {
        let input = &a[z * slice..(z + 1) * slice];
        let len = segment_len(r[1]);
        let mut acc = vec![0.0; nx];
        for c in (0..ny).step_by(len) {
            let end = (c + len).min(ny);
            segment(
                input,
                &mut out[c * nx..end * nx],
                &mut acc,
                ny,
                nx,
                r[1],
                c,
                op,
            );
        }
    });
    // z: one chunk per segment of z-slices; elements are slices.
    let len = segment_len(r[2]);
    a.par_chunks_mut(slice * len)
        .enumerate()
        .for_each(|(k, out)| {
            let mut acc = vec![0.0; slice];
            segment(&b, out, &mut acc, nz, slice, r[2], k * len, op);
        });
    a
}

/// CPU twin of the three `box_stats.wgsl` passes, on rayon. Each statistic runs on its
/// own arrays, whole rows and slices at a time, so the loops vectorise.
pub fn box_stats_cpu(values: &[f32], dims: [usize; 3], radius: [u32; 3]) -> BoxStats {
    let r = radius.map(|r| r as usize);
    let squares: Vec<f32> = values.par_iter().map(|v| v * v).collect();
    let ((min, max), (sum, sum_sq)) = rayon::join(
        || {
            rayon::join(
                || separable(values, dims, r, (f32::min, BIG)),
                || separable(values, dims, r, (f32::max, -BIG)),
            )
        },
        || {
            rayon::join(
                || separable(values, dims, r, (|a, b| a + b, 0.0)),
                || separable(&squares, dims, r, (|a, b| a + b, 0.0)),
            )
        },
    );
    BoxStats {
        dims,
        radius,
        min,
        max,
        sum,
        sum_sq,
    }
}

/// Winitzki's approximation of erf (Ruiz et al. §3.3).
#[inline]
pub fn erf_approx(x: f32) -> f32 {
    let x2 = x * x;
    let ax2 = ERF_A * x2;
    let e = (1.0 - (-x2 * (4.0 / std::f32::consts::PI + ax2) / (1.0 + ax2)).exp())
        .max(0.0)
        .sqrt();
    if x < 0.0 { -e } else { e }
}

/// One map value from the moments and the voxel's own value. Mirrors `ambient` in
/// `ambient_maps.wgsl`.
pub fn ambient(map: AmbientMap, v_x: f32, m: Moments) -> f32 {
    let [v_min, v_max, mean, mean_sq] = m;
    let variance = (mean_sq - mean * mean).max(0.0);
    if map == AmbientMap::Variance {
        return variance;
    }
    let delta = v_max - v_min;
    if delta <= 0.0 {
        return 1.0;
    }
    let mean = mean.clamp(v_min, v_max);
    let var = variance.max(VARIANCE_FLOOR);
    match map {
        AmbientMap::Cdf => {
            let t = (v_x - v_min) / delta;
            if t <= 0.0 {
                0.0
            } else if t >= 1.0 {
                1.0
            } else {
                let below = v_max - mean;
                if below <= 0.0 {
                    return 0.0;
                }
                t.powf((mean - v_min) / below)
            }
        }
        AmbientMap::Gauss => {
            let x = (v_x - mean) / (var.sqrt() * std::f32::consts::SQRT_2);
            0.5 * (1.0 + erf_approx(x))
        }
        AmbientMap::Penner => {
            let d = mean - v_x;
            if d <= 0.0 { 1.0 } else { var / (var + d * d) }
        }
        AmbientMap::Variance => variance,
    }
}

/// A map from statistics and source values on the CPU (rayon), x fastest.
pub fn map_cpu(map: AmbientMap, stats: &BoxStats, values: &[f32]) -> Vec<f32> {
    let [nx, ny, nz] = stats.dims;
    let r = stats.radius.map(|r| r as usize);
    let counts = |axis: usize, n: usize| -> Vec<usize> {
        (0..n).map(|i| window_count(i, r[axis], n)).collect()
    };
    let (cx, cy, cz) = (counts(0, nx), counts(1, ny), counts(2, nz));
    let mut out = vec![0.0; values.len()];
    out.par_chunks_mut(nx).enumerate().for_each(|(line, row)| {
        let (y, z) = (line % ny, line / ny);
        let base = line * nx;
        for (x, o) in row.iter_mut().enumerate() {
            // As the shader: the count as an integer product, then one f32 division each.
            let n = (cx[x] * cy[y] * cz[z]) as f32;
            let i = base + x;
            let m = [
                stats.min[i],
                stats.max[i],
                stats.sum[i] / n,
                stats.sum_sq[i] / n,
            ];
            *o = ambient(map, values[i], m);
        }
    });
    out
}

/// Everything on the CPU: source values, statistics, then each of `maps`.
pub fn compute_cpu(
    texels: &VolumeTexels,
    source: &Source,
    radius: [u32; 3],
    maps: &[AmbientMap],
) -> Vec<Vec<f32>> {
    let values = source.values(texels);
    let stats = box_stats_cpu(&values, texels.dims, radius);
    maps.iter().map(|&m| map_cpu(m, &stats, &values)).collect()
}

/// Opacity modulation factor (§4.2): `min(σ²/σ²_max, 1)` per voxel.
pub fn modulation(variance: &[f32], sigma2_max: f32) -> Vec<f32> {
    let s = if sigma2_max > 0.0 { sigma2_max } else { 1e-30 };
    variance.iter().map(|&v| (v / s).clamp(0.0, 1.0)).collect()
}

/// Uniforms of `box_stats.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct BoxParams {
    /// x, y, z, axis (0, 1, 2).
    dims: [u32; 4],
    /// r along this axis, segment length L, segments per line, first pass (1) or not.
    run: [u32; 4],
    /// Source map: a, b, entries − 1, opacity (1) or density (0).
    source: [f32; 4],
    /// Invocations in this pass, invocations per dispatch row, lines.
    count: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<BoxParams>() == 64);

/// Uniforms of `ambient_maps.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct MapParams {
    /// x, y, z, map code.
    dims: [u32; 4],
    /// Box radius per axis.
    radius: [u32; 4],
    source: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<MapParams>() == 48);

/// Long-lived state of the filter stage: both pipelines, built once per device.
#[derive(Debug)]
pub struct FilterGpu {
    box_pipeline: wgpu::ComputePipeline,
    map_pipeline: wgpu::ComputePipeline,
}

fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    label: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

fn stats_texture(device: &wgpu::Device, label: &str, dims: [u32; 3]) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: extent(dims),
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

fn extent(dims: [u32; 3]) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width: dims[0],
        height: dims[1],
        depth_or_array_layers: dims[2],
    }
}

/// Copies a whole 3-D texture into `buffer` with rows of `row` bytes.
fn copy_out(
    encoder: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    buffer: &wgpu::Buffer,
    row: u32,
    dims: [u32; 3],
) {
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(dims[1]),
            },
        },
        extent(dims),
    );
}

/// Strips the row padding of a read-back texture with `texel` bytes per texel.
fn unpad<T: bytemuck::Pod>(bytes: &[u8], row: u32, width: u32, texel: u32) -> Vec<T> {
    let mut out = Vec::new();
    for r in bytes.chunks_exact(row as usize) {
        out.extend(bytemuck::pod_collect_to_vec::<u8, T>(
            &r[..(width * texel) as usize],
        ));
    }
    out
}

/// The statistics on the GPU: the final (x, y, z-filtered) texture and the LUT buffer.
struct GpuStats {
    stats: wgpu::Texture,
    lut: wgpu::Buffer,
}

impl FilterGpu {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let box_module = shaders::module(device, "box_stats.wgsl")?;
        let map_module = shaders::module(device, "ambient_maps.wgsl")?;
        validated(device, "Filter::new", || FilterGpu {
            box_pipeline: pipeline(device, &box_module, "Filter::box_stats"),
            map_pipeline: pipeline(device, &map_module, "Filter::ambient_maps"),
        })
    }

    /// Runs the three separable passes (x: volume → a, y: a → b, z: b → a), one
    /// submission each.
    fn stats(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        source: &Source,
        radius: [u32; 3],
    ) -> Result<GpuStats, GpuError> {
        let device = &gpu.device;
        let dims = vol.texels.dims.map(|d| d as u32);
        let [nx, ny, nz] = dims;
        let (tex_a, tex_b, lut) = validated(device, "Filter::buffers", || {
            let lut = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Filter::lut_alpha"),
                size: (source.alpha.len().max(4) * 4) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            gpu.queue
                .write_buffer(&lut, 0, bytemuck::cast_slice(&source.alpha));
            (
                stats_texture(device, "Filter::stats_a", dims),
                stats_texture(device, "Filter::stats_b", dims),
                lut,
            )
        })?;
        let view_a = tex_a.create_view(&Default::default());
        let view_b = tex_b.create_view(&Default::default());
        let passes = [
            (0usize, &view_b, &view_a),
            (1, &view_a, &view_b),
            (2, &view_b, &view_a),
        ];
        for (axis, input, output) in passes {
            let r = radius[axis];
            let len = segment_len(r as usize) as u32;
            let n = dims[axis];
            let segments = n.div_ceil(len);
            let lines = nx * ny * nz / n;
            let count = segments * lines;
            let groups = count.div_ceil(64);
            let gx = groups.min(65535);
            let gy = groups.div_ceil(gx);
            let p = BoxParams {
                dims: [nx, ny, nz, axis as u32],
                run: [r, len, segments, u32::from(axis == 0)],
                source: source.params,
                count: [count, gx * 64, lines, 0],
            };
            validated(device, "Filter::box_stats", || {
                let uniforms = uniform_buffer(
                    device,
                    &gpu.queue,
                    "Filter::box_params",
                    bytemuck::bytes_of(&p),
                );
                let group = bind_group(
                    device,
                    "Filter::box_bind_group",
                    &self.box_pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(vol.volume_view()),
                        lut.as_entire_binding(),
                        wgpu::BindingResource::TextureView(input),
                        wgpu::BindingResource::TextureView(output),
                    ],
                );
                submit_compute(
                    device,
                    &gpu.queue,
                    "Filter::box_stats",
                    &self.box_pipeline,
                    &group,
                    [gx, gy, 1],
                    |_| {},
                );
            })?;
        }
        Ok(GpuStats { stats: tex_a, lut })
    }

    /// Statistics and then each of `maps` for an uploaded volume, read back x fastest.
    /// The statistics stay on the GPU between the maps.
    pub fn compute(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        source: &Source,
        radius: [u32; 3],
        maps: &[AmbientMap],
    ) -> Result<Vec<Vec<f32>>, GpuError> {
        let device = &gpu.device;
        let dims = vol.texels.dims.map(|d| d as u32);
        let [nx, ny, nz] = dims;
        let row = padded_row_bytes(nx * 4);
        let st = self.stats(gpu, vol, source, radius)?;
        let stats_view = st.stats.create_view(&Default::default());
        let (out, readback) = validated(device, "Filter::map_buffers", || {
            let out = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("Filter::map"),
                size: extent(dims),
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R32Float,
                usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let size = row as u64 * ny as u64 * nz as u64;
            (out, readback_buffer(device, "Filter::readback", size))
        })?;
        let out_view = out.create_view(&Default::default());
        let mut result = Vec::with_capacity(maps.len());
        for &map in maps {
            let p = MapParams {
                dims: [nx, ny, nz, map.code()],
                radius: [radius[0], radius[1], radius[2], 0],
                source: source.params,
            };
            validated(device, "Filter::ambient_map", || {
                let uniforms = uniform_buffer(
                    device,
                    &gpu.queue,
                    "Filter::map_params",
                    bytemuck::bytes_of(&p),
                );
                let group = bind_group(
                    device,
                    "Filter::map_bind_group",
                    &self.map_pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(vol.volume_view()),
                        st.lut.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&stats_view),
                        wgpu::BindingResource::TextureView(&out_view),
                    ],
                );
                submit_compute(
                    device,
                    &gpu.queue,
                    "Filter::ambient_map",
                    &self.map_pipeline,
                    &group,
                    [nx.div_ceil(8), ny.div_ceil(8), nz],
                    |encoder| copy_out(encoder, &out, &readback, row, dims),
                );
            })?;
            let bytes = read_buffer(device, &readback, "Filter::readback")?;
            result.push(unpad::<f32>(&bytes, row, nx, 4));
        }
        Ok(result)
    }

    /// The raw statistics `(v_min, v_max, Σv, Σv²)` as the GPU computes them (for tests
    /// against the CPU twin and brute force).
    pub fn box_stats(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        source: &Source,
        radius: [u32; 3],
    ) -> Result<BoxStats, GpuError> {
        let device = &gpu.device;
        let dims = vol.texels.dims.map(|d| d as u32);
        let [nx, ny, nz] = dims;
        let row = padded_row_bytes(nx * 16);
        let st = self.stats(gpu, vol, source, radius)?;
        let readback = validated(device, "Filter::stats_readback", || {
            let rb = readback_buffer(
                device,
                "Filter::stats_readback",
                row as u64 * ny as u64 * nz as u64,
            );
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("Filter::stats_copy"),
            });
            copy_out(&mut encoder, &st.stats, &rb, row, dims);
            gpu.queue.submit([encoder.finish()]);
            rb
        })?;
        let bytes = read_buffer(device, &readback, "Filter::stats_readback")?;
        let raw = unpad::<[f32; 4]>(&bytes, row, nx, 16);
        let channel = |k: usize| raw.iter().map(|v| v[k]).collect();
        Ok(BoxStats {
            dims: vol.texels.dims,
            radius,
            min: channel(0),
            max: channel(1),
            sum: channel(2),
            sum_sq: channel(3),
        })
    }
}
