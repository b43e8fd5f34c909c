//!fragment: no shader of its own; validated as part of the shaders that include it.
// Brick-list dispatch (ao::sparse, gpu::dispatch::BrickDispatch): a workgroup is the
// 8 × 8 voxels of one layer (workgroup x) of one 8³ brick (workgroups y + z · row), so
// that a brick's layers run one after the other. The including shader declares
// `p.dims: vec4<u32>` (volume size), `p.chunk: vec4<u32>` (first brick of this
// submission, bricks in it, workgroups per row) and `bricks: array<u32>` (packed
// 10 bits per axis).

// The voxel of this invocation (xyz) and whether it exists (w = 1).
fn brick_voxel(wid: vec3<u32>, lid: vec3<u32>) -> vec4<u32> {
    let slot = brick_slot(wid);
    if slot >= p.chunk.y {
        return vec4<u32>(0u);
    }
    let packed = bricks[p.chunk.x + slot];
    let brick = vec3<u32>(packed & 0x3ffu, (packed >> 10u) & 0x3ffu, (packed >> 20u) & 0x3ffu);
    let v = brick * 8u + vec3<u32>(lid.x, lid.y, wid.x);
    return vec4<u32>(v, u32(all(v < p.dims.xyz)));
}

// Whether this workgroup's list entry carries the NEAR bit (bit 30; ao::sparse::NEAR).
fn brick_near(wid: vec3<u32>) -> bool {
    return (bricks[p.chunk.x + brick_slot(wid)] & 0x40000000u) != 0u;
}

// This workgroup's brick among the submission's.
fn brick_slot(wid: vec3<u32>) -> u32 {
    return wid.y + wid.z * p.chunk.z;
}
