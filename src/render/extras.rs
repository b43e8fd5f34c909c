//! What the ray caster binds in its group 2 beyond the core volume (group 0) and the
//! clip shapes (group 1): live positional AO, the light volume of shadows and the
//! rasterised surfaces, with stand-ins bound where a feature is off so one pipeline
//! serves every case. Keep in sync with `struct Extras` and the group-2 bindings of
//! `shaders/raycast.wgsl`.

use crate::gpu::bind_group;
use glam::Vec3;

/// What the ray caster reads in its bind group 1 beyond the core volume: live positional
/// AO and the light volume. Owned by [`crate::render::gpu::RenderVolume`]; `None` = off.
#[derive(Debug, Default)]
pub struct RayExtras {
    pub live_vao: Option<crate::ao::vao::VaoInputs>,
    pub light: Option<GpuLight>,
    /// Geometry drawn inside the volume (rasterised per frame, see `render::surface`).
    pub surfaces: Vec<crate::render::surface::Surface>,
}

/// A light volume on the GPU (R16Float) with its direction.
#[derive(Debug)]
pub struct GpuLight {
    pub view: wgpu::TextureView,
    /// Unit direction towards the light.
    pub direction: Vec3,
}

/// Uniforms of the ray caster's group 1. Mirrors `struct Extras` in `raycast.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ExtrasParams {
    /// Live positional AO on, shadows on, surfaces on (0/1).
    pub flags: [u32; 4],
    /// Unit direction towards the light; w: the shadow lookup's guard limit in voxels
    /// ([`crate::render::shadow::GUARD_VOXELS`]).
    pub light: [f32; 4],
    /// A visibility pass's footprint ([`crate::ao::view::Footprint::code`]); yzw unused.
    pub marks: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<ExtrasParams>() == 48);

impl RayExtras {
    pub fn params(&self) -> ExtrasParams {
        let d = self.light.as_ref().map_or(Vec3::Z, |l| l.direction);
        ExtrasParams {
            flags: [
                u32::from(self.live_vao.is_some()),
                u32::from(self.light.is_some()),
                u32::from(!self.surfaces.is_empty()),
                0,
            ],
            light: [d.x, d.y, d.z, crate::render::shadow::GUARD_VOXELS],
            marks: [0; 4],
        }
    }
}

/// Stand-ins bound when a feature of group 1 is off (so one pipeline serves all cases).
#[derive(Debug)]
pub struct Placeholders {
    uniform: wgpu::Buffer,
    /// A filterable float 3-D texel: any such binding that is off (group 2's, and the
    /// gradient volume's in group 0).
    pub(super) texture: wgpu::TextureView,
    storage: wgpu::Buffer,
    /// Where a pipeline that is not a visibility pass "marks" (it never does): its own
    /// buffer, as it is bound read-write beside `storage` read-only.
    marks: wgpu::Buffer,
    layer: wgpu::TextureView,
}

impl Placeholders {
    pub fn new(device: &wgpu::Device) -> Self {
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let texel = |label, dimension, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: crate::gpu::extent([1, 1, 1]),
                mip_level_count: 1,
                sample_count: 1,
                dimension,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        };
        let texture = texel(
            "RayCaster::placeholder_3d",
            wgpu::TextureDimension::D3,
            wgpu::TextureFormat::R16Float,
        );
        Placeholders {
            uniform: buffer(
                "RayCaster::placeholder_uniform",
                std::mem::size_of::<crate::ao::vao::VaoParams>() as u64,
                wgpu::BufferUsages::UNIFORM,
            ),
            texture: texture.create_view(&Default::default()),
            storage: buffer(
                "RayCaster::placeholder_storage",
                16,
                wgpu::BufferUsages::STORAGE,
            ),
            marks: buffer(
                "RayCaster::placeholder_marks",
                16,
                wgpu::BufferUsages::STORAGE,
            ),
            layer: texel(
                "RayCaster::placeholder_2d",
                wgpu::TextureDimension::D2,
                crate::render::surface::LAYER_FORMAT,
            )
            .create_view(&Default::default()),
        }
    }
}

/// Layout entries of the ray caster's group 1: positional AO (0–4), extras uniform (5),
/// light volume (6), surface position and colour (7, 8), positional AO's segmentation
/// look (9), a visibility pass's marks (10, [`crate::ao::view`]).
pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    use crate::gpu::entry;
    use wgpu::TextureViewDimension::{D2, D3};
    let c = wgpu::ShaderStages::COMPUTE;
    let mut entries = crate::ao::vao::layout_entries();
    entries.push(entry::uniform(5, c));
    entries.push(entry::texture(6, c, D3, Some(true)));
    entries.push(entry::texture(7, c, D2, Some(false)));
    entries.push(entry::texture(8, c, D2, Some(false)));
    entries.push(entry::texture(9, c, D3, Some(true)));
    entries.push(entry::storage(10, c, false));
    entries
}

/// The ray caster's bind group 1 for `extras` (placeholders where a feature is off);
/// `layer` is this frame's rasterised surfaces, `marks` a visibility pass's bits.
pub fn bind_group_2(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    extras: &RayExtras,
    uniforms: &wgpu::Buffer,
    (layer, marks): (
        Option<&crate::render::surface::SurfaceLayer>,
        Option<&wgpu::Buffer>,
    ),
    placeholders: &Placeholders,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    let mut resources = match &extras.live_vao {
        Some(v) => v.resources(),
        None => vec![
            placeholders.uniform.as_entire_binding(),
            wgpu::BindingResource::TextureView(&placeholders.texture),
            wgpu::BindingResource::Sampler(sampler),
            placeholders.storage.as_entire_binding(),
            placeholders.storage.as_entire_binding(),
        ],
    };
    resources.push(uniforms.as_entire_binding());
    resources.push(wgpu::BindingResource::TextureView(
        extras
            .light
            .as_ref()
            .map_or(&placeholders.texture, |l| &l.view),
    ));
    resources.push(wgpu::BindingResource::TextureView(
        layer.map_or(&placeholders.layer, |l| &l.position),
    ));
    resources.push(wgpu::BindingResource::TextureView(
        layer.map_or(&placeholders.layer, |l| &l.color),
    ));
    resources.push(wgpu::BindingResource::TextureView(
        extras
            .live_vao
            .as_ref()
            .map_or(&placeholders.texture, |v| v.segment_weight()),
    ));
    resources.push(marks.unwrap_or(&placeholders.marks).as_entire_binding());
    bind_group(device, "RayCaster::bind_group_2", layout, &resources)
}
