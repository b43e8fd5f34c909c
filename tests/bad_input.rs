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
    // NIfTI-2: 65535³ f64, the example.
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
