// Depth peeling of one clip mesh from its clipping camera (CAO paper §3.4 step II):
// depth-only passes, front faces then back faces, each keeping the nearest surface
// strictly behind the previous layer: Z_front1, Z_back1, Z_front2, Z_back2.

struct Peel {
    projection: mat4x4<f32>, // shape space → clip space
    flags: vec4<u32>,        // x: 1 = discard fragments not behind `previous`
}

@group(0) @binding(0) var<uniform> peel: Peel;
@group(0) @binding(1) var previous: texture_depth_2d;

@vertex
fn vs(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return peel.projection * vec4<f32>(position, 1.0);
}

@fragment
fn fs(@builtin(position) frag: vec4<f32>) {
    if peel.flags.x != 0u {
        let before = textureLoad(previous, vec2<i32>(floor(frag.xy)), 0);
        if frag.z <= before {
            discard;
        }
    }
}
