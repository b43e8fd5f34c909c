//! Reading the CAO volumes back: for `volao ao`, the tests that compare them with the
//! CPU twins and the paper's mask.

use super::{CaoGpu, CaoMode, CaoVolume, Lists};
use crate::ao::sparse::{NEAR, brick_voxels};
use crate::gpu::{Gpu, GpuError, read_texture_f32};

/// What `cao_lao.wgsl` writes into `V_PAO` where no sample reads the voxel (above any
/// ambient factor).
const UNREAD: f32 = 2.0;

impl CaoGpu {
    /// Reads one of the CAO volumes back, x fastest. `V_PAO` and `V_AO` hold 1 where the
    /// ray caster cannot read them: in unreadable bricks (never computed) and at the
    /// voxels `V_PAO`'s per-voxel test left out (`UNREAD` on the GPU, which `V_AO` holds
    /// too until a frame's step IV visits the voxel and writes 1).
    pub fn read(&self, gpu: &Gpu, which: CaoVolume) -> Result<Vec<f32>, GpuError> {
        let t = match which {
            CaoVolume::ClippedOpacity => &self.v_o,
            CaoVolume::Mask => return self.read_mask(gpu),
            CaoVolume::Precomputed => &self.v_pao,
            CaoVolume::Ambient => &self.v_ao,
        };
        let mut values = read_texture_f32(gpu, t, self.dims, "Cao::read")?;
        if matches!(which, CaoVolume::Precomputed | CaoVolume::Ambient)
            && self.bricks.readable.contains(&0)
        {
            let dims = self.dims.map(|d| d as usize);
            for (i, v) in values.iter_mut().enumerate() {
                if !self.bricks.voxel_readable(crate::volume::voxel_of(i, dims)) {
                    *v = 1.0;
                }
            }
        }
        if matches!(which, CaoVolume::Precomputed | CaoVolume::Ambient) {
            for v in values.iter_mut().filter(|v| **v == UNREAD) {
                *v = 1.0;
            }
        }
        Ok(values)
    }

    /// The last frame's mask, from step IV's marks in `V_AO`: steps IV (CAO's) and V
    /// run again, which leaves `V_AO` as it was on every readable voxel.
    fn read_mask(&self, gpu: &Gpu) -> Result<Vec<f32>, GpuError> {
        // The paper's marks: every brick of step IV marks what its dilation reaches,
        // and step V then ray casts what it marked in all of them.
        let all: Vec<u32> = self.last.0.clip.iter().map(|b| b | NEAR).collect();
        let lists = &Lists {
            clip: all.clone(),
            lao: all,
        };
        self.write_lists(gpu, lists);
        // Unreadable voxels marked for recomputation too.
        let (chunks, mut params) = self.iv_dispatch(lists, CaoMode::Selective);
        params.unread_marked = 0;
        params.clipped_one = 0;
        params.ray_test = 0;
        // The dense pipeline: any of a voxel's clip samples in a dilation marks it.
        let dense = self.pipelines.clip_dense(self.segments);
        self.step_iv_with(
            gpu,
            chunks,
            params,
            dense.for_shapes(self.clip.uniforms.counts[0]),
        )?;
        let marks = read_texture_f32(gpu, &self.v_ao, self.dims, "Cao::mask")?;
        let dims = self.dims.map(|d| d as usize);
        let mut mask = vec![1.0; marks.len()];
        for &b in &lists.clip {
            for [x, y, z] in brick_voxels(b, dims) {
                let i = x + dims[0] * (y + dims[1] * z);
                // Step IV's marks: -1 recompute, -2 clipped, else a copy.
                mask[i] = if marks[i] == -1.0 {
                    0.5
                } else if marks[i] == -2.0 {
                    0.0
                } else {
                    1.0
                };
            }
        }
        self.step_v(gpu, lists, true, &|_, _| {})?;
        crate::gpu::wait(&gpu.device, "Cao::mask", crate::gpu::WAIT)?;
        Ok(mask)
    }

    /// `values` as the CAO volumes hold them (rounded to f16 when they are R16Float):
    /// for comparing a CPU twin with what was read back.
    pub fn round_as_stored(&self, values: &mut [f32]) {
        if self.v_ao.format() == wgpu::TextureFormat::R16Float {
            for v in values {
                *v = half::f16::from_f32(*v).to_f32();
            }
        }
    }
}
