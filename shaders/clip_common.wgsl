// Shadow-test clipping (CAO paper §3.2, §3.6) against up to 8 clip meshes, each seen by
// its own orthographic clipping camera. CPU twin: src/clip/cpu.rs (`ClipMapsCpu`).
//
// Per shape, 2 RGBA layers of `clip_maps` (from clip_maps.wgsl), one load per test:
//   base:      (Z_front1, Z_back1, Z_front2, Z_back2)   (two depth-peeling layers)
//   base + 1:  the same dilated (carve) or contracted (probe) by Algorithm 1.
// Empty pixels hold +3 (front) / −3 (back) so they are never inside.

struct ClipShape {
    volume_to_map: mat4x4<f32>, // volume-centred mm → (pixel x, pixel y, depth)
    info: vec4<u32>,            // mode (0 carve, 1 probe), first RGBA layer, resolution, unused
}

struct Clip {
    counts: vec4<u32>,          // shapes, probing shapes, unused, unused
    shapes: array<ClipShape, 8>,
}

@group(1) @binding(0) var<uniform> clip: Clip;

// The number of shapes when a pipeline is built for it (the ray caster's variants,
// render::Variant): the loops over the shapes then have a constant bound, which a CPU
// driver unrolls into loads of one shape's uniforms instead of per-lane gathers
// (lavapipe: half the cost of a clip test per sample). 0: `clip.counts.x`, any number.
override CLIP_SHAPES: u32 = 0u;

fn clip_shapes() -> u32 {
    if CLIP_SHAPES != 0u {
        return CLIP_SHAPES;
    }
    return clip.counts.x;
}
@group(1) @binding(1) var clip_maps: texture_2d_array<f32>;

struct ClipTest {
    inside: bool,   // inside the mesh
    near: bool,     // carve: inside the dilation; probe: inside the contraction
}

fn clip_in_interval(xy: vec2<i32>, layer: u32, z: f32, strict: bool) -> bool {
    // (front1, back1, front2, back2)
    let m = textureLoad(clip_maps, xy, layer, 0);
    if strict {
        return (m.x < z && z < m.y) || (m.z < z && z < m.w);
    }
    return (m.x <= z && z <= m.y) || (m.z <= z && z <= m.w);
}

fn clip_test(s: u32, pos: vec3<f32>) -> ClipTest {
    let shape = clip.shapes[s];
    let c = shape.volume_to_map * vec4<f32>(pos, 1.0);
    let res = f32(shape.info.z);
    var t = ClipTest(false, false);
    if !(c.x >= 0.0 && c.y >= 0.0 && c.x < res && c.y < res) {
        return t;
    }
    let xy = vec2<i32>(floor(c.xy));
    t.inside = clip_in_interval(xy, shape.info.y, c.z, false);
    t.near = clip_in_interval(xy, shape.info.y + 1u, c.z, true);
    return t;
}

// (visible, affected): visible = outside every carving mesh and, if any mesh probes,
// inside one of them; affected = inside a carving mesh's dilation, or (with probes)
// inside no probing mesh's contraction — the voxel's LAO neighbourhood may be clipped.
fn clip_classify(pos: vec3<f32>) -> vec2<bool> {
    var carved = false;
    var probed = false;
    var near_carve = false;
    var deep_probe = false;
    for (var s = 0u; s < clip_shapes(); s = s + 1u) {
        let t = clip_test(s, pos);
        if clip.shapes[s].info.x == 0u {
            carved = carved || t.inside;
            near_carve = near_carve || t.near;
        } else {
            probed = probed || t.inside;
            deep_probe = deep_probe || t.near;
        }
    }
    let probes = clip.counts.y > 0u;
    let visible = !carved && (!probes || probed);
    let affected = near_carve || (probes && !deep_probe);
    return vec2<bool>(visible, affected);
}

fn clip_visible(pos: vec3<f32>) -> bool {
    return clip_classify(pos).x;
}

// Whether `pos` in a voxel that the shapes of `carve` (bit s) cut is visible: outside
// every carving shape among them and, if some of them probe, inside one of those (a
// segmentation's segment-aware carving, texels::segments). `carve` = every bit:
// clip_visible.
fn clip_visible_for(pos: vec3<f32>, carve: u32) -> bool {
    var carved = false;
    var probes = false;
    var probed = false;
    for (var s = 0u; s < clip_shapes(); s = s + 1u) {
        if ((carve >> s) & 1u) == 0u {
            continue;
        }
        let inside = clip_test(s, pos).inside;
        if clip.shapes[s].info.x == 0u {
            carved = carved || inside;
        } else {
            probes = true;
            probed = probed || inside;
        }
    }
    return !carved && (!probes || probed);
}
