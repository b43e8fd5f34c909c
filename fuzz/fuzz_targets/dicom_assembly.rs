//! DICOM series assembly without dicom-rs or pixels: the input is decoded into the
//! header values of up to 16 files (UIDs from a small alphabet so that series and
//! instances collide; positions, orientations, spacings and rescales as any f64,
//! NaN, ±inf and huge values included), checked by `FileInfo::from_tags` as a scan
//! checks them, then grouped, chosen, ordered and measured by `dicom::plan`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use volao::volume::dicom::{self, FileInfo, HeaderTags, PlaneTags};

/// Reads the input front to back; past its end every value is 0.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let (&b, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        b
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(std::array::from_fn(|_| self.u8()))
    }
    fn pick<T: Clone>(&mut self, from: &[T]) -> T {
        from[self.u8() as usize % from.len()].clone()
    }
    /// Present with probability 3/4.
    fn some<T>(&mut self, f: impl FnOnce(&mut Self) -> T) -> Option<T> {
        (self.u8() % 4 != 0).then(|| f(self))
    }
    fn int(&mut self) -> i64 {
        match self.u8() % 4 {
            0 => self.pick(&[0, -1, 65535, 65536, 1_000_000, 1_000_001, i64::MAX, i64::MIN]),
            1 => self.u64() as i64,
            _ => i64::from(self.u8() % 6),
        }
    }
    fn float(&mut self) -> f64 {
        match self.u8() % 8 {
            0 => self.pick(&[
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::MAX,
                -f64::MAX,
                1e308,
                1e30,
                1e-30,
                f64::MIN_POSITIVE,
                5e-324,
                0.0,
                -0.0,
            ]),
            1 => f64::from_bits(self.u64()),
            2 => self.pick(&[0.0, 1.0, -1.0, 0.7071068, -0.7071068, 0.99096, 0.134158]),
            // Positions and spacings on a coarse grid, so that slices line up,
            // repeat and skip.
            _ => f64::from(self.u8() as i8) * 0.5,
        }
    }
    fn floats(&mut self, usual: usize) -> Vec<f64> {
        let n = if self.u8() % 8 == 0 {
            self.u8() as usize % 8
        } else {
            usual
        };
        (0..n).map(|_| self.float()).collect()
    }
    fn text(&mut self, from: &[&str]) -> Option<String> {
        self.some(|b| b.pick(from).to_owned())
    }
    fn plane(&mut self) -> PlaneTags {
        const AXES: [[f64; 6]; 4] = [
            [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0, 0.0, 0.99096, 0.134158],
            [1.0, 0.0, 0.0, 0.0, 0.0, -1.0],
            [0.0, 1.0, 0.0, 0.0, 0.0, -1.0],
        ];
        PlaneTags {
            position: self.some(|b| b.floats(3)),
            orientation: self.some(|b| {
                if b.u8() % 2 == 0 {
                    b.pick(&AXES).to_vec()
                } else {
                    b.floats(6)
                }
            }),
            pixel_spacing: self.some(|b| b.floats(2)),
            rescale_slope: self.some(|b| b.floats(1)),
            rescale_intercept: self.some(|b| b.floats(1)),
        }
    }
    fn header(&mut self) -> HeaderTags {
        const UIDS: [&str; 6] = ["1.2.3", "1.2.3#2", "1.2.4", "9", "1.2\n3", "\u{1b}[31m"];
        const SYNTAXES: [&str; 6] = [
            "1.2.840.10008.1.2.1",
            "1.2.840.10008.1.2",
            "1.2.840.10008.1.2.5",
            "1.2.840.10008.1.2.4.80",
            "1.2.840.10008.1.2.4.100",
            "9.9",
        ];
        let small = |b: &mut Self| {
            if b.u8() % 4 == 0 {
                b.int()
            } else {
                1 + i64::from(b.u8() % 4)
            }
        };
        let number_of_frames = if self.u8() % 4 == 0 {
            Some(if self.u8() % 4 == 0 {
                self.pick(&[0, -1, 1_000_001, i64::MAX, i64::MIN, 4096])
            } else {
                1 + i64::from(self.u8() % 6)
            })
        } else {
            None
        };
        let plane = self.plane();
        let frames = (self.u8() % 4 == 0).then(|| {
            let n = self.u8() as usize % 8;
            (0..n).map(|_| self.plane()).collect()
        });
        HeaderTags {
            rows: self.some(small),
            cols: self.some(small),
            number_of_frames,
            bits_allocated: self.some(|b| b.pick(&[8, 16, 32, 16, 12, 0, 64, -8])),
            bits_stored: self.some(|b| b.int()),
            pixel_representation: self.some(|b| i64::from(b.u8() % 3)),
            samples_per_pixel: self.some(|b| b.pick(&[1, 1, 1, 3, 0, -1])),
            photometric: self.text(&["MONOCHROME2", "MONOCHROME1", "RGB"]),
            series_uid: self.text(&UIDS),
            sop_uid: self.text(&["1", "2", "3", "4", "5", "\0"]),
            series_description: self.text(&["head", "two\nlines"]),
            modality: self.text(&["CT", "MR"]),
            transfer_syntax: self.pick(&SYNTAXES).to_owned(),
            instance_number: self.some(|b| b.int()),
            slice_thickness: self.some(|b| b.floats(1)),
            plane,
            frames,
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let want = match b.u8() % 8 {
        0 => Some(b.pick(&["0", "1", "3", "18446744073709551616"]).to_owned()),
        1 => Some(b.pick(&["1.2.3", "1.2.3#2", "1.2.4#3", "nope"]).to_owned()),
        _ => None,
    };
    let max_bytes = b.pick(&[64 << 20, 0, 4096, u64::MAX]);
    let n = 1 + b.u8() as usize % 16;
    let tags: Vec<HeaderTags> = (0..n).map(|_| b.header()).collect();
    let path = Path::new("fuzz");
    let mut infos = Vec::new();
    for (k, t) in tags.iter().enumerate() {
        match FileInfo::from_tags(t, &path.join(format!("file{k}"))) {
            Ok(info) => infos.push(info),
            Err(e) => assert!(!e.to_string().contains('\n'), "error is not one line: {e}"),
        }
    }
    let run = || {
        let mut warnings = Vec::new();
        let r = dicom::plan(&infos, want.as_deref(), path, max_bytes, &mut warnings);
        (r, warnings)
    };
    let (result, warnings) = run();
    let (again, warnings_again) = run();
    assert_eq!(format!("{result:?}"), format!("{again:?}"), "not deterministic");
    assert_eq!(warnings, warnings_again, "warnings not deterministic");
    for w in &warnings {
        assert!(!w.contains('\n'), "warning is not one line: {w:?}");
    }
    let a = match result {
        Ok(a) => a,
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "error is not one line: {msg}");
            return;
        }
    };
    // The series: every one non-empty, most slices first, one stack size each.
    assert!(a.chosen < a.series.len());
    assert!(a.series.iter().all(|s| !s.slices.is_empty()));
    assert!(a.series.windows(2).all(|w| w[0].slices.len() >= w[1].slices.len()));
    let s = &a.series[a.chosen];
    let (rows, cols) = (s.slices[0].rows, s.slices[0].cols);
    assert!(s.slices.iter().all(|x| x.rows == rows && x.cols == cols));
    assert!(s.slices.iter().all(|x| a.files_used.contains(&x.file)));
    assert!(a.files_used.iter().all(|&f| f < infos.len()));
    // The stack: distinct slices of the series, dims = slices × rows × cols.
    let order = &a.geometry.order;
    assert!(!order.is_empty() && order.len() <= s.slices.len());
    let mut seen = vec![false; s.slices.len()];
    for &i in order {
        assert!(!std::mem::replace(&mut seen[i], true), "slice {i} twice");
    }
    assert_eq!(a.dims, [cols as usize, rows as usize, order.len()]);
    let bits = infos[s.slices[0].file].bits_allocated;
    let voxels = a.dims.iter().try_fold(1u64, |p, &d| p.checked_mul(d as u64));
    assert_eq!(voxels.and_then(|v| v.checked_mul(u64::from(bits / 8))), Some(a.bytes));
    assert!(a.bytes <= max_bytes);
    // Spacing in range and the affine finite, invertible and agreeing with it.
    let g = &a.geometry;
    assert!(
        g.spacing.iter().all(|s| s.is_finite() && (1e-4..=1e4).contains(s)),
        "spacing {:?}",
        g.spacing
    );
    assert!(g.orientation.is_valid(), "{:?}", g.orientation);
    for (i, &sp) in g.spacing.iter().enumerate() {
        let len = g.orientation.linear.col(i).length();
        assert!(
            (len - f64::from(sp)).abs() <= 1e-3 * f64::from(sp),
            "axis {i}: affine column {len} mm, spacing {sp} mm"
        );
    }
    let lines = dicom::describe_series(&a.series, &s.id);
    assert_eq!(lines.lines().count(), a.series.len(), "{lines:?}");
});
