//! Test fixtures shared by the unit tests of the bake directory modules.

use glam::IVec2;

use crate::Lightmap;
use crate::maps::TransferMap;

/// Bake settings with nested values (the bake key must canonicalise them).
pub fn settings() -> serde_json::Value {
    serde_json::json!({"offsets": 3, "seed": 42, "nested": {"b": [1, 2.5], "a": "x"}})
}

/// Three small maps of a 16×8 lightmap: two with values (one tiny), one empty.
pub fn maps() -> Vec<TransferMap> {
    (0..3)
        .map(|i| {
            let mut full = Lightmap::new(16, 8);
            if i != 1 {
                full.set(i, 2, [0.25, 0.5, 1.0 / (i as f32 + 3.0)]);
                full.set(10, 7, [1e-6, 0.0, 0.0]);
            }
            TransferMap::from_full(IVec2::new(i as i32 - 1, 2), 0.1 * i as f64, 1.5, &full).unwrap()
        })
        .collect()
}
