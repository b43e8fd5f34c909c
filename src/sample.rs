//! The CPU twins' shared vocabulary: trilinear sampling as a GPU sampler does it, the
//! transfer-function table (baked, looked up with its own interpolation) and the f16
//! copies and mip chains some passes sample instead of the volume texture.
//!
//! Every twin in `stage`-like modules (`ao::lao`, `render::shadow`, `ao::vao`, `ao::cao`,
//! `render::cpu`, …) samples through these, so the GPU and CPU paths read the same values.

use crate::texels::gpu_data::VolumeMap;
use crate::texels::segments::SegmentTexels;
use crate::texels::{TexelFormat, VolumeTexels};
use crate::tf::{Lut, TransferFunction, correct_opacity};
use glam::{Vec3, Vec4};
use rayon::prelude::*;

/// The largest AO read offset ([`crate::render::RenderSettings::ao_offset`]), in voxels:
/// the ray caster reads AO up to this far off a sample with opacity, along the normal,
/// and sparse AO computes the voxels within `1 + AO_READ_REACH` of a texel with opacity
/// (`ao::sparse`), which is what keeps it exact; larger offsets are clamped to it. Both
/// `render` and `ao` read it from here.
pub const AO_READ_REACH: usize = 2;

/// How far, in texels, a trilinear read's footprint is widened either side: a sampler
/// computes its weights in fixed point (8 fractional bits on common hardware), so a read
/// within 1/256 of a texel centre may weigh the neighbour an exact computation gives
/// weight 0. A generous margin costs a few voxels of AO, never exactness.
pub const FOOTPRINT_SLACK: f32 = 1.0 / 64.0;

/// The texels a trilinear read at `uvw` of a volume of `dims` may weigh, per axis the
/// first and last index (clamped like the sampler): [`trilinear`]'s two per axis,
/// widened by [`FOOTPRINT_SLACK`] (`mark_ao` in `shaders/raycast.wgsl`).
pub fn trilinear_footprint(dims: [usize; 3], uvw: Vec3) -> [[usize; 2]; 3] {
    let c = uvw * Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) - Vec3::splat(0.5);
    [0, 1, 2].map(|a| {
        let last = dims[a] as i64 - 1;
        let lo = ((c[a] - FOOTPRINT_SLACK).floor() as i64).clamp(0, last);
        let hi = ((c[a] + FOOTPRINT_SLACK).floor() as i64 + 1).clamp(0, last);
        [lo as usize, hi as usize]
    })
}

/// Trilinear interpolation of `values` (x fastest) at texture coordinates `uvw` in
/// [0, 1]³, texel centres at (i + ½)/n, clamped at the edges like a GPU sampler.
pub fn trilinear(values: &[f32], dims: [usize; 3], uvw: Vec3) -> f32 {
    let c = uvw * Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) - Vec3::splat(0.5);
    let base = c.floor();
    let f = c - base;
    let idx = |axis: usize, off: i64| -> usize {
        (base[axis] as i64 + off).clamp(0, dims[axis] as i64 - 1) as usize
    };
    let at = |x: usize, y: usize, z: usize| values[x + dims[0] * (y + dims[1] * z)];
    let (x0, x1, y0, y1, z0, z1) = (
        idx(0, 0),
        idx(0, 1),
        idx(1, 0),
        idx(1, 1),
        idx(2, 0),
        idx(2, 1),
    );
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let c00 = lerp(at(x0, y0, z0), at(x1, y0, z0), f.x);
    let c10 = lerp(at(x0, y1, z0), at(x1, y1, z0), f.x);
    let c01 = lerp(at(x0, y0, z1), at(x1, y0, z1), f.x);
    let c11 = lerp(at(x0, y1, z1), at(x1, y1, z1), f.x);
    lerp(lerp(c00, c10, f.y), lerp(c01, c11, f.y), f.z)
}

/// The CPU twin of `shaders/volume.wgsl`: texel values (x fastest) of a volume of `dims`,
/// read through a [`VolumeMap`] and a table as the shaders' reader reads them.
#[derive(Debug, Clone, Copy)]
pub struct VolumeSampler<'a> {
    pub values: &'a [f32],
    pub dims: [usize; 3],
    pub map: VolumeMap,
    pub table: &'a [[f32; 4]],
    /// A segmentation read beside the density (`SEGMENTS` in `volume.wgsl`).
    pub segments: Option<&'a SegmentSampler>,
}

/// The CPU twin of a segmentation as `volume.wgsl` reads it (bindings 4–6): the look's
/// channels as the filtered texture returns them, the classes and the class table.
#[derive(Debug, Clone)]
pub struct SegmentSampler {
    pub dims: [usize; 3],
    /// Colour × weight (r, g, b) and weight, each in [0, 1].
    look: [Vec<f32>; 4],
    /// The weight's differences (x, y, z) and replace × weight, as the snorm texture
    /// holds them.
    gradient: [Vec<f32>; 4],
    classes: Vec<u16>,
    table: Vec<[u32; 4]>,
    /// [`SegmentTexels::modes`].
    modes: u32,
}

impl SegmentSampler {
    pub fn new(s: &SegmentTexels) -> Self {
        SegmentSampler {
            dims: s.dims,
            look: std::array::from_fn(|c| s.look.iter().map(|l| l[c] as f32 / 255.0).collect()),
            gradient: std::array::from_fn(|c| {
                s.gradient
                    .iter()
                    .map(|g| (g[c] as f32 / 127.0).max(-1.0))
                    .collect()
            }),
            classes: s.classes.clone(),
            table: s.gpu_table(),
            modes: s.modes(),
        }
    }

    fn index(&self, k: [usize; 3]) -> usize {
        k[0] + self.dims[0] * (k[1] + self.dims[1] * k[2])
    }

    /// `segment_look_at`: colour × weight and weight at `uvw`, trilinear.
    pub fn look_at(&self, uvw: Vec3) -> Vec4 {
        Vec4::from_array(std::array::from_fn(|c| {
            trilinear(&self.look[c], self.dims, uvw)
        }))
    }

    /// `segment_gradient_at`: the weight's differences at `uvw`, trilinear.
    pub fn gradient_at(&self, uvw: Vec3) -> Vec3 {
        Vec3::from_array(std::array::from_fn(|c| {
            trilinear(&self.gradient[c], self.dims, uvw)
        }))
    }

    /// How much the colour at `uvw` replaces the transfer function's (`classify_at`'s
    /// per-class mode: filtered, over the weight `w` there).
    fn replacing_at(&self, uvw: Vec3, w: f32) -> f32 {
        (trilinear(&self.gradient[3], self.dims, uvw) / w).clamp(0.0, 1.0)
    }

    /// `segment_weight_of_voxel`.
    pub fn weight_of_voxel(&self, k: [usize; 3]) -> f32 {
        self.look[3][self.index(k)]
    }

    /// `segment_class_at`: the class of the voxel nearest to `uvw`.
    pub fn class_at(&self, uvw: Vec3) -> usize {
        let k: [usize; 3] = std::array::from_fn(|a| {
            ((uvw[a].max(0.0) * self.dims[a] as f32) as usize).min(self.dims[a] - 1)
        });
        self.classes[self.index(k)] as usize
    }

    /// `carved_by_at`: the clip shapes (bit s) that carve the voxel nearest to `uvw`.
    pub fn carved_by_at(&self, uvw: Vec3) -> u32 {
        self.table[self.class_at(uvw)][0]
    }

    /// `carved_by_voxel`.
    pub fn carved_by_voxel(&self, k: [usize; 3]) -> u32 {
        self.table[self.classes[self.index(k)] as usize][0]
    }
}

impl<'a> VolumeSampler<'a> {
    /// The density of `texels` (`values`, its normalised texels) read through `lut`, as
    /// the stages that bind the volume itself read it.
    pub fn density(values: &'a [f32], texels: &VolumeTexels, lut: &'a Lut) -> Self {
        VolumeSampler {
            values,
            dims: texels.dims,
            map: VolumeMap::new(texels, lut),
            table: &lut.rgba,
            segments: None,
        }
    }

    /// The same reading `segments` beside the density.
    pub fn with_segments(self, segments: Option<&'a SegmentSampler>) -> Self {
        VolumeSampler { segments, ..self }
    }

    /// `value_at`: the texel value at `uvw`, trilinear, clamped at the edges.
    pub fn value_at(&self, uvw: Vec3) -> f32 {
        trilinear(self.values, self.dims, uvw)
    }

    /// `value_of_voxel`: the texel value of voxel `k`, unfiltered; `k` inside the volume.
    pub fn value_of_voxel(&self, k: [usize; 3]) -> f32 {
        self.values[k[0] + self.dims[0] * (k[1] + self.dims[1] * k[2])]
    }

    /// `lut_index`: the fractional table index of `value`, clamped to the table.
    fn index(&self, value: f32) -> (usize, usize, f32) {
        let [a, b, last] = self.map.lut_map();
        let t = (value * a + b).clamp(0.0, last);
        let i0 = t.floor() as usize;
        (i0, (i0 + 1).min(last as usize), t - t.floor())
    }

    /// `classify`: the transfer function's colour and opacity at `value` (interpolated
    /// as `c0 · (1 − f) + c1 · f`; [`Self::opacity`] as `a0 + (a1 − a0) · f`: the GPU's
    /// `mix` gives either within rounding).
    pub fn classify(&self, value: f32) -> [f32; 4] {
        let (i0, i1, f) = self.index(value);
        Vec4::from(self.table[i0])
            .lerp(Vec4::from(self.table[i1]), f)
            .to_array()
    }

    /// `opacity`: the transfer function's opacity at `value`.
    pub fn opacity(&self, value: f32) -> f32 {
        let (i0, i1, f) = self.index(value);
        let (a0, a1) = (self.table[i0][3], self.table[i1][3]);
        a0 + (a1 - a0) * f
    }

    /// `opacity_at`: the opacity at `uvw` (inside the box), with a segmentation's weight.
    pub fn opacity_at(&self, uvw: Vec3) -> f32 {
        let a = self.opacity(self.value_at(uvw));
        match self.segments {
            Some(s) => a * s.look_at(uvw).w,
            None => a,
        }
    }

    /// `opacity_of_voxel`: the opacity of voxel `k`, unfiltered.
    pub fn opacity_of_voxel(&self, k: [usize; 3]) -> f32 {
        let a = self.opacity(self.value_of_voxel(k));
        match self.segments {
            Some(s) => a * s.weight_of_voxel(k),
            None => a,
        }
    }

    /// `classify_at`: the colour and opacity at `uvw` of `value` (`value_at(uvw)`), with
    /// a segmentation's weight and colour (tinting or replacing the transfer function's).
    pub fn classify_at(&self, uvw: Vec3, value: f32) -> [f32; 4] {
        let tf = self.classify(value);
        let Some(s) = self.segments else {
            return tf;
        };
        let look = s.look_at(uvw);
        let rgb = Vec3::new(tf[0], tf[1], tf[2]);
        if look.w <= 0.0 {
            return [tf[0], tf[1], tf[2], 0.0];
        }
        let c = look.truncate() / look.w;
        let replace = match s.modes {
            2 => s.replacing_at(uvw, look.w),
            m => m as f32,
        };
        let out = (rgb * c).lerp(c, replace);
        [out.x, out.y, out.z, tf[3] * look.w]
    }

    /// `carved_by_at`: the clip shapes (bit s) that carve the sample at `uvw`.
    pub fn carved_by_at(&self, uvw: Vec3) -> u32 {
        self.segments.map_or(u32::MAX, |s| s.carved_by_at(uvw))
    }

    /// `carved_by_voxel`.
    pub fn carved_by_voxel(&self, k: [usize; 3]) -> u32 {
        self.segments.map_or(u32::MAX, |s| s.carved_by_voxel(k))
    }
}

/// Distance between samples along an LAO ray (`ao::lao`, `ao::cao`).
pub const LAO_STEP_MM: f32 = 1.0;

/// The opacity table for LAO: the transfer function's alpha, corrected from its
/// reference length (one voxel of the smallest spacing) to a 1 mm step.
pub fn lao_lut(tf: &TransferFunction, texels: &VolumeTexels) -> Lut {
    let min_spacing = texels.spacing.iter().copied().fold(f32::INFINITY, f32::min);
    bake_lut(tf, texels, LAO_STEP_MM / min_spacing)
}

/// Bakes `tf` over the texels' value range with opacity corrected for `step_voxels`.
pub fn bake_lut(tf: &TransferFunction, texels: &VolumeTexels, step_voxels: f32) -> Lut {
    let (a, b) = (
        texels.value_offset,
        texels.value_offset + texels.value_scale,
    );
    let (lo, hi) = (a.min(b), a.max(b));
    // Unorm texels span [lo, hi] exactly; float texels use the TF's own span, widened.
    let (lo, hi) = match texels.format {
        TexelFormat::R32Float => {
            let (mn, mx) = texels.norm_range();
            let (mn, mx) = (mn as f64, mx as f64);
            if mx > mn {
                (mn, mx)
            } else {
                (mn - 0.5, mn + 0.5)
            }
        }
        _ => (lo, hi),
    };
    let mut lut = tf.bake(lo, hi, crate::tf::LUT_ENTRIES);
    for e in &mut lut.rgba {
        e[3] = correct_opacity(e[3], step_voxels);
    }
    lut
}

/// The map from texel values to the f16 copy: `stored = (norm − lo) / scale`. Unorm
/// texels are already in [0, 1] (identity); float texels hold physical values, which
/// may exceed f16's range (65504), so they are normalised by their own range.
pub fn f16_map(texels: &VolumeTexels) -> (f64, f64) {
    match texels.format {
        TexelFormat::R32Float => {
            let (lo, hi) = texels.norm_range();
            let (lo, hi) = (lo as f64, hi as f64);
            if lo.is_finite() && hi > lo {
                (lo, hi - lo)
            } else {
                (if lo.is_finite() { lo } else { 0.0 }, 1.0)
            }
        }
        _ => (0.0, 1.0),
    }
}

/// The LUT map `t = stored · a + b` for values of the f16 copy (see [`f16_map`]).
pub fn f16_lut_map(texels: &VolumeTexels, lut: &Lut) -> (f32, f32) {
    let (a, b) = texels.lut_map(lut);
    let (lo, scale) = f16_map(texels);
    ((a as f64 * scale) as f32, (b as f64 + a as f64 * lo) as f32)
}

/// How a stage reads the f16 copy of `texels` (and its mip levels) through `lut`.
pub fn f16_volume_map(texels: &VolumeTexels, lut: &Lut) -> VolumeMap {
    let (a, b) = f16_lut_map(texels, lut);
    VolumeMap::with_lut_map(a, b, lut)
}

/// Rounds to the nearest f16 (what an R16Float texel holds).
fn to_f16(x: f32) -> u16 {
    half::f16::from_f32(x).to_bits()
}

/// Mip levels 0..=`levels` of the texel values as R16Float bits: level 0 the texels
/// mapped by [`f16_map`] and rounded to f16, each next one a 2×2×2 box filter of the one
/// before (sizes halved and rounded down, as a GPU's mip chain is), each with its dims.
///
/// f16 rather than the volume's own texture: lavapipe filters 8-bit unorm textures in
/// fixed point, which flips Eq. 4's comparisons of equal neighbours between GPU and CPU;
/// float texels filter identically on both. 11 significant bits are plenty for AO.
pub fn mip_chain(texels: &VolumeTexels, levels: u32) -> Vec<(Vec<u16>, [usize; 3])> {
    let (lo, scale) = f16_map(texels);
    let level0: Vec<u16> = (0..texels.dims.iter().product::<usize>())
        .into_par_iter()
        .map(|i| to_f16(((texels.norm_at(i) as f64 - lo) / scale) as f32))
        .collect();
    let mut chain = vec![(level0, texels.dims)];
    for _ in 0..levels {
        let Some((prev, prev_dims)) = chain.last() else {
            break;
        };
        let prev_dims = *prev_dims;
        let dims = prev_dims.map(|d| (d / 2).max(1));
        let values: Vec<u16> = (0..dims[0] * dims[1] * dims[2])
            .into_par_iter()
            .map(|i| {
                let v = crate::volume::voxel_of(i, dims);
                let mut sum = 0.0f32;
                for dz in 0..2 {
                    for dy in 0..2 {
                        for dx in 0..2 {
                            let c: [usize; 3] = std::array::from_fn(|a| {
                                (2 * v[a] + [dx, dy, dz][a]).min(prev_dims[a] - 1)
                            });
                            let bits = prev[c[0] + prev_dims[0] * (c[1] + prev_dims[1] * c[2])];
                            sum += half::f16::from_bits(bits).to_f32();
                        }
                    }
                }
                to_f16(sum / 8.0)
            })
            .collect();
        chain.push((values, dims));
    }
    chain
}

/// The texel values as an f16 pass samples them (level 0 of [`mip_chain`], as f32).
pub fn f16_texels(texels: &VolumeTexels) -> Vec<f32> {
    mip_chain(texels, 0)
        .pop()
        .map(|(bits, _)| {
            bits.iter()
                .map(|&b| half::f16::from_bits(b).to_f32())
                .collect()
        })
        .unwrap_or_default()
}

/// Texture coordinates of the centre of `voxel` in a volume of `dims`.
pub fn voxel_centre(voxel: [usize; 3], dims: [usize; 3]) -> Vec3 {
    (Vec3::new(voxel[0] as f32, voxel[1] as f32, voxel[2] as f32) + Vec3::splat(0.5))
        / Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32)
}

/// Runs `f` for every voxel (rayon over z-slices), x fastest, reporting progress in
/// z-slices: the loop every per-voxel CPU twin shares.
pub fn per_voxel(
    dims: [usize; 3],
    progress: &(dyn Fn(usize, usize) + Sync),
    f: impl Fn([usize; 3]) -> f32 + Sync,
) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..nz)
        .into_par_iter()
        .flat_map_iter(|z| {
            let slice: Vec<f32> = (0..nx * ny).map(|i| f([i % nx, i / nx, z])).collect();
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                nz,
            );
            slice
        })
        .collect()
}
