//! Segmentation label maps on real data: the facts table of ../shared/data/README.md
//! through `volao info --labels --json`, names and colours from every place they are
//! kept, placement through the affines, and one-line errors for bad inputs.

mod common;

use common::data;
use std::path::Path;
use std::process::{Command, Output};
use volao::labels::{self, LabelMap, SegmentKey};
use volao::volume::{self, LoadOptions, Orientation, Volume, VoxelData};

const TS_CT: &str = "labels/totalsegmentator/example_ct.nii.gz";
const TS_SEG: &str = "labels/totalsegmentator/example_seg_fast_force_split.nii.gz";
const SLICER_CT: &str = "labels/slicer/CTChest4.nrrd";
const SLICER_SEG: &str = "labels/slicer/Segmentation.seg.nrrd";
const SLICER_LAYERS: &str = "labels/slicer/SegmentationOverlapping.seg.nrrd";

fn volao(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volao"))
        .args(args)
        .output()
        .expect("volao runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn arg(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn image(rel: &str) -> Volume {
    volume::load(&data(rel), &LoadOptions::default())
        .expect("image loads")
        .volume
}

fn labels_on(seg: &Path, table: Option<&Path>, image: &Volume) -> LabelMap {
    labels::load(seg, table, image).expect("labels load").labels
}

fn key(layer: u16, value: u16) -> SegmentKey {
    SegmentKey { layer, value }
}

/// `volao info IMAGE --labels SEG --json`'s segments as (id → (voxels, median)).
fn info_segments(image: &str, seg: &str) -> Vec<serde_json::Value> {
    let out = volao(&[
        "info",
        arg(&data(image)),
        "--labels",
        arg(&data(seg)),
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    j["segments"].as_array().expect("a segments array").clone()
}

fn check_facts(segments: &[serde_json::Value], facts: &[(u64, &str, u64, f64)]) {
    for &(id, name, voxels, median) in facts {
        let s = segments
            .iter()
            .find(|s| s["id"] == id && s["layer"] == 0)
            .unwrap_or_else(|| panic!("segment {id} missing"));
        assert_eq!(s["name"], name, "segment {id}");
        assert_eq!(s["voxels"], voxels, "segment {id}");
        assert_eq!(s["median"], median, "segment {id}");
    }
}

#[test]
fn facts_table_totalsegmentator() {
    let segments = info_segments(TS_CT, TS_SEG);
    assert_eq!(segments.len(), 61);
    check_facts(
        &segments,
        &[
            (5, "liver", 41_692, 46.0),
            (1, "spleen", 9_668, 35.0),
            (52, "aorta", 1_839, 41.0),
            (63, "inferior_vena_cava", 2_266, 40.0),
            (31, "vertebrae_L1", 2_220, 161.0),
            // Even counts whose two middle values differ: numpy 2.4.6's np.median
            // gives 3.5 and 182.5 (the facts table's medians do not tell the conventions
            // apart: their middle values are equal).
            (9, "adrenal_gland_left", 210, 3.5),
            (27, "vertebrae_L5", 2_508, 182.5),
        ],
    );
    let liver = segments.iter().find(|s| s["id"] == 5).expect("liver");
    // 41,692 voxels of 3 × 3 × 3 mm.
    assert!((liver["volume_ml"].as_f64().expect("number") - 1125.684).abs() < 1e-9);
}

#[test]
fn facts_table_slicer() {
    let segments = info_segments(SLICER_CT, SLICER_SEG);
    assert_eq!(segments.len(), 7);
    check_facts(
        &segments,
        &[
            (1, "ribs", 8_487, 206.0),
            (5, "right lung", 34_450, -862.0),
            (6, "left lung", 33_700, -865.0),
            (7, "tissue", 154_589, 17.0),
        ],
    );
}

#[test]
fn totalsegmentator_extension_names_and_colours() {
    let ct = image(TS_CT);
    let map = labels_on(&data(TS_SEG), None, &ct);
    assert_eq!(map.segments.len(), 117, "117 names defined");
    assert_eq!(map.segments.iter().filter(|s| s.voxels > 0).count(), 61);
    let liver = &map.segments[map.index_of(key(0, 5)).expect("5")];
    assert_eq!(liver.name, "liver");
    assert_eq!(liver.color, [0, 255, 255]);
    let stomach = &map.segments[map.index_of(key(0, 6)).expect("6")];
    assert_eq!(stomach.color, [255, 128, 0]);
    assert_eq!(map.find("LIVER"), vec![key(0, 5)]);
    assert_eq!(map.find("vertebrae_L*").len(), 5);
}

#[test]
fn slicer_segment_fields() {
    let ct = image(SLICER_CT);
    let map = labels_on(&data(SLICER_SEG), None, &ct);
    let names: Vec<&str> = map.segments.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "ribs",
            "cervical vertebral column",
            "thoracic vertebral column",
            "lumbar vertebral column",
            "right lung",
            "left lung",
            "tissue"
        ]
    );
    let values: Vec<u16> = map.segments.iter().map(|s| s.key.value).collect();
    assert_eq!(values, [1, 2, 3, 4, 5, 6, 7]);
    // Segment4_Color:=0.0862745 0.772549 0.278431
    assert_eq!(map.segments[4].color, [22, 197, 71]);
}

#[test]
fn slicer_overlapping_layers_are_split() {
    let ct = image(SLICER_CT);
    let flat = labels_on(&data(SLICER_SEG), None, &ct);
    let map = labels_on(&data(SLICER_LAYERS), None, &ct);
    assert_eq!(map.layers.len(), 2);
    assert!(map.layers[0] == flat.layers[0], "layer 0 is the 7 segments");
    let sphere = &map.segments[map.index_of(key(1, 1)).expect("layer 1, label 1")];
    assert_eq!(sphere.name, "overlapping sphere");
    assert_eq!(sphere.voxels, 19_139);
    assert_eq!(map.segments.len(), 8);
    let stats = labels::statistics(&ct, &map);
    assert!(
        stats
            .iter()
            .any(|s| s.layer == 1 && s.id == 1 && s.voxels == 19_139)
    );
}

/// `values` (x fastest, `dims`) with x stored the other way round.
fn flip_x<T: Copy>(values: &[T], dims: [usize; 3]) -> Vec<T> {
    let nx = dims[0];
    (0..values.len())
        .map(|i| values[i - i % nx + nx - 1 - i % nx])
        .collect()
}

/// The same volume with x stored the other way round, and the affine saying so.
fn flipped_x(v: &Volume) -> Volume {
    let data = match &v.data {
        VoxelData::U8(d) => VoxelData::U8(flip_x(d, v.dims)),
        VoxelData::I32(d) => VoxelData::I32(flip_x(d, v.dims)),
        other => panic!("no test volume is {}", other.voxel_type()),
    };
    let o = v.orientation;
    let mut flipped = Volume::new(v.dims, v.spacing, data).expect("volume");
    flipped.scaling = v.scaling;
    flipped.orientation = Orientation {
        linear: glam::DMat3::from_cols(-o.linear.x_axis, o.linear.y_axis, o.linear.z_axis),
        offset: o.offset + o.linear.x_axis * (v.dims[0] as f64 - 1.0),
        source: o.source,
    };
    flipped
}

#[test]
fn a_flipped_label_map_lands_on_the_same_voxels() {
    let ct = image(TS_CT);
    let seg = image(TS_SEG);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("flipped.nii.gz");
    volume::save(&flipped_x(&seg), &path).expect("saves");
    assert_eq!(image_at(&path).orientation.axis_codes(), "LAS");
    let original = labels_on(&data(TS_SEG), None, &ct);
    let flipped = labels_on(&path, None, &ct);
    assert!(flipped.layers == original.layers, "same voxels");
    // The copy lost the names (no extension written); the counts are the same.
    let counts = |m: &LabelMap| {
        m.segments
            .iter()
            .filter(|s| s.voxels > 0)
            .map(|s| (s.key, s.voxels))
            .collect::<Vec<_>>()
    };
    assert_eq!(counts(&flipped), counts(&original));

    // An image stored LAS, and that image reoriented by Volume::to_ras: the labels
    // follow the voxels in both.
    let las = flipped_x(&ct);
    assert_eq!(las.orientation.axis_codes(), "LAS");
    let on_las = labels_on(&data(TS_SEG), None, &las);
    assert!(on_las.layers[0] == flip_x(&original.layers[0], ct.dims));
    let on_ras = labels_on(&data(TS_SEG), None, &las.to_ras());
    assert!(on_ras.layers == original.layers);
    assert_eq!(on_ras.segments, original.segments);
}

fn image_at(path: &Path) -> Volume {
    volume::load(path, &LoadOptions::default())
        .expect("loads")
        .volume
}

#[test]
fn freesurfer_lut_loads_every_entry() {
    let t = labels::read_table(&data("labels/tables/FreeSurferColorLUT.txt")).expect("reads");
    assert_eq!(t.entries.len(), 1_266);
    assert_eq!(t.entries.keys().max(), Some(&14_175));
    let e = &t.entries[&14_175];
    assert_eq!(e.name.as_deref(), Some("wm_rh_S_temporal_transverse"));
    assert_eq!(e.color, Some([221, 60, 60]));
    // As --label-table it wins over the file's own names.
    let ct = image(SLICER_CT);
    let map = labels_on(
        &data(SLICER_SEG),
        Some(&data("labels/tables/FreeSurferColorLUT.txt")),
        &ct,
    );
    let ribs = &map.segments[map.index_of(key(0, 1)).expect("1")];
    assert_eq!(ribs.name, "Left-Cerebral-Exterior");
    assert_eq!(ribs.color, [70, 130, 180]);
    assert_eq!(map.segments.len(), 1_265, "every named id but 0");
}

#[test]
fn niivue_json_tables_load() {
    let slicer = labels::read_table(&data("labels/tables/_slicer3d.json")).expect("reads");
    assert_eq!(slicer.entries.len(), 256);
    assert_eq!(slicer.entries[&1].name.as_deref(), Some("tissue"));
    let itk = labels::read_table(&data("labels/tables/_itksnap.json")).expect("reads");
    assert_eq!(itk.entries.len(), 131);
    assert!(
        itk.entries
            .values()
            .all(|e| e.name.is_none() && e.color.is_some())
    );
    // Colours without names: only present ids become segments, named "label N".
    let ct = image(SLICER_CT);
    let map = labels_on(
        &data(SLICER_SEG),
        Some(&data("labels/tables/_itksnap.json")),
        &ct,
    );
    assert_eq!(map.segments.len(), 7);
    assert_eq!(
        map.segments[0].name, "ribs",
        "a table without names keeps the file's"
    );
}

#[test]
fn brodmann_with_its_lut_on_ch2() {
    let lut_path = data("labels/mricron/brodmann.nii.lut");
    let lut = std::fs::read(&lut_path).expect("reads");
    let ch2 = image("nifti/ch2.nii.gz");
    let loaded = labels::load(
        &data("labels/mricron/brodmann.nii.gz"),
        Some(&lut_path),
        &ch2,
    )
    .expect("loads");
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let map = loaded.labels;
    assert_eq!(map.segments.len(), 41);
    assert_eq!(map.segments.last().map(|s| s.key.value), Some(48));
    for s in &map.segments {
        let i = s.key.value as usize;
        assert_eq!(s.color, [lut[i], lut[256 + i], lut[512 + i]], "id {i}");
        assert_eq!(s.name, format!("label {i}"));
    }
}

/// Runs `volao info` expecting one error line that holds every needle.
fn fails_with(args: &[&str], needles: &[&str]) {
    let out = volao(args);
    assert!(!out.status.success(), "{args:?} should fail");
    let err = text(&out.stderr);
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "one line expected:\n{err}"
    );
    assert!(err.starts_with("error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "missing {n:?} in {err}");
    }
}

#[test]
fn bad_inputs_give_one_clear_line() {
    let ct = data(TS_CT);
    let dir = tempfile::tempdir().expect("temp dir");

    // Another size, far away.
    let far = dir.path().join("far.nii.gz");
    let mut v = Volume::new([10, 12, 14], [1.0, 1.0, 1.0], vec![1u8; 1680].into()).expect("v");
    v.orientation.offset = glam::DVec3::new(10_000.0, 0.0, 0.0);
    volume::save(&v, &far).expect("saves");
    fails_with(
        &["info", arg(&ct), "--labels", arg(&far)],
        &[
            arg(&far),
            "does not overlap",
            arg(&ct),
            "label box [9999.5, 10009.5]",
        ],
    );

    // Float values.
    let float = dir.path().join("float.nii.gz");
    let v = Volume::new([2, 1, 1], [1.0, 1.0, 1.0], vec![0.0f32, 0.37].into()).expect("v");
    volume::save(&v, &float).expect("saves");
    fails_with(
        &["info", arg(&ct), "--labels", arg(&float)],
        &[&format!(
            "{}: a label map must hold integer labels; this one holds float values such as 0.37",
            arg(&float)
        )],
    );

    // A malformed table line.
    let table = dir.path().join("bad.txt");
    std::fs::write(
        &table,
        "# ok\r\n1 liver 255 0 0 0\r\n2 spleen red 0 0 0\r\n",
    )
    .expect("write");
    fails_with(
        &[
            "info",
            arg(&ct),
            "--labels",
            arg(&data(TS_SEG)),
            "--label-table",
            arg(&table),
        ],
        &[&format!(
            "{}:3: expected 'index name R G B A', found '2 spleen red 0 0 0'",
            arg(&table)
        )],
    );
}

#[test]
fn info_text_lists_segments() {
    let out = volao(&[
        "info",
        arg(&data(SLICER_CT)),
        "--labels",
        arg(&data(SLICER_LAYERS)),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = text(&out.stdout);
    assert!(s.contains("segments (8 present):"), "{s}");
    assert!(s.contains("overlapping sphere"), "{s}");
    assert!(s.contains("154589"), "{s}");
}
