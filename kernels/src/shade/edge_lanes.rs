//! The edge sum of [`Polygon::form_factor`](super::polygon::Polygon::form_factor) on x86-64,
//! four edges per SSE instruction: each lane runs the operations of the portable
//! [`edge_integral`](super::polygon::edge_integral) — the corner normalization of glam's
//! `normalize_or_zero`, [`edge_cross`](super::polygon::edge_cross)'s choice of scale, the cross
//! and dot products in glam's order, [`crate::trig::atan2`] — with its branches as lane selects,
//! and the lanes are then summed in edge order, so the sum is the
//! portable loop's bit for bit (test: `polygon::tests::lanes_match_the_portable_edge_sum`).
//! IEEE-754 rounds `+ − × ÷ √` alike in a lane and in a scalar register, and Rust never fuses a
//! multiply-add, so only the order of operations matters, and it is the same.
//!
//! Why: the form factor is 65 % of a CPU render of the 20-light grid (`perf`), and each of its
//! edges is a chain of a square root, three divisions and the `atan` polynomial; a quad's four
//! edges now share one chain.

use super::polygon::MAX_CORNERS;
use crate::trig::{ATAN_POLYNOMIAL, TAN_PI_8};
use core::arch::x86_64::{
    __m128, _mm_add_ps, _mm_and_ps, _mm_andnot_ps, _mm_castps_si128, _mm_castsi128_ps, _mm_cmpeq_ps, _mm_cmpge_ps,
    _mm_cmpgt_ps, _mm_cmple_ps, _mm_cmplt_ps, _mm_div_ps, _mm_min_ps, _mm_mul_ps, _mm_or_ps, _mm_set1_ps, _mm_setr_ps,
    _mm_setzero_ps, _mm_shuffle_ps, _mm_sqrt_ps, _mm_srai_epi32, _mm_storeu_ps, _mm_sub_ps,
};
use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
use glam::Vec3;

/// Three coordinates of four vectors, one vector per lane.
#[derive(Copy, Clone)]
struct Lanes3 {
    x: __m128,
    y: __m128,
    z: __m128,
}

impl Lanes3 {
    /// `v[0]` in lane 0, … `v[3]` in lane 3 (built in registers: vectors stored as scalars and
    /// reloaded as one would stall store forwarding).
    #[inline(always)]
    fn gather(v: [Vec3; 4]) -> Self {
        // SAFETY: SSE is part of every x86-64 target.
        unsafe {
            Self {
                x: _mm_setr_ps(v[0].x, v[1].x, v[2].x, v[3].x),
                y: _mm_setr_ps(v[0].y, v[1].y, v[2].y, v[3].y),
                z: _mm_setr_ps(v[0].z, v[1].z, v[2].z, v[3].z),
            }
        }
    }

    /// Lane `i` takes lane `(i + 1) mod 4`.
    #[inline(always)]
    fn rotated(self) -> Self {
        Self { x: rotated(self.x), y: rotated(self.y), z: rotated(self.z) }
    }
}

/// Lane `i` takes lane `(i + 1) mod 4`.
#[inline(always)]
fn rotated(v: __m128) -> __m128 {
    // Lanes (1, 2, 3, 0): the immediate's 2-bit fields, lowest first.
    const NEXT: i32 = 0b00_11_10_01;
    // SAFETY: SSE is part of every x86-64 target.
    unsafe { _mm_shuffle_ps::<NEXT>(v, v) }
}

/// Σᵢ `edge_integral(cᵢ, cᵢ₊₁)` over the first `count` (≤ [`MAX_CORNERS`]) of `corners`, the
/// last edge closing back to the first corner — the sum
/// [`Polygon::form_factor`](super::polygon::Polygon::form_factor)'s portable loop computes, bit
/// for bit, for any input (non-finite corners normalize to zero there and here).
#[inline(always)]
pub fn edge_sum(corners: &[Vec3; MAX_CORNERS], count: usize) -> f32 {
    let n = count.min(MAX_CORNERS);
    // Edge i runs from corner i to the next (the first after the last); past `n` both ends are
    // zero and the lane's integral is 0 (not summed anyway). A quad's ends are its starts rotated
    // by one lane; otherwise each end is normalized in its own lane (a corner normalizes to the
    // same bits in any lane) rather than shuffled from the starts by a pattern that depends on `n`.
    let start = |i: usize| if i < n { corners[i] } else { Vec3::ZERO };
    let end = |i: usize| {
        if i + 1 < n {
            corners[i + 1]
        } else if i < n {
            corners[0]
        } else {
            Vec3::ZERO
        }
    };
    let mut sum = 0.0f32;
    let mut first = 0usize;
    while first < n {
        let mut integrals = [0.0f32; 4];
        // SAFETY: SSE2 is part of every x86-64 target; the store writes the array's 4 floats.
        unsafe {
            let a = Corners::new(Lanes3::gather([start(first), start(first + 1), start(first + 2), start(first + 3)]));
            let b = if n == 4 {
                a.rotated()
            } else {
                Corners::new(Lanes3::gather([end(first), end(first + 1), end(first + 2), end(first + 3)]))
            };
            _mm_storeu_ps(integrals.as_mut_ptr(), edge_integrals(&a, &b));
        }
        // In edge order, as the portable loop adds them.
        let mut lane = 0usize;
        while lane < 4 && first + lane < n {
            sum += integrals[lane];
            lane += 1;
        }
        first += 4;
    }
    sum
}

/// `mask ? a : b` per lane (`mask` lanes all ones or all zeros).
#[inline(always)]
unsafe fn select(mask: __m128, a: __m128, b: __m128) -> __m128 {
    _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b))
}

/// [`Corner`](super::polygon::Corner) per lane: the corner, its unit direction (glam's
/// `normalize_or_zero`, `v · (1/√((x² + y²) + z²))`) and that reciprocal length where it is finite
/// and positive, else both zero.
#[derive(Copy, Clone)]
struct Corners {
    position: Lanes3,
    unit: Lanes3,
    reciprocal_length: __m128,
}

impl Corners {
    #[inline(always)]
    unsafe fn new(v: Lanes3) -> Self {
        let length =
            _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(v.x, v.x), _mm_mul_ps(v.y, v.y)), _mm_mul_ps(v.z, v.z)));
        let rcp = _mm_div_ps(_mm_set1_ps(1.0), length);
        // `rcp > 0 && rcp < ∞`: false for NaN, ∞ and non-positive values alike.
        let keep = _mm_and_ps(_mm_cmpgt_ps(rcp, _mm_setzero_ps()), _mm_cmplt_ps(rcp, _mm_set1_ps(f32::INFINITY)));
        Self {
            position: v,
            unit: Lanes3 {
                x: _mm_and_ps(keep, _mm_mul_ps(v.x, rcp)),
                y: _mm_and_ps(keep, _mm_mul_ps(v.y, rcp)),
                z: _mm_and_ps(keep, _mm_mul_ps(v.z, rcp)),
            },
            reciprocal_length: _mm_and_ps(keep, rcp),
        }
    }

    /// Lane `i` takes lane `(i + 1) mod 4`.
    #[inline(always)]
    fn rotated(self) -> Self {
        Self {
            position: self.position.rotated(),
            unit: self.unit.rotated(),
            reciprocal_length: rotated(self.reciprocal_length),
        }
    }
}

/// glam's `a × b` per lane: (a.y·b.z − b.y·a.z, a.z·b.x − b.z·a.x, a.x·b.y − b.x·a.y).
#[inline(always)]
unsafe fn cross(a: Lanes3, b: Lanes3) -> Lanes3 {
    Lanes3 {
        x: _mm_sub_ps(_mm_mul_ps(a.y, b.z), _mm_mul_ps(b.y, a.z)),
        y: _mm_sub_ps(_mm_mul_ps(a.z, b.x), _mm_mul_ps(b.z, a.x)),
        z: _mm_sub_ps(_mm_mul_ps(a.x, b.y), _mm_mul_ps(b.x, a.y)),
    }
}

/// `v · s` per lane.
#[inline(always)]
unsafe fn scaled(v: Lanes3, s: __m128) -> Lanes3 {
    Lanes3 { x: _mm_mul_ps(v.x, s), y: _mm_mul_ps(v.y, s), z: _mm_mul_ps(v.z, s) }
}

/// `mask ? a : b` per lane for three coordinates.
#[inline(always)]
unsafe fn select3(mask: __m128, a: Lanes3, b: Lanes3) -> Lanes3 {
    Lanes3 { x: select(mask, a.x, b.x), y: select(mask, a.y, b.y), z: select(mask, a.z, b.z) }
}

/// `edge_integral(a, b)` per lane: `θ·(â × b̂).z/|â × b̂|`, `θ = atan2(|â × b̂|, â·b̂)`, the
/// ratio 1 for `|â × b̂|` below the smallest normal number, with `â × b̂` as
/// [`edge_cross`](super::polygon::edge_cross) forms it.
#[inline(always)]
unsafe fn edge_integrals(a: &Corners, b: &Corners) -> __m128 {
    let zero = _mm_setzero_ps();
    let edge = Lanes3 {
        x: _mm_sub_ps(b.position.x, a.position.x),
        y: _mm_sub_ps(b.position.y, a.position.y),
        z: _mm_sub_ps(b.position.z, a.position.z),
    };
    let both = _mm_and_ps(_mm_cmpgt_ps(a.reciprocal_length, zero), _mm_cmpgt_ps(b.reciprocal_length, zero));
    // `b.reciprocal_length <= a.reciprocal_length`: â × edge/|b|, else b̂ × edge/|a| — the nearer
    // corner's direction, the farther one's scale (the least reciprocal; neither is NaN).
    let b_farther = _mm_cmple_ps(b.reciprocal_length, a.reciprocal_length);
    let unit = select3(b_farther, a.unit, b.unit);
    let scale = _mm_min_ps(a.reciprocal_length, b.reciprocal_length);
    let c = cross(unit, scaled(edge, scale));
    // Zero where either corner is (its lanes may hold NaN).
    let c = Lanes3 { x: _mm_and_ps(both, c.x), y: _mm_and_ps(both, c.y), z: _mm_and_ps(both, c.z) };
    let (u, v) = (a.unit, b.unit);
    let sin_theta =
        _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(c.x, c.x), _mm_mul_ps(c.y, c.y)), _mm_mul_ps(c.z, c.z)));
    let cos_theta = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u.x, v.x), _mm_mul_ps(u.y, v.y)), _mm_mul_ps(u.z, v.z));
    let theta = atan2_of_finite_nonnegative_y(sin_theta, cos_theta);
    let theta_over_sin =
        select(_mm_cmpge_ps(sin_theta, _mm_set1_ps(f32::MIN_POSITIVE)), _mm_div_ps(theta, sin_theta), _mm_set1_ps(1.0));
    _mm_mul_ps(c.z, theta_over_sin)
}

/// [`crate::trig::atan2`] per lane for finite `x` and `y ≥ +0` (a length): its NaN and infinity
/// cases and the sign of `y` cannot arise, the rest is its branches as selects.
#[inline(always)]
unsafe fn atan2_of_finite_nonnegative_y(y: __m128, x: __m128) -> __m128 {
    let zero = _mm_setzero_ps();
    let one = _mm_set1_ps(1.0);
    let sign_bit = _mm_set1_ps(-0.0);
    let abs_x = _mm_andnot_ps(sign_bit, x);
    let swap = _mm_cmpgt_ps(y, abs_x);
    let small = select(swap, abs_x, y);
    let large = select(swap, y, abs_x);
    let ratio = select(_mm_cmpeq_ps(large, zero), zero, _mm_div_ps(small, large));
    // trig::atan_unit: above tan(π/8) reduced by π/4, then Cephes' polynomial.
    let reduce = _mm_cmpgt_ps(ratio, _mm_set1_ps(TAN_PI_8));
    let offset = select(reduce, _mm_set1_ps(FRAC_PI_4), zero);
    let t = select(reduce, _mm_div_ps(_mm_sub_ps(ratio, one), _mm_add_ps(ratio, one)), ratio);
    let z = _mm_mul_ps(t, t);
    let [c7, c5, c3, c1] = ATAN_POLYNOMIAL;
    let mut poly = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(c7), z), _mm_set1_ps(c5));
    poly = _mm_add_ps(_mm_mul_ps(poly, z), _mm_set1_ps(c3));
    poly = _mm_add_ps(_mm_mul_ps(poly, z), _mm_set1_ps(c1));
    let mut angle = _mm_add_ps(offset, _mm_add_ps(_mm_mul_ps(_mm_mul_ps(poly, z), t), t));
    angle = select(swap, _mm_sub_ps(_mm_set1_ps(FRAC_PI_2), angle), angle);
    // x's sign bit (−0 included), spread over the lane.
    let negative_x = _mm_castsi128_ps(_mm_srai_epi32(_mm_castps_si128(x), 31));
    select(negative_x, _mm_sub_ps(_mm_set1_ps(PI), angle), angle)
}
