//!fragment: no shader of its own; validated as part of the shaders that include it.
// The uniforms of CAO's step V (cao_lao.wgsl over bricks; a frame's cao_gather.wgsl and
// cao_listed.wgsl over its voxel list). Mirrors `LaoParams` in src/ao/cao/mod.rs.
struct Params {
    dims: vec4<u32>,       // x, y, z, unused
    chunk: vec4<u32>,      // first brick (or group of 512 list entries), count, workgroups per row, unused
    mm_to_uvw: vec4<f32>,  // 1 / extent in mm per axis
    counts: vec4<u32>,     // rays K, samples M, entries of the voxel list, unused
    grid: vec4<u32>,       // ray cells per axis, skipping (0/1)
    readable: vec4<f32>,   // voxel readability (readable.wgsl): LUT index scale, offset, last, on
}
