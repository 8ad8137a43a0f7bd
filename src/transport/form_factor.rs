//! Diffuse form factors between small surface patches (texels or clusters of texels).
//!
//! `F_ij` is the fraction of the power leaving patch `i` that arrives at patch `j`, so the
//! irradiance gathered by `i` is `E_i = Σ_j F_ij B_j` (radiosity `B` in W/m²) and reciprocity
//! reads `A_i F_ij = A_j F_ji`.
//!
//! # Near-singular pairs
//! The point-to-point kernel `cosθ_i cosθ_j A_j / (π r²)` diverges as `r → 0`, which happens for
//! neighbouring texels across a concave crease. We use the point-to-disk form factor of Wallace
//! et al. (1989), `cosθ_i cosθ_j A_j / (π r² + A_j)`, which is exact for a receiver point on the
//! axis of a disk of area `A_j` and bounded by 1, with the disk area replaced by the mean
//! `(A_i + A_j)/2` so that `A_i F_ij = A_j F_ji` holds exactly (reciprocity) — the common
//! denominator makes `F_ij / A_j` symmetric. For pairs closer than a few patch sizes, both patches
//! are additionally subdivided into `SUB × SUB` sub-patches (`2·SUB` per side for direct
//! neighbours) on their tangent squares and the sub-pair factors averaged (see
//! [`unoccluded_form_factor`]); this keeps the row sums of a
//! closed box within 2% of 1 (tested).

use glam::Vec3;

/// Sub-patches per axis used for near pairs.
const SUB: usize = 4;

/// A patch as seen by the form-factor kernel.
#[derive(Clone, Copy, Debug)]
pub struct FfPatch {
    /// Centroid, metres.
    pub position_m: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// Area, m².
    pub area_m2: f32,
}

#[inline]
fn point_kernel(pi: Vec3, ni: Vec3, pj: Vec3, nj: Vec3, denom_area: f32) -> f32 {
    let d = pj - pi;
    let r2 = d.length_squared();
    if r2 <= 0.0 {
        return 0.0;
    }
    let r = r2.sqrt();
    let ci = ni.dot(d) / r;
    let cj = -nj.dot(d) / r;
    if ci <= 0.0 || cj <= 0.0 {
        return 0.0;
    }
    ci * cj / (std::f32::consts::PI * r2 + denom_area)
}

/// Point-to-disk form factor per unit sender area (m⁻²) from a receiving point (`i`'s centre and
/// normal) to the disk of patch `j`: `cosθ_i cosθ_j / (π r² + A_j)`, no subdivision. Used for
/// a texel seeing a whole cluster, where `j` is large and the pair is not singular.
#[inline]
pub fn point_to_disk(i: &FfPatch, j: &FfPatch) -> f32 {
    point_kernel(i.position_m, i.normal, j.position_m, j.normal, j.area_m2)
}

/// Two unit vectors spanning the plane orthogonal to `n`.
#[inline]
pub fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let a = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let t1 = n.cross(a).normalize();
    let t2 = n.cross(t1);
    (t1, t2)
}

/// The symmetric part `c_ij = F_ij / A_j` (m⁻²) of the unoccluded form factor, so that
/// `F_ij = c_ij A_j` and `F_ji = c_ij A_i`. Zero when the patches face away from each other.
pub fn unoccluded_form_factor(i: &FfPatch, j: &FfPatch) -> f32 {
    let mean_area = 0.5 * (i.area_m2 + j.area_m2);
    let d2 = (j.position_m - i.position_m).length_squared();
    // Far pair: one point-to-disk evaluation.
    if d2 > 16.0 * i.area_m2.max(j.area_m2) {
        return point_kernel(i.position_m, i.normal, j.position_m, j.normal, mean_area);
    }
    let si = i.area_m2.sqrt();
    let sj = j.area_m2.sqrt();
    // Exact early-out: a sub-patch point of j lies within sj/√2 of j's centre, and i's sub-patch
    // offsets are orthogonal to n_i, so n_i·(p_j' − p_i') ≤ n_i·d + sj/√2 for every sub-pair
    // (and likewise for j). When either bound is ≤ 0 every sub-pair faces away: F = 0.
    let d = j.position_m - i.position_m;
    if i.normal.dot(d) + std::f32::consts::FRAC_1_SQRT_2 * sj <= 0.0
        || -j.normal.dot(d) + std::f32::consts::FRAC_1_SQRT_2 * si <= 0.0
    {
        return 0.0;
    }
    // Near pair: subdivide both patches (as squares in their tangent planes); neighbours
    // (closer than ~1.5 patch sizes) twice as finely.
    let sub = if d2 < 2.25 * i.area_m2.max(j.area_m2) {
        2 * SUB
    } else {
        SUB
    };
    let (ti1, ti2) = tangent_frame(i.normal);
    let (tj1, tj2) = tangent_frame(j.normal);
    let sub_area = mean_area / (sub * sub) as f32;
    let mut sum = 0.0f32;
    for a in 0..sub * sub {
        let (ua, va) = (
            ((a % sub) as f32 + 0.5) / sub as f32 - 0.5,
            ((a / sub) as f32 + 0.5) / sub as f32 - 0.5,
        );
        let pi = i.position_m + (ti1 * ua + ti2 * va) * si;
        for b in 0..sub * sub {
            let (ub, vb) = (
                ((b % sub) as f32 + 0.5) / sub as f32 - 0.5,
                ((b / sub) as f32 + 0.5) / sub as f32 - 0.5,
            );
            let pj = j.position_m + (tj1 * ub + tj2 * vb) * sj;
            sum += point_kernel(pi, i.normal, pj, j.normal, sub_area);
        }
    }
    sum / (sub * sub * sub * sub) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Patches of an axis-aligned rectangle split into `n × n` cells.
    fn grid(origin: Vec3, e1: Vec3, e2: Vec3, normal: Vec3, n: usize) -> Vec<FfPatch> {
        let area = e1.length() * e2.length() / (n * n) as f32;
        let mut v = Vec::new();
        for y in 0..n {
            for x in 0..n {
                v.push(FfPatch {
                    position_m: origin
                        + e1 * ((x as f32 + 0.5) / n as f32)
                        + e2 * ((y as f32 + 0.5) / n as f32),
                    normal,
                    area_m2: area,
                });
            }
        }
        v
    }

    /// Area-weighted form factor from surface `a` to surface `b`.
    fn surface_ff(a: &[FfPatch], b: &[FfPatch]) -> f64 {
        let total_a: f64 = a.iter().map(|p| p.area_m2 as f64).sum();
        let mut s = 0.0f64;
        for pi in a {
            for pj in b {
                s += pi.area_m2 as f64 * (unoccluded_form_factor(pi, pj) * pj.area_m2) as f64;
            }
        }
        s / total_a
    }

    #[test]
    fn parallel_coaxial_squares_match_closed_form() {
        // Two unit squares, distance 1 apart: F = 0.19982 (Howell's catalogue, C-11).
        let x = 1.0f64;
        let y = 1.0f64;
        let (xx, yy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
        let exact = 2.0 / (std::f64::consts::PI * x * y)
            * ((xx * xx * yy * yy / (1.0 + x * x + y * y)).sqrt().ln()
                + x * yy * (x / yy).atan()
                + y * xx * (y / xx).atan()
                - x * x.atan()
                - y * y.atan());
        let a = grid(Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, 16);
        let b = grid(Vec3::Z, Vec3::X, Vec3::Y, -Vec3::Z, 16);
        let f = surface_ff(&a, &b);
        assert!((f - exact).abs() < 0.02 * exact, "{f} vs {exact}");
    }

    #[test]
    fn perpendicular_plates_with_common_edge_match_closed_form() {
        // Two unit squares meeting at a right angle along a common edge: F = 0.20004.
        let (h, w) = (1.0f64, 1.0f64);
        let hw = h * h + w * w;
        let exact = (1.0 / (std::f64::consts::PI * w))
            * (w * (1.0 / w).atan() + h * (1.0 / h).atan() - hw.sqrt() * (1.0 / hw.sqrt()).atan()
                + 0.25
                    * ((1.0 + w * w) * (1.0 + h * h) / (1.0 + hw)
                        * (w * w * (1.0 + hw) / ((1.0 + w * w) * hw)).powf(w * w)
                        * (h * h * (1.0 + hw) / ((1.0 + h * h) * hw)).powf(h * h))
                    .ln());
        let floor = grid(Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, 24);
        let wall = grid(Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::Y, 24);
        let f = surface_ff(&floor, &wall);
        assert!((f - exact).abs() < 0.02 * exact, "{f} vs {exact}");
    }

    #[test]
    fn reciprocity_holds_for_unequal_patches() {
        let i = FfPatch {
            position_m: Vec3::ZERO,
            normal: Vec3::Z,
            area_m2: 0.01,
        };
        let j = FfPatch {
            position_m: Vec3::new(0.3, 0.1, 0.5),
            normal: Vec3::new(-0.2, 0.0, -1.0).normalize(),
            area_m2: 0.04,
        };
        let c_ij = unoccluded_form_factor(&i, &j);
        let c_ji = unoccluded_form_factor(&j, &i);
        let (f_ij, f_ji) = (c_ij * j.area_m2, c_ji * i.area_m2);
        assert!(c_ij > 0.0);
        assert!((i.area_m2 * f_ij - j.area_m2 * f_ji).abs() < 1e-6 * i.area_m2 * f_ij);
    }

    #[test]
    fn closed_cube_rows_sum_to_one() {
        let n = 12;
        let faces = [
            (Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y, -Vec3::Z),
            (Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, Vec3::Z, -Vec3::Y),
            (Vec3::ZERO, Vec3::Y, Vec3::Z, Vec3::X),
            (Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X),
        ];
        let patches: Vec<FfPatch> = faces
            .iter()
            .flat_map(|&(o, e1, e2, nrm)| grid(o, e1, e2, nrm, n))
            .collect();
        for (k, pi) in patches.iter().enumerate() {
            let sum: f32 = patches
                .iter()
                .map(|pj| unoccluded_form_factor(pi, pj) * pj.area_m2)
                .sum();
            assert!((sum - 1.0).abs() < 0.02, "patch {k}: row sum {sum}");
        }
    }
}
