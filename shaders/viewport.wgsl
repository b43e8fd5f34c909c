// The viewer's viewport: draws the ray caster's Rgba8Unorm image 1:1 into the egui paint
// callback's viewport (one texel per framebuffer pixel, no filtering), so the window
// shows exactly the pixels `volao render` writes for the same frame. An image of
// another size (interactive quality while the view moves) is scaled with bilinear
// filtering (`fs_scaled*`).

@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var filtered: sampler;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

// One triangle covering the viewport; uv is (0, 0) at its top-left corner.
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VsOut {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VsOut;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// Straight RGBA over a dark grey (only visible where the background is transparent);
// opaque pixels pass through unchanged.
fn over_grey(c: vec4<f32>) -> vec4<f32> {
    let grey = vec3<f32>(0.12);
    return vec4<f32>(c.rgb * c.a + grey * (1.0 - c.a), 1.0);
}

fn texel(uv: vec2<f32>) -> vec4<f32> {
    let size = textureDimensions(image);
    let p = min(vec2<u32>(uv * vec2<f32>(size)), size - vec2<u32>(1u));
    return over_grey(textureLoad(image, p, 0));
}

fn scaled(uv: vec2<f32>) -> vec4<f32> {
    return over_grey(textureSampleLevel(image, filtered, uv, 0.0));
}

// Render target without sRGB encoding (egui's usual one): copy the stored values.
@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    return texel(in.uv);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

// sRGB render target: the hardware encodes on write, so decode first to store the same
// 8-bit values.
@fragment
fn fs_srgb(in: VsOut) -> @location(0) vec4<f32> {
    let c = texel(in.uv);
    return vec4<f32>(srgb_to_linear(c.rgb), c.a);
}

@fragment
fn fs_scaled(in: VsOut) -> @location(0) vec4<f32> {
    return scaled(in.uv);
}

@fragment
fn fs_scaled_srgb(in: VsOut) -> @location(0) vec4<f32> {
    let c = scaled(in.uv);
    return vec4<f32>(srgb_to_linear(c.rgb), c.a);
}

// Opaque black (the slice panes' margins around a letterboxed image).
@fragment
fn fs_black() -> @location(0) vec4<f32> {
    return vec4<f32>(0.0, 0.0, 0.0, 1.0);
}
