// Opaque or translucent triangle meshes inside the volume (Imagire et al.'s valid
// sampling path): rasterised from the view camera into the nearest surface's position
// and shaded colour per pixel; the ray caster stops (or composites) exactly there.
// CPU twin: src/render/surface.rs (`nearest_hit`).

struct Params {
    view_proj: mat4x4<f32>,  // volume-centred mm → clip space, as the ray caster's camera
    eye: vec4<f32>,          // perspective: eye position, w = 1; orthographic: towards the eye, w = 0
}

@group(0) @binding(0) var<uniform> p: Params;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) normal: vec3<f32>,
    @location(2) @interpolate(flat) color: vec4<f32>,
}

struct Targets {
    @location(0) position: vec4<f32>,  // xyz volume-centred mm, w = 1 where covered
    @location(1) color: vec4<f32>,     // shaded straight RGBA
}

@vertex
fn vs(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = p.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.color = v.color;
    return out;
}

// Two-sided headlight: rgb · (¼ + ¾ |n · v|).
@fragment
fn fs(v: VertexOut) -> Targets {
    var view = p.eye.xyz;
    if p.eye.w != 0.0 {
        view = normalize(p.eye.xyz - v.world);
    }
    let lit = 0.25 + 0.75 * abs(dot(v.normal, view));
    var out: Targets;
    out.position = vec4<f32>(v.world, 1.0);
    out.color = vec4<f32>(v.color.rgb * lit, v.color.a);
    return out;
}
