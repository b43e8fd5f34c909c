//! `volao batch`: many scenes rendered in one process on one device, with a progress bar.
//! Outputs already there are skipped (an interrupted batch resumes); a scene that fails is
//! reported with its file and reason and the others go on; the exit code says whether
//! any failed.

use crate::args::BatchArgs;
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use volao::ao::AoMethod;
use volao::ao::sparse::Coverage;
use volao::headless::{self, DeviceSlot, Prepared};
use volao::scene::Scene;

/// One scene's work: where it comes from and where its outputs go.
#[derive(Debug)]
struct Task {
    scene: PathBuf,
    png: PathBuf,
    /// With `--ao-volumes`: the AO volume's file.
    ao: Option<PathBuf>,
}

/// What became of one scene.
enum Outcome {
    /// Every output was there already.
    Skipped,
    /// Something was written; the line says what.
    Done(String),
}

/// `volao batch`.
pub fn run(args: &BatchArgs) -> Result<()> {
    let tasks = tasks(args)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let slot = DeviceSlot::default();
    let bar = indicatif::ProgressBar::new(tasks.len() as u64);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} scenes {eta} {wide_msg}")
    {
        bar.set_style(style);
    }
    let start = std::time::Instant::now();
    let (mut done, mut skipped) = (0usize, 0usize);
    let mut failed: Vec<(PathBuf, String)> = Vec::new();
    for task in &tasks {
        bar.set_message(task.scene.display().to_string());
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_task(task, args, &slot, &|line| bar.println(line))
        }));
        match result {
            Ok(Ok(Outcome::Skipped)) => skipped += 1,
            Ok(Ok(Outcome::Done(line))) => {
                done += 1;
                bar.println(line);
            }
            Ok(Err(e)) => failed.push((task.scene.clone(), format!("{e:#}"))),
            Err(panic) => failed.push((task.scene.clone(), panic_message(&*panic))),
        }
        if let Some((scene, reason)) = failed.last().filter(|(s, _)| *s == task.scene) {
            bar.println(format!("failed: {}: {reason}", scene.display()));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "batch: {} scenes: {done} rendered, {skipped} skipped (outputs exist), {} failed, in {seconds:.1} s{}",
        tasks.len(),
        failed.len(),
        if done > 0 {
            format!(" ({:.1} scenes per minute)", done as f64 * 60.0 / seconds)
        } else {
            String::new()
        }
    );
    for (scene, reason) in &failed {
        eprintln!("failed: {}: {reason}", scene.display());
    }
    if !failed.is_empty() {
        bail!(
            "{} of {} scenes failed (listed above); run the same command again to retry only those",
            failed.len(),
            tasks.len()
        );
    }
    Ok(())
}

/// The scenes the inputs name (a folder: its `.json` files, sorted), each with its
/// outputs; two scenes that would write the same file are refused before anything runs.
fn tasks(args: &BatchArgs) -> Result<Vec<Task>> {
    let mut scenes = Vec::new();
    for input in &args.inputs {
        if input.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .with_context(|| format!("{}: cannot list the folder", input.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_json(p))
                .collect();
            if found.is_empty() {
                bail!("{}: no scene files (.json) in this folder", input.display());
            }
            found.sort();
            scenes.extend(found);
        } else if is_json(input) {
            // A missing file is that scene's failure, reported with the others.
            scenes.push(input.clone());
        } else {
            bail!(
                "{}: not a scene file (.json) or a folder of them",
                input.display()
            );
        }
    }
    let mut by_output: BTreeMap<PathBuf, &Path> = BTreeMap::new();
    let mut tasks = Vec::new();
    for scene in &scenes {
        let name = scene
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let png = args.out.join(format!("{name}.png"));
        if let Some(other) = by_output.insert(png.clone(), scene) {
            bail!(
                "{} and {} would both write {}: give scenes distinct file names",
                other.display(),
                scene.display(),
                png.display()
            );
        }
        tasks.push(Task {
            scene: scene.clone(),
            png,
            ao: args
                .ao_volumes
                .then(|| args.out.join(format!("{name}.ao.nii.gz"))),
        });
    }
    Ok(tasks)
}

fn is_json(p: &Path) -> bool {
    p.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// Renders one scene (and computes its AO volume) unless its outputs exist. Warnings go
/// to `say`, one line each.
fn run_task(
    task: &Task,
    args: &BatchArgs,
    slot: &DeviceSlot,
    say: &dyn Fn(String),
) -> Result<Outcome> {
    let mut scene = Scene::open(&task.scene)?;
    scene.settle().map_err(anyhow::Error::msg)?;
    let ao_path = task
        .ao
        .as_ref()
        .filter(|_| scene.ambient_occlusion.method != AoMethod::None);
    let png_missing = !task.png.exists();
    let ao_missing = ao_path.is_some_and(|p| !p.exists());
    if !png_missing && !ao_missing {
        return Ok(Outcome::Skipped);
    }
    let warn = |what: &str| say(format!("warning: {}: {what}", task.scene.display()));
    let (volume, warnings) = headless::load_volume(&scene, &mut |_, _| {})?;
    warnings.iter().for_each(|w| warn(w));
    let start = std::time::Instant::now();
    let mut wrote = Vec::new();
    if let Some(path) = ao_path.filter(|_| ao_missing) {
        let ao = &scene.ambient_occlusion;
        let clip = if ao.method.is_clipped() {
            scene.clip_shapes.clone()
        } else {
            Vec::new()
        };
        let gpu = if args.cpu {
            volao::gpu::GpuUse::Cpu
        } else {
            slot.gpu_use()
        };
        let computed = headless::ao_volume(
            &volume,
            &scene.transfer_function,
            ao,
            &clip,
            Coverage::Every,
            &gpu,
            &|_, _| {},
        )?;
        computed.notes.iter().for_each(|n| warn(n));
        write_atomically(path, |tmp| {
            for w in volao::volume::save(&computed.volume, tmp)? {
                warn(&w);
            }
            Ok(())
        })?;
        wrote.push(path.display().to_string());
    }
    if png_missing {
        let volume = volume.to_ras();
        if let Some(note) = headless::projection_window(&mut scene, &volume.stats()) {
            warn(&note);
        }
        let prepared = Prepared::new(&mut scene, volume, &[])?;
        prepared.warnings.iter().for_each(|w| warn(w));
        let mut notes = Vec::new();
        let device = match args.cpu {
            true => None,
            false => slot.for_scene(&scene, &mut notes)?,
        };
        let out = headless::render(&scene, &prepared, device.as_ref(), &|_, _| {})?;
        notes.iter().chain(&out.notes).for_each(|n| warn(n));
        for e in &out.clip_errors {
            warn(&format!("{e} (rendered without it)"));
        }
        write_atomically(&task.png, |tmp| Ok(out.image.save_png(tmp)?))?;
        wrote.push(task.png.display().to_string());
    }
    Ok(Outcome::Done(format!(
        "{}: {} in {:.0} ms",
        task.scene.display(),
        wrote.join(", "),
        start.elapsed().as_secs_f64() * 1e3
    )))
}

/// Writes `path` through a hidden file beside it (same extension, so the writer picks the
/// same format) renamed into place, so an interrupted batch never leaves a partial output
/// that the next run would skip.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".partial.{name}"));
    let written = write(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path)
            .with_context(|| format!("{}: cannot move the output into place", path.display()))
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// What a panic said, for the failure list.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    let text = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into());
    format!("internal error (panic): {text}")
}
