// CAO step IV (Titov et al. §3.5, Algorithm 2): anti-aliased shadow-test clipping of
// the voxels of a brick list (ao::sparse) into the clipped opacity volume V_o, and the
// mask (0 clipped, ½ recompute, 1 copy V_PAO) written straight into V_AO: a copy of
// V_PAO, or the marks RECOMPUTE / CLIPPED that step V resolves (the baseline marks
// every unclipped voxel RECOMPUTE). No mask volume is kept: CAO holds 3 volumes of
// 2 bytes per voxel. One invocation per voxel.
// CPU twin: src/ao/cao.rs (`clip_volume_cpu`); keep the two in step.
//!include clip_common.wgsl
//!include bricks.wgsl

struct Params {
    dims: vec4<u32>,      // x, y, z, unused
    chunk: vec4<u32>,     // first brick, bricks, workgroups per row, unused
    spacing: vec4<f32>,   // mm per voxel, w: N extra MSAA samples
    half: vec4<f32>,      // half the volume's extent (mm)
    lut_map: vec4<f32>,   // a, b, entries − 1
    mode: vec4<u32>,      // full (0/1), V_PAO marks unreadable voxels (0/1)
}

// Marks in V_AO between steps IV and V (an ambient factor is never negative).
const RECOMPUTE: f32 = -1.0;
const CLIPPED: f32 = -2.0;

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lut_alpha: array<f32>;
@group(0) @binding(3) var<storage, read> msaa: array<vec4<f32>>;  // offsets in voxels
@group(0) @binding(4) var v_o: texture_storage_3d<r16float, write>;
@group(0) @binding(5) var v_ao: texture_storage_3d<r16float, write>;
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>, 4>; // recompute, clipped
@group(0) @binding(7) var<storage, read> bricks: array<u32>;
@group(0) @binding(8) var v_pao: texture_3d<f32>;

// TF_o: the transfer function's opacity (for a 1 mm step) of the voxel itself.
fn voxel_opacity(v: vec3<u32>) -> f32 {
    let norm = textureLoad(volume, v, 0).r;
    let t = clamp(norm * p.lut_map.x + p.lut_map.y, 0.0, p.lut_map.z);
    let i0 = u32(floor(t));
    let i1 = min(i0 + 1u, u32(p.lut_map.z));
    return mix(lut_alpha[i0], lut_alpha[i1], t - floor(t));
}

fn position_mm(v: vec3<u32>, offset: vec3<f32>) -> vec3<f32> {
    return (vec3<f32>(v) + 0.5 + offset) * p.spacing.xyz - p.half.xyz;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let at_voxel = brick_voxel(wid, lid);
    if at_voxel.w == 0u {
        return;
    }
    let v = at_voxel.xyz;
    var visible = 0u;
    var dilated = 0u;
    // Centre and the 8 corners of the voxel.
    for (var k = 0u; k < 9u; k = k + 1u) {
        var offset = vec3<f32>(0.0);
        if k > 0u {
            let c = k - 1u;
            offset = vec3<f32>(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u)) - 0.5;
        }
        let t = clip_classify(position_mm(v, offset));
        visible = visible + u32(t.x);
        dilated = dilated + u32(t.y);
    }
    let n = u32(p.spacing.w);
    var opacity = 0.0;
    if visible == 9u {
        opacity = voxel_opacity(v);
    } else if visible > 0u {
        for (var k = 0u; k < n; k = k + 1u) {
            let t = clip_classify(position_mm(v, msaa[k].xyz));
            visible = visible + u32(t.x);
            dilated = dilated + u32(t.y);
        }
        opacity = f32(visible) / f32(n + 9u) * voxel_opacity(v);
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
        atomicAdd(&counters[0], 1u);
        if unread {
            ao = 1.0;
        }
    } else {
        ao = CLIPPED;
        atomicAdd(&counters[1], 1u);
    }
    let at = vec3<i32>(v);
    textureStore(v_o, at, vec4<f32>(opacity, 0.0, 0.0, 1.0));
    textureStore(v_ao, at, vec4<f32>(ao, 0.0, 0.0, 1.0));
}
