//! The slice panes: axial, coronal and sagittal views beside the 3-D view (2×2 by
//! default, 3-D only, or 1 + 3), in patient orientation ([`crate::slice`]) with one
//! crosshair shared by every pane (a point in patient mm).
//!
//! A click or drag in a slice moves the crosshair, the mouse wheel pages through slices,
//! a shift-click or double-click in the 3-D view picks the first visible surface under
//! the pointer ([`crate::slice::pick`]). Clip shapes show as their cross-sections: drag
//! inside one to move it, drag its outline to resize it; the context menu places a new
//! shape at the crosshair or cuts along the slice. The slices are cut on the CPU (a
//! slice is at most a few hundred thousand samples) when what they show changes.

mod draw;
mod image;
mod panel;
mod pick;

use super::document::Document;
use super::viewport::ImageBinding;
use crate::clip::{ClipShape, Shape};
use crate::labels::style;
use crate::slice::{
    Convention, LabelOverlay, Plane, Sampling, SliceAxis, SliceGeometry, volume_to_world,
    world_to_volume,
};
use crate::texels::segments::ClassLook;
use draw::{cross_sections, orientation_marker, plane_color, scale_bar};
use egui::{Color32, Pos2, Rect, Stroke, Vec2, pos2};
use glam::{DVec3, Vec3};
use image::SliceTexture;
use pick::PendingPick;

pub use crate::slice::{Layout, Pane};
pub use pick::pixel_under;

/// Scroll (points) that pages one slice: one wheel notch.
const WHEEL_NOTCH: f32 = 40.0;

/// Points from a shape's outline within which a drag resizes it.
const EDGE_GRAB: f32 = 5.0;

/// The slice panes' settings and state.
pub struct SliceViews {
    pub layout: Layout,
    pub maximised: Option<Pane>,
    /// The crosshair in patient mm (RAS); `None` until a volume is shown (then its centre).
    pub crosshair: Option<DVec3>,
    pub convention: Convention,
    pub sampling: Sampling,
    pub plane: Plane,
    /// The slices use the transfer function's window/level; unticked, their own.
    pub linked_window: bool,
    /// The slices' own (window, level).
    pub window: (f64, f64),
    pub show_labels: bool,
    pub label_opacity: f32,
    pub outline: bool,
    pub show_crosshair: bool,
    /// Orientation marker in the 3-D pane, scale bars in the slices.
    pub show_markers: bool,
    geometry: Option<(usize, Plane, SliceGeometry)>,
    images: [Option<(Key, SliceTexture)>; 3],
    /// The segments' looks as of the UI frame numbered first (one computation a frame
    /// for all panes).
    looks: Option<(u64, Option<Vec<ClassLook>>)>,
    sections: [Option<(SectionKey, Vec<[Pos2; 2]>)>; 3],
    drag: Option<Drag>,
    /// Scroll not yet turned into pages.
    wheel: f32,
    /// The pane rectangles of the last frame (for the maximise key).
    last_rects: Vec<(Pane, Rect)>,
    /// A pick in the 3-D view submitted to the GPU, not read yet.
    pick: Option<PendingPick>,
}

impl std::fmt::Debug for SliceViews {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SliceViews")
            .field("layout", &self.layout)
            .field("maximised", &self.maximised)
            .field("crosshair", &self.crosshair)
            .finish_non_exhaustive()
    }
}

impl Default for SliceViews {
    fn default() -> Self {
        SliceViews {
            layout: Layout::Quad,
            maximised: None,
            crosshair: None,
            convention: Convention::Radiological,
            sampling: Sampling::Nearest,
            plane: Plane::Patient,
            linked_window: true,
            window: (400.0, 40.0),
            show_labels: true,
            label_opacity: LabelOverlay::DEFAULT_OPACITY,
            outline: false,
            show_crosshair: true,
            show_markers: true,
            geometry: None,
            images: Default::default(),
            looks: None,
            sections: Default::default(),
            drag: None,
            wheel: 0.0,
            last_rects: Vec::new(),
            pick: None,
        }
    }
}

/// What a slice image shows: it is cut again when this changes.
#[derive(Debug, Clone, PartialEq)]
struct Key {
    volume: usize,
    index: usize,
    convention: Convention,
    sampling: Sampling,
    plane: Plane,
    window: (f64, f64),
    labels: Option<(Vec<ClassLook>, bool, u32)>,
}

/// What a slice's shape outlines depend on: they are traced again when this changes.
#[derive(Debug, Clone, PartialEq)]
struct SectionKey {
    volume: usize,
    index: usize,
    convention: Convention,
    plane: Plane,
    shapes: Vec<ClipShape>,
}

#[derive(Debug, Clone)]
enum Drag {
    Crosshair(SliceAxis),
    Move {
        shape: usize,
        axis: SliceAxis,
        last: DVec3,
    },
    Resize {
        shape: usize,
        axis: SliceAxis,
        centre: DVec3,
        from: f64,
        scale: [f32; 3],
    },
}

/// Where a slice image sits in its pane: `rect` on screen, `scale` points per pixel.
#[derive(Debug, Clone, Copy)]
struct Placed {
    rect: Rect,
    scale: f32,
}

impl Placed {
    fn to_screen(self, pixel: [f64; 2]) -> Pos2 {
        self.rect.min + Vec2::new(pixel[0] as f32 + 0.5, pixel[1] as f32 + 0.5) * self.scale
    }

    fn to_pixel(self, p: Pos2) -> [f64; 2] {
        let v = (p - self.rect.min) / self.scale;
        [v.x as f64 - 0.5, v.y as f64 - 0.5]
    }
}

impl SliceViews {
    /// The panes and their rectangles in `rect`.
    pub fn pane_rects(&mut self, rect: Rect, volume_open: bool) -> Vec<(Pane, Rect)> {
        let rects = if !volume_open {
            vec![(Pane::ThreeD, rect)]
        } else if let Some(p) = self.maximised.filter(|_| self.layout != Layout::ThreeD) {
            vec![(p, rect)]
        } else {
            let r = [rect.left(), rect.top(), rect.right(), rect.bottom()];
            self.layout
                .panes(r)
                .into_iter()
                .map(|(p, [l, t, rr, b])| (p, Rect::from_min_max(pos2(l, t), pos2(rr, b))))
                .collect()
        };
        self.last_rects = rects.clone();
        rects
    }

    /// The layout key (Ctrl+L cycles the layouts) and the maximise key (Ctrl+M toggles
    /// the pane under the pointer).
    pub fn handle_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (layout, maximise) = ctx.input_mut(|i| {
            (
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::L),
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::M),
            )
        });
        if layout {
            self.layout = self.layout.next();
            self.maximised = None;
        }
        if maximise {
            let hovered = ctx.pointer_hover_pos().and_then(|p| {
                self.last_rects
                    .iter()
                    .find(|(_, r)| r.contains(p))
                    .map(|(pane, _)| *pane)
            });
            self.toggle_maximised(hovered);
        }
    }

    fn toggle_maximised(&mut self, pane: Option<Pane>) {
        self.maximised = if self.maximised.is_some() { None } else { pane };
    }

    /// The grid of the document's volume, made again when the volume or plane changes.
    fn geometry(&mut self, doc: &Document) -> SliceGeometry {
        let id = std::sync::Arc::as_ptr(&doc.volume) as usize;
        match &self.geometry {
            Some((v, p, g)) if *v == id && *p == self.plane => g.clone(),
            _ => {
                let g = SliceGeometry::new(&doc.volume, self.plane);
                if self
                    .crosshair
                    .is_none_or(|c| g.nearest_voxel(c).is_none() || self.geometry.is_none())
                {
                    self.crosshair = Some(g.centre());
                }
                self.geometry = Some((id, self.plane, g.clone()));
                g
            }
        }
    }

    /// A new volume: the crosshair goes back to its centre.
    pub fn reset(&mut self) {
        self.crosshair = None;
        self.geometry = None;
        self.drag = None;
    }

    /// The window the slices show.
    pub fn window_level(&self, doc: &Document) -> (f64, f64) {
        if self.linked_window {
            doc.tf.window_level()
        } else {
            self.window
        }
    }

    /// Where each pane was drawn last frame.
    pub fn panes(&self) -> &[(Pane, Rect)] {
        &self.last_rects
    }

    /// The grid slices are cut on (once a volume has been shown).
    pub fn grid(&self) -> Option<&SliceGeometry> {
        self.geometry.as_ref().map(|(_, _, g)| g)
    }

    /// Sets the crosshair to `world` (patient mm).
    pub fn set_crosshair(&mut self, world: DVec3) {
        self.crosshair = Some(world);
    }

    /// The segments' looks over the slices (`None`: no overlay), computed once a frame.
    fn looks(&mut self, doc: &Document, frame: u64) -> Option<Vec<ClassLook>> {
        if let Some((f, looks)) = &self.looks
            && *f == frame
        {
            return looks.clone();
        }
        let looks = doc
            .segmentation
            .as_ref()
            .filter(|_| self.show_labels)
            .map(|s| style::looks(&s.labels, &s.classes, &s.styles, &[]));
        self.looks = Some((frame, looks.clone()));
        looks
    }

    /// Draws the slice pane of `axis` in `rect` and handles its input; `true` if it
    /// changed the clip shapes. Its image goes to the GPU (`gpu`, bound with the
    /// viewport's `binding`) when what it shows changes.
    pub fn show(
        &mut self,
        ui: &mut egui::Ui,
        doc: &mut Document,
        axis: SliceAxis,
        rect: Rect,
        gpu: &crate::gpu::Gpu,
        binding: &ImageBinding,
    ) -> bool {
        let geometry = self.geometry(doc);
        let crosshair = self.crosshair.unwrap_or_else(|| geometry.centre());
        let index = geometry.index_at(axis, crosshair);
        let slot = SliceAxis::ALL.iter().position(|a| *a == axis).unwrap_or(0);
        let looks = self.looks(doc, ui.ctx().cumulative_frame_nr());
        let key = Key {
            volume: std::sync::Arc::as_ptr(&doc.volume) as usize,
            index,
            convention: self.convention,
            sampling: self.sampling,
            plane: self.plane,
            window: self.window_level(doc),
            labels: looks
                .clone()
                .map(|l| (l, self.outline, self.label_opacity.to_bits())),
        };
        let section_key = SectionKey {
            volume: key.volume,
            index,
            convention: self.convention,
            plane: self.plane,
            shapes: doc.clip_shapes.clone(),
        };
        let [w, h] = geometry.image_size(axis);
        if self.images[slot].as_ref().is_none_or(|(k, _)| *k != key) {
            let slice = geometry.cut(&doc.volume, axis, self.convention, index, self.sampling);
            let overlay = match (&doc.segmentation, &looks) {
                (Some(s), Some(l)) => Some(LabelOverlay {
                    classes: &s.classes.of_voxel,
                    looks: l,
                    opacity: self.label_opacity,
                    outline: self.outline,
                }),
                _ => None,
            };
            let (window, level) = key.window;
            let rgb = slice.rgb(window, level, overlay.as_ref());
            let old = self.images[slot].take().map(|(_, t)| t);
            let texture = SliceTexture::upload(gpu, binding, old, [w, h], &rgb);
            self.images[slot] = Some((key.clone(), texture));
        }
        // The shapes' cross-sections, traced again when the slice or a shape changes.
        if self.sections[slot]
            .as_ref()
            .is_none_or(|(k, _)| *k != section_key)
        {
            let segments = cross_sections(
                &geometry,
                &doc.volume,
                axis,
                self.convention,
                index,
                &doc.clip_shapes,
            );
            self.sections[slot] = Some((section_key, segments));
        }

        let response = ui.interact(
            rect,
            egui::Id::unique(("slice pane", axis.name())),
            egui::Sense::click_and_drag(),
        );
        let painter = ui.painter_at(rect);
        let ([l, t, r, b], scale) = crate::slice::fit(
            [w, h],
            [rect.left(), rect.top(), rect.right(), rect.bottom()],
        );
        let placed = Placed {
            rect: Rect::from_min_max(pos2(l, t), pos2(r, b)),
            scale,
        };
        match &self.images[slot] {
            Some((_, texture)) => {
                let nearest = self.sampling == Sampling::Nearest;
                texture.paint(&painter, rect, placed.rect, nearest);
            }
            None => {
                painter.rect_filled(rect, 0.0, Color32::BLACK);
            }
        }
        let mut changed = false;
        changed |= self.input(ui, &response, doc, &geometry, axis, index, placed);

        // Clip shapes' cross-sections.
        if let Some((_, segments)) = &self.sections[slot] {
            let stroke = Stroke::new(1.5, Color32::from_rgb(80, 200, 255));
            for [a, b] in segments {
                painter.line_segment(
                    [
                        placed.to_screen([a.x as f64, a.y as f64]),
                        placed.to_screen([b.x as f64, b.y as f64]),
                    ],
                    stroke,
                );
            }
        }
        // The crosshair: the other two planes' lines.
        let crosshair = self.crosshair.unwrap_or(crosshair);
        if self.show_crosshair {
            let c = placed.to_screen(geometry.world_to_pixel(axis, self.convention, crosshair));
            let others: Vec<SliceAxis> =
                SliceAxis::ALL.into_iter().filter(|a| *a != axis).collect();
            let [u, _] = axis.in_plane();
            for other in others {
                // The plane whose normal runs along the image's columns draws a vertical line.
                let color = plane_color(other).gamma_multiply(0.8);
                let stroke = Stroke::new(1.0, color);
                let gap = 8.0;
                if other.normal() == u {
                    painter.line_segment([pos2(c.x, rect.top()), pos2(c.x, c.y - gap)], stroke);
                    painter.line_segment([pos2(c.x, c.y + gap), pos2(c.x, rect.bottom())], stroke);
                } else {
                    painter.line_segment([pos2(rect.left(), c.y), pos2(c.x - gap, c.y)], stroke);
                    painter.line_segment([pos2(c.x + gap, c.y), pos2(rect.right(), c.y)], stroke);
                }
            }
        }
        // Orientation letters on the edges, the pane's name and slice, a scale bar.
        let letters = geometry.edge_letters(axis, self.convention);
        let font = egui::FontId::proportional(14.0);
        let text = Color32::from_gray(230);
        let m = 6.0;
        painter.text(
            pos2(rect.left() + m, rect.center().y),
            egui::Align2::LEFT_CENTER,
            letters[0],
            font.clone(),
            text,
        );
        painter.text(
            pos2(rect.right() - m, rect.center().y),
            egui::Align2::RIGHT_CENTER,
            letters[1],
            font.clone(),
            text,
        );
        painter.text(
            pos2(rect.center().x, rect.top() + m),
            egui::Align2::CENTER_TOP,
            letters[2],
            font.clone(),
            text,
        );
        painter.text(
            pos2(rect.center().x, rect.bottom() - m),
            egui::Align2::CENTER_BOTTOM,
            letters[3],
            font.clone(),
            text,
        );
        let title = format!(
            "{} {}/{}",
            capitalised(axis.name()),
            index + 1,
            geometry.count(axis)
        );
        painter.text(
            rect.left_top() + Vec2::new(m, m),
            egui::Align2::LEFT_TOP,
            title,
            egui::FontId::proportional(13.0),
            plane_color(axis),
        );
        if self.show_markers {
            scale_bar(&painter, rect, geometry.pixel_mm(axis) as f32 / scale);
        }
        // Maximise / restore.
        let button = Rect::from_min_size(
            pos2(rect.right() - 58.0, rect.top() + 4.0),
            Vec2::new(54.0, 18.0),
        );
        let maximised = self.maximised.is_some();
        if ui
            .put(
                button,
                egui::Button::new(if maximised { "Restore" } else { "Max" }).small(),
            )
            .on_hover_text(if maximised {
                "Restore the layout (Ctrl+M)"
            } else {
                "Maximise this pane (Ctrl+M)"
            })
            .clicked()
        {
            self.toggle_maximised(Some(Pane::Slice(axis)));
        }
        response.widget_info(|| {
            egui::WidgetInfo::labeled(egui::Role::Canvas, true, format!("{} slice", axis.name()))
        });
        changed
    }

    /// A slice pane's pointer: crosshair, paging, shape drags, the context menu.
    #[allow(clippy::too_many_arguments)]
    fn input(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        doc: &mut Document,
        geometry: &SliceGeometry,
        axis: SliceAxis,
        index: usize,
        placed: Placed,
    ) -> bool {
        let conv = self.convention;
        let world_at = |p: Pos2| geometry.pixel_to_world(axis, conv, index, placed.to_pixel(p));
        let mut changed = false;
        // Paging with the wheel.
        if response.hovered() {
            // One slice per wheel notch (a line), or per 40 points of a trackpad's scroll.
            let points: f32 = ui.input(|i| {
                i.raw
                    .events
                    .iter()
                    .filter_map(|e| match e {
                        egui::Event::MouseWheel { unit, delta, .. } => Some(match unit {
                            egui::MouseWheelUnit::Point => delta.y,
                            egui::MouseWheelUnit::Line => delta.y * WHEEL_NOTCH,
                            egui::MouseWheelUnit::Page => delta.y * 10.0 * WHEEL_NOTCH,
                        }),
                        _ => None,
                    })
                    .sum()
            });
            self.wheel += points;
            let steps = (self.wheel / WHEEL_NOTCH).trunc();
            self.wheel -= steps * WHEEL_NOTCH;
            let scroll = steps;
            if scroll != 0.0 {
                let n = geometry.count(axis);
                let next = (index as f32 + scroll).clamp(0.0, (n - 1) as f32) as usize;
                let mut c = self.crosshair.unwrap_or_else(|| geometry.centre());
                c[axis.normal()] = geometry.position(axis, next);
                self.crosshair = Some(c);
            }
        }
        if response.drag_started_by(egui::PointerButton::Primary) || response.clicked() {
            let origin = ui
                .input(|i| i.pointer.press_origin())
                .or(response.interact_pointer_pos());
            if let Some(p) = origin {
                let world = world_at(p);
                self.drag = Some(match grab(doc, geometry, axis, conv, index, placed, p) {
                    Some((shape, true)) => Drag::Resize {
                        shape,
                        axis,
                        centre: volume_to_world(
                            &doc.volume,
                            Vec3::from(doc.clip_shapes[shape].translation),
                        ),
                        from: distance_in_plane(
                            world,
                            volume_to_world(
                                &doc.volume,
                                Vec3::from(doc.clip_shapes[shape].translation),
                            ),
                            axis,
                        ),
                        scale: doc.clip_shapes[shape].scale,
                    },
                    Some((shape, false)) => Drag::Move {
                        shape,
                        axis,
                        last: world,
                    },
                    None => Drag::Crosshair(axis),
                });
            }
        }
        if let (Some(drag), Some(p)) = (self.drag.clone(), response.interact_pointer_pos())
            && (response.dragged() || response.clicked() || response.drag_started())
        {
            let world = world_at(p);
            match drag {
                Drag::Crosshair(a) if a == axis => {
                    let mut c = world;
                    c[axis.normal()] = geometry.position(axis, index);
                    self.crosshair = Some(c);
                }
                Drag::Move {
                    shape,
                    axis: a,
                    last,
                } if a == axis && shape < doc.clip_shapes.len() => {
                    let s = &mut doc.clip_shapes[shape];
                    let before = world_to_volume(&doc.volume, last);
                    let after = world_to_volume(&doc.volume, world);
                    let t = Vec3::from(s.translation) + (after - before);
                    if t != Vec3::from(s.translation) {
                        s.translation = t.to_array();
                        changed = true;
                    }
                    self.drag = Some(Drag::Move {
                        shape,
                        axis,
                        last: world,
                    });
                }
                Drag::Resize {
                    shape,
                    axis: a,
                    centre,
                    from,
                    scale,
                } if a == axis && shape < doc.clip_shapes.len() => {
                    let f = (distance_in_plane(world, centre, axis) / from.max(1e-3)) as f32;
                    let f = f.clamp(0.05, 20.0);
                    let s = &mut doc.clip_shapes[shape];
                    let new = scale.map(|v| (v * f).max(0.5));
                    if new != s.scale {
                        s.scale = new;
                        changed = true;
                    }
                }
                _ => {}
            }
        }
        if response.drag_stopped() || response.clicked() {
            self.drag = None;
        }
        if response.double_clicked() {
            self.toggle_maximised(Some(Pane::Slice(axis)));
        }
        // New shapes at the crosshair, a cut along this slice.
        let crosshair = self.crosshair.unwrap_or_else(|| geometry.centre());
        response.context_menu(|ui| {
            let at = world_to_volume(&doc.volume, crosshair);
            let size = (doc.radius / 4.0).max(1.0);
            let full = doc.clip_shapes.len() >= crate::clip::MAX_SHAPES;
            for (label, shape) in [("Sphere at the crosshair", Shape::Sphere), ("Box at the crosshair", Shape::Box)] {
                if ui.add_enabled(!full, egui::Button::new(label)).clicked() {
                    doc.clip_shapes.push(ClipShape::new(shape, at, size));
                    changed = true;
                    ui.close();
                }
            }
            if ui
                .add_enabled(!full, egui::Button::new(format!("Cut here ({} plane)", axis.name())))
                .on_hover_text("A plane through the crosshair along this slice, removing the side towards the viewer of this pane")
                .clicked()
            {
                doc.clip_shapes.push(cut_here(&doc.volume, geometry, axis, index, crosshair));
                changed = true;
                ui.close();
            }
            if full {
                ui.weak(format!("(at most {} shapes)", crate::clip::MAX_SHAPES));
            }
            ui.separator();
            if ui.button("Crosshair to the centre").clicked() {
                self.crosshair = Some(geometry.centre());
                ui.close();
            }
        });
        changed
    }
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

/// Distance (mm) between two world points within the plane of `axis`.
fn distance_in_plane(a: DVec3, b: DVec3, axis: SliceAxis) -> f64 {
    let mut d = a - b;
    d[axis.normal()] = 0.0;
    d.length()
}

/// The shape under point `p` of a slice pane, and whether `p` is on its outline (a
/// resize) rather than inside it (a move).
fn grab(
    doc: &Document,
    geometry: &SliceGeometry,
    axis: SliceAxis,
    conv: Convention,
    index: usize,
    placed: Placed,
    p: Pos2,
) -> Option<(usize, bool)> {
    let at = |q: Pos2| {
        let world = geometry.pixel_to_world(axis, conv, index, placed.to_pixel(q));
        world_to_volume(&doc.volume, world)
    };
    let here = at(p);
    // On an outline: some point within EDGE_GRAB points is on the other side.
    let ring: Vec<Vec3> = (0..12)
        .map(|k| {
            let a = k as f32 * std::f32::consts::TAU / 12.0;
            at(p + Vec2::new(a.cos(), a.sin()) * EDGE_GRAB)
        })
        .collect();
    let mut inside = None;
    for (i, s) in doc.clip_shapes.iter().enumerate() {
        if s.shape == Shape::Plane {
            continue;
        }
        let Some(c) = s.contains(here) else { continue };
        if ring.iter().any(|q| s.contains(*q) != Some(c)) {
            return Some((i, true));
        }
        if c && inside.is_none() {
            inside = Some(i);
        }
    }
    inside.map(|i| (i, false))
}

/// A plane through `crosshair` along slice `axis`, its removed side (local +z) towards
/// the world axis' positive end (R, A or S).
fn cut_here(
    volume: &crate::volume::Volume,
    geometry: &SliceGeometry,
    axis: SliceAxis,
    index: usize,
    crosshair: DVec3,
) -> ClipShape {
    let mut c = crosshair;
    c[axis.normal()] = geometry.position(axis, index);
    let at = world_to_volume(volume, c);
    // The normal in the volume's space: the world axis through the inverse affine.
    let mut ahead = c;
    ahead[axis.normal()] += 1.0;
    let n = (world_to_volume(volume, ahead) - at).normalize_or(Vec3::Z);
    let mut s = ClipShape::new(Shape::Plane, at, 1.0);
    let (x, y, z) = glam::Quat::from_rotation_arc(Vec3::Z, n).to_euler(glam::EulerRot::XYZ);
    s.rotation_deg = [x.to_degrees(), y.to_degrees(), z.to_degrees()];
    s
}

/// The readout of the crosshair: RAS mm, the voxel, its value and segment.
pub fn readout(views: &SliceViews, doc: &Document) -> Option<String> {
    let c = views.crosshair?;
    let (_, _, g) = views.geometry.as_ref()?;
    let mut s = format!("R {:.1}  A {:.1}  S {:.1} mm", c.x, c.y, c.z);
    if let Some([i, j, k]) = g.nearest_voxel(c) {
        s += &format!("  ·  voxel {i}, {j}, {k}");
        if let Some(v) = doc.volume.value(i, j, k) {
            s += &format!("  ·  {}", fmt_value(v));
        }
        if let Some(seg) = &doc.segmentation {
            let d = doc.volume.dims;
            let class = seg.classes.of_voxel.get(i + d[0] * (j + d[1] * k));
            if let Some(members) = class.and_then(|c| seg.classes.members.get(usize::from(*c))) {
                s += &format!("  ·  {}", seg.names(members));
            }
        }
    } else {
        s += "  ·  outside the volume";
    }
    Some(s)
}

fn fmt_value(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{v:.0}")
    } else {
        format!("{v:.4}")
    }
}

/// Draws the crosshair in the 3-D pane (three short axis-aligned lines in the slices'
/// colours) and an orientation marker (R, A, S arrows) in its bottom-left corner.
pub fn paint_3d(painter: &egui::Painter, rect: Rect, views: &SliceViews, doc: &Document) {
    let camera = &doc.camera;
    let radius = doc.radius;
    if views.show_crosshair
        && views.layout != Layout::ThreeD
        && let Some(c) = views.crosshair
    {
        let centre = world_to_volume(&doc.volume, c);
        let len = radius * 0.08;
        for axis in SliceAxis::ALL {
            let mut d = Vec3::ZERO;
            d[axis.normal()] = len;
            let a = super::clip_panel::project(camera, radius, rect, centre - d);
            let b = super::clip_panel::project(camera, radius, rect, centre + d);
            if let (Some(a), Some(b)) = (a, b) {
                painter.line_segment([a, b], Stroke::new(1.5, plane_color(axis)));
            }
        }
    }
    if views.show_markers {
        orientation_marker(painter, rect, camera);
    }
}

impl SliceViews {
    /// Picks the first visible surface under pixel `draw.pixel` of the 3-D view on the
    /// GPU: the ray caster's ray of that pixel stops where its opacity first passes ½
    /// ([`RayCaster::encode_pick`]); [`Self::poll_pick`] moves the crosshair there once
    /// the answer is back. `volume` names the document's volume.
    pub fn start_pick(
        &mut self,
        gpu: &crate::gpu::Gpu,
        ray_caster: &crate::render::gpu::RayCaster,
        draw: crate::render::gpu::PickDraw<'_>,
        volume: usize,
    ) -> Result<(), String> {
        self.pick = Some(PendingPick::submit(gpu, ray_caster, draw, volume)?);
        Ok(())
    }

    /// Whether a pick is waiting for the GPU.
    pub fn picking(&self) -> bool {
        self.pick.is_some()
    }

    /// Reads the pick if the GPU has answered (never waits): the crosshair moves to the
    /// surface found; a ray that met none leaves it. An error is returned to be shown.
    pub fn poll_pick(&mut self, gpu: &crate::gpu::Gpu, doc: &Document) -> Result<(), String> {
        let Some(pending) = &self.pick else {
            return Ok(());
        };
        let Some(result) = pending.poll(gpu) else {
            return Ok(());
        };
        let same_volume = pending.volume == std::sync::Arc::as_ptr(&doc.volume) as usize;
        self.pick = None;
        if let Some(hit) = result?
            && same_volume
        {
            self.crosshair = Some(volume_to_world(&doc.volume, hit));
        }
        Ok(())
    }
}
