//! The UI around the viewport: menu bar, control panel, status bar, the viewport's
//! input and paint callback, file dialogs, the unsaved-changes prompt and toasts.

use super::document::file_name;
use super::{Document, OpenRequest, Pending, ShotSize, Viewer};
use super::{ao_panel, camera_input, screenshot, tf_editor, viewport};
use crate::render::{Camera, RenderMode, Shading};
use crate::scene::Light;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use viewport::ViewportCallback;

/// The place of this frame's viewport image among the shapes: reserved while the UI is
/// laid out, under the clip outlines, and filled after the viewport's pump.
pub(super) struct ViewportSlot {
    painter: egui::Painter,
    index: egui::layers::ShapeIdx,
    rect: egui::Rect,
}

impl Viewer {
    pub(super) fn handle_input(&mut self, ui: &egui::Ui) {
        let ctx = ui.ctx().clone();
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_owned())
                .collect()
        });
        if let Some(p) = dropped.into_iter().next() {
            self.open(OpenRequest::for_path(p));
        }
        let (open, save, shot) = ctx.input_mut(|i| {
            (
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::O),
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::S),
                i.consume_key(egui::Modifiers::NONE, egui::Key::F12),
            )
        });
        if open {
            self.open_dialog();
        }
        if save {
            self.save_dialog(false);
        }
        self.chrome.slices.handle_keys(&ctx);
        if shot {
            let path = self.next_screenshot_path();
            self.request_screenshot(path, self.shots.size);
        }
        if ctx.input(|i| i.viewport().close_requested())
            && self.has_unsaved_changes()
            && !self.chrome.quit_confirmed
        {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.chrome.prompt = Some(Pending::Quit);
        }
    }

    fn open_dialog(&mut self) {
        let picked = rfd::FileDialog::new()
            .set_title("Open a volume or a scene")
            .add_filter(
                "Volumes and scenes",
                &[
                    "nii", "gz", "hdr", "img", "nrrd", "nhdr", "dcm", "mgh", "mgz", "pvm", "raw",
                    "dat", "json",
                ],
            )
            .add_filter("All files", &["*"])
            .pick_file();
        if let Some(p) = picked {
            self.open(OpenRequest::for_path(p));
        }
    }

    /// Save dialog for the scene; with `then_quit`, closes after saving (the prompt).
    fn save_dialog(&mut self, then_quit: bool) -> bool {
        let Some(doc) = &self.opened.doc else {
            return false;
        };
        let start = doc
            .scene_path
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("{}.json", doc.title)));
        let picked = rfd::FileDialog::new()
            .set_title("Save scene")
            .set_file_name(file_name(&start))
            .add_filter("volao scene", &["json"])
            .save_file();
        let Some(path) = picked else {
            return false;
        };
        match self.save_scene(&path) {
            Ok(()) => {
                if then_quit {
                    self.chrome.quit_confirmed = true;
                    self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                }
                true
            }
            Err(e) => {
                self.toast(format!("Scene not saved: {e}"), true);
                false
            }
        }
    }

    fn screenshot_dialog(&mut self) {
        let picked = rfd::FileDialog::new()
            .set_title("Save screenshot")
            .set_directory(&self.options.screenshot_dir)
            .set_file_name("volao.png")
            .add_filter("PNG image", &["png"])
            .save_file();
        if let Some(p) = picked {
            self.request_screenshot(p, self.shots.size);
        }
    }

    pub(super) fn menu_bar(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open…  (Ctrl+O)").clicked() {
                    self.open_dialog();
                }
                if ui.button("Open folder…  (DICOM series)").clicked() {
                    let picked = rfd::FileDialog::new()
                        .set_title("Open a folder of DICOM files")
                        .pick_folder();
                    if let Some(p) = picked {
                        self.open(OpenRequest::for_path(p));
                    }
                }
                ui.menu_button("Open recent", |ui| {
                    if self.chrome.recent.is_empty() {
                        ui.weak("(none yet)");
                    }
                    for p in self.chrome.recent.clone() {
                        if ui.button(p.display().to_string()).clicked() {
                            self.open(OpenRequest::for_path(p));
                        }
                    }
                });
                if ui.button("Open demo volume").clicked() {
                    self.open(OpenRequest::Demo);
                }
                ui.separator();
                if ui.button("Save scene…  (Ctrl+S)").clicked() {
                    self.save_dialog(false);
                }
                if ui.button("Screenshot…").clicked() {
                    self.screenshot_dialog();
                }
                ui.separator();
                if ui.button("Quit").clicked() {
                    ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                }
            });
            ui.menu_button("View", |ui| {
                for layout in super::slices::Layout::ALL {
                    let on = self.chrome.slices.layout == layout;
                    if ui.radio(on, layout.name()).clicked() {
                        self.chrome.slices.layout = layout;
                        self.chrome.slices.maximised = None;
                    }
                }
                ui.weak("Ctrl+L: next layout · Ctrl+M: maximise the pane under the pointer");
                ui.separator();
                let Some(doc) = &mut self.opened.doc else {
                    ui.weak("(no volume)");
                    return;
                };
                for v in camera_input::StandardView::ALL {
                    if ui.button(v.name()).clicked() {
                        v.apply(&mut doc.camera);
                    }
                }
                ui.separator();
                if ui.button("Reset camera").clicked() {
                    camera_input::reset(&mut doc.camera);
                }
                ui.checkbox(&mut doc.camera.orthographic, "Orthographic");
            });
        });
    }

    pub(super) fn side_panel(&mut self, ui: &mut egui::Ui) {
        let viewport_px = self.viewport.px;
        let ao_stats = self.ao_stats();
        let light_status = match self.light_error() {
            Some(e) => format!("failed: {e}"),
            None if self.derived.light.computing() => "computing the light volume…".to_owned(),
            None => String::new(),
        };
        let modulation_status = match self.modulation_error() {
            Some(e) => format!("failed: {e}"),
            None if self.derived.modulation.computing() => "computing…".to_owned(),
            None => String::new(),
        };
        let Some(doc) = &mut self.opened.doc else {
            ui.spinner();
            return;
        };
        ui.heading(&doc.title);
        ui.weak(&doc.info);
        ui.separator();
        egui::CollapsingHeader::new("Layout and slices")
            .default_open(false)
            .show(ui, |ui| {
                self.chrome.slices.panel(ui, doc.segmentation.is_some())
            });
        egui::CollapsingHeader::new("Camera")
            .default_open(true)
            .show(ui, |ui| {
                ui.horizontal_wrapped(|ui| {
                    for v in camera_input::StandardView::ALL {
                        if ui.button(v.name()).clicked() {
                            v.apply(&mut doc.camera);
                        }
                    }
                });
                ui.horizontal(|ui| {
                    if ui.button("Reset").clicked() {
                        camera_input::reset(&mut doc.camera);
                    }
                    ui.selectable_value(&mut doc.camera.orthographic, false, "Perspective");
                    ui.selectable_value(&mut doc.camera.orthographic, true, "Orthographic");
                });
            });
        egui::CollapsingHeader::new("Transfer function")
            .default_open(true)
            .show(ui, |ui| {
                if self
                    .chrome
                    .tf_editor
                    .show(ui, &mut doc.tf, &doc.histogram, &doc.stats)
                {
                    self.derived.tf_changed_at = Instant::now();
                }
                tf_editor::modulation_controls(
                    ui,
                    &mut doc.render.opacity_modulation,
                    &modulation_status,
                );
            });
        if let Some(seg) = &mut doc.segmentation {
            egui::CollapsingHeader::new("Segments")
                .default_open(true)
                .show(ui, |ui| self.chrome.segments_panel.show(ui, seg));
        }
        egui::CollapsingHeader::new("Ambient occlusion")
            .default_open(true)
            .show(ui, |ui| {
                ao_panel::show(
                    ui,
                    &mut doc.ao,
                    &mut doc.render.ambient,
                    &mut doc.render.ao_strength,
                    &mut doc.render.ao_offset,
                    &mut doc.ao_only,
                    &ao_stats,
                );
            });
        egui::CollapsingHeader::new("Rendering").show(ui, |ui| {
            let tf_iso = doc.view_tf().half_opacity_value().unwrap_or(0.0);
            let readable = crate::render::readable_window(doc.render.mode, &doc.tf, &doc.stats);
            let r = &mut doc.render;
            ui.add(ao_panel::slider(&mut r.step_voxels, 0.1..=2.0).text("Step (voxels)"));
            mode_controls(ui, &mut r.mode, tf_iso);
            if let Some((_, note)) = readable {
                ui.weak(note);
            }
            ui.horizontal(|ui| {
                ui.label("Shading");
                ui.selectable_value(&mut r.shading, Shading::Phong, "Phong");
                ui.selectable_value(&mut r.shading, Shading::None, "None");
            });
            ui.checkbox(&mut r.jitter, "Jittered ray start");
            ui.horizontal(|ui| {
                ui.label("Background");
                let mut rgb = r
                    .background
                    .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8);
                let mut c = [rgb[0], rgb[1], rgb[2]];
                if egui::color_picker::color_edit_button_srgb(ui, &mut c).changed() {
                    rgb[..3].copy_from_slice(&c);
                    r.background = [
                        rgb[0] as f32 / 255.0,
                        rgb[1] as f32 / 255.0,
                        rgb[2] as f32 / 255.0,
                        r.background[3],
                    ];
                }
            });
            shadow_controls(ui, doc, &light_status);
            interactive_controls(ui, &mut self.viewport.interactive);
        });
        let radius = doc.radius;
        let labels = doc.segmentation.as_ref().map(|s| Arc::clone(&s.labels));
        egui::CollapsingHeader::new("Clipping")
            .default_open(true)
            .show(ui, |ui| {
                self.chrome
                    .clip_editor
                    .panel(ui, &mut doc.clip_shapes, radius, labels.as_deref());
            });
        egui::CollapsingHeader::new("Screenshot")
            .default_open(true)
            .show(ui, |ui| {
                let label = |s: ShotSize| match s {
                    ShotSize::Window => format!("Window ({}×{})", viewport_px.0, viewport_px.1),
                    ShotSize::Fixed(w, h) => format!("{w}×{h}"),
                };
                egui::ComboBox::from_label("Size")
                    .selected_text(label(self.shots.size))
                    .show_ui(ui, |ui| {
                        ui.selectable_value(
                            &mut self.shots.size,
                            ShotSize::Window,
                            label(ShotSize::Window),
                        );
                        for (w, h) in screenshot::PRESET_SIZES {
                            let s = ShotSize::Fixed(w, h);
                            ui.selectable_value(&mut self.shots.size, s, label(s));
                        }
                    });
                if let ShotSize::Fixed(w, h) = &mut self.shots.size {
                    ui.horizontal(|ui| {
                        ui.label("Width");
                        ui.add(egui::DragValue::new(w).range(1..=screenshot::MAX_SIDE))
                            .accessible_name("Width");
                        ui.label("Height");
                        ui.add(egui::DragValue::new(h).range(1..=screenshot::MAX_SIDE))
                            .accessible_name("Height");
                    });
                }
                ui.checkbox(&mut self.shots.transparent, "Transparent background");
                ui.horizontal(|ui| {
                    if ui.button("Screenshot…").clicked() {
                        self.screenshot_dialog();
                    }
                    if ui
                        .button("Quick (F12)")
                        .on_hover_text("Saves volao-N.png and its scene in the screenshot folder")
                        .clicked()
                    {
                        let path = self.next_screenshot_path();
                        self.request_screenshot(path, self.shots.size);
                    }
                });
                if let Some(shot) = &self.shots.failed
                    && self.shots.write_job.is_none()
                {
                    let name = file_name(&shot.path);
                    if ui
                        .button(format!("Save elsewhere… (unsaved {name})"))
                        .clicked()
                        && let Some(p) = rfd::FileDialog::new()
                            .set_file_name(&name)
                            .add_filter("PNG image", &["png"])
                            .save_file()
                    {
                        self.retry_screenshot(p);
                    }
                }
            });
    }

    fn ao_stats(&self) -> ao_panel::AoStats {
        let (ao, want) = (&self.derived.ao, self.ao_key());
        let status = match ao.job() {
            Some(job) => match job.fraction() {
                Some(f) => format!("computing… {:.0} %", f * 100.0),
                None => "computing…".into(),
            },
            None if want.is_none() => "off".into(),
            None if ao.ready(want.as_ref()) => "ready".into(),
            None => match ao.error(want.as_ref()) {
                Some(message) => format!("failed: {message}"),
                None => "waiting for the transfer function to rest".into(),
            },
        };
        let frames = self.viewport.gpu.frames_rendered;
        ao_panel::AoStats {
            frame_ms: self.viewport.frame_ms,
            frames,
            ao_seconds: self.derived.ao_seconds.as_ref().map(|(s, _)| *s),
            ao_device: self.derived.ao_seconds.as_ref().map(|(_, d)| d.clone()),
            // Precomputed AO: a frame recomputes no voxel; CAO reports its own share.
            recomputed_percent: match (ao.on_gpu(), &self.derived.cao_stats) {
                (Some(key), Some(c)) if key.clipping => Some(c.percent_recomputed()),
                (Some(_), _) => Some(0.0),
                _ => None,
            },
            stages: self
                .derived
                .cao_stats
                .as_ref()
                .filter(|_| self.ao_key().is_some_and(|k| k.clipping))
                .map(|c| {
                    format!(
                        "maps {:.0} ms, clip {:.0} ms, LAO {:.0} ms",
                        c.maps_seconds * 1e3,
                        c.clip_seconds * 1e3,
                        c.lao_seconds * 1e3
                    )
                }),
            status,
        }
    }

    pub(super) fn status_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let mut cancel_load = false;
            let mut cancel_ao = false;
            if let Some(job) = &self.opened.load_job {
                ui.label(&job.label);
                progress_bar(ui, job.fraction());
                cancel_load = ui.button("Cancel").clicked();
            }
            if let Some(job) = self.derived.ao.job() {
                ui.label(&job.label);
                progress_bar(ui, job.fraction());
                cancel_ao = ui.button("Cancel").clicked();
            }
            if let Some(text) = self.ao_shown_text() {
                ui.label(text);
            }
            self.view_status(ui);
            if self.chrome.slices.layout != super::slices::Layout::ThreeD
                && let Some(doc) = &self.opened.doc
                && let Some(text) = super::slices::readout(&self.chrome.slices, doc)
            {
                ui.label(format!("Crosshair: {text}"));
            }
            if let Some(text) = &self.chrome.hover.text {
                ui.label(format!("Under the pointer: {text}"));
            }
            if let Some(note) = self.opened.doc.as_ref().and_then(|d| d.note.as_deref()) {
                ui.weak(note);
            }
            if let Some(shot) = &self.shots.pending {
                ui.label(format!("Rendering {}", file_name(shot.path())));
                progress_bar(ui, Some(shot.fraction()));
            }
            if let Some(job) = &self.shots.write_job {
                ui.label(&job.label);
                ui.spinner();
            }
            if cancel_load && let Some(job) = self.opened.load_job.take() {
                job.cancel();
                self.toast("Loading cancelled".into(), false);
            }
            if cancel_ao {
                self.derived.ao.cancel();
                // Keep the method but stop retrying until something changes.
                if let Some(key) = self.ao_key() {
                    self.derived.ao.fail(key, "cancelled".into());
                }
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                ui.weak(&self.gpu.info.name);
                if let Some(e) = &self.viewport.gpu.last_error {
                    ui.colored_label(ui.visuals().error_fg_color, e);
                }
            });
        });
    }

    /// The viewport's image: how far a slow one is (on a CPU adapter an image with CAO's
    /// update takes seconds), and whether the one drawn is at interactive quality.
    fn view_status(&self, ui: &mut egui::Ui) {
        let v = &self.viewport.gpu;
        let (work, scale, ao_exact) = (v.work_fraction(), v.shown_scale(), v.shown_ao_exact());
        let waited = self
            .scripted
            .images
            .last()
            .is_none_or(|(t, _, _)| t.elapsed() > Duration::from_millis(500));
        if let Some((fraction, in_cao)) = work
            && waited
        {
            ui.label(match in_cao {
                true => "View: updating Contextual AO",
                false => "View: ray casting",
            });
            progress_bar(ui, Some(fraction));
        } else if !ao_exact {
            ui.weak("View: precomputed AO (without the cut) until Contextual AO catches up");
        } else if scale > 1 {
            ui.weak(format!("View: interactive quality (1/{scale} resolution)"));
        }
    }

    /// The viewport: its input, a place for its image under the clip outlines (filled by
    /// [`Self::paint_viewport`] once the frame's pump has run), the outlines.
    pub(super) fn viewport(&mut self, ui: &mut egui::Ui, rect: egui::Rect) -> Option<ViewportSlot> {
        self.viewport.rect = rect;
        let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
        response
            .widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, true, "3-D viewport"));
        let ppp = ui.ctx().pixels_per_point();
        let screen = ui.ctx().content_rect().size() * ppp;
        self.viewport.px = viewport::size_in_pixels(
            rect,
            ppp,
            [screen.x.round() as u32, screen.y.round() as u32],
        );
        let hovering_files = ui.ctx().input(|i| !i.raw.hovered_files.is_empty());
        let Some(doc) = &mut self.opened.doc else {
            ui.put(rect, egui::Spinner::new().size(32.0));
            return None;
        };
        let used = self.chrome.clip_editor.handle(
            ui,
            &response,
            &doc.camera,
            doc.radius,
            &mut doc.clip_shapes,
        );
        // Shift-click or double-click: the crosshair to the surface under the pointer.
        let pick =
            response.double_clicked() || (response.clicked() && ui.input(|i| i.modifiers.shift));
        let mut pick_error = None;
        if pick && let Some(p) = response.interact_pointer_pos() {
            // The pixel of the full-quality image under the pointer, cast on the GPU as
            // that image casts it; a later frame reads where it stopped.
            let (w, h) = (self.viewport.px.0.max(1), self.viewport.px.1.max(1));
            let pixel = super::slices::pixel_under(rect, p, (w, h));
            let frame = crate::render::Frame {
                camera: doc.camera,
                settings: doc.view_settings(),
                width: w,
                height: h,
            };
            let v = &self.viewport.gpu;
            if let Some(volume) = &v.volume {
                let draw = crate::render::gpu::PickDraw {
                    volume,
                    frame: &frame,
                    clip: v.clip_maps(),
                    pixel,
                };
                let id = Arc::as_ptr(&doc.volume) as usize;
                let started = self
                    .chrome
                    .slices
                    .start_pick(&self.gpu, &v.ray_caster, draw, id);
                pick_error = started.err();
            }
        } else if !used {
            camera_input::handle(ui, &response, &mut doc.camera, doc.radius);
        }
        let slot = ViewportSlot {
            painter: ui.painter().clone(),
            index: ui.painter().add(egui::Shape::Noop),
            rect,
        };
        if self.show_outlines {
            self.chrome.clip_editor.paint(
                &ui.painter().with_clip_rect(rect),
                rect,
                &doc.camera,
                doc.radius,
                &doc.clip_shapes,
            );
        }
        if self.show_outlines
            && let Some(doc) = &self.opened.doc
        {
            super::slices::paint_3d(
                &ui.painter().with_clip_rect(rect),
                rect,
                &self.chrome.slices,
                doc,
            );
        }
        if let Some(e) = pick_error {
            self.toast(format!("Picking failed: {e}"), true);
        }
        if hovering_files {
            ui.painter()
                .rect_filled(rect, 0.0, egui::Color32::from_black_alpha(160));
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "Drop to open",
                egui::FontId::proportional(28.0),
                egui::Color32::WHITE,
            );
        }
        // Frame time: the interval between frames that ray-cast something new.
        let frames = self.viewport.gpu.frames_rendered;
        if frames > self.viewport.frames_seen {
            let dt = ui.ctx().input(|i| i.unstable_dt) * 1e3;
            if self.viewport.frames_seen > 0 && frames == self.viewport.frames_seen + 1 {
                self.viewport.frame_ms = Some(match self.viewport.frame_ms {
                    Some(m) => 0.8 * m + 0.2 * dt,
                    None => dt,
                });
            }
            self.viewport.frames_seen = frames;
        }
        Some(slot)
    }

    /// Puts this frame's paint callback in the viewport's place: the last complete image,
    /// as this frame's pump left it.
    pub(super) fn paint_viewport(&self, slot: Option<ViewportSlot>) {
        let Some(ViewportSlot {
            painter,
            index,
            rect,
        }) = slot
        else {
            return;
        };
        let image = self.viewport.gpu.paint_image();
        painter.set(
            index,
            egui_wgpu::Callback::new_paint_callback(rect, ViewportCallback { rect, image }),
        );
    }

    pub(super) fn show_prompt(&mut self, ctx: &egui::Context) {
        let Some(pending) = self.chrome.prompt.clone() else {
            return;
        };
        let what = match &pending {
            Pending::Quit => "before quitting".to_owned(),
            Pending::Open(r) => format!("before opening {}", r.label()),
        };
        let mut choice = None;
        egui::Modal::new(egui::Id::unique("unsaved_changes")).show(ctx, |ui| {
            ui.heading("Unsaved changes");
            ui.label(format!(
                "The scene has changes that are not saved. Save them {what}?"
            ));
            ui.horizontal(|ui| {
                if ui.button("Save…").clicked() {
                    choice = Some(0);
                }
                if ui.button("Discard").clicked() {
                    choice = Some(1);
                }
                if ui.button("Cancel").clicked() {
                    choice = Some(2);
                }
            });
        });
        match choice {
            Some(0) if self.save_dialog(false) => {
                self.chrome.prompt = None;
                self.proceed(pending);
            }
            // Saving was cancelled or failed: keep asking.
            Some(0) | None => {}
            Some(1) => {
                self.chrome.prompt = None;
                self.proceed(pending);
            }
            Some(_) => self.chrome.prompt = None,
        }
    }

    fn proceed(&mut self, pending: Pending) {
        match pending {
            Pending::Quit => {
                self.chrome.quit_confirmed = true;
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Pending::Open(r) => self.start_load(r),
        }
    }

    pub(super) fn show_toasts(&mut self, ctx: &egui::Context) {
        const LIFE: Duration = Duration::from_secs(8);
        self.chrome
            .toasts
            .retain(|t| t.error || t.born.elapsed() < LIFE);
        self.chrome.toasts.truncate(8);
        if self.chrome.toasts.is_empty() {
            return;
        }
        let mut dismiss = None;
        egui::Area::new(egui::Id::unique("toasts"))
            .anchor(egui::Align2::RIGHT_BOTTOM, egui::vec2(-12.0, -36.0))
            .show(ctx, |ui| {
                for (i, t) in self.chrome.toasts.iter().enumerate() {
                    egui::Frame::popup(ui.style()).show(ui, |ui| {
                        ui.set_max_width(420.0);
                        ui.horizontal(|ui| {
                            if t.error {
                                ui.colored_label(ui.visuals().error_fg_color, &t.text);
                            } else {
                                ui.label(&t.text);
                            }
                            if ui.small_button("×").clicked() {
                                dismiss = Some(i);
                            }
                        });
                    });
                }
            });
        if let Some(i) = dismiss {
            self.chrome.toasts.remove(i);
        }
        if self.chrome.toasts.iter().any(|t| !t.error) {
            ctx.request_repaint_after(Duration::from_secs(1));
        }
    }

    pub(super) fn update_title(&mut self, ctx: &egui::Context) {
        let title = match &self.opened.doc {
            Some(d) => format!(
                "{}{} — volao",
                d.title,
                if self.has_unsaved_changes() {
                    " •"
                } else {
                    ""
                }
            ),
            None => "volao".into(),
        };
        if title != self.chrome.last_title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.chrome.last_title = title;
        }
    }
}

/// Interactive quality: a lower resolution while the view moves, chosen to keep the
/// viewport at a target rate (the full-quality image follows when it rests).
fn interactive_controls(ui: &mut egui::Ui, q: &mut super::viewport::Interactive) {
    ui.checkbox(&mut q.on, "Interactive quality while moving")
        .on_hover_text(
            "While the camera or a clip shape moves, the volume is drawn at a lower \
             resolution, chosen from the measured speed to keep the target rate, and \
             with a longer step; a quarter of a second after the last move the \
             full-quality image follows (the same pixels as volao render).",
        );
    ui.add_enabled(
        q.on,
        egui::Slider::new(&mut q.target_fps, 1.0..=60.0)
            .logarithmic(true)
            .text("Target rate (images/s)"),
    )
    .on_hover_text(
        "Images per second wanted while the view moves. While Contextual AO catches up \
         with a dragged clip shape, images come at most this often and the rest of the \
         GPU's time goes to the AO.",
    );
    ui.add_enabled(
        q.on,
        egui::Slider::new(
            &mut q.step_factor,
            1.0..=super::viewport::MAX_INTERACTIVE_STEP,
        )
        .text("Step while moving (× full quality)"),
    )
    .on_hover_text(
        "How much longer the ray-cast step is while the view moves. Opacity is \
         corrected for it, so the picture keeps its look; thin structures may flicker.",
    );
}

/// Shadows on or off, and where the light comes from: the eye (a headlight, as `volao
/// render` without `--light`) or a fixed direction by azimuth and elevation (as the
/// camera's, volume RAS).
fn shadow_controls(ui: &mut egui::Ui, doc: &mut Document, status: &str) {
    ui.checkbox(&mut doc.render.shadows, "Shadows");
    if !doc.render.shadows {
        return;
    }
    let mut fixed = matches!(doc.light, Light::Directional { .. });
    ui.horizontal(|ui| {
        ui.selectable_value(&mut fixed, false, "Headlight");
        ui.selectable_value(&mut fixed, true, "Fixed light");
    });
    match (fixed, doc.light) {
        (true, Light::Headlight) => {
            doc.light = Light::Directional {
                direction: doc.camera.backward().to_array(),
            }
        }
        (false, Light::Directional { .. }) => doc.light = Light::Headlight,
        _ => {}
    }
    if let Light::Directional { direction } = &mut doc.light {
        let d = glam::Vec3::from(*direction).normalize_or(glam::Vec3::Z);
        let (mut az, mut el) = (
            d.x.atan2(d.y).to_degrees(),
            d.z.clamp(-1.0, 1.0).asin().to_degrees(),
        );
        let moved = ui
            .add(ao_panel::slider(&mut az, -180.0..=180.0).text("Light azimuth (°)"))
            .changed()
            | ui.add(ao_panel::slider(&mut el, -90.0..=90.0).text("Light elevation (°)"))
                .changed();
        if moved {
            let towards = Camera {
                azimuth_deg: az,
                elevation_deg: el,
                ..Default::default()
            };
            *direction = towards.backward().to_array();
        }
    }
    if !status.is_empty() {
        ui.weak(status);
    }
}

fn progress_bar(ui: &mut egui::Ui, fraction: Option<f32>) {
    let bar = egui::ProgressBar::new(fraction.unwrap_or(0.0))
        .desired_width(160.0)
        .show_percentage();
    ui.add(if fraction.is_none() {
        bar.animate(true)
    } else {
        bar
    });
}

/// The render modes with their names and what each shows.
const MODES: [(RenderMode, &str, &str); 5] = [
    (
        RenderMode::Composite,
        "Composite",
        "Colour and opacity of the transfer function, lit, with AO and shadows",
    ),
    (
        RenderMode::Mip,
        "Maximum intensity (MIP)",
        "The brightest value along each ray, grey over the transfer function's window",
    ),
    (
        RenderMode::Minip,
        "Minimum intensity (MinIP)",
        "The darkest value along each ray (airways); clip with a probe to look inside",
    ),
    (
        RenderMode::Average,
        "Average intensity",
        "The mean value along each ray: a simulated radiograph",
    ),
    (
        RenderMode::Iso(None),
        "Isosurface",
        "The first surface at a value, lit, coloured by the transfer function, with AO",
    ),
];

/// The mode and, for iso, its value (`tf_iso`: the transfer function's own).
fn mode_controls(ui: &mut egui::Ui, mode: &mut RenderMode, tf_iso: f64) {
    let name = |m: RenderMode| {
        MODES
            .iter()
            .find(|(k, ..)| k.code() == m.code())
            .map_or("", |(_, name, _)| *name)
    };
    egui::ComboBox::from_label("Mode")
        .selected_text(name(*mode))
        .show_ui(ui, |ui| {
            for (m, label, tip) in MODES {
                let chosen = mode.code() == m.code();
                if ui
                    .selectable_label(chosen, label)
                    .on_hover_text(tip)
                    .clicked()
                    && !chosen
                {
                    *mode = m;
                }
            }
        });
    if let RenderMode::Iso(value) = mode {
        ui.horizontal(|ui| {
            let mut auto = value.is_none();
            ui.checkbox(&mut auto, "Value from the transfer function")
                .on_hover_text("Where its opacity first reaches half its maximum");
            match (auto, value.as_mut()) {
                (true, _) => *value = None,
                (false, Some(v)) => {
                    ui.add(egui::DragValue::new(v).speed(1.0));
                }
                (false, None) => *value = Some(tf_iso),
            }
        });
    }
}
