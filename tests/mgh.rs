//! FreeSurfer MGH/MGZ: files built here byte by byte (the shared data has none), read
//! back through the public loader and the `volao` binary.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use volao::volume::{self, LoadOptions, VolumeError, mgh};

/// One test file: dims (with frames), type code, geometry, and its voxel values.
struct Mgh {
    dims: [i32; 4],
    ty: i32,
    good_ras: i16,
    delta: [f32; 3],
    mdc: [[f32; 3]; 3],
    c: [f32; 3],
}

/// An oblique orthonormal frame: the x and y axes turned 30° about S, z along S.
fn oblique() -> [[f32; 3]; 3] {
    let (s, c) = 30f32.to_radians().sin_cos();
    [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
}

const SAMPLE: Mgh = Mgh {
    dims: [5, 4, 3, 2],
    ty: 4,
    good_ras: 1,
    delta: [0.5, 1.5, 2.0],
    mdc: [[0.0; 3]; 3], // set per test
    c: [10.0, -20.0, 30.0],
};

/// The value stored at voxel (x, y, z) of frame f: distinct everywhere, signed, and
/// exact in every type tested (|v| < 128 fits u8 after the offset below).
fn value(x: usize, y: usize, z: usize, f: usize) -> f64 {
    (x + 5 * y + 20 * z + 60 * f) as f64 - 60.0
}

impl Mgh {
    fn voxels(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// The file's bytes: header, padding, big-endian voxels, a footer (TR …).
    fn bytes(&self) -> Vec<u8> {
        let h = mgh::Header {
            version: 1,
            dims: self.dims,
            ty: self.ty,
            dof: 0,
            good_ras: self.good_ras,
            delta: self.delta,
            mdc: self.mdc,
            pxyz_c: self.c,
        };
        let mut b = h.to_bytes();
        assert_eq!(b.len(), 284);
        let [nx, ny, nz, nf] = self.dims.map(|d| d as usize);
        for f in 0..nf {
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let v = value(x, y, z, f);
                        match self.ty {
                            0 => b.push((v + 60.0) as u8),
                            1 => b.extend((v as i32 * 100_000).to_be_bytes()),
                            3 => b.extend((v as f32 * 0.25).to_be_bytes()),
                            4 => b.extend((v as i16).to_be_bytes()),
                            10 => b.extend(((v + 60.0) as u16 * 300).to_be_bytes()),
                            _ => b.extend([0u8; 4]),
                        }
                    }
                }
            }
        }
        b.extend(2000f32.to_be_bytes()); // TR: footer, not voxels
        b
    }

    /// What voxel i of frame f reads back as.
    fn expected(&self, x: usize, y: usize, z: usize, f: usize) -> f64 {
        let v = value(x, y, z, f);
        match self.ty {
            0 => v + 60.0,
            1 => v * 100_000.0,
            3 => v * 0.25,
            10 => (v + 60.0) * 300.0,
            _ => v,
        }
    }
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).expect("gzip");
    e.finish().expect("gzip")
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn load(p: &Path, frame: usize) -> Result<volume::Loaded, VolumeError> {
    volume::load(
        p,
        &LoadOptions {
            frame,
            ..Default::default()
        },
    )
}

/// Checks dims, spacing, every voxel and the affine of `frame` against the formula.
fn check(m: &Mgh, l: &volume::Loaded, frame: usize) {
    let v = &l.volume;
    let [nx, ny, nz, _] = m.dims.map(|d| d as usize);
    assert_eq!(v.dims, [nx, ny, nz]);
    assert_eq!(v.spacing, m.delta);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                assert_eq!(
                    v.value(x, y, z),
                    Some(m.expected(x, y, z, frame)),
                    "voxel {x},{y},{z} of frame {frame}"
                );
            }
        }
    }
    // vox2ras = [Mdc·delta | c − Mdc·delta·dims/2] (nibabel MGHHeader.get_affine).
    let rows = v.orientation.rows();
    for r in 0..3 {
        let mut centre = f64::from(m.c[r]);
        for k in 0..3 {
            let col = f64::from(m.mdc[k][r]) * f64::from(m.delta[k]);
            assert!((rows[r][k] - col).abs() < 1e-6, "affine {rows:?}");
            centre -= col * m.dims[k] as f64 / 2.0;
        }
        assert!((rows[r][3] - centre).abs() < 1e-5, "affine {rows:?}");
    }
    // The centre voxel dims/2 lies at Pxyz_c, FreeSurfer's definition of c_ras.
    let half = glam::DVec3::from_array([nx, ny, nz].map(|d| d as f64 / 2.0));
    let c = v.orientation.linear * half + v.orientation.offset;
    assert!(
        (c - glam::DVec3::from_array(m.c.map(f64::from))).length() < 1e-5,
        "{c}"
    );
}

#[test]
fn mgh_and_mgz_read_every_type_frame_and_the_affine() {
    let dir = tempfile::tempdir().expect("temp dir");
    for ty in [0, 1, 3, 4, 10] {
        let m = Mgh {
            ty,
            mdc: oblique(),
            ..SAMPLE
        };
        let bytes = m.bytes();
        let plain = write(dir.path(), &format!("t{ty}.mgh"), &bytes);
        let packed = write(dir.path(), &format!("t{ty}.mgz"), &gzip(&bytes));
        for (p, gz) in [(&plain, false), (&packed, true)] {
            for frame in 0..2 {
                let l = load(p, frame).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                assert_eq!(l.format, volume::Format::Mgh { gzip: gz });
                assert_eq!(l.volume.voxel_count(), m.voxels() / 2);
                check(&m, &l, frame);
            }
            let e = load(p, 2).expect_err("two frames").to_string();
            let name = p.file_name().and_then(|n| n.to_str()).expect("name");
            assert!(e.contains("frames count from 0") && e.contains(name), "{e}");
        }
    }
}

#[test]
fn mgh_orientation_codes_follow_mdc() {
    let dir = tempfile::tempdir().expect("temp dir");
    // FreeSurfer's conformed space: x → left, y → inferior, z → anterior.
    let lia = Mgh {
        dims: [4, 3, 2, 1],
        mdc: [[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
        ..SAMPLE
    };
    let p = write(dir.path(), "lia.mgz", &gzip(&lia.bytes()));
    let l = load(&p, 0).expect("loads");
    assert_eq!(l.volume.orientation.axis_codes(), "LIA");
    check(&lia, &l, 0);
    // goodRASflag = 0: nibabel's default (delta 1, its coronal Mdc, centre 0).
    let unset = Mgh { good_ras: 0, ..lia };
    let p = write(dir.path(), "unset.mgh", &unset.bytes());
    let l = load(&p, 0).expect("loads");
    let default = Mgh {
        delta: [1.0; 3],
        mdc: mgh::DEFAULT_MDC,
        c: [0.0; 3],
        ..unset
    };
    check(&default, &l, 0);
    assert_eq!(l.volume.orientation.axis_codes(), "LSP");
    assert!(
        l.warnings.iter().any(|w| w.contains("goodRASflag")),
        "{:?}",
        l.warnings
    );
}

#[test]
fn bad_mgh_files_are_refused_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let m = Mgh {
        mdc: oblique(),
        ..SAMPLE
    };
    let good = m.bytes();
    let mut cases: Vec<(&str, Vec<u8>, &str)> = Vec::new();
    // Frame 0 (i16, half the voxels) ends here; a cut before it leaves it incomplete.
    let frame0_end = 284 + m.voxels();
    cases.push(("cut.mgh", good[..frame0_end - 1].to_vec(), "truncated"));
    cases.push(("header.mgh", good[..50].to_vec(), "truncated"));
    let cut = gzip(&good[..frame0_end - 61]);
    cases.push(("cut.mgz", cut, "truncated"));
    let mut crc = gzip(&good);
    let n = crc.len();
    crc[n - 8] ^= 1;
    cases.push(("crc.mgz", crc, "CRC32"));
    let mut ty = good.clone();
    ty[23] = 2;
    cases.push(("long.mgh", ty, "MRI_LONG"));
    let mut version = good.clone();
    version[3] = 2;
    cases.push(("v2.mgh", version, "version 2"));
    let mut zero = good.clone();
    zero[8..12].copy_from_slice(&0i32.to_be_bytes());
    cases.push(("zero.mgh", zero, "must be ≥ 1"));
    let mut huge = good.clone();
    for k in 0..3 {
        huge[4 + 4 * k..8 + 4 * k].copy_from_slice(&i32::MAX.to_be_bytes());
    }
    cases.push(("huge.mgh", huge, "more than this machine can hold"));
    for (name, bytes, want) in cases {
        let p = write(dir.path(), name, &bytes);
        let e = load(&p, 0).expect_err(name).to_string();
        assert!(!e.contains('\n'), "{name}: {e}");
        assert!(e.contains(name), "{name}: does not name the file: {e}");
        assert!(e.contains(want), "{name}: {e}");
    }
    // The memory cap is honoured before anything is allocated.
    let p = write(dir.path(), "ok.mgh", &good);
    let e = volume::load(
        &p,
        &LoadOptions {
            max_bytes: Some(100),
            ..Default::default()
        },
    )
    .expect_err("over the cap")
    .to_string();
    assert!(e.contains("more than this machine can hold"), "{e}");
}

#[test]
fn volao_info_and_convert_read_mgz() {
    let dir = tempfile::tempdir().expect("temp dir");
    let m = Mgh {
        ty: 3,
        mdc: oblique(),
        ..SAMPLE
    };
    let p = write(dir.path(), "brain.mgz", &gzip(&m.bytes()));
    let volao = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_volao"))
            .args(args)
            .output()
            .expect("volao runs");
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).expect("utf-8")
    };
    let info = volao(&["info", p.to_str().expect("utf-8"), "--json"]);
    let j: serde_json::Value = serde_json::from_str(&info).expect("JSON");
    assert_eq!(j["dims"], serde_json::json!([5, 4, 3]));
    assert_eq!(j["format"], "MGZ (FreeSurfer MGH, gzip)");
    assert_eq!(j["voxel_type"], "f32");
    let out = dir.path().join("brain.nii.gz");
    volao(&[
        "convert",
        p.to_str().expect("utf-8"),
        out.to_str().expect("utf-8"),
        "--frame",
        "1",
    ]);
    let back = volume::load(&out, &LoadOptions::default()).expect("NIfTI written");
    let mgz = load(&p, 1).expect("loads");
    assert!(back.volume.data.bits_eq(&mgz.volume.data));
    let (a, b) = (
        back.volume.orientation.rows(),
        mgz.volume.orientation.rows(),
    );
    for r in 0..3 {
        for c in 0..4 {
            assert!((a[r][c] - b[r][c]).abs() < 1e-4, "{a:?} vs {b:?}");
        }
    }
}
