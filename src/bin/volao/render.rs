//! `volao render`: a volume or a scene file to PNG, headless.
//!
//! The image is rendered from a [`Scene`]: the scene file's, or a default one for a plain
//! volume file. Flags given on the command line are applied onto it (they override the
//! scene; flags left out keep it), and `--save-scene` writes exactly the scene rendered.

use crate::args::{RenderArgs, parse_background, set, set_within};
use crate::progress::{load_with_bar, slice_bar};
use anyhow::{Result, bail};
use volao::ao::{AoMethod, AoSettings};
use volao::headless::{self, DeviceSlot, Prepared};
use volao::render::RenderSettings;
use volao::render::offscreen::Rendered;
use volao::scene::{Light, MeshSource, Scene, SegmentationSource, VolumeSource};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, Stats, Volume};

/// `volao render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let file = args.scene_file()?;
    let source = args.volume_source(file.as_ref());
    let volume = match &source.path {
        Some(p) => load_with_bar(p, &source.load_options())?.volume,
        None => volume::demo::head_phantom(128),
    }
    .to_ras();
    let stats = volume.stats();
    let mut scene = file.unwrap_or_else(|| Scene::default_for(source.clone(), &stats));
    scene.volume = source;
    args.apply_to(&mut scene, &stats)?;
    scene.settle().map_err(anyhow::Error::msg)?;
    if let Some(note) = headless::projection_window(&mut scene, &stats) {
        eprintln!("note: {note}");
    }
    let prepared = args.prepare(&mut scene, volume)?;

    let start = std::time::Instant::now();
    let layout = args.layout.unwrap_or(volao::slice::Layout::ThreeD);
    let (full_w, full_h) = (scene.width, scene.height);
    let mut pane = scene.clone();
    (pane.width, pane.height) = layout.three_d_size(full_w, full_h);
    let mut out = render_scene(&pane, &prepared, !args.cpu)?;
    if args.annotate {
        annotate_3d(&mut out.image, &scene.camera);
    }
    if layout != volao::slice::Layout::ThreeD {
        out.image = with_slices(
            layout,
            &scene,
            &prepared,
            args.at,
            args.annotate,
            &out.image,
        );
    }
    for e in &out.clip_errors {
        eprintln!("warning: {e} (rendered without it)");
    }
    let seconds = start.elapsed().as_secs_f64();
    if out.downsampled > 0 {
        eprintln!(
            "note: the volume was halved {}× to fit the adapter's 3-D texture limits",
            out.downsampled
        );
    }
    out.image.save_png(&args.output)?;
    println!(
        "{}: {}×{} in {:.0} ms on {}{}",
        args.output.display(),
        scene.width,
        scene.height,
        seconds * 1e3,
        out.device,
        ao_note(&scene.ambient_occlusion, out.ao_seconds)
    );
    if let Some(stats) = &out.cao {
        crate::ao::print_cao(stats);
    }
    if let Some(v) = &out.view {
        println!(
            "view culling: AO computed for the {} voxels this image reads, {:.1} % of the {} the transfer function can show (--no-view-culling: all)",
            v.needed,
            100.0 * v.fraction(),
            v.readable
        );
    }
    if scene.render.shadows {
        eprintln!("{}", light_note(&scene.render, &out));
    }
    if let Some(path) = &args.save_scene {
        scene.save(path)?;
        println!("scene: {}", path.display());
    }
    Ok(())
}

/// `image` (the 3-D view) with the three slices through `at` (default: the volume's
/// centre) in `layout`'s panes of the scene's size, greys in the transfer function's
/// window, with the segmentation's colours over them when there is one (as `volao slice
/// --labels`).
fn with_slices(
    layout: volao::slice::Layout,
    scene: &Scene,
    prepared: &Prepared,
    at: Option<[f64; 3]>,
    annotate: bool,
    image: &volao::render::Image,
) -> volao::render::Image {
    use volao::slice::{Convention, LabelOverlay, Plane, Sampling, SliceAxis, SliceGeometry};
    let volume = &prepared.volume;
    let overlay = prepared
        .segments
        .as_ref()
        .map(|s| LabelOverlay::of(s, LabelOverlay::DEFAULT_OPACITY, false));
    let geometry = SliceGeometry::new(volume, Plane::Patient);
    let at = at.map_or_else(|| geometry.centre(), glam::DVec3::from_array);
    let (window, level) = scene.transfer_function.window_level();
    let slices: Vec<_> = SliceAxis::ALL
        .into_iter()
        .map(|axis| {
            let index = geometry.index_at(axis, at);
            let s = geometry.cut(
                volume,
                axis,
                Convention::Radiological,
                index,
                Sampling::Nearest,
            );
            let mut rgb = s.rgb(window, level, overlay.as_ref());
            if annotate {
                let letters = geometry.edge_letters(axis, Convention::Radiological);
                volao::slice::annotate(&mut rgb, s.width, letters, geometry.pixel_mm(axis));
            }
            (axis, [s.width, s.height], rgb)
        })
        .collect();
    volao::slice::compose(layout, scene.width, scene.height, image, &slices)
}

/// Draws the orientation marker of `camera` into the 3-D view `image` (opaque where
/// drawn, so it shows on a transparent background too).
fn annotate_3d(image: &mut volao::render::Image, camera: &volao::render::Camera) {
    let before: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mut rgb = before.clone();
    volao::slice::orientation_marker(&mut rgb, image.width as usize, camera);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        let new = &rgb[3 * i..3 * i + 3];
        if new != &before[3 * i..3 * i + 3] {
            *p = [new[0], new[1], new[2], 255];
        }
    }
}

impl RenderArgs {
    /// The scene file the input names (a `.json`), with its paths resolved against it.
    fn scene_file(&self) -> Result<Option<Scene>> {
        let Some(path) = self.input.as_ref().filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        }) else {
            return Ok(None);
        };
        Ok(Some(Scene::open(path)?))
    }

    /// The scene's segmentation (`--labels` replaces it; `--segment` changes its
    /// styles) placed on `volume`'s grid, and its meshes.
    fn prepare(&self, scene: &mut Scene, volume: Volume) -> Result<Prepared> {
        if let Some(path) = &self.labels.labels {
            let styles = scene
                .segmentation
                .take()
                .map(|s| s.styles)
                .unwrap_or_default();
            scene.segmentation = Some(SegmentationSource {
                path: path.clone(),
                table: self.labels.label_table.clone(),
                styles,
            });
        }
        if scene.segmentation.is_none() && !self.segment.is_empty() {
            bail!("--segment needs a segmentation: give --labels SEG");
        }
        let prepared = Prepared::new(scene, volume, &self.segment)?;
        for w in &prepared.warnings {
            eprintln!("warning: {w}");
        }
        Ok(prepared)
    }

    /// Which volume, and how to read it: the scene's (a raw layout given by flags
    /// replaces the scene's; its frame stays), else the input file and the flags.
    fn volume_source(&self, scene: Option<&Scene>) -> VolumeSource {
        let flags = self.load.options();
        match scene {
            Some(s) => {
                let mut options = s.load_options();
                if !flags.raw.is_empty() {
                    options.raw = flags.raw;
                }
                if flags.level != 0 {
                    options.level = flags.level;
                }
                VolumeSource::from_load_options(s.volume.path.clone(), &options)
            }
            None => VolumeSource::from_load_options(self.input.clone(), &flags),
        }
    }

    /// Applies the flags given onto `scene` and checks the values; flags left out keep
    /// the scene's. `stats` (the loaded volume's) place a `--tf` preset.
    pub fn apply_to(&self, scene: &mut Scene, stats: &Stats) -> Result<()> {
        self.apply_view(scene, stats)?;
        self.apply_render_settings(&mut scene.render)?;
        if let Some(direction) = self.light {
            scene.light = Light::Directional { direction };
        }
        if self.opacity_modulation.is_some() {
            scene.render.opacity_modulation = self.opacity_modulation;
        }
        if self.show_clip.is_some() {
            scene.render.clip_surface = self.show_clip;
        }
        scene.width = self.width.unwrap_or(scene.width);
        scene.height = self.height.unwrap_or(scene.height);
        self.apply_ao(scene)
    }

    /// The transfer function and the camera.
    fn apply_view(&self, scene: &mut Scene, stats: &Stats) -> Result<()> {
        if let Some(name) = &self.tf {
            scene.transfer_function = TransferFunction::preset(Preset::from_name(name)?, stats);
        }
        if let Some((w, l)) = self.window_level {
            scene.transfer_function = scene.transfer_function.with_window_level(w, l);
        }
        let camera = &mut scene.camera;
        if let Some(c) = &self.camera {
            (camera.azimuth_deg, camera.elevation_deg, camera.distance) = (c[0], c[1], c[2]);
            if camera.distance <= 0.0 {
                bail!(
                    "--camera: the distance must be positive (it is in bounding-sphere radii; {} is the default)",
                    volao::render::camera::DEFAULT_DISTANCE
                );
            }
        }
        camera.orthographic |= self.ortho;
        Ok(())
    }

    /// Background, ambient coefficient, AO strength and where it applies, shading, step
    /// and shadows.
    fn apply_render_settings(&self, settings: &mut RenderSettings) -> Result<()> {
        if let Some(b) = &self.background {
            settings.background = parse_background(b)?;
        }
        set_within(
            &mut settings.ambient,
            self.ambient,
            0.0..=1.0,
            "--ambient must be between 0 and 1",
        )?;
        set_within(
            &mut settings.ao_strength,
            self.ao_strength,
            0.0..=10.0,
            "--ao-strength must be between 0 and 10",
        )?;
        settings.ao_ambient_only |= self.ao_ambient_only;
        set_within(
            &mut settings.ao_offset,
            self.ao_offset,
            0.0..=volao::sample::AO_READ_REACH as f32,
            "--ao-offset must be between 0 and 2 voxels",
        )?;
        set(&mut settings.shading, self.shading);
        set(&mut settings.mode, self.mode);
        if let Some(step) = self.step {
            if step.is_nan() || step <= 0.0 || step.is_infinite() {
                bail!("--step must be positive (voxels between samples)");
            }
            settings.step_voxels = step;
        }
        settings.shadows |= self.shadows;
        if self.no_skipping {
            settings.empty_space_skipping = false;
        }
        if self.no_view_culling {
            settings.view_culling = false;
        }
        Ok(())
    }

    /// The AO method and its parameters, the clip shapes and the meshes.
    fn apply_ao(&self, scene: &mut Scene) -> Result<()> {
        let ao = &mut scene.ambient_occlusion;
        set(&mut ao.method, self.ao);
        set(&mut ao.rays, self.rays);
        if let Some(m) = self.samples {
            if m == 0 {
                bail!("--samples must be at least 1");
            }
            ao.samples = m;
        }
        self.vao.apply(&mut ao.vao)?;
        self.clip.apply(ao)?;
        scene.clip_shapes = self.clip.shapes_or(std::mem::take(&mut scene.clip_shapes));
        if !self.mesh.is_empty() {
            scene.meshes = self
                .mesh
                .iter()
                .map(|p| MeshSource {
                    path: p.clone(),
                    rgba: self.mesh_rgba,
                })
                .collect();
        }
        self.fast_ao.apply(&mut scene.ambient_occlusion)
    }
}

/// Renders `scene` (its data in `prepared`) on a fresh device, or on the CPU twin, with a
/// progress bar while the AO is computed.
fn render_scene(scene: &Scene, prepared: &Prepared, gpu: bool) -> Result<Rendered> {
    let ao = &scene.ambient_occlusion;
    let bar = slice_bar("ambient occlusion", ao.method != AoMethod::None);
    let mut notes = Vec::new();
    let device = match gpu {
        false => None,
        true => DeviceSlot::default().for_scene(scene, &mut notes)?,
    };
    for note in &notes {
        eprintln!("warning: {note}");
    }
    let out = headless::render(scene, prepared, device.as_ref(), &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    for note in &out.notes {
        eprintln!("warning: {note}");
    }
    bar.finish_and_clear();
    Ok(out)
}

/// What the summary line says about the AO: method, parameters and time.
fn ao_note(ao: &AoSettings, seconds: f64) -> String {
    if ao.method == AoMethod::None {
        String::new()
    } else if matches!(ao.method, AoMethod::Vao | AoMethod::VaoLive) {
        format!(
            " (positional AO{}, {} directions × {} samples, r_max {} mm: {:.0} ms)",
            if ao.method == AoMethod::VaoLive {
                " live"
            } else {
                ""
            },
            ao.vao.directions,
            ao.vao.samples,
            ao.vao.r_max_mm,
            seconds * 1e3
        )
    } else if volao::ao::fast::handles(ao.method) {
        format!(
            " (AO {}: {:.0} ms)",
            volao::ao::fast::describe(ao),
            seconds * 1e3
        )
    } else {
        format!(
            " (AO {} rays × {} samples: {:.0} ms)",
            ao.rays.name(),
            ao.samples,
            seconds * 1e3
        )
    }
}

/// What `--shadows` reports on stderr: the light volume's time, direction and size.
fn light_note(settings: &RenderSettings, out: &Rendered) -> String {
    let d = settings.light_direction;
    format!(
        "shadows: light volume {:.0} ms (towards the light {:.2}, {:.2}, {:.2}; {}filtered, guard {} voxels)",
        out.light_seconds * 1e3,
        d[0],
        d[1],
        d[2],
        if out.downsampled > 0 {
            "volume halved, "
        } else {
            ""
        },
        volao::render::shadow::GUARD_VOXELS
    )
}
