// Ambient maps from box statistics (Ruiz et al. 2010 §3.2–3.3, Penner's baseline, and
// the variance of §4.2). One invocation per voxel.
// CPU twin: src/ao/filter/mod.rs (`ambient`, `ambient_run`), which evaluates pow and exp
// with vectorisable approximations (within 1e-6); keep the two in step.
//!include volume.wgsl

struct Params {
    dims: vec4<u32>,    // x, y, z, map (0 Penner, 1 CDF, 2 Gauss, 3 variance)
    radius: vec4<u32>,  // box radius per axis
    source: vec4<f32>,  // w: opacity (1) or density (0); xyz unused (the map is volume.wgsl's)
}

// The density and the opacity table: volume.wgsl (group 3), its voxels unfiltered.
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var stats: texture_3d<f32>;
@group(0) @binding(2) var out_map: texture_storage_3d<r32float, write>;

const VARIANCE_FLOOR: f32 = 1e-12;
const ERF_A: f32 = 0.1400123;
const FOUR_OVER_PI: f32 = 1.2732395;
const SQRT_2: f32 = 1.4142135;

// Same as in box_stats.wgsl.
fn source_value(norm: f32) -> f32 {
    if p.source.w == 0.0 {
        return data_value(norm);
    }
    return opacity(norm);
}

// The source value of voxel `k`: with a segmentation, its opacity × the voxel's weight
// (`Source::decode` with weights).
fn source_of_voxel(k: vec3<i32>) -> f32 {
    let v = source_value(value_of_voxel(k));
    if p.source.w == 0.0 {
        return v;
    }
    return v * segment_weight_of_voxel(k);
}

// Voxels of the cropped window [i - r, i + r] ∩ [0, n).
fn window_count(i: u32, r: u32, n: u32) -> u32 {
    return min(i + r, n - 1u) - (i - min(i, r)) + 1u;
}

// Winitzki's erf approximation (Ruiz et al. §3.3).
fn erf_approx(x: f32) -> f32 {
    let x2 = x * x;
    let ax2 = ERF_A * x2;
    let e = sqrt(max(1.0 - exp(-x2 * (FOUR_OVER_PI + ax2) / (1.0 + ax2)), 0.0));
    return select(e, -e, x < 0.0);
}

fn ambient(map: u32, v_x: f32, m: vec4<f32>) -> f32 {
    let v_min = m.x;
    let v_max = m.y;
    let variance = max(m.w - m.z * m.z, 0.0);
    if map == 3u {
        return variance;
    }
    let delta = v_max - v_min;
    if delta <= 0.0 {
        return 1.0;
    }
    let mean = clamp(m.z, v_min, v_max);
    let v = max(variance, VARIANCE_FLOOR);
    if map == 1u {
        let t = (v_x - v_min) / delta;
        if t <= 0.0 {
            return 0.0;
        }
        if t >= 1.0 {
            return 1.0;
        }
        let below = v_max - mean;
        if below <= 0.0 {
            return 0.0;
        }
        return pow(t, (mean - v_min) / below);
    }
    if map == 2u {
        let x = (v_x - mean) / (sqrt(v) * SQRT_2);
        return 0.5 * (1.0 + erf_approx(x));
    }
    let d = mean - v_x;
    if d <= 0.0 {
        return 1.0;
    }
    return v / (v + d * d);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let dims = p.dims.xyz;
    if any(gid >= dims) {
        return;
    }
    let n = f32(window_count(gid.x, p.radius.x, dims.x) * window_count(gid.y, p.radius.y, dims.y)
        * window_count(gid.z, p.radius.z, dims.z));
    let s = textureLoad(stats, gid, 0);
    let m = vec4<f32>(s.x, s.y, s.z / n, s.w / n);
    let v_x = source_of_voxel(vec3<i32>(gid));
    textureStore(out_map, gid, vec4<f32>(ambient(p.dims.w, v_x, m), 0.0, 0.0, 1.0));
}
