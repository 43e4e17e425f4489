//! The cosine-weighted solid angle (form factor) of a polygon above the horizon: the analytic
//! core of linearly transformed cosines (Heitz, Dupuy, Hill, Neubelt 2016, "Real-Time
//! Polygonal-Light Shading with Linearly Transformed Cosines").
//!
//! For a polygon with corners `pᵢ` (relative to the shading point, local frame with z = normal),
//! `∫_P max(0, cos θ)/π dω = 1/(2π) Σ_edges θᵢ · (p̂ᵢ × p̂ᵢ₊₁)·z / |p̂ᵢ × p̂ᵢ₊₁|` after clipping the
//! polygon to the upper hemisphere (Lambert 1760; Arvo 1995). The edge angle is taken as
//! `atan2(|a × b|, a·b)`, accurate for both tiny and near-antipodal edges (the `acos` form loses
//! all digits for short edges), and `θ/sin θ → 1` as the edge vanishes, so no NaN can appear.
//!
//! The cross product `p̂ᵢ × p̂ᵢ₊₁` is formed from the edge, as `p̂ᵢ × (pᵢ₊₁ − pᵢ)/|pᵢ₊₁|` or
//! `p̂ᵢ₊₁ × (pᵢ₊₁ − pᵢ)/|pᵢ|` (equal in real arithmetic), scaled by the farther corner. For a
//! light of size `s` at distance `d` each edge's term is `O(s/d)` while the polygon's sum is
//! `O((s/d)²)`, and the cross product of two nearly equal unit vectors loses `ε` absolutely — a
//! relative error `ε·(d/s)²` in the sum: 7 % for a 1 mm light 1 m away, off axis, its sign and
//! size changed by a backend's multiply-add fusion. The difference of two close corners is exact
//! in `f32` (Sterbenz), so the edge form errs by `ε·|edge|/max(|pᵢ|, |pᵢ₊₁|)` absolutely, at
//! most `2ε` and `ε·s/d` for a distant light: the relative error of the sum is `ε·d/s`, what the
//! corners' own rounding allows.

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
                // Where edge a→b crosses z = 0; a.z ≠ b.z because exactly one is < 0. Stepped
                // from the end nearer the plane (t ≤ ½): from the other, a crossing beside it
                // takes t ≈ 1, whose rounding moves it by ε·|b − a| — all of it where a long edge
                // ends near the shading point (an LTC's `M⁻¹` squeezes a huge light's corners
                // towards its horizon: `U_S` 0.03 for 0.97).
                let (near, far) = if a.z.abs() <= b.z.abs() { (a, b) } else { (b, a) };
                let t = near.z / (near.z - far.z);
                let mut crossing = near + t * (far - near);
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

/// Σᵢ [`edge_integral`] of the edge from corner `i` to corner `i + 1` over the first `count`
/// (≤ [`MAX_CORNERS`]) of `corners`, the last edge closing back to the first corner: the sum of
/// [`Polygon::form_factor`]. This portable loop is what SPIR-V runs; x86-64 runs
/// [`super::edge_lanes::edge_sum`], four edges at a time and the same bits.
#[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
pub fn portable_edge_sum(corners: &[Vec3; MAX_CORNERS], count: usize) -> f32 {
    let n = count.min(MAX_CORNERS);
    let mut sum = 0.0f32;
    // Each corner's direction is found once and carried to the next edge as its start.
    let first = Corner::new(corners[0]);
    let mut a = first;
    let mut i = 0usize;
    while i < n {
        let b = if i + 1 < n { Corner::new(corners[i + 1]) } else { first };
        sum += edge_integral(&a, &b);
        a = b;
        i += 1;
    }
    sum
}

/// A polygon corner relative to the shading point, with its unit direction and the reciprocal
/// of its distance — both zero where the corner is zero or not finite (the direction is glam's
/// `normalize_or_zero`, bit for bit).
#[derive(Copy, Clone)]
pub struct Corner {
    /// The corner, relative to the shading point.
    pub position: Vec3,
    /// Its unit direction, or zero.
    pub unit: Vec3,
    /// `1/|position|`, or 0 where `unit` is zero.
    pub reciprocal_length: f32,
}

impl Corner {
    /// The corner at `position` from the shading point.
    #[inline(always)]
    pub fn new(position: Vec3) -> Self {
        let reciprocal_length = position.length_recip();
        if reciprocal_length.is_finite() && reciprocal_length > 0.0 {
            Self { position, unit: position * reciprocal_length, reciprocal_length }
        } else {
            Self { position, unit: Vec3::ZERO, reciprocal_length: 0.0 }
        }
    }
}

/// `â × b̂` of corners `a`, `b` formed from the edge between them, scaled by the farther one (see
/// the module's note on cancellation): zero where either direction is.
#[inline(always)]
pub fn edge_cross(a: &Corner, b: &Corner) -> Vec3 {
    if !(a.reciprocal_length > 0.0 && b.reciprocal_length > 0.0) {
        return Vec3::ZERO;
    }
    // â × (b − a)/|b| where b is the farther corner, else b̂ × (b − a)/|a|: the nearer corner's
    // direction, the farther one's scale (the lesser reciprocal; neither is NaN).
    let unit = if b.reciprocal_length <= a.reciprocal_length { a.unit } else { b.unit };
    unit.cross((b.position - a.position) * a.reciprocal_length.min(b.reciprocal_length))
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::edge_lanes::edge_sum;
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
use portable_edge_sum as edge_sum;

/// The contribution `θ · (â × b̂)·z / |â × b̂|` of the edge from corner `a` to `b`, with
/// `â × b̂` from [`edge_cross`]. `θ/sin θ` is taken wherever `sin θ` is a normal number — also
/// for a nearly antipodal edge, `θ ≈ π`: a horizon edge passing close by the shading point, whose
/// `±π` a cut-off at `sin θ = 10⁻⁷` dropped — and its limit 1 below. `sin θ = |â × b̂|` squares
/// the cross product's coordinates, which underflow below ~10⁻¹⁹ (10⁻²² with subnormals), so
/// an antipodal edge still loses its `±π` where the shading point is within ~10⁻¹⁹ of the
/// light's plane, relative to the light's size; a vanishing edge loses nothing.
/// Always inlined: each edge is a chain of a square root, two divisions and the `atan2`
/// polynomial, and only inlined into `portable_edge_sum`'s loop can a processor overlap one
/// edge's chain with the next (measured on the CPU before the lanes: a quad's form factor 1.7×
/// faster, the same bits).
#[inline(always)]
pub fn edge_integral(a: &Corner, b: &Corner) -> f32 {
    let cross = edge_cross(a, b);
    let sin_theta = cross.length();
    let cos_theta = a.unit.dot(b.unit);
    let theta = trig::atan2(sin_theta, cos_theta);
    let theta_over_sin = if sin_theta >= f32::MIN_POSITIVE { theta / sin_theta } else { 1.0 };
    cross.z * theta_over_sin
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The form factor of the quad with corners `q`.
    fn quad_form_factor(q: [Vec3; 4]) -> f32 {
        Polygon::quad(q).form_factor()
    }

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
            (Vec3::new(-1.0, 2.0, -1.0), Vec3::X * 2.0, Vec3::Z * 1.25), // mostly below the horizon
            (Vec3::new(0.2, 0.5, -0.25), Vec3::Y, Vec3::new(0.3, 0.0, 1.0)), // a quarter below, slanted
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
            let angles: f32 =
                (0..4).map(|i| edge_integral(&Corner::new(quad[i]), &Corner::new(quad[(i + 1) % 4]))).sum();
            irregular += usize::from(angles != 0.0);
            assert_eq!(quad_form_factor(quad), 0.0, "{quad:?}");
        }
        assert!(irregular > 0, "some quads' edge angles leave a rounding residue");
    }

    /// The form factor (normal +z) of the quad `q` wholly above the horizon (f32 corners relative
    /// to the shading point, taken exactly) by the same edge formula in f64, whose rounding
    /// (`10⁻¹⁶·(d/s)²` relative) is far below the f32 tolerances of the tests using it.
    pub(crate) fn form_factor_f64(q: [Vec3; 4]) -> f64 {
        let q = q.map(|c| c.as_dvec3());
        let sum: f64 = (0..4)
            .map(|i| {
                let (a, b) = (q[i].normalize(), q[(i + 1) % 4].normalize());
                let cross = a.cross(b);
                cross.z * cross.length().atan2(a.dot(b)) / cross.length()
            })
            .sum();
        (sum / (2.0 * std::f64::consts::PI)).abs()
    }

    #[test]
    fn small_lights_off_axis_keep_their_precision() {
        // A square of side s about unit distance away, off axis: each edge's term is O(s) and the
        // sum O(s²·cos θ), so the cross product of two nearly equal unit directions (error ε)
        // left a relative error ε/(s²·cos θ) — 7 % at s = 10⁻³, 17× at s = 10⁻⁴. Formed from the
        // edge it is ε/(s·cos θ), what the corners' rounding allows: within 20 times that.
        for centre in [Vec3::new(0.5, 0.5, 0.7), Vec3::new(0.6, 0.3, 0.2), Vec3::new(-0.8, 0.1, 0.05)] {
            for s in [1e-2f32, 1e-3, 3e-4, 1e-4] {
                // The square facing the origin, its edges along two directions ⟂ centre.
                let n = centre.normalize();
                let u = n.any_orthonormal_vector() * s;
                let v = n.cross(u);
                let corner = centre - 0.5 * (u + v);
                let q = [corner, corner + u, corner + u + v, corner + v];
                let expected = form_factor_f64(q);
                let got = f64::from(quad_form_factor(q));
                let tolerance = 20.0 * f64::from(f32::EPSILON / (s * n.z));
                assert!(expected > 0.0);
                assert!(
                    (got - expected).abs() <= tolerance * expected,
                    "side {s} at {centre}: {got} vs {expected} ({:.2e} relative, tolerance {tolerance:.2e})",
                    (got - expected).abs() / expected
                );
            }
        }
    }

    #[test]
    fn a_light_just_in_front_of_the_shading_point_fills_its_quarter_sphere() {
        // A vertical light (plane y = ε, x and z in [−1, 1]) crossing the horizon, the shading
        // point (normal +z) a hair in front of its centre: the light fills the quarter sphere
        // y > 0, z > 0, form factor 1/2. Clipped, its horizon edge runs between two nearly
        // opposite directions, whose ±π a cut-off at sin θ = 10⁻⁷ dropped (1.4·10⁻⁹ at ε = 2·10⁻⁸).
        for epsilon in [1e-3f32, 5e-8, 2e-8, 1e-12] {
            let q = [
                Vec3::new(-1.0, epsilon, -1.0),
                Vec3::new(1.0, epsilon, -1.0),
                Vec3::new(1.0, epsilon, 1.0),
                Vec3::new(-1.0, epsilon, 1.0),
            ];
            let got = quad_form_factor(q);
            assert!((got - 0.5).abs() < 1e-3, "ε = {epsilon}: {got}");
        }
    }

    /// An edge 2.5·10⁴ long that crosses the horizon 8·10⁻⁸ of its length from its lower end:
    /// the crossing is stepped from that end. Stepped from the upper one, `t` rounded to
    /// `1 − 6·10⁻⁸` moved it by `ε·|b − a|` ≈ 10⁻⁵, its whole distance from the plane `x = 0`,
    /// and the horizon edge from it passed the shading point on the wrong side: the form factor
    /// came out 0.030 for 0.970. (An LTC's `M⁻¹` at roughness 0 and a view 89.99° from the normal
    /// squeezes a huge light's corners towards its horizon so; `U_S` was 0.62 for 0.98.)
    #[test]
    fn a_crossing_beside_the_lower_end_of_a_long_edge_keeps_its_place() {
        let polygon = Polygon {
            corners: [
                Vec3::new(3.332_618_5e-5, 361.75, 6.437_744e-6),
                Vec3::new(135.984_65, 25_370.15, 49.512_825),
                Vec3::new(136.104_42, 24_894.445, 49.556_442),
                Vec3::new(-2.143_201e-5, -135.990_23, -4.140_102e-6),
                Vec3::ZERO,
                Vec3::ZERO,
            ],
            count: 4,
        };
        let clipped = polygon.clip_to_horizon();
        // The crossing on the third edge, in f64: x = −1.006141·10⁻⁵, y = −135.98814.
        let crossing = clipped.corners[3];
        assert!((crossing.x + 1.006_141e-5).abs() < 1e-9, "{crossing}");
        assert!((crossing.y + 135.988_14).abs() < 1e-3, "{crossing}");
        // The f64 edge sum of the f64 clip of the same corners.
        let got = polygon.form_factor();
        assert!((got - 0.969_825).abs() < 1e-5, "{got}");
    }
}
