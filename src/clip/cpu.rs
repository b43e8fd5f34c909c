//! CPU twin of the clip tests (`shaders/clip_common.wgsl`) and of the map building
//! (`shaders/clip_maps.wgsl`, Algorithm 1), working on maps read back from the GPU.

use super::camera::EMPTY;
use super::gpu_data::{ClipUniforms, LAYERS_PER_SHAPE};
use glam::{Mat4, Vec3, Vec4};

/// The clip maps and uniforms as the shaders see them.
#[derive(Debug, Clone)]
pub struct ClipMapsCpu {
    pub resolution: u32,
    /// `layers × resolution²` values, x fastest.
    pub layers: Vec<f32>,
    pub uniforms: ClipUniforms,
}

/// Result of testing a point against one shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClipTest {
    pub inside: bool,
    /// Carve: inside the dilation; probe: inside the contraction.
    pub near: bool,
}

impl ClipMapsCpu {
    fn at(&self, layer: u32, x: u32, y: u32) -> f32 {
        let r = self.resolution as usize;
        self.layers[layer as usize * r * r + y as usize * r + x as usize]
    }

    fn in_interval(&self, x: u32, y: u32, layer: u32, z: f32, strict: bool) -> bool {
        let f1 = self.at(layer, x, y);
        let b1 = self.at(layer + 1, x, y);
        let f2 = self.at(layer + 2, x, y);
        let b2 = self.at(layer + 3, x, y);
        if strict {
            (f1 < z && z < b1) || (f2 < z && z < b2)
        } else {
            (f1 <= z && z <= b1) || (f2 <= z && z <= b2)
        }
    }

    /// `clip_test` of `clip_common.wgsl`.
    pub fn test(&self, s: usize, pos: Vec3) -> ClipTest {
        let shape = &self.uniforms.shapes[s];
        let c = Mat4::from_cols_array_2d(&shape.volume_to_map) * Vec4::from((pos, 1.0));
        let res = shape.info[2] as f32;
        let mut t = ClipTest {
            inside: false,
            near: false,
        };
        if !(c.x >= 0.0 && c.y >= 0.0 && c.x < res && c.y < res) {
            return t;
        }
        let (x, y) = (c.x.floor() as u32, c.y.floor() as u32);
        // info[1] is the shape's first RGBA array layer: 4 maps each.
        let first = shape.info[1] * 4;
        t.inside = self.in_interval(x, y, first, c.z, false);
        t.near = self.in_interval(x, y, first + 4, c.z, true);
        t
    }

    /// `clip_classify` of `clip_common.wgsl`: (visible, affected).
    pub fn classify(&self, pos: Vec3) -> (bool, bool) {
        let (mut carved, mut probed, mut near_carve, mut deep_probe) = (false, false, false, false);
        for s in 0..self.uniforms.counts[0] as usize {
            let t = self.test(s, pos);
            if self.uniforms.shapes[s].info[0] == 0 {
                carved |= t.inside;
                near_carve |= t.near;
            } else {
                probed |= t.inside;
                deep_probe |= t.near;
            }
        }
        let probes = self.uniforms.counts[1] > 0;
        let visible = !carved && (!probes || probed);
        let affected = near_carve || (probes && !deep_probe);
        (visible, affected)
    }

    /// `clip_visible_for` of `clip_common.wgsl`: whether `pos` in a voxel the shapes of
    /// `carve` (bit s) cut is visible.
    pub fn visible_for(&self, pos: Vec3, carve: u32) -> bool {
        let (mut carved, mut probes, mut probed) = (false, false, false);
        for s in 0..self.uniforms.counts[0] as usize {
            if (carve >> s) & 1 == 0 {
                continue;
            }
            let inside = self.test(s, pos).inside;
            if self.uniforms.shapes[s].info[0] == 0 {
                carved |= inside;
            } else {
                probes = true;
                probed |= inside;
            }
        }
        !carved && (!probes || probed)
    }

    /// One map layer of shape `slot` (0..8: Z_front1 … D_back2).
    pub fn layer(&self, slot: usize, layer: u32) -> &[f32] {
        let r = self.resolution as usize;
        let l = slot * LAYERS_PER_SHAPE as usize + layer as usize;
        &self.layers[l * r * r..(l + 1) * r * r]
    }
}

/// The dilation (carve) or contraction (probe) layers of one shape from its four
/// resolved Z layers (`z[k]`, `resolution²` each): Algorithm 1 over blocks of `f`×`f`
/// pixels, as `clip_maps.wgsl` does it (reduce, dilate, expand).
pub fn dilate(
    z: [&[f32]; 4],
    resolution: u32,
    r_xy: f32,
    r_z: f32,
    probe: bool,
    f: u32,
) -> [Vec<f32>; 4] {
    let res = resolution as i32;
    let f = f.max(1) as i32;
    let blocks = (res + f - 1) / f;
    let identity = if probe {
        [-EMPTY, EMPTY, -EMPTY, EMPTY]
    } else {
        [EMPTY, -EMPTY, EMPTY, -EMPTY]
    };
    let widest = |a: [f32; 4], b: [f32; 4]| -> [f32; 4] {
        if probe {
            [
                a[0].max(b[0]),
                a[1].min(b[1]),
                a[2].max(b[2]),
                a[3].min(b[3]),
            ]
        } else {
            [
                a[0].min(b[0]),
                a[1].max(b[1]),
                a[2].min(b[2]),
                a[3].max(b[3]),
            ]
        }
    };
    let mut reduced = vec![identity; (blocks * blocks) as usize];
    for by in 0..blocks {
        for bx in 0..blocks {
            let mut acc = identity;
            for j in 0..f {
                for i in 0..f {
                    let (x, y) = (bx * f + i, by * f + j);
                    if x < res && y < res {
                        let q = (y * res + x) as usize;
                        acc = widest(acc, [z[0][q], z[1][q], z[2][q], z[3][q]]);
                    }
                }
            }
            reduced[(by * blocks + bx) as usize] = acc;
        }
    }
    let reach = ((r_xy + (f - 1) as f32) / f as f32).ceil() as i32;
    let gap = |i: i32| (i.abs() * f - (f - 1)).max(0) as f32;
    let r = r_xy.ceil() as i32;
    let mut dilated = vec![identity; (blocks * blocks) as usize];
    for by in 0..blocks {
        for bx in 0..blocks {
            let mut d = identity;
            for j in -reach..=reach {
                for i in -reach..=reach {
                    let (qx, qy) = (bx + i, by + j);
                    if qx < 0 || qy < 0 || qx >= blocks || qy >= blocks {
                        continue;
                    }
                    let dist = glam::Vec2::new(gap(i), gap(j)).length();
                    if dist > r_xy {
                        continue;
                    }
                    let ratio = dist / r_xy;
                    let h = r_z * (1.0 - ratio * ratio).max(0.0).sqrt();
                    let zq = reduced[(qy * blocks + qx) as usize];
                    let shifted = if probe {
                        [zq[0] + h, zq[1] - h, zq[2] + h, zq[3] - h]
                    } else {
                        [zq[0] - h, zq[1] + h, zq[2] - h, zq[3] + h]
                    };
                    d = widest(d, shifted);
                }
            }
            if probe {
                let (lo_x, lo_y) = (bx * f, by * f);
                let (hi_x, hi_y) = (lo_x + f - 1, lo_y + f - 1);
                if lo_x < r || lo_y < r || hi_x >= res - r || hi_y >= res - r {
                    d = [EMPTY, -EMPTY, EMPTY, -EMPTY];
                }
            }
            dilated[(by * blocks + bx) as usize] = d;
        }
    }
    let mut out: [Vec<f32>; 4] = std::array::from_fn(|_| vec![0.0; (res * res) as usize]);
    for y in 0..res {
        for x in 0..res {
            let d = dilated[((y / f) * blocks + x / f) as usize];
            for k in 0..4 {
                out[k][(y * res + x) as usize] = d[k];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Algorithm 1 per pixel, as the paper writes it: the reference the block dilation
    /// must cover.
    fn exact(z: &[f32], res: i32, r_xy: f32, r_z: f32, probe: bool, back: bool) -> Vec<f32> {
        let r = r_xy.ceil() as i32;
        let mut out = vec![0.0; z.len()];
        for y in 0..res {
            for x in 0..res {
                // Carving moves fronts to −z (min) and backs to +z (max); probing the reverse.
                let outward = probe != back;
                let mut d = if outward { -EMPTY } else { EMPTY };
                for j in -r..=r {
                    for i in -r..=r {
                        let (qx, qy) = (x + i, y + j);
                        let dist = ((i * i + j * j) as f32).sqrt();
                        if qx < 0 || qy < 0 || qx >= res || qy >= res || dist > r_xy {
                            continue;
                        }
                        let h = r_z * (1.0 - (dist / r_xy).powi(2)).max(0.0).sqrt();
                        let zq = z[(qy * res + qx) as usize];
                        d = if outward {
                            d.max(zq + h)
                        } else {
                            d.min(zq - h)
                        };
                    }
                }
                out[(y * res + x) as usize] = d;
            }
        }
        out
    }

    /// On depth maps of a bumpy blob, the block dilation holds every depth
    /// Algorithm 1's dilation holds at every pixel, and the contraction no depth that
    /// Algorithm 1's lacks; for a lone pixel it equals Algorithm 1 along the axes.
    #[test]
    fn the_block_dilation_covers_algorithm_1() {
        let res = 48i32;
        let n = (res * res) as usize;
        let mut front = vec![EMPTY; n];
        let mut back = vec![-EMPTY; n];
        for y in 0..res {
            for x in 0..res {
                let (dx, dy) = (x as f32 - 20.0, y as f32 - 26.0);
                let rr = (dx * dx + dy * dy).sqrt();
                if rr < 14.0 {
                    let bump = 0.03 * ((x * 7 + y * 13) % 5) as f32;
                    front[(y * res + x) as usize] = 0.3 + rr * 0.01 + bump;
                    back[(y * res + x) as usize] = 0.8 - rr * 0.01 - bump;
                }
            }
        }
        let none_f = vec![EMPTY; n];
        let none_b = vec![-EMPTY; n];
        let (r_xy, r_z) = (9.5, 0.2);
        for probe in [false, true] {
            for f in [1, 2, 4] {
                let z = [&front[..], &back[..], &none_f[..], &none_b[..]];
                let d = dilate(z, res as u32, r_xy, r_z, probe, f);
                let want_front = exact(&front, res, r_xy, r_z, probe, false);
                let want_back = exact(&back, res, r_xy, r_z, probe, true);
                // Depths lie in [0, 1]: compare which of them each pixel holds.
                for i in 0..n {
                    for z in (0..=100).map(|k| k as f32 / 100.0) {
                        let block = d[0][i] <= z && z <= d[1][i];
                        let paper = want_front[i] <= z && z <= want_back[i];
                        if probe {
                            assert!(!block || paper, "probe f {f} px {i} z {z}: deeper");
                        } else {
                            assert!(!paper || block, "carve f {f} px {i} z {z}: narrower");
                        }
                    }
                }
            }
        }
        // A lone pixel, dilated per pixel (f = 1): exactly Algorithm 1 along the axes.
        let mut lone = vec![EMPTY; n];
        lone[(24 * res + 24) as usize] = 0.5;
        let z = [&lone[..], &none_b[..], &none_f[..], &none_b[..]];
        let d = dilate(z, res as u32, r_xy, r_z, false, 1);
        let want = exact(&lone, res, r_xy, r_z, false, false);
        for k in -9..=9 {
            for i in [(24 * res + 24 + k) as usize, ((24 + k) * res + 24) as usize] {
                assert!(
                    (d[0][i] - want[i]).abs() < 1e-6,
                    "axis offset {k}: {} vs {}",
                    d[0][i],
                    want[i]
                );
            }
        }
    }
}
