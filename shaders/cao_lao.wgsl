// CAO step V (Titov et al. §3.5): the ambient factor V_AO per voxel from step IV's
// marks: clipped → 1, unaffected → the copy of V_PAO step IV left, affected → a full
// LAO ray cast (Eq. 2–3) on the clipped opacity volume V_o. With `full` set every
// unclipped voxel is ray cast: the "LAO every frame" baseline, and how V_PAO itself is
// made (no clipping). A list entry without the NEAR bit is a brick no shape is near
// (listed by the baseline only): nothing clipped, step IV left no mark.
// Both paths run the very same `lao` function (cao_ray.wgsl, which a frame's listed ray
// cast, cao_listed.wgsl, runs too), which is what makes CAO bit-exact.
// Runs over a brick list (ao::sparse); LAO rays step over empty cells (lao_ray.wgsl).
// CPU twin: src/ao/cao.rs (`lao_on_opacity_cpu`).
//!include bricks.wgsl

const RECOMPUTE: f32 = -1.0;
// What the V_PAO run leaves in a voxel the ray caster cannot read (with skipping): no
// ambient factor is above 1, and no pixel weights it. A frame's step IV reads it from
// V_PAO and writes V_AO = 1 there itself, so a frame's step V never repeats the
// per-voxel readability test (7³ texel fetches, more than a 6-ray LAO's samples).
const UNREAD: f32 = 2.0;
// Whether this is the per-frame pipeline (ao::sparse::FRAME): step IV has
// resolved every unreadable voxel already.
override FRAME: bool = false;
//!include cao_ray.wgsl
//!include readable.wgsl

//!include cao_params.wgsl
//!include cao_format.wgsl
//!include volume.wgsl

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var v_o: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> rays: array<vec4<f32>>;  // xyz direction, w weight
@group(0) @binding(4) var v_ao: CaoReadWrite;
@group(0) @binding(5) var<storage, read> bricks: array<u32>;
@group(0) @binding(6) var<storage, read> occupied: array<u32>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>, 4>; // [2]: ray cast
// The density for the readable-voxel test: volume.wgsl (group 3), its voxels alone.
@group(0) @binding(8) var<storage, read> readable_prefix: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if ray_cast_voxel(wid, lid) {
        atomicAdd(&ray_cast, 1u);
    }
    // One global atomic per workgroup: millions on one counter serialise on a CPU driver.
    workgroupBarrier();
    if lid.x == 0u && lid.y == 0u {
        atomicAdd(&counters[2], atomicLoad(&ray_cast));
    }
}

var<workgroup> ray_cast: atomic<u32>;

// Step V for one voxel; true if it was ray cast.
fn ray_cast_voxel(wid: vec3<u32>, lid: vec3<u32>) -> bool {
    let at_voxel = brick_voxel(wid, lid);
    if at_voxel.w == 0u {
        return false;
    }
    let v = at_voxel.xyz;
    let at = vec3<i32>(v);
    var mark = RECOMPUTE;
    if brick_near(wid) {
        mark = textureLoad(v_ao, at).r;
    }
    if mark >= 0.0 {
        return false;  // a copy of V_PAO
    }
    var a = 1.0;
    var traced = mark == RECOMPUTE;
    if !FRAME && traced && !voxel_readable(v) {
        traced = false;
        a = UNREAD;
    }
    if traced {
        a = lao(v);
    }
    textureStore(v_ao, at, vec4<f32>(a, 0.0, 0.0, 1.0));
    return traced;
}
