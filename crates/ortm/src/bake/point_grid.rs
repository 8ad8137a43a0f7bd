//! Points in a uniform grid of cubes, for the neighbour queries of the bake: the texels within a
//! subsurface profile's support ([`crate::bake::transport::SupportGrid`]) and the texel centres
//! near a receiver ([`crate::bake::near_gather`]).
//!
//! Each point is an index (a texel's, in the grid's order) at a position in metres; a cube of
//! side `cell_m` holds the points whose positions floor to it. Queries visit whole cubes, so they
//! return a superset of the points within the asked distance: callers test the distance
//! themselves. Cubes are visited in `z`, `y`, `x` order and each cube's points in insertion
//! order, so a query's order is deterministic.

use std::collections::HashMap;

use glam::Vec3;

/// Point indices in a uniform grid of cubes `cell_m` wide (module docs).
pub struct PointGrid {
    cell_m: f64,
    cells: HashMap<(i64, i64, i64), Vec<u32>>,
}

impl PointGrid {
    /// The grid of cubes `cell_m` wide (metres, > 0) holding `points` (index, position).
    pub fn new(cell_m: f64, points: impl IntoIterator<Item = (u32, Vec3)>) -> Self {
        let mut grid = Self {
            cell_m,
            cells: HashMap::new(),
        };
        for (i, p) in points {
            grid.cells.entry(grid.key(p)).or_default().push(i);
        }
        grid
    }

    /// Whether the grid holds no point.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    fn key(&self, p: Vec3) -> (i64, i64, i64) {
        let q = (p.as_dvec3() / self.cell_m).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    }

    /// Calls `f` with every point in the cubes at most `rings` cubes from `p`'s along each axis
    /// (a superset of the points within `rings · cell_m` of `p`).
    pub fn for_each_around(&self, p: Vec3, rings: i64, mut f: impl FnMut(u32)) {
        if self.cells.is_empty() {
            return;
        }
        let (x, y, z) = self.key(p);
        for dz in -rings..=rings {
            for dy in -rings..=rings {
                for dx in -rings..=rings {
                    if let Some(list) = self.cells.get(&(x + dx, y + dy, z + dz)) {
                        list.iter().for_each(|&i| f(i));
                    }
                }
            }
        }
    }

    /// Calls `f` with every point within `r` metres of `p` (and a few more).
    pub fn for_each_within(&self, p: Vec3, r: f32, f: impl FnMut(u32)) {
        let rings = (f64::from(r.max(0.0)) / self.cell_m).ceil() as i64;
        self.for_each_around(p, rings, f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every point within the distance is visited, against a brute-force scan, at radii
    /// below, at and above the cube size.
    #[test]
    fn within_visits_every_point_in_range() {
        let points: Vec<(u32, Vec3)> = (0..2000u32)
            .map(|i| {
                let h =
                    |k: u32| ((i.wrapping_mul(2654435761).wrapping_add(k * 40503)) % 1000) as f32;
                (i, Vec3::new(h(1), h(2), h(3)) * 1e-3 - 0.5)
            })
            .collect();
        let grid = PointGrid::new(0.05, points.iter().copied());
        for (k, &(_, p)) in points.iter().enumerate().step_by(97) {
            for r in [0.01f32, 0.05, 0.13] {
                let mut seen = Vec::new();
                grid.for_each_within(p, r, |i| seen.push(i));
                seen.sort_unstable();
                let before = seen.len();
                seen.dedup();
                assert_eq!(seen.len(), before, "point {k}: a point visited twice");
                for &(i, q) in &points {
                    if (q - p).length() <= r {
                        assert!(
                            seen.binary_search(&i).is_ok(),
                            "point {k}, r {r}: {i} missed"
                        );
                    }
                }
            }
        }
    }
}
