//! [`SlabDispatch`]: the one z-slab loop of every per-voxel compute stage (LAO, the light
//! volume, positional AO, CAO's steps IV and V, cone tracing, the filter passes).
//!
//! A stage bounds the work of one submission (so no dispatch runs into a driver watchdog
//! or the readback bound) and, where it writes a storage buffer, the voxels that buffer
//! holds. The dispatcher cuts the volume into slabs of whole z-slices within both bounds,
//! writes the stage's uniforms for each slab into one buffer (the stage's `Params` struct
//! sets its own slab fields, [`SlabParams::set_slab`]), submits, and optionally copies
//! each slab's output to the host.
//!
//! In the viewer a submission must also be short in time: wgpu has one in-order queue, so
//! a long one delays the UI's own frame behind it. [`Slicing`] sizes submissions for that.

pub use super::slicing::Slicing;
use super::{GpuError, read_buffer, validated};
use crate::gpu::Gpu;
use std::time::Instant;

/// Invocations per workgroup of the linear stages (`@workgroup_size(64)`).
pub const LINEAR_GROUP: u32 = 64;

/// Most workgroups along one dispatch dimension (WebGPU's guaranteed limit).
pub const MAX_GROUPS: u32 = 65535;

/// Work per submission, in ray samples: small enough that no dispatch runs into a driver
/// watchdog (about a second on a mid-range GPU) or the 60 s readback bound on a busy
/// lavapipe, large enough to keep a GPU busy. One place for every stage's budget.
pub mod budget {
    /// LAO and CAO's step V: a trilinear fetch and a LUT lookup per sample.
    pub const LAO_SAMPLES: u64 = 1 << 30;
    /// Light rays and positional AO, whose samples cost more (branches, f16 fetches,
    /// clip tests): at 2^30, one slab of the full Engine outran the 60 s readback bound
    /// on a busy 2-core lavapipe.
    pub const COSTLY_SAMPLES: u64 = 1 << 27;
}

/// How a stage's invocations cover a slab.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grid {
    /// One invocation per voxel of the slab, in 64-wide workgroups folded into two
    /// dimensions; the shader reads its voxel from `row_stride` (see [`Slab`]).
    Linear,
    /// 8×8 workgroups over x and y, one layer of workgroups per z-slice.
    Tiles,
}

/// One slab of z-slices and how it is dispatched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slab {
    /// First z-slice.
    pub z0: u32,
    /// Number of z-slices.
    pub depth: u32,
    /// Voxels in the slab.
    pub voxels: u32,
    /// Linear grids: invocations per row of workgroups (index = y · row_stride + x).
    pub row_stride: u32,
    /// Workgroups to dispatch.
    pub groups: [u32; 3],
}

/// A 1-D index space of `count` invocations in 64-wide workgroups, folded into two
/// dimensions: the workgroups and the invocations per row of them.
pub fn fold_linear(count: u32) -> ([u32; 3], u32) {
    let groups = count.div_ceil(LINEAR_GROUP);
    let gx = groups.clamp(1, MAX_GROUPS);
    let gy = groups.div_ceil(gx);
    ([gx, gy, 1], gx * LINEAR_GROUP)
}

/// The first 16 bytes of every slab stage's uniforms: the volume's size and the first
/// z-slice of this dispatch (each shader's `struct Params` starts with
/// `dims: vec3<u32>, z0: u32`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SlabOrigin {
    pub dims: [u32; 3],
    pub z0: u32,
}

impl SlabOrigin {
    /// The origin of the first slab of a volume of `dims`.
    pub fn of(dims: [u32; 3]) -> Self {
        SlabOrigin { dims, z0: 0 }
    }
}

/// A stage's uniform struct: it knows which of its fields say where the slab is.
pub trait SlabParams: bytemuck::Pod {
    fn set_slab(&mut self, slab: &Slab);
}

/// Implements [`SlabParams`] for a uniform struct with a `slab: SlabOrigin` field
/// (`tiles`), and also `voxels` and `row_stride` (`linear`, the fields a
/// [`Grid::Linear`] shader reads).
macro_rules! slab_fields {
    ($params:ty, tiles) => {
        impl $crate::gpu::dispatch::SlabParams for $params {
            fn set_slab(&mut self, slab: &$crate::gpu::dispatch::Slab) {
                self.slab.z0 = slab.z0;
            }
        }
    };
    ($params:ty, linear) => {
        impl $crate::gpu::dispatch::SlabParams for $params {
            fn set_slab(&mut self, slab: &$crate::gpu::dispatch::Slab) {
                self.slab.z0 = slab.z0;
                self.voxels = slab.voxels;
                self.row_stride = slab.row_stride;
            }
        }
    };
}
pub(crate) use slab_fields;

/// The slabs of one per-voxel pass over a volume.
#[derive(Debug, Clone, Copy)]
pub struct SlabDispatch {
    dims: [u32; 3],
    depth: u32,
    grid: Grid,
    /// Work per voxel, in the budget's units (sizes slabs under a slice time).
    work_per_voxel: u64,
}

impl SlabDispatch {
    /// Slabs of `dims` with at most `budget / work_per_voxel` voxels each (and at most
    /// `max_voxels`, an output buffer's capacity), never less than one z-slice.
    pub fn new(
        dims: [u32; 3],
        grid: Grid,
        work_per_voxel: u64,
        budget: u64,
        max_voxels: u64,
    ) -> Self {
        let slice = (dims[0] as u64 * dims[1] as u64).max(1);
        let nz = dims[2].max(1) as u64;
        let depth = ((budget / work_per_voxel.max(1)).min(max_voxels) / slice).clamp(1, nz) as u32;
        SlabDispatch {
            dims,
            depth,
            grid,
            work_per_voxel: work_per_voxel.max(1),
        }
    }

    /// The whole volume in one slab.
    pub fn whole(dims: [u32; 3], grid: Grid) -> Self {
        SlabDispatch {
            dims,
            depth: dims[2].max(1),
            grid,
            work_per_voxel: 1,
        }
    }

    /// z-slices per slab (the last may be thinner).
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Voxels in the thickest slab: what a per-slab output buffer must hold.
    pub fn max_slab_voxels(&self) -> u64 {
        self.dims[0] as u64 * self.dims[1] as u64 * self.depth as u64
    }

    /// Whether the volume takes more than one slab.
    pub fn is_split(&self) -> bool {
        self.depth < self.dims[2]
    }

    pub fn slabs(&self) -> impl Iterator<Item = Slab> + '_ {
        (0..self.dims[2])
            .step_by(self.depth.max(1) as usize)
            .map(move |z0| self.slab_at(z0, self.depth))
    }

    /// The slab of up to `depth` z-slices from `z0`.
    fn slab_at(&self, z0: u32, depth: u32) -> Slab {
        let [nx, ny, nz] = self.dims;
        let depth = depth.clamp(1, nz.saturating_sub(z0).max(1));
        let voxels = nx * ny * depth;
        let (groups, row_stride) = match self.grid {
            Grid::Linear => fold_linear(voxels),
            Grid::Tiles => ([nx.div_ceil(8), ny.div_ceil(8), depth], 0),
        };
        Slab {
            z0,
            depth,
            voxels,
            row_stride,
            groups,
        }
    }

    /// Runs `pass` over the slabs with `base`'s slab fields set, one submission each
    /// (ending with what `after` encodes), calls `each` after each of them (which waits
    /// for it) and reports progress in z-slices. With a slice time ([`Slicing`]) a slab is as thick as fits in it (never
    /// thicker than [`Self::depth`]) and is waited for before the next.
    fn run_paced<P: SlabParams>(
        &self,
        gpu: &Gpu,
        pass: &Pass<'_>,
        base: P,
        after: impl Fn(&mut wgpu::CommandEncoder, &Slab),
        mut each: impl FnMut(&Slab) -> Result<(), GpuError>,
        progress: &dyn Fn(usize, usize),
    ) -> Result<(), GpuError> {
        let paced = gpu.slicing.is_on();
        let slice = self.dims[0] as u64 * self.dims[1] as u64 * self.work_per_voxel;
        let mut z0 = 0;
        while z0 < self.dims[2] {
            let max = self.depth as u64 * slice;
            let depth = (gpu.slicing.units(pass.label, max) / slice).max(1) as u32;
            let slab = self.slab_at(z0, depth.min(self.depth));
            let start = Instant::now();
            let mut p = base;
            p.set_slab(&slab);
            pass.submit(gpu, &p, slab.groups, |encoder| after(encoder, &slab))?;
            each(&slab)?;
            if paced {
                gpu.slicing
                    .measured(pass.label, slab.depth as u64 * slice, start.elapsed());
            }
            z0 += slab.depth;
            progress(z0 as usize, self.dims[2] as usize);
        }
        Ok(())
    }

    /// Runs `pass` once per slab writing `out` (f32 per voxel of the slab), copies each
    /// slab's values to `readback` and returns them all, x fastest.
    pub fn run_readback<P: SlabParams>(
        &self,
        gpu: &Gpu,
        pass: &Pass<'_>,
        base: P,
        out: &wgpu::Buffer,
        readback: &wgpu::Buffer,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Vec<f32>, GpuError> {
        let total = self.dims.iter().map(|&d| d as usize).product();
        let mut result = Vec::with_capacity(total);
        self.run_paced(
            gpu,
            pass,
            base,
            |encoder, slab| {
                encoder.copy_buffer_to_buffer(out, 0, readback, 0, slab.voxels as u64 * 4);
            },
            |slab| {
                let bytes = slab.voxels as usize * 4;
                let back = read_buffer(&gpu.device, readback, pass.label)?;
                result.extend(bytemuck::pod_collect_to_vec::<u8, f32>(&back[..bytes]));
                Ok(())
            },
            progress,
        )?;
        Ok(result)
    }
}

/// What one slab pass binds: its pipeline, its bind groups (index, group) and the
/// uniform buffer the dispatcher rewrites for every slab (bound in one of the groups).
#[derive(Debug, Clone, Copy)]
pub struct Pass<'a> {
    pub label: &'a str,
    pub pipeline: &'a wgpu::ComputePipeline,
    pub bind_groups: &'a [(u32, &'a wgpu::BindGroup)],
    pub uniforms: &'a wgpu::Buffer,
}

impl Pass<'_> {
    /// One submission: `params` into the uniform buffer (ordered before this
    /// submission's commands and after the previous one's), `groups` workgroups, then
    /// whatever `after` encodes.
    fn submit<P: bytemuck::Pod>(
        &self,
        gpu: &Gpu,
        params: &P,
        groups: [u32; 3],
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<(), GpuError> {
        validated(&gpu.device, self.label, || {
            gpu.queue
                .write_buffer(self.uniforms, 0, bytemuck::bytes_of(params));
            super::submit_compute_with(
                &gpu.device,
                &gpu.queue,
                self.label,
                self.pipeline,
                self.bind_groups,
                groups,
                after,
            );
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn slabs_cover_the_volume_once_within_the_budget() {
        for (dims, per_voxel, budget, cap) in [
            ([7, 5, 13], 10, 700, u64::MAX),
            ([7, 5, 13], 10, 1, u64::MAX),
            ([7, 5, 13], 1, u64::MAX, 70),
            ([1, 1, 1], 1, 1, 1),
        ] {
            for grid in [Grid::Linear, Grid::Tiles] {
                let d = SlabDispatch::new(dims, grid, per_voxel, budget, cap);
                let mut z = 0;
                for s in d.slabs() {
                    assert_eq!(s.z0, z);
                    assert!(s.depth >= 1 && s.depth <= d.depth());
                    assert_eq!(s.voxels, dims[0] * dims[1] * s.depth);
                    let invocations = match grid {
                        Grid::Linear => s.groups[0] as u64 * s.groups[1] as u64 * 64,
                        Grid::Tiles => {
                            s.groups[0] as u64 * 8 * s.groups[1] as u64 * 8 * s.groups[2] as u64
                        }
                    };
                    assert!(invocations >= s.voxels as u64);
                    z += s.depth;
                }
                assert_eq!(z, dims[2]);
                let slab_voxels = d.max_slab_voxels();
                assert!(d.depth() == 1 || slab_voxels * per_voxel <= budget);
                assert!(d.depth() == 1 || slab_voxels <= cap);
            }
        }
    }

    #[test]
    fn slices_stay_full_when_they_wait_behind_other_work() {
        let s = Slicing::default();
        assert_eq!(s.units("x", 1234), 1234, "no slice time: the whole budget");
        s.set_target(Some(Duration::from_millis(30)));
        // The device does 1e8 units/s; every other submission also waited 70 ms behind
        // the UI's frames, which taken at face value would shrink the slices to nothing.
        let mut units = s.units("x", u64::MAX);
        for i in 0..200 {
            let wait = if i % 2 == 1 { 0.07 } else { 0.0 };
            let took = units as f64 / 1e8 + wait;
            s.measured("x", units, Duration::from_secs_f64(took));
            units = s.units("x", u64::MAX);
        }
        let slice_ms = units as f64 / 1e8 * 1e3;
        assert!((20.0..=30.5).contains(&slice_ms), "{slice_ms} ms slices");
        // A device that really got slower is followed.
        for _ in 0..200 {
            s.measured("x", units, Duration::from_secs_f64(units as f64 / 1e7));
            units = s.units("x", u64::MAX);
        }
        let slice_ms = units as f64 / 1e7 * 1e3;
        assert!(
            (20.0..=30.5).contains(&slice_ms),
            "{slice_ms} ms after slowing down"
        );
    }

    #[test]
    fn linear_folding_stays_within_the_dispatch_limit() {
        for count in [1, 64, 65, 64 * 65535, 64 * 65535 + 1, 300_000_000] {
            let (g, row) = fold_linear(count);
            assert!(g[0] <= MAX_GROUPS && g[1] <= MAX_GROUPS);
            assert_eq!(row, g[0] * 64);
            assert!(g[0] as u64 * g[1] as u64 * 64 >= count as u64);
        }
    }
}

/// The uniforms of a brick-list stage: the volume's size, then where this submission's
/// bricks start in the list, how many there are and the workgroups per row (each
/// shader's `struct Params` starts with `dims: vec4<u32>, chunk: vec4<u32>`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BrickChunk {
    pub dims: [u32; 3],
    pub _pad: u32,
    /// First brick of this submission in the list, bricks in it, workgroups per row,
    /// unused.
    pub chunk: [u32; 4],
}

impl BrickChunk {
    pub fn of(dims: [u32; 3]) -> Self {
        BrickChunk {
            dims,
            _pad: 0,
            chunk: [0; 4],
        }
    }
}

/// A uniform struct with a `bricks: BrickChunk` field that the dispatcher sets.
pub trait ChunkParams: bytemuck::Pod {
    fn set_chunk(&mut self, first: u32, count: u32, row: u32);
}

macro_rules! chunk_fields {
    ($params:ty) => {
        impl $crate::gpu::dispatch::ChunkParams for $params {
            fn set_chunk(&mut self, first: u32, count: u32, row: u32) {
                self.bricks.chunk = [first, count, row, 0];
            }
        }
    };
}
pub(crate) use chunk_fields;

/// One pass over a list of 8³ bricks (`ao::sparse`): the dispatch size follows the list,
/// not the volume. A workgroup is 8 × 8 voxels of one brick layer; `[8, row, rows]`
/// workgroups cover a submission's bricks (layer = x, brick = first + y + z · row), so
/// that consecutive workgroups work on one brick.
/// Submissions are cut, like slabs, so that none exceeds the work budget.
#[derive(Debug, Clone, Copy)]
pub struct BrickDispatch {
    /// Where the list starts in the bound brick buffer.
    offset: u32,
    bricks: u32,
    per_submission: u32,
    /// Work per voxel, in the budget's units.
    work_per_voxel: u64,
}

impl BrickDispatch {
    /// A list of `bricks` bricks of 512 voxels starting at `offset` in the brick buffer,
    /// with `work_per_voxel` each, at most `budget` per submission (and at most
    /// `max_bricks`, an output buffer's capacity).
    pub fn new(
        offset: usize,
        bricks: usize,
        work_per_voxel: u64,
        budget: u64,
        max_bricks: u64,
    ) -> Self {
        let per = (budget / (512 * work_per_voxel.max(1))).clamp(1, max_bricks.max(1));
        BrickDispatch {
            offset: offset as u32,
            bricks: bricks as u32,
            per_submission: per.min(u32::MAX as u64) as u32,
            work_per_voxel: work_per_voxel.max(1),
        }
    }

    /// (first brick in the list, bricks) of each submission.
    pub fn chunks(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        (0..self.bricks)
            .step_by(self.per_submission.max(1) as usize)
            .map(move |first| (first, self.per_submission.min(self.bricks - first)))
    }

    pub fn len(&self) -> u32 {
        self.bricks
    }

    pub fn is_empty(&self) -> bool {
        self.bricks == 0
    }

    /// Bricks in the largest submission.
    pub fn max_chunk(&self) -> u32 {
        self.per_submission.min(self.bricks)
    }

    /// Work of one brick, in the budget's units.
    pub fn brick_work(&self) -> u64 {
        512 * self.work_per_voxel
    }

    /// Submits the chunk of up to `count` bricks from `first` (counted from the list's
    /// start; at most [`Self::max_chunk`]) with `after(encoder)` at its end; returns the
    /// bricks submitted.
    pub fn submit_chunk<P: ChunkParams>(
        &self,
        gpu: &Gpu,
        pass: &Pass<'_>,
        base: P,
        (first, count): (u32, u32),
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> Result<u32, GpuError> {
        let count = count
            .clamp(1, self.per_submission.max(1))
            .min(self.bricks.saturating_sub(first));
        if count == 0 {
            return Ok(0);
        }
        let row = count.clamp(1, MAX_GROUPS);
        let rows = count.div_ceil(row);
        let mut p = base;
        p.set_chunk(self.offset + first, count, row);
        pass.submit(gpu, &p, [8, row, rows], after)?;
        Ok(count)
    }

    /// Runs `pass` once per chunk (one submission each) with `base`'s chunk fields set,
    /// calling `after(encoder, first, count)` in each submission's encoder (to copy its
    /// output) and `each(first, count)` after submitting it (first counts from the
    /// list's start). With `wait_between`, waits for each chunk before the next. With a
    /// slice time ([`Slicing`]) a chunk holds the bricks that fit in it and is always
    /// waited for.
    pub fn run<P: ChunkParams>(
        &self,
        gpu: &Gpu,
        pass: &Pass<'_>,
        base: P,
        wait_between: bool,
        mut each: impl FnMut(u32, u32) -> Result<(), GpuError>,
        after: impl Fn(&mut wgpu::CommandEncoder, u32, u32),
    ) -> Result<(), GpuError> {
        let paced = gpu.slicing.is_on();
        let wait = paced || (wait_between && self.bricks > self.per_submission);
        let brick = self.brick_work();
        let mut first = 0;
        while first < self.bricks {
            let max = self.per_submission.max(1) as u64 * brick;
            let wanted = (gpu.slicing.units(pass.label, max) / brick).max(1) as u32;
            let count = wanted
                .min(self.per_submission.max(1))
                .min(self.bricks - first);
            let start = Instant::now();
            self.submit_chunk(gpu, pass, base, (first, count), |encoder| {
                after(encoder, first, count)
            })?;
            if wait {
                super::wait(&gpu.device, pass.label, super::WAIT)?;
            }
            each(first, count)?;
            if paced {
                gpu.slicing
                    .measured(pass.label, count as u64 * brick, start.elapsed());
            }
            first += count;
        }
        Ok(())
    }
}
