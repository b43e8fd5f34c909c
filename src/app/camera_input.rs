//! Mouse control of the orbit camera and the six standard medical views.
//!
//! Left drag orbits, right or middle drag pans in the view plane (the point under the
//! cursor stays under it), the wheel zooms. The volume is shown in RAS (the viewer loads
//! volumes with [`crate::volume::Volume::to_ras`]), so the standard views are fixed
//! camera directions: anterior looks from +y, right from +x, superior from +z.

use crate::render::Camera;
use crate::render::camera::DEFAULT_DISTANCE;
use glam::Vec3;

/// Degrees of orbit per point of mouse movement.
pub const ORBIT_DEG_PER_POINT: f32 = 0.4;

/// Closest and farthest zoom, in bounding-sphere radii.
pub const DISTANCE_RANGE: (f32, f32) = (0.3, 40.0);

/// The six standard views of radiology, named by where the viewer stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StandardView {
    Anterior,
    Posterior,
    Left,
    Right,
    Superior,
    Inferior,
}

impl StandardView {
    pub const ALL: [StandardView; 6] = [
        StandardView::Anterior,
        StandardView::Posterior,
        StandardView::Left,
        StandardView::Right,
        StandardView::Superior,
        StandardView::Inferior,
    ];

    pub fn name(self) -> &'static str {
        match self {
            StandardView::Anterior => "Anterior",
            StandardView::Posterior => "Posterior",
            StandardView::Left => "Left",
            StandardView::Right => "Right",
            StandardView::Superior => "Superior",
            StandardView::Inferior => "Inferior",
        }
    }

    /// The camera's azimuth and elevation (degrees) for this view.
    pub fn azimuth_elevation(self) -> (f32, f32) {
        match self {
            StandardView::Anterior => (0.0, 0.0),
            StandardView::Posterior => (180.0, 0.0),
            // The patient's left is −x: the eye stands at −x.
            StandardView::Left => (-90.0, 0.0),
            StandardView::Right => (90.0, 0.0),
            // Looking down from +z (or up from −z), anterior at the top of the screen.
            StandardView::Superior => (0.0, 90.0),
            StandardView::Inferior => (0.0, -90.0),
        }
    }

    /// Turns the camera to this view, keeping zoom, projection and the pan.
    pub fn apply(self, camera: &mut Camera) {
        (camera.azimuth_deg, camera.elevation_deg) = self.azimuth_elevation();
    }
}

/// Camera reset: the default view of `volao render`, keeping the projection.
pub fn reset(camera: &mut Camera) {
    *camera = Camera {
        orthographic: camera.orthographic,
        ..Camera::default()
    };
}

/// Screen right and up as world directions (the camera's view-matrix rows).
pub fn screen_axes(camera: &Camera) -> (Vec3, Vec3) {
    camera.screen_axes()
}

/// Orbits by a mouse movement of `delta` points (x right, y down): the volume turns with
/// the mouse. Elevation stops at the poles.
pub fn orbit(camera: &mut Camera, delta: egui::Vec2) {
    camera.azimuth_deg = wrap_degrees(camera.azimuth_deg + delta.x * ORBIT_DEG_PER_POINT);
    camera.elevation_deg =
        (camera.elevation_deg + delta.y * ORBIT_DEG_PER_POINT).clamp(-90.0, 90.0);
}

fn wrap_degrees(a: f32) -> f32 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

/// Millimetres per pixel in the plane through the target, for a viewport `height_px`
/// tall and a volume of bounding-sphere `radius` (mm).
pub fn mm_per_pixel(camera: &Camera, radius: f32, height_px: f32) -> f32 {
    let half_h = if camera.orthographic {
        radius * 1.05 * camera.distance / DEFAULT_DISTANCE
    } else {
        camera.distance * radius * (camera.fov_y_deg.to_radians() * 0.5).tan()
    };
    2.0 * half_h / height_px.max(1.0)
}

/// Pans by a mouse movement of `delta_px` physical pixels in a viewport `height_px`
/// tall: what was under the cursor (in the target's plane) stays under it.
pub fn pan(camera: &mut Camera, delta_px: egui::Vec2, radius: f32, height_px: f32) {
    let (right, up) = screen_axes(camera);
    let s = mm_per_pixel(camera, radius, height_px);
    let t = Vec3::from(camera.target) - right * delta_px.x * s + up * delta_px.y * s;
    camera.target = t.into();
}

/// Zooms by a wheel movement (points; positive = away from the user = closer).
pub fn zoom(camera: &mut Camera, scroll: f32) {
    let d = camera.distance * (-scroll * 0.002).exp();
    camera.distance = d.clamp(DISTANCE_RANGE.0, DISTANCE_RANGE.1);
}

/// Applies this frame's mouse input on the viewport `response` to the camera. Returns
/// whether the camera changed. `radius` is the volume's bounding-sphere radius (mm).
pub fn handle(ui: &egui::Ui, response: &egui::Response, camera: &mut Camera, radius: f32) -> bool {
    let before = *camera;
    let ppp = ui.ctx().pixels_per_point();
    let height_px = response.rect.height() * ppp;
    if response.dragged_by(egui::PointerButton::Primary) {
        orbit(camera, response.drag_delta());
    }
    if response.dragged_by(egui::PointerButton::Secondary)
        || response.dragged_by(egui::PointerButton::Middle)
    {
        pan(camera, response.drag_delta() * ppp, radius, height_px);
    }
    if response.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            zoom(camera, scroll);
        }
    }
    *camera != before
}

#[cfg(test)]
mod tests {
    use super::*;

    fn screen_px(camera: &Camera, p: Vec3, radius: f32, size: (f32, f32)) -> egui::Vec2 {
        let s = camera.view_proj(radius, size.0 / size.1).project_point3(p);
        egui::vec2((s.x + 1.0) * 0.5 * size.0, (1.0 - s.y) * 0.5 * size.1)
    }

    #[test]
    fn standard_views_put_the_named_side_towards_the_viewer() {
        // The point nearest the eye is on the named side of the (RAS) volume.
        let sides = [
            (StandardView::Anterior, Vec3::Y),
            (StandardView::Posterior, -Vec3::Y),
            (StandardView::Left, -Vec3::X),
            (StandardView::Right, Vec3::X),
            (StandardView::Superior, Vec3::Z),
            (StandardView::Inferior, -Vec3::Z),
        ];
        for (view, side) in sides {
            let mut cam = Camera::default();
            view.apply(&mut cam);
            let eye = cam.eye(100.0);
            assert!(
                eye.normalize().dot(side) > 0.999,
                "{view:?}: eye at {eye}, expected towards {side}"
            );
            // Depth in clip space: the named side is nearer than the opposite one.
            let vp = cam.view_proj(100.0, 1.0);
            let near = vp.project_point3(side * 50.0).z;
            let far = vp.project_point3(-side * 50.0).z;
            assert!(near < far, "{view:?}");
        }
        // Superior view: anterior (+y) at the top of the screen.
        let mut cam = Camera::default();
        StandardView::Superior.apply(&mut cam);
        let s = cam.view_proj(100.0, 1.0).project_point3(Vec3::Y * 50.0);
        assert!(s.y > 0.5, "anterior at screen y {}", s.y);
    }

    #[test]
    fn panning_keeps_the_point_under_the_cursor() {
        for orthographic in [false, true] {
            let mut cam = Camera {
                azimuth_deg: 30.0,
                elevation_deg: 20.0,
                orthographic,
                ..Default::default()
            };
            let (radius, size) = (80.0, (640.0, 480.0));
            let p = Vec3::from(cam.target);
            let before = screen_px(&cam, p, radius, size);
            let delta = egui::vec2(37.0, -21.0);
            pan(&mut cam, delta, radius, size.1);
            let after = screen_px(&cam, p, radius, size);
            let moved = after - before;
            assert!(
                (moved - delta).length() < 0.05,
                "ortho {orthographic}: moved {moved:?}, mouse {delta:?}"
            );
        }
    }

    #[test]
    fn orbit_turns_the_volume_with_the_mouse() {
        // Dragging right moves the front of the volume (+y, facing the viewer) right.
        let mut cam = Camera::default();
        let size = (400.0, 400.0);
        let front = Vec3::Y * 40.0;
        let before = screen_px(&cam, front, 100.0, size);
        orbit(&mut cam, egui::vec2(20.0, 0.0));
        let after = screen_px(&cam, front, 100.0, size);
        assert!(after.x > before.x + 1.0, "{before:?} → {after:?}");
        // Dragging down tilts the top towards the viewer: the front moves down.
        let mut cam = Camera::default();
        orbit(&mut cam, egui::vec2(0.0, 20.0));
        let after = screen_px(&cam, front, 100.0, size);
        assert!(after.y > before.y + 1.0, "{before:?} → {after:?}");
        // Elevation stops at the poles, azimuth wraps.
        orbit(&mut cam, egui::vec2(1000.0, 1000.0));
        assert_eq!(cam.elevation_deg, 90.0);
        assert!((-180.0..180.0).contains(&cam.azimuth_deg));
    }

    #[test]
    fn zoom_is_bounded_and_reversible() {
        let mut cam = Camera::default();
        zoom(&mut cam, 120.0);
        assert!(cam.distance < DEFAULT_DISTANCE);
        zoom(&mut cam, -120.0);
        assert!((cam.distance - DEFAULT_DISTANCE).abs() < 1e-5);
        zoom(&mut cam, 1e6);
        assert_eq!(cam.distance, DISTANCE_RANGE.0);
    }
}
