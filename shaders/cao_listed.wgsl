// CAO step V of a frame, second part (ao::cao::listed): the LAO ray cast (cao_ray.wgsl)
// of the voxels cao_gather.wgsl listed, one invocation per entry; entries come in groups
// of 512 dispatched like bricks (gpu::dispatch::BrickDispatch). The same `lao` as the
// ray cast over bricks (cao_lao.wgsl) and as `V_PAO`'s: CAO stays bit-exact.
// CPU twin: src/ao/cao/cpu.rs (`lao_on_opacity_cpu`).
//!include cao_ray.wgsl

//!include cao_params.wgsl
//!include cao_format.wgsl

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var v_o: texture_3d<f32>;
@group(0) @binding(2) var linear_clamp: sampler;
@group(0) @binding(3) var<storage, read> rays: array<vec4<f32>>;  // xyz direction, w weight
@group(0) @binding(4) var v_ao: CaoWrite;
@group(0) @binding(5) var<storage, read> occupied: array<u32>;
@group(0) @binding(6) var<storage, read> listed: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let group = wid.y + wid.z * p.chunk.z;
    if group >= p.chunk.y {
        return;
    }
    let entry = (p.chunk.x + group) * 512u + lid.x + 8u * lid.y + 64u * wid.x;
    if entry >= p.counts.z {
        return;
    }
    let index = listed[entry];
    let plane = p.dims.x * p.dims.y;
    let v = vec3<u32>(index % p.dims.x, (index % plane) / p.dims.x, index / plane);
    textureStore(v_ao, vec3<i32>(v), vec4<f32>(lao(v), 0.0, 0.0, 1.0));
}
