//! CPU mirror of the gutter-dilation pass (`shaders/dilate.wgsl`): every texel with
//! alpha > 0, and every texel the [`DilatePlan`] marks covered, is copied unchanged; another
//! empty texel whose [`DilatePlan`] source is covered in
//! the input becomes that texel's RGB with alpha [`FILLED_ALPHA`] (nearest-texel copy, see
//! [`crate::dilate`]); every other texel is 0. Both GPU paths
//! ([`crate::dilate::DilatePath`]) give exactly this.

use crate::dilate::{DilatePlan, FILLED_ALPHA};
use crate::error::PassError;
use crate::types::TexelImage;

/// Dilates `src` with `plan`.
///
/// # Errors
/// [`PassError::InvalidInput`] when the plan was built for another map size or holds a
/// source index outside the map.
pub fn dilate(src: &TexelImage, plan: &DilatePlan) -> Result<TexelImage, PassError> {
    if (plan.width, plan.height) != (src.width, src.height) || plan.sources.len() != src.rgba.len()
    {
        return Err(PassError::InvalidInput {
            what: "DilatePlan".into(),
            problem: format!(
                "built for a {}×{} map, the map is {}×{}; build the plan from this map's \
                 coverage",
                plan.width, plan.height, src.width, src.height
            ),
        });
    }
    plan.check_sources()?;
    let mut out = TexelImage::new(src.width, src.height);
    for y in 0..src.height {
        for x in 0..src.width {
            let c = src.get(x, y);
            let own = y as usize * src.width as usize + x as usize;
            *out.at_mut(x, y) = if c[3] > 0.0 || plan.sources[own] as usize == own {
                c
            } else {
                match plan.source(x, y) {
                    Some((sx, sy)) => {
                        let v = src.get(sx, sy);
                        if v[3] > 0.0 {
                            [v[0], v[1], v[2], FILLED_ALPHA]
                        } else {
                            [0.0; 4]
                        }
                    }
                    None => [0.0; 4],
                }
            };
        }
    }
    Ok(out)
}
