//! `volao bench cao`: the CAO paper's evaluation (Titov et al. §4, Tables 2–4, Fig. 10)
//! with a clip shape moving along a fixed path every frame, for three methods measured
//! side by side in one run:
//!
//! - `lao-every-frame`: the paper's baseline, dense (every voxel and sample), every
//!   pixel cast;
//! - `cao-paper`: the paper's CAO, dense step IV and V, every pixel cast;
//! - `cao`: sparse CAO (issue #15, `volao::ao::sparse`), what rendering runs, whose
//!   render casts only the rays near the shape's last and new pose and keeps its last
//!   image's other pixels (`volao::render::reuse`), as the viewer does while a shape is
//!   dragged;
//! - `lao-sparse`: LAO every frame over the readable voxels (`cao`'s skipping), every
//!   pixel cast: the baseline with the same skipping;
//! - `lao-view` and `cao-view`: the same two with view culling (issue #46,
//!   `volao::ao::view`): each frame a visibility pass of the image (clipped with the
//!   frame's maps) first, then step V only in the bricks it marked; `cao-view` renders
//!   as `cao` does. Their frame time includes the visibility pass.
//!
//! Every frame of every method is rendered and compared with `lao-every-frame`'s image
//! of the same pose: `differing_pixels` must be 0.

use anyhow::Result;
use glam::Vec3;
use std::path::PathBuf;
use std::time::Instant;
use volao::ao::cao::{CaoGpu, CaoMode, CaoStats, Pose};
use volao::ao::lao::Rays;
use volao::ao::rays::RaySet;
use volao::ao::sparse::Coverage;
use volao::clip::{ClipShape, Shape};
use volao::render::gpu::{RayCaster, RenderVolume};
use volao::render::reuse::{ImageInputs, reusable};
use volao::render::{Frame, RenderSettings, Shading};
use volao::texels::{UploadLimits, VolumeTexels};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, RawOverrides, VoxelType};

#[derive(clap::Args, Debug)]
pub struct CaoBenchArgs {
    /// The shared data folder.
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Largest volume side for Tables 3–4: volumes are halved until they fit (256 keeps
    /// the Engine at its full 256×256×110).
    #[arg(long, default_value_t = 256)]
    pub max_dim: usize,
    /// Largest volume side for Table 2 (percent recomputed does not depend on the ray
    /// count, so it runs with 6 rays at the paper's sizes).
    #[arg(long, default_value_t = 512)]
    pub table2_max_dim: usize,
    /// Frames per configuration (the shape moves along its path).
    #[arg(long, default_value_t = 4)]
    pub frames: usize,
    /// Image size (square).
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Depth/dilation map size.
    #[arg(long, default_value_t = volao::clip::gpu::DEFAULT_RESOLUTION)]
    pub clip_resolution: u32,
    /// Ray patterns of Table 3, a comma list (6, 14, 26, 54).
    #[arg(long, value_delimiter = ',', default_value = "6,14,26,54", value_parser = crate::args::parse_rays)]
    pub rays: Vec<RaySet>,
    /// Scenes of Tables 3 (a comma list of engine, lobster, cranium); Table 4 runs on
    /// the Engine when it is listed.
    #[arg(long, value_delimiter = ',', default_value = "engine,lobster,cranium")]
    pub scenes: Vec<String>,
    /// The tables to run, a comma list of 2, 3, 4.
    #[arg(long, value_delimiter = ',', default_value = "2,3,4")]
    pub tables: Vec<u32>,
    /// One JSON object per line instead of markdown tables.
    #[arg(long)]
    pub json: bool,
}

/// The paper's Table 3 speedups for the Engine (6, 14, 26, 54 rays).
fn paper_speedup(set: RaySet) -> Option<f64> {
    match set {
        RaySet::Six => Some(1.66),
        RaySet::Fourteen => Some(2.29),
        RaySet::TwentySix => Some(2.95),
        RaySet::FiftyFour => Some(3.79),
        _ => None,
    }
}

/// The methods, in the order they run each frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Method {
    LaoEveryFrame,
    CaoPaper,
    Cao,
    LaoSparse,
    LaoView,
    CaoView,
}

impl Method {
    /// The paper's three (Table 4 and the memory figures).
    const PAPER: [Method; 3] = [Method::LaoEveryFrame, Method::CaoPaper, Method::Cao];
    const ALL: [Method; 6] = [
        Method::LaoEveryFrame,
        Method::CaoPaper,
        Method::Cao,
        Method::LaoSparse,
        Method::LaoView,
        Method::CaoView,
    ];

    fn name(self) -> &'static str {
        match self {
            Method::LaoEveryFrame => "lao-every-frame",
            Method::CaoPaper => "cao-paper",
            Method::Cao => "cao",
            Method::LaoSparse => "lao-sparse",
            Method::LaoView => "lao-view",
            Method::CaoView => "cao-view",
        }
    }

    fn mode(self) -> CaoMode {
        match self {
            Method::LaoEveryFrame | Method::LaoSparse | Method::LaoView => CaoMode::Full,
            _ => CaoMode::Selective,
        }
    }

    fn coverage(self) -> Coverage {
        match self {
            Method::LaoEveryFrame | Method::CaoPaper => Coverage::Dense,
            _ => Coverage::Readable,
        }
    }

    /// Whether each frame's step V is culled to what the image reads.
    fn culls_view(self) -> bool {
        matches!(self, Method::LaoView | Method::CaoView)
    }

    /// Whether its image reuses the last one's pixels away from the change.
    fn reuses(self) -> bool {
        matches!(self, Method::Cao | Method::CaoView)
    }
}

struct Scene {
    key: &'static str,
    name: &'static str,
    file: &'static str,
    raw: RawOverrides,
    shape: &'static str,
    samples: u32,
    paper_percent: f64,
}

fn scenes() -> [Scene; 3] {
    let cranium_raw = RawOverrides {
        dims: Some([256, 256, 108]),
        ty: Some(VoxelType::I16),
        endian: Some(volume::Endian::Little),
        spacing: Some([0.957031, 0.957031, 1.5]),
        offset: None,
    };
    [
        Scene {
            key: "engine",
            name: "Engine",
            file: "raw/engine.raw",
            raw: RawOverrides::default(),
            shape: "sphere",
            samples: 20,
            paper_percent: 14.94,
        },
        Scene {
            key: "lobster",
            name: "Lobster (paper: Beetle)",
            file: "pvm/Lobster.pvm",
            raw: RawOverrides::default(),
            shape: "cube",
            samples: 40,
            paper_percent: 20.24,
        },
        Scene {
            key: "cranium",
            name: "Cranium CT (paper: Skeleton)",
            file: "raw/cranium-ct.raw",
            raw: cranium_raw,
            shape: "rectangular prism",
            samples: 50,
            paper_percent: 16.13,
        },
    ]
}

impl Scene {
    /// The scene's clip shape at rest, sized for a volume of half-extent `half`.
    fn base_shape(&self, half: Vec3) -> ClipShape {
        let r = half.min_element();
        match self.key {
            "engine" => ClipShape::new(Shape::Sphere, Vec3::ZERO, r * 0.45),
            "lobster" => ClipShape::new(Shape::Box, Vec3::ZERO, r * 0.4),
            _ => ClipShape {
                scale: [r * 0.35, r * 0.6, r * 0.3],
                ..ClipShape::new(Shape::Box, Vec3::ZERO, 1.0)
            },
        }
    }
}

struct Bench {
    gpu: volao::gpu::Gpu,
    rc: RayCaster,
    vol: RenderVolume,
    tf: TransferFunction,
    frame: Frame,
    resolution: u32,
    /// The voxels the transfer function can make visible (what `cao` computes).
    readable: Vec<bool>,
}

/// A frame's figures: CAO stats, the render time and the image.
struct Timed {
    stats: CaoStats,
    /// The visibility pass, and the fraction of the readable voxels it marked (view
    /// methods).
    view_seconds: f64,
    view_fraction: Option<f64>,
    /// Bytes of CAO's voxel list after the frame.
    list_bytes: u64,
    render_seconds: f64,
    pixels: Vec<[u8; 4]>,
    /// The image and what it shows, for the next frame to reuse.
    shown: Option<Shown>,
}

/// An image and the inputs it was rendered with.
struct Shown {
    image: volao::render::Image,
    inputs: ImageInputs,
    /// The voxels its AO reads weigh (view methods).
    view: Option<volao::ao::view::ViewMask>,
}

impl Timed {
    fn total_ms(&self) -> f64 {
        (self.view_seconds + self.stats.clip_seconds + self.stats.lao_seconds + self.render_seconds)
            * 1e3
    }
}

impl Bench {
    fn new(
        gpu: volao::gpu::Gpu,
        volume: &volume::Volume,
        max_dim: usize,
        size: u32,
        resolution: u32,
    ) -> Result<Self> {
        let tf = TransferFunction::preset(Preset::CaoSingleColor, &volume.stats());
        let settings = RenderSettings {
            shading: Shading::Phong,
            ambient: 0.8,
            ..Default::default()
        };
        let texels = VolumeTexels::new(
            volume,
            UploadLimits {
                max_dim,
                max_bytes: volao::render::gpu::MAX_VOLUME_BYTES,
            },
        );
        let vol = RenderVolume::from_texels(&gpu, texels, &tf, settings.step_voxels)?;
        let rc = RayCaster::new(&gpu.device)?;
        let readable = Coverage::Readable
            .bricks(&vol.texels, vol.ranges(), &tf)
            .readable_mask(&vol.texels);
        Ok(Bench {
            gpu,
            rc,
            vol,
            tf,
            frame: super::frame(20.0, settings, size),
            resolution,
            readable,
        })
    }

    fn cao(&self, set: RaySet, samples: u32, coverage: Coverage) -> Result<CaoGpu> {
        let setup = volao::ao::cao::CaoSetup {
            tf: &self.tf,
            rays: &Rays::uniform(set.directions()),
            samples,
            msaa: volao::ao::cao::DEFAULT_MSAA,
        };
        let bricks = coverage.bricks(&self.vol.texels, self.vol.ranges(), &self.tf);
        Ok(CaoGpu::new(
            &self.gpu,
            &self.vol,
            setup,
            bricks,
            &|_, _| {},
        )?)
    }

    /// One frame: AO update and render. With `previous` (the sparse method's last
    /// image), only the pixels whose rays pass near a shape that moved are cast
    /// (`volao::render::reuse`).
    fn frame(
        &mut self,
        cao: &mut CaoGpu,
        shapes: &[ClipShape],
        method: Method,
        previous: Option<&Shown>,
    ) -> Result<Timed> {
        let reach = cao.reach_mm(&self.vol.texels);
        let pose = Pose {
            shapes,
            resolution: self.resolution,
            reach_mm: reach,
            mode: method.mode(),
        };
        let (mut view_seconds, mut view_fraction, mut kept) = (0.0, None, None);
        if method.culls_view() {
            // The visibility pass clips with the maps the frame will.
            let start = Instant::now();
            cao.pose_maps(&self.gpu, &self.vol.texels, &pose)?;
            // As the image reuses the last one's pixels away from the change, so does
            // its visibility pass (the rays elsewhere read what they read then).
            let now = ImageInputs::of(Some(&cao.clip), shapes, &self.vol.texels, reach, true);
            let changed = match (previous, &now) {
                (Some(old), Some(new)) if reusable(&self.frame, &self.vol.extras) => old
                    .view
                    .as_ref()
                    .map(|v| (v, &old.image, old.inputs.changed(new))),
                _ => None,
            };
            let view = self.rc.mark_view(
                &self.gpu,
                &self.vol,
                &self.frame,
                Some(&cao.clip),
                volao::ao::view::Marking::BRICKS,
                changed
                    .as_ref()
                    .map(|(v, image, c)| (*v, *image, c.as_slice())),
            )?;
            cao.set_view(Some(&view));
            view_seconds = start.elapsed().as_secs_f64();
            let needed = (0..self.readable.len())
                .filter(|&i| self.readable[i] && view.contains(i))
                .count();
            let readable = self.readable.iter().filter(|r| **r).count();
            view_fraction = Some(needed as f64 / readable.max(1) as f64);
            kept = Some(view);
        }
        let view = kept;
        let stats = cao.update(&self.gpu, &self.vol.texels, pose)?;
        self.vol.set_ambient_occlusion_view(cao.ao_view());
        let inputs = ImageInputs::of(Some(&cao.clip), shapes, &self.vol.texels, reach, true);
        let start = Instant::now();
        let image = match (previous, &inputs) {
            (Some(old), Some(new)) if reusable(&self.frame, &self.vol.extras) => {
                let changed = old.inputs.changed(new);
                self.rc.render_reusing(
                    &self.gpu,
                    &self.vol,
                    &self.frame,
                    Some(&cao.clip),
                    &old.image,
                    &changed,
                )?
            }
            _ => self
                .rc
                .render(&self.gpu, &self.vol, &self.frame, Some(&cao.clip))?,
        };
        Ok(Timed {
            stats,
            view_seconds,
            view_fraction,
            list_bytes: cao.list_bytes(),
            render_seconds: start.elapsed().as_secs_f64(),
            shown: inputs.map(|inputs| Shown {
                image: image.clone(),
                inputs,
                view,
            }),
            pixels: image.pixels,
        })
    }

    fn half(&self) -> Vec3 {
        Vec3::from(self.vol.texels.extent()) * 0.5
    }

    fn dims(&self) -> [usize; 3] {
        self.vol.texels.dims
    }
}

/// The shape at frame `k` of `n`: it travels along a fixed arc through the volume, so
/// every frame clips a different region.
fn moving(shape: &ClipShape, half: Vec3, k: usize, n: usize) -> ClipShape {
    let t = k as f32 / n.max(1) as f32;
    let angle = std::f32::consts::TAU * t * 0.5;
    let path = Vec3::new(angle.cos(), angle.sin(), 0.0) * half.min_element() * 0.4;
    let mut s = shape.clone();
    s.translation = (Vec3::from(shape.translation) + path).to_array();
    s.rotation_deg[2] += 90.0 * t;
    s
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    sum / n.max(1) as f64
}

fn differing(a: &[[u8; 4]], b: &[[u8; 4]]) -> usize {
    a.iter().zip(b).filter(|(x, y)| x != y).count() + a.len().abs_diff(b.len())
}

/// One method's frames of one configuration.
struct Run {
    method: Method,
    frames: Vec<Timed>,
    differing_pixels: usize,
}

impl Run {
    fn mean_ms(&self) -> f64 {
        mean(self.frames.iter().map(Timed::total_ms))
    }

    fn percent(&self) -> f64 {
        mean(self.frames.iter().map(|t| match self.method {
            // The paper's count: category b over the whole volume.
            Method::CaoPaper => 100.0 * t.stats.category_b as f64 / t.stats.voxels as f64,
            _ => t.stats.percent_recomputed(),
        }))
    }

    /// Percent of the voxels steps IV and V visited.
    fn visited(&self) -> [f64; 2] {
        let pct = |f: &dyn Fn(&CaoStats) -> u64| {
            mean(
                self.frames
                    .iter()
                    .map(|t| 100.0 * f(&t.stats) as f64 / t.stats.voxels as f64),
            )
        };
        [pct(&|s| s.clip_voxels), pct(&|s| s.lao_voxels)]
    }

    fn stage_ms(&self, f: impl Fn(&Timed) -> f64) -> f64 {
        mean(self.frames.iter().map(|t| f(t) * 1e3))
    }

    /// Mean fraction of the readable voxels the view needed (view methods).
    fn view_fraction(&self) -> Option<f64> {
        let f: Vec<f64> = self.frames.iter().filter_map(|t| t.view_fraction).collect();
        (!f.is_empty()).then(|| mean(f.into_iter()))
    }
}

/// The three methods over `frames` poses of `shapes_at`, side by side: per pose,
/// `lao-every-frame` first (the reference image), then the others.
fn compare(
    b: &mut Bench,
    set: RaySet,
    samples: u32,
    methods: &[Method],
    frames: usize,
    shapes_at: &dyn Fn(usize) -> Vec<ClipShape>,
) -> Result<Vec<Run>> {
    let mut caos = Vec::new();
    // The sparse method's last image, which its next frame reuses where nothing changed.
    let mut last = Vec::new();
    for &m in methods {
        let mut cao = b.cao(set, samples, m.coverage())?;
        // A warm-up frame compiles pipelines and builds the clip maps, at a pose other
        // than the first frame's (every timed frame moves the shape).
        let t = b.frame(&mut cao, &shapes_at(frames), m, None)?;
        caos.push(cao);
        last.push(t.shown.filter(|_| m.reuses()));
    }
    let mut runs: Vec<Run> = methods
        .iter()
        .map(|&method| Run {
            method,
            frames: Vec::new(),
            differing_pixels: 0,
        })
        .collect();
    for k in 0..frames {
        let shapes = shapes_at(k);
        let mut reference: Option<Vec<[u8; 4]>> = None;
        for ((run, cao), last) in runs.iter_mut().zip(&mut caos).zip(&mut last) {
            let mut t = b.frame(cao, &shapes, run.method, last.as_ref())?;
            if run.method.reuses() {
                *last = t.shown.take();
            }
            match &reference {
                None => reference = Some(t.pixels.clone()),
                Some(r) => run.differing_pixels += differing(r, &t.pixels),
            }
            run.frames.push(t);
        }
    }
    Ok(runs)
}

/// `volao bench cao`.
pub fn cao_bench(args: &CaoBenchArgs) -> Result<()> {
    let adapter = volao::gpu::request_device()?.describe();
    let json = args.json;
    let emit = |value: serde_json::Value| {
        println!("{value}");
    };
    if !json {
        println!("adapter: {adapter}");
        println!(
            "Table 2 at up to {} voxels a side, Tables 3–4 at up to {}; {} frames per configuration, {}² images, {}² clip maps",
            args.table2_max_dim, args.max_dim, args.frames, args.size, args.clip_resolution
        );
    }
    // A scene's volume (RAS) uploaded to a fresh device at up to `max_dim` voxels a side.
    let bench = |s: &Scene, max_dim: usize| -> Result<Bench> {
        let volume = volume::load(
            &args.data.join(s.file),
            &LoadOptions {
                raw: s.raw.clone(),
                ..Default::default()
            },
        )?
        .volume
        .to_ras();
        Bench::new(
            volao::gpu::request_device()?,
            &volume,
            max_dim,
            args.size,
            args.clip_resolution,
        )
    };
    let chosen: Vec<Scene> = scenes()
        .into_iter()
        .filter(|s| args.scenes.iter().any(|k| k == s.key))
        .collect();
    if chosen.is_empty() {
        anyhow::bail!(
            "--scenes {:?}: none of engine, lobster, cranium",
            args.scenes
        );
    }

    // Table 2: percent of voxels recomputed (independent of the ray count).
    let table2: &[Scene] = if args.tables.contains(&2) {
        &chosen
    } else {
        &[]
    };
    if !json && !table2.is_empty() {
        println!("\n### Table 2: voxels recomputed per frame\n");
        println!(
            "| scene | dims | samples per ray | clip shape | % recomputed, paper's count (cao-paper) | % ray cast by sparse cao | % (paper) |"
        );
        println!("|---|---|---|---|---|---|---|");
    }
    for s in table2 {
        let mut b = bench(s, args.table2_max_dim)?;
        let (half, frames) = (b.half(), args.frames);
        let base = s.base_shape(half);
        let runs = compare(
            &mut b,
            RaySet::Six,
            s.samples,
            &[Method::CaoPaper, Method::Cao],
            frames,
            &|k| vec![moving(&base, half, k, frames)],
        )?;
        let (paper_count, sparse) = (runs[0].percent(), runs[1].percent());
        if json {
            emit(serde_json::json!({
                "table": 2, "scene": s.key, "dims": b.dims(), "samples": s.samples,
                "shape": s.shape, "frames": frames,
                "percent_recomputed": paper_count, "percent_ray_cast_sparse": sparse,
                "paper_percent": s.paper_percent, "differing_pixels": runs[1].differing_pixels,
                "adapter": adapter,
            }));
        } else {
            println!(
                "| {} | {:?} | {} | {} | {paper_count:.2} | {sparse:.2} | {} |",
                s.name,
                b.dims(),
                s.samples,
                s.shape,
                s.paper_percent
            );
        }
    }

    // Table 3: the three methods per ray count, with Fig. 10's stages.
    let mut memory = Vec::new();
    for s in &chosen {
        let mut list_bytes = 0;
        let mut b = bench(s, args.max_dim)?;
        let (half, frames) = (b.half(), args.frames);
        let base = s.base_shape(half);
        let rays: &[RaySet] = if args.tables.contains(&3) {
            &args.rays
        } else {
            &[]
        };
        if !json && !rays.is_empty() {
            println!(
                "\n### Table 3: mean frame time, {} {:?}, {} samples per ray\n",
                s.name,
                b.dims(),
                s.samples
            );
            println!(
                "| rays | method | mean frame (ms) | speedup over lao-every-frame | paper's CAO speedup | visibility / clip + mask / ray cast / render (ms) | % visited by clip + mask / ray cast | % ray cast | % of readable voxels the view needed | differing pixels |"
            );
            println!("|---|---|---|---|---|---|---|---|---|---|");
        }
        for &set in rays {
            let runs = compare(&mut b, set, s.samples, &Method::ALL, frames, &|k| {
                vec![moving(&base, half, k, frames)]
            })?;
            let reference = runs[0].mean_ms();
            for run in &runs {
                list_bytes = run
                    .frames
                    .iter()
                    .map(|t| t.list_bytes)
                    .fold(list_bytes, u64::max);
                let stages = serde_json::json!({
                    "visibility": run.stage_ms(|t| t.view_seconds),
                    "clip_mask": run.stage_ms(|t| t.stats.clip_seconds),
                    "ray_cast": run.stage_ms(|t| t.stats.lao_seconds),
                    "render": run.stage_ms(|t| t.render_seconds),
                });
                if json {
                    emit(serde_json::json!({
                        "table": 3, "scene": s.key, "dims": b.dims(),
                        "rays": set.directions().len(), "samples": s.samples,
                        "method": run.method.name(), "frames": frames,
                        "mean_frame_ms": run.mean_ms(), "stages_ms": stages,
                        "percent_recomputed": run.percent(),
                        "percent_visited": {"clip_mask": run.visited()[0], "ray_cast": run.visited()[1]},
                        "speedup_over_lao_every_frame": reference / run.mean_ms(),
                        "view_fraction": run.view_fraction(),
                        "differing_pixels": run.differing_pixels, "adapter": adapter,
                    }));
                } else {
                    let paper = match (run.method, paper_speedup(set), s.key) {
                        (Method::CaoPaper, Some(p), "engine") => format!("{p}"),
                        _ => String::new(),
                    };
                    let [clip, lao] = run.visited();
                    let needed = run
                        .view_fraction()
                        .map_or(String::new(), |f| format!("{:.1}", 100.0 * f));
                    println!(
                        "| {} | {} | {:.0} | {:.2} | {paper} | {:.0} / {:.0} / {:.0} / {:.0} | {clip:.1} / {lao:.1} | {:.2} | {needed} | {} |",
                        set.name(),
                        run.method.name(),
                        run.mean_ms(),
                        reference / run.mean_ms(),
                        run.stage_ms(|t| t.view_seconds),
                        run.stage_ms(|t| t.stats.clip_seconds),
                        run.stage_ms(|t| t.stats.lao_seconds),
                        run.stage_ms(|t| t.render_seconds),
                        run.percent(),
                        run.differing_pixels
                    );
                }
            }
        }
        let voxels = b.dims().iter().product::<usize>() as f64;
        memory.push((
            s.key,
            b.cao(RaySet::Six, 1, Coverage::Readable)?.bytes_per_voxel(),
            list_bytes as f64 / voxels,
        ));

        // Table 4: one vs two meshes (Engine, 26 rays).
        if s.key != "engine" || !args.tables.contains(&4) {
            continue;
        }
        let second = ClipShape {
            scale: [half.min_element() * 0.3; 3],
            ..ClipShape::new(Shape::Box, Vec3::new(-half.x * 0.5, half.y * 0.4, 0.0), 1.0)
        };
        if !json {
            println!("\n### Table 4: one vs two clip meshes (Engine, 26 rays)\n");
            println!(
                "| meshes | method | mean frame (ms) | % ray cast | slowdown | differing pixels |"
            );
            println!("|---|---|---|---|---|---|");
        }
        let methods = Method::PAPER;
        let one = compare(
            &mut b,
            RaySet::TwentySix,
            s.samples,
            &methods,
            frames,
            &|k| vec![moving(&base, half, k, frames)],
        )?;
        let two = compare(
            &mut b,
            RaySet::TwentySix,
            s.samples,
            &methods,
            frames,
            &|k| vec![moving(&base, half, k, frames), second.clone()],
        )?;
        for (meshes, runs) in [(1, &one), (2, &two)] {
            for (run, single) in runs.iter().zip(&one) {
                let slowdown = run.mean_ms() / single.mean_ms() - 1.0;
                if json {
                    emit(serde_json::json!({
                        "table": 4, "scene": s.key, "dims": b.dims(), "rays": 26,
                        "meshes": meshes, "method": run.method.name(), "frames": frames,
                        "mean_frame_ms": run.mean_ms(), "percent_recomputed": run.percent(),
                        "slowdown": slowdown, "differing_pixels": run.differing_pixels,
                        "adapter": adapter,
                    }));
                } else {
                    println!(
                        "| {meshes} | {} | {:.0} | {:.2} | {} | {} |",
                        run.method.name(),
                        run.mean_ms(),
                        run.percent(),
                        if meshes == 2 {
                            format!("{:+.0} % (paper: 8–16 %)", slowdown * 100.0)
                        } else {
                            String::new()
                        },
                        run.differing_pixels
                    );
                }
            }
        }
    }

    if !json {
        let maps =
            volao::clip::gpu::LAYERS_PER_SHAPE as u64 * 4 * (args.clip_resolution as u64).pow(2);
        for (scene, bytes, list) in memory {
            println!(
                "\nGPU memory ({scene}): {bytes} B per voxel for CAO (V_o, V_m, V_PAO, V_AO) plus the density V \
                 (the paper keeps 5 full-size volumes), and sparse CAO's voxel list, {list:.2} B per voxel here \
                 (4 B per voxel of the frame's step-V bricks, at most {}); clip maps {:.0} MiB per shape ({} maps of {}² f32).",
                volao::ao::cao::MAX_LIST_BYTES_PER_VOXEL,
                maps as f64 / (1 << 20) as f64,
                volao::clip::gpu::LAYERS_PER_SHAPE,
                args.clip_resolution
            );
        }
        println!(
            "Times are wall-clock per stage with a wait after each, on {adapter}; differing pixels \
             compare every frame's image with lao-every-frame's. The sparse cao's render casts \
             only the rays near the shape's last and new pose and keeps its last image's other \
             pixels; the others cast every pixel."
        );
    }
    Ok(())
}
