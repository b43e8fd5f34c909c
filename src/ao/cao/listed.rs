//! A frame's step V over a compact list of the voxels it ray casts.
//!
//! Step V over bricks dispatches every voxel of the bricks near a shape that the ray
//! caster can read, and most of them only find a copy of `V_PAO` in their mark; on a
//! SIMD adapter a row of lanes with one voxel to ray cast costs as much as a full one.
//! With skipping, a frame ([`CaoMode::Selective`]) instead lists the voxels step IV
//! marked for a ray cast (`shaders/cao_gather.wgsl`, linear indices), reads the list's
//! length back, and ray casts exactly those (`shaders/cao_listed.wgsl`), one invocation
//! each. Both ray casts run the same `lao` (`shaders/cao_ray.wgsl`): the bits are those
//! of step V over bricks, and of LAO every frame.
//!
//! The list holds 4 bytes per entry, allocated for the frame's bricks and grown when a
//! frame needs more, up to [`MAX_LIST_BYTES_PER_VOXEL`] of the volume; a frame with more
//! voxels to ray cast than that falls back to step V over bricks.

use super::voxel_list::{Bound, GROUP, MAX_LIST_BYTES_PER_VOXEL, Parts, VoxelList, pass};
use super::{CaoGpu, CaoMode, LaoParams, Lists};
use crate::gpu::dispatch::{BrickDispatch, budget};
use crate::gpu::{Gpu, GpuError, validated};

impl CaoGpu {
    /// Whether a frame in `mode` ray casts over a list of its voxels: CAO's frames with
    /// skipping, once `V_PAO` is made (the baseline and `--no-skipping` run over bricks).
    pub(super) fn lists_voxels(&self, mode: CaoMode) -> bool {
        mode == CaoMode::Selective && self.pao_ready && self.bricks.skipping
    }

    /// Entries the list may hold at most.
    fn max_listed(&self) -> u64 {
        let voxels: u64 = self.dims.iter().map(|&d| d as u64).product();
        (voxels * MAX_LIST_BYTES_PER_VOXEL / 4).max(GROUP as u64)
    }

    /// Makes room in the list for the voxels of `lists`' step-V bricks (up to the cap).
    pub(super) fn reserve_list(&mut self, gpu: &Gpu, lists: &Lists) -> Result<(), GpuError> {
        let dims = self.dims.map(|d| d as usize);
        let wanted = crate::ao::sparse::Bricks::voxels_in(&lists.lao, dims).min(self.max_listed());
        let held = self.list.as_ref().map_or(0, |l| l.capacity as u64);
        if wanted <= held {
            return Ok(());
        }
        let capacity = wanted.next_power_of_two().min(self.max_listed()) as u32;
        let device = &gpu.device;
        let pipelines = &self.pipelines.listed;
        let bound = Bound {
            v_o: &self.views[0],
            v_ao: &self.views[2],
            sampler: &self.pipelines.sampler,
            rays: &self.rays_buffer,
            occupied: &self.occupied_buffer,
            bricks: &self.lists,
            counters: &self.counters,
        };
        let list = validated(device, "Cao::listed", || {
            VoxelList::new(gpu, pipelines, &bound, &self.lao_params, capacity)
        })?;
        self.list = Some(list);
        Ok(())
    }

    /// Bytes the voxel list holds now.
    pub fn list_bytes(&self) -> u64 {
        self.list.as_ref().map_or(0, |l| 4 * l.capacity as u64)
    }

    /// The gathering pass over step V's bricks, and its dispatch.
    pub(super) fn gather_parts(&self, lists: &Lists) -> Option<(Parts<'_>, BrickDispatch)> {
        let list = self.list.as_ref()?;
        let chunks = BrickDispatch::new(
            lists.clip.len(),
            lists.lao.len(),
            1,
            budget::LAO_SAMPLES,
            u64::MAX,
        );
        let parts = (
            "Cao::gather",
            &self.pipelines.listed.gather,
            &list.gather.1,
            &list.gather.0,
        );
        Some((parts, chunks))
    }

    /// The listed ray cast of `count` entries, its dispatch (groups of 512 entries) and
    /// its uniforms; `None` where they do not fit in the list (step V over bricks then).
    pub(super) fn trace_parts(&self, count: u64) -> Option<(Parts<'_>, BrickDispatch, LaoParams)> {
        let list = self.list.as_ref()?;
        if count > list.capacity as u64 {
            return None;
        }
        let groups = count.div_ceil(GROUP as u64) as usize;
        let chunks = BrickDispatch::new(
            0,
            groups,
            self.rays as u64 * self.samples as u64,
            budget::LAO_SAMPLES,
            u64::MAX,
        );
        let mut params = self.lao_params;
        params.listed = count as u32;
        let parts = (
            "Cao::listed",
            &self.pipelines.listed.trace,
            &list.trace.1,
            &list.trace.0,
        );
        Some((parts, chunks, params))
    }

    /// Step V of a frame over its listed voxels, waiting for the list's length: the
    /// entries ray cast, or `None` if they did not fit and step V ran over bricks.
    pub(super) fn step_v_listed(&self, gpu: &Gpu, lists: &Lists) -> Result<Option<u64>, GpuError> {
        let Some((parts, chunks)) = self.gather_parts(lists) else {
            self.step_v(gpu, lists, true, &|_, _| {})?;
            return Ok(None);
        };
        let group = [(0, parts.2)];
        let gather = pass(&parts, &group);
        chunks.run(
            gpu,
            &gather,
            self.lao_params,
            false,
            |_, _| Ok(()),
            |_, _, _| {},
        )?;
        let count = self.read_counters(gpu)?[3];
        match self.trace_parts(count) {
            Some((parts, chunks, params)) => {
                let group = [(0, parts.2)];
                let trace = pass(&parts, &group);
                chunks.run(gpu, &trace, params, true, |_, _| Ok(()), |_, _, _| {})?;
                Ok(Some(count))
            }
            None => {
                self.step_v(gpu, lists, true, &|_, _| {})?;
                Ok(None)
            }
        }
    }

    /// The list's length from the counters read back after gathering.
    pub(super) fn listed_of(bytes: &[u8]) -> u64 {
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
        c.get(3).copied().unwrap_or(0) as u64
    }
}
