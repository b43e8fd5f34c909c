//! Malformed input gets one clear error and never a panic, a hang or a huge allocation.

mod common;

use common::{Rng, data, shared_files};
use std::path::Path;
use volao::volume::{
    self, LoadOptions, Volume, VolumeError, VoxelData, format::pvm_to_volume, nifti, raw,
};

/// Memory cap for mutated files: far above any real file here, far below the machine.
const CAP: u64 = 256 << 20;

/// Loads bytes the way the file loader would, in memory: every case must return.
fn load_bytes(kind: &str, bytes: &[u8]) -> Result<Volume, VolumeError> {
    let path = Path::new("mutant");
    match kind {
        "nifti" => nifti::load_bytes(bytes, 0, CAP, path),
        "pvm" => pvm_to_volume(bytes, CAP, path, &mut Vec::new()).map(|(v, _)| v),
        _ => unreachable!(),
    }
}

/// A valid result must be self-consistent: a volume with as many voxels as its dims say.
fn check_consistent(res: Result<Volume, VolumeError>, what: &str) {
    match res {
        Ok(v) => {
            assert_eq!(
                v.voxel_count(),
                v.dims.iter().product::<usize>(),
                "{what}: inconsistent volume"
            );
            assert!(
                v.spacing.iter().all(|s| s.is_finite() && *s > 0.0),
                "{what}: bad spacing {:?}",
                v.spacing
            );
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "{what}: error is not one line: {msg}");
        }
    }
}

fn kind_of(file: &str) -> Option<&'static str> {
    if file.ends_with(".pvm") {
        Some("pvm")
    } else if file.contains(".nii") {
        Some("nifti")
    } else {
        None
    }
}

#[test]
fn truncation_sweep_never_panics() {
    for (file, _) in shared_files() {
        let Some(kind) = kind_of(file) else { continue };
        let bytes = std::fs::read(data(file)).expect("read");
        // Every offset in the first 1 KiB (headers), then 64 offsets spread over the rest.
        let mut cuts: Vec<usize> = (0..bytes.len().min(1024)).collect();
        cuts.extend((1..=64).map(|k| bytes.len() * k / 65));
        for cut in cuts {
            let res = load_bytes(kind, &bytes[..cut]);
            assert!(
                res.is_err() || cut == bytes.len(),
                "{file} cut at {cut} of {} loaded",
                bytes.len()
            );
            check_consistent(res, &format!("{file} cut at {cut}"));
        }
    }
}

#[test]
fn truncated_raw_files_report_expected_and_actual_bytes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let bytes = std::fs::read(data("raw/engine.raw")).expect("read");
    std::fs::copy(data("raw/engine.dat"), dir.path().join("engine.dat")).expect("copy sidecar");
    for cut in [0, 1, 1000, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(dir.path().join("engine.raw"), &bytes[..cut]).expect("write");
        let err = volume::load(&dir.path().join("engine.raw"), &LoadOptions::default())
            .expect_err("truncated");
        let msg = err.to_string();
        assert!(
            msg.contains(&format!("needs {} bytes", bytes.len()))
                && msg.contains(&format!("holds {cut}")),
            "{msg}"
        );
    }
}

#[test]
fn random_mutations_never_panic() {
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    for (file, _) in shared_files() {
        let Some(kind) = kind_of(file) else { continue };
        let original = std::fs::read(data(file)).expect("read");
        // Gzip files: mutate the decompressed stream too, or nearly every mutation only
        // exercises the gzip checksum.
        let mut streams = vec![original.clone()];
        if original.starts_with(&[0x1f, 0x8b]) {
            let mut plain = Vec::new();
            std::io::Read::read_to_end(
                &mut flate2::read::GzDecoder::new(&original[..]),
                &mut plain,
            )
            .expect("gunzip");
            streams.push(plain);
        }
        for stream in &streams {
            for round in 0..1000 {
                let mut bytes = stream.clone();
                let flips = 1 + rng.below(8);
                for _ in 0..flips {
                    // Mostly in the header, sometimes anywhere.
                    let span = if rng.below(4) == 0 {
                        bytes.len()
                    } else {
                        bytes.len().min(600)
                    };
                    let at = rng.below(span);
                    bytes[at] = match rng.below(3) {
                        0 => rng.next() as u8,
                        1 => bytes[at] ^ (1 << rng.below(8)),
                        _ => [0, 0xff, 0x7f, 0x80][rng.below(4)],
                    };
                }
                check_consistent(
                    load_bytes(kind, &bytes),
                    &format!("{file} mutation {round}"),
                );
            }
        }
    }
}

#[test]
fn sidecar_mutations_never_panic() {
    let mut rng = Rng(42);
    for side in ["raw/engine.dat", "raw/hydrogenatom.dat"] {
        let text = std::fs::read(data(side)).expect("read");
        for _ in 0..1000 {
            let mut bytes = text.clone();
            for _ in 0..1 + rng.below(4) {
                let at = rng.below(bytes.len());
                bytes[at] = rng.next() as u8;
            }
            if let Ok(s) = std::str::from_utf8(&bytes) {
                let _ = raw::parse_dat(s);
            }
        }
    }
}

/// A NIfTI-1 header for `dims` of `datatype`, little-endian, single file.
fn header(dims: [i16; 3], datatype: i16, pixdim: [f32; 3]) -> Vec<u8> {
    let v = Volume::new([1, 1, 1], [1.0; 3], VoxelData::U8(vec![0])).expect("valid");
    let mut h = nifti::encode_header(&v);
    for (k, d) in dims.iter().enumerate() {
        h[42 + 2 * k..44 + 2 * k].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&datatype.to_le_bytes());
    for (k, p) in pixdim.iter().enumerate() {
        h[80 + 4 * k..84 + 4 * k].copy_from_slice(&p.to_le_bytes());
    }
    h.extend([0u8; 4]);
    h
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn load_err(path: &Path) -> String {
    let msg = volume::load(path, &LoadOptions::default())
        .expect_err("must be refused")
        .to_string();
    assert!(
        msg.contains(
            &path
                .file_name()
                .expect("name")
                .to_string_lossy()
                .into_owned()
        ),
        "names the file: {msg}"
    );
    assert!(!msg.contains('\n'), "one line: {msg}");
    msg
}

#[test]
fn absurd_sizes_are_refused_before_allocating() {
    let dir = tempfile::tempdir().expect("temp dir");
    // NIfTI-1: 32767³ f64 = 281 TB.
    let p = write(
        dir.path(),
        "huge.nii",
        &header([32767, 32767, 32767], 64, [1.0; 3]),
    );
    let msg = load_err(&p);
    assert!(
        msg.contains("more than this machine can hold") || msg.contains("truncated"),
        "{msg}"
    );
    // NIfTI-2: 65535³ f64, the issue's example.
    let v = Volume::new([1, 1, 1], [1.0; 3], VoxelData::F64(vec![0.0])).expect("valid");
    let mut h = {
        let wide =
            Volume::new([40_000, 1, 1], [1.0; 3], VoxelData::U8(vec![0; 40_000])).expect("valid");
        nifti::encode_header(&wide)
    };
    assert_eq!(h.len(), 540);
    for k in 0..3 {
        h[24 + 8 * k..32 + 8 * k].copy_from_slice(&65535i64.to_le_bytes());
    }
    h[12..14].copy_from_slice(&nifti::datatype_code(v.data.voxel_type()).to_le_bytes());
    h.extend([0u8; 4]);
    let p = write(dir.path(), "huge2.nii", &h);
    let msg = load_err(&p);
    assert!(
        msg.contains("65535×65535×65535 f64") && msg.contains("more than this machine can hold"),
        "{msg}"
    );
    // Gzip: a tiny compressed file cannot hold a 1 GiB volume.
    let p = dir.path().join("claims.nii.gz");
    {
        use std::io::Write;
        let mut gz = flate2::write::GzEncoder::new(
            std::fs::File::create(&p).expect("create"),
            flate2::Compression::default(),
        );
        gz.write_all(&header([1024, 1024, 256], 2, [1.0; 3]))
            .expect("write");
        gz.finish().expect("finish");
    }
    let msg = load_err(&p);
    assert!(msg.contains("truncated") && msg.contains("gzip"), "{msg}");
    // Raw flags claiming more than the file holds.
    let p = write(dir.path(), "small.raw", &[0u8; 100]);
    let opts = LoadOptions {
        raw: volume::RawOverrides {
            dims: Some([65535, 65535, 65535]),
            ty: Some(volume::VoxelType::F64),
            ..Default::default()
        },
        ..Default::default()
    };
    let msg = volume::load(&p, &opts).expect_err("refused").to_string();
    assert!(msg.contains("small.raw"), "{msg}");
}

#[test]
fn bad_headers_get_clear_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases: &[(&str, Vec<u8>, &str)] = &[
        ("zero.nii", header([0, 4, 4], 2, [1.0; 3]), "must be ≥ 1"),
        (
            "negative.nii",
            header([4, -3, 4], 2, [1.0; 3]),
            "must be ≥ 1",
        ),
        (
            "rgb.nii",
            header([2, 2, 2], 128, [1.0; 3]),
            "RGB24 is not supported",
        ),
        (
            "complex.nii",
            header([2, 2, 2], 32, [1.0; 3]),
            "complex64 is not supported",
        ),
        ("short.nii", header([4, 4, 4], 4, [1.0; 3]), "truncated"),
    ];
    for (name, bytes, needle) in cases {
        let msg = load_err(&write(dir.path(), name, bytes));
        assert!(msg.contains(needle), "{name}: {msg}");
    }
    // 5-D vector data is refused with an explanation.
    let mut h = header([2, 2, 2], 16, [1.0; 3]);
    h[40..42].copy_from_slice(&5i16.to_le_bytes());
    h[48..50].copy_from_slice(&1i16.to_le_bytes());
    h[50..52].copy_from_slice(&3i16.to_le_bytes());
    let msg = load_err(&write(dir.path(), "vector.nii", &h));
    assert!(msg.contains("5-D") && msg.contains("3 components"), "{msg}");
}

#[test]
fn unusable_nifti_spacing_becomes_1mm_with_a_warning() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = header([2, 2, 2], 2, [f32::NAN, 0.0, -2.0]);
    bytes.extend([7u8; 8]);
    let p = write(dir.path(), "spacing.nii", &bytes);
    let loaded = volume::load(&p, &LoadOptions::default()).expect("loads");
    assert_eq!(loaded.volume.spacing, [1.0, 1.0, 2.0]);
    assert_eq!(loaded.warnings.len(), 3, "{:?}", loaded.warnings);
}

#[test]
fn nan_and_inf_voxels_load_and_are_counted() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = vec![
        1.0f32,
        f32::NAN,
        f32::INFINITY,
        -2.0,
        f32::NEG_INFINITY,
        0.5,
        3.0,
        f32::NAN,
    ];
    let v = Volume::new([2, 2, 2], [1.0; 3], VoxelData::F32(data)).expect("valid");
    let p = dir.path().join("nan.nii.gz");
    volume::save(&v, &p).expect("write");
    let s = volume::load(&p, &LoadOptions::default())
        .expect("loads")
        .volume
        .stats();
    assert_eq!((s.non_finite, s.finite, s.min, s.max), (4, 4, -2.0, 3.0));
}

#[test]
fn raw_without_a_layout_says_which_flags_to_pass() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = write(dir.path(), "mystery.raw", &[0u8; 64]);
    let msg = load_err(&p);
    assert!(msg.contains("--dims") && msg.contains("--type"), "{msg}");
    let p = write(dir.path(), "mystery.bin", &[1u8; 64]);
    assert!(load_err(&p).contains("unknown volume format"));
    let bad = volume::RawOverrides {
        dims: Some([4, 4, 4]),
        ty: Some(volume::VoxelType::U8),
        spacing: Some([1.0, f32::NAN, 1.0]),
        ..Default::default()
    };
    let msg = volume::load(
        &dir.path().join("mystery.raw"),
        &LoadOptions {
            raw: bad,
            ..Default::default()
        },
    )
    .expect_err("nan spacing")
    .to_string();
    assert!(msg.contains("spacing"), "{msg}");
}

// ---- DICOM and NRRD: truncation and mutation -------------------------------------------

/// Small DICOM files in several transfer syntaxes (native, deflate, RLE, JPEG 2000,
/// JPEG lossless, big endian, enhanced multi-frame).
const DICOM_SMALL: &[&str] = &[
    "dicom/files/CT_small.dcm",
    "dicom/files/deflated.dcm",
    "dicom/files/emri_small_RLE.dcm",
    "dicom/files/emri_small_big_endian.dcm",
    "dicom/files/emri_small_jpeg_2k_lossless.dcm",
    "dicom/files/eCT_Supplemental.dcm",
    "dicom/files/jpeg_lossless_sel1.dcm",
];

fn shared(rel: &str) -> Vec<u8> {
    let p = common::data_dir().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn dicom_bytes(files: &[&[u8]]) -> Result<Volume, VolumeError> {
    volume::dicom::load_bytes(files, None, CAP, Path::new("mutant"), &mut Vec::new())
}

fn nrrd_bytes(bytes: &[u8]) -> Result<Volume, VolumeError> {
    volume::nrrd::load_bytes(bytes, CAP, Path::new("mutant.nrrd"))
}

/// An attached NRRD built from the shared detached one (header + its raw voxels), and a
/// small gzip one written by volao.
fn nrrd_samples() -> Vec<(String, Vec<u8>)> {
    let header = shared("nrrd/avg152.nhdr");
    let text = String::from_utf8(header).expect("text header");
    let attached: String = text
        .lines()
        .filter(|l| !l.starts_with("data file"))
        .map(|l| format!("{l}\n"))
        .collect();
    let mut avg = attached.into_bytes();
    avg.push(b'\n');
    avg.extend(shared("nrrd/avg152.raw"));
    let dir = tempfile::tempdir().expect("temp dir");
    let small = Volume::new(
        [12, 10, 8],
        [0.5, 1.0, 2.0],
        VoxelData::I16((0..960).map(|i| (i * 37 % 2000 - 1000) as i16).collect()),
    )
    .expect("valid");
    let p = dir.path().join("small.nrrd");
    volume::save(&small, &p).expect("write nrrd");
    vec![
        ("avg152 attached".into(), avg),
        ("small gzip".into(), std::fs::read(&p).expect("read")),
        ("4-D ascii".into(), shared("nrrd/4d-example4.nrrd")),
    ]
}

#[test]
fn dicom_and_nrrd_truncation_sweep_never_panics() {
    for file in DICOM_SMALL {
        let bytes = shared(file);
        let whole = dicom_bytes(&[&bytes]).unwrap_or_else(|e| panic!("{file}: {e}"));
        let mut cuts: Vec<usize> = (0..bytes.len().min(1024)).step_by(13).collect();
        cuts.extend((1..=24).map(|k| bytes.len() * k / 25));
        for cut in cuts {
            match dicom_bytes(&[&bytes[..cut]]) {
                // A cut after the pixel data may leave a complete image.
                Ok(v) => assert!(
                    v.data.bits_eq(&whole.data),
                    "{file} cut at {cut}: wrong voxels"
                ),
                Err(e) => assert!(!e.to_string().contains('\n'), "{file}: {e}"),
            }
        }
    }
    for (name, bytes) in nrrd_samples() {
        let whole = nrrd_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut cuts: Vec<usize> = (0..bytes.len().min(600)).step_by(3).collect();
        cuts.extend((1..=24).map(|k| bytes.len() * k / 25));
        for cut in cuts {
            match nrrd_bytes(&bytes[..cut]) {
                Ok(v) => assert!(
                    v.data.bits_eq(&whole.data) || name == "4-D ascii",
                    "{name} cut at {cut} of {} loaded wrong voxels",
                    bytes.len()
                ),
                Err(e) => assert!(!e.to_string().contains('\n'), "{name}: {e}"),
            }
        }
    }
}

#[test]
fn dicom_and_nrrd_mutations_never_panic() {
    let mut rng = Rng(0xd1c0_4e44_0000_0017);
    let mut mutate = |bytes: &[u8], header: usize| {
        let mut b = bytes.to_vec();
        for _ in 0..1 + rng.below(8) {
            let span = if rng.below(4) == 0 {
                b.len()
            } else {
                b.len().min(header)
            };
            let at = rng.below(span);
            b[at] = match rng.below(3) {
                0 => rng.next() as u8,
                1 => b[at] ^ (1 << rng.below(8)),
                _ => [0, 0xff, 0x7f, 0x80][rng.below(4)],
            };
        }
        b
    };
    for file in DICOM_SMALL {
        let bytes = shared(file);
        for round in 0..40 {
            let m = mutate(&bytes, 2048);
            check_consistent(dicom_bytes(&[&m]), &format!("{file} mutation {round}"));
        }
    }
    // Series assembly: three MR slices, one of them mutated.
    let slices: Vec<Vec<u8>> = (1..=3)
        .map(|k| shared(&format!("dicom/brain-mr/brain_{k:03}.dcm")))
        .collect();
    for round in 0..30 {
        let m = mutate(&slices[round % 3], 2048);
        let mut files: Vec<&[u8]> = slices.iter().map(Vec::as_slice).collect();
        files[round % 3] = &m;
        check_consistent(dicom_bytes(&files), &format!("series mutation {round}"));
    }
    for (name, bytes) in nrrd_samples() {
        for round in 0..100 {
            let m = mutate(&bytes, 500);
            check_consistent(nrrd_bytes(&m), &format!("{name} mutation {round}"));
        }
    }
}

// ---- Integrity of gzip streams ---------------------------------------------------------

fn gzip_cases(original: &[u8]) -> Vec<(&'static str, Vec<u8>)> {
    let n = original.len();
    let mut flipped = original.to_vec();
    flipped[n / 2] ^= 0x10;
    let mut crc = original.to_vec();
    crc[n - 8] ^= 0x01;
    let mut isize = original.to_vec();
    isize[n - 4] ^= 0x01;
    vec![
        ("flipped deflate bit", flipped),
        ("bad CRC32", crc),
        ("bad ISIZE", isize),
    ]
}

#[test]
fn corrupt_gzip_nifti_and_nrrd_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (file, name) in [
        ("nifti/avg152T1_LR_nifti.nii.gz", "case.nii.gz"),
        ("nrrd/cranium-ct.nrrd", "case.nrrd"),
    ] {
        let original = shared(file);
        for (what, bytes) in gzip_cases(&original) {
            let p = write(dir.path(), name, &bytes);
            let msg = load_err(&p);
            assert!(
                msg.contains("gzip") || msg.contains("corrupt"),
                "{file}, {what}: {msg}"
            );
        }
        // And the in-memory loaders used by fuzzing agree.
        for (what, bytes) in gzip_cases(&original) {
            let res = if name.ends_with(".nrrd") {
                nrrd_bytes(&bytes)
            } else {
                nifti::load_bytes(&bytes, 0, CAP, Path::new("m.nii.gz"))
            };
            assert!(res.is_err(), "{file}, {what}: loaded from memory");
        }
    }
}

// ---- Absurd values ---------------------------------------------------------------------

#[test]
fn absurd_spacing_becomes_1mm_with_a_warning_naming_the_field() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = header([2, 2, 2], 2, [1e-30, 1e30, 3e38]);
    bytes.extend([7u8; 8]);
    let p = write(dir.path(), "absurd.nii", &bytes);
    let l = volume::load(&p, &LoadOptions::default()).expect("loads");
    assert_eq!(l.volume.spacing, [1.0, 1.0, 1.0]);
    for k in 1..=3 {
        assert!(
            l.warnings
                .iter()
                .any(|w| w.contains(&format!("pixdim[{k}]"))),
            "{:?}",
            l.warnings
        );
    }
    // A .dat sidecar with an absurd SliceThickness.
    write(dir.path(), "v.raw", &[1u8; 8]);
    write(
        dir.path(),
        "v.dat",
        b"ObjectFileName: v.raw\nResolution: 2 2 2\nSliceThickness: 1 1e-30 1\nFormat: UCHAR\n",
    );
    let l = volume::load(&dir.path().join("v.dat"), &LoadOptions::default()).expect("loads");
    assert_eq!(l.volume.spacing, [1.0, 1.0, 1.0]);
    assert!(
        l.warnings
            .iter()
            .any(|w| w.contains(".dat SliceThickness (y)")),
        "{:?}",
        l.warnings
    );
    // NRRD spacings.
    let text = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nspacings: 1e30 1 1\nencoding: raw\n\n\0\0\0\0\0\0\0\0";
    let p = write(dir.path(), "s.nrrd", text);
    let l = volume::load(&p, &LoadOptions::default()).expect("loads");
    assert_eq!(l.volume.spacing, [1.0, 1.0, 1.0]);
    assert!(
        l.warnings.iter().any(|w| w.contains("spacings (x)")),
        "{:?}",
        l.warnings
    );
}

#[test]
fn infinite_scl_slope_is_ignored_with_a_warning() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = header([2, 2, 2], 2, [1.0; 3]);
    bytes[112..116].copy_from_slice(&f32::INFINITY.to_le_bytes());
    bytes.extend([7u8; 8]);
    let p = write(dir.path(), "inf.nii", &bytes);
    let l = volume::load(&p, &LoadOptions::default()).expect("loads");
    assert!(l.volume.scaling.is_identity());
    assert!(
        l.warnings.iter().any(|w| w.contains("scl_slope = inf")),
        "{:?}",
        l.warnings
    );
}

#[test]
fn f64_beyond_f32_range_is_rescaled_with_a_warning() {
    let dir = tempfile::tempdir().expect("temp dir");
    let values = vec![1e300, -2e300, 0.0, 5e299, 1e-10, 3e300, 7.0, -1e300];
    let v = Volume::new([2, 2, 2], [1.0; 3], VoxelData::F64(values.clone())).expect("valid");
    let p = dir.path().join("huge.nii");
    volume::save(&v, &p).expect("write");
    let l = volume::load(&p, &LoadOptions::default()).expect("loads");
    assert!(
        l.warnings.iter().any(|w| w.contains("f32")),
        "{:?}",
        l.warnings
    );
    // Stored values are kept exactly; the GPU copy is scaled into f32 range.
    assert!(l.volume.data.bits_eq(&VoxelData::F64(values.clone())));
    let factor = volume::f64_scale_for_f32(&l.volume.data).expect("needs scaling");
    // f32 keeps ~7 digits of the largest magnitude; values 1e300 times smaller round to 0.
    let max_abs = values.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for x in &values {
        let texel = (x / factor) as f32;
        assert!(texel.is_finite(), "{x} / {factor}");
        assert!(
            (texel as f64 * factor - x).abs() <= 1e-6 * max_abs,
            "{x} / {factor}"
        );
    }
}

// ---- Messages --------------------------------------------------------------------------

#[test]
fn header_without_its_image_names_both_files_and_the_os_error_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::copy(
        common::data_dir().join("analyze/analyze75.hdr"),
        dir.path().join("lonely.hdr"),
    )
    .expect("copy");
    let msg = load_err(&dir.path().join("lonely.hdr"));
    assert!(msg.contains("lonely.img"), "{msg}");
    assert_eq!(msg.matches("os error 2").count(), 1, "{msg}");
    // The same for a NIfTI pair.
    let v = Volume::new([2, 2, 2], [1.0; 3], VoxelData::U8(vec![1; 8])).expect("valid");
    let mut h = nifti::encode_header(&v);
    h[344..348].copy_from_slice(b"ni1\0");
    write(dir.path(), "pair.hdr", &h);
    let msg = load_err(&dir.path().join("pair.hdr"));
    assert!(msg.contains("pair.img"), "{msg}");
    assert_eq!(msg.matches("os error 2").count(), 1, "{msg}");
}

#[test]
fn dat_naming_a_missing_or_absurd_file_names_the_dat_and_cuts_the_name() {
    let dir = tempfile::tempdir().expect("temp dir");
    write(
        dir.path(),
        "gone.dat",
        b"ObjectFileName: gone.raw\nResolution: 2 2 2\nFormat: UCHAR\n",
    );
    let msg = load_err(&dir.path().join("gone.dat"));
    assert!(msg.contains("gone.raw"), "{msg}");
    let long = format!("x{}\u{0}y.raw", "a".repeat(5000));
    write(
        dir.path(),
        "long.dat",
        format!("ObjectFileName: {long}\nResolution: 2 2 2\nFormat: UCHAR\n").as_bytes(),
    );
    let msg = load_err(&dir.path().join("long.dat"));
    assert!(msg.len() < 600, "{} characters: {msg}", msg.len());
    assert!(!msg.contains('\0'), "raw NUL in {msg:?}");
}

// ---- DICOM series assembly on plain header values (what fuzz/dicom_assembly drives) ----

/// A single-frame axial slice of 4×3 16-bit pixels at height `z`.
fn slice_tags(series: &str, sop: &str, z: f64) -> volume::dicom::HeaderTags {
    volume::dicom::HeaderTags {
        rows: Some(3),
        cols: Some(4),
        series_uid: Some(series.into()),
        sop_uid: Some(sop.into()),
        transfer_syntax: "1.2.840.10008.1.2.1".into(),
        plane: volume::dicom::PlaneTags {
            position: Some(vec![0.0, 0.0, z]),
            orientation: Some(vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
            pixel_spacing: Some(vec![0.5, 0.25]),
            ..Default::default()
        },
        ..Default::default()
    }
}

fn plan_of(
    tags: &[volume::dicom::HeaderTags],
) -> (Result<volume::dicom::Assembly, VolumeError>, Vec<String>) {
    let infos: Vec<_> = tags
        .iter()
        .enumerate()
        .map(|(k, t)| {
            volume::dicom::FileInfo::from_tags(t, Path::new(&format!("f{k}.dcm"))).expect("valid")
        })
        .collect();
    let mut warnings = Vec::new();
    let plan = volume::dicom::plan(&infos, None, Path::new("dir"), CAP, &mut warnings);
    (plan, warnings)
}

#[test]
fn dicom_assembly_from_header_values_orders_measures_and_reports_gaps() {
    // z = 6, 0, 2, 2 (a duplicate), 4, 12: two slices missing, at 8 and 10.
    let zs = [6.0, 0.0, 2.0, 2.0, 4.0, 12.0];
    let tags: Vec<_> = zs
        .iter()
        .enumerate()
        .map(|(k, &z)| slice_tags("1.2.3", &k.to_string(), z))
        .collect();
    let (plan, warnings) = plan_of(&tags);
    let a = plan.expect("assembles");
    assert_eq!(a.dims, [4, 3, 5]);
    assert_eq!(a.bytes, 4 * 3 * 5 * 2);
    let s = &a.series[a.chosen];
    let z: Vec<f64> = a
        .geometry
        .order
        .iter()
        .map(|&i| s.slices[i].position.expect("positioned").z)
        .collect();
    assert_eq!(z, [0.0, 2.0, 4.0, 6.0, 12.0]);
    assert_eq!(a.geometry.spacing, [0.25, 0.5, 2.0]);
    assert!(
        warnings.iter().any(|w| w.contains("1 slice repeat")),
        "{warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("about 2 slice(s) seem to be missing")),
        "{warnings:?}"
    );
    // A NaN position is no position: the stack falls back to instance order, 1 mm.
    let mut tags = tags;
    tags[4].plane.position = Some(vec![0.0, f64::NAN, 4.0]);
    let (plan, warnings) = plan_of(&tags);
    assert_eq!(plan.expect("assembles").geometry.spacing[2], 1.0);
    assert!(
        warnings.iter().any(|w| w.contains("instance order")),
        "{warnings:?}"
    );
}

/// Found by fuzz/dicom_assembly: a SeriesInstanceUID or SeriesDescription with a
/// newline or an escape sequence went raw into the "several series" warning and the
/// series list of `volao info`.
#[test]
fn dicom_series_text_with_control_characters_stays_on_one_line() {
    let mut tags = vec![
        slice_tags("1.2\n3", "1", 0.0),
        slice_tags("1.2\n3", "2", 1.0),
        slice_tags("\u{1b}[31m", "3", 0.0),
    ];
    tags[2].series_description = Some("two\nlines".into());
    let (plan, warnings) = plan_of(&tags);
    let a = plan.expect("assembles");
    assert_eq!(a.series.len(), 2);
    let several = warnings
        .iter()
        .find(|w| w.contains("series here"))
        .expect("several series reported");
    assert!(
        several.contains(r"1.2\n3") && !several.contains('\n'),
        "{several:?}"
    );
    let list = volume::dicom::describe_series(&a.series, &a.series[a.chosen].id);
    assert_eq!(list.lines().count(), 2, "{list:?}");
    assert!(
        !list.contains('\u{1b}') && list.contains(r"two\nlines"),
        "{list:?}"
    );
}

// ---- MGH/MGZ ------------------------------------------------------------------------

fn mgh_bytes(bytes: &[u8]) -> Result<Volume, VolumeError> {
    volume::mgh::load_bytes(bytes, 0, CAP, Path::new("mutant.mgh"), &mut Vec::new())
}

/// A two-frame 6×5×4 i16 MGH with an oblique Mdc, and the same gzipped (MGZ).
fn mgh_samples() -> Vec<(&'static str, Vec<u8>)> {
    let h = volume::mgh::Header {
        version: 1,
        dims: [6, 5, 4, 2],
        ty: 4,
        dof: 0,
        good_ras: 1,
        delta: [0.9, 1.1, 2.5],
        mdc: [[0.8, 0.6, 0.0], [-0.6, 0.8, 0.0], [0.0, 0.0, -1.0]],
        pxyz_c: [1.0, 2.0, 3.0],
    };
    let mut plain = h.to_bytes();
    for i in 0..6 * 5 * 4 * 2 {
        plain.extend(((i * 37 % 2000) as i16 - 1000).to_be_bytes());
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut gz, &plain).expect("gzip");
    vec![("mgh", plain), ("mgz", gz.finish().expect("gzip"))]
}

#[test]
fn mgh_truncation_and_mutations_never_panic() {
    let mut rng = Rng(0x0f5e_4f00_0000_0017);
    for (name, bytes) in mgh_samples() {
        let whole = mgh_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut cuts: Vec<usize> = (0..bytes.len().min(400)).collect();
        cuts.extend((1..=24).map(|k| bytes.len() * k / 25));
        for cut in cuts {
            match mgh_bytes(&bytes[..cut]) {
                // Frame 0 may be complete in a plain file cut inside frame 1.
                Ok(v) => assert!(
                    name == "mgh" && cut >= 284 + 240 && v.data.bits_eq(&whole.data),
                    "{name} cut at {cut} of {} loaded",
                    bytes.len()
                ),
                Err(e) => {
                    let msg = e.to_string();
                    assert!(!msg.contains('\n'), "{name}: {msg}");
                    assert!(msg.starts_with("mutant.mgh: "), "{name}: {msg}");
                }
            }
        }
        for round in 0..300 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.below(6) {
                let span = if rng.below(4) == 0 { b.len() } else { 90 };
                let at = rng.below(span.min(b.len()));
                b[at] = match rng.below(3) {
                    0 => rng.next() as u8,
                    1 => b[at] ^ (1 << rng.below(8)),
                    _ => [0, 0xff, 0x7f, 0x80][rng.below(4)],
                };
            }
            let res = mgh_bytes(&b);
            if let Ok(v) = &res {
                assert!(v.orientation.is_valid(), "{name} mutation {round}");
            }
            check_consistent(res, &format!("{name} mutation {round}"));
        }
    }
}
