//! The real `volao` binary opens its window under Xvfb on lavapipe, draws frames, writes a
//! screenshot through `--screenshot … --exit-after-frames N` and exits; the screenshot
//! and its scene reproduce with `volao render`. Needs `xvfb-run` (`.ci/run` installs
//! xvfb and xauth); without it the test fails with that instruction, it never skips.

mod common;

use common::data;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use volao::render::Image;
use volao::render::image::{Tolerance, check};

fn out_dir() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("viewer_binary")
}

/// Runs `cmd`, killing it after `limit`. Returns (success, stderr).
fn run_bounded(mut cmd: Command, limit: Duration) -> (bool, String) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            let out = child.wait_with_output().expect("output");
            let text = String::from_utf8_lossy(&out.stderr).into_owned()
                + &String::from_utf8_lossy(&out.stdout);
            return (status.success(), text);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().expect("output");
            panic!(
                "{cmd:?} did not finish within {limit:?}; output:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn xvfb_run() -> Command {
    let found = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        found,
        "xvfb-run is missing: the viewer smoke test needs a virtual X server. \
         Install it with: sudo apt-get install -y xvfb xauth (.ci/run does)"
    );
    let mut cmd = Command::new("xvfb-run");
    cmd.args(["-a", "-s", "-screen 0 1280x800x24"]);
    // Mesa wants a private runtime dir; keep the user's settings out of the run.
    let runtime = out_dir().join("xdg");
    let _ = std::fs::create_dir_all(&runtime);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700));
    }
    cmd.env("XDG_RUNTIME_DIR", &runtime);
    cmd
}

fn render(scene: &Path, png: &Path) -> Image {
    let out = Command::new(env!("CARGO_BIN_EXE_volao"))
        .args([
            "render",
            &scene.display().to_string(),
            "-o",
            &png.display().to_string(),
        ])
        .output()
        .expect("volao runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Image::load_png(png).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_binary_opens_a_window_renders_and_writes_a_screenshot() {
    let dir = tempfile::tempdir().expect("temp dir");
    let shot = dir.path().join("shot.png");
    let mut cmd = xvfb_run();
    cmd.arg(env!("CARGO_BIN_EXE_volao")).args([
        "view",
        &data("pvm/Bucky.pvm").display().to_string(),
        "--size",
        "640x480",
        "--exit-after-frames",
        "5",
        "--screenshot",
        &shot.display().to_string(),
    ]);
    let (ok, output) = run_bounded(cmd, Duration::from_secs(240));
    assert!(ok, "volao view failed:\n{output}");
    let img = Image::load_png(&shot).unwrap_or_else(|e| panic!("{e}\n{output}"));
    // The viewport is the 3-D pane of the 2×2 layout a file opens on: a quarter of the
    // window less the side panel, menu and status bars.
    assert!(
        img.width > 100 && img.width < 320 && img.height > 150 && img.height < 240,
        "screenshot {}×{}",
        img.width,
        img.height
    );
    let lit = img.pixels.iter().filter(|p| p[0] > 40).count();
    assert!(lit > img.pixels.len() / 20, "only {lit} lit pixels");
    // Its scene reproduces it headless, pixel for pixel (same renderer, same adapter).
    let scene = dir.path().join("shot.json");
    let again = render(&scene, &dir.path().join("again.png"));
    check(
        "binary_shot_vs_render",
        &img,
        &again,
        Tolerance::EXACT,
        &out_dir(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn a_bad_file_exits_with_one_error_line() {
    let (ok, output) = run_bounded(
        {
            let mut c = Command::new(env!("CARGO_BIN_EXE_volao"));
            c.args([
                "view",
                "/nonexistent/scan.nii.gz",
                "--exit-after-frames",
                "1",
            ]);
            c
        },
        Duration::from_secs(30),
    );
    assert!(!ok);
    assert!(
        output.starts_with("error: ") && output.contains("/nonexistent/scan.nii.gz"),
        "{output}"
    );
}

/// Under a working X server but without a usable Vulkan driver, the viewer says what
/// `volao gpu` says (which driver to install), not that the display is missing.
#[test]
fn without_an_adapter_the_viewer_names_the_driver_to_install() {
    let mut cmd = xvfb_run();
    cmd.env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .arg(env!("CARGO_BIN_EXE_volao"))
        .args(["view", "--exit-after-frames", "1"]);
    let (ok, output) = run_bounded(cmd, Duration::from_secs(60));
    assert!(!ok, "{output}");
    assert!(
        output.contains("no usable GPU adapter") && output.contains("mesa-vulkan-drivers"),
        "{output}"
    );
    assert!(!output.contains("needs a display"), "{output}");
}

/// The scripted clip drag of docs/benchmarks.md (`--bench-clip-drag`, the Engine with
/// 14-ray CAO) always finishes: without interactive quality (`--target-rate off`: the
/// images of a moving view at full size), at the default target rate and at one a
/// second. Until 2026-12-07 an image at full size never started while CAO's update was
/// on its way, which during a drag is always: the run never finished, whether the size
/// was full because interactive quality was off or because the measured rate kept the
/// target rate without a reduction (at 256², one a second, on a quiet machine). The
/// viewer's watchdog ends a stalled run with what it was waiting for, so a failure says
/// where it stuck.
#[test]
fn the_scripted_clip_drag_always_finishes() {
    // The benchmark's scene, reading the Engine from wherever the test data are.
    let bench = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/scenes/engine_cao.json");
    let mut json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&bench).unwrap_or_else(|e| panic!("{}: {e}", bench.display())),
    )
    .expect("the benchmark scene is JSON");
    json["volume"]["path"] = data("raw/engine.raw").display().to_string().into();
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = dir.path().join("engine_cao.json");
    std::fs::write(&scene, json.to_string()).expect("scene written");
    for rate in ["off", "10", "1"] {
        let mut cmd = xvfb_run();
        cmd.arg(env!("CARGO_BIN_EXE_volao")).args([
            "view",
            &scene.display().to_string(),
            "--size",
            "256x256",
            "--clip-maps",
            "128",
            "--bench-clip-drag",
            "6",
            "--target-rate",
            rate,
        ]);
        let start = Instant::now();
        let (ok, output) = run_bounded(cmd, Duration::from_secs(400));
        eprintln!(
            "target rate {rate}: the drag finished in {:.0} s\n{output}",
            start.elapsed().as_secs_f64()
        );
        assert!(
            ok,
            "the scripted drag failed at target rate {rate}:\n{output}"
        );
        // The report: its images, and at least five CAO updates while dragging.
        let updates = output
            .split("CAO updates while dragging: ")
            .nth(1)
            .and_then(|rest| rest.split(',').next())
            .and_then(|n| n.trim().parse::<u32>().ok());
        assert!(
            output.contains("images while dragging a clip shape") && updates >= Some(5),
            "the drag's report is missing:\n{output}"
        );
        if rate == "off" {
            assert!(
                output.contains("at 1/1"),
                "the test needs images at full size while dragging:\n{output}"
            );
        }
    }
}
