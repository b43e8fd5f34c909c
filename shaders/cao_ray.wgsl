//!fragment: no shader of its own; validated as part of the shaders that include it.
// CAO's LAO of one voxel (Eq. 2–3) on the clipped opacity volume V_o: the one function
// every CAO ray cast runs (cao_lao.wgsl over bricks, cao_listed.wgsl over a frame's
// listed voxels), which is what makes CAO and LAO every frame agree bit for bit.
// CPU twin: src/ao/cao/cpu.rs (`lao_on_opacity_cpu`). The including shader declares
// `v_o: texture_3d<f32>`, `linear_clamp: sampler`, `rays: array<vec4<f32>>` (xyz
// direction, w weight), `occupied: array<u32>` and `p` with `dims`, `mm_to_uvw`,
// `counts` (rays K, samples M) and `grid` as in cao_lao.wgsl.
//!include lao_ray.wgsl

fn opacity_in_box(uvw: vec3<f32>) -> f32 {
    return textureSampleLevel(v_o, linear_clamp, uvw, 0.0).r;
}

fn lao(v: vec3<u32>) -> f32 {
    let centre = (vec3<f32>(v) + 0.5) / vec3<f32>(p.dims.xyz);
    let samples = p.counts.y;
    var total = 0.0;
    for (var k = 0u; k < p.counts.x; k = k + 1u) {
        let ray = rays[k];
        let step = ray.xyz * p.mm_to_uvw.xyz;
        total = total + ray.w * lao_ray(centre, step, samples) / f32(samples);
    }
    return total / f32(p.counts.x);
}
