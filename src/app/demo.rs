//! The first screen: the demo head opens with ambient occlusion on and a sphere taking
//! off the top of the skull, seen from above the right eye, so that the first picture
//! shows what volao is for (AO inside a cut).
//!
//! Which AO the adapter can afford is measured, not guessed: a short Local-AO probe on a
//! small copy of the phantom gives the adapter's rate, from which the cost of Contextual
//! AO on the demo head follows. The most rays that keep both the precomputation and a
//! dragging frame within budget win; when not even 6 rays do (a CPU adapter such as
//! lavapipe), a fast ambient map is shown instead and the status bar says why.

use crate::ao::rays::RaySet;
use crate::ao::{AoEngine, AoInput, AoMethod, AoRequest, AoSettings};
use crate::clip::{ClipShape, Shape};
use crate::gpu::Gpu;
use crate::render::Camera;
use crate::texels::{UploadLimits, VolumeTexels};
use crate::tf::TransferFunction;
use crate::volume::Volume;
use glam::Vec3;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Edge of the phantom the probe runs on (32³: tens of milliseconds on lavapipe).
const PROBE_SIZE: usize = 32;

/// Longest Contextual-AO precomputation (V_PAO) the first screen may wait for.
pub const PRECOMPUTE_BUDGET: Duration = Duration::from_secs(3);

/// Longest CAO update per frame while the user drags the sphere (10 frames a second).
pub const FRAME_BUDGET: Duration = Duration::from_millis(100);

/// A CAO frame while dragging costs about this share of the whole V_PAO precomputation
/// with the demo's sphere. Measured with sparse CAO on lavapipe, 128³, `volao render`
/// of the demo's first screen (2026-12-04): step IV and the ray cast 84, 133 and 231 ms
/// a frame against 1.21, 1.55 and 2.00 s of AO for 6, 14 and 26 rays (0.07–0.12). It
/// was 0.45 with the dense CAO (0.93 s against 2.1 s).
const FRAME_SHARE: f64 = 0.12;

/// How the demo starts.
#[derive(Debug, Clone)]
pub struct DemoStart {
    pub camera: Camera,
    pub clip_shapes: Vec<ClipShape>,
    pub ao: AoSettings,
    /// For the status bar: which AO was chosen and why.
    pub note: String,
}

/// The sphere that takes off the top of the skull (mm from the volume's centre).
pub fn skull_cap() -> ClipShape {
    ClipShape::new(Shape::Sphere, Vec3::new(0.0, 0.0, 80.0), 60.0)
}

/// The demo's first view: from the front right, above the eyes, into the cut.
pub fn camera() -> Camera {
    Camera {
        azimuth_deg: -30.0,
        elevation_deg: 30.0,
        ..Camera::default()
    }
}

/// Seconds Local AO with `rays` rays takes on `voxels` voxels, from the probe's rate.
fn estimate(probe: Duration, probe_voxels: usize, voxels: usize, rays: usize) -> f64 {
    probe.as_secs_f64() * (voxels as f64 / probe_voxels as f64) * (rays as f64 / 6.0)
}

/// The ray sets the first screen may use, most rays first.
const RAY_SETS: [RaySet; 4] = [
    RaySet::FiftyFour,
    RaySet::TwentySix,
    RaySet::Fourteen,
    RaySet::Six,
];

/// The most rays whose estimated precomputation (from the probe's time on
/// `probe_voxels` voxels, for `voxels`) `fits`, with that estimate.
fn most_rays(
    probe: Duration,
    probe_voxels: usize,
    voxels: usize,
    fits: impl Fn(f64) -> bool,
) -> Option<(RaySet, f64)> {
    RAY_SETS
        .into_iter()
        .map(|rays| {
            let k = rays.directions().len();
            (rays, estimate(probe, probe_voxels, voxels, k))
        })
        .find(|&(_, pre)| fits(pre))
}

/// Picks the AO for the demo from the probe's time (6-ray LAO on `probe_voxels` voxels)
/// for a volume of `voxels` voxels.
pub fn choose(probe: Duration, probe_voxels: usize, voxels: usize) -> (AoSettings, String) {
    let mut ao = AoSettings::default();
    let budget = |pre: f64| {
        pre <= PRECOMPUTE_BUDGET.as_secs_f64() && pre * FRAME_SHARE <= FRAME_BUDGET.as_secs_f64()
    };
    if let Some((rays, pre)) = most_rays(probe, probe_voxels, voxels, budget) {
        ao.method = AoMethod::Cao;
        ao.rays = rays;
        let note = format!(
            "(demo: {} rays, the most this adapter affords: ≈ {pre:.1} s, then \
             ≈ {:.0} ms a dragged frame)",
            rays.directions().len(),
            pre * FRAME_SHARE * 1e3
        );
        return (ao, note);
    }
    let pre = estimate(probe, probe_voxels, voxels, 6);
    ao.method = AoMethod::Gauss;
    let note = format!(
        "(demo: {} here would take ≈ {pre:.1} s, then ≈ {:.1} s a dragged frame)",
        AoMethod::Cao.label(),
        pre * FRAME_SHARE
    );
    (ao, note)
}

/// Times 6-ray Local AO on a `PROBE_SIZE`³ phantom on `gpu`: the fastest of three runs
/// after one untimed run that builds the pipelines (the viewer starts up beside it: one
/// run took 17 to 45 ms on lavapipe). `None` when the probe fails.
fn probe(gpu: &Gpu, tf: &TransferFunction) -> Option<(Duration, usize)> {
    let small = crate::volume::demo::head_phantom(PROBE_SIZE).to_ras();
    let texels = VolumeTexels::new(&small, UploadLimits::NONE);
    let engine = AoEngine::on(Some(Arc::new(Gpu::new(
        gpu.instance.clone(),
        gpu.adapter.clone(),
        gpu.device.clone(),
        gpu.queue.clone(),
    ))));
    let settings = AoSettings {
        method: AoMethod::Lao,
        rays: RaySet::Six,
        ..AoSettings::default()
    };
    let request = AoRequest {
        tf,
        settings: &settings,
        clip: None,
        // What the viewer computes in compositing.
        coverage: crate::ao::sparse::Coverage::Readable,
        view: None,
    };
    let run = || engine.compute(AoInput::Texels(&texels), &request, &|_, _| {});
    run().ok()?;
    let mut best = Duration::MAX;
    for _ in 0..3 {
        let start = Instant::now();
        run().ok()?;
        best = best.min(start.elapsed());
    }
    Some((best, small.dims.iter().product()))
}

/// The AO a file opens with (not a scene, which says its own): Local AO with the most
/// rays whose precomputation on `voxels` voxels the probe's rate puts within
/// [`PRECOMPUTE_BUDGET`], else the fast ambient map; and a note saying so.
pub fn file_ao(gpu: &Gpu, voxels: usize, tf: &TransferFunction) -> (AoSettings, String) {
    let measured = probe(gpu, tf);
    choose_lao(measured, voxels)
}

/// [`file_ao`]'s choice from the probe's time (6-ray LAO on `probe_voxels` voxels).
pub fn choose_lao(probe: Option<(Duration, usize)>, voxels: usize) -> (AoSettings, String) {
    let mut ao = AoSettings::default();
    let Some((t, probe_voxels)) = probe else {
        ao.method = AoMethod::Gauss;
        return (ao, "(the AO probe failed, so the fast ambient map)".into());
    };
    let fits = |pre: f64| pre <= PRECOMPUTE_BUDGET.as_secs_f64();
    if let Some((rays, pre)) = most_rays(t, probe_voxels, voxels, fits) {
        ao.method = AoMethod::Lao;
        ao.rays = rays;
        let k = rays.directions().len();
        return (
            ao,
            format!("(opened with {k}-ray Local AO, the most this adapter affords: ≈ {pre:.1} s)"),
        );
    }
    ao.method = AoMethod::Gauss;
    let pre = estimate(t, probe_voxels, voxels, 6);
    (
        ao,
        format!(
            "(opened with the fast ambient map: {} would take ≈ {pre:.1} s here; choose it in the AO panel)",
            AoMethod::Lao.label()
        ),
    )
}

/// The demo's start on `gpu` for the demo `volume` shown with `tf`.
pub fn start(gpu: &Gpu, volume: &Volume, tf: &TransferFunction) -> DemoStart {
    let voxels = volume.dims.iter().product();
    let adapter = gpu.info.name.clone();
    let (ao, note) = match probe(gpu, tf) {
        Some((t, probe_voxels)) => choose(t, probe_voxels, voxels),
        None => {
            let ao = AoSettings {
                method: AoMethod::Gauss,
                ..AoSettings::default()
            };
            let note = format!("(demo: the AO probe failed on {adapter}, so the fast ambient map)");
            (ao, note)
        }
    };
    DemoStart {
        camera: camera(),
        clip_shapes: vec![skull_cap()],
        ao,
        note,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fast_adapter_gets_cao_with_many_rays_a_slow_one_an_ambient_map() {
        let n = 128 * 128 * 128;
        let p = 32 * 32 * 32;
        // 1 ms for the probe: 54 rays take 1·64·9 ms ≈ 0.58 s, a frame 69 ms.
        let (ao, note) = choose(Duration::from_millis(1), p, n);
        assert_eq!((ao.method, ao.rays), (AoMethod::Cao, RaySet::FiftyFour));
        assert!(note.contains("54 rays"), "{note}");
        // 3 ms: a 54-ray frame would take 0.12·3·64·9 ms ≈ 207 ms; 26 rays ≈ 100 ms.
        let (ao, _) = choose(Duration::from_millis(3), p, n);
        assert_eq!((ao.method, ao.rays), (AoMethod::Cao, RaySet::TwentySix));
        // 10 ms: 14 rays ≈ 0.18 s a frame; 6 rays 0.64 s to precompute, 77 ms a frame.
        let (ao, _) = choose(Duration::from_millis(10), p, n);
        assert_eq!((ao.method, ao.rays), (AoMethod::Cao, RaySet::Six));
        // A file: LAO with the most rays within the budget.
        let (ao, _) = choose_lao(Some((Duration::from_millis(1), p)), n);
        assert_eq!((ao.method, ao.rays), (AoMethod::Lao, RaySet::FiftyFour));
        // 25 ms: 14 rays ≈ 25·64·14/6 ms = 3.7 s, over the budget; 6 rays 1.6 s.
        let (ao, _) = choose_lao(Some((Duration::from_millis(25), p)), n);
        assert_eq!((ao.method, ao.rays), (AoMethod::Lao, RaySet::Six));
        // 60 ms: even 6 rays take 60·64 ms = 3.8 s.
        let (ao, note) = choose_lao(Some((Duration::from_millis(60), p)), n);
        assert_eq!(ao.method, AoMethod::Gauss);
        assert!(note.contains("ambient map"), "{note}");
        // Lavapipe's 17–45 ms: not even 6 rays.
        let (ao, note) = choose(Duration::from_millis(32), p, n);
        assert_eq!(ao.method, AoMethod::Gauss);
        // 32 ms · 64 = 2.0 s to precompute, 0.25 s a frame.
        assert!(
            note.contains("Contextual AO") && note.contains("2.0 s") && note.contains("0.2 s"),
            "{note}"
        );
    }
}
