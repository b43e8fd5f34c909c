//! `volao batch` as a user runs it: many scenes in one process, outputs equal to `volao
//! render` / `volao ao` of each scene, resumable, a failing scene reported while the
//! others complete, a summary and a non-zero exit.

mod common;

use common::{data, text, volao_cli as volao};
use std::path::{Path, PathBuf};
use volao::ao::AoMethod;
use volao::ao::rays::RaySet;
use volao::scene::{Scene, VolumeSource};

/// A small scene of a shared file, written to `dir/name.json`.
fn scene(dir: &Path, name: &str, volume: &str, ao: AoMethod, azimuth: f32) -> PathBuf {
    let path = data(volume);
    let loaded = volao::volume::load(&path, &Default::default()).expect("loads");
    let source = VolumeSource {
        path: Some(path),
        frame: 0,
        raw: None,
        level: 0,
    };
    let mut s = Scene::default_for(source, &loaded.volume.stats());
    (s.width, s.height) = (40, 32);
    s.camera.azimuth_deg = azimuth;
    s.ambient_occlusion.method = ao;
    s.ambient_occlusion.rays = RaySet::Six;
    s.ambient_occlusion.samples = 4;
    let file = dir.join(format!("{name}.json"));
    s.save(&file).expect("scene saved");
    file
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("lists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn batch_renders_what_volao_render_renders_and_resumes_without_rendering_again() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scenes = dir.path().join("scenes");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&scenes).expect("mkdir");
    let a = scene(&scenes, "bucky", "pvm/Bucky.pvm", AoMethod::Lao, 30.0);
    scene(&scenes, "storm", "pvm/Storm-t11.pvm", AoMethod::None, 60.0);
    let run = volao(&[Path::new("batch"), &scenes, Path::new("--out"), &out]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout)
            .contains("batch: 2 scenes: 2 rendered, 0 skipped (outputs exist), 0 failed"),
        "summary: {}",
        text(&run.stdout)
    );
    assert_eq!(files_in(&out), ["bucky.png", "storm.png"]);
    // The same bytes as `volao render` of the scene.
    let single = dir.path().join("single.png");
    let r = volao(&[Path::new("render"), &a, Path::new("-o"), &single]);
    assert!(r.status.success(), "{}", text(&r.stderr));
    assert_eq!(
        std::fs::read(&single).expect("read"),
        std::fs::read(out.join("bucky.png")).expect("read")
    );
    // A second run renders nothing and leaves the images as they were.
    let before = std::fs::metadata(out.join("bucky.png"))
        .and_then(|m| m.modified())
        .expect("mtime");
    let again = volao(&[Path::new("batch"), &scenes, Path::new("--out"), &out]);
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert!(
        text(&again.stdout).contains("2 scenes: 0 rendered, 2 skipped (outputs exist), 0 failed"),
        "{}",
        text(&again.stdout)
    );
    let after = std::fs::metadata(out.join("bucky.png"))
        .and_then(|m| m.modified())
        .expect("mtime");
    assert_eq!(before, after, "not written again");
    // A deleted output is the only one made again.
    std::fs::remove_file(out.join("storm.png")).expect("rm");
    let third = volao(&[Path::new("batch"), &scenes, Path::new("--out"), &out]);
    assert!(
        text(&third.stdout).contains("1 rendered, 1 skipped"),
        "{}",
        text(&third.stdout)
    );
}

#[test]
fn a_failing_scene_is_reported_and_the_others_complete() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let good = scene(dir.path(), "a_good", "pvm/Bucky.pvm", AoMethod::None, 0.0);
    let corrupt = scene(
        dir.path(),
        "b_corrupt",
        "pvm/Bucky.pvm",
        AoMethod::None,
        0.0,
    );
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&corrupt).expect("read")).expect("json");
    json["volume"]["path"] = data("nifti/not-nifti.nii").display().to_string().into();
    std::fs::write(&corrupt, json.to_string()).expect("write");
    let malformed = dir.path().join("c_malformed.json");
    std::fs::write(&malformed, "{ not json").expect("write");
    let missing = dir.path().join("d_missing.json");
    let last = scene(
        dir.path(),
        "e_good",
        "pvm/Storm-t11.pvm",
        AoMethod::None,
        90.0,
    );
    let run = volao(&[
        Path::new("batch"),
        &good,
        &corrupt,
        &malformed,
        &missing,
        &last,
        Path::new("--out"),
        &out,
    ]);
    assert!(!run.status.success(), "a failed scene fails the batch");
    let (stdout, stderr) = (text(&run.stdout), text(&run.stderr));
    assert!(
        stdout.contains("batch: 5 scenes: 2 rendered, 0 skipped (outputs exist), 3 failed"),
        "summary: {stdout}"
    );
    for (file, reason) in [
        (&corrupt, "not-nifti.nii"),
        (&malformed, "malformed JSON"),
        (&missing, "d_missing.json"),
    ] {
        let line = format!("failed: {}: ", file.display());
        assert!(
            stderr
                .lines()
                .any(|l| l.starts_with(&line) && l.contains(reason)),
            "{line}…{reason} in:\n{stderr}"
        );
    }
    assert!(stderr.contains("error: 3 of 5 scenes failed"), "{stderr}");
    assert_eq!(
        files_in(&out),
        ["a_good.png", "e_good.png"],
        "no partial files"
    );
}

#[test]
fn ao_volumes_equal_volao_ao_of_the_scene() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let s = scene(dir.path(), "bucky", "pvm/Bucky.pvm", AoMethod::Lao, 0.0);
    let none = scene(
        dir.path(),
        "plain",
        "pvm/Storm-t11.pvm",
        AoMethod::None,
        0.0,
    );
    let run = volao(&[
        Path::new("batch"),
        &s,
        &none,
        Path::new("--out"),
        &out,
        Path::new("--ao-volumes"),
    ]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert_eq!(
        files_in(&out),
        ["bucky.ao.nii.gz", "bucky.png", "plain.png"],
        "no AO volume for a scene without AO"
    );
    let single = dir.path().join("single.nii.gz");
    let bucky = data("pvm/Bucky.pvm");
    let ao = volao(&[
        Path::new("ao"),
        &bucky,
        Path::new("-o"),
        &single,
        Path::new("--method"),
        Path::new("lao"),
        Path::new("--rays"),
        Path::new("6"),
        Path::new("--samples"),
        Path::new("4"),
    ]);
    assert!(ao.status.success(), "{}", text(&ao.stderr));
    let values = |p: &Path| match volao::volume::load(p, &Default::default())
        .expect("loads")
        .volume
        .data
    {
        volao::volume::VoxelData::F32(v) => v,
        other => panic!("AO volumes are f32, not {other:?}"),
    };
    let (batch, cli) = (values(&out.join("bucky.ao.nii.gz")), values(&single));
    assert_eq!(batch.len(), 32 * 32 * 32);
    assert!(batch.iter().any(|a| *a < 1.0), "some occlusion");
    assert_eq!(batch, cli, "every voxel as volao ao");
}
