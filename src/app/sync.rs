//! The viewer's per-frame bookkeeping of the volumes it derives from the document in
//! the background ([`super::derived`]): start, collect and upload AO, opacity
//! modulation and the light volume, and keep the transfer function and clip shapes on
//! the GPU in step with the document.

use super::ao_job::{AoData, AoInput, compute_ao};
use super::derived::*;
use super::jobs::{Job, Keyed, Polled};
use super::viewport::{ClipSetup, INTERACTIVE_REST, MAX_INTERACTIVE_SCALE, Want};
use super::{Viewer, ao_panel};
use crate::ao::AoMethod;
use crate::ao::cao::CaoMode;
use crate::ao::filter::StatisticSource;
use crate::gpu::Gpu;
use crate::render::Frame;
use crate::render::gpu::RenderVolume;
use crate::texels::VolumeTexels;
use crate::texels::gpu::GpuVolume;
use crate::texels::segments::SegmentTexels;
use std::sync::Arc;
use std::time::Instant;

/// Puts a derived result on the GPU volume: `Ok(false)` when it does not fit (dropped).
type Upload<'a, K> = &'a dyn Fn(&Gpu, &mut RenderVolume, &K, &[f32]) -> Result<bool, String>;

/// How [`Viewer::keep_derived`] handles one derived volume.
struct DerivedVolume<'a, K> {
    /// For messages: "Shadows" (failed: …).
    what: &'static str,
    slot: fn(&mut Derived) -> &mut Keyed<K, Vec<f32>>,
    upload: Upload<'a, K>,
    /// Removes the GPU's copy.
    clear: &'a dyn Fn(&Gpu, &mut RenderVolume),
    /// Keep a stale result on screen until the next one arrives.
    keep_stale: bool,
}

impl Viewer {
    pub(super) fn ao_key(&self) -> Option<AoKey> {
        let doc = self.opened.doc.as_ref()?;
        (doc.ao.method != AoMethod::None).then(|| AoKey {
            settings: doc.ao,
            // CAO and its baseline keep the AO exact under clipping, as in `volao render`.
            clipping: matches!(doc.ao.method, AoMethod::Cao | AoMethod::LaoFull),
            opacity: doc.tf.opacity.clone(),
            coverage: crate::ao::sparse::Coverage::for_render(&doc.render),
            segments: self.segments_seen(),
            doc_generation: self.opened.generation,
        })
    }

    /// What AO and shadows see of the segmentation as built ([`seen`]).
    fn segments_seen(&self) -> Option<Vec<[u32; 3]>> {
        self.derived.segments.as_ref().map(|b| seen(&b.texels))
    }

    /// Whether the segmentation's looks wait to be sent to the viewport's volume.
    pub(super) fn segments_waiting(&self) -> bool {
        self.derived.segments.as_ref().is_some_and(|b| !b.uploaded)
    }

    /// Keeps the segmentation on the viewport's volume in step with the styles and the
    /// clip shapes' cuts: rebuilt when they change (only the looks and the class table
    /// are uploaded again: the classes stay). A change the AO sees (visibility, opacity,
    /// outline, cuts) restarts the AO once it rests, as a transfer-function edit does;
    /// colours and tint/replace only redraw.
    pub(super) fn sync_segments(&mut self) {
        let want = self.opened.doc.as_ref().and_then(|d| {
            d.segmentation.as_ref().map(|s| SegmentsKey {
                styles: s.styles.clone(),
                cuts: d.clip_shapes.iter().map(|c| c.cuts.clone()).collect(),
                doc_generation: self.opened.generation,
            })
        });
        let current = self.derived.segments.as_ref().map(|b| &b.key);
        if want.as_ref() != current {
            let built = want.and_then(|key| {
                let doc = self.opened.doc.as_ref()?;
                let texels = doc.segmentation.as_ref()?.texels(&doc.clip_shapes);
                Some((key, texels))
            });
            let before = self.segments_seen();
            let version = self.derived.segments.as_ref().map_or(0, |b| b.version) + 1;
            self.derived.segments = built.map(|(key, texels)| SegmentsBuilt {
                key,
                texels: Arc::new(texels),
                uploaded: false,
                version,
            });
            if self.segments_seen() != before {
                self.derived.tf_changed_at = Instant::now();
            }
            if self.derived.segments.is_none() {
                let gpu = Arc::clone(&self.gpu);
                self.upload(|g| g.set_segments(&gpu, None));
            }
        }
        if !self.segments_waiting() {
            return;
        }
        // As with the transfer function: edits go in between images, as motion.
        if !self.between_images() {
            return;
        }
        let gpu = Arc::clone(&self.gpu);
        let Some(built) = &mut self.derived.segments else {
            return;
        };
        let texels = SegmentTexels::clone(&built.texels);
        built.uploaded = true;
        self.upload(|g| {
            g.set_segments(&gpu, Some(texels));
            true
        });
    }

    /// Whether an edit of what the viewport reads may go to the GPU now: not while an
    /// image is being ray-cast (it is asked for again at the next frame); then the edit
    /// counts as motion (interactive quality).
    fn between_images(&mut self) -> bool {
        if self.viewport.gpu.working() {
            self.ctx.request_repaint();
            return false;
        }
        self.viewport.motion.changed_at = Instant::now();
        true
    }

    /// Keeps the AO on the GPU in step with the settings and the transfer function.
    /// While a slow one is computed the viewport shows a cheap ambient map
    /// ([`super::preview`]); until that arrives, the previous AO stays on screen.
    pub(super) fn update_ao(&mut self) {
        let want = self.ao_key();
        match self.derived.ao.poll(want.as_ref()) {
            Polled::Nothing => {}
            Polled::Ready(key, r) => {
                let gpu = Arc::clone(&self.gpu);
                let v = &mut self.viewport.gpu;
                let applied = match (r.kind, &mut v.volume) {
                    (AoData::Volume(values), Some(g)) => {
                        if values.len() != g.texels.dims.iter().product::<usize>() {
                            Err("the AO volume does not match the uploaded volume (it was \
                                 halved to fit the GPU); AO needs the full resolution"
                                .to_owned())
                        } else {
                            g.set_ambient_occlusion(&gpu, &values);
                            v.set_cao(None);
                            Ok(())
                        }
                    }
                    (AoData::Cao(cao), Some(_)) => {
                        // Its V_AO is posed for the current shapes by the next image
                        // (until then the approximation stays on screen).
                        v.set_cao(Some(*cao));
                        Ok(())
                    }
                    (_, None) => Err("no volume".to_owned()),
                };
                match applied {
                    Ok(()) => {
                        self.derived.ao_seconds = Some((r.seconds, r.device));
                        self.derived.ao.uploaded(key);
                        self.derived.preview.cancel();
                        self.derived.shown = AoShown::Exact;
                    }
                    Err(message) => self.derived.ao.fail(key, message),
                }
            }
            Polled::Failed(message) => {
                self.toast(format!("Ambient occlusion failed: {message}"), true)
            }
        }
        self.poll_preview(want.as_ref());
        if !self.derived.ao.settled(want.as_ref()) {
            self.drop_stale_ao(want.as_ref());
        }
        self.start_preview(want.as_ref());
        if self.derived.ao.settled(want.as_ref()) {
            return;
        }
        let Some(key) = want else {
            return;
        };
        // Live positional AO needs no precomputation: the ray caster evaluates it at every
        // sample, so it follows the transfer function and the clip shapes at once.
        if key.settings.method == AoMethod::VaoLive {
            let gpu = Arc::clone(&self.gpu);
            let Some(tf) = self.opened.doc.as_ref().map(|d| d.tf.clone()) else {
                return;
            };
            let vao = key.settings.vao;
            let v = &mut self.viewport.gpu;
            let applied = v.volume.as_mut().map(|g| {
                g.set_live_vao(&gpu, &tf, Some(&vao))
                    .map_err(|e| e.to_string())
            });
            if applied.is_some() {
                v.touch();
            }
            match applied {
                Some(Ok(())) => {
                    self.derived.ao.uploaded(key);
                    self.derived.shown = AoShown::Exact;
                }
                Some(Err(message)) => {
                    self.toast(format!("Ambient occlusion failed: {message}"), true);
                    self.derived.ao.fail(key, message);
                }
                None => {}
            }
            return;
        }
        if !self.resting() {
            return;
        }
        let Some(doc) = &self.opened.doc else {
            return;
        };
        let label = format!(
            "Ambient occlusion ({}{})",
            ao_panel::method_name(doc.ao.method),
            if key.clipping { ", CAO" } else { "" }
        );
        let input = AoInput {
            gpu: Arc::clone(&self.gpu),
            volume: Arc::clone(&doc.volume),
            // CAO precomputes V_PAO on its own copy of the uploaded texels.
            texels: key.clipping.then(|| self.uploaded_texels()).flatten(),
            tf: doc.tf.clone(),
            settings: doc.ao,
            step_voxels: doc.render.step_voxels,
            clipping: key.clipping,
            coverage: key.coverage,
            segments: self
                .derived
                .segments
                .as_ref()
                .map(|b| Arc::clone(&b.texels)),
            update: None,
        };
        // Only the segments' look moved on since the CAO kept: update its V_PAO.
        let update = match self.derived.reusable_cao.take() {
            Some((old, cao)) if old.differs_in_segments_only(&key) => {
                let by_class = old.opacity_changes(&key);
                input.segments.as_ref().map(|s| {
                    let changed = s
                        .classes
                        .iter()
                        .map(|&c| by_class.get(c as usize).copied().unwrap_or(true))
                        .collect();
                    (cao, changed)
                })
            }
            _ => None,
        };
        let mut input = input;
        input.update = update;
        let job = Job::spawn(label, self.repaint_fn(), move |p| compute_ao(input, p));
        self.derived.ao.start(key, job);
    }

    /// The settings moved on: drops the AO on the GPU made for others. When the new
    /// settings get an ambient map first, the old AO stays on screen until it arrives
    /// (tens of milliseconds; the status bar says so), so that a frame never lacks AO
    /// once AO is chosen; otherwise it goes at once (never a wrong AO for long).
    fn drop_stale_ao(&mut self, want: Option<&AoKey>) {
        // Live positional AO lives in the ray caster: nothing of it stays on screen.
        let was_live = self
            .derived
            .ao
            .on_gpu()
            .is_some_and(|k| k.settings.method == AoMethod::VaoLive);
        let on_gpu = self.derived.ao.on_gpu().cloned();
        let stale_exact = self.derived.ao.reset();
        let stale_preview = self
            .derived
            .preview
            .on_gpu()
            .is_some_and(|k| Some(k) != want);
        if !(stale_exact || stale_preview) {
            return;
        }
        if stale_preview {
            self.derived.preview.reset();
        }
        let keep =
            self.preview_key(want).is_some() && self.derived.shown != AoShown::Nothing && !was_live;
        let gpu = Arc::clone(&self.gpu);
        let tf = self.opened.doc.as_ref().map(|d| d.tf.clone());
        let v = &mut self.viewport.gpu;
        // CAO for the same settings but another look of the segmentation is kept, to
        // update rather than recompute (update_ao); anything else goes.
        let reusable = match (on_gpu, want) {
            (Some(old), Some(new)) if old.differs_in_segments_only(new) => {
                v.cao.take().map(|c| (old, Box::new(c)))
            }
            _ => None,
        };
        self.derived.reusable_cao = reusable;
        v.set_cao(None);
        if let Some(g) = &mut v.volume {
            if !keep {
                g.clear_ambient_occlusion(&gpu);
            }
            if let Some(tf) = &tf {
                // Turning live positional AO off cannot fail (nothing is uploaded).
                let _ = g.set_live_vao(&gpu, tf, None);
            }
            v.touch();
        }
        self.derived.shown = if keep {
            AoShown::Previous
        } else {
            AoShown::Nothing
        };
    }

    pub(super) fn modulation_key(&self) -> Option<ModulationKey> {
        let doc = self.opened.doc.as_ref()?;
        let settings = doc.render.opacity_modulation?;
        Some(ModulationKey {
            settings,
            opacity: (settings.source == StatisticSource::Opacity).then(|| doc.tf.opacity.clone()),
            doc_generation: self.opened.generation,
        })
    }

    /// Keeps the opacity modulation on the GPU in step with its settings (and with the
    /// transfer function when the variance is the opacity's), as [`Self::update_ao`] does
    /// for AO: a stale modulation is dropped at once, the new one computed off the UI
    /// thread on the uploaded texels.
    pub(super) fn update_modulation(&mut self) {
        let want = self.modulation_key();
        let Some((key, texels)) = self.keep_derived(
            want.as_ref(),
            DerivedVolume {
                what: "Opacity modulation",
                slot: |d| &mut d.modulation,
                upload: &|gpu, g, _, values| {
                    let fit = values.len() == g.texels.dims.iter().product::<usize>();
                    if fit {
                        g.set_opacity_modulation(gpu, values);
                    }
                    Ok(fit)
                },
                clear: &|gpu, g| g.clear_opacity_modulation(gpu),
                keep_stale: false,
            },
        ) else {
            return;
        };
        let Some(doc) = &self.opened.doc else {
            return;
        };
        let (gpu, tf, step, m) = (
            Arc::clone(&self.gpu),
            doc.tf.clone(),
            doc.render.step_voxels,
            key.settings,
        );
        let job = Job::spawn("Opacity modulation", self.repaint_fn(), move |_| {
            if crate::ao::fast::twin_is_faster(&gpu) {
                return Ok(crate::ao::fast::modulation_cpu(&texels, &tf, &m));
            }
            let vol = GpuVolume::for_compute(&gpu, texels, &tf, step).map_err(|e| e.to_string())?;
            crate::ao::fast::modulation_gpu(&gpu, &vol, &tf, &m).map_err(|e| e.to_string())
        });
        self.derived.modulation.start(key, job);
    }

    /// What the light volume of shadows must be computed for, if shadows are on.
    pub(super) fn light_key(&self) -> Option<LightKey> {
        let doc = self.opened.doc.as_ref()?;
        doc.render.shadows.then(|| LightKey {
            direction: doc.view_settings().light_direction,
            opacity: doc.tf.opacity.clone(),
            clip: doc.clip_shapes.clone(),
            segments: self.segments_seen(),
            doc_generation: self.opened.generation,
        })
    }

    /// Keeps the light volume of shadows in step with the light (a headlight follows the
    /// camera), the transfer function's opacity and the clip shapes, recomputed once they
    /// rest. Unlike AO, the previous light volume stays on screen meanwhile: shadows that
    /// lag a moving camera or shape read better than shadows that blink off.
    pub(super) fn update_light(&mut self) {
        let want = self.light_key();
        if want != self.derived.light_wanted.as_ref().map(|(k, _)| k.clone()) {
            self.derived.light_wanted = want.clone().map(|k| (k, Instant::now()));
        }
        let Some((key, texels)) = self.keep_derived(
            want.as_ref(),
            DerivedVolume {
                what: "Shadows",
                slot: |d| &mut d.light,
                upload: &|gpu, g, key: &LightKey, values| {
                    let dir = glam::Vec3::from(key.direction);
                    g.set_light_volume(gpu, Some((values, dir)))
                        .map(|_| true)
                        .map_err(|e| e.to_string())
                },
                clear: &|gpu, g| {
                    // Turning shadows off cannot fail (nothing is uploaded).
                    let _ = g.set_light_volume(gpu, None);
                },
                keep_stale: true,
            },
        ) else {
            return;
        };
        let still = self
            .derived
            .light_wanted
            .as_ref()
            .is_some_and(|(_, since)| since.elapsed() >= AO_DEBOUNCE);
        if !still {
            self.ctx.request_repaint_after(AO_DEBOUNCE);
            return;
        }
        let Some(doc) = &self.opened.doc else {
            return;
        };
        let (gpu, tf) = (Arc::clone(&self.gpu), doc.tf.clone());
        let (shapes, radius, resolution) = (key.clip.clone(), doc.radius, doc.ao.clip_resolution);
        let segments = self
            .derived
            .segments
            .as_ref()
            .map(|b| Arc::clone(&b.texels));
        let dir = match crate::render::shadow::light_direction(key.direction) {
            Ok(d) => d,
            Err(message) => {
                self.toast(format!("Shadows: {message}"), true);
                return;
            }
        };
        let job = Job::spawn("Shadows", self.repaint_fn(), move |p| {
            let lut = crate::render::shadow::light_lut(&tf, &texels);
            // On the grid of the uploaded texels (halved to fit, if it was).
            let segments = segments.map(|s| match s.dims == texels.dims {
                true => SegmentTexels::clone(&s),
                false => s.subsampled(texels.dims, 1 << texels.downsampled),
            });
            // Its own clip maps, as `volao render` makes them (the margin is unused).
            let maps = match shapes.is_empty() {
                true => None,
                false => {
                    let mut m = crate::clip::gpu::ClipMaps::new(&gpu).map_err(|e| e.to_string())?;
                    let request =
                        crate::clip::gpu::MapRequest::clipping(&shapes, radius, resolution);
                    m.update(&gpu, request).map_err(|e| e.to_string())?;
                    Some(m)
                }
            };
            gpu.stage::<crate::render::shadow::LightGpu>()
                .and_then(|l| {
                    let progress = |d: usize, t: usize| p.set(d as u64, t as u64);
                    let lit = crate::render::shadow::Lit {
                        texels: &texels,
                        segments: segments.as_ref(),
                        lut: &lut,
                    };
                    l.compute(&gpu, lit, dir, maps.as_ref(), &progress)
                })
                .map_err(|e| e.to_string())
        });
        self.derived.light.start(key, job);
    }

    /// One frame of a volume derived from the document in the background (opacity
    /// modulation, the light volume): uploads a finished result, drops a stale one (or
    /// keeps it on screen with `keep_stale` until the next arrives, clearing it only when
    /// nothing is wanted), and returns the key and texels to start a job for when one is
    /// due and the transfer function rests.
    fn keep_derived<K: Clone + PartialEq>(
        &mut self,
        want: Option<&K>,
        d: DerivedVolume<'_, K>,
    ) -> Option<(K, VolumeTexels)> {
        let slot = d.slot;
        match slot(&mut self.derived).poll(want) {
            Polled::Nothing => {}
            Polled::Ready(key, values) => {
                let gpu = Arc::clone(&self.gpu);
                let mut error = None;
                let uploaded = self.upload(|g| match (d.upload)(&gpu, g, &key, &values) {
                    Ok(fit) => fit,
                    Err(e) => {
                        error = Some(e);
                        false
                    }
                });
                if uploaded {
                    slot(&mut self.derived).uploaded(key);
                } else if let Some(e) = error {
                    self.toast(format!("{} failed: {e}", d.what), true);
                }
            }
            Polled::Failed(message) => self.toast(format!("{} failed: {message}", d.what), true),
        }
        if slot(&mut self.derived).settled(want) {
            return None;
        }
        if slot(&mut self.derived).reset() && (!d.keep_stale || want.is_none()) {
            let gpu = Arc::clone(&self.gpu);
            self.upload(|g| {
                (d.clear)(&gpu, g);
                true
            });
        }
        let key = want?.clone();
        if !self.resting() {
            return None;
        }
        Some((key, self.uploaded_texels()?))
    }

    /// Whether the transfer function has rested long enough to recompute what depends on
    /// it (asks for a repaint when it has not).
    fn resting(&self) -> bool {
        let resting =
            self.derived.tf_changed_at.elapsed() >= AO_DEBOUNCE && !self.tf_editor_dragging();
        if !resting {
            self.ctx.request_repaint_after(AO_DEBOUNCE);
        }
        resting
    }

    /// A copy of the texels the viewport's volume was made from.
    pub(super) fn uploaded_texels(&self) -> Option<VolumeTexels> {
        self.viewport.gpu.volume.as_ref().map(|g| g.texels.clone())
    }

    /// Runs `f` on the viewport's volume and redraws; false when there is none or `f`
    /// says the values did not fit.
    fn upload(&mut self, f: impl FnOnce(&mut RenderVolume) -> bool) -> bool {
        let v = &mut self.viewport.gpu;
        let done = v.volume.as_mut().is_some_and(f);
        v.touch();
        done
    }

    fn tf_editor_dragging(&self) -> bool {
        self.ctx.input(|i| i.pointer.any_down())
    }

    /// Sends the transfer function and step to the GPU volume when they changed.
    pub(super) fn sync_transfer_function(&mut self) {
        let Some(doc) = &self.opened.doc else {
            return;
        };
        let want = (doc.view_tf(), doc.render.step_voxels);
        if self.derived.uploaded_tf.as_ref() == Some(&want) {
            return;
        }
        // An image being ray-cast would start again with every edit while a curve is
        // dragged: edits go in between images, and count as motion (interactive quality).
        if !self.between_images() {
            return;
        }
        let gpu = Arc::clone(&self.gpu);
        let v = &mut self.viewport.gpu;
        if let Some(g) = &mut v.volume {
            g.set_transfer_function(&gpu, &want.0, want.1);
            v.touch();
        }
        self.derived.uploaded_tf = Some(want);
    }

    /// What the viewport should show now: the document's frame and clip shapes, at
    /// interactive quality while the view moves.
    pub(super) fn want(&self) -> Option<Want> {
        let doc = self.opened.doc.as_ref()?;
        let cao_mode = if doc.ao.method == AoMethod::LaoFull {
            CaoMode::Full
        } else {
            CaoMode::Selective
        };
        Some(Want {
            frame: Frame {
                camera: doc.camera,
                settings: doc.view_settings(),
                width: self.viewport.px.0.max(1),
                height: self.viewport.px.1.max(1),
            },
            clip: doc.clip_shapes.clone(),
            setup: ClipSetup {
                radius: doc.radius,
                resolution: doc.ao.clip_resolution,
                cao_mode,
            },
            scale: 1,
            step_factor: 1.0,
            image_interval: None,
            moving: false,
        })
    }

    /// Moves the viewport's image towards what the document says, within this frame's
    /// slice of GPU time: CAO's update when the shapes moved, then the ray cast, at
    /// interactive quality while the view moves (see [`super::viewport`]). Never
    /// waits for the GPU.
    pub(super) fn pump_viewport(&mut self) {
        let Some(mut want) = self.want() else {
            return;
        };
        if self.shots.pending.is_some() {
            // A screenshot reads the same V_AO and clip maps: they stay as they are.
            self.ctx.request_repaint();
            return;
        }
        let view = (want.frame, want.clip.clone());
        if self.viewport.motion.last.as_ref() != Some(&view) {
            self.viewport.motion.last = Some(view);
            self.viewport.motion.changed_at = Instant::now();
        }
        let moving = self.viewport.motion.changed_at.elapsed() < INTERACTIVE_REST;
        want.moving = moving;
        if moving && self.viewport.interactive.on {
            want.scale = self.interactive_scale(&want.frame);
            want.step_factor = self.viewport.interactive.step_factor;
            want.image_interval = Some(std::time::Duration::from_secs_f64(seconds_per_image(
                self.viewport.interactive.target_fps,
            )));
        }
        let v = &mut self.viewport.gpu;
        let pumped = v.pump(&self.gpu, &want, &mut self.viewport.pacer);
        let busy = v.working()
            || !v.is_current(&Want {
                scale: 1,
                ..want.clone()
            });
        // A transfer function waiting for the image being made to finish is not shown yet.
        let tf_waiting = self.segments_waiting()
            || self.opened.doc.as_ref().is_some_and(|d| {
                self.derived.uploaded_tf.as_ref() != Some(&(d.view_tf(), d.render.step_voxels))
            });
        self.viewport.current = !busy && !moving && !tf_waiting;
        if let Some(stats) = pumped.stats {
            self.derived.cao_stats = Some(stats);
            self.viewport.cao_updates += 1;
            if self.options.bench_clip_drag.is_some() {
                self.scripted.cao_updates.push(Instant::now());
            }
        }
        for e in pumped.clip_errors {
            self.toast(format!("Clip shape left out: {e}"), true);
        }
        if let Some(e) = pumped.error {
            self.toast(format!("Viewport: {e}"), true);
        }
        if let Some((seconds, scale)) = pumped.completed {
            self.scripted.images.push((Instant::now(), seconds, scale));
        }
        if busy {
            self.ctx.request_repaint();
        } else if moving {
            self.ctx.request_repaint_after(INTERACTIVE_REST);
        }
    }

    /// The scale of the interactive image: the smallest (up to 1/4 of the size on each
    /// axis) whose ray cast the measured rate finishes at the target rate.
    pub(super) fn interactive_scale(&self, frame: &Frame) -> u32 {
        let pixels = frame.width as f64 * frame.height as f64;
        interactive_scale(
            pixels,
            self.viewport.pacer.rate(super::viewport::STRIP),
            self.viewport.interactive.target_fps,
        )
    }
}

/// Seconds between images at the interactive target rate (at least half an image a
/// second).
fn seconds_per_image(target_fps: f32) -> f64 {
    1.0 / target_fps.max(0.5) as f64
}

/// The smallest reduction (1 to [`MAX_INTERACTIVE_SCALE`] on each axis) at which an
/// image of `pixels` is ray-cast at `target_fps` at the measured `rate` (pixels per
/// second); 2 before anything was measured.
fn interactive_scale(pixels: f64, rate: Option<f64>, target_fps: f32) -> u32 {
    let Some(rate) = rate.filter(|r| *r > 0.0) else {
        return 2;
    };
    let budget = seconds_per_image(target_fps);
    (1..=MAX_INTERACTIVE_SCALE)
        .find(|&s| pixels / (s * s) as f64 / rate <= budget)
        .unwrap_or(MAX_INTERACTIVE_SCALE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interactive_scale_keeps_the_target_rate_within_its_range() {
        let px = 512.0 * 512.0;
        // A GPU that casts the full image 30 times a second needs no reduction at 10/s.
        assert_eq!(interactive_scale(px, Some(px * 30.0), 10.0), 1);
        // Twice too slow for 10/s: half the size on each axis is a quarter of the work.
        assert_eq!(interactive_scale(px, Some(px * 5.0), 10.0), 2);
        // Nine times too slow: a third on each axis.
        assert_eq!(interactive_scale(px, Some(px * 10.0 / 9.0), 10.0), 3);
        // Far too slow: never below a quarter.
        assert_eq!(
            interactive_scale(px, Some(1.0), 10.0),
            MAX_INTERACTIVE_SCALE
        );
        // Nothing measured yet, or a broken rate.
        assert_eq!(interactive_scale(px, None, 10.0), 2);
        assert_eq!(interactive_scale(px, Some(0.0), 10.0), 2);
        // A lower target rate asks less reduction.
        assert_eq!(interactive_scale(px, Some(px * 5.0), 4.0), 1);
    }
}
