//! `volao slice`: slices in patient orientation, checked against readers independent of
//! volao (nibabel, pynrrd, dcm2niix through `tests/slice_reference.py`), and its flags.

mod common;

use common::{data, data_dir, text, volao_cli as volao};
use std::process::Command;

fn path(p: &std::path::Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Axial, coronal and sagittal slices of NIfTI (RAS, LAS, anisotropic), Analyze, NRRD
/// (LPS) and DICOM (CT, and the oblique MR both resampled and in its own planes) equal
/// the same slices cut with numpy from nibabel's `as_closest_canonical`, pynrrd and
/// dcm2niix, pixel for pixel. Needs python3 with numpy, nibabel, pynrrd and pillow, and
/// dcm2niix (`.ci/run` installs them); missing, the test fails saying so.
#[test]
fn slices_equal_independent_readers() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/slice_reference.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_volao"))
        .arg(data_dir())
        .output()
        .expect("python3 runs (install python3 with numpy, nibabel, pynrrd, pillow)");
    let stdout = text(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        text(&out.stderr)
            .lines()
            .filter(|l| !l.starts_with("warning:"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert!(stdout.contains("78 of 78 slices equal"), "{stdout}");
}

fn grey_png(p: &std::path::Path) -> image::DynamicImage {
    image::open(p).expect("PNG written")
}

#[test]
fn index_at_and_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("s.png");
    let file = data("nifti/avg152T1_LR_nifti.nii");
    // avg152 (LAS, 2 mm): the axial slice through z = 0 mm is index 36 (origin −72 mm).
    let o = volao(&["slice", path(&file), "--at", "0,0,0", "-o", path(&out)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("axial slice 36 of 91"),
        "{}",
        text(&o.stdout)
    );
    let img = grey_png(&out);
    assert_eq!((img.width(), img.height()), (91, 109));

    let o = volao(&["slice", path(&file), "--index", "91", "-o", path(&out)]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("numbered 0 to 90"), "{err}");

    let o = volao(&["slice", path(&file), "--axis", "oblique", "-o", path(&out)]);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("expected axial, coronal or sagittal"));
}

#[test]
fn labels_overlay_and_annotations() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ct = data("labels/totalsegmentator/example_ct.nii.gz");
    let seg = data("labels/totalsegmentator/example_seg_fast_force_split.nii.gz");
    let plain = dir.path().join("plain.png");
    let labelled = dir.path().join("labelled.png");
    let outlined = dir.path().join("outlined.png");
    let annotated = dir.path().join("annotated.png");
    let wl = ["--window-level", "400,40", "--axis", "coronal"];
    for (out, extra) in [
        (&plain, vec![]),
        // Every segment red, so any pixel the overlay touches shows it.
        (
            &labelled,
            vec!["--labels", path(&seg), "--segment", "*:color=#ff0000"],
        ),
        (&outlined, vec!["--labels", path(&seg), "--outline"]),
        (&annotated, vec!["--annotate"]),
    ] {
        let mut args = vec!["slice", path(&ct), "-o", path(out)];
        args.extend(wl);
        args.extend(extra);
        let o = volao(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let plain = grey_png(&plain).to_rgb8();
    let labelled = grey_png(&labelled).to_rgb8();
    let outlined = grey_png(&outlined).to_rgb8();
    let coloured = |img: &image::RgbImage| {
        img.pixels()
            .filter(|p| p[0] != p[1] || p[1] != p[2])
            .count()
    };
    assert_eq!(coloured(&plain), 0);
    let (filled, edges) = (coloured(&labelled), coloured(&outlined));
    assert!(filled > 1000, "segments coloured: {filled}");
    assert!(
        edges > 100 && edges < filled,
        "outlines {edges} of {filled}"
    );
    // The overlay changes exactly the pixels it colours; the others keep their grey.
    let changed = plain
        .pixels()
        .zip(labelled.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(changed, filled);
    assert!(labelled.pixels().all(|p| p[0] >= p[1] && p[1] == p[2]));
    let annotated = grey_png(&annotated).to_luma8();
    let changed = plain
        .pixels()
        .zip(annotated.pixels())
        .filter(|(a, b)| a[0] != b[0])
        .count();
    assert!(
        changed > 50,
        "letters and scale bar drawn: {changed} pixels"
    );
}

/// `volao render --layout 2x2`: the 3-D pane is `volao render` at that pane's size, pixel
/// for pixel, and the axial pane is `volao slice`'s image scaled to fit.
#[test]
fn render_layout_holds_the_3d_view_and_the_slices() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = data("pvm/Bucky.pvm");
    let quad = dir.path().join("quad.png");
    let o = volao(&[
        "render",
        path(&file),
        "--layout",
        "2x2",
        "--width",
        "200",
        "--height",
        "160",
        "-o",
        path(&quad),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    // The top-right pane: x from 101 to 200, y from 0 to 79 (a 2-pixel gap in the middle).
    let (x0, w, h) = (101u32, 99u32, 79u32);
    let alone = dir.path().join("alone.png");
    let o = volao(&[
        "render",
        path(&file),
        "--width",
        &w.to_string(),
        "--height",
        &h.to_string(),
        "-o",
        path(&alone),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let quad = grey_png(&quad).to_rgba8();
    let alone = grey_png(&alone).to_rgba8();
    for y in 0..h {
        for x in 0..w {
            assert_eq!(
                quad.get_pixel(x0 + x, y),
                alone.get_pixel(x, y),
                "3-D pane at {x},{y}"
            );
        }
    }
    // The axial pane (0..99 × 0..79) shows the axial slice, 32×32 scaled ×2.47, centred.
    let slice = dir.path().join("axial.png");
    let o = volao(&["slice", path(&file), "-o", path(&slice)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let slice = grey_png(&slice).to_luma8();
    let scale = (99.0f32 / 32.0).min(79.0 / 32.0);
    let left = (99.0 - 32.0 * scale) / 2.0;
    for (u, v) in [(5u32, 5u32), (16, 16), (20, 9), (31, 31)] {
        let (x, y) = (left + (u as f32 + 0.5) * scale, (v as f32 + 0.5) * scale);
        let p = quad.get_pixel(x as u32, y as u32);
        let g = slice.get_pixel(u, v)[0];
        assert_eq!([p[0], p[1], p[2]], [g, g, g], "axial pixel {u},{v}");
    }
}

/// `volao render --annotate` draws the orientation marker in the bottom-left corner and
/// leaves the rest of the image as without it.
#[test]
fn render_annotate_draws_only_the_orientation_marker() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = data("pvm/Bucky.pvm");
    let (plain, marked) = (dir.path().join("plain.png"), dir.path().join("marked.png"));
    for (out, extra) in [(&plain, None), (&marked, Some("--annotate"))] {
        let mut args = vec![
            "render",
            path(&file),
            "--width",
            "160",
            "--height",
            "120",
            "-o",
            path(out),
        ];
        args.extend(extra);
        let o = volao(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let (plain, marked) = (grey_png(&plain).to_rgba8(), grey_png(&marked).to_rgba8());
    let mut changed = 0;
    for (x, y, p) in marked.enumerate_pixels() {
        if p != plain.get_pixel(x, y) {
            changed += 1;
            assert!(
                x < 60 && y > 60,
                "changed pixel at {x},{y} outside the corner"
            );
        }
    }
    assert!(changed > 30, "marker drawn: {changed} pixels");
}

/// `volao render --layout 2x2 --labels SEG`: the slice panes carry the segments'
/// colours, the axial pane pixel for pixel `volao slice --labels`'s image scaled to fit;
/// without `--labels` they are grey.
#[test]
fn render_layout_slices_show_the_segmentation() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ct = data("labels/totalsegmentator/example_ct.nii.gz");
    let seg = data("labels/totalsegmentator/example_seg_fast_force_split.nii.gz");
    // Every segment red, so any pixel the overlay touches shows it.
    let red = ["--labels", path(&seg), "--segment", "*:color=#ff0000"];
    let (plain, labelled) = (
        dir.path().join("plain.png"),
        dir.path().join("labelled.png"),
    );
    for (out, extra) in [(&plain, &[][..]), (&labelled, &red[..])] {
        let mut args = vec![
            "render",
            path(&ct),
            "--layout",
            "2x2",
            "--width",
            "200",
            "--height",
            "160",
            "--ao",
            "none",
            "-o",
            path(out),
        ];
        args.extend(extra);
        let o = volao(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let slice = dir.path().join("axial.png");
    let mut args = vec!["slice", path(&ct), "-o", path(&slice)];
    args.extend(red);
    let o = volao(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (plain, labelled) = (grey_png(&plain).to_rgb8(), grey_png(&labelled).to_rgb8());
    let slice = grey_png(&slice).to_rgb8();
    // The slice panes: the axial pane (top left, 0..99 × 0..79) and the bottom row.
    let in_slices = |x: u32, y: u32| (x < 99 && y < 79) || y >= 81;
    let coloured = |img: &image::RgbImage| {
        img.enumerate_pixels()
            .filter(|(x, y, p)| in_slices(*x, *y) && (p[0] != p[1] || p[1] != p[2]))
            .count()
    };
    assert_eq!(coloured(&plain), 0);
    let red_pixels = coloured(&labelled);
    assert!(
        red_pixels > 200,
        "segments coloured in the slice panes: {red_pixels}"
    );
    let (w, h) = slice.dimensions();
    let ([l, t, _, _], s) = volao::slice::fit([w as usize, h as usize], [0.0, 0.0, 99.0, 79.0]);
    let mut compared = 0;
    for y in 0..79u32 {
        for x in 0..99u32 {
            let u = ((x as f32 + 0.5 - l) / s).floor();
            let v = ((y as f32 + 0.5 - t) / s).floor();
            if u < 0.0 || v < 0.0 || u >= w as f32 || v >= h as f32 {
                continue;
            }
            assert_eq!(
                labelled.get_pixel(x, y),
                slice.get_pixel(u as u32, v as u32),
                "axial pane at {x},{y}"
            );
            compared += 1;
        }
    }
    assert!(
        compared > 3000,
        "{compared} pixels of the axial pane compared"
    );
}
