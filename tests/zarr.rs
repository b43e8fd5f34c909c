//! OME-Zarr stores: `volao convert` writes a pyramid that loads back exactly (dims,
//! spacing, affine, voxels), coarser levels are 2× means placed where their blocks are,
//! `volao info` lists the levels, an NGFF 0.4 (Zarr v2) store written by hand reads, and
//! broken stores give one clear line each.

mod common;

use common::{data, text, volao_cli};
use std::path::{Path, PathBuf};
use volao::volume::{self, Format, LoadOptions, VoxelData};

fn load(path: &Path) -> volume::Loaded {
    volume::load(path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn load_level(path: &Path, level: usize) -> volume::Loaded {
    volume::load(
        path,
        &LoadOptions {
            level,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{} level {level}: {e}", path.display()))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Converts `src` with the CLI into `dir/NAME.ome.zarr`.
fn convert(src: &Path, dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(format!("{name}.ome.zarr"));
    let mut args = vec!["convert", s(src), s(&out)];
    args.extend_from_slice(extra);
    let run = volao_cli(&args);
    assert!(run.status.success(), "{}", text(&run.stderr));
    out
}

#[test]
fn converted_nifti_loads_back_exactly() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = data("nifti/avg152T1_LR_nifti.nii.gz");
    let store = convert(&src, dir.path(), "avg152", &[]);
    let a = load(&src).volume;
    let b = load(&store);
    assert_eq!(
        b.format,
        Format::OmeZarr {
            ngff: volume::zarr::NgffVersion::V0_5,
            zarr_format: 3,
            level: 0,
            levels: 2
        }
    );
    assert_eq!(b.volume.dims, a.dims);
    assert_eq!(b.volume.spacing, a.spacing);
    assert_eq!(b.volume.orientation.rows(), a.orientation.rows());
    assert_eq!(b.volume.orientation.axis_codes(), "LAS");
    assert_eq!(
        b.volume.orientation.source,
        volume::orient::AffineSource::Header
    );
    assert!(b.volume.data.bits_eq(&a.data), "voxels differ");
    // RFC-4 orientation is in the store, so nothing is assumed.
    assert!(
        b.warnings.iter().all(|w| !w.contains("orientation")),
        "{:?}",
        b.warnings
    );
}

/// Every voxel type the writer meets in the shared data, and both orientations
/// (an RAS raw volume, LAS NIfTI), with 1, 2 and 3 levels.
#[test]
fn library_round_trip_of_several_types() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases = [
        ("nifti/avg152T1_LR_nifti2.nii.gz", 2), // f32
        ("nifti/big.nii.gz", 1),                // f32, big-endian source, ≤ 64: one level
        ("pvm/Bucky.pvm", 1),                   // u8
        ("raw/engine.raw", 3),                  // u8, 256×256×110
    ];
    for (i, (file, levels)) in cases.into_iter().enumerate() {
        let a = load(&data(file)).volume;
        let store = dir.path().join(format!("v{i}.ome.zarr"));
        let warnings = volume::save(&a, &store).expect("saves");
        assert!(warnings.is_empty(), "{file}: {warnings:?}");
        let b = load(&store);
        assert!(
            matches!(b.format, Format::OmeZarr { levels: l, .. } if l == levels),
            "{file}: {}",
            b.format
        );
        assert_eq!(b.volume.dims, a.dims, "{file}");
        assert_eq!(b.volume.spacing, a.spacing, "{file}");
        assert_eq!(b.volume.orientation.rows(), a.orientation.rows(), "{file}");
        assert!(b.volume.data.bits_eq(&a.data), "{file}: voxels differ");
    }
    // An i16 CT with 3 levels (256 → 128 → 64).
    let ct = volume::load(
        &data("raw/cranium-ct.raw"),
        &LoadOptions {
            raw: common::shared_files()
                .into_iter()
                .find(|(f, _)| *f == "raw/cranium-ct.raw")
                .map(|(_, r)| r)
                .unwrap_or_default(),
            ..Default::default()
        },
    )
    .expect("cranium loads")
    .volume;
    let store = dir.path().join("ct.ome.zarr");
    volume::save(&ct, &store).expect("saves");
    let b = load(&store);
    assert!(b.volume.data.bits_eq(&ct.data));
    assert_eq!(b.volume.data.voxel_type(), volume::VoxelType::I16);
    assert_eq!(load_level(&store, 2).volume.dims, [64, 64, 27]);
}

/// Level 1 is the 2×2×2 mean of level 0 (rounded), at twice the spacing, and its voxel
/// (0,0,0) sits at the centre of the block it averages.
#[test]
fn level_one_is_the_mean_of_level_zero_in_place() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = data("nifti/avg152T1_LR_nifti.nii.gz");
    let a = load(&src).volume;
    let store = dir.path().join("avg.ome.zarr");
    volume::save(&a, &store).expect("saves");
    let l1 = load_level(&store, 1);
    let [nx, ny, nz] = a.dims;
    let out = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    assert_eq!(l1.volume.dims, out);
    assert_eq!(l1.volume.spacing, a.spacing.map(|s| 2.0 * s));
    let VoxelData::U8(v0) = &a.data else {
        panic!("avg152 is u8")
    };
    let VoxelData::U8(v1) = &l1.volume.data else {
        panic!("level 1 keeps u8")
    };
    let mut differing = 0;
    for z in 0..out[2] {
        for y in 0..out[1] {
            for x in 0..out[0] {
                let mut sum = 0u32;
                let mut n = 0u32;
                for (xx, yy, zz) in
                    (0..8).map(|k| (2 * x + (k & 1), 2 * y + (k >> 1 & 1), 2 * z + (k >> 2)))
                {
                    if xx < nx && yy < ny && zz < nz {
                        sum += v0[xx + nx * (yy + ny * zz)] as u32;
                        n += 1;
                    }
                }
                let want = (sum as f64 / n as f64).round() as u8;
                if v1[x + out[0] * (y + out[1] * z)] != want {
                    differing += 1;
                }
            }
        }
    }
    assert_eq!(differing, 0);
    let centre = a.orientation.linear * glam::DVec3::splat(0.5) + a.orientation.offset;
    assert!(
        (l1.volume.orientation.offset - centre).abs().max_element() < 1e-9,
        "{} vs {centre}",
        l1.volume.orientation.offset
    );
    assert_eq!(l1.volume.orientation.axis_codes(), "LAS");
}

#[test]
fn info_lists_the_levels() {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = convert(&data("raw/engine.raw"), dir.path(), "engine", &[]);
    let out = volao_cli(&["info", s(&store), "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    assert_eq!(j["dims"], serde_json::json!([256, 256, 110]));
    assert!(
        j["format"]
            .as_str()
            .is_some_and(|f| f.starts_with("OME-Zarr 0.5 (Zarr v3)")),
        "{}",
        j["format"]
    );
    let dims: Vec<serde_json::Value> = j["levels"]
        .as_array()
        .expect("levels listed")
        .iter()
        .map(|l| l["dims"].clone())
        .collect();
    assert_eq!(
        dims,
        [
            serde_json::json!([256, 256, 110]),
            serde_json::json!([128, 128, 55]),
            serde_json::json!([64, 64, 28])
        ]
    );
    assert_eq!(
        j["levels"][2]["spacing_mm"],
        serde_json::json!([4.0, 4.0, 4.0])
    );
    assert_eq!(j["levels"][1]["path"], "s1");

    // Text, and --level reads a coarser one.
    let out = volao_cli(&["info", s(&store), "--level", "2"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let t = text(&out.stdout);
    for needle in ["levels:       3", "s2", "64×64×28", "level 2 of 3"] {
        assert!(t.contains(needle), "missing {needle:?} in:\n{t}");
    }
}

/// An NGFF 0.4 store on Zarr v2 as other tools write it: `.zgroup`/`.zattrs`, a
/// channel axis before z, y, x, big-endian i16, uncompressed chunks, micrometre units.
#[test]
fn ngff_04_zarr_v2_store_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let store = dir.path().join("v2.zarr");
    let level = store.join("0");
    std::fs::create_dir_all(&level).expect("mkdir");
    std::fs::write(store.join(".zgroup"), r#"{"zarr_format": 2}"#).expect("write");
    let attrs = serde_json::json!({"multiscales": [{
        "version": "0.4",
        "axes": [
            {"name": "c", "type": "channel"},
            {"name": "z", "type": "space", "unit": "micrometer"},
            {"name": "y", "type": "space", "unit": "micrometer"},
            {"name": "x", "type": "space", "unit": "micrometer"}
        ],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1.0, 500.0, 250.0, 125.0]},
            {"type": "translation", "translation": [0.0, 3000.0, 2000.0, 1000.0]}
        ]}]
    }]});
    std::fs::write(store.join(".zattrs"), attrs.to_string()).expect("write");
    // shape (c, z, y, x) = (2, 3, 4, 5), one chunk per channel.
    let zarray = serde_json::json!({
        "zarr_format": 2, "shape": [2, 3, 4, 5], "chunks": [1, 3, 4, 5],
        "dtype": ">i2", "compressor": null, "fill_value": 0, "order": "C",
        "filters": null, "dimension_separator": "."
    });
    std::fs::write(level.join(".zarray"), zarray.to_string()).expect("write");
    let n = 3 * 4 * 5;
    for c in 0..2i16 {
        let bytes: Vec<u8> = (0..n as i16)
            .flat_map(|i| (i * 10 - 300 + 1000 * c).to_be_bytes())
            .collect();
        std::fs::write(level.join(format!("{c}.0.0.0")), bytes).expect("write");
    }
    let l = load(&store);
    assert_eq!(
        l.format,
        Format::OmeZarr {
            ngff: volume::zarr::NgffVersion::V0_4,
            zarr_format: 2,
            level: 0,
            levels: 1
        }
    );
    assert_eq!(l.volume.dims, [5, 4, 3]);
    assert_eq!(l.volume.spacing, [0.125, 0.25, 0.5]);
    let want: Vec<i16> = (0..n as i16).map(|i| i * 10 - 300).collect();
    assert_eq!(l.volume.data, VoxelData::I16(want));
    assert_eq!(l.volume.orientation.offset, glam::DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(l.volume.orientation.axis_codes(), "RAS");
    let joined = l.warnings.join("\n");
    assert!(
        joined.contains("axis c (channel) has 2 entries"),
        "{joined}"
    );
    assert!(joined.contains("assuming x runs left-to-right"), "{joined}");
}

/// Each broken store: a non-zero exit and one line naming the store and the problem.
#[test]
fn bad_stores_give_one_clear_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = convert(
        &data("nifti/avg152T1_LR_nifti.nii.gz"),
        dir.path(),
        "good",
        &[],
    );

    let empty = dir.path().join("empty.zarr");
    std::fs::create_dir(&empty).expect("mkdir");

    let plain = dir.path().join("plain.zarr");
    std::fs::create_dir(&plain).expect("mkdir");
    std::fs::write(
        plain.join("zarr.json"),
        r#"{"zarr_format": 3, "node_type": "group", "attributes": {"foo": 1}}"#,
    )
    .expect("write");

    let garbled = dir.path().join("garbled.zarr");
    std::fs::create_dir(&garbled).expect("mkdir");
    std::fs::write(garbled.join("zarr.json"), "{not json").expect("write");

    let u64_store = convert(&data("nifti/big.nii.gz"), dir.path(), "u64", &[]);
    let meta_path = u64_store.join("s0").join("zarr.json");
    let mut meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&meta_path).expect("read")).expect("json");
    meta["data_type"] = "uint64".into();
    meta["fill_value"] = 0.into();
    std::fs::write(&meta_path, meta.to_string()).expect("write");

    let missing_level = convert(
        &data("nifti/avg152T1_LR_nifti.nii.gz"),
        dir.path(),
        "missing",
        &[],
    );
    std::fs::remove_dir_all(missing_level.join("s1")).expect("rm");

    let cases: [(&Path, &[&str], &str); 6] = [
        (&empty, &[], "not a Zarr store"),
        (&plain, &[], "without OME-Zarr \"multiscales\""),
        (&garbled, &[], "bad Zarr group metadata"),
        (&u64_store, &[], "voxel type uint64 is not supported"),
        (
            &good,
            &["--level", "5"],
            "level 5 requested but the store has 2 levels",
        ),
        (&missing_level, &["--level", "1"], "level 1 (array \"s1\")"),
    ];
    for (store, extra, needle) in cases {
        let mut args = vec!["info", s(store)];
        args.extend_from_slice(extra);
        let out = volao_cli(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = text(&out.stderr);
        assert_eq!(
            err.trim_end().lines().count(),
            1,
            "{args:?}: one line expected, got:\n{err}"
        );
        assert!(
            err.starts_with("error: ") && err.contains(s(store)) && err.contains(needle),
            "{args:?}: expected {needle:?} in {err}"
        );
    }

    // The writer never writes into an existing store.
    let out = volao_cli(&["convert", s(&data("pvm/Bucky.pvm")), s(&good)]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("already exists"),
        "{}",
        text(&out.stderr)
    );
    // --level on anything else is refused.
    let out = volao_cli(&["info", s(&data("pvm/Bucky.pvm")), "--level", "1"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--level applies to OME-Zarr stores only"),
        "{}",
        text(&out.stderr)
    );
}
