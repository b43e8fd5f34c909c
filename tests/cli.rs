//! The `volao` binary as a user runs it: output, exit codes, one-line errors.

mod common;

use common::data;
use std::process::{Command, Output};

fn volao(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volao"))
        .args(args)
        .output()
        .expect("volao runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn info_json_reports_the_file() {
    let file = data("nifti/avg152T1_LR_nifti.nii.gz");
    let out = volao(&[
        "info",
        file.to_str().expect("utf-8 path"),
        "--json",
        "--bins",
        "16",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    assert_eq!(j["dims"], serde_json::json!([91, 109, 91]));
    assert_eq!(j["voxel_type"], "u8");
    assert_eq!(j["orientation"], "LAS");
    assert_eq!(j["format"], "NIfTI-1, gzip");
    assert_eq!(j["histogram"]["counts"].as_array().map(Vec::len), Some(16));
    assert_eq!(j["stats"]["max"], 255.0);
}

#[test]
fn info_text_shows_histogram_and_descriptions() {
    let file = data("pvm/Bucky.pvm");
    let out = volao(&["info", file.to_str().expect("utf-8 path")]);
    assert!(out.status.success());
    let s = text(&out.stdout);
    for needle in [
        "32×32×32",
        "PVM3, DDS v3d compressed",
        "Bucky Ball",
        "histogram (32 bins",
        "mean:         35.8498",
    ] {
        assert!(s.contains(needle), "missing {needle:?} in:\n{s}");
    }
}

#[test]
fn bad_files_give_one_error_line_and_a_nonzero_exit() {
    let not_nifti = data("nifti/not-nifti.nii");
    let dir = tempfile::tempdir().expect("temp dir");
    let bare_raw = dir.path().join("bare.raw");
    std::fs::write(&bare_raw, [0u8; 64]).expect("write");
    let cases = [
        vec!["info".to_owned(), not_nifti.display().to_string()],
        vec!["info".to_owned(), "/nonexistent/scan.nii.gz".to_owned()],
        vec!["info".to_owned(), bare_raw.display().to_string()],
    ];
    for args in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = volao(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = text(&out.stderr);
        assert_eq!(
            err.trim_end().lines().count(),
            1,
            "{args:?}: one line expected, got:\n{err}"
        );
        assert!(
            err.starts_with("error: ") && err.contains(args[1]),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn convert_writes_a_file_that_info_reads_back() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out_path = dir.path().join("cranium.nii.gz");
    let raw = data("raw/cranium-ct.raw");
    let out = volao(&[
        "convert",
        raw.to_str().expect("utf-8 path"),
        out_path.to_str().expect("utf-8 path"),
        "--dims",
        "256",
        "256",
        "108",
        "--type",
        "i16",
        "--spacing",
        "0.957031",
        "0.957031",
        "1.5",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = volao(&["info", out_path.to_str().expect("utf-8 path"), "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    assert_eq!(j["voxel_type"], "i16");
    assert_eq!(j["stats"]["min"], -1024.0);
    assert_eq!(j["stats"]["max"], 2986.0);
}

#[test]
fn info_without_a_file_describes_the_demo_volume() {
    let out = volao(&["info", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("valid JSON");
    assert_eq!(j["dims"], serde_json::json!([128, 128, 128]));
    assert_eq!(j["voxel_type"], "i16");
}

#[test]
fn render_writes_a_png_and_a_scene_that_reproduces_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let png = dir.path().join("bucky.png");
    let scene = dir.path().join("bucky.json");
    let again = dir.path().join("again.png");
    let bucky = data("pvm/Bucky.pvm");
    let p = |p: &std::path::Path| p.to_str().expect("utf-8 path").to_owned();
    let out = volao(&[
        "render",
        &p(&bucky),
        "-o",
        &p(&png),
        "--width",
        "72",
        "--height",
        "48",
        "--tf",
        "mr-t1-brain",
        "--camera",
        "-30,15,3",
        "--background",
        "transparent",
        "--window-level",
        "200,120",
        "--save-scene",
        &p(&scene),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("72×48"), "{}", text(&out.stdout));
    let out = volao(&["render", &p(&scene), "-o", &p(&again)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (a, b) = (
        std::fs::read(&png).expect("png"),
        std::fs::read(&again).expect("png"),
    );
    assert_eq!(a, b, "the saved scene reproduces the image byte for byte");
    let img = volao::render::Image::load_png(&png).expect("decodes");
    assert_eq!((img.width, img.height), (72, 48));
    assert!(
        img.pixels.iter().any(|p| p[3] == 0),
        "transparent background"
    );
    assert!(img.pixels.iter().any(|p| p[3] > 0), "something rendered");
}

#[test]
fn render_rejects_bad_options_in_one_line() {
    for args in [
        vec!["render", "-o", "/tmp/x.png", "--camera", "1,2"],
        vec!["render", "-o", "/tmp/x.png", "--tf", "nope"],
        vec!["render", "-o", "/tmp/x.png", "--background", "#12"],
        vec!["render", "/nonexistent/scene.json", "-o", "/tmp/x.png"],
    ] {
        let out = volao(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = text(&out.stderr);
        assert!(err.contains("error"), "{args:?}: {err}");
    }
}

#[test]
fn ao_writes_a_volume_in_the_input_geometry() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out_path = dir.path().join("ao.nii.gz");
    let input = data("nifti/avg152T1_LR_nifti.nii.gz");
    let out = volao(&[
        "ao",
        input.to_str().expect("utf-8 path"),
        "-o",
        out_path.to_str().expect("utf-8 path"),
        "--method",
        "lao",
        "--rays",
        "6",
        "--samples",
        "6",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let src = volao::volume::load(&input, &Default::default())
        .expect("input loads")
        .volume;
    let ao = volao::volume::load(&out_path, &Default::default())
        .expect("AO loads")
        .volume;
    assert_eq!(ao.dims, src.dims);
    assert_eq!(ao.spacing, src.spacing);
    assert_eq!(ao.orientation.axis_codes(), "LAS", "orientation kept");
    assert_eq!(ao.orientation.rows(), src.orientation.rows());
    let s = ao.stats();
    assert!(s.min >= 0.0 && s.max <= 1.0 && s.min < s.max, "{s:?}");
    assert_eq!(s.non_finite, 0);
}

#[test]
fn cao_renders_with_clip_flags_prints_its_figures_and_its_scene_reproduces_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = |p: &std::path::Path| p.to_str().expect("utf-8 path").to_owned();
    let (png, scene, again) = (
        dir.path().join("cao.png"),
        dir.path().join("cao.json"),
        dir.path().join("again.png"),
    );
    let bucky = data("pvm/Bucky.pvm");
    let out = volao(&[
        "render",
        &p(&bucky),
        "-o",
        &p(&png),
        "--width",
        "64",
        "--height",
        "64",
        "--ao",
        "cao",
        "--rays",
        "6",
        "--samples",
        "6",
        "--clip",
        "sphere:4,0,0,9",
        "--clip",
        "torus:-6,2,0,8,2,0,45,0",
        "--clip-resolution",
        "128",
        "--save-scene",
        &p(&scene),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = text(&out.stdout);
    assert!(
        s.contains("% of voxels ray cast") && s.contains("clip + mask"),
        "{s}"
    );
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene).expect("scene")).expect("json");
    assert_eq!(saved["clip_shapes"].as_array().map(Vec::len), Some(2));
    assert_eq!(saved["ambient_occlusion"]["method"], "cao");
    let out = volao(&["render", &p(&scene), "-o", &p(&again)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read(&png).expect("png"),
        std::fs::read(&again).expect("png"),
        "the saved scene reproduces the carved image byte for byte"
    );
    // A bad shape is refused before any work, in one line.
    for bad in ["sphere:0,0,0", "blob:1,2,3", "torus:0,0,0,5,9"] {
        let out = volao(&["render", &p(&bucky), "-o", &p(&png), "--clip", bad]);
        assert!(!out.status.success(), "{bad} should fail");
        assert!(
            text(&out.stderr).contains("clip shape"),
            "{}",
            text(&out.stderr)
        );
    }
    // A broken mesh is reported and the other shape still clips.
    let open = dir.path().join("open.obj");
    std::fs::write(
        &open,
        "v 0 0 0\nv 9 0 0\nv 0 9 0\nv 0 0 9\nf 1 2 3\nf 1 2 4\n",
    )
    .expect("write");
    let out = volao(&[
        "render",
        &p(&bucky),
        "-o",
        &p(&png),
        "--width",
        "32",
        "--height",
        "32",
        "--clip",
        &format!("mesh:{}", p(&open)),
        "--clip",
        "sphere:0,0,0,8",
        "--clip-resolution",
        "64",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains("open.obj") && err.contains("not closed"),
        "{err}"
    );
}

#[test]
fn ao_with_clip_shapes_writes_the_cao_volume() {
    let dir = tempfile::tempdir().expect("temp dir");
    let bucky = data("pvm/Bucky.pvm");
    let p = |p: &std::path::Path| p.to_str().expect("utf-8 path").to_owned();
    let run = |method: &str, name: &str| {
        let out_path = dir.path().join(name);
        let out = volao(&[
            "ao",
            &p(&bucky),
            "-o",
            &p(&out_path),
            "--method",
            method,
            "--rays",
            "6",
            "--samples",
            "6",
            "--clip",
            "sphere:5,5,0,8",
            "--clip-resolution",
            "64",
        ]);
        (out, out_path)
    };
    let (out, cao_path) = run("cao", "cao.nii.gz");
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("% of voxels ray cast"),
        "{}",
        text(&out.stdout)
    );
    let (out, full_path) = run("lao-full", "full.nii.gz");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let load = |path: &std::path::Path| match volao::volume::load(path, &Default::default())
        .expect("AO loads")
        .volume
        .data
    {
        volao::volume::VoxelData::F32(v) => v,
        other => panic!("{:?}", other.voxel_type()),
    };
    let (cao, full) = (load(&cao_path), load(&full_path));
    assert_eq!(cao.len(), 32 * 32 * 32);
    assert!(cao.iter().all(|a| (0.0..=1.0).contains(a)));
    assert_eq!(cao, full, "CAO equals LAO every frame");
    let out = volao(&[
        "ao",
        &p(&bucky),
        "-o",
        &p(&dir.path().join("x.nii.gz")),
        "--clip",
        "sphere:0,0,0,5",
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("--method cao"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn clip_shapes_and_meshes_drawn_as_surfaces_are_saved_in_the_scene() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = |p: &std::path::Path| p.to_str().expect("utf-8 path").to_owned();
    let bucky = data("pvm/Bucky.pvm");
    // A small cube (mm from the volume's centre), drawn green and opaque.
    let cube = dir.path().join("cube.obj");
    let mut obj = String::new();
    for i in 0..8 {
        let c = |b: i32| if i & b == 0 { -3 } else { 3 };
        obj += &format!("v {} {} {}\n", c(1) + 8, c(2), c(4));
    }
    for f in [
        [1, 3, 4, 2],
        [5, 6, 8, 7],
        [1, 2, 6, 5],
        [3, 7, 8, 4],
        [1, 5, 7, 3],
        [2, 4, 8, 6],
    ] {
        obj += &format!(
            "f {} {} {}\nf {} {} {}\n",
            f[0], f[1], f[2], f[0], f[2], f[3]
        );
    }
    std::fs::write(&cube, obj).expect("write");
    let (png, scene, again, plain) = (
        dir.path().join("shown.png"),
        dir.path().join("shown.json"),
        dir.path().join("again.png"),
        dir.path().join("plain.png"),
    );
    let common = |out: &std::path::Path| {
        vec![
            "render".to_owned(),
            p(&bucky),
            "-o".into(),
            p(out),
            "--width".into(),
            "48".into(),
            "--height".into(),
            "48".into(),
            "--clip".into(),
            "sphere:-6,0,0,7".into(),
            "--clip-resolution".into(),
            "64".into(),
        ]
    };
    let mut shown = common(&png);
    shown.extend(
        [
            "--show-clip",
            "1,0,0,0.6",
            "--mesh",
            &p(&cube),
            "--mesh-rgba",
            "0,1,0,1",
            "--save-scene",
        ]
        .map(str::to_owned),
    );
    shown.push(p(&scene));
    let args: Vec<&str> = shown.iter().map(String::as_str).collect();
    let out = volao(&args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = volao(
        &common(&plain)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene).expect("scene")).expect("json");
    assert_eq!(
        saved["meshes"][0]["path"], "cube.obj",
        "relative to the scene"
    );
    assert_eq!(
        saved["render"]["clip_surface"],
        serde_json::json!([1.0, 0.0, 0.0, 0.6])
    );
    let out = volao(&["render", &p(&scene), "-o", &p(&again)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        std::fs::read(&png).expect("png"),
        std::fs::read(&again).expect("png"),
        "the scene reproduces the surfaces"
    );
    let (a, b) = (
        volao::render::Image::load_png(&png).expect("png"),
        volao::render::Image::load_png(&plain).expect("png"),
    );
    let more = |c: usize| {
        a.pixels
            .iter()
            .zip(&b.pixels)
            .filter(|(x, y)| x[c] as i32 > y[c] as i32 + 40)
            .count()
    };
    let (redder, greener) = (more(0), more(1));
    assert!(redder > 20 && greener > 5, "red {redder}, green {greener}");
}

#[test]
fn info_into_a_closed_pipe_exits_quietly() {
    use std::process::Stdio;
    let file = data("nifti/avg152T1_LR_nifti.nii.gz");
    for _ in 0..3 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_volao"))
            .args(["info", file.to_str().expect("utf-8 path"), "--bins", "4096"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("volao runs");
        // Close the reading end before volao writes (as `| head -0` or `| true` does).
        drop(child.stdout.take());
        let out = child.wait_with_output().expect("volao ends");
        let err = text(&out.stderr);
        assert!(
            !err.contains("panicked") && !err.contains("Broken pipe"),
            "{err}"
        );
        assert_eq!(out.status.code(), Some(0), "{err}");
    }
}

#[test]
fn info_on_a_dicom_folder_lists_the_series_and_series_flag_chooses() {
    let dir = tempfile::tempdir().expect("temp dir");
    let shared = common::data_dir();
    for f in ["brain_001.dcm", "brain_002.dcm"] {
        std::fs::copy(shared.join("dicom/brain-mr").join(f), dir.path().join(f)).expect("copy");
    }
    std::fs::copy(
        shared.join("dicom/files/CT_small.dcm"),
        dir.path().join("ct.dcm"),
    )
    .expect("copy");
    let d = dir.path().to_str().expect("utf-8 path");
    let out = volao(&["info", d]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = text(&out.stdout);
    assert!(
        s.contains("DICOM series of 2 files") && s.contains("[1]"),
        "{s}"
    );
    let out = volao(&["info", d, "--series", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("128×128×1"),
        "{}",
        text(&out.stdout)
    );
    let out = volao(&["info", d, "--series", "7"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("numbered from 0"), "{err}");
}

#[test]
fn convert_writes_nrrd_that_reads_back() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("nifti/avg152T1_LR_nifti.nii");
    let out_path = dir.path().join("avg.nrrd");
    let out = volao(&[
        "convert",
        input.to_str().expect("utf-8 path"),
        out_path.to_str().expect("utf-8 path"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let a = volao::volume::load(&input, &Default::default())
        .expect("loads")
        .volume;
    let b = volao::volume::load(&out_path, &Default::default())
        .expect("nrrd loads")
        .volume;
    assert!(a.data.bits_eq(&b.data));
    assert_eq!(a.orientation.rows(), b.orientation.rows());
}

#[test]
fn bench_render_times_the_configurations_asked_for_as_json_lines() {
    let file = data("nifti/avg152T1_LR_nifti.nii.gz");
    let out = volao(&[
        "bench",
        "render",
        file.to_str().expect("utf-8 path"),
        "--width",
        "48",
        "--height",
        "32",
        "--runs",
        "1",
        "--mode",
        "composite,mip",
        "--shading",
        "none,phong",
        "--gradient",
        "volume,samples",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<serde_json::Value> = text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert_eq!(lines.len(), 8, "one object per mode × shading × gradient");
    let expected = ["composite", "mip"].into_iter().flat_map(|m| {
        ["none", "phong"]
            .into_iter()
            .flat_map(move |s| ["volume", "samples"].map(|g| (m, s, g)))
    });
    for (j, (mode, shading, gradient)) in lines.iter().zip(expected) {
        assert_eq!(j["mode"], mode);
        assert_eq!(j["shading"], shading);
        assert_eq!(j["gradient"], gradient);
        assert_eq!(j["size"], serde_json::json!([48, 32]));
        assert!(
            j["median_frame_ms"].as_f64().is_some_and(|t| t > 0.0),
            "{j}"
        );
        assert!(j["adapter"].as_str().is_some_and(|a| !a.is_empty()), "{j}");
    }
    let out = volao(&[
        "bench",
        "render",
        file.to_str().expect("utf-8 path"),
        "--ao",
        "cao",
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("unclipped"),
        "{}",
        text(&out.stderr)
    );
    // Clipped frames: the shapes are counted in the JSON.
    let out = volao(&[
        "bench",
        "render",
        file.to_str().expect("utf-8 path"),
        "--width",
        "32",
        "--height",
        "32",
        "--runs",
        "1",
        "--clip",
        "sphere:0,0,0,20",
        "--clip",
        "box:0,0,30,20,20,20",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value =
        serde_json::from_str(text(&out.stdout).lines().next().expect("a line")).expect("JSON");
    assert_eq!(j["clip_shapes"], 2, "{j}");
}

/// The voxels of an f32 volume file, x fastest.
fn voxels_f32(path: &std::path::Path) -> Vec<f32> {
    let v = volao::volume::load(path, &Default::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume;
    (0..v.voxel_count())
        .map(|i| v.data.get_f64(i) as f32)
        .collect()
}

#[test]
fn ao_visible_only_computes_the_readable_voxels_bit_for_bit_and_writes_one_elsewhere() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("nifti/avg152T1_LR_nifti.nii.gz");
    let run = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        let mut args = vec![
            "ao",
            input.to_str().expect("utf-8 path"),
            "-o",
            path.to_str().expect("utf-8 path"),
            "--method",
            "lao",
            "--rays",
            "6",
            "--samples",
            "8",
        ];
        args.extend(extra);
        let out = volao(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        voxels_f32(&path)
    };
    let every = run("every.nii", &[]);
    let visible = run("visible.nii", &["--visible-only"]);
    let (mut kept, mut dropped) = (0, 0);
    for (a, b) in every.iter().zip(&visible) {
        if *b == 1.0 && *a != 1.0 {
            dropped += 1;
        } else {
            assert_eq!(a.to_bits(), b.to_bits(), "a computed voxel differs");
            kept += usize::from(*a < 1.0);
        }
    }
    assert!(
        kept > 1000 && dropped > 1000,
        "kept {kept}, dropped {dropped}"
    );
}

#[test]
fn no_skipping_renders_the_same_image_and_is_saved_in_the_scene() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = data("nifti/avg152T1_LR_nifti.nii.gz");
    let run = |name: &str, extra: &[&str]| {
        let png = dir.path().join(format!("{name}.png"));
        let scene = dir.path().join(format!("{name}.json"));
        let mut args = vec![
            "render",
            input.to_str().expect("utf-8 path"),
            "-o",
            png.to_str().expect("utf-8 path"),
            "--width",
            "64",
            "--height",
            "64",
            "--ao",
            "cao",
            "--rays",
            "6",
            "--samples",
            "8",
            "--clip",
            "sphere:10,0,20,30",
            "--save-scene",
            scene.to_str().expect("utf-8 path"),
        ];
        args.extend(extra);
        let out = volao(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let img = image::open(&png).expect("png").to_rgba8().into_raw();
        let saved: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&scene).expect("scene")).expect("json");
        (img, saved["render"]["empty_space_skipping"].clone())
    };
    let (skipped, on) = run("skipped", &[]);
    let (naive, off) = run("naive", &["--no-skipping"]);
    assert!(skipped == naive, "--no-skipping changed the image");
    assert_eq!(on, serde_json::json!(true));
    assert_eq!(off, serde_json::json!(false));
}

#[test]
fn bench_cao_prints_one_json_object_per_method_with_no_differing_pixels() {
    let dir = data("README.md");
    let dir = dir.parent().expect("data folder");
    let out = volao(&[
        "bench",
        "cao",
        "--data",
        dir.to_str().expect("utf-8 path"),
        "--max-dim",
        "32",
        "--table2-max-dim",
        "32",
        "--frames",
        "1",
        "--rays",
        "6",
        "--scenes",
        "engine",
        "--tables",
        "2,3",
        "--size",
        "32",
        "--clip-resolution",
        "64",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<serde_json::Value> = text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    let methods = [
        "lao-every-frame",
        "cao-paper",
        "cao",
        "lao-sparse",
        "lao-view",
        "cao-view",
    ];
    assert_eq!(lines.len(), 7, "Table 2, then Table 3's six methods");
    assert_eq!(lines[0]["table"], 2);
    for (j, method) in lines[1..].iter().zip(methods) {
        // The view-culled methods say how much of the readable volume the view needed.
        let view = j["view_fraction"].as_f64();
        assert_eq!(view.is_some(), method.ends_with("-view"), "{j}");
        assert!(view.is_none_or(|f| f > 0.0 && f <= 1.0), "{j}");
        assert_eq!(j["table"], 3);
        assert_eq!(j["scene"], "engine");
        assert_eq!(j["method"], method);
        assert_eq!(j["rays"], 6);
        assert_eq!(j["differing_pixels"], 0, "{j}");
        for stage in ["visibility", "clip_mask", "ray_cast", "render"] {
            assert!(j["stages_ms"][stage].as_f64().is_some(), "{j}");
        }
        assert!(j["mean_frame_ms"].as_f64().is_some_and(|t| t > 0.0), "{j}");
    }
}

/// The average projection of the cranium CT with its bone window was black (every ray
/// is mostly air, its mean far below the window): it now gets a window that shows the
/// data, and says so; MinIP says why it is dark.
#[test]
fn projections_choose_a_window_that_shows_the_data() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ct = data("nrrd/cranium-ct.nrrd");
    let out = dir.path().join("average.png");
    let o = volao(&[
        "render",
        ct.to_str().expect("utf-8 path"),
        "--mode",
        "average",
        "--width",
        "96",
        "--height",
        "96",
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("note: average: the transfer function's window"),
        "{}",
        text(&o.stderr)
    );
    let img = image::open(&out).expect("png").to_luma8();
    let bright = img.pixels().filter(|p| p[0] > 64).count();
    assert!(
        bright > 96 * 96 / 10,
        "the average shows the head: {bright} bright pixels"
    );
    let o = volao(&[
        "render",
        ct.to_str().expect("utf-8 path"),
        "--mode",
        "minip",
        "--width",
        "64",
        "--height",
        "64",
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("note: MinIP: rays through the surroundings"),
        "{}",
        text(&o.stderr)
    );
}
