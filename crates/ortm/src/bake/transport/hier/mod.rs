//! Hierarchical transport: the first-bounce operator `F` (form factors with visibility) as
//! links between clusters of a [`tree::Tree`], refined down to single texels only where a
//! block-level link would be inaccurate, and the multi-bounce solution
//! `B = X (E_d + F B)` (see the [module docs](super) for the notation) by iterating on it.
//! Memory and time grow about as `n log n` in the number of patches `n`, instead of the dense
//! solve's `n²` and `n³` ([`super::dense`]).
//!
//! # Links and error control
//! Refinement starts from the pair (root, root) and splits the larger cluster of a pair until
//! the pair is *admissible* — both clusters flat (`|Σ A n| / A ≥` [`MIN_FLATNESS`]), apart
//! (`r_I + r_J < d`), and with an estimated error `F_IJ · (r_I + r_J) / d ≤ ε` — or both are
//! single texels. The two directions of a pair (`I ← J` and `J ← I`) are refined together: each
//! direction has its own error test (`F_IJ` and `F_JI` differ by the areas), the one that fails
//! goes on splitting alone, and where both are admissible one set of visibility rays serves
//! both links (the maze's links at 1024² in 118 s instead of 165–174 s with a set of rays per
//! direction). `F_IJ` is the unoccluded block form factor
//! `cos⁺θ_I cos⁺θ_J A_J / (π d²)` between the centroids, with the clusters' mean cosines
//! (from `Σ A n`), and `(r_I + r_J)/d` the relative variation of the kernel across the blocks.
//! Visibility is the fraction of [`Settings::visibility_rays`] rays between member texels
//! that arrive; a partly visible pair whose form factor exceeds
//! [`PARTIAL_VISIBILITY_FACTOR`]`·ε` is refined (shadow boundaries resolve down to texels where
//! they carry light), so for such a pair the rays stop at the first that disagrees with the
//! ones before (the verdict is the same; 18 % less time for the links of the maze at 512²). Texel pairs use the exact
//! kernel of the dense solve ([`super::Kernels::form_factor_c`]: collocated at the receiver's
//! centre, the sender's square integrated exactly within 8 texel sizes, one visibility ray).
//! `ε` is [`Settings::tolerance`].
//!
//! # Receivers
//! A link into a cluster stores the direction `ω` to the sender and
//! `g = cos⁺θ_J A_J V / (π d²)`; gathering adds `g B_J ω` to the cluster's *irradiance
//! vector* `Φ_I` (W/m² per channel, a 3-vector), which is pushed down to the texels, where
//! `E_i = max(0, n_i · Φ)`: every texel gets its own cosine to every link's direction. A link
//! into a single texel stores the scalar `cos⁺θ_i g` (or the exact kernel). The direction is
//! not stored but recomputed from the two nodes' centroids ([`Tree::direction`]), so a link is
//! 8 bytes (sender, coefficient): the links are most of a large bake's memory (the maze at
//! 1024², ε = 10⁻⁴: about 190 M links — from the resident memory its progress lines show —,
//! 1.5 GB; 3.8 GB with the direction stored).
//!
//! # Solve
//! Jacobi iteration `B ← X (E_d + F B)` from `B = B_o`, with `E_d = B_o / ρ̄` on translucent
//! texels and `B_i = B_o,i + ρ_i (F B)_i` on opaque ones; the subsurface operator `X` is kept
//! sparse (every pair within the profile's support, the dense solve's weights). Each sweep
//! pulls `B` up the tree (area-weighted means), gathers over the links and pushes `Φ` down.
//! It stops when the largest relative change of a channel's total radiosity power is below
//! [`Settings::convergence`]; the error after `k` sweeps falls like `ρ^k`.
//!
//! # Limits
//! The sparse subsurface operator holds every pair within the support (fine at texel sizes
//! comparable to the diffusion length; a translucent material with a support of many texels
//! grows it as `n × support²`). Block links assume the clusters see each other as wholes
//! (`Φ` is clamped per texel, not per link), which the flatness and distance tests bound.

pub mod subsurface;
pub mod tree;

use glam::Vec3;
use rayon::prelude::*;

use super::{Cancelled, Kernels, Patch, SetupProgress, SupportGrid};
use subsurface::SubsurfaceWalk;
use tree::Tree;

/// A partly visible pair is refined when its form factor exceeds this fraction of `ε`: partial
/// visibility is not noise but a shadow boundary, and its error adds up over the many links of
/// a receiver beside an occluder (at ε = 10⁻³ on the head, 3.6 % with a factor of 1, 2.2 % with
/// 0.1 for a third more links).
pub const PARTIAL_VISIBILITY_FACTOR: f32 = 0.1;

/// The tolerance `ε` of `ortm bake --tolerance` given without a value and of `ortm solve`: the
/// largest of 10⁻³, 3·10⁻⁴, 10⁻⁴ at which the bake's evaluator on this operator is within 2 %
/// (indirect relative RMSE, interior texels) of the exact dense solve on the Cornell box, the
/// maze and the head at 64² (`ortm bench accuracy --cases cornell-64,maze-64,head-64
/// --tolerances 1e-3,3e-4,1e-4`: Cornell 4.4 / 2.3 / 0.9 %, maze 1.2 / 0.5 / 0.2 %, head 2.4 /
/// 1.5 / 1.0 %).
pub const DEFAULT_TOLERANCE: f32 = 1e-4;

/// Smallest `|Σ A n| / A` of a cluster that may be linked as a whole (~25° of spread).
pub const MIN_FLATNESS: f32 = 0.9;

/// The subsurface walk's tolerance that `ortm bake --tolerance` and `ortm bench accuracy
/// --tolerances` take unless told otherwise ([`Settings::subsurface_tolerance`]): on the head
/// at 512² the walk is then 0.52 % of the subsurface term's RMS off its exact sum and visits 306
/// nodes per receiver (487 at 10⁻⁴, 0.18 %); the head's 64² rows of `ortm bench accuracy
/// --tolerances 1e-4` read the same to 0.1 point with it, and its 512² bake takes 97 s
/// instead of 112 s.
pub const DEFAULT_SUBSURFACE_TOLERANCE: f32 = 1e-3;

/// Settings of the hierarchical operator and its solve.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// `ε`: the largest estimated error of one link, as a form factor (module docs).
    pub tolerance: f32,
    /// The subsurface walk's tolerance ([`subsurface`], "Error control"; the bake's cell
    /// integration and its normalisation); `None`: [`Settings::tolerance`]. A separate knob
    /// since the two errors differ in kind (what each costs and gives on the head:
    /// [`DEFAULT_SUBSURFACE_TOLERANCE`]).
    pub subsurface_tolerance: Option<f32>,
    /// Rays that estimate a block link's visibility.
    pub visibility_rays: u32,
    /// Stop when the relative change of every channel's power in a sweep is below this.
    pub convergence: f64,
    /// At most this many sweeps.
    pub max_iterations: u32,
    /// Stop refining with [`BuildError::TooLarge`] once the links found and the pairs still to
    /// refine would take more bytes than this (`None`: no limit).
    pub max_bytes: Option<u64>,
    /// Rounds of balancing of the subsurface weights ([`Kernels::balance_rounds`]) in the
    /// kernels that [`crate::bake::transport::Transport::build_hierarchical`] makes (callers
    /// of [`Operator::build`] set their kernels' own); 0: the columns capped alone.
    pub subsurface_balance_rounds: u32,
}

/// Why [`Operator::build`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// The progress's cancel flag was raised.
    #[error("cancelled")]
    Cancelled,
    /// The links would exceed [`Settings::max_bytes`].
    #[error(
        "the hierarchical operator needs more than {limit} bytes ({links} links and {pending} \
         pairs to refine after round {round}); raise the tolerance (each tenfold rise has cut \
         the links 2–5× in the tests) or use a smaller lightmap"
    )]
    TooLarge {
        /// Links found so far.
        links: usize,
        /// Pairs left to refine.
        pending: usize,
        /// Refinement round (from 1).
        round: u32,
        /// The limit, bytes.
        limit: u64,
    },
}

impl From<Cancelled> for BuildError {
    fn from(_: Cancelled) -> Self {
        Self::Cancelled
    }
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            subsurface_tolerance: None,
            visibility_rays: 8,
            convergence: 1e-6,
            max_iterations: 1000,
            max_bytes: None,
            subsurface_balance_rounds: 0,
        }
    }
}

/// One link into a receiver node: the receiver's texels get the irradiance
/// `max(0, n_i · ω)·coef·B_S` (block receiver) or `coef·B_S` (texel receiver) from the sender
/// node's area-weighted mean radiosity `B_S`. The direction `ω` from the receiver's centroid to
/// the sender's is not stored — it is the one the refinement linked them by
/// ([`Tree::direction`]) — so a link is 8 bytes.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct Link {
    /// Sender node.
    pub send: u32,
    /// `g` (block receiver) or the scalar form factor (texel receiver).
    pub coef: f32,
}

impl Link {
    /// The irradiance (W/m²) this link brings a receiving texel of normal `n` per W/m² of the
    /// sender's mean radiosity, `dir` being its [`Operator::link_direction`] (what
    /// [`Operator::gather`] adds, per link: the gather clamps the sum of a node's links at the
    /// texel, this clamps each link).
    #[inline]
    pub fn irradiance_per_radiosity(&self, dir: Vec3, n: Vec3) -> f32 {
        if dir == Vec3::ZERO {
            self.coef
        } else {
            n.dot(dir).max(0.0) * self.coef
        }
    }
}

/// A pair of nodes still to refine: `(x, y, wanted)` with `x < y` (or `x == y`, a node with
/// itself), `wanted` the directions that still need links: [`RECV_X`] (`x` receives from `y`)
/// and [`RECV_Y`]. Both directions of a pair are refined together, so one set of visibility
/// rays serves both links (each direction keeps its own error test).
type Pair = (u32, u32, u8);

/// In a [`Pair`]'s directions: `x` receives from `y`.
const RECV_X: u8 = 1;
/// In a [`Pair`]'s directions: `y` receives from `x`.
const RECV_Y: u8 = 2;

/// The pair `(a, b)` with directions `wanted` (bit [`RECV_X`]: `a` receives), ordered so that
/// its first node is the smaller.
#[inline]
fn ordered(a: u32, b: u32, wanted: u8) -> Pair {
    if a <= b {
        (a, b, wanted)
    } else {
        (b, a, (wanted & RECV_X) << 1 | (wanted & RECV_Y) >> 1)
    }
}

/// The result of refining one node pair: up to one link each way, and up to three pairs to
/// refine further (no allocation per pair).
struct Refined {
    links: [(u32, Link); 2],
    n_links: u8,
    split: [Pair; 3],
    n_split: u8,
}

impl Refined {
    const EMPTY: Self = Self {
        links: [(0, Link { send: 0, coef: 0.0 }); 2],
        n_links: 0,
        split: [(0, 0, 0); 3],
        n_split: 0,
    };

    fn link(&mut self, receiver: u32, link: Link) {
        self.links[self.n_links as usize] = (receiver, link);
        self.n_links += 1;
    }

    fn pair(&mut self, pair: Pair) {
        self.split[self.n_split as usize] = pair;
        self.n_split += 1;
    }
}

/// Frontier pairs refined per parallel batch: bounds the per-round results held at once
/// (2²⁰ [`Refined`] values, ~64 MB) however large the frontier grows.
const REFINE_BATCH: usize = 1 << 20;

/// The sparse subsurface operator: per translucent receiver, `(sender, S_ij per channel)`.
#[derive(serde::Serialize, serde::Deserialize)]
struct Subsurface {
    start: Vec<u32>,
    entries: Vec<(u32, [f32; 3])>,
}

/// The hierarchical first-bounce operator over a set of patches, and its solve.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Operator {
    patches: Vec<Patch>,
    tree: Tree,
    /// Links grouped by receiver node: those of node `r` are `links[start[r]..start[r + 1]]`.
    start: Vec<u32>,
    links: Vec<Link>,
    translucent: Vec<bool>,
    subsurface: Option<Subsurface>,
    /// Built by [`Operator::build_links_only`]: no subsurface operator, no solve.
    links_only: bool,
    /// The subsurface term as a walk of the tree ([`Operator::build_links_only`] over
    /// translucent patches).
    walk: Option<SubsurfaceWalk>,
    /// [`Settings::tolerance`] of the build.
    tolerance: f32,
}

/// A solution and how it was reached.
pub struct Solution {
    /// Final radiosity per patch, W/m².
    pub b: Vec<Vec3>,
    /// Sweeps made.
    pub iterations: u32,
    /// Relative change of the last sweep (largest over channels).
    pub change: f64,
}

impl Operator {
    /// Builds the operator over `patches` (subsurface weights normalised here, as
    /// [`super::dense::DenseTransport::new`] does). Reports "transport: links" (one step per
    /// refinement round), "transport: subsurface weights" and "transport: subsurface cap" to
    /// `progress`; stops when it is cancelled or the links outgrow [`Settings::max_bytes`].
    pub fn build(
        patches: &[Patch],
        kernels: &Kernels,
        settings: &Settings,
        progress: &SetupProgress,
    ) -> Result<Self, BuildError> {
        let mut patches = patches.to_vec();
        kernels.normalise_subsurface_with(&mut patches, progress)?;
        let tree = Tree::build(&patches);
        let (start, links) = refine_links(&patches, &tree, kernels, settings, progress)?;
        let translucent: Vec<bool> = patches
            .iter()
            .map(|p| kernels.is_translucent(p.material))
            .collect();
        let subsurface = translucent
            .iter()
            .any(|&t| t)
            .then(|| subsurface_rows(&patches, &translucent, kernels));
        progress.check()?;
        Ok(Self {
            patches,
            tree,
            start,
            links,
            translucent,
            subsurface,
            links_only: false,
            walk: None,
            tolerance: settings.tolerance,
        })
    }

    /// The links and the subsurface walk, for the bake's cell integration
    /// ([`crate::bake::cells`]): no sparse subsurface operator, so the set-up costs no
    /// `n × support²` pairs. The subsurface weights are normalised by the walk
    /// ([`SubsurfaceWalk::normalise`]) on the operator's copy of the patches
    /// ([`Operator::patches`]). [`Operator::solve`] refuses such an operator.
    ///
    /// # Errors
    /// As [`Operator::build`].
    pub fn build_links_only(
        patches: &[Patch],
        kernels: &Kernels,
        settings: &Settings,
        progress: &SetupProgress,
    ) -> Result<Self, BuildError> {
        let mut patches = patches.to_vec();
        let tree = Tree::build(&patches);
        let walk = if patches.iter().any(|p| kernels.is_translucent(p.material)) {
            let eps = settings.subsurface_tolerance.unwrap_or(settings.tolerance);
            let mut w = SubsurfaceWalk::new(&tree, &patches, eps);
            w.normalise(&tree, &mut patches, kernels, progress)?;
            Some(w)
        } else {
            None
        };
        let (start, links) = refine_links(&patches, &tree, kernels, settings, progress)?;
        Ok(Self {
            translucent: vec![false; patches.len()],
            patches,
            tree,
            start,
            links,
            subsurface: None,
            links_only: true,
            walk,
            tolerance: settings.tolerance,
        })
    }

    /// The operator's patches (for [`Operator::build_links_only`], with the subsurface scales
    /// of the walk's normalisation).
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }

    /// The subsurface walk ([`Operator::build_links_only`] over translucent patches).
    pub fn subsurface_walk(&self) -> Option<&SubsurfaceWalk> {
        self.walk.as_ref()
    }

    /// The tolerance `ε` it was built at ([`Settings::tolerance`]).
    pub fn tolerance(&self) -> f32 {
        self.tolerance
    }

    /// The cluster tree.
    pub fn tree(&self) -> &Tree {
        &self.tree
    }

    /// The direction of the links into node `node`'s from sender `send`: unit, from the
    /// receiver's centroid to the sender's for a block receiver, zero for a texel receiver
    /// (whose links are scalar) — what [`Link::irradiance_per_radiosity`] takes.
    #[inline]
    pub fn link_direction(&self, node: u32, send: u32) -> Vec3 {
        if self.tree.nodes[node as usize].is_leaf() {
            Vec3::ZERO
        } else {
            self.tree.direction(node, send)
        }
    }

    /// The links into node `node` of [`Operator::tree`].
    #[inline]
    pub fn links_of(&self, node: u32) -> &[Link] {
        &self.links[self.start[node as usize] as usize..self.start[node as usize + 1] as usize]
    }

    /// Number of links.
    pub fn link_count(&self) -> usize {
        self.links.len()
    }

    /// Links between single texels (the refined near field).
    pub fn texel_link_count(&self) -> usize {
        (0..self.tree.nodes.len())
            .filter(|&r| self.tree.nodes[r].is_leaf())
            .map(|r| {
                self.links[self.start[r] as usize..self.start[r + 1] as usize]
                    .iter()
                    .filter(|l| self.tree.nodes[l.send as usize].is_leaf())
                    .count()
            })
            .sum()
    }

    /// Bytes held by the tree, the links and the subsurface operator.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.tree.nodes.len() * size_of::<tree::Node>()
            + (self.tree.order.len() + self.tree.leaf_of.len() + self.start.len()) * 4
            + self.links.len() * size_of::<Link>()
            + self.patches.len() * size_of::<Patch>()
            + self.subsurface.as_ref().map_or(0, |s| {
                s.start.len() * 4 + s.entries.len() * size_of::<(u32, [f32; 3])>()
            })
    }

    /// The irradiance `F B` (W/m²) that radiosity `b` (W/m², per patch) sends to every patch.
    pub fn gather(&self, b: &[Vec3]) -> Vec<Vec3> {
        let nodes = &self.tree.nodes;
        // Pull: area-weighted mean radiosity of every node, children before parents.
        let mut b_node = vec![Vec3::ZERO; nodes.len()];
        for id in (0..nodes.len()).rev() {
            let n = &nodes[id];
            b_node[id] = if n.is_leaf() {
                b[self.tree.order[n.first as usize] as usize]
            } else {
                let [c0, c1] = n.children.map(|c| c as usize);
                let (a0, a1) = (nodes[c0].area_m2, nodes[c1].area_m2);
                let a = a0 + a1;
                if a > 0.0 {
                    (b_node[c0] * a0 + b_node[c1] * a1) / a
                } else {
                    Vec3::ZERO
                }
            };
        }
        // Gather per receiver node: Φ (3 channels × vector) and the scalar part.
        let gathered: Vec<([Vec3; 3], Vec3)> = (0..nodes.len())
            .into_par_iter()
            .map(|r| {
                let mut phi = [Vec3::ZERO; 3];
                let mut e = Vec3::ZERO;
                let leaf = nodes[r].is_leaf();
                for l in &self.links[self.start[r] as usize..self.start[r + 1] as usize] {
                    let flux = b_node[l.send as usize] * l.coef;
                    if leaf {
                        e += flux;
                    } else {
                        let dir = self.tree.direction(r as u32, l.send);
                        for (c, p) in phi.iter_mut().enumerate() {
                            *p += dir * flux[c];
                        }
                    }
                }
                (phi, e)
            })
            .collect();
        // Push Φ down (parents before children), then every texel takes its cosine.
        let mut phi: Vec<[Vec3; 3]> = gathered.iter().map(|g| g.0).collect();
        for id in 0..nodes.len() {
            let n = &nodes[id];
            if !n.is_leaf() {
                let p = phi[id];
                for c in n.children {
                    for (ch, v) in phi[c as usize].iter_mut().enumerate() {
                        *v += p[ch];
                    }
                }
            }
        }
        let mut e = vec![Vec3::ZERO; b.len()];
        for (i, out) in e.iter_mut().enumerate() {
            let leaf = self.tree.leaf_of[i] as usize;
            let n = self.patches[i].normal;
            let v = &phi[leaf];
            *out =
                gathered[leaf].1 + Vec3::new(n.dot(v[0]), n.dot(v[1]), n.dot(v[2])).max(Vec3::ZERO);
        }
        e
    }

    /// Final radiosity for the first-order lightmap `b_o` (W/m², per patch): Jacobi sweeps
    /// `B ← X (E_d + F B)` (module docs). Reports "transport: solve" (one step per sweep).
    pub fn solve(
        &self,
        b_o: &[Vec3],
        settings: &Settings,
        progress: &SetupProgress,
    ) -> Result<Solution, Cancelled> {
        self.solve_with_source(b_o, None, settings, progress)
    }

    /// [`Operator::solve`] with radiosity `source` (W/m², one per patch) emitted by the
    /// patches beside their first scattering of `b_o`: sweeps `B ← X (E_d + F B) + source`,
    /// so the source and all its bounces are in `B` (as
    /// [`super::dense::FactoredTransport::solve_with_source`]).
    pub fn solve_with_source(
        &self,
        b_o: &[Vec3],
        source: Option<&[Vec3]>,
        settings: &Settings,
        progress: &SetupProgress,
    ) -> Result<Solution, Cancelled> {
        self.solve_corrected(b_o, source, None, settings, progress)
    }

    /// [`Operator::solve_with_source`] with `correction` adding to every gather's irradiance
    /// (W/m², one per patch) what a sparse operator gives for the current `B` — the near
    /// field gathered by rays ([`crate::bake::near_gather::Correction::gather`]): sweeps
    /// `B ← X (E_d + F B + correction(B)) + source`.
    #[expect(
        clippy::type_complexity,
        reason = "a borrowed closure, spelled where it is taken"
    )]
    pub fn solve_corrected(
        &self,
        b_o: &[Vec3],
        source: Option<&[Vec3]>,
        correction: Option<&(dyn Fn(&[Vec3], &mut [Vec3]) + Sync)>,
        settings: &Settings,
        progress: &SetupProgress,
    ) -> Result<Solution, Cancelled> {
        assert_eq!(
            b_o.len(),
            self.patches.len(),
            "one first-order value per patch"
        );
        if let Some(s) = source {
            assert_eq!(s.len(), self.patches.len(), "one source value per patch");
        }
        let with_source = |mut b: Vec<Vec3>| {
            if let Some(s) = source {
                for (x, v) in b.iter_mut().zip(s) {
                    *x += *v;
                }
            }
            b
        };
        assert!(
            !self.links_only,
            "an operator built by build_links_only has no subsurface operator to solve with"
        );
        let e_d: Vec<Vec3> = b_o
            .iter()
            .zip(&self.patches)
            .map(|(b, p)| {
                Vec3::select(
                    p.rho.cmpgt(Vec3::ZERO),
                    *b / p.rho.max(Vec3::splat(1e-30)),
                    Vec3::ZERO,
                )
            })
            .collect();
        let power = |b: &[Vec3]| -> [f64; 3] {
            let mut s = [0.0f64; 3];
            for (v, p) in b.iter().zip(&self.patches) {
                for (c, x) in s.iter_mut().enumerate() {
                    *x += v[c] as f64 * p.area_m2 as f64;
                }
            }
            s
        };
        progress.phase("transport: solve", settings.max_iterations as u64);
        let mut b = with_source(b_o.to_vec());
        let mut last = power(&b);
        let (mut iterations, mut change) = (0u32, f64::INFINITY);
        while iterations < settings.max_iterations {
            progress.check()?;
            let mut e = self.gather(&b);
            if let Some(c) = correction {
                c(&b, &mut e);
            }
            b = with_source(self.exitance(b_o, &e_d, &e));
            iterations += 1;
            progress.advance(1);
            let now = power(&b);
            change = (0..3)
                .map(|c| (now[c] - last[c]).abs() / now[c].abs().max(1e-300))
                .fold(0.0, f64::max);
            last = now;
            if change < settings.convergence {
                break;
            }
        }
        Ok(Solution {
            b,
            iterations,
            change,
        })
    }

    /// `B = X (E_d + E)`: `B_o + ρ E` on opaque patches, `Σ_j S_ij (E_d,j + E_j)` on
    /// translucent ones.
    fn exitance(&self, b_o: &[Vec3], e_d: &[Vec3], e: &[Vec3]) -> Vec<Vec3> {
        (0..self.patches.len())
            .into_par_iter()
            .map(|i| {
                if !self.translucent[i] {
                    return b_o[i] + self.patches[i].rho * e[i];
                }
                let s = self
                    .subsurface
                    .as_ref()
                    .expect("translucent patches have rows");
                let mut out = Vec3::ZERO;
                for &(j, w) in &s.entries[s.start[i] as usize..s.start[i + 1] as usize] {
                    let j = j as usize;
                    out += Vec3::from(w) * (e_d[j] + e[j]);
                }
                out
            })
            .collect()
    }
}

/// Refines from (root, root) in rounds (all pairs of a round in parallel) and returns the
/// links grouped by receiver node (`start`, `links`); none without radiosity.
fn refine_links(
    patches: &[Patch],
    tree: &Tree,
    kernels: &Kernels,
    settings: &Settings,
    progress: &SetupProgress,
) -> Result<(Vec<u32>, Vec<Link>), BuildError> {
    if !kernels.effects.radiosity {
        return Ok((vec![0; tree.nodes.len() + 1], Vec::new()));
    }
    // The tree's depth bounds the rounds: each splits one node of every pair.
    let depth = (patches.len() as f64).log2().ceil() as u64 + 1;
    progress.phase("transport: links", 2 * depth);
    let mut frontier: Vec<Pair> = vec![(0, 0, RECV_X | RECV_Y)];
    let mut found: Vec<(u32, Link)> = Vec::new();
    let mut round = 0u32;
    while !frontier.is_empty() {
        progress.check()?;
        round += 1;
        let mut next = Vec::new();
        for batch in frontier.chunks(REFINE_BATCH) {
            let results: Vec<Refined> = batch
                .par_iter()
                .map(|&pair| refine(patches, tree, kernels, settings, pair))
                .collect();
            for res in results {
                found.extend_from_slice(&res.links[..res.n_links as usize]);
                next.extend_from_slice(&res.split[..res.n_split as usize]);
            }
        }
        frontier = next;
        progress.advance(1);
        if let Some(limit) = settings.max_bytes {
            let bytes = found.len() * std::mem::size_of::<(u32, Link)>()
                + frontier.len() * std::mem::size_of::<Pair>();
            if bytes as u64 > limit {
                return Err(BuildError::TooLarge {
                    links: found.len(),
                    pending: frontier.len(),
                    round,
                    limit,
                });
            }
        }
    }
    found.par_sort_unstable_by_key(|&(r, l)| (r, l.send));
    let mut start = vec![0u32; tree.nodes.len() + 1];
    for &(r, _) in &found {
        start[r as usize + 1] += 1;
    }
    for i in 0..tree.nodes.len() {
        start[i + 1] += start[i];
    }
    Ok((start, found.into_iter().map(|(_, l)| l).collect()))
}

/// One step of the refinement of the pair `(x, y)` in the directions `wanted` ([`Pair`]).
/// Each direction is tested on its own — a link into `x` is admissible when
/// `F_xy · (r_x + r_y) / d ≤ ε` — and the directions that fail are split further; the
/// visibility rays are cast once for both (the verdict of [`block_visibility`] is a function
/// of the unordered pair).
fn refine(
    patches: &[Patch],
    tree: &Tree,
    kernels: &Kernels,
    settings: &Settings,
    (x, y, wanted): Pair,
) -> Refined {
    let mut out = Refined::EMPTY;
    let (nx, ny) = (&tree.nodes[x as usize], &tree.nodes[y as usize]);
    if x == y {
        if !nx.is_leaf() {
            let [a, b] = nx.children;
            out.pair((a, a, wanted));
            out.pair(ordered(a, b, wanted));
            out.pair((b, b, wanted));
        }
        return out;
    }
    if nx.is_leaf() && ny.is_leaf() {
        let (i, j) = (tree.members(x)[0] as usize, tree.members(y)[0] as usize);
        let (pi, pj) = (&patches[i], &patches[j]);
        // Texel pairs use the dense solve's kernel, both ways with one ray.
        let (c_ij, c_ji) = kernels.form_factor_pair(pi, pj);
        let (f_x, f_y) = (c_ij * pj.area_m2, c_ji * pi.area_m2);
        if wanted & RECV_X != 0 && f_x > 0.0 {
            out.link(x, Link { send: y, coef: f_x });
        }
        if wanted & RECV_Y != 0 && f_y > 0.0 {
            out.link(y, Link { send: x, coef: f_y });
        }
        return out;
    }
    // The larger node is split (`y` when the radii are equal), in every direction given.
    let split = |out: &mut Refined, wanted: u8| {
        if !ny.is_leaf() && (nx.is_leaf() || ny.radius_m >= nx.radius_m) {
            for c in ny.children {
                out.pair(ordered(x, c, wanted));
            }
        } else {
            for c in nx.children {
                out.pair(ordered(c, y, wanted));
            }
        }
    };
    let d = ny.centroid - nx.centroid;
    let dist = d.length();
    let size = nx.radius_m + ny.radius_m;
    if dist <= size || nx.flatness() < MIN_FLATNESS || ny.flatness() < MIN_FLATNESS {
        split(&mut out, wanted);
        return out;
    }
    let w = d / dist; // = tree.direction(x, y), which the link does not store
    let cos_x = nx.normal_sum.dot(w) / nx.area_m2;
    let cos_y = -ny.normal_sum.dot(w) / ny.area_m2;
    if cos_x <= 0.0 || cos_y <= 0.0 {
        // Facing away as wholes; members may still face each other when the pair is close
        // for its size.
        if size > 0.5 * dist {
            split(&mut out, wanted);
        }
        return out;
    }
    // Per direction (into x, into y): the receiver's cosine, the sender's cosine and area.
    let mut admissible = 0u8;
    let mut coefs = [(0.0f32, 0.0f32); 2]; // (g, f) into x, into y
    for (k, (cos_r, cos_s, area_s, bit)) in [
        (cos_x, cos_y, ny.area_m2, RECV_X),
        (cos_y, cos_x, nx.area_m2, RECV_Y),
    ]
    .into_iter()
    .enumerate()
    {
        if wanted & bit == 0 {
            continue;
        }
        let g = cos_s * area_s / (std::f32::consts::PI * dist * dist);
        let f = cos_r * g;
        coefs[k] = (g, f);
        if f * size / dist <= settings.tolerance {
            admissible |= bit;
        }
    }
    let mut to_split = wanted & !admissible;
    if admissible != 0 {
        // A partly visible pair is split in a direction whose form factor is large enough,
        // whatever the fraction: when every admissible direction is such, the rays may stop
        // at the first that disagrees with the others.
        let threshold = settings.tolerance * PARTIAL_VISIBILITY_FACTOR;
        let split_if_partial = [coefs[0].1 > threshold, coefs[1].1 > threshold];
        let stop = [RECV_X, RECV_Y]
            .iter()
            .enumerate()
            .all(|(k, &bit)| admissible & bit == 0 || split_if_partial[k]);
        let v = block_visibility(
            patches,
            tree,
            kernels,
            (x, y),
            settings.visibility_rays,
            stop,
        );
        if v > 0.0 {
            for (k, (bit, receiver, sender, leaf)) in
                [(RECV_X, x, y, nx.is_leaf()), (RECV_Y, y, x, ny.is_leaf())]
                    .into_iter()
                    .enumerate()
            {
                if admissible & bit == 0 {
                    continue;
                }
                if v < 1.0 && split_if_partial[k] {
                    to_split |= bit;
                    continue;
                }
                let (g, f) = coefs[k];
                let coef = if leaf { f * v } else { g * v };
                out.link(receiver, Link { send: sender, coef });
            }
        }
    }
    if to_split != 0 {
        split(&mut out, to_split);
    }
    out
}

/// Fraction of `rays` rays between member texels of nodes `r` and `s` that arrive (members
/// picked by a hash of the pair, so the result is deterministic). With `stop_if_partial`, it
/// returns 0.5 as soon as one ray has arrived and one has not — the caller only needs to know
/// that the fraction lies strictly between 0 and 1 — which spares the remaining rays of the
/// pairs that will be split (about a third of the tested pairs on the maze).
fn block_visibility(
    patches: &[Patch],
    tree: &Tree,
    kernels: &Kernels,
    (r, s): (u32, u32),
    rays: u32,
    stop_if_partial: bool,
) -> f32 {
    let (mr, ms) = (tree.members(r), tree.members(s));
    let mut state = ((r as u64) << 32 | s as u64) ^ 0x9e37_79b9_7f4a_7c15;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let rays = rays.max(1);
    let mut seen = 0u32;
    for n in 0..rays {
        let a = &patches[mr[(next() % mr.len() as u64) as usize] as usize];
        let b = &patches[ms[(next() % ms.len() as u64) as usize] as usize];
        seen += u32::from(kernels.visible(a, b));
        if stop_if_partial && seen != 0 && seen != n + 1 {
            return 0.5;
        }
    }
    seen as f32 / rays as f32
}

/// The subsurface rows `S_ij` of every translucent receiver (every sender within the
/// profile's support, self term included).
fn subsurface_rows(patches: &[Patch], translucent: &[bool], kernels: &Kernels) -> Subsurface {
    let grid = SupportGrid::new(patches, kernels);
    let rows: Vec<Vec<(u32, [f32; 3])>> = (0..patches.len())
        .into_par_iter()
        .map(|i| {
            let mut row = Vec::new();
            if !translucent[i] {
                return row;
            }
            let a = &patches[i];
            grid.for_each_near(a.position_m, |j| {
                if let Some(s) = kernels.subsurface(a, &patches[j as usize], i == j as usize)
                    && s.iter().any(|&x| x != 0.0)
                {
                    row.push((j, s.map(|x| x as f32)));
                }
            });
            row
        })
        .collect();
    let mut start = Vec::with_capacity(rows.len() + 1);
    start.push(0u32);
    let mut entries = Vec::new();
    for row in rows {
        entries.extend(row);
        start.push(entries.len() as u32);
    }
    Subsurface { start, entries }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::bake::raycast::Visibility;
    use crate::bake::texels::TexelGrid;
    use crate::bake::transport::form_factor::unoccluded_form_factor;
    use crate::bake::transport::{Effects, texel_patches};

    /// The texel patches of `scene`'s lightmap, their tree and the default kernels.
    fn texel_tree(scene: &crate::scene::Scene) -> (Vec<Patch>, Tree, Kernels) {
        let grid = TexelGrid::build(scene).unwrap();
        let vis = Arc::new(Visibility::new(&scene.mesh));
        let kernels = Kernels::new(scene, Effects::default(), vis);
        let patches = texel_patches(&grid);
        let tree = Tree::build(&patches);
        (patches, tree, kernels)
    }

    /// Refining both directions of a pair together still gives every direction its own links:
    /// on the Cornell box at 24² no texel pair is covered twice by the links (a receiver
    /// texel's leaf and ancestors, each link's sender members), and of the texel pairs that
    /// face each other and see each other (one ray), at least 97 % are covered in both
    /// directions and at most 1 % in one only (measured: 98.5 % and 0.1 % of 40,678; the rest
    /// lie in block pairs beside the blocks whose rays all missed). A pair refined in one
    /// direction only would leave its mirror uncovered.
    #[test]
    fn links_cover_each_facing_pair_once_in_both_directions() {
        let scene = crate::scene::cornell::cornell_box(24);
        let (patches, tree, kernels) = texel_tree(&scene);
        let settings = Settings {
            tolerance: 1e-3,
            ..Settings::default()
        };
        let (start, links) =
            refine_links(&patches, &tree, &kernels, &settings, &SetupProgress::none()).unwrap();
        let n = patches.len();
        let mut cover = vec![0u8; n * n];
        for r in 0..tree.nodes.len() {
            for l in &links[start[r] as usize..start[r + 1] as usize] {
                for &i in tree.members(r as u32) {
                    for &j in tree.members(l.send) {
                        let c = &mut cover[i as usize * n + j as usize];
                        *c += 1;
                        assert!(*c == 1, "pair ({i}, {j}) covered twice");
                    }
                }
            }
        }
        let (mut facing, mut both, mut one) = (0usize, 0usize, 0usize);
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (&patches[i], &patches[j]);
                let (fa, fb) = (a.ff(), b.ff());
                if unoccluded_form_factor(&fa, &fb) <= 0.0
                    || unoccluded_form_factor(&fb, &fa) <= 0.0
                    || !kernels.visible(a, b)
                {
                    continue;
                }
                facing += 1;
                match (cover[i * n + j], cover[j * n + i]) {
                    (1, 1) => both += 1,
                    (0, 0) => {}
                    _ => one += 1,
                }
            }
        }
        println!(
            "{n} texels: {facing} facing visible pairs, {both} covered both ways, {one} one way"
        );
        assert!(facing > 10_000, "{facing}");
        assert!(
            both as f64 >= 0.97 * facing as f64,
            "{both} of {facing} ({one} one way)"
        );
        assert!(
            one as f64 <= 0.01 * facing as f64,
            "{one} of {facing} one way"
        );
    }

    /// Stopping the rays at the first disagreement answers the refinement's question — is
    /// the pair partly visible? — exactly as all the rays do: on every node pair of the maze
    /// at 32² up to depth 6 (where the partitions make many pairs partly visible), 0.5 where
    /// the full fraction lies strictly between 0 and 1, the full fraction (0 or 1) elsewhere.
    #[test]
    fn early_stop_keeps_the_partial_visibility_verdict() {
        let scene = crate::scene::maze::maze(32);
        let (patches, tree, kernels) = texel_tree(&scene);
        // Nodes of the first six levels (parents precede children).
        let mut level = vec![0u32];
        let mut nodes = vec![0u32];
        for _ in 0..6 {
            level = (level.iter())
                .flat_map(|&n| {
                    let node = &tree.nodes[n as usize];
                    if node.is_leaf() {
                        vec![]
                    } else {
                        node.children.to_vec()
                    }
                })
                .collect();
            nodes.extend(&level);
        }
        let (mut partial, mut whole) = (0, 0);
        for &r in &nodes {
            for &s in &nodes {
                let full = block_visibility(&patches, &tree, &kernels, (r, s), 8, false);
                let early = block_visibility(&patches, &tree, &kernels, (r, s), 8, true);
                if full > 0.0 && full < 1.0 {
                    assert_eq!(early, 0.5, "pair ({r}, {s}): fraction {full}");
                    partial += 1;
                } else {
                    assert_eq!(early, full, "pair ({r}, {s})");
                    whole += 1;
                }
            }
        }
        println!("{partial} partly visible pairs, {whole} wholly (in)visible");
        assert!(partial > 100 && whole > 100, "{partial} / {whole}");
    }
}
