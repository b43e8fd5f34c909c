// Precomputed positional ambient occlusion: the ambient factor 1 − A_P(x) at every voxel
// centre of a z-slab. The function itself is in vao_common.wgsl (shared with the ray
// caster's live mode). CPU twin: src/ao/vao.rs (`vao_cpu`).
//!include vao_common.wgsl

struct Slab {
    dims: vec4<u32>,  // x, y, z, first z of this slab
    work: vec4<u32>,  // voxels in this slab, invocations per row
}

@group(0) @binding(0) var<uniform> slab: Slab;
@group(0) @binding(1) var<storage, read_write> ambient: array<f32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = gid.x + gid.y * slab.work.y;
    if index >= slab.work.x {
        return;
    }
    let nx = slab.dims.x;
    let ny = slab.dims.y;
    let voxel = vec3<u32>(index % nx, (index / nx) % ny, slab.dims.w + index / (nx * ny));
    let centre = (vec3<f32>(voxel) + 0.5) / vec3<f32>(slab.dims.xyz);
    ambient[index] = 1.0 - positional_ao(centre);
}
