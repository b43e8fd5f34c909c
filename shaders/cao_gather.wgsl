// CAO step V of a frame, first part (ao::cao::listed): the voxels of step V's bricks
// that step IV marked RECOMPUTE, listed compactly (linear indices, x fastest) for the ray
// cast (cao_listed.wgsl), so that it dispatches one invocation per voxel it computes
// instead of one per voxel of a brick. The order of the list varies from run to run
// (atomics); each voxel's value does not depend on it. Entries past the list's capacity
// are counted and not written: the frame then ray casts over the bricks (cao_lao.wgsl).
//!include bricks.wgsl

const RECOMPUTE: f32 = -1.0;

//!include cao_params.wgsl

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var v_ao: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> bricks: array<u32>;
@group(0) @binding(3) var<storage, read_write> counters: array<atomic<u32>, 4>; // [3]: listed
@group(0) @binding(4) var<storage, read_write> listed: array<u32>;

// This workgroup's entries, and where they start in the list (one global atomic per
// workgroup: millions on one counter serialise on a CPU driver).
var<workgroup> taken: atomic<u32>;
var<workgroup> first: u32;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if brick_slot(wid) >= p.chunk.y {
        return;  // the whole workgroup
    }
    let at_voxel = brick_voxel(wid, lid);
    var take = false;
    if at_voxel.w != 0u && brick_near(wid) {
        take = textureLoad(v_ao, vec3<i32>(at_voxel.xyz), 0).r == RECOMPUTE;
    }
    var mine = 0u;
    if take {
        mine = atomicAdd(&taken, 1u);
    }
    workgroupBarrier();
    if lid.x == 0u && lid.y == 0u {
        first = atomicAdd(&counters[3], atomicLoad(&taken));
    }
    let start = workgroupUniformLoad(&first);
    let entry = start + mine;
    if take && entry < arrayLength(&listed) {
        let v = at_voxel.xyz;
        listed[entry] = v.x + p.dims.x * (v.y + p.dims.y * v.z);
    }
}
