//! The clip shapes as the shaders see them: uniform structs shared by the GPU passes
//! (`clip::gpu`) and their CPU twin (`clip::cpu`). Keep in sync with
//! `shaders/clip_common.wgsl`.

use super::MAX_SHAPES;

/// Layers per shape in the map array (see `shaders/clip_common.wgsl`).
pub const LAYERS_PER_SHAPE: u32 = 8;

/// Default depth-map size (pixels, square).
pub const DEFAULT_RESOLUTION: u32 = 1024;

/// One shape as the shaders see it. Mirrors `struct ClipShape` in `clip_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ShapeUniform {
    pub volume_to_map: [[f32; 4]; 4],
    /// mode (0 carve, 1 probe), first layer, resolution, unused.
    pub info: [u32; 4],
}

/// Mirrors `struct Clip` in `clip_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ClipUniforms {
    /// shapes, probing shapes, unused, unused.
    pub counts: [u32; 4],
    pub shapes: [ShapeUniform; MAX_SHAPES],
}

const _: () = assert!(std::mem::size_of::<ClipUniforms>() == 16 + MAX_SHAPES * 80);
