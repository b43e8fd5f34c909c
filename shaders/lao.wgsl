// Local Ambient Occlusion (Hernell et al.; CAO paper Eq. 2–3) over a list of voxels
// (ao::sparse::Bricks::voxel_list: the readable ones, already tested): one invocation
// per entry, written to a compact buffer in list order. The list comes in groups of 512
// entries dispatched like bricks (gpu::dispatch::BrickDispatch); each submission's part
// is in `voxels`, padded with NONE. CPU twin: src/ao/lao.rs (`lao_voxel`); keep the two
// in step.
//
//   A_k(x) = 1/M · Σ_{m=1..M} Π_{i=1..m-1} (1 − a_i)        (Eq. 2)
//   A(x)   = 1/K · Σ_k w_k A_k(x)                             (Eq. 3)
//
// Sample i lies i mm from the voxel centre along ray k (spacing-aware); samples outside
// the volume are empty. a_i comes from the transfer function's opacity, corrected for a
// 1 mm step. Rays step over empty cells (lao_ray.wgsl).
//!include lao_ray.wgsl
//!include volume.wgsl

const NONE: u32 = 0xffffffffu;

struct Params {
    dims: vec4<u32>,       // x, y, z, unused
    chunk: vec4<u32>,      // first group, groups, workgroups per row, unused
    mm_to_uvw: vec4<f32>,  // 1 / extent in mm per axis
    counts: vec4<u32>,     // rays K, samples M, unused, unused
    grid: vec4<u32>,       // ray cells per axis, skipping (0/1)
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> rays: array<vec4<f32>>;  // xyz direction, w weight
@group(0) @binding(2) var<storage, read_write> v_pao: array<f32>;
@group(0) @binding(3) var<storage, read> voxels: array<u32>;  // this submission's, x fastest
@group(0) @binding(4) var<storage, read> occupied: array<u32>;

// The density's opacity under the LAO table (volume.wgsl: group 3).
fn opacity_in_box(uvw: vec3<f32>) -> f32 {
    return opacity_at(uvw);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let group = wid.y + wid.z * p.chunk.z;
    if group >= p.chunk.y {
        return;
    }
    let out = group * 512u + lid.x + 8u * lid.y + 64u * wid.x;
    let index = voxels[out];
    if index == NONE {
        return;
    }
    let plane = p.dims.x * p.dims.y;
    let voxel = vec3<u32>(index % p.dims.x, (index % plane) / p.dims.x, index / plane);
    let centre = (vec3<f32>(voxel) + 0.5) / vec3<f32>(p.dims.xyz);
    let samples = p.counts.y;
    var total = 0.0;
    for (var k = 0u; k < p.counts.x; k = k + 1u) {
        let ray = rays[k];
        let step = ray.xyz * p.mm_to_uvw.xyz;
        total = total + ray.w * lao_ray(centre, step, samples) / f32(samples);
    }
    v_pao[out] = total / f32(p.counts.x);
}
