//! Render modes (`--mode`): MIP, MinIP, average and isosurface on the GPU against their
//! CPU twins, golden images, known values, and clipping in every mode.
//! Runs on lavapipe in CI; never skipped.

mod common;

use common::{data, device, flat_tf, u8_volume};
use glam::Vec3;
use std::path::PathBuf;
use std::sync::Arc;
use volao::ao::AoSettings;
use volao::clip::{ClipMode, ClipShape, Shape};
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::image::Tolerance;
use volao::render::offscreen::{self, RenderJob};
use volao::render::{Camera, Frame, Image, RenderMode, RenderSettings, cpu};
use volao::tf::{ColorStop, OpacityPoint, Preset, TransferFunction};
use volao::volume::{self, LoadOptions, Volume};

const MODES: [RenderMode; 4] = [
    RenderMode::Mip,
    RenderMode::Minip,
    RenderMode::Average,
    RenderMode::Iso(None),
];

fn out_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("modes")
}

fn load(rel: &str) -> Volume {
    volume::load(&data(rel), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .volume
        .to_ras()
}

fn frame(size: u32, mode: RenderMode, azimuth_deg: f32, elevation_deg: f32) -> Frame {
    Frame {
        camera: Camera {
            azimuth_deg,
            elevation_deg,
            ..Default::default()
        },
        settings: RenderSettings {
            mode,
            ..Default::default()
        },
        width: size,
        height: size,
    }
}

/// The transfer function for a mode: the volume's default preset (CT bone for the
/// cranium) for iso and MIP; MinIP and the average look through air, so they get a
/// window over the whole range (else they are black).
fn tf_for(mode: RenderMode, v: &Volume) -> TransferFunction {
    let stats = v.stats();
    let tf = TransferFunction::preset(Preset::default_for(&stats), &stats);
    match mode {
        RenderMode::Minip | RenderMode::Average => {
            tf.with_window_level(stats.max - stats.min, (stats.max + stats.min) / 2.0)
        }
        _ => tf,
    }
}

use common::TWIN;

/// An isosurface hit is a yes/no per ray: where lavapipe's filter weights put a sample
/// on the other side of the iso value at a silhouette, the pixel is surface on one side
/// and background on the other. A few such pixels may differ by anything.
const ISO_TWIN: Tolerance = Tolerance {
    max_outlier_diff: 255,
    ..TWIN
};

#[test]
fn every_mode_on_the_gpu_matches_its_cpu_twin_and_skipping_changes_nothing() {
    let gpu = device();
    let rc = RayCaster::new(&gpu.device).unwrap_or_else(|e| panic!("{e}"));
    let mut failures = Vec::new();
    for (name, file) in [
        ("engine", "raw/engine.raw"),
        ("cranium", "raw/cranium-ct.raw"),
    ] {
        let v = load(file);
        let texels = common::small_texels(&v);
        for mode in MODES {
            let tf = tf_for(mode, &v);
            let f = frame(96, mode, 30.0, 20.0);
            let vol = RenderVolume::from_texels(&gpu, texels.clone(), &tf, f.settings.step_voxels)
                .unwrap_or_else(|e| panic!("{e}"));
            let g = rc
                .render(&gpu, &vol, &f, None)
                .unwrap_or_else(|e| panic!("{e}"));
            let (cv, occ) = cpu::prepare(&texels, &vol.lut);
            let c = cpu::render(&texels, &cv, &vol.lut, &occ, &f);
            let label = format!("twin_{name}_{}", mode.to_string().replace(':', "_"));
            // The test proves nothing on an empty image.
            let lit = g.pixels.iter().filter(|p| p[..3] != [0, 0, 0]).count();
            assert!(lit > 500, "{label}: only {lit} non-black pixels");
            let tol = if matches!(mode, RenderMode::Iso(_)) {
                ISO_TWIN
            } else {
                TWIN
            };
            if let Err(e) = common::twin(&label, &g, &c, tol, &out_dir()) {
                failures.push(e);
            }
            // Skipping blocks (on by default) changes no pixel, on either side.
            let mut naive = f;
            naive.settings.empty_space_skipping = false;
            let g_naive = rc
                .render(&gpu, &vol, &naive, None)
                .unwrap_or_else(|e| panic!("{e}"));
            assert!(
                g.pixels == g_naive.pixels,
                "{label}: skipping changed the GPU image"
            );
            let c_naive = cpu::render(&texels, &cv, &vol.lut, &occ, &naive);
            assert!(
                c.pixels == c_naive.pixels,
                "{label}: skipping changed the CPU image"
            );
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A 33³ volume of zeros with a bright voxel of `value` at the centre. Its 26
/// neighbours share the value so that trilinear sampling reaches it wherever a sample
/// falls inside the centre voxel's cell.
fn bright_voxel(value: u8) -> Volume {
    u8_volume([33; 3], |x, y, z| {
        let near = |c: usize| c.abs_diff(16) <= 1;
        if near(x) && near(y) && near(z) {
            value
        } else {
            0
        }
    })
}

/// The centre pixel of an odd-sized frame looking at the volume's centre, GPU and CPU.
fn centre_pixel(v: &Volume, tf: &TransferFunction, mode: RenderMode) -> ([u8; 4], [u8; 4]) {
    let gpu = Arc::new(device());
    let mut f = frame(33, mode, 0.0, 0.0);
    f.settings.jitter = false;
    let ao = AoSettings::default();
    let job = RenderJob::new(v, tf, &f, &ao);
    let pick = |image: &Image| image.pixels[(16 * 33 + 16) as usize];
    let g = offscreen::render(Some(&gpu), &job, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let c = offscreen::render(None, &job, &|_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    (pick(&g.image), pick(&c.image))
}

#[test]
fn mip_of_one_bright_voxel_has_its_value_at_its_pixel() {
    // The flat TF's window is 0…255, so grey = value / 255.
    let tf = flat_tf(0.5);
    let v = bright_voxel(200);
    let (g, c) = centre_pixel(&v, &tf, RenderMode::Mip);
    for (device, p) in [("GPU", g), ("CPU twin", c)] {
        assert!(
            p[..3].iter().all(|&x| x.abs_diff(200) <= 1) && p[3] == 255,
            "{device}: MIP pixel {p:?}, expected grey 200"
        );
    }
    // MinIP of the same ray sees the zeros around the voxel; the mean lies between.
    let (g, c) = centre_pixel(&v, &tf, RenderMode::Minip);
    assert_eq!((g[0], c[0]), (0, 0), "MinIP");
    let (g, c) = centre_pixel(&v, &tf, RenderMode::Average);
    assert!(
        g[0] > 0 && g[0] < 200 && g[0].abs_diff(c[0]) <= 1,
        "average {g:?} {c:?}"
    );
}

#[test]
fn clipping_applies_in_every_mode() {
    let gpu = Arc::new(device());
    let v = bright_voxel(200);
    // Zeros transparent (composite shows only the voxel), window 0…255.
    let tf = TransferFunction {
        name: "ramp".into(),
        opacity: OpacityPoint::list(&[(0.0, 0.0), (255.0, 1.0)]),
        color: ColorStop::list(&[(0.0, [1.0; 3])]),
    };
    let ao = AoSettings::default();
    // A carving sphere around the bright voxel removes it from every mode's ray.
    let carve = [ClipShape::new(Shape::Sphere, Vec3::ZERO, 6.0)];
    for mode in [
        RenderMode::Composite,
        RenderMode::Mip,
        RenderMode::Iso(Some(100.0)),
    ] {
        let mut f = frame(33, mode, 0.0, 0.0);
        f.settings.jitter = false;
        let pixel = |clip: &[ClipShape]| {
            let job = RenderJob {
                clip,
                ..RenderJob::new(&v, &tf, &f, &ao)
            };
            let r = offscreen::render(Some(&gpu), &job, &|_, _| {})
                .unwrap_or_else(|e| panic!("{mode}: {e}"));
            r.image.pixels[16 * 33 + 16]
        };
        let (whole, carved) = (pixel(&[]), pixel(&carve));
        assert!(
            whole[0] > 100,
            "{mode}: the voxel should show unclipped: {whole:?}"
        );
        assert!(
            carved[0] <= 2,
            "{mode}: the carved voxel still shows: {carved:?}"
        );
    }
}

#[test]
fn iso_finds_the_surface_between_samples() {
    // A 9³ cube of 200 in zeros: the centre ray meets a face where the trilinear ramp
    // between two voxels crosses the iso value, and the hit is lit and opaque.
    let v = u8_volume([33; 3], |x, y, z| {
        if [x, y, z].iter().all(|c| c.abs_diff(16) <= 4) {
            200
        } else {
            0
        }
    });
    let tf = flat_tf(0.5);
    for iso in [50.0, 150.0] {
        let (g, c) = centre_pixel(&v, &tf, RenderMode::Iso(Some(iso)));
        for (device, p) in [("GPU", g), ("CPU twin", c)] {
            assert!(p[3] == 255 && p[0] > 50, "{device} iso {iso}: {p:?}");
        }
    }
}

#[test]
fn golden_images_of_each_mode() {
    let gpu = Arc::new(device());
    let mut failures = Vec::new();
    for (name, file) in [
        ("engine", "raw/engine.raw"),
        ("cranium", "raw/cranium-ct.raw"),
    ] {
        let v = load(file);
        for mode in MODES {
            let tf = tf_for(mode, &v);
            let f = frame(128, mode, 30.0, 20.0);
            let ao = AoSettings::default();
            // Every ray through a whole scan meets air, so MinIP looks inside a probe.
            let probe = ClipShape {
                mode: ClipMode::Probe,
                ..ClipShape::new(Shape::Sphere, Vec3::ZERO, 40.0)
            };
            let clip = if mode == RenderMode::Minip {
                vec![probe]
            } else {
                Vec::new()
            };
            let job = RenderJob {
                clip: &clip,
                ..RenderJob::new(&v, &tf, &f, &ao)
            };
            let image = offscreen::render(Some(&gpu), &job, &|_, _| {})
                .unwrap_or_else(|e| panic!("{e}"))
                .image;
            let mode_name = mode.to_string().replace(':', "_");
            let stem = format!("mode_{name}_{mode_name}");
            if let Err(e) = common::golden(&stem, &image, &out_dir()) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn modes_parse_and_print_as_the_cli_and_scenes_write_them() {
    for s in [
        "composite",
        "mip",
        "minip",
        "average",
        "iso",
        "iso:300",
        "iso:-500.5",
    ] {
        let m: RenderMode = s.parse().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.to_string(), s);
    }
    assert_eq!(
        "ISO:300".parse::<RenderMode>(),
        Ok(RenderMode::Iso(Some(300.0)))
    );
    for bad in ["", "max", "iso:", "iso:nan", "iso:inf", "iso:abc"] {
        let e = bad.parse::<RenderMode>().expect_err(bad);
        assert!(e.contains("expected composite, mip"), "{bad:?}: {e}");
    }
    let settings = RenderSettings {
        mode: RenderMode::Iso(Some(300.0)),
        ..Default::default()
    };
    let json = serde_json::to_string(&settings).unwrap_or_else(|e| panic!("{e}"));
    assert!(json.contains(r#""mode":"iso:300""#), "{json}");
    let back: RenderSettings = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.mode, settings.mode);
    // Composite is the default and is not written, so older scenes stay as they were.
    let json = serde_json::to_string(&RenderSettings::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(!json.contains("mode"), "{json}");
}
