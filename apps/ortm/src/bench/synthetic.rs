//! Synthetic transfer maps for `ortm bench render` when no bake is given: maps with the
//! crops a real bake of the same scene would get (see [`synthetic_transfer_maps`]).

use ortm::Lightmap;
use ortm::bake::texels::TexelGrid;
use ortm::maps::{MapsError, TransferMap};

/// Synthetic transfer maps for benchmarks, with the crops a real bake of the same scene
/// would get when every pair of covered texels exchanges light: the map of offset `Δt` is
/// non-zero at receiver `t` exactly when both `t` and `t + Δt` are covered texels of `grid`
/// (value `0.01·ρ(t)/(1 + |Δt|²)`, dimensionless), then cropped by
/// [`TransferMap::from_full`] like a baked map. A real bake's maps are zero where
/// visibility or the kernels vanish, so these are an upper bound on its stored texels (with
/// multiple bounces, nearly tight: the paper's 3 atlases for 50 maps of 256² imply maps
/// filled to ≈ 85 %).
pub fn synthetic_transfer_maps(
    grid: &TexelGrid,
    offsets: &[glam::IVec2],
) -> Result<Vec<TransferMap>, MapsError> {
    let (w, h) = (grid.width, grid.height);
    let albedo = grid.albedo_map();
    let n = offsets.len().max(1) as f64;
    offsets
        .iter()
        .map(|&o| {
            let mut full = Lightmap::new(w, h);
            let k = 0.01 / (1.0 + o.length_squared() as f32);
            for t in &grid.texels {
                if grid.at(t.x as i32 + o.x, t.y as i32 + o.y).is_some() {
                    let rho = albedo.get(t.x, t.y);
                    full.set(t.x, t.y, rho.map(|c| (c * k).max(1e-6)));
                }
            }
            TransferMap::from_full(o, 1.0 / n, k as f64, &full)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_maps_are_non_zero_exactly_where_receiver_and_sender_are_covered() {
        let scene = ortm::scene::cornell_box(32);
        let grid = TexelGrid::build(&scene).unwrap();
        let offsets = [
            glam::IVec2::ZERO,
            glam::IVec2::new(5, -3),
            glam::IVec2::new(-31, 31),
        ];
        let maps = synthetic_transfer_maps(&grid, &offsets).unwrap();
        for (m, o) in maps.iter().zip(offsets) {
            assert_eq!(m.offset, o);
            for y in 0..32 {
                for x in 0..32 {
                    let both = grid.at(x, y).is_some() && grid.at(x + o.x, y + o.y).is_some();
                    let v = m.value_at(x as u32, y as u32);
                    assert_eq!(v.iter().all(|c| *c > 0.0), both, "({x}, {y}) offset {o}");
                    assert_eq!(v.iter().any(|c| *c != 0.0), both, "({x}, {y}) offset {o}");
                }
            }
        }
        // The zero offset covers every covered texel; the far corner offset almost nothing.
        assert!(maps[0].stored_texels() as usize >= grid.texels.len());
        assert!(maps[2].stored_texels() < maps[1].stored_texels());
    }
}
