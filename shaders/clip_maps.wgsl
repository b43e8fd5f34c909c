// Builds one clip mesh's maps from its four peeled depth layers (CAO paper §3.4
// step III). CPU twin: src/clip/cpu.rs (`resolve`, `dilate`).
//
//   resolve: Z maps, empty pixels → ±3 (never inside)
//   reduce:  per block of f×f pixels, the extreme Z of each layer (the one the dilation
//            needs: min of fronts and max of backs to dilate, the reverse to contract)
//   dilate:  Algorithm 1 over blocks: D_front = min over the disk of Z_front − r_z·√(1 − (d/r_xy)²),
//            D_back = max of Z_back + …; contraction: max / min with the signs swapped.
//            d is the smallest pixel distance between the two blocks (from the gaps
//            between them along x and y), so every pixel's value is at least as wide as
//            the per-pixel Algorithm 1 (conservative); with f = 1 it is exactly
//            Algorithm 1.
//   expand:  each pixel takes its block's dilated values.

struct Params {
    radii: vec4<f32>,   // r_xy (pixels), r_z (depth), unused, unused
    info: vec4<u32>,    // resolution, first RGBA layer, probe (0/1), block size f
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var front1: texture_depth_2d;
@group(0) @binding(2) var back1: texture_depth_2d;
@group(0) @binding(3) var front2: texture_depth_2d;
@group(0) @binding(4) var back2: texture_depth_2d;
@group(0) @binding(5) var maps: texture_storage_2d_array<rgba32float, write>;
@group(0) @binding(6) var blocks_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var blocks_in: texture_2d<f32>;

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

// The value a layer starts from before taking extremes (nothing found yet).
fn identity() -> vec4<f32> {
    if p.info.z != 0u {
        return vec4<f32>(-EMPTY, EMPTY, -EMPTY, EMPTY);
    }
    return vec4<f32>(EMPTY, -EMPTY, EMPTY, -EMPTY);
}

// Carve: fronts take the min and backs the max; probe: the reverse.
fn widest(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    if p.info.z != 0u {
        return vec4<f32>(max(a.x, b.x), min(a.y, b.y), max(a.z, b.z), min(a.w, b.w));
    }
    return vec4<f32>(min(a.x, b.x), max(a.y, b.y), min(a.z, b.z), max(a.w, b.w));
}

@compute @workgroup_size(8, 8, 1)
fn resolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let res = p.info.x;
    if gid.x >= res || gid.y >= res {
        return;
    }
    let xy = vec2<i32>(gid.xy);
    let z = resolved(xy);
    textureStore(maps, xy, p.info.y, z);
}

@compute @workgroup_size(8, 8, 1)
fn reduce(@builtin(global_invocation_id) gid: vec3<u32>) {
    let f = p.info.w;
    let blocks = (p.info.x + f - 1u) / f;
    if gid.x >= blocks || gid.y >= blocks {
        return;
    }
    var acc = identity();
    for (var j = 0u; j < f; j = j + 1u) {
        for (var i = 0u; i < f; i = i + 1u) {
            let q = gid.xy * f + vec2<u32>(i, j);
            if q.x < p.info.x && q.y < p.info.x {
                acc = widest(acc, resolved(vec2<i32>(q)));
            }
        }
    }
    textureStore(blocks_out, vec2<i32>(gid.xy), acc);
}

@compute @workgroup_size(8, 8, 1)
fn dilate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let f = p.info.w;
    let blocks = i32((p.info.x + f - 1u) / f);
    let b = vec2<i32>(gid.xy);
    if b.x >= blocks || b.y >= blocks {
        return;
    }
    let r_xy = p.radii.x;
    let r_z = p.radii.y;
    let probe = p.info.z != 0u;
    // Pixels of two blocks (i, j) blocks apart are at least max(|i|·f − (f − 1), 0)
    // apart along x, and the same along y.
    let reach = i32(ceil((r_xy + f32(f - 1u)) / f32(f)));
    var d = identity();
    for (var j = -reach; j <= reach; j = j + 1) {
        for (var i = -reach; i <= reach; i = i + 1) {
            let q = b + vec2<i32>(i, j);
            if q.x < 0 || q.y < 0 || q.x >= blocks || q.y >= blocks {
                continue;
            }
            let gap = max(abs(vec2<i32>(i, j)) * i32(f) - vec2<i32>(i32(f) - 1), vec2<i32>(0));
            let dist = length(vec2<f32>(gap));
            if dist > r_xy {
                continue;
            }
            let ratio = dist / r_xy;
            let h = r_z * sqrt(max(1.0 - ratio * ratio, 0.0));
            let z = textureLoad(blocks_in, q, 0);
            if probe {
                d = widest(d, z + vec4<f32>(h, -h, h, -h));
            } else {
                d = widest(d, z + vec4<f32>(-h, h, -h, h));
            }
        }
    }
    // Contraction: pixels beyond the map are outside the mesh, so no pixel whose disk
    // leaves the map is deep inside.
    if probe {
        let lo = b * i32(f);
        let hi = lo + vec2<i32>(i32(f) - 1);
        let r = i32(ceil(r_xy));
        if lo.x < r || lo.y < r || hi.x >= i32(p.info.x) - r || hi.y >= i32(p.info.x) - r {
            d = vec4<f32>(EMPTY, -EMPTY, EMPTY, -EMPTY);
        }
    }
    textureStore(blocks_out, b, d);
}

@compute @workgroup_size(8, 8, 1)
fn expand(@builtin(global_invocation_id) gid: vec3<u32>) {
    let res = p.info.x;
    if gid.x >= res || gid.y >= res {
        return;
    }
    let xy = vec2<i32>(gid.xy);
    let d = textureLoad(blocks_in, xy / i32(p.info.w), 0);
    textureStore(maps, xy, p.info.y + 1u, d);
}
