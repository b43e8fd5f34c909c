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
