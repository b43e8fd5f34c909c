// The volume reader: how every stage reads the volume. Its bind group is group 3 in every
// shader that includes it (texels::reader on the Rust side; CPU twin: sample::VolumeSampler):
// the texel texture, its sampler, the value map and the transfer function's table. A
// stage binds the density (the ray caster, LAO, CAO's clip and readable test, gradient,
// box statistics, ambient maps) or the f16 copy of it (light) with the map that goes
// with it, and the table baked for its own step.

// Mirrors texels::gpu_data::VolumeMap.
struct VolumeMap {
    lut: vec4<f32>,    // table index t = texel · x + y, clamped to [0, z] (the last entry)
    value: vec4<f32>,  // the data's value = texel · x + y (box statistics of the density)
}

@group(3) @binding(0) var volume: texture_3d<f32>;
@group(3) @binding(1) var volume_sampler: sampler;
@group(3) @binding(2) var<uniform> volume_map: VolumeMap;
@group(3) @binding(3) var<storage, read> volume_lut: array<vec4<f32>>;

// The texel value at texture coordinates `uvw`, trilinear, clamped at the edges.
fn value_at(uvw: vec3<f32>) -> f32 {
    return textureSampleLevel(volume, volume_sampler, uvw, 0.0).r;
}

// The texel value of voxel `k`, unfiltered; `k` inside the volume.
fn value_of_voxel(k: vec3<i32>) -> f32 {
    return textureLoad(volume, k, 0).r;
}

// The volume's size in voxels.
fn volume_dims() -> vec3<u32> {
    return textureDimensions(volume);
}

// The fractional table index of texel value `value`, clamped to the table.
fn lut_index(value: f32) -> f32 {
    return clamp(value * volume_map.lut.x + volume_map.lut.y, 0.0, volume_map.lut.z);
}

// The transfer function's straight colour and opacity at texel value `value`: linear
// interpolation between the two nearest entries.
fn classify(value: f32) -> vec4<f32> {
    let t = lut_index(value);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(volume_map.lut.z));
    return mix(volume_lut[i0], volume_lut[i1], t - floor(t));
}

// The transfer function's opacity at texel value `value` (classify's alpha).
fn opacity(value: f32) -> f32 {
    let t = lut_index(value);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(volume_map.lut.z));
    return mix(volume_lut[i0].a, volume_lut[i1].a, t - floor(t));
}

// The opacity at texture coordinates `uvw` (inside the box).
fn opacity_at(uvw: vec3<f32>) -> f32 {
    return opacity(value_at(uvw));
}

// The data's value (the volume's own units) at texel value `value`.
fn data_value(value: f32) -> f32 {
    return value * volume_map.value.x + volume_map.value.y;
}
