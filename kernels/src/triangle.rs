//! Ray–triangle intersection: the watertight test of Woop, Benthin & Wald, "Watertight
//! Ray/Triangle Intersection", JCGT 2(1), 2013.
//!
//! The ray is sheared so it runs along +z from the origin; the 2-D edge functions of the projected
//! triangle are then evaluated on the same operands for both triangles sharing an edge, which
//! traverse it in opposite directions, and come out exactly opposite — in the kernels by ordering
//! the edge's endpoints canonically, so that a GPU compiler that fuses the products into
//! multiply-adds fuses the same operands in both — so a ray through an edge or vertex hits at
//! least one of them. An edge function that is exactly 0 counts as inside, which keeps the test
//! watertight without the paper's f64 fallback (SPIR-V cannot assume `Float64`). That fallback
//! also re-evaluates edge functions that rounded to 0; without it, two of them 0 at a vertex off
//! the ray are taken for what they are, rounding, and the triangle is missed (`rounded_onto_a_vertex`).
//! Both faces are hit, matching Vulkan ray query without culling flags.

// `!(x >= y)` sends a NaN determinant or distance down the "no hit" branch on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::{Vec2, Vec3, Vec3A};

/// The component of `v` along `axis` (0 = x, 1 = y, otherwise z), written as a branch so it
/// compiles to SPIR-V without dynamic vector indexing.
pub fn component(v: Vec3, axis: u32) -> f32 {
    match axis {
        0 => v.x,
        1 => v.y,
        _ => v.z,
    }
}

/// A hit on one triangle.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct TriangleHit {
    /// Ray parameter of the hit, in `[tmin, tmax]` (`tmax` for an empty range that a hit at
    /// its ends' rounding passed).
    pub t: f32,
    /// Barycentric weights of vertices 1 and 2 (Vulkan's convention): the hit point is
    /// `(1 − u − v)·v0 + u·v1 + v·v2`.
    pub barycentrics: Vec2,
}

/// A ray prepared for the watertight test: the paper's axis permutation and shear, computed once
/// per ray and reused for every triangle it meets.
///
/// The permutation and shear are folded into one 3×3 matrix whose rows are
/// `e_kx − S_x·e_kz`, `e_ky − S_y·e_kz` and `S_z·e_kz`: every entry is 1, 0, −S_x, −S_y or S_z,
/// so `M·(v − o)` (SIMD columns on the CPU) rounds exactly like the paper's scalar
/// `A[kx] − S_x·A[kz]` — one rounded product and one rounded sum per component, the other terms
/// exact — without branching on the axis indices per triangle.
#[derive(Copy, Clone, Debug)]
pub struct WatertightRay {
    origin: Vec3A,
    /// Columns of the shear matrix.
    columns: [Vec3A; 3],
}

/// Unit vector along `axis` (0 = x, 1 = y, otherwise z).
fn unit(axis: u32) -> Vec3A {
    match axis {
        0 => Vec3A::X,
        1 => Vec3A::Y,
        _ => Vec3A::Z,
    }
}

impl WatertightRay {
    /// Prepares a ray. `direction` need not be unit length but must be finite, its largest
    /// component within `trace::MIN_DIRECTION` … `trace::MAX_DIRECTION` in magnitude (as a
    /// traceable ray's is), so that `1/d` of that component is finite and a normal float.
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        let abs = direction.abs();
        let kz = if abs.x > abs.y {
            if abs.x > abs.z {
                0
            } else {
                2
            }
        } else if abs.y > abs.z {
            1
        } else {
            2
        };
        let mut kx = if kz == 2 { 0 } else { kz + 1 };
        let mut ky = if kx == 2 { 0 } else { kx + 1 };
        let dz = component(direction, kz);
        // Swap to keep the winding when the dominant direction component is negative.
        if dz < 0.0 {
            core::mem::swap(&mut kx, &mut ky);
        }
        let (sx, sy, sz) = (component(direction, kx) / dz, component(direction, ky) / dz, 1.0 / dz);
        let rows = [unit(kx) - sx * unit(kz), unit(ky) - sy * unit(kz), sz * unit(kz)];
        let columns = [
            Vec3A::new(rows[0].x, rows[1].x, rows[2].x),
            Vec3A::new(rows[0].y, rows[1].y, rows[2].y),
            Vec3A::new(rows[0].z, rows[1].z, rows[2].z),
        ];
        Self { origin: Vec3A::from(origin), columns }
    }

    /// A vertex in the ray's sheared frame: (x, y) on the plane the ray pierces at the origin,
    /// z the scaled distance along the ray.
    #[inline(always)]
    fn transform(&self, v: Vec3A) -> Vec3A {
        let d = v - self.origin;
        self.columns[0] * d.x + self.columns[1] * d.y + self.columns[2] * d.z
    }

    /// Intersects the triangle `(v0, v1, v2)`; returns the hit if its parameter lies in
    /// `[tmin, tmax]` (both inclusive, as Vulkan's ray query) and the triangle is not degenerate as
    /// seen from the ray.
    pub fn intersect(&self, v0: Vec3, v1: Vec3, v2: Vec3, tmin: f32, tmax: f32) -> Option<TriangleHit> {
        self.intersect_a(Vec3A::from(v0), Vec3A::from(v1), Vec3A::from(v2), tmin, tmax)
    }

    /// [`intersect`](Self::intersect) on SIMD-aligned vertices.
    #[inline(always)]
    pub fn intersect_a(&self, v0: Vec3A, v1: Vec3A, v2: Vec3A, tmin: f32, tmax: f32) -> Option<TriangleHit> {
        // Rust never fuses a product into an addition, so on the CPU the plain cross product is
        // exactly antisymmetric and equals the canonical one up to the sign of a zero, which no
        // comparison here sees (tested); skipping the ordering there keeps the CPU traversal
        // 13–15 % faster (`raywave bench trace`, sphere field, one thread). A SPIR-V driver may
        // fuse where the module does not forbid it ([`edge_function`]), so the kernels order the
        // endpoints.
        if cfg!(target_arch = "spirv") {
            self.intersect_with(v0, v1, v2, tmin, tmax, |p, q| edge_function(p, q, &cross_2d))
        } else {
            self.intersect_with(v0, v1, v2, tmin, tmax, cross_2d)
        }
    }

    /// [`intersect_a`](Self::intersect_a) with the edge function `edge(p, q)` of the directed
    /// edge `p → q` (vertices in the ray's sheared frame) as given: the tests pass one whose
    /// products are fused, as a GPU compiler may evaluate them.
    #[inline(always)]
    fn intersect_with<F: Fn(Vec3A, Vec3A) -> f32>(
        &self,
        v0: Vec3A,
        v1: Vec3A,
        v2: Vec3A,
        tmin: f32,
        tmax: f32,
        edge: F,
    ) -> Option<TriangleHit> {
        let a = self.transform(v0);
        let b = self.transform(v1);
        let c = self.transform(v2);

        // Scaled barycentrics: edge functions opposite v0, v1, v2.
        let u = edge(c, b);
        let v = edge(a, c);
        let w = edge(b, a);
        // Non-short-circuit operators: one branch instead of six data-dependent ones, which
        // incoherent rays mispredict.
        let outside = ((u < 0.0) | (v < 0.0) | (w < 0.0)) & ((u > 0.0) | (v > 0.0) | (w > 0.0));
        let det = u + v + w;
        let det_abs = det.abs();
        // A subnormal determinant (a sliver a few units in the last place wide as seen from the
        // ray) counts as degenerate, as 0 does: its reciprocal overflows to infinity, which made
        // the hit's t and barycentrics non-finite (found by fuzzing a CPU render; a GPU that
        // flushes subnormals to zero misses it too).
        // Written so that a NaN determinant fails too (`!(x ≥ y)`, not `x < y`): edge products
        // that overflow — a ray origin far beyond the scene's — had returned a NaN hit, which as
        // the first hit found stopped the traversal from accepting any later box or triangle.
        if outside | !(det_abs >= f32::MIN_POSITIVE && det_abs.is_finite()) {
            return None;
        }
        // Rare (an edge function exactly 0), so a branch that is almost never taken.
        if ((u == 0.0) | (v == 0.0) | (w == 0.0)) && rounded_onto_a_vertex(a, b, c, u, v, w) {
            return None;
        }

        let t_scaled = u * a.z + v * b.z + w * c.z;
        // Compare t·|det| against the range without dividing, sign-corrected for back faces (a
        // NaN fails, as above).
        let t_scaled_abs = if det < 0.0 { -t_scaled } else { t_scaled };
        if !(t_scaled_abs >= tmin * det_abs && t_scaled_abs <= tmax * det_abs) {
            return None;
        }
        let rcp_det = 1.0 / det;
        let t = t_scaled * rcp_det;
        // A t that overflowed (where `tmax·|det|` did too, and the check passed on ∞ ≤ ∞) is no
        // hit within a finite range.
        if !t.is_finite() {
            return None;
        }
        // `t_scaled · (1/det)` rounds twice and can land an ulp outside the range just checked;
        // `max`/`min`, not `clamp`, which panics on an empty range (`tmin > tmax`).
        let t = t.max(tmin).min(tmax);
        Some(TriangleHit { t, barycentrics: Vec2::new(v * rcp_det, w * rcp_det) })
    }
}

/// Whether two of the edge functions `u`, `v`, `w` (opposite the sheared vertices `a`, `b`, `c`)
/// are exactly 0 at a vertex that is not at the sheared origin, where the ray runs: two zeros
/// put the ray through their shared vertex only where that vertex sits there. Anywhere else they
/// are rounding — the triangle projects onto a line through the ray (a ray in its plane, a sliver
/// seen end-on), the true values below the products' rounding — and the third value alone had
/// made a hit at that vertex however far the ray passed: 0.74 from a triangle 0.5 across, for
/// rays in its plane beside it (a reviewer's search). Seen so the triangle has no area, and its
/// neighbours' shared edges, exactly 0 too, count as inside theirs. A vertex so near the ray that
/// its edge products underflow counts as on it ([`off_the_ray`]).
#[inline(always)]
fn rounded_onto_a_vertex(a: Vec3A, b: Vec3A, c: Vec3A, u: f32, v: f32, w: f32) -> bool {
    ((v == 0.0) & (w == 0.0) & off_the_ray(a, b, c))
        | ((u == 0.0) & (w == 0.0) & off_the_ray(b, c, a))
        | ((u == 0.0) & (v == 0.0) & off_the_ray(c, a, b))
}

/// Whether the sheared vertex `p` lies off the ray, which runs through the sheared frame's (x, y)
/// origin, by more than its edge products with the other vertices `q`, `r` resolve: where
/// `|p| · max(|q|, |r|)` (largest x or y magnitudes) is below `f32::MIN_POSITIVE` those products
/// underflow — to 0 on a GPU that flushes subnormals, from 2⁻¹⁵⁰ on the CPU — and every triangle
/// of `p`'s fan gets the same two zeros. Taken for rounding, they had let a ray through a closed
/// pyramid's apex 2·10⁻³⁸ off it (a 1 m pyramid, flushed; a 10⁻⁸ one on the CPU).
#[inline(always)]
fn off_the_ray(p: Vec3A, q: Vec3A, r: Vec3A) -> bool {
    planar_extent(p) * planar_extent(q).max(planar_extent(r)) >= f32::MIN_POSITIVE
}

/// The larger of a sheared vertex's x and y magnitudes: its distance from the ray, to a factor √2.
#[inline(always)]
fn planar_extent(p: Vec3A) -> f32 {
    p.x.abs().max(p.y.abs())
}

/// The 2-D cross product `p.x·q.y − p.y·q.x` of two vertices in the ray's sheared frame.
#[inline(always)]
fn cross_2d(p: Vec3A, q: Vec3A) -> f32 {
    p.x * q.y - p.y * q.x
}

/// The edge function of the directed edge `p → q` as seen from the ray, `cross(p, q)`, evaluated
/// on the edge's endpoints in one canonical order (by x, then y) and negated when the edge runs
/// the other way; exactly 0 when the endpoints coincide as seen from the ray (an edge along it),
/// as the unfused product is. The two triangles sharing an edge traverse it in opposite
/// directions, so they get exactly opposite values as long as `cross` rounds the same operands
/// the same way — which watertightness rests on. That holds for any one evaluation, fused or not;
/// SPIR-V does not promise that a driver fuses the three inlined copies in `intersect_with` alike,
/// but NVIDIA's did (0 leaks on an H100). Evaluated as written, `p.x·q.y − p.y·q.x` is exactly
/// antisymmetric already, but SPIR-V lets a driver fuse a product into the subtraction unless the
/// result is decorated `NoContraction` (rust-gpu 0.11 does not decorate), and a fused
/// `fma(p.x, q.y, −p.y·q.x)` is not the negation of `fma(q.x, p.y, −q.y·p.x)`: on an NVIDIA H100
/// (driver 580.159.04) 1 276 of 10⁶ rays aimed at the shared edges and vertices of a closed
/// sphere went through it, all at edges (`trace_robustness`). raywave's Vulkan backend now
/// decorates every float operation of its kernels so (the host's
/// `vulkan::spirv::without_contraction`), which also keeps the vertex transform that precedes
/// this (`M·(v − o)`, inlined three times) rounded alike in every triangle; the canonical order
/// stays for an engine that builds these kernels into shaders it does not pass through that.
#[inline(always)]
fn edge_function<F: Fn(Vec3A, Vec3A) -> f32>(p: Vec3A, q: Vec3A, cross: &F) -> f32 {
    let same_x = q.x == p.x;
    let reversed = (q.x < p.x) | (same_x & (q.y < p.y));
    let coincident = same_x & (q.y == p.y);
    let (first, second) = if reversed { (q, p) } else { (p, q) };
    let value = if coincident { 0.0 } else { cross(first, second) };
    if reversed {
        -value
    } else {
        value
    }
}

/// Unit geometric normal of triangle `(v0, v1, v2)` by the right-hand rule (counter-clockwise
/// winding faces the viewer). Returns zero for a degenerate triangle rather than NaN.
pub fn geometric_normal(v0: Vec3, v1: Vec3, v2: Vec3) -> Vec3 {
    unit_normal((v1 - v0).cross(v2 - v0))
}

/// The unit vector along `cross` (a cross product of two edges, the normal of their plane),
/// scaled by its largest component before it is normalized: `normalize` squares the components,
/// so the normal of a triangle about 10⁻¹¹ across (a subnormal squared length) came out too long
/// (by 23 % for one the offset tests met), and that of one under 10⁻¹² or over 10¹⁰ across as
/// zero (a squared length that under- or overflowed). Zero for a zero or non-finite `cross`.
pub fn unit_normal(cross: Vec3) -> Vec3 {
    let largest = cross.abs().max_element();
    if largest > 0.0 && largest.is_finite() {
        (cross / largest).normalize_or_zero()
    } else {
        Vec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V0: Vec3 = Vec3::new(0.0, 0.0, 0.0);
    const V1: Vec3 = Vec3::new(1.0, 0.0, 0.0);
    const V2: Vec3 = Vec3::new(0.0, 1.0, 0.0);

    fn hit(origin: Vec3, dir: Vec3) -> Option<TriangleHit> {
        WatertightRay::new(origin, dir).intersect(V0, V1, V2, 0.0, 1e30)
    }

    #[test]
    fn hits_inside_with_vulkan_barycentrics() {
        let h = hit(Vec3::new(0.25, 0.5, 2.0), Vec3::NEG_Z).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6);
        assert!((h.barycentrics - Vec2::new(0.25, 0.5)).abs().max_element() < 1e-6);
    }

    #[test]
    fn hits_both_faces() {
        let front = hit(Vec3::new(0.2, 0.2, 1.0), Vec3::NEG_Z).unwrap();
        let back = hit(Vec3::new(0.2, 0.2, -1.0), Vec3::Z).unwrap();
        assert_eq!(front.barycentrics, back.barycentrics);
        assert!((front.t - 1.0).abs() < 1e-6 && (back.t - 1.0).abs() < 1e-6);
    }

    #[test]
    fn misses_outside_and_outside_the_range() {
        assert!(hit(Vec3::new(0.8, 0.8, 1.0), Vec3::NEG_Z).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), Vec3::Z).is_none(), "behind the origin");
        let r = WatertightRay::new(Vec3::new(0.2, 0.2, 1.0), Vec3::NEG_Z);
        assert!(r.intersect(V0, V1, V2, 0.0, 0.5).is_none(), "beyond tmax");
        assert!(r.intersect(V0, V1, V2, 1.5, 9.0).is_none(), "before tmin");
        assert!(r.intersect(V0, V1, V2, 1.0, 1.0).is_some(), "range is inclusive");
    }

    /// Two edge functions that round to 0 off the ray had made a hit at their vertex, however far
    /// the ray passed: a reviewer's triangle 3·10⁻⁵ across, met 0.67 away.
    #[test]
    fn edge_functions_rounded_to_zero_are_no_vertex_hit() {
        let v0 = Vec3::new(-0.36423773, -0.02848357, 0.28932792);
        let v1 = Vec3::new(-0.36426103, -0.028465021, 0.2893141);
        let v2 = Vec3::new(-0.3642494, -0.028474245, 0.28932104);
        let origin = Vec3::new(-0.4977292, -0.5756026, -0.5287687);
        let dir = Vec3::new(0.11014137, -0.10362632, 0.04732912);
        assert_eq!(WatertightRay::new(origin, dir).intersect(v0, v1, v2, 0.0, 2.836), None);
        // A vertex exactly on the ray is hit there, by every triangle of its fan.
        let fan = [V1, V2, Vec3::new(-1.0, 0.5, 0.0), Vec3::new(-0.5, -1.0, 0.0), V1];
        for down in [Vec3::NEG_Z, Vec3::new(0.0, 0.0, -1e-30)] {
            let ray = WatertightRay::new(Vec3::Z, down);
            for pair in fan.windows(2) {
                let h = ray.intersect(V0, pair[0], pair[1], 0.0, 1e31).expect("the vertex on the ray");
                assert_eq!(h.barycentrics, Vec2::ZERO);
            }
        }
    }

    /// `p.x·q.y − p.y·q.x` with subnormal operands and products flushed to 0, as a GPU may.
    fn flushed_cross(p: Vec3A, q: Vec3A) -> f32 {
        let flush = |x: f32| if x.abs() < f32::MIN_POSITIVE { 0.0 } else { x };
        flush(flush(flush(p.x) * flush(q.y)) - flush(flush(p.y) * flush(q.x)))
    }

    /// A closed square pyramid whose apex lies 2·10⁻³⁸ (and 10⁻³⁰) off a ray along its axis: the
    /// apex's edge products underflow, to the same two zeros in every side face, which must not
    /// be taken for rounding — the ray had gone through to the base, on the CPU for a 10⁻⁸
    /// pyramid and with products flushed as a GPU may for a 1 m one.
    #[test]
    fn a_ray_past_a_vertex_by_less_than_its_products_resolve_meets_its_fan() {
        let ray = WatertightRay::new(Vec3::Z, Vec3::NEG_Z);
        for (off, size) in [(2e-38, 0.5), (1e-37, 0.1), (1e-30, 1e-9), (2e-38, 1e-8), (1e-30, 1e-16)] {
            let apex = Vec3::new(off, 0.0, 0.0);
            let corner = |x: f32, y: f32| Vec3::new(x * size, y * size, -size);
            let ring = [corner(1.0, 1.0), corner(-1.0, 1.0), corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0)];
            for flushed in [false, true] {
                let first_side_hit = ring.windows(2).find_map(|edge| {
                    let [p, q, r] = [apex, edge[0], edge[1]].map(Vec3A::from);
                    if flushed {
                        ray.intersect_with(p, q, r, 0.0, 10.0, |p, q| edge_function(p, q, &flushed_cross))
                    } else {
                        ray.intersect_with(p, q, r, 0.0, 10.0, cross_2d)
                    }
                });
                let hit =
                    first_side_hit.unwrap_or_else(|| panic!("apex {off} off, size {size}, flushed {flushed}: no side"));
                assert!((hit.t - 1.0).abs() <= 1e-6, "at the apex, not {}", hit.t);
            }
        }
    }

    /// Rays in a tilted triangle's plane, running beside it parallel to its long edge, 0.07–0.5
    /// outside: none may hit it at a vertex, where two edge functions rounded to 0 had put 2923
    /// of them (of 3019 hits). Where all three are rounding noise of one sign the float test
    /// cannot tell (nor can pbrt-v4's, which re-evaluates only zeros in f64): 96 of the 200 000
    /// rays still hit, anywhere; the bound guards that count.
    #[test]
    fn rays_in_a_triangles_plane_beside_it_do_not_hit_it_far_away() {
        let normal = Vec3::new(0.3, 0.8, -0.52).normalize();
        let (e1, e2) = normal.any_orthonormal_pair();
        let c0 = Vec3::new(0.1, 0.2, 0.3);
        let (v0, v1, v2) = (c0, c0 + e1 * 0.5, c0 + e2 * 0.5);
        let point = |h: TriangleHit| {
            v0 * (1.0 - h.barycentrics.x - h.barycentrics.y) + v1 * h.barycentrics.x + v2 * h.barycentrics.y
        };
        let (mut at_vertex, mut far) = (0, 0);
        let mut rng = 0x2545_f491_u32;
        let mut uniform = || {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            rng as f32 / u32::MAX as f32
        };
        for _ in 0..200_000 {
            let beyond = 0.05 + 0.3 * uniform();
            let start = c0 + (e1 + e2) * (0.25 + beyond) + (e1 - e2) * (uniform() - 0.5);
            let dir = (e1 - e2).normalize() * if uniform() < 0.5 { 1.0 } else { -1.0 };
            let origin = start - dir * 0.6;
            if let Some(h) = WatertightRay::new(origin, dir).intersect(v0, v1, v2, 0.0, 1.2) {
                let b = h.barycentrics;
                at_vertex += u32::from(b == Vec2::ZERO || b == Vec2::X || b == Vec2::Y);
                far += u32::from((origin + dir * h.t - point(h)).length() > 1e-3);
            }
        }
        assert_eq!(at_vertex, 0, "hits at a vertex");
        assert!(far <= 2 * 96, "{far} hits off the triangle");
    }

    #[test]
    fn rays_through_a_shared_edge_hit_one_of_the_two_triangles() {
        // Two triangles sharing the diagonal (1,0)-(0,1) of the unit square.
        let v3 = Vec3::new(1.0, 1.0, 0.0);
        let mut leaks = 0;
        for i in 0..=1000 {
            let s = i as f32 / 1000.0;
            let origin = Vec3::new(1.0 - s, s, 3.0) + Vec3::new(0.3, -0.7, 0.0);
            let dir = Vec3::new(1.0 - s, s, 0.0) - origin;
            let r = WatertightRay::new(origin, dir);
            let first = r.intersect(V0, V1, V2, 0.0, 1e30);
            let second = r.intersect(V1, v3, V2, 0.0, 1e30);
            leaks += u32::from(first.is_none() && second.is_none());
        }
        assert_eq!(leaks, 0);
    }

    /// `p.x·q.y − p.y·q.x` with the first product fused into the subtraction, as a GPU compiler
    /// may evaluate it.
    fn fused_cross(p: Vec3A, q: Vec3A) -> f32 {
        p.x.mul_add(q.y, -(p.y * q.x))
    }

    /// Pairs of random triangles sharing an edge, apexes on either side, and rays from random
    /// origins aimed at random points of the shared edge, with the edge products fused: no ray
    /// passes between the two. The fused product alone is not antisymmetric (on most of these
    /// edges `fused(p, q) ≠ −fused(q, p)`, which let rays through the edges on an H100); the
    /// canonical edge function is, exactly.
    #[test]
    fn shared_edges_stay_watertight_when_the_edge_products_are_fused() {
        let mut rng = crate::hash::CounterRng::new(17);
        let (mut leaks, mut asymmetric, mut canonical_asymmetric) = (0, 0, 0);
        const PAIRS: u32 = 20_000;
        for i in 0..PAIRS {
            let (e0, e1) = (rng.vec3(-1.0, 1.0), rng.vec3(-1.0, 1.0));
            let side = (e1 - e0).cross(rng.unit_vec3()).normalize();
            let mid = e0.lerp(e1, rng.next_f32());
            let (apex_a, apex_b) = (mid + side * rng.range(0.1, 1.0), mid - side * rng.range(0.1, 1.0));
            let target = e0.lerp(e1, rng.next_f32());
            let origin = target + rng.unit_vec3() * rng.range(0.5, 3.0);
            let ray = WatertightRay::new(origin, target - origin);
            let [e0, e1, apex_a, apex_b] = [e0, e1, apex_a, apex_b].map(Vec3A::from);
            let fused_edge = |p, q| edge_function(p, q, &fused_cross);
            let first = ray.intersect_with(e0, e1, apex_a, 0.0, 1e30, fused_edge);
            // The shared edge in the same slot of both triangles (w), or in another (u).
            let second = if i.is_multiple_of(2) {
                ray.intersect_with(e1, e0, apex_b, 0.0, 1e30, fused_edge)
            } else {
                ray.intersect_with(apex_b, e1, e0, 0.0, 1e30, fused_edge)
            };
            leaks += u32::from(first.is_none() && second.is_none());
            let (p, q) = (ray.transform(e0), ray.transform(e1));
            asymmetric += u32::from(fused_cross(p, q) != -fused_cross(q, p));
            assert_eq!(edge_function(p, p, &fused_cross), 0.0, "an edge along the ray");
            canonical_asymmetric += u32::from(edge_function(p, q, &fused_cross) != -edge_function(q, p, &fused_cross));
        }
        assert_eq!((leaks, canonical_asymmetric), (0, 0), "leaks, asymmetric canonical edge functions");
        assert!(asymmetric > PAIRS / 2, "fused products asymmetric on only {asymmetric} of {PAIRS} edges");
    }

    /// Unfused, the canonical edge function equals the plain cross product (up to the sign of a
    /// zero, which no comparison sees): what lets the CPU skip the ordering. Half the vertices
    /// lie on a small integer grid so that ties in x and y, and zero cross products, are common.
    #[test]
    fn unfused_the_canonical_edge_function_is_the_plain_cross_product() {
        let mut rng = crate::hash::CounterRng::new(29);
        let mut vertex = |i: u32| {
            let v = rng.vec3(-2.0, 2.0);
            Vec3A::from(if i.is_multiple_of(2) { v.round() } else { v })
        };
        for i in 0..100_000 {
            let (p, q) = (vertex(i), vertex(i / 2));
            assert_eq!(edge_function(p, q, &cross_2d), cross_2d(p, q), "{p} → {q}");
        }
    }

    /// A ray origin so far from the triangle that the edge products overflow (∞ − ∞ = NaN) gives
    /// no hit, not one at t = NaN.
    #[test]
    fn edge_products_that_overflow_give_no_hit() {
        let ray = WatertightRay::new(Vec3::new(1e30, 1e30, 0.0), Vec3::Z);
        let (u, v) = (ray.transform(V1.into()), ray.transform(V2.into()));
        assert!(cross_2d(u, v).is_nan(), "the case overflows");
        assert_eq!(ray.intersect(V0, V1, V2, 0.0, f32::MAX), None);
    }

    /// A hit's t lies in `[tmin, tmax]` even where the range check, made on `t·det`, passes a `t`
    /// that the division rounds an ulp outside: random rays against random triangles, each
    /// range an ulp inside the hit's unbounded t on one side.
    #[test]
    fn hit_parameters_stay_inside_the_range() {
        let mut rng = crate::hash::CounterRng::new(41);
        let mut rounded_in = 0;
        for _ in 0..20_000 {
            let [v0, v1, v2] = [rng.vec3(-1.0, 1.0), rng.vec3(-1.0, 1.0), rng.vec3(-1.0, 1.0)];
            let target = v0 + (v1 - v0) * 0.3 + (v2 - v0) * 0.3;
            let origin = target + rng.unit_vec3() * rng.range(0.5, 64.0);
            let ray = WatertightRay::new(origin, (target - origin) * rng.range(0.1, 10.0));
            let Some(unbounded) = ray.intersect(v0, v1, v2, 0.0, f32::MAX) else { continue };
            for (tmin, tmax) in [(0.0, unbounded.t.next_down()), (unbounded.t.next_up(), f32::MAX)] {
                if let Some(hit) = ray.intersect(v0, v1, v2, tmin, tmax) {
                    assert!((tmin..=tmax).contains(&hit.t), "{} outside [{tmin}, {tmax}]", hit.t);
                    rounded_in += 1;
                }
            }
        }
        assert!(rounded_in > 100, "only {rounded_in} ranges met the rounding");
    }

    /// An empty range (`tmin > tmax`, which the stage never passes but the public test takes)
    /// whose products with the determinant both round to 0 lets a hit at t = 0 through the
    /// range check: its t is put in range without a panic (`f32::clamp` had asserted
    /// `min ≤ max`).
    #[test]
    fn an_empty_range_whose_products_underflow_does_not_panic() {
        let (tmin, tmax) = (f32::from_bits(2), f32::from_bits(1));
        // Exact binary coordinates: the determinant is 0.25 exactly, and both products halve or
        // quarter the smallest subnormal, rounding to 0.
        let ray = WatertightRay::new(Vec3::new(0.125, 0.125, 0.0), Vec3::Z);
        let hit = ray.intersect(V0, V1 * 0.5, V2 * 0.5, tmin, tmax).expect("the range check passes");
        assert_eq!(hit.t, tmax);
    }

    #[test]
    fn axis_aligned_and_negative_zero_directions_work() {
        for dir in [Vec3::NEG_Z, Vec3::new(-0.0, 0.0, -1.0), Vec3::new(0.0, -0.0, -1.0)] {
            assert!(hit(Vec3::new(0.1, 0.1, 1.0), dir).is_some(), "{dir}");
        }
        // A ray in the triangle's plane sees a degenerate (zero-area) triangle.
        assert!(hit(Vec3::new(-1.0, 0.2, 0.0), Vec3::X).is_none());
    }

    /// Slivers whose determinant is subnormal in the ray's frame are misses, never a hit with an
    /// infinite or NaN t or barycentrics; a tiny but normal triangle still hits.
    #[test]
    fn subnormal_slivers_miss_and_tiny_triangles_hit_finitely() {
        for exponent in 15..=30 {
            let size = 10f32.powi(-exponent);
            let (v0, v1, v2) = (Vec3::new(0.0, 0.0, 1.0), Vec3::new(size, 0.0, 1.0), Vec3::new(0.0, size, 1.0));
            let ray = WatertightRay::new(Vec3::new(0.2 * size, 0.2 * size, 0.0), Vec3::Z);
            match ray.intersect(v0, v1, v2, 0.0, f32::MAX) {
                Some(hit) => {
                    assert!(hit.t.is_finite() && hit.barycentrics.is_finite(), "size {size:e}: {hit:?}");
                    assert!((hit.t - 1.0).abs() < 1e-6, "size {size:e}: {hit:?}");
                }
                None => assert!(size * size < 2.0 * f32::MIN_POSITIVE, "size {size:e}: a normal triangle missed"),
            }
        }
    }

    /// A tilted triangle 10⁻¹⁸ to 10¹⁸ across has the unit normal it has at size 1: `normalize`
    /// on the cross product gave one 2 % too long at 10⁻¹¹ (a subnormal squared length), and
    /// zero from 10⁻¹² down and from 10¹⁰ up (a squared length that under- or overflowed).
    #[test]
    fn tiny_and_huge_triangles_have_unit_normals() {
        let corners = [Vec3::new(0.1, -0.3, 0.2), Vec3::new(0.9, 0.2, -0.4), Vec3::new(-0.2, 0.7, 0.5)];
        let expected = geometric_normal(corners[0], corners[1], corners[2]);
        let old = |[a, b, c]: [Vec3; 3]| (b - a).cross(c - a).normalize_or_zero();
        assert!((old(corners) - expected).length() < 1e-6);
        for exponent in -18..=18 {
            let scaled = corners.map(|v| v * 10f32.powi(exponent));
            let n = geometric_normal(scaled[0], scaled[1], scaled[2]);
            assert!((n - expected).length() < 1e-6, "10^{exponent}: {n} against {expected}");
        }
        let at = |exponent: i32| old(corners.map(|v| v * 10f32.powi(exponent)));
        assert!(at(-11).length() > 1.02 && at(-12) == Vec3::ZERO && at(10) == Vec3::ZERO);
        assert_eq!(unit_normal(Vec3::new(f32::INFINITY, 0.0, 0.0)), Vec3::ZERO);
        assert_eq!(unit_normal(Vec3::NAN), Vec3::ZERO);
    }

    #[test]
    fn degenerate_normal_is_zero_not_nan() {
        assert_eq!(geometric_normal(V0, V1, V1), Vec3::ZERO);
        assert_eq!(geometric_normal(V0, V1, V2), Vec3::Z);
    }
}
