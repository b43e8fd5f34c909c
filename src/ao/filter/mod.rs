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

use crate::gpu::dispatch::{Grid, SlabDispatch, fold_linear};
use crate::gpu::{
    Gpu, GpuError, copy_texture_out, read_buffer, storage_buffer, submit_compute_with, texture_3d,
    texture_readback, uniform_group, unpad, validated,
};
use crate::sample::bake_lut;
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::texels::gpu_data::VolumeMap;
use crate::texels::reader::{Reading, SegmentBindings, VOLUME_GROUP};
use crate::texels::segments::SegmentTexels;
use crate::tf::{Lut, TransferFunction};
use rayon::prelude::*;

mod cpu;

pub use cpu::{FilterCpu, box_stats_cpu, compute_cpu, map_cpu};

/// Most outputs one segment (one GPU invocation) produces; bounds its private array.
pub const SEGMENT_MAX: usize = 64;

/// Identity of `min` / `max` in the passes (finite, so WGSL can write it too).
pub(crate) const BIG: f32 = 3.0e38;

/// Variance floor for the Gaussian and Penner maps.
pub const VARIANCE_FLOOR: f32 = 1e-12;

/// Winitzki's constant `a = 8(π − 3)/(3π(4 − π))` of the erf approximation.
pub const ERF_A: f32 = 0.140_012_3;

pub use super::settings::{OpacityModulation, RadiusUnit, StatisticSource};

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
    /// A segmentation's weight per voxel, on the opacity (the GPU reads the volume's
    /// own: `source_of_voxel`); `None`: 1.
    pub weights: Option<std::sync::Arc<Vec<f32>>>,
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
                    weights: None,
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
            weights: None,
        }
    }

    /// The same with `segments`' weights on the opacity (the CPU twin of the shaders'
    /// `source_of_voxel` on a volume with a segmentation).
    pub fn with_segments(self, segments: Option<&SegmentTexels>) -> Self {
        let weights = segments
            .map(|s| std::sync::Arc::new(s.look.iter().map(|l| l[3] as f32 / 255.0).collect()));
        Source { weights, ..self }
    }

    /// How the shaders read the source (`volume.wgsl`): the value map and the opacity
    /// table share `(a, b)`.
    pub fn map(&self) -> VolumeMap {
        let [a, b, last, _] = self.params;
        VolumeMap {
            lut: [a, b, last, 0.0],
            value: [a, b, 0.0, 0.0],
        }
    }

    /// The opacity table as the reader binds it (its colour unused).
    pub fn table(&self) -> Vec<[f32; 4]> {
        self.alpha.iter().map(|&a| [0.0, 0.0, 0.0, a]).collect()
    }

    /// What the box-statistics and ambient-map passes bind to read `vol` through
    /// `table` ([`Self::table`] on the GPU): its voxels, unfiltered.
    fn reading<'a>(&self, vol: &'a GpuVolume, table: &'a wgpu::Buffer) -> Reading<'a> {
        Reading {
            texels: vol.volume_view(),
            sampler: None,
            lut: Some((self.map(), table)),
            segments: SegmentBindings::Look(&vol.segments),
        }
    }

    /// `v` for a normalised texel (CPU twin of `source_value` in the shaders).
    #[inline(always)]
    pub fn value(&self, norm: f32) -> f32 {
        let p = &self.params;
        if p[3] == 0.0 {
            return norm * p[0] + p[1];
        }
        let t = (norm * p[0] + p[1]).clamp(0.0, p[2]);
        // t ≥ 0, so truncation is floor (and no libm call).
        let i0 = t as usize;
        let i1 = (i0 + 1).min(p[2] as usize);
        let f = t - i0 as f32;
        self.alpha[i0] + (self.alpha[i1] - self.alpha[i0]) * f
    }

    /// `v` for every voxel, x fastest.
    pub fn values(&self, texels: &VolumeTexels) -> Vec<f32> {
        let mut out = vec![0.0; texels.dims.iter().product()];
        out.par_chunks_mut(1 << 16)
            .enumerate()
            .for_each(|(k, run)| self.decode(texels, k << 16, run));
        out
    }

    /// `v` of voxels `start..start + out.len()` (x fastest) into `out`, decoded per
    /// format (the same numbers as `VolumeTexels::norm_at`).
    #[inline(always)]
    pub fn decode(&self, texels: &VolumeTexels, start: usize, out: &mut [f32]) {
        let bytes = &texels.bytes[start * texels.format.bytes()..];
        self.decode_texels(texels, bytes, out);
        if let (Some(w), true) = (&self.weights, self.params[3] != 0.0) {
            for (o, w) in out.iter_mut().zip(&w[start..]) {
                *o *= w;
            }
        }
    }

    /// The texels of `bytes` decoded per format.
    #[inline(always)]
    fn decode_texels(&self, texels: &VolumeTexels, bytes: &[u8], out: &mut [f32]) {
        use crate::texels::TexelFormat;
        match texels.format {
            TexelFormat::R8Unorm => self.decode_as(bytes, out, |[b]| b as f32 / 255.0),
            TexelFormat::R16Unorm => {
                self.decode_as(bytes, out, |b| u16::from_le_bytes(b) as f32 / 65535.0)
            }
            TexelFormat::R32Float => self.decode_as(bytes, out, f32::from_le_bytes),
        }
    }

    /// [`Self::decode`] for texels of `N` bytes read by `norm`; density is one
    /// multiply-add per texel, kept free of the LUT branch so that the loop vectorises.
    #[inline(always)]
    fn decode_as<const N: usize>(
        &self,
        bytes: &[u8],
        out: &mut [f32],
        norm: impl Fn([u8; N]) -> f32,
    ) {
        let texels = bytes.as_chunks::<N>().0.iter().take(out.len());
        let [a, b, _, opacity] = self.params;
        if opacity == 0.0 {
            for (o, &t) in out.iter_mut().zip(texels) {
                *o = norm(t) * a + b;
            }
        } else {
            for (o, &t) in out.iter_mut().zip(texels) {
                *o = self.value(norm(t));
            }
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

/// `max(a, b)` as one instruction (`f32::max` also orders NaNs, which costs two more;
/// the maps never see a NaN).
#[inline(always)]
fn max_of(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `min(a, b)`, as [`max_of`].
#[inline(always)]
fn min_of(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `2^y`, branch-free so that loops over it vectorise: `y = i + f` with `i` the nearest
/// integer and `f ∈ [−½, ½]`, `2^f` by its degree-7 Taylor polynomial (relative error
/// below 1e-7 before rounding) and `2^i` by the exponent bits. `y` is clamped to
/// [−125, 127], and results below 2^−125 flush to 0, so none is subnormal (slow on x86).
#[inline(always)]
pub fn exp2_approx(y: f32) -> f32 {
    // Adding 1.5 · 2^23 rounds to an integer, which then sits in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let tiny = y < -125.0;
    let y = min_of(max_of(y, -125.0), 127.0);
    let shifted = y + ROUND;
    let i = shifted.to_bits() as i32 - ROUND.to_bits() as i32;
    let l = (y - (shifted - ROUND)) * std::f32::consts::LN_2;
    let p = 1.0
        + l * (1.0
            + l * (0.5
                + l * (1.0 / 6.0
                    + l * (1.0 / 24.0 + l * (1.0 / 120.0 + l * (1.0 / 720.0 + l / 5040.0))))));
    let power = p * f32::from_bits(((i + 127) << 23) as u32);
    if tiny { 0.0 } else { power }
}

/// `log2(x)` for finite `x > 0` (subnormals included), branch-free: `x = m · 2^e` with
/// `m ∈ [√½, √2)` and `ln m = 2 atanh(s)`, `s = (m − 1)/(m + 1)`, by its series to `s¹¹`
/// (`|s| ≤ 0.172`: relative error below 1e-9 before rounding).
#[inline(always)]
pub fn log2_approx(x: f32) -> f32 {
    // Subnormals are scaled by 2^64 first.
    let tiny = x < f32::MIN_POSITIVE;
    let x = if tiny {
        x * 18_446_744_073_709_551_616.0
    } else {
        x
    };
    let bits = x.to_bits() as i32;
    let m = f32::from_bits(((bits & 0x007f_ffff) | 0x3f80_0000) as u32);
    let big = m > std::f32::consts::SQRT_2;
    let m = if big { m * 0.5 } else { m };
    let e = ((bits >> 23) & 0xff) - 127 + i32::from(big) - if tiny { 64 } else { 0 };
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let ln_m = 2.0
        * s
        * (1.0
            + s2 * (1.0 / 3.0
                + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0 + s2 / 11.0)))));
    e as f32 + ln_m * std::f32::consts::LOG2_E
}

/// Winitzki's approximation of erf (Ruiz et al. §3.3).
#[inline(always)]
pub fn erf_approx(x: f32) -> f32 {
    let x2 = x * x;
    let ax2 = ERF_A * x2;
    let arg = -x2 * (4.0 / std::f32::consts::PI + ax2) / (1.0 + ax2);
    let e = (1.0 - exp2_approx(arg * std::f32::consts::LOG2_E))
        .max(0.0)
        .sqrt();
    if x < 0.0 { -e } else { e }
}

// The maps, one function each, written with selects instead of early returns so that
// loops over them vectorise. `m` is `(v_min, v_max, E[v], E[v²])`; a map ignores the
// moments it does not read.

/// CDF reconstruction (§3.2): `t^β`; 1 where the box is homogeneous.
#[inline(always)]
fn cdf(v_x: f32, [v_min, v_max, mean, _]: Moments) -> f32 {
    let delta = v_max - v_min;
    let mean = min_of(max_of(mean, v_min), v_max);
    let t = (v_x - v_min) / delta;
    let below = v_max - mean;
    let power = exp2_approx((mean - v_min) / below * log2_approx(t));
    let o = if below <= 0.0 { 0.0 } else { power };
    let o = if t >= 1.0 { 1.0 } else { o };
    let o = if t <= 0.0 { 0.0 } else { o };
    if delta <= 0.0 { 1.0 } else { o }
}

/// `E[v²] − E[v]²`, never negative.
#[inline(always)]
fn variance([_, _, mean, mean_sq]: Moments) -> f32 {
    max_of(mean_sq - mean * mean, 0.0)
}

/// Gaussian CDF (§3.3, Eq. 4), `½(1 + erf(x))` with `x = d/(σ√2)`, `d = v_x − μ`, and
/// Winitzki's erf ([`erf_approx`]) rearranged: with `D = d²` and `V = 2σ²`, `x² = D/V`
/// and its exponent `−x²(4/π + a x²)/(1 + a x²) = −D(4V/π + aD)/(V(V + aD))`, one
/// division and no square root. 1 where the box is homogeneous.
#[inline(always)]
fn gauss(v_x: f32, m: Moments) -> f32 {
    let [v_min, v_max, mean, _] = m;
    let mean = min_of(max_of(mean, v_min), v_max);
    let big_v = 2.0 * max_of(variance(m), VARIANCE_FLOOR);
    let d = v_x - mean;
    let big_d = d * d;
    let ad = ERF_A * big_d;
    let arg = -big_d * (4.0 / std::f32::consts::PI * big_v + ad) / (big_v * (big_v + ad));
    let e = max_of(1.0 - exp2_approx(arg * std::f32::consts::LOG2_E), 0.0).sqrt();
    let o = 0.5 * (1.0 + if d < 0.0 { -e } else { e });
    if v_max - v_min <= 0.0 { 1.0 } else { o }
}

/// Penner's one-tailed Chebyshev bound; 1 where the box is homogeneous.
#[inline(always)]
fn penner(v_x: f32, m: Moments) -> f32 {
    let [v_min, v_max, mean, _] = m;
    let mean = min_of(max_of(mean, v_min), v_max);
    let var = max_of(variance(m), VARIANCE_FLOOR);
    // Below the mean only: at or above it the bound is var / var = 1 exactly.
    let d = max_of(mean - v_x, 0.0);
    let o = var / (var + d * d);
    if v_max - v_min <= 0.0 { 1.0 } else { o }
}

/// One map value from the moments and the voxel's own value. Mirrors `ambient` in
/// `ambient_maps.wgsl`, except that `pow` and `exp` are [`exp2_approx`] and
/// [`log2_approx`] (within 1e-6 of the exact functions), which vectorise.
pub fn ambient(map: AmbientMap, v_x: f32, m: Moments) -> f32 {
    match map {
        AmbientMap::Penner => penner(v_x, m),
        AmbientMap::Cdf => cdf(v_x, m),
        AmbientMap::Gauss => gauss(v_x, m),
        AmbientMap::Variance => variance(m),
    }
}

/// [`ambient`] over a run of voxels: `values` are the voxels' own values, `stats` the
/// runs of `(v_min, v_max, Σv, Σv²)` (a map's unread statistics may be empty), and the
/// box of voxel `i` holds `counts[i]` voxels (the integer rounded to f32 once, as the
/// shader does).
#[inline(always)]
pub(crate) fn ambient_run(
    map: AmbientMap,
    values: &[f32],
    stats: [&[f32]; 4],
    counts: &[f32],
    out: &mut [f32],
) {
    // An unread statistic's run is replaced by any run of the right length, so that one
    // loop serves every map.
    let stats = stats.map(|s| if s.is_empty() { values } else { s });
    #[allow(
        clippy::redundant_closure,
        reason = "a closure is inlined into the loop, a function item passed as a value was not, and only then does the loop vectorise"
    )]
    match map {
        AmbientMap::Penner => map_loop(|v, m| penner(v, m), values, stats, counts, out),
        AmbientMap::Cdf => map_loop(|v, m| cdf(v, m), values, stats, counts, out),
        AmbientMap::Gauss => map_loop(|v, m| gauss(v, m), values, stats, counts, out),
        AmbientMap::Variance => map_loop(|_, m| variance(m), values, stats, counts, out),
    }
}

/// The loop of [`ambient_run`], monomorphised per map so that it vectorises.
#[inline(always)]
fn map_loop(
    f: impl Fn(f32, Moments) -> f32,
    values: &[f32],
    [min, max, sum, sum_sq]: [&[f32]; 4],
    counts: &[f32],
    out: &mut [f32],
) {
    let stats = min.iter().zip(max).zip(sum.iter().zip(sum_sq)).zip(counts);
    for ((o, &v), (((&lo, &hi), (&s, &s2)), &n)) in out.iter_mut().zip(values).zip(stats) {
        *o = f(v, [lo, hi, s / n, s2 / n]);
    }
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
    dims: [u32; 3],
    /// The axis of this pass (0, 1, 2).
    axis: u32,
    /// r along this axis.
    radius: u32,
    /// Segment length L and segments per line.
    segment_len: u32,
    segments: u32,
    /// 1 for the first pass (it reads the volume), 0 after.
    first: u32,
    /// Source map: a, b, entries − 1, opacity (1) or density (0).
    source: [f32; 4],
    /// Invocations in this pass, invocations per row of workgroups, lines.
    invocations: u32,
    row_stride: u32,
    lines: u32,
    _pad: u32,
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
    box_stage: crate::gpu::Segmentable,
    map_stage: crate::gpu::Segmentable,
}

fn stats_texture(device: &wgpu::Device, label: &str, dims: [u32; 3]) -> wgpu::Texture {
    texture_3d(
        device,
        label,
        dims,
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
    )
}

struct GpuStats {
    stats: wgpu::Texture,
    lut: wgpu::Buffer,
}

impl crate::gpu::Stage for FilterGpu {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        use crate::gpu::Segmentable;
        Ok(FilterGpu {
            box_stage: Segmentable::new(device, "Filter::box_stats", "box_stats.wgsl", &[])?,
            map_stage: Segmentable::new(device, "Filter::ambient_maps", "ambient_maps.wgsl", &[])?,
        })
    }
}

impl FilterGpu {
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
        let box_pipeline = &self.box_stage.get(device, vol.segments.on)?.pipeline;
        let dims = vol.texels.dims.map(|d| d as u32);
        let [nx, ny, nz] = dims;
        let (tex_a, tex_b, lut) = validated(device, "Filter::buffers", || {
            let lut = storage_buffer(
                gpu,
                "Filter::lut",
                bytemuck::cast_slice(&source.table()),
                wgpu::BufferUsages::empty(),
            );
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
            let (groups, row_stride) = fold_linear(count);
            let p = BoxParams {
                dims,
                axis: axis as u32,
                radius: r,
                segment_len: len,
                segments,
                first: u32::from(axis == 0),
                source: source.params,
                invocations: count,
                row_stride,
                lines,
                _pad: 0,
            };
            validated(device, "Filter::box_stats", || {
                let (_uniforms, group) = uniform_group(
                    gpu,
                    "Filter::box",
                    box_pipeline,
                    &p,
                    &[
                        wgpu::BindingResource::TextureView(input),
                        wgpu::BindingResource::TextureView(output),
                    ],
                );
                let volume = source
                    .reading(vol, &lut)
                    .group_of(gpu, "Filter::box", box_pipeline);
                submit_compute_with(
                    device,
                    &gpu.queue,
                    "Filter::box_stats",
                    box_pipeline,
                    &[(0, &group), (VOLUME_GROUP, &volume)],
                    groups,
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
        let st = self.stats(gpu, vol, source, radius)?;
        let map_pipeline = &self.map_stage.get(device, vol.segments.on)?.pipeline;
        let stats_view = st.stats.create_view(&Default::default());
        let (out, readback, row) = validated(device, "Filter::map_buffers", || {
            let out = crate::gpu::output_volume(device, "Filter::map", dims);
            let (readback, row) = texture_readback(device, "Filter::readback", dims, 4);
            (out, readback, row)
        })?;
        // One dispatch over the whole volume (each invocation reads a box from the stats).
        let whole_volume = SlabDispatch::whole(dims, Grid::Tiles)
            .slabs()
            .next()
            .map_or([1, 1, 1], |s| s.groups);
        let out_view = out.create_view(&Default::default());
        let mut result = Vec::with_capacity(maps.len());
        for &map in maps {
            let p = MapParams {
                dims: [nx, ny, nz, map.code()],
                radius: [radius[0], radius[1], radius[2], 0],
                source: source.params,
            };
            validated(device, "Filter::ambient_map", || {
                let (_uniforms, group) = uniform_group(
                    gpu,
                    "Filter::map",
                    map_pipeline,
                    &p,
                    &[
                        wgpu::BindingResource::TextureView(&stats_view),
                        wgpu::BindingResource::TextureView(&out_view),
                    ],
                );
                let volume = source.reading(vol, &st.lut);
                let volume = volume.group_of(gpu, "Filter::map", map_pipeline);
                submit_compute_with(
                    device,
                    &gpu.queue,
                    "Filter::ambient_map",
                    map_pipeline,
                    &[(0, &group), (VOLUME_GROUP, &volume)],
                    whole_volume,
                    |encoder| copy_texture_out(encoder, &out, &readback, row, dims),
                );
            })?;
            let bytes = read_buffer(device, &readback, "Filter::readback")?;
            result.push(unpad::<f32>(&bytes, row, nx));
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
        let nx = dims[0];
        let st = self.stats(gpu, vol, source, radius)?;
        let (readback, row) = validated(device, "Filter::stats_readback", || {
            let (rb, row) = texture_readback(device, "Filter::stats_readback", dims, 16);
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("Filter::stats_copy"),
            });
            copy_texture_out(&mut encoder, &st.stats, &rb, row, dims);
            gpu.queue.submit([encoder.finish()]);
            (rb, row)
        })?;
        let bytes = read_buffer(device, &readback, "Filter::stats_readback")?;
        let raw = unpad::<[f32; 4]>(&bytes, row, nx);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectorisable `exp2` and `log2` against f64 over their whole useful range,
    /// and `t^β` as the CDF map uses it against `powf` in f64.
    #[test]
    fn fast_exp2_log2_and_pow_match_f64() {
        let mut worst = [0.0f64; 3];
        for i in 0..=200_000 {
            let y = (-127.0 + 254.0 * i as f64 / 200_000.0) as f32;
            let want = (y as f64).exp2();
            let got = exp2_approx(y) as f64;
            // Below 2^−125 the result flushes to 0, and nothing is subnormal.
            if y >= -125.0 {
                worst[0] = worst[0].max((got - want).abs() / want);
                assert!(got >= f32::MIN_POSITIVE as f64, "2^{y} = {got}");
            } else {
                assert_eq!(got, 0.0, "2^{y}");
            }
        }
        for i in 1..=200_000u32 {
            // Mantissas across [1, 2) and exponents from subnormal to large.
            let x = f32::from_bits(i.wrapping_mul(2_654_435_761) % 0x7f00_0000 + 1);
            let want = (x as f64).log2();
            let got = log2_approx(x) as f64;
            worst[1] = worst[1].max((got - want).abs() / want.abs().max(1.0));
        }
        for i in 1..1000 {
            let t = i as f32 / 1000.0;
            for beta in [0.0f32, 1e-3, 0.1, 0.5, 1.0, 2.0, 7.5, 40.0, 1e3] {
                let got = exp2_approx(beta * log2_approx(t)) as f64;
                let want = (t as f64).powf(beta as f64);
                worst[2] = worst[2].max((got - want).abs());
            }
        }
        eprintln!(
            "exp2 rel {:.1e}, log2 {:.1e}, pow abs {:.1e}",
            worst[0], worst[1], worst[2]
        );
        assert!(worst[0] < 2e-7, "exp2: {}", worst[0]);
        assert!(worst[1] < 2e-7, "log2: {}", worst[1]);
        assert!(worst[2] < 5e-7, "pow: {}", worst[2]);
    }

    /// The select-based maps keep the special cases of the equations exactly.
    #[test]
    fn map_special_cases_are_exact() {
        // Homogeneous box: 1 for every map whatever the voxel.
        for map in [AmbientMap::Cdf, AmbientMap::Gauss, AmbientMap::Penner] {
            assert_eq!(ambient(map, 0.3, [0.3, 0.3, 0.3, 0.09]), 1.0, "{map:?}");
        }
        let m = [0.0, 1.0, 0.25, 0.25];
        // CDF: 0 at the minimum, 1 at the maximum, t^β between.
        assert_eq!(ambient(AmbientMap::Cdf, 0.0, m), 0.0);
        assert_eq!(ambient(AmbientMap::Cdf, 1.0, m), 1.0);
        let beta = 0.25f64 / 0.75;
        let want = 0.5f64.powf(beta);
        assert!((ambient(AmbientMap::Cdf, 0.5, m) as f64 - want).abs() < 1e-6);
        // Penner: 1 at or above the mean, σ²/(σ² + d²) below it.
        assert_eq!(ambient(AmbientMap::Penner, 0.25, m), 1.0);
        assert_eq!(ambient(AmbientMap::Penner, 0.9, m), 1.0);
        let var = 0.25f64 - 0.0625;
        let want = var / (var + 0.25f64.powi(2));
        assert!((ambient(AmbientMap::Penner, 0.0, m) as f64 - want).abs() < 1e-6);
        // Gaussian: ½ at the mean, and the rearranged exponent is Winitzki's erf.
        assert!((ambient(AmbientMap::Gauss, 0.25, m) - 0.5).abs() < 1e-6);
        for i in 0..=100 {
            let v_x = i as f32 / 100.0;
            for var in [1e-6f32, 1e-3, 0.1875] {
                let mean_sq = var + 0.0625;
                let got = ambient(AmbientMap::Gauss, v_x, [0.0, 1.0, 0.25, mean_sq]);
                let x = (v_x - 0.25) / ((mean_sq - 0.0625).sqrt() * std::f32::consts::SQRT_2);
                let want = 0.5 * (1.0 + erf_approx(x));
                assert!(
                    (got - want).abs() < 2e-6,
                    "v {v_x} σ² {var}: {got} vs {want}"
                );
            }
        }
        assert_eq!(ambient(AmbientMap::Variance, 0.0, m), 0.1875);
    }
}
