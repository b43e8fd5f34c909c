// Direct volume ray caster: one invocation per pixel of a tile.
// CPU twin: src/render/cpu.rs (same steps, same order; keep them in sync).
//!include common.wgsl
//!include clip_common.wgsl
//!include vao_common.wgsl
//!include volume.wgsl

struct Params {
    inv_view_proj: mat4x4<f32>,
    box_half: vec4<f32>,  // w: the gradient volume's scale M (0: none bound)
    background: vec4<f32>,
    shading: vec4<f32>,   // ambient k, specular, shininess, phong on
    voxel_uvw: vec4<f32>, // one voxel in uvw per axis, smallest spacing (mm)
    edge: vec4<f32>,      // x: the gradient scale for "is this an edge"; yzw unused
    step: vec4<f32>,      // dt (mm), jitter on, max steps, skipping on
    image: vec4<u32>,     // width, height, tile x0, tile y0
    grid: vec4<u32>,      // occupancy grid dims, block edge (voxels)
    mode: vec4<f32>,      // render mode (0 composite … 4 iso), u = norm · y + z
    ao: vec4<f32>,        // AO strength, AO on the ambient term only (0/1), AO read offset (voxels), A_open
    reuse: vec4<u32>,     // x: balls holding every change since the image in the target (0: cast every pixel)
    balls: array<vec4<f32>, 8>, // centre (mm), radius
}

// Pipeline-overridable constants: render::gpu::Variant builds one pipeline per
// combination a frame needs, so code for what is off is not compiled in. The defaults
// (every feature in, composite) give the general shader, in which the uniform flags
// below decide alone. On lavapipe (Mesa 22.3) both sides of a branch run, masked, so a
// feature left in costs its texture fetches on every sample even while it is off.
override MODE: u32 = 0u;          // RenderMode::code
override PHONG: bool = true;      // shading.w may be 1
override AO_VOLUME: bool = true;  // an AO volume is bound (else A = 1: a 1×1×1 texel of 1)
override LIVE_VAO: bool = true;   // extras.flags.x may be 1
override SHADOWS: bool = true;    // extras.flags.y may be 1
override SURFACES: bool = true;   // extras.flags.z may be 1
override CLIP: bool = true;       // clip.counts.x may be > 0
override MODULATION: bool = true; // an opacity-modulation volume is bound (else × 1)
override SKIPPING: bool = true;   // step.w may be 1
override FIND: bool = true;       // shading fetches: find a sample with opacity first
// 1: a gradient volume is bound (one fetch per gradient), 0: six density samples,
// 2: box_half.w decides (the general shader).
override GRADIENT: u32 = 2u;
// A segmentation's weight has edges (some class hidden, fainter or outlined): shading
// looks at its gradient (texels::segments::SegmentTexels::edges; without, it is 0).
override SEGMENT_EDGES: bool = true;
// Some class's weight is below 1 (hidden, fainter, outlined: SegmentTexels::edges).
// Without, every weight is 1: a step needs no look for its opacity, only a sample that
// shows does for its colour.
override SEGMENT_WEIGHTS: bool = true;
// Picking (render::gpu::RayCaster::pick; CPU twin: render::cpu::pick): a composite ray
// stops at the first sample at which its accumulated opacity reaches PICK_OPACITY and
// writes where that sample lies (volume-centred mm, w = 1) to `picked`. Off, the code
// is compiled out and `picked` (a placeholder) is never written.
override PICK: bool = false;
const PICK_OPACITY: f32 = 0.5;
// The visibility pass of view-dependent AO (ao::view): every AO read marks the voxels
// its trilinear footprint weighs in `ao_marks` (the image itself is not used).
override MARK_AO: bool = false;

// The AO is read the full offset out wherever the gradient is at least 1/AO_EDGE_GAIN
// of a full edge: through the whole soft ramp of a CT surface, whose deeper samples
// would otherwise read the occluded inside (CPU twin: render::cpu::AO_EDGE_GAIN).
const AO_EDGE_GAIN: f32 = 8.0;

// A sample within CUT_SHELL voxels (of the smallest spacing) behind a carved sample in a
// block that may have opacity lies on a cut face (docs/algorithms.md, "Cut faces"): the material's
// gradient there is not the surface's, so it is lit without a direction and its AO is
// read back along the ray, in the carved space (CPU twin: render::cpu::CUT_SHELL).
const CUT_SHELL: f32 = 2.0;

const MODE_COMPOSITE: u32 = 0u;
const MODE_MIP: u32 = 1u;
const MODE_MINIP: u32 = 2u;
const MODE_AVERAGE: u32 = 3u;
const MODE_ISO: u32 = 4u;

// The density and the transfer function are read through volume.wgsl (group 3).
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var linear_clamp: sampler;
@group(0) @binding(2) var ambient_occlusion: texture_3d<f32>;
@group(0) @binding(3) var occupancy: texture_3d<u32>;
@group(0) @binding(4) var out_image: texture_storage_2d<rgba8unorm, write>;
// min(σ²/σ²_max, 1) per voxel (Ruiz et al. §4.2); a single texel of 1 when off.
@group(0) @binding(5) var opacity_modulation: texture_3d<f32>;
// (min, max) of the texel values a trilinear sample in each occupancy block can read.
@group(0) @binding(6) var block_range: texture_3d<f32>;
// The density's central differences per voxel ÷ M, with a border of one voxel
// (render::gradient); a single texel when there is none.
@group(0) @binding(7) var gradient_volume: texture_3d<f32>;
@group(0) @binding(8) var<storage, read_write> picked: vec4<f32>;

// Group 2 (src/render/shadow.rs): live positional AO (vao_common.wgsl, bindings 0–4)
// and the light volume for shadows.
struct Extras {
    flags: vec4<u32>,  // live positional AO on, shadows on
    light: vec4<f32>,  // unit direction towards the light (volume space), w = guard (voxels)
    marks: vec4<u32>,  // MARK_AO: x the footprint (ao::view::Footprint::code), y the cell edge
}

@group(2) @binding(5) var<uniform> extras: Extras;
@group(2) @binding(6) var light_volume: texture_3d<f32>;
@group(2) @binding(7) var surface_position: texture_2d<f32>;  // nearest surface, w = covered
@group(2) @binding(8) var surface_color: texture_2d<f32>;     // its shaded straight RGBA
// One bit per cell of the AO volume (x fastest): what MARK_AO pipelines mark.
@group(2) @binding(10) var<storage, read_write> ao_marks: array<atomic<u32>>;

// Any texel a sampler's fixed-point weights may weigh (CPU twin: sample::FOOTPRINT_SLACK).
const FOOTPRINT_SLACK: f32 = 1.0 / 64.0;

// The cells the last AO read of this invocation marked (consecutive samples along a
// ray mostly read the same ones: marked once).
var<private> marked_lo: vec3<i32> = vec3<i32>(-1);
var<private> marked_hi: vec3<i32> = vec3<i32>(-1);

// Marks the cells (of extras.marks.y voxels a side) of the voxels an AO read at `at` (for
// the sample at `uvw`) weighs: its trilinear footprint, widened by FOOTPRINT_SLACK
// (CPU twin: ao::view::ViewMarks::mark).
fn mark_ao(uvw: vec3<f32>, at: vec3<f32>) {
    let dims = vec3<i32>(volume_dims());
    var read = at;
    if extras.marks.x == 2u {
        read = uvw;  // tests: the AO read offset ignored
    }
    let c = read * vec3<f32>(dims) - 0.5;
    var lo = clamp(vec3<i32>(floor(c - FOOTPRINT_SLACK)), vec3<i32>(0), dims - 1);
    var hi = clamp(vec3<i32>(floor(c + FOOTPRINT_SLACK)) + 1, vec3<i32>(0), dims - 1);
    if extras.marks.x == 1u {
        // tests: the nearest texel only
        lo = clamp(vec3<i32>(floor(read * vec3<f32>(dims))), vec3<i32>(0), dims - 1);
        hi = lo;
    }
    let edge = i32(max(extras.marks.y, 1u));
    let grid = (dims + edge - 1) / edge;
    lo = lo / edge;
    hi = hi / edge;
    if all(lo == marked_lo) && all(hi == marked_hi) {
        return;
    }
    marked_lo = lo;
    marked_hi = hi;
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            for (var x = lo.x; x <= hi.x; x++) {
                let i = u32(x + grid.x * (y + grid.y * z));
                atomicOr(&ao_marks[i >> 5u], 1u << (i & 31u));
            }
        }
    }
}

// Front-to-back "over" of straight colour `c` with opacity `a` behind `acc`.
fn over(acc: vec4<f32>, rgb: vec3<f32>, a: f32) -> vec4<f32> {
    return vec4<f32>(acc.rgb + (1.0 - acc.a) * a * rgb, acc.a + (1.0 - acc.a) * a);
}

const OPAQUE: f32 = 0.99;

// How far `d` (texture coordinates) may be followed from `uvw` inside the box, as a
// fraction of it in [0, 1].
fn inside_box(uvw: vec3<f32>, d: vec3<f32>) -> f32 {
    let room = select(uvw, vec3<f32>(1.0) - uvw, d > vec3<f32>(0.0));
    let ad = abs(d);
    let r = select(vec3<f32>(1.0), clamp(room / max(ad, vec3<f32>(1e-20)), vec3<f32>(0.0), vec3<f32>(1.0)), ad > vec3<f32>(0.0));
    return min(r.x, min(r.y, r.z));
}

// Shadow factor at a view-ray sample (CPU twin: render::shadow::shadow_factor).
// Guard limit (Papaioannou et al. §5.1): the light volume is read at a point moved from
// the sample towards the light by d0 = g / cos θ (g = extras.light.w voxels, θ between the
// light and the normal, cos θ at least ½), so the surface layer the sample lies in does
// not shadow itself. Filtered occlusion (Imagire et al. Eq. 3–4): ¼, ½, ¼ of the light
// volume there and at the half-step positions towards the previous and the next view
// sample, kept on the valid sampling path (inside the box).
fn shadow(uvw: vec3<f32>, view: vec3<f32>, cos_theta: f32) -> f32 {
    let to_uvw = 1.0 / (2.0 * p.box_half.xyz);
    let guard = extras.light.w * p.voxel_uvw.w / max(cos_theta, 0.5);
    let o = uvw + extras.light.xyz * guard * to_uvw;
    let half_step = -view * (0.5 * p.step.x) * to_uvw;
    let ahead = half_step * inside_box(uvw, half_step);
    let behind = half_step * inside_box(uvw, -half_step);
    return 0.25 * textureSampleLevel(light_volume, linear_clamp, o - behind, 0.0).r
        + 0.5 * textureSampleLevel(light_volume, linear_clamp, o, 0.0).r
        + 0.25 * textureSampleLevel(light_volume, linear_clamp, o + ahead, 0.0).r;
}

// PCG hash of the pixel → [0, 1); identical to render::jitter.
fn jitter(x: u32, y: u32) -> f32 {
    var h = x * 1973u + y * 9277u + 26699u;
    h = h * 747796405u + 2891336453u;
    let word = ((h >> ((h >> 28u) + 4u)) ^ h) * 277803737u;
    let r = (word >> 22u) ^ word;
    return f32(r >> 8u) / 16777216.0;
}

// Ray–box intersection (slab method): (t_enter, t_exit); empty if t_exit <= t_enter.
fn intersect_box(origin: vec3<f32>, dir: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    let inv = 1.0 / dir;
    let a = (lo - origin) * inv;
    let b = (hi - origin) * inv;
    let t_near = min(a, b);
    let t_far = max(a, b);
    return vec2<f32>(max(max(t_near.x, t_near.y), t_near.z), min(min(t_far.x, t_far.y), t_far.z));
}

// Whether the ray over [t_enter, t_exit] meets a ball where something changed since the
// image the target holds (render::reuse; CPU twin: reuse::meets_change). A ray that
// meets none would cast that image's pixel again.
fn meets_change(origin: vec3<f32>, dir: vec3<f32>, t_enter: f32, t_exit: f32) -> bool {
    if t_exit <= t_enter {
        return false;
    }
    for (var i = 0u; i < p.reuse.x; i = i + 1u) {
        let b = p.balls[i];
        let t = clamp(dot(b.xyz - origin, dir), t_enter, t_exit);
        let d = origin + dir * t - b.xyz;
        if dot(d, d) <= b.w * b.w {
            return true;
        }
    }
    return false;
}

// The density's gradient by central differences one voxel either side, in texel units
// per mm: from the gradient volume (the same differences interpolated, rounded to f16;
// render::gradient) when one is bound, else from six samples (CPU twin:
// render::cpu::shade, which takes the six).
fn gradient(uvw: vec3<f32>) -> vec3<f32> {
    if GRADIENT == 1u || (GRADIENT == 2u && p.box_half.w > 0.0) {
        let n = vec3<f32>(volume_dims());
        let at = (uvw * n + 1.0) / (n + 2.0);
        let g = textureSampleLevel(gradient_volume, linear_clamp, at, 0.0).xyz;
        return g * (p.box_half.w / (2.0 * p.voxel_uvw.w));
    }
    let d = p.voxel_uvw.xyz;
    return vec3<f32>(
        value_at(uvw + vec3<f32>(d.x, 0.0, 0.0)) - value_at(uvw - vec3<f32>(d.x, 0.0, 0.0)),
        value_at(uvw + vec3<f32>(0.0, d.y, 0.0)) - value_at(uvw - vec3<f32>(0.0, d.y, 0.0)),
        value_at(uvw + vec3<f32>(0.0, 0.0, d.z)) - value_at(uvw - vec3<f32>(0.0, 0.0, d.z)),
    ) / (2.0 * p.voxel_uvw.w);
}

// The lit colour of a sample (CPU twin: render::cpu::light), docs/algorithms.md "Shading
// with ambient occlusion". By default the AO factor A_s = clamp(1 − s(1 − min(A / A_open, 1)), 0, 1)
// (A_open = ao.w: what the AO method gives an open flat surface, so such a surface keeps
// its light) scales ambient and diffuse light, C_TF · A_s · (k + (1 − k) · D · S) + spec · S;
// with ao.y, the ambient term only, with A_s = clamp(1 − s(1 − A), 0, 1):
// C_TF · (k · A_s + (1 − k) · D · S) + spec · S.
fn light(rgb: vec3<f32>, ao: f32, diffuse: f32, specular: f32, lit: f32) -> vec3<f32> {
    let k = p.shading.x;
    var c: vec3<f32>;
    if p.ao.y != 0.0 {
        let a = clamp(1.0 - p.ao.x * (1.0 - ao), 0.0, 1.0);
        c = rgb * (k * a + (1.0 - k) * diffuse * lit);
    } else {
        let a = clamp(1.0 - p.ao.x * (1.0 - min(ao / p.ao.w, 1.0)), 0.0, 1.0);
        c = rgb * a * (k + (1.0 - k) * diffuse * lit);
    }
    return c + vec3<f32>(specular * lit);
}

// Blinn–Phong (a headlight, or the directional light of shadows), with the AO factor.
fn shade(rgb: vec3<f32>, uvw: vec3<f32>, view: vec3<f32>, cut: bool) -> vec3<f32> {
    let shadows = SHADOWS && extras.flags.y != 0u;
    let phong = PHONG && p.shading.w != 0.0;
    var diffuse = 1.0;
    var specular = 0.0;
    // cos θ of the shadow lookup's guard limit: 1 where there is no normal.
    var cos_theta = 1.0;
    // Where the AO is read: off the surface, ao.z voxels (of the smallest spacing) out of
    // the material along the normal (docs/algorithms.md): inside the material every
    // voxel is occluded.
    var ao_at = uvw;
    if phong || ((AO_VOLUME || (LIVE_VAO && extras.flags.x != 0u)) && p.ao.z > 0.0) {
        var g = gradient(uvw);
        // How much of an edge this is (1 = a clear surface); flat regions are lit fully.
        var strength = length(g) * abs(volume_map.lut.x) * p.voxel_uvw.w * p.edge.x;
        if SEGMENTS && SEGMENT_EDGES {
            // A segment's boundary the density does not show (an organ in tissue of the
            // same HU) is lit by the gradient of the segmentation's weight where that
            // is the stronger edge (a full step of weight across a voxel is one edge).
            let gw = segment_gradient_at(uvw) / (2.0 * p.voxel_uvw.w);
            let sw = length(gw) * p.voxel_uvw.w * 2.0;
            if sw > strength {
                g = gw;
                strength = sw;
            }
        }
        var edge = clamp(strength, 0.0, 1.0);
        if MODE == MODE_ISO && strength > 0.0 {
            edge = 1.0;  // an isosurface is a surface however soft its gradient
        }
        if strength > 0.0 {
            // The gradient points into denser material: out of it is −g.
            let out = p.ao.z * min(AO_EDGE_GAIN * edge, 1.0) * p.voxel_uvw.w;
            ao_at = uvw - normalize(g) * out / (2.0 * p.box_half.xyz);
        }
        if phong && strength > 0.0 && shadows {
            // Directional light: two-sided Blinn–Phong with the half vector of light and eye.
            let n = normalize(g);
            diffuse = mix(1.0, abs(dot(n, extras.light.xyz)), edge);
            cos_theta = diffuse;
            let h = extras.light.xyz + view;
            if dot(h, h) > 1e-12 {
                specular = p.shading.y * pow(abs(dot(n, normalize(h))), p.shading.z) * edge;
            }
        } else if phong && strength > 0.0 {
            // Headlight: the light comes from the eye, so the half vector is the view vector.
            let n_dot_v = abs(dot(normalize(g), view));
            diffuse = mix(1.0, n_dot_v, edge);
            specular = p.shading.y * pow(n_dot_v, p.shading.z) * edge;
        }
    }
    // A cut face: lit without a direction; out of the material is back towards the eye,
    // through what was carved. (Selected after the gradient's code rather than branching
    // around it: on lavapipe a per-lane branch there cost a clipped Phong frame a fifth.)
    diffuse = select(diffuse, 1.0, cut);
    specular = select(specular, 0.0, cut);
    cos_theta = select(cos_theta, 1.0, cut);
    ao_at = select(ao_at, uvw + view * (p.ao.z * p.voxel_uvw.w) / (2.0 * p.box_half.xyz), cut);
    var ao = 1.0;
    if MARK_AO {
        mark_ao(uvw, ao_at);
    }
    if AO_VOLUME {
        ao = textureSampleLevel(ambient_occlusion, linear_clamp, ao_at, 0.0).r;
    }
    if LIVE_VAO && extras.flags.x != 0u {
        ao = 1.0 - positional_ao(ao_at);  // live mode: Eq. 8 where the AO is read
    }
    var lit = 1.0;
    if shadows {
        lit = shadow(uvw, view, cos_theta);
    }
    return light(rgb, ao, diffuse, specular, lit);
}

// The mode's value at a sample: projections map the TF's window to [0, 1]; iso puts
// the surface at 0.
fn mode_value(uvw: vec3<f32>) -> f32 {
    return value_at(uvw) * p.mode.y + p.mode.z;
}

// Whether the clip shapes leave the sample at `pos` (uvw `uvw`): with a segmentation,
// those that carve its voxel's class.
fn unclipped(pos: vec3<f32>, uvw: vec3<f32>) -> bool {
    if SEGMENTS {
        return clip_visible_for(pos, carved_by_at(uvw));
    }
    return clip_visible(pos);
}

// Whether a projection or an isosurface sees the sample at `pos`: unclipped, and not in
// a hidden segment (weight below ½).
fn visible(pos: vec3<f32>) -> bool {
    let uvw = pos / (2.0 * p.box_half.xyz) + 0.5;
    if SEGMENTS && SEGMENT_WEIGHTS && segment_look_at(uvw).a < 0.5 {
        return false;
    }
    return !CLIP || clip.counts.x == 0u || unclipped(pos, uvw);
}

// MIP, MinIP or average of the mode value over the ray's unclipped samples: opaque
// grey, or nothing when every sample is clipped.
fn project(origin: vec3<f32>, dir: vec3<f32>, t_enter: f32, t_exit: f32, offset: f32, max_steps: u32, mode: u32) -> vec4<f32> {
    var best = 0.0;
    var sum = 0.0;
    var count = 0u;
    // MIP and MinIP jump over blocks that cannot change the pixel: the grey is
    // clamp(best, 0, 1), so once a sample is in, a block whose values all stay at or
    // below max(best, 0) (MIP), or at or above min(best, 1) (MinIP), changes nothing.
    let skip = (mode == MODE_MIP || mode == MODE_MINIP) && SKIPPING && p.step.w != 0.0;
    var k = 0u;
    loop {
        if k >= max_steps {
            break;
        }
        let t = t_enter + (f32(k) + offset) * p.step.x;
        if t >= t_exit {
            break;
        }
        let pos = origin + dir * t;
        if skip && count > 0u {
            let block = block_at(pos / (2.0 * p.box_half.xyz) + 0.5);
            let r = block_u(block);
            if (mode == MODE_MIP && r.y <= max(best, 0.0)) || (mode == MODE_MINIP && r.x >= min(best, 1.0)) {
                k = max(k + 1u, past_block(origin, dir, block, t_enter, offset));
                continue;
            }
        }
        k = k + 1u;
        if !visible(pos) {
            continue;
        }
        let u = mode_value(pos / (2.0 * p.box_half.xyz) + 0.5);
        if count == 0u {
            best = u;
        } else if mode == MODE_MIP {
            best = max(best, u);
        } else {
            best = min(best, u);
        }
        sum = sum + u;
        count = count + 1u;
        // The grey is clamped to [0, 1]: once MIP reaches white or MinIP black, no
        // later sample can change the pixel.
        if (mode == MODE_MIP && best >= 1.0) || (mode == MODE_MINIP && best <= 0.0) {
            break;
        }
    }
    if count == 0u {
        return vec4<f32>(0.0);
    }
    if mode == MODE_AVERAGE {
        best = sum / f32(count);
    }
    return vec4<f32>(vec3<f32>(clamp(best, 0.0, 1.0)), 1.0);
}

// The occupancy block of a sample.
fn block_at(uvw: vec3<f32>) -> vec3<u32> {
    let dims = vec3<f32>(volume_dims());
    // The block edge is a power of two: a shift, not a division (exact for u32).
    return min(vec3<u32>(clamp(uvw, vec3<f32>(0.0), vec3<f32>(1.0)) * dims) >> vec3<u32>(countTrailingZeros(p.grid.w)), p.grid.xyz - vec3<u32>(1u));
}

// The mode value's range (lo, hi) over every sample a block can give.
fn block_u(block: vec3<u32>) -> vec2<f32> {
    let r = textureLoad(block_range, block, 0).rg;
    let a = r.x * p.mode.y + p.mode.z;
    let b = r.y * p.mode.y + p.mode.z;
    return vec2<f32>(min(a, b), max(a, b));
}

// The first regular sample index past `block` along the ray (as compositing skips).
fn past_block(origin: vec3<f32>, dir: vec3<f32>, block: vec3<u32>, t_enter: f32, offset: f32) -> u32 {
    let dims = vec3<f32>(volume_dims());
    let half = p.box_half.xyz;
    let lo = vec3<f32>(block * p.grid.w) / dims * 2.0 * half - half;
    let hi = vec3<f32>((block + vec3<u32>(1u)) * p.grid.w) / dims * 2.0 * half - half;
    let leave = intersect_box(origin, dir, lo, hi).y;
    return u32(max(ceil((leave - t_enter) / p.step.x - offset), 0.0));
}

fn inside_surface(origin: vec3<f32>, dir: vec3<f32>, t: f32) -> bool {
    let pos = origin + dir * t;
    return visible(pos) && mode_value(pos / (2.0 * p.box_half.xyz) + 0.5) >= 0.0;
}

// Bisection steps that place an isosurface hit between two samples (1/64 of a step).
const ISO_REFINE: u32 = 6u;

// The first point of the ray inside the isosurface (value ≥ iso, unclipped), refined
// between the last sample outside and the first inside, and the last point before it
// found outside (x: -1 when there is none).
fn iso_hit(origin: vec3<f32>, dir: vec3<f32>, t_enter: f32, t_exit: f32, offset: f32, max_steps: u32) -> vec2<f32> {
    var before = t_enter;
    var after = t_enter;
    var found = false;
    for (var k = 0u; k < max_steps; k = k + 1u) {
        let t = t_enter + (f32(k) + offset) * p.step.x;
        if t >= t_exit {
            break;
        }
        if SKIPPING && p.step.w != 0.0 {
            // A block whose values all stay below the iso value holds no hit: jump to
            // its last sample, which is then the sample before, as without skipping.
            let block = block_at((origin + dir * t) / (2.0 * p.box_half.xyz) + 0.5);
            if block_u(block).y < 0.0 {
                let last = max(k + 1u, past_block(origin, dir, block, t_enter, offset)) - 1u;
                before = t_enter + (f32(last) + offset) * p.step.x;
                k = last;
                continue;
            }
        }
        if inside_surface(origin, dir, t) {
            found = true;
            after = t;
            break;
        }
        before = t;
    }
    if !found {
        return vec2<f32>(-1.0, 0.0);
    }
    // Refined after the loop, not inside it: on SIMD drivers that run branches masked
    // (lavapipe) the bisection's fetches would otherwise cost every step.
    var lo = before;
    var hi = after;
    for (var i = 0u; i < ISO_REFINE; i = i + 1u) {
        let mid = 0.5 * (lo + hi);
        if inside_surface(origin, dir, mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    return vec2<f32>(hi, lo);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let tile = textureDimensions(out_image);
    if gid.x >= tile.x || gid.y >= tile.y {
        return;
    }
    let px = gid.x + p.image.z;
    let py = gid.y + p.image.w;
    let ndc = vec2<f32>(
        (f32(px) + 0.5) / f32(p.image.x) * 2.0 - 1.0,
        1.0 - (f32(py) + 0.5) / f32(p.image.y) * 2.0,
    );
    let near = p.inv_view_proj * vec4<f32>(ndc, 0.0, 1.0);
    let far = p.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let origin = near.xyz / near.w;
    let dir = normalize(far.xyz / far.w - origin);
    let half = p.box_half.xyz;
    let hit = intersect_box(origin, dir, -half, half);
    let t_enter = max(hit.x, 0.0);
    let t_exit = hit.y;
    if p.reuse.x > 0u && !meets_change(origin, dir, t_enter, t_exit) {
        return;  // the target already holds this pixel
    }
    let dt = p.step.x;
    var acc = vec4<f32>(0.0);
    // A surface inside the view (render::surface): the valid sampling path ends there.
    var pending = false;
    var t_surf = 0.0;
    var surf = vec4<f32>(0.0);
    if SURFACES && extras.flags.z != 0u {
        let sp = textureLoad(surface_position, vec2<u32>(px, py), 0);
        if sp.w > 0.0 {
            pending = true;
            t_surf = dot(sp.xyz - origin, dir);
            surf = textureLoad(surface_color, vec2<u32>(px, py), 0);
        }
    }
    let mode = MODE;
    if t_exit > t_enter && mode != MODE_COMPOSITE {
        var offset = 0.0;
        if p.step.y != 0.0 {
            offset = jitter(px, py);
        }
        let max_steps = u32(p.step.z);
        var front = 3.0e38;  // surfaces nearer than this are drawn over the result
        var result = vec4<f32>(0.0);
        if mode == MODE_ISO {
            let hit = iso_hit(origin, dir, t_enter, t_exit, offset, max_steps);
            let t_hit = hit.x;
            if t_hit >= 0.0 {
                front = t_hit;
                let uvw = (origin + dir * t_hit) / (2.0 * half) + 0.5;
                // Just before the hit the ray was inside the material but clipped: the
                // hit is on a cut face.
                let lo = origin + dir * hit.y;
                let cut = !visible(lo) && mode_value(lo / (2.0 * half) + 0.5) >= 0.0;
                result = vec4<f32>(shade(classify_at(uvw, value_at(uvw)).rgb, uvw, -dir, cut), 1.0);
            }
        } else {
            result = project(origin, dir, t_enter, t_exit, offset, max_steps, mode);
        }
        if pending && t_surf < front {
            acc = over(acc, surf.rgb, surf.a);
            pending = false;
        }
        acc = over(acc, result.rgb, result.a);
        pending = pending && result.a < 1.0;
    }
    if t_exit > t_enter && mode == MODE_COMPOSITE {
        var offset = 0.0;
        if p.step.y != 0.0 {
            offset = jitter(px, py);
        }
        let max_steps = u32(p.step.z);
        // The three nested loops visit the samples of the CPU twin's single loop in the
        // same order with the same arithmetic. They serve drivers that run every branch
        // masked on SIMD lanes (lavapipe): the innermost jumps over transparent blocks
        // without fetching, the middle one fetches and classifies and, with FIND, goes on
        // until a sample has opacity, so shading (gradient, AO, shadows) runs once per
        // sample that shows instead of once per step.
        var k = 0u;
        // The last carved sample in a block that may have opacity (cut faces lie just
        // behind it).
        var cut_t = -3.0e38;
        loop {
            var t = 0.0;
            var uvw = vec3<f32>(0.0);
            var rgba = vec4<f32>(0.0);
            var look = vec4<f32>(1.0);
            var found = false;
            var stop = false;
            loop {
                loop {
                    if k >= max_steps {
                        stop = true;
                        break;
                    }
                    t = t_enter + (f32(k) + offset) * dt;
                    if pending && t_surf <= t {
                        // The surface lies before this sample in transparent space (or
                        // before the first one): composite it here.
                        acc = over(acc, surf.rgb, surf.a);
                        pending = false;
                        if surf.a >= 1.0 {
                            stop = true;
                            break;
                        }
                    }
                    if t >= t_exit {
                        stop = true;
                        break;
                    }
                    let pos = origin + dir * t;
                    uvw = pos / (2.0 * half) + 0.5;
                    if !(SKIPPING && p.step.w != 0.0) {
                        break;
                    }
                    // Empty-space skipping: jump to the first sample past a transparent block.
                    let block = block_at(uvw);
                    if textureLoad(occupancy, block, 0).r != 0u {
                        break;
                    }
                    k = max(k + 1u, past_block(origin, dir, block, t_enter, offset));
                }
                if stop {
                    break;
                }
                // Shadow-test clipping (CAO step VI): clipped samples are empty.
                if CLIP && clip.counts.x > 0u && !unclipped(origin + dir * t, uvw) {
                    // Only shading that fetches (FIND) looks at cut faces: a carved sample
                    // in a block that may have opacity (with skipping, every sample here).
                    if FIND && ((SKIPPING && p.step.w != 0.0) || textureLoad(occupancy, block_at(uvw), 0).r != 0u) {
                        cut_t = t;
                    }
                    k = k + 1u;
                    continue;
                }
                let norm = value_at(uvw);
                // The opacity first; the segments' colour only once a sample shows.
                rgba = classify(norm);
                if SEGMENT_WEIGHTS {
                    look = segment_look_at(uvw);
                    rgba.a = rgba.a * look.a;
                }
                if rgba.a > 0.0 {
                    found = true;
                    break;
                }
                k = k + 1u;
                if !FIND {
                    break;
                }
            }
            if stop {
                break;
            }
            if !found {
                continue;
            }
            if SEGMENTS && !SEGMENT_WEIGHTS {
                look = segment_look_at(uvw);
            }
            rgba = vec4<f32>(segment_colour(uvw, rgba.rgb, look), rgba.a);
            if MODULATION {
                rgba.a = rgba.a * textureSampleLevel(opacity_modulation, linear_clamp, uvw, 0.0).r;
            }
            // The last step ends at the box exit: correct its opacity for its length.
            let len = min(dt, t_exit - t);
            let rgb = shade(rgba.rgb, uvw, -dir, t - cut_t <= CUT_SHELL * p.voxel_uvw.w);
            if pending && t_surf < t + len {
                // The surface cuts this step: the part before it, the surface, then (if
                // it is translucent) the part behind it, each for its true length.
                let before = max(t_surf - t, 0.0);
                acc = over(acc, rgb, 1.0 - pow(1.0 - rgba.a, before / dt));
                acc = over(acc, surf.rgb, surf.a);
                pending = false;
                if surf.a >= 1.0 {
                    break;
                }
                acc = over(acc, rgb, 1.0 - pow(1.0 - rgba.a, (len - before) / dt));
            } else {
                if len < dt {
                    rgba.a = 1.0 - pow(1.0 - rgba.a, len / dt);
                }
                acc = vec4<f32>(acc.rgb + (1.0 - acc.a) * rgba.a * rgb, acc.a + (1.0 - acc.a) * rgba.a);
            }
            if PICK && acc.a >= PICK_OPACITY {
                picked = vec4<f32>(origin + dir * t, 1.0);
                break;
            }
            if acc.a > OPAQUE {
                break;
            }
            k = k + 1u;
        }
    }
    if pending {
        // Behind the volume (or the ray missed the box).
        acc = over(acc, surf.rgb, surf.a);
    }
    let bg = p.background;
    let alpha = acc.a + (1.0 - acc.a) * bg.a;
    var rgb = acc.rgb + (1.0 - acc.a) * bg.a * bg.rgb;
    if alpha > 0.0 {
        rgb = rgb / alpha;
    }
    textureStore(out_image, vec2<u32>(gid.xy), vec4<f32>(clamp(rgb, vec3<f32>(0.0), vec3<f32>(1.0)), alpha));
}
