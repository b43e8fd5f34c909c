//! The in-memory NRRD path: header parsing (fields, vectors, kinds, data-file patterns),
//! axis layout, raw/gzip/ascii/hex decoding and the geometry.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use volao::volume::nrrd;

/// Memory cap for voxels: well under libFuzzer's default 2 GiB RSS limit.
const CAP: u64 = 64 << 20;

fuzz_target!(|data: &[u8]| {
    // The header parser alone, on any text.
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = nrrd::parse_header(text, Path::new("fuzz.nhdr"));
    }
    match nrrd::load_bytes(data, CAP, Path::new("fuzz.nrrd")) {
        Ok(v) => {
            let n = v.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
            assert!(!v.dims.contains(&0), "zero dimension {:?}", v.dims);
            assert_eq!(Some(v.voxel_count()), n, "dims {:?}", v.dims);
            assert!((v.data.byte_len()) as u64 <= CAP);
            assert!(
                v.spacing.iter().all(|s| s.is_finite() && (1e-4..=1e4).contains(s)),
                "spacing {:?}",
                v.spacing
            );
            assert!(v.orientation.is_valid(), "{:?}", v.orientation);
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "error is not one line: {msg}");
        }
    }
});
