//! The InVesalius `.plist` sidecar reader (an XML property list → the raw layout).
#![no_main]

use libfuzzer_sys::fuzz_target;
use volao::volume::raw::parse_invesalius_plist;

fuzz_target!(|data: &[u8]| {
    match parse_invesalius_plist(data) {
        Ok(layout) => {
            // A layout is complete: dims (each ≥ 1), a type and a spacing (checked for
            // finiteness later, where it is combined with flags in `raw::resolve`).
            let dims = layout.dims.expect("a parsed plist gives dimensions");
            assert!(dims.iter().all(|&n| n >= 1), "dimension 0 in {dims:?}");
            assert!(layout.ty.is_some() && layout.spacing.is_some());
            // Parsing is a pure function of the bytes.
            let again = parse_invesalius_plist(data).map(|d| format!("{d:?}"));
            assert_eq!(again, Ok(format!("{layout:?}")));
        }
        Err(msg) => {
            assert!(!msg.contains(['\n', '\r']), "error is not one line: {msg:?}");
        }
    }
});
