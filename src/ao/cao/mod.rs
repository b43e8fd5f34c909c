//! Contextual Ambient Occlusion (Titov et al.): LAO that stays exact under clipping by
//! recomputing only the voxels whose neighbourhood a clip shape touches.
//!
//! Once per transfer function (§3.4 step I): `V_PAO`, LAO of every voxel on the
//! unclipped opacity volume. Every frame (§3.5):
//!
//! - step IV (`shaders/cao_clip.wgsl`, Algorithm 2): anti-aliased shadow-test clipping
//!   into the clipped opacity volume `V_o`, and the mask (0 clipped, ½ recompute, 1 copy)
//!   written into `V_AO` itself: a copy of `V_PAO`, or a mark for step V;
//! - step V (`shaders/cao_lao.wgsl`): `V_AO` = 1 where clipped, a full LAO ray cast on
//!   `V_o` where marked for it;
//! - step VI: the ray caster clips with the same test and reads `V_AO`.
//!
//! [`CaoMode::Full`] is the paper's baseline ("LAO every frame"): the same clipping, and
//! a ray cast for every unclipped voxel. `V_PAO` is made by that very pipeline with no
//! clip shapes, so a copied voxel holds the bits a recomputation would produce: CAO and
//! the baseline agree bit for bit (tests/cao.rs).
//!
//! LAO here interpolates the classified opacity `V_o` (the paper's `TF_o`), where
//! `--ao lao` classifies interpolated densities; both use 1 mm steps and Eq. 2–3.
//!
//! Both steps run over brick lists ([`super::sparse`]): step IV over the bricks near a
//! shape now or in the previous frame (their `V_o` and `V_m` change), step V over those
//! of them the ray caster can read and a change of opacity can reach
//! ([`Bricks::reached`]; every readable brick in the baseline); a CAO frame then ray
//! casts only the voxels step IV marked, from a list (`listed`). Outside the
//! lists `V_o = α`, `V_m = 1` and `V_AO = V_PAO` hold from the previous frames;
//! unreadable voxels keep whatever they hold, which no pixel uses. [`Bricks::dense`] turns all of it off.

use super::lao::{Rays, STEP_MM, lao_lut};
use super::sparse::{Bricks, MAX_CUT_BALLS, RAY_TEST_MARGIN, VoxelTest};
use crate::clip::gpu::{ClipMaps, MapRequest};
use crate::gpu::dispatch::{BrickChunk, BrickDispatch, Pass, budget, chunk_fields};
use crate::gpu::{
    Gpu, GpuError, read_buffer, readback_buffer, storage_buffer, uniform_group, validated,
};
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::texels::gpu_data::VolumeMap;
use crate::texels::reader::{self, Reading, SegmentBindings, VOLUME_GROUP};
use crate::tf::TransferFunction;
use glam::Vec3;
use std::time::Instant;

pub use super::settings::DEFAULT_MSAA;
pub use cpu::{StepVInputs, clip_volume_cpu, clip_volume_cpu_reading, lao_on_opacity_cpu};
pub use frame::{CaoFrame, Pose};
pub use pao::PaoUpdate;
pub use pipelines::CaoPipelines;
pub use voxel_list::MAX_LIST_BYTES_PER_VOXEL;

mod cpu;
mod frame;
mod listed;
mod pao;
mod pipelines;
mod readback;
mod voxel_list;

/// Selective recomputation (CAO) or the baseline that ray casts every voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaoMode {
    Selective,
    Full,
}

/// The N extra sample offsets (voxels, within the voxel's cell): a Halton sequence in
/// bases 2, 3, 5, identical on the GPU and the CPU.
pub fn msaa_offsets(n: u32) -> Vec<Vec3> {
    let halton = |mut i: u32, base: u32| {
        let (mut f, mut r) = (1.0f64, 0.0f64);
        while i > 0 {
            f /= base as f64;
            r += f * (i % base) as f64;
            i /= base;
        }
        r as f32
    };
    (1..=n)
        .map(|i| Vec3::new(halton(i, 2), halton(i, 3), halton(i, 5)) - Vec3::splat(0.5))
        .collect()
}

/// How far (mm) a clipped point can change a voxel's ambient factor: the LAO ray
/// reaches (M − 1) mm (the last sample's opacity is never used), trilinear
/// interpolation reads voxels up to one voxel away, and a voxel's opacity depends on
/// clip samples anywhere in its cell (half a voxel): 1.5 voxel diagonals in all.
pub fn reach_mm(samples: u32, spacing: [f32; 3]) -> f32 {
    (samples.max(1) - 1) as f32 * STEP_MM + 1.5 * Vec3::from(spacing).length()
}

/// Uniforms of step IV. Mirrors `struct Params` in `cao_clip.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ClipParams {
    /// The volume's size and this submission's bricks.
    bricks: BrickChunk,
    spacing: [f32; 3],
    /// N, the extra anti-aliasing samples.
    msaa: f32,
    /// Half the volume's extent (mm).
    half: [f32; 3],
    _pad0: f32,
    /// 1: the baseline (every unclipped voxel marked for a ray cast), 0: CAO.
    full: u32,
    /// 1: `V_PAO` marks the voxels the ray caster cannot read (a frame with skipping,
    /// after the `V_PAO` run), 0: it does not (that run itself, or no skipping).
    unread_marked: u32,
    /// 1: clipped voxels get `V_AO` = 1 here, what step V over bricks would write (a
    /// frame whose step V runs over the voxel list, which holds only voxels to ray
    /// cast), 0: they are marked CLIPPED.
    clipped_one: u32,
    /// Step IV's per-ray test (`rays_meet_cut` in `cao_clip.wgsl`): 0 off (every
    /// affected voxel is ray cast: the baseline, `--no-skipping`, a probing shape),
    /// else 1 + the number of balls in [`Self::balls`]. Whether a voxel's centre alone
    /// decides if a dilation reaches it is the pipeline's (`CENTRE_REACH`).
    ray_test: u32,
    /// LAO rays K, samples M, the step (mm) and the longest ray's step (mm), for the
    /// per-ray test.
    rays: f32,
    samples: f32,
    step_mm: f32,
    longest_step_mm: f32,
    /// Centre (volume mm) and radius of each carving shape's ball ([`Bricks::cut_balls`]).
    balls: [[f32; 4]; MAX_CUT_BALLS],
}

const _: () = assert!(std::mem::size_of::<ClipParams>() == 224);

chunk_fields!(ClipParams);

/// Uniforms of step V. Mirrors `struct Params` in `cao_lao.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LaoParams {
    /// The volume's size and this submission's bricks.
    bricks: BrickChunk,
    mm_to_uvw: [f32; 3],
    _pad0: f32,
    rays: u32,
    samples: u32,
    /// Entries of the voxel list (its ray cast, `cao_listed.wgsl`).
    listed: u32,
    _pad1: u32,
    /// Bricks per axis and whether rays step over empty ones (0/1).
    grid: [u32; 4],
    /// The per-voxel readability test ([`VoxelTest::uniform`]).
    readable: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<LaoParams>() == 96);

chunk_fields!(LaoParams);

/// Which CAO volume to read back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaoVolume {
    /// `V_o`, the clipped opacity volume.
    ClippedOpacity,
    /// The mask (0 clipped, ½ recompute, 1 copy) of the last frame, over its step-IV
    /// bricks (1 elsewhere): not kept, so reading it runs steps IV and V again.
    Mask,
    /// `V_PAO`, LAO of the unclipped volume.
    Precomputed,
    /// `V_AO`, this frame's ambient factor.
    Ambient,
}

/// Per-frame figures.
#[derive(Debug, Clone, Default)]
pub struct CaoStats {
    pub voxels: u64,
    /// Voxels ray cast this frame (category b; every unclipped voxel in the baseline),
    /// among the readable ones when skipping.
    pub recomputed: u64,
    /// Voxels of category b among those step IV visited (with skipping off: the paper's
    /// count, the same for CAO and the baseline).
    pub category_b: u64,
    /// Voxels fully clipped (category a) among those step IV visited.
    pub clipped: u64,
    /// Voxels steps IV and V visited.
    pub clip_voxels: u64,
    pub lao_voxels: u64,
    /// Seconds: depth/dilation maps (only when a shape's geometry changed), clip + mask
    /// (step IV), ray casting (step V).
    pub maps_seconds: f64,
    pub clip_seconds: f64,
    pub lao_seconds: f64,
    /// Shapes left out, with why.
    pub clip_errors: Vec<String>,
    /// Step V ray cast over a list of the voxels to ray cast (`listed`) rather than
    /// over bricks.
    pub listed: bool,
}

impl CaoStats {
    pub fn percent_recomputed(&self) -> f64 {
        100.0 * self.recomputed as f64 / self.voxels.max(1) as f64
    }
}

fn volume_texture(
    device: &wgpu::Device,
    label: &str,
    dims: [u32; 3],
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
    crate::gpu::texture_3d(
        device,
        label,
        dims,
        format,
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
    )
}

/// The CAO volumes and pipelines for one uploaded volume.
#[derive(Debug)]
pub struct CaoGpu {
    pipelines: std::sync::Arc<CaoPipelines>,
    pub clip: ClipMaps,
    v_o: wgpu::Texture,
    v_pao: wgpu::Texture,
    v_ao: wgpu::Texture,
    views: [wgpu::TextureView; 3],
    counters: wgpu::Buffer,
    counters_readback: wgpu::Buffer,
    /// The LAO rays and the ray cells, for the listed ray cast's bind group.
    rays_buffer: wgpu::Buffer,
    occupied_buffer: wgpu::Buffer,
    /// A frame's voxels to ray cast ([`listed`]), made on the first frame that lists.
    list: Option<voxel_list::VoxelList>,
    /// This frame's brick lists: step IV's, then step V's (room for two of every brick).
    lists: wgpu::Buffer,
    /// Uniforms of steps IV and V, rewritten per submission, and the bind groups reading them.
    clip_uniforms: wgpu::Buffer,
    /// Step V's uniforms and bind group for `V_PAO` \[0\] and for frames \[1\].
    lao_uniforms: [wgpu::Buffer; 2],
    clip_group: wgpu::BindGroup,
    lao_group: [wgpu::BindGroup; 2],
    /// The volume reader's groups (`volume.wgsl`) of step IV and of step V (\[0\]
    /// `V_PAO`, \[1\] frames).
    clip_volume: wgpu::BindGroup,
    lao_volume: [wgpu::BindGroup; 2],
    clip_params: ClipParams,
    lao_params: LaoParams,
    /// Whether step IV reads the volume's segmentation (segment-aware carving).
    segments: bool,
    /// The segmentation's textures step IV reads (shared with the volume it was made
    /// from): [`Self::set_segments`] writes new looks and cuts into them.
    segment_textures: Option<crate::texels::segments::GpuSegments>,
    dims: [u32; 3],
    rays: usize,
    samples: u32,
    msaa: u32,
    bricks: Bricks,
    /// Bricks near a shape in the previous frame: their `V_o` and `V_AO` must be brought
    /// back this frame if no shape is near them now.
    was_near: Vec<bool>,
    /// Per brick, whether the image reads it ([`Self::set_view`]; `None`: every brick).
    view: Option<Vec<bool>>,
    /// Bricks whose step V a view left out while a change reached them: their `V_AO` is
    /// not this pose's until a frame that sees them runs it.
    stale: Vec<bool>,
    /// The last frame's lists and mode (to read its mask back).
    last: (Lists, CaoMode),
    /// Seconds spent on `V_PAO`.
    pub precompute_seconds: f64,
    /// `V_PAO` is made: with skipping it marks the voxels the ray caster cannot read
    /// (`UNREAD` in `cao_lao.wgsl`), and each frame's step IV resolves them.
    pao_ready: bool,
    /// This frame's balls for step IV's per-ray test (`None`: off).
    cut_balls: Option<Vec<[f32; 4]>>,
    /// The per-ray test's margin beyond where a shape can carve (mm): normally
    /// [`RAY_TEST_MARGIN`] voxel diagonals; tests narrow it to show exactness rests on it.
    pub ray_test_margin_mm: f32,
}

/// What CAO's `V_PAO` is precomputed for ([`CaoGpu::new`]).
#[derive(Debug, Clone, Copy)]
pub struct CaoSetup<'a> {
    pub tf: &'a TransferFunction,
    /// The LAO rays, K of them.
    pub rays: &'a Rays,
    /// Samples per ray, M.
    pub samples: u32,
    /// Extra anti-aliasing samples of step IV, N.
    pub msaa: u32,
}

/// What one frame's steps IV and V visit.
#[derive(Debug, Clone, Default)]
struct Lists {
    clip: Vec<u32>,
    lao: Vec<u32>,
}

impl CaoGpu {
    /// Allocates the four CAO volumes (V, V_o, V_PAO, V_AO; V is `vol`'s) and
    /// precomputes `V_PAO` for `setup` over `bricks` ([`Bricks::dense`]: every voxel).
    pub fn new(
        gpu: &Gpu,
        vol: &GpuVolume,
        setup: CaoSetup<'_>,
        bricks: Bricks,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Self, GpuError> {
        let CaoSetup {
            tf,
            rays,
            samples,
            msaa,
        } = setup;
        let device = &gpu.device;
        if !device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE)
        {
            return Err(GpuError::Validation {
                stage: "CaoGpu::new".into(),
                message: "the adapter cannot filter 32-bit float textures (FLOAT32_FILTERABLE), which CAO's opacity volume needs".into(),
            });
        }
        let texels = &vol.texels;
        let dims = texels.dims.map(|d| d as u32);
        assert_eq!(bricks.grid, super::sparse::grid_of(texels.dims));
        let pipelines = gpu.stage::<CaoPipelines>()?;
        let lut = lao_lut(tf, texels);
        let offsets: Vec<[f32; 4]> = msaa_offsets(msaa.max(1))
            .iter()
            .map(|o| [o.x, o.y, o.z, 0.0])
            .collect();
        let packed: Vec<[f32; 4]> = rays
            .directions
            .iter()
            .zip(&rays.weights)
            .map(|(d, w)| [d.x, d.y, d.z, *w])
            .collect();
        let occupied = bricks.rays.words();
        let segments = vol.segments.on;
        if segments {
            pipelines.prepare_segments(device)?;
        }
        let clip = ClipMaps::new(gpu)?;
        let extent = texels.extent();
        let clip_params = ClipParams {
            bricks: BrickChunk::of(dims),
            spacing: texels.spacing,
            msaa: msaa as f32,
            half: [extent[0] * 0.5, extent[1] * 0.5, extent[2] * 0.5],
            _pad0: 0.0,
            full: 0,
            unread_marked: 0,
            clipped_one: 0,
            ray_test: 0,
            rays: rays.directions.len() as f32,
            samples: samples.max(1) as f32,
            step_mm: STEP_MM,
            longest_step_mm: rays
                .directions
                .iter()
                .map(|d| d.length() * STEP_MM)
                .fold(0.0, f32::max),
            balls: [[0.0; 4]; MAX_CUT_BALLS],
        };
        let lao_params = LaoParams {
            bricks: BrickChunk::of(dims),
            mm_to_uvw: super::lao::mm_to_uvw(texels),
            _pad0: 0.0,
            rays: rays.directions.len() as u32,
            samples: samples.max(1),
            listed: 0,
            _pad1: 0,
            grid: bricks.rays.uniform(bricks.skipping),
            readable: VoxelTest::uniform(bricks.voxels.as_ref()),
        };
        let mut cao = validated(device, "CaoGpu::new", || {
            let storage = |label, bytes: &[u8]| {
                storage_buffer(gpu, label, bytes, wgpu::BufferUsages::empty())
            };
            let format = pipelines.format;
            let v_o = volume_texture(device, "Cao::v_o", dims, format);
            let v_pao = volume_texture(device, "Cao::v_pao", dims, format);
            let v_ao = volume_texture(device, "Cao::v_ao", dims, format);
            let views = [&v_o, &v_pao, &v_ao].map(|t| t.create_view(&Default::default()));
            let table = reader::table(gpu, "Cao::lut", &lut);
            let msaa_buffer = storage("Cao::msaa", bytemuck::cast_slice(&offsets));
            let ray_buffer = storage("Cao::rays", bytemuck::cast_slice(&packed));
            let occupied_buffer = storage("Cao::occupied", bytemuck::cast_slice(&occupied));
            let prefix = VoxelTest::prefix_of(bricks.voxels.as_ref());
            let prefix_buffer = storage("Cao::readable_prefix", bytemuck::cast_slice(&prefix));
            let lists = storage_buffer(
                gpu,
                "Cao::lists",
                &vec![0u8; 8 * bricks.count()],
                wgpu::BufferUsages::COPY_DST,
            );
            let counters = storage_buffer(
                gpu,
                "Cao::counters",
                &[0u8; 16],
                wgpu::BufferUsages::COPY_SRC,
            );
            let volume_view = vol.volume_view();
            let (clip_uniforms, clip_group) = uniform_group(
                gpu,
                "Cao::clip",
                pipelines.clip_for(&bricks, segments).any(),
                &clip_params,
                &[
                    msaa_buffer.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&views[0]),
                    wgpu::BindingResource::TextureView(&views[2]),
                    counters.as_entire_binding(),
                    lists.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&views[1]),
                    ray_buffer.as_entire_binding(),
                ],
            );
            let lao_group = |frame: bool| {
                uniform_group(
                    gpu,
                    "Cao::lao",
                    pipelines.lao_for(&bricks, frame),
                    &lao_params,
                    &[
                        wgpu::BindingResource::TextureView(&views[0]),
                        wgpu::BindingResource::Sampler(&pipelines.sampler),
                        ray_buffer.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&views[2]),
                        lists.as_entire_binding(),
                        occupied_buffer.as_entire_binding(),
                        counters.as_entire_binding(),
                        prefix_buffer.as_entire_binding(),
                    ],
                )
            };
            // Step V reads the density's voxels alone (the readable-voxel test).
            let voxels = Reading {
                texels: volume_view,
                sampler: None,
                lut: None,
                segments: SegmentBindings::None,
            };
            let lao_volume = [false, true]
                .map(|frame| voxels.group_of(gpu, "Cao::lao", pipelines.lao_for(&bricks, frame)));
            let map = VolumeMap::new(texels, &lut);
            let reading = Reading::sampled(
                volume_view,
                &pipelines.sampler,
                map,
                &table,
                SegmentBindings::All(&vol.segments),
            );
            let clip_volume =
                reading.bind_group((device, &gpu.queue), "Cao::clip", &pipelines.volume_layout);
            // Auto layouts are per pipeline: one bind group (and uniforms) for each.
            let lao_groups = [lao_group(false), lao_group(true)];
            CaoGpu {
                pipelines,
                segments,
                segment_textures: segments.then(|| vol.segments.clone()),
                clip,
                v_o,
                v_pao,
                v_ao,
                views,
                counters,
                counters_readback: readback_buffer(device, "Cao::counters_readback", 16),
                rays_buffer: ray_buffer,
                occupied_buffer,
                list: None,
                lists,
                clip_uniforms,
                lao_uniforms: [lao_groups[0].0.clone(), lao_groups[1].0.clone()],
                clip_group,
                lao_group: [lao_groups[0].1.clone(), lao_groups[1].1.clone()],
                clip_volume,
                lao_volume,
                clip_params,
                lao_params,
                dims,
                rays: rays.directions.len(),
                samples: samples.max(1),
                msaa,
                was_near: vec![false; bricks.count()],
                view: None,
                stale: vec![false; bricks.count()],
                last: (Lists::default(), CaoMode::Selective),
                bricks,
                precompute_seconds: 0.0,
                pao_ready: false,
                cut_balls: None,
                ray_test_margin_mm: RAY_TEST_MARGIN * Vec3::from(texels.spacing).length(),
            }
        })?;
        let start = Instant::now();
        // V_PAO: the baseline pipeline with nothing clipped, copied aside. Step IV writes
        // every brick whose V_o or V_m is read; unwritten texels stay 0 (V_o's α there).
        cao.clip.update(gpu, MapRequest::NOTHING)?;
        let b = &cao.bricks;
        let lists = Lists {
            clip: b.list(|i| b.used(i)),
            lao: b.list(|i| b.readable[i] != 0),
        };
        cao.write_lists(gpu, &lists);
        cao.step_iv(gpu, &lists, CaoMode::Full)?;
        cao.step_v(gpu, &lists, false, progress)?;
        cao.last = (lists, CaoMode::Full);
        validated(device, "Cao::v_pao", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_texture_to_texture(
                cao.v_ao.as_image_copy(),
                cao.v_pao.as_image_copy(),
                cao.v_ao.size(),
            );
            gpu.queue.submit([encoder.finish()]);
        })?;
        crate::gpu::wait(device, "Cao::v_pao", crate::gpu::WAIT)?;
        cao.pao_ready = true;
        cao.precompute_seconds = start.elapsed().as_secs_f64();
        Ok(cao)
    }

    /// How far a clipped point can reach (mm): the dilation radius before pixel margins.
    pub fn reach_mm(&self, texels: &VolumeTexels) -> f32 {
        reach_mm(self.samples, texels.spacing)
    }

    /// The bricks this CAO processes.
    pub fn bricks(&self) -> &Bricks {
        &self.bricks
    }

    /// From the next frame on, step V runs only in the bricks holding a voxel `view`
    /// marks (a visibility pass of the image to draw, [`crate::ao::view`]); `None`: in
    /// every brick. `V_AO` stays exact on every marked voxel; a brick left out while a
    /// change reached it is recomputed by the first frame that sees it.
    pub fn set_view(&mut self, view: Option<&crate::ao::view::ViewMask>) {
        self.view = view.map(|v| v.bricks(super::sparse::BRICK));
    }

    fn run_timed(&self, gpu: &Gpu, lists: &Lists, mode: CaoMode) -> Result<CaoStats, GpuError> {
        let device = &gpu.device;
        let t1 = Instant::now();
        self.step_iv(gpu, lists, mode)?;
        crate::gpu::wait(device, "Cao::clip", crate::gpu::WAIT)?;
        let t2 = Instant::now();
        let listed = if self.lists_voxels(mode) {
            self.step_v_listed(gpu, lists)?.is_some()
        } else {
            self.step_v(gpu, lists, true, &|_, _| {})?;
            false
        };
        let c = self.read_counters(gpu)?;
        let t3 = Instant::now();
        let seconds = [(t2 - t1).as_secs_f64(), (t3 - t2).as_secs_f64()];
        Ok(self.stats_of(lists, c, listed, seconds))
    }

    /// A frame's figures from its lists, counters, whether step V ran over the voxel list
    /// (whose length is the voxels ray cast) and stage times (step IV, step V).
    fn stats_of(&self, lists: &Lists, c: [u64; 4], listed: bool, seconds: [f64; 2]) -> CaoStats {
        let dims = self.dims.map(|d| d as usize);
        CaoStats {
            voxels: dims.iter().map(|&d| d as u64).product(),
            recomputed: if listed { c[3] } else { c[2] },
            listed,
            category_b: c[0],
            clipped: c[1],
            clip_voxels: Bricks::voxels_in(&lists.clip, dims),
            lao_voxels: Bricks::voxels_in(&lists.lao, dims),
            maps_seconds: 0.0,
            clip_seconds: seconds[0],
            lao_seconds: seconds[1],
            clip_errors: Vec::new(),
        }
    }

    fn write_lists(&self, gpu: &Gpu, lists: &Lists) {
        gpu.queue.write_buffer(&self.counters, 0, &[0u8; 16]);
        if !lists.clip.is_empty() {
            gpu.queue
                .write_buffer(&self.lists, 0, bytemuck::cast_slice(&lists.clip));
        }
        if !lists.lao.is_empty() {
            gpu.queue.write_buffer(
                &self.lists,
                4 * lists.clip.len() as u64,
                bytemuck::cast_slice(&lists.lao),
            );
        }
    }

    /// (category b, clipped, ray cast over bricks, listed) of the steps just submitted.
    fn read_counters(&self, gpu: &Gpu) -> Result<[u64; 4], GpuError> {
        let device = &gpu.device;
        validated(device, "Cao::counters", || {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.counters, 0, &self.counters_readback, 0, 16);
            gpu.queue.submit([encoder.finish()]);
        })?;
        let bytes = read_buffer(device, &self.counters_readback, "Cao::counters")?;
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok([c[0], c[1], c[2], c[3]].map(u64::from))
    }

    /// Step IV's bricks over `lists.clip` and its uniforms.
    fn iv_dispatch(&self, lists: &Lists, mode: CaoMode) -> (BrickDispatch, ClipParams) {
        // Bound each submission's clip samples (41 per voxel per shape at worst).
        let per_voxel = (9 + self.msaa as u64) * self.clip.uniforms.counts[0].max(1) as u64;
        let chunks = BrickDispatch::new(
            0,
            lists.clip.len(),
            per_voxel,
            budget::LAO_SAMPLES,
            u64::MAX,
        );
        let mut params = self.clip_params;
        params.full = u32::from(mode == CaoMode::Full);
        params.unread_marked = u32::from(self.pao_ready);
        params.clipped_one = u32::from(self.lists_voxels(mode));
        // None in the baseline (`begin` asks for balls only in CAO mode).
        if let Some(balls) = &self.cut_balls {
            params.ray_test = 1 + balls.len() as u32;
            params.balls[..balls.len()].copy_from_slice(balls);
        }
        (chunks, params)
    }

    /// Step IV's bind group of the clip maps (group 1).
    fn iv_clip_group(&self, device: &wgpu::Device) -> wgpu::BindGroup {
        let layout = self.pipelines.clip_for(&self.bricks, self.segments).any();
        self.clip
            .bind_group(device, &layout.get_bind_group_layout(1))
    }

    /// Step V's bricks over `lists.lao` (after step IV's in the list buffer).
    fn v_dispatch(&self, lists: &Lists) -> BrickDispatch {
        let per_voxel = self.rays as u64 * self.samples as u64;
        BrickDispatch::new(
            lists.clip.len(),
            lists.lao.len(),
            per_voxel,
            budget::LAO_SAMPLES,
            u64::MAX,
        )
    }

    /// `f` of step V's pass, for a frame or for `V_PAO`.
    fn with_step_v<R>(&self, frame: bool, f: impl FnOnce(&Pass<'_>) -> R) -> R {
        let i = usize::from(frame);
        let groups = [(0, &self.lao_group[i]), (VOLUME_GROUP, &self.lao_volume[i])];
        f(&Pass {
            label: "Cao::step_v",
            pipeline: self.pipelines.lao_for(&self.bricks, frame),
            bind_groups: &groups,
            uniforms: &self.lao_uniforms[i],
        })
    }

    /// `f` of step IV's pass with `pipeline` (CAO's for its bricks, or the dense one).
    fn with_step_iv<R>(
        &self,
        device: &wgpu::Device,
        pipeline: &wgpu::ComputePipeline,
        f: impl FnOnce(&Pass<'_>) -> R,
    ) -> R {
        let clip_group = self.iv_clip_group(device);
        let groups = [
            (0, &self.clip_group),
            (1, &clip_group),
            (VOLUME_GROUP, &self.clip_volume),
        ];
        f(&Pass {
            label: "Cao::step_iv",
            pipeline,
            bind_groups: &groups,
            uniforms: &self.clip_uniforms,
        })
    }

    /// Step IV over `lists.clip`.
    fn step_iv(&self, gpu: &Gpu, lists: &Lists, mode: CaoMode) -> Result<(), GpuError> {
        let (chunks, params) = self.iv_dispatch(lists, mode);
        self.step_iv_with(gpu, chunks, params, self.clip_pipeline())
    }

    /// Step IV's pipeline for these bricks and the shapes the clip maps are posed for.
    fn clip_pipeline(&self) -> &wgpu::ComputePipeline {
        let shapes = self.clip.uniforms.counts[0];
        self.pipelines
            .clip_for(&self.bricks, self.segments)
            .for_shapes(shapes)
    }

    /// Step IV with `pipeline` (CAO's for its bricks, or the dense one for the paper's
    /// mask).
    fn step_iv_with(
        &self,
        gpu: &Gpu,
        chunks: BrickDispatch,
        params: ClipParams,
        pipeline: &wgpu::ComputePipeline,
    ) -> Result<(), GpuError> {
        self.with_step_iv(&gpu.device, pipeline, |pass| {
            chunks.run(gpu, pass, params, false, |_, _| Ok(()), |_, _, _| {})
        })
    }

    /// Step V over `lists.lao`, for a frame or for `V_PAO`; `progress` counts bricks.
    fn step_v(
        &self,
        gpu: &Gpu,
        lists: &Lists,
        frame: bool,
        progress: &dyn Fn(usize, usize),
    ) -> Result<(), GpuError> {
        let chunks = self.v_dispatch(lists);
        let total = chunks.len() as usize;
        self.with_step_v(frame, |pass| {
            chunks.run(
                gpu,
                pass,
                self.lao_params,
                true,
                |first, count| {
                    progress((first + count) as usize, total);
                    Ok(())
                },
                |_, _, _| {},
            )
        })
    }

    /// `V_AO` for the ray caster.
    pub fn ao_view(&self) -> &wgpu::TextureView {
        &self.views[2]
    }

    /// `V_PAO` (LAO of the unclipped volume), for images that cannot wait for `V_AO`:
    /// the ray caster reads it like `V_AO` (voxels it marks unread are never read).
    pub fn pao_view(&self) -> &wgpu::TextureView {
        &self.views[1]
    }

    /// GPU memory of the CAO volumes per voxel, in bytes (V_o, V_PAO, V_AO; the density
    /// volume V is the ray caster's).
    pub fn bytes_per_voxel(&self) -> u32 {
        3 * self.v_ao.format().block_copy_size(None).unwrap_or(4)
    }
}
