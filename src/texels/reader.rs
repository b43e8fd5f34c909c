//! What a GPU stage binds to read the volume: bind group [`VOLUME_GROUP`] of every shader
//! that includes `shaders/volume.wgsl` (its `value_at`, `opacity_at`, `classify`, …) —
//! the texel texture, its sampler, the [`VolumeMap`] and the transfer function's table,
//! and a segmentation beside them ([`super::segments::GpuSegments`], bindings 4–6). A
//! page table for bricked volumes is one more binding here.

use super::gpu_data::VolumeMap;
use super::segments::GpuSegments;
use crate::gpu::{Gpu, entry, storage_buffer, uniform_buffer};
use crate::tf::Lut;

/// The bind group index of the volume reader in every shader that includes it.
pub const VOLUME_GROUP: u32 = 3;

/// The layout of the reader's group (pooled by wgpu: every pipeline with an explicit
/// layout that includes it accepts the same bind groups).
pub fn layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    use wgpu::TextureViewDimension::D3;
    let c = wgpu::ShaderStages::COMPUTE;
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("VolumeReader::layout"),
        entries: &[
            entry::texture(0, c, D3, Some(true)),
            entry::sampler(1, c),
            entry::uniform(2, c),
            entry::storage(3, c, true),
            entry::texture(4, c, D3, Some(true)),
            entry::texture(5, c, D3, None),
            entry::storage(6, c, true),
            entry::texture(7, c, D3, Some(true)),
        ],
    })
}

/// The transfer function's table as the reader binds it: one RGBA entry (straight
/// colour, opacity) per index.
pub fn table(gpu: &Gpu, label: &str, lut: &Lut) -> wgpu::Buffer {
    storage_buffer(
        gpu,
        label,
        bytemuck::cast_slice(&lut.rgba),
        wgpu::BufferUsages::COPY_DST,
    )
}

/// What one stage reads: a texture of texel values, and, where its shader uses them, how
/// to sample it between voxels and the map and table of its transfer function. A layout
/// derived from a shader holds only the bindings it uses: a stage that only loads
/// voxels (gradient, CAO's readable test) binds the texels alone.
#[derive(Debug)]
pub struct Reading<'a> {
    pub texels: &'a wgpu::TextureView,
    pub sampler: Option<&'a wgpu::Sampler>,
    pub lut: Option<(VolumeMap, &'a wgpu::Buffer)>,
    /// The segmentation's bindings its shader uses.
    pub segments: SegmentBindings<'a>,
}

/// Which of a segmentation's bindings a stage's shader uses (`volume.wgsl`): none (it
/// reads no opacity), the look (4: `opacity_at`, `opacity_of_voxel`), the look and the
/// cuts (4–6: `carved_by_*`) or all (4–7: `classify_at`, `segment_gradient_at`). Every pipeline binds them, with or without
/// `SEGMENTS`: without a segmentation they are [`GpuSegments::none`]'s.
#[derive(Debug, Clone, Copy)]
pub enum SegmentBindings<'a> {
    None,
    Look(&'a GpuSegments),
    Cuts(&'a GpuSegments),
    All(&'a GpuSegments),
}

impl<'a> Reading<'a> {
    /// Every binding: `texels` sampled with `sampler`, through `map` and `table`.
    pub fn sampled(
        texels: &'a wgpu::TextureView,
        sampler: &'a wgpu::Sampler,
        map: VolumeMap,
        table: &'a wgpu::Buffer,
        segments: SegmentBindings<'a>,
    ) -> Self {
        Reading {
            texels,
            sampler: Some(sampler),
            lut: Some((map, table)),
            segments,
        }
    }

    /// The reader's bind group for `layout` ([`layout`], or group [`VOLUME_GROUP`] of a
    /// pipeline whose layout is derived from its shader).
    pub fn bind_group(
        &self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        label: &str,
        layout: &wgpu::BindGroupLayout,
    ) -> wgpu::BindGroup {
        let map = self.lut.map(|(map, _)| {
            let label = format!("{label}::volume_map");
            uniform_buffer(device, queue, &label, bytemuck::bytes_of(&map))
        });
        let mut entries = vec![(0, wgpu::BindingResource::TextureView(self.texels))];
        if let Some(sampler) = self.sampler {
            entries.push((1, wgpu::BindingResource::Sampler(sampler)));
        }
        if let (Some(map), Some((_, table))) = (&map, self.lut) {
            entries.push((2, map.as_entire_binding()));
            entries.push((3, table.as_entire_binding()));
        }
        match self.segments {
            SegmentBindings::None => {}
            SegmentBindings::Look(s) => {
                entries.push((4, wgpu::BindingResource::TextureView(&s.look_view)));
            }
            SegmentBindings::Cuts(s) | SegmentBindings::All(s) => {
                entries.push((4, wgpu::BindingResource::TextureView(&s.look_view)));
                entries.push((5, wgpu::BindingResource::TextureView(&s.classes_view)));
                entries.push((6, s.table.as_entire_binding()));
                if let SegmentBindings::All(_) = self.segments {
                    entries.push((7, wgpu::BindingResource::TextureView(&s.gradient_view)));
                }
            }
        }
        let entries: Vec<_> = entries
            .into_iter()
            .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{label}::volume")),
            layout,
            entries: &entries,
        })
    }

    /// The bind group for `pipeline`'s group [`VOLUME_GROUP`] (a layout derived from its
    /// shader).
    pub fn group_of(
        &self,
        gpu: &Gpu,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
    ) -> wgpu::BindGroup {
        let layout = pipeline.get_bind_group_layout(VOLUME_GROUP);
        self.bind_group((&gpu.device, &gpu.queue), label, &layout)
    }
}
