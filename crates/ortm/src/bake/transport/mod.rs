//! Light transport between lightmap texels: the radiance transfer `R(t, t')` of the paper's
//! Eq. 7 — radiosity with visibility (all bounces) and subsurface scattering.
//!
//! # Model
//! Per colour channel, texel `i` turns irradiance `E` (W/m²) into radiosity `B` (W/m²) by an
//! *exitance operator* `X`: `B_i = ρ_i E_i` for opaque diffuse texels, and
//! `B_i = Σ_j S_ij E_j` for translucent ones, with `S_ij = R_d(|x_i − x_j|) A_j` the dipole (or
//! exponential) profile ([`crate::scene::subsurface`], tabulated by [`dipole`]) between texels
//! of the same translucent material. Radiosity travels between texels by the form factors
//! `F_ij` with visibility ([`form_factor`], [`crate::bake::raycast`]):
//! `E_i = E_direct,i + Σ_j F_ij B_j`. So `B = X(E_d + F B)` and, with the first-order
//! lightmap `B_o = ρ̄ E_d` (ρ̄ = the effective albedo: ρ, or the profile's total diffuse
//! reflectance),
//!
//! ```text
//! B = B_o + R B_o,   R = (I − X F)⁻¹ X ρ̄⁻¹ − I .
//! ```
//!
//! For purely diffuse scenes `R = K + K² + …` with `K = ρF` (all bounces). For translucent
//! texels the first term `X ρ̄⁻¹ − I` redistributes the first-order light under the skin (its
//! diagonal is negative: light that entered at `t` and leaves elsewhere).
//!
//! # Evaluating R for any pair
//! The offset stage needs `R(t, t')` for arbitrary pairs of texels of lightmaps far too large to
//! invert. [`Transport`] splits `R = R_fine + R_rem`:
//! - `R_fine(i, j) = (X ρ̄⁻¹ − I)_ij + ρ̄_i F_ij` — the subsurface redistribution and the first
//!   diffuse bounce, evaluated exactly per pair (one visibility ray);
//! - `R_rem` — every higher-order term (bounce² and up, subsurface-then-bounce, …), which is smooth,
//!   solved densely ([`dense`]) at a coarse level where each patch is a cluster of texels
//!   ([`coarse`]), and spread to texel pairs by area: `R_rem(i, j) ≈ R_rem(I, J)·A_j/A_J`.
//!   The error of this approximation is measured against the exact solve in the tests and by
//!   `ortm bench transport`.
//!
//! For small lightmaps (≤ ~4,000 covered texels) [`dense::DenseTransport`] solves the whole system
//! exactly: the ground truth of every later stage.

pub mod coarse;
pub mod dense;
pub mod dipole;
pub mod form_factor;

use std::sync::Arc;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
use crate::scene::Scene;
use crate::scene::subsurface::Profile;
use dipole::RdTable;
use form_factor::{FfPatch, unoccluded_form_factor};

/// Which transport effects a bake includes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Effects {
    /// Interreflection between surfaces (radiosity with visibility, all bounces).
    pub radiosity: bool,
    /// Subsurface scattering in translucent materials.
    pub subsurface: bool,
}

impl Default for Effects {
    fn default() -> Self {
        Self {
            radiosity: true,
            subsurface: true,
        }
    }
}

/// A surface patch: one texel, or a cluster of texels at the coarse level.
#[derive(Clone, Copy, Debug)]
pub struct Patch {
    /// Centroid, metres.
    pub position_m: Vec3,
    /// Unit normal (shading normal, used for the form-factor cosines).
    pub normal: Vec3,
    /// Unit normal used to lift visibility rays off the surface.
    pub lift_normal: Vec3,
    /// Area, m².
    pub area_m2: f32,
    /// Effective albedo ρ̄ per channel.
    pub rho: Vec3,
    /// Material index (subsurface transfer only between patches of one material).
    pub material: u32,
}

impl Patch {
    /// The patch as seen by the form-factor kernels.
    pub fn ff(&self) -> FfPatch {
        FfPatch {
            position_m: self.position_m,
            normal: self.normal,
            area_m2: self.area_m2,
        }
    }
}

/// Patches of every covered texel of `grid`, in texel order.
pub fn texel_patches(grid: &TexelGrid) -> Vec<Patch> {
    grid.texels
        .iter()
        .map(|t| Patch {
            position_m: t.position_m,
            normal: t.normal,
            lift_normal: t.face_normal,
            area_m2: t.area_m2,
            rho: t.albedo,
            material: t.material,
        })
        .collect()
}

/// The per-pair kernels shared by the dense solver and the pair evaluator: form factors with
/// visibility and subsurface profile weights.
pub struct Kernels {
    /// Effects enabled.
    pub effects: Effects,
    /// Subsurface profile per material (`None` = opaque, or subsurface disabled).
    pub profiles: Vec<Option<Profile>>,
    /// Support radius per material's profile, metres (beyond it `R_d` is negligible).
    pub support_m: Vec<f64>,
    /// Per material, the profile tabulated on `[0, support_m]` (what the pair kernels read).
    pub tables: Vec<Option<RdTable>>,
    /// Ray caster over the scene.
    pub visibility: Arc<Visibility>,
}

impl Kernels {
    /// Kernels for `scene` with `effects`.
    pub fn new(scene: &Scene, effects: Effects, visibility: Arc<Visibility>) -> Self {
        let profiles = scene
            .materials
            .iter()
            .map(|m| m.subsurface.as_ref().map(Profile::new))
            .collect();
        Self::from_parts(effects, profiles, visibility)
    }

    /// Kernels from parts: `profiles` per material index (`None` = opaque).
    pub fn from_parts(
        effects: Effects,
        profiles: Vec<Option<Profile>>,
        visibility: Arc<Visibility>,
    ) -> Self {
        let profiles: Vec<Option<Profile>> = profiles
            .into_iter()
            .map(|p| p.filter(|_| effects.subsurface))
            .collect();
        let support_m = profiles
            .iter()
            .map(|p| p.map_or(0.0, |p| p.support_radius(1e-4)))
            .collect();
        let tables = profiles
            .iter()
            .zip(&support_m)
            .map(|(p, &r)| p.as_ref().map(|p| RdTable::new(p, r)))
            .collect();
        Self {
            effects,
            profiles,
            support_m,
            tables,
            visibility,
        }
    }

    /// Symmetric form-factor factor `c_ij = F_ij / A_j` (m⁻²) with visibility; `F_ij = c_ij A_j`.
    #[inline]
    pub fn form_factor_c(&self, a: &Patch, b: &Patch) -> f32 {
        if !self.effects.radiosity {
            return 0.0;
        }
        let c = unoccluded_form_factor(&a.ff(), &b.ff());
        if c <= 0.0 {
            return 0.0;
        }
        let eps = 1e-3 * a.area_m2.max(b.area_m2).sqrt();
        let pa = a.position_m + a.lift_normal * eps;
        let pb = b.position_m + b.lift_normal * eps;
        if self.visibility.visible(pa, pb, eps) {
            c
        } else {
            0.0
        }
    }

    /// Subsurface exitance weights `S_ij` (per channel, dimensionless: fraction of `E_j·A_j`
    /// per unit area leaving at `i`, i.e. `B_i = Σ_j S_ij E_j`). `self_pair` selects the
    /// near-singular self term, integrated over a disk of the patch's area.
    #[inline]
    pub fn subsurface(&self, a: &Patch, b: &Patch, self_pair: bool) -> Option<[f64; 3]> {
        if a.material != b.material {
            return None;
        }
        let p = self.profiles[a.material as usize].as_ref()?;
        if self_pair {
            let radius = (a.area_m2 as f64 / std::f64::consts::PI).sqrt();
            return Some(p.disk_integral(radius));
        }
        let r = (a.position_m - b.position_m).length() as f64;
        if r > self.support_m[a.material as usize] {
            return Some([0.0; 3]);
        }
        let rd = match &self.tables[a.material as usize] {
            Some(t) => t.rd(r),
            None => p.rd(r),
        };
        let area = b.area_m2 as f64;
        Some([rd[0] * area, rd[1] * area, rd[2] * area])
    }

    /// True when material `m` scatters under the surface.
    #[inline]
    pub fn is_translucent(&self, m: u32) -> bool {
        self.profiles[m as usize].is_some()
    }

    /// `R_fine(i, j)` per channel: subsurface redistribution plus the first diffuse bounce
    /// (see the module docs). `i == j` must be signalled by `same`.
    #[inline]
    pub fn r_fine(&self, a: &Patch, b: &Patch, same: bool) -> [f64; 3] {
        let s = self.r_subsurface(a, b, same);
        let f = self.r_bounce(a, b, same);
        [s[0] + f[0], s[1] + f[1], s[2] + f[2]]
    }

    /// The subsurface part of `R_fine(i, j)`: `S_ij / ρ̄_j − δ_ij` between texels of one
    /// translucent material, else 0. No ray is cast.
    #[inline]
    pub fn r_subsurface(&self, a: &Patch, b: &Patch, same: bool) -> [f64; 3] {
        let mut out = [0.0f64; 3];
        if self.is_translucent(a.material)
            && let Some(s) = self.subsurface(a, b, same)
        {
            for (c, o) in out.iter_mut().enumerate() {
                let rho = b.rho[c] as f64;
                *o = if rho > 0.0 { s[c] / rho } else { 0.0 } - if same { 1.0 } else { 0.0 };
            }
        }
        out
    }

    /// The first-bounce part of `R_fine(i, j)`: `ρ̄_i F_ij` with visibility (one shadow ray when
    /// the patches face each other); 0 for `i == j`.
    #[inline]
    pub fn r_bounce(&self, a: &Patch, b: &Patch, same: bool) -> [f64; 3] {
        let mut out = [0.0f64; 3];
        if !same {
            let f = self.form_factor_c(a, b) as f64 * b.area_m2 as f64;
            if f > 0.0 {
                for (c, o) in out.iter_mut().enumerate() {
                    *o = a.rho[c] as f64 * f;
                }
            }
        }
        out
    }
}

/// Evaluates `R(t, t')` for any pair of covered texels of a lightmap (see the module docs).
pub struct Transport {
    /// Covered texels as patches (texel order of the grid).
    pub patches: Vec<Patch>,
    /// Kernels.
    pub kernels: Kernels,
    /// Higher-order remainder at the coarse level.
    pub remainder: coarse::Remainder,
}

impl Transport {
    /// Builds the evaluator: texel patches, BVH, and the coarse remainder solve with clusters of
    /// `block × block` texels.
    pub fn new(scene: &Scene, grid: &TexelGrid, effects: Effects, block: u32) -> Self {
        let visibility = Arc::new(Visibility::new(&scene.mesh));
        let kernels = Kernels::new(scene, effects, visibility);
        let patches = texel_patches(grid);
        let remainder = coarse::Remainder::new(grid, &patches, &kernels, block);
        Self {
            patches,
            kernels,
            remainder,
        }
    }

    /// True when texel `i` is translucent (its `R(i, i)` holds the subsurface point mass `−1`).
    #[inline]
    pub fn is_translucent(&self, i: u32) -> bool {
        self.kernels
            .is_translucent(self.patches[i as usize].material)
    }

    /// `R(i, j)` per channel for texels `i` (receiver) and `j` (sender), indices into the grid's
    /// texels: the fraction of `B_o(j)` added to `B(i)`.
    #[inline]
    pub fn r(&self, i: u32, j: u32) -> [f32; 3] {
        let (a, b) = (&self.patches[i as usize], &self.patches[j as usize]);
        let fine = self.kernels.r_fine(a, b, i == j);
        let rem = self.remainder.r(i, j, b.area_m2);
        [
            (fine[0] + rem[0] as f64) as f32,
            (fine[1] + rem[1] as f64) as f32,
            (fine[2] + rem[2] as f64) as f32,
        ]
    }
}
