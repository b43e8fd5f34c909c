//! The whole in-memory NIfTI path: NIfTI-1 header (via the `nifti` crate), NIfTI-2
//! header (ours), gzip, layout validation and the voxel read.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use volao::volume::{VoxelType, nifti};

/// Memory cap for voxels: well under libFuzzer's default 2 GiB RSS limit.
const CAP: u64 = 64 << 20;

fuzz_target!(|data: &[u8]| {
    match nifti::load_bytes(data, 0, CAP, Path::new("fuzz.nii")) {
        Ok(v) => {
            let n = v.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
            assert!(!v.dims.contains(&0), "zero dimension {:?}", v.dims);
            assert_eq!(Some(v.voxel_count()), n, "dims {:?}", v.dims);
            let ty: VoxelType = v.data.voxel_type();
            assert!((v.voxel_count() * ty.size()) as u64 <= CAP);
            // A plain file holds every voxel byte it yields, after the header.
            if !data.starts_with(&[0x1f, 0x8b]) {
                assert!(v.voxel_count() * ty.size() + 348 <= data.len());
            }
            assert!(
                v.spacing.iter().all(|s| s.is_finite() && *s > 0.0),
                "spacing {:?}",
                v.spacing
            );
            assert!(v.orientation.is_valid(), "{:?}", v.orientation);
            let s = v.scaling;
            assert!(
                s.slope.is_finite() && s.slope != 0.0 && s.inter.is_finite(),
                "{s:?}"
            );
            // Every voxel is addressable through the public accessor.
            let [nx, ny, nz] = v.dims;
            assert!(v.value(nx - 1, ny - 1, nz - 1).is_some());
            assert!(v.value(nx, 0, 0).is_none());
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "error is not one line: {msg}");
        }
    }
});
