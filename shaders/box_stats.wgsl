// Separable box statistics (Ruiz et al. 2010 §3): one pass per axis of the van Herk /
// Gil-Werman algorithm with op = (min, max, +, +). One invocation per segment of
// L = min(2r + 1, 64) outputs of one line; every window of the segment contains the
// pivot m = c + r, so window(i) = op(S[i − r], P[i + r]) with the suffixes
// S[a] = op(v[a..m)) and prefixes P[b] = op(v[m..=b]). Windows are cropped at the faces.
// CPU twin: src/ao/filter/cpu.rs (`segment`, `FilterCpu`); keep the two in step.
//!include volume.wgsl

struct Params {
    dims: vec4<u32>,    // x, y, z, axis
    run: vec4<u32>,     // r, segment length L, segments per line, first pass (1)
    source: vec4<f32>,  // w: opacity (1) or density (0); xyz unused (the map is volume.wgsl's)
    count: vec4<u32>,   // invocations, invocations per dispatch row, lines
}

// The density and the opacity table: volume.wgsl (group 3), its voxels unfiltered.
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var stats_in: texture_3d<f32>;
@group(0) @binding(2) var stats_out: texture_storage_3d<rgba32float, write>;

const BIG: f32 = 3.0e38;
const SEGMENT_MAX: u32 = 64u;

// Density (norm · a + b) or transfer-function opacity of a texel; src/ao/filter.rs
// `Source::value`.
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

fn combine(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(min(a.x, b.x), max(a.y, b.y), a.z + b.z, a.w + b.w);
}

fn at(line: vec3<u32>, k: u32) -> vec3<u32> {
    var pos = line;
    pos[p.dims.w] = k;
    return pos;
}

fn fetch(pos: vec3<u32>) -> vec4<f32> {
    if p.run.w == 1u {
        let v = source_of_voxel(vec3<i32>(pos));
        return vec4<f32>(v, v, v, v * v);
    }
    return textureLoad(stats_in, pos, 0);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = gid.x + gid.y * p.count.y;
    if index >= p.count.x {
        return;
    }
    let axis = p.dims.w;
    let n = p.dims[axis];
    let r = i32(p.run.x);
    let len = i32(p.run.y);
    // Neighbouring invocations take neighbouring lines (x fastest for the y and z
    // passes), so their loads and stores touch neighbouring texels.
    let segment = index / p.count.z;
    let line_index = index % p.count.z;
    // The line: the two other coordinates, in x, y, z order.
    var line = vec3<u32>(0u);
    if axis == 0u {
        line = vec3<u32>(0u, line_index % p.dims.y, line_index / p.dims.y);
    } else if axis == 1u {
        line = vec3<u32>(line_index % p.dims.x, 0u, line_index / p.dims.x);
    } else {
        line = vec3<u32>(line_index % p.dims.x, line_index / p.dims.x, 0u);
    }
    let c = i32(segment) * len;
    let m = c + r;
    let first = c - r;
    let ni = i32(n);
    let identity = vec4<f32>(BIG, -BIG, 0.0, 0.0);
    var s: array<vec4<f32>, SEGMENT_MAX>;
    for (var j = 0; j < len; j = j + 1) {
        s[j] = identity;
    }
    var acc = identity;
    for (var a = m - 1; a >= first; a = a - 1) {
        // Outside the line the run is cropped: a < 0 repeats S[0], a >= n adds nothing.
        if a >= 0 && a < ni {
            acc = combine(fetch(at(line, u32(a))), acc);
        }
        let j = a - first;
        if j < len {
            s[j] = acc;
        }
    }
    acc = identity;
    for (var j = 0; j < len; j = j + 1) {
        let b = m + j;
        if b < ni {
            acc = combine(acc, fetch(at(line, u32(b))));
        }
        let i = c + j;
        if i >= ni {
            break;
        }
        textureStore(stats_out, at(line, u32(i)), combine(s[j], acc));
    }
}
