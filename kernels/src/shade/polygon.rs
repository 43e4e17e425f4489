//! The cosine-weighted solid angle (form factor) of a polygon above the horizon: the analytic
//! core of linearly transformed cosines (Heitz, Dupuy, Hill, Neubelt 2016, "Real-Time
//! Polygonal-Light Shading with Linearly Transformed Cosines").
//!
//! For a polygon with corners `pᵢ` (relative to the shading point, local frame with z = normal),
//! `∫_P max(0, cos θ)/π dω = 1/(2π) Σ_edges θᵢ · (p̂ᵢ × p̂ᵢ₊₁)·z / |p̂ᵢ × p̂ᵢ₊₁|` after clipping the
//! polygon to the upper hemisphere (Lambert 1760; Arvo 1995). The edge angle is taken as
//! `atan2(|a × b|, a·b)`, accurate for both tiny and near-antipodal edges (the `acos` form loses
//! all digits for short edges), and `θ/sin θ → 1` as the edge vanishes, so no NaN can appear.

use crate::trig;
use core::f32::consts::PI;
use glam::Vec3;

/// Most corners a polygon here can have: a quad clipped against two planes (the surface's
/// horizon, then the horizon of the LTC's cosine space) gains at most one corner per plane.
pub const MAX_CORNERS: usize = 6;

/// A convex polygon of up to [`MAX_CORNERS`] corners.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Polygon {
    /// Corners in order; only the first `count` are meaningful.
    pub corners: [Vec3; MAX_CORNERS],
    /// Number of corners, 0 or 3..=6.
    pub count: u32,
}

impl Polygon {
    /// The quad `q` (corners in order).
    pub fn quad(q: [Vec3; 4]) -> Self {
        Self { corners: [q[0], q[1], q[2], q[3], Vec3::ZERO, Vec3::ZERO], count: 4 }
    }

    /// Every corner mapped by `f` (a linear map keeps the polygon convex and its order).
    // Inlined, as `form_factor_above_horizon`, into the lobes' integrals: as calls they took a
    // tenth of the 20-light grid's CPU shade time.
    #[inline]
    pub fn map(mut self, f: impl Fn(Vec3) -> Vec3) -> Self {
        let mut i = 0usize;
        while i < MAX_CORNERS {
            self.corners[i] = f(self.corners[i]);
            i += 1;
        }
        self
    }

    /// The polygon clipped against the half-space `z ≥ 0` (Sutherland–Hodgman). Corners exactly
    /// on the plane are kept; a polygon entirely below, left with < 3 corners, or with no corner
    /// above the plane (lying in it: a light whose plane holds the shading point) becomes empty —
    /// the last so that its zero solid angle is exact rather than the rounding residue of its
    /// edge angles, which differs between backends' `atan2`.
    /// A polygon already at [`MAX_CORNERS`] is clipped with its last crossing dropped (never
    /// happens for a quad clipped twice).
    pub fn clip_to_horizon(&self) -> Self {
        let n = self.count as usize;
        let mut out = Polygon { corners: [Vec3::ZERO; MAX_CORNERS], count: 0 };
        let mut k = 0usize;
        let mut above = false;
        let mut i = 0usize;
        while i < n && n <= MAX_CORNERS {
            let a = self.corners[i];
            let b = self.corners[(i + 1) % n];
            above |= a.z > 0.0;
            let a_in = a.z >= 0.0;
            let b_in = b.z >= 0.0;
            if a_in && k < MAX_CORNERS {
                out.corners[k] = a;
                k += 1;
            }
            if a_in != b_in && k < MAX_CORNERS {
                // Where edge a→b crosses z = 0; a.z ≠ b.z because exactly one is < 0.
                let t = a.z / (a.z - b.z);
                let mut crossing = a + t * (b - a);
                crossing.z = 0.0;
                out.corners[k] = crossing;
                k += 1;
            }
            i += 1;
        }
        out.count = if k >= 3 && above { k as u32 } else { 0 };
        out
    }

    /// The form factor `∫ max(0, cos θ)/π dω` of the polygon (corners relative to the shading
    /// point, z = normal) after clipping it to `z ≥ 0`, in `[0, 1]`, for either winding. 0 for a
    /// polygon entirely below the horizon, lying in it, or seen edge-on.
    pub fn form_factor(&self) -> f32 {
        self.clip_to_horizon().form_factor_above_horizon()
    }

    /// [`Polygon::form_factor`] of a polygon that [`Polygon::clip_to_horizon`] returned, without
    /// clipping it again (which would change nothing): for callers that integrate the clipped
    /// polygon more than once.
    #[inline]
    pub fn form_factor_above_horizon(&self) -> f32 {
        let sum = edge_sum(&self.corners, self.count as usize);
        let form_factor = (sum / (2.0 * PI)).abs();
        if form_factor.is_finite() {
            form_factor.min(1.0)
        } else {
            0.0
        }
    }
}

/// Σᵢ [`edge_integral`]`(ĉᵢ, ĉᵢ₊₁)` over the first `count` (≤ [`MAX_CORNERS`]) of `corners`,
/// the last edge closing back to the first corner, `ĉ` each corner normalized (or zero): the sum
/// of [`Polygon::form_factor`]. This portable loop is what SPIR-V runs; x86-64 runs
/// [`super::edge_lanes::edge_sum`], four edges at a time and the same bits.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
pub fn portable_edge_sum(corners: &[Vec3; MAX_CORNERS], count: usize) -> f32 {
    let n = count.min(MAX_CORNERS);
    let mut sum = 0.0f32;
    // Each corner's direction is normalized once and carried to the next edge as its start.
    let first = corners[0].normalize_or_zero();
    let mut a = first;
    let mut i = 0usize;
    while i < n {
        let b = if i + 1 < n { corners[i + 1].normalize_or_zero() } else { first };
        sum += edge_integral(a, b);
        a = b;
        i += 1;
    }
    sum
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::edge_lanes::edge_sum;
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
use portable_edge_sum as edge_sum;

/// The contribution `θ · (â × b̂)·z / |â × b̂|` of the edge from direction `a` to `b` (unit).
/// Always inlined: each edge is a chain of a square root, two divisions and the `atan2`
/// polynomial, and only inlined into `portable_edge_sum`'s loop can a processor overlap one
/// edge's chain with the next (measured on the CPU before the lanes: a quad's form factor 1.7×
/// faster, the same bits).
#[inline(always)]
pub fn edge_integral(a: Vec3, b: Vec3) -> f32 {
    let cross = a.cross(b);
    let sin_theta = cross.length();
    let cos_theta = a.dot(b);
    let theta = trig::atan2(sin_theta, cos_theta);
    // θ / sin θ, with its limit 1 for a vanishing edge (sin θ = 0 with θ = 0).
    let theta_over_sin = if sin_theta > 1.0e-7 { theta / sin_theta } else { 1.0 };
    cross.z * theta_over_sin
}

/// The form factor of the quad with corners `q` (see [`Polygon::form_factor`]).
pub fn quad_form_factor(q: [Vec3; 4]) -> f32 {
    Polygon::quad(q).form_factor()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// `∫ f(l) dω` over the parallelogram `corner + s·u + t·v` seen from the origin, by the
    /// midpoint rule on an `n × n` grid over its plane, in f64: the shade tests' brute-force
    /// reference for integrals over a light.
    pub(crate) fn solid_angle_integral(corner: Vec3, u: Vec3, v: Vec3, n: u32, f: impl Fn(glam::DVec3) -> f64) -> f64 {
        let (c, u, v) = (corner.as_dvec3(), u.as_dvec3(), v.as_dvec3());
        let area_normal = u.cross(v);
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                let p = c + u * ((f64::from(i) + 0.5) / f64::from(n)) + v * ((f64::from(j) + 0.5) / f64::from(n));
                let d2 = p.length_squared();
                let l = p / d2.sqrt();
                sum += f(l) * area_normal.dot(l).abs() / d2;
            }
        }
        sum / f64::from(n * n)
    }

    /// The form factor of the quad `corner + s·u + t·v` from the origin, numerically.
    fn reference(corner: Vec3, u: Vec3, v: Vec3) -> f64 {
        solid_angle_integral(corner, u, v, 1000, |l| l.z.max(0.0) / std::f64::consts::PI)
    }

    #[test]
    fn matches_numerical_integration_above_and_across_the_horizon() {
        let cases = [
            (Vec3::new(-0.5, -0.5, 1.0), Vec3::X, Vec3::Y),      // centred overhead
            (Vec3::new(0.5, -0.3, 0.2), Vec3::X * 2.0, Vec3::Y), // low, off to the side
            (Vec3::new(-0.5, 1.0, -0.5), Vec3::X, Vec3::Z),      // vertical, crossing the horizon
            (Vec3::new(-1.0, 2.0, -1.0), Vec3::X * 2.0, Vec3::Z * 0.5), // mostly below the horizon
        ];
        for (corner, u, v) in cases {
            let q = [corner, corner + u, corner + u + v, corner + v];
            let expected = reference(corner, u, v);
            let got = f64::from(quad_form_factor(q));
            assert!((got - expected).abs() <= 2e-3 * expected.max(1e-3), "{corner}: {got} vs {expected}");
        }
    }

    /// The x86-64 lanes sum the edges bit for bit as the portable loop does: random polygons of
    /// 0–6 corners at random scales (up to 10⁶ and down to 10⁻⁶) with some corners repeated,
    /// zero, opposite, on the horizon, huge or non-finite.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[test]
    fn lanes_match_the_portable_edge_sum() {
        use crate::hash::{pcg3d, unit_float};
        let mut nonzero = 0;
        for k in 0..200_000u32 {
            let h = pcg3d(glam::UVec3::new(k, 0, 11));
            let count = (h.x % 7) as usize;
            let scale = 10f32.powf(unit_float(h.y) * 12.0 - 6.0);
            let mut corners = [Vec3::ZERO; MAX_CORNERS];
            for (i, corner) in corners.iter_mut().enumerate() {
                let r = pcg3d(glam::UVec3::new(k, i as u32 + 1, 11));
                let random = Vec3::new(unit_float(r.x), unit_float(r.y), unit_float(r.z)) * 2.0 - Vec3::ONE;
                *corner = match r.x % 23 {
                    0 => Vec3::ZERO,
                    1 => Vec3::new(random.x, random.y, 0.0),
                    2 => Vec3::splat(f32::NAN),
                    3 => Vec3::new(f32::INFINITY, 1.0, 1.0),
                    4 => Vec3::splat(3.0e38),
                    _ => random * scale,
                };
            }
            match h.z % 5 {
                0 => corners[1] = corners[0],
                1 => corners[2] = -corners[0],
                _ => {}
            }
            let portable = portable_edge_sum(&corners, count);
            let lanes = super::super::edge_lanes::edge_sum(&corners, count);
            assert_eq!(lanes.to_bits(), portable.to_bits(), "{count} corners {corners:?}: {lanes} vs {portable}");
            nonzero += usize::from(portable != 0.0);
        }
        assert!(nonzero > 100_000, "{nonzero}");
    }

    #[test]
    fn limits_and_hard_cases_are_finite() {
        // A huge quad overhead covers the whole hemisphere: form factor → 1.
        let big = 1.0e4;
        let q = [
            Vec3::new(-big, -big, 1.0),
            Vec3::new(big, -big, 1.0),
            Vec3::new(big, big, 1.0),
            Vec3::new(-big, big, 1.0),
        ];
        assert!((quad_form_factor(q) - 1.0).abs() < 1e-3);
        // Entirely below, edge-on, degenerate, tiny (1e-6 sr), on the shading plane.
        let below = q.map(|p| Vec3::new(p.x, p.y, -1.0));
        assert_eq!(quad_form_factor(below), 0.0);
        let edge_on =
            [Vec3::new(0.0, -1.0, 1.0), Vec3::new(0.0, 1.0, 1.0), Vec3::new(0.0, 1.0, 2.0), Vec3::new(0.0, -1.0, 2.0)];
        assert!(quad_form_factor(edge_on).abs() < 1e-6);
        assert_eq!(quad_form_factor([Vec3::Z; 4]), 0.0);
        let s = 5.0e-4;
        let tiny = [Vec3::new(0.0, 0.0, 1.0), Vec3::new(s, 0.0, 1.0), Vec3::new(s, s, 1.0), Vec3::new(0.0, s, 1.0)];
        let expected = s * s / core::f32::consts::PI; // area·cos·cos/(π d²) with d = 1
        assert!((quad_form_factor(tiny) - expected).abs() < 0.02 * expected, "{}", quad_form_factor(tiny));
        let on_plane =
            [Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(2.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)];
        assert_eq!(quad_form_factor(on_plane), 0.0);
        // In the plane at irregular corners, whose edge angles do not cancel exactly in f32.
        let mut irregular = 0;
        for k in 1..200 {
            let c = |i: u32| {
                let h = crate::hash::pcg3d(glam::UVec3::new(k, i, 7));
                Vec3::new(crate::hash::unit_float(h.x) * 4.0 - 2.0, crate::hash::unit_float(h.y) * 4.0 + 0.1, 0.0)
            };
            let quad = [c(0), c(1), c(2), c(3)];
            let angles: f32 = (0..4).map(|i| edge_integral(quad[i].normalize(), quad[(i + 1) % 4].normalize())).sum();
            irregular += usize::from(angles != 0.0);
            assert_eq!(quad_form_factor(quad), 0.0, "{quad:?}");
        }
        assert!(irregular > 0, "some quads' edge angles leave a rounding residue");
    }
}
