//! The clip shapes as the shaders see them: uniform structs shared by the GPU passes
//! (`clip::gpu`) and their CPU twin (`clip::cpu`). Keep in sync with
//! `shaders/clip_common.wgsl`.

use super::MAX_SHAPES;

/// Maps per shape (see `shaders/clip_common.wgsl`): Z_front1, Z_back1, Z_front2, Z_back2
/// and the same dilated or contracted.
pub const LAYERS_PER_SHAPE: u32 = 8;

/// Texture array layers per shape: the maps packed four to an RGBA texel, so a clip
/// test reads one texel where it read four.
pub const ARRAY_LAYERS_PER_SHAPE: u32 = LAYERS_PER_SHAPE / 4;

/// Default depth-map size (pixels, square).
pub const DEFAULT_RESOLUTION: u32 = 1024;

/// One shape as the shaders see it. Mirrors `struct ClipShape` in `clip_common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ShapeUniform {
    pub volume_to_map: [[f32; 4]; 4],
    /// mode (0 carve, 1 probe), first array layer (RGBA), resolution, unused.
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
