// CAO step V (Titov et al. §3.5): the ambient factor V_AO per voxel from the mask:
// clipped (0) → 1, unaffected (1) → copy V_PAO, affected (½) → a full LAO ray cast
// (Eq. 2–3) on the clipped opacity volume V_o. With `full` set every unclipped voxel is
// ray cast: the "LAO every frame" baseline, and how V_PAO itself is made (no clipping).
// Both paths run the very same `lao` function, which is what makes CAO bit-exact.
// CPU twin: src/ao/cao.rs (`lao_on_opacity_cpu`).

struct Params {
    dims: vec4<u32>,       // x, y, z, first z of this slab
    mm_to_uvw: vec4<f32>,  // 1 / extent in mm per axis
    counts: vec4<u32>,     // rays K, samples M, full (0/1), unused
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var v_o: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> rays: array<vec4<f32>>;  // xyz direction, w weight
@group(0) @binding(4) var v_m: texture_3d<f32>;
@group(0) @binding(5) var v_pao: texture_3d<f32>;
@group(0) @binding(6) var v_ao: texture_storage_3d<r32float, write>;

fn opacity_at(uvw: vec3<f32>) -> f32 {
    if any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)) {
        return 0.0;
    }
    return textureSampleLevel(v_o, linear_clamp, uvw, 0.0).r;
}

fn lao(v: vec3<u32>) -> f32 {
    let centre = (vec3<f32>(v) + 0.5) / vec3<f32>(p.dims.xyz);
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
                transmittance = transmittance * (1.0 - opacity_at(centre + step * f32(m)));
            }
        }
        total = total + ray.w * sum / f32(samples);
    }
    return total / f32(p.counts.x);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = vec3<u32>(gid.x, gid.y, gid.z + p.dims.w);
    if any(v >= p.dims.xyz) {
        return;
    }
    let mask = textureLoad(v_m, v, 0).r;
    var a = 1.0;
    if mask == 1.0 && p.counts.z == 0u {
        a = textureLoad(v_pao, v, 0).r;
    } else if mask > 0.0 {
        a = lao(v);
    }
    textureStore(v_ao, vec3<i32>(v), vec4<f32>(a, 0.0, 0.0, 1.0));
}
