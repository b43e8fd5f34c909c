//! A segmentation as every stage reads it beside the density (`volume.wgsl` bindings
//! 4–7, compiled in where a pipeline sets `SEGMENTS`; CPU twin:
//! [`crate::sample::VolumeSampler`]'s `segments`).
//!
//! Each voxel holds a *class*: one combination of segments, one per layer of the label
//! map (a voxel of two overlapping segments is a class of its own). A class's
//! [`ClassLook`] says how it shows (colour, opacity, whether the colour tints or
//! replaces the transfer function's, outline only) and which clip shapes carve it. The
//! shaders read four things:
//!
//! - the *look* volume (RGBA8, filtered): per voxel the class colour premultiplied by its
//!   opacity weight, and the weight. Sampled trilinearly, it blends neighbouring classes
//!   (label-aware interpolation), so a segment's boundary is the smooth `w = ½` level of
//!   the interpolated weight instead of the voxels' cubes, and the gradient of the weight
//!   lights a boundary the density does not show (an organ inside tissue of the same HU).
//!   An outline class keeps its weight only on its boundary voxels.
//! - the class of each voxel (R16Uint, read nearest) and the class table: which shapes
//!   carve a sample;
//! - per voxel, the weight's differences one voxel either side (its gradient, where
//!   shading takes a segment's normal) and whether the colour replaces the transfer
//!   function's × the weight (RGBA8 snorm, filtered: tinted and replacing classes meet
//!   smoothly).

use crate::gpu::{Gpu, filled_texture_3d, storage_buffer};
use crate::volume::voxel_of;
use rayon::prelude::*;

/// How one class shows and which shapes carve it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassLook {
    /// sRGB-free straight colour (what the transfer function's colours are).
    pub color: [u8; 3],
    /// Opacity weight in [0, 1]: multiplies the transfer function's opacity (0 = hidden).
    pub opacity: f32,
    /// The colour replaces the transfer function's; otherwise it multiplies (tints) it.
    pub replace: bool,
    /// Only the class's boundary voxels show.
    pub outline: bool,
    /// Bit `s`: clip shape `s` carves this class.
    pub carved_by: u32,
}

impl ClassLook {
    /// What a voxel outside every segment looks like by default: the transfer function
    /// alone, carved by every shape.
    pub const PLAIN: ClassLook = ClassLook {
        color: [255, 255, 255],
        opacity: 1.0,
        replace: false,
        outline: false,
        carved_by: u32::MAX,
    };

    /// The class's entry in the table the shaders read: the shapes that carve it (its
    /// look and mode are in the textures); the rest unused.
    pub fn gpu(&self) -> [u32; 4] {
        [self.carved_by, 0, 0, 0]
    }
}

/// `x` in [−1, 1] as an 8-bit snorm texel holds it.
pub fn snorm8(x: f32) -> i8 {
    (x.clamp(-1.0, 1.0) * 127.0).round() as i8
}

/// A segmentation on the texel grid: classes per voxel, their looks, and the look volume.
#[derive(Debug, Clone)]
pub struct SegmentTexels {
    pub dims: [usize; 3],
    /// The class of each voxel (x fastest).
    pub classes: Vec<u16>,
    /// Per class, how it shows.
    pub table: Vec<ClassLook>,
    /// Per voxel: colour × weight and weight, as RGBA8 (what the look texture holds).
    pub look: Vec<[u8; 4]>,
    /// Per voxel: the weight's differences one voxel either side, `w(x + 1) − w(x − 1)`
    /// per axis (clamped at the faces), and whether its colour replaces the transfer
    /// function's × its weight, as RGBA8 snorm (the gradient texture).
    pub gradient: Vec<[i8; 4]>,
}

impl SegmentTexels {
    /// Classes `classes` (x fastest, each below `table.len()`) of a volume of `dims`.
    pub fn new(dims: [usize; 3], classes: Vec<u16>, table: Vec<ClassLook>) -> Self {
        assert_eq!(classes.len(), dims.iter().product::<usize>());
        let mut s = SegmentTexels {
            dims,
            classes,
            table,
            look: Vec::new(),
            gradient: Vec::new(),
        };
        s.look = s.looks();
        s.gradient = s.differences();
        s
    }

    /// Changes the looks; whether any changed.
    pub fn set_table(&mut self, table: Vec<ClassLook>) -> bool {
        if table == self.table {
            return false;
        }
        self.table = table;
        self.look = self.looks();
        self.gradient = self.differences();
        true
    }

    /// Per voxel: whether `table` changes its opacity weight (what `V_o` and `V_PAO`
    /// read; colours and cuts change neither).
    pub fn voxels_changed_by(&self, table: &[ClassLook]) -> Vec<bool> {
        let weight = |c: &ClassLook| (c.opacity.clamp(0.0, 1.0).to_bits(), c.outline);
        let changed: Vec<bool> = self
            .table
            .iter()
            .zip(table)
            .map(|(a, b)| weight(a) != weight(b))
            .collect();
        self.classes
            .iter()
            .map(|&c| changed.get(c as usize).copied().unwrap_or(true))
            .collect()
    }

    /// Whether every class's colour tints (0) or replaces (1) the transfer function's, or
    /// they differ (2): `SEGMENT_MODES` of `volume.wgsl`.
    pub fn modes(&self) -> u32 {
        let replace = |c: &ClassLook| c.replace;
        match (
            self.table.iter().all(replace),
            self.table.iter().any(replace),
        ) {
            (true, _) => 1,
            (false, false) => 0,
            (false, true) => 2,
        }
    }

    /// Whether the weight has edges (a class hidden, fainter or outlined); without, its
    /// gradient is 0 everywhere (`SEGMENT_EDGES` of `raycast.wgsl`).
    pub fn edges(&self) -> bool {
        self.table.iter().any(|c| c.opacity < 1.0 || c.outline)
    }

    /// The class table as the shaders read it.
    pub fn gpu_table(&self) -> Vec<[u32; 4]> {
        self.table.iter().map(ClassLook::gpu).collect()
    }

    /// The look of every voxel.
    fn looks(&self) -> Vec<[u8; 4]> {
        let dims = self.dims;
        let unorm = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        let entries: Vec<[u8; 4]> = self
            .table
            .iter()
            .map(|c| {
                let w = c.opacity.clamp(0.0, 1.0);
                let [r, g, b] = c.color.map(|v| unorm(v as f32 / 255.0 * w));
                [r, g, b, unorm(w)]
            })
            .collect();
        let outlines = self.table.iter().any(|c| c.outline);
        (0..self.classes.len())
            .into_par_iter()
            .map(|i| {
                let class = self.classes[i];
                let c = &self.table[class as usize];
                if outlines && c.outline && self.interior(i, dims) {
                    [0; 4]
                } else {
                    entries[class as usize]
                }
            })
            .collect()
    }

    /// Per block of `edge`³ voxels widened by one voxel (what a trilinear sample in it
    /// reads, as [`super::BlockRanges::new`]): whether any voxel there has weight. A
    /// block without is empty whatever the transfer function: the ray caster skips it.
    pub fn shown_blocks(&self, edge: usize) -> Vec<bool> {
        let dims = self.dims;
        let grid: [usize; 3] = std::array::from_fn(|a| dims[a].div_ceil(edge));
        (0..grid.iter().product::<usize>())
            .into_par_iter()
            .map(|b| {
                let bi = voxel_of(b, grid);
                let lo: [usize; 3] = std::array::from_fn(|a| (bi[a] * edge).saturating_sub(1));
                let hi: [usize; 3] = std::array::from_fn(|a| ((bi[a] + 1) * edge + 1).min(dims[a]));
                (lo[2]..hi[2]).any(|z| {
                    (lo[1]..hi[1]).any(|y| {
                        let row = dims[0] * (y + dims[1] * z);
                        self.look[row + lo[0]..row + hi[0]].iter().any(|l| l[3] > 0)
                    })
                })
            })
            .collect()
    }

    /// The weight's differences of every voxel (see [`Self::gradient`]).
    fn differences(&self) -> Vec<[i8; 4]> {
        let dims = self.dims;
        let stride = [1, dims[0], dims[0] * dims[1]];
        let w = |i: usize| self.look[i][3] as f32 / 255.0;
        (0..self.look.len())
            .into_par_iter()
            .map(|i| {
                let v = voxel_of(i, dims);
                let mut d = [0i8; 4];
                for a in 0..3 {
                    let lo = if v[a] > 0 { i - stride[a] } else { i };
                    let hi = if v[a] + 1 < dims[a] { i + stride[a] } else { i };
                    d[a] = snorm8(w(hi) - w(lo));
                }
                let replace = self.table[self.classes[i] as usize].replace;
                d[3] = snorm8(if replace { w(i) } else { 0.0 });
                d
            })
            .collect()
    }

    /// Whether voxel `i`'s six neighbours inside the volume are all of its class.
    fn interior(&self, i: usize, dims: [usize; 3]) -> bool {
        let v = voxel_of(i, dims);
        let class = self.classes[i];
        let stride = [1, dims[0], dims[0] * dims[1]];
        (0..3).all(|a| {
            (v[a] == 0 || self.classes[i - stride[a]] == class)
                && (v[a] + 1 == dims[a] || self.classes[i + stride[a]] == class)
        })
    }

    /// The voxels every `factor`-th along each axis (a volume halved to fit the adapter
    /// keeps the class of the voxel at each new voxel's first corner).
    pub fn subsampled(&self, dims: [usize; 3], factor: usize) -> Self {
        let classes = (0..dims.iter().product::<usize>())
            .map(|i| {
                let v = voxel_of(i, dims);
                let o: [usize; 3] = std::array::from_fn(|a| (v[a] * factor).min(self.dims[a] - 1));
                self.classes[o[0] + self.dims[0] * (o[1] + self.dims[1] * o[2])]
            })
            .collect();
        SegmentTexels::new(dims, classes, self.table.clone())
    }

    /// The look as f32 RGBA per voxel (the CPU twin's copy of the texture).
    pub fn look_f32(&self) -> Vec<[f32; 4]> {
        self.look
            .iter()
            .map(|l| l.map(|v| v as f32 / 255.0))
            .collect()
    }
}

/// A segmentation on the GPU: the look and class textures and the class table
/// (`volume.wgsl` bindings 4–6). Every volume has one: without a segmentation, one
/// voxel of class 0 with [`ClassLook::PLAIN`]'s look, which pipelines without `SEGMENTS`
/// bind and never read. A clone shares the textures (what a stage's bind groups hold).
#[derive(Debug, Clone)]
pub struct GpuSegments {
    look: wgpu::Texture,
    pub look_view: wgpu::TextureView,
    pub classes_view: wgpu::TextureView,
    gradient: wgpu::Texture,
    pub gradient_view: wgpu::TextureView,
    pub table: wgpu::Buffer,
    dims: [u32; 3],
    /// Whether a segmentation is uploaded (the stages then read it: `SEGMENTS`).
    pub on: bool,
    /// [`SegmentTexels::modes`] and [`SegmentTexels::edges`] of what is uploaded.
    pub modes: u32,
    pub edges: bool,
}

impl GpuSegments {
    /// No segmentation.
    pub fn none(gpu: &Gpu) -> Self {
        let plain = SegmentTexels::new([1, 1, 1], vec![0], vec![ClassLook::PLAIN]);
        let mut s = Self::new(gpu, &plain);
        s.on = false;
        s
    }

    /// Uploads `segments`.
    pub fn new(gpu: &Gpu, segments: &SegmentTexels) -> Self {
        let (device, queue) = (&gpu.device, &gpu.queue);
        let dims = segments.dims.map(|d| d as u32);
        let upload = |label, format, bytes: &[u8]| {
            filled_texture_3d(device, queue, label, dims, format, bytes)
        };
        let look = upload(
            "GpuSegments::look",
            wgpu::TextureFormat::Rgba8Unorm,
            bytemuck::cast_slice(&segments.look),
        );
        let gradient = upload(
            "GpuSegments::gradient",
            wgpu::TextureFormat::Rgba8Snorm,
            bytemuck::cast_slice(&segments.gradient),
        );
        let classes = upload(
            "GpuSegments::classes",
            wgpu::TextureFormat::R16Uint,
            bytemuck::cast_slice(&segments.classes),
        );
        GpuSegments {
            look_view: look.create_view(&Default::default()),
            classes_view: classes.create_view(&Default::default()),
            gradient_view: gradient.create_view(&Default::default()),
            gradient,
            look,
            table: storage_buffer(
                gpu,
                "GpuSegments::table",
                bytemuck::cast_slice(&segments.gpu_table()),
                wgpu::BufferUsages::COPY_DST,
            ),
            dims,
            on: true,
            modes: segments.modes(),
            edges: segments.edges(),
        }
    }

    /// Writes the looks and the class table of `segments` (the same classes as uploaded).
    pub fn update(&mut self, gpu: &Gpu, segments: &SegmentTexels) {
        debug_assert_eq!(segments.dims.map(|d| d as u32), self.dims);
        (self.modes, self.edges) = (segments.modes(), segments.edges());
        crate::gpu::write_texture_3d(
            &gpu.queue,
            &self.look,
            0,
            self.dims,
            4,
            bytemuck::cast_slice(&segments.look),
        );
        crate::gpu::write_texture_3d(
            &gpu.queue,
            &self.gradient,
            0,
            self.dims,
            4,
            bytemuck::cast_slice(&segments.gradient),
        );
        let table = segments.gpu_table();
        let bytes: &[u8] = bytemuck::cast_slice(&table);
        if self.table.size() == bytes.len() as u64 {
            gpu.queue.write_buffer(&self.table, 0, bytes);
        } else {
            self.table = storage_buffer(
                gpu,
                "GpuSegments::table",
                bytes,
                wgpu::BufferUsages::COPY_DST,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hidden_class_has_no_weight_and_an_outline_keeps_its_boundary() {
        let dims = [4, 4, 4];
        let classes: Vec<u16> = (0..64)
            .map(|i| {
                let v = voxel_of(i, dims);
                u16::from(v.iter().all(|&c| c >= 1))
            })
            .collect();
        let shown = ClassLook {
            color: [255, 0, 0],
            ..ClassLook::PLAIN
        };
        let mut s = SegmentTexels::new(dims, classes.clone(), vec![ClassLook::PLAIN, shown]);
        assert_eq!(s.look[0], [255, 255, 255, 255]);
        assert_eq!(s.look[1 + 4 + 16], [255, 0, 0, 255]);
        let hidden = ClassLook {
            opacity: 0.0,
            ..shown
        };
        assert!(s.set_table(vec![ClassLook::PLAIN, hidden]));
        assert_eq!(s.look[1 + 4 + 16], [0; 4]);
        let outline = ClassLook {
            outline: true,
            ..shown
        };
        s.set_table(vec![ClassLook::PLAIN, outline]);
        // (2, 2, 2) has all six neighbours in class 1 (the block 1..=3); (1, 1, 1) does not.
        assert_eq!(s.look[2 + 8 + 32], [0; 4]);
        assert_eq!(s.look[1 + 4 + 16], [255, 0, 0, 255]);
    }
}
