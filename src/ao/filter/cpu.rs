//! CPU twin of the filter stage, cache-blocked so that a whole CT takes tens of
//! milliseconds rather than hundreds.
//!
//! The arithmetic is that of `box_stats.wgsl`: the same van Herk / Gil-Werman segments,
//! the same runs, the same operations in the same order (x, then y, then z), so every
//! statistic is bit for bit the one the straightforward three-volume twin computed, and
//! the GPU's up to its own rounding. Only the schedule differs, one z segment of `L`
//! slices at a time:
//!
//! 1. **Per slice** (in parallel), for the slices the segment needs and no earlier one
//!    did: decode the source values, then per statistic the x pass and the y pass, into
//!    a ring of `L + 2r` planes. The x pass runs on [`LANES`] rows at once, interleaved,
//!    so that its runs are as wide as the y pass's.
//! 2. **Per tile of the slice** (in parallel): the z pass over the ring, and straight
//!    away the maps (or the raw statistics) of the segment's voxels. The ring is stored
//!    tile by tile, so a tile's planes lie together, and they are swept once in order
//!    ([`warm`]) before the z runs read them.
//!
//! Every run keeps [`COLUMNS`] floats (the x pass: [`LANES`]) in registers from one
//! element to the next, so a step of a run is a load, an operation and a store.
//!
//! So the 3-D statistics never exist as whole volumes, each plane is computed once, and
//! only the statistics the requested maps read are computed ([`Stat::needed_by`]).
//! [`FilterCpu`] keeps the ring, the per-thread scratch and (with
//! [`FilterCpu::compute_into`]) the outputs between calls.

use super::{AmbientMap, BIG, BoxStats, Source, ambient_run, segment_len, window_count};
use crate::texels::VolumeTexels;
use rayon::prelude::*;

/// Rows the x pass interleaves (16 floats: four SSE or two AVX2 registers per step).
const LANES: usize = 16;

/// Voxels of a slice that one z-pass task owns (2 KiB per statistic and slice: a
/// segment's planes of one statistic fit in L2, its z runs in L1).
const TILE: usize = 512;

/// Floats of a y or z run kept in registers at once (four AVX2 registers).
const COLUMNS: usize = 32;

/// One of the four box statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stat {
    Min,
    Max,
    Sum,
    SumSq,
}

impl Stat {
    const ALL: [Stat; 4] = [Stat::Min, Stat::Max, Stat::Sum, Stat::SumSq];

    fn index(self) -> usize {
        self as usize
    }

    /// The statistics `map` reads: the CDF needs no E[v²], the variance no extremes;
    /// Penner and the Gaussian need the extremes to recognise a homogeneous box.
    fn needed_by(map: AmbientMap) -> &'static [Stat] {
        match map {
            AmbientMap::Cdf => &[Stat::Min, Stat::Max, Stat::Sum],
            AmbientMap::Penner | AmbientMap::Gauss => &Stat::ALL,
            AmbientMap::Variance => &[Stat::Sum, Stat::SumSq],
        }
    }
}

/// The associative operation of one statistic, with its identity.
trait Op {
    const IDENTITY: f32;
    fn op(a: f32, b: f32) -> f32;
}

struct MinOp;
struct MaxOp;
struct AddOp;

impl Op for MinOp {
    const IDENTITY: f32 = BIG;
    #[inline(always)]
    fn op(a: f32, b: f32) -> f32 {
        if b < a { b } else { a }
    }
}

impl Op for MaxOp {
    const IDENTITY: f32 = -BIG;
    #[inline(always)]
    fn op(a: f32, b: f32) -> f32 {
        if b > a { b } else { a }
    }
}

impl Op for AddOp {
    const IDENTITY: f32 = 0.0;
    #[inline(always)]
    fn op(a: f32, b: f32) -> f32 {
        a + b
    }
}

/// One segment of a line of `n` elements of `elem` floats each (element `a` is
/// `at(a)`): writes the windows `[i − r, i + r]` of outputs `i ∈ [c, c + L)` into `out`
/// (`elem` floats each, contiguous). The same runs in the same order as `main` in
/// `box_stats.wgsl`: suffixes `S = op(v, S)` backward from the pivot, prefixes
/// `P = op(P, v)` forward, then `op(S, P)`. The elements are taken `W` floats at a
/// time, whose runs stay in registers (then one float at a time for the rest).
#[inline(always)]
fn segment<'a, O: Op, const W: usize>(
    at: impl Fn(usize) -> &'a [f32],
    line: (usize, usize, usize),
    c: usize,
    out: &mut [f32],
) {
    let elem = line.1;
    let mut col = 0;
    while col + W <= elem {
        segment_columns::<O, W>(&at, line, c, col, out);
        col += W;
    }
    while col < elem {
        segment_columns::<O, 1>(&at, line, c, col, out);
        col += 1;
    }
}

/// [`segment`] for the `W` floats of every element starting at float `col`.
#[inline(always)]
fn segment_columns<'a, O: Op, const W: usize>(
    at: &impl Fn(usize) -> &'a [f32],
    (n, elem, r): (usize, usize, usize),
    c: usize,
    col: usize,
    out: &mut [f32],
) {
    let outs = segment_len(r).min(n - c);
    let (ci, ri, ni) = (c as i64, r as i64, n as i64);
    let (m, first) = (ci + ri, ci - ri);
    let load = |a: usize| -> &[f32; W] {
        at(a)[col..col + W]
            .try_into()
            .unwrap_or_else(|_| unreachable!("W floats"))
    };
    // S[j] for j = a − first; the run reaches j ≤ 2r − 1, so S[2r] (when L = 2r + 1)
    // is the empty suffix. Suffixes beyond the last output (a segment cut short by the
    // line's end) are only accumulated.
    let mut suffix = [O::IDENTITY; W];
    for j in (2 * r).min(outs)..outs {
        *columns_mut(out, j * elem + col) = suffix;
    }
    let mut a = m - 1;
    while a >= first {
        // Outside the line the run is cropped: a < 0 repeats S[j + 1], a ≥ n adds
        // nothing (and lies beyond the last output).
        if a >= 0 && a < ni {
            for (s, &v) in suffix.iter_mut().zip(load(a as usize)) {
                *s = O::op(v, *s);
            }
        }
        let j = (a - first) as usize;
        if j < outs {
            *columns_mut(out, j * elem + col) = suffix;
        }
        a -= 1;
    }
    let mut prefix = [O::IDENTITY; W];
    for j in 0..outs {
        let b = m as usize + j;
        if b < n {
            for (p, &v) in prefix.iter_mut().zip(load(b)) {
                *p = O::op(*p, v);
            }
        }
        for (o, &p) in columns_mut::<W>(out, j * elem + col)
            .iter_mut()
            .zip(&prefix)
        {
            *o = O::op(*o, p);
        }
    }
}

/// The `W` floats of `out` from `start`.
#[inline(always)]
fn columns_mut<const W: usize>(out: &mut [f32], start: usize) -> &mut [f32; W] {
    (&mut out[start..start + W])
        .try_into()
        .unwrap_or_else(|_| unreachable!("W floats"))
}

/// [`segment`] with the statistic's operation.
#[inline(always)]
fn stat_segment<'a, const W: usize>(
    stat: Stat,
    at: impl Fn(usize) -> &'a [f32],
    line: (usize, usize, usize),
    c: usize,
    out: &mut [f32],
) {
    match stat {
        Stat::Min => segment::<MinOp, W>(at, line, c, out),
        Stat::Max => segment::<MaxOp, W>(at, line, c, out),
        Stat::Sum | Stat::SumSq => segment::<AddOp, W>(at, line, c, out),
    }
}

/// Every segment of a line whose `n` elements of `elem` floats lie contiguously in
/// `input`; outputs contiguous in `out`. `W` as in [`segment`].
#[inline(always)]
fn line_pass<const W: usize>(
    stat: Stat,
    input: &[f32],
    (n, elem, r): (usize, usize, usize),
    out: &mut [f32],
) {
    let len = segment_len(r);
    for c in (0..n).step_by(len) {
        let end = (c + len).min(n);
        let at = |a: usize| &input[a * elem..(a + 1) * elem];
        stat_segment::<W>(stat, at, (n, elem, r), c, &mut out[c * elem..end * elem]);
    }
}

/// The source values the statistics are taken of, decoded a run of voxels at a time.
#[derive(Debug, Clone, Copy)]
enum Values<'a> {
    Texels(&'a VolumeTexels, &'a Source),
    Plain(&'a [f32], [usize; 3]),
}

impl Values<'_> {
    fn dims(&self) -> [usize; 3] {
        match self {
            Values::Texels(t, _) => t.dims,
            Values::Plain(_, dims) => *dims,
        }
    }

    /// Voxels `start..start + out.len()` (x fastest) into `out`.
    #[inline(always)]
    fn decode(&self, start: usize, out: &mut [f32]) {
        match self {
            Values::Texels(t, source) => source.decode(t, start, out),
            Values::Plain(v, _) => out.copy_from_slice(&v[start..start + out.len()]),
        }
    }
}

/// Per-thread buffers of the slice stage.
#[derive(Debug, Default)]
struct SliceScratch {
    values: Vec<f32>,
    /// The slice's values, [`LANES`] rows interleaved: `packed[(g · nx + x) · LANES + k]`
    /// is row `g · LANES + k`.
    packed: Vec<f32>,
    /// The same for the squares.
    packed_sq: Vec<f32>,
    packed_out: Vec<f32>,
    xs: Vec<f32>,
    /// The y pass's output, before it is dealt out to the ring's tiles.
    plane: Vec<f32>,
}

/// The x and y passes of every wanted statistic over slice `z`, into `outs`.
#[inline(always)]
fn slice_planes(
    input: Values,
    z: usize,
    r: [usize; 3],
    outs: Vec<(Stat, Vec<&mut [f32]>)>,
    s: &mut SliceScratch,
) {
    let [nx, ny, _] = input.dims();
    let groups = ny.div_ceil(LANES);
    s.values.resize(nx * ny, 0.0);
    s.packed.resize(groups * nx * LANES, 0.0);
    s.packed_out.resize(nx * LANES, 0.0);
    s.xs.resize(nx * ny, 0.0);
    s.plane.resize(nx * ny, 0.0);
    input.decode(z * nx * ny, &mut s.values);
    // Interleave once for all statistics, so that each step of an x run is one wide
    // operation.
    for (g, group) in s.packed.chunks_exact_mut(nx * LANES).enumerate() {
        let rows = LANES.min(ny - g * LANES);
        for k in 0..rows {
            let row = &s.values[(g * LANES + k) * nx..][..nx];
            for (lanes, &v) in group.chunks_exact_mut(LANES).zip(row) {
                lanes[k] = v;
            }
        }
    }
    if outs.iter().any(|(stat, _)| *stat == Stat::SumSq) {
        s.packed_sq.clear();
        s.packed_sq.extend(s.packed.iter().map(|v| v * v));
    }
    for (stat, out) in outs {
        let packed = if stat == Stat::SumSq {
            &s.packed_sq
        } else {
            &s.packed
        };
        for (g, group) in packed.chunks_exact(nx * LANES).enumerate() {
            line_pass::<LANES>(stat, group, (nx, LANES, r[0]), &mut s.packed_out);
            let rows = LANES.min(ny - g * LANES);
            for k in 0..rows {
                let row = &mut s.xs[(g * LANES + k) * nx..][..nx];
                for (o, lanes) in row.iter_mut().zip(s.packed_out.chunks_exact(LANES)) {
                    *o = lanes[k];
                }
            }
        }
        // y: elements are whole rows.
        line_pass::<COLUMNS>(stat, &s.xs, (ny, nx, r[1]), &mut s.plane);
        for (dst, src) in out.into_iter().zip(s.plane.chunks(TILE)) {
            dst[..src.len()].copy_from_slice(src);
        }
    }
}

/// What the z stage writes per voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Output {
    Map(AmbientMap),
    Stat(Stat),
}

/// A slice and the planes (one per wanted statistic) its x and y passes fill.
type SliceJob<'a> = (usize, Vec<(Stat, Vec<&'a mut [f32]>)>);

/// Per-thread buffers of the z stage.
#[derive(Debug, Default)]
struct TileScratch {
    /// Where in the ring the tile's parts of the planes a z segment reads start.
    rows: Vec<usize>,
    values: Vec<f32>,
    /// Per wanted statistic, one segment of z outputs of the tile.
    stats: Vec<Vec<f32>>,
    /// Box sizes of tile `counts_for.0`'s voxels in slices whose z window holds
    /// `counts_for.1` voxels.
    counts: Vec<f32>,
    counts_for: Option<(usize, usize)>,
}

/// A thread's buffers.
#[derive(Debug, Default)]
struct Scratch {
    slice: SliceScratch,
    tile: TileScratch,
}

/// The CPU twin with its buffers kept between calls: the ring of 2-D statistics planes
/// and each worker thread's scratch, so that a map computed again (after a
/// transfer-function edit, say) allocates nothing but its output, and nothing at all
/// with [`FilterCpu::compute_into`]. On x86-64 CPUs with AVX2 the hot stages run a
/// build for it, eight floats wide.
#[derive(Debug)]
pub struct FilterCpu {
    /// Per wanted statistic, `slots` planes, tile-major: the [`TILE`] voxels of tile `t`
    /// in slot `slot` are chunk `t · slots + slot`.
    ring: Vec<Vec<f32>>,
    /// One per rayon worker thread (by `rayon::current_thread_index`), plus one for
    /// calls from outside the pool.
    scratch: Vec<std::sync::Mutex<Scratch>>,
    simd: Simd,
}

impl Default for FilterCpu {
    fn default() -> Self {
        FilterCpu {
            ring: Vec::new(),
            scratch: Vec::new(),
            simd: Simd::detect(),
        }
    }
}

impl FilterCpu {
    /// A twin that runs the target's baseline build even where the CPU has AVX2 (to
    /// check that both give the same bits).
    pub fn baseline() -> Self {
        FilterCpu {
            simd: Simd::Baseline,
            ..Default::default()
        }
    }

    /// Box statistics of `values` (x fastest) over the cropped box of every voxel: the
    /// CPU twin of the three `box_stats.wgsl` passes.
    pub fn box_stats(&mut self, values: &[f32], dims: [usize; 3], radius: [u32; 3]) -> BoxStats {
        let outputs = Stat::ALL.map(Output::Stat);
        let mut results = Vec::new();
        self.run(Values::Plain(values, dims), radius, &outputs, &mut results);
        let [min, max, sum, sum_sq]: [Vec<f32>; 4] = results
            .try_into()
            .unwrap_or_else(|_| unreachable!("one result per output"));
        BoxStats {
            dims,
            radius,
            min,
            max,
            sum,
            sum_sq,
        }
    }

    /// Source values, the statistics `maps` read, then each map, x fastest.
    pub fn compute(
        &mut self,
        texels: &VolumeTexels,
        source: &Source,
        radius: [u32; 3],
        maps: &[AmbientMap],
    ) -> Vec<Vec<f32>> {
        let mut results = Vec::new();
        self.compute_into(texels, source, radius, maps, &mut results);
        results
    }

    /// [`Self::compute`] into `results`, whose allocations are reused: a map recomputed
    /// into the buffers it was last written to costs no fresh memory.
    pub fn compute_into(
        &mut self,
        texels: &VolumeTexels,
        source: &Source,
        radius: [u32; 3],
        maps: &[AmbientMap],
        results: &mut Vec<Vec<f32>>,
    ) {
        let outputs: Vec<Output> = maps.iter().map(|&m| Output::Map(m)).collect();
        self.run(Values::Texels(texels, source), radius, &outputs, results);
    }

    /// Runs `f` with the calling thread's scratch.
    fn with_scratch<R>(
        scratch: &[std::sync::Mutex<Scratch>],
        f: impl FnOnce(&mut Scratch) -> R,
    ) -> R {
        let last = scratch.len() - 1;
        let i = rayon::current_thread_index().map_or(last, |i| i.min(last));
        let mut s = scratch[i].lock().unwrap_or_else(|e| e.into_inner());
        f(&mut s)
    }

    /// Everything: a ring of 2-D statistics planes per wanted statistic, filled one
    /// segment of slices ahead of the z pass, which writes the outputs tile by tile.
    fn run(
        &mut self,
        input: Values,
        radius: [u32; 3],
        outputs: &[Output],
        results: &mut Vec<Vec<f32>>,
    ) {
        let r = radius.map(|r| r as usize);
        let [nx, ny, nz] = input.dims();
        let slice = nx * ny;
        let flags = wanted(outputs);
        let stats: Vec<Stat> = Stat::ALL.into_iter().filter(|s| flags[s.index()]).collect();
        let len = segment_len(r[2]);
        // Segment c reads planes c − r .. c + L + r: that many slots, each slice
        // computed once. Old contents are never read: every slot is written first.
        let slots = (len + 2 * r[2]).min(nz);
        self.ring.resize_with(stats.len(), Vec::new);
        for plane in &mut self.ring {
            plane.resize(slots * slice.div_ceil(TILE) * TILE, 0.0);
        }
        let threads = rayon::current_num_threads() + 1;
        if self.scratch.len() != threads {
            self.scratch = (0..threads).map(|_| Default::default()).collect();
        }
        // A tile's box sizes depend on this run's dims and radius: none is kept from an
        // earlier run (a thread that took no tile since could otherwise reuse the sizes of
        // another volume's tile of the same index and z window).
        for s in &self.scratch {
            s.lock().unwrap_or_else(|e| e.into_inner()).tile.counts_for = None;
        }
        let (ring, scratch, simd) = (&mut self.ring, &self.scratch, self.simd);
        // Every voxel of every output is written below, so old contents may stay.
        results.resize_with(outputs.len(), Vec::new);
        for result in results.iter_mut() {
            result.resize(slice * nz, 0.0);
        }
        // Window sizes: x · y per slice position, z per slice.
        let cz: Vec<usize> = (0..nz).map(|z| window_count(z, r[2], nz)).collect();
        let cxy: Vec<usize> = (0..slice)
            .map(|i| window_count(i % nx, r[0], nx) * window_count(i / nx, r[1], ny))
            .collect();
        let needs_values = outputs.iter().any(|o| matches!(o, Output::Map(_)));
        // Per tile, per output, its part of every slice.
        let mut tiles: Vec<Vec<Vec<&mut [f32]>>> = (0..slice.div_ceil(TILE))
            .map(|_| outputs.iter().map(|_| Vec::with_capacity(nz)).collect())
            .collect();
        for (o, result) in results.iter_mut().enumerate() {
            for part in result.chunks_mut(slice) {
                for (t, tile) in part.chunks_mut(TILE).enumerate() {
                    tiles[t][o].push(tile);
                }
            }
        }
        let mut planned = 0;
        for c in (0..nz).step_by(len) {
            // The planes this segment still lacks, in parallel over slices.
            let upto = (c + len + r[2]).min(nz);
            let mut jobs: Vec<SliceJob> = (planned..upto).map(|z| (z, Vec::new())).collect();
            let mut job_of_slot = vec![None; slots];
            for (k, (z, _)) in jobs.iter().enumerate() {
                job_of_slot[z % slots] = Some(k);
            }
            for (&stat, plane) in stats.iter().zip(ring.iter_mut()) {
                for job in &mut jobs {
                    job.1.push((stat, Vec::with_capacity(tiles.len())));
                }
                // Tile-major: the TILE voxels of tile t in slot `slot` (which holds the
                // slices ≡ slot mod slots; at most one is new) are chunk t · slots + slot.
                for (i, part) in plane.chunks_mut(TILE).enumerate() {
                    if let Some(job) = job_of_slot[i % slots] {
                        jobs[job].1.last_mut().expect("pushed above").1.push(part);
                    }
                }
            }
            jobs.into_par_iter().for_each(|(z, outs)| {
                Self::with_scratch(scratch, |s| {
                    simd.slice_planes(input, z, r, outs, &mut s.slice)
                })
            });
            planned = upto;
            // The z pass and the outputs of slices c .. c + L, in parallel over tiles.
            let ring = &*ring;
            let pass = ZPass {
                input,
                outputs,
                stats: &stats,
                ring,
                slots,
                len,
                r,
                cz: &cz,
                cxy: &cxy,
                needs_values,
            };
            tiles.par_iter_mut().enumerate().for_each(|(t, outs)| {
                Self::with_scratch(scratch, |s| simd.z_tile(&pass, t, c, outs, &mut s.tile))
            });
        }
    }
}

/// What every tile of the z stage shares.
struct ZPass<'a> {
    input: Values<'a>,
    outputs: &'a [Output],
    /// The wanted statistics, in ring order.
    stats: &'a [Stat],
    ring: &'a [Vec<f32>],
    slots: usize,
    /// Segment length along z.
    len: usize,
    r: [usize; 3],
    /// Window sizes: along z per slice, x · y per position in a slice.
    cz: &'a [usize],
    cxy: &'a [usize],
    needs_values: bool,
}

/// The z pass of tile `t` for the segment starting at slice `c`, and the outputs of its
/// voxels in those slices (`outs[output][z]` is the tile's part of slice z).
#[inline(always)]
fn z_tile(p: &ZPass, t: usize, c: usize, outs: &mut [Vec<&mut [f32]>], s: &mut TileScratch) {
    let [nx, ny, nz] = p.input.dims();
    let slice = nx * ny;
    let t0 = t * TILE;
    let w = TILE.min(slice - t0);
    let outs_here = p.len.min(nz - c);
    s.values.resize(w, 0.0);
    s.counts.resize(w, 0.0);
    s.stats.resize_with(p.stats.len(), Vec::new);
    // Where the tile's part of each plane the segment reads starts in the ring.
    let lo = c.saturating_sub(p.r[2]);
    s.rows.clear();
    s.rows
        .extend((lo..(c + p.len + p.r[2]).min(nz)).map(|a| (t * p.slots + a % p.slots) * TILE));
    for (k, &stat) in p.stats.iter().enumerate() {
        s.stats[k].resize(p.len * w, 0.0);
        let (rows, ring) = (&s.rows, &p.ring[k]);
        let at = |a: usize| &ring[rows[a - lo]..][..w];
        warm(ring, rows, w);
        let out = &mut s.stats[k][..outs_here * w];
        stat_segment::<COLUMNS>(stat, at, (nz, w, p.r[2]), c, out);
    }
    for j in 0..outs_here {
        let z = c + j;
        if p.needs_values {
            p.input.decode(z * slice + t0, &mut s.values[..w]);
            if s.counts_for != Some((t, p.cz[z])) {
                s.counts_for = Some((t, p.cz[z]));
                for (n, &cxy) in s.counts.iter_mut().zip(&p.cxy[t0..t0 + w]) {
                    *n = (cxy * p.cz[z]) as f32;
                }
            }
        }
        let row = |stat: Stat| -> &[f32] {
            match p.stats.iter().position(|&s| s == stat) {
                Some(k) => &s.stats[k][j * w..(j + 1) * w],
                None => &[],
            }
        };
        for (output, parts) in p.outputs.iter().zip(outs.iter_mut()) {
            let dst = &mut *parts[z];
            match *output {
                Output::Stat(stat) => dst.copy_from_slice(row(stat)),
                Output::Map(map) => {
                    ambient_run(map, &s.values[..w], Stat::ALL.map(row), &s.counts[..w], dst)
                }
            }
        }
    }
}

/// Reads one float per cache line of each of `rows` (`w` floats from each offset into
/// `ring`), in order. The column runs of the z pass stride from plane to plane, which
/// the hardware prefetcher does not follow, so without this sequential sweep first they
/// wait on memory for most of their time (about three quarters of the z pass on the
/// development VM).
#[inline(always)]
fn warm(ring: &[f32], rows: &[usize], w: usize) {
    const FLOATS_PER_LINE: usize = 16;
    let mut seen = 0;
    for &start in rows {
        for v in ring[start..start + w].iter().step_by(FLOATS_PER_LINE) {
            seen ^= v.to_bits();
        }
    }
    std::hint::black_box(seen);
}

/// The instruction set the two hot stages are compiled for. Both give the same bits:
/// the operations are the same IEEE ones, only wider (and never fused).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
enum Simd {
    /// The target's baseline (SSE2 on x86-64): four floats per operation.
    #[default]
    Baseline,
    /// AVX2, where the CPU has it: eight.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Simd {
    /// The widest set this CPU runs.
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            return Simd::Avx2;
        }
        Simd::Baseline
    }

    fn slice_planes(
        self,
        input: Values,
        z: usize,
        r: [usize; 3],
        outs: Vec<(Stat, Vec<&mut [f32]>)>,
        s: &mut SliceScratch,
    ) {
        match self {
            Simd::Baseline => slice_planes(input, z, r, outs, s),
            #[cfg(target_arch = "x86_64")]
            #[allow(unsafe_code, reason = "calls the AVX2 build of the stage")]
            // SAFETY: `Simd::Avx2` exists only where `detect` saw the CPU report AVX2.
            Simd::Avx2 => unsafe { avx2::slice_planes(input, z, r, outs, s) },
        }
    }

    fn z_tile(
        self,
        p: &ZPass,
        t: usize,
        c: usize,
        outs: &mut [Vec<&mut [f32]>],
        s: &mut TileScratch,
    ) {
        match self {
            Simd::Baseline => z_tile(p, t, c, outs, s),
            #[cfg(target_arch = "x86_64")]
            #[allow(unsafe_code, reason = "calls the AVX2 build of the stage")]
            // SAFETY: as in `slice_planes`.
            Simd::Avx2 => unsafe { avx2::z_tile(p, t, c, outs, s) },
        }
    }
}

/// The hot stages compiled for AVX2: the same source, inlined (every function they call
/// is `#[inline(always)]`), so LLVM vectorises them eight floats wide.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::*;

    #[target_feature(enable = "avx2")]
    pub(super) fn slice_planes(
        input: Values,
        z: usize,
        r: [usize; 3],
        outs: Vec<(Stat, Vec<&mut [f32]>)>,
        s: &mut SliceScratch,
    ) {
        super::slice_planes(input, z, r, outs, s)
    }

    #[target_feature(enable = "avx2")]
    pub(super) fn z_tile(
        p: &ZPass,
        t: usize,
        c: usize,
        outs: &mut [Vec<&mut [f32]>],
        s: &mut TileScratch,
    ) {
        super::z_tile(p, t, c, outs, s)
    }
}

/// The statistics each of `outputs` needs, as flags by [`Stat::index`].
fn wanted(outputs: &[Output]) -> [bool; 4] {
    let mut wanted = [false; 4];
    for o in outputs {
        match *o {
            Output::Map(map) => {
                for s in Stat::needed_by(map) {
                    wanted[s.index()] = true;
                }
            }
            Output::Stat(s) => wanted[s.index()] = true,
        }
    }
    wanted
}

/// [`FilterCpu::box_stats`] with fresh buffers.
pub fn box_stats_cpu(values: &[f32], dims: [usize; 3], radius: [u32; 3]) -> BoxStats {
    FilterCpu::default().box_stats(values, dims, radius)
}

/// A map from statistics and source values, x fastest (the CPU twin of
/// `ambient_maps.wgsl`).
pub fn map_cpu(map: AmbientMap, stats: &BoxStats, values: &[f32]) -> Vec<f32> {
    let [nx, ny, nz] = stats.dims;
    let r = stats.radius.map(|r| r as usize);
    let mut out = vec![0.0; values.len()];
    out.par_chunks_mut(nx).enumerate().for_each(|(line, row)| {
        let (y, z) = (line % ny, line / ny);
        let cyz = window_count(y, r[1], ny) * window_count(z, r[2], nz);
        let counts: Vec<f32> = (0..nx)
            .map(|x| (window_count(x, r[0], nx) * cyz) as f32)
            .collect();
        let run = line * nx..(line + 1) * nx;
        let stats = [&stats.min, &stats.max, &stats.sum, &stats.sum_sq].map(|s| &s[run.clone()]);
        ambient_run(map, &values[run], stats, &counts, row);
    });
    out
}

/// [`FilterCpu::compute`] with fresh buffers.
pub fn compute_cpu(
    texels: &VolumeTexels,
    source: &Source,
    radius: [u32; 3],
    maps: &[AmbientMap],
) -> Vec<Vec<f32>> {
    FilterCpu::default().compute(texels, source, radius, maps)
}
