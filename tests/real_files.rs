//! Every file in ../shared/data loads with exactly the dimensions, spacing and type its
//! README gives, and min/max/mean within 1e-4 of the README's figures.

mod common;

use common::{data, shared_files};
use volao::volume::{self, LoadOptions, VoxelType};

struct Expect {
    file: &'static str,
    dims: [usize; 3],
    spacing: [f32; 3],
    ty: VoxelType,
    min: f64,
    max: f64,
    /// `None` where the README gives no mean.
    mean: Option<f64>,
    orientation: &'static str,
}

const fn e(
    file: &'static str,
    dims: [usize; 3],
    spacing: [f32; 3],
    ty: VoxelType,
    (min, max): (f64, f64),
    mean: Option<f64>,
    orientation: &'static str,
) -> Expect {
    Expect {
        file,
        dims,
        spacing,
        ty,
        min,
        max,
        mean,
        orientation,
    }
}

/// Figures from ../shared/data/README.md. Files without an orientation are "RAS" by assumption.
const EXPECTED: &[Expect] = &[
    e(
        "pvm/Bucky.pvm",
        [32, 32, 32],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 255.0),
        Some(35.8498),
        "RAS",
    ),
    e(
        "pvm/Lobster.pvm",
        [301, 324, 56],
        [1.0, 1.0, 1.4],
        VoxelType::U8,
        (0.0, 255.0),
        Some(13.0526),
        "RAS",
    ),
    e(
        "pvm/Storm-t11.pvm",
        [28, 28, 23],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 226.0),
        Some(5.2463),
        "RAS",
    ),
    e(
        "pvm/Storm-t01.pvm",
        [28, 28, 23],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 0.0),
        Some(0.0),
        "RAS",
    ),
    e(
        "raw/engine.raw",
        [256, 256, 110],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 255.0),
        Some(26.0058),
        "RAS",
    ),
    e(
        "raw/hydrogenatom.raw",
        [128, 128, 128],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 250.0),
        Some(2.8567),
        "RAS",
    ),
    e(
        "raw/cranium-ct.raw",
        [256, 256, 108],
        [0.957031, 0.957031, 1.5],
        VoxelType::I16,
        (-1024.0, 2986.0),
        Some(-585.9553),
        "RAS",
    ),
    e(
        "nifti/ch2.nii.gz",
        [181, 217, 181],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 254.0),
        Some(44.6118),
        "RAS",
    ),
    e(
        "nifti/avg152T1_LR_nifti.nii",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        VoxelType::U8,
        (0.0, 255.0),
        Some(82.8972),
        "LAS",
    ),
    e(
        "nifti/avg152T1_LR_nifti.nii.gz",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        VoxelType::U8,
        (0.0, 255.0),
        Some(82.8972),
        "LAS",
    ),
    e(
        "nifti/avg152T1_LR_nifti2.nii.gz",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        VoxelType::F32,
        (0.0, 255.0),
        Some(82.8972),
        "LAS",
    ),
    e(
        "nifti/big.nii.gz",
        [64, 64, 21],
        [4.0, 4.0, 6.0],
        VoxelType::F32,
        (-8.71075, 18.5825),
        Some(0.1354),
        "LAS",
    ),
    e(
        "nifti/little.nii.gz",
        [64, 64, 21],
        [4.0, 4.0, 6.0],
        VoxelType::F32,
        (-8.71075, 18.5825),
        Some(0.1354),
        "LAS",
    ),
    e(
        "nifti/with_extension.nii.gz",
        [161, 191, 151],
        [1.0, 1.0, 1.0],
        VoxelType::U8,
        (0.0, 1.0),
        None,
        "LPI",
    ),
];

/// The README rounds to 4 decimals (6 significant digits for big/little), so "within
/// 1e-4" means within 1e-4 of the printed figure, plus half a unit in its last digit.
fn close(actual: f64, expected: f64) -> bool {
    (actual - expected).abs() <= 1e-4 + 5e-6 * expected.abs().max(1.0)
}

#[test]
fn every_shared_file_matches_the_readme() {
    let mut failures = Vec::new();
    for (file, raw) in shared_files() {
        let exp = EXPECTED
            .iter()
            .find(|x| x.file == file)
            .unwrap_or_else(|| panic!("no expectation for {file}"));
        let loaded = match volume::load(
            &data(file),
            &LoadOptions {
                raw,
                ..Default::default()
            },
        ) {
            Ok(l) => l,
            Err(e) => {
                failures.push(format!("{file}: {e}"));
                continue;
            }
        };
        let v = &loaded.volume;
        let s = v.stats();
        let mut check = |ok: bool, what: String| {
            if !ok {
                failures.push(format!("{file}: {what}"));
            }
        };
        check(
            v.dims == exp.dims,
            format!("dims {:?} != {:?}", v.dims, exp.dims),
        );
        check(
            v.spacing == exp.spacing,
            format!("spacing {:?} != {:?}", v.spacing, exp.spacing),
        );
        check(
            v.data.voxel_type() == exp.ty,
            format!("type {} != {}", v.data.voxel_type(), exp.ty),
        );
        check(
            close(s.min, exp.min),
            format!("min {} != {}", s.min, exp.min),
        );
        check(
            close(s.max, exp.max),
            format!("max {} != {}", s.max, exp.max),
        );
        if let Some(mean) = exp.mean {
            check(close(s.mean, mean), format!("mean {} != {mean}", s.mean));
        }
        check(
            s.non_finite == 0,
            format!("{} non-finite voxels", s.non_finite),
        );
        check(
            v.orientation.axis_codes() == exp.orientation,
            format!(
                "orientation {} != {}",
                v.orientation.axis_codes(),
                exp.orientation
            ),
        );
    }
    assert!(
        failures.is_empty(),
        "{} mismatches:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn every_expectation_names_a_tested_file() {
    let files: Vec<_> = shared_files().into_iter().map(|(f, _)| f).collect();
    for e in EXPECTED {
        assert!(
            files.contains(&e.file),
            "{} is expected but never loaded",
            e.file
        );
    }
}

#[test]
fn big_and_little_endian_files_hold_the_same_voxels() {
    let big =
        volume::load(&data("nifti/big.nii.gz"), &LoadOptions::default()).expect("big.nii.gz loads");
    let little = volume::load(&data("nifti/little.nii.gz"), &LoadOptions::default())
        .expect("little.nii.gz loads");
    assert!(big.volume.data.bits_eq(&little.volume.data));
    assert_eq!(
        big.volume.orientation.rows(),
        little.volume.orientation.rows()
    );
}

#[test]
fn nifti1_and_nifti2_avg152_agree_voxel_for_voxel() {
    let one = volume::load(
        &data("nifti/avg152T1_LR_nifti.nii"),
        &LoadOptions::default(),
    )
    .expect("loads")
    .volume;
    let two = volume::load(
        &data("nifti/avg152T1_LR_nifti2.nii.gz"),
        &LoadOptions::default(),
    )
    .expect("loads")
    .volume;
    assert_eq!(one.dims, two.dims);
    for i in 0..one.voxel_count() {
        assert_eq!(one.data.get_f64(i), two.data.get_f64(i), "voxel {i}");
    }
    assert_eq!(one.orientation.rows(), two.orientation.rows());
}

#[test]
fn four_d_file_with_one_frame_refuses_frame_1() {
    let err = volume::load(
        &data("nifti/little.nii.gz"),
        &LoadOptions {
            frame: 1,
            ..Default::default()
        },
    )
    .expect_err("frame 1 does not exist");
    let msg = err.to_string();
    assert!(
        msg.contains("little.nii.gz") && msg.contains("1 frame"),
        "{msg}"
    );
}

#[test]
fn not_nifti_is_rejected_with_a_clear_one_line_error() {
    let err =
        volume::load(&data("nifti/not-nifti.nii"), &LoadOptions::default()).expect_err("not NIfTI");
    let msg = err.to_string();
    assert!(
        msg.contains("not-nifti.nii") && msg.contains("not a NIfTI file"),
        "{msg}"
    );
    assert!(!msg.contains('\n'), "one line: {msg}");
}

#[test]
fn reorienting_las_to_ras_flips_x_and_keeps_values() {
    let v = volume::load(
        &data("nifti/avg152T1_LR_nifti.nii"),
        &LoadOptions::default(),
    )
    .expect("loads")
    .volume;
    let r = v.to_ras();
    assert_eq!(r.orientation.axis_codes(), "RAS");
    assert_eq!(r.dims, v.dims);
    let [nx, _, _] = v.dims;
    for (x, y, z) in [(0, 0, 0), (10, 50, 40), (90, 108, 90), (45, 60, 30)] {
        assert_eq!(v.value(x, y, z), r.value(nx - 1 - x, y, z));
    }
    // World position of voxel (0,0,0) in the RAS copy is the old voxel (nx-1, 0, 0).
    let rows = v.orientation.rows();
    let old_x = rows[0][0] * (nx as f64 - 1.0) + rows[0][3];
    assert_eq!(r.orientation.rows()[0][3], old_x);
}

#[test]
fn invesalius_plist_beside_the_raw_file_gives_its_layout() {
    let loaded = volume::load(&data("raw/cranium-ct.raw"), &LoadOptions::default())
        .expect("loads without flags");
    assert_eq!(loaded.format.to_string(), "raw with .plist sidecar");
    let v = &loaded.volume;
    assert_eq!(v.dims, [256, 256, 108]);
    assert_eq!(v.data.voxel_type(), VoxelType::I16);
    for (s, want) in v.spacing.iter().zip([0.957031, 0.957031, 1.5]) {
        assert!((s - want).abs() < 1e-6, "spacing {:?}", v.spacing);
    }
    let s = v.stats();
    assert!(
        close(s.min, -1024.0) && close(s.max, 2986.0) && close(s.mean, -585.9553),
        "{s:?}"
    );
}

/// README figures for the DICOM, NRRD and Analyze files (spacing within 1e-5 mm: DICOM
/// slice spacing is computed from positions, not copied).
struct Expect2 {
    path: &'static str,
    dims: [usize; 3],
    spacing: [f32; 3],
    min: f64,
    max: f64,
    mean: f64,
    orientation: &'static str,
    format: &'static str,
}

#[allow(clippy::too_many_arguments, reason = "one row of the README table")]
const fn x(
    path: &'static str,
    dims: [usize; 3],
    spacing: [f32; 3],
    (min, max): (f64, f64),
    mean: f64,
    orientation: &'static str,
    format: &'static str,
) -> Expect2 {
    Expect2 {
        path,
        dims,
        spacing,
        min,
        max,
        mean,
        orientation,
        format,
    }
}

/// `../shared/data/README.md`, sections DICOM, NRRD and Analyze 7.5. Orientation is what
/// the geometry fields say (DICOM LPS patient axes with rows running L→R: "LPS").
const NEW_FORMATS: &[Expect2] = &[
    x(
        "dicom/cranium-ct",
        [256, 256, 108],
        [0.957031, 0.957031, 1.5],
        (-1024.0, 2986.0),
        -585.9553,
        "LPS",
        "DICOM series of 108 files",
    ),
    x(
        "dicom/cranium-ct/IM0050.dcm",
        [256, 256, 108],
        [0.957031, 0.957031, 1.5],
        (-1024.0, 2986.0),
        -585.9553,
        "LPS",
        "DICOM series of 108 files",
    ),
    x(
        "dicom/brain-mr",
        [256, 256, 20],
        [0.859375, 0.859375, 7.071068],
        (0.0, 1059.0),
        167.5369,
        "LPS",
        "DICOM series of 20 files",
    ),
    x(
        "nrrd/cranium-ct.nrrd",
        [256, 256, 108],
        [0.957031, 0.957031, 1.5],
        (-1024.0, 2986.0),
        -585.9553,
        "LPS",
        "NRRD (attached, gzip)",
    ),
    // The header says LPS but carries the NIfTI's RAS affine unchanged: (−2,0,0) in LPS
    // is 2 mm towards the patient's right, so by the NRRD spec this is RPS.
    x(
        "nrrd/avg152.nhdr",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        (0.0, 255.0),
        82.8972,
        "RPS",
        "NRRD (detached header, raw)",
    ),
    x(
        "analyze/analyze75.hdr",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        (0.0, 255.0),
        82.8972,
        "LAS",
        "Analyze 7.5 (.hdr/.img pair)",
    ),
    x(
        "analyze/analyze75.img",
        [91, 109, 91],
        [2.0, 2.0, 2.0],
        (0.0, 255.0),
        82.8972,
        "LAS",
        "Analyze 7.5 (.hdr/.img pair)",
    ),
];

fn shared_path(rel: &str) -> std::path::PathBuf {
    let p = common::data_dir().join(rel);
    assert!(
        p.exists(),
        "{} is missing from the shared data folder",
        p.display()
    );
    p
}

#[test]
fn dicom_nrrd_and_analyze_files_match_the_readme() {
    let mut failures = Vec::new();
    for exp in NEW_FORMATS {
        let loaded = match volume::load(&shared_path(exp.path), &LoadOptions::default()) {
            Ok(l) => l,
            Err(e) => {
                failures.push(format!("{}: {e}", exp.path));
                continue;
            }
        };
        let v = &loaded.volume;
        let s = v.stats();
        let mut check = |ok: bool, what: String| {
            if !ok {
                failures.push(format!("{}: {what}", exp.path));
            }
        };
        check(
            v.dims == exp.dims,
            format!("dims {:?} != {:?}", v.dims, exp.dims),
        );
        check(
            v.spacing
                .iter()
                .zip(exp.spacing)
                .all(|(a, b)| (a - b).abs() < 1e-5),
            format!("spacing {:?} != {:?}", v.spacing, exp.spacing),
        );
        check(
            close(s.min, exp.min),
            format!("min {} != {}", s.min, exp.min),
        );
        check(
            close(s.max, exp.max),
            format!("max {} != {}", s.max, exp.max),
        );
        check(
            close(s.mean, exp.mean),
            format!("mean {} != {}", s.mean, exp.mean),
        );
        check(
            v.orientation.axis_codes() == exp.orientation,
            format!(
                "orientation {} != {}",
                v.orientation.axis_codes(),
                exp.orientation
            ),
        );
        check(
            loaded.format.to_string() == exp.format,
            format!("format {:?} != {:?}", loaded.format.to_string(), exp.format),
        );
    }
    assert!(
        failures.is_empty(),
        "{} mismatches:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn nrrd_and_analyze_hold_the_nifti_voxels() {
    let nii = volume::load(
        &data("nifti/avg152T1_LR_nifti.nii"),
        &LoadOptions::default(),
    )
    .expect("loads")
    .volume;
    for other in ["nrrd/avg152.nhdr", "analyze/analyze75.hdr"] {
        let v = volume::load(&shared_path(other), &LoadOptions::default())
            .expect("loads")
            .volume;
        assert!(v.data.bits_eq(&nii.data), "{other}: voxels differ");
    }
    let analyze = volume::load(
        &shared_path("analyze/analyze75.hdr"),
        &LoadOptions::default(),
    )
    .expect("loads");
    // nibabel's affine for this file: LAS with the centre at the origin.
    assert_eq!(
        analyze.volume.orientation.rows(),
        [
            [-2.0, 0.0, 0.0, 90.0],
            [0.0, 2.0, 0.0, -108.0],
            [0.0, 0.0, 2.0, -90.0]
        ]
    );
    assert!(
        analyze
            .warnings
            .iter()
            .any(|w| w.contains("assuming LAS") && w.contains("nibabel")),
        "{:?}",
        analyze.warnings
    );
    let raw = volume::load(&data("raw/cranium-ct.raw"), &LoadOptions::default())
        .expect("loads")
        .volume;
    for other in ["nrrd/cranium-ct.nrrd", "dicom/cranium-ct"] {
        let v = volume::load(&shared_path(other), &LoadOptions::default())
            .expect("loads")
            .volume;
        for i in (0..raw.voxel_count()).step_by(97) {
            assert_eq!(
                v.scaling.apply(v.data.get_f64(i)),
                raw.data.get_f64(i),
                "{other}: voxel {i}"
            );
        }
    }
}

#[test]
fn nrrd_rgb_is_refused_and_4d_reads_frames_counting_from_0() {
    let err = volume::load(
        &shared_path("nrrd/rgb-2d-example1.nrrd"),
        &LoadOptions::default(),
    )
    .expect_err("RGB is not a scalar volume");
    let msg = err.to_string();
    assert!(
        msg.contains("rgb-2d-example1.nrrd") && msg.contains("3 components per voxel"),
        "{msg}"
    );
    let four = shared_path("nrrd/4d-example4.nrrd");
    for frame in 0..2 {
        let v = volume::load(
            &four,
            &LoadOptions {
                frame,
                ..Default::default()
            },
        )
        .expect("frame loads")
        .volume;
        assert_eq!(v.dims, [4, 3, 2]);
        assert_eq!(v.spacing, [1.0, 0.5, 0.3]);
    }
    let msg = volume::load(
        &four,
        &LoadOptions {
            frame: 2,
            ..Default::default()
        },
    )
    .expect_err("2 frames")
    .to_string();
    assert!(
        msg.contains("2 frames") && msg.contains("count from 0"),
        "{msg}"
    );
}

/// `dicom/files/`: (file, frames×rows×cols as x×y×z, min, max, mean) from the README,
/// or the transfer syntax named in the refusal.
const DICOM_FILES: &[(&str, [usize; 3], f64, f64, f64)] = &[
    ("CT_small.dcm", [128, 128, 1], -896.0, 1167.0, -119.0739),
    ("deflated.dcm", [512, 512, 1], 0.0, 255.0, 127.1160),
    // The README's figures are pydicom's, which ignores the Pixel Value Transformation
    // in the shared functional groups (intercept −1024); volao and dcm2niix apply it.
    (
        "eCT_Supplemental.dcm",
        [512, 512, 2],
        -1024.0,
        172.0,
        380.0381 - 1024.0,
    ),
    ("emri_small.dcm", [64, 64, 10], 0.0, 467.0, 109.6991),
    ("emri_small_RLE.dcm", [64, 64, 10], 0.0, 467.0, 109.6991),
    (
        "emri_small_big_endian.dcm",
        [64, 64, 10],
        0.0,
        467.0,
        109.6991,
    ),
    (
        "emri_small_jpeg_2k_lossless.dcm",
        [64, 64, 10],
        0.0,
        467.0,
        109.6991,
    ),
    ("explicit_big.dcm", [256, 256, 1], 0.0, 891.0, 195.2477),
    ("explicit_little.dcm", [256, 256, 16], 0.0, 252.0, 32.2647),
    ("implicit_little.dcm", [256, 256, 1], 0.0, 575.0, 65.5278),
    ("jpeg_2000.dcm", [512, 512, 1], -3339.0, 1385.0, -871.1976),
    (
        "jpeg_lossless_sel1.dcm",
        [512, 400, 1],
        -196.0,
        406.0,
        70.9624,
    ),
    ("rle.dcm", [512, 512, 1], -3024.0, 1254.0, -871.3037),
];

#[test]
fn dicom_single_files_in_every_transfer_syntax_match_the_readme() {
    let mut failures = Vec::new();
    for &(file, dims, min, max, mean) in DICOM_FILES {
        let path = shared_path(&format!("dicom/files/{file}"));
        match volume::load(&path, &LoadOptions::default()) {
            Ok(l) => {
                let v = &l.volume;
                let s = v.stats();
                if v.dims != dims
                    || !close(s.min, min)
                    || !close(s.max, max)
                    || !close(s.mean, mean)
                {
                    failures.push(format!(
                        "{file}: dims {:?} min {} max {} mean {} (want {dims:?} {min} {max} {mean})",
                        v.dims, s.min, s.max, s.mean
                    ));
                }
            }
            Err(e) => failures.push(format!("{file}: {e}")),
        }
    }
    // Lossy JPEG: another IDCT may differ by ±1 per pixel (README), so the mean by < 1.
    let l = volume::load(
        &shared_path("dicom/files/jpeg_baseline_8bit.dcm"),
        &LoadOptions::default(),
    )
    .expect("JPEG baseline loads");
    let s = l.volume.stats();
    assert_eq!(l.volume.dims, [512, 512, 96]);
    assert!((s.mean - 67.6597).abs() < 1.0 && s.max <= 255.0, "{s:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn jpeg_ls_is_refused_naming_the_transfer_syntax() {
    for file in ["jpeg_ls.dcm", "emri_small_jpeg_ls_lossless.dcm"] {
        let msg = volume::load(
            &shared_path(&format!("dicom/files/{file}")),
            &LoadOptions::default(),
        )
        .expect_err("JPEG-LS needs CharLS")
        .to_string();
        assert!(
            msg.contains(file) && msg.contains("JPEG-LS") && msg.contains("1.2.840.10008.1.2.4.8"),
            "{msg}"
        );
        assert!(!msg.contains('\n'), "{msg}");
    }
}

#[test]
fn mr_series_spacing_comes_from_positions_not_the_header() {
    let l = volume::load(&shared_path("dicom/brain-mr"), &LoadOptions::default()).expect("loads");
    let v = &l.volume;
    // SliceThickness 5 and SpacingBetweenSlices 2 in the header; positions 7.071068 apart.
    assert!((v.spacing[2] - 7.071068).abs() < 1e-5, "{:?}", v.spacing);
    // The affine keeps the obliquity: the slice axis tilts out of the axial plane.
    let z = v.orientation.linear.z_axis;
    assert!(z.y.abs() > 0.5, "slice axis {z:?}");
    // brain_001.dcm carries 2.4 MB of zeros after its pixel data: said, nothing else
    // (the 0.1 mm rounding jitter of the positions is not reported as irregular).
    assert_eq!(l.warnings.len(), 1, "{:?}", l.warnings);
    assert!(
        l.warnings[0].contains("1 file carries bytes after the pixel data"),
        "{:?}",
        l.warnings
    );
}

/// Runs dcm2niix on `dir` (must be installed: `.ci/run` installs it) and loads its NIfTI.
fn dcm2niix(dir: &std::path::Path) -> volume::Volume {
    let out = tempfile::tempdir().expect("temp dir");
    let status = std::process::Command::new("dcm2niix")
        .args(["-z", "n", "-b", "n", "-f", "converted", "-o"])
        .arg(out.path())
        .arg(dir)
        .output()
        .unwrap_or_else(|e| {
            panic!("dcm2niix is needed for this test (apt-get install dcm2niix): {e}")
        });
    assert!(
        status.status.success(),
        "dcm2niix failed: {}",
        String::from_utf8_lossy(&status.stderr)
    );
    volume::load(&out.path().join("converted.nii"), &LoadOptions::default())
        .expect("dcm2niix output loads")
        .volume
}

#[test]
fn dicom_series_match_dcm2niix_voxel_for_voxel() {
    for series in ["dicom/cranium-ct", "dicom/brain-mr"] {
        let dir = shared_path(series);
        let ours = volume::load(&dir, &LoadOptions::default())
            .expect("loads")
            .volume
            .to_ras();
        let theirs = dcm2niix(&dir).to_ras();
        assert_eq!(ours.dims, theirs.dims, "{series}");
        for (a, b) in ours.spacing.iter().zip(theirs.spacing) {
            assert!(
                (a - b).abs() < 1e-4,
                "{series}: spacing {:?} vs {:?}",
                ours.spacing,
                theirs.spacing
            );
        }
        let mut wrong = 0;
        for i in 0..ours.voxel_count() {
            let a = ours.scaling.apply(ours.data.get_f64(i));
            let b = theirs.scaling.apply(theirs.data.get_f64(i));
            if a != b {
                wrong += 1;
            }
        }
        assert_eq!(wrong, 0, "{series}: {wrong} voxels differ from dcm2niix");
        // Same affine (dcm2niix writes f32 srows: compare to 1e-3 mm).
        let (ra, rb) = (ours.orientation.rows(), theirs.orientation.rows());
        for r in 0..3 {
            for c in 0..4 {
                assert!(
                    (ra[r][c] - rb[r][c]).abs() < 1e-3,
                    "{series}: affine\n{ra:?}\nvs dcm2niix\n{rb:?}"
                );
            }
        }
    }
}

#[test]
fn dicom_folder_with_two_series_picks_the_larger_and_lists_both() {
    let dir = tempfile::tempdir().expect("temp dir");
    for f in ["brain_001.dcm", "brain_002.dcm", "brain_003.dcm"] {
        std::fs::copy(
            shared_path(&format!("dicom/brain-mr/{f}")),
            dir.path().join(f),
        )
        .expect("copy");
    }
    std::fs::copy(
        shared_path("dicom/files/CT_small.dcm"),
        dir.path().join("ct.dcm"),
    )
    .expect("copy");
    let l = volume::load(dir.path(), &LoadOptions::default()).expect("loads");
    assert_eq!(l.volume.dims, [256, 256, 3]);
    let list = l
        .volume
        .descriptions
        .iter()
        .find(|(k, _)| k == "all series")
        .map(|(_, t)| t.clone())
        .expect("series listed");
    assert_eq!(list.lines().count(), 2, "{list}");
    assert!(
        l.warnings.iter().any(|w| w.contains("--series")),
        "{:?}",
        l.warnings
    );
    let ct = volume::load(
        dir.path(),
        &LoadOptions {
            series: Some("1".into()),
            ..Default::default()
        },
    )
    .expect("series 1 loads");
    assert_eq!(ct.volume.dims, [128, 128, 1]);
    let msg = volume::load(
        dir.path(),
        &LoadOptions {
            series: Some("2".into()),
            ..Default::default()
        },
    )
    .expect_err("only 2 series")
    .to_string();
    assert!(msg.contains("numbered from 0"), "{msg}");
}

#[test]
fn dicom_series_with_a_missing_slice_warns() {
    let dir = tempfile::tempdir().expect("temp dir");
    for k in [1, 2, 3, 5, 6] {
        let f = format!("brain_{k:03}.dcm");
        std::fs::copy(
            shared_path(&format!("dicom/brain-mr/{f}")),
            dir.path().join(&f),
        )
        .expect("copy");
    }
    // The same image twice (a copy under another name): one is dropped, with a warning.
    std::fs::copy(
        shared_path("dicom/brain-mr/brain_006.dcm"),
        dir.path().join("copy.dcm"),
    )
    .expect("copy");
    let l = volume::load(dir.path(), &LoadOptions::default()).expect("loads");
    assert_eq!(l.volume.dims[2], 5);
    let all = l.warnings.join("\n");
    assert!(
        all.contains("irregular") && all.contains("missing"),
        "{all}"
    );
    assert!(all.contains("SOPInstanceUID"), "{all}");
}
