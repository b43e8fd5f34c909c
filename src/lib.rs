//! volao: direct volume rendering with physically based, clip-aware ambient occlusion.
//!
//! How data flows from a file to a pixel:
//!
//! 1. [`volume`] loads a file (NIfTI, Analyze, NRRD, DICOM series, PVM/DDS, raw) into a [`volume::Volume`]: voxels in
//!    their stored type and units, spacing in mm, orientation in RAS.
//! 2. `tf` maps values to colour and opacity (transfer function, in the data's units).
//! 3. `ao` computes ambient occlusion volumes (LAO, CAO, filter-based, cone-traced,
//!    Beer's-law positional AO) — each on the GPU with a CPU twin.
//! 4. `clip` turns clip meshes into depth and dilation maps for exact CAO.
//! 5. [`gpu`] owns the device; `render` ray-casts the volume with the AO term.
//! 6. `app` is the eframe viewer; `scene` files reproduce any view headlessly.
//!
//! Steps 2–6 land with their issues; today the crate has the volume model, loaders,
//! writers, the demo volume and the GPU device path.

pub mod ao;
pub mod app;
pub mod bench;
pub mod bench_cao;
pub mod bench_filter;
pub mod clip;
pub mod gpu;
pub mod process;
pub mod render;
pub mod scene;
pub mod tf;
pub mod volume;
