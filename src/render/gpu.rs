//! The GPU ray caster: [`RayCaster`] holds what lives as long as the device (pipeline,
//! layout, sampler); [`GpuVolume`] holds one volume's textures and its transfer function;
//! a [`Frame`] is all that changes per frame.

use super::texels::{BlockRanges, UploadLimits, VolumeTexels};
use super::{Frame, Image};
use crate::gpu::{
    Gpu, GpuError, bind_group, padded_row_bytes, read_buffer, readback_buffer, shaders,
    uniform_buffer, validated,
};
use crate::tf::{Lut, TransferFunction, correct_opacity};

/// Largest tile rendered in one submission: keeps each dispatch short (no driver
/// watchdog on real GPUs) and lets any image size fit the 2-D texture limit.
pub const TILE: u32 = 2048;

/// Bytes of voxels we upload before halving the resolution.
pub const MAX_VOLUME_BYTES: u64 = 2 << 30;

/// Long-lived ray-casting state: built once per device.
#[derive(Debug)]
pub struct RayCaster {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    clip_layout: wgpu::BindGroupLayout,
    /// `@group(1)` with no clip shapes (zeroed uniforms, a blank map).
    no_clip: wgpu::BindGroup,
    sampler: wgpu::Sampler,
    /// Group 2: live positional AO and shadows (`render::shadow`).
    layout_2: wgpu::BindGroupLayout,
    placeholders: super::shadow::Placeholders,
    surfaces: super::surface::SurfaceRenderer,
}

/// One volume on the GPU with its transfer function baked.
#[derive(Debug)]
pub struct GpuVolume {
    pub texels: VolumeTexels,
    ranges: BlockRanges,
    volume_view: wgpu::TextureView,
    ao_view: wgpu::TextureView,
    modulation_view: wgpu::TextureView,
    occupancy: wgpu::Texture,
    occupancy_view: wgpu::TextureView,
    lut_buffer: wgpu::Buffer,
    /// The baked LUT currently on the GPU (alpha corrected for `lut_step`).
    pub lut: Lut,
    lut_step: f32,
    tf: TransferFunction,
    /// Live positional AO and the light volume (bind group 1), see `render::shadow`.
    pub extras: super::shadow::RayExtras,
}

fn texture_3d(
    device: &wgpu::Device,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: dims[2],
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

fn write_3d(
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    dims: [u32; 3],
    bytes_per_texel: u32,
    data: &[u8],
) {
    queue.write_texture(
        texture.as_image_copy(),
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(dims[0] * bytes_per_texel),
            rows_per_image: Some(dims[1]),
        },
        wgpu::Extent3d {
            width: dims[0],
            height: dims[1],
            depth_or_array_layers: dims[2],
        },
    );
}

/// Bakes `tf` over the texels' value range with opacity corrected for `step_voxels`.
pub fn bake_lut(tf: &TransferFunction, texels: &VolumeTexels, step_voxels: f32) -> Lut {
    let (a, b) = (
        texels.value_offset,
        texels.value_offset + texels.value_scale,
    );
    let (lo, hi) = (a.min(b), a.max(b));
    // Unorm texels span [lo, hi] exactly; float texels use the TF's own span, widened.
    let (lo, hi) = match texels.format {
        super::texels::TexelFormat::R32Float => {
            let (mn, mx) = texels.norm_range();
            let (mn, mx) = (mn as f64, mx as f64);
            if mx > mn {
                (mn, mx)
            } else {
                (mn - 0.5, mn + 0.5)
            }
        }
        _ => (lo, hi),
    };
    let mut lut = tf.bake(lo, hi, crate::tf::LUT_ENTRIES);
    for e in &mut lut.rgba {
        e[3] = correct_opacity(e[3], step_voxels);
    }
    lut
}

impl GpuVolume {
    /// Uploads a volume (halving it until it fits the adapter) with a transfer function.
    pub fn new(
        gpu: &Gpu,
        volume: &crate::volume::Volume,
        tf: &TransferFunction,
        step_voxels: f32,
    ) -> Result<Self, GpuError> {
        let limits = gpu.device.limits();
        let texels = VolumeTexels::new(
            volume,
            UploadLimits {
                max_dim: limits.max_texture_dimension_3d as usize,
                max_bytes: MAX_VOLUME_BYTES,
            },
        );
        Self::from_texels(gpu, texels, tf, step_voxels)
    }

    pub fn from_texels(
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
            let volume = texture_3d(device, "GpuVolume::volume", dims, texels.format.wgpu());
            write_3d(
                queue,
                &volume,
                dims,
                texels.format.bytes() as u32,
                &texels.bytes,
            );
            // No AO volume yet: a single texel of 1 makes A(x) = 1 everywhere.
            let ao = texture_3d(
                device,
                "GpuVolume::ambient_occlusion",
                [1, 1, 1],
                wgpu::TextureFormat::R32Float,
            );
            write_3d(queue, &ao, [1, 1, 1], 4, bytemuck::bytes_of(&1.0f32));
            let occupancy = texture_3d(
                device,
                "GpuVolume::occupancy",
                grid,
                wgpu::TextureFormat::R8Uint,
            );
            write_3d(queue, &occupancy, grid, 1, &occ);
            let lut_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("GpuVolume::lut"),
                size: (lut.rgba.len() * 16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&lut_buffer, 0, bytemuck::cast_slice(&lut.rgba));
            GpuVolume {
                volume_view: volume.create_view(&Default::default()),
                ao_view: ao.create_view(&Default::default()),
                modulation_view: no_modulation(device, queue),
                occupancy_view: occupancy.create_view(&Default::default()),
                occupancy,
                lut_buffer,
                lut,
                lut_step: step_voxels,
                tf: tf.clone(),
                extras: Default::default(),
                ranges,
                texels,
            }
        })
    }

    /// Re-bakes the transfer function (and the skip grid) if it or the step changed.
    pub fn set_transfer_function(&mut self, gpu: &Gpu, tf: &TransferFunction, step_voxels: f32) {
        if *tf == self.tf && step_voxels == self.lut_step {
            return;
        }
        self.lut = bake_lut(tf, &self.texels, step_voxels);
        self.tf = tf.clone();
        self.lut_step = step_voxels;
        if let Some(live) = &mut self.extras.live_vao {
            live.set_transfer_function(gpu, &self.texels, tf);
        }
        gpu.queue
            .write_buffer(&self.lut_buffer, 0, bytemuck::cast_slice(&self.lut.rgba));
        let occ = self.ranges.occupancy(&self.texels, &self.lut);
        write_3d(
            &gpu.queue,
            &self.occupancy,
            self.ranges.grid.map(|d| d as u32),
            1,
            &occ,
        );
    }

    /// The volume texture (for compute passes such as LAO).
    pub fn volume_view(&self) -> &wgpu::TextureView {
        &self.volume_view
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the ambient factor A(x).
    ///
    /// Stored as R32Float (filtered with `FLOAT32_FILTERABLE`), the format CAO's compute
    /// passes write, so a precomputed and a per-frame AO volume shade alike.
    pub fn set_ambient_occlusion(&mut self, gpu: &Gpu, values: &[f32]) {
        let dims = self.texels.dims.map(|d| d as u32);
        let texture = texture_3d(
            &gpu.device,
            "GpuVolume::ambient_occlusion",
            dims,
            wgpu::TextureFormat::R32Float,
        );
        write_3d(&gpu.queue, &texture, dims, 4, bytemuck::cast_slice(values));
        self.ao_view = texture.create_view(&Default::default());
    }

    /// Uses an AO volume already on the GPU (R32Float, the volume's dims), such as
    /// CAO's `V_AO`.
    pub fn set_ambient_occlusion_view(&mut self, view: &wgpu::TextureView) {
        self.ao_view = view.clone();
    }

    /// Back to no ambient occlusion (A = 1 everywhere), as right after upload. The viewer
    /// shows this while a new AO volume is computed for a changed transfer function.
    pub fn clear_ambient_occlusion(&mut self, gpu: &Gpu) {
        let ao = texture_3d(
            &gpu.device,
            "GpuVolume::ambient_occlusion",
            [1, 1, 1],
            wgpu::TextureFormat::R32Float,
        );
        write_3d(&gpu.queue, &ao, [1, 1, 1], 4, bytemuck::bytes_of(&1.0f32));
        self.ao_view = ao.create_view(&Default::default());
    }

    /// Drops the opacity modulation (factor 1 everywhere).
    pub fn clear_opacity_modulation(&mut self, gpu: &Gpu) {
        self.modulation_view = no_modulation(&gpu.device, &gpu.queue);
    }

    /// Uses `values` (one per voxel, x fastest, in [0, 1]) as the opacity factor of
    /// variance modulation. Stored as R16Unorm like the AO volume; returns the values as
    /// the GPU will sample them (for the CPU twin).
    pub fn set_opacity_modulation(&mut self, gpu: &Gpu, values: &[f32]) -> Vec<f32> {
        let dims = self.texels.dims.map(|d| d as u32);
        let quantised: Vec<u16> = values
            .iter()
            .map(|&a| (a.clamp(0.0, 1.0) * 65535.0).round() as u16)
            .collect();
        let texture = texture_3d(
            &gpu.device,
            "GpuVolume::opacity_modulation",
            dims,
            wgpu::TextureFormat::R16Unorm,
        );
        write_3d(
            &gpu.queue,
            &texture,
            dims,
            2,
            bytemuck::cast_slice(&quantised),
        );
        self.modulation_view = texture.create_view(&Default::default());
        quantised.iter().map(|&q| q as f32 / 65535.0).collect()
    }

    /// The occupancy grid for the current LUT (for the CPU twin).
    pub fn occupancy(&self) -> Vec<u8> {
        self.ranges.occupancy(&self.texels, &self.lut)
    }
}

/// No opacity modulation: a single texel of 1.
fn no_modulation(device: &wgpu::Device, queue: &wgpu::Queue) -> wgpu::TextureView {
    let texture = texture_3d(
        device,
        "GpuVolume::opacity_modulation",
        [1, 1, 1],
        wgpu::TextureFormat::R8Unorm,
    );
    write_3d(queue, &texture, [1, 1, 1], 1, &[255]);
    texture.create_view(&Default::default())
}

impl RayCaster {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "raycast.wgsl")?;
        let surfaces = super::surface::SurfaceRenderer::new(device)?;
        validated(device, "RayCaster::new", || {
            let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty,
                count: None,
            };
            let tex = |sample_type| wgpu::BindingType::Texture {
                sample_type,
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            };
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RayCaster::layout"),
                entries: &[
                    entry(
                        0,
                        wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                    ),
                    entry(1, tex(wgpu::TextureSampleType::Float { filterable: true })),
                    entry(
                        2,
                        wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    ),
                    entry(
                        3,
                        wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Storage { read_only: true },
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                    ),
                    entry(4, tex(wgpu::TextureSampleType::Float { filterable: true })),
                    entry(5, tex(wgpu::TextureSampleType::Uint)),
                    entry(
                        6,
                        wgpu::BindingType::StorageTexture {
                            access: wgpu::StorageTextureAccess::WriteOnly,
                            format: wgpu::TextureFormat::Rgba8Unorm,
                            view_dimension: wgpu::TextureViewDimension::D2,
                        },
                    ),
                    entry(7, tex(wgpu::TextureSampleType::Float { filterable: true })),
                ],
            });
            let clip_layout = crate::clip::gpu::bind_group_layout(device);
            let layout_2 = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("RayCaster::layout_2"),
                entries: &super::shadow::layout_entries(),
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("RayCaster::pipeline_layout"),
                bind_group_layouts: &[Some(&layout), Some(&clip_layout), Some(&layout_2)],
                immediate_size: 0,
            });
            let pipeline = crate::gpu::compute_pipeline(
                device,
                "RayCaster::pipeline",
                &module,
                "main",
                Some(&pipeline_layout),
            );
            let sampler = crate::gpu::linear_sampler(device, "RayCaster::linear_clamp");
            let no_clip = crate::clip::gpu::empty_bind_group(device, &clip_layout);
            RayCaster {
                pipeline,
                layout,
                clip_layout,
                no_clip,
                sampler,
                layout_2,
                placeholders: super::shadow::Placeholders::new(device),
                surfaces,
            }
        })
    }

    /// Encodes the ray casting of one tile of `frame` into `encoder`, writing the caller's
    /// `target` (Rgba8Unorm with `STORAGE_BINDING`; its size is the tile's, `origin` where
    /// it sits in the frame), with no readback, clipped by `clip` as
    /// [`Self::render_clipped`] is. The viewer draws `target` through a paint callback and
    /// copies screenshot tiles out of it asynchronously; the pixels are those
    /// [`Self::render_clipped`] reads back for the same frame.
    pub fn encode_tile(
        &self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        vol: &GpuVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        (target, origin): (&wgpu::Texture, (u32, u32)),
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let params = frame.params(&vol.texels, &vol.lut, origin.0, origin.1);
        let clip_group = clip.map(|c| c.bind_group(device, &self.clip_layout));
        let clip_group = clip_group.as_ref().unwrap_or(&self.no_clip);
        let (tw, th) = (target.width(), target.height());
        // The surfaces, rasterised for the whole frame (submitted before the caller's
        // encoder, so they are ready when the ray cast reads them).
        let layer = match vol.extras.surfaces.is_empty() {
            true => None,
            false => Some(self.surfaces.rasterise(
                (device, queue),
                &vol.extras.surfaces,
                frame,
                &vol.texels,
            )?),
        };
        validated(device, "RayCaster::encode_tile", || {
            let uniforms = uniform_buffer(
                device,
                queue,
                "RayCaster::params",
                bytemuck::bytes_of(&params),
            );
            let target_view = target.create_view(&Default::default());
            let group = bind_group(
                device,
                "RayCaster::bind_group",
                &self.layout,
                &[
                    uniforms.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&vol.volume_view),
                    wgpu::BindingResource::Sampler(&self.sampler),
                    vol.lut_buffer.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&vol.ao_view),
                    wgpu::BindingResource::TextureView(&vol.occupancy_view),
                    wgpu::BindingResource::TextureView(&target_view),
                    wgpu::BindingResource::TextureView(&vol.modulation_view),
                ],
            );
            let group_2 = super::shadow::bind_group_2(
                device,
                queue,
                &self.layout_2,
                &vol.extras,
                layer.as_ref(),
                &self.placeholders,
                &self.sampler,
            );
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("RayCaster::encode_tile"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.set_bind_group(1, clip_group, &[]);
            pass.set_bind_group(2, &group_2, &[]);
            pass.dispatch_workgroups(tw.div_ceil(8), th.div_ceil(8), 1);
        })
    }

    /// Renders a frame in tiles of at most [`TILE`]² and reads it back.
    pub fn render(&self, gpu: &Gpu, vol: &GpuVolume, frame: &Frame) -> Result<Image, GpuError> {
        self.render_clipped(gpu, vol, frame, None)
    }

    /// [`Self::render`] with shadow-test clipping against `clip`'s shapes.
    pub fn render_clipped(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
    ) -> Result<Image, GpuError> {
        let clip_group = clip.map(|c| c.bind_group(&gpu.device, &self.clip_layout));
        let clip_group = clip_group.as_ref().unwrap_or(&self.no_clip);
        let (w, h) = (frame.width.max(1), frame.height.max(1));
        let mut image = Image {
            width: w,
            height: h,
            pixels: vec![[0; 4]; (w * h) as usize],
        };
        let layer = match vol.extras.surfaces.is_empty() {
            true => None,
            false => Some(self.surfaces.rasterise(
                (&gpu.device, &gpu.queue),
                &vol.extras.surfaces,
                frame,
                &vol.texels,
            )?),
        };
        let mut y0 = 0;
        while y0 < h {
            let mut x0 = 0;
            while x0 < w {
                let size = ((w - x0).min(TILE), (h - y0).min(TILE));
                let tile =
                    self.render_tile(gpu, vol, frame, clip_group, layer.as_ref(), (x0, y0), size)?;
                image.blit(&tile, x0, y0);
                x0 += TILE;
            }
            y0 += TILE;
        }
        Ok(image)
    }

    #[allow(
        clippy::too_many_arguments,
        reason = "one tile of one frame: every argument is a different input"
    )]
    fn render_tile(
        &self,
        gpu: &Gpu,
        vol: &GpuVolume,
        frame: &Frame,
        clip_group: &wgpu::BindGroup,
        layer: Option<&super::surface::SurfaceLayer>,
        (x0, y0): (u32, u32),
        (tw, th): (u32, u32),
    ) -> Result<Image, GpuError> {
        let device = &gpu.device;
        let params = frame.params(&vol.texels, &vol.lut, x0, y0);
        let row = padded_row_bytes(tw * 4);
        let readback = validated(device, "RayCaster::tile", || {
            let uniforms = uniform_buffer(
                device,
                &gpu.queue,
                "RayCaster::params",
                bytemuck::bytes_of(&params),
            );
            let target = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("RayCaster::tile"),
                size: wgpu::Extent3d {
                    width: tw,
                    height: th,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let target_view = target.create_view(&Default::default());
            let readback = readback_buffer(device, "RayCaster::readback", row as u64 * th as u64);
            let group = bind_group(
                device,
                "RayCaster::bind_group",
                &self.layout,
                &[
                    uniforms.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&vol.volume_view),
                    wgpu::BindingResource::Sampler(&self.sampler),
                    vol.lut_buffer.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&vol.ao_view),
                    wgpu::BindingResource::TextureView(&vol.occupancy_view),
                    wgpu::BindingResource::TextureView(&target_view),
                    wgpu::BindingResource::TextureView(&vol.modulation_view),
                ],
            );
            let group_2 = super::shadow::bind_group_2(
                device,
                &gpu.queue,
                &self.layout_2,
                &vol.extras,
                layer,
                &self.placeholders,
                &self.sampler,
            );
            crate::gpu::submit_compute_with(
                device,
                &gpu.queue,
                "RayCaster::tile",
                &self.pipeline,
                &[&group, clip_group, &group_2],
                [tw.div_ceil(8), th.div_ceil(8), 1],
                |encoder| {
                    encoder.copy_texture_to_buffer(
                        target.as_image_copy(),
                        wgpu::TexelCopyBufferInfo {
                            buffer: &readback,
                            layout: wgpu::TexelCopyBufferLayout {
                                offset: 0,
                                bytes_per_row: Some(row),
                                rows_per_image: Some(th),
                            },
                        },
                        wgpu::Extent3d {
                            width: tw,
                            height: th,
                            depth_or_array_layers: 1,
                        },
                    );
                },
            );
            readback
        })?;
        let bytes = read_buffer(device, &readback, "RayCaster::readback")?;
        let mut pixels = Vec::with_capacity((tw * th) as usize);
        for r in bytes.chunks_exact(row as usize) {
            pixels.extend(
                r[..(tw * 4) as usize]
                    .chunks_exact(4)
                    .map(|c| [c[0], c[1], c[2], c[3]]),
            );
        }
        Ok(Image {
            width: tw,
            height: th,
            pixels,
        })
    }
}
