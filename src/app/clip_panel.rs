//! Clipping in the viewer: the panel that adds, removes and edits clip shapes
//! ([`crate::clip::ClipShape`]: plane, sphere, box, cylinder, torus, OBJ/STL mesh; carve
//! or probe), their outlines over the viewport, and mouse manipulation.
//!
//! Mouse (in the viewport): click a shape's outline to select it; drag it to move it in
//! the view plane; Ctrl+drag to rotate it; the wheel over a selected plane pushes it
//! along its normal (NiiVue's convention). Elsewhere the mouse moves the camera.

use crate::clip::{ClipMode, ClipShape, Cuts, Shape};
use crate::labels::LabelMap;
use crate::render::Camera;
use glam::{Quat, Vec3};

/// Degrees of rotation per point of Ctrl+drag.
pub const ROTATE_DEG_PER_POINT: f32 = 0.5;

/// Pick distance around an outline, in points.
const PICK: f32 = 8.0;

/// Selection and the drag in progress.
#[derive(Debug, Default)]
pub struct ClipEditor {
    pub selected: Option<usize>,
    drag: Option<usize>,
    /// Draw the shapes as translucent surfaces as well as outlines.
    pub translucent: bool,
    /// The selected shape's cuts as typed (shape index, text) and why the text is not
    /// used (the shape keeps its last good cuts meanwhile).
    cuts_text: Option<(usize, String)>,
    cuts_error: Option<String>,
}

/// Which segments a shape cuts, as the panel's combo box names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CutsKind {
    All,
    Only,
    Except,
}

impl CutsKind {
    fn of(cuts: &Cuts) -> Self {
        match cuts {
            Cuts::All => CutsKind::All,
            Cuts::Only(_) => CutsKind::Only,
            Cuts::Except(_) => CutsKind::Except,
        }
    }

    fn name(self) -> &'static str {
        match self {
            CutsKind::All => "All segments",
            CutsKind::Only => "Only",
            CutsKind::Except => "All except",
        }
    }
}

/// The cuts of `kind` with the comma-separated names or patterns of `text`.
fn cuts_from(kind: CutsKind, text: &str) -> Cuts {
    let names: Vec<String> = text
        .split(',')
        .map(|n| n.trim().to_owned())
        .filter(|n| !n.is_empty())
        .collect();
    match kind {
        CutsKind::All => Cuts::All,
        CutsKind::Only => Cuts::Only(names),
        CutsKind::Except => Cuts::Except(names),
    }
}

/// The names of `cuts`, comma-separated.
fn cuts_text(cuts: &Cuts) -> String {
    match cuts {
        Cuts::All => String::new(),
        Cuts::Only(n) | Cuts::Except(n) => n.join(", "),
    }
}

/// The front-facing triangles of `shape` projected over the viewport, filled with
/// `colour`: a translucent surface one layer thick (back faces would double it). Mesh
/// files are shown by their outline only (they would be reloaded every frame).
pub fn surface_mesh(
    shape: &ClipShape,
    camera: &Camera,
    radius: f32,
    rect: egui::Rect,
    colour: egui::Color32,
) -> egui::Mesh {
    let mut mesh = egui::Mesh::default();
    if matches!(shape.shape, Shape::Mesh { .. }) {
        return mesh;
    }
    let Ok(m) = shape.posed_geometry(radius) else {
        return mesh;
    };
    let points: Vec<Option<egui::Pos2>> = m
        .vertices
        .iter()
        .map(|&v| project(camera, radius, rect, v))
        .collect();
    for t in &m.triangles {
        let [Some(a), Some(b), Some(c)] = t.map(|i| points[i as usize]) else {
            continue;
        };
        // Screen y points down: counter-clockwise in the volume is clockwise here.
        if (b - a).x * (c - a).y - (b - a).y * (c - a).x >= 0.0 {
            continue;
        }
        let base = mesh.vertices.len() as u32;
        for p in [a, b, c] {
            mesh.colored_vertex(p, colour);
        }
        mesh.add_triangle(base, base + 1, base + 2);
    }
    mesh
}

/// Makes a fresh shape of one kind.
pub type MakeShape = fn() -> Shape;

/// The shapes a user can add, with the button label.
pub const KINDS: [(&str, MakeShape); 5] = [
    ("Plane", || Shape::Plane),
    ("Sphere", || Shape::Sphere),
    ("Box", || Shape::Box),
    ("Cylinder", || Shape::Cylinder),
    ("Torus", || Shape::Torus { tube: 0.3 }),
];

/// A new shape at the volume's centre, sized to a third of the volume (`radius` is its
/// bounding-sphere radius in mm). Planes face the viewer's right (+x).
pub fn new_shape(shape: Shape, radius: f32) -> ClipShape {
    let mut s = ClipShape::new(shape, Vec3::ZERO, (radius / 3.0).max(0.5));
    if s.shape == Shape::Plane {
        s.scale = [1.0; 3];
        // Local +z (the removed side) along +x: a sagittal cut.
        s.rotation_deg = [0.0, 90.0, 0.0];
    }
    s
}

/// World (volume mm) → points inside `rect`, or `None` behind the eye.
pub(super) fn project(
    camera: &Camera,
    radius: f32,
    rect: egui::Rect,
    p: Vec3,
) -> Option<egui::Pos2> {
    let vp = camera.view_proj(radius, rect.width() / rect.height().max(1.0));
    let clip = vp * p.extend(1.0);
    if clip.w <= 1e-6 && !camera.orthographic {
        return None;
    }
    let ndc = clip.truncate() / clip.w;
    Some(egui::pos2(
        rect.left() + (ndc.x + 1.0) * 0.5 * rect.width(),
        rect.top() + (1.0 - ndc.y) * 0.5 * rect.height(),
    ))
}

/// Millimetres per point in the view plane through `p`, for a viewport `height` points
/// tall.
pub fn mm_per_point_at(camera: &Camera, radius: f32, height: f32, p: Vec3) -> f32 {
    if camera.orthographic {
        return crate::app::camera_input::mm_per_pixel(camera, radius, height);
    }
    let eye = camera.eye(radius);
    let forward = (Vec3::from(camera.target) - eye).normalize_or_zero();
    let depth = (p - eye).dot(forward).max(radius * 1e-3);
    2.0 * depth * (camera.fov_y_deg.to_radians() * 0.5).tan() / height.max(1.0)
}

/// Moves `shape` by a mouse movement of `delta` points in the view plane through its
/// centre: its projection follows the mouse.
pub fn move_in_view_plane(
    shape: &mut ClipShape,
    camera: &Camera,
    radius: f32,
    height: f32,
    delta: egui::Vec2,
) {
    let (right, up) = crate::app::camera_input::screen_axes(camera);
    let centre = Vec3::from(shape.translation);
    let s = mm_per_point_at(camera, radius, height, centre);
    shape.translation = (centre + right * delta.x * s - up * delta.y * s).to_array();
}

/// Rotates `shape` about the screen's up (horizontal drag) and right (vertical drag) axes.
pub fn rotate_in_view(shape: &mut ClipShape, camera: &Camera, delta: egui::Vec2) {
    let (right, up) = crate::app::camera_input::screen_axes(camera);
    let turn = Quat::from_axis_angle(up, (delta.x * ROTATE_DEG_PER_POINT).to_radians())
        * Quat::from_axis_angle(right, (delta.y * ROTATE_DEG_PER_POINT).to_radians());
    let q = (turn * shape.rotation()).normalize();
    let (x, y, z) = q.to_euler(glam::EulerRot::XYZ);
    shape.rotation_deg = [x, y, z].map(f32::to_degrees);
}

/// The shape's normal (local +z, the side a plane removes).
pub fn normal(shape: &ClipShape) -> Vec3 {
    shape.rotation() * Vec3::Z
}

/// Pushes `shape` `mm` along its normal.
pub fn push_along_normal(shape: &mut ClipShape, mm: f32) {
    shape.translation = (Vec3::from(shape.translation) + normal(shape) * mm).to_array();
}

fn circle(centre: Vec3, a: Vec3, b: Vec3, n: usize) -> Vec<Vec3> {
    (0..=n)
        .map(|i| {
            let t = i as f32 / n as f32 * std::f32::consts::TAU;
            centre + a * t.cos() + b * t.sin()
        })
        .collect()
}

/// Outline polylines of a shape in volume space (mm). `radius` sizes the drawn plane.
pub fn outline(shape: &ClipShape, radius: f32) -> Vec<Vec<Vec3>> {
    let s = Vec3::from(shape.scale);
    let local: Vec<Vec<Vec3>> = match &shape.shape {
        Shape::Plane => {
            let l = radius;
            vec![
                vec![
                    Vec3::new(-l, -l, 0.0),
                    Vec3::new(l, -l, 0.0),
                    Vec3::new(l, l, 0.0),
                    Vec3::new(-l, l, 0.0),
                    Vec3::new(-l, -l, 0.0),
                ],
                vec![Vec3::ZERO, Vec3::Z * radius * 0.3],
            ]
        }
        Shape::Sphere => vec![
            circle(Vec3::ZERO, Vec3::X * s.x, Vec3::Y * s.y, 48),
            circle(Vec3::ZERO, Vec3::Y * s.y, Vec3::Z * s.z, 48),
            circle(Vec3::ZERO, Vec3::X * s.x, Vec3::Z * s.z, 48),
        ],
        Shape::Box | Shape::Mesh { .. } => {
            let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z) * s;
            let mut v = vec![
                vec![
                    c(-1., -1., -1.),
                    c(1., -1., -1.),
                    c(1., 1., -1.),
                    c(-1., 1., -1.),
                    c(-1., -1., -1.),
                ],
                vec![
                    c(-1., -1., 1.),
                    c(1., -1., 1.),
                    c(1., 1., 1.),
                    c(-1., 1., 1.),
                    c(-1., -1., 1.),
                ],
            ];
            for (x, y) in [(-1., -1.), (1., -1.), (1., 1.), (-1., 1.)] {
                v.push(vec![c(x, y, -1.), c(x, y, 1.)]);
            }
            v
        }
        Shape::Cylinder => {
            let mut v = vec![
                circle(Vec3::Z * -s.z, Vec3::X * s.x, Vec3::Y * s.y, 48),
                circle(Vec3::Z * s.z, Vec3::X * s.x, Vec3::Y * s.y, 48),
            ];
            for (x, y) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
                let p = Vec3::new(x * s.x, y * s.y, 0.0);
                v.push(vec![p - Vec3::Z * s.z, p + Vec3::Z * s.z]);
            }
            v
        }
        Shape::Torus { tube } => {
            let r = *tube;
            vec![
                circle(Vec3::ZERO, Vec3::X * s.x, Vec3::Z * s.z, 64),
                circle(
                    Vec3::ZERO,
                    Vec3::X * s.x * (1.0 + r),
                    Vec3::Z * s.z * (1.0 + r),
                    64,
                ),
                circle(
                    Vec3::ZERO,
                    Vec3::X * s.x * (1.0 - r),
                    Vec3::Z * s.z * (1.0 - r),
                    64,
                ),
            ]
        }
    };
    let m = shape.shape_to_volume();
    local
        .into_iter()
        .map(|line| line.into_iter().map(|p| m.transform_point3(p)).collect())
        .collect()
}

/// Distance in points from `pos` to the shape's projected outline.
fn distance_to_outline(
    shape: &ClipShape,
    camera: &Camera,
    radius: f32,
    rect: egui::Rect,
    pos: egui::Pos2,
) -> f32 {
    let mut best = f32::INFINITY;
    for line in outline(shape, radius) {
        let pts: Vec<egui::Pos2> = line
            .iter()
            .filter_map(|&p| project(camera, radius, rect, p))
            .collect();
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let ab = b - a;
            let t = ((pos - a).dot(ab) / ab.length_sq().max(1e-9)).clamp(0.0, 1.0);
            best = best.min((a + ab * t).distance(pos));
        }
    }
    best
}

impl ClipEditor {
    /// The clipping panel. Returns whether the shapes changed.
    /// With a segmentation (`labels`), the selected shape's row also says which segments
    /// it cuts.
    pub fn panel(
        &mut self,
        ui: &mut egui::Ui,
        shapes: &mut Vec<ClipShape>,
        radius: f32,
        labels: Option<&LabelMap>,
    ) -> bool {
        let before = shapes.clone();
        ui.horizontal_wrapped(|ui| {
            ui.label("Add");
            for (label, make) in KINDS {
                if ui.button(label).clicked() && shapes.len() < crate::clip::MAX_SHAPES {
                    shapes.push(new_shape(make(), radius));
                    self.selected = Some(shapes.len() - 1);
                }
            }
            if ui.button("Mesh…").clicked()
                && let Some(path) = rfd::FileDialog::new()
                    .add_filter("Closed mesh", &["obj", "stl"])
                    .pick_file()
            {
                let mut s = new_shape(Shape::Mesh { path }, radius);
                s.scale = [1.0; 3];
                shapes.push(s);
                self.selected = Some(shapes.len() - 1);
            }
        });
        if shapes.is_empty() {
            ui.weak("No clip shapes. Click one to add it, then drag it in the viewport.");
        } else {
            ui.weak("Click an outline to select · drag moves · Ctrl+drag rotates · wheel pushes a plane");
            ui.checkbox(&mut self.translucent, "Show as translucent surfaces");
        }
        let mut remove = None;
        for (i, s) in shapes.iter_mut().enumerate() {
            let selected = self.selected == Some(i);
            ui.horizontal(|ui| {
                if ui
                    .selectable_label(selected, format!("{}: {}", i + 1, s.describe()))
                    .clicked()
                {
                    self.selected = Some(i);
                }
            });
            if !selected {
                continue;
            }
            ui.horizontal(|ui| {
                ui.selectable_value(&mut s.mode, ClipMode::Carve, "Carve");
                ui.selectable_value(&mut s.mode, ClipMode::Probe, "Probe");
                if ui.button("Remove").clicked() {
                    remove = Some(i);
                }
            });
            let row = |ui: &mut egui::Ui, name: &str, v: &mut [f32; 3], speed: f32| {
                ui.horizontal(|ui| {
                    ui.label(name);
                    for (axis, x) in ["x", "y", "z"].iter().zip(v.iter_mut()) {
                        ui.add(egui::DragValue::new(x).speed(speed))
                            .accessible_name(format!("{name} {axis}"));
                    }
                });
            };
            if let Some(labels) = labels {
                self.cuts_ui(ui, i, &mut s.cuts, labels);
            } else if !s.cuts.is_all() {
                ui.weak(format!(
                    "Cuts {:?} (open a segmentation to edit)",
                    cuts_text(&s.cuts)
                ));
            }
            row(ui, "Centre mm", &mut s.translation, 0.5);
            row(ui, "Rotation °", &mut s.rotation_deg, 1.0);
            if s.shape != Shape::Plane {
                row(ui, "Size mm", &mut s.scale, 0.2);
                for x in &mut s.scale {
                    *x = x.max(0.01);
                }
            }
        }
        if let Some(i) = remove {
            shapes.remove(i);
            self.selected = None;
        }
        *shapes != before
    }

    /// Which segments shape `index` cuts: a combo box (all, only, all except) and the
    /// names or patterns (`vertebrae*,rib*,aorta`), checked against `labels`; a text
    /// naming nothing shows why and is not used.
    fn cuts_ui(&mut self, ui: &mut egui::Ui, index: usize, cuts: &mut Cuts, labels: &LabelMap) {
        if self.cuts_text.as_ref().is_none_or(|(i, _)| *i != index) {
            self.cuts_text = Some((index, cuts_text(cuts)));
            self.cuts_error = None;
        }
        let Some((_, text)) = &mut self.cuts_text else {
            return;
        };
        let mut kind = CutsKind::of(cuts);
        let before = kind;
        let mut edited = false;
        ui.horizontal(|ui| {
            egui::ComboBox::from_label("Cuts")
                .selected_text(kind.name())
                .show_ui(ui, |ui| {
                    for k in [CutsKind::All, CutsKind::Only, CutsKind::Except] {
                        ui.selectable_value(&mut kind, k, k.name());
                    }
                });
            if kind != CutsKind::All {
                edited = ui
                    .add(
                        egui::TextEdit::singleline(text)
                            .hint_text("vertebrae*,rib*,aorta")
                            .desired_width(140.0),
                    )
                    .on_hover_text(
                        "Segment names or values, comma-separated; * matches any run of \
                         characters; unlabelled: the voxels in no segment",
                    )
                    .accessible_name("Cut segments")
                    .changed();
            }
        });
        if kind == before && !edited {
            if let Some(e) = &self.cuts_error {
                ui.colored_label(ui.visuals().error_fg_color, e);
            }
            return;
        }
        let wanted = cuts_from(kind, text);
        let probe = ClipShape {
            cuts: wanted.clone(),
            ..ClipShape::new(Shape::Sphere, Vec3::ZERO, 1.0)
        };
        match crate::labels::style::check_cuts(labels, std::slice::from_ref(&probe)) {
            Ok(()) => {
                *cuts = wanted;
                self.cuts_error = None;
            }
            Err(e) => {
                // "clip shape 1: …" of the one-shape check: name this shape instead.
                let e = e.split_once(": ").map_or(e.as_str(), |(_, m)| m).to_owned();
                self.cuts_error = Some(e);
            }
        }
        if let Some(e) = &self.cuts_error {
            ui.colored_label(ui.visuals().error_fg_color, e);
        }
    }

    /// Draws the outlines over the viewport (the selected one highlighted).
    pub fn paint(
        &self,
        painter: &egui::Painter,
        rect: egui::Rect,
        camera: &Camera,
        radius: f32,
        shapes: &[ClipShape],
    ) {
        for (i, s) in shapes.iter().enumerate() {
            let selected = self.selected == Some(i);
            let colour = match (selected, s.mode) {
                (true, _) => egui::Color32::from_rgb(255, 200, 40),
                (false, ClipMode::Carve) => {
                    egui::Color32::from_rgba_unmultiplied(80, 200, 255, 160)
                }
                (false, ClipMode::Probe) => {
                    egui::Color32::from_rgba_unmultiplied(120, 255, 120, 160)
                }
            };
            let stroke = egui::Stroke::new(if selected { 2.0 } else { 1.2 }, colour);
            if self.translucent {
                let fill =
                    egui::Color32::from_rgba_unmultiplied(colour.r(), colour.g(), colour.b(), 50);
                painter.add(egui::Shape::mesh(surface_mesh(
                    s, camera, radius, rect, fill,
                )));
            }
            for line in outline(s, radius) {
                let pts: Vec<egui::Pos2> = line
                    .iter()
                    .filter_map(|&p| project(camera, radius, rect, p))
                    .collect();
                painter.add(egui::Shape::line(pts, stroke));
            }
        }
    }

    /// Mouse manipulation on the viewport. Returns whether the input was used (so the
    /// camera does not also move).
    pub fn handle(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        camera: &Camera,
        radius: f32,
        shapes: &mut [ClipShape],
    ) -> bool {
        let rect = response.rect;
        let hit = |pos: egui::Pos2, shapes: &[ClipShape]| {
            shapes
                .iter()
                .enumerate()
                .map(|(i, s)| (i, distance_to_outline(s, camera, radius, rect, pos)))
                .filter(|(_, d)| *d <= PICK)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        if response.clicked()
            && let Some(pos) = response.interact_pointer_pos()
        {
            self.selected = hit(pos, shapes);
            return self.selected.is_some();
        }
        if response.drag_started_by(egui::PointerButton::Primary) {
            let origin = ui.input(|i| i.pointer.press_origin());
            self.drag = origin.and_then(|p| hit(p, shapes));
            if self.drag.is_some() {
                self.selected = self.drag;
            }
        }
        if response.drag_stopped() {
            let was = self.drag.take();
            return was.is_some();
        }
        if let Some(i) = self.drag
            && response.dragged()
            && let Some(s) = shapes.get_mut(i)
        {
            let delta = response.drag_delta();
            if ui.input(|i| i.modifiers.command) {
                rotate_in_view(s, camera, delta);
            } else {
                move_in_view_plane(s, camera, radius, rect.height(), delta);
            }
            return true;
        }
        // The wheel over the selected plane pushes it along its normal.
        if let Some(i) = self.selected
            && let Some(s) = shapes.get_mut(i)
            && s.shape == Shape::Plane
            && response.hovered()
        {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                push_along_normal(s, scroll * radius * 0.002);
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dragged_shape_follows_the_mouse() {
        let rect = egui::Rect::from_min_size(egui::pos2(100.0, 50.0), egui::vec2(640.0, 480.0));
        let radius = 90.0;
        for orthographic in [false, true] {
            let camera = Camera {
                azimuth_deg: 35.0,
                elevation_deg: -20.0,
                orthographic,
                ..Default::default()
            };
            let mut s = ClipShape::new(Shape::Sphere, Vec3::new(10.0, -20.0, 5.0), 12.0);
            let before = project(&camera, radius, rect, Vec3::from(s.translation)).expect("front");
            let delta = egui::vec2(-23.0, 17.0);
            move_in_view_plane(&mut s, &camera, radius, rect.height(), delta);
            let after = project(&camera, radius, rect, Vec3::from(s.translation)).expect("front");
            assert!(
                ((after - before) - delta).length() < 0.05,
                "ortho {orthographic}: moved {:?}",
                after - before
            );
        }
    }

    #[test]
    fn planes_push_along_their_normal_and_rotation_keeps_it_unit() {
        let mut p = new_shape(Shape::Plane, 100.0);
        assert!((normal(&p) - Vec3::X).length() < 1e-5, "{}", normal(&p));
        push_along_normal(&mut p, 7.0);
        assert!((Vec3::from(p.translation) - Vec3::X * 7.0).length() < 1e-4);
        let camera = Camera::default();
        rotate_in_view(&mut p, &camera, egui::vec2(180.0, 0.0)); // 90° about screen up
        let n = normal(&p);
        assert!((n.length() - 1.0).abs() < 1e-5);
        // The anterior view's up is +z: a 90° turn about it takes +x to ±y.
        assert!(n.z.abs() < 1e-4 && n.x.abs() < 1e-4, "{n}");
        p.check(0).expect("still a valid pose");
    }

    #[test]
    fn translucent_surfaces_keep_only_front_faces() {
        let camera = Camera::default();
        let rect = egui::Rect::from_min_size(egui::pos2(0.0, 0.0), egui::vec2(200.0, 200.0));
        let s = ClipShape::new(Shape::Sphere, Vec3::ZERO, 20.0);
        let all = s.posed_geometry(100.0).expect("sphere").triangles.len();
        let m = surface_mesh(&s, &camera, 100.0, rect, egui::Color32::WHITE);
        let shown = m.indices.len() / 3;
        assert!(
            shown > all * 2 / 5 && shown < all * 3 / 5,
            "{shown} of {all}"
        );
        let centre = project(&camera, 100.0, rect, Vec3::ZERO).expect("in front");
        assert!(rect.contains(centre));
    }

    #[test]
    fn clicks_pick_the_nearest_outline() {
        let rect = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(400.0, 400.0));
        let camera = Camera::default();
        let s = ClipShape::new(Shape::Sphere, Vec3::ZERO, 20.0);
        // The sphere's silhouette circle (xz plane, facing the anterior view) at +x.
        let edge = project(&camera, 100.0, rect, Vec3::X * 20.0).expect("front");
        assert!(distance_to_outline(&s, &camera, 100.0, rect, edge) < 0.5);
        // Beyond the silhouette, diagonally, nothing is hit.
        let outside = project(&camera, 100.0, rect, Vec3::new(30.0, 0.0, 30.0)).expect("front");
        assert!(distance_to_outline(&s, &camera, 100.0, rect, outside) > PICK);
    }
}
