// Cone-traced ambient occlusion for volumes (Dalla Favera & Celes 2012 §III-C, adapted):
// one invocation per voxel; cones over the whole sphere, each sampled by tangent spheres
// whose occlusion is the mean opacity read from the mip level matching the sphere;
// front to back along a cone, A_cone = Π (1 − o_k); A = mean over cones.
// CPU twin: src/ao/cone.rs (`cone_voxel`); keep the two in step.

struct Params {
    dims: vec4<u32>,       // x, y, z, mip levels
    mm_to_uvw: vec4<f32>,  // 1 / extent in mm per axis
    counts: vec4<u32>,     // cones, spheres per cone
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var opacity_mips: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> directions: array<vec4<f32>>;  // xyz axis
@group(0) @binding(4) var<storage, read> spheres: array<vec4<f32>>;     // centre (mm), LOD
@group(0) @binding(5) var out_ambient: texture_storage_3d<r32float, write>;

// Mean opacity at `uvw` over a texel of LOD `lod`: linear within the two nearest levels
// (each picked exactly), blended here.
fn occlusion(uvw: vec3<f32>, lod: f32) -> f32 {
    let l0 = floor(lod);
    let a = textureSampleLevel(opacity_mips, linear_clamp, uvw, l0).r;
    let f = lod - l0;
    if f == 0.0 {
        return a;
    }
    let l1 = min(l0 + 1.0, f32(p.dims.w - 1u));
    let b = textureSampleLevel(opacity_mips, linear_clamp, uvw, l1).r;
    return a + (b - a) * f;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if any(gid >= p.dims.xyz) {
        return;
    }
    let centre = (vec3<f32>(gid) + 0.5) / vec3<f32>(p.dims.xyz);
    var total = 0.0;
    for (var c = 0u; c < p.counts.x; c = c + 1u) {
        let axis = directions[c].xyz * p.mm_to_uvw.xyz;
        var visible = 1.0;
        for (var k = 0u; k < p.counts.y; k = k + 1u) {
            let s = spheres[k];
            let uvw = centre + axis * s.x;
            if any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)) {
                continue;
            }
            visible = visible * (1.0 - occlusion(uvw, s.y));
        }
        total = total + visible;
    }
    textureStore(out_ambient, gid, vec4<f32>(total / f32(p.counts.x), 0.0, 0.0, 1.0));
}
