//! How far a lightmap is from the truth: an independent reference and the figures that compare
//! a lightmap with it.
//!
//! - [`reference`]: a texture-space Monte Carlo path tracer that shares none of the bake's
//!   approximations (no clusters, offsets or cells): per covered texel, the first order as the
//!   transport defines it plus the indirect light traced from the texel's surface point.
//! - [`compare`]: relative RMSE of the total and of the indirect term over interior covered
//!   texels (all 4 neighbours covered), energy ratio, worst texels.
//!
//! Every value is radiosity `B = π·L_out` in W/m², linear RGB, one per covered texel of a
//! [`crate::bake::texels::TexelGrid`], in the grid's texel order.

pub mod compare;
pub mod reference;
