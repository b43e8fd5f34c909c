//! Depth and dilation maps of the clip shapes on the GPU (CAO paper §3.4 steps II–III).
//!
//! For each shape, depth-only render passes peel two layers of front and back faces
//! (`shaders/clip_depth.wgsl`), then a compute pass (`shaders/clip_maps.wgsl`) resolves
//! empty pixels and builds the dilation (carve) or contraction (probe) maps by
//! Algorithm 1. All maps live in one `Rgba32Float` 2-D array texture, 2 layers per shape
//! of 4 maps each.
//! Maps are re-rendered only when a shape's geometry (shape, scale, mode, margin,
//! resolution) changes; moving a shape only rewrites its matrix in the uniforms.

use super::camera::ClipCamera;
pub use super::gpu_data::{
    ARRAY_LAYERS_PER_SHAPE, ClipUniforms, DEFAULT_RESOLUTION, LAYERS_PER_SHAPE, ShapeUniform,
};
use super::mesh::TriMesh;
use super::{ClipError, ClipMode, ClipShape, MAX_SHAPES, Shape};
use crate::gpu::{Gpu, GpuError, bind_group, shaders, uniform_buffer, validated};
use glam::Mat4;

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PeelUniform {
    projection: [[f32; 4]; 4],
    flags: [u32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct MapsParams {
    radii: [f32; 4],
    info: [u32; 4],
}

/// One pass of `clip_maps.wgsl`: entry point index, (binding, resource) pairs, size.
type Step<'a> = (usize, Vec<(u32, wgpu::BindingResource<'a>)>, u32);

/// What makes a shape's maps: if it is unchanged, the maps are reused.
#[derive(Debug, Clone, PartialEq)]
struct GeometryKey {
    shape: Shape,
    scale: [f32; 3],
    /// The plane's slab depends on where it is (it must cover the volume).
    plane_reach: f32,
    mode: ClipMode,
    reach_mm: f32,
    resolution: u32,
}

#[derive(Debug, Clone)]
struct Slot {
    key: GeometryKey,
    camera: ClipCamera,
}

/// What [`ClipMaps::update`] did.
#[derive(Debug, Default)]
pub struct ClipUpdate {
    /// Shapes left out, with why (the others still clip).
    pub errors: Vec<ClipError>,
    /// Shapes whose depth and dilation maps were (re)built.
    pub rebuilt: usize,
}

/// The pipelines that build clip maps (depth peeling, then `clip_maps.wgsl`), built
/// once per device.
#[derive(Debug)]
pub struct ClipPipelines {
    peel_front: wgpu::RenderPipeline,
    peel_back: wgpu::RenderPipeline,
    /// `clip_maps.wgsl` entry points: resolve, reduce, dilate, expand.
    passes: [wgpu::ComputePipeline; 4],
}

impl crate::gpu::Stage for ClipPipelines {
    fn create(device: &wgpu::Device) -> Result<Self, GpuError> {
        let [depth_module, maps_module] =
            shaders::modules(device, ["clip_depth.wgsl", "clip_maps.wgsl"])?;
        validated(device, "ClipPipelines::create", || {
            let peel = |label, cull| {
                crate::gpu::depth_tested_pipeline(
                    device,
                    label,
                    &depth_module,
                    wgpu::VertexBufferLayout {
                        array_stride: 12,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x3],
                    },
                    wgpu::PrimitiveState {
                        topology: wgpu::PrimitiveTopology::TriangleList,
                        front_face: wgpu::FrontFace::Ccw,
                        cull_mode: Some(cull),
                        ..Default::default()
                    },
                    &[],
                )
            };
            let passes = ["resolve", "reduce", "dilate", "expand"].map(|entry| {
                crate::gpu::compute_pipeline(device, entry, &maps_module, entry, None)
            });
            ClipPipelines {
                // Front faces: cull the back ones, and vice versa.
                peel_front: peel("ClipMaps::peel_front", wgpu::Face::Back),
                peel_back: peel("ClipMaps::peel_back", wgpu::Face::Front),
                passes,
            }
        })
    }
}

/// The clip shapes' maps and uniforms on the GPU.
#[derive(Debug)]
pub struct ClipMaps {
    pipelines: std::sync::Arc<ClipPipelines>,
    maps: wgpu::Texture,
    maps_view: wgpu::TextureView,
    dummy_depth: wgpu::TextureView,
    resolution: u32,
    slots: Vec<Slot>,
    pub uniforms: ClipUniforms,
    uniform_buffer: wgpu::Buffer,
}

fn depth_texture(device: &wgpu::Device, label: &str, size: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Depth32Float,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    })
}

fn maps_texture(device: &wgpu::Device, resolution: u32, layers: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("ClipMaps::maps"),
        size: wgpu::Extent3d {
            width: resolution,
            height: resolution,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

fn array_view(texture: &wgpu::Texture) -> wgpu::TextureView {
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// The maps' resolution for `resolution` asked: what the device allows, at least 16.
fn map_resolution(gpu: &Gpu, resolution: u32) -> u32 {
    resolution.clamp(16, gpu.device.limits().max_texture_dimension_2d)
}

/// The uniforms posing `shapes` with the clipping cameras of `slots`, in order.
fn posed_uniforms<'a>(shapes: impl Iterator<Item = &'a ClipShape>, slots: &[Slot]) -> ClipUniforms {
    let mut uniforms: ClipUniforms = bytemuck::Zeroable::zeroed();
    for (i, (shape, slot)) in shapes.zip(slots).enumerate() {
        uniforms.shapes[i] = shape_uniform(shape, &slot.camera, i);
        uniforms.counts[0] += 1;
        uniforms.counts[1] += u32::from(shape.mode == ClipMode::Probe);
    }
    uniforms
}

/// What a request for the maps of some shapes asks for: the resolution, clamped to what
/// the adapter allows; the shapes that can clip, with their geometry keys; and the
/// report of those that cannot.
struct Usable<'a> {
    resolution: u32,
    shapes: Vec<(&'a ClipShape, GeometryKey)>,
    report: ClipUpdate,
}

/// What the maps are wanted for ([`ClipMaps::update`], [`ClipMaps::posed`],
/// [`ClipMaps::fits`]): the shapes, with what sizes their maps.
#[derive(Debug, Clone, Copy)]
pub struct MapRequest<'a> {
    pub shapes: &'a [ClipShape],
    /// The volume's bounding radius (mm): sizes planes.
    pub volume_radius: f32,
    /// How far a clipped point can influence the ambient factor (the LAO ray length
    /// plus the interpolation footprint), in mm: the dilation.
    pub reach_mm: f32,
    /// The maps' size in pixels (square), before the adapter's limit.
    pub resolution: u32,
}

impl MapRequest<'static> {
    /// No shapes: maps that clip nothing (CAO's precomputation of `V_PAO`).
    pub const NOTHING: MapRequest<'static> = MapRequest {
        shapes: &[],
        volume_radius: 1.0,
        reach_mm: 1.0,
        resolution: 16,
    };
}

impl<'a> MapRequest<'a> {
    /// Maps that only clip the picture (no AO depends on the clipping, so the dilation
    /// is unused: 1 mm).
    pub fn clipping(shapes: &'a [ClipShape], volume_radius: f32, resolution: u32) -> Self {
        MapRequest {
            shapes,
            volume_radius,
            reach_mm: CLIPPING_REACH_MM,
            resolution,
        }
    }
}

/// The dilation of maps that only clip (no AO reads them): [`MapRequest::clipping`]'s,
/// which the viewer uses too, so that both cut alike.
pub const CLIPPING_REACH_MM: f32 = 1.0;

/// The usable part of `request`.
fn usable<'a>(gpu: &Gpu, request: MapRequest<'a>) -> Usable<'a> {
    let MapRequest {
        shapes,
        volume_radius,
        reach_mm,
        resolution,
    } = request;
    let resolution = map_resolution(gpu, resolution);
    let mut report = ClipUpdate::default();
    if shapes.len() > MAX_SHAPES {
        report.errors.push(ClipError::TooMany {
            count: shapes.len(),
        });
    }
    let mut usable = Vec::new();
    for (i, s) in shapes.iter().take(MAX_SHAPES).enumerate() {
        if let Err(e) = s.check(i) {
            report.errors.push(e);
            continue;
        }
        let key = GeometryKey {
            shape: s.shape.clone(),
            scale: s.scale,
            plane_reach: if s.shape == Shape::Plane {
                s.plane_slab_size(volume_radius)
            } else {
                0.0
            },
            mode: s.mode,
            reach_mm,
            resolution,
        };
        usable.push((s, key));
    }
    Usable {
        resolution,
        shapes: usable,
        report,
    }
}

/// Block size f of the dilation (`clip_maps.wgsl`): the smallest power of two keeping
/// the kernel within 24 blocks, so building the maps costs O((r_xy / f)²) per block.
pub fn block_size(r_xy: f32) -> u32 {
    let need = (r_xy / 24.0).ceil().max(1.0) as u32;
    need.next_power_of_two()
}

/// The bind group layout entries of `@group(1)` in `clip_common.wgsl`, for pipelines
/// with explicit layouts.
pub fn layout_entries(visibility: wgpu::ShaderStages) -> [wgpu::BindGroupLayoutEntry; 2] {
    use crate::gpu::entry;
    [
        entry::uniform(0, visibility),
        entry::texture(
            1,
            visibility,
            wgpu::TextureViewDimension::D2Array,
            Some(false),
        ),
    ]
}

/// The layout of `@group(1)` in `clip_common.wgsl` (compute stage).
pub fn bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("clip::layout"),
        entries: &layout_entries(wgpu::ShaderStages::COMPUTE),
    })
}

/// A `@group(1)` with no clip shapes: wgpu zero-initialises the uniforms (0 shapes) and
/// the one-texel map array.
pub fn empty_bind_group(device: &wgpu::Device, layout: &wgpu::BindGroupLayout) -> wgpu::BindGroup {
    let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("clip::no_shapes"),
        size: std::mem::size_of::<ClipUniforms>() as u64,
        usage: wgpu::BufferUsages::UNIFORM,
        mapped_at_creation: false,
    });
    let maps = maps_texture(device, 1, ARRAY_LAYERS_PER_SHAPE);
    bind_group(
        device,
        "clip::no_shapes",
        layout,
        &[
            uniforms.as_entire_binding(),
            wgpu::BindingResource::TextureView(&array_view(&maps)),
        ],
    )
}

/// The clip uniforms for the current poses: volume mm → each shape's map coordinates.
fn shape_uniform(shape: &ClipShape, camera: &ClipCamera, slot: usize) -> ShapeUniform {
    let to_map: Mat4 = camera.to_map * shape.shape_to_volume().inverse();
    ShapeUniform {
        volume_to_map: to_map.to_cols_array_2d(),
        info: [
            u32::from(shape.mode == ClipMode::Probe),
            slot as u32 * ARRAY_LAYERS_PER_SHAPE,
            camera.resolution,
            0,
        ],
    }
}

impl ClipMaps {
    pub fn new(gpu: &Gpu) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let pipelines = gpu.stage::<ClipPipelines>()?;
        validated(device, "ClipMaps::new", || {
            let maps = maps_texture(device, 1, ARRAY_LAYERS_PER_SHAPE);
            let dummy = depth_texture(device, "ClipMaps::no_previous_layer", 1);
            let uniforms: ClipUniforms = bytemuck::Zeroable::zeroed();
            ClipMaps {
                pipelines,
                maps_view: array_view(&maps),
                maps,
                dummy_depth: dummy.create_view(&Default::default()),
                resolution: 1,
                slots: Vec::new(),
                uniform_buffer: uniform_buffer(
                    device,
                    &gpu.queue,
                    "ClipMaps::uniforms",
                    bytemuck::bytes_of(&uniforms),
                ),
                uniforms,
            }
        })
    }

    /// Brings the maps and uniforms up to date with `request`'s shapes.
    ///
    /// Shapes that cannot be used (bad pose, broken mesh, beyond [`MAX_SHAPES`]) are left
    /// out and reported; the others clip.
    pub fn update(&mut self, gpu: &Gpu, request: MapRequest<'_>) -> Result<ClipUpdate, GpuError> {
        let device = &gpu.device;
        let MapRequest {
            volume_radius,
            reach_mm,
            ..
        } = request;
        let Usable {
            resolution,
            shapes: usable,
            mut report,
        } = usable(gpu, request);
        let layers = (usable.len().max(1) as u32) * ARRAY_LAYERS_PER_SHAPE;
        if resolution != self.resolution || layers > self.maps.depth_or_array_layers() {
            self.maps = validated(device, "ClipMaps::allocate", || {
                maps_texture(device, resolution, layers)
            })?;
            self.maps_view = array_view(&self.maps);
            self.resolution = resolution;
            self.slots.clear();
        }
        let mut slots = Vec::with_capacity(usable.len());
        let mut kept = Vec::with_capacity(usable.len());
        for (shape, key) in usable {
            let idx = slots.len();
            let reuse = self.slots.get(idx).filter(|s| s.key == key).cloned();
            let built = match reuse {
                Some(s) => s,
                None => {
                    let mesh = match shape.geometry(volume_radius) {
                        Ok(m) => m,
                        Err(e) => {
                            report.errors.push(e);
                            continue;
                        }
                    };
                    let camera = ClipCamera::frame(&mesh, reach_mm, resolution);
                    self.render_shape(gpu, &mesh, &camera, shape.mode, idx)?;
                    report.rebuilt += 1;
                    Slot { key, camera }
                }
            };
            kept.push(shape.clone());
            slots.push(built);
        }
        self.slots = slots;
        let uniforms = posed_uniforms(kept.iter(), &self.slots);
        self.uniforms = uniforms;
        gpu.queue
            .write_buffer(&self.uniform_buffer, 0, bytemuck::bytes_of(&uniforms));
        Ok(report)
    }

    /// A copy of these maps posed for `request`'s shapes (its own uniforms, the same textures), so
    /// that an image can be clipped at one pose while these maps move to another; `None`
    /// when `shapes` need other maps than those built (a shape added, removed or
    /// resized, or one that cannot clip): then only [`Self::update`] will do. Posed for
    /// the shapes [`Self::update`] was given, the copy clips every point alike.
    pub fn posed(&self, gpu: &Gpu, request: MapRequest<'_>) -> Option<ClipMaps> {
        let Usable {
            resolution,
            shapes: usable,
            report,
        } = usable(gpu, request);
        let same = report.errors.is_empty()
            && usable.len() == self.slots.len()
            && self.built_for(&usable, resolution);
        if !same {
            return None;
        }
        let uniforms = posed_uniforms(usable.iter().map(|(s, _)| *s), &self.slots);
        Some(ClipMaps {
            pipelines: std::sync::Arc::clone(&self.pipelines),
            maps: self.maps.clone(),
            maps_view: self.maps_view.clone(),
            dummy_depth: self.dummy_depth.clone(),
            resolution,
            slots: self.slots.clone(),
            uniforms,
            uniform_buffer: uniform_buffer(
                &gpu.device,
                &gpu.queue,
                "ClipMaps::posed",
                bytemuck::bytes_of(&uniforms),
            ),
        })
    }

    /// Whether [`Self::update`] to `request` would only re-pose the maps built (no map
    /// rebuilt: a copy from [`Self::posed`] stays valid across it).
    pub fn fits(&self, gpu: &Gpu, request: MapRequest<'_>) -> bool {
        let usable = usable(gpu, request);
        self.built_for(&usable.shapes, usable.resolution)
    }

    /// Whether every one of `usable` finds its maps built at `resolution`: the same
    /// geometry key in the same slot.
    fn built_for(&self, usable: &[(&ClipShape, GeometryKey)], resolution: u32) -> bool {
        resolution == self.resolution
            && usable.len() <= self.slots.len()
            && usable
                .iter()
                .zip(&self.slots)
                .all(|((_, k), s)| *k == s.key)
    }

    /// The clipping cameras of the shapes now in use, in order.
    pub fn cameras(&self) -> Vec<ClipCamera> {
        self.slots.iter().map(|s| s.camera).collect()
    }

    /// Bind group for `@group(1)` of a pipeline that includes `clip_common.wgsl`.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
    ) -> wgpu::BindGroup {
        bind_group(
            device,
            "ClipMaps::bind_group",
            layout,
            &[
                self.uniform_buffer.as_entire_binding(),
                wgpu::BindingResource::TextureView(&self.maps_view),
            ],
        )
    }

    /// Peels the mesh's depth layers and builds its maps into `slot`'s layers.
    fn render_shape(
        &self,
        gpu: &Gpu,
        mesh: &TriMesh,
        camera: &ClipCamera,
        mode: ClipMode,
        slot: usize,
    ) -> Result<(), GpuError> {
        let device = &gpu.device;
        let res = camera.resolution;
        validated(device, "ClipMaps::render_shape", || {
            let vertices: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| v.to_array()).collect();
            let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
            let buffer = |label, usage, bytes: &[u8]| {
                let b = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes.len() as u64,
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                gpu.queue.write_buffer(&b, 0, bytes);
                b
            };
            let vbuf = buffer(
                "ClipMaps::vertices",
                wgpu::BufferUsages::VERTEX,
                bytemuck::cast_slice(&vertices),
            );
            let ibuf = buffer(
                "ClipMaps::indices",
                wgpu::BufferUsages::INDEX,
                bytemuck::cast_slice(&indices),
            );
            let depths: Vec<wgpu::Texture> = (0..4)
                .map(|_| depth_texture(device, "ClipMaps::peeled_depth", res))
                .collect();
            let views: Vec<wgpu::TextureView> = depths
                .iter()
                .map(|t| t.create_view(&Default::default()))
                .collect();
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ClipMaps::render_shape"),
            });
            for layer in 0..4 {
                let pipeline = if layer % 2 == 0 {
                    &self.pipelines.peel_front
                } else {
                    &self.pipelines.peel_back
                };
                let peel = PeelUniform {
                    projection: camera.projection.to_cols_array_2d(),
                    flags: [u32::from(layer > 0), 0, 0, 0],
                };
                let uniforms = uniform_buffer(
                    device,
                    &gpu.queue,
                    "ClipMaps::peel",
                    bytemuck::bytes_of(&peel),
                );
                let previous = if layer == 0 {
                    &self.dummy_depth
                } else {
                    &views[layer - 1]
                };
                let group = bind_group(
                    device,
                    "ClipMaps::peel",
                    &pipeline.get_bind_group_layout(0),
                    &[
                        uniforms.as_entire_binding(),
                        wgpu::BindingResource::TextureView(previous),
                    ],
                );
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("ClipMaps::peel"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &views[layer],
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.set_vertex_buffer(0, vbuf.slice(..));
                pass.set_index_buffer(ibuf.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..indices.len() as u32, 0, 0..1);
            }
            let (r_xy, r_z) = camera.dilation_radii();
            let f = block_size(r_xy);
            let blocks = res.div_ceil(f);
            let params = MapsParams {
                radii: [r_xy, r_z, 0.0, 0.0],
                info: [
                    res,
                    slot as u32 * ARRAY_LAYERS_PER_SHAPE,
                    u32::from(mode == ClipMode::Probe),
                    f,
                ],
            };
            let uniforms = uniform_buffer(
                device,
                &gpu.queue,
                "ClipMaps::maps_params",
                bytemuck::bytes_of(&params),
            );
            let storage = array_view(&self.maps);
            let block_texture = |label| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: blocks,
                        height: blocks,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba32Float,
                    usage: wgpu::TextureUsages::STORAGE_BINDING
                        | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
            };
            let (reduced, dilated) = (
                block_texture("ClipMaps::reduced").create_view(&Default::default()),
                block_texture("ClipMaps::dilated").create_view(&Default::default()),
            );
            use wgpu::BindingResource::TextureView as Tex;
            // The uniforms, the four depth layers (bindings 1–4) and one output.
            let from_depths = |output| {
                let mut entries = vec![(0, uniforms.as_entire_binding())];
                entries.extend((0..4).map(|k| (1 + k as u32, Tex(&views[k]))));
                entries.push(output);
                entries
            };
            // (pass, bindings it uses, workgroups)
            let steps: [Step<'_>; 4] = [
                (0, from_depths((5, Tex(&storage))), res),
                (1, from_depths((6, Tex(&reduced))), blocks),
                (
                    2,
                    vec![
                        (0, uniforms.as_entire_binding()),
                        (6, Tex(&dilated)),
                        (7, Tex(&reduced)),
                    ],
                    blocks,
                ),
                (
                    3,
                    vec![
                        (0, uniforms.as_entire_binding()),
                        (5, Tex(&storage)),
                        (7, Tex(&dilated)),
                    ],
                    res,
                ),
            ];
            for (pass_index, entries, size) in steps {
                let pipeline = &self.pipelines.passes[pass_index];
                let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
                    .into_iter()
                    .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
                    .collect();
                let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("ClipMaps::maps"),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &entries,
                });
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("ClipMaps::maps"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
            }
            gpu.queue.submit([encoder.finish()]);
        })
    }

    /// Reads every map layer in use back (for the CPU twin and tests).
    pub fn read_back(&self, gpu: &Gpu) -> Result<super::cpu::ClipMapsCpu, GpuError> {
        let array_layers = (self.slots.len().max(1) as u32) * ARRAY_LAYERS_PER_SHAPE;
        let texels = crate::gpu::read_texture_f32(
            gpu,
            &self.maps,
            [self.resolution, self.resolution, array_layers],
            "ClipMaps::read_back",
        )?;
        // RGBA texels, array layer by array layer → one map after another.
        let plane = (self.resolution as usize).pow(2);
        let mut layers = vec![0.0; texels.len()];
        for (l, rgba) in texels.chunks_exact(plane * 4).enumerate() {
            for (i, t) in rgba.chunks_exact(4).enumerate() {
                for (c, &v) in t.iter().enumerate() {
                    layers[(l * 4 + c) * plane + i] = v;
                }
            }
        }
        Ok(super::cpu::ClipMapsCpu {
            resolution: self.resolution,
            layers,
            uniforms: self.uniforms,
        })
    }
}
