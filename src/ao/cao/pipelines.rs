//! CAO's pipelines, built once per device: step IV (by the number of clip shapes) and
//! step V, with skipping and dense.

use super::voxel_list::ListedPipelines;
use crate::ao::sparse::{self, Bricks};
use crate::gpu::shaders::{self, Constants, Swaps};
use crate::gpu::{GpuError, specialised_pipeline, validated};

/// CAO's pipelines and sampler, built once per device.
#[derive(Debug)]
pub struct CaoPipelines {
    /// Step IV, and its dense variant (`--no-skipping`: every voxel tests its corners).
    clip: ClipPipelines,
    clip_dense: ClipPipelines,
    /// The same reading a segmentation (`SEGMENTS`: segment-aware carving), built when
    /// a volume with one first needs them ([`Self::prepare_segments`]).
    segment_clip: [std::sync::OnceLock<ClipPipelines>; 2],
    clip_module: wgpu::ShaderModule,
    clip_layout: wgpu::PipelineLayout,
    /// Step V with skipping, and its dense variant (`--no-skipping`).
    lao: wgpu::ComputePipeline,
    lao_dense: wgpu::ComputePipeline,
    /// `V_PAO` of readable voxels only: every ray sample fetched.
    lao_readable: wgpu::ComputePipeline,
    /// Step V of a frame with skipping: readable voxels, every ray sample fetched.
    lao_frame: wgpu::ComputePipeline,
    /// A frame's step V over a list of its voxels.
    pub(super) listed: ListedPipelines,
    pub(super) sampler: wgpu::Sampler,
    /// The volume reader's group of step IV (`volume.wgsl`).
    pub(super) volume_layout: wgpu::BindGroupLayout,
    /// The format of `V_o`, `V_PAO` and `V_AO`: R16Float (2 bytes per voxel each) where
    /// the adapter can write it from a shader, else R32Float.
    pub(super) format: wgpu::TextureFormat,
}

/// Step IV's pipelines by the number of clip shapes they are built for (`CLIP_SHAPES` of
/// `clip_common.wgsl`, a constant bound that lavapipe unrolls: step IV about 20 %
/// faster with skipping, 45 % without): index 0 reads the number from the uniforms (any
/// number), 1 and 2 are built for that many. All share one explicit layout, so one set
/// of bind groups serves them all.
#[derive(Debug)]
pub(super) struct ClipPipelines([wgpu::ComputePipeline; 3]);

impl ClipPipelines {
    /// The one layout of every step IV pipeline (`cao_clip.wgsl`'s groups 0 and 1), so
    /// that the bind groups made for one serve the others, skipping or dense.
    fn layout(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        volume: &wgpu::BindGroupLayout,
    ) -> wgpu::PipelineLayout {
        use crate::gpu::entry;
        use wgpu::TextureViewDimension::D3;
        let c = wgpu::ShaderStages::COMPUTE;
        let group_0 = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("Cao::clip"),
            entries: &[
                entry::uniform(0, c),
                entry::storage(1, c, true),
                entry::storage_texture(2, c, format, D3),
                entry::storage_texture(3, c, format, D3),
                entry::storage(4, c, false),
                entry::storage(5, c, true),
                entry::texture(6, c, D3, Some(false)),
                entry::storage(7, c, true),
            ],
        });
        let group_1 = crate::clip::gpu::bind_group_layout(device);
        device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("Cao::clip"),
            bind_group_layouts: &[Some(&group_0), Some(&group_1), None, Some(volume)],
            immediate_size: 0,
        })
    }

    fn new(
        device: &wgpu::Device,
        label: &str,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        variant: Constants,
    ) -> Self {
        let built_for = |shapes: u32| {
            let mut constants = vec![("CLIP_SHAPES", f64::from(shapes))];
            constants.extend_from_slice(variant);
            specialised_pipeline(device, label, module, Some(layout), &constants, "main")
        };
        ClipPipelines([built_for(0), built_for(1), built_for(2)])
    }

    /// The pipeline for `shapes` clip shapes.
    pub(super) fn for_shapes(&self, shapes: u32) -> &wgpu::ComputePipeline {
        self.0.get(shapes as usize).unwrap_or(&self.0[0])
    }

    /// The one whose layouts the bind groups are made with.
    pub(super) fn any(&self) -> &wgpu::ComputePipeline {
        &self.0[0]
    }
}

impl crate::gpu::Stage for CaoPipelines {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        let build = |format: wgpu::TextureFormat| -> Result<Self, GpuError> {
            let swaps: Swaps<'_> = match format {
                wgpu::TextureFormat::R16Float => &[],
                _ => &[("cao_format.wgsl", "cao_format_r32.wgsl")],
            };
            let clip_module = shaders::module_swapping(device, "cao_clip.wgsl", swaps)?;
            let lao_module = shaders::module_swapping(device, "cao_lao.wgsl", swaps)?;
            let lao = |label: &str, constants: Constants| {
                specialised_pipeline(device, label, &lao_module, None, constants, "main")
            };
            let listed = ListedPipelines::create(device, swaps)?;
            let volume_layout = crate::texels::reader::layout(device);
            let clip_layout = ClipPipelines::layout(device, format, &volume_layout);
            let clip = |label: &str, constants: Constants| {
                ClipPipelines::new(device, label, &clip_module, &clip_layout, constants)
            };
            validated(device, "CaoPipelines::create", || CaoPipelines {
                clip: clip("Cao::clip", &[]),
                clip_dense: clip("Cao::clip_dense", sparse::DENSE_CLIP),
                segment_clip: Default::default(),
                lao: lao("Cao::lao", &[]),
                lao_dense: lao("Cao::lao_dense", sparse::DENSE),
                lao_readable: lao("Cao::lao_readable", sparse::READABLE),
                lao_frame: lao("Cao::lao_frame", sparse::FRAME),
                listed,
                clip_module: clip_module.clone(),
                clip_layout: clip_layout.clone(),
                volume_layout,
                sampler: crate::gpu::linear_sampler(device, "Cao::linear_clamp"),
                format,
            })
        };
        let narrow = device
            .features()
            .contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
        match narrow && std::env::var_os("VOLAO_CAO_F32").is_none() {
            true => build(wgpu::TextureFormat::R16Float)
                .or_else(|_| build(wgpu::TextureFormat::R32Float)),
            false => build(wgpu::TextureFormat::R32Float),
        }
    }
}

impl CaoPipelines {
    /// Builds step IV's pipelines that read a segmentation, unless built already.
    pub(super) fn prepare_segments(&self, device: &wgpu::Device) -> Result<(), GpuError> {
        let variants: [(&str, Constants); 2] = [
            ("Cao::clip_segments", &[("SEGMENTS", 1.0)]),
            (
                "Cao::clip_dense_segments",
                &[
                    ("SHARED_CORNERS", 0.0),
                    ("CENTRE_REACH", 0.0),
                    ("SEGMENTS", 1.0),
                ],
            ),
        ];
        for (slot, (label, constants)) in self.segment_clip.iter().zip(variants) {
            if slot.get().is_none() {
                let built = validated(device, "CaoPipelines::prepare_segments", || {
                    ClipPipelines::new(
                        device,
                        label,
                        &self.clip_module,
                        &self.clip_layout,
                        constants,
                    )
                })?;
                let _ = slot.set(built);
            }
        }
        Ok(())
    }

    /// The dense step IV: the paper's mask, whatever the bricks; with `segments`, the
    /// one reading a segmentation ([`Self::prepare_segments`] first).
    pub(super) fn clip_dense(&self, segments: bool) -> &ClipPipelines {
        self.clip_variant(false, segments)
    }

    /// Step IV's pipelines for `bricks` (and a segmentation: `segments`).
    pub(super) fn clip_for(&self, bricks: &Bricks, segments: bool) -> &ClipPipelines {
        self.clip_variant(bricks.skipping, segments)
    }

    fn clip_variant(&self, skipping: bool, segments: bool) -> &ClipPipelines {
        let i = usize::from(!skipping);
        match (segments, self.segment_clip[i].get()) {
            (true, Some(built)) => built,
            (true, None) => panic!("CaoPipelines::prepare_segments was not called"),
            (false, _) if skipping => &self.clip,
            (false, _) => &self.clip_dense,
        }
    }

    /// Step V's pipeline for `bricks`, for `V_PAO` or (`frame`) for a frame.
    pub(super) fn lao_for(&self, bricks: &Bricks, frame: bool) -> &wgpu::ComputePipeline {
        match (bricks.skipping, frame) {
            (false, _) => &self.lao_dense,
            (true, true) => &self.lao_frame,
            (true, false) if sparse::readable_only(bricks) => &self.lao_readable,
            (true, false) => &self.lao,
        }
    }
}
