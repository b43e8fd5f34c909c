//!fragment: no shader of its own; validated as part of the shaders that include it.
// Per-voxel readability for sparse AO (ao::sparse).

// Whether the ray caster can read voxel v's AO: a sample that weights v lies within one
// voxel of it and reads only the 3³ texels around it, so v is readable if their range
// may give non-zero opacity under the rendering LUT (`readable_prefix[i]`: entries
// before i with opacity > 0). The index margin is one entry wider than the CPU's test
// (ao::sparse::Bricks::readable_mask), so the GPU computes every voxel the twin does.
// The including shader declares `volume: texture_3d<f32>`, `readable_prefix:
// array<u32>`, `p.dims: vec4<u32>` and `p.readable: vec4<f32>` (LUT index =
// norm · x + y, last entry z; w: 0 off, else 1 + the texels taken below v on each
// axis, which is 1 — tests take 0 to show that exactness rests on it).
fn voxel_readable(v: vec3<u32>) -> bool {
    if !SKIPPING || p.readable.w == 0.0 {
        return true;
    }
    let top = vec3<i32>(p.dims.xyz) - vec3<i32>(1);
    let below = -i32(p.readable.w - 1.0);
    var lo = 3.0e38;
    var hi = -3.0e38;
    for (var dz = below; dz <= 1; dz = dz + 1) {
        for (var dy = below; dy <= 1; dy = dy + 1) {
            for (var dx = below; dx <= 1; dx = dx + 1) {
                let t = clamp(vec3<i32>(v) + vec3<i32>(dx, dy, dz), vec3<i32>(0), top);
                let n = textureLoad(volume, t, 0).r;
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
