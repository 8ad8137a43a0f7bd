//! Face data for ortm (issue 7): everything that describes *the face* rather than the transport.
//!
//! - [`skin`]: measured subsurface coefficients of Jensen, Marschner, Levoy & Hanrahan 2001
//!   (σ_s', σ_a per RGB channel in mm⁻¹, η = 1.3), the two skin presets among them, and the
//!   exponential-falloff alternative (the paper's Sec. 4.2 uses both);
//! - [`head`]: the scanned head preset — where its OBJ lives (`$ORTM_HEAD_OBJ` or
//!   `../shared/faces/head.obj`), metres per model unit, albedo, skin preset and the credit line
//!   the CC BY 3.0 licence requires;
//! - [`figures`]: the light and camera set-ups of the paper's face figures (Figs. 3–6), as
//!   plain data in metres, W/sr and W/m².
//!
//! This crate is plain data plus a few closed-form helpers (glam only). The `ortm` crate
//! depends on it and converts the data into its own scene and light types; nothing here depends
//! on `ortm`.

pub mod figures;
pub mod head;
pub mod skin;

pub use figures::{FIGURES, FigCamera, FigLight, Figure};
pub use head::{
    HEAD_ALBEDO, HEAD_CREDIT, HEAD_METRES_PER_UNIT, HEAD_OBJ_ENV, HEAD_SKIN, head_obj_path,
};
pub use skin::{Falloff, MEASURED, MeasuredMaterial, SKIN_ETA, measured};
