//! load → write (each writer) → load gives identical voxels, spacing and scaling.

mod common;

use common::{data, shared_files};
use std::path::Path;
use volao::volume::{self, LoadOptions, Scaling, Volume, VoxelData, VoxelType, nifti};

fn reload(path: &Path) -> Volume {
    volume::load(path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("reloading {}: {e}", path.display()))
        .volume
}

/// Writers that can hold this volume exactly: PVM only stores unsigned 8/16-bit, raw has
/// no scaling field.
fn writers_for(v: &Volume) -> Vec<&'static str> {
    let mut w = vec!["nii", "nii.gz"];
    if v.scaling.is_identity() {
        w.push("raw");
        if matches!(v.data.voxel_type(), VoxelType::U8 | VoxelType::U16) {
            w.push("pvm");
        }
    }
    w
}

fn assert_round_trip(name: &str, v: &Volume, dir: &Path) {
    for ext in writers_for(v) {
        let out = dir.join(format!("{}.{ext}", name.replace('/', "_")));
        volume::save(v, &out).unwrap_or_else(|e| panic!("{name} → .{ext}: {e}"));
        let back = reload(&out);
        assert_eq!(back.dims, v.dims, "{name} via .{ext}: dims");
        assert!(
            back.data.bits_eq(&v.data),
            "{name} via .{ext}: voxels differ"
        );
        assert_eq!(back.spacing, v.spacing, "{name} via .{ext}: spacing");
        assert_eq!(back.scaling, v.scaling, "{name} via .{ext}: scaling");
        if ext.starts_with("nii") {
            assert_eq!(
                back.orientation.axis_codes(),
                v.orientation.axis_codes(),
                "{name} via .{ext}: orientation"
            );
            for (a, b) in back
                .orientation
                .rows()
                .iter()
                .flatten()
                .zip(v.orientation.rows().iter().flatten())
            {
                // NIfTI-1 stores the affine as f32.
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1.0),
                    "{name} via .{ext}: affine {a} vs {b}"
                );
            }
        }
        if ext == "pvm" {
            assert_eq!(
                back.descriptions, v.descriptions,
                "{name} via .pvm: description strings"
            );
        }
    }
}

#[test]
fn every_shared_file_survives_every_writer() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (file, raw) in shared_files() {
        let v = volume::load(
            &data(file),
            &LoadOptions {
                raw,
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{file}: {e}"))
        .volume;
        assert_round_trip(file, &v, dir.path());
    }
}

/// One small volume of every voxel type, with extreme values and (for floats) NaN/Inf.
fn every_type() -> Vec<Volume> {
    let dims = [5, 3, 4];
    let n = 60usize;
    let datas = vec![
        VoxelData::U8((0..n).map(|i| (i * 37 % 256) as u8).collect()),
        VoxelData::I8((0..n).map(|i| (i as i32 * 37 % 256 - 128) as i8).collect()),
        VoxelData::U16(
            (0..n)
                .map(|i| if i == 7 { u16::MAX } else { (i * 1000) as u16 })
                .collect(),
        ),
        VoxelData::I16(
            (0..n)
                .map(|i| {
                    if i == 3 {
                        i16::MIN
                    } else {
                        (i as i16 - 30) * 100
                    }
                })
                .collect(),
        ),
        VoxelData::U32(
            (0..n)
                .map(|i| if i == 9 { u32::MAX } else { i as u32 * 70_000 })
                .collect(),
        ),
        VoxelData::I32(
            (0..n)
                .map(|i| {
                    if i == 1 {
                        i32::MIN
                    } else {
                        (i as i32 - 30) * 70_000
                    }
                })
                .collect(),
        ),
        VoxelData::F32(
            (0..n)
                .map(|i| match i {
                    2 => f32::NAN,
                    4 => f32::INFINITY,
                    _ => i as f32 * 0.37 - 5.0,
                })
                .collect(),
        ),
        VoxelData::F64(
            (0..n)
                .map(|i| match i {
                    5 => f64::NEG_INFINITY,
                    _ => i as f64 * 1e-3 - 1e300 * (i % 2) as f64,
                })
                .collect(),
        ),
    ];
    datas
        .into_iter()
        .map(|d| Volume::new(dims, [0.5, 1.25, 3.0], d).expect("valid volume"))
        .collect()
}

#[test]
fn every_voxel_type_round_trips() {
    let dir = tempfile::tempdir().expect("temp dir");
    for v in every_type() {
        let name = format!("type_{}", v.data.voxel_type());
        assert_round_trip(&name, &v, dir.path());
    }
}

#[test]
fn scaled_nifti_keeps_stored_values_and_the_scaling() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut v = Volume::new(
        [4, 4, 4],
        [1.0; 3],
        VoxelData::U16((0..64).map(|i| i * 50).collect()),
    )
    .expect("valid");
    v.scaling = Scaling {
        slope: 1.0,
        inter: -1024.0,
    };
    assert_round_trip("scaled", &v, dir.path());
    let back = reload(&dir.path().join("scaled.nii.gz"));
    let s = back.stats();
    assert_eq!(
        (s.min, s.max),
        (-1024.0, 63.0 * 50.0 - 1024.0),
        "physical Hounsfield range"
    );
    // Raw has no scaling field: physical values are written as f32.
    volume::save(&v, &dir.path().join("scaled.raw")).expect("raw write");
    let raw = reload(&dir.path().join("scaled.raw"));
    assert_eq!(raw.data.voxel_type(), VoxelType::F32);
    assert_eq!(raw.stats().min, -1024.0);
}

#[test]
fn the_demo_volume_round_trips() {
    let dir = tempfile::tempdir().expect("temp dir");
    assert_round_trip("demo", &volume::demo::head_phantom(32), dir.path());
}

#[test]
fn dimensions_beyond_nifti1_are_written_as_nifti2() {
    let dir = tempfile::tempdir().expect("temp dir");
    let v = Volume::new(
        [40_000, 1, 2],
        [1.0; 3],
        VoxelData::U8((0..80_000).map(|i| (i % 251) as u8).collect()),
    )
    .expect("valid");
    let out = dir.path().join("wide.nii");
    volume::save(&v, &out).expect("write");
    let loaded = volume::load(&out, &LoadOptions::default()).expect("reload");
    assert_eq!(loaded.format.to_string(), "NIfTI-2");
    assert!(loaded.volume.data.bits_eq(&v.data));
}

/// Splits a `.nii` into a `.hdr`/`.img` pair (magic `ni1`, vox_offset 0).
fn split_pair(nii: &[u8], dir: &Path, stem: &str) {
    let mut hdr = nii[..348].to_vec();
    hdr[108..112].copy_from_slice(&0f32.to_le_bytes());
    hdr[344..348].copy_from_slice(b"ni1\0");
    std::fs::write(dir.join(format!("{stem}.hdr")), hdr).expect("write hdr");
    std::fs::write(dir.join(format!("{stem}.img")), &nii[352..]).expect("write img");
}

#[test]
fn hdr_img_pairs_load_from_either_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let v = reload(&data("nifti/avg152T1_LR_nifti.nii"));
    let nii = std::fs::read(data("nifti/avg152T1_LR_nifti.nii")).expect("read");
    split_pair(&nii, dir.path(), "pair");
    for name in ["pair.hdr", "pair.img"] {
        let loaded =
            volume::load(&dir.path().join(name), &LoadOptions::default()).expect("pair loads");
        assert!(loaded.volume.data.bits_eq(&v.data), "{name}");
        assert_eq!(loaded.volume.orientation.axis_codes(), "LAS");
        assert_eq!(loaded.format.to_string(), "NIfTI-1 (.hdr/.img pair)");
    }
}

#[test]
fn four_d_nifti_loads_the_requested_frame() {
    let dir = tempfile::tempdir().expect("temp dir");
    let frames: Vec<Vec<i16>> = (0..3)
        .map(|f| (0..24).map(|i| (f * 1000 + i) as i16).collect())
        .collect();
    let v = Volume::new([2, 3, 4], [1.0; 3], VoxelData::I16(frames[0].clone())).expect("valid");
    let mut bytes = nifti::encode_header(&v);
    bytes[40..42].copy_from_slice(&4i16.to_le_bytes()); // dim[0] = 4
    bytes[48..50].copy_from_slice(&3i16.to_le_bytes()); // dim[4] = 3 frames
    bytes.extend([0u8; 4]);
    for f in &frames {
        f.iter().for_each(|x| bytes.extend(x.to_le_bytes()));
    }
    let path = dir.path().join("four_d.nii");
    std::fs::write(&path, bytes).expect("write");
    for (k, frame) in frames.iter().enumerate() {
        let loaded = volume::load(
            &path,
            &LoadOptions {
                frame: k,
                ..Default::default()
            },
        )
        .expect("frame loads");
        assert_eq!(
            loaded.volume.data,
            VoxelData::I16(frame.clone()),
            "frame {k}"
        );
    }
    let err = volume::load(
        &path,
        &LoadOptions {
            frame: 3,
            ..Default::default()
        },
    )
    .expect_err("no frame 3");
    assert!(err.to_string().contains("3 frames"), "{err}");
}

/// Byte-swaps a little-endian NIfTI-2 header field by field (strings stay as they are).
fn nifti2_to_big_endian(h: &mut [u8]) {
    // (offset, element size, count) of every numeric field of the 540-byte header.
    const FIELDS: &[(usize, usize, usize)] = &[
        (0, 4, 1),    // sizeof_hdr
        (12, 2, 2),   // datatype, bitpix
        (16, 8, 8),   // dim
        (80, 8, 3),   // intent_p1..3
        (104, 8, 8),  // pixdim
        (168, 8, 10), // vox_offset .. slice_end
        (344, 4, 2),  // qform_code, sform_code
        (352, 8, 18), // quatern_b .. srow_z
        (496, 4, 3),  // slice_code, xyzt_units, intent_code
    ];
    for &(at, size, count) in FIELDS {
        for k in 0..count {
            h[at + k * size..at + (k + 1) * size].reverse();
        }
    }
}

#[test]
fn big_endian_nifti2_reads_like_little_endian() {
    let dir = tempfile::tempdir().expect("temp dir");
    let values: Vec<i16> = (0..80_000).map(|i| (i % 4001) as i16 - 2000).collect();
    let mut v = Volume::new(
        [40_000, 1, 2],
        [0.5, 2.0, 3.0],
        VoxelData::I16(values.clone()),
    )
    .expect("valid");
    v.scaling = Scaling {
        slope: 0.5,
        inter: -3.0,
    };
    let mut header = nifti::encode_header(&v);
    assert_eq!(header.len(), 540, "wide volumes are written as NIfTI-2");
    nifti2_to_big_endian(&mut header);
    let mut bytes = header;
    bytes.extend([0u8; 4]);
    values.iter().for_each(|x| bytes.extend(x.to_be_bytes()));
    let path = dir.path().join("be2.nii");
    std::fs::write(&path, bytes).expect("write");
    let loaded = volume::load(&path, &LoadOptions::default()).expect("big-endian NIfTI-2 loads");
    assert_eq!(loaded.format.to_string(), "NIfTI-2");
    assert!(loaded.volume.data.bits_eq(&v.data));
    assert_eq!(loaded.volume.spacing, v.spacing);
    assert_eq!(loaded.volume.scaling, v.scaling);
}
