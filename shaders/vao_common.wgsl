// Positional ambient occlusion by ray marching (Papaioannou et al. 2010, §5.2):
// the per-point function A_P(x) of Eq. 8 with the directional obscurance of Eq. 7.
// Included by vao.wgsl (precomputed volume) and raycast.wgsl (live mode), so both modes
// run this very code. CPU twin: src/ao/vao.rs (`positional_ao`); keep the two in step.
//
// For each of N_dir directions ω_k (with one constant jitter j_k per ray) the samples
// x_i = x + ω_k · (i + j_k) · Δ, i = 0 … N_samples − 1, Δ = r_max / N_samples, read the
// opacity V of the transfer function (defined per voxel length v_s):
//   R(x_i) = 0 if V(x_i) < V(x_{i−1}) (x_{−1} = x), else 1                      (Eq. 4)
//   γ_k    = 1 − [Π_i (1 − V(x_i))^R(x_i)]^(Δ / v_s)                             (Eq. 7)
//   A_P(x) = 1/N_dir · Σ_k γ_k                                                   (Eq. 8)
// A ray stops at an accepted sample with V ≥ V_thres, or once γ_k is within 1/256 of 1.
// Samples outside the volume box are empty. Isosurface mode (§5.2.1): γ_k = 1 if a
// sample beyond the guard distance lies within d_tol of d_iso (data values), else 0.
//!include clip_common.wgsl
//!include volume.wgsl

struct VaoParams {
    mm_to_uvw: vec4<f32>,  // 1 / extent (mm) per axis; w = stratum length Δ (mm)
    map: VolumeMap,        // how the f16 level's values map to vao_alpha (volume.wgsl's struct)
    counts: vec4<u32>,     // N_dir, N_samples, mip level, mode (0 Beer's law, 1 isosurface)
    limits: vec4<f32>,     // V_thres, product below which γ ≈ 1, d_iso, d_tol (texel units)
    guard: vec4<f32>,      // isosurface guard distance (mm), Eq. 7 exponent Δ / v_s, unused × 2
}

@group(2) @binding(0) var<uniform> vao: VaoParams;
@group(2) @binding(1) var vao_volume: texture_3d<f32>;  // R16Float texel values with mips
@group(2) @binding(2) var vao_sampler: sampler;
@group(2) @binding(3) var<storage, read> vao_alpha: array<f32>;
@group(2) @binding(4) var<storage, read> vao_rays: array<vec4<f32>>;  // xyz direction, w jitter
// A segmentation's weights on the opacity as f16 (ao::vao::VaoInputs::with_segments;
// float, so that Eq. 4's comparisons filter as in the twin), read where a pipeline sets
// SEGMENTS (volume.wgsl).
@group(2) @binding(9) var vao_segment_weight: texture_3d<f32>;

// The segmentation's weight at `uvw` (1 without one).
fn vao_weight(uvw: vec3<f32>) -> f32 {
    if SEGMENTS {
        return textureSampleLevel(vao_segment_weight, vao_sampler, uvw, 0.0).r;
    }
    return 1.0;
}

fn vao_inside(uvw: vec3<f32>) -> bool {
    return all(uvw >= vec3<f32>(0.0)) && all(uvw <= vec3<f32>(1.0));
}

// The texel value at `uvw` from the mip level whose voxel matches the stratum length.
fn vao_value(uvw: vec3<f32>) -> f32 {
    return textureSampleLevel(vao_volume, vao_sampler, uvw, f32(vao.counts.z)).r;
}

// True where a clip shape removes the volume (clip_common.wgsl): clipped space is
// empty for positional AO too, so it follows the clip shapes in live mode.
fn vao_clipped(uvw: vec3<f32>) -> bool {
    if clip.counts.x == 0u {
        return false;
    }
    return !clip_visible((uvw - vec3<f32>(0.5)) / vao.mm_to_uvw.xyz);
}

// Opacity per voxel length v_s (Eq. 6's V), from the transfer function.
fn vao_opacity(norm: f32) -> f32 {
    let t = clamp(norm * vao.map.lut.x + vao.map.lut.y, 0.0, vao.map.lut.z);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(vao.map.lut.z));
    return mix(vao_alpha[i0], vao_alpha[i1], t - floor(t));
}

// γ(x, ω) of one ray (Eq. 7, or §5.2.1 in isosurface mode). `x` in texture coordinates.
fn vao_obscurance(x: vec3<f32>, ray: vec4<f32>) -> f32 {
    let stratum = vao.mm_to_uvw.w;
    let step = ray.xyz * vao.mm_to_uvw.xyz * stratum;
    let n = vao.counts.y;
    if vao.counts.w == 1u {
        for (var i = 0u; i < n; i = i + 1u) {
            let s = f32(i) + ray.w;
            let uvw = x + step * s;
            if !vao_inside(uvw) {
                break;
            }
            if vao_clipped(uvw) {
                continue;
            }
            if s * stratum >= vao.guard.x && abs(vao_value(uvw) - vao.limits.z) < vao.limits.w {
                return 1.0;
            }
        }
        return 0.0;
    }
    var prev = 0.0;
    if vao_inside(x) && !vao_clipped(x) {
        prev = vao_opacity(vao_value(x)) * vao_weight(x);
    }
    var product = 1.0;
    for (var i = 0u; i < n; i = i + 1u) {
        let uvw = x + step * (f32(i) + ray.w);
        // The box is convex: once outside, every further sample is empty.
        if !vao_inside(uvw) {
            break;
        }
        var v = 0.0;
        if !vao_clipped(uvw) {
            v = vao_opacity(vao_value(uvw)) * vao_weight(uvw);
        }
        let accepted = v >= prev;
        prev = v;
        if accepted {
            product = product * (1.0 - v);
            if v >= vao.limits.x || product <= vao.limits.y {
                break;
            }
        }
    }
    if product <= 0.0 {
        return 1.0;
    }
    return 1.0 - pow(product, vao.guard.y);
}

// A_P(x), Eq. 8: the fraction of light reaching x that the surroundings block.
fn positional_ao(x: vec3<f32>) -> f32 {
    var total = 0.0;
    for (var k = 0u; k < vao.counts.x; k = k + 1u) {
        total = total + vao_obscurance(x, vao_rays[k]);
    }
    return total / f32(max(vao.counts.x, 1u));
}
