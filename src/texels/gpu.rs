//! One volume on the GPU, as every stage reads it: [`GpuVolume`] holds the density
//! texture, the occupancy blocks and their texel ranges, and the transfer function
//! baked into a table (for the frame's step, and for another step the viewer's
//! interactive images use). The ray caster's own inputs beside it (AO, modulation,
//! gradient, live positional AO, light, surfaces) are `render::gpu::RenderVolume`'s; the
//! AO stages read this alone.

use super::segments::{GpuSegments, SegmentTexels};
use super::{BlockRanges, UploadLimits, VolumeTexels};
use crate::gpu::{Gpu, GpuError, filled_texture_3d, validated};
use crate::sample::bake_lut;
use crate::tf::{Lut, TransferFunction};

/// One volume on the GPU with its transfer function baked.
#[derive(Debug)]
pub struct GpuVolume {
    pub texels: VolumeTexels,
    ranges: BlockRanges,
    volume_view: wgpu::TextureView,
    occupancy: wgpu::Texture,
    /// One texel per occupancy block: whether a sample in it may have opacity.
    pub occupancy_view: wgpu::TextureView,
    /// (min, max) of `norm` per occupancy block: the projection and iso modes' skip test.
    pub block_range_view: wgpu::TextureView,
    /// The baked table on the GPU (RGBA, alpha corrected for `lut_step`).
    pub lut_buffer: wgpu::Buffer,
    /// The baked LUT currently on the GPU.
    pub lut: Lut,
    lut_step: f32,
    /// The same transfer function baked for another step ([`Self::prepare_step`]), and
    /// the transfer function's generation it was baked in.
    step_lut: Option<(f32, u64, wgpu::Buffer)>,
    tf: TransferFunction,
    /// Changes whenever the transfer function is baked anew.
    tf_generation: u64,
    /// The segmentation every stage reads beside the density ([`GpuSegments::none`]
    /// without one).
    pub segments: GpuSegments,
    /// Its classes and looks on the texel grid (the CPU twins read them).
    pub segment_texels: Option<SegmentTexels>,
}

/// A fresh generation number, unique across volumes (what a table baked for another
/// step compares to know it is stale).
fn next_generation() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl GpuVolume {
    /// Uploads a volume (halving it until it fits the adapter) with a transfer function
    /// baked for `step_voxels`.
    pub fn new(
        gpu: &Gpu,
        volume: &crate::volume::Volume,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let texels = VolumeTexels::new(volume, UploadLimits::of(gpu));
        Self::for_compute(gpu, texels, tf, step_voxels)
    }

    /// Uploads `texels`: the density, the occupancy blocks and their ranges, and the
    /// transfer function baked for `step_voxels`.
    pub fn for_compute(
        gpu: &Gpu,
        texels: VolumeTexels,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let (device, queue) = (&gpu.device, &gpu.queue);
        let dims = texels.dims.map(|d| d as u32);
        let ranges = BlockRanges::new(&texels);
        let lut = bake_lut(tf, &texels, step_voxels);
        let occ = ranges.occupancy(&texels, &lut);
        let grid = ranges.grid.map(|d| d as u32);
        validated(device, "GpuVolume::upload", || {
            let volume = filled_texture_3d(
                device,
                queue,
                "GpuVolume::volume",
                dims,
                texels.format.wgpu(),
                &texels.bytes,
            );
            let occupancy = filled_texture_3d(
                device,
                queue,
                "GpuVolume::occupancy",
                grid,
                wgpu::TextureFormat::R8Uint,
                &occ,
            );
            let range_texels: Vec<[f32; 2]> = ranges.ranges.iter().map(|&(a, b)| [a, b]).collect();
            let block_range = filled_texture_3d(
                device,
                queue,
                "GpuVolume::block_range",
                grid,
                wgpu::TextureFormat::Rg32Float,
                bytemuck::cast_slice(&range_texels),
            );
            let lut_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("GpuVolume::lut"),
                size: (lut.rgba.len() * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&lut_buffer, 0, bytemuck::cast_slice(&lut.rgba));
            GpuVolume {
                volume_view: volume.create_view(&Default::default()),
                occupancy_view: occupancy.create_view(&Default::default()),
                block_range_view: block_range.create_view(&Default::default()),
                occupancy,
                lut_buffer,
                lut,
                lut_step: step_voxels,
                step_lut: None,
                tf: tf.clone(),
                tf_generation: next_generation(),
                segments: GpuSegments::none(gpu),
                segment_texels: None,
                ranges,
                texels,
            }
        })
    }

    /// Bakes the transfer function for frames of `step_voxels` too, unless it is the
    /// step of [`Self::set_transfer_function`] or was baked already: frames of either
    /// step then composite with opacity corrected for their own step. The occupancy
    /// grid stays valid (a step changes no opacity from zero to non-zero or back).
    pub fn prepare_step(&mut self, gpu: &Gpu, step_voxels: f32) {
        let baked = |l: &(f32, u64, wgpu::Buffer)| (l.0, l.1) == (step_voxels, self.tf_generation);
        if step_voxels == self.lut_step || self.step_lut.as_ref().is_some_and(baked) {
            return;
        }
        let lut = bake_lut(&self.tf, &self.texels, step_voxels);
        let buffer = match self.step_lut.take() {
            Some((_, _, b)) if b.size() == (lut.rgba.len() * 16) as u64 => b,
            _ => gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("GpuVolume::step_lut"),
                size: (lut.rgba.len() * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        gpu.queue
            .write_buffer(&buffer, 0, bytemuck::cast_slice(&lut.rgba));
        self.step_lut = Some((step_voxels, self.tf_generation, buffer));
    }

    /// The LUT buffer for frames of `step_voxels`: the one baked by
    /// [`Self::prepare_step`] for it, else the transfer function's own.
    pub fn lut_buffer_for(&self, step_voxels: f32) -> &wgpu::Buffer {
        match &self.step_lut {
            Some((step, generation, buffer))
                if *step == step_voxels
                    && *generation == self.tf_generation
                    && step_voxels != self.lut_step =>
            {
                buffer
            }
            _ => &self.lut_buffer,
        }
    }

    /// Re-bakes the transfer function (and the skip grid) if it or the step changed;
    /// whether it did.
    pub fn set_transfer_function(
        &mut self,
        gpu: &Gpu,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> bool {
        if *tf == self.tf && step_voxels == self.lut_step {
            return false;
        }
        self.tf_generation = next_generation();
        self.lut = bake_lut(tf, &self.texels, step_voxels);
        self.tf = tf.clone();
        self.lut_step = step_voxels;
        gpu.queue
            .write_buffer(&self.lut_buffer, 0, bytemuck::cast_slice(&self.lut.rgba));
        self.write_occupancy(gpu);
        true
    }

    /// Writes the occupancy grid of the transfer function and the segmentation.
    fn write_occupancy(&self, gpu: &Gpu) {
        let grid = self.ranges.grid.map(|d| d as u32);
        crate::gpu::write_texture_3d(&gpu.queue, &self.occupancy, 0, grid, 1, &self.occupancy());
    }

    /// Sets the segmentation every stage reads beside the density (`None`: none). One on
    /// the volume's grid before halving is subsampled to the texels'. Only the looks and
    /// the table are written when the classes stay; whether anything changed.
    pub fn set_segments(&mut self, gpu: &Gpu, segments: Option<SegmentTexels>) -> bool {
        let Some(s) = segments else {
            let had = self.segment_texels.take().is_some();
            if had {
                self.segments = GpuSegments::none(gpu);
                self.write_occupancy(gpu);
            }
            return had;
        };
        let s = if s.dims == self.texels.dims {
            s
        } else {
            s.subsampled(self.texels.dims, 1 << self.texels.downsampled)
        };
        match &self.segment_texels {
            Some(old) if old.classes == s.classes => {
                if old.table == s.table {
                    return false;
                }
                self.segments.update(gpu, &s);
            }
            _ => self.segments = GpuSegments::new(gpu, &s),
        }
        self.segment_texels = Some(s);
        self.write_occupancy(gpu);
        true
    }

    /// The volume texture (for compute passes such as LAO).
    pub fn volume_view(&self) -> &wgpu::TextureView {
        &self.volume_view
    }

    /// Per-block texel ranges (the occupancy grid's and sparse AO's source).
    pub fn ranges(&self) -> &BlockRanges {
        &self.ranges
    }

    /// The occupancy grid for the current LUT and segmentation: blocks where every
    /// voxel a sample reads is hidden are empty too.
    pub fn occupancy(&self) -> Vec<u8> {
        let mut occ = self.ranges.occupancy(&self.texels, &self.lut);
        if let Some(s) = &self.segment_texels {
            for (o, shown) in occ.iter_mut().zip(s.shown_blocks(self.ranges.edge)) {
                *o &= u8::from(shown);
            }
        }
        occ
    }
}
