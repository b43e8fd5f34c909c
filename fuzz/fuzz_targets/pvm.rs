//! PVM / PVM2 / PVM3 headers, the PVM3 strings and the DDS v3d/v3e decompressor.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use volao::volume::format::{Format, pvm_to_volume};
use volao::volume::{Scaling, VoxelData};

/// Memory cap for voxels: well under libFuzzer's default 2 GiB RSS limit.
const CAP: u64 = 64 << 20;

fuzz_target!(|data: &[u8]| {
    let mut warnings = Vec::new();
    match pvm_to_volume(data, CAP, Path::new("fuzz.pvm"), &mut warnings) {
        Ok((v, format)) => {
            let n = v.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
            assert!(!v.dims.contains(&0), "zero dimension {:?}", v.dims);
            assert_eq!(Some(v.voxel_count()), n, "dims {:?}", v.dims);
            let bytes = match &v.data {
                VoxelData::U8(d) => d.len(),
                VoxelData::U16(d) => 2 * d.len(),
                other => panic!("PVM gave {} voxels", other.voxel_type()),
            };
            assert!(bytes as u64 <= CAP);
            assert!(
                v.spacing.iter().all(|s| s.is_finite() && *s > 0.0),
                "spacing {:?}",
                v.spacing
            );
            assert_eq!(v.scaling, Scaling::IDENTITY);
            let Format::Pvm { dds, .. } = format else {
                panic!("PVM loader reported {format}");
            };
            // Uncompressed files hold every voxel byte they yield.
            if dds.is_none() {
                assert!(bytes < data.len());
            }
            for (label, text) in &v.descriptions {
                assert!(
                    !text.is_empty() && !text.contains('\0'),
                    "{label}: {text:?}"
                );
            }
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "error is not one line: {msg}");
        }
    }
});
