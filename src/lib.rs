//! volao: direct volume rendering with physically based, clip-aware ambient occlusion.
//!
//! How data flows from a file to a pixel (modules in that order):
//!
//! 1. [`volume`] loads a file (NIfTI, Analyze, NRRD, MGH/MGZ, DICOM series, OME-Zarr, PVM/DDS, raw) into a [`volume::Volume`]: voxels in
//!    their stored type and units, spacing in mm, orientation in RAS.
//!    [`labels`] places a segmentation label map on a volume's grid through the two
//!    affines, with its segments' names and colours and statistics of the volume under
//!    each; [`labels::style`] turns what the user chose per segment (visible, opacity,
//!    colour, tint/replace, outline) and which segments each clip shape cuts into
//!    classes (one per combination of overlapping segments) and their looks.
//! 2. [`tf`] maps values to colour and opacity (the transfer function, in the data's
//!    units); [`scene`] files hold a volume, its transfer function, camera, light, AO
//!    settings, clip shapes, meshes and segmentation, so any view can be reproduced
//!    headlessly.
//! 3. [`texels`] turns the volume into texels for the GPU (halved until it fits), with
//!    the block ranges every stage's skipping reads, and uploads them
//!    ([`texels::gpu::GpuVolume`]: the density, occupancy, block ranges and baked table);
//!    it sits below [`ao`] and [`render`], which both read it (the ray caster's
//!    `render::gpu::RenderVolume` adds AO, modulation, gradient and extras around it). Every GPU stage reads the volume through one module,
//!    `shaders/volume.wgsl` (bind group 3: texels, sampler, [`texels::gpu_data::VolumeMap`],
//!    table; built by [`texels::reader`]), and every CPU twin through its twin
//!    [`sample::VolumeSampler`]; [`sample`] also holds trilinear sampling, f16 mip
//!    chains and how far off a sample AO is read, exactly as the shaders do them. A
//!    segmentation is part of the same reader ([`texels::segments`]: bindings 4–7, the
//!    classes' filtered look and weight gradient, their cuts), compiled into a stage's
//!    pipeline only where a volume has one, so `opacity_at` and `classify_at` give every
//!    mode, shading and AO stage the segments' opacity and colour.
//! 4. [`gpu`] owns the device (one path for viewer, CLI and tests), the shaders, the
//!    resource helpers, [`gpu::dispatch::SlabDispatch`] (the z-slab loop of the dense
//!    per-voxel compute stages) and [`gpu::dispatch::BrickDispatch`] (CAO's lists of
//!    8³ bricks, LAO's of readable voxels), which in the viewer cut long work into short submissions
//!    ([`gpu::dispatch::Slicing`]). Each stage's pipelines are built once per device
//!    ([`gpu::Gpu::stage`]).
//! 5. [`ao`] computes the ambient factor `A(x)`: [`ao::AoEngine`] picks the method's stage
//!    (LAO, CAO, positional AO, filter maps, cone tracing; each a GPU pass with its CPU
//!    twin beside it) and the GPU or the twin; [`ao::sparse`] says which bricks and voxels LAO
//!    and CAO visit (those the ray caster can read, near a shape) and which 4³ cells
//!    their rays step over; a CAO frame's step IV marks a voxel only if one of its rays
//!    passes near a cut, lists the voxels it marked and ray casts only those
//!    ([`ao::cao`]'s voxel list). [`ao::view`] narrows that to one image: the ray
//!    caster's visibility pass (`MARK_AO`) marks the voxels its AO reads weigh, and
//!    `volao render` computes LAO and CAO only there. [`clip`] turns clip shapes into
//!    the depth and dilation maps CAO and the ray caster clip with.
//! 6. [`render`] ray-casts the volume into an image in one of its [`render::RenderMode`]s,
//!    stepping over 4³ blocks that cannot change the pixel
//!    (compositing with the AO factor on ambient and diffuse light, shadows from
//!    `render::shadow`'s filtered light volume and surfaces; MIP, MinIP, average;
//!    isosurface), shading from [`render::gradient`]'s precomputed central differences
//!    (one fetch per gradient instead of six); [`render::offscreen`] does one frame for the CLI and tests on the
//!    device it is given. [`render::reuse`] says where clip shapes that moved can change
//!    an image, so a frame of the same view casts only the rays that pass there.
//!    [`slice`] cuts axial, coronal and sagittal slices of the volume in patient
//!    orientation (a grid on the RAS axes over any affine, radiological by default) for
//!    the viewer's slice panes, `volao slice` and `volao render --layout`, and picks the
//!    first visible surface under a point of the 3-D view.
//! 7. `app` (cargo feature `viewer`, on by default) is the eframe viewer: the same
//!    texels, stages and ray caster behind a UI (the viewer owns its viewport's GPU
//!    work; egui's callback resources hold only the draw pipelines, and each frame's
//!    paint callback carries the image to show)
//!    whose background jobs compute AO (shown first as an ambient-map preview),
//!    modulation and light volumes; the demo opens carved, with AO. Its viewport image
//!    (the ray cast in strips and tiles costed by what the same part of the picture took
//!    last time) and CAO's per-frame update behind it are submitted in slices between
//!    UI frames ([`gpu::pacer::Pacer`]), so the UI thread never waits for the GPU; a
//!    dragged shape's images read CAO's `V_PAO` while its `V_AO` is updated (never a
//!    `V_AO` of another pose), each starting as a copy of the last image of its view and
//!    casting only the rays near what changed, at most at the interactive target rate
//!    while the update runs, and at rest the image waits for the exact one. Files open
//!    on the 2×2 layout (`app::slices`: axial, 3-D, coronal, sagittal, one crosshair).
//!
//! [`headless`] is the one path from a scene file to a PNG or an AO volume without a
//! window: `volao render`, `volao ao`, `volao batch` and the Python module (`python/`)
//! all load, render and compute through it, on one device per process.
//!
//! The command-line interface and the benchmarks live in the binary (`src/bin/volao`);
//! [`process`] holds the few process-wide settings it makes at start.

pub mod volume;

pub mod labels;

pub mod scene;
pub mod tf;

pub mod texels;

pub mod sample;

pub mod gpu;

pub mod ao;
pub mod clip;

pub mod render;

pub mod slice;

pub mod headless;

#[cfg(feature = "viewer")]
pub mod app;

pub mod process;
