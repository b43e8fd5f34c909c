//! Opaque or translucent geometry inside the volume (Imagire et al. 2007, §3.2: the
//! valid sampling path). Triangle meshes are rasterised from the view camera
//! (`shaders/surface.wgsl`) into the nearest surface's position and shaded colour per
//! pixel; the ray caster ends its sampling path exactly at that surface, with the last
//! partial step's opacity corrected for its true length, composites the surface, and —
//! for a translucent one — goes on behind it. CPU twin: [`nearest_hit`] (ray–triangle
//! intersection) with the same shading.

use crate::gpu::{GpuError, bind_group, shaders, uniform_buffer, validated};
use crate::render::Frame;
use crate::texels::VolumeTexels;
use glam::{Mat4, Vec3, Vec4};

/// A triangle mesh in the volume's centred physical space (mm, RAS, the box is
/// `[−extent/2, extent/2]`, as the camera sees it) with one straight RGBA colour;
/// alpha 1 is opaque.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    pub triangles: Vec<[Vec3; 3]>,
    pub rgba: [f32; 4],
}

/// Why a mesh file was refused.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceError {
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error("{path}, line {line}: {message}")]
    Parse {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: no faces (a mesh needs `f` lines with at least three vertices)")]
    Empty { path: String },
}

/// Reads a Wavefront OBJ mesh: `v x y z` vertices (mm, volume RAS frame, origin at the
/// volume's centre — the space the camera orbits) and `f` faces (`i`, `i/t`, `i//n`,
/// `i/t/n`, negative indices relative to the end), polygons split into fans. Other
/// statements (normals, texture coordinates, groups, materials) are ignored.
pub fn load_obj(path: &std::path::Path, rgba: [f32; 4]) -> Result<Surface, SurfaceError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| SurfaceError::Io {
        path: name.clone(),
        message: e.to_string(),
    })?;
    parse_obj(&text, &name, rgba)
}

/// [`load_obj`] on text; `name` names it in errors.
pub fn parse_obj(text: &str, name: &str, rgba: [f32; 4]) -> Result<Surface, SurfaceError> {
    let mut vertices: Vec<Vec3> = Vec::new();
    let mut triangles = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let err = |message: String| SurfaceError::Parse {
            path: name.to_owned(),
            line: i + 1,
            message,
        };
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let c: Vec<f32> = words
                    .take(3)
                    .map(|w| {
                        w.parse::<f32>()
                            .map_err(|e| err(format!("vertex {w:?}: {e}")))
                    })
                    .collect::<Result<_, _>>()?;
                match c.as_slice() {
                    [x, y, z] if c.iter().all(|v| v.is_finite()) => {
                        vertices.push(Vec3::new(*x, *y, *z));
                    }
                    _ => return Err(err("a vertex needs three finite coordinates".into())),
                }
            }
            Some("f") => {
                let idx: Vec<Vec3> = words
                    .map(|w| {
                        let first = w.split('/').next().unwrap_or("");
                        let k: i64 = first
                            .parse()
                            .map_err(|e| err(format!("face index {w:?}: {e}")))?;
                        let n = vertices.len() as i64;
                        let at = if k > 0 { k - 1 } else { n + k };
                        if k == 0 || at < 0 || at >= n {
                            return Err(err(format!(
                                "face index {k} refers to no vertex ({n} so far)"
                            )));
                        }
                        Ok(vertices[at as usize])
                    })
                    .collect::<Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(err(format!(
                        "a face needs 3 vertices, this one has {}",
                        idx.len()
                    )));
                }
                for k in 1..idx.len() - 1 {
                    triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if triangles.is_empty() {
        return Err(SurfaceError::Empty {
            path: name.to_owned(),
        });
    }
    Ok(Surface { triangles, rgba })
}

/// Unit face normal, or zero for a degenerate triangle.
fn normal(t: &[Vec3; 3]) -> Vec3 {
    (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero()
}

/// Two-sided headlight shading of a surface colour: `rgb · (¼ + ¾ |n · v|)`.
pub fn shade_surface(rgba: [f32; 4], n: Vec3, view: Vec3) -> Vec4 {
    let lit = 0.25 + 0.75 * n.dot(view).abs();
    Vec4::new(rgba[0] * lit, rgba[1] * lit, rgba[2] * lit, rgba[3])
}

/// Where the camera is, as the surface shader reads it: perspective → eye position with
/// w = 1; orthographic → direction towards the eye with w = 0.
fn eye(frame: &Frame, radius: f32) -> Vec4 {
    if frame.camera.orthographic {
        frame.camera.backward().extend(0.0)
    } else {
        frame.camera.eye(radius).extend(1.0)
    }
}

/// Bounding-sphere radius of the volume box, as `Frame::params` computes it.
fn radius(texels: &VolumeTexels) -> f32 {
    (Vec3::from(texels.extent()) * 0.5).length()
}

/// CPU twin: the nearest surface along a ray (`t` from `origin`, unit `dir`) and its
/// shaded colour, by Möller–Trumbore intersection.
pub fn nearest_hit(
    surfaces: &[Surface],
    frame: &Frame,
    texels: &VolumeTexels,
    origin: Vec3,
    dir: Vec3,
) -> Option<(f32, Vec4)> {
    let mut best: Option<(f32, Vec3, [f32; 4])> = None;
    for s in surfaces {
        for tri in &s.triangles {
            let (e1, e2) = (tri[1] - tri[0], tri[2] - tri[0]);
            let pv = dir.cross(e2);
            let det = e1.dot(pv);
            if det.abs() < 1e-12 {
                continue;
            }
            let inv = 1.0 / det;
            let tv = origin - tri[0];
            let u = tv.dot(pv) * inv;
            let qv = tv.cross(e1);
            let v = dir.dot(qv) * inv;
            let t = e2.dot(qv) * inv;
            if u < 0.0 || v < 0.0 || u + v > 1.0 || t < 0.0 {
                continue;
            }
            if best.is_none_or(|b| t < b.0) {
                best = Some((t, normal(tri), s.rgba));
            }
        }
    }
    best.map(|(t, n, rgba)| {
        let e = eye(frame, radius(texels));
        let view = if e.w != 0.0 {
            (e.truncate() - (origin + dir * t)).normalize()
        } else {
            e.truncate()
        };
        (t, shade_surface(rgba, n, view))
    })
}

/// Uniforms of `surface.wgsl`. Mirrors `struct Params` there.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct SurfaceParams {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<SurfaceParams>() == 80);

/// One vertex as `surface.wgsl` reads it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    color: [f32; 4],
}

/// Position and colour format of the rasterised surface layer.
pub const LAYER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// The rasterised nearest surface per pixel of a whole frame.
#[derive(Debug)]
pub struct SurfaceLayer {
    pub position: wgpu::TextureView,
    pub color: wgpu::TextureView,
}

/// Long-lived surface rasteriser.
#[derive(Debug)]
pub struct SurfaceRenderer {
    pipeline: wgpu::RenderPipeline,
}

impl SurfaceRenderer {
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let module = shaders::module(device, "surface.wgsl")?;
        validated(device, "Surface::new", || {
            let target = Some(wgpu::ColorTargetState {
                format: LAYER_FORMAT,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            });
            let pipeline = crate::gpu::depth_tested_pipeline(
                device,
                "Surface::pipeline",
                &module,
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![
                        0 => Float32x3, 1 => Float32x3, 2 => Float32x4
                    ],
                },
                wgpu::PrimitiveState {
                    cull_mode: None,
                    ..Default::default()
                },
                &[target.clone(), target],
            );
            SurfaceRenderer { pipeline }
        })
    }

    /// Rasterises `surfaces` for the whole of `frame` (one texel per pixel).
    pub fn rasterise(
        &self,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        surfaces: &[Surface],
        frame: &Frame,
        texels: &VolumeTexels,
    ) -> Result<SurfaceLayer, GpuError> {
        let (w, h) = (frame.width.max(1), frame.height.max(1));
        let max = device.limits().max_texture_dimension_2d;
        if w > max || h > max {
            return Err(GpuError::Validation {
                stage: "Surface::rasterise".into(),
                message: format!(
                    "surfaces in a {w}×{h} image: the adapter's 2-D textures stop at {max} pixels per side"
                ),
            });
        }
        let r = radius(texels);
        let view_proj: Mat4 = frame.camera.view_proj(r, w as f32 / h as f32);
        let params = SurfaceParams {
            view_proj: view_proj.to_cols_array_2d(),
            eye: eye(frame, r).to_array(),
        };
        let vertices: Vec<Vertex> = surfaces
            .iter()
            .flat_map(|s| {
                s.triangles.iter().flat_map(move |t| {
                    let n = normal(t).to_array();
                    t.map(|p| Vertex {
                        position: p.to_array(),
                        normal: n,
                        color: s.rgba,
                    })
                })
            })
            .collect();
        validated(device, "Surface::rasterise", || {
            let size = wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            };
            let texture = |label, format| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
            };
            let position =
                texture("Surface::position", LAYER_FORMAT).create_view(&Default::default());
            let color = texture("Surface::color", LAYER_FORMAT).create_view(&Default::default());
            let depth = texture("Surface::depth", wgpu::TextureFormat::Depth32Float)
                .create_view(&Default::default());
            let vertex_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("Surface::vertices"),
                size: (std::mem::size_of_val(vertices.as_slice()) as u64).max(16),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&vertex_buffer, 0, bytemuck::cast_slice(&vertices));
            let uniforms = uniform_buffer(
                device,
                queue,
                "Surface::params",
                bytemuck::bytes_of(&params),
            );
            let group = bind_group(
                device,
                "Surface::bind_group",
                &self.pipeline.get_bind_group_layout(0),
                &[uniforms.as_entire_binding()],
            );
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("Surface::rasterise"),
            });
            {
                let attachment = |view| {
                    Some(wgpu::RenderPassColorAttachment {
                        view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Store,
                        },
                    })
                };
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("Surface::rasterise"),
                    color_attachments: &[attachment(&position), attachment(&color)],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &depth,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.set_vertex_buffer(0, vertex_buffer.slice(..));
                pass.draw(0..vertices.len() as u32, 0..1);
            }
            queue.submit([encoder.finish()]);
            SurfaceLayer { position, color }
        })
    }
}
