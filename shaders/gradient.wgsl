// The gradient volume (render::gradient): per voxel k, the central differences
// v(k + e) − v(k − e) of the density along x, y and z, each index clamped to the volume
// as the sampler clamps it, divided by p.scale.x, with a border of one voxel on every
// side (k = −1 … n). f(x + e) − f(x − e) of the trilinear field f is the trilinear
// interpolation of these differences, so the ray caster reads at (uvw·n + 1)/(n + 2)
// with one fetch what its six-fetch central differences give, rounded to f16.
// CPU twin: render::gradient::central_differences.
//!include common.wgsl
//!include volume.wgsl

struct Params {
    dims: vec4<u32>,   // the volume's dims (the output has two more per axis)
    scale: vec4<f32>,  // x: 1 / M (render::gradient::GradientVolume::scale)
}

// The density: volume.wgsl (group 3), its voxels alone.
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var gradient: texture_storage_3d<rgba16float, write>;

fn texel(k: vec3<i32>) -> f32 {
    let hi = vec3<i32>(p.dims.xyz) - vec3<i32>(1);
    return value_of_voxel(clamp(k, vec3<i32>(0), hi));
}

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if !in_grid(id, p.dims.xyz + vec3<u32>(2u)) {
        return;
    }
    let k = vec3<i32>(id) - vec3<i32>(1);
    let g = vec3<f32>(
        texel(k + vec3<i32>(1, 0, 0)) - texel(k - vec3<i32>(1, 0, 0)),
        texel(k + vec3<i32>(0, 1, 0)) - texel(k - vec3<i32>(0, 1, 0)),
        texel(k + vec3<i32>(0, 0, 1)) - texel(k - vec3<i32>(0, 0, 1)),
    ) * p.scale.x;
    textureStore(gradient, id, vec4<f32>(g, 0.0));
}
