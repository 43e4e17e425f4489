//! The child-box test of a CWBVH node for all eight children at once, in the 256-bit registers of
//! AVX2: the CPU's x86-64-v3 traversal runs it instead of [`BoxRay`]'s two halves of four lanes.
//!
//! It computes exactly what [`BoxRay::child_hits`] computes — the same IEEE operations on the same
//! operands per child, and the same hit-mask bits — with about half the instructions: one
//! byte-to-float conversion per plane array instead of two, no per-half broadcasts, and the meta
//! bytes decoded with per-lane variable shifts instead of word arithmetic.
//!
//! Every `unsafe fn` here has one precondition: the CPU supports AVX2. They are `#[inline(always)]`
//! so that they compile into the caller's x86-64-v3 build; only [`BoxRay8`]'s test calls them, and
//! a `BoxRay8` exists only where AVX2 was detected.

use super::{BoxRay, ChildBoxTest, FAR_SLACK};
use core::arch::x86_64::{
    __m128, __m256, __m256i, _mm256_add_ps, _mm256_and_si256, _mm256_broadcastss_ps, _mm256_castps_si256,
    _mm256_castsi256_si128, _mm256_cmp_ps, _mm256_cmpeq_epi32, _mm256_cvtepi32_ps, _mm256_cvtepu8_epi32,
    _mm256_extracti128_si256, _mm256_max_ps, _mm256_min_ps, _mm256_mul_ps, _mm256_set1_epi32, _mm256_set1_ps,
    _mm256_sllv_epi32, _mm256_srli_epi32, _mm256_xor_si256, _mm_add_ps, _mm_blendv_ps, _mm_castsi128_ps,
    _mm_cvtepu8_epi32, _mm_cvtsi128_si32, _mm_cvtsi32_si128, _mm_cvtsi64_si128, _mm_mul_ps, _mm_or_si128, _mm_set_ps,
    _mm_shuffle_epi32, _mm_shuffle_ps, _mm_slli_epi32, _mm_sub_ps, _CMP_LE_OQ,
};
use raywave_shared::bvh::CwBvhNode;

/// A ray prepared for the eight-lane child-box test. It can only be made where AVX2 is known to
/// be present (see [`BoxRay8::new`]), which is what makes its test sound to call.
pub(super) struct BoxRay8 {
    /// Ray origin in lanes 0–2.
    origin: __m128,
    /// 1 / the scaled direction (as in [`BoxRay`]) in lanes 0–2.
    inv_direction: __m128,
    /// [`BoxRay`]'s `t_scale`.
    t_scale: f32,
    /// All bits set in the lanes of axes along which the direction is negative.
    negative: __m128,
    /// Per axis, the plane array (0 = min x … 5 = max z) of the near and of the far planes.
    near_arrays: [usize; 3],
    far_arrays: [usize; 3],
    octant_inv: u32,
}

impl BoxRay8 {
    /// Prepares `ray` for the eight-lane test.
    ///
    /// # Safety
    /// The CPU must support AVX2 (check with `is_x86_feature_detected!("avx2")`): every test of
    /// the returned ray runs AVX2 instructions.
    #[inline(always)]
    pub(super) unsafe fn new(ray: &BoxRay) -> Self {
        let lanes = |v: glam::Vec3| _mm_set_ps(0.0, v.z, v.y, v.x);
        // `blendv` reads only the sign bit: −1 picks the max plane, +0 the min plane.
        let sign = |axis: usize| if ray.negative[axis] == 1 { -1.0 } else { 0.0 };
        let negative = _mm_set_ps(0.0, sign(2), sign(1), sign(0));
        let near = |axis: usize| axis * 2 + ray.negative[axis] as usize;
        Self {
            origin: lanes(ray.origin),
            inv_direction: lanes(ray.inv_direction),
            t_scale: ray.t_scale,
            negative,
            near_arrays: [near(0), near(1), near(2)],
            far_arrays: [near(0) ^ 1, near(1) ^ 1, near(2) ^ 1],
            octant_inv: ray.octant_inv,
        }
    }
}

impl ChildBoxTest for BoxRay8 {
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
        // SAFETY: a `BoxRay8` is only made by `BoxRay8::new`, whose caller guarantees AVX2.
        unsafe { child_hits(self, node, tmin, tmax) }
    }
}

/// The eight bytes of plane array `array` (children 0–7 in lanes 0–7) as exact floats.
#[inline(always)]
unsafe fn plane_array(node: &CwBvhNode, array: usize) -> __m256 {
    let bytes = u64::from(node.child_bounds[array * 2]) | (u64::from(node.child_bounds[array * 2 + 1]) << 32);
    _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bytes as i64)))
}

/// Lane `axis` (0–2) of `v` in all eight lanes.
#[inline(always)]
unsafe fn splat_lane(v: __m128, axis: usize) -> __m256 {
    _mm256_broadcastss_ps(match axis {
        0 => v,
        1 => _mm_shuffle_ps::<0x55>(v, v),
        _ => _mm_shuffle_ps::<0xaa>(v, v),
    })
}

/// Slab distances of plane array `array` of the eight children along `axis`:
/// q·scale + offset.
#[inline(always)]
unsafe fn slab(node: &CwBvhNode, array: usize, scale: __m128, offset: __m128, axis: usize) -> __m256 {
    _mm256_add_ps(_mm256_mul_ps(plane_array(node, array), splat_lane(scale, axis)), splat_lane(offset, axis))
}

/// [`BoxRay::child_hits`] in eight lanes.
#[inline(always)]
unsafe fn child_hits(ray: &BoxRay8, node: &CwBvhNode, tmin: f32, tmax: f32) -> u32 {
    let e = node.exponents_and_imask;
    // Cell sizes 2^(e − 127) from the exponent bytes (lane 3, the imask, is not used).
    let cell = _mm_castsi128_ps(_mm_slli_epi32::<23>(_mm_cvtepu8_epi32(_mm_cvtsi32_si128(e as i32))));
    let scale = _mm_mul_ps(cell, ray.inv_direction);
    let origin = _mm_set_ps(0.0, node.origin[2], node.origin[1], node.origin[0]);
    let offset = _mm_mul_ps(_mm_sub_ps(origin, ray.origin), ray.inv_direction);
    // As in `BoxRay::child_hits`: min planes at q·scale + (offset − scale), max planes at
    // q·scale + (offset + scale); the near plane of a negative axis is the max plane.
    let (low, high) = (_mm_sub_ps(offset, scale), _mm_add_ps(offset, scale));
    let near_offset = _mm_blendv_ps(low, high, ray.negative);
    let far_offset = _mm_blendv_ps(high, low, ray.negative);
    let near = |axis: usize| slab(node, ray.near_arrays[axis], scale, near_offset, axis);
    let far = |axis: usize| slab(node, ray.far_arrays[axis], scale, far_offset, axis);
    let t_near = _mm256_max_ps(_mm256_max_ps(near(0), near(1)), _mm256_max_ps(near(2), _mm256_set1_ps(tmin)));
    let t_far = _mm256_mul_ps(
        _mm256_min_ps(_mm256_min_ps(far(0), far(1)), _mm256_min_ps(far(2), _mm256_set1_ps(tmax))),
        _mm256_set1_ps(FAR_SLACK),
    );
    let hit = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far));
    decode_meta(node, hit, ray.octant_inv)
}

/// `child_hit_bits` of both meta words at once: per child lane, its triangle count (or 1 for an
/// internal child) shifted to its hit-mask bit where `hit` is set, the lanes then ORed together.
#[inline(always)]
unsafe fn decode_meta(node: &CwBvhNode, hit: __m256i, octant_inv: u32) -> u32 {
    let meta_bytes = u64::from(node.child_meta[0]) | (u64::from(node.child_meta[1]) << 32);
    let meta = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(meta_bytes as i64));
    let internal_bits = _mm256_set1_epi32(0x18);
    let internal = _mm256_cmpeq_epi32(_mm256_and_si256(meta, internal_bits), internal_bits);
    let bit = _mm256_xor_si256(
        _mm256_and_si256(meta, _mm256_set1_epi32(0x1f)),
        _mm256_and_si256(internal, _mm256_set1_epi32(octant_inv as i32)),
    );
    let count = _mm256_and_si256(_mm256_srli_epi32::<5>(meta), hit);
    let bits = _mm256_sllv_epi32(count, bit);
    let four = _mm_or_si128(_mm256_castsi256_si128(bits), _mm256_extracti128_si256::<1>(bits));
    let two = _mm_or_si128(four, _mm_shuffle_epi32::<0x4e>(four));
    _mm_cvtsi128_si32(_mm_or_si128(two, _mm_shuffle_epi32::<0xb1>(two))) as u32
}
