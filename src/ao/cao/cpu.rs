//! The CPU twins of CAO's steps IV and V (for the tests that compare them with the GPU).

use super::super::lao::{Rays, STEP_MM, ray_sum};
use super::super::sparse::Bricks;
use super::{CaoMode, msaa_offsets};
use crate::clip::cpu::ClipMapsCpu;
use crate::sample::{SegmentSampler, VolumeSampler, trilinear};
use crate::texels::VolumeTexels;
use crate::tf::Lut;
use glam::Vec3;
use rayon::prelude::*;

/// Step IV on the CPU: (`V_o`, `V_m`) from the GPU's clip maps, for the twin tests.
pub fn clip_volume_cpu(
    texels: &VolumeTexels,
    lut: &Lut,
    maps: &ClipMapsCpu,
    msaa: u32,
) -> (Vec<f32>, Vec<f32>) {
    clip_volume_cpu_reading(texels, lut, maps, msaa, None)
}

/// [`clip_volume_cpu`] with a segmentation: each voxel's weight on its opacity, and
/// only the shapes that cut its class clipping it (`cao_clip.wgsl` with `SEGMENTS`).
pub fn clip_volume_cpu_reading(
    texels: &VolumeTexels,
    lut: &Lut,
    maps: &ClipMapsCpu,
    msaa: u32,
    segments: Option<&SegmentSampler>,
) -> (Vec<f32>, Vec<f32>) {
    let [nx, ny, nz] = texels.dims;
    let norm = texels.norm_values();
    let volume = VolumeSampler::density(&norm, texels, lut).with_segments(segments);
    let spacing = Vec3::from(texels.spacing);
    let half = Vec3::from(texels.extent()) * 0.5;
    let offsets = msaa_offsets(msaa.max(1));
    // TF_o: the transfer function's opacity of the voxel itself, with its weight
    // (`voxel_opacity`).
    let voxel_opacity = |k: [usize; 3]| volume.opacity_of_voxel(k);
    // clip_classify's (visible, affected); visible by the shapes that cut the class.
    let classify = |pos: Vec3, carve: u32| {
        let (visible, affected) = maps.classify(pos);
        match segments {
            Some(_) => (maps.visible_for(pos, carve), affected),
            None => (visible, affected),
        }
    };
    let per_voxel: Vec<(f32, f32)> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let k = crate::volume::voxel_of(i, texels.dims);
            let carve = volume.carved_by_voxel(k);
            let v = Vec3::new(k[0] as f32, k[1] as f32, k[2] as f32);
            let at = |o: Vec3| (v + Vec3::splat(0.5) + o) * spacing - half;
            let (mut visible, mut dilated) = (0u32, 0u32);
            for k in 0..9u32 {
                let o = if k == 0 {
                    Vec3::ZERO
                } else {
                    let c = k - 1;
                    Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32)
                        - Vec3::splat(0.5)
                };
                let (vis, aff) = classify(at(o), carve);
                visible += u32::from(vis);
                dilated += u32::from(aff);
            }
            let mut o = 0.0;
            if visible == 9 {
                o = voxel_opacity(k);
            } else if visible > 0 {
                for off in offsets.iter().take(msaa as usize) {
                    let (vis, aff) = classify(at(*off), carve);
                    visible += u32::from(vis);
                    dilated += u32::from(aff);
                }
                o = visible as f32 / (msaa + 9) as f32 * voxel_opacity(k);
            }
            let m = if dilated == 0 {
                1.0
            } else if visible > 0 {
                0.5
            } else {
                0.0
            };
            (o, m)
        })
        .collect();
    per_voxel.into_iter().unzip()
}

/// What CAO's step V reads, x fastest: `V_o`, the mask `V_m` and `V_PAO`.
#[derive(Debug, Clone, Copy)]
pub struct StepVInputs<'a> {
    pub v_o: &'a [f32],
    pub v_m: &'a [f32],
    pub v_pao: &'a [f32],
}

/// Step V on the CPU: `V_AO` from `inputs` (twin of `cao_lao.wgsl`), for every voxel,
/// with rays stepping over the empty cells of `bricks`.
pub fn lao_on_opacity_cpu(
    texels: &VolumeTexels,
    inputs: StepVInputs<'_>,
    rays: &Rays,
    samples: u32,
    mode: CaoMode,
    bricks: &Bricks,
) -> Vec<f32> {
    let StepVInputs { v_o, v_m, v_pao } = inputs;
    let dims = texels.dims;
    let [nx, ny, nz] = dims;
    let extent = Vec3::from(texels.extent());
    let scale = Vec3::splat(STEP_MM) / extent;
    let samples = samples.max(1);
    let size = Vec3::new(nx as f32, ny as f32, nz as f32);
    let opacity_at = |uvw: Vec3| {
        if uvw.cmplt(Vec3::ZERO).any() || uvw.cmpgt(Vec3::ONE).any() {
            0.0
        } else {
            trilinear(v_o, dims, uvw)
        }
    };
    let readable = bricks.readable_mask(texels);
    (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let m = v_m[i];
            if m == 1.0 && mode == CaoMode::Selective {
                return v_pao[i];
            }
            if m <= 0.0 || !readable[i] {
                return 1.0;
            }
            let v = Vec3::new(
                (i % nx) as f32,
                ((i / nx) % ny) as f32,
                (i / (nx * ny)) as f32,
            );
            let centre = (v + Vec3::splat(0.5)) / size;
            let mut total = 0.0;
            for (d, w) in rays.directions.iter().zip(&rays.weights) {
                let step = *d * scale;
                let sum = ray_sum(centre, step, samples, bricks, dims, opacity_at);
                total += w * sum / samples as f32;
            }
            total / rays.directions.len() as f32
        })
        .collect()
}
