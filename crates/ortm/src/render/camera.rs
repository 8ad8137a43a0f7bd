//! Cameras and image sizes: the default camera framing a mesh, and the `--camera` and
//! `--size` options. Positions in metres, angles in degrees, sizes in pixels; up is +y.
//!
//! [`default_camera`] looks along −z at the mesh's bounding sphere (the Cornell box's open
//! side and the head's face are towards +z); use `--camera` for anything else.

use glam::Vec3;
use passes::display::Camera;

use super::RenderError;
use crate::scene::Mesh;
use crate::scene::light::{SpecError, spec_floats};

/// A camera looking along −z at the bounding sphere of `mesh`, from far enough that the
/// sphere fits both the vertical field of view (`fov_y_deg`) and the horizontal one at
/// `aspect` = width/height. Up is +y.
pub fn default_camera(mesh: &Mesh, aspect: f32, fov_y_deg: f32) -> Camera {
    let (centre, radius) = match mesh.bounding_sphere() {
        Some((c, r)) => (c, r.max(1e-3)),
        None => (Vec3::ZERO, 1.0),
    };
    let half_y = (fov_y_deg.to_radians() * 0.5).clamp(1e-3, 1.5);
    let half_x = (half_y.tan() * aspect.max(1e-3)).atan();
    let dist = radius / half_y.min(half_x).sin();
    let eye = centre + Vec3::Z * dist;
    Camera {
        eye: eye.to_array(),
        target: centre.to_array(),
        up: [0.0, 1.0, 0.0],
        fov_y_deg,
        near: (dist - radius).max(dist * 1e-3) * 0.5,
        far: (dist + radius) * 2.0,
    }
}

/// Syntax of `--camera`.
pub const CAMERA_SYNTAX: &str = "EX,EY,EZ:TX,TY,TZ[:FOV_Y_DEG] (eye and target in metres, up = +y)";

/// Parses a `--camera` specification ([`CAMERA_SYNTAX`]); the field of view defaults to
/// `default_fov_deg`. Near and far planes come from the eye–target distance and
/// `scene_radius_m` (the mesh's bounding-sphere radius): `far = dist + 2·radius`,
/// `near = far / 2000`.
pub fn parse_camera(
    spec: &str,
    default_fov_deg: f32,
    scene_radius_m: f32,
) -> Result<Camera, RenderError> {
    let err = SpecError::maker("--camera", spec, CAMERA_SYNTAX);
    let parts: Vec<&str> = spec.split(':').collect();
    if !(2..=3).contains(&parts.len()) {
        return Err(err(format!(
            "has {} ':'-separated fields, expected 2 or 3",
            parts.len()
        ))
        .into());
    }
    let eye = Vec3::from_array(spec_floats::<3>(parts[0], &err)?);
    let target = Vec3::from_array(spec_floats::<3>(parts[1], &err)?);
    let fov = match parts.get(2) {
        Some(p) => spec_floats::<1>(p, &err)?[0],
        None => default_fov_deg,
    };
    if !(fov > 0.0 && fov < 180.0) {
        return Err(err(format!("field of view {fov}° must be in (0, 180)")).into());
    }
    let dir = target - eye;
    if dir.length() <= 0.0 {
        return Err(err("eye and target are the same point".into()).into());
    }
    if dir.normalize().cross(Vec3::Y).length() < 1e-4 {
        return Err(err(
            "the view direction is vertical (parallel to up = +y); tilt it slightly".into(),
        )
        .into());
    }
    let far = dir.length() + 2.0 * scene_radius_m.max(1e-3);
    Ok(Camera {
        eye: eye.to_array(),
        target: target.to_array(),
        up: [0.0, 1.0, 0.0],
        fov_y_deg: fov,
        near: far / 2000.0,
        far,
    })
}

/// Syntax of `--size`.
pub const SIZE_SYNTAX: &str = "WIDTHxHEIGHT in pixels, e.g. 1280x720";

/// Parses `WxH` (e.g. `1280x720`), each side in `1..=16384`.
pub fn parse_size(spec: &str) -> Result<(u32, u32), RenderError> {
    let err = SpecError::maker("--size", spec, SIZE_SYNTAX);
    let err = |problem: &str| RenderError::from(err(problem.to_owned()));
    let (w, h) = spec
        .split_once(['x', 'X'])
        .ok_or_else(|| err("no `x` between width and height"))?;
    let p = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=16384).contains(v))
            .ok_or_else(|| err("each side must be a whole number in 1..=16384"))
    };
    Ok((p(w)?, p(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_and_size_specs() {
        let c = parse_camera("0,1,3:0,1,0", 40.0, 0.5).unwrap();
        assert_eq!(
            (c.eye, c.target, c.fov_y_deg),
            ([0.0, 1.0, 3.0], [0.0, 1.0, 0.0], 40.0)
        );
        assert!(c.near > 0.0 && c.far >= 4.0 && c.near < c.far);
        assert_eq!(
            parse_camera("0,1,3:0,1,0:25", 40.0, 0.5).unwrap().fov_y_deg,
            25.0
        );
        assert!(parse_camera("0,1,0:0,0,0", 40.0, 0.5).is_err());
        assert!(parse_camera("0,0,0:0,0,0", 40.0, 0.5).is_err());
        assert!(parse_camera("0,1,3:0,1,0:180", 40.0, 0.5).is_err());
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert!(parse_size("640*480").is_err());
        assert!(parse_size("0x480").is_err());
    }

    #[test]
    fn default_camera_sees_the_whole_bounding_sphere() {
        let mesh = Mesh {
            positions_m: vec![Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 2.0, 0.0)],
            ..Default::default()
        };
        for aspect in [0.5, 1.0, 2.0] {
            let c = default_camera(&mesh, aspect, 40.0);
            let centre = Vec3::new(1.0, 1.0, -1.0);
            let r = (Vec3::new(4.0, 2.0, 2.0)).length() * 0.5;
            assert_eq!(c.target, centre.to_array());
            let d = Vec3::from(c.eye) - centre;
            // Looking along −z, and the sphere's angular radius fits both half-angles.
            assert!(d.x.abs() < 1e-6 && d.y.abs() < 1e-6 && d.z > 0.0);
            let ang = (r / d.length()).asin();
            let half_y = 20f32.to_radians();
            let half_x = (half_y.tan() * aspect).atan();
            assert!(ang <= half_y.min(half_x) + 1e-5, "aspect {aspect}");
            assert!(
                ang >= 0.99 * half_y.min(half_x),
                "not tight, aspect {aspect}"
            );
            assert!(c.near < d.length() - r && c.far > d.length() + r);
        }
    }
}
