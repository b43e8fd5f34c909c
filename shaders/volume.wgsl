// The volume reader: how every stage reads the volume. Its bind group is group 3 in every
// shader that includes it (texels::reader on the Rust side; CPU twin: sample::VolumeSampler):
// the texel texture, its sampler, the value map and the transfer function's table. A
// stage binds the density (the ray caster, LAO, CAO's clip and readable test, gradient,
// box statistics, ambient maps) or the f16 copy of it (light) with the map that goes
// with it, and the table baked for its own step. A segmentation beside the density
// (texels::segments) is bindings 4–6, read only where a pipeline sets SEGMENTS.

// Mirrors texels::gpu_data::VolumeMap.
struct VolumeMap {
    lut: vec4<f32>,    // table index t = texel · x + y, clamped to [0, z] (the last entry)
    value: vec4<f32>,  // the data's value = texel · x + y (box statistics of the density)
}

@group(3) @binding(0) var volume: texture_3d<f32>;
@group(3) @binding(1) var volume_sampler: sampler;
@group(3) @binding(2) var<uniform> volume_map: VolumeMap;
@group(3) @binding(3) var<storage, read> volume_lut: array<vec4<f32>>;

// Whether a segmentation is read (texels::segments; a pipeline variant). Off, the
// functions below read the density alone, as without one.
override SEGMENTS: bool = false;
// Whether a segment's colour tints (0) or replaces (1) the transfer function's in every
// class, or each class says (2): texels::segments::SegmentTexels::modes.
override SEGMENT_MODES: u32 = 2u;
// Per voxel: the class colour × its opacity weight, and the weight (filtered).
@group(3) @binding(4) var segment_look: texture_3d<f32>;
// Per voxel: its class (a combination of segments), read nearest.
@group(3) @binding(5) var segment_classes: texture_3d<u32>;
// Per class: the clip shapes that carve it (bit s); y, z, w unused
// (texels::segments::ClassLook::gpu).
@group(3) @binding(6) var<storage, read> segment_table: array<vec4<u32>>;
// Per voxel: the weight's differences one voxel either side, w(x + 1) − w(x − 1) per
// axis (snorm, filtered): its gradient wherever it is sampled, in one fetch; and in w
// whether its colour replaces the transfer function's, × the weight.
@group(3) @binding(7) var segment_gradient: texture_3d<f32>;

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

// The segmentation's look at `uvw`: colour × weight and weight, trilinear (1 without one).
fn segment_look_at(uvw: vec3<f32>) -> vec4<f32> {
    if SEGMENTS {
        return textureSampleLevel(segment_look, volume_sampler, uvw, 0.0);
    }
    return vec4<f32>(1.0);
}

// The weight's differences one voxel either side at `uvw` (0 without a segmentation).
fn segment_gradient_at(uvw: vec3<f32>) -> vec3<f32> {
    if SEGMENTS {
        return textureSampleLevel(segment_gradient, volume_sampler, uvw, 0.0).xyz;
    }
    return vec3<f32>(0.0);
}

// The segmentation's opacity weight of voxel `k` (1 without one).
fn segment_weight_of_voxel(k: vec3<i32>) -> f32 {
    if SEGMENTS {
        return textureLoad(segment_look, k, 0).a;
    }
    return 1.0;
}

// The class of the voxel nearest to `uvw` (0 without a segmentation).
fn segment_class_at(uvw: vec3<f32>) -> u32 {
    if SEGMENTS {
        let d = textureDimensions(segment_classes);
        let k = min(vec3<u32>(max(uvw, vec3<f32>(0.0)) * vec3<f32>(d)), d - vec3<u32>(1u));
        return textureLoad(segment_classes, k, 0).r;
    }
    return 0u;
}

// The clip shapes (bit s) that carve the voxel nearest to `uvw`: every one without a
// segmentation.
fn carved_by_at(uvw: vec3<f32>) -> u32 {
    if SEGMENTS {
        return segment_table[segment_class_at(uvw)].x;
    }
    return 0xffffffffu;
}

// The same for voxel `k`.
fn carved_by_voxel(k: vec3<i32>) -> u32 {
    if SEGMENTS {
        return segment_table[textureLoad(segment_classes, k, 0).r].x;
    }
    return 0xffffffffu;
}

// The colour and opacity at `uvw` of texel value `value` (value_at(uvw)): the transfer
// function's, with a segmentation's weight on the opacity and its colour tinting
// (multiplying) or replacing the transfer function's.
fn classify_at(uvw: vec3<f32>, value: f32) -> vec4<f32> {
    let tf = classify(value);
    if !SEGMENTS {
        return tf;
    }
    let look = segment_look_at(uvw);
    return vec4<f32>(segment_colour(uvw, tf.rgb, look), tf.a * look.a);
}

// The colour at `uvw` of a sample whose transfer-function colour is `rgb` and whose
// segmentation look is `look` (segment_look_at(uvw)): classify_at's colour, for a caller
// that weighed the opacity first and colours only samples that show.
fn segment_colour(uvw: vec3<f32>, rgb: vec3<f32>, look: vec4<f32>) -> vec3<f32> {
    if !SEGMENTS || look.a <= 0.0 {
        return rgb;
    }
    let c = look.rgb / look.a;
    var replace = f32(SEGMENT_MODES);
    if SEGMENT_MODES == 2u {
        // Filtered as the colour is, so a tinted class meets a replacing one smoothly.
        let r = textureSampleLevel(segment_gradient, volume_sampler, uvw, 0.0).w;
        replace = clamp(r / look.a, 0.0, 1.0);
    }
    return mix(rgb * c, c, replace);
}

// The opacity at texture coordinates `uvw` (inside the box).
fn opacity_at(uvw: vec3<f32>) -> f32 {
    return opacity(value_at(uvw)) * segment_look_at(uvw).a;
}

// The opacity of voxel `k`, unfiltered.
fn opacity_of_voxel(k: vec3<i32>) -> f32 {
    return opacity(value_of_voxel(k)) * segment_weight_of_voxel(k);
}

// The data's value (the volume's own units) at texel value `value`.
fn data_value(value: f32) -> f32 {
    return value * volume_map.value.x + volume_map.value.y;
}
