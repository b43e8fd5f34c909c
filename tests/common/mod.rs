//! Shared helpers for integration tests.
#![allow(
    dead_code,
    reason = "each test binary uses a different subset of these helpers"
)]

use std::path::PathBuf;

/// How many elements differ between two slices of the same length (pixels, voxels).
pub fn differing<T: PartialEq>(a: &[T], b: &[T]) -> usize {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).filter(|(x, y)| x != y).count()
}

/// The shared real volumes (`../shared/data` beside the checkout, or `$VOLAO_DATA`).
/// Missing data is a failure with instructions, never a silent skip.
pub fn data_dir() -> PathBuf {
    let dir = std::env::var_os("VOLAO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    assert!(
        dir.join("README.md").is_file(),
        "test data not found at {}: the tests read the real volumes from ../shared/data \
         (or set VOLAO_DATA to that folder); see README.md, 'Test data'",
        dir.display()
    );
    dir
}

pub fn data(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.is_file(),
        "{} is missing from the shared data folder",
        p.display()
    );
    p
}

/// Every loadable file in the shared data folder with the raw flags it needs.
pub fn shared_files() -> Vec<(&'static str, volao::volume::RawOverrides)> {
    use volao::volume::{Endian, RawOverrides, VoxelType};
    let none = RawOverrides::default;
    vec![
        ("nifti/ch2.nii.gz", none()),
        ("nifti/avg152T1_LR_nifti.nii", none()),
        ("nifti/avg152T1_LR_nifti.nii.gz", none()),
        ("nifti/avg152T1_LR_nifti2.nii.gz", none()),
        ("nifti/big.nii.gz", none()),
        ("nifti/little.nii.gz", none()),
        ("nifti/with_extension.nii.gz", none()),
        ("pvm/Bucky.pvm", none()),
        ("pvm/Lobster.pvm", none()),
        ("pvm/Storm-t01.pvm", none()),
        ("pvm/Storm-t11.pvm", none()),
        ("raw/engine.raw", none()),
        ("raw/hydrogenatom.raw", none()),
        (
            "raw/cranium-ct.raw",
            RawOverrides {
                dims: Some([256, 256, 108]),
                ty: Some(VoxelType::I16),
                endian: Some(Endian::Little),
                spacing: Some([0.957031, 0.957031, 1.5]),
                offset: None,
            },
        ),
    ]
}

/// Tiny deterministic PRNG (xorshift64*), so mutation tests are reproducible.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// The GPU device for a test. No adapter is a failure that says how to get one, never a
/// skip: GPU tests run on Mesa's lavapipe in CI.
pub fn device() -> volao::gpu::Gpu {
    volao::gpu::request_device().unwrap_or_else(|e| {
        panic!("{e}\n(GPU tests run on Mesa's lavapipe in CI; they are not skipped.)")
    })
}

/// A volume's texels at full resolution (no halving).
pub fn texels(v: &volao::volume::Volume) -> volao::texels::VolumeTexels {
    volao::texels::VolumeTexels::new(
        v,
        volao::texels::UploadLimits {
            max_dim: 4096,
            max_bytes: 1 << 30,
        },
    )
}

/// The `size` voxels of `v` starting at `origin` (u8, i16 and i32 volumes), scaling kept.
pub fn crop(
    v: &volao::volume::Volume,
    origin: [usize; 3],
    size: [usize; 3],
) -> volao::volume::Volume {
    use volao::volume::VoxelData;
    let [nx, ny, _] = v.dims;
    let idx = |i: usize| {
        let (x, y, z) = (
            i % size[0],
            (i / size[0]) % size[1],
            i / (size[0] * size[1]),
        );
        origin[0] + x + nx * (origin[1] + y + ny * (origin[2] + z))
    };
    let n = size.iter().product::<usize>();
    let data = match &v.data {
        VoxelData::U8(d) => VoxelData::U8((0..n).map(|i| d[idx(i)]).collect()),
        VoxelData::I16(d) => VoxelData::I16((0..n).map(|i| d[idx(i)]).collect()),
        VoxelData::I32(d) => VoxelData::I32((0..n).map(|i| d[idx(i)]).collect()),
        other => panic!("crop: {:?} not needed here", other.voxel_type()),
    };
    let mut out = volao::volume::Volume::new(size, v.spacing, data).expect("valid crop");
    out.scaling = v.scaling;
    out
}

/// Cropped real volumes (engine, cranium CT) with the CT-bone preset, small enough for
/// CPU twins.
pub fn real_crops() -> Vec<(
    &'static str,
    volao::volume::Volume,
    volao::tf::TransferFunction,
)> {
    [
        ("engine", "raw/engine.raw", [96, 96, 40], [40, 40, 24]),
        ("cranium", "raw/cranium-ct.raw", [30, 108, 40], [40, 32, 24]),
    ]
    .into_iter()
    .map(|(name, file, origin, size)| {
        let full = volao::volume::load(&data(file), &Default::default())
            .unwrap_or_else(|e| panic!("{e}"))
            .volume;
        let v = crop(&full, origin, size);
        let tf = volao::tf::TransferFunction::preset(volao::tf::Preset::CtBone, &v.stats());
        (name, v, tf)
    })
    .collect()
}

/// An 8-bit volume of unit spacing with `f(x, y, z)` at each voxel.
pub fn u8_volume(
    n: [usize; 3],
    mut f: impl FnMut(usize, usize, usize) -> u8,
) -> volao::volume::Volume {
    let data = (0..n[0] * n[1] * n[2])
        .map(|i| f(i % n[0], (i / n[0]) % n[1], i / (n[0] * n[1])))
        .collect();
    volao::volume::Volume::new(n, [1.0; 3], volao::volume::VoxelData::U8(data))
        .expect("valid volume")
}

/// The same opacity `alpha` for every value of 8-bit data, in white.
pub fn flat_tf(alpha: f32) -> volao::tf::TransferFunction {
    use volao::tf::{ColorStop, OpacityPoint};
    volao::tf::TransferFunction {
        name: "flat".into(),
        opacity: vec![
            OpacityPoint { value: 0.0, alpha },
            OpacityPoint {
                value: 255.0,
                alpha,
            },
        ],
        color: vec![ColorStop {
            value: 0.0,
            rgb: [1.0; 3],
        }],
    }
}

/// White, transparent up to `from` and rising linearly to opacity `alpha` at `to` (data
/// units), that opacity beyond.
pub fn ramp_tf(from: f64, to: f64, alpha: f32) -> volao::tf::TransferFunction {
    use volao::tf::{ColorStop, OpacityPoint};
    volao::tf::TransferFunction {
        name: "ramp".into(),
        opacity: vec![
            OpacityPoint {
                value: from,
                alpha: 0.0,
            },
            OpacityPoint { value: to, alpha },
        ],
        color: vec![ColorStop {
            value: 0.0,
            rgb: [1.0; 3],
        }],
    }
}

/// A real volume's texels shrunk (by the renderer's own downsampling) to ≤ 64 voxels per
/// axis, so CPU twins stay fast in CI.
pub fn small_texels(volume: &volao::volume::Volume) -> volao::texels::VolumeTexels {
    volao::texels::VolumeTexels::new(
        volume,
        volao::texels::UploadLimits {
            max_dim: 64,
            max_bytes: 1 << 30,
        },
    )
}

/// Golden images are lavapipe renders committed to the repository. A different LLVM or
/// Mesa version may round texture filtering differently, shifting surface edges by a
/// fraction of a step: allow small differences and a few edge pixels.
pub const GOLDEN: volao::render::image::Tolerance = volao::render::image::Tolerance {
    max_channel_diff: 3,
    max_outlier_fraction: 0.01,
    max_outlier_diff: 80,
};

/// Checks `image` against `tests/golden/{stem}.png` within [`GOLDEN`] (differences
/// written to `out_dir`), or writes it there when `VOLAO_BLESS` is set.
pub fn golden(
    stem: &str,
    image: &volao::render::Image,
    out_dir: &std::path::Path,
) -> Result<(), String> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{stem}.png"));
    if std::env::var_os("VOLAO_BLESS").is_some() {
        image.save_png(&path).unwrap_or_else(|e| panic!("{e}"));
        return Ok(());
    }
    let expected = volao::render::Image::load_png(&path)
        .unwrap_or_else(|e| panic!("{e} (run with VOLAO_BLESS=1 to create it)"));
    volao::render::image::check(&format!("golden_{stem}"), image, &expected, GOLDEN, out_dir)
        .map(|_| ())
}

/// GPU against CPU twin. GPU texture filtering is not the CPU's f32 trilinear: lavapipe
/// (like real GPUs) uses reduced-precision interpolation weights, so a sample can differ
/// by ~1/256 of the step between neighbouring texels. Along a ray these differences shift
/// where a surface starts by a fraction of a step, which moves a few pixels by more than
/// a few levels.
pub const TWIN: volao::render::image::Tolerance = volao::render::image::Tolerance {
    max_channel_diff: 3,
    max_outlier_fraction: 0.01,
    max_outlier_diff: 64,
};

/// Compares a GPU image with its CPU twin's within `tol` (differences written to
/// `out_dir`) and prints how close they were.
pub fn twin(
    label: &str,
    gpu: &volao::render::Image,
    cpu: &volao::render::Image,
    tol: volao::render::image::Tolerance,
    out_dir: &std::path::Path,
) -> Result<(), String> {
    let cmp = volao::render::image::check(label, gpu, cpu, tol, out_dir)?;
    eprintln!(
        "{label}: max diff {}, mean {:.3}, outliers {}",
        cmp.max_diff, cmp.mean_diff, cmp.outliers
    );
    Ok(())
}

/// The tests' oblique view (azimuth 30°, elevation 20°) at `size`² with `settings`.
pub fn oblique_frame(settings: volao::render::RenderSettings, size: u32) -> volao::render::Frame {
    volao::render::Frame {
        camera: volao::render::Camera {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            ..Default::default()
        },
        settings,
        width: size,
        height: size,
    }
}

/// Runs the `volao` binary with `args` and waits for it.
pub fn volao_cli<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_volao"))
        .args(args)
        .output()
        .expect("volao runs")
}

/// A child's output as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}
