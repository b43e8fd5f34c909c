//! One CAO frame: what it is for ([`Pose`]) and its work, waited for in one call
//! ([`CaoGpu::update`]) or submitted in slices without waiting (the viewer's per-frame
//! update). The volumes and passes it runs are the long-lived [`CaoGpu`]'s.
//!
//! [`CaoGpu::begin`] re-poses the clip maps and writes the brick lists; each
//! [`CaoGpu::advance`] submits the chunks of step IV, then of step V, that fit in the
//! [`Pacer`]'s slice of one UI frame (step V over the voxel list: gathering, then, once
//! the list's length has come back through an asynchronous map, the listed ray cast);
//! once all are submitted, the counters are copied and mapped asynchronously, and
//! [`CaoGpu::poll_stats`] returns the frame's figures when the map has completed. The
//! work and its order are those of [`CaoGpu::update`] (the same chunks of the same lists
//! through the same pipelines; only where submissions are cut differs, which changes no
//! voxel), so the viewer's `V_AO` is bit for bit the one `volao render` computes.

use super::{CaoGpu, CaoMode, CaoStats, Lists};
use crate::clip::ClipShape;
use crate::clip::gpu::{ClipUpdate, MapRequest};
use crate::gpu::dispatch::{BrickDispatch, ChunkParams, Pass};
use crate::gpu::pacer::{Pacer, Stamp};
use crate::gpu::{Gpu, GpuError, readback_buffer, validated};
use crate::texels::VolumeTexels;
use glam::Vec3;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Clip tests and LAO samples per second assumed before anything was measured (about
/// lavapipe's on two cores): the first slices are short on any adapter.
const FIRST_RATE: f64 = 1e8;

/// What an asynchronous map of the counters returned.
type Mapped = Arc<Mutex<Option<Result<(), String>>>>;

/// What one CAO frame is for: the clip shapes, their maps' resolution (pixels) and
/// reach (mm: normally [`CaoGpu::reach_mm`]; tests shrink it to show exactness depends
/// on it), and which voxels step V ray casts.
#[derive(Debug, Clone, Copy)]
pub struct Pose<'a> {
    pub shapes: &'a [ClipShape],
    pub resolution: u32,
    pub reach_mm: f32,
    pub mode: CaoMode,
}

/// One frame of CAO being submitted piece by piece.
#[derive(Debug)]
pub struct CaoFrame {
    pub(super) lists: Lists,
    mode: CaoMode,
    /// Bricks of step IV and of step V submitted so far.
    next: [u32; 2],
    /// Shapes left out, with why.
    pub(super) clip_errors: Vec<String>,
    started: Instant,
    /// When the GPU finished step IV and step V (seen at a device poll).
    done: [Option<Stamp>; 2],
    /// Everything is submitted.
    all_submitted: bool,
    /// The counters' copy and its map, until the figures are taken.
    counters: Option<(wgpu::Buffer, Mapped)>,
    /// Step V over the voxel list ([`super::listed`]), when the frame lists them.
    listing: Option<Listing>,
}

/// How far step V over the voxel list has come.
#[derive(Debug, Default)]
struct Listing {
    /// Bricks gathered.
    gathered: u32,
    /// The counters' copy after gathering and its map, until the list's length is read.
    count_map: Option<(wgpu::Buffer, Mapped)>,
    /// The list's length.
    count: Option<u64>,
    /// Groups of entries ray cast.
    traced: u32,
    /// The list did not hold them all: step V runs over bricks.
    over_bricks: bool,
}

impl CaoFrame {
    /// A frame over `lists`; `listing`: step V over the voxel list.
    pub(super) fn new(
        lists: Lists,
        (mode, listing): (CaoMode, bool),
        clip_errors: Vec<String>,
    ) -> Self {
        CaoFrame {
            lists,
            mode,
            next: [0, 0],
            clip_errors,
            started: Instant::now(),
            done: [None, None],
            all_submitted: false,
            counters: None,
            listing: listing.then(Listing::default),
        }
    }

    /// Whether all of the frame's work is submitted: anything submitted after it (the
    /// ray cast of this pose) sees its `V_AO` complete (one in-order queue).
    pub fn submitted(&self) -> bool {
        self.all_submitted
    }

    /// Shapes the clip maps left out, with why.
    pub fn clip_errors(&self) -> &[String] {
        &self.clip_errors
    }

    /// Where the frame stands, in one line (for the viewer's watchdog).
    pub fn describe(&self) -> String {
        let listing = match &self.listing {
            None => "over bricks".to_owned(),
            Some(l) => format!(
                "listing: {} gathered, count {}, {} traced{}",
                l.gathered,
                match (l.count, &l.count_map) {
                    (Some(n), _) => n.to_string(),
                    (None, Some((_, m))) => match came_back(m) {
                        true => "mapped, not read".to_owned(),
                        false => "being mapped".to_owned(),
                    },
                    (None, None) => "not asked".to_owned(),
                },
                l.traced,
                if l.over_bricks { ", over bricks" } else { "" }
            ),
        };
        let stamped = |i: usize| match &self.done[i] {
            None => "not submitted",
            Some(s) => match s.get() {
                Some(_) => "done",
                None => "running",
            },
        };
        format!(
            "CAO frame {:.1} s old: step IV {}/{} bricks ({}), step V {}/{} bricks ({}), {listing}, \
             all submitted {}, counters {}",
            self.started.elapsed().as_secs_f64(),
            self.next[0],
            self.lists.clip.len(),
            stamped(0),
            self.next[1],
            self.lists.lao.len(),
            stamped(1),
            self.all_submitted,
            match &self.counters {
                None => "not mapped",
                Some((_, m)) => match came_back(m) {
                    true => "mapped",
                    false => "being mapped",
                },
            }
        )
    }

    /// Bricks submitted and bricks in all, over both steps (for progress; gathering the
    /// voxel list counts as a brick's worth of work per brick).
    pub fn progress(&self) -> (u32, u32) {
        let gathered = self.listing.as_ref().map_or(0, |l| l.gathered);
        (
            self.next[0] + self.next[1] + gathered,
            (self.lists.clip.len() + self.lists.lao.len()) as u32 + gathered,
        )
    }
}

/// Copies the counters into a buffer of their own and maps it asynchronously.
fn map_counters(
    gpu: &Gpu,
    counters: &wgpu::Buffer,
    label: &str,
) -> Result<(wgpu::Buffer, Mapped), GpuError> {
    let device = &gpu.device;
    let readback = readback_buffer(device, label, 16);
    validated(device, label, || {
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(counters, 0, &readback, 0, 16);
        gpu.queue.submit([encoder.finish()]);
    })?;
    let mapped: Mapped = Arc::default();
    let m = Arc::clone(&mapped);
    readback
        .slice(..)
        .map_async(wgpu::MapMode::Read, move |result| {
            if let Ok(mut state) = m.lock() {
                *state = Some(result.map_err(|e| e.to_string()));
            }
        });
    Ok((readback, mapped))
}

/// Whether an asynchronous map has come back (done or failed).
fn came_back(mapped: &Mapped) -> bool {
    mapped.lock().is_ok_and(|state| state.is_some())
}

/// The bytes of a mapped counters' copy once its map has completed (`None` before).
fn mapped_bytes(
    (buffer, mapped): &(wgpu::Buffer, Mapped),
    label: &str,
) -> Option<Result<Vec<u8>, GpuError>> {
    let state = mapped.lock().ok()?.clone()?;
    let failed = |message: String| GpuError::Readback {
        stage: label.into(),
        message,
    };
    if let Err(message) = state {
        return Some(Err(failed(message)));
    }
    let bytes = match buffer.slice(..).get_mapped_range() {
        Ok(view) => view.to_vec(),
        Err(e) => return Some(Err(failed(e.to_string()))),
    };
    buffer.unmap();
    Some(Ok(bytes))
}

/// Submits `chunks` of `pass` with `params` from `*next` on, as many as the pacer's slice
/// holds (at least one while any of it is left), advancing `*next`. Returns true once
/// all are submitted.
fn submit_paced<P: ChunkParams>(
    gpu: &Gpu,
    pacer: &mut Pacer,
    pass: &Pass<'_>,
    params: P,
    chunks: &BrickDispatch,
    next: &mut u32,
) -> Result<bool, GpuError> {
    while *next < chunks.len() {
        let left = (chunks.len() - *next) as u64;
        let n = pacer.take(gpu, pass.label, (chunks.brick_work(), left), FIRST_RATE);
        if n == 0 {
            return Ok(false);
        }
        let n = n.min(chunks.max_chunk() as u64);
        let piece = (pass.label, n * chunks.brick_work());
        let first = *next;
        *next += pacer.submit(gpu, piece, FIRST_RATE, || {
            chunks.submit_chunk(gpu, pass, params, (first, n as u32), |_| {})
        })?;
    }
    Ok(true)
}

impl CaoGpu {
    /// One frame: update the clip maps for `shapes` (moved shapes only change matrices),
    /// clip (step IV) and compute `V_AO` (step V), waiting for each. `reach_mm` is
    /// normally [`Self::reach_mm`]; tests shrink it to show exactness depends on it. The
    /// viewer submits the same work in slices without waiting ([`Self::begin`],
    /// [`Self::advance`]).
    pub fn update(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        pose: Pose<'_>,
    ) -> Result<CaoStats, GpuError> {
        let t0 = Instant::now();
        let mode = pose.mode;
        let frame = self.begin(gpu, texels, pose)?;
        crate::gpu::wait(&gpu.device, "Cao::maps", crate::gpu::WAIT)?;
        let t1 = Instant::now();
        let mut stats = self.run_timed(gpu, &frame.lists, mode)?;
        stats.maps_seconds = (t1 - t0).as_secs_f64();
        stats.clip_errors = frame.clip_errors;
        Ok(stats)
    }

    /// Poses the clip maps for `pose` without starting a frame: a visibility pass can
    /// then clip with the maps the frame will (its [`Self::update`] finds them posed).
    pub fn pose_maps(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        pose: &Pose<'_>,
    ) -> Result<(), GpuError> {
        let request = MapRequest {
            shapes: pose.shapes,
            volume_radius: Vec3::from(texels.extent()).length() * 0.5,
            reach_mm: pose.reach_mm,
            resolution: pose.resolution,
        };
        self.clip.update(gpu, request).map(|_| ())
    }

    /// Starts one frame: re-poses the clip maps for `shapes` (a new geometry's maps are
    /// rendered and submitted here), picks the bricks steps IV and V visit and writes
    /// their lists. Nothing is waited for.
    pub fn begin(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        pose: Pose<'_>,
    ) -> Result<CaoFrame, GpuError> {
        let Pose {
            shapes,
            resolution,
            reach_mm,
            mode,
        } = pose;
        let request = MapRequest {
            shapes,
            volume_radius: Vec3::from(texels.extent()).length() * 0.5,
            reach_mm,
            resolution,
        };
        let ClipUpdate { errors, .. } = self.clip.update(gpu, request)?;
        let b = &self.bricks;
        let cameras = self.clip.cameras();
        let near = b.near(texels.dims, texels.spacing, &self.clip.uniforms, &cameras);
        let touched: Vec<bool> = (0..b.count())
            .map(|i| near[i] || self.was_near[i] || self.stale[i])
            .collect();
        let seen = |i: usize| self.view.as_ref().is_none_or(|v| v[i]);
        // Step IV marks voxels for step V only in bricks a change can reach; elsewhere
        // it copies V_PAO (and writes 1 where it clips), so step V skips them.
        let reached = match mode {
            CaoMode::Selective => b.reached(
                texels.dims,
                texels.spacing,
                &self.clip.uniforms,
                &cameras,
                reach_mm,
            ),
            CaoMode::Full => vec![true; b.count()],
        };
        // Step V's bricks before the view: a view leaves some out (stale until seen).
        let needs_v = |i: usize| match mode {
            CaoMode::Selective => touched[i] && reached[i] && b.readable[i] != 0,
            CaoMode::Full => b.readable[i] != 0,
        };
        let lists = Lists {
            clip: b.list_flagged(|i| touched[i] && b.used(i), |i| reached[i]),
            lao: match mode {
                CaoMode::Selective => b.list_flagged(|i| needs_v(i) && seen(i), |_| true),
                CaoMode::Full => b.list_flagged(|i| needs_v(i) && seen(i), |i| touched[i]),
            },
        };
        let stale: Vec<bool> = (0..b.count()).map(|i| needs_v(i) && !seen(i)).collect();
        self.stale = stale;
        self.was_near = near;
        self.cut_balls = match mode {
            CaoMode::Selective => {
                b.cut_balls(&self.clip.uniforms, &cameras, self.ray_test_margin_mm)
            }
            CaoMode::Full => None,
        };
        let listing = self.lists_voxels(mode);
        if listing {
            self.reserve_list(gpu, &lists)?;
        }
        self.write_lists(gpu, &lists);
        self.last = (lists.clone(), mode);
        Ok(CaoFrame::new(
            lists,
            (mode, listing),
            errors.iter().map(|e| e.to_string()).collect(),
        ))
    }

    /// Submits what fits of `frame`'s work in the pacer's slice (at least one chunk while
    /// any of the slice is left). Returns true once all of it is submitted.
    pub fn advance(
        &self,
        gpu: &Gpu,
        frame: &mut CaoFrame,
        pacer: &mut Pacer,
    ) -> Result<bool, GpuError> {
        if frame.submitted() {
            return Ok(true);
        }
        let device = &gpu.device;
        let (iv, params) = self.iv_dispatch(&frame.lists, frame.mode);
        if frame.next[0] < iv.len() {
            let next = &mut frame.next[0];
            let submitted = self.with_step_iv(device, self.clip_pipeline(), |pass| {
                submit_paced(gpu, pacer, pass, params, &iv, next)
            })?;
            if !submitted {
                return Ok(false);
            }
        }
        if frame.done[0].is_none() {
            frame.done[0] = Some(Stamp::when_done(gpu));
        }
        if !self.advance_listed(gpu, frame, pacer)? {
            return Ok(false);
        }
        if frame.listing.as_ref().is_none_or(|l| l.over_bricks) {
            let v = self.v_dispatch(&frame.lists);
            let next = &mut frame.next[1];
            let submitted = self.with_step_v(true, |pass| {
                submit_paced(gpu, pacer, pass, self.lao_params, &v, next)
            })?;
            if !submitted {
                return Ok(false);
            }
        }
        frame.done[1] = Some(Stamp::when_done(gpu));
        // The counters, read back asynchronously into a buffer of this frame's own.
        let (readback, mapped) = map_counters(gpu, &self.counters, "Cao::counters")?;
        frame.counters = Some((readback, mapped));
        frame.all_submitted = true;
        Ok(true)
    }

    /// The frame's figures once its counters are back (after a device poll), with the
    /// stage times as seen from the UI thread: from `begin` to step IV done, and from
    /// there to step V done. Returns them once.
    pub fn poll_stats(&self, frame: &mut CaoFrame) -> Option<Result<CaoStats, GpuError>> {
        let bytes = match mapped_bytes(frame.counters.as_ref()?, "Cao::counters")? {
            Ok(bytes) => bytes,
            Err(e) => {
                frame.counters = None;
                return Some(Err(e));
            }
        };
        frame.counters = None;
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let when = |i: usize| {
            frame.done[i]
                .as_ref()
                .and_then(Stamp::get)
                .unwrap_or_else(Instant::now)
        };
        let (iv, v) = (when(0), when(1));
        let seconds = [
            (iv - frame.started).as_secs_f64(),
            v.saturating_duration_since(iv).as_secs_f64(),
        ];
        let listed = frame.listing.as_ref().is_some_and(|l| !l.over_bricks);
        let c = [c[0], c[1], c[2], c[3]].map(u64::from);
        let mut stats = self.stats_of(&frame.lists, c, listed, seconds);
        stats.clip_errors = frame.clip_errors.clone();
        Some(Ok(stats))
    }
}

impl CaoGpu {
    /// Step V over the voxel list, as far as the pacer's slice goes: gathering, then
    /// (once the list's length is back, read without waiting) the ray cast. True once it
    /// is all submitted, or when the frame does not list its voxels or they did not fit.
    fn advance_listed(
        &self,
        gpu: &Gpu,
        frame: &mut CaoFrame,
        pacer: &mut Pacer,
    ) -> Result<bool, GpuError> {
        let Some(listing) = frame.listing.as_mut() else {
            return Ok(true);
        };
        if listing.over_bricks {
            return Ok(true);
        }
        let Some((parts, chunks)) = self.gather_parts(&frame.lists) else {
            listing.over_bricks = true;
            return Ok(true);
        };
        let group = [(0, parts.2)];
        let pass = super::voxel_list::pass(&parts, &group);
        let gathered = &mut listing.gathered;
        if !submit_paced(gpu, pacer, &pass, self.lao_params, &chunks, gathered)? {
            return Ok(false);
        }
        let count = match listing.count {
            Some(count) => count,
            None => {
                if listing.count_map.is_none() {
                    listing.count_map = Some(map_counters(gpu, &self.counters, "Cao::listed")?);
                }
                let Some(bytes) = listing
                    .count_map
                    .as_ref()
                    .and_then(|m| mapped_bytes(m, "Cao::listed"))
                else {
                    return Ok(false);
                };
                listing.count_map = None;
                let count = CaoGpu::listed_of(&bytes?);
                listing.count = Some(count);
                count
            }
        };
        let Some((parts, chunks, params)) = self.trace_parts(count) else {
            listing.over_bricks = true;
            return Ok(true);
        };
        let group = [(0, parts.2)];
        let pass = super::voxel_list::pass(&parts, &group);
        submit_paced(gpu, pacer, &pass, params, &chunks, &mut listing.traced)
    }
}
