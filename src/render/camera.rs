//! Orbit camera around the volume's centre, in the volume's physical space (mm, RAS).
//!
//! Azimuth 0° looks from anterior (+y) towards posterior with superior (+z) up, so the
//! patient's right is on the viewer's left, as in a radiological anterior view.

use glam::camera::rh::{proj::directx, view::look_at_mat4};
use glam::{Mat4, Vec3};

/// Camera pose and projection. `distance` is in units of the volume's bounding-sphere
/// radius, so the same camera frames volumes of any size alike.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Camera {
    pub azimuth_deg: f32,
    pub elevation_deg: f32,
    /// Eye distance from the target in bounding-sphere radii (perspective), or the zoom
    /// (orthographic: the view spans `distance / DEFAULT_DISTANCE` times the sphere).
    pub distance: f32,
    /// Vertical field of view (perspective).
    pub fov_y_deg: f32,
    pub orthographic: bool,
    /// Point looked at, in mm relative to the volume's centre (panning moves it).
    pub target: [f32; 3],
}

/// A distance at which a volume fills most of a 30° field of view (the bounding sphere
/// itself needs 3.9; its empty corners rarely hold anything visible).
pub const DEFAULT_DISTANCE: f32 = 3.2;

impl Default for Camera {
    fn default() -> Self {
        Camera {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance: DEFAULT_DISTANCE,
            fov_y_deg: 30.0,
            orthographic: false,
            target: [0.0; 3],
        }
    }
}

impl Camera {
    /// Unit vector from the target towards the eye.
    pub fn backward(&self) -> Vec3 {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        Vec3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin())
    }

    /// Screen right and up as world directions (the view matrix's rows).
    pub fn screen_axes(&self) -> (Vec3, Vec3) {
        let back = self.backward();
        let up0 = if back.z.abs() > 0.999 {
            Vec3::Y
        } else {
            Vec3::Z
        };
        let right = up0.cross(back).normalize();
        (right, back.cross(right))
    }

    /// Eye position for a volume whose bounding sphere has `radius` mm.
    pub fn eye(&self, radius: f32) -> Vec3 {
        Vec3::from(self.target) + self.backward() * self.distance * radius
    }

    /// World (volume-centred mm) → clip space, wgpu conventions (depth 0..1, y up),
    /// which glam calls the DirectX convention.
    pub fn view_proj(&self, radius: f32, aspect: f32) -> Mat4 {
        let target = Vec3::from(self.target);
        let eye = self.eye(radius);
        // Looking straight up or down: z cannot be "up"; use +y then.
        let up = if self.backward().z.abs() > 0.999 {
            Vec3::Y
        } else {
            Vec3::Z
        };
        let view = look_at_mat4(eye, target, up);
        let dist = self.distance * radius;
        let proj = if self.orthographic {
            let half_h = radius * 1.05 * self.distance / DEFAULT_DISTANCE;
            let half_w = half_h * aspect;
            directx::orthographic(-half_w, half_w, -half_h, half_h, 0.0, dist + 2.0 * radius)
        } else {
            let near = (dist - 1.5 * radius).max(radius * 1e-3);
            directx::perspective(
                self.fov_y_deg.to_radians(),
                aspect,
                near,
                dist + 2.0 * radius,
            )
        };
        proj * view
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anterior_view_puts_patient_right_on_screen_left() {
        let cam = Camera::default();
        let vp = cam.view_proj(100.0, 1.0);
        let right = vp.project_point3(Vec3::new(50.0, 0.0, 0.0)); // patient's right (+x)
        let up = vp.project_point3(Vec3::new(0.0, 0.0, 50.0));
        assert!(right.x < 0.0, "patient right at screen x {}", right.x);
        assert!(up.y > 0.0, "superior at screen y {}", up.y);
    }

    #[test]
    fn the_bounding_sphere_fits_the_view() {
        // Perspective needs 1/sin(15°) ≈ 3.86 radii for the whole sphere; the default is
        // closer because volumes rarely fill their corners. Orthographic fits at default.
        for (ortho, distance) in [(false, 4.0), (true, DEFAULT_DISTANCE)] {
            let cam = Camera {
                orthographic: ortho,
                distance,
                ..Default::default()
            };
            let vp = cam.view_proj(1.0, 1.0);
            for p in [Vec3::X, -Vec3::X, Vec3::Z, -Vec3::Z, Vec3::Y, -Vec3::Y] {
                let s = vp.project_point3(p);
                assert!(
                    s.x.abs() < 1.0 && s.y.abs() < 1.0 && (0.0..=1.0).contains(&s.z),
                    "{p} → {s} (ortho {ortho})"
                );
            }
        }
    }
}
