//! The interreflection's near field, gathered by rays: a correction to the transport's form
//! factors between nearby texels, and to the first bounce of the direct light from nearby
//! opaque surface, for each receiver texel (`ortm solve --near-gather G`). A bake of
//! multi-resolution maps on the hierarchical transport takes the form factors alone
//! ([`form_factor_rows`]) into every receiver's first bounce (`ortm bake --levels ε --tolerance
//! --near-gather G`, [`crate::bake::multires::with_gathered_rows`]): `ΔE` depends on the
//! lights, which a bake does not know, and the higher bounces stay the transport's.
//!
//! # Why
//! The transport ([`crate::bake::transport`]) takes the surface a texel sees as the other
//! texels' squares, each on its own tangent plane at its centre, seen from the receiver's
//! centre with one visibility ray between the centres ([`form_factor`](crate::bake::transport::form_factor)),
//! and holds each sender's light at one value over its square. Where the surface curves or
//! folds within a few texels — creases, nostrils, the mouth's and the eyelids' slits, the ears —
//! those squares miss part of what the receiver really sees, and the light that reaches it
//! depends on where within the senders the direct light falls. On the head at 256² the worst
//! texels of the radiosity-only solve against the path-traced reference are in the slits of
//! the lips and the eyelids, where the other side lies a fraction of a texel away and fills
//! most of the hemisphere: 0.49 W/m² against the reference's 0.05 at one, 0.20 against 0.56
//! beside it (README, *The interreflection's near field*).
//!
//! # Method
//! For every receiver texel `i`, `G × G` stratified cosine-distributed rays leave its centre
//! (about its shading normal, lifted along its face normal as every ray of the bake is) and
//! find the first surface. A hit on surface facing the ray lies in the square of some texel
//! (the coverage rule of [`crate::bake::texels`]); its share of the rays, `1/G²`, goes to the
//! texel centres around the hit's lightmap UV with their bilinear weights (the lightmap's own
//! interpolation; only covered centres of the holding texel's chart, renormalised), so a ray
//! that lands near a sender's edge reads the light between it and its neighbour, not the
//! sender's centre. These shares estimate the form factors with the mesh's own geometry and
//! visibility. Over the *near set* `N_i` — the texels whose centres lie within `reach` texel
//! sizes (`reach · √A_i`) of `i`'s centre in 3D, across seams too — the correction
//!
//! ```text
//! ΔF_ij = Σ_rays w_j(y) / G² − F_ij       (j ∈ N_i, F_ij the transport's kernel with visibility)
//! ΔE_i  = Σ_{rays on opaque surface} (W(y)·ρ(y)·E_d(y) − Σ_j w_j(y)·B_in,j) / G²
//! ```
//!
//! (`w_j(y)` the bilinear weights of the hit `y` kept in `N_i`, `W(y)` their sum)
//! replaces the transport's near form factors by the gathered ones — the solve adds `ΔF·B` to
//! every gather, so all bounces see them ([`Correction::gather`]) — and adds the first bounce of
//! the direct light as it falls at the hit points `y` (ray-cast, as the first order is) instead
//! of the sender texels' transfer input `B_in`: the irradiance `ΔE` enters the solve beside the
//! direct light, `B = X (E_d + ΔE + (F + ΔF) B)`, so it is scattered under skin and bounced like
//! it ([`Correction::input`]). Translucent senders keep their texel value (their exitance is the
//! light scattered under the skin, smooth over the profile, not `ρ̄ E_d` at the hit): only the
//! geometry is gathered for them. Texels beyond the near set keep the transport's kernel; a ray
//! that reaches one is dropped (the kernel has it).
//!
//! The correction is deterministic (stratified rays, fixed order) and costs `G²` rays per
//! texel plus the near set's kernels and visibility rays. Its noise is the gathered
//! form factors' quadrature error: with `G = 32`, 1,024 rays per texel. Spreading each ray
//! bilinearly rather than crediting the texel that holds the hit took the head at 256²
//! (radiosity alone) from 9.31 % to 8.80 % indirect against the path-traced reference, at 64²
//! from 15.2 % to 13.3 % (55a9752 → 9dcd2a9; README, *The interreflection's near field*).
//!
//! Where the transport's kernel is exact (flat walls: the Cornell box) the correction only adds
//! that noise, largest where a sender's light peaks within a texel (the ceiling beside a
//! lamp): at 64² 1.23 % → 5.62 % indirect with `G = 32`, 1.77 % with `G = 64`. Where a texel is
//! coarser than a slit it faces (the head at 64², skin: 7–9 mm texels on lips closed on each
//! other), the rays find the slit's far side filling the hemisphere, but the light the texels
//! there hold is that of their centres, near the slit's mouth; with skin the two sides then
//! relight each other too much (the head at 64² with both effects: 27.2 % → 28.6 %). Off by
//! default for both reasons.
//!
//! Units: `ΔF` dimensionless, `ΔE` W/m² (irradiance), `B` W/m².

use std::sync::atomic::{AtomicU64, Ordering};

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use thiserror::Error;

use crate::bake::lighting::{direct_at, lift_m};
use crate::bake::point_grid::PointGrid;
use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
use crate::bake::transport::form_factor::tangent_frame;
use crate::bake::transport::{Cancelled, Kernels, Patch, SetupProgress};
use crate::scene::{Light, Scene, SurfaceAlbedo};

/// Default reach of the near set, in texel sizes (`√A_i`). On the head at 256² (radiosity
/// alone, against the path-traced reference, `G = 32`, at 9dcd2a9) 4, 8, 16 and 32 sizes took
/// the indirect error from 16.0 % to 10.0 %, 9.25 %, 8.80 % and 8.62 % (README, *The
/// interreflection's near field*); the near set's kernels cost as its area, the reach squared.
pub const DEFAULT_REACH: f32 = 16.0;

/// Most rays per side (`G`): 4,096 rays per texel.
pub const MAX_RAYS_PER_SIDE: u32 = 64;

/// How the near field is gathered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearGather {
    /// Rays per side: `G × G` stratified rays per receiver texel.
    pub rays_per_side: u32,
    /// The near set's radius in texel sizes (`√A` of the receiver).
    pub reach: f32,
    /// Most bytes the rows may hold (`None`: no limit); [`correction`] stops with
    /// [`GatherError::TooLarge`] once they pass it. On the head at 256² the default settings
    /// hold 7.1 M entries, about 59 MB.
    pub max_bytes: Option<u64>,
}

impl NearGather {
    /// `G × G` rays per texel and the default reach.
    pub fn new(rays_per_side: u32) -> Self {
        Self {
            rays_per_side,
            reach: DEFAULT_REACH,
            max_bytes: None,
        }
    }

    /// Checks the settings; the error says what is allowed.
    pub fn check(&self) -> Result<(), String> {
        if !(2..=MAX_RAYS_PER_SIDE).contains(&self.rays_per_side) {
            return Err(format!(
                "{} rays per side: give 2 to {MAX_RAYS_PER_SIDE} (G × G rays per texel)",
                self.rays_per_side
            ));
        }
        if !(self.reach.is_finite() && self.reach > 0.0 && self.reach <= 64.0) {
            return Err(format!(
                "a reach of {} texel sizes: give a number above 0, at most 64",
                self.reach
            ));
        }
        Ok(())
    }
}

/// The gathered near field of every receiver texel ([module docs](self)).
pub struct Correction {
    /// Per receiver, its near senders and `ΔF_ij` (non-zero ones only).
    pub rows: Vec<Vec<(u32, f32)>>,
    /// Per receiver, `ΔE_i` (W/m²): the first bounce of the direct light at the hit points on
    /// opaque near senders, less the same rays' senders' transfer input.
    pub irradiance: Vec<Vec3>,
}

impl Correction {
    /// Adds `ΔF·b` to the gathered irradiance `e` (W/m²; one value per texel).
    pub fn gather(&self, b: &[Vec3], e: &mut [Vec3]) {
        e.par_iter_mut()
            .zip(&self.rows)
            .for_each(|(e, row)| *e += row.iter().map(|&(j, f)| b[j as usize] * f).sum::<Vec3>());
    }

    /// Adds `ΔF` to a dense form-factor matrix `F` (row = receiver).
    pub fn add_to(&self, f: &mut faer::Mat<f64>) {
        for (i, row) in self.rows.iter().enumerate() {
            for &(j, d) in row {
                f[(i, j as usize)] += d as f64;
            }
        }
    }

    /// The solve's first-order input with `ΔE` beside the direct light: `b_in + ρ̄·ΔE` per
    /// texel (the solves divide their input by `ρ̄` to find `E_d`, so this is
    /// `E_d + ΔE`). The final is then made from the original `b_in`
    /// ([`crate::bake::lighting::with_first_order`]).
    pub fn input(&self, b_in: &[Vec3], patches: &[Patch]) -> Vec<Vec3> {
        b_in.iter()
            .zip(&self.irradiance)
            .zip(patches)
            .map(|((b, e), p)| *b + p.rho * *e)
            .collect()
    }

    /// Number of stored `ΔF` entries.
    pub fn entries(&self) -> usize {
        self.rows.iter().map(Vec::len).sum()
    }
}

/// Bytes one receiver's row holds with `entries` `ΔF` entries (its vector, entries and `ΔE`).
fn row_bytes(entries: usize) -> u64 {
    (std::mem::size_of::<Vec<(u32, f32)>>()
        + entries * std::mem::size_of::<(u32, f32)>()
        + std::mem::size_of::<Vec3>()) as u64
}

/// Why [`correction`] stopped.
#[derive(Debug, Error)]
pub enum GatherError {
    /// The progress' cancel flag was raised.
    #[error("cancelled")]
    Cancelled,
    /// The rows outgrew [`NearGather::max_bytes`] (checked as they are gathered).
    #[error(
        "the gathered near field outgrew its memory budget: {:.1} kB so far, limit {:.1} kB",
        *bytes as f64 / 1e3,
        *limit as f64 / 1e3
    )]
    TooLarge {
        /// Bytes held when the budget was passed.
        bytes: u64,
        /// The budget, bytes.
        limit: u64,
    },
}

impl From<Cancelled> for GatherError {
    fn from(_: Cancelled) -> Self {
        Self::Cancelled
    }
}

/// One receiver's `ΔF` entries and `ΔE`.
type Row = (Vec<(u32, f32)>, Vec3);

/// The gathered form factors `ΔF` of every covered texel: per receiver, its near senders and
/// `ΔF_ij` (non-zero ones only).
pub type FormFactorRows = Vec<Vec<(u32, f32)>>;

/// The gathered form factors `ΔF` alone (no light) of the receivers `receivers` (texel
/// indices; the other rows are left empty), each as [`correction`] finds it: a row depends on
/// its receiver alone, so a shard's rows equal the whole bake's. A bake's transfer rows take
/// them as a first-bounce correction ([`crate::bake::multires::with_gathered_rows`]); `ΔE`
/// needs the lights, which a bake does not know. Reports "near gather: receivers" to
/// `progress`.
#[expect(
    clippy::too_many_arguments,
    reason = "the scene, its grid, patches, kernels and rays, and which receivers"
)]
pub fn form_factor_rows(
    scene: &Scene,
    grid: &TexelGrid,
    patches: &[Patch],
    kernels: &Kernels,
    vis: &Visibility,
    settings: NearGather,
    receivers: std::ops::Range<u32>,
    progress: &SetupProgress,
) -> Result<FormFactorRows, GatherError> {
    let dark = vec![Vec3::ZERO; patches.len()];
    let ctx = Ctx::new(scene, grid, patches, kernels, &[], vis, &dark, settings);
    let end = (receivers.end as usize).min(patches.len());
    let range = (receivers.start as usize).min(end)..end;
    let mut rows = vec![Vec::new(); patches.len()];
    for (i, (row, _)) in range.clone().zip(rows_of(&ctx, range, progress)?) {
        rows[i] = row;
    }
    Ok(rows)
}

/// The gathered near field of every covered texel of `grid` (rasterised from `scene`;
/// `patches` its [`crate::bake::transport::texel_patches`], `b_in` the transfer input the
/// solve is given, W/m²). Reports "near gather: receivers" to `progress`.
#[expect(
    clippy::too_many_arguments,
    reason = "the scene, its grid, patches, kernels, lights and rays, and the input: what the solve holds"
)]
pub fn correction(
    scene: &Scene,
    grid: &TexelGrid,
    patches: &[Patch],
    kernels: &Kernels,
    lights: &[Light],
    vis: &Visibility,
    b_in: &[Vec3],
    settings: NearGather,
    progress: &SetupProgress,
) -> Result<Correction, GatherError> {
    let ctx = Ctx::new(scene, grid, patches, kernels, lights, vis, b_in, settings);
    let mut rows = Vec::with_capacity(patches.len());
    let mut irradiance = Vec::with_capacity(patches.len());
    for (row, e) in rows_of(&ctx, 0..patches.len(), progress)? {
        rows.push(row);
        irradiance.push(e);
    }
    Ok(Correction { rows, irradiance })
}

/// The rows of the receivers `receivers` (texel indices), in order, with the memory budget
/// checked as they are gathered; reports "near gather: receivers" to `progress`.
fn rows_of(
    ctx: &Ctx<'_>,
    receivers: std::ops::Range<usize>,
    progress: &SetupProgress,
) -> Result<Vec<Row>, GatherError> {
    const CHUNK: usize = 256;
    progress.phase("near gather: receivers", receivers.len() as u64);
    let bytes = AtomicU64::new(0);
    let (start, end) = (receivers.start, receivers.end);
    let chunks: Vec<Vec<Row>> = (0..(end - start).div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            progress.check()?;
            let range = start + c * CHUNK..(start + (c + 1) * CHUNK).min(end);
            let len = range.len();
            let out: Vec<Row> = range.map(|i| receiver(ctx, i)).collect();
            let size: u64 = out.iter().map(|r| row_bytes(r.0.len())).sum();
            let total = bytes.fetch_add(size, Ordering::Relaxed) + size;
            if let Some(limit) = ctx.settings.max_bytes
                && total > limit
            {
                return Err(GatherError::TooLarge {
                    bytes: total,
                    limit,
                });
            }
            progress.advance(len as u64);
            Ok(out)
        })
        .collect::<Result<_, _>>()?;
    Ok(chunks.into_iter().flatten().collect())
}

/// The texels sharing a ray's hit at lightmap UV `uv` on chart `chart`, and their weights:
/// the bilinear weights of the four texel centres around it, those covered by `chart` kept
/// and renormalised; else the chart's texel among those four whose centre is nearest, or none
/// (a hit on a triangle too small to hold a texel's centre nearby).
fn bilinear(grid: &TexelGrid, uv: Vec2, chart: u32) -> Shares {
    let px = uv.x * grid.width as f32 - 0.5;
    let py = (1.0 - uv.y) * grid.height as f32 - 0.5;
    let (x0, y0) = (px.floor(), py.floor());
    let (fx, fy) = (px - x0, py - y0);
    let mut out = Shares::default();
    let mut sum = 0.0;
    let mut nearest: Option<(u32, f32)> = None;
    for (dx, dy, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        if let Some(s) = grid.at(x0 as i32 + dx, y0 as i32 + dy)
            && grid.texels[s as usize].chart == chart
        {
            if w > 0.0 {
                out.push((s, w));
                sum += w;
            }
            if nearest.is_none_or(|(_, best)| w > best) {
                nearest = Some((s, w));
            }
        }
    }
    if sum <= 0.0 {
        let mut one = Shares::default();
        if let Some((s, _)) = nearest {
            one.push((s, 1.0));
        }
        return one;
    }
    out.entries[..out.len].iter_mut().for_each(|e| e.1 /= sum);
    out
}

/// At most four texels and their weights ([`bilinear`]), in order.
#[derive(Default)]
struct Shares {
    entries: [(u32, f32); 4],
    len: usize,
}

impl Shares {
    fn push(&mut self, e: (u32, f32)) {
        self.entries[self.len] = e;
        self.len += 1;
    }

    fn as_slice(&self) -> &[(u32, f32)] {
        &self.entries[..self.len]
    }
}

/// What every receiver reads.
struct Ctx<'a> {
    scene: &'a Scene,
    grid: &'a TexelGrid,
    patches: &'a [Patch],
    kernels: &'a Kernels,
    lights: &'a [Light],
    vis: &'a Visibility,
    b_in: &'a [Vec3],
    /// The texel centres, in cubes as wide as the near set's radius at the median texel size.
    centres: PointGrid,
    /// The texels' albedo rule.
    albedo: SurfaceAlbedo<'a>,
    settings: NearGather,
}

impl<'a> Ctx<'a> {
    #[expect(
        clippy::too_many_arguments,
        reason = "what every receiver reads, as the callers hold it"
    )]
    fn new(
        scene: &'a Scene,
        grid: &'a TexelGrid,
        patches: &'a [Patch],
        kernels: &'a Kernels,
        lights: &'a [Light],
        vis: &'a Visibility,
        b_in: &'a [Vec3],
        settings: NearGather,
    ) -> Self {
        let mut sizes: Vec<f32> = patches.iter().map(|p| p.area_m2.sqrt()).collect();
        let mid = sizes.len() / 2;
        let median = if sizes.is_empty() {
            1.0
        } else {
            *sizes.select_nth_unstable_by(mid, f32::total_cmp).1
        };
        Self {
            scene,
            grid,
            patches,
            kernels,
            lights,
            vis,
            b_in,
            centres: PointGrid::new(
                f64::from((settings.reach * median).max(1e-9)),
                (patches.iter().enumerate()).map(|(i, p)| (i as u32, p.position_m)),
            ),
            albedo: scene.surface_albedo(),
            settings,
        }
    }
}

/// One receiver's `ΔF` row and `ΔE`.
fn receiver(c: &Ctx<'_>, i: usize) -> Row {
    let Ctx {
        scene,
        grid,
        patches,
        kernels,
        lights,
        vis,
        b_in,
        centres,
        albedo,
        settings,
    } = c;
    let g = settings.rays_per_side as usize;
    let rays = (g * g) as f32;
    let t = &grid.texels[i];
    let a = &patches[i];
    let r = settings.reach * a.area_m2.sqrt();
    let r2 = r * r;
    // The near set and the transport's form factors to it.
    let mut row: Vec<(u32, f32)> = Vec::new();
    centres.for_each_within(a.position_m, r, |j| {
        let b = &patches[j as usize];
        if j as usize != i && (b.position_m - a.position_m).length_squared() <= r2 {
            row.push((j, -kernels.form_factor_c(a, b) * b.area_m2));
        }
    });
    row.sort_unstable_by_key(|e| e.0);
    // The rays.
    let eps = lift_m(a.area_m2);
    let origin = t.position_m + t.face_normal * eps;
    let (t1, t2) = tangent_frame(t.normal);
    let far = 2.0 * r + 4.0 * a.area_m2.sqrt();
    let mut e = Vec3::ZERO;
    for s in 0..g * g {
        let u1 = ((s / g) as f32 + 0.5) / g as f32;
        let u2 = ((s % g) as f32 + 0.5) / g as f32;
        let (rr, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
        let z = (1.0 - u1).max(0.0).sqrt();
        let dir = (t1 * (rr * phi.cos()) + t2 * (rr * phi.sin()) + t.normal * z).normalize();
        let Some(hit) = vis.closest_triangle_hit(origin, dir, (eps, far), t.triangle) else {
            continue;
        };
        let at = scene.mesh.surface_at(hit.triangle, hit.barycentrics);
        let (p, normal, uv) = (at.position_m, at.normal, at.uv);
        let material = scene.mesh.triangles[hit.triangle as usize].material;
        if normal.dot(dir) >= 0.0 {
            continue;
        }
        // The hit's chart (a ray may land in the strip along a chart's edge whose texel
        // centres lie outside it: it reads the chart's nearest centres).
        let Some(&chart) = grid.triangle_chart.get(hit.triangle as usize) else {
            continue;
        };
        // The ray's share goes to the texel centres around the hit, bilinearly (the
        // lightmap's own interpolation), within the hit's chart.
        let mut credited = 0.0f32;
        let mut input = Vec3::ZERO;
        let shares = bilinear(grid, uv, chart);
        let Some(&(j, _)) = shares.as_slice().first() else {
            continue;
        };
        for &(s, w) in shares.as_slice() {
            if let Ok(k) = row.binary_search_by_key(&s, |e| e.0) {
                row[k].1 += w / rays;
                credited += w;
                input += b_in[s as usize] * w;
            }
        }
        if credited > 0.0 && !kernels.is_translucent(material) {
            let rho = albedo.at(material, uv);
            let lift = lift_m(patches[j as usize].area_m2);
            let lifted = p + at.face_normal * lift;
            let (e_d, _) = direct_at(p, normal, (lifted, lift), lights, vis);
            e += (rho * e_d * credited - input) / rays;
        }
    }
    row.retain(|e| e.1 != 0.0);
    (row, e)
}
