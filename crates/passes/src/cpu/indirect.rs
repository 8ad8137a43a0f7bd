//! CPU mirror of the indirect-light pass (`shaders/indirect.wgsl`): per texel
//! `final − first order` in RGB, alpha = the first-order map's (coverage).

use crate::error::PassError;
use crate::types::TexelImage;

/// `final_map − first_order` per texel (RGB), alpha from `first_order`.
///
/// # Errors
/// [`PassError::InvalidInput`] when the maps differ in size.
pub fn indirect(first_order: &TexelImage, final_map: &TexelImage) -> Result<TexelImage, PassError> {
    if (first_order.width, first_order.height) != (final_map.width, final_map.height) {
        return Err(PassError::InvalidInput {
            what: "indirect maps".into(),
            problem: format!(
                "first order is {}×{}, final is {}×{}",
                first_order.width, first_order.height, final_map.width, final_map.height
            ),
        });
    }
    let rgba = first_order
        .rgba
        .iter()
        .zip(&final_map.rgba)
        .map(|(a, b)| [b[0] - a[0], b[1] - a[1], b[2] - a[2], a[3]])
        .collect();
    Ok(TexelImage {
        width: first_order.width,
        height: first_order.height,
        rgba,
    })
}
