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
//! # Subsurface weights
//! `S_ij = ∫_{P_j} R_d(|x_i − y|) dA(y)` (`R_d` in m⁻², so `S` is dimensionless): the profile
//! seen from receiver point `x_i`, integrated over sender texel `j`'s footprint `P_j`, the
//! parallelogram its texel maps to on its triangle's plane ([`footprint`]; polar integration
//! for near pairs and the self pair, Gauss–Legendre for far ones). So a sender's light spreads
//! over the surface it stands for, not from a point: the midpoint rule `R_d(r_ij)·A_j` is off
//! wherever the profile changes across a texel (skin's blue channel falls by `e` in 0.7 mm; the
//! head's texels are 1.8 mm at 256², 7 mm at 64²). Sender `j`'s incident power `E_j A_j` (W)
//! leaves as `Σ_i S_ij E_j A_i = Q_j E_j A_j`, with `Q_j = Σ_i S_ij A_i / A_j`. Where the
//! footprints tile the surface (a chart's interior, any texel size) `Q_j` is the profile's
//! integral over the plane, ρ̄ (Jensen's total diffuse reflectance, the first order's albedo;
//! tested to 0.1 %), and less near an edge of the surface.
//!
//! Footprints overlap where the centres of two charts' texels nearly coincide on a UV seam
//! (each stands for its own whole footprint) and where a curved surface folds its tangent
//! planes together; there `Q_j` exceeds what the continuous model re-emits and the discrete
//! operator would create light. That model's own re-emission at the texel,
//! `Q̂_j = ∫_S R_d(|x_j − y|) dA(y)` over the mesh's triangles of its material
//! ([`surface`]), is ρ̄ on a plane, more than ρ̄ where a fold brings more surface within the
//! profile's Euclidean reach, and less at an open edge. So every sender's column is scaled per
//! channel by `min(1, Q̂_j / Q_j)` ([`Patch::subsurface_scale`], set by
//! [`Kernels::normalise_subsurface`]): no texel re-emits more than the continuous surface
//! does, and where the footprints do not overlap the profile is kept exactly. Clusters, tree
//! nodes and kernels built without a mesh ([`Kernels::from_parts`]) are capped at ρ̄, the
//! plane's value. The scale belongs to the sender, so [`Kernels::subsurface`] — the only
//! source of `S` for the dense solve, the coarse level, the hierarchical operator and the pair
//! evaluator — applies it, and each of them normalises the patches it is given. Clusters and
//! tree nodes, which have no footprint, use the midpoint rule (a disk of their area for the
//! self pair).
//!
//! The cap holds the columns; nothing holds the rows `Σ_j S_ij`, what texel `i` re-emits under
//! a uniform irradiance, which the continuous model puts at `Q̂_i`. Footprints of unequal size
//! (UV stretch, seams) leave them off by 4.0 % RMS on the head at 64² and 2.5 % at 256²
//! (README, "The subsurface weights' rows"). [`Kernels::balance_rounds`] > 0 balances both:
//! `S_ij = α_i raw_ij β_j` with a receiver factor ([`Patch::subsurface_gather`]) beside the
//! sender's, rows and area-weighted columns scaled to `Q̂` in turn (Sinkhorn's iteration)
//! from every pair's raw weight — for the solves (`ortm solve --balance-subsurface R`) and the
//! bake's subsurface walk (`ortm bake --balance-subsurface R`); off by default.
//!
//! # Evaluating R for any pair
//! The offset stage needs `R(t, t')` for arbitrary pairs of texels of lightmaps far too large to
//! invert. [`Transport`] splits `R = R_fine + R_rem`:
//! - `R_fine(i, j) = (X ρ̄⁻¹ − I)_ij + ρ̄_i F_ij` — the subsurface redistribution and the first
//!   diffuse bounce, evaluated exactly per pair (one visibility ray);
//! - `R_rem` — every higher-order term (bounce² and up, subsurface-then-bounce, …), which is smooth,
//!   solved densely ([`dense`]) at a coarse level where each patch is a cluster of texels
//!   ([`coarse`]), and spread to texel pairs by area: `R_rem(i, j) ≈ R_rem(I, J)·A_j/A_J`
//!   (smooth except where the surface faces itself at close range: the hierarchical rows keep
//!   the texels of such slits as clusters of their own, [`coarse`], "Slits").
//!   The error of this approximation is measured against the exact solve in the tests and by
//!   `ortm bench transport`.
//!
//! For small lightmaps (≤ ~4,000 covered texels) [`dense::DenseTransport`] solves the whole system
//! exactly: the ground truth of every later stage.

pub mod coarse;
pub mod dense;
pub mod dipole;
pub mod footprint;
pub mod form_factor;
pub mod hier;
pub mod surface;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::bake::BakeEvent;
use crate::bake::point_grid::PointGrid;
use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
use crate::scene::Scene;
use crate::scene::subsurface::Profile;
use dipole::RdTable;
use form_factor::{FfPatch, unoccluded_form_factor};

/// Progress reporting and cancellation for the transport's set-up: phases and steps go to
/// `events` (the bake's progress bars), and `cancel` is polled between steps.
#[derive(Clone, Copy)]
pub struct SetupProgress<'a> {
    events: Option<&'a (dyn Fn(BakeEvent) + Sync)>,
    cancel: Option<&'a AtomicBool>,
}

/// The set-up stopped because its `cancel` flag was raised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cancelled;

impl<'a> SetupProgress<'a> {
    /// No reporting, never cancelled.
    pub fn none() -> Self {
        Self {
            events: None,
            cancel: None,
        }
    }

    /// Reports to `events` and stops when `cancel` is raised.
    pub fn new(events: &'a (dyn Fn(BakeEvent) + Sync), cancel: &'a AtomicBool) -> Self {
        Self {
            events: Some(events),
            cancel: Some(cancel),
        }
    }

    /// A phase of `total` steps starts.
    pub fn phase(&self, name: &'static str, total: u64) {
        if let Some(e) = self.events {
            e(BakeEvent::Phase { name, total });
        }
    }

    /// `n` more steps are done.
    pub fn advance(&self, n: u64) {
        if let Some(e) = self.events {
            e(BakeEvent::Advance(n));
        }
    }

    /// `Err(Cancelled)` once the cancel flag is raised.
    pub fn check(&self) -> Result<(), Cancelled> {
        match self.cancel {
            Some(c) if c.load(Ordering::Relaxed) => Err(Cancelled),
            _ => Ok(()),
        }
    }
}

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
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
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
    /// Per channel, the factor (≤ 1) on this patch's subsurface weights as a sender, set by
    /// [`Kernels::normalise_subsurface`] (see the module docs, "Subsurface weights"); 1 until
    /// then, and for opaque patches.
    pub subsurface_scale: Vec3,
    /// Per channel, the factor on this patch's subsurface weights as a receiver: 1 unless the
    /// weights are balanced ([`Kernels::balance_rounds`]), which scales the rows as well as the
    /// columns; set with [`Patch::subsurface_scale`].
    pub subsurface_gather: Vec3,
    /// A texel's footprint ([`crate::bake::texels::Texel::footprint_m`]): the profile is
    /// integrated over it as a sender (module docs, "Subsurface weights"), and its form factors
    /// are collocated at its centre ([`form_factor`]). `None` for clusters and tree nodes,
    /// which use the midpoint rule and the area-mean form factors.
    pub footprint_m: Option<[Vec3; 2]>,
}

impl Patch {
    /// The patch as seen by the form-factor kernels.
    pub fn ff(&self) -> FfPatch {
        FfPatch {
            position_m: self.position_m,
            normal: self.normal,
            area_m2: self.area_m2,
            texel: self.footprint_m.is_some(),
        }
    }
}

/// The fraction of a profile's power beyond its support radius ([`Kernels::support_m`]).
const SUPPORT_FRACTION: f64 = 1e-4;

/// Bytes of one pair's raw weight kept by [`Kernels::balance_rounds`]: receiver index and
/// three `f32`.
const BALANCE_PAIR_BYTES: u64 = 16;

/// The most rounds of balancing ([`Kernels::balance_rounds`]) `ortm solve` and `ortm bake`
/// take (each is two passes over the weights; 50 hold the rows within ~0.2 %).
pub const MAX_BALANCE_ROUNDS: u32 = 1000;

/// Checks `rounds` of balancing for `grid`'s texels in `scene` before anything is built: at
/// most [`MAX_BALANCE_ROUNDS`], and the pairs' memory ([`balance_memory_bytes`]) within half
/// of `limit` (bytes; `None`: no limit). `Err` with what is wrong and the fix, to follow the
/// flag's name in a message.
pub fn check_balance(
    scene: &Scene,
    grid: &TexelGrid,
    effects: Effects,
    rounds: u32,
    limit: Option<u64>,
) -> Result<(), String> {
    if rounds > MAX_BALANCE_ROUNDS {
        return Err(format!(
            "at most {MAX_BALANCE_ROUNDS} rounds (50 hold the rows within ~0.2 %); 0 turns it off"
        ));
    }
    if let (1.., Some(limit)) = (rounds, limit) {
        let need = balance_memory_bytes(scene, grid, effects);
        if need > limit / 2 {
            return Err(format!(
                "the skin weights of {} covered texels need about {:.1} MB to balance, more \
                 than half the memory limit ({:.1} MB: physical memory or \
                 ORTM_MEMORY_LIMIT_BYTES); give a smaller --size, or 0 to keep the capped weights",
                grid.texels.len(),
                need as f64 / 1e6,
                limit as f64 / 1e6,
            ));
        }
    }
    Ok(())
}

/// The memory [`Kernels::balance_rounds`] keeps for `grid`'s texels in `scene`, estimated
/// before anything is built: [`BALANCE_PAIR_BYTES`] per pair of texels of a translucent
/// material within its profile's support, `π r² / A_j` receivers per sender as on a plane
/// (bytes; 0 without subsurface scattering). For a memory check ahead of the solve.
pub fn balance_memory_bytes(scene: &Scene, grid: &TexelGrid, effects: Effects) -> u64 {
    if !effects.subsurface {
        return 0;
    }
    let support: Vec<Option<f64>> = (scene.materials.iter())
        .map(|m| (m.subsurface.as_ref()).map(|s| Profile::new(s).support_radius(SUPPORT_FRACTION)))
        .collect();
    let n = grid.texels.len() as f64;
    (grid.texels.iter())
        .map(
            |t| match support.get(t.material as usize).copied().flatten() {
                Some(r) => {
                    let pairs = std::f64::consts::PI * r * r / (t.area_m2 as f64).max(1e-30);
                    pairs.clamp(1.0, n) as u64 * BALANCE_PAIR_BYTES
                }
                None => 0,
            },
        )
        .sum()
}

/// Patches of every covered texel of `grid`, in texel order (subsurface weights not yet
/// normalised: [`Kernels::normalise_subsurface`]; [`Transport::new`] and
/// [`dense::DenseTransport::new`] do it).
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
            subsurface_scale: Vec3::ONE,
            subsurface_gather: Vec3::ONE,
            footprint_m: Some(t.footprint_m),
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
    /// The mesh's translucent triangles, whose integral of the profile caps what a texel
    /// re-emits ([`Kernels::scale_subsurface`]); `None` for kernels built from parts alone.
    pub surface: Option<surface::SurfaceReemission>,
    /// Rounds of balancing of the subsurface weights' rows and columns
    /// ([`Kernels::normalise_subsurface`], module docs "Subsurface weights"); 0 (the default):
    /// the columns capped alone. Honoured where the weights are normalised pair by pair (the
    /// dense solve, the hierarchical solve's sparse operator, the pair evaluator, and the
    /// bake's subsurface walk, [`hier::subsurface::SubsurfaceWalk::normalise`], which then
    /// balances from every pair as well); the near field's sub-texels
    /// ([`crate::bake::near_field`]) are not balanced (`ortm solve` refuses the two together:
    /// measured worse than either alone).
    pub balance_rounds: u32,
}

impl Kernels {
    /// Kernels for `scene` with `effects`.
    pub fn new(scene: &Scene, effects: Effects, visibility: Arc<Visibility>) -> Self {
        let profiles = scene
            .materials
            .iter()
            .map(|m| m.subsurface.as_ref().map(Profile::new))
            .collect();
        let mut k = Self::from_parts(effects, profiles, visibility);
        if k.profiles.iter().any(Option::is_some) {
            let translucent = |m: u32| k.is_translucent(m);
            k.surface = Some(surface::SurfaceReemission::new(&scene.mesh, translucent));
        }
        k
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
            .map(|p| p.map_or(0.0, |p| p.support_radius(SUPPORT_FRACTION)))
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
            surface: None,
            balance_rounds: 0,
        }
    }

    /// Form-factor factor `c_ij = F_ij / A_j` (m⁻²) from receiver `a` to sender `b`, with
    /// visibility; `F_ij = c_ij A_j` ([`form_factor`] module docs: collocated at a texel's
    /// centre, so `c_ij ≠ c_ji` for near texel pairs).
    #[inline]
    pub fn form_factor_c(&self, a: &Patch, b: &Patch) -> f32 {
        if !self.effects.radiosity {
            return 0.0;
        }
        let c = unoccluded_form_factor(&a.ff(), &b.ff());
        if c > 0.0 && self.visible(a, b) {
            c
        } else {
            0.0
        }
    }

    /// `(c_ab, c_ba)` of [`Kernels::form_factor_c`] both ways with one visibility ray.
    #[inline]
    pub fn form_factor_pair(&self, a: &Patch, b: &Patch) -> (f32, f32) {
        if !self.effects.radiosity {
            return (0.0, 0.0);
        }
        let (fa, fb) = (a.ff(), b.ff());
        let c_ab = unoccluded_form_factor(&fa, &fb).max(0.0);
        // Only collocated texel pairs differ by direction; the area-mean kernel of clusters is
        // symmetric bit for bit, so it is not evaluated twice.
        let c_ba = if fa.texel && fb.texel {
            unoccluded_form_factor(&fb, &fa).max(0.0)
        } else {
            c_ab
        };
        if (c_ab > 0.0 || c_ba > 0.0) && self.visible(a, b) {
            (c_ab, c_ba)
        } else {
            (0.0, 0.0)
        }
    }

    /// One visibility ray between the patches' centres, lifted off their surfaces (the ray of
    /// every texel pair, and of each member pair a block link samples, [`hier`]).
    #[inline]
    pub(crate) fn visible(&self, a: &Patch, b: &Patch) -> bool {
        let eps = 1e-3 * a.area_m2.max(b.area_m2).sqrt();
        let pa = a.position_m + a.lift_normal * eps;
        let pb = b.position_m + b.lift_normal * eps;
        self.visibility.visible(pa, pb, eps)
    }

    /// Subsurface exitance weights `S_ij` (per channel, dimensionless: fraction of `E_j·A_j`
    /// per unit area leaving at `i`, i.e. `B_i = Σ_j S_ij E_j`): the profile weights of
    /// [`Kernels::subsurface_raw`] times the sender's [`Patch::subsurface_scale`] and the
    /// receiver's [`Patch::subsurface_gather`] (module docs, "Subsurface weights"). `self_pair`
    /// selects the near-singular self term.
    #[inline]
    pub fn subsurface(&self, a: &Patch, b: &Patch, self_pair: bool) -> Option<[f64; 3]> {
        let s = self.subsurface_raw(a, b, self_pair)?;
        let k = b.subsurface_scale * a.subsurface_gather;
        Some([s[0] * k.x as f64, s[1] * k.y as f64, s[2] * k.z as f64])
    }

    /// The profile weights before normalisation. For a texel (a patch with a footprint):
    /// `∫_{P_j} R_d(|x_i − y|) dA(y)` over its footprint ([`footprint`]), the self pair
    /// included. For clusters and tree nodes, the midpoint rule `R_d(|x_i − x_j|)·A_j`, and for
    /// `self_pair` the profile integrated over a disk of the patch's area,
    /// `∫₀^a R_d(r) 2πr dr` with `πa² = A_j`. 0 beyond the profile's support (centre distance);
    /// `None` between different materials.
    #[inline]
    pub fn subsurface_raw(&self, a: &Patch, b: &Patch, self_pair: bool) -> Option<[f64; 3]> {
        if a.material != b.material {
            return None;
        }
        let m = a.material as usize;
        let p = self.profiles[m].as_ref()?;
        let table = self.tables[m].as_ref();
        if let (Some(f), Some(table)) = (b.footprint_m, table) {
            if !self_pair && (a.position_m - b.position_m).length() as f64 > self.support_m[m] {
                return Some([0.0; 3]);
            }
            return Some(footprint::footprint_weight(
                table,
                a.position_m,
                b.position_m,
                f,
            ));
        }
        if self_pair {
            let radius = (a.area_m2 as f64 / std::f64::consts::PI).sqrt();
            return Some(p.disk_integral(radius));
        }
        let r = (a.position_m - b.position_m).length() as f64;
        if r > self.support_m[m] {
            return Some([0.0; 3]);
        }
        let rd = match table {
            Some(t) => t.rd(r),
            None => p.rd(r),
        };
        let area = b.area_m2 as f64;
        Some([rd[0] * area, rd[1] * area, rd[2] * area])
    }

    /// Per patch and channel, the fraction of its incident power that the raw weights
    /// ([`Kernels::subsurface_raw`]) re-emit over `patches`: `Q_j = Σ_i S_ij A_i / A_j` (self
    /// term included; 0 for opaque patches). The continuous profile re-emits at most the
    /// material's total diffuse reflectance ρ̄ (module docs, "Subsurface weights").
    pub fn subsurface_reemission(&self, patches: &[Patch]) -> Vec<[f64; 3]> {
        self.subsurface_reemission_with(patches, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Kernels::subsurface_reemission`] reporting one step per patch to `progress`
    /// ("subsurface weights") and stopping when it is cancelled.
    pub fn subsurface_reemission_with(
        &self,
        patches: &[Patch],
        progress: &SetupProgress,
    ) -> Result<Vec<[f64; 3]>, Cancelled> {
        Ok(self.reemission(patches, progress, false)?.0)
    }

    /// `Q_j` of every patch ([`Kernels::subsurface_reemission`]) and, with `keep_near`, the
    /// raw weights of the texel pairs integrated in polar form ([`NearWeights`]; empty without).
    fn reemission(
        &self,
        patches: &[Patch],
        progress: &SetupProgress,
        keep_near: bool,
    ) -> Result<(Vec<[f64; 3]>, NearWeights), Cancelled> {
        let n = patches.len();
        let (q, near) = self.per_sender(
            patches,
            progress,
            keep_near,
            || [0.0f64; 3],
            |q, j, i, s| {
                let inv_area = 1.0 / patches[j].area_m2 as f64;
                let w = patches[i as usize].area_m2 as f64 * inv_area;
                for c in 0..3 {
                    q[c] += s[c] * w;
                }
            },
        )?;
        Ok((q.unwrap_or_else(|| vec![[0.0; 3]; n]), near))
    }

    /// Visits every translucent sender `j`'s receivers `i` within the profile's support, with
    /// their raw weight `raw_ij` ([`Kernels::subsurface_raw`]): `add(acc_j, j, i, raw_ij)` into
    /// an accumulator per sender made by `init`, senders in parallel. With `keep_near`, also
    /// keeps the raw weights of the pairs integrated in polar form ([`NearWeights`]). Reports
    /// "transport: subsurface weights" (one step per patch). `None` for the accumulators when
    /// no patch scatters (nothing visited).
    fn per_sender<T: Send>(
        &self,
        patches: &[Patch],
        progress: &SetupProgress,
        keep_near: bool,
        init: impl Fn() -> T + Sync,
        add: impl Fn(&mut T, usize, u32, [f64; 3]) + Sync,
    ) -> Result<(Option<Vec<T>>, NearWeights), Cancelled> {
        let cell = self.support_m.iter().copied().fold(0.0f64, f64::max);
        if cell <= 0.0 || !patches.iter().any(|p| self.is_translucent(p.material)) {
            return Ok((None, NearWeights::default()));
        }
        progress.phase("transport: subsurface weights", patches.len() as u64);
        let grid = SupportGrid::new(patches, self);
        type Near = Vec<(u32, [f32; 3])>;
        let per_sender: Vec<(T, Near)> = patches
            .par_iter()
            .enumerate()
            .map(|(j, b)| {
                let mut acc = init();
                let mut near: Near = Vec::new();
                if j % 1024 == 0 {
                    progress.advance(1024.min(patches.len() - j) as u64);
                }
                if !self.is_translucent(b.material) || progress.check().is_err() {
                    return (acc, near);
                }
                grid.for_each_near(b.position_m, |i| {
                    let a = &patches[i as usize];
                    if let Some(s) = self.subsurface_raw(a, b, i as usize == j) {
                        if keep_near
                            && b.footprint_m
                                .is_some_and(|f| footprint::is_near(a.position_m, b.position_m, f))
                        {
                            near.push((i, s.map(|x| x as f32)));
                        }
                        add(&mut acc, j, i, s);
                    }
                });
                (acc, near)
            })
            .collect();
        progress.check()?;
        let near = NearWeights::by_receiver(patches.len(), per_sender.iter().map(|(_, n)| n));
        Ok((Some(per_sender.into_iter().map(|(a, _)| a).collect()), near))
    }

    /// Sets every patch's [`Patch::subsurface_scale`] so that no sender re-emits more than
    /// the continuous surface does: `min(1, Q̂_j / Q_j)` per channel
    /// ([`Kernels::scale_subsurface`]), with `Q_j` from [`Kernels::subsurface_reemission`]
    /// (module docs, "Subsurface weights"). Depends
    /// only on the patches' geometry (any earlier scale is replaced), so it may be applied
    /// again. Returns the number of patches scaled in some channel.
    pub fn normalise_subsurface(&self, patches: &mut [Patch]) -> usize {
        self.normalise_subsurface_with(patches, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Kernels::normalise_subsurface`] with progress and cancellation
    /// ([`Kernels::subsurface_reemission_with`]).
    pub fn normalise_subsurface_with(
        &self,
        patches: &mut [Patch],
        progress: &SetupProgress,
    ) -> Result<usize, Cancelled> {
        if self.balance_rounds > 0 {
            return Ok(self.balance_subsurface(patches, progress, false)?.0);
        }
        let q = self.subsurface_reemission_with(patches, progress)?;
        self.scale_subsurface_with(patches, &q, progress)
    }

    /// The weights balanced in rows and columns ([`Kernels::balance_rounds`] rounds): every
    /// translucent patch gets a receiver factor `α_i` ([`Patch::subsurface_gather`]) and a
    /// sender factor `β_j` ([`Patch::subsurface_scale`]) such that, with `S_ij = α_i raw_ij
    /// β_j`, every row `Σ_j S_ij` (what a uniform irradiance makes texel `i` re-emit) and every
    /// column `Σ_i A_i S_ij / A_j` (what a sender re-emits) approach `Q̂`
    /// ([`Kernels::continuous_reemission`]) — Sinkhorn's alternating scaling, rows then
    /// columns, so the columns hold exactly after the last round. The capped form
    /// ([`Kernels::scale_subsurface`]) holds the columns alone, and footprints of unequal size
    /// (UV stretch, seams) leave its rows a few percent off `Q̂` (README, "The subsurface
    /// weights' rows"). Keeps every pair's raw weight (`n × support²` of them, as the sparse
    /// subsurface operator does) for the rounds. Returns the number of patches scaled and,
    /// with `keep_near`, the near pairs' raw weights ([`Kernels::normalise_subsurface_keeping_near`]).
    fn balance_subsurface(
        &self,
        patches: &mut [Patch],
        progress: &SetupProgress,
        keep_near: bool,
    ) -> Result<(usize, NearWeights), Cancelled> {
        let n = patches.len();
        for p in patches.iter_mut() {
            p.subsurface_scale = Vec3::ONE;
            p.subsurface_gather = Vec3::ONE;
        }
        // Per sender `j`: every receiver `i` with its raw weight `raw_ij`.
        type Pairs = Vec<(u32, [f32; 3])>;
        let (per_sender, near) = self.per_sender(
            patches,
            progress,
            keep_near,
            Pairs::new,
            |pairs, _, i, s| {
                if s != [0.0; 3] {
                    pairs.push((i, s.map(|x| x as f32)));
                }
            },
        )?;
        let Some(per_sender) = per_sender else {
            return Ok((0, near));
        };
        let q_hat = self.continuous_reemissions(patches, progress)?;
        progress.phase("transport: subsurface balance", self.balance_rounds as u64);
        let area: Vec<f64> = patches.iter().map(|p| p.area_m2 as f64).collect();
        let ratio = |target: f64, sum: f64| if sum > 0.0 { target / sum } else { 1.0 };
        let (mut alpha, mut beta) = (vec![[1.0f64; 3]; n], vec![[1.0f64; 3]; n]);
        for _ in 0..self.balance_rounds {
            progress.check()?;
            let mut row = vec![[0.0f64; 3]; n];
            for (pairs, b) in per_sender.iter().zip(&beta) {
                for &(i, w) in pairs {
                    for c in 0..3 {
                        row[i as usize][c] += w[c] as f64 * b[c];
                    }
                }
            }
            for ((a, r), q) in alpha.iter_mut().zip(&row).zip(&q_hat) {
                if let Some(q) = q {
                    *a = [0, 1, 2].map(|c| ratio(q[c], r[c]));
                }
            }
            beta = (per_sender.par_iter().enumerate())
                .map(|(j, pairs)| {
                    let Some(q) = q_hat[j] else {
                        return [1.0; 3];
                    };
                    let mut col = [0.0f64; 3];
                    for &(i, w) in pairs {
                        for c in 0..3 {
                            col[c] += area[i as usize] * alpha[i as usize][c] * w[c] as f64;
                        }
                    }
                    [0, 1, 2].map(|c| ratio(q[c] * area[j], col[c]))
                })
                .collect();
            progress.advance(1);
        }
        let as_vec = |v: [f64; 3]| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        let mut scaled = 0;
        for ((p, a), b) in patches.iter_mut().zip(&alpha).zip(&beta) {
            p.subsurface_gather = as_vec(*a);
            p.subsurface_scale = as_vec(*b);
            scaled +=
                usize::from(p.subsurface_gather != Vec3::ONE || p.subsurface_scale != Vec3::ONE);
        }
        Ok((scaled, near))
    }

    /// [`Kernels::normalise_subsurface_with`] (the number of patches scaled) that also returns
    /// the raw weights of the texel pairs it integrated in polar form ([`NearWeights`]), the
    /// costly ones, for the cell integration to reuse instead of integrating them again.
    pub fn normalise_subsurface_keeping_near(
        &self,
        patches: &mut [Patch],
        progress: &SetupProgress,
    ) -> Result<(usize, NearWeights), Cancelled> {
        if self.balance_rounds > 0 {
            return self.balance_subsurface(patches, progress, true);
        }
        let (q, near) = self.reemission(patches, progress, true)?;
        let scaled = self.scale_subsurface_with(patches, &q, progress)?;
        Ok((scaled, near))
    }

    /// Sets every patch's [`Patch::subsurface_scale`] to `min(1, Q̂_j / Q_j)` per channel from its
    /// re-emission `q[j]` (1 for opaque patches), where `Q̂_j` is what the continuous surface
    /// re-emits at the patch ([`surface::SurfaceReemission`]) for a texel of kernels built
    /// from a scene, else ρ̄ (clusters, tree nodes, kernels from parts: the plane's value).
    /// Returns the number of patches scaled in some channel.
    pub fn scale_subsurface(&self, patches: &mut [Patch], q: &[[f64; 3]]) -> usize {
        self.scale_subsurface_with(patches, q, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Kernels::scale_subsurface`] reporting "transport: subsurface cap" to `progress` where
    /// it integrates the continuous surface at the texels (~40 s at 1024² on the head), and
    /// stopping when it is cancelled (the patches' scales are then left as they were).
    pub fn scale_subsurface_with(
        &self,
        patches: &mut [Patch],
        q: &[[f64; 3]],
        progress: &SetupProgress,
    ) -> Result<usize, Cancelled> {
        let caps = self.continuous_reemissions(patches, progress)?;
        let scaled = (patches.par_iter_mut().zip(q).zip(caps))
            .map(|((p, q), cap)| {
                p.subsurface_scale = Vec3::ONE;
                p.subsurface_gather = Vec3::ONE;
                let Some(cap) = cap else {
                    return 0;
                };
                for c in 0..3 {
                    if q[c] > cap[c] {
                        p.subsurface_scale[c] = (cap[c] / q[c]) as f32;
                    }
                }
                usize::from(p.subsurface_scale != Vec3::ONE)
            })
            .sum();
        Ok(scaled)
    }

    /// [`Kernels::continuous_reemission`] of every patch, in parallel, reporting "transport:
    /// subsurface cap" where texels of a scene's translucent surface ask for the continuous
    /// surface's integral (~40 s at 1024² on the head; every other patch is done at once,
    /// unreported) and stopping when it is cancelled.
    fn continuous_reemissions(
        &self,
        patches: &[Patch],
        progress: &SetupProgress,
    ) -> Result<Vec<Option<[f64; 3]>>, Cancelled> {
        let n = patches.len();
        let none = SetupProgress::none();
        let progress = if self.surface.is_some()
            && (patches.iter()).any(|p| p.footprint_m.is_some() && self.is_translucent(p.material))
        {
            progress.phase("transport: subsurface cap", n as u64);
            progress
        } else {
            &none
        };
        let caps = (patches.par_iter().enumerate())
            .map(|(j, p)| {
                if j % 4096 == 0 {
                    progress.advance(4096.min(n - j) as u64);
                }
                if progress.check().is_err() {
                    return None;
                }
                self.continuous_reemission(p)
            })
            .collect();
        progress.check()?;
        Ok(caps)
    }

    /// `Q̂` of patch `p` per channel: what the continuous surface re-emits per unit of power
    /// entering at its centre ([`surface::SurfaceReemission`]) for a texel of kernels built from
    /// a scene, else the plane's value ρ̄ (clusters, tree nodes, kernels from parts); `None` for
    /// an opaque patch. The cap of [`Kernels::scale_subsurface`].
    pub fn continuous_reemission(&self, p: &Patch) -> Option<[f64; 3]> {
        let m = p.material as usize;
        let profile = self.profiles[m].as_ref()?;
        Some(match (&self.surface, &self.tables[m], p.footprint_m) {
            (Some(s), Some(table), Some(_)) => {
                s.at(table, p.material, p.position_m, self.support_m[m])
            }
            _ => std::array::from_fn(|c| profile.channels[c].total_reflectance()),
        })
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
        self.r_subsurface_raw(a, b, same, None)
    }

    /// [`Kernels::r_subsurface`] with the pair's raw weight `raw`
    /// ([`Kernels::subsurface_raw`]) when it is known (e.g. from [`NearWeights`]); computed
    /// when `None`.
    #[inline]
    pub fn r_subsurface_raw(
        &self,
        a: &Patch,
        b: &Patch,
        same: bool,
        raw: Option<[f64; 3]>,
    ) -> [f64; 3] {
        let mut out = [0.0f64; 3];
        let scaled = |s: [f64; 3]| {
            let k = b.subsurface_scale * a.subsurface_gather;
            [s[0] * k.x as f64, s[1] * k.y as f64, s[2] * k.z as f64]
        };
        if self.is_translucent(a.material)
            && let Some(s) = raw
                .filter(|_| a.material == b.material)
                .map(scaled)
                .or_else(|| self.subsurface(a, b, same))
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

/// The raw subsurface weights ([`Kernels::subsurface_raw`]) of the texel pairs that
/// [`footprint::footprint_weight`] integrates in polar form ([`footprint::is_near`]: centres
/// within [`footprint::NEAR_SIZES`] footprint sizes, and the self pairs), per receiver: a
/// dozen pairs per texel, but the polar form costs far more than the Gauss rule of the others.
/// The normalisation computes them ([`Kernels::normalise_subsurface_keeping_near`]) and the
/// cell integration reads them back ([`Transport::r_subsurface`]), so each is integrated
/// once. Stored as f32 (16 bytes per pair: 200 MB for the head's 961,180 texels at 1024²;
/// the normalisation itself sums the f64 values), so a kept weight differs from the one
/// integrated anew by its rounding, ≤ 6·10⁻⁸ relative.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct NearWeights {
    /// Receiver `i`'s pairs are `entries[start[i]..start[i + 1]]`, sorted by sender (empty
    /// when nothing is kept).
    start: Vec<usize>,
    /// `(sender j, S_ij^raw)` per channel.
    entries: Vec<(u32, [f32; 3])>,
}

impl NearWeights {
    /// From each sender's list of `(receiver, weight)`, senders in index order.
    fn by_receiver<'a>(
        n: usize,
        per_sender: impl Iterator<Item = &'a Vec<(u32, [f32; 3])>> + Clone,
    ) -> Self {
        let mut start = vec![0usize; n + 1];
        for list in per_sender.clone() {
            for &(i, _) in list {
                start[i as usize + 1] += 1;
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut entries = vec![(0u32, [0.0f32; 3]); start[n]];
        for (j, list) in per_sender.enumerate() {
            for &(i, s) in list {
                entries[fill[i as usize]] = (j as u32, s);
                fill[i as usize] += 1;
            }
        }
        Self { start, entries }
    }

    /// The raw weight that sender `j` gives receiver `i`, when it is kept.
    #[inline]
    pub fn get(&self, i: u32, j: u32) -> Option<[f64; 3]> {
        let (a, b) = (*self.start.get(i as usize)?, self.start[i as usize + 1]);
        let list = &self.entries[a..b];
        list.binary_search_by_key(&j, |e| e.0)
            .ok()
            .map(|k| list[k].1.map(f64::from))
    }

    /// Pairs kept.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when no pair is kept.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// The translucent patches in a uniform grid of cells one support radius wide (the largest
/// of the materials' supports): every pair within the support lies in neighbouring cells.
pub struct SupportGrid(PointGrid);

impl SupportGrid {
    /// The grid of the translucent patches of `patches` (empty when no material scatters).
    pub fn new(patches: &[Patch], kernels: &Kernels) -> Self {
        let cell_m = kernels.support_m.iter().copied().fold(0.0f64, f64::max);
        let translucent = (patches.iter().enumerate())
            .filter(|(_, p)| cell_m > 0.0 && kernels.is_translucent(p.material))
            .map(|(i, p)| (i as u32, p.position_m));
        Self(PointGrid::new(cell_m, translucent))
    }

    /// Calls `f` with every translucent patch in the 27 cells around `p` (a superset of those
    /// within the support).
    pub fn for_each_near(&self, p: Vec3, f: impl FnMut(u32)) {
        self.0.for_each_around(p, 1, f);
    }
}

/// First bytes of [`Transport::to_bytes`].
const TRANSPORT_MAGIC: &[u8; 8] = b"ORTMTRNS";
/// Version of [`Transport::to_bytes`]'s layout (the serde form of its parts, postcard-encoded).
const TRANSPORT_VERSION: u32 = 4;

/// Evaluates `R(t, t')` for any pair of covered texels of a lightmap (see the module docs).
pub struct Transport {
    /// Covered texels as patches (texel order of the grid).
    pub patches: Vec<Patch>,
    /// Kernels.
    pub kernels: Kernels,
    /// Higher-order remainder at the coarse level.
    pub remainder: coarse::Remainder,
    /// The hierarchical first-bounce operator, when the bake asked for one
    /// ([`Transport::build_hierarchical`]): the cell integration takes the first bounce from
    /// its links ([`crate::bake::cells`]) instead of from the coarse clusters and texel pairs.
    pub links: Option<hier::Operator>,
    /// The raw subsurface weights of the texel pairs integrated in polar form, kept from the
    /// normalisation ([`NearWeights`]; empty with the hierarchical operator).
    pub near: NearWeights,
}

impl Transport {
    /// Builds the evaluator: texel patches, BVH, and the coarse remainder solve with clusters of
    /// `block × block` texels (0: [`coarse::auto_block`]).
    pub fn new(scene: &Scene, grid: &TexelGrid, effects: Effects, block: u32) -> Self {
        Self::build(scene, grid, effects, block, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Transport::new`] reporting its phases to `progress` (subsurface weights, the coarse
    /// level's form factors, its solve per channel) and stopping between steps when it is
    /// cancelled. The result does not depend on `progress`.
    pub fn build(
        scene: &Scene,
        grid: &TexelGrid,
        effects: Effects,
        block: u32,
        progress: &SetupProgress,
    ) -> Result<Self, Cancelled> {
        let visibility = Arc::new(Visibility::new(&scene.mesh));
        let kernels = Kernels::new(scene, effects, visibility);
        let mut patches = texel_patches(grid);
        let (_, near) = kernels.normalise_subsurface_keeping_near(&mut patches, progress)?;
        let mut t = Self::with_remainder(grid, patches, kernels, block, (None, None), progress)?;
        t.near = near;
        Ok(t)
    }

    /// The transport of normalised `patches`: the coarse remainder with clusters of
    /// `block × block` texels (0: [`coarse::auto_block`]), with the slit texels alone when
    /// `slits` ([`coarse::Remainder::build`]), and the hierarchical operator `links`.
    fn with_remainder(
        grid: &TexelGrid,
        patches: Vec<Patch>,
        kernels: Kernels,
        block: u32,
        (links, slits): (Option<hier::Operator>, Option<usize>),
        progress: &SetupProgress,
    ) -> Result<Self, Cancelled> {
        let block = if block == 0 {
            coarse::auto_block(grid)
        } else {
            block
        };
        let remainder = coarse::Remainder::build(grid, &patches, &kernels, block, slits, progress)?;
        Ok(Self {
            patches,
            kernels,
            remainder,
            links,
            near: NearWeights::default(),
        })
    }

    /// [`Transport::build`] with the hierarchical operator at `settings`
    /// ([`hier::Operator::build_links_only`] over the texel patches), for the multi-resolution
    /// rows ([`crate::bake::multires::hierarchical_row`]) and the cell integration: its links
    /// carry the first bounce and its walk the subsurface term, whose normalisation it also
    /// does (the walk's, to `settings.tolerance`, instead of every pair within the support).
    /// The coarse remainder keeps the slit texels alone ([`coarse::slit_texels`]); the offsets'
    /// bakes take [`Transport::build_hierarchical_with_slits`] without them.
    ///
    /// # Errors
    /// [`hier::BuildError`] when cancelled or when the links outgrow `settings.max_bytes`.
    pub fn build_hierarchical(
        scene: &Scene,
        grid: &TexelGrid,
        effects: Effects,
        block: u32,
        settings: &hier::Settings,
        progress: &SetupProgress,
    ) -> Result<Self, hier::BuildError> {
        let slits = Some(coarse::MAX_SLIT_TEXELS);
        Self::build_hierarchical_with_slits(scene, grid, effects, block, slits, settings, progress)
    }

    /// [`Transport::build_hierarchical`] with at most `Some(max)` of the coarse remainder's
    /// slit texels ([`coarse::slit_texels`]; [`coarse::MAX_SLIT_TEXELS`] by default, `ortm bake
    /// --slit-texels N`) or without them (`None`: the clusters are the tiles alone, as the
    /// offsets' cell integration takes them — its far field visits every sender cluster per
    /// receiver, so 3,072 more clusters cost the head's 1024² bake 85 s).
    pub fn build_hierarchical_with_slits(
        scene: &Scene,
        grid: &TexelGrid,
        effects: Effects,
        block: u32,
        slits: Option<usize>,
        settings: &hier::Settings,
        progress: &SetupProgress,
    ) -> Result<Self, hier::BuildError> {
        let visibility = Arc::new(Visibility::new(&scene.mesh));
        let mut kernels = Kernels::new(scene, effects, visibility);
        kernels.balance_rounds = settings.subsurface_balance_rounds;
        let op =
            hier::Operator::build_links_only(&texel_patches(grid), &kernels, settings, progress)?;
        let patches = op.patches().to_vec();
        Ok(Self::with_remainder(
            grid,
            patches,
            kernels,
            block,
            (Some(op), slits),
            progress,
        )?)
    }

    /// The transport as bytes (a sharded bake's plan hands it to its shards,
    /// [`crate::bake::shard`]): everything but the kernels, which [`Transport::from_bytes`]
    /// rebuilds from the scene (profiles, tables, BVH: cheap and deterministic). Floats are
    /// stored bit for bit, so the shards compute exactly what one process would.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.write_to(&mut out)
            .expect("writing to a Vec cannot fail");
        out
    }

    /// [`Transport::to_bytes`] written into `w` as it is encoded (no copy in memory).
    ///
    /// # Errors
    /// The writer's error.
    pub fn write_to(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        #[derive(Serialize)]
        struct Parts<'a> {
            effects: Effects,
            patches: &'a [Patch],
            remainder: &'a coarse::Remainder,
            links: Option<&'a hier::Operator>,
            near: &'a NearWeights,
        }
        w.write_all(TRANSPORT_MAGIC)?;
        w.write_all(&TRANSPORT_VERSION.to_le_bytes())?;
        postcard::to_io(
            &Parts {
                effects: self.kernels.effects,
                patches: &self.patches,
                remainder: &self.remainder,
                links: self.links.as_ref(),
                near: &self.near,
            },
            w,
        )
        .map_err(std::io::Error::other)?;
        Ok(())
    }

    /// The transport of [`Transport::to_bytes`], with its kernels rebuilt for `scene`.
    ///
    /// # Errors
    /// A message when the bytes are not a transport of this version, or were made with other
    /// effects or for another number of texels than `grid`'s.
    pub fn from_bytes(scene: &Scene, grid: &TexelGrid, bytes: &[u8]) -> Result<Self, String> {
        #[derive(Deserialize)]
        struct Parts {
            effects: Effects,
            patches: Vec<Patch>,
            remainder: coarse::Remainder,
            links: Option<hier::Operator>,
            near: NearWeights,
        }
        let head = TRANSPORT_MAGIC.len();
        if bytes.len() < head + 4 || &bytes[..head] != TRANSPORT_MAGIC {
            return Err("not an ortm transport file".into());
        }
        let version = u32::from_le_bytes(bytes[head..head + 4].try_into().expect("4 bytes"));
        if version != TRANSPORT_VERSION {
            return Err(format!(
                "transport version {version}, this ortm reads version {TRANSPORT_VERSION}"
            ));
        }
        let p: Parts = postcard::from_bytes(&bytes[head + 4..]).map_err(|e| e.to_string())?;
        if p.patches.len() != grid.texels.len() || p.remainder.cluster_of.len() != grid.texels.len()
        {
            return Err(format!(
                "{} texels in the transport, {} in the lightmap",
                p.patches.len(),
                grid.texels.len()
            ));
        }
        let visibility = Arc::new(Visibility::new(&scene.mesh));
        Ok(Self {
            patches: p.patches,
            kernels: Kernels::new(scene, p.effects, visibility),
            remainder: p.remainder,
            links: p.links,
            near: p.near,
        })
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
        let s = self.r_subsurface(i, j);
        let f = self.kernels.r_bounce(a, b, i == j);
        let rem = self.remainder.r(i, j, b.area_m2);
        [
            (s[0] + f[0] + rem[0] as f64) as f32,
            (s[1] + f[1] + rem[1] as f64) as f32,
            (s[2] + f[2] + rem[2] as f64) as f32,
        ]
    }

    /// [`Kernels::r_subsurface`] of texels `i` (receiver) and `j` (sender), its polar-form
    /// weight read from [`Transport::near`] when kept there.
    #[inline]
    pub fn r_subsurface(&self, i: u32, j: u32) -> [f64; 3] {
        let (a, b) = (&self.patches[i as usize], &self.patches[j as usize]);
        self.kernels
            .r_subsurface_raw(a, b, i == j, self.near.get(i, j))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SubsurfaceModel;
    use crate::scene::subsurface::skin1;

    fn skin_kernels(model: SubsurfaceModel) -> Kernels {
        Kernels::from_parts(
            Effects {
                radiosity: false,
                subsurface: true,
            },
            vec![Some(skin1(model))],
            Arc::new(Visibility::from_triangles(Vec::new())),
        )
    }

    /// A flat `n × n` grid of square patches of side `pitch` metres in the z = 0 plane.
    fn flat_grid(n: usize, pitch: f32) -> Vec<Patch> {
        let mut v = Vec::new();
        for y in 0..n {
            for x in 0..n {
                v.push(Patch {
                    position_m: Vec3::new(x as f32 * pitch, y as f32 * pitch, 0.0),
                    normal: Vec3::Z,
                    lift_normal: Vec3::Z,
                    area_m2: pitch * pitch,
                    rho: Vec3::ONE,
                    material: 0,
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: None,
                });
            }
        }
        v
    }

    /// Rows `Σ_j S_ij` and area-weighted columns `Σ_i A_i S_ij / A_j` of the weights over
    /// `patches`, per patch and channel.
    fn rows_and_columns(k: &Kernels, patches: &[Patch]) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let n = patches.len();
        let (mut rows, mut cols) = (vec![[0.0f64; 3]; n], vec![[0.0f64; 3]; n]);
        for (i, a) in patches.iter().enumerate() {
            for (j, b) in patches.iter().enumerate() {
                let s = k.subsurface(a, b, i == j).unwrap();
                for c in 0..3 {
                    rows[i][c] += s[c];
                    cols[j][c] += s[c] * a.area_m2 as f64 / b.area_m2 as f64;
                }
            }
        }
        (rows, cols)
    }

    /// Texels of unequal size (a stretched UV layout: columns 1.5 and 3 mm wide in turn) on a
    /// square of skin 54 mm wide: the capped weights never re-emit more than ρ̄ (the plane's
    /// value, what kernels from parts take for `Q̂`) but gather anything from 0.48 ρ̄ (at the
    /// border, where the profile leaves the square) upwards; balanced
    /// ([`Kernels::balance_rounds`]) every row and column is ρ̄ within 10⁻³, borders included.
    #[test]
    fn balanced_weights_hold_rows_and_columns() {
        let mut k = skin_kernels(SubsurfaceModel::Dipole);
        let rho: [f64; 3] =
            std::array::from_fn(|c| k.profiles[0].unwrap().channels[c].total_reflectance());
        let n = 24;
        let widths: Vec<f32> = (0..n)
            .map(|x| if x % 2 == 0 { 1.5e-3 } else { 3e-3 })
            .collect();
        let mut patches = Vec::new();
        let pitch = 2.25e-3f32;
        for y in 0..n {
            let mut x0 = 0.0f32;
            for &w in &widths {
                patches.push(Patch {
                    position_m: Vec3::new(x0 + 0.5 * w, y as f32 * pitch, 0.0),
                    area_m2: w * pitch,
                    ..flat_grid(1, pitch)[0]
                });
                x0 += w;
            }
        }
        let worst = |sums: &[[f64; 3]]| {
            (sums.iter())
                .flat_map(|s| (0..3).map(move |c| (s[c] / rho[c] - 1.0).abs()))
                .fold(0.0f64, f64::max)
        };
        let mut capped = patches.clone();
        k.normalise_subsurface(&mut capped);
        let (rows, cols) = rows_and_columns(&k, &capped);
        println!(
            "capped: rows {:.4}, columns {:.4}",
            worst(&rows),
            worst(&cols)
        );
        assert!(
            cols.iter()
                .all(|q| (0..3).all(|c| q[c] <= rho[c] * (1.0 + 1e-6)))
        );
        assert!(worst(&rows) > 0.05, "the capped rows are off ρ̄");
        k.balance_rounds = 60;
        let mut balanced = patches.clone();
        let scaled = k.normalise_subsurface(&mut balanced);
        assert_eq!(scaled, patches.len());
        let (rows, cols) = rows_and_columns(&k, &balanced);
        println!(
            "balanced: rows {:.2e}, columns {:.2e}",
            worst(&rows),
            worst(&cols)
        );
        assert!(worst(&rows) < 1e-3 && worst(&cols) < 1e-5);
        // Balancing again from the balanced patches gives the same weights.
        let mut again = balanced.clone();
        k.normalise_subsurface(&mut again);
        for (a, b) in again.iter().zip(&balanced) {
            assert_eq!(
                (a.subsurface_scale, a.subsurface_gather),
                (b.subsurface_scale, b.subsurface_gather)
            );
        }
    }

    /// On a regular grid the raw weights never re-emit more than ρ̄ (the midpoint rule falls
    /// short of the integral), so normalisation leaves the profile untouched; well inside the
    /// grid they re-emit nearly all of ρ̄.
    #[test]
    fn regular_grid_keeps_the_profile() {
        // Grids wider than twice the profile's support (dipole 18.8 mm, exponential 36.8 mm),
        // texels of 0.5 / 1 mm and 2 mm (~ the head at 128²). `deficit` bounds the midpoint
        // rule's shortfall 1 − Q/ρ̄ at the centre, 25% above the measured worst channel:
        // 2.04%, 9.77%, 3.13%, 9.45%.
        for (model, n, pitch, deficit) in [
            (SubsurfaceModel::Dipole, 81usize, 0.5e-3f32, 0.0255),
            (SubsurfaceModel::Dipole, 41, 2e-3, 0.122),
            (SubsurfaceModel::Exponential, 81, 1e-3, 0.039),
            (SubsurfaceModel::Exponential, 41, 2e-3, 0.118),
        ] {
            let k = skin_kernels(model);
            let rho: [f64; 3] =
                std::array::from_fn(|c| k.profiles[0].unwrap().channels[c].total_reflectance());
            let mut patches = flat_grid(n, pitch);
            assert_eq!(k.normalise_subsurface(&mut patches), 0, "{model:?} {pitch}");
            let q = k.subsurface_reemission(&patches);
            let centre = q[n * (n / 2) + n / 2];
            let rel = [0, 1, 2].map(|c| centre[c] / rho[c]);
            println!("{model:?}, pitch {pitch} m: Q/ρ̄ at the centre {rel:?}");
            for c in 0..3 {
                assert!(rel[c] > 1.0 - deficit, "{model:?} {pitch} m: Q/ρ̄ = {rel:?}");
            }
        }
    }

    /// The set-up reports its phases with totals that its steps reach, gives the same
    /// transport as without reporting, and stops with `Cancelled` when its flag is raised.
    #[test]
    fn setup_progress_reaches_its_totals_and_cancels() {
        use std::sync::Mutex;
        let scene = crate::scene::cornell::cornell_box(24);
        let grid = TexelGrid::build(&scene).unwrap();
        let log: Mutex<Vec<(&'static str, u64, u64)>> = Mutex::new(Vec::new());
        let events = |e: BakeEvent| {
            let mut l = log.lock().unwrap();
            match e {
                BakeEvent::Phase { name, total } => l.push((name, total, 0)),
                BakeEvent::Advance(n) => l.last_mut().expect("a phase first").2 += n,
                BakeEvent::Message(_) => {}
            }
        };
        let cancel = AtomicBool::new(false);
        let progress = SetupProgress::new(&events, &cancel);
        let built = Transport::build(&scene, &grid, Effects::default(), 4, &progress).unwrap();
        let plain = Transport::new(&scene, &grid, Effects::default(), 4);
        let n_c = plain.remainder.clusters.len() as u64;
        let log = log.into_inner().unwrap();
        assert_eq!(
            log,
            vec![
                (
                    "transport: form factors",
                    n_c * (n_c - 1) / 2,
                    n_c * (n_c - 1) / 2
                ),
                ("transport: solve (R, G, B)", 3, 3),
            ]
        );
        assert_eq!(built.remainder.full, plain.remainder.full);
        assert_eq!(built.remainder.rem, plain.remainder.rem);
        cancel.store(true, Ordering::Relaxed);
        let none = |_: BakeEvent| {};
        let stopped = Transport::build(
            &scene,
            &grid,
            Effects::default(),
            4,
            &SetupProgress::new(&none, &cancel),
        );
        assert_eq!(stopped.err(), Some(Cancelled));
    }

    /// Σ_i S_ij A_i / A_j with the normalised weights ([`Kernels::subsurface`]), by brute force.
    fn reemitted(k: &Kernels, patches: &[Patch], j: usize) -> [f64; 3] {
        let b = &patches[j];
        let mut q = [0.0f64; 3];
        for (i, a) in patches.iter().enumerate() {
            let s = k.subsurface(a, b, i == j).unwrap();
            for c in 0..3 {
                q[c] += s[c] * a.area_m2 as f64 / b.area_m2 as f64;
            }
        }
        q
    }

    /// A seam: a second chart's texel centre 0.05 texel pitches from a texel of a 2 mm grid.
    /// Both stand at the other's profile peak, and the raw weights re-emit 1.35 / 1.99 / 3.53 ×
    /// ρ̄ (R/G/B) from each; the normalised ones re-emit exactly ρ̄ from each. The pair's four
    /// direct neighbours see two samples at one pitch and re-emit up to 1.018 × ρ̄ in red: they
    /// are scaled too; no sender exceeds ρ̄ any more, and texels farther away keep their weights.
    #[test]
    fn coincident_seam_texels_share_their_light() {
        let k = skin_kernels(SubsurfaceModel::Dipole);
        let rho: [f64; 3] =
            std::array::from_fn(|c| k.profiles[0].unwrap().channels[c].total_reflectance());
        let (n, pitch) = (21usize, 2e-3f32);
        let mut patches = flat_grid(n, pitch);
        let centre = n * (n / 2) + n / 2;
        let mut twin = patches[centre];
        twin.position_m.x += 0.05 * pitch;
        patches.push(twin);
        let raw = k.subsurface_reemission(&patches);
        let scaled = k.normalise_subsurface(&mut patches);
        let pair = [centre, patches.len() - 1];
        println!(
            "raw Q/ρ̄ of the seam texels: {:?}; {scaled} patches scaled",
            pair.map(|j| [0, 1, 2].map(|c| raw[j][c] / rho[c]))
        );
        assert_eq!(scaled, 6, "the pair and its four direct neighbours");
        for j in pair {
            let q = reemitted(&k, &patches, j);
            for c in 0..3 {
                assert!(raw[j][c] > 1.3 * rho[c], "raw {:?} vs ρ̄ {rho:?}", raw[j]);
                assert!((q[c] - rho[c]).abs() < 1e-6 * rho[c], "{q:?} vs ρ̄ {rho:?}");
            }
        }
        for j in 0..patches.len() {
            let q = reemitted(&k, &patches, j);
            for c in 0..3 {
                assert!(
                    q[c] <= rho[c] * (1.0 + 1e-6),
                    "patch {j}: {q:?} vs ρ̄ {rho:?}"
                );
            }
        }
        // Two pitches from the pair (4 mm): untouched.
        let other = centre + 2;
        assert_eq!(patches[other].subsurface_scale, Vec3::ONE);
        let q = reemitted(&k, &patches, other);
        for c in 0..3 {
            assert!((q[c] - raw[other][c]).abs() < 1e-9 * raw[other][c]);
        }
    }
}
