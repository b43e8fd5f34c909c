//! DICOM series assembly from in-memory files: the input is split at the 4-byte marker
//! `#%#%` into up to 8 DICOM files, each parsed by dicom-rs (header and pixel data) and
//! then grouped, ordered by ImagePositionPatient, checked and decoded into one volume.
//! Panics inside dicom-rs are contained by volao (an error); any other panic aborts.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use volao::volume::dicom;

/// Memory cap for voxels: well under libFuzzer's default 2 GiB RSS limit.
const CAP: u64 = 64 << 20;

fn split(data: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut rest = data;
    while out.len() < 7 {
        match rest.windows(4).position(|w| w == b"#%#%") {
            Some(p) => {
                out.push(&rest[..p]);
                rest = &rest[p + 4..];
            }
            None => break,
        }
    }
    out.push(rest);
    out
}

/// libFuzzer's panic hook aborts on every panic, even one volao contains: dicom-rs
/// panics on some damaged input (its RLE decoder), which volao turns into an error.
/// Keep aborting on every other panic.
fn hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let fuzzer_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !volao::process::is_containing() {
                fuzzer_hook(info);
            }
        }));
    });
}

fuzz_target!(|data: &[u8]| {
    hook();
    let files = split(data);
    let mut warnings = Vec::new();
    match dicom::load_bytes(&files, None, CAP, Path::new("fuzz"), &mut warnings) {
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
            let s = v.scaling;
            assert!(s.slope.is_finite() && s.slope != 0.0 && s.inter.is_finite(), "{s:?}");
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "error is not one line: {msg}");
        }
    }
    for w in &warnings {
        assert!(!w.contains('\n'), "warning is not one line: {w}");
    }
});
