// GPU smoke test: writes a known value to every voxel of a 3-D storage texture and a
// storage buffer, so a readback proves the device runs compute work and writes every
// slice of a 3-D texture (wgpu's GL backend gets that wrong). CPU twin: src/gpu/smoke.rs.
//!include common.wgsl

@group(0) @binding(0) var out_volume: texture_storage_3d<r32float, write>;
@group(0) @binding(1) var<storage, read_write> out_linear: array<u32>;

// value(x, y, z) = x + 100 y + 10000 z, exact in f32 for the small grids used.
fn smoke_value(id: vec3<u32>) -> f32 {
    return f32(id.x) + 100.0 * f32(id.y) + 10000.0 * f32(id.z);
}

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let dims = textureDimensions(out_volume);
    if !in_grid(id, dims) {
        return;
    }
    textureStore(out_volume, id, vec4<f32>(smoke_value(id), 0.0, 0.0, 1.0));
    out_linear[linear_index(id, dims)] = linear_index(id, dims) * 3u + 1u;
}
