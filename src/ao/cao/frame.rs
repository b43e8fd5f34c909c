//! One CAO frame submitted in slices without waiting: the viewer's per-frame update.
//!
//! [`CaoGpu::begin`] re-poses the clip maps and writes the brick lists; each
//! [`CaoGpu::advance`] submits the chunks of step IV, then of step V, that fit in the
//! [`Pacer`]'s slice of one UI frame; once all are submitted, the counters are copied and
//! mapped asynchronously, and [`CaoGpu::poll_stats`] returns the frame's figures when the
//! map has completed. The work and its order are those of [`CaoGpu::update`] (the same
//! chunks of the same lists through the same pipelines; only where submissions are cut
//! differs, which changes no voxel), so the viewer's `V_AO` is bit for bit the one
//! `volao render` computes.

use super::{CaoGpu, CaoMode, CaoStats, Lists};
use crate::gpu::dispatch::Pass;
use crate::gpu::pacer::Pacer;
use crate::gpu::{Gpu, GpuError, readback_buffer, validated};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Clip tests and LAO samples per second assumed before anything was measured (about
/// lavapipe's on two cores): the first slices are short on any adapter.
const FIRST_RATE: f64 = 1e8;

/// When something finished, recorded by a queue callback.
type Stamp = Arc<Mutex<Option<Instant>>>;

/// What an asynchronous map of the counters returned.
type Mapped = Arc<Mutex<Option<Result<(), String>>>>;

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
}

impl CaoFrame {
    pub(super) fn new(lists: Lists, mode: CaoMode, clip_errors: Vec<String>) -> Self {
        CaoFrame {
            lists,
            mode,
            next: [0, 0],
            clip_errors,
            started: Instant::now(),
            done: [None, None],
            all_submitted: false,
            counters: None,
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

    /// Bricks submitted and bricks in all, over both steps (for progress).
    pub fn progress(&self) -> (u32, u32) {
        (
            self.next[0] + self.next[1],
            (self.lists.clip.len() + self.lists.lao.len()) as u32,
        )
    }
}

/// A callback stamping when the work submitted so far is done.
fn stamp_when_done(gpu: &Gpu) -> Stamp {
    let stamp: Stamp = Arc::default();
    let s = Arc::clone(&stamp);
    gpu.queue.on_submitted_work_done(move || {
        if let Ok(mut t) = s.lock() {
            *t = Some(Instant::now());
        }
    });
    stamp
}

impl CaoGpu {
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
            let clip_group = self.iv_clip_group(device);
            let pass = Pass {
                label: "Cao::step_iv",
                pipeline: &self.pipelines.clip,
                bind_groups: &[&self.clip_group, &clip_group],
                uniforms: &self.clip_uniforms,
            };
            while frame.next[0] < iv.len() {
                let left = (iv.len() - frame.next[0]) as u64;
                let n = pacer.take(gpu, pass.label, (iv.brick_work(), left), FIRST_RATE);
                if n == 0 {
                    return Ok(false);
                }
                let n = n.min(iv.max_chunk() as u64);
                let piece = (pass.label, n * iv.brick_work());
                frame.next[0] += pacer.submit(gpu, piece, FIRST_RATE, || {
                    iv.submit_chunk(gpu, &pass, params, (frame.next[0], n as u32), |_| {})
                })?;
            }
        }
        if frame.done[0].is_none() {
            frame.done[0] = Some(stamp_when_done(gpu));
        }
        let v = self.v_dispatch(&frame.lists);
        let (pipeline, group, uniforms) = self.v_parts(true);
        let pass = Pass {
            label: "Cao::step_v",
            pipeline,
            bind_groups: &[group],
            uniforms,
        };
        while frame.next[1] < v.len() {
            let left = (v.len() - frame.next[1]) as u64;
            let n = pacer.take(gpu, pass.label, (v.brick_work(), left), FIRST_RATE);
            if n == 0 {
                return Ok(false);
            }
            let n = n.min(v.max_chunk() as u64);
            let piece = (pass.label, n * v.brick_work());
            frame.next[1] += pacer.submit(gpu, piece, FIRST_RATE, || {
                v.submit_chunk(
                    gpu,
                    &pass,
                    self.lao_params,
                    (frame.next[1], n as u32),
                    |_| {},
                )
            })?;
        }
        frame.done[1] = Some(stamp_when_done(gpu));
        // The counters, read back asynchronously into a buffer of this frame's own.
        let readback = readback_buffer(device, "Cao::counters_readback", 16);
        validated(device, "Cao::counters", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.counters, 0, &readback, 0, 16);
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
        frame.counters = Some((readback, mapped));
        frame.all_submitted = true;
        Ok(true)
    }

    /// The frame's figures once its counters are back (after a device poll), with the
    /// stage times as seen from the UI thread: from `begin` to step IV done, and from
    /// there to step V done. Returns them once.
    pub fn poll_stats(&self, frame: &mut CaoFrame) -> Option<Result<CaoStats, GpuError>> {
        let state = {
            let (_, mapped) = frame.counters.as_ref()?;
            mapped.lock().ok()?.clone()?
        };
        let (buffer, _) = frame.counters.take()?;
        if let Err(message) = state {
            return Some(Err(GpuError::Readback {
                stage: "Cao::counters".into(),
                message,
            }));
        }
        let bytes = match buffer.slice(..).get_mapped_range() {
            Ok(view) => view.to_vec(),
            Err(e) => {
                return Some(Err(GpuError::Readback {
                    stage: "Cao::counters".into(),
                    message: e.to_string(),
                }));
            }
        };
        buffer.unmap();
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        let when = |i: usize| {
            frame.done[i]
                .as_ref()
                .and_then(|s| s.lock().ok().and_then(|t| *t))
                .unwrap_or_else(Instant::now)
        };
        let (iv, v) = (when(0), when(1));
        let seconds = [
            (iv - frame.started).as_secs_f64(),
            v.saturating_duration_since(iv).as_secs_f64(),
        ];
        let mut stats = self.stats_of(&frame.lists, [c[0], c[1], c[2]].map(u64::from), seconds);
        stats.clip_errors = frame.clip_errors.clone();
        Some(Ok(stats))
    }
}
