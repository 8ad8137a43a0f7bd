//! Light and camera set-ups of the paper's face figures (Sunshine-Hill & Faloutsos 2006,
//! Figs. 3–6), for the head at [`crate::HEAD_METRES_PER_UNIT`].
//!
//! Coordinates are metres in the head's frame: +x the head's left (image right when seen from
//! the front), +y up, +z out of the face (the nose tip is at ≈ (0, −0.032, 0.047) m, the ear rims
//! at x ≈ ±0.08 m, z ≈ −0.075 m, the back of the skull at z ≈ −0.175 m). Point intensities
//! are in W/sr, directional irradiance in W/m²; colours are linear RGB multipliers. Renders
//! are auto-exposed, so only the ratios between lights of one figure matter.

use glam::Vec3;

/// A light of a figure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FigLight {
    /// Isotropic point light.
    Point {
        /// Position, metres.
        position_m: Vec3,
        /// Linear RGB tint.
        color: Vec3,
        /// Radiant intensity, W/sr.
        intensity_w_sr: f32,
    },
    /// Distant light.
    Directional {
        /// Direction the light travels (from the light towards the head).
        direction: Vec3,
        /// Linear RGB tint.
        color: Vec3,
        /// Irradiance on a surface facing the light, W/m².
        irradiance_w_m2: f32,
    },
}

/// A pinhole camera looking at `target_m` from `eye_m`, up = +y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FigCamera {
    /// Eye position, metres.
    pub eye_m: Vec3,
    /// Point looked at, metres.
    pub target_m: Vec3,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
}

/// One figure of the paper, re-created on the head.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Figure {
    /// Short id, also the PNG's file stem (`fig3_two_lights`, …).
    pub id: &'static str,
    /// The paper's figure number and caption.
    pub paper: &'static str,
    /// What the image should show (checked by eye on every render, stated in the README).
    pub look_for: &'static str,
    /// Lights.
    pub lights: &'static [FigLight],
    /// Camera.
    pub camera: FigCamera,
    /// First order (left) beside the final image (right), as the paper's viewer shows them.
    pub side_by_side: bool,
}

const fn point(x: f32, y: f32, z: f32, color: Vec3, intensity_w_sr: f32) -> FigLight {
    FigLight::Point {
        position_m: Vec3::new(x, y, z),
        color,
        intensity_w_sr,
    }
}

const WHITE: Vec3 = Vec3::ONE;
/// A saturated blue and red as in the paper's Fig. 3.
const BLUE: Vec3 = Vec3::new(0.15, 0.3, 1.0);
const RED: Vec3 = Vec3::new(1.0, 0.12, 0.05);

/// Target of the frontal views: the middle of the face.
const FACE: Vec3 = Vec3::new(0.0, -0.03, -0.02);

/// The figures, in the paper's order.
pub const FIGURES: [Figure; 5] = [
    Figure {
        id: "fig3_two_lights",
        paper: "Fig. 3: subsurface scattering in a mesh lit by two point lights (blue in front, \
                red behind)",
        look_for: "red light from behind bleeding through the nose contour and the ears into \
                   the blue-lit side; absent from the first-order half",
        lights: &[
            point(0.12, 0.04, 0.45, BLUE, 1.0),
            point(-0.45, 0.02, -0.3, RED, 1.5),
        ],
        camera: FigCamera {
            eye_m: Vec3::new(-0.22, 0.0, 0.5),
            target_m: FACE,
            fov_y_deg: 34.0,
        },
        side_by_side: true,
    },
    Figure {
        id: "fig4_first_order_vs_global",
        paper: "Fig. 4: comparing first-order and global illumination (directional light)",
        look_for: "the global-illumination half smoother and more saturated, shadows filled \
                   by interreflection and softened by subsurface scattering",
        lights: &[FigLight::Directional {
            direction: Vec3::new(-0.45, -0.35, -0.82),
            color: WHITE,
            irradiance_w_m2: 5.0,
        }],
        camera: FigCamera {
            eye_m: Vec3::new(0.0, 0.0, 0.55),
            target_m: FACE,
            fov_y_deg: 36.0,
        },
        side_by_side: true,
    },
    Figure {
        id: "fig5_point_light",
        paper: "Fig. 5: radiosity and subsurface scattering with one point light source",
        look_for: "soft, reddish shadow terminators (skin scatters red furthest) and light \
                   reflected into the eye sockets and under the chin",
        lights: &[point(0.2, 0.12, 0.35, WHITE, 1.0)],
        camera: FigCamera {
            eye_m: Vec3::new(0.25, -0.02, 0.48),
            target_m: FACE,
            fov_y_deg: 34.0,
        },
        side_by_side: false,
    },
    Figure {
        id: "fig6a_light_from_above",
        paper: "Fig. 6a: global illumination, directional light from above the head",
        look_for: "the underside of the nose, not directly lit, receiving light reflected \
                   from the upper lip and cheeks (black in the first-order half)",
        lights: &[FigLight::Directional {
            direction: Vec3::new(0.0, -1.0, -0.3),
            color: WHITE,
            irradiance_w_m2: 5.0,
        }],
        camera: FigCamera {
            eye_m: Vec3::new(0.1, -0.11, 0.45),
            target_m: Vec3::new(0.0, -0.04, 0.0),
            fov_y_deg: 30.0,
        },
        side_by_side: true,
    },
    Figure {
        id: "fig6b_backlit_ear",
        paper: "Fig. 6b: back-lit face: subsurface scattering gives the thin parts a warm glow",
        look_for: "the ear rim, lit only from behind, glowing red on its front side; dark in \
                   the first-order half",
        lights: &[point(0.02, 0.0, -0.6, WHITE, 2.0)],
        camera: FigCamera {
            eye_m: Vec3::new(0.42, -0.01, 0.22),
            target_m: Vec3::new(0.06, -0.03, -0.06),
            fov_y_deg: 34.0,
        },
        side_by_side: true,
    },
];

/// The figure with `id`, or `None`.
pub fn figure(id: &str) -> Option<&'static Figure> {
    FIGURES.iter().find(|f| f.id == id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_well_formed() {
        let mut ids: Vec<_> = FIGURES.iter().map(|f| f.id).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), FIGURES.len());
        for f in &FIGURES {
            assert!(!f.lights.is_empty(), "{}", f.id);
            assert!(
                (f.camera.eye_m - f.camera.target_m).length() > 0.1,
                "{}",
                f.id
            );
            assert!(f.camera.fov_y_deg > 5.0 && f.camera.fov_y_deg < 90.0);
            assert!(figure(f.id).is_some());
        }
        // Fig. 3: one blue light in front of the face, one red light behind it.
        let fig3 = figure("fig3_two_lights").unwrap();
        let (mut front_blue, mut back_red) = (false, false);
        for l in fig3.lights {
            if let FigLight::Point {
                position_m, color, ..
            } = l
            {
                front_blue |= position_m.z > 0.1 && color.z > color.x;
                back_red |= position_m.z < -0.1 && color.x > color.z;
            }
        }
        assert!(front_blue && back_red);
    }
}
