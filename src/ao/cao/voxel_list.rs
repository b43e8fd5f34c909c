//! The voxel list of a CAO frame's step V ([`super::listed`]): its buffer, the
//! gathering and listed ray-cast pipelines and the bind groups that read it. What CAO
//! does with them is in `listed.rs`; nothing here knows CAO's own types.

use crate::gpu::dispatch::Pass;
use crate::gpu::{
    Gpu, GpuError, compute_pipeline, shaders, specialised_pipeline, uniform_group, validated,
};

/// A pass's pipeline, bind group and uniforms (the caller makes the [`Pass`]).
pub(super) type Parts<'a> = (
    &'a str,
    &'a wgpu::ComputePipeline,
    &'a wgpu::BindGroup,
    &'a wgpu::Buffer,
);

/// The [`Pass`] of `parts`, binding `group` (`&parts.2`).
pub(super) fn pass<'a>(parts: &Parts<'a>, group: &'a [(u32, &'a wgpu::BindGroup)]) -> Pass<'a> {
    Pass {
        label: parts.0,
        pipeline: parts.1,
        bind_groups: group,
        uniforms: parts.3,
    }
}

/// The most the list may take, in bytes per voxel of the volume (on top of the 6 of the
/// CAO volumes): room for a quarter of the voxels.
pub const MAX_LIST_BYTES_PER_VOXEL: u64 = 1;

/// The list's entries, dispatched in groups of this many (like a brick of 8³ voxels).
pub(super) const GROUP: u32 = 512;

/// The gathering and listed ray-cast pipelines, built with CAO's.
#[derive(Debug)]
pub(super) struct ListedPipelines {
    pub(super) gather: wgpu::ComputePipeline,
    pub(super) trace: wgpu::ComputePipeline,
}

impl ListedPipelines {
    /// `swaps` chooses the CAO volumes' format in the shaders (`cao_format.wgsl`).
    pub(super) fn create(
        device: &wgpu::Device,
        swaps: shaders::Swaps<'_>,
    ) -> Result<Self, GpuError> {
        let gather = shaders::module(device, "cao_gather.wgsl")?;
        let trace = shaders::module_swapping(device, "cao_listed.wgsl", swaps)?;
        let readable = crate::ao::sparse::READABLE;
        validated(device, "CaoPipelines::listed", || ListedPipelines {
            gather: compute_pipeline(device, "Cao::gather", &gather, "main", None),
            trace: specialised_pipeline(device, "Cao::listed", &trace, None, readable, "main"),
        })
    }
}

/// What the listed passes bind besides the list itself.
pub(super) struct Bound<'a> {
    pub v_o: &'a wgpu::TextureView,
    pub v_ao: &'a wgpu::TextureView,
    pub sampler: &'a wgpu::Sampler,
    pub rays: &'a wgpu::Buffer,
    pub occupied: &'a wgpu::Buffer,
    pub bricks: &'a wgpu::Buffer,
    pub counters: &'a wgpu::Buffer,
}

/// The list and the bind groups that read it.
#[derive(Debug)]
pub(super) struct VoxelList {
    /// Entries it holds.
    pub(super) capacity: u32,
    pub(super) gather: (wgpu::Buffer, wgpu::BindGroup),
    pub(super) trace: (wgpu::Buffer, wgpu::BindGroup),
}

impl VoxelList {
    pub(super) fn new<P: bytemuck::Pod>(
        gpu: &Gpu,
        pipelines: &ListedPipelines,
        bound: &Bound<'_>,
        params: &P,
        capacity: u32,
    ) -> Self {
        let list = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("Cao::listed"),
            size: 4 * capacity.max(1) as u64,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        // Both passes read the list and the same uniforms, each with its own bind group.
        let group = |label, pipeline, resources: &[wgpu::BindingResource<'_>]| {
            uniform_group(gpu, label, pipeline, params, resources)
        };
        let v_ao = wgpu::BindingResource::TextureView(bound.v_ao);
        let gather = group(
            "Cao::gather",
            &pipelines.gather,
            &[
                v_ao.clone(),
                bound.bricks.as_entire_binding(),
                bound.counters.as_entire_binding(),
                list.as_entire_binding(),
            ],
        );
        let trace = group(
            "Cao::listed",
            &pipelines.trace,
            &[
                wgpu::BindingResource::TextureView(bound.v_o),
                wgpu::BindingResource::Sampler(bound.sampler),
                bound.rays.as_entire_binding(),
                v_ao,
                bound.occupied.as_entire_binding(),
                list.as_entire_binding(),
            ],
        );
        VoxelList {
            capacity,
            gather,
            trace,
        }
    }
}
