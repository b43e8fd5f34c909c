//! Ambient occlusion: the factor `A(x)` in [0, 1] per voxel (1 = unoccluded) that the
//! renderer's ambient term `k · A(x) · C_TF(x)` uses.
//!
//! [`settings`] says what a scene asks for ([`AoSettings`]); [`engine::AoEngine`] is the
//! one place that picks the stage and the GPU or its CPU twin for a method:
//!
//! - [`lao`]: Local Ambient Occlusion (Hernell; CAO paper Eq. 2–3), precomputed `V_PAO`;
//! - [`cao`]: Contextual AO (Titov et al.), LAO kept exact under clipping by
//!   recomputing only the voxels the clip shapes affect, and its LAO-every-frame baseline;
//! - [`vao`]: positional AO with Beer's law (Papaioannou et al. Eq. 4–8), precomputed or
//!   evaluated live at every ray-cast sample;
//! - [`filter`]: Ruiz et al.'s ambient maps from separable box statistics (CDF,
//!   Gaussian, Penner's bound) and opacity modulation by local variance;
//! - [`cone`]: cone tracing with tangent spheres (Dalla Favera & Celes);
//! - [`rays`]: the ray sets (6/14/26/54 directions, Fibonacci lattices).
//!
//! Each stage file holds its GPU pass (`shaders/*.wgsl`), its uniform structs and its
//! CPU twin, which mirrors the shader line by line and is what the tests compare with.

pub mod cao;
pub mod cone;
pub mod engine;
pub mod fast;
pub mod filter;
pub mod lao;
pub mod rays;
pub mod settings;
pub mod sparse;
pub mod vao;
pub mod view;

pub use engine::{Ambient, AoComputed, AoEngine, AoInput, AoRequest};
pub use settings::{
    AoMethod, AoSettings, ConePreset, ConeSet, OpacityModulation, RadiusUnit, StatisticSource,
    VaoSettings,
};
