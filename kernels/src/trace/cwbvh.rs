//! Software closest-hit traversal of a compressed wide BVH8 (Ylitie, Karras & Laine, HPG 2017),
//! written once for the CPU and SPIR-V: no recursion, a fixed-size stack, `u32` indices.
//!
//! Node groups `(first child, hit bits 24–31 | imask bits 0–7)` and triangle groups
//! `(first triangle, hit bits 0–23)` drive the traversal: a node test turns the eight quantised
//! child boxes into one 32-bit hit mask, whose high byte lists internal children in front-to-back
//! order for the ray's octant and whose low 24 bits list the triangles of hit leaves.

use super::{ClosestHitQuery, Hit, OcclusionQuery, Ray};
use crate::triangle::WatertightRay;
use glam::{UVec2, Vec3, Vec3A, Vec4};
use raywave_shared::bvh::CwBvhNode;

#[cfg(target_arch = "x86_64")]
mod avx2;

/// Traversal stack depth: node groups waiting to be expanded. A full stack drops the groups it
/// cannot push (their subtrees go untested), so trees deeper than [`MAX_TREE_DEPTH`] are refused.
pub const STACK_SIZE: usize = 32;

/// The deepest tree (root = level 1, counting internal nodes) the traversal walks without
/// dropping a group: [`STACK_SIZE`] + 1. The stack holds groups of strictly increasing level
/// (a group is pushed before its level's expanded child is walked, and popped only when that
/// child's subtree is done), one per level whose nodes form a group of siblings — levels 2 to
/// the depth; the root's own group is never pushed. The host refuses deeper trees when it
/// builds them (`CpuScene::build_with`, `Error::SceneTooLarge`), since obvhs's builder
/// promises no depth.
pub const MAX_TREE_DEPTH: u32 = STACK_SIZE as u32 + 1;

/// Slack on the far side of every box test: 1 + 2·γ(10) with γ(n) = n·ε/(1 − n·ε), ε = 2⁻²⁴
/// (Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013, whose slab takes three roundings;
/// pbrt-v4 `Bounds3::IntersectP`). A quantised plane's distance here takes six: `1/d`, the
/// node origin's offset from the ray origin and its product with `1/d`, the product of the
/// plane's grid index with the scaled cell, the one-cell expansion and their sum — ten half-ulp
/// errors where Vulkan lets `1/d` be 2.5 ulp off (the CPU rounds it correctly). Where those
/// terms nearly cancel — a plane close to the ray origin — the error is not relative to the
/// small result; the expansion's absolute margin of one cell (below) covers it there.
const FAR_SLACK: f32 = 1.0 + 2.0 * (10.0 * f32::EPSILON * 0.5) / (1.0 - 10.0 * f32::EPSILON * 0.5);

/// The floor under a direction component's magnitude before it is inverted, in the box test's
/// direction (scaled so that its largest component is in [1, 2), [`BoxRay`]): zero (and ±0)
/// components become ±10⁻³⁰, so that slab distances stay finite (no `0 · ∞`) for axis-aligned
/// rays; `10³⁰ ×` the scene's 10⁸ coordinate limit still fits `f32`. Relative to the largest
/// component whatever the direction's length, the floor moves the box test's ray sideways by
/// 10⁻³⁰ of the distance it travels, which the one-cell box expansion covers for any hit closer
/// than 10³⁰ cells of its node.
const BOX_FLOOR: f32 = 1e-30;

/// The scene as the software trace stage reads it: node and triangle buffers built by the host.
pub struct CwBvhScene<'a> {
    /// BVH nodes; node 0 is the root.
    pub nodes: &'a [CwBvhNode],
    /// Triangle vertices in BVH leaf order, three per triangle (w unused).
    pub vertices: &'a [Vec4],
    /// (instance, primitive) of each triangle, in BVH leaf order.
    pub ids: &'a [UVec2],
}

/// The four bytes of `w`, low byte first, as exact floats in [0, 255].
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
#[inline(always)]
fn unpack_bytes(w: u32) -> Vec4 {
    Vec4::new((w & 0xff) as f32, ((w >> 8) & 0xff) as f32, ((w >> 16) & 0xff) as f32, (w >> 24) as f32)
}

/// The four bytes of `w`, low byte first, as exact floats in [0, 255]: the same values as the
/// portable version, widened in SSE registers (bytes → 16 → 32-bit lanes → floats).
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
#[inline(always)]
fn unpack_bytes(w: u32) -> Vec4 {
    use core::arch::x86_64::{
        _mm_cvtepi32_ps, _mm_cvtsi32_si128, _mm_setzero_si128, _mm_unpacklo_epi16, _mm_unpacklo_epi8,
    };
    // SAFETY: these are SSE2 intrinsics, and SSE2 is enabled for this target (see the cfg).
    unsafe {
        let zero = _mm_setzero_si128();
        let lanes = _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(w as i32), zero), zero);
        Vec4::from(_mm_cvtepi32_ps(lanes))
    }
}

/// Node index of the internal child in `slot` (0–7): internal children are stored contiguously
/// from `child_base` in slot order, so it is `child_base` plus the internal slots below `slot` in
/// `imask` (bit i set when slot i is internal).
#[inline(always)]
fn internal_child(child_base: u32, imask: u32, slot: u32) -> u32 {
    child_base + (imask & !(0xffff_ffffu32 << slot)).count_ones()
}

/// Index of the highest set bit of a non-zero word.
#[inline(always)]
fn highest_bit(bits: u32) -> u32 {
    31 - bits.leading_zeros()
}

/// A ray prepared for box tests, on its direction scaled by the power of two that brings the
/// largest component into [1, 2) — exactly, so the box test traces the same line — and the ray
/// parameter scaled by the inverse ([`Self::t_scale`]). Unscaled, the floor under the other
/// components was as large as a short direction itself: a traceable `(0, 0, 10⁻¹²)` ray missed
/// a 10⁻⁹-wide cluster 10⁸ away that the same ray of unit direction hits.
struct BoxRay {
    origin: Vec3,
    /// 1 / the scaled direction, components floored at [`BOX_FLOOR`].
    inv_direction: Vec3,
    /// The box test's ray parameter per unit of the ray's own: a power of two.
    t_scale: f32,
    /// Per axis: 1 when the direction is negative (near plane = max plane).
    negative: [u32; 3],
    /// The ray's octant, inverted, as obvhs orders children: bit 2 = x ≥ 0, bit 1 = y ≥ 0, bit 0 = z ≥ 0.
    octant_inv: u32,
}

impl BoxRay {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        // The largest component's biased exponent e: scaled by 2^(127 − e) it lies in [1, 2),
        // and t by 2^(e − 127). Clamped so that both factors are normal floats; a traceable
        // direction's e is at least 87 (10⁻¹²).
        let exponent = ((ray.direction.abs().max_element().to_bits() >> 23) & 0xff).clamp(1, 253);
        let d = ray.direction * f32::from_bits((254 - exponent) << 23);
        let t_scale = f32::from_bits(exponent << 23);
        let safe = |c: f32| if c.abs() < BOX_FLOOR { BOX_FLOOR.copysign(c) } else { c };
        let inv_direction = Vec3::new(1.0 / safe(d.x), 1.0 / safe(d.y), 1.0 / safe(d.z));
        let negative =
            [u32::from(inv_direction.x < 0.0), u32::from(inv_direction.y < 0.0), u32::from(inv_direction.z < 0.0)];
        let octant_inv = ((1 - negative[0]) << 2) | ((1 - negative[1]) << 1) | (1 - negative[2]);
        Self { origin: ray.origin, inv_direction, t_scale, negative, octant_inv }
    }
}

/// A ray prepared for testing a node's eight child boxes: the test the traversal runs per node.
trait ChildBoxTest {
    /// The ray's octant, inverted (see [`BoxRay::octant_inv`]).
    fn octant_inv(&self) -> u32;

    /// The box test's ray parameter per unit of the ray's own ([`BoxRay::t_scale`]): the factor
    /// `child_hits`' range takes.
    fn t_scale(&self) -> f32;

    /// The hit mask of `node`'s children for this ray within `[tmin, tmax]`: internal children
    /// hit at bits 24–31 in traversal order, the triangles of hit leaves at bits 0–23.
    fn child_hits(&self, node: &CwBvhNode, tmin: f32, tmax: f32) -> u32;
}

/// The portable test: four children at once as `Vec4` lanes (SSE on the CPU, vector instructions
/// in SPIR-V).
impl ChildBoxTest for BoxRay {
    #[inline(always)]
    fn octant_inv(&self) -> u32 {
        self.octant_inv
    }

    #[inline(always)]
    fn t_scale(&self) -> f32 {
        self.t_scale
    }

    #[inline(always)]
    fn child_hits(&self, node: &CwBvhNode, tmin: f32, tmax: f32) -> u32 {
        let e = node.exponents_and_imask;
        let cell = Vec3::new(
            f32::from_bits((e & 0xff) << 23),
            f32::from_bits(((e >> 8) & 0xff) << 23),
            f32::from_bits(((e >> 16) & 0xff) << 23),
        );
        // Slab distance of quantised plane q on an axis: (origin + q·cell − ray origin) / d.
        let scale = cell * self.inv_direction;
        let offset = (Vec3::from_array(node.origin) - self.origin) * self.inv_direction;
        // Every child box is moved one grid cell outwards (min planes at q − 1, max planes at
        // q + 1). The expansion keeps every triangle strictly inside its child box, so a ray
        // parallel to an axis that lies exactly on a box plane (zero-length slab,
        // `(q − o)·1/d = 0`) still enters the box; it costs about 1 % larger boxes. It is folded
        // into the offsets: (q ∓ 1)·scale + offset = q·scale + (offset ∓ scale).
        let offsets = [offset - scale, offset + scale];
        let mut hits = 0;
        let mut half = 0;
        while half < 2 {
            let slab = |axis: u32, near: bool| {
                // Near plane: the min plane for a positive direction, the max plane otherwise.
                let max_plane = u32::from(near) ^ (1 - self.negative[axis as usize]);
                let scale = [scale.x, scale.y, scale.z][axis as usize];
                let plane_offset = offsets[max_plane as usize];
                let plane_offset = [plane_offset.x, plane_offset.y, plane_offset.z][axis as usize];
                unpack_bytes(node.child_bounds[((axis * 2 + max_plane) * 2 + half) as usize]) * scale
                    + Vec4::splat(plane_offset)
            };
            // Balanced max/min trees: two dependent operations instead of three.
            let t_near = slab(0, true).max(slab(1, true)).max(slab(2, true).max(Vec4::splat(tmin)));
            let t_far = slab(0, false).min(slab(1, false)).min(slab(2, false).min(Vec4::splat(tmax))) * FAR_SLACK;
            let lanes = t_near.cmple(t_far).bitmask();
            hits |= child_hit_bits(node.child_meta[half as usize], lanes, self.octant_inv);
            half += 1;
        }
        hits
    }
}

/// The hit-mask bits of the four children whose meta bytes are `meta_word` (low byte first) and
/// whose lanes are set in `lanes`: an internal child sets bit `24 + slot`, its slot permuted by
/// the ray's inverted octant into traversal order; a leaf sets its triangle count (unary, top 3
/// meta bits) at its triangle offset; an empty slot (meta 0) sets nothing. The four bytes are
/// decoded side by side in one word and without branches, so the random hit patterns of
/// incoherent rays cost no mispredictions.
#[inline(always)]
fn child_hit_bits(meta_word: u32, lanes: u32, octant_inv: u32) -> u32 {
    // Internal children have meta bits 3 and 4 set (slot 24–31); leaf offsets are below 24.
    let internal = ((meta_word & (meta_word << 1) & 0x1010_1010) >> 4) * 0xff;
    let bit = (meta_word ^ ((octant_inv * 0x0101_0101) & internal)) & 0x1f1f_1f1f;
    // Lane k's bit moved to bit 8k (the four products of the multiplication cannot overlap),
    // widened to a byte mask.
    let hit = ((lanes * 0x0020_4081) & 0x0101_0101) * 0xff;
    let count = (meta_word >> 5) & 0x0707_0707 & hit;
    (count & 0xff) << (bit & 0xff)
        | ((count >> 8) & 0xff) << ((bit >> 8) & 0xff)
        | ((count >> 16) & 0xff) << ((bit >> 16) & 0xff)
        | (count >> 24) << (bit >> 24)
}

impl CwBvhScene<'_> {
    #[inline(always)]
    fn triangle_hit(&self, ray: &WatertightRay, index: u32, tmin: f32, tmax: f32) -> Option<(f32, glam::Vec2)> {
        let base = (index * 3) as usize;
        let v0 = Vec3A::from_vec4(self.vertices[base]);
        let v1 = Vec3A::from_vec4(self.vertices[base + 1]);
        let v2 = Vec3A::from_vec4(self.vertices[base + 2]);
        ray.intersect_a(v0, v1, v2, tmin, tmax).map(|h| (h.t, h.barycentrics))
    }
}

/// Bytes of one CWBVH node.
#[cfg(target_arch = "x86_64")]
const NODE_BYTES: usize = core::mem::size_of::<CwBvhNode>();

/// Bytes of one triangle's vertices (three `Vec4`s; the ids, which `shared::bvh::TRIANGLE_BYTES`
/// counts too, are read only for the closest hit).
#[cfg(target_arch = "x86_64")]
const TRIANGLE_VERTEX_BYTES: usize = 3 * core::mem::size_of::<Vec4>();

impl CwBvhScene<'_> {
    /// Starts loading, without a branch, everything a node test can lead to next: the node's
    /// internal children, all eight node slots from `child_base` where they are stored
    /// contiguously, and the eight triangles from its first hit one (a leaf's triangles are
    /// contiguous from `primitive_base`, at their hit bits' offsets). The loads overlap with each
    /// other and with the work before the traversal reaches them. Hinting only the hit children,
    /// in loops over the hit bits, mispredicted the loops' exits about once per node test, which
    /// cost more than the unused lines these blocks load (x86-64-v3, diffuse rays, 1 thread:
    /// +36 % on the hairball, +13 % on the sphere field; simulated mispredictions per hairball ray
    /// 178 → 94). Loading only the internal children that exist and only the hit triangles'
    /// span, clamped without branches, measured 5–11 % slower.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn prefetch_children(&self, node: &CwBvhNode, hits: u32) {
        let first_child = self.nodes.as_ptr().wrapping_add(node.child_base as usize);
        prefetch_block::<{ 8 * NODE_BYTES }>(first_child.cast());
        // 0 when no triangle was hit: a wasted hint at `primitive_base`.
        let first_hit = (hits & 0x00ff_ffff).trailing_zeros() & 31;
        let first_triangle = self.vertices.as_ptr().wrapping_add(3 * (node.primitive_base + first_hit) as usize);
        prefetch_block::<{ 8 * TRIANGLE_VERTEX_BYTES }>(first_triangle.cast());
    }

    #[cfg(not(target_arch = "x86_64"))]
    fn prefetch_children(&self, _node: &CwBvhNode, _hits: u32) {}
}

/// Hints the CPU to load every 64-byte cache line of the `BYTES` bytes from `start` into L1.
/// `start` may point anywhere, past the end of a buffer included: nothing is read.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch_block<const BYTES: usize>(start: *const i8) {
    use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
    const LINE: usize = 64;
    let mut offset = 0;
    while offset < BYTES {
        // SAFETY: a prefetch is a hint that never faults and reads nothing the program can
        // observe, whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(offset)) };
        offset += LINE;
    }
    // The last line, which an unaligned `start` spills into.
    // SAFETY: as above.
    unsafe { _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(BYTES - 1)) };
}

/// The closest (or, for any-hit queries, the first found) triangle a traversal reports.
struct Found {
    /// Triangle index in BVH order, `u32::MAX` for none.
    index: u32,
    t: f32,
    barycentrics: glam::Vec2,
    stats: TraversalStats,
}

/// Work one traversal did: for tests (early exit) and benchmark diagnostics.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct TraversalStats {
    /// Nodes whose eight child boxes were tested.
    pub nodes: u32,
    /// Ray–triangle tests.
    pub triangles: u32,
}

/// Whether the traversal tests a node's triangles one iteration later, after the next node test:
/// their loads, started by the prefetch right after the first test, then have a node test's time
/// to arrive instead of stalling the triangle test (x86-64 CPU, diffuse rays: +9 % on the
/// hairball, +13 % on the sphere field; the next node is tested with a `tmax` those triangles
/// have not shrunk yet, which costs under 2 % more node and triangle tests). Only where that
/// prefetch exists: lavapipe ran the SPIR-V traversal slower with the deferral (sphere field,
/// primary rays: 1.7 → 1.2 Mrays/s).
const DEFER_TRIANGLES: bool = cfg!(target_arch = "x86_64");

impl CwBvhScene<'_> {
    /// Walks the tree front to back. With `any_hit` it returns at the first triangle hit in
    /// `[tmin, tmax]` (occlusion), otherwise it shrinks `tmax` to each closer hit (closest hit).
    ///
    /// On x86-64 ([`DEFER_TRIANGLES`]) the triangles a node test finds are tested one iteration
    /// later, after the next node test.
    #[inline(always)]
    fn traverse<B: ChildBoxTest>(&self, ray: &Ray, box_ray: &B, any_hit: bool) -> Found {
        let tri_ray = WatertightRay::new(ray.origin, ray.direction);
        // Exact: `t_scale` is a power of two (the range's ends at most move into or out of the
        // subnormals, where the box test is conservative either way).
        let t_scale = box_ray.t_scale();
        let box_tmin = ray.tmin * t_scale;
        // The box test's `found.t`, updated with it.
        let mut box_tmax = ray.tmax * t_scale;
        let mut stack = [UVec2::ZERO; STACK_SIZE];
        let mut stack_len = 0usize;
        // Start with a group whose only internal hit is the root (node 0 = first child of group 0).
        let mut node_group = UVec2::new(0, 0x8000_0000);
        let mut triangle_group = UVec2::ZERO;
        let mut found =
            Found { index: u32::MAX, t: ray.tmax, barycentrics: glam::Vec2::ZERO, stats: TraversalStats::default() };
        loop {
            // Triangles of the node tested in this iteration, for the next one (when deferring).
            let mut next_triangles = UVec2::ZERO;
            if node_group.y & 0xff00_0000 != 0 {
                let bit = highest_bit(node_group.y & 0xff00_0000);
                let imask = node_group.y;
                node_group.y &= !(1u32 << bit);
                if node_group.y & 0xff00_0000 != 0 && stack_len < STACK_SIZE {
                    stack[stack_len] = node_group;
                    stack_len += 1;
                }
                let slot = (bit - 24) ^ box_ray.octant_inv();
                let child = internal_child(node_group.x, imask & 0xff, slot);
                let node = &self.nodes[child as usize];
                let hits = box_ray.child_hits(node, box_tmin, box_tmax);
                found.stats.nodes += 1;
                self.prefetch_children(node, hits);
                node_group = UVec2::new(node.child_base, (hits & 0xff00_0000) | (node.exponents_and_imask >> 24));
                let node_triangles = UVec2::new(node.primitive_base, hits & 0x00ff_ffff);
                if DEFER_TRIANGLES {
                    next_triangles = node_triangles;
                } else {
                    triangle_group = node_triangles;
                }
            } else {
                // Groups are only pushed with internal hits left, so this is reached only when
                // nothing remains to expand: the root group is exhausted, or the stack emptied and
                // this iteration only tests the last node's triangles.
                node_group = UVec2::ZERO;
            }
            while triangle_group.y != 0 {
                let bit = highest_bit(triangle_group.y);
                triangle_group.y &= !(1u32 << bit);
                let index = triangle_group.x + bit;
                found.stats.triangles += 1;
                if let Some((t, barycentrics)) = self.triangle_hit(&tri_ray, index, ray.tmin, found.t) {
                    if found.index == u32::MAX || t < found.t {
                        (found.index, found.t, found.barycentrics) = (index, t, barycentrics);
                        box_tmax = t * t_scale;
                        if any_hit {
                            return found;
                        }
                    }
                }
            }
            // (Zero when not deferring: this iteration tested the node's triangles already.)
            triangle_group = next_triangles;
            if node_group.y & 0xff00_0000 == 0 {
                if stack_len == 0 {
                    if triangle_group.y == 0 {
                        return found;
                    }
                    // No node left, but the last node's triangles are still to be tested.
                    continue;
                }
                stack_len -= 1;
                node_group = stack[stack_len];
            }
        }
    }
}

impl CwBvhScene<'_> {
    /// The work a closest-hit (`any_hit = false`) or occlusion (`any_hit = true`) query does for
    /// `ray`.
    pub fn traversal_stats(&self, ray: &Ray, any_hit: bool) -> TraversalStats {
        self.traverse(ray, &BoxRay::new(ray), any_hit).stats
    }
}

impl CwBvhScene<'_> {
    /// The closest hit with child-box test `box_ray`, written out where it is called so that each
    /// instruction-set build below compiles the whole traversal.
    #[inline(always)]
    fn closest_hit_with<B: ChildBoxTest>(&self, ray: &Ray, box_ray: &B) -> Hit {
        let found = self.traverse(ray, box_ray, false);
        if found.index == u32::MAX {
            return Hit::MISS;
        }
        let id = self.ids[found.index as usize];
        Hit { t: found.t, primitive: id.y, instance: id.x, barycentrics: found.barycentrics }
    }

    /// Whether anything blocks the ray, with child-box test `box_ray`, written out where it is
    /// called (see [`closest_hit_with`](Self::closest_hit_with)).
    #[inline(always)]
    fn occluded_with<B: ChildBoxTest>(&self, ray: &Ray, box_ray: &B) -> bool {
        self.traverse(ray, box_ray, true).index != u32::MAX
    }
}

impl ClosestHitQuery for CwBvhScene<'_> {
    fn closest_hit(&self, ray: &Ray) -> Hit {
        self.closest_hit_with(ray, &BoxRay::new(ray))
    }
}

impl OcclusionQuery for CwBvhScene<'_> {
    fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_with(ray, &BoxRay::new(ray))
    }
}

/// The traversal compiled for x86-64-v3 CPUs (AVX2, FMA, BMI1/2, LZCNT, POPCNT), for hosts that
/// detect those features at run time: the same source with VEX-encoded vector instructions and
/// single-instruction population and leading-zero counts, and the child-box test of all eight
/// children in one 256-bit register (private module `avx2`) instead of two halves of four. Results are
/// bit-identical to the portable build: the eight-lane test performs the same IEEE operations per
/// child, and Rust never contracts a multiply and an add into an FMA.
#[cfg(target_arch = "x86_64")]
impl CwBvhScene<'_> {
    /// [`ClosestHitQuery::closest_hit`] for x86-64-v3, with the eight-lane child-box test.
    ///
    /// # Safety
    /// The CPU must support AVX2, FMA, BMI1, BMI2, LZCNT and POPCNT (check with
    /// `is_x86_feature_detected!`).
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub unsafe fn closest_hit_x86_64_v3(&self, ray: &Ray) -> Hit {
        // SAFETY: the caller guarantees AVX2.
        self.closest_hit_with(ray, &unsafe { avx2::BoxRay8::new(&BoxRay::new(ray)) })
    }

    /// [`OcclusionQuery::occluded`] for x86-64-v3.
    ///
    /// # Safety
    /// As for [`closest_hit_x86_64_v3`](Self::closest_hit_x86_64_v3).
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    pub unsafe fn occluded_x86_64_v3(&self, ray: &Ray) -> bool {
        // SAFETY: the caller guarantees AVX2.
        self.occluded_with(ray, &unsafe { avx2::BoxRay8::new(&BoxRay::new(ray)) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::pcg3d;
    use glam::UVec3;

    /// The hit-mask bits child by child, as the decoding is specified (one branch per child).
    fn child_hit_bits_reference(meta_word: u32, lanes: u32, octant_inv: u32) -> u32 {
        let mut bits = 0;
        for k in 0..4 {
            let meta = (meta_word >> (8 * k)) & 0xff;
            if lanes & (1 << k) == 0 || meta == 0 {
                continue;
            }
            let bit = if meta & 0x18 == 0x18 { (meta & 0x1f) ^ octant_inv } else { meta & 0x1f };
            bits |= (meta >> 5) << bit;
        }
        bits
    }

    /// A meta byte obvhs can write: empty, internal child `0b001_11xxx`, or a leaf with 1–3
    /// triangles (unary count in the top bits) at an offset that leaves them below bit 24.
    fn meta_byte(random: u32) -> u32 {
        match random % 3 {
            0 => 0,
            1 => 0b0011_1000 | ((random >> 2) & 7),
            _ => {
                let count = 1 + (random >> 2) % 3;
                let offset = (random >> 4) % (25 - count);
                (((1 << count) - 1) << 5) | offset
            }
        }
    }

    #[test]
    fn word_parallel_child_decoding_matches_child_by_child_decoding() {
        for i in 0..20_000u32 {
            let h = pcg3d(UVec3::new(i, 17, 3));
            let meta_word = (0..4).fold(0, |w, k| w | (meta_byte(h.x >> (8 * k)) << (8 * k)));
            let (lanes, octant_inv) = (h.y & 0xf, h.z & 7);
            assert_eq!(
                child_hit_bits(meta_word, lanes, octant_inv),
                child_hit_bits_reference(meta_word, lanes, octant_inv),
                "meta {meta_word:#010x} lanes {lanes:#x} octant {octant_inv}"
            );
        }
        // Every slot internal and hit: the eight octant permutations of bits 24–31.
        for octant_inv in 0..8 {
            let all_internal = 0x3b3a_3938; // slots 0–3 of the first half
            assert_eq!(
                child_hit_bits(all_internal, 0xf, octant_inv),
                child_hit_bits_reference(all_internal, 0xf, octant_inv)
            );
        }
    }

    /// A node with random grid, child boxes (min ≤ max per child) and meta bytes, around the origin.
    fn random_node(i: u32) -> CwBvhNode {
        let h = |k: u32| pcg3d(UVec3::new(i, k, 41));
        let (a, b) = (h(0), h(1));
        let origin = [a.x, a.y, a.z].map(|r| (r % 2000) as f32 * 0.01 - 10.0);
        let exponent = |r: u32| 122 + r % 5;
        let mut child_bounds = [0u32; 12];
        for axis in 0..3 {
            for half in 0..2 {
                let (lo, hi) = (h(2 + axis * 2 + half), h(8 + axis * 2 + half));
                let (mut min_word, mut max_word) = (0, 0);
                for k in 0..4 {
                    let (x, y) = ((lo.x >> (8 * k)) & 0xff, (hi.x >> (8 * k)) & 0xff);
                    min_word |= x.min(y) << (8 * k);
                    max_word |= x.max(y) << (8 * k);
                }
                child_bounds[(axis * 4 + half) as usize] = min_word;
                child_bounds[(axis * 4 + 2 + half) as usize] = max_word;
            }
        }
        let meta = |r: u32| (0..4).fold(0, |w, k| w | (meta_byte(r >> (8 * k)) << (8 * k)));
        CwBvhNode {
            origin,
            exponents_and_imask: exponent(b.x) | exponent(b.y) << 8 | exponent(b.z) << 16 | (a.x & 0xff) << 24,
            child_base: 0,
            primitive_base: 0,
            child_meta: [meta(h(20).x), meta(h(20).y)],
            child_bounds,
        }
    }

    /// A ray from a random point around `node` towards a random point of its grid; every fifth
    /// one axis-aligned instead, with ±0 components.
    fn random_ray(i: u32, node: &CwBvhNode) -> Ray {
        let (a, b) = (pcg3d(UVec3::new(i, 1, 43)), pcg3d(UVec3::new(i, 2, 43)));
        let unit = |r: u32| (r >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0;
        let e = node.exponents_and_imask;
        let cell = |shift: u32| f32::from_bits(((e >> shift) & 0xff) << 23);
        let extent = 255.0 * Vec3::new(cell(0), cell(8), cell(16));
        let grid = |r: UVec3| Vec3::from_array(node.origin) + extent * Vec3::new(unit(r.x), unit(r.y), unit(r.z)).abs();
        let origin = grid(a) + extent * Vec3::new(unit(b.z), unit(a.x ^ b.y), unit(a.y ^ b.x));
        let direction = match i % 5 {
            0 => [Vec3::X, Vec3::NEG_Y, Vec3::new(-0.0, 0.0, 1.0), Vec3::new(0.0, -0.0, -1.0)][(i / 5 % 4) as usize],
            _ => grid(b) - origin,
        };
        Ray { origin, direction, tmin: 0.1 * unit(b.x).abs(), tmax: 0.5 + 2.0 * unit(b.y).abs() }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_lane_child_box_test_matches_the_portable_test() {
        if !std::is_x86_feature_detected!("avx2") {
            // CI's x86-64 machines have AVX2, where this path is what the CPU traversal runs.
            // CI as the other tests read it (`CI` = `true` or `1`).
            let in_ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
            assert!(!in_ci, "no AVX2 on this CI machine: the eight-lane test cannot run");
            std::eprintln!("SKIP: no AVX2 on this CPU: the eight-lane test cannot run here, nor can anything call it");
            return;
        }
        let mut hits_seen = 0;
        for i in 0..50_000u32 {
            let node = random_node(i);
            let ray = random_ray(i, &node);
            let portable = BoxRay::new(&ray);
            // SAFETY: AVX2 was detected above.
            let wide = unsafe { avx2::BoxRay8::new(&portable) };
            let (tmin, tmax) = (ray.tmin * portable.t_scale, ray.tmax * portable.t_scale);
            assert_eq!(wide.t_scale(), portable.t_scale);
            let expected = portable.child_hits(&node, tmin, tmax);
            assert_eq!(wide.child_hits(&node, tmin, tmax), expected, "node {i}: {node:?} {ray:?}");
            hits_seen += u32::from(expected != 0);
        }
        assert!(hits_seen > 5_000, "too few rays hit a child ({hits_seen}) for the comparison to mean much");
    }

    /// A caterpillar tree `depth` levels deep (root = 1) and its triangles: each chain node's
    /// internal children are a side node holding one triangle (slot 0) and the next chain node
    /// (slot 1); the last chain node holds one triangle too. A ray whose direction is negative on
    /// every axis (inverted octant 0) expands slot 1 first, pushing the side node's group at
    /// every level from 2 to `depth`. The deepest side node's triangle is the closest along that
    /// ray (`t` = 1), the others at `t` ≥ 3.
    fn caterpillar(depth: u32) -> (std::vec::Vec<CwBvhNode>, std::vec::Vec<Vec4>, std::vec::Vec<UVec2>) {
        // A grid from −8 in cells of 1/16: every child box spans [−8, 7.94] on each axis.
        let exponents = 123 | 123 << 8 | 123 << 16;
        let node = |imask: u32, child_base: u32, primitive_base: u32, child_meta: u32| CwBvhNode {
            origin: [-8.0; 3],
            exponents_and_imask: exponents | imask << 24,
            child_base,
            primitive_base,
            child_meta: [child_meta, 0],
            child_bounds: [0, 0, u32::MAX, u32::MAX, 0, 0, u32::MAX, u32::MAX, 0, 0, u32::MAX, u32::MAX],
        };
        // Internal children in slots 0 and 1 (meta 0b001_11xxx); one triangle at offset 0.
        let (two_internal, one_triangle) = ((0x38 | 0x39 << 8), 0x20);
        // Chain node k (level k) is node 2(k − 1); its side child at level k + 1 is node 2k − 1,
        // which holds triangle k − 1. The last chain node holds triangle `depth` − 1.
        let mut nodes = std::vec::Vec::new();
        for level in 1..depth {
            nodes.push(node(0b11, 2 * level - 1, 0, two_internal));
            nodes.push(node(0, 0, level - 1, one_triangle));
        }
        nodes.push(node(0, 0, depth - 1, one_triangle));
        // The ray below runs from (4, 4, 4) along −(1, 1, 1): a triangle across the diagonal
        // at (s, s, s) is hit at t = 4 − s.
        let triangle_at = |s: f32| {
            [Vec3::new(s + 1.0, s - 1.0, s), Vec3::new(s, s + 1.0, s - 1.0), Vec3::new(s - 1.0, s, s + 1.0)]
                .map(|v| v.extend(0.0))
        };
        let deepest_side = depth - 2;
        let vertices = (0..depth)
            .flat_map(|triangle| triangle_at(if triangle == deepest_side { 3.0 } else { 1.0 - 0.01 * triangle as f32 }))
            .collect();
        let ids = (0..depth).map(|triangle| UVec2::new(0, triangle)).collect();
        (nodes, vertices, ids)
    }

    #[test]
    fn a_tree_max_tree_depth_deep_fills_the_stack_without_dropping_a_group() {
        let ray = Ray { origin: Vec3::splat(4.0), direction: Vec3::splat(-1.0), tmin: 0.0, tmax: 100.0 };
        let closest = |depth: u32| {
            let (nodes, vertices, ids) = caterpillar(depth);
            let scene = CwBvhScene { nodes: &nodes, vertices: &vertices, ids: &ids };
            let hit = scene.closest_hit(&ray);
            assert_eq!(scene.occluded(&ray), hit.is_hit(), "depth {depth}");
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: AVX2 (and the rest of x86-64-v3 with it on every such CPU) was detected.
                let wide = unsafe { scene.closest_hit_x86_64_v3(&ray) };
                assert_eq!((wide.primitive, wide.t), (hit.primitive, hit.t), "depth {depth}");
            }
            (hit.primitive, hit.t)
        };
        for depth in 2..=MAX_TREE_DEPTH {
            assert_eq!(closest(depth), (depth - 2, 1.0), "depth {depth}: the deepest side node's triangle");
        }
        // One level deeper the stack is full when the deepest side node's group comes: it is
        // dropped, and the ray hits the first side node's triangle (t = 4 − 0.99) instead. This
        // is why the host refuses such trees; it shows the limit is exactly the stack's.
        let too_deep = MAX_TREE_DEPTH + 1;
        assert_eq!(closest(too_deep), (0, 3.0), "depth {too_deep}");
    }

    #[test]
    fn byte_unpacking_is_exact_and_low_byte_first() {
        assert_eq!(unpack_bytes(0x04_03_02_01), Vec4::new(1.0, 2.0, 3.0, 4.0));
        assert_eq!(unpack_bytes(0xff_00_80_7f), Vec4::new(127.0, 128.0, 0.0, 255.0));
        for w in [0u32, u32::MAX, 0x1234_5678, 0x8000_0001] {
            let portable =
                Vec4::new((w & 0xff) as f32, ((w >> 8) & 0xff) as f32, ((w >> 16) & 0xff) as f32, (w >> 24) as f32);
            assert_eq!(unpack_bytes(w), portable, "{w:#x}");
        }
    }
}
