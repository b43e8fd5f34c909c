//! The Inviwo-style `.dat` sidecar parser.
#![no_main]

use libfuzzer_sys::fuzz_target;
use volao::volume::raw::parse_dat;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match parse_dat(text) {
        Ok(dat) => {
            // Parsing is a pure function of the text (compared as Debug text: NaN ≠ NaN).
            let again = parse_dat(text).map(|d| format!("{d:?}"));
            assert_eq!(again, Ok(format!("{dat:?}")));
            if let Some(obj) = &dat.object_file {
                assert_eq!(obj.trim(), obj, "object file name keeps surrounding blanks");
            }
            // A resolution written back in the sidecar syntax reads back unchanged.
            if let Some([x, y, z]) = dat.dims {
                let again = parse_dat(&format!("Resolution: {x} {y} {z}\n"));
                assert_eq!(again.map(|d| d.dims), Ok(Some([x, y, z])));
            }
            // So does the spacing, in Rust's round-trip float notation (bit-exact but NaN).
            if let Some([x, y, z]) = dat.spacing {
                let again = parse_dat(&format!("SliceThickness: {x:?} {y:?} {z:?}\n"))
                    .map(|d| d.spacing.map(|s| s.map(f32::to_bits)));
                if [x, y, z].iter().all(|s| !s.is_nan()) {
                    assert_eq!(again, Ok(Some([x, y, z].map(f32::to_bits))));
                } else {
                    assert!(again.is_ok());
                }
            }
        }
        Err(msg) => {
            assert!(
                !msg.contains(['\n', '\r']),
                "error is not one line: {msg:?}"
            );
        }
    }
});
