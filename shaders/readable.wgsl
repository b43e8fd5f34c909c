//!fragment: no shader of its own; validated as part of the shaders that include it.
// Per-voxel readability for sparse AO (ao::sparse).

// Whether the ray caster can read voxel v's AO: the point that weights v lies within one
// voxel of it and within render::AO_READ_REACH voxels of a sample with opacity, which
// reads the 2³ texels of its cell, so v is readable if the texels within 1 + reach of it
// (7³) may give non-zero opacity under the rendering LUT (`readable_prefix[i]`: entries
// before i with opacity > 0). The index margin is one entry wider than the CPU's test
// (ao::sparse::Bricks::readable_mask), so the GPU computes every voxel the twin does.
// The including shader includes volume.wgsl and declares `readable_prefix:
// array<u32>`, `p.dims: vec4<u32>` and `p.readable: vec4<f32>` (LUT index =
// norm · x + y, last entry z; w: 0 off, else 1 + the texels taken below v on each
// axis, 1 + reach, as many above (at least 1) — tests take fewer to show that exactness
// rests on it).
fn voxel_readable(v: vec3<u32>) -> bool {
    if !SKIPPING || p.readable.w == 0.0 {
        return true;
    }
    let top = vec3<i32>(p.dims.xyz) - vec3<i32>(1);
    let below = -i32(p.readable.w - 1.0);
    let above = max(-below, 1);
    var lo = 3.0e38;
    var hi = -3.0e38;
    for (var dz = below; dz <= above; dz = dz + 1) {
        for (var dy = below; dy <= above; dy = dy + 1) {
            for (var dx = below; dx <= above; dx = dx + 1) {
                let t = clamp(vec3<i32>(v) + vec3<i32>(dx, dy, dz), vec3<i32>(0), top);
                let n = value_of_voxel(t);
                lo = min(lo, n);
                hi = max(hi, n);
            }
        }
    }
    let a = lo * p.readable.x + p.readable.y;
    let b = hi * p.readable.x + p.readable.y;
    let last = p.readable.z;
    let first = u32(clamp(floor(min(a, b)) - 2.0, 0.0, last));
    let end = u32(clamp(floor(max(a, b)) + 3.0, 0.0, last));
    return readable_prefix[end + 1u] > readable_prefix[first];
}
