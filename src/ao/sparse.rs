//! Sparse AO (issue #15): the 8³ bricks an AO stage must process, and the bricks an LAO
//! ray may step over, so that per-frame work follows what can be seen and what a clip
//! shape touches while every pixel stays what the dense computation gives.
//!
//! Three facts carry it, each conservative:
//!
//! - **Readable bricks.** The ray caster reads `V_AO` (trilinearly) only at samples of
//!   non-zero opacity. A sample that gives weight to a voxel of brick `b` lies within one
//!   voxel of it, so it reads only texels of `b` widened by one voxel — exactly the range
//!   the ray caster's occupancy block `b` holds ([`BlockRanges`]). A brick whose block
//!   is transparent under the rendering LUT can have any AO. Clipping only lowers
//!   opacity, so the unclipped test stays valid while shapes move.
//! - **Empty cells along LAO rays.** An LAO sample inside a cell's box (a cube of
//!   [`RAY_CELL`] voxels, finer than a brick) reads only the cell's texels widened by one
//!   voxel; where the LAO LUT gives those texels zero opacity, the sample's factor
//!   `1 − a` is exactly 1. The ray still adds its transmittance once per
//!   skipped sample, in order, so the sum is the dense one bit for bit.
//! - **Bricks near a shape.** Outside every shape's clipping-camera box (which holds the
//!   shape and its dilation, [`crate::clip::camera::ClipCamera::frame`]) step IV gives
//!   `V_o = α` and `V_m = 1`: nothing to do. A probing shape clips everything outside
//!   it, so with one every brick is near.
//! - **Bricks a change can reach.** A cut lowers opacity only in occupied bricks that
//!   meet a carving shape; beyond the LAO reach of those, every ray reads `V_o = α` and
//!   a ray cast would give `V_PAO`'s bits ([`Bricks::reached`]).
//!
//! With skipping off ([`Bricks::dense`], `--no-skipping`) every list holds every brick
//! and no ray skips: the paper's dense CAO.

use super::view::ViewMask;
use crate::clip::camera::{ClipCamera, bound_in_volume, carved_ball};
use crate::clip::gpu::ClipUniforms;
use crate::gpu::shaders::Constants;
use crate::render::{RenderMode, RenderSettings};
use crate::texels::{BLOCK, BlockRanges, VolumeTexels};
use crate::tf::{Lut, TransferFunction};
use glam::Vec3;

/// Which voxels an AO computation covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Coverage {
    /// Every voxel, with only the skip that changes no value (empty samples along LAO
    /// rays): what `volao ao` writes.
    #[default]
    Every,
    /// The voxels the ray caster can read, and empty samples skipped; the others hold 1
    /// when read back. For rendering, and `volao ao --visible-only`.
    Readable,
    /// Every voxel and every sample: `--no-skipping`, the paper's dense computation.
    Dense,
}

impl Coverage {
    /// What rendering with `s` needs: readable voxels in compositing (whose AO is read
    /// only where the TF's opacity is non-zero) and in the projections (which read no
    /// AO: switching to them keeps it), every voxel for an isosurface (shaded wherever
    /// it lies), nothing skipped with skipping off.
    pub fn for_render(s: &RenderSettings) -> Self {
        match (s.empty_space_skipping, s.mode) {
            (false, _) => Coverage::Dense,
            (true, RenderMode::Iso(_)) => Coverage::Every,
            (true, _) => Coverage::Readable,
        }
    }

    /// The bricks for `tf` on `texels`, whose block ranges (of any edge dividing
    /// [`BRICK`]) are `ranges`.
    pub fn bricks(
        self,
        texels: &VolumeTexels,
        ranges: &BlockRanges,
        tf: &TransferFunction,
    ) -> Bricks {
        let lao = crate::sample::lao_lut(tf, texels);
        match self {
            Coverage::Dense => Bricks::dense(texels.dims),
            Coverage::Every => Bricks::new(texels, ranges, None, &lao),
            // Opacity uncorrected for the step: zero exactly where every step's is.
            Coverage::Readable => {
                let render = crate::sample::bake_lut(tf, texels, 1.0);
                Bricks::new(texels, ranges, Some(&render), &lao)
            }
        }
    }
}

/// `mask` (one flag per cell of `grid`, x fastest) grown by `k[a]` cells along each axis
/// a: a box, which holds every cell within that distance.
pub fn dilate(mask: &[bool], grid: [usize; 3], k: [usize; 3]) -> Vec<bool> {
    let mut out = mask.to_vec();
    let stride = [1, grid[0], grid[0] * grid[1]];
    let mut prefix = Vec::new();
    for a in 0..3 {
        let src = out.clone();
        let n = grid[a];
        // Every line along axis a: a running count, then "any set within ±k".
        for start in (0..src.len()).filter(|&i| crate::volume::voxel_of(i, grid)[a] == 0) {
            prefix.clear();
            prefix.push(0usize);
            for c in 0..n {
                let set = usize::from(src[start + c * stride[a]]);
                prefix.push(prefix[c] + set);
            }
            for c in 0..n {
                let (lo, hi) = (c.saturating_sub(k[a]), (c + k[a]).min(n - 1));
                out[start + c * stride[a]] = prefix[hi + 1] > prefix[lo];
            }
        }
    }
    out
}

/// Per brick of a volume of `dims` (x fastest over [`grid_of`]): whether it holds a
/// voxel `voxels` flags.
pub fn bricks_holding(voxels: &[bool], dims: [usize; 3]) -> Vec<bool> {
    let grid = grid_of(dims);
    let mut bricks = vec![false; grid.iter().product()];
    for (i, _) in voxels.iter().enumerate().filter(|(_, v)| **v) {
        let v = crate::volume::voxel_of(i, dims).map(|c| c / BRICK);
        bricks[v[0] + grid[0] * (v[1] + grid[1] * v[2])] = true;
    }
    bricks
}

/// Brick edge in voxels: a whole number of the ray caster's occupancy blocks, whose
/// ranges [`BlockRanges::merged`] turns into the bricks'.
pub const BRICK: usize = 8;
const _: () = assert!(BRICK.is_multiple_of(BLOCK));
const _: () = assert!(super::view::Marking::BRICKS.edge == BRICK);

/// Bricks per axis at most (a packed brick index has 10 bits per axis).
pub const MAX_BRICKS_PER_AXIS: usize = 1 << 10;

/// A list entry's flag: a shape is near the brick this frame or was in the last one
/// (CAO's step V then reads step IV's marks).
pub const NEAR: u32 = 1 << 30;

/// Which bricks the AO stages process, for one volume and transfer function.
#[derive(Debug, Clone, PartialEq)]
pub struct Bricks {
    /// Bricks per axis.
    pub grid: [usize; 3],
    /// 1 where the ray caster may read the brick's AO, x fastest.
    pub readable: Vec<u8>,
    /// 1 where an LAO sample in the brick may have non-zero opacity, x fastest.
    pub occupied: Vec<u8>,
    /// The same for the finer cells LAO rays step over ([`RAY_CELL`] voxels a side).
    pub rays: RayCells,
    /// Whether anything is skipped (false: every brick, every sample).
    pub skipping: bool,
    /// Within readable bricks, the per-voxel test (`None`: every voxel of them).
    pub voxels: Option<VoxelTest>,
    /// The voxels one image reads the AO of ([`Bricks::within`]; `None`: any view).
    pub view: Option<std::sync::Arc<ViewMask>>,
}

/// Edge of the cells an LAO ray steps over, in voxels: finer than a brick, so a ray
/// leaving a surface reaches empty space sooner (the cranium CT's 54-ray `V_PAO` under
/// `ct-bone`: 20 % of 4³ cells occupied against 29 % of 8³ bricks).
pub const RAY_CELL: usize = 4;

/// Which [`RAY_CELL`]-cells an LAO sample may find opacity in.
#[derive(Debug, Clone, PartialEq)]
pub struct RayCells {
    /// Cells per axis.
    pub grid: [usize; 3],
    /// 1 where a sample inside the cell may have non-zero opacity, x fastest.
    pub occupied: Vec<u8>,
}

impl RayCells {
    /// Every cell occupied: no sample skipped.
    fn all(dims: [usize; 3]) -> Self {
        let grid = dims.map(|d| d.div_ceil(RAY_CELL).max(1));
        RayCells {
            grid,
            occupied: vec![1; grid.iter().product()],
        }
    }

    /// Cells of `texels` occupied under the LAO LUT `lut`: their texels widened by one
    /// voxel (what a trilinear sample inside reads) may give non-zero opacity.
    fn of(texels: &VolumeTexels, lut: &Lut) -> Self {
        let ranges = BlockRanges::of_cells(texels, RAY_CELL, 1);
        RayCells {
            grid: ranges.grid,
            occupied: ranges.occupancy(texels, lut),
        }
    }

    /// As the shaders read them: one u32 per cell.
    pub fn words(&self) -> Vec<u32> {
        self.occupied.iter().map(|&o| u32::from(o)).collect()
    }

    /// The shaders' `grid` uniform: cells per axis, and whether rays skip (0/1).
    pub fn uniform(&self, skipping: bool) -> [u32; 4] {
        let g = self.grid.map(|g| g as u32);
        [g[0], g[1], g[2], u32::from(skipping)]
    }
}

/// The per-voxel readability test: voxel `v` is readable if the range of the 3³ texels
/// around it may give non-zero opacity under the rendering LUT.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelTest {
    /// The rendering LUT (opacity uncorrected for the step).
    pub lut: Lut,
    /// `prefix[i]`: the LUT's entries before `i` with opacity > 0 (`prefix.len()` is the
    /// LUT's length + 1).
    pub prefix: Vec<u32>,
    /// LUT index = norm · a + b; the last entry.
    pub map: [f32; 3],
    /// value = norm · value_scale + value_offset.
    pub value_map: [f64; 2],
    /// Texels taken below the voxel on each axis, and as many above (at least 1):
    /// `1 + AO_READ_REACH`, as the ray caster reads AO up to that far off a sample with
    /// opacity (`sample::AO_READ_REACH`). Tests take fewer to show that exactness rests
    /// on it.
    pub below: usize,
}

impl VoxelTest {
    fn new(texels: &VolumeTexels, lut: &Lut) -> Self {
        let mut prefix = Vec::with_capacity(lut.rgba.len() + 1);
        let mut n = 0u32;
        prefix.push(0);
        for e in &lut.rgba {
            n += u32::from(e[3] > 0.0);
            prefix.push(n);
        }
        let (a, b) = texels.lut_map(lut);
        VoxelTest {
            lut: lut.clone(),
            prefix,
            map: [a, b, (lut.rgba.len().max(2) - 1) as f32],
            value_map: [texels.value_scale, texels.value_offset],
            below: 1 + crate::sample::AO_READ_REACH,
        }
    }

    /// The shaders' uniform: scale, offset, last entry, on.
    pub fn uniform(test: Option<&VoxelTest>) -> [f32; 4] {
        match test {
            Some(t) => [t.map[0], t.map[1], t.map[2], 1.0 + t.below as f32],
            None => [0.0; 4],
        }
    }

    /// The prefix counts as the shaders read them (a single 1 when off).
    pub fn prefix_of(test: Option<&VoxelTest>) -> Vec<u32> {
        test.map(|t| t.prefix.clone()).unwrap_or_else(|| vec![0, 1])
    }
}

impl Bricks {
    /// Every brick readable and occupied, no ray skipping: the dense computation.
    pub fn dense(dims: [usize; 3]) -> Self {
        let grid = grid_of(dims);
        let n = grid.iter().product();
        Bricks {
            grid,
            readable: vec![1; n],
            occupied: vec![1; n],
            rays: RayCells::all(dims),
            skipping: false,
            voxels: None,
            view: None,
        }
    }

    /// These bricks restricted to the voxels `view` marks (issue #46): a brick stays
    /// readable only if it holds a marked voxel, and the per-voxel lists
    /// ([`Self::readable_mask`], [`Self::voxel_list`]) keep only marked voxels. What the
    /// rays skip is unchanged, so every value computed is the one without the view.
    pub fn within(mut self, view: std::sync::Arc<ViewMask>) -> Self {
        for (r, seen) in self.readable.iter_mut().zip(view.bricks(BRICK)) {
            *r &= u8::from(seen);
        }
        self.view = Some(view);
        self
    }

    /// Bricks for `ranges` of `texels` (blocks of any edge dividing [`BRICK`]):
    /// readable under `render_lut` (every brick when `None`, for a render mode that
    /// reads AO at samples the LUT's opacity does not decide, such as an isosurface),
    /// occupied under the LAO LUT `lao_lut`.
    pub fn new(
        texels: &VolumeTexels,
        ranges: &BlockRanges,
        render_lut: Option<&Lut>,
        lao_lut: &Lut,
    ) -> Self {
        let merged;
        let ranges = if ranges.edge == BRICK {
            ranges
        } else {
            merged = ranges.merged(BRICK / ranges.edge);
            &merged
        };
        assert_eq!(
            ranges.grid,
            grid_of(texels.dims),
            "block ranges of another volume"
        );
        let readable = match render_lut {
            // The ray caster reads AO up to AO_READ_REACH (< BRICK) voxels off a sample
            // with opacity: into the neighbouring bricks too.
            Some(lut) => {
                let occupied: Vec<bool> = ranges
                    .occupancy(texels, lut)
                    .iter()
                    .map(|&o| o != 0)
                    .collect();
                let near = dilate(&occupied, ranges.grid, [1; 3]);
                near.into_iter().map(u8::from).collect()
            }
            None => vec![1; ranges.ranges.len()],
        };
        let occupied = ranges.occupancy(texels, lao_lut);
        Bricks {
            grid: ranges.grid,
            readable,
            occupied,
            rays: RayCells::of(texels, lao_lut),
            skipping: true,
            voxels: render_lut.map(|lut| VoxelTest::new(texels, lut)),
            view: None,
        }
    }

    pub fn count(&self) -> usize {
        self.readable.len()
    }

    /// Whether the brick holding voxel `v` is readable.
    pub fn voxel_readable(&self, v: [usize; 3]) -> bool {
        self.readable[self.index(v.map(|c| c / BRICK))] != 0
    }

    /// Per voxel (x fastest): readable by its brick and, with a per-voxel test, by the
    /// range of the texels around it (the CPU twin of `voxel_readable` in
    /// `shaders/readable.wgsl`, whose margin is one LUT entry wider: every voxel readable
    /// here is computed there).
    pub fn readable_mask(&self, texels: &VolumeTexels) -> Vec<bool> {
        let mut mask = self.mask_by_range(texels, |t, lo, hi| {
            let [s, o] = t.value_map;
            let (a, b) = (lo as f64 * s + o, hi as f64 * s + o);
            !t.lut.is_transparent_over(a.min(b), a.max(b))
        });
        self.keep_in_view(&mut mask);
        mask
    }

    /// Clears `mask`'s voxels outside the view, if there is one.
    fn keep_in_view(&self, mask: &mut [bool]) {
        use rayon::prelude::*;
        if let Some(view) = &self.view {
            mask.par_iter_mut()
                .enumerate()
                .for_each(|(i, m)| *m = *m && view.contains(i));
        }
    }

    /// The voxels the GPU's LAO computes, as linear indices (x fastest) in brick order
    /// (x fastest within a brick): those of readable bricks that pass `voxel_readable`
    /// of `shaders/readable.wgsl` (its wider margin, in f32 as there), evaluated here
    /// once so that the dispatch holds only them and no invocation repeats the test.
    pub fn voxel_list(&self, texels: &VolumeTexels) -> Vec<u32> {
        let dims = texels.dims;
        assert!(
            dims.iter().product::<usize>() <= u32::MAX as usize,
            "voxel indices beyond u32"
        );
        let mut mask = self.mask_by_range(texels, |t, lo, hi| {
            let last = t.map[2];
            let a = lo * t.map[0] + t.map[1];
            let b = hi * t.map[0] + t.map[1];
            let first = (a.min(b).floor() - 2.0).clamp(0.0, last) as usize;
            let end = (a.max(b).floor() + 3.0).clamp(0.0, last) as usize;
            t.prefix[end + 1] > t.prefix[first]
        });
        self.keep_in_view(&mut mask);
        let mut list = Vec::new();
        for b in self.list(|i| self.readable[i] != 0) {
            list.extend(
                brick_voxels(b, dims)
                    .map(|v| v[0] + dims[0] * (v[1] + dims[1] * v[2]))
                    .filter(|&i| mask[i])
                    .map(|i| i as u32),
            );
        }
        list
    }

    /// Per voxel (x fastest): its brick is readable and, with a per-voxel test,
    /// `keep(test, lo, hi)` holds for the range of the texels from `below` under it to
    /// `max(below, 1)` over it on every axis (clamped to the volume). The range is taken
    /// separably (a window minimum and maximum along x, then y, then z: the same numbers
    /// as over the cube), in slabs of z-slices.
    fn mask_by_range(
        &self,
        texels: &VolumeTexels,
        keep: impl Fn(&VoxelTest, f32, f32) -> bool + Sync,
    ) -> Vec<bool> {
        use rayon::prelude::*;
        let dims = texels.dims;
        let slice = dims[0] * dims[1];
        let mut mask = vec![false; slice * dims[2]];
        let Some(test) = self.voxels.as_ref() else {
            mask.par_iter_mut()
                .enumerate()
                .for_each(|(i, m)| *m = self.voxel_readable(crate::volume::voxel_of(i, dims)));
            return mask;
        };
        let (below, above) = (test.below, test.below.max(1));
        let window = |c: usize, n: usize| c.saturating_sub(below)..=(c + above).min(n - 1);
        mask.par_chunks_mut(slice * BRICK)
            .enumerate()
            .for_each(|(slab, out)| {
                let z0 = slab * BRICK;
                let z1 = (z0 + BRICK).min(dims[2]);
                let zs = *window(z0, dims[2]).start()..=*window(z1 - 1, dims[2]).end();
                // The in-plane window range of each slice the slab's windows reach.
                let planes: Vec<(Vec<f32>, Vec<f32>)> = zs
                    .clone()
                    .map(|z| plane_ranges(texels, z, &window))
                    .collect();
                for z in z0..z1 {
                    for i in 0..slice {
                        let v = [i % dims[0], i / dims[0], z];
                        let at = &mut out[(z - z0) * slice + i];
                        if !self.voxel_readable(v) {
                            continue;
                        }
                        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                        for zz in window(z, dims[2]) {
                            let (l, h) = &planes[zz - zs.start()];
                            lo = lo.min(l[i]);
                            hi = hi.max(h[i]);
                        }
                        *at = keep(test, lo, hi);
                    }
                }
            });
        mask
    }

    fn index(&self, b: [usize; 3]) -> usize {
        b[0] + self.grid[0] * (b[1] + self.grid[1] * b[2])
    }

    /// Whether step IV must write brick `i` when it is near a shape: its clipped opacity
    /// may be read by a ray (occupied) or its mask by step V (readable).
    pub fn used(&self, i: usize) -> bool {
        self.readable[i] != 0 || self.occupied[i] != 0
    }

    /// The bricks `keep` selects, packed for the shaders ([`pack`]), x fastest.
    pub fn list(&self, keep: impl Fn(usize) -> bool) -> Vec<u32> {
        (0..self.count())
            .filter(|&i| keep(i))
            .map(|i| pack(crate::volume::voxel_of(i, self.grid)))
            .collect()
    }

    /// The bricks `keep` selects, those `near` selects flagged [`NEAR`].
    pub fn list_flagged(
        &self,
        keep: impl Fn(usize) -> bool,
        near: impl Fn(usize) -> bool,
    ) -> Vec<u32> {
        (0..self.count())
            .filter(|&i| keep(i))
            .map(|i| pack(crate::volume::voxel_of(i, self.grid)) | if near(i) { NEAR } else { 0 })
            .collect()
    }

    /// Voxels in the bricks of `list`, clipped to a volume of `dims`.
    pub fn voxels_in(list: &[u32], dims: [usize; 3]) -> u64 {
        list.iter()
            .map(|&p| {
                let b = unpack(p);
                (0..3)
                    .map(|i| (dims[i] - b[i] * BRICK).min(BRICK) as u64)
                    .product::<u64>()
            })
            .sum()
    }

    /// Bricks near any shape of `clip` (see the module docs): inside a carving shape's
    /// clipping-camera box and its bounding sphere ([`ClipCamera::reach_bound`]), both
    /// widened by a voxel, or anywhere when a shape probes. `cameras` are the shapes'
    /// clipping cameras, in the order of `clip`. With skipping off, every brick.
    pub fn near(
        &self,
        dims: [usize; 3],
        spacing: [f32; 3],
        clip: &ClipUniforms,
        cameras: &[ClipCamera],
    ) -> Vec<bool> {
        if self.every_brick(clip, cameras) {
            return vec![true; self.count()];
        }
        let shapes = clip.counts[0] as usize;
        let mut near = vec![false; self.count()];
        let spacing = Vec3::from(spacing);
        let half = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * spacing * 0.5;
        let voxel = spacing.length();
        for (s, camera) in clip.shapes[..shapes].iter().zip(cameras) {
            let res = s.info[2] as f32;
            let (to_volume, centre) = bound_in_volume(s, camera);
            let radius = camera.reach_bound() + voxel;
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for c in 0..8 {
                let m = Vec3::new(
                    if c & 1 == 0 { 0.0 } else { res },
                    if c & 2 == 0 { 0.0 } else { res },
                    if c & 4 == 0 { 0.0 } else { 1.0 },
                );
                let mm = to_volume.transform_point3(m);
                lo = lo.min(mm);
                hi = hi.max(mm);
            }
            if !(lo.is_finite() && hi.is_finite()) {
                return vec![true; self.count()];
            }
            // Voxel coordinates (voxel v spans [v, v + 1]), widened by one voxel.
            let lo = (lo + half) / spacing - Vec3::ONE;
            let hi = (hi + half) / spacing + Vec3::ONE;
            let range = |a: usize| {
                let first = (lo[a].max(0.0) / BRICK as f32).floor() as usize;
                let last = (hi[a].max(0.0) / BRICK as f32).floor() as usize;
                (first.min(self.grid[a]), (last + 1).min(self.grid[a]))
            };
            let (x, y, z) = (range(0), range(1), range(2));
            let box_of = BrickBox { spacing, half };
            for bz in z.0..z.1 {
                for by in y.0..y.1 {
                    for bx in x.0..x.1 {
                        let b = [bx, by, bz];
                        if box_of.meets(b, centre, radius) || !centre.is_finite() {
                            near[self.index(b)] = true;
                        }
                    }
                }
            }
        }
        near
    }

    /// Bricks whose voxels' ambient factor the shapes of `clip` can change at all: those
    /// within `reach_mm` (the LAO reach, [`crate::ao::cao::reach_mm`]) of a brick whose
    /// opacity a shape can lower, that is, an occupied brick that meets a carving
    /// shape's clipping sphere widened by a voxel (a voxel's opacity depends on clip
    /// samples anywhere in its cell). The clipping sphere is the mesh's bound and three
    /// pixels for the maps' quantisation, as [`ClipCamera::reach_bound`] counts them
    /// without the dilation. Elsewhere `V_o = α` within every LAO ray's reach, so a ray
    /// cast gives `V_PAO`'s bits: step IV copies them even where a shape's dilation
    /// reaches (a cut into empty space changes no AO). Every brick when skipping is off
    /// or a shape probes (it clips all around it).
    pub fn reached(
        &self,
        dims: [usize; 3],
        spacing: [f32; 3],
        clip: &ClipUniforms,
        cameras: &[ClipCamera],
        reach_mm: f32,
    ) -> Vec<bool> {
        if self.every_brick(clip, cameras) {
            return vec![true; self.count()];
        }
        let spacing = Vec3::from(spacing);
        let half = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32) * spacing * 0.5;
        let brick_mm = spacing * BRICK as f32;
        let box_of = BrickBox { spacing, half };
        let grid = self.grid.map(|g| g as i64);
        let mut changed = Vec::new();
        let shapes = clip.counts[0] as usize;
        for (s, camera) in clip.shapes[..shapes].iter().zip(cameras) {
            let (centre, carved) = carved_ball(s, camera);
            let radius = carved + spacing.length();
            if !(centre.is_finite() && radius.is_finite()) {
                return vec![true; self.count()];
            }
            let first = ((centre - radius + half) / brick_mm).floor();
            let last = ((centre + radius + half) / brick_mm).floor();
            let range = |a: usize| first[a].max(0.0) as i64..=(last[a] as i64).min(grid[a] - 1);
            for bz in range(2) {
                for by in range(1) {
                    for bx in range(0) {
                        let b = [bx, by, bz].map(|c| c as usize);
                        if self.occupied[self.index(b)] != 0 && box_of.meets(b, centre, radius) {
                            changed.push([bx, by, bz]);
                        }
                    }
                }
            }
        }
        // The offsets between two bricks whose boxes lie within the reach (1 % and
        // 0.01 mm more against rounding).
        let reach = reach_mm * 1.01 + 0.01;
        let n = (Vec3::splat(reach) / brick_mm).ceil().as_ivec3();
        let mut stencil = Vec::new();
        for dz in -n.z..=n.z {
            for dy in -n.y..=n.y {
                for dx in -n.x..=n.x {
                    let d = glam::IVec3::new(dx, dy, dz);
                    let gap = (d.abs() - glam::IVec3::ONE)
                        .max(glam::IVec3::ZERO)
                        .as_vec3();
                    if (gap * brick_mm).length() <= reach {
                        stencil.push([dx as i64, dy as i64, dz as i64]);
                    }
                }
            }
        }
        let mut reached = vec![false; self.count()];
        for c in &changed {
            for d in &stencil {
                let b = [c[0] + d[0], c[1] + d[1], c[2] + d[2]];
                if (0..3).all(|a| (0..grid[a]).contains(&b[a])) {
                    reached[self.index(b.map(|c| c as usize))] = true;
                }
            }
        }
        reached
    }

    /// The balls of step IV's per-ray test (`rays_meet_cut` in `cao_clip.wgsl`), in
    /// volume mm: per carving shape, where a sample can read a texel whose clipped
    /// opacity its cut changed — its carved ball (`carved_ball`) widened by
    /// `margin_mm` (normally [`RAY_TEST_MARGIN`] voxel diagonals: half a diagonal for
    /// the clip samples of the texel's cell, one for the sample's trilinear read), 1 %
    /// and 0.01 mm more against rounding. An LAO ray none of whose samples lies in one
    /// reads `V_o = α` throughout, as `V_PAO`'s did, so its voxel keeps `V_PAO`'s bits.
    /// `None` where every affected voxel must be ray cast: skipping off, a probing
    /// shape, cameras that do not match the shapes, or more than [`MAX_CUT_BALLS`]
    /// shapes.
    pub fn cut_balls(
        &self,
        clip: &ClipUniforms,
        cameras: &[ClipCamera],
        margin_mm: f32,
    ) -> Option<Vec<[f32; 4]>> {
        let shapes = clip.counts[0] as usize;
        if self.every_brick(clip, cameras) || shapes > MAX_CUT_BALLS {
            return None;
        }
        clip.shapes[..shapes]
            .iter()
            .zip(cameras)
            .map(|(s, camera)| {
                let (centre, carved) = carved_ball(s, camera);
                let radius = (carved + margin_mm) * 1.01 + 0.01;
                (centre.is_finite() && radius.is_finite())
                    .then_some([centre.x, centre.y, centre.z, radius])
            })
            .collect()
    }

    /// Whether the shape tests leave every brick in: skipping off, a probing shape
    /// (it clips everything outside it) or cameras that do not match the shapes.
    fn every_brick(&self, clip: &ClipUniforms, cameras: &[ClipCamera]) -> bool {
        !self.skipping || clip.counts[1] > 0 || cameras.len() != clip.counts[0] as usize
    }
}

/// The most carving shapes step IV's per-ray test takes ([`Bricks::cut_balls`]); with
/// more, every affected voxel is ray cast.
pub const MAX_CUT_BALLS: usize = 8;

/// The margin of step IV's per-ray test beyond where a shape can carve, in voxel
/// diagonals ([`Bricks::cut_balls`]).
pub const RAY_TEST_MARGIN: f32 = 1.5;

/// Brick boxes in volume mm, for a volume of `spacing` and half-extent `half`.
struct BrickBox {
    spacing: Vec3,
    half: Vec3,
}

impl BrickBox {
    /// Whether brick `b`'s box meets the ball of `radius` around `centre`.
    fn meets(&self, b: [usize; 3], centre: Vec3, radius: f32) -> bool {
        let brick_mm = self.spacing * BRICK as f32;
        let lo = Vec3::new(b[0] as f32, b[1] as f32, b[2] as f32) * brick_mm - self.half;
        centre.clamp(lo, lo + brick_mm).distance(centre) <= radius
    }
}

/// The smallest and largest texel of slice `z` over `window` along x, then y, per texel
/// of the slice (x fastest).
fn plane_ranges(
    texels: &VolumeTexels,
    z: usize,
    window: &impl Fn(usize, usize) -> std::ops::RangeInclusive<usize>,
) -> (Vec<f32>, Vec<f32>) {
    let [nx, ny, _] = texels.dims;
    let base = z * nx * ny;
    let mut row_lo = vec![0.0; nx * ny];
    let mut row_hi = vec![0.0; nx * ny];
    for y in 0..ny {
        let row: Vec<f32> = (0..nx).map(|x| texels.norm_at(base + y * nx + x)).collect();
        for x in 0..nx {
            let w = &row[window(x, nx)];
            row_lo[y * nx + x] = w.iter().copied().fold(f32::INFINITY, f32::min);
            row_hi[y * nx + x] = w.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        }
    }
    let mut lo = vec![0.0; nx * ny];
    let mut hi = vec![0.0; nx * ny];
    for y in 0..ny {
        for x in 0..nx {
            let (mut l, mut h) = (f32::INFINITY, f32::NEG_INFINITY);
            for yy in window(y, ny) {
                l = l.min(row_lo[yy * nx + x]);
                h = h.max(row_hi[yy * nx + x]);
            }
            lo[y * nx + x] = l;
            hi[y * nx + x] = h;
        }
    }
    (lo, hi)
}

/// The `override` constants that make a skipping pipeline (a shader including
/// `lao_ray.wgsl`) its dense variant, the computation as the papers write it: the
/// skipping code is compiled out, so that `--no-skipping` runs as fast as the plain
/// loops did.
pub const DENSE: Constants = &[("SKIPPING", 0.0)];

/// CAO's dense step IV (`cao_clip.wgsl`): it tests the corners of every voxel itself (the
/// same bits) and marks a voxel when any of its clip samples lies in a dilation (the
/// paper's mask).
pub const DENSE_CLIP: Constants = &[("SHARED_CORNERS", 0.0), ("CENTRE_REACH", 0.0)];

/// Rays from readable voxels (LAO for rendering, CAO's `V_PAO`): they fetch every
/// sample inside the box (`boxed_ray` in `lao_ray.wgsl`: the in-box samples found once
/// per ray instead of a bounds test per sample), the same bits. Such rays start at
/// surfaces and cross occupied cells, where a per-sample cell check costs more than it
/// saves on lavapipe (the cranium CT's 54-ray `V_PAO`: 49.6 s with the check, 39.1 s
/// without); the voxels skipped are the saving.
/// Exported AO volumes (every voxel, most of them in empty space) keep stepping over
/// empty cells.
pub const READABLE: Constants = &[("RAY_SKIPPING", 0.0)];

/// Whether `bricks` computes only readable voxels (whose rays fetch every sample:
/// [`READABLE`]).
pub fn readable_only(bricks: &Bricks) -> bool {
    bricks.skipping && bricks.voxels.is_some()
}

/// CAO's per-frame step V (`cao_lao.wgsl`): rays fetch every sample (the same bits, see
/// `lao_ray.wgsl`), and the readable-voxel test is step IV's (it reads what the `V_PAO`
/// run marked).
pub const FRAME: Constants = &[("RAY_SKIPPING", 0.0), ("FRAME", 1.0)];

/// Bricks per axis for a volume of `dims`.
pub fn grid_of(dims: [usize; 3]) -> [usize; 3] {
    dims.map(|d| d.div_ceil(BRICK).max(1))
}

/// A brick's coordinates as the shaders read them: 10 bits per axis.
pub fn pack(b: [usize; 3]) -> u32 {
    debug_assert!(b.iter().all(|&c| c < MAX_BRICKS_PER_AXIS));
    (b[0] | b[1] << 10 | b[2] << 20) as u32
}

/// The voxels of packed brick `b` inside `dims`, x fastest.
pub fn brick_voxels(b: u32, dims: [usize; 3]) -> impl Iterator<Item = [usize; 3]> {
    let o = unpack(b).map(|c| c * BRICK);
    (0..BRICK * BRICK * BRICK)
        .map(move |i| {
            [
                o[0] + i % BRICK,
                o[1] + (i / BRICK) % BRICK,
                o[2] + i / (BRICK * BRICK),
            ]
        })
        .filter(move |v| (0..3).all(|a| v[a] < dims[a]))
}

pub fn unpack(p: u32) -> [usize; 3] {
    let p = p as usize;
    [p & 0x3ff, (p >> 10) & 0x3ff, (p >> 20) & 0x3ff]
}

/// The LAO rays' empty-space test on the CPU (twin of `empty_run` in `lao_ray.wgsl`):
/// how many samples from `m` on (all before the last, `samples`) have opacity exactly 0
/// because they lie outside the volume or in an unoccupied cell ([`RAY_CELL`]); 0 when
/// sample `m` must be fetched.
pub fn empty_run(
    bricks: &Bricks,
    dims: [usize; 3],
    centre: Vec3,
    step: Vec3,
    m: u32,
    samples: u32,
) -> u32 {
    if !bricks.skipping || m >= samples {
        return 0;
    }
    let uvw = centre + step * m as f32;
    if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
        // A straight ray that has left the box never comes back.
        return samples - m;
    }
    let cells = &bricks.rays;
    let size = Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32);
    let last = Vec3::new(
        (cells.grid[0] - 1) as f32,
        (cells.grid[1] - 1) as f32,
        (cells.grid[2] - 1) as f32,
    );
    let edge = RAY_CELL as f32;
    let b = (uvw * size / edge).floor().min(last);
    let i = b.x as usize + cells.grid[0] * (b.y as usize + cells.grid[1] * b.z as usize);
    if cells.occupied[i] != 0 {
        return 0;
    }
    let lo = b * edge / size;
    let hi = (b + Vec3::ONE) * edge / size;
    let mut exit = f32::INFINITY;
    for a in 0..3 {
        if step[a] > 0.0 {
            exit = exit.min((hi[a] - centre[a]) / step[a]);
        } else if step[a] < 0.0 {
            exit = exit.min((lo[a] - centre[a]) / step[a]);
        }
    }
    // Samples m ..= floor(exit) lie in the cell (m itself does); the texels they read
    // extend half a voxel past it, far more than rounding.
    let inside = (exit.floor().max(m as f32) as u32).min(samples - 1);
    inside - m + 1
}

#[cfg(test)]
mod tests {
    #[test]
    fn dilation_grows_a_box_per_axis() {
        let grid = [5, 4, 3];
        let mut mask = vec![false; 60];
        mask[2 + 5 + 20] = true; // (2, 1, 1)
        let d = super::dilate(&mask, grid, [1, 2, 0]);
        let set: Vec<[usize; 3]> = (0..60)
            .filter(|&i| d[i])
            .map(|i| crate::volume::voxel_of(i, grid))
            .collect();
        assert_eq!(set.len(), 3 * 4);
        assert!(set.iter().all(|v| (1..=3).contains(&v[0]) && v[2] == 1));
    }

    use super::*;

    #[test]
    fn packing_round_trips() {
        for b in [[0, 0, 0], [1023, 0, 5], [3, 1023, 1023], [17, 42, 999]] {
            assert_eq!(unpack(pack(b)), b);
        }
    }

    /// Each variant names constants its shader declares `override`: wgpu would refuse
    /// an unknown one, and a renamed constant must not leave a variant silently the
    /// same as the skipping shader.
    #[test]
    fn every_variant_names_overrides_of_its_shader() {
        let source = |name| crate::gpu::shaders::source(name).expect("embedded shader");
        let declared = |code: &str, constants: Constants| {
            for (name, _) in constants {
                assert!(
                    code.contains(&format!("override {name}: ")),
                    "{name} not declared"
                );
            }
        };
        declared(&source("cao_clip.wgsl"), DENSE_CLIP);
        for shader in ["cao_lao.wgsl", "lao.wgsl"] {
            for constants in [DENSE, READABLE] {
                declared(&source(shader), constants);
            }
        }
        declared(&source("cao_lao.wgsl"), FRAME);
        declared(&source("cao_listed.wgsl"), READABLE);
    }

    #[test]
    fn voxels_in_clips_the_last_bricks() {
        let dims = [20, 8, 9];
        let all = Bricks::dense(dims);
        let list = all.list(|_| true);
        assert_eq!(list.len(), 3 * 2);
        assert_eq!(Bricks::voxels_in(&list, dims), 20 * 8 * 9);
    }
}
