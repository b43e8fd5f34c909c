// Resolves the four peeled depth layers of one clip mesh into Z maps (empty pixels →
// ±3, never inside) and builds the dilation maps by Algorithm 1 of the CAO paper
// (§3.4 step III): D_front = min over the disk of Z_front − r_z·√(1 − (d/r_xy)²),
// D_back = max of Z_back + …; for probing the contraction (max / min, signs swapped).
// CPU twin: src/clip/cpu.rs (`resolve`, `dilate`).

struct Params {
    radii: vec4<f32>,   // r_xy (pixels), r_z (depth), unused, unused
    info: vec4<u32>,    // resolution, first layer, probe (0/1), unused
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var front1: texture_depth_2d;
@group(0) @binding(2) var back1: texture_depth_2d;
@group(0) @binding(3) var front2: texture_depth_2d;
@group(0) @binding(4) var back2: texture_depth_2d;
@group(0) @binding(5) var maps: texture_storage_2d_array<r32float, write>;

const EMPTY: f32 = 3.0;

// The resolved layers at a pixel: (front1, back1, front2, back2).
fn resolved(xy: vec2<i32>) -> vec4<f32> {
    let f1 = textureLoad(front1, xy, 0);
    let b1 = textureLoad(back1, xy, 0);
    let f2 = textureLoad(front2, xy, 0);
    let b2 = textureLoad(back2, xy, 0);
    var out = vec4<f32>(EMPTY, -EMPTY, EMPTY, -EMPTY);
    if f1 < 1.0 && b1 < 1.0 && b1 >= f1 {
        out.x = f1;
        out.y = b1;
        if f2 < 1.0 && b2 < 1.0 && b2 >= f2 {
            out.z = f2;
            out.w = b2;
        }
    }
    return out;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let res = p.info.x;
    if gid.x >= res || gid.y >= res {
        return;
    }
    let xy = vec2<i32>(gid.xy);
    let z = resolved(xy);
    let base = p.info.y;
    textureStore(maps, xy, base, vec4<f32>(z.x, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 1u, vec4<f32>(z.y, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 2u, vec4<f32>(z.z, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 3u, vec4<f32>(z.w, 0.0, 0.0, 1.0));

    let r_xy = p.radii.x;
    let r_z = p.radii.y;
    let probe = p.info.z != 0u;
    let reach = i32(floor(r_xy));
    // carve: fronts take the min, backs the max; probe: the reverse.
    var d = vec4<f32>(EMPTY, -EMPTY, EMPTY, -EMPTY);
    if probe {
        d = vec4<f32>(-EMPTY, EMPTY, -EMPTY, EMPTY);
    }
    for (var j = -reach; j <= reach; j = j + 1) {
        for (var i = -reach; i <= reach; i = i + 1) {
            let q = xy + vec2<i32>(i, j);
            if q.x < 0 || q.y < 0 || q.x >= i32(res) || q.y >= i32(res) {
                continue;
            }
            let dist = length(vec2<f32>(f32(i), f32(j)));
            if dist > r_xy {
                continue;
            }
            let ratio = dist / r_xy;
            let h = r_z * sqrt(max(1.0 - ratio * ratio, 0.0));
            let zq = resolved(q);
            if probe {
                d = vec4<f32>(max(d.x, zq.x + h), min(d.y, zq.y - h), max(d.z, zq.z + h), min(d.w, zq.w - h));
            } else {
                d = vec4<f32>(min(d.x, zq.x - h), max(d.y, zq.y + h), min(d.z, zq.z - h), max(d.w, zq.w + h));
            }
        }
    }
    if probe {
        // Pixels beyond the map are outside the mesh: no contraction reaches past them.
        if xy.x < reach || xy.y < reach || xy.x >= i32(res) - reach || xy.y >= i32(res) - reach {
            d = vec4<f32>(EMPTY, -EMPTY, EMPTY, -EMPTY);
        }
    }
    textureStore(maps, xy, base + 4u, vec4<f32>(d.x, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 5u, vec4<f32>(d.y, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 6u, vec4<f32>(d.z, 0.0, 0.0, 1.0));
    textureStore(maps, xy, base + 7u, vec4<f32>(d.w, 0.0, 0.0, 1.0));
}
