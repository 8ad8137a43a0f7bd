//! The scanned head preset: where the mesh lives, its scale, albedo, skin and credit line.
//!
//! The mesh is "Infinite, 3D Head Scan" by Lee Perry-Smith (Infinite Realities), from the McGuire
//! Computer Graphics Archive, CC BY 3.0. It is never copied into the repository: it is read from
//! `$ORTM_HEAD_OBJ`, or from `../shared/faces/head.obj` beside the checkout ([`head_obj_path`]).
//! Anything that shows an image made from it must carry [`HEAD_CREDIT`].
//!
//! # Scale
//! The OBJ is in arbitrary model units. [`HEAD_METRES_PER_UNIT`] = 0.88 m per unit was measured
//! on the mesh (this crate's `tests` repeat the measurement on the file): the head proper
//! (above the neck) is 0.167 units wide above the ears, 0.252 units from the nose tip to the back
//! of the skull, and the eyes are ≈ 0.071 units apart; adult means of ≈ 0.15 m, ≈ 0.22 m and
//! ≈ 63 mm give 0.87–0.90 m per unit. (The shared README's 0.34 m per
//! unit comes from the 0.45-unit width of the whole bust, shoulders included, taken for a head
//! width: at 0.34 the head would be 57 mm wide and subsurface light would travel 2.6× too far
//! relative to the face.)

use std::path::PathBuf;

use glam::Vec3;

/// Environment variable naming the head OBJ (overrides the default path).
pub const HEAD_OBJ_ENV: &str = "ORTM_HEAD_OBJ";

/// Metres per model unit of `head.obj` (see the module docs for the measurement).
pub const HEAD_METRES_PER_UNIT: f32 = 0.88;

/// Diffuse albedo (linear RGB) for the head when rendered opaque; with subsurface scattering the
/// transport uses the skin profile's total diffuse reflectance instead.
pub const HEAD_ALBEDO: [f32; 3] = [0.8, 0.6, 0.5];

/// The measured skin of [`crate::skin::MEASURED`] the head uses.
pub const HEAD_SKIN: &str = "skin1";

/// Credit line required by the scan's CC BY 3.0 licence, for every image made from it.
pub const HEAD_CREDIT: &str = "Head scan © Lee Perry-Smith / Infinite Realities, CC BY 3.0";

/// Where to get the mesh when it is missing.
pub const HEAD_SOURCE: &str = "\"Infinite, 3D Head Scan\" by Lee Perry-Smith (Infinite Realities), \
     McGuire Computer Graphics Archive";

/// SHA-256 of the expected `head.obj` (hex), as listed in the shared README.
pub const HEAD_OBJ_SHA256: &str =
    "762544f36d38048ac1ea6ff3f2438171d516d32c44d126756664d0fccbbe1553";

/// Default lightmap side of the head, texels.
pub const HEAD_LIGHTMAP_SIDE: u32 = 256;

/// Axis-aligned boxes in **model units** around the rims of the two ears (helix and upper
/// pinna; `|x| ≥ 0.088`, behind the cheek), used to pick ear texels for the back-lit ear check.
pub const EAR_BOXES_UNITS: [(Vec3, Vec3); 2] = [
    (Vec3::new(0.088, -0.075, -0.13), Vec3::new(0.2, 0.02, -0.05)),
    (
        Vec3::new(-0.2, -0.075, -0.13),
        Vec3::new(-0.088, 0.02, -0.05),
    ),
];

/// True when the point `p_m` (metres, head at [`HEAD_METRES_PER_UNIT`]) lies on an ear rim.
pub fn is_ear_point(p_m: Vec3) -> bool {
    let p = p_m / HEAD_METRES_PER_UNIT;
    EAR_BOXES_UNITS
        .iter()
        .any(|(lo, hi)| p.cmpge(*lo).all() && p.cmple(*hi).all())
}

/// Where the head OBJ is read from: `$ORTM_HEAD_OBJ` when set (and not empty), else
/// `../shared/faces/head.obj` relative to the repository root.
pub fn head_obj_path() -> PathBuf {
    match std::env::var_os(HEAD_OBJ_ENV) {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/faces/head.obj"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads the vertex positions of the shared head (model units).
    fn positions() -> Option<Vec<Vec3>> {
        let text = std::fs::read_to_string(head_obj_path()).ok()?;
        Some(
            text.lines()
                .filter_map(|l| l.strip_prefix("v "))
                .map(|l| {
                    let v: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
                    Vec3::new(v[0], v[1], v[2])
                })
                .collect(),
        )
    }

    #[test]
    fn scale_gives_an_adult_head() {
        let v = positions().expect("../shared/faces/head.obj is readable");
        // The head proper: above the neck (y > −0.2 units).
        let head: Vec<Vec3> = v.iter().copied().filter(|p| p.y > -0.2).collect();
        let depth = head.iter().map(|p| p.z).fold(f32::MIN, f32::max)
            - head.iter().map(|p| p.z).fold(f32::MAX, f32::min);
        // Temple width: a slice above the ears (y in [0.02, 0.04] units).
        let slice: Vec<&Vec3> = head.iter().filter(|p| p.y > 0.02 && p.y < 0.04).collect();
        let width = slice.iter().map(|p| p.x).fold(f32::MIN, f32::max)
            - slice.iter().map(|p| p.x).fold(f32::MAX, f32::min);
        // The measurement the scale rests on (module doc, README): 0.252 and 0.167 units.
        assert!((depth - 0.252).abs() < 0.002, "depth {depth} units");
        assert!((width - 0.167).abs() < 0.002, "width {width} units");
        let (depth_m, width_m) = (depth * HEAD_METRES_PER_UNIT, width * HEAD_METRES_PER_UNIT);
        // Nose tip to back of the skull ≈ 0.19–0.23 m; width above the ears ≈ 0.13–0.16 m.
        assert!((0.19..0.23).contains(&depth_m), "depth {depth_m} m");
        assert!((0.13..0.16).contains(&width_m), "width {width_m} m");
        // Both ear boxes hold vertices of the scan.
        for (lo, hi) in EAR_BOXES_UNITS {
            let n = v
                .iter()
                .filter(|p| p.cmpge(lo).all() && p.cmple(hi).all())
                .count();
            assert!(n > 100, "ear box {lo}..{hi}: {n} vertices");
        }
    }

    #[test]
    fn ear_test_matches_boxes() {
        let s = HEAD_METRES_PER_UNIT;
        assert!(is_ear_point(Vec3::new(0.09, -0.02, -0.08) * s));
        assert!(is_ear_point(Vec3::new(-0.09, -0.02, -0.08) * s));
        assert!(!is_ear_point(Vec3::new(0.0, -0.036, 0.053) * s)); // nose tip
    }
}
