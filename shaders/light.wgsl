// Light volume for volumetric shadows from a directional light: the transmittance
// T(x) = Π_i (1 − α(x + L · t_i)) from every voxel centre towards the light, one
// invocation per voxel of a z-slab. CPU twin: src/render/shadow.rs (`light_voxel`).
//
// Samples t_i = (i + s) · h, i = 0, 1, … while inside the box, s = start.x (1.5: the
// voxel's own opacity does not dim its light), the same for every voxel (a per-voxel
// jittered start made T differ from voxel to voxel by up to one sample of the surface
// the voxel lies in: a speckle in the light itself). α is the transfer function's
// opacity corrected for the step h. The ray caster samples T filtered
// (render::shadow::filter_light).
// A ray stops once T < 1e-4 (nothing further can be seen). Clipped space (clip shapes,
// clip_common.wgsl) is empty: light passes through what the user carved away.
//!include clip_common.wgsl
//!include volume.wgsl

struct Params {
    dims: vec4<u32>,      // x, y, z, first z of this slab
    work: vec4<u32>,      // voxels in this slab, invocations per row, max steps
    step_uvw: vec4<f32>,  // direction to the light × h, in texture coordinates
    start: vec4<f32>,     // x: first sample (steps from the centre); yzw unused
    half: vec4<f32>,      // half the volume's extent (mm)
}

// The density's f16 copy with the light's table: volume.wgsl (group 3).
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> transmittance: array<f32>;

const T_STOP: f32 = 1e-4;

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
        let uvw = centre + p.step_uvw.xyz * (f32(i) + p.start.x);
        if any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)) || t < T_STOP {
            break;
        }
        // Clipped space lets light through: the shapes that cut the sample's segment.
        let pos = (uvw - vec3<f32>(0.5)) * 2.0 * p.half.xyz;
        var open = clip.counts.x == 0u;
        if !open && SEGMENTS {
            open = clip_visible_for(pos, carved_by_at(uvw));
        } else if !open {
            open = clip_visible(pos);
        }
        if open {
            t = t * (1.0 - opacity_at(uvw));
        }
    }
    transmittance[index] = t;
}
