//! `volao bench cao`: the CAO paper's evaluation (Titov et al. §4, Tables 2–4, Fig. 10)
//! with a clip shape moving along a fixed path every frame.

use anyhow::Result;
use glam::Vec3;
use std::path::PathBuf;
use std::time::Instant;
use volao::ao::cao::{CaoGpu, CaoMode, CaoStats};
use volao::ao::lao::Rays;
use volao::ao::rays::RaySet;
use volao::clip::{ClipShape, Shape};
use volao::render::gpu::{GpuVolume, RayCaster};
use volao::render::texels::{UploadLimits, VolumeTexels};
use volao::render::{Frame, RenderSettings, Shading};
use volao::tf::{Preset, TransferFunction};
use volao::volume::{self, LoadOptions, RawOverrides, VoxelType};

#[derive(clap::Args, Debug)]
pub struct CaoBenchArgs {
    /// The shared data folder.
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Largest volume side: volumes are halved until they fit (the paper's full sizes
    /// take minutes per frame on a CPU driver; use 512 on a real GPU).
    #[arg(long, default_value_t = 128)]
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
}

/// The paper's Table 3 speedups for the Engine (6, 14, 26, 54 rays).
const PAPER_SPEEDUP: [f64; 4] = [1.66, 2.29, 2.95, 3.79];

struct Bench {
    gpu: volao::gpu::Gpu,
    rc: RayCaster,
    vol: GpuVolume,
    tf: TransferFunction,
    frame: Frame,
    resolution: u32,
}

/// A frame's figures: CAO stats and the render time.
struct Timed {
    stats: CaoStats,
    render_seconds: f64,
}

impl Timed {
    fn total_ms(&self) -> f64 {
        (self.stats.clip_seconds + self.stats.lao_seconds + self.render_seconds) * 1e3
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
        let vol = GpuVolume::from_texels(&gpu, texels, &tf, settings.step_voxels)?;
        let rc = RayCaster::new(&gpu.device)?;
        Ok(Bench {
            gpu,
            rc,
            vol,
            tf,
            frame: super::frame(20.0, settings, size),
            resolution,
        })
    }

    fn cao(&self, set: RaySet, samples: u32) -> Result<CaoGpu> {
        Ok(CaoGpu::new(
            &self.gpu,
            &self.vol,
            &self.tf,
            &Rays::uniform(set.directions()),
            samples,
            volao::ao::cao::DEFAULT_MSAA,
            &|_, _| {},
        )?)
    }

    /// One frame: AO update and render.
    fn frame(&mut self, cao: &mut CaoGpu, shapes: &[ClipShape], mode: CaoMode) -> Result<Timed> {
        let reach = cao.reach_mm(&self.vol.texels);
        let stats = cao.update(
            &self.gpu,
            &self.vol.texels,
            shapes,
            self.resolution,
            reach,
            mode,
        )?;
        self.vol.set_ambient_occlusion_view(cao.ao_view());
        let start = Instant::now();
        self.rc
            .render(&self.gpu, &self.vol, &self.frame, Some(&cao.clip))?;
        Ok(Timed {
            stats,
            render_seconds: start.elapsed().as_secs_f64(),
        })
    }

    fn half(&self) -> Vec3 {
        Vec3::from(self.vol.texels.extent()) * 0.5
    }
}

/// The shape of scene `i` at frame `k` of `n`: it travels along a fixed arc through
/// the volume, so every frame clips a different region.
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

/// `volao bench cao`.
pub fn cao_bench(args: &CaoBenchArgs) -> Result<()> {
    let adapter = volao::gpu::request_device()?.describe();
    println!("adapter: {adapter}");
    let load = |rel: &str, raw: RawOverrides| -> Result<volume::Volume> {
        Ok(volume::load(
            &args.data.join(rel),
            &LoadOptions {
                raw,
                ..Default::default()
            },
        )?
        .volume
        .to_ras())
    };
    let cranium_raw = RawOverrides {
        dims: Some([256, 256, 108]),
        ty: Some(VoxelType::I16),
        endian: Some(volume::Endian::Little),
        spacing: Some([0.957031, 0.957031, 1.5]),
        offset: None,
    };
    let scenes = [
        (
            "Engine",
            "raw/engine.raw",
            RawOverrides::default(),
            Shape::Sphere,
            20u32,
            14.94,
        ),
        (
            "Lobster (paper: Beetle)",
            "pvm/Lobster.pvm",
            RawOverrides::default(),
            Shape::Box,
            40,
            20.24,
        ),
        (
            "Cranium CT (paper: Skeleton)",
            "raw/cranium-ct.raw",
            cranium_raw,
            Shape::Box,
            50,
            16.13,
        ),
    ];
    println!(
        "Table 2 at up to {} voxels a side, Tables 3–4 halved to at most {}; {} frames per configuration, {}² images, {}² clip maps",
        args.table2_max_dim, args.max_dim, args.frames, args.size, args.clip_resolution
    );

    // Table 2: percent of voxels recomputed (independent of the ray count).
    println!("\n### Table 2: voxels recomputed per frame\n");
    println!(
        "| scene | dims | samples per ray | clip shape | % recomputed (volao, mean of frames) | % (paper) |"
    );
    println!("|---|---|---|---|---|---|");
    let mut engine_bench = None;
    for (name, rel, raw, shape, samples, paper) in scenes {
        let volume = load(rel, raw)?;
        let mut b = Bench::new(
            volao::gpu::request_device()?,
            &volume,
            args.table2_max_dim,
            args.size,
            args.clip_resolution,
        )?;
        let half = b.half();
        let r = half.min_element();
        let base = match shape {
            Shape::Sphere => ClipShape::new(Shape::Sphere, Vec3::ZERO, r * 0.45),
            _ if name.starts_with("Lobster") => ClipShape::new(Shape::Box, Vec3::ZERO, r * 0.4),
            _ => ClipShape {
                scale: [r * 0.35, r * 0.6, r * 0.3],
                ..ClipShape::new(Shape::Box, Vec3::ZERO, 1.0)
            },
        };
        let mut cao = b.cao(RaySet::Six, samples)?;
        let mut pct = Vec::new();
        for k in 0..args.frames {
            let t = b.frame(
                &mut cao,
                &[moving(&base, half, k, args.frames)],
                CaoMode::Selective,
            )?;
            pct.push(t.stats.percent_recomputed());
        }
        println!(
            "| {name} | {:?} | {samples} | {} | {:.2} | {paper} |",
            b.vol.texels.dims,
            if shape == Shape::Sphere {
                "sphere"
            } else if name.starts_with("Lobster") {
                "cube"
            } else {
                "rectangular prism"
            },
            mean(pct.into_iter())
        );
        if name == "Engine" {
            let b = Bench::new(
                volao::gpu::request_device()?,
                &volume,
                args.max_dim,
                args.size,
                args.clip_resolution,
            )?;
            let r = b.half().min_element();
            engine_bench = Some((b, ClipShape::new(Shape::Sphere, Vec3::ZERO, r * 0.45)));
        }
    }
    let Some((mut b, base)) = engine_bench else {
        anyhow::bail!("the engine scene did not run");
    };
    let half = b.half();

    // Table 3: LAO every frame vs CAO, and Fig. 10's stages.
    println!(
        "\n### Table 3: mean frame time, LAO every frame vs CAO (Engine, 20 samples per ray)\n"
    );
    println!(
        "| rays | LAO every frame (ms) | CAO (ms) | speedup (volao) | speedup (paper) | CAO stages: clip + mask / ray cast / render (ms) | LAO: ray cast (ms) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut memory = 0;
    for (i, set) in [
        RaySet::Six,
        RaySet::Fourteen,
        RaySet::TwentySix,
        RaySet::FiftyFour,
    ]
    .into_iter()
    .enumerate()
    {
        let mut cao = b.cao(set, 20)?;
        memory = cao.bytes_per_voxel();
        let mut full = Vec::new();
        let mut sel = Vec::new();
        // One warm-up frame each compiles pipelines and builds the clip maps.
        b.frame(
            &mut cao,
            &[moving(&base, half, 0, args.frames)],
            CaoMode::Full,
        )?;
        for k in 0..args.frames {
            let shapes = [moving(&base, half, k, args.frames)];
            full.push(b.frame(&mut cao, &shapes, CaoMode::Full)?);
            sel.push(b.frame(&mut cao, &shapes, CaoMode::Selective)?);
        }
        let f = mean(full.iter().map(Timed::total_ms));
        let c = mean(sel.iter().map(Timed::total_ms));
        println!(
            "| {} | {f:.0} | {c:.0} | {:.2} | {} | {:.0} / {:.0} / {:.0} | {:.0} |",
            set.name(),
            f / c,
            PAPER_SPEEDUP[i],
            mean(sel.iter().map(|t| t.stats.clip_seconds * 1e3)),
            mean(sel.iter().map(|t| t.stats.lao_seconds * 1e3)),
            mean(sel.iter().map(|t| t.render_seconds * 1e3)),
            mean(full.iter().map(|t| t.stats.lao_seconds * 1e3)),
        );
    }

    // Table 4: one vs two meshes.
    println!("\n### Table 4: one vs two clip meshes (Engine, CAO, 26 rays)\n");
    println!("| meshes | mean frame (ms) | % recomputed | slowdown |");
    println!("|---|---|---|---|");
    let mut cao = b.cao(RaySet::TwentySix, 20)?;
    let second = ClipShape {
        scale: [half.min_element() * 0.3; 3],
        ..ClipShape::new(Shape::Box, Vec3::new(-half.x * 0.5, half.y * 0.4, 0.0), 1.0)
    };
    b.frame(
        &mut cao,
        &[base.clone(), second.clone()],
        CaoMode::Selective,
    )?;
    let mut one = Vec::new();
    let mut two = Vec::new();
    for k in 0..args.frames {
        let first = moving(&base, half, k, args.frames);
        one.push(b.frame(&mut cao, std::slice::from_ref(&first), CaoMode::Selective)?);
        two.push(b.frame(&mut cao, &[first, second.clone()], CaoMode::Selective)?);
    }
    let t1 = mean(one.iter().map(Timed::total_ms));
    let t2 = mean(two.iter().map(Timed::total_ms));
    println!(
        "| 1 | {t1:.0} | {:.2} | |",
        mean(one.iter().map(|t| t.stats.percent_recomputed()))
    );
    println!(
        "| 2 | {t2:.0} | {:.2} | {:+.0} % (paper: 8–16 %) |",
        mean(two.iter().map(|t| t.stats.percent_recomputed())),
        (t2 / t1 - 1.0) * 100.0
    );

    let texel = b.vol.texels.format.bytes();
    let maps = volao::clip::gpu::LAYERS_PER_SHAPE as u64 * 4 * (args.clip_resolution as u64).pow(2);
    println!(
        "\nGPU memory: {} B per voxel for CAO (V_o, V_m, V_PAO, V_AO as f32) + {texel} B for the density V \
         (the paper keeps 5 full-size volumes); clip maps {:.0} MiB per shape ({} layers of {}² f32).",
        memory,
        maps as f64 / (1 << 20) as f64,
        volao::clip::gpu::LAYERS_PER_SHAPE,
        args.clip_resolution
    );
    println!("Times are wall-clock per stage with a wait after each, on {adapter}.");
    Ok(())
}
