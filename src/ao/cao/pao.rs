//! Updating `V_PAO` where only part of the opacity changed — a segment hidden, shown or
//! made fainter ([`crate::texels::segments`]) — instead of recomputing it: the voxels
//! whose LAO rays can read a changed `V_o` are those within [`reach_mm`] of it, so only
//! the bricks that close to a changed brick are ray cast again, with the passes and lists
//! of [`CaoGpu::new`]'s precomputation, which is why the values are the same bits.

use super::{CaoGpu, CaoMode, Lists, reach_mm};
use crate::ao::sparse::BRICK;
use crate::clip::gpu::MapRequest;
use crate::gpu::{Gpu, GpuError, validated};
use crate::texels::VolumeTexels;
use std::time::Instant;

/// What one [`CaoGpu::update_pao`] did.
#[derive(Debug, Clone, Copy, Default)]
pub struct PaoUpdate {
    /// Bricks whose unclipped `V_o` was written again (step IV).
    pub clip_bricks: usize,
    /// Bricks whose `V_PAO` was ray cast again (step V).
    pub lao_bricks: usize,
    /// Of all bricks.
    pub bricks: usize,
    pub seconds: f64,
}

/// `mask` (one flag per brick of `grid`) grown by `k[a]` bricks along each axis a (a box,
/// which holds every brick within that distance).
pub fn dilate(mask: &[bool], grid: [usize; 3], k: [usize; 3]) -> Vec<bool> {
    let mut out = mask.to_vec();
    let stride = [1, grid[0], grid[0] * grid[1]];
    for a in 0..3 {
        let src = out.clone();
        for (i, o) in out.iter_mut().enumerate() {
            let c = crate::volume::voxel_of(i, grid)[a];
            let (lo, hi) = (c.saturating_sub(k[a]), (c + k[a]).min(grid[a] - 1));
            *o = (lo..=hi).any(|d| src[i - c * stride[a] + d * stride[a]]);
        }
    }
    out
}

impl CaoGpu {
    /// Recomputes `V_PAO` after the opacity changed only inside the bricks `changed`
    /// flags (by [`crate::ao::sparse::Bricks`] index): step V ray casts the readable
    /// bricks within the rays' reach of them, after step IV with nothing clipped wrote
    /// the unclipped `V_o` of every brick within the reach of those (all step V reads), and
    /// those are copied into `V_PAO` — the values [`CaoGpu::new`] computes, bit for bit.
    /// `V_AO` holds `V_PAO` in every brick written here: the next frame ([`Self::update`]
    /// or [`Self::begin`]) clips for its pose again.
    pub fn update_pao(
        &mut self,
        gpu: &Gpu,
        texels: &VolumeTexels,
        changed: &[bool],
        progress: &dyn Fn(usize, usize),
    ) -> Result<PaoUpdate, GpuError> {
        let start = Instant::now();
        let b = &self.bricks;
        assert_eq!(changed.len(), b.count());
        let reach = reach_mm(self.samples, texels.spacing);
        // Bricks along each axis that hold every point within the reach of a brick.
        let k = texels
            .spacing
            .map(|s| (reach / (BRICK as f32 * s)).ceil() as usize);
        // The voxels to ray cast, and what their rays read: the reach again from any of
        // them (the far side of the last brick of `near` may be k bricks out).
        let near = dilate(changed, b.grid, k);
        let far = dilate(&near, b.grid, k);
        let lists = Lists {
            clip: b.list(|i| far[i] && b.used(i)),
            lao: b.list(|i| near[i] && b.readable[i] != 0),
        };
        let update = PaoUpdate {
            clip_bricks: lists.clip.len(),
            lao_bricks: lists.lao.len(),
            bricks: b.count(),
            seconds: 0.0,
        };
        if lists.clip.is_empty() {
            return Ok(update);
        }
        let nothing = MapRequest {
            shapes: &[],
            volume_radius: 1.0,
            reach_mm: 1.0,
            resolution: 16,
        };
        self.clip.update(gpu, nothing)?;
        // The next frame lists every brick again, as after the precomputation.
        self.was_near.iter_mut().for_each(|n| *n = true);
        self.write_lists(gpu, &lists);
        self.step_iv(gpu, &lists, CaoMode::Full)?;
        self.step_v(gpu, &lists, false, progress)?;
        self.last = (lists.clone(), CaoMode::Full);
        // Step V's bricks into V_PAO; step IV's others (marked, not ray cast) back from it.
        let lao: Vec<bool> = (0..b.count())
            .map(|i| near[i] && b.readable[i] != 0)
            .collect();
        let device = &gpu.device;
        validated(device, "Cao::update_pao", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            for i in (0..b.count()).filter(|&i| far[i] && b.used(i)) {
                let (from, to) = match lao[i] {
                    true => (&self.v_ao, &self.v_pao),
                    false => (&self.v_pao, &self.v_ao),
                };
                let v = crate::volume::voxel_of(i, b.grid);
                let origin = v.map(|c| (c * BRICK) as u32);
                let size: [u32; 3] =
                    std::array::from_fn(|a| (BRICK as u32).min(self.dims[a] - origin[a]));
                encoder.copy_texture_to_texture(
                    at(from, origin),
                    at(to, origin),
                    wgpu::Extent3d {
                        width: size[0],
                        height: size[1],
                        depth_or_array_layers: size[2],
                    },
                );
            }
            gpu.queue.submit([encoder.finish()]);
        })?;
        crate::gpu::wait(device, "Cao::update_pao", crate::gpu::WAIT)?;
        Ok(PaoUpdate {
            seconds: start.elapsed().as_secs_f64(),
            ..update
        })
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

#[cfg(test)]
mod tests {
    use super::dilate;

    #[test]
    fn dilation_grows_a_box_per_axis() {
        let grid = [5, 4, 3];
        let mut mask = vec![false; 60];
        mask[2 + 5 + 20] = true; // (2, 1, 1)
        let d = dilate(&mask, grid, [1, 2, 0]);
        let set: Vec<[usize; 3]> = (0..60)
            .filter(|&i| d[i])
            .map(|i| crate::volume::voxel_of(i, grid))
            .collect();
        assert_eq!(set.len(), 3 * 4);
        assert!(set.iter().all(|v| (1..=3).contains(&v[0]) && v[2] == 1));
    }
}
