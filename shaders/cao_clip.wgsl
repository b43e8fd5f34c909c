// CAO step IV (Titov et al. §3.5, Algorithm 2): anti-aliased shadow-test clipping of
// the voxels of a brick list (ao::sparse) into the clipped opacity volume V_o, and the
// mask (0 clipped, ½ recompute, 1 copy V_PAO) written straight into V_AO: a copy of
// V_PAO, or the marks RECOMPUTE / CLIPPED that step V resolves (the baseline marks
// every unclipped voxel RECOMPUTE). No mask volume is kept: CAO holds 3 volumes of
// 2 bytes per voxel. One invocation per voxel.
// CPU twin: src/ao/cao.rs (`clip_volume_cpu`); keep the two in step.
//!include clip_common.wgsl
//!include bricks.wgsl
//!include cao_format.wgsl
//!include volume.wgsl

struct Params {
    dims: vec4<u32>,      // x, y, z, unused
    chunk: vec4<u32>,     // first brick, bricks, workgroups per row, unused
    spacing: vec4<f32>,   // mm per voxel, w: N extra MSAA samples
    half: vec4<f32>,      // half the volume's extent (mm)
    mode: vec4<u32>,      // full (0/1), V_PAO marks unreadable voxels (0/1), clipped → 1 (0/1),
                          // per-ray test (0 off, else 1 + balls)
    lao: vec4<f32>,       // LAO rays K, samples M, step (mm), the longest ray step (mm)
    balls: array<vec4<f32>, 8>,  // per carving shape: centre (volume mm), radius (ao::sparse::Bricks::cut_balls)
}

// Marks in V_AO between steps IV and V (an ambient factor is never negative).
const RECOMPUTE: f32 = -1.0;
const CLIPPED: f32 = -2.0;

// The density and the LAO table: volume.wgsl (group 3).
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> msaa: array<vec4<f32>>;  // offsets in voxels
@group(0) @binding(2) var v_o: CaoWrite;
@group(0) @binding(3) var v_ao: CaoWrite;
@group(0) @binding(4) var<storage, read_write> counters: array<atomic<u32>, 4>; // recompute, clipped
@group(0) @binding(5) var<storage, read> bricks: array<u32>;
@group(0) @binding(6) var v_pao: texture_3d<f32>;
@group(0) @binding(7) var<storage, read> rays: array<vec4<f32>>;  // LAO rays: xyz direction, w weight

// TF_o: the transfer function's opacity (for a 1 mm step) of the voxel itself, with a
// segmentation's weight.
fn voxel_opacity(v: vec3<u32>) -> f32 {
    return opacity_of_voxel(vec3<i32>(v));
}

fn position_mm(v: vec3<u32>, offset: vec3<f32>) -> vec3<f32> {
    return (vec3<f32>(v) + 0.5 + offset) * p.spacing.xyz - p.half.xyz;
}

// Whether voxels share their corners' clip tests (below): `false` in the dense pipeline
// (`--no-skipping`, ao::sparse::DENSE_CLIP), which tests the 8 corners of every
// voxel as Algorithm 2 is written. The same classifications either way.
override SHARED_CORNERS: bool = true;
// Whether a voxel is affected when its centre lies in a dilation, as with skipping: the
// reach (ao::cao::reach_mm) runs from the voxel's centre and already covers its cell's
// clip samples and the trilinear stencils. The corners and anti-aliasing samples then
// need only whether they are visible, which reads half the clip maps. `false` in the
// dense pipeline: any of the 9 + N samples in a dilation marks the voxel, as Algorithm 2
// is written (the paper's mask).
override CENTRE_REACH: bool = true;

// The classification (bit 0 visible, bit 1 affected) of the corners of this workgroup's
// voxels: the 9 × 9 × 2 lattice points of one layer of a brick, shared by up to 8 voxels
// each (3.5 clip tests per voxel instead of 9). Lattice point L is voxel L's corner
// (−½, −½, −½): the same position, computed the same way, as every voxel it is a corner
// of would compute it.
var<workgroup> corners: array<u32, 162>;
// Voxels of this workgroup in category b and clipped: one global atomic each per
// workgroup (millions on one counter serialise on a CPU driver).
var<workgroup> affected: atomic<u32>;
var<workgroup> clipped: atomic<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if brick_slot(wid) >= p.chunk.y {
        return;  // the whole workgroup
    }
    // This layer's voxel (0, 0): the lattice's first point.
    let origin = brick_voxel(wid, vec3<u32>(0u)).xyz;
    if SHARED_CORNERS && !SEGMENTS {
        for (var i = lid.x + 8u * lid.y; i < 162u; i = i + 64u) {
            let l = origin + vec3<u32>(i % 9u, (i / 9u) % 9u, i / 81u);
            corners[i] = classify_bits(position_mm(l, vec3<f32>(-0.5)), 0xffffffffu);
        }
    }
    workgroupBarrier();
    classify_voxel(origin + vec3<u32>(lid.x, lid.y, 0u), lid.x + 9u * lid.y, brick_near(wid));
    workgroupBarrier();
    if lid.x == 0u && lid.y == 0u {
        atomicAdd(&counters[0], atomicLoad(&affected));
        atomicAdd(&counters[1], atomicLoad(&clipped));
    }
}

// clip_classify's (visible, affected) as bits 0 and 1; visible alone with CENTRE_REACH.
// With a segmentation a voxel is visible where the shapes that carve its class leave it
// (`carve`: clip_visible_for); affected as without one (any shape's dilation: what a
// shape removes of its neighbours may change its LAO).
fn classify_bits(pos: vec3<f32>, carve: u32) -> u32 {
    if SEGMENTS {
        let visible = clip_visible_for(pos, carve);
        if CENTRE_REACH {
            return u32(visible);
        }
        return u32(visible) | (u32(clip_classify(pos).y) << 1u);
    }
    if CENTRE_REACH {
        return u32(clip_visible(pos));
    }
    let t = clip_classify(pos);
    return u32(t.x) | (u32(t.y) << 1u);
}

// Corner k (bit a of k: +½ on axis a, else −½) of voxel v, whose corner (−½, −½, −½) is
// `corners[c]` when they are shared (never with a segmentation: the voxels sharing a
// corner may be of classes different shapes carve).
fn corner_bits(v: vec3<u32>, c: u32, k: u32, carve: u32) -> u32 {
    if SHARED_CORNERS && !SEGMENTS {
        return corners[c + (k & 1u) + 9u * ((k >> 1u) & 1u) + 81u * ((k >> 2u) & 1u)];
    }
    let offset = vec3<f32>(f32(k & 1u), f32((k >> 1u) & 1u), f32((k >> 2u) & 1u)) - 0.5;
    return classify_bits(position_mm(v, offset), carve);
}

// Step IV for voxel v, whose corner (−½, −½, −½) is `corners[c]` when they are shared.
// `reached`: the brick's list entry carries NEAR, set where a change of opacity can reach
// it (ao::sparse::Bricks::reached; always in the baseline and the paper's mask). Elsewhere
// V_o = α within every LAO ray's reach, so the voxel keeps V_PAO's bits even where a
// shape's dilation reaches it, and a clipped voxel gets 1 here (step V skips the brick).
fn classify_voxel(v: vec3<u32>, c: u32, reached: bool) {
    if any(v >= p.dims.xyz) {
        return;
    }
    var visible = 0u;
    var dilated = 0u;
    // The centre and the 8 corners of the voxel.
    let centre = position_mm(v, vec3<f32>(0.0));
    let carve = carved_by_voxel(vec3<i32>(v));
    var t = clip_classify(centre);
    if SEGMENTS {
        t.x = clip_visible_for(centre, carve);
    }
    visible = visible + u32(t.x);
    dilated = dilated + u32(t.y);
    for (var k = 0u; k < 8u; k = k + 1u) {
        let bits = corner_bits(v, c, k, carve);
        visible = visible + (bits & 1u);
        dilated = dilated + (bits >> 1u);
    }
    let n = u32(p.spacing.w);
    var opacity = 0.0;
    if visible == 9u {
        opacity = voxel_opacity(v);
    } else if visible > 0u {
        for (var k = 0u; k < n; k = k + 1u) {
            let bits = classify_bits(position_mm(v, msaa[k].xyz), carve);
            visible = visible + (bits & 1u);
            dilated = dilated + (bits >> 1u);
        }
        opacity = f32(visible) / f32(n + 9u) * voxel_opacity(v);
    }
    if CENTRE_REACH {
        dilated = u32(t.y);
    }
    var ao = RECOMPUTE;
    // With p.mode.y, V_PAO holds UNREAD (cao_lao.wgsl) where the ray caster cannot read
    // the voxel: V_AO = 1 there, what step V would write, and step V leaves it alone.
    let pao = textureLoad(v_pao, v, 0).r;
    let unread = p.mode.y != 0u && pao > 1.0;
    if dilated == 0u {
        if p.mode.x == 0u || unread {
            ao = min(pao, 1.0);  // unaffected: copy
        }
    } else if visible > 0u {
        atomicAdd(&affected, 1u);
        if unread {
            ao = 1.0;
        } else if !reached || !rays_meet_cut(centre) {
            ao = min(pao, 1.0);
        }
    } else {
        // With p.mode.z step V runs over a list of the voxels to ray cast only
        // (cao_gather.wgsl): V_AO = 1 here, what step V over bricks would write.
        ao = select(CLIPPED, 1.0, p.mode.z != 0u || !reached);
        atomicAdd(&clipped, 1u);
    }
    let at = vec3<i32>(v);
    textureStore(v_o, at, vec4<f32>(opacity, 0.0, 0.0, 1.0));
    textureStore(v_ao, at, vec4<f32>(ao, 0.0, 0.0, 1.0));
}

// Step IV's per-ray test (ao::sparse::Bricks::cut_balls): whether some LAO ray of the
// voxel centred at `x` (mm) may read a texel whose V_o a cut changed, that is, whether
// the segment its fetched samples lie on (1 ..= M − 1 steps from x) meets a carving
// shape's ball. A voxel whose rays all miss reads V_o = α along every ray, as V_PAO's
// ray cast did, and keeps V_PAO's bits. True with the test off (p.mode.w = 0).
fn rays_meet_cut(x: vec3<f32>) -> bool {
    if p.mode.w == 0u {
        return true;
    }
    let balls = p.mode.w - 1u;
    let last = p.lao.y - 1.0;
    if last < 1.0 {
        return false;  // no sample is fetched
    }
    // A ball that holds every ray's first sample (p.lao.w: the longest step, mm) is met;
    // one that none of the samples can reach is not.
    var far = 0u;
    for (var b = 0u; b < balls; b = b + 1u) {
        let d = distance(x, p.balls[b].xyz);
        if d + p.lao.w <= p.balls[b].w {
            return true;
        }
        if d - last * p.lao.w > p.balls[b].w {
            far = far | (1u << b);
        }
    }
    for (var k = 0u; k < u32(p.lao.x); k = k + 1u) {
        let step = rays[k].xyz * p.lao.z;
        let along = max(dot(step, step), 1e-12);
        for (var b = 0u; b < balls; b = b + 1u) {
            if (far & (1u << b)) != 0u {
                continue;
            }
            let ball = p.balls[b];
            let t = clamp(dot(ball.xyz - x, step) / along, 1.0, last);
            let off = x + step * t - ball.xyz;
            if dot(off, off) <= ball.w * ball.w {
                return true;
            }
        }
    }
    return false;
}
