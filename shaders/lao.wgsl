// Local Ambient Occlusion (Hernell et al.; CAO paper Eq. 2–3), one invocation per voxel
// of a z-slab. CPU twin: src/ao/lao.rs (`lao_voxel`); keep the two in step.
//
//   A_k(x) = 1/M · Σ_{m=1..M} Π_{i=1..m-1} (1 − a_i)        (Eq. 2)
//   A(x)   = 1/K · Σ_k w_k A_k(x)                             (Eq. 3)
//
// Sample i lies i mm from the voxel centre along ray k (spacing-aware); samples outside
// the volume are empty. a_i comes from the transfer function's opacity, corrected for a
// 1 mm step.

struct Params {
    dims: vec4<u32>,       // x, y, z, first z of this slab
    mm_to_uvw: vec4<f32>,  // 1 / extent in mm per axis
    lut_map: vec4<f32>,    // a, b, entries - 1
    counts: vec4<u32>,     // rays K, samples M, voxels in this slab, invocations per row
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> lut_alpha: array<f32>;
@group(0) @binding(4) var<storage, read> rays: array<vec4<f32>>;  // xyz direction, w weight
@group(0) @binding(5) var<storage, read_write> v_pao: array<f32>;

fn alpha_at(uvw: vec3<f32>) -> f32 {
    if any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)) {
        return 0.0;
    }
    let norm = textureSampleLevel(volume, linear_clamp, uvw, 0.0).r;
    let t = clamp(norm * p.lut_map.x + p.lut_map.y, 0.0, p.lut_map.z);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(p.lut_map.z));
    return mix(lut_alpha[i0], lut_alpha[i1], t - floor(t));
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let index = gid.x + gid.y * p.counts.w;
    if index >= p.counts.z {
        return;
    }
    let nx = p.dims.x;
    let ny = p.dims.y;
    let voxel = vec3<u32>(index % nx, (index / nx) % ny, p.dims.w + index / (nx * ny));
    let centre = (vec3<f32>(voxel) + 0.5) / vec3<f32>(p.dims.xyz);
    let samples = p.counts.y;
    var total = 0.0;
    for (var k = 0u; k < p.counts.x; k = k + 1u) {
        let ray = rays[k];
        let step = ray.xyz * p.mm_to_uvw.xyz;
        var transmittance = 1.0;
        var sum = 0.0;
        for (var m = 1u; m <= samples; m = m + 1u) {
            sum = sum + transmittance;
            if m < samples {
                transmittance = transmittance * (1.0 - alpha_at(centre + step * f32(m)));
            }
        }
        total = total + ray.w * sum / f32(samples);
    }
    v_pao[index] = total / f32(p.counts.x);
}
