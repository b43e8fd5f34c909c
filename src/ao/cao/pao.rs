//! Updating `V_PAO` where only part of the opacity changed — a segment hidden, shown or
//! made fainter ([`crate::texels::segments`]) — instead of recomputing it: the voxels
//! whose LAO rays can read a changed `V_o` are those within [`reach_mm`] of it, so only
//! they are ray cast again, by the `lao` every CAO ray cast runs, on the `V_o` the
//! precomputation read, which is why the values are the same bits.

use super::{CaoGpu, CaoMode, Lists, reach_mm};
use crate::ao::sparse::{BRICK, bricks_holding, dilate};
use crate::clip::gpu::MapRequest;
use crate::gpu::{Gpu, GpuError, read_texture_f32, validated};
use crate::texels::VolumeTexels;
use crate::texels::segments::SegmentTexels;
use std::time::Instant;

/// Step IV's mark of a voxel step V ray casts (`RECOMPUTE` in the shaders).
const RECOMPUTE: f32 = -1.0;

/// What one [`CaoGpu::update_pao`] did.
#[derive(Debug, Clone, Copy, Default)]
pub struct PaoUpdate {
    /// Bricks whose unclipped `V_o` was written again (step IV).
    pub clip_bricks: usize,
    /// Bricks whose voxels within the reach were ray cast again (step V).
    pub lao_bricks: usize,
    /// Voxels ray cast again.
    pub recomputed: u64,
    /// Of all bricks.
    pub bricks: usize,
    pub seconds: f64,
}

impl CaoGpu {
    /// Recomputes `V_PAO` after the opacity changed only at the voxels `changed` flags (a
    /// segment hidden: [`crate::texels::segments::SegmentTexels::voxels_changed_by`]).
    /// The voxels within the rays' reach of them ([`reach_mm`], a box per axis) are
    /// marked and ray cast from a list, as a frame's step V does, after step IV with
    /// nothing clipped wrote the unclipped `V_o` of every brick within the reach of
    /// theirs (all they read); their bricks are then copied into `V_PAO`. The same `lao`
    /// of the same `V_o` as [`CaoGpu::new`]'s precomputation: the same bits. `V_AO` holds
    /// `V_PAO` in every brick written here: the next frame ([`Self::update`] or
    /// [`Self::begin`]) clips for its pose again.
    pub fn update_pao(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        changed: &[bool],
    ) -> Result<PaoUpdate, GpuError> {
        let start = Instant::now();
        let dims = self.dims.map(|d| d as usize);
        assert_eq!(changed.len(), dims.iter().product::<usize>());
        let reach = reach_mm(self.samples, texels.spacing);
        let within = texels.spacing.map(|s| (reach / s).floor() as usize);
        let recompute = dilate(changed, dims, within);
        let b = &self.bricks;
        let near = bricks_holding(&recompute, dims);
        // What their rays read: the reach again, in whole bricks.
        let k = texels
            .spacing
            .map(|s| (reach / (BRICK as f32 * s)).ceil() as usize);
        let far = dilate(&near, b.grid, k);
        let lao: Vec<bool> = (0..b.count())
            .map(|i| near[i] && b.readable[i] != 0)
            .collect();
        let lists = Lists {
            clip: b.list(|i| far[i] && b.used(i)),
            lao: b.list_flagged(|i| lao[i], |_| true),
        };
        let grid = b.grid;
        // Bricks step IV writes, and whether step V's too.
        let written: Vec<(usize, bool)> = (0..b.count())
            .filter(|&i| far[i] && b.used(i))
            .map(|i| (i, lao[i]))
            .collect();
        let mut update = PaoUpdate {
            clip_bricks: lists.clip.len(),
            lao_bricks: lists.lao.len(),
            bricks: b.count(),
            ..Default::default()
        };
        if lists.clip.is_empty() {
            return Ok(update);
        }
        let pao = read_texture_f32(gpu, &self.v_pao, self.dims, "Cao::update_pao")?;
        self.clip.update(gpu, MapRequest::NOTHING)?;
        // The next frame lists every brick again, as after the precomputation.
        self.was_near.iter_mut().for_each(|n| *n = true);
        self.reserve_list(gpu, &lists)?;
        self.write_lists(gpu, &lists);
        self.step_iv(gpu, &lists, CaoMode::Full)?;
        // Step IV marked every voxel of its bricks: step V's keep V_PAO but where a
        // readable voxel is within the reach (V_PAO holds UNREAD > 1 where it is not).
        for &(i, _) in written.iter().filter(|(_, lao)| *lao) {
            let (origin, size) = brick_box(i, grid, self.dims);
            let marks: Vec<f32> = (0..size.iter().product::<u32>() as usize)
                .map(|j| {
                    let o = crate::volume::voxel_of(j, size.map(|s| s as usize));
                    let v: [usize; 3] = std::array::from_fn(|a| origin[a] as usize + o[a]);
                    let at = v[0] + dims[0] * (v[1] + dims[1] * v[2]);
                    match recompute[at] && pao[at] <= 1.0 {
                        true => RECOMPUTE,
                        false => pao[at],
                    }
                })
                .collect();
            self.write_region(gpu, origin, size, &marks);
        }
        update.recomputed = match self.step_v_listed(gpu, &lists)? {
            Some(n) => n,
            None => recompute.iter().filter(|&&r| r).count() as u64,
        };
        // Step V's bricks into V_PAO; step IV's others (marked, not ray cast) back from it.
        let device = &gpu.device;
        validated(device, "Cao::update_pao", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            for &(i, lao) in &written {
                let (from, to) = match lao {
                    true => (&self.v_ao, &self.v_pao),
                    false => (&self.v_pao, &self.v_ao),
                };
                let (origin, size) = brick_box(i, grid, self.dims);
                encoder.copy_texture_to_texture(at(from, origin), at(to, origin), extent(size));
            }
            gpu.queue.submit([encoder.finish()]);
        })?;
        crate::gpu::wait(device, "Cao::update_pao", crate::gpu::WAIT)?;
        update.seconds = start.elapsed().as_secs_f64();
        Ok(update)
    }

    /// Writes the looks and cuts of `segments` (the classes this CAO was made with) into
    /// the textures step IV reads; whether it reads a segmentation at all.
    pub fn set_segments(&mut self, gpu: &Gpu, segments: &SegmentTexels) -> bool {
        let dims = self.dims.map(|d| d as usize);
        match &mut self.segment_textures {
            // The same classes: the same table size, so the bind groups' buffers stay.
            Some(t)
                if segments.dims == dims && t.table.size() == 16 * segments.table.len() as u64 =>
            {
                t.update(gpu, segments);
                true
            }
            _ => false,
        }
    }

    /// Writes `values` (x fastest) into `V_AO` at `origin`, in its format.
    fn write_region(&self, gpu: &Gpu, origin: [u32; 3], size: [u32; 3], values: &[f32]) {
        let bytes: Vec<u8> = match self.pipelines.format {
            wgpu::TextureFormat::R16Float => values
                .iter()
                .flat_map(|&v| half::f16::from_f32(v).to_le_bytes())
                .collect(),
            _ => bytemuck::cast_slice(values).to_vec(),
        };
        let texel = (bytes.len() / values.len()) as u32;
        gpu.queue.write_texture(
            at(&self.v_ao, origin),
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(size[0] * texel),
                rows_per_image: Some(size[1]),
            },
            extent(size),
        );
    }
}

/// The first voxel and the size of brick `i` of `grid` in a volume of `dims`.
fn brick_box(i: usize, grid: [usize; 3], dims: [u32; 3]) -> ([u32; 3], [u32; 3]) {
    let v = crate::volume::voxel_of(i, grid);
    let origin = v.map(|c| (c * BRICK) as u32);
    let size = std::array::from_fn(|a| (BRICK as u32).min(dims[a] - origin[a]));
    (origin, size)
}

fn extent(size: [u32; 3]) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width: size[0],
        height: size[1],
        depth_or_array_layers: size[2],
    }
}

/// Texel `origin` of `texture` as a copy's source or destination.
fn at(texture: &wgpu::Texture, origin: [u32; 3]) -> wgpu::TexelCopyTextureInfo<'_> {
    wgpu::TexelCopyTextureInfo {
        texture,
        mip_level: 0,
        origin: wgpu::Origin3d {
            x: origin[0],
            y: origin[1],
            z: origin[2],
        },
        aspect: wgpu::TextureAspect::All,
    }
}
