//! The identity of a bake and the names of its files: [`BakeKey`] (which bake a file belongs
//! to) and [`map_file_name`] (where map `i` lives). Both the map files and the index use them.

use glam::IVec2;

use crate::io::sha256_hex;

/// Identifies one bake configuration: SHA-256 (hex) of the scene hash and the canonical JSON of
/// the settings. Files stamped with a different key belong to another bake.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BakeKey(String);

impl BakeKey {
    /// Key of `(scene_hash, settings)`. Object keys of `settings` are sorted recursively before
    /// hashing, so key order does not matter; number formatting follows `serde_json`.
    pub fn new(scene_hash: &str, settings: &serde_json::Value) -> Self {
        let mut canon = String::new();
        canonical_json(settings, &mut canon);
        let mut bytes = b"ortm-bake-key-v1\0".to_vec();
        bytes.extend_from_slice(&(scene_hash.len() as u64).to_le_bytes());
        bytes.extend_from_slice(scene_hash.as_bytes());
        bytes.extend_from_slice(canon.as_bytes());
        Self(sha256_hex(&bytes))
    }

    /// The key as 64 lower-case hex digits.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The key as an owned string.
    pub fn into_string(self) -> String {
        self.0
    }
}

/// Serialises `v` with object keys sorted at every level.
fn canonical_json(v: &serde_json::Value, out: &mut String) {
    use serde_json::Value;
    match v {
        Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            out.push('{');
            for (i, k) in keys.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&Value::String(k.clone()).to_string());
                out.push(':');
                canonical_json(&map[k], out);
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                canonical_json(item, out);
            }
            out.push(']');
        }
        scalar => out.push_str(&scalar.to_string()),
    }
}

/// Deterministic file name of map `index` with `offset`: `map_<index:05>_<±dx>_<±dy>.exr`,
/// e.g. `map_00012_+3_-17.exr`.
pub fn map_file_name(index: u32, offset: IVec2) -> String {
    format!("map_{index:05}_{:+}_{:+}.exr", offset.x, offset.y)
}

/// Inverse of [`map_file_name`]; `None` unless `name` is exactly such a name.
pub(crate) fn parse_map_file_name(name: &str) -> Option<(u32, IVec2)> {
    let stem = name.strip_prefix("map_")?.strip_suffix(".exr")?;
    let mut it = stem.split('_');
    let index: u32 = it.next()?.parse().ok()?;
    let dx: i32 = it.next()?.parse().ok()?;
    let dy: i32 = it.next()?.parse().ok()?;
    let offset = IVec2::new(dx, dy);
    (it.next().is_none() && map_file_name(index, offset) == name).then_some((index, offset))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_round_trip() {
        for (i, o) in [
            (0, IVec2::ZERO),
            (12, IVec2::new(3, -17)),
            (123456, IVec2::new(-9, 0)),
        ] {
            let n = map_file_name(i, o);
            assert_eq!(parse_map_file_name(&n), Some((i, o)), "{n}");
            assert!(crate::io::plain_file_name(&n));
        }
        assert_eq!(
            map_file_name(12, IVec2::new(3, -17)),
            "map_00012_+3_-17.exr"
        );
        for bad in [
            "map_1_+0_+0.exr",
            "map_00001_0_+0.exr",
            "map_00001_+0_+0.png",
            "x.exr",
        ] {
            assert_eq!(parse_map_file_name(bad), None, "{bad}");
        }
    }

    #[test]
    fn bake_key_ignores_key_order_but_not_values() {
        let a = serde_json::json!({"x": 1, "y": {"p": true, "q": [1, 2]}});
        let b: serde_json::Value =
            serde_json::from_str(r#"{"y": {"q": [1, 2], "p": true}, "x": 1}"#).unwrap();
        assert_eq!(BakeKey::new("s", &a), BakeKey::new("s", &b));
        assert_ne!(BakeKey::new("s", &a), BakeKey::new("t", &a));
        let c = serde_json::json!({"x": 2, "y": {"p": true, "q": [1, 2]}});
        assert_ne!(BakeKey::new("s", &a), BakeKey::new("s", &c));
        // Scene hash and settings are length-separated: shifting text between them differs.
        assert_ne!(
            BakeKey::new("a", &serde_json::json!("b")),
            BakeKey::new("a\"", &serde_json::json!(""))
        );
        assert!(crate::io::is_hex_digest(BakeKey::new("s", &a).as_str()));
    }
}
