//! Making the viewport's image without ever waiting for the GPU on the UI thread.
//!
//! Each UI frame the viewer says what it wants on screen ([`Want`]: the frame, the clip
//! shapes' poses and the interactive scale) and [`ViewportGpu::pump`] moves one image
//! ([`Work`]) towards it, submitting only what fits in the [`Pacer`]'s slice:
//!
//! 1. when the shapes moved, CAO's update for their new pose ([`CaoGpu::begin`] /
//!    [`CaoGpu::advance`]: steps IV and V in chunks of bricks) or, without CAO, the clip
//!    maps re-posed;
//! 2. the ray cast of the frame in strips of rows into a back image;
//! 3. once every strip is submitted the back image becomes the one drawn. The queue is
//!    in order, so the paint that follows sees it complete.
//!
//! An image is consistent with the pose it was made for: its clipping and its `V_AO` come
//! from the same CAO frame, and nothing else changes them until it is shown; an image made
//! while `V_AO` is not exact for its pose reads `V_PAO` instead. Requests
//! coalesce: while an image is made, newer poses only replace the wanted one, and the
//! next image is made for the newest (a CAO update is never abandoned half-way, since
//! the next one relies on what it restored). A full-quality image still being ray-cast
//! when the view moves again is dropped for an interactive one. A change to the volume,
//! its transfer function or AO during a ray cast starts the strips again.

use super::*;
use crate::render::gpu::TileDraw;
use crate::render::reuse::screen_rect;

/// Pass label of strips that cast only the pixels near a change (their times say nothing
/// of what a full strip costs: kept apart from [`STRIP`]'s rate and tile costs).
const STRIP_REUSING: &str = "Viewport::strip_reusing";

/// The share of a frame's slice kept for CAO's update once an image has been shown
/// since it began, or it has waited [`CAO_PATIENCE`] behind the images (which come first
/// until then: the image of a shape moved shows before the update for it).
const CAO_SHARE: f64 = 0.5;
const CAO_PATIENCE: std::time::Duration = std::time::Duration::from_millis(500);

impl ViewportGpu {
    /// What an image made for `want` would show now.
    fn key_of(&self, want: &Want) -> ViewKey {
        let s = want.scale.max(1);
        let mut frame = Frame {
            width: want.frame.width.max(1).div_ceil(s),
            height: want.frame.height.max(1).div_ceil(s),
            ..want.frame
        };
        if s > 1 {
            frame.settings.step_voxels *= want.step_factor.clamp(1.0, MAX_INTERACTIVE_STEP);
        }
        ViewKey {
            frame,
            revision: self.revision,
            clip: want.clip.clone(),
            scale: s,
            ao_exact: true,
        }
    }

    /// Whether an image started now would read an exact `V_AO` for `clip`.
    fn ao_exact(&self, clip: &[ClipShape]) -> bool {
        self.cao.is_none()
            || (self.cao_work.is_none() && self.ao_exact_for.as_deref() == Some(clip))
    }

    /// Whether the image drawn is the full-quality one of `want`.
    pub(in crate::app) fn is_current(&self, want: &Want) -> bool {
        self.work.is_none()
            && self.cao_work.is_none()
            && want.scale <= 1
            && self
                .shown
                .as_ref()
                .is_some_and(|s| s.key == self.key_of(want))
    }

    /// Whether an image or CAO's update is being made.
    pub(in crate::app) fn working(&self) -> bool {
        self.work.is_some() || self.cao_work.is_some()
    }

    /// How far the image being made is, or else CAO's update (then true), if either is.
    pub(in crate::app) fn work_fraction(&self) -> Option<(f32, bool)> {
        match (&self.work, &self.cao_work) {
            (Some(w), _) => Some((w.fraction(), false)),
            (None, Some(c)) => Some((c.fraction(), true)),
            (None, None) => None,
        }
    }

    /// Whether a CAO update is being submitted or its figures have not come back.
    pub(in crate::app) fn cao_in_flight(&self) -> bool {
        self.cao_work.is_some() || self.stats_pending.is_some()
    }

    /// Whether the image drawn read an exact `V_AO` for its shapes (false: it read
    /// `V_PAO`, while CAO's update caught up with a shape being dragged).
    pub fn shown_ao_exact(&self) -> bool {
        self.shown.as_ref().is_none_or(|s| s.key.ao_exact)
    }

    /// The interactive scale of the image drawn (1: full quality).
    pub(in crate::app) fn shown_scale(&self) -> u32 {
        self.shown.as_ref().map_or(1, |s| s.key.scale)
    }

    /// The image being made: when it started and how far its submissions have come
    /// (row times width plus column; it only grows while the same image is made).
    pub(in crate::app) fn work_progress(&self) -> Option<(Instant, u64)> {
        self.work.as_ref().map(|w| {
            let done = u64::from(w.next_row) * u64::from(w.key.frame.width);
            (w.started, done + u64::from(w.next_column))
        })
    }

    /// The image and the CAO update being made, in one line (for the scripted runs'
    /// watchdog).
    pub(in crate::app) fn describe_work(&self) -> String {
        let work = match &self.work {
            None => "no image being made".to_owned(),
            Some(w) => format!(
                "image {}×{} (scale {}, exact AO {}, {}) started {:.1} s ago: rows {}..{} of \
                 {}..{}, column {}",
                w.key.frame.width,
                w.key.frame.height,
                w.key.scale,
                w.key.ao_exact,
                match (w.reused, &w.clip) {
                    (true, _) => "reusing",
                    (false, Some(_)) => "own clip maps",
                    (false, None) => "full",
                },
                w.started.elapsed().as_secs_f64(),
                w.next_row,
                w.rows.end,
                w.rows.start,
                w.rows.end,
                w.next_column
            ),
        };
        let cao = match &self.cao_work {
            None => "no CAO update".to_owned(),
            Some(c) => format!(
                "CAO update began {:.1} s ago (tainted {}, imaged {}): {}",
                c.began.elapsed().as_secs_f64(),
                c.tainted,
                c.imaged,
                c.frame.describe()
            ),
        };
        let pending = match &self.stats_pending {
            None => String::new(),
            Some(f) => format!("; figures pending: {}", f.describe()),
        };
        let compiling = match &self.compiling {
            None => "",
            Some(_) => "; a pipeline compiling",
        };
        format!(
            "{work}; {cao}{pending}{compiling}; {} images so far, AO exact for the shapes \
             drawn: {}",
            self.frames_rendered,
            self.shown_ao_exact()
        )
    }

    /// Moves the viewport's image towards `want` within the pacer's slice (see the
    /// module's documentation). Never waits for the GPU.
    pub(in crate::app) fn pump(&mut self, gpu: &Gpu, want: &Want, pacer: &mut Pacer) -> Pumped {
        let mut out = Pumped::default();
        if let (Some(cao), Some(f)) = (&self.cao, &mut self.stats_pending)
            && let Some(result) = cao.poll_stats(f)
        {
            match result {
                Ok(stats) => out.stats = Some(stats),
                Err(e) => out.error = Some(e.to_string()),
            }
            self.stats_pending = None;
        }
        if self.volume.is_none() {
            self.work = None;
            self.cao_work = None;
            return out;
        }
        let key = self.key_of(want);
        if self
            .cao_work
            .as_ref()
            .is_some_and(|c| c.generation != self.cao_generation)
        {
            self.cao_work = None;
            self.synced_clip = None;
        }
        if let Some(w) = &mut self.work {
            if w.key.scale == 1 && key.scale > 1 {
                // The view moves again: an interactive image comes sooner.
                self.work = None;
            } else if w.key.revision != self.revision {
                // The view changed under it: every pixel is cast again, none reused.
                w.key.revision = self.revision;
                w.changed.clear();
                w.rows = 0..w.key.frame.height;
                w.columns = 0..w.key.frame.width;
                w.next_row = 0;
                w.next_column = 0;
                w.reused = false;
            }
        }
        // CAO's update for the shapes wanted, unless its V_AO is exact for them already.
        if self.cao.is_some()
            && self.cao_work.is_none()
            && self.ao_exact_for.as_ref() != Some(&key.clip)
        {
            // The update poses the clip maps for these shapes and rewrites V_AO: an image
            // being made for other shapes, or reading V_AO, would mix two poses. It is
            // dropped, and one that reads V_PAO takes its place if the view moves.
            // An image with its own copy of the maps goes on unless the update rebuilds
            // them (a shape added or resized): the copy shares their textures.
            let rebuilds = || match (&self.cao, &self.volume) {
                (Some(cao), Some(vol)) => {
                    let reach = cao.reach_mm(&vol.texels);
                    !cao.clip.fits(gpu, want.setup.maps(&key.clip, reach))
                }
                _ => true,
            };
            let drop = self.work.as_ref().is_some_and(|w| {
                w.key.ao_exact
                    || match w.clip {
                        None => w.key.clip != key.clip,
                        Some(_) => rebuilds(),
                    }
            });
            if drop && let Some(w) = self.work.take() {
                self.frames_dropped_by_cao += u64::from(!w.key.ao_exact);
            }
            match self.begin_cao(gpu, &key.clip, want.setup) {
                Ok(errors) => out.clip_errors = errors,
                Err(e) => {
                    out.error = Some(e);
                    return out;
                }
            }
        }
        // An image that reads V_AO is never made while an update is on its way (which
        // rewrites it): dropped above, or started reading V_PAO (`start`).
        debug_assert!(
            self.cao_work.is_none() || self.work.as_ref().is_none_or(|w| !w.key.ao_exact),
            "an image reads a V_AO being updated"
        );
        for (tag, took) in pacer.timed(STRIP) {
            if let Some(i) = self.tiles_in_flight.iter().position(|s| s.0 == tag) {
                let (_, size, step, tile) = self.tiles_in_flight.swap_remove(i);
                self.tile_costs.record(size, step, tile, took.as_secs_f64());
            }
        }
        // A strip that cast only the pixels near a change says nothing of what its
        // part of the picture costs.
        pacer.timed(STRIP_REUSING);
        if self.work.is_none() && self.should_start(&key, want) {
            match self.start(gpu, key, want) {
                Ok(errors) => out.clip_errors.extend(errors),
                Err(e) => {
                    out.error = Some(e);
                    return out;
                }
            }
        }
        // The image first (the view follows the mouse), then CAO with what is left of
        // the slice, and at least CAO_SHARE of it once an image came since the update
        // began (or it waited CAO_PATIENCE): interactive images come every frame while
        // a shape is dragged, and would otherwise leave CAO nothing until the drag stops.
        let keeps_share = |c: &CaoWork| c.imaged || c.began.elapsed() > CAO_PATIENCE;
        let mut held = match self.cao_work.as_ref().is_some_and(keeps_share) {
            true => pacer.hold(CAO_SHARE),
            false => 0.0,
        };
        let mut advanced = self.advance(gpu, pacer);
        if matches!(advanced, Ok(Advanced::Starved)) && held > 0.0 {
            // Not one piece of the image fitted in its share: it takes the whole of
            // what is left.
            pacer.release(held);
            held = 0.0;
            advanced = self.advance(gpu, pacer);
        }
        pacer.release(held);
        // An image that got nothing at all this frame goes first in the next: CAO submits
        // nothing now, so the queue drains and the image's piece fits (or goes alone).
        // Else CAO's small pieces would fill every slice, and an image whose least piece
        // costs more than what they leave would wait for the whole update.
        let image_starved = matches!(advanced, Ok(Advanced::Starved));
        match advanced {
            Ok(Advanced::Going | Advanced::Starved) => {}
            Ok(Advanced::Done) => {
                if let Some(w) = self.work.take() {
                    out.completed = Some((w.started.elapsed().as_secs_f64(), w.key.scale));
                    let reused = w.reused;
                    if let Some(old) = self.shown.take() {
                        if old.key.scale != w.key.scale {
                            // Kept for the next image at its scale (the full-quality one
                            // after a drag), which then casts only what changed.
                            if let Some(older) = self.kept.replace(old) {
                                self.spare = Some(older.target);
                            }
                        } else {
                            self.spare = Some(old.target);
                        }
                    }
                    self.shown = Some(Shown {
                        target: w.target,
                        key: w.key,
                        inputs: w.inputs,
                    });
                    self.frames_rendered += 1;
                    self.frames_reused += u64::from(reused);
                    self.last_error = None;
                    if let Some(c) = &mut self.cao_work {
                        c.imaged = true;
                    }
                }
            }
            Err(e) => {
                self.work = None;
                self.last_error = Some(e.to_string());
                out.error = Some(e.to_string());
            }
        }
        if !image_starved && let Err(e) = self.advance_cao(gpu, pacer) {
            self.cao_work = None;
            self.synced_clip = None;
            self.last_error = Some(e.to_string());
            out.error = Some(e.to_string());
        }
        out
    }

    /// Whether to start an image for `key` now. Not while CAO's update is on its way,
    /// unless the view moves (`want.moving`), the image drawn shows another view and the
    /// last image started at least `want.image_interval` ago: dragging a shape, the
    /// clipping follows the mouse at the interactive target rate with `V_PAO` for AO, and
    /// the rest of the GPU's time goes to the update; at rest the image waits for the
    /// exact AO. Whether the view moves is not told by the image's scale: where the
    /// measured rate reaches the target rate at full size, a moving view's images are at
    /// scale 1 too (until 2026-12-07 that stopped every image for as long as a drag
    /// with CAO went on, since each update began as the last one ended: the scripted
    /// drag then never finished).
    fn should_start(&self, key: &ViewKey, want: &Want) -> bool {
        let shown = self.shown.as_ref().map(|s| &s.key);
        if shown == Some(key) {
            return false;
        }
        if self.cao_work.is_none() {
            return true;
        }
        want.moving
            && !shown.is_some_and(|s| s.same_view(key))
            && due(self.last_start, want.image_interval, Instant::now())
    }

    /// Begins CAO's update for `clip` (posing the clip maps for it). Returns the shapes
    /// left out, with why.
    fn begin_cao(
        &mut self,
        gpu: &Gpu,
        clip: &[ClipShape],
        setup: ClipSetup,
    ) -> Result<Vec<String>, String> {
        let (Some(cao), Some(vol)) = (&mut self.cao, &self.volume) else {
            return Ok(Vec::new());
        };
        self.synced_clip = Some(clip.to_vec());
        let reach = cao.reach_mm(&vol.texels);
        let frame = cao
            .begin(
                gpu,
                &vol.texels,
                Pose {
                    shapes: clip,
                    resolution: setup.resolution,
                    reach_mm: reach,
                    mode: setup.cao_mode,
                },
            )
            .map_err(|e| e.to_string())?;
        let errors = frame.clip_errors().to_vec();
        self.cao_work = Some(CaoWork {
            generation: self.cao_generation,
            clip: clip.to_vec(),
            frame,
            tainted: false,
            began: Instant::now(),
            imaged: false,
        });
        Ok(errors)
    }

    /// Submits what fits of CAO's update; once all of it is submitted, its `V_AO` is
    /// exact for its shapes unless the clip maps moved meanwhile.
    fn advance_cao(&mut self, gpu: &Gpu, pacer: &mut Pacer) -> Result<(), GpuError> {
        let (Some(c), Some(cao)) = (&mut self.cao_work, &self.cao) else {
            return Ok(());
        };
        if !cao.advance(gpu, &mut c.frame, pacer)? {
            return Ok(());
        }
        if let Some(c) = self.cao_work.take() {
            self.ao_exact_for = (!c.tainted).then_some(c.clip);
            self.stats_pending = Some(c.frame);
        }
        Ok(())
    }

    /// Starts an image for `key`: poses CAO or the clip maps when the shapes moved,
    /// allocates the back image. Returns the shapes left out, with why.
    fn start(&mut self, gpu: &Gpu, key: ViewKey, want: &Want) -> Result<Vec<String>, String> {
        if let Some(vol) = &mut self.volume {
            vol.prepare_step(gpu, key.frame.settings.step_voxels);
        }
        let mut errors = Vec::new();
        // With CAO, an image of other shapes than CAO's maps are posed for gets its own
        // copy of the maps posed for them: CAO's update keeps its pose (and stays exact),
        // and its next one does not drop the image. So does an image made while an update
        // is on its way, even of the shapes CAO's maps are posed for (it starts in the
        // frame the update began): the next update, which during a drag begins as this
        // one ends, re-poses those maps. Clipping with CAO's own maps, such an image was
        // dropped then, and its successor, started in that same frame, clipped with them
        // again: an image that took longer than an update never came (until 2026-12-07).
        let moved = self.synced_clip.as_ref() != Some(&key.clip);
        let mut own_clip = None;
        if (moved || self.cao_work.is_some())
            && let (Some(cao), Some(vol)) = (&self.cao, &self.volume)
        {
            let setup = want.setup;
            let reach = cao.reach_mm(&vol.texels);
            own_clip = cao.clip.posed(gpu, setup.maps(&key.clip, reach));
        }
        if moved && own_clip.is_none() {
            // Whatever happens, these shapes are done with (an error is not retried).
            self.synced_clip = Some(key.clip.clone());
            let Some(vol) = &self.volume else {
                return Err("no volume".into());
            };
            let setup = want.setup;
            let (maps, reach) = if let Some(cao) = &mut self.cao {
                // Posed for the image of a shape being dragged while CAO's update for
                // an earlier pose is on its way: that update is no longer exact.
                if let Some(c) = &mut self.cao_work
                    && c.clip != key.clip
                {
                    c.tainted = true;
                }
                if self.ao_exact_for.as_ref() != Some(&key.clip) {
                    self.ao_exact_for = None;
                }
                let reach = cao.reach_mm(&vol.texels);
                (Some(&mut cao.clip), reach)
            } else if key.clip.is_empty() {
                self.clip = None;
                (None, 0.0)
            } else {
                if self.clip.is_none() {
                    self.clip = Some(ClipMaps::new(gpu).map_err(|e| e.to_string())?);
                }
                // No AO depends on the clipping: the maps `volao render` makes.
                (self.clip.as_mut(), crate::clip::gpu::CLIPPING_REACH_MM)
            };
            if let Some(maps) = maps {
                let report = maps
                    .update(gpu, setup.maps(&key.clip, reach))
                    .map_err(|e| e.to_string())?;
                errors = report.errors.iter().map(|e| e.to_string()).collect();
            }
        }
        let key = ViewKey {
            ao_exact: self.ao_exact(&key.clip),
            ..key
        };
        // Without an exact V_AO for these shapes the image reads V_PAO (the stand-in
        // set with CAO), so that its AO and its clipping never come from two poses.
        if let Some(vol) = &mut self.volume {
            vol.read_stand_in(!key.ao_exact);
        }
        let (width, height) = (key.frame.width, key.frame.height);
        let inputs = self.inputs_of(&key, own_clip.as_ref());
        let target = self.target(&gpu.device, (width, height));
        // An image of the same view shown or kept: this one starts as its copy and casts
        // only the pixels whose rays pass near a change (render::reuse).
        let base = [self.shown.as_ref(), self.kept.as_ref()]
            .into_iter()
            .flatten()
            .find(|s| {
                s.key.frame == key.frame
                    && s.key.revision == key.revision
                    && s.key.scale == key.scale
            });
        let reusable = self
            .volume
            .as_ref()
            .is_some_and(|v| crate::render::reuse::reusable(&key.frame, &v.extras));
        let mut changed = Vec::new();
        let (mut rows, mut columns) = (0..height, 0..width);
        let mut reused = false;
        if let (Some(base), Some(new), true) = (base, &inputs, reusable)
            && let Some(old) = &base.inputs
            && let Some(vol) = &self.volume
        {
            changed = old.changed(new);
            (rows, columns) = match screen_rect(&key.frame, &vol.texels, &changed) {
                Some((x0, y0, x1, y1)) => (y0..y1, x0..x1),
                None => (0..0, 0..0),
            };
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            encoder.copy_texture_to_texture(
                base.target.texture.as_image_copy(),
                target.texture.as_image_copy(),
                crate::gpu::extent([width, height, 1]),
            );
            gpu.queue.submit([encoder.finish()]);
            reused = true;
        }
        let started = Instant::now();
        self.last_start = Some(started);
        self.work = Some(Work {
            key,
            inputs,
            next_row: rows.start,
            changed,
            rows,
            columns,
            reused,
            clip: own_clip,
            target,
            next_column: 0,
            started,
        });
        Ok(errors)
    }

    /// What an image of `key` clipped by `own_clip` (else the viewport's maps) depends on
    /// beyond its view ([`ImageInputs`]); `None` when it may depend on the shapes anywhere.
    fn inputs_of(&self, key: &ViewKey, own_clip: Option<&ClipMaps>) -> Option<ImageInputs> {
        let vol = self.volume.as_ref()?;
        let maps = own_clip.or(self.clip_maps());
        let reach = self.cao.as_ref().map_or(0.0, |c| c.reach_mm(&vol.texels));
        let cut_ao = self.cao.is_some() && key.ao_exact;
        ImageInputs::of(maps, &key.clip, &vol.texels, reach, cut_ao)
    }

    /// Submits what fits of the image being made, in the pieces [`next_tile`] cuts (each
    /// costed by [`TileCosts`], else the pacer's mean rate).
    fn advance(&mut self, gpu: &Gpu, pacer: &mut Pacer) -> Result<Advanced, crate::gpu::GpuError> {
        let ViewportGpu {
            work,
            cao,
            volume,
            clip,
            ray_caster,
            strips,
            compiling,
            tile_costs,
            tiles_in_flight,
            next_strip_tag,
            ..
        } = self;
        let (Some(w), Some(vol)) = (work.as_mut(), volume.as_ref()) else {
            return Ok(Advanced::Going);
        };
        let clip = w
            .clip
            .as_ref()
            .or(cao.as_ref().map(|c| &c.clip))
            .or(clip.as_ref());
        let (width, height) = (w.key.frame.width, w.key.frame.height);
        // A pipeline variant not built yet compiles on a worker thread (~0.1 s on
        // lavapipe), not in the UI's frame; the image waits for it.
        let surfaces = !vol.extras.surfaces.is_empty();
        let variant = Variant::of(vol, &w.key.frame, clip, surfaces);
        if ray_caster.has_pipeline(variant) {
            // Built (here or on the worker thread): nothing is compiling for it any more.
            if compiling.as_ref().is_some_and(|(v, _)| *v == variant) {
                *compiling = None;
            }
        } else {
            match compiling {
                Some((v, state)) if *v == variant => {
                    let failed = state.lock().ok().and_then(|s| s.clone());
                    match failed {
                        // Still compiling.
                        None => return Ok(Advanced::Going),
                        // It failed there: the ray cast below builds it again and
                        // reports the error.
                        Some(_) => *compiling = None,
                    }
                }
                _ => {
                    let state: Compiled = Default::default();
                    let (rc, device, s) = (
                        std::sync::Arc::clone(ray_caster),
                        gpu.device.clone(),
                        std::sync::Arc::clone(&state),
                    );
                    let spawned = std::thread::Builder::new()
                        .name("volao-pipeline".into())
                        .spawn(move || {
                            let r = rc.build_pipeline(&device, variant);
                            if let Ok(mut s) = s.lock() {
                                *s = Some(r.err().map(|e| e.to_string()));
                            }
                        });
                    if spawned.is_ok() {
                        *compiling = Some((variant, state));
                        return Ok(Advanced::Going);
                    }
                }
            }
        }
        // An image reads V_AO only when it is exact for its shapes, else V_PAO.
        debug_assert!(
            cao.is_none() || vol.reads_stand_in() != w.key.ao_exact,
            "an image reads the wrong AO volume"
        );
        let pixel_rate = pacer.rate(STRIP).unwrap_or_else(|| first_pixel_rate(gpu));
        let step = w.key.frame.settings.step_voxels;
        let reusing = !w.changed.is_empty();
        let columns = w.columns.clone();
        let estimate = |t: Tile| {
            // Reusing, only the columns near a change may be cast.
            let t = match reusing {
                true => {
                    let x0 = t.0.clamp(columns.start, columns.end);
                    let x1 = (t.0 + t.2).clamp(columns.start, columns.end);
                    (x0, t.1, x1 - x0, t.3)
                }
                false => t,
            };
            tile_costs
                .estimate((width, height), step, t)
                .unwrap_or_else(|| {
                    ((t.2.min(width - t.0) * t.3.min(height - t.1)) as f64) / pixel_rate
                })
        };
        let mut submitted = false;
        while w.next_row < w.rows.end {
            let (x0, y0) = (w.next_column, w.next_row);
            let idle = pacer.has_time() && !pacer.busy();
            let slice = (pacer.slice.as_secs_f64(), pacer.left());
            let Some(tile) = next_tile((width, (x0, y0)), slice, idle, estimate) else {
                return Ok(match submitted {
                    true => Advanced::Going,
                    false => Advanced::Starved,
                });
            };
            let (tx, ty, tw, th) = tile;
            let strip = strips.of_size(&gpu.device, (tw, th));
            let tag = *next_strip_tag;
            *next_strip_tag += 1;
            let (cw, ch) = (tw.min(width - tx), th.min(height - ty));
            let label = if reusing { STRIP_REUSING } else { STRIP };
            pacer.submit_estimated(
                gpu,
                (label, (cw * ch) as u64),
                (estimate(tile), tag),
                || -> Result<(), crate::gpu::GpuError> {
                    let mut encoder = gpu.device.create_command_encoder(&Default::default());
                    let extent = crate::gpu::extent([cw, ch, 1]);
                    if reusing {
                        // The strip starts as the image's pixels: those whose rays meet
                        // no change are not cast.
                        encoder.copy_texture_to_texture(
                            wgpu::TexelCopyTextureInfo {
                                texture: &w.target.texture,
                                mip_level: 0,
                                origin: wgpu::Origin3d { x: tx, y: ty, z: 0 },
                                aspect: wgpu::TextureAspect::All,
                            },
                            strip.as_image_copy(),
                            extent,
                        );
                    }
                    let tile = TileDraw {
                        volume: vol,
                        frame: &w.key.frame,
                        clip,
                        target: strip,
                        origin: (tx, ty),
                        changed: &w.changed,
                    };
                    ray_caster.encode_tile(gpu, tile, &mut encoder)?;
                    encoder.copy_texture_to_texture(
                        strip.as_image_copy(),
                        wgpu::TexelCopyTextureInfo {
                            texture: &w.target.texture,
                            mip_level: 0,
                            origin: wgpu::Origin3d { x: tx, y: ty, z: 0 },
                            aspect: wgpu::TextureAspect::All,
                        },
                        extent,
                    );
                    gpu.queue.submit([encoder.finish()]);
                    Ok(())
                },
            )?;
            submitted = true;
            if !reusing {
                tiles_in_flight.push((tag, (width, height), step, tile));
            }
            if tiles_in_flight.len() > 4 * RECENT_TILES {
                // Never timed (the pacer was replaced): forgotten.
                tiles_in_flight.remove(0);
            }
            if tx + tw >= width {
                w.next_column = 0;
                w.next_row += th;
            } else {
                w.next_column = tx + tw;
            }
        }
        Ok(Advanced::Done)
    }
}

/// Whether an image may start at `now` if the last one started at `last` and images
/// start at most every `interval`.
fn due(last: Option<Instant>, interval: Option<std::time::Duration>, now: Instant) -> bool {
    match (last, interval) {
        (Some(last), Some(interval)) => now.saturating_duration_since(last) >= interval,
        _ => true,
    }
}

/// How far [`ViewportGpu::advance`] moved the image being made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Advanced {
    /// Pieces went, or it waits for something other than the queue (a pipeline
    /// compiling), or there is no image to make.
    Going,
    /// Not one piece fitted in what was left of the slice.
    Starved,
    /// All of it is submitted.
    Done,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn images_start_at_most_once_per_interval() {
        let t0 = Instant::now();
        let tenth = Some(Duration::from_millis(100));
        // Nothing started yet, or no limit: now.
        assert!(due(None, tenth, t0));
        assert!(due(Some(t0), None, t0));
        // Within the interval: not yet; once it has passed: yes.
        assert!(!due(Some(t0), tenth, t0 + Duration::from_millis(99)));
        assert!(due(Some(t0), tenth, t0 + Duration::from_millis(100)));
    }
}
