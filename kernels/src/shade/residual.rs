//! A quadrature correction of the LTC lobe's integral over a light towards the GGX lobe the table
//! was fitted to: `U_S = ∫_P D_LTC + ∫_P (G − D_LTC)`, the first term exact (the polygon form
//! factors of [`super::ltc`]), the second — the residual — by a fixed 9-point rule on each
//! triangle of the light. Off by default (`ShadeParams::analytic_residual`); `raywave render
//! --analytic-residual` turns it on.
//!
//! Why: one LTC mixture per table cell fits the GGX lobe well where its mass is (median relative
//! L1 error 0.3–3.5 % per roughness row), but not in the far tails, so a light that catches only
//! a tail gets a `U_S` off by 30–170 % of its (small) value, and at grazing views neighbouring
//! table cells in different fit basins leave errors up to 60 % even for lights near the mirror
//! direction. The residual `G − D_LTC` is smooth wherever the lobe's peak is not on the light, and
//! there a low-order rule integrates it well. Measured against the f64 reference
//! (`tests/analytic_lighting.rs`, roughness ≥ 0.1): on its 120-light grid the cases beyond 5 % of
//! the reference fall from 34 to 2 (both at 89.9°, 8.8 % and 10.0 %; the largest error from 173 %
//! to 10 %, up to 80° from 173 % to 3.2 %); on 357 random lights from 184 to 3, none made worse. It
//! costs the CPU shade stage 1.6–1.9× its time (Cornell box, `shade/cpu-residual` bench).
//!
//! When the rule may be trusted is measured, not guessed: the same nodes integrate `D_LTC`, whose
//! exact integral is known. If that quadrature is within [`RESOLVED_TOLERANCE`] of the exact form
//! factor the nodes resolve the lobe's shape over this light and the residual is added in full;
//! beyond twice the tolerance (a peak on or near the light) it is dropped; in between it fades
//! linearly, so `U` stays continuous across the image.
//!
//! The rule: the light clipped to the horizon is cut into triangles around its centre direction;
//! each triangle's chords `p(s, t) = A + s(B − A) + t(C − A)` project to the sphere with the
//! solid-angle Jacobian `|p·((B − A) × (C − A))|/|p|³`, integrated by the collapsed (Duffy) product
//! of 3-point Gauss–Legendre rules (exact for polynomials of degree 5 in `s` and `t`). A 3-point
//! rule per triangle was tried and let wrong corrections through (an albedo-relative error of
//! 37 %).
//!
//! Where the check is fooled: the two grid cases left beyond 5 % (89.9° views, lights around the
//! mirror direction) are lights over which the nodes integrate `D_LTC` well but not `G` — against a
//! brute-force 3000² integration over the light, the nodes' `∫ G` is 11 % high at roughness 0.5 and
//! 68 % at 0.35, their `∫ D_LTC` within 0.2 % and 3.2 % of exact (so the residual is trusted in
//! full and in part). At such views the GGX lobe's shape departs furthest from the LTC's, and the
//! LTC's quadrature stops vouching for the GGX lobe's. The lobe varies there on a scale far below
//! the fan's triangles: splitting every triangle into quarters `k` times, `∫ G` is still 5.4 % and
//! 1.0 % high at `k = 3` (64× the nodes) and 1.1 % and 0.2 % at `k = 4`, while one split moves it
//! the wrong way (68 → 82 % and 11 → 22 % high). Tried and dropped (measured on the same grid):
//! checking each fan triangle against its own exact LTC integral and splitting it into quarters,
//! twice, where it misses — the overhead light at 89.9° and roughness 0.1 got worse (1.7 % → 58 %:
//! trusted and dropped pieces of one light mixed); choosing per piece between this control variate
//! and the direct `∫ G − exact ∫ D_LTC` by their change under splitting (adaptive quadrature's
//! error estimate) — it fixes that overhead light and takes the roughness-0.35 mirror light from
//! 8 % to 6 % (with the earlier 2.6·10⁵-sample reference), but the roughness-0.5 one passes the
//! global check and never reaches it, and one random light got worse; forcing it at views beyond
//! 80° — the mirror lights got worse (26 % and 45 %); centring the fan on the mirror direction —
//! 23 % and 25 %.

// `!(x > 0.0)` sends NaN down the "nothing to add" branch on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::ltc::LtcLobe;
use super::polygon::Polygon;
use crate::sampling::warp::{ggx_d, GGX_MIN_ALPHA};
use glam::{Vec2, Vec3};

/// Relative difference between the nodes' integral of the LTC lobe and its exact form factor up to
/// which the residual is trusted in full (it fades out up to twice this). 2 %, measured on the 120
/// lights of `tests/analytic_lighting.rs` at roughness ≥ 0.1 (with its earlier 2.6·10⁵-sample
/// reference): 5 % let a grazing correction overshoot (64 % off the reference), 1 % dropped
/// corrections that helped (6 cases beyond 5 % instead of 2).
pub const RESOLVED_TOLERANCE: f32 = 0.02;

/// `cos θ` of the most grazing view the table was fitted at (θ = 1.57,
/// `raywave_host::ltc_fit::MAX_THETA`); views beyond are evaluated there, as the lookup does.
pub const MIN_COS_VIEW: f32 = 7.963e-4;

/// The isotropic GGX lobe `f·cos θ_l` (F = 1, height-correlated Smith masking-shadowing) the LTC
/// table stands for, at one shading point, in the LTC frame (z = normal, view in the `+x` half).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GgxLobe {
    /// `α = max(roughness², GGX_MIN_ALPHA)` (the table's fit clamps to the same 10⁻⁴).
    alpha: f32,
    /// Unit view direction, `z ≥ MIN_COS_VIEW`.
    view: Vec3,
    /// Smith `Λ` of the view.
    lambda_view: f32,
}

impl GgxLobe {
    /// The lobe for perceptual `roughness` (clamped to `[0, 1]`) seen from `cos_theta_v = n·v`
    /// (clamped to `[MIN_COS_VIEW, 1]`), the view in the frame's `+x` half as [`super::ltc::ShadingFrame`]
    /// puts it.
    pub fn new(roughness: f32, cos_theta_v: f32) -> Self {
        let r = if roughness > 0.0 { roughness.min(1.0) } else { 0.0 };
        let alpha = (r * r).max(GGX_MIN_ALPHA);
        let z = if cos_theta_v > MIN_COS_VIEW { cos_theta_v.min(1.0) } else { MIN_COS_VIEW };
        let view = Vec3::new((1.0 - z * z).max(0.0).sqrt(), 0.0, z);
        Self { alpha, view, lambda_view: smith_lambda(alpha * alpha, z) }
    }

    /// `f(v, l)·cos θ_l` (sr⁻¹) at the unit local direction `l`: `D(h)·G₂/(4 cos θ_v)`, 0 at or
    /// below the horizon. Integrates to the lobe's albedo (the table's magnitude).
    pub fn eval(&self, l: Vec3) -> f32 {
        if !(l.z > 0.0) {
            return 0.0;
        }
        let h = (self.view + l).normalize_or_zero();
        let d = ggx_d(h, Vec2::splat(self.alpha));
        let g2 = 1.0 / (1.0 + self.lambda_view + smith_lambda(self.alpha * self.alpha, l.z));
        d * g2 / (4.0 * self.view.z)
    }
}

/// Smith's `Λ = (√(1 + α² tan²θ) − 1)/2` for `cos θ = z ∈ (0, 1]`, as `ε/(2(1 + √(1 + ε)))`
/// with `ε = α² tan²θ` (no cancellation near the normal).
fn smith_lambda(alpha2: f32, z: f32) -> f32 {
    let z2 = z * z;
    // z2 floored: a direction a hair above the horizon (z² underflowing) gets a huge Λ, not ∞/∞.
    let eps = alpha2 * (1.0 - z2).max(0.0) / z2.max(1.0e-30);
    eps / (2.0 * (1.0 + (1.0 + eps).sqrt()))
}

/// Node `i` (0, 1, 2) of the 3-point Gauss–Legendre rule on `[0, 1]` and its weight.
fn gauss3(i: u32) -> (f32, f32) {
    // Nodes 1/2 ∓ √(3/5)/2, weights 5/18, 8/18, 5/18.
    const OFFSET: f32 = 0.387_298_35;
    if i == 0 {
        (0.5 - OFFSET, 5.0 / 18.0)
    } else if i == 1 {
        (0.5, 8.0 / 18.0)
    } else {
        (0.5 + OFFSET, 5.0 / 18.0)
    }
}

/// `(∫ G, ∫ D_LTC)` over the spherical triangle with unit corners `a`, `b`, `c` by the collapsed
/// 3 × 3 Gauss rule (module documentation).
fn triangle_integrals(a: Vec3, b: Vec3, c: Vec3, ltc: &LtcLobe, ggx: &GgxLobe) -> (f32, f32) {
    let (ab, ac) = (b - a, c - a);
    let normal = ab.cross(ac);
    let (mut sum_ggx, mut sum_ltc) = (0.0f32, 0.0f32);
    let mut i = 0u32;
    while i < 3 {
        let (s, ws) = gauss3(i);
        let mut j = 0u32;
        while j < 3 {
            let (x, wt) = gauss3(j);
            let p = a + ab * s + ac * (x * (1.0 - s));
            let length = p.length();
            if length > 0.0 {
                let l = p / length;
                let weight = ws * wt * (1.0 - s) * p.dot(normal).abs() / (length * length * length);
                sum_ggx += weight * ggx.eval(l);
                sum_ltc += weight * ltc.pdf(l);
            }
            j += 1;
        }
        i += 1;
    }
    (sum_ggx, sum_ltc)
}

/// The correction to add to the LTC lobe's integral `ltc_integral` (its exact form factor over
/// `clipped`, the light already clipped to the horizon, local corners) so that the sum
/// approximates the integral of the normalized GGX lobe `ggx.eval/magnitude` over the light;
/// faded out where the nodes do not resolve the lobe (module documentation). 0 for an empty
/// polygon, a lobe without magnitude or a non-finite result.
pub fn residual(ltc: &LtcLobe, ggx: &GgxLobe, clipped: &Polygon, ltc_integral: f32) -> f32 {
    if clipped.count < 3 || !(ltc_integral > 0.0) || !(ltc.magnitude > 0.0) {
        return 0.0;
    }
    let (sum_ggx, sum_ltc) = polygon_integrals(clipped, ltc, ggx);
    let miss = (sum_ltc - ltc_integral).abs() / ltc_integral;
    let trust = (2.0 - miss / RESOLVED_TOLERANCE).clamp(0.0, 1.0);
    let correction = trust * (sum_ggx / ltc.magnitude - sum_ltc);
    if correction.is_finite() {
        correction
    } else {
        0.0
    }
}

/// `(∫ G, ∫ D_LTC)` over the polygon (at least 3 corners) by the fan of triangles around its
/// centre direction.
fn polygon_integrals(clipped: &Polygon, ltc: &LtcLobe, ggx: &GgxLobe) -> (f32, f32) {
    let n = clipped.count as usize;
    let unit = clipped.map(|c| c.normalize_or_zero());
    let mut centre = Vec3::ZERO;
    let mut i = 0usize;
    while i < n {
        centre += unit.corners[i];
        i += 1;
    }
    let centre = centre.normalize_or_zero();
    let (mut sum_ggx, mut sum_ltc) = (0.0f32, 0.0f32);
    let mut i = 0usize;
    while i < n {
        let (g, d) = triangle_integrals(centre, unit.corners[i], unit.corners[(i + 1) % n], ltc, ggx);
        sum_ggx += g;
        sum_ltc += d;
        i += 1;
    }
    (sum_ggx, sum_ltc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shade::ltc::{local_quad, lookup, specular_form_factor, specular_form_factor_corrected, ShadingFrame};
    use glam::Vec4;
    use raywave_shared::ltc_table::packed_entries;
    use std::vec::Vec;

    #[test]
    fn hard_cases_stay_finite_and_in_range() {
        let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
        let quads = [
            // Overhead, tiny (~1e-6 sr), hemisphere-sized, crossing the horizon, in the plane, below.
            (Vec3::new(-0.5, -0.5, 1.0), Vec3::X, Vec3::Y),
            (Vec3::new(0.3, 0.2, 1.0), Vec3::X * 1e-3, Vec3::Y * 1e-3),
            (Vec3::new(-1e4, -1e4, 1.0), Vec3::X * 2e4, Vec3::Y * 2e4),
            (Vec3::new(-1.0, -0.6, -0.4), Vec3::Y * 1.2, Vec3::Z),
            (Vec3::new(1.0, 0.0, 0.0), Vec3::X, Vec3::Y),
            (Vec3::new(-0.5, -0.5, -1.0), Vec3::X, Vec3::Y),
            // Axis-aligned and far from the origin.
            (Vec3::new(-3e4, 2e4, 5e4), Vec3::X * 10.0, Vec3::Z * 10.0),
        ];
        // A direction a hair above the horizon, whose cos² underflows.
        for roughness in [0.0f32, 0.5, 1.0] {
            let f = GgxLobe::new(roughness, 0.5).eval(Vec3::new(1.0, 0.0, 1.0e-20));
            assert!(f.is_finite() && f >= 0.0, "{roughness}: {f}");
        }
        let views = [1.0f32, 0.5, 1e-3, 0.0, -0.2, f32::NAN];
        for roughness in [0.0f32, 0.02, 0.1, 0.5, 1.0, f32::NAN] {
            for cos_v in views {
                let lobe = lookup(&table, roughness, cos_v);
                let ggx = GgxLobe::new(roughness, cos_v);
                let v = Vec3::new((1.0 - cos_v * cos_v).max(0.0).sqrt(), 0.0, cos_v);
                let frame = ShadingFrame::new(Vec3::Z, v);
                for (corner, u, w) in quads {
                    let quad = local_quad(&frame, Vec3::ZERO, corner, u, w);
                    let exact_ltc = specular_form_factor(&lobe, quad);
                    let corrected = specular_form_factor_corrected(&lobe, &ggx, quad);
                    let case = (roughness, cos_v, corner);
                    assert!((0.0..=1.0).contains(&corrected), "{case:?}: {corrected}");
                    if exact_ltc == 0.0 {
                        assert_eq!(corrected, 0.0, "{case:?}: no LTC mass, no residual");
                    }
                }
            }
        }
    }

    #[test]
    fn a_hemisphere_light_still_catches_the_whole_lobe() {
        // Under a hemisphere-sized light the residual is dropped or tiny: the corrected U_S of a
        // rough lobe (which the nodes resolve) stays the LTC's ≈ 1, within 1 %.
        let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
        for (roughness, cos_v) in [(1.0f32, 1.0f32), (0.7, 0.6)] {
            let lobe = lookup(&table, roughness, cos_v);
            let ggx = GgxLobe::new(roughness, cos_v);
            let frame = ShadingFrame::new(Vec3::Z, Vec3::new((1.0 - cos_v * cos_v).sqrt(), 0.0, cos_v));
            let big = local_quad(&frame, Vec3::ZERO, Vec3::new(-1e4, -1e4, 1.0), Vec3::X * 2e4, Vec3::Y * 2e4);
            let u = specular_form_factor_corrected(&lobe, &ggx, big);
            assert!((u - 1.0).abs() < 0.01, "{roughness} {cos_v}: {u}");
        }
    }
}
