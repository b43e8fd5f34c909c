//! OME-Zarr stores (NGFF 0.4 on Zarr v2, NGFF 0.5 on Zarr v3; local folders), read with
//! `zarrs` and `ome_zarr_metadata`.
//!
//! - [`meta`]: the multiscale metadata (axes, units, scale/translation, RFC-4 orientation).
//! - [`read`]: one resolution level into a [`super::Volume`], and the list of levels.
//! - [`write`]: a volume as an NGFF 0.5 pyramid, readable by the Python `ome-zarr` package.
//!
//! Axes: volao's voxel x, y, z are the array's last, middle and first spatial axes (an
//! OME-Zarr `(z, y, x)` array in C order has x fastest, as volao's voxels). Without RFC-4
//! orientation an image is taken as RAS (x left-to-right, y posterior-to-anterior, z
//! inferior-to-superior), with a warning: see `docs/ome-zarr.md`.

pub mod meta;
pub mod read;
pub mod write;

pub use meta::NgffVersion;
pub use read::{LevelInfo, StoreInfo, ZarrLoaded, is_zarr_store, load, store_info};
pub use write::save;
