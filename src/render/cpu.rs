//! CPU twin of `shaders/raycast.wgsl`: the same steps in the same order, in f32, on
//! rayon. Tests compare it with the GPU; it is also the fallback without an adapter.

use super::{Frame, Image, OPAQUE, RaycastParams, jitter};
use crate::ao::view::{Marking, ViewMarks, ViewMask};
use crate::sample::{SegmentSampler, VolumeSampler, trilinear};
use crate::texels::{BlockRanges, VolumeTexels};
use crate::tf::Lut;
use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;

/// A volume prepared for CPU ray casting.
#[derive(Debug, Clone)]
pub struct CpuVolume {
    pub dims: [usize; 3],
    /// Texel values as the GPU samples them (normalised), x fastest.
    pub norm: Vec<f32>,
    /// Ambient occlusion per voxel in [0, 1]; `None` means 1 everywhere.
    pub ao: Option<Vec<f32>>,
    /// Live positional AO: evaluated at every sample instead of `ao` (CPU twin of the
    /// ray caster's live mode).
    pub live_vao: Option<crate::ao::vao::PositionalAo>,
    /// Light volume for shadows from a directional light.
    pub light: Option<super::shadow::LightVolume>,
    /// Geometry drawn inside the volume, with what `nearest_hit` needs besides the ray.
    pub surfaces: Option<CpuSurfaces>,
    /// Opacity factor per voxel in [0, 1] (variance modulation); `None` means 1.
    pub modulation: Option<Vec<f32>>,
    /// Clip shapes' maps (read back from the GPU): shadow-test clipping of every sample.
    pub clip: Option<crate::clip::cpu::ClipMapsCpu>,
    /// (min, max) of `norm` per occupancy block, for the projection and iso modes'
    /// skipping; `None` skips nothing there.
    pub block_ranges: Option<BlockRanges>,
    /// A segmentation read beside the density (`SEGMENTS`).
    pub segments: Option<SegmentSampler>,
    /// A visibility pass ([`mark_view`]): AO reads mark voxels here (`MARK_AO`).
    pub marks: Option<ViewMarks>,
}

/// Surfaces for the CPU twin: the meshes, and the frame and texels that place the camera.
#[derive(Debug, Clone)]
pub struct CpuSurfaces {
    pub surfaces: Vec<super::surface::Surface>,
    pub frame: Frame,
    pub texels: VolumeTexels,
}

/// The colour at `uvw` of `value` (`classify_at(uvw, value).rgb` in raycast.wgsl).
fn classify(volume: &Reader, uvw: Vec3, value: f32) -> Vec3 {
    Vec4::from(volume.classify_at(uvw, value)).truncate()
}

/// raycast.wgsl's `unclipped`: whether the clip shapes (those that carve the sample's
/// class, with a segmentation) leave the sample at `pos` (`uvw`).
fn unclipped(vol: &CpuVolume, volume: &Reader, pos: Vec3, uvw: Vec3) -> bool {
    vol.clip.as_ref().is_none_or(|c| {
        c.uniforms.counts[0] == 0
            || match volume.segments {
                Some(_) => c.visible_for(pos, volume.carved_by_at(uvw)),
                None => c.classify(pos).0,
            }
    })
}

fn over(acc: Vec4, rgb: Vec3, a: f32) -> Vec4 {
    (acc.truncate() + (1.0 - acc.w) * a * rgb).extend(acc.w + (1.0 - acc.w) * a)
}

impl CpuVolume {
    pub fn new(texels: &VolumeTexels) -> Self {
        CpuVolume {
            dims: texels.dims,
            norm: texels.norm_values(),
            ao: None,
            live_vao: None,
            light: None,
            surfaces: None,
            modulation: None,
            clip: None,
            block_ranges: None,
            segments: None,
            marks: None,
        }
    }
}

fn intersect_box(origin: Vec3, dir: Vec3, lo: Vec3, hi: Vec3) -> (f32, f32) {
    let inv = Vec3::ONE / dir;
    let a = (lo - origin) * inv;
    let b = (hi - origin) * inv;
    let near = a.min(b);
    let far = a.max(b);
    (near.max_element(), far.min_element())
}

/// The density and the transfer function as `volume.wgsl` reads them.
type Reader<'a> = VolumeSampler<'a>;

/// raycast.wgsl's `shade`.
fn shade(
    p: &RaycastParams,
    vol: &CpuVolume,
    volume: &Reader,
    rgb: Vec3,
    uvw: Vec3,
    view: Vec3,
    cut: bool,
) -> Vec3 {
    let lit_at = |cos_theta: f32| {
        vol.light.as_ref().map_or(1.0, |l| {
            super::shadow::shadow_factor(&l.values, vol.dims, p, uvw, view, l.direction, cos_theta)
        })
    };
    let phong = p.shading[3] != 0.0;
    let (mut diffuse, mut specular, mut lit) = (1.0, 0.0, None);
    // Where the AO is read: p.ao[2] voxels out of the material along the normal
    // (raycast.wgsl's `ao_at`).
    let mut ao_at = uvw;
    let reads_ao = vol.ao.is_some() || vol.marks.is_some() || vol.live_vao.is_some();
    if phong || (reads_ao && p.ao[2] > 0.0) {
        let d = Vec3::new(p.voxel_uvw[0], p.voxel_uvw[1], p.voxel_uvw[2]);
        let differences = |s: &dyn Fn(Vec3) -> f32| {
            Vec3::new(
                s(Vec3::new(d.x, 0.0, 0.0)) - s(Vec3::new(-d.x, 0.0, 0.0)),
                s(Vec3::new(0.0, d.y, 0.0)) - s(Vec3::new(0.0, -d.y, 0.0)),
                s(Vec3::new(0.0, 0.0, d.z)) - s(Vec3::new(0.0, 0.0, -d.z)),
            ) / (2.0 * p.voxel_uvw[3])
        };
        let mut g = differences(&|o| volume.value_at(uvw + o));
        let mut strength = g.length() * volume.map.lut[0].abs() * p.voxel_uvw[3] * p.edge[0];
        if let Some(segments) = volume.segments {
            // The weight's edge where it is the stronger.
            let gw = segments.gradient_at(uvw) / (2.0 * p.voxel_uvw[3]);
            let sw = gw.length() * p.voxel_uvw[3] * 2.0;
            if sw > strength {
                (g, strength) = (gw, sw);
            }
        }
        let mut edge = strength.clamp(0.0, 1.0);
        if p.mode[0] as u32 == MODE_ISO && strength > 0.0 {
            edge = 1.0; // an isosurface is a surface however soft its gradient
        }
        if strength > 0.0 {
            let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
            let out = p.ao[2] * (AO_EDGE_GAIN * edge).min(1.0) * p.voxel_uvw[3];
            ao_at = uvw - g.normalize() * out / (2.0 * half);
        }
        if let (true, true, Some(l)) = (phong, strength > 0.0, &vol.light) {
            let n = g.normalize();
            diffuse = 1.0 + (n.dot(l.direction).abs() - 1.0) * edge;
            lit = Some(lit_at(diffuse));
            let h = l.direction + view;
            if h.dot(h) > 1e-12 {
                specular = p.shading[1] * n.dot(h.normalize()).abs().powf(p.shading[2]) * edge;
            }
        } else if phong && strength > 0.0 && vol.light.is_none() {
            let n_dot_v = g.normalize().dot(view).abs();
            diffuse = 1.0 + (n_dot_v - 1.0) * edge;
            specular = p.shading[1] * n_dot_v.powf(p.shading[2]) * edge;
        }
    }
    if cut {
        // A cut face: lit without a direction; out of the material is back towards the
        // eye, through what was carved.
        let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
        (diffuse, specular, lit) = (1.0, 0.0, None);
        ao_at = uvw + view * (p.ao[2] * p.voxel_uvw[3]) / (2.0 * half);
    }
    if let Some(marks) = &vol.marks {
        marks.mark(uvw, ao_at);
    }
    let mut ao = vol
        .ao
        .as_ref()
        .map_or(1.0, |ao| trilinear(ao, vol.dims, ao_at));
    if let Some(pao) = &vol.live_vao {
        ao = 1.0 - pao.positional_ao(ao_at);
    }
    let lit = lit.unwrap_or_else(|| lit_at(1.0));
    light(p, rgb, ao, diffuse, specular, lit)
}

/// The lit colour of a sample, as `light` in raycast.wgsl: by default the AO factor
/// `A_s = clamp(1 − s(1 − min(A / A_open, 1)), 0, 1)` (`A_open` =
/// [`super::AoReference::open_plane`]) on ambient and diffuse light,
/// `C_TF · A_s · (k + (1 − k) · D · S) + spec · S`; with `ao_ambient_only`, on the ambient
/// term only with `A_s = clamp(1 − s(1 − A), 0, 1)`, `C_TF · (k · A_s + (1 − k) · D · S) +
/// spec · S`.
fn light(p: &RaycastParams, rgb: Vec3, ao: f32, diffuse: f32, specular: f32, lit: f32) -> Vec3 {
    let k = p.shading[0];
    let c = if p.ao[1] != 0.0 {
        let a = (1.0 - p.ao[0] * (1.0 - ao)).clamp(0.0, 1.0);
        rgb * (k * a + (1.0 - k) * diffuse * lit)
    } else {
        let a = (1.0 - p.ao[0] * (1.0 - (ao / p.ao[3]).min(1.0))).clamp(0.0, 1.0);
        rgb * a * (k + (1.0 - k) * diffuse * lit)
    };
    c + Vec3::splat(specular * lit)
}

/// The occupancy block of the sample at `uvw` and its index in the grid (raycast.wgsl's
/// `block_at`).
fn block_at(p: &RaycastParams, dims: Vec3, uvw: Vec3) -> (glam::UVec3, usize) {
    let grid = glam::UVec3::new(p.grid[0], p.grid[1], p.grid[2]);
    let block = ((uvw.clamp(Vec3::ZERO, Vec3::ONE) * dims).as_uvec3() / p.grid[3])
        .min(grid - glam::UVec3::ONE);
    let index = block.x as usize
        + grid.x as usize * (block.y as usize + grid.y as usize * block.z as usize);
    (block, index)
}

/// The first regular sample past `block` along the ray (raycast.wgsl's `past_block`).
fn past_block(
    p: &RaycastParams,
    dims: Vec3,
    (origin, dir): (Vec3, Vec3),
    block: glam::UVec3,
    t_enter: f32,
    offset: f32,
) -> u32 {
    let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
    let lo = (block * p.grid[3]).as_vec3() / dims * 2.0 * half - half;
    let hi = ((block + glam::UVec3::ONE) * p.grid[3]).as_vec3() / dims * 2.0 * half - half;
    let leave = intersect_box(origin, dir, lo, hi).1;
    ((leave - t_enter) / p.step[0] - offset).ceil().max(0.0) as u32
}

/// The AO is read the full offset out wherever the gradient is at least 1/8 of a full
/// edge (raycast.wgsl's `AO_EDGE_GAIN`).
const AO_EDGE_GAIN: f32 = 8.0;

/// A sample within this many voxels (of the smallest spacing) behind a carved sample in
/// a block that may have opacity lies on a cut face: lit without a direction, its AO read back along
/// the ray (raycast.wgsl's `CUT_SHELL`; docs/algorithms.md, "Cut faces").
pub const CUT_SHELL: f32 = 2.0;

const MODE_COMPOSITE: u32 = 0;
const MODE_MIP: u32 = 1;
const MODE_MINIP: u32 = 2;
const MODE_AVERAGE: u32 = 3;
const MODE_ISO: u32 = 4;

/// Bisection steps that place an isosurface hit between two samples.
const ISO_REFINE: u32 = 6;

/// One ray through the box: what `project` and `iso_hit` walk.
struct Ray<'a> {
    p: &'a RaycastParams,
    vol: &'a CpuVolume,
    volume: &'a Reader<'a>,
    origin: Vec3,
    dir: Vec3,
    t_enter: f32,
    t_exit: f32,
    offset: f32,
}

impl Ray<'_> {
    fn half(&self) -> Vec3 {
        Vec3::new(self.p.box_half[0], self.p.box_half[1], self.p.box_half[2])
    }

    /// Sample `k`'s distance along the ray and position.
    fn sample(&self, k: u32) -> (f32, Vec3) {
        let t = self.t_enter + (k as f32 + self.offset) * self.p.step[0];
        (t, self.origin + self.dir * t)
    }

    /// Where skipping is on: the mode value's range (lo, hi) over the occupancy block of
    /// `pos`, and the first regular sample past that block.
    fn block_u(&self, pos: Vec3) -> Option<((f32, f32), u32)> {
        let ranges = self.vol.block_ranges.as_ref()?;
        if self.p.step[3] == 0.0 {
            return None;
        }
        let d = self.vol.dims;
        let dims = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
        let uvw = pos / (2.0 * self.half()) + Vec3::splat(0.5);
        let (block, index) = block_at(self.p, dims, uvw);
        let (mn, mx) = ranges.ranges[index];
        let a = mn * self.p.mode[1] + self.p.mode[2];
        let b = mx * self.p.mode[1] + self.p.mode[2];
        let ray = (self.origin, self.dir);
        let next = past_block(self.p, dims, ray, block, self.t_enter, self.offset);
        Some(((a.min(b), a.max(b)), next))
    }

    /// raycast.wgsl's `visible`: unclipped and not in a hidden segment.
    fn visible(&self, pos: Vec3) -> bool {
        let uvw = pos / (2.0 * self.half()) + Vec3::splat(0.5);
        if let Some(s) = self.volume.segments
            && s.look_at(uvw).w < 0.5
        {
            return false;
        }
        unclipped(self.vol, self.volume, pos, uvw)
    }

    fn mode_value(&self, pos: Vec3) -> f32 {
        let uvw = pos / (2.0 * self.half()) + Vec3::splat(0.5);
        self.volume.value_at(uvw) * self.p.mode[1] + self.p.mode[2]
    }

    /// MIP, MinIP or average over the unclipped samples (raycast.wgsl's `project`).
    fn project(&self, mode: u32) -> Vec4 {
        let (mut best, mut sum, mut count) = (0.0f32, 0.0f32, 0u32);
        // MIP and MinIP jump over blocks that cannot change the pixel: the grey is
        // clamp(best, 0, 1), so once a sample is in, a block whose values all stay at or
        // below max(best, 0) (MIP), or at or above min(best, 1) (MinIP), changes nothing.
        let skip = mode == MODE_MIP || mode == MODE_MINIP;
        let extreme = |best: f32, count: u32, u: f32| {
            if count == 0 {
                u
            } else if mode == MODE_MIP {
                best.max(u)
            } else {
                best.min(u)
            }
        };
        let mut k = 0u32;
        while k < self.p.step[2] as u32 {
            let (t, pos) = self.sample(k);
            if t >= self.t_exit {
                break;
            }
            if skip
                && count > 0
                && let Some(((lo, hi), next)) = self.block_u(pos)
                && ((mode == MODE_MIP && hi <= best.max(0.0))
                    || (mode == MODE_MINIP && lo >= best.min(1.0)))
            {
                k = (k + 1).max(next);
                continue;
            }
            k += 1;
            if !self.visible(pos) {
                continue;
            }
            let u = self.mode_value(pos);
            best = extreme(best, count, u);
            sum += u;
            count += 1;
            // The grey is clamped to [0, 1]: white MIP or black MinIP is final.
            if (mode == MODE_MIP && best >= 1.0) || (mode == MODE_MINIP && best <= 0.0) {
                break;
            }
        }
        if count == 0 {
            return Vec4::ZERO;
        }
        if mode == MODE_AVERAGE {
            best = sum / count as f32;
        }
        Vec3::splat(best.clamp(0.0, 1.0)).extend(1.0)
    }

    fn inside_surface(&self, t: f32) -> bool {
        let pos = self.origin + self.dir * t;
        self.visible(pos) && self.mode_value(pos) >= 0.0
    }

    /// The first point inside the isosurface, refined, and the last point before it found
    /// outside (raycast.wgsl's `iso_hit`).
    fn iso_hit(&self) -> Option<(f32, f32)> {
        let mut before = self.t_enter;
        let mut after = None;
        let mut k = 0u32;
        while k < self.p.step[2] as u32 {
            let (t, pos) = self.sample(k);
            if t >= self.t_exit {
                break;
            }
            // A block whose values all stay below the iso value holds no hit: jump to its
            // last sample, which is then the sample before, as without skipping.
            if let Some(((_, hi), next)) = self.block_u(pos)
                && hi < 0.0
            {
                let last = (k + 1).max(next) - 1;
                before = self.sample(last).0;
                k = last + 1;
                continue;
            }
            if self.inside_surface(t) {
                after = Some(t);
                break;
            }
            before = t;
            k += 1;
        }
        let (mut lo, mut hi) = (before, after?);
        for _ in 0..ISO_REFINE {
            let mid = 0.5 * (lo + hi);
            if self.inside_surface(mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some((hi, lo))
    }
}

/// The ray through the centre of pixel `(px, py)` (of the whole frame) as `main` in
/// raycast.wgsl casts it: origin on the near plane, unit direction, and where it enters
/// (not before its origin) and leaves the volume's box (`t_exit <= t_enter`: it misses).
pub fn ray(p: &RaycastParams, px: u32, py: u32) -> (Vec3, Vec3, f32, f32) {
    let inv = Mat4::from_cols_array_2d(&p.inv_view_proj);
    let ndc_x = (px as f32 + 0.5) / p.image[0] as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - (py as f32 + 0.5) / p.image[1] as f32 * 2.0;
    let near = inv * Vec4::new(ndc_x, ndc_y, 0.0, 1.0);
    let far = inv * Vec4::new(ndc_x, ndc_y, 1.0, 1.0);
    let origin = near.truncate() / near.w;
    let dir = (far.truncate() / far.w - origin).normalize();
    let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
    let (t0, t1) = intersect_box(origin, dir, -half, half);
    (origin, dir, t0.max(0.0), t1)
}

/// Accumulated opacity at which a pick stops (`PICK_OPACITY` of raycast.wgsl).
pub const PICK_OPACITY: f32 = 0.5;

/// One pixel, exactly as `main` in raycast.wgsl computes it (before 8-bit quantisation);
/// `None` where it would leave the target's pixel as it is (its ray meets none of the
/// balls of [`super::reuse`]).
pub fn pixel(
    p: &RaycastParams,
    vol: &CpuVolume,
    volume: &Reader,
    occupancy: &[u8],
    px: u32,
    py: u32,
) -> Option<Vec4> {
    cast(p, vol, volume, occupancy, (px, py), false).map(|(rgba, _)| rgba)
}

/// Where the composite ray of pixel `(px, py)` first reaches [`PICK_OPACITY`] (its
/// sample's position, volume-centred mm), as a `PICK` pipeline of raycast.wgsl finds it:
/// the same steps, jitter, clipping, segment weights and modulation as the image.
pub fn pick(
    p: &RaycastParams,
    vol: &CpuVolume,
    volume: &Reader,
    occupancy: &[u8],
    px: u32,
    py: u32,
) -> Option<Vec3> {
    cast(p, vol, volume, occupancy, (px, py), true).and_then(|(_, picked)| picked)
}

/// `main` of raycast.wgsl for one pixel; with `pick`, as its `PICK` variant (the ray
/// stops where the opacity reaches [`PICK_OPACITY`], and says where).
fn cast(
    p: &RaycastParams,
    vol: &CpuVolume,
    volume: &Reader,
    occupancy: &[u8],
    (px, py): (u32, u32),
    pick: bool,
) -> Option<(Vec4, Option<Vec3>)> {
    let mut picked = None;
    let (origin, dir, t_enter, t_exit) = ray(p, px, py);
    let half = Vec3::new(p.box_half[0], p.box_half[1], p.box_half[2]);
    if p.reuse[0] > 0 && !super::reuse::meets_change(p, origin, dir, t_enter, t_exit) {
        return None;
    }
    let dt = p.step[0];
    let mut acc = Vec4::ZERO;
    let hit = vol
        .surfaces
        .as_ref()
        .and_then(|s| super::surface::nearest_hit(&s.surfaces, &s.frame, &s.texels, origin, dir));
    let mut pending = hit.is_some();
    let (t_surf, surf) = hit.unwrap_or((0.0, Vec4::ZERO));
    let mode = p.mode[0] as u32;
    if t_exit > t_enter && mode != MODE_COMPOSITE {
        let ray = Ray {
            p,
            vol,
            volume,
            origin,
            dir,
            t_enter,
            t_exit,
            offset: if p.step[1] != 0.0 {
                jitter(px, py)
            } else {
                0.0
            },
        };
        let (front, result) = if mode == MODE_ISO {
            match ray.iso_hit() {
                Some((t_hit, t_lo)) => {
                    let uvw = (origin + dir * t_hit) / (2.0 * half) + Vec3::splat(0.5);
                    let norm = volume.value_at(uvw);
                    // Just before the hit the ray was inside the material but clipped:
                    // the hit is on a cut face.
                    let lo = origin + dir * t_lo;
                    let cut = !ray.visible(lo) && ray.mode_value(lo) >= 0.0;
                    let rgb = shade(p, vol, volume, classify(volume, uvw, norm), uvw, -dir, cut);
                    (t_hit, rgb.extend(1.0))
                }
                None => (3.0e38, Vec4::ZERO),
            }
        } else {
            (3.0e38, ray.project(mode))
        };
        if pending && t_surf < front {
            acc = over(acc, surf.truncate(), surf.w);
            pending = false;
        }
        acc = over(acc, result.truncate(), result.w);
        pending = pending && result.w < 1.0;
    }
    if t_exit > t_enter && mode == MODE_COMPOSITE {
        let offset = if p.step[1] != 0.0 {
            jitter(px, py)
        } else {
            0.0
        };
        let max_steps = p.step[2] as u32;
        let dims = Vec3::new(vol.dims[0] as f32, vol.dims[1] as f32, vol.dims[2] as f32);
        // One loop over the samples; the shader nests three around the same steps (skip,
        // fetch, shade) for SIMD drivers that run every branch masked.
        let mut k = 0u32;
        // The last carved sample in a block that may have opacity (cut faces lie just
        // behind it).
        let mut cut_t = -3.0e38f32;
        while k < max_steps {
            let t = t_enter + (k as f32 + offset) * dt;
            if pending && t_surf <= t {
                acc = over(acc, surf.truncate(), surf.w);
                pending = false;
                if surf.w >= 1.0 {
                    break;
                }
            }
            if t >= t_exit {
                break;
            }
            let pos = origin + dir * t;
            let uvw = pos / (2.0 * half) + Vec3::splat(0.5);
            if p.step[3] != 0.0 {
                let (block, index) = block_at(p, dims, uvw);
                if occupancy[index] == 0 {
                    let next = past_block(p, dims, (origin, dir), block, t_enter, offset);
                    k = (k + 1).max(next);
                    continue;
                }
            }
            // Shadow-test clipping (CAO step VI): clipped samples are empty.
            if !unclipped(vol, volume, pos, uvw) {
                // In a block that may have opacity (with skipping, every sample here).
                if p.step[3] != 0.0 || occupancy[block_at(p, dims, uvw).1] != 0 {
                    cut_t = t;
                }
                k += 1;
                continue;
            }
            let norm = volume.value_at(uvw);
            let mut rgba = Vec4::from(volume.classify_at(uvw, norm));
            if rgba.w > 0.0 {
                if let Some(m) = &vol.modulation {
                    rgba.w *= trilinear(m, vol.dims, uvw);
                }
                let len = dt.min(t_exit - t);
                let cut = t - cut_t <= CUT_SHELL * p.voxel_uvw[3];
                let rgb = shade(p, vol, volume, rgba.truncate(), uvw, -dir, cut);
                if pending && t_surf < t + len {
                    let before = (t_surf - t).max(0.0);
                    acc = over(acc, rgb, 1.0 - (1.0 - rgba.w).powf(before / dt));
                    acc = over(acc, surf.truncate(), surf.w);
                    pending = false;
                    if surf.w >= 1.0 {
                        break;
                    }
                    acc = over(acc, rgb, 1.0 - (1.0 - rgba.w).powf((len - before) / dt));
                } else {
                    if len < dt {
                        rgba.w = 1.0 - (1.0 - rgba.w).powf(len / dt);
                    }
                    acc = (acc.truncate() + (1.0 - acc.w) * rgba.w * rgb)
                        .extend(acc.w + (1.0 - acc.w) * rgba.w);
                }
                if pick && acc.w >= PICK_OPACITY {
                    picked = Some(origin + dir * t);
                    break;
                }
                if acc.w > OPAQUE {
                    break;
                }
            }
            k += 1;
        }
    }
    if pending {
        acc = over(acc, surf.truncate(), surf.w);
    }
    let bg = Vec4::from(p.background);
    let alpha = acc.w + (1.0 - acc.w) * bg.w;
    let mut rgb = acc.truncate() + (1.0 - acc.w) * bg.w * bg.truncate();
    if alpha > 0.0 {
        rgb /= alpha;
    }
    Some((rgb.clamp(Vec3::ZERO, Vec3::ONE).extend(alpha), picked))
}

/// Renders a whole frame on the CPU. `occupancy` comes from [`BlockRanges::occupancy`].
pub fn render(
    texels: &VolumeTexels,
    vol: &CpuVolume,
    lut: &Lut,
    occupancy: &[u8],
    frame: &Frame,
) -> Image {
    render_reusing(texels, vol, lut, occupancy, frame, None)
}

/// Where the ray of pixel `(px, py)` of `frame` first reaches [`PICK_OPACITY`]
/// (volume-centred mm), as `RayCaster::pick` finds it for the same inputs as [`render`].
pub fn pick_pixel(
    texels: &VolumeTexels,
    vol: &CpuVolume,
    lut: &Lut,
    occupancy: &[u8],
    frame: &Frame,
    (px, py): (u32, u32),
) -> Option<Vec3> {
    let p = frame.params(texels, lut, 0, 0);
    let volume =
        VolumeSampler::density(&vol.norm, texels, lut).with_segments(vol.segments.as_ref());
    pick(&p, vol, &volume, occupancy, px, py)
}

/// [`render`] over `previous`, an image of the same view whose inputs differ from this
/// frame's only inside `balls` ([`super::reuse`]): the pixels whose rays meet none of them
/// are `previous`'s, as `RayCaster::render_reusing` leaves them.
pub fn render_reusing(
    texels: &VolumeTexels,
    vol: &CpuVolume,
    lut: &Lut,
    occupancy: &[u8],
    frame: &Frame,
    previous: Option<(&Image, &[super::reuse::Ball])>,
) -> Image {
    let mut p = frame.params(texels, lut, 0, 0);
    if let Some((old, balls)) = previous {
        if balls.is_empty() {
            return old.clone();
        }
        super::reuse::set_balls(&mut p, balls);
    }
    let volume =
        VolumeSampler::density(&vol.norm, texels, lut).with_segments(vol.segments.as_ref());
    let (w, h) = (frame.width, frame.height);
    let pixels: Vec<[u8; 4]> = (0..w * h)
        .into_par_iter()
        .map(|i| match pixel(&p, vol, &volume, occupancy, i % w, i / w) {
            // Round to nearest, as the GPU's unorm8 store does.
            Some(c) => c.to_array().map(|x| (x * 255.0).round() as u8),
            None => previous.map_or([0; 4], |(old, _)| old.pixels[i as usize]),
        })
        .collect();
    Image {
        width: w,
        height: h,
        pixels,
    }
}

/// The twin of [`super::gpu::RayCaster::mark_view`]: ray casts `frame` of `vol` as
/// [`render`] would once its AO is set, and returns the voxels (or cells) its AO reads
/// weigh, as `marking` says. `vol.ao` may be anything meanwhile: AO never changes a
/// sample's opacity.
pub fn mark_view(
    texels: &VolumeTexels,
    vol: &mut CpuVolume,
    lut: &Lut,
    occupancy: &[u8],
    frame: &Frame,
    marking: impl Into<Marking>,
) -> ViewMask {
    let marking: Marking = marking.into();
    if !frame.settings.mode.uses_ao() {
        return ViewMask::from_words(texels.dims, marking.edge.max(1), Vec::new());
    }
    vol.marks = Some(ViewMarks::new(texels.dims, marking));
    render(texels, vol, lut, occupancy, frame);
    let marks = vol.marks.take().expect("set above");
    marks.into_mask()
}

pub fn prepare(texels: &VolumeTexels, lut: &Lut) -> (CpuVolume, Vec<u8>) {
    let ranges = BlockRanges::new(texels);
    let occupancy = ranges.occupancy(texels, lut);
    let volume = CpuVolume {
        block_ranges: Some(ranges),
        ..CpuVolume::new(texels)
    };
    (volume, occupancy)
}
