//! The viewer's orbit camera: a target point, a distance (metres) and two angles; orbit,
//! pan and zoom from mouse drags and the wheel; framing of a bounding sphere; projection of
//! world points to viewport pixels (for the light gizmos) and back to rays (for dragging).
//!
//! # Conventions
//! Right-handed world, `+y` up (as in the scenes). `yaw = 0, pitch = 0` looks along `−z`
//! (the default camera of `ortm render`). Pixels: `(0, 0)` is the viewport's top-left
//! corner, `y` down.

use glam::{Mat4, Vec3, Vec4Swizzles};
use passes::display::Camera;

/// Vertical field of view of the viewer, degrees.
pub const DEFAULT_FOV_DEG: f32 = 40.0;

/// An orbit camera around `target`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// Point orbited and looked at, metres.
    pub target: Vec3,
    /// Eye distance from the target, metres.
    pub distance_m: f32,
    /// Rotation about `+y`, radians (0: the eye is on the `+z` side of the target).
    pub yaw: f32,
    /// Elevation, radians, within ±89°.
    pub pitch: f32,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    /// Radius of the framed scene, metres (sets the clipping planes).
    pub scene_radius_m: f32,
}

impl OrbitCamera {
    /// A camera looking along `−z` at a sphere (`centre`, `radius_m`) that fills a view of
    /// `aspect` = width/height with a small margin.
    pub fn framing(centre: Vec3, radius_m: f32, fov_y_deg: f32, aspect: f32) -> Self {
        let r = if radius_m.is_finite() && radius_m > 0.0 {
            radius_m
        } else {
            1.0
        };
        let half_y = (fov_y_deg.to_radians() * 0.5).clamp(1e-3, 1.5);
        let half_x = (half_y.tan() * aspect.max(1e-3)).atan();
        let half = half_y.min(half_x);
        Self {
            target: centre,
            distance_m: 1.1 * r / half.sin(),
            yaw: 0.0,
            pitch: 0.0,
            fov_y_deg,
            scene_radius_m: r,
        }
    }

    /// Unit vector from the target towards the eye.
    pub fn back(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Vec3::new(sy * cp, sp, cy * cp)
    }

    /// Eye position, metres.
    pub fn eye(&self) -> Vec3 {
        self.target + self.back() * self.distance_m
    }

    /// Camera right and up unit vectors (world).
    pub fn right_up(&self) -> (Vec3, Vec3) {
        let fwd = -self.back();
        let right = fwd.cross(Vec3::Y).normalize_or(Vec3::X);
        (right, right.cross(fwd))
    }

    /// Rotates by a mouse drag of `(dx, dy)` pixels (0.01 rad per pixel).
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx * 0.01;
        self.pitch = (self.pitch + dy * 0.01).clamp(-89f32.to_radians(), 89f32.to_radians());
    }

    /// Moves the target in the view plane by a drag of `(dx, dy)` pixels in a viewport
    /// `height_px` tall, so the point under the cursor at the target's depth follows it.
    pub fn pan(&mut self, dx: f32, dy: f32, height_px: f32) {
        let (right, up) = self.right_up();
        let m_per_px = self.metres_per_pixel(height_px);
        self.target += (-dx * right + dy * up) * m_per_px;
    }

    /// Zooms by `steps` wheel steps (positive: closer), 10% per step.
    pub fn zoom(&mut self, steps: f32) {
        let min = self.scene_radius_m * 1e-3;
        self.distance_m = (self.distance_m * 0.9f32.powf(steps)).max(min);
    }

    /// World size of one pixel at the target's depth, metres.
    pub fn metres_per_pixel(&self, height_px: f32) -> f32 {
        2.0 * self.distance_m * (self.fov_y_deg.to_radians() * 0.5).tan() / height_px.max(1.0)
    }

    /// The `passes` camera (near/far planes around the scene).
    pub fn to_camera(self) -> Camera {
        let far = self.distance_m + 4.0 * self.scene_radius_m;
        let near = (self.distance_m - 2.0 * self.scene_radius_m).max(far * 1e-4);
        Camera {
            eye: self.eye().into(),
            target: self.target.into(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: self.fov_y_deg,
            near,
            far,
        }
    }

    /// Pixel position of world point `p` in a `size_px` viewport, or `None` behind the eye.
    pub fn project(&self, p: Vec3, size_px: [f32; 2]) -> Option<[f32; 2]> {
        let m: Mat4 = self.to_camera().view_proj(size_px[0] / size_px[1].max(1.0));
        let c = m * p.extend(1.0);
        if c.w <= 1e-9 {
            return None;
        }
        let ndc = c.xyz() / c.w;
        Some([
            (ndc.x * 0.5 + 0.5) * size_px[0],
            (0.5 - ndc.y * 0.5) * size_px[1],
        ])
    }

    /// Moves world point `p` in the plane through `p` parallel to the image plane by a drag
    /// of `(dx, dy)` pixels (so it follows the cursor).
    pub fn drag_point(&self, p: Vec3, dx: f32, dy: f32, height_px: f32) -> Vec3 {
        let (right, up) = self.right_up();
        let depth = (p - self.eye()).dot(-self.back()).max(1e-6);
        let m_per_px = 2.0 * depth * (self.fov_y_deg.to_radians() * 0.5).tan() / height_px.max(1.0);
        p + (dx * right - dy * up) * m_per_px
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_the_centre_and_framed_sphere_fits() {
        let c = Vec3::new(0.3, -0.2, 1.0);
        let cam = OrbitCamera::framing(c, 0.5, 40.0, 800.0 / 600.0);
        let p = cam.project(c, [800.0, 600.0]).unwrap();
        assert!((p[0] - 400.0).abs() < 1e-3 && (p[1] - 300.0).abs() < 1e-3);
        // The sphere's top point (seen from the front) is inside the image, near the edge.
        let top = cam.project(c + Vec3::Y * 0.5, [800.0, 600.0]).unwrap();
        assert!(top[1] > 0.0 && top[1] < 60.0, "{top:?}");
        // A tall view is limited by its width: the sphere's right point stays inside.
        let cam = OrbitCamera::framing(c, 0.5, 40.0, 0.5);
        let right = cam
            .project(c + cam.right_up().0 * 0.5, [300.0, 600.0])
            .unwrap();
        assert!(right[0] < 300.0 && right[0] > 270.0, "{right:?}");
    }

    #[test]
    fn orbit_keeps_the_distance_and_pan_follows_the_cursor() {
        let mut cam = OrbitCamera::framing(Vec3::ZERO, 1.0, 40.0, 1.0);
        let d = cam.distance_m;
        cam.orbit(120.0, -50.0);
        assert!(((cam.eye() - cam.target).length() - d).abs() < 1e-4);
        // A point dragged 100 px right and 40 px down lands 100 px right, 40 px down.
        let size = [640.0, 480.0];
        let p = Vec3::new(0.1, 0.2, -0.1);
        let before = cam.project(p, size).unwrap();
        let q = cam.drag_point(p, 100.0, 40.0, size[1]);
        let after = cam.project(q, size).unwrap();
        assert!(
            (after[0] - before[0] - 100.0).abs() < 0.5,
            "{before:?} {after:?}"
        );
        assert!(
            (after[1] - before[1] - 40.0).abs() < 0.5,
            "{before:?} {after:?}"
        );
        // Panning moves the scene with the cursor: the old target moves by the drag.
        let t = cam.target;
        let before = cam.project(t, size).unwrap();
        cam.pan(30.0, -20.0, size[1]);
        let after = cam.project(t, size).unwrap();
        assert!(
            (after[0] - before[0] - 30.0).abs() < 0.5 && (after[1] - before[1] + 20.0).abs() < 0.5
        );
    }
}
