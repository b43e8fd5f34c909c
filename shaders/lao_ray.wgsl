//!fragment: no shader of its own; validated as part of the shaders that include it.
// One LAO ray (Eq. 2): Σ_{m=1..M} Π_{i<m} (1 − a_i), sample i lying i steps from the
// voxel centre. Shared by lao.wgsl and cao_lao.wgsl; CPU twin: ao::lao::ray_sum.
//
// With skipping (ao::sparse), runs of samples known to have opacity exactly 0 (outside
// the volume, or inside a cell of RAY_CELL³ voxels the LAO LUT leaves empty) are not
// fetched: their factor is 1, and the transmittance is still added once per sample, in order, so the sum is
// the dense one bit for bit. Rays from readable voxels (RAY_SKIPPING off) skip only the
// samples past the box (boxed_ray). The including shader declares
// `opacity_in_box(uvw) -> f32` (a sample's opacity, uvw inside the box),
// `p.dims: vec4<u32>`, `p.grid: vec4<u32>` (cells per axis, skipping 0/1) and
// `occupied: array<u32>` (1 per cell where a sample may be opaque).

// Whether this pipeline skips at all: `false` in the dense pipelines (`--no-skipping`),
// which a CPU driver then compiles without the skipping code (ao::sparse::DENSE).
override SKIPPING: bool = true;
// Whether rays step over empty cells: `false` for rays from readable voxels only (LAO
// for rendering, CAO's V_PAO and frames: ao::sparse::READABLE), which start at
// surfaces and cross occupied cells, where the per-sample check costs more than it saves
// (they still stop fetching at the box: boxed_ray).
override RAY_SKIPPING: bool = true;
// Edge of the cells rays step over, in voxels (ao::sparse::RAY_CELL).
const RAY_CELL: u32 = 4u;

fn in_box(uvw: vec3<f32>) -> bool {
    return !(any(uvw < vec3<f32>(0.0)) || any(uvw > vec3<f32>(1.0)));
}

// A sample's opacity: 0 outside the volume.
fn ray_opacity(uvw: vec3<f32>) -> f32 {
    if !in_box(uvw) {
        return 0.0;
    }
    return opacity_in_box(uvw);
}

// The ray parameter (in samples) at which `centre + step · t` leaves the box [lo, hi].
fn box_exit(centre: vec3<f32>, step: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> f32 {
    var exit = 3.0e38;
    for (var a = 0u; a < 3u; a = a + 1u) {
        if step[a] > 0.0 {
            exit = min(exit, (hi[a] - centre[a]) / step[a]);
        } else if step[a] < 0.0 {
            exit = min(exit, (lo[a] - centre[a]) / step[a]);
        }
    }
    return exit;
}

// Samples from m on (all before the last) whose opacity is exactly 0; 0: fetch m.
fn empty_run(centre: vec3<f32>, step: vec3<f32>, m: u32, samples: u32) -> u32 {
    let uvw = centre + step * f32(m);
    if !in_box(uvw) {
        return samples - m;  // a straight ray that left the box never comes back
    }
    let size = vec3<f32>(p.dims.xyz);
    let b = min(vec3<u32>(floor(uvw * size / f32(RAY_CELL))), p.grid.xyz - vec3<u32>(1u));
    if occupied[b.x + p.grid.x * (b.y + p.grid.y * b.z)] != 0u {
        return 0u;
    }
    let lo = vec3<f32>(b * RAY_CELL) / size;
    let hi = vec3<f32>((b + vec3<u32>(1u)) * RAY_CELL) / size;
    let exit = box_exit(centre, step, lo, hi);
    // Samples m ..= floor(exit) lie in the box; what they read reaches half a voxel
    // past it, far more than rounding.
    let inside = min(u32(max(floor(exit), f32(m))), samples - 1u);
    return inside - m + 1u;
}

fn lao_ray(centre: vec3<f32>, step: vec3<f32>, samples: u32) -> f32 {
    if !SKIPPING || p.grid.w == 0u {
        return dense_ray(centre, step, samples);
    }
    if !RAY_SKIPPING {
        return boxed_ray(centre, step, samples);
    }
    var transmittance = 1.0;
    var sum = transmittance;  // sample 1
    var m = 1u;
    loop {
        if m >= samples {
            break;
        }
        if p.grid.w != 0u {
            let run = empty_run(centre, step, m, samples);
            if run > 0u {
                // Samples m .. m + run − 1 leave the transmittance as it is.
                for (var j = 0u; j < run; j = j + 1u) {
                    sum = sum + transmittance;
                }
                m = m + run;
                continue;
            }
        }
        transmittance = transmittance * (1.0 - ray_opacity(centre + step * f32(m)));
        m = m + 1u;
        sum = sum + transmittance;
    }
    return sum;
}

// The samples 1 ..= n that lie in the box (a prefix: the ray is straight and the box
// convex, and `centre + step * f32(m)` is monotonic in m per axis): estimated from the
// box exit, then settled with the per-sample test itself, so it is the same n.
fn samples_in_box(centre: vec3<f32>, step: vec3<f32>, samples: u32) -> u32 {
    let exit = min(box_exit(centre, step, vec3<f32>(0.0), vec3<f32>(1.0)), f32(samples));
    var n = min(u32(max(floor(exit), 0.0)), samples - 1u);
    loop {
        if n + 1u >= samples || !in_box(centre + step * f32(n + 1u)) {
            break;
        }
        n = n + 1u;
    }
    loop {
        if n == 0u || in_box(centre + step * f32(n)) {
            break;
        }
        n = n - 1u;
    }
    return n;
}

// The dense sum with the samples past the box exit not fetched (their opacity is 0, so
// the transmittance stays as it is): for rays from readable voxels.
fn boxed_ray(centre: vec3<f32>, step: vec3<f32>, samples: u32) -> f32 {
    let n = samples_in_box(centre, step, samples);
    var transmittance = 1.0;
    var sum = 0.0;
    for (var m = 1u; m <= n; m = m + 1u) {
        sum = sum + transmittance;
        transmittance = transmittance * (1.0 - opacity_in_box(centre + step * f32(m)));
    }
    for (var m = n + 1u; m <= samples; m = m + 1u) {
        sum = sum + transmittance;
    }
    return sum;
}

// The same sum, every sample fetched (skipping off): the plain loop.
fn dense_ray(centre: vec3<f32>, step: vec3<f32>, samples: u32) -> f32 {
    var transmittance = 1.0;
    var sum = 0.0;
    for (var m = 1u; m <= samples; m = m + 1u) {
        sum = sum + transmittance;
        if m < samples {
            transmittance = transmittance * (1.0 - ray_opacity(centre + step * f32(m)));
        }
    }
    return sum;
}
