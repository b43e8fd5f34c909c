// Light volume for volumetric shadows from a directional light: the transmittance
// T(x) = Π_i (1 − α(x + L · t_i)) from every voxel centre towards the light, one
// invocation per voxel of a z-slab. CPU twin: src/render/shadow.rs (`light_voxel`).
//
// Samples t_i = (i + s) · h, i = 0, 1, … while inside the box, s = lut_map.w (1.5: the
// voxel's own opacity does not dim its light), the same for every voxel (a per-voxel
// jittered start made T differ from voxel to voxel by up to one sample of the surface
// the voxel lies in: a speckle in the light itself). α is the transfer function's
// opacity corrected for the step h. The ray caster samples T filtered
// (render::shadow::filter_light).
// A ray stops once T < 1e-4 (nothing further can be seen). Clipped space (clip shapes,
// clip_common.wgsl) is empty: light passes through what the user carved away.
//!include clip_common.wgsl

struct Params {
    dims: vec4<u32>,      // x, y, z, first z of this slab
    work: vec4<u32>,      // voxels in this slab, invocations per row, max steps
    step_uvw: vec4<f32>,  // direction to the light × h, in texture coordinates
    lut_map: vec4<f32>,   // a, b, entries - 1, first sample (steps from the centre)
    half: vec4<f32>,      // half the volume's extent (mm)
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> lut_alpha: array<f32>;
@group(0) @binding(4) var<storage, read_write> transmittance: array<f32>;

const T_STOP: f32 = 1e-4;

fn alpha_at(uvw: vec3<f32>) -> f32 {
    let norm = textureSampleLevel(volume, linear_clamp, uvw, 0.0).r;
    let t = clamp(norm * p.lut_map.x + p.lut_map.y, 0.0, p.lut_map.z);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(p.lut_map.z));
    return mix(lut_alpha[i0], lut_alpha[i1], t - floor(t));
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = gid.x + gid.y * p.work.y;
    if index >= p.work.x {
        return;
    }
    let nx = p.dims.x;
    let ny = p.dims.y;
    let voxel = vec3<u32>(index % nx, (index / nx) % ny, p.dims.w + index / (nx * ny));
    let centre = (vec3<f32>(voxel) + 0.5) / vec3<f32>(p.dims.xyz);
    var t = 1.0;
    for (var i = 0u; i < p.work.z; i = i + 1u) {
        let uvw = centre + p.step_uvw.xyz * (f32(i) + p.lut_map.w);
        if any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)) || t < T_STOP {
            break;
        }
        if clip.counts.x == 0u || clip_visible((uvw - vec3<f32>(0.5)) * 2.0 * p.half.xyz) {
            t = t * (1.0 - alpha_at(uvw));
        }
    }
    transmittance[index] = t;
}
