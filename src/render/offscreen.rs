//! Offscreen rendering for the CLI, tests and benchmarks: one frame with its ambient
//! occlusion, opacity modulation, shadows, clip shapes and surfaces, on the device the
//! caller gives (`None`: the CPU twin).

use super::cpu;
use super::gpu::{RayCaster, RenderVolume};
use super::shadow::{LightGpu, LightVolume, Lit, light_cpu_reading, light_direction, light_lut};
use super::{Frame, Image, RenderSettings};
use crate::ao::cao::CaoStats;
use crate::ao::vao::PositionalAo;
use crate::ao::view::{Marking, ViewMask};
use crate::ao::{Ambient, AoEngine, AoInput, AoMethod, AoRequest, AoSettings};
use crate::clip::ClipShape;
use crate::clip::gpu::{ClipMaps, MapRequest};
use crate::gpu::{Gpu, GpuError};
use crate::texels::segments::SegmentTexels;
use crate::texels::{UploadLimits, VolumeTexels};
use crate::tf::TransferFunction;
use crate::volume::Volume;
use std::sync::Arc;

/// What rendered an image and how.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub image: Image,
    /// The adapter, or "CPU twin".
    pub device: String,
    /// How many times the volume was halved to fit the adapter.
    pub downsampled: u32,
    /// Seconds spent computing ambient occlusion (0 without).
    pub ao_seconds: f64,
    /// Seconds spent on the light volume of shadows, filter and upload included (0
    /// without shadows).
    pub light_seconds: f64,
    /// CAO / LAO-every-frame figures for the frame.
    pub cao: Option<CaoStats>,
    /// Clip shapes left out, with why (the others clipped).
    pub clip_errors: Vec<String>,
    /// How the AO was computed, where that needs saying (see [`crate::ao::AoComputed`]).
    pub notes: Vec<String>,
    /// With view culling ([`crate::ao::view`]): how many voxels the image needed.
    pub view: Option<ViewFigures>,
}

/// What a visibility pass found ([`crate::ao::view`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewFigures {
    /// Voxels whose AO the image reads.
    pub marked: usize,
    /// Voxels the transfer function can make visible (what is computed without view
    /// culling).
    pub readable: usize,
    /// Readable voxels the image reads: what was computed.
    pub needed: usize,
}

impl ViewFigures {
    /// The fraction of the readable voxels this view needed.
    pub fn fraction(&self) -> f64 {
        self.needed as f64 / self.readable.max(1) as f64
    }
}

/// One frame to render: the volume (already in RAS order) and everything drawn with it.
#[derive(Debug, Clone, Copy)]
pub struct RenderJob<'a> {
    pub volume: &'a Volume,
    pub tf: &'a TransferFunction,
    pub frame: &'a Frame,
    pub ao: &'a AoSettings,
    /// Clip shapes (mm from the volume's centre).
    pub clip: &'a [ClipShape],
    /// Triangle meshes drawn inside the volume (see `render::surface`).
    pub surfaces: &'a [super::surface::Surface],
    /// A segmentation on the volume's grid, with its looks and the shapes' cuts.
    pub segments: Option<&'a SegmentTexels>,
}

impl<'a> RenderJob<'a> {
    /// A frame of `volume` with no clip shapes and no surfaces.
    pub fn new(
        volume: &'a Volume,
        tf: &'a TransferFunction,
        frame: &'a Frame,
        ao: &'a AoSettings,
    ) -> Self {
        RenderJob {
            volume,
            tf,
            frame,
            ao,
            clip: &[],
            surfaces: &[],
            segments: None,
        }
    }
}

/// Renders `job` on `gpu`, or on the CPU twin for `None`. Clipping, CAO and its baseline
/// need the GPU: the clip shapes' depth maps are rasterised. `progress(done, total)`
/// reports AO precomputation in z-slices.
pub fn render(
    gpu: Option<&Arc<Gpu>>,
    job: &RenderJob<'_>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let mut surfaces = job.surfaces.to_vec();
    if let Some(rgba) = job.frame.settings.clip_surface {
        let v = job.volume;
        let radius = glam::Vec3::new(
            v.dims[0] as f32 * v.spacing[0],
            v.dims[1] as f32 * v.spacing[1],
            v.dims[2] as f32 * v.spacing[2],
        )
        .length()
            * 0.5;
        // Shapes that cannot be built are reported by the clipping below.
        surfaces.extend(job.clip.iter().filter_map(|c| {
            let m = c.posed_geometry(radius).ok()?;
            Some(super::surface::Surface {
                triangles: m
                    .triangles
                    .iter()
                    .map(|t| t.map(|i| m.vertices[i as usize]))
                    .collect(),
                rgba,
            })
        }));
    }
    // Intensity projections show values, not light: nothing that only lights or
    // occludes is computed for them.
    let settings = job.frame.settings;
    let mut notes = Vec::new();
    let unlit_frame;
    let no_ao;
    // The shading normalises the AO by what the method gives an open flat surface.
    let referenced = Frame {
        settings: RenderSettings {
            ao_reference: job.ao.reference(),
            ..settings
        },
        ..*job.frame
    };
    let mut job = RenderJob {
        frame: &referenced,
        ..*job
    };
    if !settings.mode.uses_ao()
        && (job.ao.method != AoMethod::None
            || settings.shadows
            || settings.opacity_modulation.is_some())
    {
        notes.push(format!(
            "render mode {}: ambient occlusion, shadows and opacity modulation do not apply; not computed",
            settings.mode
        ));
        unlit_frame = Frame {
            settings: RenderSettings {
                shadows: false,
                opacity_modulation: None,
                ..referenced.settings
            },
            ..*job.frame
        };
        no_ao = AoSettings {
            method: AoMethod::None,
            ..*job.ao
        };
        job.frame = &unlit_frame;
        job.ao = &no_ao;
    }
    let needs_gpu = !job.clip.is_empty() || job.ao.method.is_clipped();
    let mut rendered = match gpu {
        Some(g) => render_gpu(g, &job, &surfaces, progress),
        None if needs_gpu => Err(GpuError::Unsupported {
            what: "clipping, CAO and lao-full need a GPU adapter: the clip shapes' depth maps are rasterised (drop --cpu)".into(),
        }),
        None => render_cpu(&job, &surfaces, progress),
    }?;
    notes.append(&mut rendered.notes);
    rendered.notes = notes;
    Ok(rendered)
}

/// Puts computed AO where the ray caster reads it: a volume, live positional AO, or
/// CAO's `V_AO` (whose state is returned: it also holds the clip maps the frame clips
/// with).
pub fn show_ambient(
    g: &Gpu,
    vol: &mut RenderVolume,
    tf: &TransferFunction,
    ao: &AoSettings,
    ambient: Ambient,
) -> Result<Option<Box<crate::ao::cao::CaoGpu>>, GpuError> {
    match ambient {
        Ambient::One => {}
        Ambient::Live => vol.set_live_vao(g, tf, Some(&ao.vao))?,
        Ambient::Values(a) => vol.set_ambient_occlusion(g, &a),
        Ambient::Cao(c) => {
            vol.set_ambient_occlusion_view(c.ao_view());
            return Ok(Some(c));
        }
    }
    Ok(None)
}

fn render_gpu(
    g: &Arc<Gpu>,
    job: &RenderJob<'_>,
    surfaces: &[super::surface::Surface],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let RenderJob {
        volume,
        tf,
        frame,
        ao,
        clip,
        ..
    } = *job;
    let rc = g.stage::<RayCaster>()?;
    let mut vol = RenderVolume::new(g, volume, tf, frame.settings.step_voxels)?;
    vol.set_segments(g, job.segments.cloned());
    vol.extras.surfaces = surfaces.to_vec();
    // Opacity modulation changes which samples show: set before the visibility pass.
    if let Some(m) = &frame.settings.opacity_modulation {
        let f = crate::ao::fast::modulation(g, &vol, tf, m)?;
        vol.set_opacity_modulation(g, &f);
    }
    let start = std::time::Instant::now();
    let mut clip_errors = Vec::new();
    // Without CAO, maps that only clip the picture; with it, CAO's own (posed below).
    let mut maps = None;
    if !ao.method.is_clipped() && !clip.is_empty() {
        let mut m = ClipMaps::new(g)?;
        let radius = glam::Vec3::from(vol.texels.extent()).length() * 0.5;
        let update = m.update(g, MapRequest::clipping(clip, radius, ao.clip_resolution))?;
        clip_errors = update.errors.iter().map(|e| e.to_string()).collect();
        maps = Some(m);
    }
    let view = match culls_view(frame, ao) {
        true => Some(Arc::new(view_gpu(
            g,
            &rc,
            &vol,
            frame,
            ao,
            clip,
            maps.as_ref(),
        )?)),
        false => None,
    };
    let engine = AoEngine::on(Some(Arc::clone(g)));
    let request = AoRequest {
        tf,
        settings: ao,
        clip: Some(clip),
        coverage: crate::ao::sparse::Coverage::for_render(&frame.settings),
        view: view.as_ref(),
    };
    let computed = engine.compute(AoInput::Uploaded(&vol), &request, progress)?;
    let cao_state = show_ambient(g, &mut vol, tf, ao, computed.ambient)?;
    if let Some(stats) = &computed.cao {
        clip_errors = stats.clip_errors.clone();
    }
    let clip_maps = cao_state.as_ref().map(|c| &c.clip).or(maps.as_ref());
    let ao_seconds = start.elapsed().as_secs_f64();
    let light_start = std::time::Instant::now();
    if frame.settings.shadows {
        let dir = light_dir(frame)?;
        let t = g.stage::<LightGpu>()?.compute(
            g,
            Lit {
                texels: &vol.texels,
                segments: vol.segment_texels.as_ref(),
                lut: &light_lut(tf, &vol.texels),
            },
            dir,
            clip_maps,
            progress,
        )?;
        vol.set_light_volume(g, Some((&t, dir)))?;
    }
    let light_seconds = light_start.elapsed().as_secs_f64();
    let image = rc.render(g, &vol, frame, clip_maps)?;
    Ok(Rendered {
        image,
        device: g.describe(),
        downsampled: vol.texels.downsampled,
        ao_seconds,
        light_seconds,
        cao: computed.cao,
        clip_errors,
        notes: computed.notes,
        view: view.map(|v| view_figures(&v, &vol.texels, tf, frame)),
    })
}

/// Whether `frame` computes its AO only where it reads it ([`crate::ao::view`]): LAO,
/// CAO and lao-full in a mode that reads AO, unless `--no-view-culling`.
pub fn culls_view(frame: &Frame, ao: &AoSettings) -> bool {
    frame.settings.view_culling
        && frame.settings.mode.uses_ao()
        && matches!(ao.method, AoMethod::Lao | AoMethod::Cao | AoMethod::LaoFull)
}

/// The visibility pass on the GPU: the voxels `frame` of `vol` reads the AO of, clipped
/// by `maps`, or for CAO and lao-full by maps posed as CAO poses its own for `clip`
/// (the same request, so the same maps the image then clips with).
fn view_gpu(
    g: &Gpu,
    rc: &RayCaster,
    vol: &RenderVolume,
    frame: &Frame,
    ao: &AoSettings,
    clip: &[ClipShape],
    maps: Option<&ClipMaps>,
) -> Result<ViewMask, GpuError> {
    let posed;
    let maps = match (ao.method.is_clipped(), maps) {
        (true, _) => {
            let mut m = ClipMaps::new(g)?;
            let request = MapRequest {
                shapes: clip,
                volume_radius: glam::Vec3::from(vol.texels.extent()).length() * 0.5,
                reach_mm: crate::ao::cao::reach_mm(ao.samples, vol.texels.spacing),
                resolution: ao.clip_resolution,
            };
            m.update(g, request)?;
            posed = m;
            Some(&posed)
        }
        (false, maps) => maps,
    };
    // CAO's frame needs bricks only (its V_PAO's dispatch is by brick); LAO lists voxels.
    let marking = match ao.method.is_clipped() {
        true => Marking::BRICKS,
        false => Marking::VOXELS,
    };
    rc.mark_view(g, vol, frame, maps, marking, None)
}

/// What a visibility pass found: the voxels marked against those the transfer function
/// can make visible.
fn view_figures(
    view: &ViewMask,
    texels: &VolumeTexels,
    tf: &TransferFunction,
    frame: &Frame,
) -> ViewFigures {
    let ranges = crate::texels::BlockRanges::new(texels);
    let readable = crate::ao::sparse::Coverage::for_render(&frame.settings)
        .bricks(texels, &ranges, tf)
        .readable_mask(texels);
    let readable_count = readable.iter().filter(|r| **r).count();
    let needed = readable
        .iter()
        .enumerate()
        .filter(|(i, r)| **r && view.contains(*i))
        .count();
    ViewFigures {
        marked: view.count(),
        readable: readable_count,
        needed,
    }
}

fn render_cpu(
    job: &RenderJob<'_>,
    surfaces: &[super::surface::Surface],
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered, GpuError> {
    let (volume, tf, frame, ao) = (job.volume, job.tf, job.frame, job.ao);
    let texels = VolumeTexels::new(volume, UploadLimits::NONE);
    let lut = crate::sample::bake_lut(tf, &texels, frame.settings.step_voxels);
    let (mut cv, occ) = cpu::prepare(&texels, &lut);
    if let Some(s) = job.segments {
        cv.segments = Some(crate::sample::SegmentSampler::new(s));
    }
    if !surfaces.is_empty() {
        cv.surfaces = Some(cpu::CpuSurfaces {
            surfaces: surfaces.to_vec(),
            frame: *frame,
            texels: texels.clone(),
        });
    }
    if let Some(m) = &frame.settings.opacity_modulation {
        cv.modulation = Some(quantise16(&crate::ao::fast::modulation_cpu(&texels, tf, m)));
    }
    let start = std::time::Instant::now();
    let view = culls_view(frame, ao).then(|| {
        Arc::new(cpu::mark_view(
            &texels,
            &mut cv,
            &lut,
            &occ,
            frame,
            Marking::VOXELS,
        ))
    });
    let request = AoRequest {
        tf,
        settings: ao,
        clip: None,
        coverage: crate::ao::sparse::Coverage::for_render(&frame.settings),
        view: view.as_ref(),
    };
    // The GPU keeps AO volumes as f32 (R32Float), so the twin uses them as computed.
    let input = match job.segments {
        Some(s) => AoInput::Segmented(&texels, s),
        None => AoInput::Texels(&texels),
    };
    let computed = AoEngine::on(None).compute(input, &request, progress)?;
    match computed.ambient {
        Ambient::Values(a) => cv.ao = Some(a),
        Ambient::Live => {
            let twin = PositionalAo::new(&texels, tf, &ao.vao).with_segments(job.segments);
            cv.live_vao = Some(twin);
        }
        Ambient::One | Ambient::Cao(_) => {}
    }
    let ao_seconds = start.elapsed().as_secs_f64();
    let light_start = std::time::Instant::now();
    if frame.settings.shadows {
        let dir = light_dir(frame)?;
        let lut = light_lut(tf, &texels);
        let segments = cv.segments.as_ref();
        let t = light_cpu_reading(&texels, &lut, segments, dir, None, progress);
        cv.light = Some(LightVolume::new(&t, texels.dims, dir));
    }
    let light_seconds = light_start.elapsed().as_secs_f64();
    let threads = rayon::current_num_threads();
    let image = cpu::render(&texels, &cv, &lut, &occ, frame);
    Ok(Rendered {
        image,
        device: format!("CPU twin ({threads} threads)"),
        downsampled: 0,
        ao_seconds,
        light_seconds,
        cao: None,
        clip_errors: Vec::new(),
        notes: computed.notes,
        view: view.map(|v| view_figures(&v, &texels, tf, frame)),
    })
}

/// The frame's light direction, checked (shadows need a real direction).
fn light_dir(frame: &Frame) -> Result<glam::Vec3, GpuError> {
    light_direction(frame.settings.light_direction).map_err(|message| GpuError::Validation {
        stage: "shadows".into(),
        message,
    })
}

/// As the GPU path stores modulation volumes (R16Unorm).
fn quantise16(values: &[f32]) -> Vec<f32> {
    values
        .iter()
        .map(|&x| (x.clamp(0.0, 1.0) * 65535.0).round() / 65535.0)
        .collect()
}
