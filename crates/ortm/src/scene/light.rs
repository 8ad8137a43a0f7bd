//! Light sources and their one text syntax.
//!
//! A [`Light`] is a point, spot or directional light in SI units: positions in metres,
//! point and spot intensity in W/sr, directional irradiance in W/m², colours as linear-RGB
//! multipliers of that quantity. Directions are unit vectors pointing where the light
//! travels (a spot's axis, a directional light's rays).
//!
//! # Text form
//! Every string form of a light (the `--light` option of `ortm render` and `ortm view`, the
//! commands `ortm demo face` prints and runs) is [`LIGHT_SYNTAX`]: [`parse_light`] reads it
//! and `Display` writes it, so `parse_light(&l.to_string()) == Ok(l)` for any valid light
//! whose direction is already unit length. The scene file's `[[light]]` tables are the file
//! form (`scene::file`, `docs/scene-format.md`).
//!
//! ```text
//! point:X,Y,Z:INTENSITY_W_SR[:R,G,B]
//! spot:X,Y,Z:DX,DY,DZ:INTENSITY_W_SR:INNER_DEG,OUTER_DEG[:R,G,B]
//! dir:DX,DY,DZ:IRRADIANCE_W_M2[:R,G,B]        (`directional:` is accepted too)
//! ```

use std::fmt;

use glam::Vec3;

/// A light source. Colours are linear RGB multipliers of the stated power quantity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Isotropic point light.
    Point {
        /// Position in metres.
        position_m: Vec3,
        /// Linear RGB tint (multiplies the intensity per channel).
        color: Vec3,
        /// Radiant intensity in W/sr.
        intensity_w_sr: f32,
    },
    /// Spot light with a smooth falloff between the inner and outer cone.
    Spot {
        /// Position in metres.
        position_m: Vec3,
        /// Unit direction the spot points to.
        direction: Vec3,
        /// Linear RGB tint.
        color: Vec3,
        /// Radiant intensity on the axis, in W/sr.
        intensity_w_sr: f32,
        /// Half-angle of full intensity, degrees.
        inner_deg: f32,
        /// Half-angle beyond which the intensity is zero, degrees.
        outer_deg: f32,
    },
    /// Directional (distant) light.
    Directional {
        /// Unit direction the light travels (from the light towards the scene).
        direction: Vec3,
        /// Linear RGB tint.
        color: Vec3,
        /// Irradiance on a surface facing the light, W/m².
        irradiance_w_m2: f32,
    },
}

impl Light {
    /// The light's type as the scene file names it: `point`, `spot` or `directional`.
    pub fn type_name(&self) -> &'static str {
        match self {
            Light::Point { .. } => "point",
            Light::Spot { .. } => "spot",
            Light::Directional { .. } => "directional",
        }
    }

    /// The linear-RGB tint.
    pub fn color(&self) -> Vec3 {
        match *self {
            Light::Point { color, .. }
            | Light::Spot { color, .. }
            | Light::Directional { color, .. } => color,
        }
    }

    /// The position in metres (point and spot lights); `None` for a directional light.
    pub fn position(&self) -> Option<Vec3> {
        match *self {
            Light::Point { position_m, .. } | Light::Spot { position_m, .. } => Some(position_m),
            Light::Directional { .. } => None,
        }
    }

    /// The strength: intensity in W/sr (point, spot) or irradiance in W/m² (directional).
    pub fn strength(&self) -> f32 {
        match *self {
            Light::Point { intensity_w_sr, .. } | Light::Spot { intensity_w_sr, .. } => {
                intensity_w_sr
            }
            Light::Directional {
                irradiance_w_m2, ..
            } => irradiance_w_m2,
        }
    }

    /// Where the light points or travels (spot and directional lights); `None` for a point
    /// light.
    pub fn direction(&self) -> Option<Vec3> {
        match *self {
            Light::Spot { direction, .. } | Light::Directional { direction, .. } => Some(direction),
            Light::Point { .. } => None,
        }
    }

    /// Shadow-map layers the first-order pass gives this light: 6 (a cube) for a point
    /// light, 1 for a spot or directional light.
    pub fn shadow_layers(&self) -> u32 {
        match self {
            Light::Point { .. } => 6,
            Light::Spot { .. } | Light::Directional { .. } => 1,
        }
    }
}

/// Syntax of a light's text form (`--light`; also the `ortm render --help` text).
pub const LIGHT_SYNTAX: &str = "point:X,Y,Z:INTENSITY_W_SR[:R,G,B] | \
     spot:X,Y,Z:DX,DY,DZ:INTENSITY_W_SR:INNER_DEG,OUTER_DEG[:R,G,B] | \
     dir:DX,DY,DZ:IRRADIANCE_W_M2[:R,G,B] (metres; direction = where the light travels/points)";

/// A command-line value (`--light`, `--camera`, `--size`) that could not be parsed: the
/// message quotes the text, says what is wrong and gives the accepted syntax.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{what} {spec:?} is invalid: {problem}; expected {syntax}")]
pub struct SpecError {
    /// Which option (`--light`, `--camera`, `--size`).
    pub what: &'static str,
    /// The text given.
    pub spec: String,
    /// What is wrong.
    pub problem: String,
    /// The accepted syntax.
    pub syntax: &'static str,
}

impl SpecError {
    /// A maker of errors about `spec`, given to option `what` with syntax `syntax`: call it
    /// with the problem.
    pub fn maker<'a>(
        what: &'static str,
        spec: &'a str,
        syntax: &'static str,
    ) -> impl Fn(String) -> SpecError + 'a {
        move |problem| SpecError {
            what,
            spec: spec.to_owned(),
            problem,
            syntax,
        }
    }
}

/// Parses `N` comma-separated finite numbers from one `:`-field `part` of a spec; errors
/// are made by `err`.
pub fn spec_floats<const N: usize>(
    part: &str,
    err: &impl Fn(String) -> SpecError,
) -> Result<[f32; N], SpecError> {
    let vals: Vec<&str> = part.split(',').collect();
    if vals.len() != N {
        return Err(err(format!(
            "`{part}` has {} comma-separated numbers, expected {N}",
            vals.len()
        )));
    }
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(vals) {
        *o = v
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| err(format!("`{v}` is not a finite number")))?;
    }
    Ok(out)
}

/// Parses a light's text form ([`LIGHT_SYNTAX`]). Directions are normalised; the colour
/// defaults to white. Strengths must be ≥ 0, spot angles `0 ≤ inner ≤ outer < 90`.
pub fn parse_light(spec: &str) -> Result<Light, SpecError> {
    let fields = Fields {
        parts: spec.split(':').collect(),
        err: SpecError::maker("--light", spec, LIGHT_SYNTAX),
    };
    match fields.parts[0].trim() {
        "point" => {
            fields.count_in(3, 4)?;
            Ok(Light::Point {
                position_m: fields.vec3(1)?,
                intensity_w_sr: fields.strength(2)?,
                color: fields.color(3)?,
            })
        }
        "spot" => {
            fields.count_in(5, 6)?;
            let [inner_deg, outer_deg] = spec_floats::<2>(fields.parts[4], &fields.err)?;
            if !(0.0..90.0).contains(&outer_deg) || !(0.0..=outer_deg).contains(&inner_deg) {
                return Err((fields.err)(format!(
                    "cone angles {inner_deg}, {outer_deg} must satisfy 0 ≤ inner ≤ outer < 90"
                )));
            }
            Ok(Light::Spot {
                position_m: fields.vec3(1)?,
                direction: fields.direction(2)?,
                intensity_w_sr: fields.strength(3)?,
                inner_deg,
                outer_deg,
                color: fields.color(5)?,
            })
        }
        "dir" | "directional" => {
            fields.count_in(3, 4)?;
            Ok(Light::Directional {
                direction: fields.direction(1)?,
                irradiance_w_m2: fields.strength(2)?,
                color: fields.color(3)?,
            })
        }
        other => Err((fields.err)(format!(
            "unknown light type `{other}` (use point, spot or dir)"
        ))),
    }
}

/// The `:`-separated fields of a light spec and the error maker for it.
struct Fields<'a, E: Fn(String) -> SpecError> {
    parts: Vec<&'a str>,
    err: E,
}

impl<E: Fn(String) -> SpecError> Fields<'_, E> {
    /// Checks that a light of this type has `lo..=hi` fields.
    fn count_in(&self, lo: usize, hi: usize) -> Result<(), SpecError> {
        let n = self.parts.len();
        if n < lo || n > hi {
            return Err((self.err)(format!(
                "has {n} ':'-separated fields, a {} light takes {lo}..={hi}",
                self.parts[0]
            )));
        }
        Ok(())
    }

    /// Field `i` as three numbers.
    fn vec3(&self, i: usize) -> Result<Vec3, SpecError> {
        spec_floats::<3>(self.parts[i], &self.err).map(Vec3::from_array)
    }

    /// Field `i` as an intensity or irradiance (≥ 0).
    fn strength(&self, i: usize) -> Result<f32, SpecError> {
        let p = self.parts[i];
        let [s] = spec_floats::<1>(p, &self.err)?;
        if s < 0.0 {
            return Err((self.err)(format!("strength `{p}` is negative")));
        }
        Ok(s)
    }

    /// Field `i` as a direction (normalised; not zero).
    fn direction(&self, i: usize) -> Result<Vec3, SpecError> {
        let p = self.parts[i];
        self.vec3(i)?
            .try_normalize()
            .ok_or_else(|| (self.err)(format!("direction `{p}` is the zero vector")))
    }

    /// The optional colour field `i` (white when absent; no negative channel).
    fn color(&self, i: usize) -> Result<Vec3, SpecError> {
        let Some(p) = self.parts.get(i) else {
            return Ok(Vec3::ONE);
        };
        let c = self.vec3(i)?;
        if c.min_element() < 0.0 {
            return Err((self.err)(format!("colour `{p}` has a negative channel")));
        }
        Ok(c)
    }
}

/// Writes the light's text form ([`LIGHT_SYNTAX`], colour always given; numbers in Rust's
/// shortest round-trip form), which [`parse_light`] reads back. Fields in the syntax's
/// order: type, position, direction, strength, cone angles, colour.
impl fmt::Display for Light {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = |v: Vec3| format!("{},{},{}", v.x, v.y, v.z);
        let kind = match self {
            Light::Directional { .. } => "dir",
            other => other.type_name(),
        };
        f.write_str(kind)?;
        if let Some(p) = self.position() {
            write!(f, ":{}", v(p))?;
        }
        if let Some(d) = self.direction() {
            write!(f, ":{}", v(d))?;
        }
        write!(f, ":{}", self.strength())?;
        if let Light::Spot {
            inner_deg,
            outer_deg,
            ..
        } = self
        {
            write!(f, ":{inner_deg},{outer_deg}")?;
        }
        write!(f, ":{}", v(self.color()))
    }
}

impl std::str::FromStr for Light {
    type Err = SpecError;

    /// [`parse_light`].
    fn from_str(s: &str) -> Result<Self, SpecError> {
        parse_light(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_specs_parse_and_bad_ones_say_why() {
        let l = parse_light("point:0.1,0.5,-2:8").unwrap();
        assert_eq!(
            l,
            Light::Point {
                position_m: Vec3::new(0.1, 0.5, -2.0),
                color: Vec3::ONE,
                intensity_w_sr: 8.0
            }
        );
        let Light::Spot {
            direction,
            inner_deg,
            outer_deg,
            color,
            ..
        } = parse_light("spot:0,1,0:0,-2,0:40:20,35:1,0.5,0.25").unwrap()
        else {
            panic!("not a spot")
        };
        assert_eq!(direction, Vec3::NEG_Y);
        assert_eq!((inner_deg, outer_deg), (20.0, 35.0));
        assert_eq!(color, Vec3::new(1.0, 0.5, 0.25));
        let Light::Directional {
            direction,
            irradiance_w_m2,
            ..
        } = parse_light("dir:0,0,-3:20").unwrap()
        else {
            panic!("not directional")
        };
        assert_eq!((direction, irradiance_w_m2), (Vec3::NEG_Z, 20.0));
        for (bad, needle) in [
            ("lamp:0,0,0:1", "unknown light type"),
            ("point:0,0:1", "expected 3"),
            ("point:0,0,0:-1", "negative"),
            ("point:0,0,0:x", "not a finite number"),
            ("dir:0,0,0:5", "zero vector"),
            ("spot:0,0,0:0,-1,0:1:40,30", "inner ≤ outer"),
            ("point:0,0,0", "fields"),
        ] {
            let e = parse_light(bad).unwrap_err().to_string();
            assert!(e.contains(needle), "{bad}: {e}");
            assert!(e.contains("point:X,Y,Z"), "syntax missing: {e}");
        }
    }

    #[test]
    fn the_text_form_reads_back_exactly() {
        let lights = [
            Light::Point {
                position_m: Vec3::new(0.1, -0.25, 3.0e-3),
                color: Vec3::new(1.0, 0.5, 0.125),
                intensity_w_sr: 0.3,
            },
            Light::Spot {
                position_m: Vec3::new(0.0, 1.0, 0.0),
                direction: Vec3::NEG_Y,
                color: Vec3::ONE,
                intensity_w_sr: 40.0,
                inner_deg: 20.0,
                outer_deg: 35.5,
            },
            Light::Directional {
                direction: Vec3::new(-0.45, -0.35, -0.82).normalize(),
                color: Vec3::ONE,
                irradiance_w_m2: 5.0,
            },
        ];
        for l in lights {
            assert_eq!(parse_light(&l.to_string()), Ok(l), "{l}");
        }
        assert_eq!(
            lights[0].to_string(),
            "point:0.1,-0.25,0.003:0.3:1,0.5,0.125"
        );
    }
}
